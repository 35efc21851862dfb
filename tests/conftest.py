"""The suite's shared set-up. First of all it makes the suite hermetic (issue 37): it passes
whatever the user's environment holds, because before granel, numba, dask or matplotlib is
imported the environment they read is reset to the suite's own (`hermetic_environment`); a test
that needs a setting makes it itself (monkeypatch), and children inherit the reset environment."""

import os
import sys
import tempfile
from pathlib import Path

# settings that change what granel and its libraries do: cleared (prefixes, then names)
CLEARED_PREFIXES = ("GRANEL_", "NUMBA_", "DASK_", "MPL", "XDG_", "TYPER_", "_TYPER_")
CLEARED = ("PYTHONWARNINGS", "FORCE_COLOR", "NO_COLOR", "CLICOLOR", "CLICOLOR_FORCE", "COLUMNS", "LINES",
           "TTY_COMPATIBLE", "TTY_INTERACTIVE", "JUPYTER_COLUMNS", "JUPYTER_LINES")
# where caches live: the user's choice is kept when it is a folder the suite can write, else cleared
LOCATIONS = ("NUMBA_CACHE_DIR", "GRANEL_CACHE")


def _usable_folder(path: str) -> bool:
    try:
        folder = Path(path).expanduser()
        folder.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=folder)
        os.close(fd)
        os.unlink(probe)
        return True
    except (OSError, ValueError):
        return False


def _suite_home() -> Path:
    """A home of the suite's own, kept between sessions (its caches stay warm) and private to this
    user: the user's home may be read-only or hold configuration (dask, matplotlib) that the
    suite must not read."""
    base = Path(tempfile.gettempdir()) / f"granel-suite-{os.getuid() if hasattr(os, 'getuid') else 'user'}"
    try:
        base.mkdir(mode=0o700, exist_ok=True)
        st = base.stat()
        if hasattr(os, "getuid") and (st.st_uid != os.getuid() or st.st_mode & 0o077):
            raise PermissionError(base)
        (base / "home").mkdir(exist_ok=True)
        return base / "home"
    except OSError:
        return Path(tempfile.mkdtemp(prefix="granel-suite-home-"))


def hermetic_environment(environ=os.environ) -> dict:
    """Reset `environ` as the module's docstring says; returns what was cleared or replaced."""
    changed = {}
    for key in list(environ):
        if key in LOCATIONS:
            if not environ[key].strip() or not _usable_folder(environ[key]):
                changed[key] = environ.pop(key)
        elif key.startswith(CLEARED_PREFIXES) or key in CLEARED:
            changed[key] = environ.pop(key)
    changed["HOME"] = environ.get("HOME")
    environ["HOME"] = str(_suite_home())
    environ["PYTHONUTF8"] = "1"  # children read and print UTF-8 whatever the locale (the harness tests others)
    os.umask(0o022)
    return changed


RESET = hermetic_environment()
if "numba" in sys.modules:  # a plugin imported it first: numba reads its settings at import
    from numba.core import config as _numba_config

    _numba_config.reload_config()

import numpy as np  # noqa: E402 (after the environment is reset)
import pytest  # noqa: E402

from granel.granular.materials import STEEL
from granel.granular.packing import Medium, Wall, medium_from_table
from granel.granular.system import ContactLaw, Excitation, Stepper, build_system, initial_state


def make_system(rows, law=ContactLaw(0.0, 0.0, 100.0), walls=(), excitations=(), material=STEEL):
    """A single-medium system from [(label, x, y, R)]."""
    med = medium_from_table("M", [dict(label=l, x=x, y=y, radius=r) for l, x, y, r in rows], material)
    med.walls = list(walls)
    return build_system([med], law, excitations=list(excitations))


@pytest.fixture
def system_factory():
    return make_system
