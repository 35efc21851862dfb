"""The paper's headline case from Python: a strong half-sine shock on SSGM:C against the plate.

Runs the built-in `paper` scenario, prints the energy ledger (eq. 13) and the share of the input
energy that reached the solid, and draws the media's and the solid's energies over time.

    python examples/shock_on_the_paper_interface.py          # 0.8 ms, about 3 s
    GRANEL_EXAMPLE_QUICK=1 python examples/...               # 0.05 ms (what the tests run)
"""

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from granel import scenario as S  # noqa: E402
from granel.run import run_scenario  # noqa: E402

duration = "0.05ms" if os.environ.get("GRANEL_EXAMPLE_QUICK") else "0.8ms"
sc = S.load("paper", ['excitations.0.granule="SSGM:C"', f'simulation.duration="{duration}"'])
ds = run_scenario(sc)

t = ds["time"].values * 1e3
work = ds["input_work"].values
print(f"input work {work[-1]:.4e} J, largest balance error {np.abs(ds['balance_error'].values).max():.2e} J")
print(f"solid energy at the end: {ds['energy_solid'].values[-1] / work[-1]:.1%} of the input")

fig, ax = plt.subplots(figsize=(6, 3.5))
for name in ("energy_lsgm", "energy_ssgm", "energy_solid"):
    ax.plot(t, ds[name].values / work[-1], label=name.removeprefix("energy_"))
ax.set_xlabel("time [ms]")
ax.set_ylabel("energy / input work")
ax.legend()
fig.tight_layout()
fig.savefig("shock_energies.png", dpi=150)
print("wrote shock_energies.png")
