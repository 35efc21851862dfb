"""Which fields a scenario's run uses: an override (`--set`, a sweep's axis or overrides, a
design's variable) that names a field the run ignores is refused, naming why, instead of
running as if it had been honoured (a constant load's `tau`, a rigid solid's `thickness`).

Fields written in a scenario file itself are not refused when a shortcut makes them idle (the
paper's plate thickness under `--solid rigid`): only what the user asks to change is checked."""

from __future__ import annotations

from ..granular.loads import KINDS
from ..solid.kinds import KINDS as SOLID_KINDS
from .schema import Scenario, ScenarioError

# the load fields each kind of excitation reads (its class's `fields`), besides these
LOAD_COMMON = {"granule", "kind", "direction"}
LOAD_FIELDS = {kind: set(cls.fields) for kind, cls in KINDS.items()}
# the solid fields each kind builds with (`SolidKind.fields`); the position and size also place
# the media and the contact points of every kind
SOLID_FIELDS = {name: set(kind.fields) for name, kind in SOLID_KINDS.items()} | {"none": {"kind"}}
# the fast method's exact integrator alone reads these (`coupling.exact.solver.ExactSolver`)
EXACT_ONLY = {"integrator", "force_model", "adaptive", "rtol", "atol", "ledger_tol", "max_step", "mode_cutoff", "modes"}


def unused_reason(sc: Scenario, path: str) -> str | None:
    """Why the run of `sc` ignores the field at dotted `path` (list items by index), or None."""
    parts = path.strip().split(".")
    head = parts[0]
    if head == "excitations" and len(parts) >= 3 and parts[1].isdigit() and int(parts[1]) < len(sc.excitations):
        e, field = sc.excitations[int(parts[1])], parts[2]
        if field not in LOAD_COMMON and field not in LOAD_FIELDS[e.kind]:
            return (f"a {e.kind} load does not use {field} (it uses "
                    f"{', '.join(sorted(LOAD_FIELDS[e.kind]))})")
    if head == "solid" and len(parts) >= 2:
        kind = "none" if sc.solid is None else sc.solid.kind
        if parts[1] not in SOLID_FIELDS[kind]:
            return f"a {kind} solid does not use {parts[1]}" if kind != "none" else "the scenario has no solid"
    if head == "simulation" and len(parts) == 2:
        sim = sc.simulation
        fixed_anyway = parts[1] == "adaptive" and not sim.adaptive  # Newmark and the paper's steps are fixed
        if parts[1] in EXACT_ONLY - {"integrator"} and (sim.solver == "paper" or sim.integrator == "newmark") \
                and not fixed_anyway:
            which = "the paper's algorithm" if sim.solver == "paper" else "the Newmark integrator"
            return f"{which} does not use {parts[1]} (only the fast method's exact integrator does)"
        if parts[1] == "integrator" and sim.solver == "paper":
            return "the paper's algorithm has its own integrator (simulation.integrator belongs to solver = \"fast\")"
    if head == "media" and len(parts) >= 3 and parts[1].isdigit() and int(parts[1]) < len(sc.media):
        m, field = sc.media[int(parts[1])], parts[2]
        if m.granules_file and field in ("gap", "labels", "channel_walls", "outer_wall", "center_y", "face_x"):
            return f"a medium from granules_file takes its geometry and labels from the file, not {field}"
        if m.radii is not None and field in ("labels", "channel_walls", "outer_wall"):
            return f"a chain (radii) does not use {field} (its walls are `walls`, its labels 1..n)"
    return None


def check_overrides_used(sc: Scenario, overrides) -> None:
    """ScenarioError (exit 2) for the first `key=value` override whose field the run ignores
    (removals, `key=-`, are not checked)."""
    for item in overrides or []:
        if "=" not in item:
            continue
        key, value = item.split("=", 1)
        if value.strip() == "-":
            continue
        why = unused_reason(sc, key)
        if why:
            raise ScenarioError(f"{key.strip()} = {value.strip()}: the run does not use this field: {why}")
