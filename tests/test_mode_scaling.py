"""Modes of a solid proportional to a cached one (another thickness, modulus or density of the
same plate or beam) scaled from the cache, against direct eigen-solves; the cases that must be
refused; the assembled plate scaled from a cached one; a coupled run on scaled modes."""

import numpy as np
import pytest
import scipy.sparse as sp

from granel import scenario as S
from granel.solid.base import Material, Slab, SolidModel
from granel.solid.beam import build_beam
from granel.solid.modal import at_dofs, modal_analysis
from granel.solid.mode_cache import all_modes, modes_below
from granel.solid.mode_scaling import ScaledShapes
from granel.solid.plate import CachedPlate, LayerSpec, PlateMesh, assemble_plate, build_plate

from test_symmetry import EPS, eigen_bounds

E, RHO, NU = 200e9, 7850.0, 0.3
W, L, H = 0.01, 0.1, 0.001
LAYERS = [LayerSpec("A", "left", 0.05, 1e-3), LayerSpec("B", "right", 0.04, 5e-4), LayerSpec("C", "right", 0.06, 5e-4)]
MESH = PlateMesh(2, 2.5, 8e-3)  # a coarse plate (a few hundred DOFs) with three rigid layers


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("GRANEL_CACHE", str(tmp_path))
    return tmp_path


def plate_args(h=H, e=E, rho=RHO, nu=NU, layers=LAYERS, mesh=MESH):
    return (Slab(0.0, 0.0, W, L, h), Material(e, rho, nu), layers, mesh)


def mode_files(folder):
    return sorted(p.name for p in folder.glob("modes-*.shapes.npy"))


def assert_same_modes(got, direct, K, M):
    """The scaled modes against a direct solve of the target (`direct` may hold more modes, the
    comparison is on the first len(got)): each frequency within what the two sets' residuals allow
    (`eigen_bounds`: no dense solve is closer to the exact frequencies than that, and a scaled set
    carries its base's error); each scaled pair backward stable, LAPACK's n eps (|K| + w^2 |M|)
    |phi|; shapes M-orthonormal to n eps kappa of the unit-diagonal M; and each group of modes the
    bounds cannot separate spans the direct group's space, to the Davis-Kahan angle: the
    bounds over the group's distance to the other frequencies (1 - cos below half its square,
    besides the normalisation errors). Returns the largest frequency error as a share of its bound."""
    K, M = K.toarray(), M.toarray()
    n, k = len(K), len(got.omega)
    w, w0 = got.omega, direct.omega
    Phi, Phi0 = np.asarray(got.shapes), np.asarray(direct.shapes)
    assert w.shape == w0[:k].shape
    beta = eigen_bounds(K, M, Phi, w**2) + eigen_bounds(K, M, Phi0[:, :k], w0[:k] ** 2)
    share = np.abs(w**2 - w0[:k] ** 2) / beta
    assert np.all(share <= 1)
    r = np.linalg.norm(K @ Phi - (M @ Phi) * w**2, axis=0)
    assert np.all(r <= n * EPS * (np.linalg.norm(K, 2) + w**2 * np.linalg.norm(M, 2)) * np.linalg.norm(Phi, axis=0))
    d = 1 / np.sqrt(np.diag(M))
    orth = np.abs(Phi.T @ M @ Phi - np.eye(k)).max()
    assert orth < n * EPS * np.linalg.cond(d[:, None] * M * d[None, :])
    orth0 = np.abs(Phi0[:, :k].T @ M @ Phi0[:, :k] - np.eye(k)).max()
    C = Phi0[:, :k].T @ (M @ Phi)  # the direct shapes' coordinates of the scaled ones
    lam = w0**2
    split = np.flatnonzero(np.diff(lam[:k]) > 2 * (beta[:-1] + beta[1:])) + 1
    compared = 0
    for group in np.split(np.arange(k), split):
        lo, hi = group[0], group[-1]
        below = lam[lo] - lam[lo - 1] if lo > 0 else np.inf
        above = lam[hi + 1] - lam[hi] if hi + 1 < len(lam) else np.inf
        spread = np.sqrt(np.sum(beta[group] ** 2))
        distance = min(below, above) - 2 * beta[group].max()
        if distance <= spread:
            continue  # too close to a mode outside the comparison to be pinned down
        s = np.linalg.svd(C[np.ix_(group, group)], compute_uv=False)
        assert np.abs(s - 1).max() <= 0.5 * (spread / distance) ** 2 + orth + orth0
        compared += len(group)
    assert compared >= 0.9 * k
    return share.max()


