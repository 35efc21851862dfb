"""A displacement-driven rigid wall (a shaker, `[[walls]] motion`): its motion against its
definition, the linear response of a preloaded granule on it against the driven
oscillator's analytic amplitude, and bad input."""

import math

import numpy as np
import pytest

from granel import scenario as S
from granel.analysis.narrowband import harmonic_amplitudes
from granel.granular.loads import WallDrive
from granel.run import run_scenario

R, E, NU, RHO = 0.005, 200e9, 0.3, 7850.0


def _motion_reference(d: WallDrive, t: float) -> float:
    """The wall's displacement from its definition: U r(tau) sin(2 pi f tau + phase), tau = t - t0
    in [0, duration], the ramp r = (1 - cos(pi x)) / 2, x = min(tau, duration - tau) f / cycles."""
    tau = t - d.t0
    if tau < 0 or tau > d.duration:
        return 0.0
    x = min(tau, d.duration - tau) * d.frequency / d.ramp_cycles if d.ramp_cycles > 0 else 1.0
    r = 0.5 * (1 - math.cos(math.pi * x)) if x < 1 else 1.0
    return d.amplitude * r * math.sin(2 * math.pi * d.frequency * tau + d.phase)


@pytest.mark.parametrize("drive", [WallDrive(2e-6, 5e3, 1e-4, 2e-3, 0.3, 2.5), WallDrive(-1e-6, 3e4, 0.0, math.inf, 0.0, 0.0),
                                   WallDrive(1e-6, 1e4, 0.0, 1e-3, 0.0, 4.0)])
def test_wall_motion_and_speed(drive):
    """The wall's motion (the compiled law, `granular.laws.wall_motion`, which the integrator and
    `WallDrive` both call) equals its definition at 2,001 times (1e-12 of the amplitude: the
    phase's rounding, 2 pi f t eps), and its speed is the derivative of its displacement (central
    differences, 1e-6 of the peak speed)."""
    T = drive.t0 + min(drive.duration, 3e-3) + 1e-4
    h = 1e-9
    peak = drive.peak_speed()
    for t in np.linspace(0.0, T, 2001):
        s, v = drive(t)
        assert s == pytest.approx(_motion_reference(drive, t), abs=1e-12 * abs(drive.amplitude))
        if all(abs(t - k) > 2 * h for k in drive.kinks()):
            fd = (drive(t + h)[0] - drive(t - h)[0]) / (2 * h)
            assert v == pytest.approx(fd, abs=1e-6 * peak)
    assert drive(drive.t0 - 1e-6) == (0.0, 0.0)


def shaker_scenario(tmp_path, ratio, F0=10.0, U=1e-9, cycles=60, motion_extra=""):
    """A steel granule (R = 5 mm) pressed by F0 against a wall that shakes along its normal by U at
    `ratio` times the contact's linear frequency f0 = sqrt(k / m) / 2 pi, k = 3/2 A^(2/3) F0^(1/3)
    (A = 4/3 E / (1 - nu^2) sqrt(R)), starting from the static equilibrium; no damping. Returns
    (scenario, f, k)."""
    A = 4 / 3 * E / (1 - NU**2) * math.sqrt(R)
    d0 = (F0 / A) ** (2 / 3)
    m = 4 / 3 * math.pi * R**3 * RHO
    k = 1.5 * A ** (2 / 3) * F0 ** (1 / 3)
    f = ratio * math.sqrt(k / m) / (2 * math.pi)
    (tmp_path / "one.csv").write_text("label,x,y,radius\nA,0.0,0.0,0.005\n")
    (tmp_path / "shaker.toml").write_text(f"""name = "shaker"
[simulation]
duration = {cycles / f!r}
output_every = {1 / (40 * f)!r}
equilibrate = true
[contact]
mu = 0.0
alpha_n = 0.0
[solid]
kind = "rigid"
x0 = 1.0
y0 = 1.0
[[media]]
name = "G"
side = "none"
granules_file = "one.csv"
[[walls]]
p0 = [{R - d0!r}, -0.01]
p1 = [{R - d0!r}, 0.01]
normal = [-1.0, 0.0]
name = "shaker"
motion = {{ amplitude = {U!r}, frequency = {f!r}, ramp_cycles = 5{motion_extra} }}
[[excitations]]
granule = "G:A"
kind = "constant"
value = {F0!r}
direction = [1.0, 0.0]
""")
    return S.load(str(tmp_path / "shaker.toml")), f, k


