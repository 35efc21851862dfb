"""The compiled load law's layout (`laws.load_force`): each load kind's code and the number of
parameter slots a load carries. `loads` (the kinds) and `laws` (the compiled law) both read it,
so that neither imports the other at load time."""

KIND_HALF_SINE, KIND_BURST, KIND_TABLE, KIND_CONSTANT, KIND_HARMONIC, KIND_CHIRP = range(6)
LOAD_PARAMS = 8
