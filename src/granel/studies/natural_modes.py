"""The natural modes of a scenario's solid (`granel modes`): periods and kinds, and Fig. 6."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from .. import scenario as S
from ..solid.base import SolidModel
from ..solid.modal import Modes, classify_modes, modal_analysis

FIG6_MODES = (0, 3, 6)  # the modes Fig. 6 draws beside the mesh (1, 4 and 7)
CLASSIFIED = 7  # the modes classified at least (all if the solid has fewer)


@dataclass
class ScenarioModes:
    """A solid's lowest modes: `shown` of them reported, `kinds` of at least the first
    `CLASSIFIED`."""

    solid: SolidModel
    modes: Modes
    kinds: list[str]
    shown: int
    plot: Path | None = None

    def summary(self) -> dict:
        """The numbers `granel modes --json` prints."""
        out = {
            "solid": self.solid.kind,
            "dofs": self.solid.ndof,
            "elements": self.solid.nelements,
            "periods_ms": [float(p) for p in self.modes.periods[: self.shown] * 1e3],
            "kinds": self.kinds[: self.shown],
            "modes_computed": self.modes.count,
        }
        if self.plot is not None:
            out["plot"] = str(self.plot)
        return out


def scenario_modes(sc: S.Scenario, count: int, plot=None) -> ScenarioModes:
    """The lowest `count` modes of the scenario's elastic solid (`solid.modal.modal_analysis`),
    each classified bending / axial / bulk (`classify_modes`). Only the granular system (for the
    contact points) and the solid are built: no static equilibrium. With `plot`, Fig. 6 (the mesh
    and modes 1, 4 and 7) is drawn there, so at least 7 modes are computed."""
    from ..viz.plots import plot_modes  # lazy: matplotlib only for --plot

    if count < 1:
        raise S.ScenarioError(f"--count {count}: give a whole number of modes >= 1")
    if S.elastic_solid(sc) is None:
        raise S.ScenarioError(f"modes: the solid is {sc.solid.kind if sc.solid else 'none'}, which has no modes; choose "
                              "an elastic one (--solid plate or --solid beam)")
    system, _, _ = S.build_granular(sc, sc.base)
    solid = S.build_solid(sc, system)
    want = max(count, CLASSIFIED if plot is not None else 0)
    modes = modal_analysis(solid, min(want, solid.ndof) if want < solid.ndof else None)
    shown = min(count, modes.count)
    kinds = classify_modes(solid, modes, range(max(shown, min(CLASSIFIED, modes.count))))
    if plot is not None:
        plot_modes(solid, modes, kinds, tuple(k for k in FIG6_MODES if k < modes.count), plot)
    return ScenarioModes(solid, modes, kinds, shown, None if plot is None else Path(plot))


def mode_rows(res: ScenarioModes) -> tuple[str, list[str], list[list[str]]]:
    """`granel modes`'s table: (title, header, rows)."""
    model, periods = res.solid, res.modes.periods
    return (f"{model.kind}: {model.ndof} DOFs, {model.nelements} elements", ["mode", "period [ms]", "frequency [kHz]", "kind"],
            [[str(k + 1), f"{periods[k] * 1e3:.5f}", f"{1 / periods[k] / 1e3:.3f}", res.kinds[k]] for k in range(res.shown)])
