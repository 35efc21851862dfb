"""The analytic dispersion branches (`solid.dispersion`) against closed forms from the
literature, none derived here from the root finder's equations:

- S0 at low k: the plate speed of a layer with bulk speeds c_p, c_s, 2 c_s sqrt(1 - c_s^2/c_p^2)
  (Graff, Wave Motion in Elastic Solids, sec. 8.1); for the plane-stress speeds it is the
  bar speed sqrt(E / rho) of a thin strip;
- A0 at low k: the layer's flexural branch w = k^2 sqrt(D / (rho h)), D / (rho h) = c_plate^2 h^2 / 12
  (Graff sec. 8.1), which is Euler-Bernoulli's for the strip of depth h;
- A0 and S0 at large kh: the Rayleigh speed, the root of the Rayleigh cubic
  eta^3 - 8 eta^2 + (24 - 16 kappa) eta - 16 (1 - kappa) = 0, eta = (c_R/c_s)^2, kappa = c_s^2/c_p^2
  (Graff sec. 6.3), and Viktorov's approximation;
- the cut-offs at k = 0: symmetric n c_p/(2h), n odd, and n c_s/(2h), n even; antisymmetric
  n c_s/(2h), n odd, and n c_p/(2h), n even (thickness-stretch and thickness-shear resonances,
  Graff sec. 8.1);
- the Lame modes: phase speed sqrt(2) c_s exactly, at k h = (2m + 1) pi (symmetric) and 2 m pi
  (antisymmetric) (Graff sec. 8.1, "Lame modes").

The roots are found to relative accuracy ROOT_RTOL = 1e-12 in frequency; the tolerances below are
that accuracy times a margin for the reference's own rounding, or the size of the neglected
term of an asymptotic form (stated at each test)."""

import math

import numpy as np
import pytest

from granel.solid.dispersion import (
    ROOT_RTOL,
    euler_bernoulli_frequency,
    lamb_branches,
    lamb_frequencies,
    plane_stress_speeds,
    rayleigh_lamb,
)

E, NU, RHO = 200e9, 0.3, 7850.0  # the paper's steel
H = 0.01  # the paper's plate width: the layer's thickness
SPEEDS = plane_stress_speeds(E, NU, RHO)
ROOTS = 100 * ROOT_RTOL  # the root finder's accuracy, with a margin for the reference's rounding


def rayleigh_speed(c_p, c_s):
    """The Rayleigh cubic's root in (0, 1) (Graff sec. 6.3): written here, in the test."""
    kappa = (c_s / c_p) ** 2
    roots = np.roots([1.0, -8.0, 24.0 - 16.0 * kappa, -16.0 * (1.0 - kappa)])
    eta = [r.real for r in roots if abs(r.imag) < 1e-12 and 0 < r.real < 1]
    assert len(eta) == 1
    return c_s * math.sqrt(eta[0])


def test_plane_stress_speeds():
    c_p, c_s = plane_stress_speeds(E, NU, RHO)
    assert c_p == pytest.approx(math.sqrt(E / (RHO * (1 - NU**2))), rel=1e-15)
    assert c_s == pytest.approx(math.sqrt(E / (2 * RHO * (1 + NU))), rel=1e-15)
    with pytest.raises(ValueError):
        plane_stress_speeds(E, 0.5, RHO)


def test_s0_starts_at_the_plate_speed():
    """S0's phase speed at kh -> 0 is the plate speed, here the thin strip's bar speed; its first
    correction is Love's lateral inertia, c / c_0 - 1 = -nu^2 k^2 r^2 / 2 with r^2 = h^2 / 12 the
    strip's squared radius of gyration (Love's rod theory with lateral inertia), with the plane-stress
    nu (the strip's lateral contraction). Both at kh = 1e-2, where the next term is (kh)^2 = 1e-4
    times the first: tolerance 1e-3 of the correction."""
    c_p, c_s = SPEEDS
    plate = 2 * c_s * math.sqrt(1 - (c_s / c_p) ** 2)
    assert plate == pytest.approx(math.sqrt(E / RHO), rel=1e-14)  # the bar speed of the thin strip
    kh = np.array([1e-3, 1e-2])
    c = 2 * np.pi * lamb_frequencies(kh / H, H, SPEEDS, "symmetric", 1)[0] / (kh / H)
    np.testing.assert_allclose(c / plate - 1, -NU**2 * kh**2 / 24, rtol=1e-3)


def test_a0_starts_on_the_flexural_branch():
    """A0 at kh -> 0 is the strip's Euler-Bernoulli branch w = k^2 c_plate h / sqrt(12)
    (E I / (rho A) = E h^2 / (12 rho)); shear and rotary inertia lower it by a relative
    (kh)^2 (1 + E / (kappa G)) / 24 (the long-wave expansion of Timoshenko's beam theory), at most
    0.3 (kh)^2 for any shear coefficient kappa >= 1/2 and nu < 1/2. Checked: the bound at
    kh = 1e-3 and 1e-2, and the order: halving kh divides the deviation by 4 (to 1 %: the next
    term is of relative order (kh)^2 = 4e-4)."""
    c_p, c_s = SPEEDS
    plate = 2 * c_s * math.sqrt(1 - (c_s / c_p) ** 2)
    kh = np.array([1e-3, 1e-2, 2e-2])
    k = kh / H
    f = lamb_frequencies(k, H, SPEEDS, "antisymmetric", 1)[0]
    euler = euler_bernoulli_frequency(k, E * H**3 / 12, RHO * H)
    np.testing.assert_allclose(euler, k**2 * plate * H / math.sqrt(12) / (2 * math.pi), rtol=1e-14)
    deviation = f / euler - 1
    assert np.all(deviation < 0) and np.all(-deviation < 0.3 * kh**2)
    assert deviation[2] / deviation[1] == pytest.approx(4.0, rel=1e-2)


