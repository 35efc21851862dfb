"""The commands the README and the docs show, run as written (issue 37, item 2).

Every shell block (```sh) of README.md and docs/*.md is read, continuation lines joined, a
trailing `# comment` kept as the command's promise. The quick suite checks that each `granel`
command parses (the command exists, its options and arguments are accepted: the command line's
own parser, nothing runs), that the `granel` commands quoted in the prose name real options, that
each `make` target exists and that CI runs what the README's blocks show. The slow suite runs each
page's commands in order in a scratch folder holding a copy of `scenarios/`, each shortened only
where it must be (`SHORTER`: fewer trials, fewer frequencies, a sweep's axes cut to their ends,
local stand-ins for a cluster's head node and shared folder), and requires exit 0, the outputs
the command names (its -o/--out/--output/--plot path and the files its comment lists), and JSON
on standard output where it asks for JSON."""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import socket
import subprocess
import sys
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest
import tomli_w
from typer.main import get_command

from granel.cli import app

ROOT = Path(__file__).resolve().parent.parent
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SHELL = {"sh", "bash", "shell", "console"}
NOT_SHELL = {"python", "toml", "csv", "json", "yaml", "text", "md", "markdown"}
PROGRAMS = {"granel", "make", "dask"}
OUTPUT_OPTIONS = ("-o", "--output", "--out", "--plot")
# a file a comment promises: a name with one of these suffixes
PROMISED = re.compile(r"(?<![\w/.-])([\w-]+(?:\.[\w-]+)*\.(?:toml|md|nc|png|pdf|mp4|gif|csv|pvd|extxyz|json|xdmf))\b")
TIMEOUT = 900  # seconds a shown command may take here (the longest, `granel paper`, takes about 3 min)


@dataclass(frozen=True)
class Shown:
    """One command as a page shows it."""

    page: Path
    line: int
    text: str
    comment: str = ""
    inline: bool = False  # quoted in the prose, not in a block

    @property
    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"

    @property
    def words(self) -> list[str]:
        return shlex.split(self.text, comments=True)

    @property
    def argv(self) -> list[str]:
        """The words before a redirection."""
        w = self.words
        return w[: w.index("<")] if "<" in w else w

    @property
    def stdin(self) -> str | None:
        w = self.words
        return w[w.index("<") + 1] if "<" in w else None

    @property
    def program(self) -> str:
        return self.argv[0]


def _split_comment(line: str) -> tuple[str, str]:
    """(command, comment) of a shell line: the comment starts at a `#` that begins a word outside
    quotes."""
    quote = None
    for i, c in enumerate(line):
        if quote:
            quote = None if c == quote else quote
        elif c in "'\"":
            quote = c
        elif c == "#" and (i == 0 or line[i - 1].isspace()):
            return line[:i].rstrip(), line[i:].lstrip("# ").strip()
    return line.rstrip(), ""


def shown_commands(page: Path) -> list[Shown]:
    """The commands of `page`'s shell blocks, in order."""
    out, fence, pending, start = [], None, "", 0
    for number, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
        stripped = line.strip()
        if stripped.startswith("```"):
            fence = None if fence is not None else (stripped[3:].strip().split() or [""])[0]
            continue
        if fence not in SHELL:
            continue
        if not pending and (not stripped or stripped.startswith("#")):
            continue  # a comment line: what a command printed, or a note
        if not pending:
            start = number
        if stripped.endswith("\\"):
            pending += stripped[:-1] + " "
            continue
        text, comment = _split_comment(pending + stripped)
        pending = ""
        out.append(Shown(page, start, text, comment))
    return out


def inline_commands(page: Path) -> list[Shown]:
    """`granel ...` and `make ...` commands quoted in the prose (outside blocks)."""
    out, fence = [], False
    for number, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
        if line.strip().startswith("```"):
            fence = not fence
            continue
        if fence:
            continue
        for m in re.finditer(r"`((?:granel|make) [^`]+)`", line):
            out.append(Shown(page, number, m.group(1), inline=True))
    return out


ALL_SHOWN = [s for p in PAGES for s in shown_commands(p)]
ALL_INLINE = [s for p in PAGES for s in inline_commands(p)]


# ------------------------------------------------------------------------------------------------
# quick: every shown command is one the tools know


GROUP = get_command(app)


