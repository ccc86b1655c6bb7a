"""The rod engine: compiled kernel (kernel.py, contact.py), problem data (model.py), driver."""

from .model import (
                    Contact,
                    Controls,
                    Ends,
                    Problem,
                    Rod,
                    RodState,
                    Solver,
                    Stage,
                    constant,
                    hairpin_state,
                    ramp,
                    stable_time_step,
                    state_from,
                    straight_state,
)
from .simulate import simulate, time_step

__all__ = ["Contact", "Controls", "Ends", "Problem", "Rod", "RodState", "Solver", "Stage",
           "constant", "hairpin_state", "ramp", "simulate", "stable_time_step", "state_from", "straight_state",
           "time_step"]
