"""Linear elastic solids: plane-stress Q8 plate with rigid layers, Euler-Bernoulli beam, modes and
their disk cache, Newmark, exact modal propagation; behind one interface (`SolidModel`).
May import: guard."""
