"""Records a run leaves: the trajectory recorded while it runs, checkpoints, result Datasets and
NetCDF files, and units of the command line.
May import: guard."""
