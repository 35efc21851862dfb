"""A chain on a shaker, exported for ParaView and OVITO.

Six uncompressed beads between a wall that shakes by 1 um at 5 kHz and a fixed wall respond
every two drive periods (a period-doubled response; `granel.analysis.narrowband.response_period`),
then the run is written as VTU + PVD (ParaView), extended XYZ (OVITO) and CSV by `granel export`.

    python examples/shaker_and_export.py                     # 100 periods, a few seconds
    GRANEL_EXAMPLE_QUICK=1 python examples/...               # 60 periods
"""

import os
import subprocess
import sys
from pathlib import Path

from granel import scenario as S
from granel.analysis.narrowband import response_period
from granel.io.results import write_netcdf
from granel.run import run_scenario

R, n, f = 0.005, 6, 5e3
cycles = 60 if os.environ.get("GRANEL_EXAMPLE_QUICK") else 100
Path("chain.csv").write_text("label,x,y,radius\n" + "".join(f"{k + 1},{2 * R * k!r},0.0,{R}\n" for k in range(n)))
Path("shaker.toml").write_text(f"""name = "shaker-chain"
[simulation]
duration = {cycles / f!r}
output_every = {1 / (40 * f)!r}
[contact]
mu = 0.0
alpha_n = 0.5
[solid]
kind = "none"
[[media]]
name = "C"
side = "none"
granules_file = "chain.csv"
[[walls]]
p0 = [{-R!r}, -0.01]
p1 = [{-R!r}, 0.01]
normal = [1.0, 0.0]
name = "shaker"
motion = {{ amplitude = 1e-6, frequency = {f!r}, ramp_cycles = 5 }}
[[walls]]
p0 = [{2 * R * (n - 1) + R!r}, -0.01]
p1 = [{2 * R * (n - 1) + R!r}, 0.01]
normal = [-1.0, 0.0]
name = "fixed"
""")
ds = run_scenario(S.load("shaker.toml"))
t, F = ds["time"].values, ds["wall_force_normal"].values[:, 1]
m = response_period(t, F, 1 / f, window=(t[-1] - 20 / f, t[-1]))
print(f"the fixed wall's force repeats every {m} drive period(s)")
write_netcdf(ds, "shaker.nc")
subprocess.run([sys.executable, "-m", "granel", "export", "shaker.nc", "-o", "shaker-export", "--format", "vtk,extxyz,csv"],
               check=True)
