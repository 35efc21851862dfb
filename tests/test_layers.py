"""The layout's rules, read from the code: every folder's `__init__` docstring (and each module
at the package root) ends with a line "May import: ..." naming the folders it may import; an
import of granel's own code that runs against that line fails here, lazy imports inside
functions included. The package root holds only the command line and the run."""

from __future__ import annotations

import ast
import re
import warnings
from pathlib import Path

import pytest

import granel

PACKAGE = Path(granel.__file__).resolve().parent
ROOT_MODULES = {"__init__", "__main__", "cli", "run", "problem"}


def _unit(module: str) -> str:
    """The folder (or root module) a module belongs to: granel.coupling.exact.loop -> coupling."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "granel"


def _may_import(unit: str, package: Path = PACKAGE) -> set[str] | None:
    """The units named by the "May import:" line of a unit's docstring (None: everything)."""
    path = package / unit / "__init__.py" if (package / unit).is_dir() else package / f"{unit}.py"
    doc = ast.get_docstring(ast.parse(path.read_text())) or ""
    lines = [ln for ln in doc.splitlines() if ln.startswith("May import:")]
    assert lines, f"{path}: its docstring has no 'May import:' line"
    text = lines[-1][len("May import:"):].strip().rstrip(".")
    if text == "everything":
        return None
    if text.startswith("nothing"):
        return set()
    return {u.strip() for u in text.split(",")}


# the layers from the bottom up: a unit may import only units below it (its "May import:" line
# chooses among them)
ORDER = ["guard", "io", "solid", "granular", "coupling", "analysis", "problem", "scenario", "run", "viz", "studies",
         "cli"]
# a module named in a string ("granel.coupling.exact.loop:compile_plan", loaded by importlib)
BY_NAME = re.compile(r"^granel(\.[A-Za-z_]\w*)+(:\w+)?$")


def _imports(path: Path, package: Path = PACKAGE) -> list[tuple[int, str]]:
    """(line, module) of every import of granel's code in a file, relative ones resolved, and of
    every module a string names to be loaded by name (importlib)."""
    rel = path.relative_to(package.parent).with_suffix("")
    parts = list(rel.parts)
    is_pkg = parts[-1] == "__init__"
    if is_pkg:
        parts = parts[:-1]
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = parts if is_pkg else parts[:-1]
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target == "granel":  # from granel import scenario: the names are modules or the version
                found += [(node.lineno, f"granel.{a.name}") for a in node.names]
            elif target.startswith("granel."):
                found.append((node.lineno, target))
        elif isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names if a.name.startswith("granel.")]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and BY_NAME.match(node.value):
            found.append((node.lineno, node.value.split(":")[0]))
    return found


def _module(path: Path, package: Path = PACKAGE) -> str:
    rel = path.relative_to(package.parent).with_suffix("")
    return ".".join(p for p in rel.parts if p != "__init__")


def violations(package: Path = PACKAGE) -> list[str]:
    """Every import of a module whose unit's "May import:" line does not name the target's unit."""
    wrong = []
    for path in sorted(p for p in package.rglob("*.py") if "__pycache__" not in p.parts):
        unit = _unit(_module(path, package))
        if unit in ("granel", "__main__"):  # the package itself, `python -m granel`
            continue
        allowed = _may_import(unit, package)
        if allowed is None:
            continue
        for line, target in _imports(path, package):
            other = _unit(target)
            if other == unit or target == "granel.__version__":
                continue
            if other not in allowed:
                wrong.append(f"{path.relative_to(package.parent)}:{line} imports {target} ({unit} may import: "
                             f"{', '.join(sorted(allowed)) or 'nothing'})")
    return wrong


def test_the_root_holds_only_the_command_line_and_the_run():
    assert {p.stem for p in PACKAGE.glob("*.py")} == ROOT_MODULES


@pytest.mark.parametrize("folder", sorted(p.name for p in PACKAGE.iterdir() if (p / "__init__.py").exists()))
def test_every_folder_says_what_lives_there_and_what_it_may_import(folder):
    doc = ast.get_docstring(ast.parse((PACKAGE / folder / "__init__.py").read_text())) or ""
    assert doc.splitlines()[0].strip(), f"{folder}/__init__.py: no docstring"
    assert _may_import(folder) is not None


def test_no_import_runs_against_the_layers():
    wrong = violations()
    assert not wrong, "\n".join(wrong)


def test_the_checker_sees_imports_against_the_order(tmp_path):
    """On a small package of the same shape: a solid module importing the scenario at the top and
    the run inside a function is caught twice; its import of its own folder and of guard is not."""
    pkg = tmp_path / "granel"
    (pkg / "solid").mkdir(parents=True)
    (pkg / "guard").mkdir()
    (pkg / "scenario").mkdir()
    (pkg / "__init__.py").write_text('"""root"""\n')
    (pkg / "run.py").write_text('"""run\nMay import: scenario, solid, guard."""\n')
    (pkg / "solid" / "__init__.py").write_text('"""solids\nMay import: guard."""\n')
    (pkg / "guard" / "__init__.py").write_text('"""guard\nMay import: nothing."""\n')
    (pkg / "scenario" / "__init__.py").write_text('"""scenarios\nMay import: solid, guard."""\n')
    (pkg / "scenario" / "build.py").write_text("from ..solid import plate\n")
    (pkg / "solid" / "plate.py").write_text("from . import modal\nfrom ..guard import exits\nfrom ..scenario import build\n"
                                            "def f():\n    from ..run import run_scenario\n")
    (pkg / "solid" / "modal.py").write_text("")
    (pkg / "guard" / "exits.py").write_text("")
    found = violations(pkg)
    assert len(found) == 2, found
    assert "granel/solid/plate.py:3 imports granel.scenario" in found[0]
    assert "granel/solid/plate.py:5 imports granel.run" in found[1]


