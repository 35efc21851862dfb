"""Coupled stepping of the granules with the solid at the interface: the solvers (the paper's
algorithm, exact modal propagation, Newmark, sparse) and the one driver loop.
May import: granular, solid, io, guard."""
