"""What a run will need, estimated from its scenario before anything is built (`run_needs`), so
that a mistyped count or duration is refused with its estimate (`guard.resources`) instead of
ending in a MemoryError, a swap storm or a disk full of a partial result.

The model counts what granel keeps in memory: each granule's arrays and contact lists, the state
of every output (six numbers a stored granule, held twice: while running and in the result), every
accepted step's record (a fixed step's count is exact; an adaptive run takes at least
duration / max_step), the solid's assembled matrices and, up to `solid.modal.DENSE_LIMIT`
degrees of freedom, its dense eigen-solution, beyond them its sparse factors and the Lanczos
vectors of its lowest modes, and the modal state of every solid output; the
result file what `simulation.outputs` keeps, uncompressed (compression only makes it smaller)."""

from __future__ import annotations

from dataclasses import dataclass

from ..coupling.settings import LARGE_SOLID_MODES
from ..solid.kinds import kind_of
from .schema import Scenario, present_solid

BYTES_PER_GRANULE = 2048  # arrays, neighbour and wall candidates, labels
BYTES_PER_GRANULE_OUTPUT = 2 * 6 * 8  # x, y, theta, v_x, v_y, omega in float64, twice
BYTES_PER_ELEMENT = 6 * 1024  # a Q8 element's 16 x 16 blocks of K and M in COO form
DENSE_LIMIT = 8000  # solid.modal.DENSE_LIMIT: all modes by a dense solver up to this many DOFs
# beyond DENSE_LIMIT a solid is factorised (shift-invert Lanczos, the residual modes' static
# solve, sparse Newmark): SuperLU's factors of a plate's K hold FILL sqrt(n) nonzeros per DOF, 12
# bytes each (measured 1.4-2.0 on Morley's plate of 14k-57k DOFs, 3.3-3.6 on Mindlin's of
# 19k-76k: the smallest, so the estimate stays a lower bound)
FILL = 1.4
BYTES_PER_FACTOR_ENTRY = 12
# the exact integrator's modes of a large solid: up to LARGE_SOLID_MODES of them, found by Lanczos
# with 2 k + 1 basis vectors (scipy's eigsh), then held as shapes
LANCZOS_VECTORS_PER_MODE = 3
RESULT_OVERHEAD = 128 * 1024  # a result file's HDF5 headers, coordinates and attributes


@dataclass(frozen=True)
class Needs:
    granules: int
    outputs: int
    steps: int  # accepted steps recorded (a lower bound for adaptive runs)
    solid_dofs: int
    memory: float  # bytes
    result: float  # bytes of the result file

    def describe(self) -> str:
        parts = [f"{self.granules:,} granules", f"{self.outputs:,} outputs", f"{self.steps:,} steps"]
        if self.solid_dofs:
            parts.append(f"a solid of about {self.solid_dofs:,} degrees of freedom")
        return ", ".join(parts)


def granule_count(sc: Scenario) -> int:
    """Granules of the hexagonal media and chains (granule tables count once read: 0 here)."""
    n = 0
    for m in sc.media:
        if m.radii is not None:
            n += len(m.radii)
        elif m.columns is not None:
            n += sum(m.columns)
    return n


def solid_dofs(sc: Scenario, focus=()) -> tuple[int, int]:
    """(degrees of freedom, elements) of the scenario's solid, at least, as its kind counts them
    (`SolidKind.size`; `focus`: the contacts' heights, once known); (0, 0) without an elastic
    solid."""
    s = present_solid(sc)
    return (0, 0) if s is None else kind_of(s.kind).size(s, focus)


def run_needs(sc: Scenario, granules: int | None = None, focus=()) -> Needs:
    """The memory and result size of a run of `sc` (`granules`: the built count, if known;
    `focus`: the heights y of the solid's contacts, if known)."""
    sim = sc.simulation
    n = granule_count(sc) if granules is None else granules
    outputs = int(min(sim.duration / sim.output_every, 1e18)) + 1
    fixed = not (sim.solver == "fast" and sim.integrator == "exact" and sim.adaptive)
    steps = int(min(sim.duration / (sim.dt if fixed else sim.max_step), 1e18))
    ndof, nel = solid_dofs(sc, focus)
    contacts = (len(focus) or sum(m.columns[0] if m.columns else 1 for m in sc.media if m.side != "none")) if ndof else 0
    solid_every = sim.solid_output_every or sim.output_every
    solid_outputs = int(min(sim.duration / solid_every, 1e18)) + 1 if ndof else 0
    modal = ndof if ndof <= DENSE_LIMIT else 0
    factor = BYTES_PER_FACTOR_ENTRY * FILL * ndof**1.5 if ndof > DENSE_LIMIT else 0.0
    lanczos = LANCZOS_VECTORS_PER_MODE * LARGE_SOLID_MODES * ndof * 8 if ndof > DENSE_LIMIT and not fixed else 0.0
    kept = sim.outputs  # what the run keeps and stores (simulation.outputs)
    traced = n if kept.granules == "all" else 0 if kept.granules == "none" else len(kept.granules)
    solid_outputs *= kept.solid
    memory = (n * BYTES_PER_GRANULE + outputs * traced * BYTES_PER_GRANULE_OUTPUT + steps * 2 * (4 + contacts) * 8
              + nel * BYTES_PER_ELEMENT + 3.0 * modal * modal * 8 + factor + lanczos
              + solid_outputs * max(modal, ndof) * 2 * (8 + 4))
    result = (RESULT_OVERHEAD + outputs * (traced * 6 * 8 + 16 * 8 + kept.contacts * contacts * 3 * 8)
              + kept.steps * steps * (4 + contacts) * 8 + solid_outputs * max(modal, ndof) * 2 * 4)
    return Needs(n, outputs, steps, ndof, float(memory), float(result))


def check_needs(sc: Scenario, granules: int | None = None, focus=()) -> Needs:
    """ResourceError (exit 2) when a run of `sc` needs more memory than this process may use."""
    from ..guard.resources import check_memory

    needs = run_needs(sc, granules, focus)
    check_memory(needs.memory, f"this run ({needs.describe()})",
                 "lower the counts (media columns, solid mesh), simulation.duration, or store fewer outputs "
                 "(simulation.output_every, simulation.solid_output_every); GRANEL_MAX_MEMORY sets the limit")
    return needs
