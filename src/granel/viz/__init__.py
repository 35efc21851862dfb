"""Pictures of results and scenarios: the paper's figures, plots, schematics, movies, and exports
for ParaView and OVITO.
May import: analysis, run, scenario, solid, granular, io, guard."""
