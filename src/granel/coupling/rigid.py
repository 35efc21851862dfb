"""Granular media against rigid boundaries (`--solid rigid`): RK4 at a constant step."""

from __future__ import annotations

import numpy as np

from ..checkpoint import checkpoint_period, load_checkpoint, save_checkpoint
from ..granular.system import GranularState, Stepper, build_neighbours


class Recorder:
    """Collects the output-step snapshots that become the result Dataset."""

    def __init__(self):
        self.times: list[float] = []
        self.rec: dict[str, list] = {k: [] for k in (
            "pos", "theta", "vel", "omega", "energy_media", "energy_solid",
            "dissipated_viscous", "dissipated_friction", "input_work", "balance_error")}

    def snapshot(self, stepper: Stepper, state: GranularState, e_solid: float = 0.0, su=None, **extra):
        em = stepper.medium_energy(state, su)
        r = self.rec
        self.times.append(state.t)
        r["pos"].append(state.pos.copy())
        r["theta"].append(state.theta.copy())
        r["vel"].append(state.vel.copy())
        r["omega"].append(state.omega.copy())
        r["energy_media"].append(em)
        r["energy_solid"].append(e_solid)
        dv, df, w = state.dissipated_viscous, state.dissipated_friction, state.input_work
        r["dissipated_viscous"].append(dv)
        r["dissipated_friction"].append(df)
        r["input_work"].append(w)
        r["balance_error"].append(e_solid + em.sum() + dv + df - w)
        for k, v in extra.items():
            r.setdefault(k, []).append(v)


def output_schedule(duration: float, dt: float, output_every: float) -> tuple[int, int]:
    """(steps between outputs, number of outputs after t = 0); outputs fall on step multiples."""
    per = max(1, int(round(output_every / dt)))
    nout = int(np.ceil(duration / (per * dt) - 1e-9))
    return per, nout


def simulate_rigid(stepper: Stepper, state: GranularState, duration: float, dt: float, output_every: float,
                   progress=None, checkpoint=None, checkpoint_every: float = 0.0, resume=None,
                   fingerprint: str = "") -> Recorder:
    """Integrate to `duration`; the solid's contact points stay put (zero motion).

    With `checkpoint` and `checkpoint_every` > 0 the state and the outputs so far are saved
    atomically every `checkpoint_every` of simulated time; `resume` restarts from such a file.
    """
    rec = Recorder()
    per, nout = output_schedule(duration, dt, output_every)
    start = 0
    if resume is not None:
        st, recorded, times = load_checkpoint(resume, fingerprint)
        state.y[:] = st["y"]
        state.t = float(st["t"])
        stepper.nl = build_neighbours(stepper.system, st["ref_pos"])
        rec.rec.update(recorded)
        rec.times = times
        start = int(st["k"])
    else:
        rec.snapshot(stepper, state)
    ck_per = checkpoint_period(checkpoint, checkpoint_every, per, dt)
    for k in range(start, nout):
        stepper.advance(state, dt, per)
        rec.snapshot(stepper, state)
        if progress is not None:
            progress(state.t, per)
        if ck_per and (k + 1) % ck_per == 0 and k + 1 < nout:
            save_checkpoint(checkpoint, fingerprint,
                            {"y": state.y, "t": state.t, "ref_pos": stepper.nl.ref_pos, "k": k + 1},
                            rec.rec, rec.times)
    return rec
