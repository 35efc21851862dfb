"""granel: nonlinear acoustics of granular-elastic-solid interfaces.

Physics (granular/, solid/), numerics (coupling/) and I/O (scenario, results, cli)
live in separate modules. Equation numbers in comments refer to
Wang, Tawfick & Vakakis, Phys. Rev. E 104, 044906 (2021).
"""

__version__ = "0.1.0"