def parse_granel(argv: list[str], strict: bool = True) -> tuple[str, dict]:
    """(command name, its parameters) as `granel` parses `argv` (after the program's name), or
    the parser's own error (an unknown command or option, a missing or extra argument). Not
    strict: arguments may be missing or extra (a command quoted in the prose), options not."""
    if all(w.startswith("-") for w in argv):  # the program's own options (--version, --help): not run
        unknown = [w for w in argv if w not in {o for p in GROUP.params for o in p.opts} | {"--help"}]
        assert not unknown, f"granel has no option {unknown}"
        return "", {}
    ctx = GROUP.make_context("granel", list(argv), resilient_parsing=not strict)
    rest = [*getattr(ctx, "_protected_args", getattr(ctx, "protected_args", [])), *ctx.args]
    if not rest:
        raise AssertionError("no command after granel")
    name, cmd, rest = GROUP.resolve_command(ctx, rest)
    sub = cmd.make_context(name, rest, parent=ctx, resilient_parsing=not strict)
    return name, sub.params


def makefile_targets() -> set[str]:
    text = (ROOT / "Makefile").read_text(encoding="utf-8")
    return {m.group(1) for m in re.finditer(r"^([\w.-]+)\s*:(?!=)", text, re.M)}


def make_targets(argv: list[str]) -> list[str]:
    """The targets of a `make` command line (variables VAR=value and options left out)."""
    return [w for w in argv[1:] if "=" not in w and not w.startswith("-")]


def _ids(shown: Shown) -> str:
    return f"{shown.where} {shown.text[:60]}"


def test_the_pages_show_commands():
    """The reader finds the blocks: the README's command list and every page's runnable blocks."""
    readme = [s for s in ALL_SHOWN if s.page.name == "README.md"]
    assert sum(s.program == "granel" for s in readme) >= 15, [s.text for s in readme]
    assert {s.program for s in ALL_SHOWN} <= PROGRAMS, sorted({s.program for s in ALL_SHOWN} - PROGRAMS)
    assert any(s.stdin for s in readme), "the README shows a scenario read from standard input"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_command_hides_in_a_block_that_is_not_run(page):
    """A block of another language that holds shell commands would escape these tests."""
    fence, hidden = None, []
    for number, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
        stripped = line.strip()
        if stripped.startswith("```"):
            fence = None if fence is not None else (stripped[3:].strip().split() or [""])[0]
            continue
        if fence is not None and fence not in SHELL | NOT_SHELL and re.match(r"(granel|make) \w", stripped):
            hidden.append(f"{number}: ```{fence}: {stripped}")
    assert not hidden, hidden


def synopses(page: Path) -> list[Shown]:
    """`granel COMMAND ...` lines of ```text blocks: a command's synopsis (brackets for options)."""
    out, fence = [], None
    for number, line in enumerate(page.read_text(encoding="utf-8").splitlines(), 1):
        stripped = line.strip()
        if stripped.startswith("```"):
            fence = None if fence is not None else (stripped[3:].strip().split() or [""])[0]
            continue
        if fence == "text" and stripped.startswith("granel "):
            out.append(Shown(page, number, stripped))
    return out


def options_of(command: str) -> set[str]:
    ctx = GROUP.make_context("granel", [command], resilient_parsing=True)
    cmd = GROUP.get_command(ctx, command)
    assert cmd is not None, f"no command granel {command}"
    return {o for p in cmd.params for o in (*p.opts, *p.secondary_opts)}


@pytest.mark.parametrize("shown", [s for p in PAGES for s in synopses(p)], ids=_ids)
def test_every_synopsis_names_real_options(shown):
    command = shown.text.split()[1]
    named = set(re.findall(r"(?<![\w-])(--?[a-z][\w-]*)", shown.text))
    unknown = named - options_of(command)
    assert not unknown, f"{shown.where}: granel {command} has no option {sorted(unknown)}"


@pytest.mark.parametrize("shown", [s for s in ALL_SHOWN if s.program == "granel"], ids=_ids)
def test_every_shown_granel_command_parses(shown):
    try:
        parse_granel(shown.argv[1:])
    except Exception as e:  # the parser's own errors (click's UsageError and kin)
        pytest.fail(f"{shown.where}: `{shown.text}`: {getattr(e, 'format_message', lambda: str(e))()}")


@pytest.mark.parametrize("shown", [s for s in ALL_INLINE if s.program == "granel"], ids=_ids)
def test_granel_commands_in_the_prose_name_real_options(shown):
    try:
        parse_granel(shown.argv[1:], strict=False)
    except Exception as e:
        pytest.fail(f"{shown.where}: `{shown.text}`: {getattr(e, 'format_message', lambda: str(e))()}")


@pytest.mark.parametrize("shown", [s for s in ALL_SHOWN + ALL_INLINE if s.program == "make"], ids=_ids)
def test_every_shown_make_target_exists(shown):
    missing = [t for t in make_targets(shown.argv) if t not in makefile_targets()]
    assert not missing, f"{shown.where}: `{shown.text}`: no Makefile target {missing}"


