"""granel: nonlinear acoustics of granular-elastic-solid interfaces.

The folders follow the data: scenario -> problem -> coupling (solvers, driver) -> io (trajectory,
result) -> analysis -> viz and studies -> cli, on the physics of granular/ and solid/ and the
guarantees of guard/ (docs/architecture.md). Equation numbers refer to
Wang, Tawfick & Vakakis, Phys. Rev. E 104, 044906 (2021).
"""

import sys as _sys

__version__ = "0.1.0"

# modules that moved into folders: the old name still imports, with a warning naming the new one
MOVED = {
    "granel.units": "granel.io.units", "granel.trajectory": "granel.io.trajectory",
    "granel.checkpoint": "granel.io.checkpoint", "granel.results": "granel.io.results",
    "granel.materials": "granel.granular.materials", "granel.excitation": "granel.granular.loads",
    "granel.jit": "granel.guard.jit", "granel.figures": "granel.viz.figures", "granel.plots": "granel.viz.plots",
    "granel.schematics": "granel.viz.schematics", "granel.animate": "granel.viz.animate",
    "granel.export": "granel.viz.export", "granel.sweep": "granel.studies.sweep",
    "granel.design": "granel.studies.design", "granel.design_report": "granel.studies.design_report",
    "granel.spectrum": "granel.studies.spectrum", "granel.report": "granel.studies.paper",
    "granel.claims": "granel.studies.claims", "granel.benchmark": "granel.studies.benchmark",
}


class _MovedFinder:
    """Finds a moved module under its old name: the module at its new place, after a FutureWarning."""

    @staticmethod
    def find_spec(name, path=None, target=None):
        if name not in MOVED:
            return None
        import importlib.util

        return importlib.util.spec_from_loader(name, _MovedFinder)

    @staticmethod
    def create_module(spec):
        return None

    @staticmethod
    def exec_module(module):
        import importlib
        import warnings

        new = MOVED[module.__name__]
        warnings.warn(f"{module.__name__} moved to {new}: import it from there", FutureWarning, stacklevel=2)
        _sys.modules[module.__name__] = importlib.import_module(new)


if not any(f is _MovedFinder for f in _sys.meta_path):
    _sys.meta_path.append(_MovedFinder)
