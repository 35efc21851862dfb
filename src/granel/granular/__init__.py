"""Discrete elements: packings, contact laws (eqs. 2-6), the compiled RHS and RK4 stepping."""