def test_ci_runs_what_the_readme_blocks_show():
    """What the README promises, CI runs: each make target of its blocks, whole, in .ci/run."""
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    ran = {w for line in ci.splitlines() if line.strip().startswith("make ") for w in make_targets(shlex.split(line))}
    shown = {t for s in ALL_SHOWN if s.program == "make" and s.page.name == "README.md" for t in make_targets(s.argv)}
    assert shown and shown <= ran, f"the README shows make {sorted(shown - ran)}, which .ci/run never runs"


def test_dask_commands_exist_beside_granel():
    """The cluster's commands the docs show come with granel's dependencies."""
    for s in ALL_SHOWN:
        if s.program == "dask":
            assert shutil.which("dask", path=str(Path(sys.executable).parent)), f"{s.where}: no dask command"


# ------------------------------------------------------------------------------------------------
# slow: every page's commands run, shortened only where they must be


TRIALS = 4  # a design's trials: enough for the screening, the ranking and the confirmation
WORKERS = 2  # this machine's cores


def _option(argv: list[str], *names: str) -> int | None:
    for i, w in enumerate(argv):
        if w in names and i + 1 < len(argv):
            return i
    return None


def fewer_trials(argv: list[str]) -> list[str]:
    """A design runs TRIALS trials (at most what it shows): the search's steps, not its length."""
    if argv[:2] != ["granel", "design"]:
        return argv
    i = _option(argv, "--trials")
    if i is None:
        return [*argv, "--trials", str(TRIALS)]
    return [*argv[: i + 1], str(min(int(argv[i + 1]), TRIALS)), *argv[i + 2:]]


def fewer_frequencies(argv: list[str]) -> list[str]:
    """A spectrum over START:STOP:COUNT runs its two highest-frequency points (a run lasts a
    number of drive periods, so the high end is the short one)."""
    i = _option(argv, "--frequencies")
    if argv[:2] != ["granel", "spectrum"] or i is None or argv[i + 1].count(":") != 2:
        return argv
    start, stop, count = argv[i + 1].split(":")
    if int(count) <= 2:
        return argv
    from granel.studies.spectrum import parse_frequency

    top = parse_frequency(stop)
    return [*argv[: i + 1], f"{top / 2:g}:{top:g}:2", *argv[i + 2:]]


def fewer_cluster_workers(argv: list[str]) -> list[str]:
    """`dask worker --nworkers N`: at most this machine's cores."""
    i = _option(argv, "--nworkers")
    if argv[:2] != ["dask", "worker"] or i is None:
        return argv
    return [*argv[: i + 1], str(min(int(argv[i + 1]), WORKERS)), *argv[i + 2:]]


SHORTER = (fewer_trials, fewer_frequencies, fewer_cluster_workers)


def trimmed_study(path: Path) -> None:
    """A sweep file cut to the ends of each axis (2 values each), in place: the same cases' kinds,
    fewer of them."""
    spec = tomllib.loads(path.read_text(encoding="utf-8"))
    for axis in spec.get("axes", []):
        for key in ("values", "labels"):
            if key in axis and len(axis[key]) > 2:
                axis[key] = [axis[key][0], axis[key][-1]]
        for key in ("logspace", "linspace"):
            if key in axis and axis[key][2] > 2:
                axis[key] = [axis[key][0], axis[key][1], 2]
    path.write_text(tomli_w.dumps(spec), encoding="utf-8")


class Cluster:
    """A local dask scheduler and worker standing in for a cluster's head node (HEAD), started
    by the page's own `dask scheduler` / `dask worker` lines, or on first use of HEAD."""

    def __init__(self, scratch: Path):
        self.scratch, self.procs, self.port, self.workers = scratch, [], None, 0

    def _free_port(self) -> int:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            return s.getsockname()[1]

    def start(self, argv: list[str]) -> None:
        dask = str(Path(sys.executable).parent / "dask")
        if argv[1] == "scheduler":
            self.port = self._free_port()
            self._spawn([dask, "scheduler", "--host", "127.0.0.1", "--port", str(self.port),
                         "--no-dashboard"])
            self._wait_port()
        elif argv[1] == "worker":
            if self.port is None:
                self.start(["dask", "scheduler"])
            rest = [w.replace("HEAD", "127.0.0.1").replace(":8786", f":{self.port}") for w in argv[2:]]
            self._spawn([dask, "worker", *rest, "--no-dashboard"])
            self.workers += 1

    def address(self) -> str:
        if self.port is None:
            self.start(["dask", "scheduler"])
        if not self.workers:
            self.start(["dask", "worker", "tcp://HEAD:8786", "--nworkers", "1", "--nthreads", "1"])
        return f"127.0.0.1:{self.port}"

    def _spawn(self, cmd):
        log = open(self.scratch / f".{cmd[1]}-{len(self.procs)}.log", "wb")
        self.procs.append(subprocess.Popen(cmd, cwd=self.scratch, stdout=log, stderr=subprocess.STDOUT))

    def _wait_port(self, seconds: float = 60.0):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", self.port)) == 0:
                    return
            time.sleep(0.2)
        raise AssertionError(f"the dask scheduler did not listen on {self.port} within {seconds} s")

    def stop(self):
        for p in reversed(self.procs):
            p.terminate()
        for p in self.procs:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()


