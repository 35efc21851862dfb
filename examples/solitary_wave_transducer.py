"""The solitary-wave transducer: a chain of beads standing on a plate, read at a bead of the chain.

A solitary wave sent down the built-in `chain-on-plate` (ten steel beads, R = 4.76 mm, on the
middle of a clamped steel plate 150 mm square) comes back from the plate as a primary reflected
solitary wave and, from plates of middling thickness, a secondary one: the plate, pushed away by
the primary, swings back and strikes the chain again. Their arrival times and amplitudes at the
sensor bead C:6 (the sixth from the struck end) change with the plate's thickness, which is how
such transducers measure plates (Yang, Silvestro, Khatri, De Nardo & Daraio, Phys. Rev. E 83,
046606, 2011). The rigid wall is the thick plate's limit. docs/solids.md ("The solitary-wave
transducer") shows the figure.

    python examples/solitary_wave_transducer.py              # eleven thicknesses, about 15 s
    GRANEL_EXAMPLE_QUICK=1 python examples/...               # four
"""

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy.signal import find_peaks  # noqa: E402

from granel import scenario as S  # noqa: E402
from granel.run import run_scenario  # noqa: E402

quick = bool(os.environ.get("GRANEL_EXAMPLE_QUICK"))
thicknesses = [1e-3, 2e-3, 4e-3, 8e-3] if quick else [0.75e-3, 1e-3, 1.25e-3, 1.5e-3, 2e-3, 2.5e-3, 3e-3, 4e-3, 6e-3,
                                                     8e-3, 12e-3]
SENSOR = "C:6"
WINDOW = "1.5ms"
SHARE = 0.1  # a reflected wave: a peak of the sensor's speed away from the plate above this share of the incident's


def reflected_waves(ds, sensor=SENSOR, share=SHARE):
    """The sensor bead's velocity toward the plate, the incident wave's peak (time, speed), and the
    reflected waves' (time, speed / incident): the peaks of its speed away from the plate."""
    k = list(ds["granule"].values).index(sensor)
    t, v = ds["time"].values, ds["v_x"].values[:, k]
    inc = float(v.max())
    peaks, _ = find_peaks(-v, height=share * inc, prominence=share * inc)
    return t, v, (float(t[v.argmax()]), inc), [(float(t[p]), float(-v[p] / inc)) for p in peaks]


rows = []
fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.5))
for j, h in enumerate([None, *thicknesses]):
    over = ['solid.kind="rigid"'] if h is None else [f"solid.width={h!r}"]
    ds = run_scenario(S.load("chain-on-plate", [*over, f'simulation.duration="{WINDOW}"']))
    t, v, (t_inc, inc), waves = reflected_waves(ds)
    name = "rigid wall" if h is None else f"{1e3 * h:g} mm"
    rows.append((h, t_inc, waves))
    said = ", ".join(f"{1e6 * (tw - t_inc):.0f} us ({a:.2f})" for tw, a in waves[:3]) or "none"
    print(f"{name:>10}: reflected waves after the incident at {SENSOR}: {said}")
    if h is None or h in (1e-3, 2e-3, 4e-3, 8e-3):
        left.plot(1e6 * t, v / inc + 2.2 * len(left.lines), lw=1, label=name)
left.set_xlabel("time [us]")
left.set_ylabel(f"{SENSOR}'s velocity toward the plate / incident peak (offset)")
left.set_title("the sensor bead: incident wave up, reflected waves down")
left.legend(fontsize=8, loc="upper right")
for which, marker in ((0, "o-"), (1, "s--")):
    hs = [1e3 * h for h, _, w in rows if h is not None and len(w) > which]
    dt = [1e6 * (w[which][0] - t0) for h, t0, w in rows if h is not None and len(w) > which]
    right.plot(hs, dt, marker, label=("primary" if which == 0 else "secondary") + " reflected wave")
rigid = rows[0]
right.axhline(1e6 * (rigid[2][0][0] - rigid[1]), color="k", lw=0.8, ls=":", label="rigid wall")
right.set_xscale("log")
right.set_xlabel("plate thickness h [mm]")
right.set_ylabel("arrival after the incident wave [us]")
right.grid(True, which="both", alpha=0.3)
right.legend()
fig.tight_layout()
fig.savefig("solitary_wave_transducer.png", dpi=120)
print("wrote solitary_wave_transducer.png")
