"""What `make demo` leaves, as the README says (CI runs this after `make demo`):

    python tests/tools/check_demo.py demo-out

the run (a result granel reads back, ending at its duration), the paper's report (every figure
and movie it links exists), Figs. 1-11 and the 24 Appendix C movies. Exit 0 when all hold, 1
with one line per miss."""

from __future__ import annotations

import re
import sys
from pathlib import Path


def misses(out: Path) -> list[str]:
    from granel import scenario as S
    from granel.run import load_result
    from granel.studies.paper import CASES

    found = []
    run = out / "paper-rigid-LSGM3-strong.nc"
    try:
        end, duration = float(load_result(run)["time"].values[-1]), S.load("paper").simulation.duration
        if abs(end - duration) > 1e-9 * duration:  # the last output falls at the duration (round-off aside)
            found.append(f"{run}: ends at {end} s, not at the paper's duration {duration} s")
    except Exception as e:  # any failure to read it back is a miss
        found.append(f"{run}: not a result granel reads ({e})")
    paper = out / "paper"
    report = paper / "report.md"
    if not report.is_file():
        return [*found, f"{report}: missing"]
    text = report.read_text(encoding="utf-8")
    links = re.findall(r"\]\(([^)#\s]+)\)", text)
    found += [f"{report} links {link}, which is missing" for link in links
              if "://" not in link and not (paper / link).exists()]
    for k in range(1, 12):
        if not list((paper / "figures").glob(f"fig{k}_*")):
            found.append(f"{paper / 'figures'}: no figure {k}")
    movies = sorted((paper / "animations").glob("*.mp4")) + sorted((paper / "animations").glob("*.gif"))
    if len(movies) != 2 * len(CASES):
        found.append(f"{paper / 'animations'}: {len(movies)} movies, not {2 * len(CASES)}")
    return found


def main(argv: list[str]) -> int:
    out = Path(argv[1] if len(argv) > 1 else "demo-out")
    found = misses(out)
    for line in found:
        print(f"check_demo: {line}")
    if not found:
        print(f"check_demo: {out} holds what the README says make demo leaves")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
