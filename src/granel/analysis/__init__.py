"""Functions of result Datasets (or plain arrays): reciprocity metrics, modal energies, energy
densities, narrowband measures; nothing here runs a simulation.
May import: solid, granular, io, guard."""

from .modal import (  # noqa: F401
    accumulated_modal_energy,
    modal_coordinates,
    modal_energies,
    modes_for_fraction,
    time_averaged_accumulation,
    time_averaged_shares,
)
from .reciprocity import arrival_time, nonreciprocity_index, reciprocity_metrics  # noqa: F401
from .signals import amplitude_spectrum, dominant_frequency, peak_time, peak_width, zero_crossing_frequency  # noqa: F401
from .density import granule_energy_density, solid_energy_density  # noqa: F401
from .narrowband import (  # noqa: F401
    Drive,
    drive_of,
    harmonic_amplitudes,
    lock_in,
    nonreciprocity_db,
    response_period,
    steady_window,
    transmissibility,
)
