"""Pictures of results and scenarios: the paper's figures, plots, schematics, movies, and exports
for ParaView and OVITO. A result's pictures read the model it carries (`analysis.result_model`),
from a Dataset their caller read (`run.load_result` upgrades a result of an earlier granel) or
from a file read by `io.model.read_result`; a scenario's drawings build it (`scenario.built_models`).
May import: analysis, scenario, solid, granular, io, guard."""
