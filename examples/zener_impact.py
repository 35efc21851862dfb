"""Zener's impact: a steel sphere striking a thin steel plate, against Zener's theory.

The scenario scenarios/impact/zener-plate.toml (a 2 mm sphere at 0.1 m/s on the centre of a
clamped disc 10 cm across, its mesh graded toward the contact) is run at several plate
thicknesses, which sweep Zener's parameter lambda = m v0 / (Z a) (Z = 8 sqrt(D rho h) the plate's
impedance under a point force, a = (m v0^2 / k)^(2/5) the Hertz approach's scale). Zener's
equation x'' + lambda (x^(3/2))' + x^(3/2) = 0 is integrated beside it with scipy. Left: the
contact force histories; right: the coefficient of restitution over lambda. docs/solids.md
("Zener's impact") shows the figure.

    python examples/zener_impact.py                  # five thicknesses, about 20 s
    GRANEL_EXAMPLE_QUICK=1 python examples/...       # two
"""

import math
import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

from granel import scenario as S  # noqa: E402
from granel.run import run_scenario  # noqa: E402

HERE = Path(__file__).resolve().parent
SCENARIO = HERE.parent / "scenarios" / "impact" / "zener-plate.toml"
quick = bool(os.environ.get("GRANEL_EXAMPLE_QUICK"))
thicknesses = [2e-3, 0.7e-3] if quick else [3e-3, 2e-3, 1.4e-3, 1e-3, 0.7e-3]


def zener(m, k, Z, v0, t):
    """Zener's restitution and contact force at times t: x' = u - lambda x^(3/2), u' = -x^(3/2)."""
    a = (m * v0**2 / k) ** 0.4
    lam = m * v0 / (Z * a)

    def parted(s, y):
        return y[0] if s > 1e-6 else 1.0
    parted.terminal, parted.direction = True, -1
    sol = solve_ivp(lambda s, y: [y[1] - lam * max(y[0], 0) ** 1.5, -max(y[0], 0) ** 1.5], (0, 50), [0, 1],
                    method="DOP853", rtol=1e-12, atol=1e-15, dense_output=True, events=parted)
    s = t * v0 / a
    x = np.where(s < sol.t[-1], sol.sol(np.minimum(s, sol.t[-1]))[0], 0.0)
    return lam, -sol.y[1, -1], k * a**1.5 * np.maximum(x, 0) ** 1.5


fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
rows = []
for h in thicknesses:
    sc = S.load(str(SCENARIO), [f"solid.width={h}"])
    mat = sc.materials[sc.solid.material]
    R, v0 = sc.media[0].radii[0], sc.initial_velocities[0].v[0]
    m = mat.rho * 4 / 3 * math.pi * R**3
    k = 4 / 3 * mat.E / (1 - mat.nu**2) * math.sqrt(R)  # eq. 3: a bead on the solid's face
    Z = 8 * math.sqrt(mat.E * h**3 / (12 * (1 - mat.nu**2)) * mat.rho * h)
    ds = run_scenario(sc)
    t, f, v = ds["time"].values, ds["contact_force_normal"].values[:, 0], ds["v_x"].values[:, 0]
    lam, e, ref = zener(m, k, Z, v0, t)
    after = int(np.argmax(f > 0)) + int(np.argmax(f[int(np.argmax(f > 0)):] <= 0))
    got = -v[after] / v0
    rows.append((lam, e, got))
    print(f"h = {1e3 * h:.1f} mm  lambda = {lam:.3f}  restitution {got:.4f} (Zener {e:.4f})  "
          f"peak force {f.max():.3f} N (Zener {ref.max():.3f} N)")
    line, = left.plot(1e6 * t, f, label=f"h = {1e3 * h:.1f} mm, lambda = {lam:.2f}")
    left.plot(1e6 * t, ref, "k:", lw=1)
left.set_xlim(0, 30)
left.set_xlabel("time [us]")
left.set_ylabel("contact force [N]")
left.set_title("granel (lines), Zener (dotted)")
left.legend(fontsize=8)
lam, e, got = map(np.array, zip(*sorted(rows)))
grid = np.linspace(0.02, max(1.2, lam.max()), 60)
curve = [zener(1.0, 1.0, 1.0 / g, 1.0, np.zeros(1))[1] for g in grid]  # lambda = m v0 / (Z a) = 1 / Z here
right.plot(grid, curve, "k-", lw=1, label="Zener's equation")
right.plot(lam, got, "o", label="granel (a graded clamped disc)")
right.set_xlabel("Zener's parameter lambda")
right.set_ylabel("coefficient of restitution")
right.grid(True, alpha=0.3)
right.legend()
fig.tight_layout()
fig.savefig("zener_impact.png", dpi=120)
print("wrote zener_impact.png")
