"""Applications built on runs: sweeps and their modes (run, reciprocity, spectrum), design
searches and their reports, the paper's study and its statements, the reciprocity study, a
scenario's natural modes, benchmarks.
May import: viz, analysis, run, scenario, problem, coupling, solid, granular, io, guard."""
