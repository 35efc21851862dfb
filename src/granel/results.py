"""Results as xarray Datasets <-> NetCDF files (h5netcdf engine), written atomically."""

from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import xarray as xr

from . import __version__


@contextmanager
def atomic_path(path: str | Path):
    """Yield a temporary path beside `path`; on success rename it over `path`, else remove it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_netcdf(ds: xr.Dataset, path: str | Path) -> Path:
    """Write atomically (temporary file in the same directory, then rename)."""
    with atomic_path(path) as tmp:
        ds.to_netcdf(tmp, engine="h5netcdf", invalid_netcdf=False)
    return Path(path)


def read_netcdf(path: str | Path) -> xr.Dataset:
    """Load a result file fully into memory (the file is closed afterwards)."""
    with xr.open_dataset(path, engine="h5netcdf") as ds:
        return ds.load()


def base_attrs(scenario_toml: str, solver: dict) -> dict:
    attrs = {"granel_version": __version__, "scenario": scenario_toml, "conventions": "granel-1"}
    for k, v in solver.items():
        attrs[f"solver_{k}"] = v if isinstance(v, (int, float, str)) else str(v)
    return attrs


def granular_dataset(times, labels, media_names, medium_index, rec: dict, attrs: dict) -> xr.Dataset:
    """Assemble the standard result Dataset from recorded arrays (see the README for names)."""
    t = np.asarray(times)
    coords = {
        "time": ("time", t, {"units": "s"}),
        "granule": ("granule", np.array(labels, dtype=object)),
        "medium": ("granule", np.array([media_names[k] for k in medium_index], dtype=object)),
    }
    pos = np.asarray(rec["pos"])
    vel = np.asarray(rec["vel"])
    data = {
        "x": (("time", "granule"), pos[:, :, 0], {"units": "m", "long_name": "centre x"}),
        "y": (("time", "granule"), pos[:, :, 1], {"units": "m", "long_name": "centre y"}),
        "theta": (("time", "granule"), np.asarray(rec["theta"]), {"units": "rad"}),
        "v_x": (("time", "granule"), vel[:, :, 0], {"units": "m/s"}),
        "v_y": (("time", "granule"), vel[:, :, 1], {"units": "m/s"}),
        "omega": (("time", "granule"), np.asarray(rec["omega"]), {"units": "rad/s"}),
    }
    em = np.asarray(rec["energy_media"])
    for k, name in enumerate(media_names):
        data[f"energy_{name.lower()}"] = ("time", em[:, k], {"units": "J", "long_name": f"energy of {name}, eq. (11)"})
    for key, long in (
        ("energy_solid", "solid energy 1/2 v'Mv + 1/2 x'Kx, eq. (11)"),
        ("dissipated_viscous", "work of viscous contact forces, eq. (12)"),
        ("dissipated_friction", "work of friction forces, eq. (12)"),
        ("input_work", "work of the applied forces"),
        ("balance_error", "E_solid + E_granular + D - input work, eq. (13)"),
    ):
        data[key] = ("time", np.asarray(rec[key]), {"units": "J", "long_name": long})
    for key, val in rec.items():
        if key.startswith("extra:"):
            name = key[6:]
            dims, arr, a = val
            data[name] = (dims, np.asarray(arr), a)
    return xr.Dataset(data, coords=coords, attrs=attrs)
