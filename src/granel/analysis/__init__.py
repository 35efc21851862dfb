"""Post-processing of result Datasets: reciprocity metrics, modal energies, energy densities.

Every function takes result Datasets (as written by `granel run`) or plain arrays and returns
numbers or arrays; nothing here runs a simulation.
"""

from .modal import (  # noqa: F401
    accumulated_modal_energy,
    modal_coordinates,
    modal_energies,
    modes_for_fraction,
    time_averaged_accumulation,
)
from .reciprocity import arrival_time, nonreciprocity_index, reciprocity_metrics  # noqa: F401
from .density import beam_energy_density_grid, granule_energy_density, solid_energy_density  # noqa: F401
