"""Does the plate's spectrum spread in wavenumber like a diffusion behind the granular layer?

The reference study's follow-up (arXiv 2509.15415) reports that, behind the granular layer, the
plate's kinetic energy spreads over wavenumber like a diffusion (near-parabolic), where a bare
plate's stays hyperbolic. This script runs the paper's plate under the strong shock from each side
(LSGM:3 and SSGM:C) and the bare plate under the same shock through one granule
(scenarios/wavefield/bare-plate.toml), analyses each run's wavefield (granel.analysis.wavefield)
and prints the growth exponents of the spectrum's variance (kinetic and modal energy spectra,
fitted from the energy's arrival and over the late window from LATE) and its entropy, as a
Markdown table, and draws them (wavefield_behind_the_layers.png). docs/wavefield.md shows and
discusses the result.

    python examples/wavefield_behind_the_layers.py           # 0.8 ms runs (the paper's), a minute
    WAVEFIELD_DURATION=3ms python examples/...               # longer records
    GRANEL_EXAMPLE_QUICK=1 python examples/...               # 0.1 ms runs
"""

import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import LogNorm  # noqa: E402

from granel import scenario as S  # noqa: E402
from granel.analysis.result_model import result_modes, result_solid  # noqa: E402
from granel.analysis.wavefield import analyse_wavefield, growth_exponent  # noqa: E402
from granel.run import run_scenario  # noqa: E402

HERE = Path(__file__).resolve().parent
duration = "0.1ms" if os.environ.get("GRANEL_EXAMPLE_QUICK") else os.environ.get("WAVEFIELD_DURATION", "0.8ms")
LATE = 0.2e-3  # [s] the late window starts here (the bare plate's granule has left it by then)
CASES = {
    "behind the LSGM (shock on LSGM:3)": ("paper", ['excitations.0.granule="LSGM:3"']),
    "behind the SSGM (shock on SSGM:C)": ("paper", ['excitations.0.granule="SSGM:C"']),
    "bare plate (one granule, same shock)": (str(HERE.parent / "scenarios" / "wavefield" / "bare-plate.toml"), []),
}

results = {}
for label, (name, overrides) in CASES.items():
    sc = S.load(name, [*overrides, 'solid.kind="plate"', 'excitations.0.shock="strong"',
                       f'simulation.duration="{duration}"'])
    ds = run_scenario(sc)
    results[label] = analyse_wavefield(ds, result_solid(ds), result_modes(ds))
    print(f"ran {label}")

print()
print("| case | arrival [ms] | kinetic: from the arrival | kinetic: late | modal: from the arrival | modal: late | "
      "modal entropy 20 us after the arrival [nats] | modal entropy, late mean [nats] |")
print("|---|---|---|---|---|---|---|---|")
for label, wf in results.items():
    t, h = wf.spectrum.t, wf.modal.moments.entropy
    cells = [label, f"{wf.arrival * 1e3:.3f}"]
    for m in (wf.kinetic, wf.modal):
        late = growth_exponent(t, m.moments.variance, LATE, t[-1]) if t[-1] > 2 * LATE else None
        cells += [f"{m.growth.exponent:.2f} +- {m.growth.stderr:.2f}",
                  f"{late.exponent:.2f} +- {late.stderr:.2f}" if late else "-"]
    cells += [f"{float(h[np.argmin(np.abs(t - (wf.arrival + 20e-6)))]):.2f}",
              f"{np.nanmean(h[t >= LATE]):.2f}" if t[-1] > LATE else "-"]
    print("| " + " | ".join(cells) + " |")

fig, axes = plt.subplots(3, len(results), figsize=(5 * len(results), 11), squeeze=False, layout="constrained")
for j, (label, wf) in enumerate(results.items()):
    t, k = wf.spectrum.t * 1e3, wf.spectrum.k
    E = wf.modal.energy
    sel = k <= wf.k_resolved
    top = E[sel].max()
    im = axes[0, j].pcolormesh(t, k[sel], np.maximum(E[sel], 1e-5 * top), shading="auto", cmap="magma",
                               norm=LogNorm(1e-5 * top, top), rasterized=True)
    fig.colorbar(im, ax=axes[0, j], label="modal energy [J]")
    axes[0, j].set(title=label, xlabel="t [ms]", ylabel="k [rad/m]")
    for name, m, style in (("kinetic", wf.kinetic, dict(lw=0.5, color="tab:blue")),
                           ("modal", wf.modal, dict(lw=1.3, color="tab:orange"))):
        g = m.growth
        axes[1, j].plot(t, m.moments.variance, label=f"{name}: exponent {g.exponent:.2f} +- {g.stderr:.2f}", **style)
        axes[2, j].plot(t, m.moments.entropy, label=name, **style)
    for g, color in ((wf.kinetic.growth, "tab:gray"), (wf.modal.growth, "k")):
        tt = np.linspace(g.t0, g.t_end, 200)[1:]
        axes[1, j].plot(tt * 1e3, g.prefactor * (tt - g.t0) ** g.exponent, "--", color=color, lw=1)
    axes[1, j].set(xlabel="t [ms]", ylabel="variance [(rad/m)^2]", yscale="log",
                   ylim=(1e2, 3 * np.nanmax(wf.modal.moments.variance)))
    axes[2, j].set(xlabel="t [ms]", ylabel="entropy [nats]", ylim=(0, None))
    axes[1, j].legend(fontsize=8)
    axes[2, j].legend(fontsize=8)
fig.savefig("wavefield_behind_the_layers.png", dpi=90)
print("\nwrote wavefield_behind_the_layers.png")
