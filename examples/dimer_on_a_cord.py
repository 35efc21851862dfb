"""A granular dimer chain striking a tensioned cord: how much of the shock's energy the cord takes,
as its tension (its impedance 2 sqrt(T rho A)) changes.

The built-in study scenarios/string/dimer-cord.toml (twenty steel beads alternating 5 and 3 mm in
radius, on a 1 x 1 mm steel wire 0.3 m long, held at both ends) is run at several tensions; for
each, the share of the input work the cord holds 1.2 ms after the shock (the pulse has crossed
into it, and its waves have not yet come back from its ends: the cord is made long enough), and
what the chain keeps (the rest the contacts' dashpots dissipated). docs/solids.md ("String")
shows the figure.

    python examples/dimer_on_a_cord.py                 # six tensions, about 10 s
    GRANEL_EXAMPLE_QUICK=1 python examples/...         # three
"""

import math
import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from granel import scenario as S  # noqa: E402
from granel.run import run_scenario  # noqa: E402

HERE = Path(__file__).resolve().parent
SCENARIO = HERE.parent / "scenarios" / "string" / "dimer-cord.toml"
quick = bool(os.environ.get("GRANEL_EXAMPLE_QUICK"))
tensions = [5.0, 80.0, 1200.0] if quick else [5.0, 20.0, 80.0, 300.0, 1200.0, 3000.0]  # up to 3 GPa in the wire
WINDOW = 1.2e-3  # the pulse reaches the cord at about 0.34 ms and has crossed its contact by 1 ms

rows = []
for T in tensions:
    base = S.load(str(SCENARIO))
    s = base.solid
    rho_a = base.materials[s.material].rho * s.width * s.thickness
    c = math.sqrt(T / rho_a)
    # a cord long enough that its waves return to the chain (after L / c) only after the window,
    # with 1 mm elements and its middle on a node
    elements = 2 * max(150, math.ceil(c * WINDOW / 2e-3))
    length = elements * 1e-3
    ds = run_scenario(S.load(str(SCENARIO), [f"solid.tension={T}", f"solid.length={length!r}",
                                             f"solid.beam_elements={elements}", f"simulation.duration={WINDOW!r}"]))
    work = float(ds["input_work"].values[-1])
    cord = float(ds["energy_solid"].values[-1]) / work
    chain = float(ds["energy_d"].values[-1]) / work
    rows.append((T, 2 * math.sqrt(T * rho_a), cord, chain))
    print(f"T = {T:6.0f} N  impedance {rows[-1][1]:5.2f} N s/m  cord takes {100 * cord:5.1f} %  "
          f"chain keeps {100 * chain:5.1f} % (a {length:.2f} m cord)")

T, Z, cord, chain = map(np.array, zip(*rows))
fig, ax = plt.subplots(figsize=(6, 4))
ax.semilogx(Z, 100 * cord, "o-", label="held by the cord")
ax.semilogx(Z, 100 * chain, "s--", label="share left in the chain")
ax.set_xlabel("cord impedance 2 sqrt(T rho A) [N s/m]")
ax.set_ylabel("share of the input work at 1.2 ms [%]")
ax.set_title("a dimer chain striking a tensioned cord")
ax.grid(True, which="both", alpha=0.3)
ax.legend()
fig.tight_layout()
fig.savefig("dimer_cord.png", dpi=120)
print("wrote dimer_cord.png")
