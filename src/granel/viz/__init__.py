"""Pictures of results and scenarios: the paper's figures, plots, schematics, movies, and exports
for ParaView and OVITO. A result's pictures read the model it carries (`analysis.result_model`);
`run` is imported only to draw a scenario (`run.built_models`, in schematics and plots) and to
read a result file (`run.load_result`, which gives a result of an earlier granel its model record).
May import: analysis, run, solid, granular, io, guard."""