@pytest.mark.parametrize("change", [dict(e=70e9), dict(rho=2700.0), dict(h=1.7e-3),
                                    dict(e=100e9, rho=8500.0, h=0.6e-3)], ids=["E", "rho", "thickness", "all-three"])
def test_plate_modes_scaled_from_the_cache_equal_a_direct_solve(cache, change):
    base = build_plate(*plate_args())
    assert all_modes(base).origin == "computed"
    target = build_plate(*plate_args(**change))
    assert isinstance(target, CachedPlate)  # the assembled plate is the cached one scaled, too
    modes = all_modes(target)
    assert modes.origin == "scaled" and len(mode_files(cache)) == 1  # nothing new stored
    fresh = assemble_plate(*plate_args(**change))
    assert_same_modes(modes, modal_analysis(fresh), fresh.K, fresh.M)
    again = all_modes(target)  # a second call finds the same base: the same numbers
    assert again.origin == "scaled" and np.array_equal(again.omega, modes.omega)


def test_the_assembled_plate_scaled_from_the_cache(cache):
    """K, M and the element volumes of another thickness, modulus and density from the cached
    plate, to round-off; contacts, geometry and element energies as assembled."""
    build_plate(*plate_args())
    args = plate_args(h=1.3e-3, e=70e9, rho=2700.0)
    scaled, fresh = build_plate(*args), assemble_plate(*args)
    assert isinstance(scaled, CachedPlate)
    # the base times a ratio (one rounding) against an assembly that rounds each element's product
    # by E, h or rho and sums a node's elements: a few eps of the largest entry (measured 1.4 eps)
    for a, b in ((scaled.K, fresh.K), (scaled.M, fresh.M)):
        assert abs(a - b).max() <= 4 * EPS * abs(b).max()
    assert np.allclose(scaled.element_volume, fresh.element_volume, rtol=4 * EPS, atol=0)  # measured 1.5 eps
    assert scaled.contacts == fresh.contacts and scaled.info == fresh.info
    q = np.random.default_rng(1).normal(size=fresh.ndof) * 1e-6
    for a, b in zip(scaled.element_energies(q, q), fresh.element_energies(q, q)):
        assert np.array_equal(a, b)  # a cached plate assembles the same plate for these: the same arithmetic
    # stored under its own arguments: the next build reads it as it is
    assert len(list(cache.glob("plate-*.npz"))) == 2
    assert abs(build_plate(*args).K - scaled.K).max() == 0


@pytest.mark.parametrize("change", [dict(e=70e9, rho=2700.0), dict(thickness=2e-3), dict(width=0.012)],
                         ids=["E-rho", "thickness", "depth"])
def test_beam_modes_scaled_from_the_cache_equal_a_direct_solve(cache, change):
    """The beam has bending DOFs only (K = E I K0, M = rho A M0): its modulus, density and both
    section sizes scale exactly (I = t w^3 / 12, A = w t). The first frequencies agree only
    within a dense solve's own error: this beam's w_max / w_1 is 3,600, and against a 40-digit
    solve of the same matrices the dense solver is 1.3e-10 off at mode 1 for steel, 3.4e-11 for
    aluminium (the two beams' matrices proportional to 3e-14), so the scaled set and the direct
    one differ by the sum of the two solves' errors; both are eigenpairs to round-off."""
    def beam(e=E, rho=RHO, thickness=H, width=W):
        return build_beam(Slab(0.0, 0.0, width, L, thickness), Material(e, rho, 0.3), [("c", "left", 0.05)], 40)

    assert all_modes(beam()).origin == "computed"
    target = beam(**change)
    modes = all_modes(target)
    assert modes.origin == "scaled"
    assert_same_modes(modes, modal_analysis(target), target.K, target.M)


@pytest.mark.parametrize("change", [dict(nu=0.33), dict(layers=[LayerSpec("A", "left", 0.05, 0.9e-3), *LAYERS[1:]]),
                                    dict(mesh=PlateMesh(3, 2.5, 8e-3))],
                         ids=["poisson-ratio", "layer-length", "mesh"])