def placed(argv: list[str], scratch: Path, cluster: Cluster) -> list[str]:
    """Placeholders made real: the head node HEAD is the local stand-in; an absolute path that is
    not on this machine (a cluster's shared folder) lands in the scratch folder."""
    out = []
    for w in argv:
        if "HEAD" in w:
            w = re.sub(r"HEAD:\d+", cluster.address(), w)
        elif w.startswith("/") and not Path(w).exists() and not Path(w).parent.exists():
            w = str(scratch / w.lstrip("/"))
        out.append(w)
    return out


def promised_outputs(shown: Shown, argv: list[str], name: str, params: dict) -> list[Path]:
    """What the command says it writes: its output options' paths (a folder's files named in the
    comment inside it), `granel init NAME`'s NAME.toml, and the files its comment names."""
    paths = []
    i = _option(argv, *OUTPUT_OPTIONS)
    target = Path(argv[i + 1]) if i is not None else None
    if target is not None:
        paths.append(target)
    if name == "init" and target is None:
        paths.append(Path(f"{params['name']}.toml"))
    folder = target if target is not None and not target.suffix else Path(".")
    paths += [folder / m for m in PROMISED.findall(shown.comment) if m not in {p.name for p in paths}]
    return paths


def run_page(page: Path, scratch: Path) -> list[str]:
    """Run `page`'s commands in order in `scratch`; the failures, as lines."""
    shutil.copytree(ROOT / "scenarios", scratch / "scenarios")
    for study in (scratch / "scenarios" / "sweeps").glob("*.toml"):
        trimmed_study(study)
    cluster, failures = Cluster(scratch), []
    env = {**os.environ, "COLUMNS": "200"}
    try:
        for shown in shown_commands(page):
            if shown.program == "make":
                continue  # CI runs the README's make targets whole (test_ci_runs_what_the_readme_blocks_show)
            argv = shown.argv
            for rule in SHORTER:
                argv = rule(argv)
            argv = placed(argv, scratch, cluster)
            if shown.program == "dask":
                cluster.start(argv)
                continue
            name, params = parse_granel(argv[1:])
            stdin = open(scratch / shown.stdin, "rb") if shown.stdin else subprocess.DEVNULL
            t0 = time.perf_counter()
            try:
                proc = subprocess.run([sys.executable, "-m", "granel", *argv[1:]], cwd=scratch, stdin=stdin, env=env,
                                      capture_output=True, text=True, timeout=TIMEOUT)
            finally:
                if shown.stdin:
                    stdin.close()
            took = time.perf_counter() - t0
            said = f"{shown.where}: `{shown.text}`" + (f" (run as `{shlex.join(argv)}`)" if argv != shown.argv else "")
            print(f"{took:7.1f} s  {said}")
            if proc.returncode != 0:
                failures.append(f"{said}: exit {proc.returncode}: {proc.stderr.strip()[-800:]}")
                continue
            missing = [str(p) for p in promised_outputs(shown, argv, name, params) if not (scratch / p).exists()]
            if missing:
                failures.append(f"{said}: did not write {missing}")
            if any(w in ("--json", "--json-summary") for w in argv):
                try:
                    json.loads(proc.stdout)
                except json.JSONDecodeError as e:
                    failures.append(f"{said}: standard output is not JSON ({e}): {proc.stdout[:200]!r}")
    finally:
        cluster.stop()
    return failures


RUNNABLE = [p for p in PAGES if any(s.program != "make" for s in shown_commands(p))]


@pytest.mark.slow
@pytest.mark.parametrize("page", RUNNABLE, ids=lambda p: str(p.relative_to(ROOT)))
def test_the_shown_commands_run_and_write_what_they_promise(page, tmp_path):
    failures = run_page(page, tmp_path)
    assert not failures, "\n".join(failures)


def python_blocks(page: Path) -> str:
    """The page's Python blocks, joined in order (each continues the one before)."""
    text = page.read_text(encoding="utf-8")
    return "\n".join(m.group(1) for m in re.finditer(r"^```python\n(.*?)^```", text, re.M | re.S))


@pytest.mark.slow
def test_the_readme_python_runs(tmp_path):
    code = python_blocks(ROOT / "README.md")
    assert "run_scenario" in code
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=TIMEOUT)
    assert proc.returncode == 0, proc.stderr[-2000:]
