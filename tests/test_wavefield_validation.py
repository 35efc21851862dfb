"""Issue 31, item 2: the ridges of the frequency-wavenumber map of an impulsively excited solid (a
single granule pressed against it by a short half-sine, scenarios/wavefield/impact.toml) lie on
the analytic dispersion branches,
computed without the finite-element model (`solid.dispersion`, validated in test_dispersion):
the plate's Rayleigh-Lamb branches of a layer of its width with the plane-stress speeds, the
beam's Euler-Bernoulli branch; within 1 % in frequency.

How a ridge is located (`analysis.wavefield.map_ridges`): the map is |V(k, f)|^2 of the sampled
velocities through Hann windows in time and along the length, zero-padded 4 times; a ridge point
is a peak that is the largest within 3 unpadded bins each way (a Hann window's first sidelobe is
2.5 bins out), at least 1e-3 of the largest peak, refined by a parabola through the logarithms
of the peak and its neighbours in k and in f.

Over which wavenumbers (`Wavefield.k_window` .. `k_resolved`):
- from k_window = 8 pi / L_w (L_w the sampled length): a standing wave's part running the other
  way lies two main-lobe half-widths (4 pi / L_w each) away and pulls its ridge by less than 4e-4
  in k (test_wavefield's synthetic standing wave); below it, the lowest modes' ridges are pulled
  by up to several %;
- to k_resolved, where the elements' dispersion error, (k l)^4 / 1440 for quadratic elements
  (Ainsworth 2004, p = 2, l the longest element along the length) and for the beam's Hermite
  cubics alike, reaches 0.25 %; the plate's strip, resolved by only 6 Q8 elements across its
  width, errs more than this 1-D estimate (its flexural waves bend across the width), which the
  1 % leaves room for;
- at frequencies below the cut-off of each family's fourth branch (the plate: A0-A2, S0-S2 are
  the branches drawn) and the outputs' Nyquist frequency.
The frequency resolution is no limit here: the record (0.8 ms) resolves the strip's standing
modes (spacing >= c_g / 2L, 10 kHz and more, against 1 / T = 1.25 kHz), and a peak is located to
well under a tenth of a bin."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from granel.solid.dispersion import euler_bernoulli_frequency, lamb_frequencies, plane_stress_speeds

SCENARIO = Path(__file__).resolve().parents[1] / "scenarios" / "wavefield" / "impact.toml"
E, NU, RHO = 200e9, 0.3, 7850.0  # the scenario's steel and plate, read back below
WIDTH, LENGTH, THICKNESS = 0.01, 0.1, 0.001
TOLERANCE = 0.01  # the 1 % in frequency


def impact_wavefield(tmp_path, kind):
    from granel.analysis.result_model import result_modes, result_solid
    from granel.analysis.wavefield import analyse_wavefield
    from granel.run import load_result

    nc = tmp_path / f"{kind}.nc"
    res = subprocess.run([sys.executable, "-m", "granel", "run", str(SCENARIO), "--solid", kind, "-o", str(nc)],
                         capture_output=True, text=True, timeout=1200)
    assert res.returncode == 0, res.stderr
    ds = load_result(nc)
    model = result_solid(ds)
    r = model.recipe
    assert (r.E, r.rho, r.width, r.length, r.thickness) == (E, RHO, WIDTH, LENGTH, THICKNESS)
    assert kind == "beam" or r.nu == NU  # a beam's recipe carries no Poisson ratio
    return analyse_wavefield(ds, model, result_modes(ds))


def validated(wf, f_top):
    r = wf.ridges  # already k_window <= k <= k_max (= k_resolved by default)
    keep = (r.k >= wf.k_window) & (r.k <= wf.k_resolved) & (r.f <= f_top)
    return r.k[keep], r.f[keep]


@pytest.mark.slow  # about 45 s from an empty mode cache (the plate's 3167 modes), 8 s after
def test_plate_ridges_lie_on_the_rayleigh_lamb_branches(tmp_path):
    wf = impact_wavefield(tmp_path, "plate")
    speeds = plane_stress_speeds(E, NU, RHO)
    # below the fourth branch of either family (their cut-offs) and the Nyquist frequency
    f_top = min(lamb_frequencies([0.0], WIDTH, speeds, family, 4)[3, 0] for family in ("symmetric", "antisymmetric"))
    f_top = min(f_top, 0.9 * wf.fk.f[-1])
    k, f = validated(wf, f_top)
    sym = lamb_frequencies(k, WIDTH, speeds, "symmetric", 3)
    anti = lamb_frequencies(k, WIDTH, speeds, "antisymmetric", 3)
    branches = np.vstack([sym, anti])  # S0 S1 S2 A0 A1 A2
    error = f[None, :] / branches - 1
    nearest = np.argmin(np.abs(error), axis=0)
    worst = np.abs(error[nearest, np.arange(len(k))])
    assert wf.k_window < 260 and 650 < wf.k_resolved < 720  # the range: 8 pi / L_w .. (1440 * 0.0025)^(1/4) / l
    assert len(k) >= 20
    assert np.all(worst < TOLERANCE), [(round(a), round(b / 1e3, 2), round(100 * e, 3)) for a, b, e in zip(k, f, worst)
                                       if e >= TOLERANCE]
    on = {name: int(np.sum((nearest == i) & (worst < TOLERANCE))) for i, name in enumerate(["S0", "S1", "S2", "A0",
                                                                                             "A1", "A2"])}
    assert on["A0"] >= 5 and on["S0"] >= 5, on


def test_beam_ridges_lie_on_the_euler_bernoulli_branch(tmp_path):
    wf = impact_wavefield(tmp_path, "beam")
    k, f = validated(wf, 0.9 * wf.fk.f[-1])
    branch = euler_bernoulli_frequency(k, E * THICKNESS * WIDTH**3 / 12, RHO * THICKNESS * WIDTH)
    error = np.abs(f / branch - 1)
    assert len(k) >= 6
    assert np.all(error < TOLERANCE), [(round(a), round(b / 1e3, 2), round(100 * e, 3)) for a, b, e in zip(k, f, error)]