def test_other_plates_are_not_scaled(cache, change):
    """A Poisson ratio, a rigid layer's length or a mesh of its own: the modes are computed (the
    first two keep the base's DOF count and sparsity: the check is on the matrices' values)."""
    base = build_plate(*plate_args())
    all_modes(base)
    other = build_plate(*plate_args(e=70e9, **change))
    assert not isinstance(other, CachedPlate)  # not a scaled plate either
    assert other.ndof == base.ndof or "mesh" in change
    modes = all_modes(other)
    assert modes.origin == "computed" and len(mode_files(cache)) == 2
    assert np.array_equal(modes.omega, modal_analysis(other).omega)


def test_a_term_that_does_not_scale_is_refused(cache):
    """A spring of fixed stiffness on one DOF: doubling the plate's stiffness does not double K, so
    its modes are not the base's scaled (the same DOF count, sparsity and kind)."""
    plate = assemble_plate(*plate_args())
    spring = sp.csr_matrix(([1e9], ([3], [3])), shape=plate.K.shape)
    base = SolidModel("plate", plate.M, plate.K + spring, plate.contacts)
    all_modes(base)
    stiffer = SolidModel("plate", plate.M, 2 * plate.K + spring, plate.contacts)
    assert all_modes(stiffer).origin == "computed"
    proportional = SolidModel("plate", plate.M, 2 * (plate.K + spring), plate.contacts)
    assert all_modes(proportional).origin == "scaled"


def test_damaged_or_missing_bases_are_not_used(cache):
    build_plate(*plate_args())
    all_modes(build_plate(*plate_args()))
    (record,) = cache.glob("modes-*.scale.npz")
    record.write_bytes(b"not a record")
    assert all_modes(build_plate(*plate_args(h=1.5e-3))).origin == "computed"
    for f in cache.glob("modes-*.shapes.npy"):
        f.unlink()
    assert all_modes(build_plate(*plate_args(h=1.2e-3))).origin == "computed"


def test_sets_cached_before_the_records_become_bases(cache):
    """Modes stored without a scale-free record (an older cache) get one at their next use."""
    base = build_plate(*plate_args())
    all_modes(base)
    for f in cache.glob("modes-*.scale.npz"):
        f.unlink()
    assert all_modes(base).origin == "cache" and len(list(cache.glob("modes-*.scale.npz"))) == 1
    assert all_modes(build_plate(*plate_args(e=120e9))).origin == "scaled"


def test_modes_below_a_cut_off_are_scaled_when_the_base_reaches_it(cache):
    """modes_below: a cached set serves a proportional solid when it holds every mode below the
    wanted cut-off (in its own frequencies), or the wanted count; otherwise they are computed."""
    base = build_plate(*plate_args())
    low = modes_below(base, 1.0e6)
    assert low.origin == "computed"
    target = build_plate(*plate_args(h=1.4e-3, e=100e9, rho=8500.0))  # frequencies x 0.68
    f_top = 0.6e6
    modes = modes_below(target, f_top)
    assert modes.origin == "scaled" and isinstance(modes.shapes, np.ndarray)
    fresh = assemble_plate(*plate_args(h=1.4e-3, e=100e9, rho=8500.0))
    direct = modal_analysis(fresh, modes.count + 1)
    assert direct.omega[-1] > 2 * np.pi * f_top >= direct.omega[-2]  # the count is the direct one
    # the set's lowest modes from dense solves (of the base's and the target's first 220 modes)
    # agree within those solves' accuracy (against all the target's modes: the next one bounds the
    # last group's distance)
    assert_same_modes(modes, modal_analysis(fresh), fresh.K, fresh.M)
    # 1.0 MHz on the target is 1.47 MHz on the base: beyond its set
    assert modes_below(target, 1.0e6).origin == "computed"
    # a count bound that the base's set holds
    capped = modes_below(build_plate(*plate_args(e=150e9)), 5e6, max_count=10)
    assert capped.origin == "scaled" and capped.count == 10


