"""The result Dataset of a run: the trajectory's variables per output, per step and at the solid's
outputs, the model record (`io.model`) and the run's attributes, as a `io.results.ResultSpec`
(an xarray Dataset, or straight to NetCDF)."""

from __future__ import annotations

import numpy as np

from .. import __version__
from .model import model_record, record_entries
from .results import ResultSpec, wall_names


def base_attrs(scenario_toml: str, solver: dict) -> dict:
    attrs = {"granel_version": __version__, "scenario": scenario_toml, "conventions": "granel-1"}
    for k, v in solver.items():
        attrs[f"solver_{k}"] = v if isinstance(v, (int, float, str)) else str(v)
    return attrs


def trajectory_spec(traj, system, model, attrs: dict, omega=None) -> ResultSpec:
    """The result of a run (see the README for the names) from its `Trajectory`, its granular
    system and its solid model, with the model record (`io.model`), as a `ResultSpec` (`omega`:
    the natural frequencies of the modal coordinates, if the solid state is modal). Only what the
    trajectory kept (`Trajectory.stored`) is written: the states of a few traced granules go along
    a `traced` dimension; the energies, the balance and the model record are always there."""
    t = traj.times
    r = traj.series
    nt = len(t)
    names = [c.name for c in model.contacts]
    coords = {
        "time": ("time", t, {"units": "s"}),
        "granule": ("granule", np.array(system.labels, dtype=object)),
        "medium": ("granule", np.array([system.media[k] for k in system.medium_index], dtype=object)),
        "contact": ("contact", np.array(names, dtype=object)),
        "wall": ("wall", np.array(wall_names(system), dtype=object)),
    }
    keep = traj.stored
    data = {}
    if keep.traced is None or len(keep.traced):
        dim = "granule"
        if keep.traced is not None:  # the traces of a few granules, along their own dimension
            dim = "traced"
            coords["traced"] = ("traced", np.array([system.labels[k] for k in keep.traced], dtype=object))
        pos, vel = r("pos"), r("vel")
        data.update({
            "x": (("time", dim), pos[:, :, 0], {"units": "m", "long_name": "centre x"}),
            "y": (("time", dim), pos[:, :, 1], {"units": "m", "long_name": "centre y"}),
            "theta": (("time", dim), r("theta"), {"units": "rad"}),
            "v_x": (("time", dim), vel[:, :, 0], {"units": "m/s"}),
            "v_y": (("time", dim), vel[:, :, 1], {"units": "m/s"}),
            "omega": (("time", dim), r("omega"), {"units": "rad/s"}),
        })
    em = r("energy_media").reshape(nt, -1)
    for k, name in enumerate(system.media):
        data[f"energy_{name.lower()}"] = ("time", em[:, k], {"units": "J", "long_name": f"energy of {name}, eq. (11)"})
    if system.has_gravity:
        data["energy_gravity"] = ("time", r("energy_gravity").astype(float),
                                  {"units": "J", "long_name": "the granules' gravitational potential energy, "
                                   "-sum m g . (x - x as built)"})
    for key, long in (
        ("energy_solid", "solid energy 1/2 v'Mv + 1/2 x'Kx, eq. (11)"),
        ("energy_solid_kinetic", "solid kinetic energy 1/2 v'Mv"),
        ("energy_solid_potential", "solid strain energy 1/2 x'Kx"),
        ("dissipated_viscous", "work of viscous contact forces, eq. (12)"),
        ("dissipated_friction", "work of friction forces, eq. (12)"),
        ("input_work", "work of the applied forces"),
        ("balance_error", "E_solid + E_granular (+ E_gravity) + D - input work, eq. (13), minus its value at t = 0"),
    ):
        data[key] = ("time", r(key).astype(float), {"units": "J", "long_name": long})
    for key, long in (("normal", "normal force on the solid (along n_ik)"), ("tangential", "tangential force on the solid (along t_ik = k x n_ik)")):
        if keep.contacts:
            data[f"contact_force_{key}"] = (("time", "contact"), r(f"force_{key}").astype(float).reshape(nt, -1),
                                            {"units": "N", "long_name": long})
    if "wall_force" in traj.names and system.walls and keep.walls:
        fw = r("wall_force").astype(float).reshape(nt, len(system.walls), 2)
        nrm = np.array([np.asarray(w.normal, float) / np.hypot(*w.normal) for w in system.walls])
        tan = np.array([(np.asarray(w.p1, float) - w.p0) / np.hypot(*(np.asarray(w.p1, float) - w.p0)) for w in system.walls])
        data["wall_force_normal"] = (("time", "wall"), -np.einsum("kwi,wi->kw", fw, nrm),
                                     {"units": "N", "long_name": "force pressing each rigid wall (along -n, n into the granules)"})
        data["wall_force_tangential"] = (("time", "wall"), np.einsum("kwi,wi->kw", fw, tan),
                                         {"units": "N", "long_name": "force on each rigid wall along it (p0 -> p1)"})
    steps = _step_variables(traj, t, len(names))
    if not keep.contacts:
        del steps["lambda_max"]
    if not keep.steps:
        steps = {k: v for k, v in steps.items() if not k.startswith("step_")}
    data.update(steps)
    if model.ndof and keep.solid:
        data.update(_solid_variables(traj, omega))
    record, record_attrs = record_entries(model_record(system, model))
    data.update(record)
    stored = {"outputs_granules": "all" if keep.traced is None else f"{len(keep.traced)} traced",
              "outputs_left_out": " ".join(g for g in ("contacts", "walls", "steps", "solid") if not getattr(keep, g))}
    return ResultSpec(data, coords, {**attrs, **record_attrs, **stored}, compression=keep.compression)