def test_a_moved_module_imports_under_its_old_name_with_a_warning():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        from granel.sweep import run_sweep  # noqa: F401 - the old place
    from granel.studies.sweep import run_sweep as new

    assert run_sweep is new
    assert any("granel.sweep moved to granel.studies.sweep" in str(w.message) for w in caught)


def test_the_layers_are_ordered():
    """Every unit is in ORDER, and its "May import:" line names only units below it: a folder
    cannot allow a higher one."""
    units = {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").exists()} | {"run", "problem", "cli"}
    assert units == set(ORDER), sorted(units ^ set(ORDER))
    wrong = []
    for unit in ORDER:
        allowed = _may_import(unit)
        below = set(ORDER[: ORDER.index(unit)])
        if allowed is None:
            assert unit == ORDER[-1], f"{unit} may import everything, but it is not the top"
            continue
        wrong += [f"{unit} may import {u}, which is not below it" for u in sorted(allowed - below)]
    assert not wrong, wrong


def test_a_module_loaded_by_name_is_an_import(tmp_path):
    """On a small package: a lower unit naming a higher module in a string is caught."""
    pkg = tmp_path / "granel"
    (pkg / "guard").mkdir(parents=True)
    (pkg / "coupling").mkdir()
    (pkg / "__init__.py").write_text('"""root"""\n')
    (pkg / "guard" / "__init__.py").write_text('"""guard\nMay import: nothing."""\n')
    (pkg / "coupling" / "__init__.py").write_text('"""coupling\nMay import: guard."""\n')
    (pkg / "guard" / "ahead.py").write_text('PLAN = "granel.coupling.loop:compile_plan"\n')
    (pkg / "coupling" / "loop.py").write_text('ENTRY = "granel.guard.ahead"\n')
    found = violations(pkg)
    assert len(found) == 1 and "granel/guard/ahead.py:1 imports granel.coupling.loop" in found[0], found


# what reads a scenario's text: its TOML parser, the scenario's own readers and validators
PARSERS = {("tomllib", "loads"), ("tomllib", "load"), ("S", "load_raw"), ("S", "validate"), ("Scenario", "model_validate"),
           ("S", "apply_overrides")}
PARSING_UNITS = {"scenario", "run"}


def scenario_parses(package: Path = PACKAGE) -> list[str]:
    """Every call outside the scenario layer and the run that parses a scenario (`PARSERS`), and
    every reading of a result's stored scenario text (`attrs["scenario"]` parsed or indexed)."""
    found = []
    for path in sorted(p for p in package.rglob("*.py") if "__pycache__" not in p.parts):
        unit = _unit(_module(path, package))
        if unit in PARSING_UNITS or path.name == "reading.py":  # guard.reading: the one reader of users' files
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and isinstance(node.func.value, ast.Name):
                if (node.func.value.id, node.func.attr) in PARSERS:
                    found.append(f"{path.relative_to(package.parent)}:{node.lineno} calls "
                                 f"{node.func.value.id}.{node.func.attr}")
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in ("load_raw", "validate"):
                found.append(f"{path.relative_to(package.parent)}:{node.lineno} calls {node.func.id}")
    return found


def test_only_the_scenario_layer_and_the_run_parse_a_scenario():
    """A result is read through its model record (`analysis.result_model`), never by parsing the
    scenario text it stores again."""
    found = scenario_parses()
    assert not found, "\n".join(found)


def test_the_pictures_do_not_import_the_run():
    assert "run" not in (_may_import("viz") or {"run"})
    wrong = [v for v in violations() if v.startswith("granel/viz/") and "granel.run" in v]
    assert not wrong, wrong


@pytest.mark.parametrize("solver,sparse", [("paper", None), ("fast", None), ("fast-newmark", None), ("paper", True)],
                         ids=["paper's algorithm", "exact modal", "modal Newmark", "sparse Newmark"])
def test_each_solver_is_a_solver(solver, sparse):
    """Every solver `run.make_solver` gives satisfies `coupling.protocol.Solver`: its attributes,
    and its methods with the protocol's parameters."""
    import inspect

    from granel import scenario as S
    from granel.coupling.protocol import Solver
    from granel.run import make_solver

    sets = ['solid.kind="beam"', 'simulation.duration="0.01ms"',
            f'simulation.solver="{solver.split("-")[0]}"'] + (['simulation.integrator="newmark"'] if "newmark" in solver else [])
    made = make_solver(S.build_problem(S.load("paper", sets)), sparse=sparse)
    assert isinstance(made, Solver), type(made).__name__
    for name, member in vars(Solver).items():
        if callable(member) and not name.startswith("_"):
            want = list(inspect.signature(member).parameters)[1:]
            have = list(inspect.signature(getattr(made, name)).parameters)
            assert have[: len(want)] == want, f"{type(made).__name__}.{name}{tuple(have)}: the protocol's is {tuple(want)}"
    assert isinstance(made.name, str) and made.name