def test_scaled_shapes_read_like_the_array(cache):
    """The memory-mapped shapes of a scaled set read as the scaled matrix would: rows, columns,
    products with sparse and dense matrices, numpy functions."""
    all_modes(build_plate(*plate_args()))
    target = build_plate(*plate_args(rho=2700.0))
    modes = all_modes(target)
    phi = modes.shapes
    assert isinstance(phi, ScaledShapes)
    full = np.asarray(phi)
    assert phi.shape == full.shape and len(phi) == len(full) and phi.ndim == 2
    rows = np.array([3, 1, 40])
    assert np.array_equal(phi[rows], full[rows]) and np.array_equal(phi[:, :5], full[:, :5])
    assert np.array_equal(phi[:, 7], full[:, 7]) and phi[2, 3] == full[2, 3]
    B = target.contact_map()
    assert np.array_equal(at_dofs(B, phi, slice(0, 9)), B @ full[:, :9])
    # the products with the factor applied before or after: each within its sum's rounding, (terms)
    # eps of the sum of absolute values, besides the factor's own rounding
    terms = np.diff(target.M.tocsr().indptr).max() + 1
    assert np.allclose(target.M @ phi, target.M @ full, rtol=0, atol=2 * terms * EPS * (abs(target.M) @ np.abs(full)))
    x = np.random.default_rng(2).normal(size=(full.shape[1], 3))
    assert np.allclose(phi @ x, full @ x, rtol=0, atol=2 * (len(x) + 1) * EPS * (np.abs(full) @ np.abs(x)))
    assert np.allclose(np.einsum("ij,ij->j", phi, phi), np.einsum("ij,ij->j", full, full), rtol=2 * (len(full) + 1) * EPS, atol=0)
    assert np.array_equal(2 * phi, 2 * full) and np.array_equal(phi.T, full.T)


def test_a_coupled_run_on_scaled_modes_equals_one_on_computed_modes(tmp_path, monkeypatch):
    """A short plate run (strong shock on SSGM:C, a coarse plate 1.3 mm thick) with its modes
    scaled from the 1 mm plate's equals the run whose modes are solved for, at fixed 100 ns steps:
    energies, speeds and contact forces as close to it as a run on another direct solve of the
    same plate (of 3K, 3M, the shapes times sqrt(3)) is. The run amplifies the modes' round-off
    to about 1e-10 (the granules' vertical speeds, smallest against their largest); the scaled
    modes are just one more set of modes exact to round-off, so they may differ from the computed
    ones as much as a second solve does, a few times more by chance, not ten. Measured: at most
    1.6e-10 and 0.99 of the second solve's spread (Prescott's kernels: 4.0e-11 and 0.79)."""
    from granel.run import run_scenario

    # fixed steps: an error-controlled run can round a step's grid level differently on modes
    # that differ in their last digits, and then differs at its tolerance, not at the modes'
    mesh = ["solid.mesh.nx=2", "solid.mesh.growth=3.0", "solid.mesh.max_size=0.01", 'excitations.0.granule="SSGM:C"',
            'simulation.duration="0.05ms"', "simulation.adaptive=false", "simulation.dt=1e-7"]
    thick = S.load("paper", [*mesh, "solid.thickness=0.0013"])
    monkeypatch.setenv("GRANEL_CACHE", str(tmp_path / "fresh"))
    fresh = run_scenario(thick)
    assert len(mode_files(tmp_path / "fresh")) == 1
    monkeypatch.setenv("GRANEL_CACHE", str(tmp_path / "scaled"))
    sc = S.load("paper", mesh)
    system, _, _ = S.build_granular(sc)
    assert all_modes(S.build_solid(sc, system)).origin == "computed"
    scaled = run_scenario(thick)
    assert len(mode_files(tmp_path / "scaled")) == 1  # the 1 mm plate's modes only
    assert np.array_equal(scaled["step_dt"].values, fresh["step_dt"].values)
    from granel.solid import modal, mode_cache
    from granel.solid.base import SolidModel

    def tripled(model):  # the same modes from another solve: of 3K, 3M
        md = modal_analysis(SolidModel(model.kind, 3 * model.M, 3 * model.K, model.contacts))
        return modal.Modes(md.omega, md.shapes * np.sqrt(3))

    monkeypatch.setattr(mode_cache, "all_modes", tripled)
    other = run_scenario(thick)
    assert np.array_equal(other["step_dt"].values, fresh["step_dt"].values)
    names = ("energy_solid", "energy_lsgm", "energy_ssgm", "input_work", "v_x", "v_y", "contact_force_normal")

    def spread(ds):
        return np.array([np.abs(ds[k].values - fresh[k].values).max() / np.abs(fresh[k].values).max() for k in names])

    floor = spread(other).max()  # the run's round-off from its modes'
    assert 0 < floor < 1e-6  # amplified round-off, not a different solution
    assert np.all(spread(scaled) <= 10 * floor), spread(scaled) / floor
