"""Discrete elements: materials, packings, loads, contact laws (eqs. 2-6), the compiled
right-hand side and RK4 stepping, static equilibria.
May import: guard, solid."""
