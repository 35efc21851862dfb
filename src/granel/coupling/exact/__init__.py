"""The exact modal integrator, the fast method's default: every mode of the solid (the eigenmodes
below a cut-off, then residual modes for the dropped ones) is propagated in closed form under an
interface force that is a polynomial over the step (`operators`); the unknowns are the forces at
the polynomial's nodes, found by Newton on the interface map (`interface`, `newton`); a step's
error is the granules' embedded RK4 error and its defect of the energy ledger (13) (`ledger`);
outputs come by dense output inside the step that passes them (`dense`); `loop` steps through a
batch of outputs over the records of `state`; `solver` puts it behind the solver interface.
docs/coupling.md derives the method; docs/architecture.md maps its equations to functions."""

from .dense import dense, dense_state, trial_step  # noqa: F401
from .loop import accept, advance_outputs  # noqa: F401
from .operators import contacts_of_modes, ensure_ops, modes_of_contacts  # noqa: F401
from .state import DenseOut, ExactConfig, ExactSolid, ExactState, initial_state, ops_cache  # noqa: F401
