"""Starting a run from a stored state: a config's `initial_state: "FILE.h5#RUN_ID"`.

One job: read the final state of a stored run (`read_state`, I/O) and make it the starting
state of a Problem that a scene built for the straight rod (`continue_from`, no I/O). What the
new run takes from the stored one, and how its own controls combine with it:

- positions, directors, velocities and angular velocities (at rest if the store has no rates);
- the clock: the new run starts at the stored final time, so its history goes on from there;
- the clamps: they hold the frames the stored run's clamps held (its `clamp_frames`, or the
  frames half an element beyond its end elements for a store written before them), so the
  rod does not snap;
- end and start rotations add (a twist ramp of the new run turns on from the stored rotation,
  and Lk of the new run is the stored Lk plus the turns it adds), stiffness and radius factors
  multiply, the end displacement goes on from the stored one;
- the axial load ramps from the stored load to the new one (the scene's first load ramp, which
  starts from zero for a straight rod, starts from the stored load instead).

The rod itself (elements, rest length, rest radius) must be the stored run's: a mismatch is a
ConfigError naming initial_state.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import config as C
from .rod.model import Controls, Problem, RodState, Table, state_from

KEY = "initial_state"
RESTARTABLE = ("ok", "not_converged")


@dataclass(frozen=True)
class StoredState:
    """The final state of a stored run and its controls there (SI units, rad).

    positions (n+1, 3), directors (n, 3, 3) rows d1 d2 d3, velocities (n+1, 3),
    angular_velocities (n, 3) in the material frame, clamp_frames (2, 3, 3) before rotation
    or None (not stored).
    """

    source: str
    positions: np.ndarray
    directors: np.ndarray
    velocities: np.ndarray
    angular_velocities: np.ndarray
    clamp_frames: np.ndarray | None
    time: float
    end_rotation: float
    start_rotation: float
    end_force: float
    end_displacement: float
    stiffness_factor: float
    radius_factor: float
    rest_length: float
    rest_radius: float
    at_rest: bool  # the store had no rates

    @property
    def elements(self) -> int:
        return len(self.directors)


def _error(value: str, allowed: str) -> C.ConfigError:
    return C.ConfigError(KEY, value, allowed)


def read_state(value: str) -> StoredState:
    """The final state of the run `value` names ("FILE.h5#RUN_ID"); a ConfigError naming
    initial_state if the file is not a store, the run is not in it, or it ended unstable."""
    from .store import StoreError, read_store

    value = C.initial_state(KEY, value)
    file, run_id = C.split_initial_state(value)
    if not Path(file).is_file():
        raise _error(value, f"{C.INITIAL_STATE_FORMAT}; there is no file {file}")
    try:
        with read_store(file) as store:
            ids = store.run_ids()
            if run_id not in ids:
                shown = ", ".join(ids[:5]) + (", ..." if len(ids) > 5 else "")
                raise _error(value, f"a run stored in {file}; it has no run {run_id!r} "
                             f"(stored: {shown or 'none'})")
            result = store.read_run(run_id, snapshots=False)
    except (StoreError, OSError) as exc:
        raise _error(value, f"{C.INITIAL_STATE_FORMAT}; {file} is not a readable rodphase "
                     f"store ({exc})") from None
    if result.status not in RESTARTABLE:
        raise _error(value, f"a run whose status is one of {', '.join(RESTARTABLE)}; {run_id} "
                     f"is {result.status}: {result.message}")
    n = len(result.directors)
    history = result.history

    def last(name: str, default: float) -> float:
        column = history.get(name)
        return float(column[-1]) if column is not None and len(column) else default

    diagnostics = result.diagnostics
    at_rest = result.velocities is None or result.angular_velocities is None
    return StoredState(
        source=value, positions=np.asarray(result.positions, float),
        directors=np.asarray(result.directors, float),
        velocities=np.zeros((n + 1, 3)) if at_rest else np.asarray(result.velocities, float),
        angular_velocities=(np.zeros((n, 3)) if at_rest
                            else np.asarray(result.angular_velocities, float)),
        clamp_frames=None if result.clamp_frames is None else np.asarray(result.clamp_frames),
        time=float(diagnostics.get("final_time", last("time", 0.0))),
        end_rotation=last("end_rotation", 0.0), start_rotation=last("start_rotation", 0.0),
        end_force=last("applied_force", 0.0), end_displacement=last("end_displacement", 0.0),
        stiffness_factor=last("stiffness_factor", 1.0), radius_factor=last("radius_factor", 1.0),
        rest_length=float(np.sum(result.rest_lengths)),
        rest_radius=float(diagnostics.get("rest_radius", math.nan)), at_rest=at_rest)


def checked_initial_state(cfg):
    """`cfg`, once the store and run its initial_state names (if any) were found and hold
    the same rod: the loaders (CLI, API) refuse them before anything runs or any store is
    made. config.py validates the key's form; this reads the store."""
    check_initial_state(cfg)
    return cfg


