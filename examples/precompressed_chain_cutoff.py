"""A precompressed chain filters: below its cut-off a harmonic drive crosses it, above it not.

Twenty steel beads (R = 5 mm) pressed by 10 N against a wall (the built-in study
scenarios/narrowband/precompressed-chain.toml, started from its static equilibrium) are driven by
0.1 N at 0.8 and 1.1 times the linear cut-off f_c = (1/pi) sqrt(K/m); the force the far wall
feels at the drive frequency is fitted over whole periods (granel.analysis.narrowband).

    python examples/precompressed_chain_cutoff.py            # 3 ms a run, a few seconds
    GRANEL_EXAMPLE_QUICK=1 python examples/...               # 1 ms a run
"""

import math
import os
from pathlib import Path

from granel import scenario as S
from granel.analysis.narrowband import harmonic_amplitudes, transmissibility
from granel.run import run_scenario

HERE = Path(__file__).resolve().parent
SCENARIO = HERE.parent / "scenarios" / "narrowband" / "precompressed-chain.toml"
quick = bool(os.environ.get("GRANEL_EXAMPLE_QUICK"))

E, nu, R, rho, F0 = 200e9, 0.3, 0.005, 7850.0, 10.0
A = 4 / 3 * E / (2 * (1 - nu**2)) * math.sqrt(R / 2)  # Hertz, two equal spheres
K = 1.5 * A ** (2 / 3) * F0 ** (1 / 3)  # the contacts' linear stiffness under F0
m = 4 / 3 * math.pi * R**3 * rho
fc = math.sqrt(K / m) / math.pi
print(f"cut-off f_c = {fc / 1e3:.2f} kHz")

duration = 1e-3 if quick else 3e-3
for ratio in (0.8, 1.1):
    f = ratio * fc
    sc = S.load(str(SCENARIO), [f"excitations.0.frequency={f!r}", f"simulation.duration={duration!r}"])
    ds = run_scenario(sc)
    t, F = ds["time"].values, ds["wall_force_normal"].values[:, 0]
    amp = harmonic_amplitudes(t, F, f, orders=(1,), subharmonics=(), window=(duration / 2, duration))["f"]
    print(f"{ratio:.1f} f_c: the far wall feels {20 * math.log10(transmissibility(amp, 0.1)):+.1f} dB of the drive")