@pytest.mark.parametrize("family", ["symmetric", "antisymmetric"])
def test_lowest_branches_tend_to_the_rayleigh_speed(family):
    """A0 and S0 at kh = 80 run at the Rayleigh speed: they differ from it by about
    exp(-kh sqrt(1 - c_R^2/c_s^2)) ~ exp(-32), far below the root accuracy."""
    c_p, c_s = SPEEDS
    c_r = rayleigh_speed(c_p, c_s)
    f = lamb_frequencies([80 / H], H, SPEEDS, family, 1)[0, 0]
    assert 2 * np.pi * f / (80 / H) == pytest.approx(c_r, rel=ROOTS)
    # Viktorov's approximation c_R / c_s = (0.87 + 1.12 nu') / (1 + nu'), good to 0.5 % for nu' >= 0
    nu_layer = NU / (1 + NU)  # the Poisson ratio of the 2-D layer with these bulk speeds
    assert c_r / c_s == pytest.approx((0.87 + 1.12 * nu_layer) / (1 + nu_layer), rel=5e-3)


def test_cut_off_frequencies():
    """At k = 0 the symmetric family cuts on at n c_p/(2h), n odd, and n c_s/(2h), n even; the
    antisymmetric at n c_s/(2h), n odd, and n c_p/(2h), n even (row 0: A0 and S0, at 0)."""
    c_p, c_s = SPEEDS
    count = 7

    def expected(p_parity, s_parity):
        cuts = [n * c_p / (2 * H) for n in range(1, 2 * count) if n % 2 == p_parity]
        cuts += [n * c_s / (2 * H) for n in range(1, 2 * count) if n % 2 == s_parity]
        return np.array([0.0] + sorted(cuts)[: count - 1])

    sym = lamb_frequencies([0.0], H, SPEEDS, "symmetric", count)[:, 0]
    anti = lamb_frequencies([0.0], H, SPEEDS, "antisymmetric", count)[:, 0]
    np.testing.assert_allclose(sym, expected(1, 0), rtol=ROOTS, atol=0)
    np.testing.assert_allclose(anti, expected(0, 1), rtol=ROOTS, atol=0)


@pytest.mark.parametrize("family,kh", [("symmetric", math.pi), ("symmetric", 3 * math.pi),
                                       ("antisymmetric", 2 * math.pi), ("antisymmetric", 4 * math.pi)])
def test_lame_modes(family, kh):
    """Where q = k (phase speed sqrt(2) c_s) the Rayleigh-Lamb equations reduce to cos(kh/2) = 0
    (symmetric) or sin(kh/2) = 0 (antisymmetric): a branch of the family passes through
    f = sqrt(2) c_s k / (2 pi) there."""
    c_s = SPEEDS.c_s
    k = kh / H
    f = lamb_frequencies([k], H, SPEEDS, family, 6)[:, 0]
    lame = math.sqrt(2) * c_s * k / (2 * math.pi)
    assert np.min(np.abs(f / lame - 1)) < ROOTS


def test_branches_are_ordered_and_roots():
    """Each frequency returned is a sign change of its family's function (the root itself), and
    the branches ascend."""
    k = np.linspace(0, 2000, 41)
    b = lamb_branches(k, H, SPEEDS, 4)
    for family, f in (("symmetric", b.symmetric), ("antisymmetric", b.antisymmetric)):
        assert np.all(np.isfinite(f))
        assert np.all(np.diff(f, axis=0) > 0)
        for j in range(1, len(k)):
            for n in range(4):
                w = 2 * np.pi * f[n, j]
                lo, hi = (rayleigh_lamb(w * (1 + s * 1e-9), k[j], H, SPEEDS, family) for s in (-1, 1))
                assert lo * hi <= 0


def test_lowest_phase_speeds_are_monotone():
    """Over kh from 1e-5 to 1e3, A0's phase speed rises from 0 toward the Rayleigh speed and S0's
    falls from the plate speed toward it, monotonically (Graff sec. 8.1, Rose ch. 6): a spurious
    root (a sign change of rounding near w = 0) would break either (it did, at kh ~ 1, before
    the terms' small-argument forms were made exact)."""
    c_p, c_s = SPEEDS
    c_r = rayleigh_speed(c_p, c_s)
    plate = 2 * c_s * math.sqrt(1 - (c_s / c_p) ** 2)
    k = np.geomspace(1e-5, 1e3, 300) / H
    b = lamb_branches(k, H, SPEEDS, 1)
    a0, s0 = 2 * np.pi * b.antisymmetric[0] / k, 2 * np.pi * b.symmetric[0] / k
    # monotone to the roots' accuracy (where the speeds have converged, they differ by less)
    assert np.all(np.diff(a0) > -ROOTS * c_r) and np.all(a0 < c_r * (1 + ROOTS))
    assert np.all(np.diff(s0) < ROOTS * plate) and np.all(s0 > c_r * (1 - ROOTS)) and np.all(s0 < plate * (1 + ROOTS))
    assert a0[0] < 1e-4 * c_r and s0[0] > plate * (1 - 1e-9)


def test_bad_arguments():
    with pytest.raises(ValueError):
        lamb_frequencies([1.0], H, SPEEDS, "shear")
    with pytest.raises(ValueError):
        lamb_frequencies([-1.0], H, SPEEDS, "symmetric")
