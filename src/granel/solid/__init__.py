"""Linear elastic solids: plane-stress Q8 plate with rigid layers, Euler-Bernoulli beam,
Newmark time stepping and modal analysis, behind one interface (`SolidModel`)."""