def _step_variables(traj, times: np.ndarray, nc: int) -> dict:
    """Per accepted step (Fig. 11), and per output interval: the smallest step, the mean
    iterations and the largest |lambda| (A9) since the previous output."""
    st_t = traj.step_series("t")
    dts = traj.step_series("h")
    it = traj.step_series("iterations")
    lam = traj.step_series("lam").reshape(len(st_t), nc)
    # the steps that end in (t_{j-1}, t_j]
    idx = np.searchsorted(st_t, times + 1e-15 * np.maximum(times, 1e-12), side="right")
    step_size = np.full(len(times), np.nan)
    iters = np.full(len(times), np.nan)
    lmax = np.zeros((len(times), nc), np.float32)
    full = np.flatnonzero(idx[1:] > idx[:-1])  # outputs j = full + 1 have steps in their interval
    if len(full):
        starts, end = idx[full], idx[-1]  # consecutive segments: the empty ones between add nothing
        step_size[full + 1] = np.minimum.reduceat(dts[:end], starts)
        iters[full + 1] = np.add.reduceat(it[:end], starts) / np.diff(np.append(starts, end))
        if nc:
            lmax[full + 1] = np.maximum.reduceat(lam[:end], starts, axis=0)
    return {
        "step_size": (("time",), step_size, {"units": "s", "long_name": "smallest step since the previous output"}),
        "iterations": (("time",), iters, {"long_name": "mean interface iterations since the previous output"}),
        "lambda_max": (("time", "contact"), lmax, {"long_name": "max |lambda| (A9) since the previous output"}),
        "step_time": (("step",), st_t, {"units": "s", "long_name": "time at the end of each accepted step"}),
        "step_dt": (("step",), dts, {"units": "s"}),
        "step_iterations": (("step",), it, {}),
        "step_lambda": (("step", "contact"), lam, {"long_name": "|lambda| (A9) of each step at each contact"}),
    }


def _solid_variables(traj, omega) -> dict:
    ts = traj.solid_times
    nst = len(ts)
    out = {"solid_time": (("solid_time",), ts, {"units": "s"})}
    if "eta" in traj.solid_names:  # mass-normalised modal coordinates: q = Phi eta
        out["solid_eta"] = (("solid_time", "mode"), traj.solid_series("eta").astype(np.float32, copy=False).reshape(nst, -1),
                            {"long_name": "modal displacements (mass-normalised modes)"})
        out["solid_eta_dot"] = (("solid_time", "mode"), traj.solid_series("eta_dot").astype(np.float32, copy=False).reshape(nst, -1),
                                {"long_name": "modal velocities"})
        out["mode_omega"] = (("mode",), np.asarray(omega, float), {"units": "rad/s"})
    else:  # reduced nodal coordinates (solids too large for all modes)
        out["solid_x"] = (("solid_time", "dof"), traj.solid_series("q").astype(np.float32, copy=False).reshape(nst, -1),
                          {"long_name": "reduced solid displacements q"})
        out["solid_v"] = (("solid_time", "dof"), traj.solid_series("v").astype(np.float32, copy=False).reshape(nst, -1),
                          {"long_name": "reduced solid velocities"})
    return out