def check_initial_state(cfg) -> None:
    """Refuse early (before a store is made or a sweep starts) an initial_state whose file or
    run is missing or whose rod is not the config's; nothing to do without one."""
    value = cfg.get(KEY)
    if value is not None:
        check_geometry(cfg, read_state(value))


def check_geometry(cfg, stored: StoredState) -> None:
    rod = cfg["rod"]
    _same_rod(stored, rod.elements, rod.length, rod.radius, "this config")


def _same_rod(stored: StoredState, elements: int, length: float, radius: float,
              ours: str) -> None:
    for name, mine, theirs in (("rod.elements", elements, stored.elements),
                               ("rod.length", length, stored.rest_length),
                               ("rod.radius", radius, stored.rest_radius)):
        if not math.isclose(mine, theirs, rel_tol=1e-9):
            raise _error(stored.source, f"a stored run of the same rod: it has {name} = "
                         f"{theirs:g}, {ours} {mine:g} (set {name}: {theirs:g}, or start "
                         "from the straight rod)")


def _shifted(table: Table, offset: float) -> Table:
    return table[0], tuple(v + offset for v in table[1])


def _scaled(table: Table, factor: float) -> Table:
    return table[0], tuple(v * factor for v in table[1])


def _from_load(table: Table, load: float) -> Table:
    """A load ramp that starts from `load` instead of its own first value."""
    times, values = table
    if len(times) < 2:
        return table  # a constant load: the new one at once
    return times, (float(load),) + tuple(values[1:])


def _continued(controls: Controls, stored: StoredState, first_load: bool) -> Controls:
    changes = dict(end_rotation=_shifted(controls.end_rotation, stored.end_rotation),
                   start_rotation=_shifted(controls.start_rotation, stored.start_rotation),
                   stiffness=_scaled(controls.stiffness, stored.stiffness_factor),
                   radius=_scaled(controls.radius, stored.radius_factor))
    if first_load:
        changes["end_force"] = _from_load(controls.end_force, stored.end_force)
    return dataclasses.replace(controls, **changes)


def clamp_reference(stored: StoredState, axis) -> tuple[np.ndarray, np.ndarray]:
    """The clamps' frames before rotation: the stored ones, or (a store without them) those
    half an element beyond the stored end elements turned back by the stored rotations."""
    from .rod.kernel import rotated_frame
    from .rod.simulate import clamp_frames

    if stored.clamp_frames is not None:
        return stored.clamp_frames[0].copy(), stored.clamp_frames[1].copy()
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    start, end = clamp_frames(_state(stored))
    # the kernel's own turn of a clamp frame, backwards: what it will turn forwards again
    back_start, back_end = np.empty((3, 3)), np.empty((3, 3))
    rotated_frame(start, axis, -stored.start_rotation, back_start)
    rotated_frame(end, axis, -stored.end_rotation, back_end)
    return back_start, back_end


def _state(stored: StoredState) -> RodState:
    state = state_from(stored.positions, stored.directors, stored.time)
    state.v[:] = stored.velocities.T
    state.w[:] = stored.angular_velocities.T
    return state


def continue_from(problem: Problem, stored: StoredState) -> Problem:
    """`problem` (built by a scene for its usual starting state) started from `stored`
    instead: see the module docstring for what is taken and how the controls combine."""
    rod = problem.rod
    _same_rod(stored, rod.elements, rod.length, rod.radius, "this problem")
    # the load ramp to continue is the first table that sets the load: the problem's, if its
    # first stage runs on the run clock, else the first stage's own
    first_own = bool(problem.stages) and problem.stages[0].controls is not None
    stages = tuple(
        s if s.controls is None else
        dataclasses.replace(s, controls=_continued(s.controls, stored, first_load=i == 0))
        for i, s in enumerate(problem.stages))
    return dataclasses.replace(
        problem, state=_state(stored), stages=stages,
        controls=_continued(problem.controls, stored, first_load=not first_own),
        clamp_reference=clamp_reference(stored, problem.ends.axis),
        end_displacement_offset=problem.end_displacement_offset + stored.end_displacement,
        continued=True)
