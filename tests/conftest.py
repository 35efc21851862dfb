import numpy as np
import pytest

from granel.granular.materials import STEEL
from granel.granular.packing import Medium, Wall, medium_from_table
from granel.granular.system import ContactLaw, Excitation, Stepper, build_system, initial_state


def make_system(rows, law=ContactLaw(0.0, 0.0, 100.0), walls=(), excitations=(), material=STEEL):
    """A single-medium system from [(label, x, y, R)]."""
    med = medium_from_table("M", [dict(label=l, x=x, y=y, radius=r) for l, x, y, r in rows], material)
    med.walls = list(walls)
    return build_system([med], law, excitations=list(excitations))


@pytest.fixture
def system_factory():
    return make_system