@pytest.mark.parametrize("ratio", [0.5, 2.0])
def test_a_preloaded_granule_follows_its_shaker_as_a_driven_oscillator(tmp_path, ratio):
    """Linearised, m x'' = -k (x + s) with s = U sin(w t): the granule moves by
    U / |1 - r^2| and the wall takes k U r^2 / |1 - r^2| at r = f / f0. With U = 1 nm against a
    10 N preload (overlap 1.2 um) the contact is linear to 1e-3: the amplitudes at the drive
    frequency over the last 30 of 60 periods agree within 1e-4 (measured: 1.333334 and 0.333332
    for the granule, 0.333334 and 1.333332 for the wall, at r = 0.5 and 2); the wall starts at
    the preload, 10 N; the energy balance (13) stays within 1e-4 of the wall's work."""
    sc, f, k = shaker_scenario(tmp_path, ratio)
    U = 1e-9
    ds = run_scenario(sc)
    t = ds["time"].values
    x = ds["x"].values[:, 0] - ds["x"].values[0, 0]
    F = ds["wall_force_normal"].values[:, 0]
    window = (t[-1] - 30 / f, t[-1])
    X = harmonic_amplitudes(t, x, f, orders=(1,), subharmonics=(), window=window)["f"]
    Fw = harmonic_amplitudes(t, F, f, orders=(1,), subharmonics=(), window=window)["f"]
    assert X / U == pytest.approx(1 / abs(1 - ratio**2), rel=1e-4)
    assert Fw / (k * U) == pytest.approx(ratio**2 / abs(1 - ratio**2), rel=1e-4)
    assert F[0] == pytest.approx(10.0, rel=1e-9)
    assert np.abs(ds["balance_error"].values).max() < 1e-4 * np.abs(ds["input_work"].values).max()


@pytest.mark.parametrize("motion, needle", [
    ("amplitude = 1e-6, frequency = 0.0", r"walls.0.motion.frequency"),
    ("amplitude = 0.0, frequency = 1e3", r"walls.0.motion.*amplitude"),
    ("amplitude = 1e-6, frequency = 1e3, phase = 1.0", r"walls.0.motion.*phase"),
    ("amplitude = 1e-6, frequency = 1e3, duration = -1.0", r"walls.0.motion.*duration"),
    ("amplitude = 1e-6", r"walls.0.motion.frequency"),
    ("amplitude = 1e-6, frequency = 1e3, speed = 2.0", r"walls.0.motion.speed"),
])
def test_bad_wall_motion_is_refused(tmp_path, motion, needle):
    sc, _, _ = shaker_scenario(tmp_path, 0.5)
    path = tmp_path / "shaker.toml"
    text = path.read_text()
    start = text.index("motion = {")
    end = text.index("}", start) + 1
    path.write_text(text[:start] + "motion = { " + motion + " }" + text[end:])
    with pytest.raises(S.ScenarioError, match=needle):
        S.load(str(path))


def uncompressed_chain(tmp_path, f, U=1e-6, n=6, cycles=60, alpha_n=0.5):
    """n steel beads (R = 5 mm) just touching, without preload, between a wall shaking by U at f
    (left) and a fixed wall (right): the setting of Pozharskiy et al. (PRE 2015)."""
    rows = ["label,x,y,radius"] + [f"{k + 1},{2 * R * k!r},0.0,{R}" for k in range(n)]
    (tmp_path / "c.csv").write_text("\n".join(rows) + "\n")
    xr = 2 * R * (n - 1) + R
    (tmp_path / "c.toml").write_text(f"""name = "driven-chain"
[simulation]
duration = {cycles / f!r}
output_every = {1 / (40 * f)!r}
[contact]
mu = 0.0
alpha_n = {alpha_n!r}
[solid]
kind = "rigid"
x0 = 1.0
y0 = 1.0
[[media]]
name = "C"
side = "none"
granules_file = "c.csv"
[[walls]]
p0 = [{-R!r}, -0.01]
p1 = [{-R!r}, 0.01]
normal = [1.0, 0.0]
name = "shaker"
motion = {{ amplitude = {U!r}, frequency = {f!r}, ramp_cycles = 5 }}
[[walls]]
p0 = [{xr!r}, -0.01]
p1 = [{xr!r}, 0.01]
normal = [-1.0, 0.0]
name = "fixed"
""")
    return S.load(str(tmp_path / "c.toml"))


def test_an_uncompressed_chain_on_a_shaker_locks_to_one_or_two_drive_periods(tmp_path):
    """Six beads with no precompression between a wall shaking by 1 um and a fixed wall (Tsuji
    damping 0.5): the force on the fixed wall over the last 20 of 60 periods repeats every drive
    period at 3 kHz and every two at 5 kHz (a period-doubled response, its f/2 content as large
    as its fundamental: measured 0.78 N at f and 4e-4 N at f/2 at 3 kHz, 0.70 N at f and 1.00 N at
    f/2 at 5 kHz); the energy balance (13) within 1e-6 of the shaker's work."""
    from granel.analysis.narrowband import response_period

    out = {}
    for f in (3e3, 5e3):
        ds = run_scenario(uncompressed_chain(tmp_path, f))
        t, F = ds["time"].values, ds["wall_force_normal"].values[:, 1]
        window = (t[-1] - 20 / f, t[-1])
        out[f] = (response_period(t, F, 1 / f, window=window),
                  harmonic_amplitudes(t, F, f, orders=(1,), subharmonics=(2,), window=window))
        assert np.abs(ds["balance_error"].values).max() < 1e-6 * np.abs(ds["input_work"].values).max()
    assert out[3e3][0] == 1 and out[5e3][0] == 2
    assert out[3e3][1]["f/2"] < 1e-2 * out[3e3][1]["f"]
    assert out[5e3][1]["f/2"] > out[5e3][1]["f"] > 0.1
