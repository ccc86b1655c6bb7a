"""What one run produces: final state, sampled history, status, diagnostics, timings."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

STATUSES = ("ok", "unstable", "not_converged", "error")

# The history: one row per sampled time, one column per quantity, in the order the kernel
# writes them (rod/kernel.py derives its slot indices H_* from this table). (name, unit, meaning)
HISTORY = (
    ("time", "s", "time at the row"),
    ("end_rotation", "rad", "the end rotation control"),
    ("end_force", "N", "axial force the outside exerts on the end node (load or reaction)"),
    ("end_torque", "N m", "axial torque the outside exerts on the end element"),
    ("end_displacement", "m", "end node along the axis from its initial place"),
    ("applied_force", "N", "the end-force control"),
    ("stretch_energy", "J", "stretch and shear energy"),
    ("bend_energy", "J", "bend and twist energy (with the clamp springs)"),
    ("kinetic_energy", "J", "kinetic energy, at the time of the potential energies"),
    ("contacts", "1", "touching element pairs"),
    ("penetration", "1", "largest overlap / radius"),
    ("residual", "1", "largest free nodal force / force scale"),
    ("stiffness_factor", "1", "the modulus ramp's factor on E and G"),
    ("radius_factor", "1", "the growth factor on the radius"),
    ("contact_energy", "J", "penalty springs (rod on rod and rod on the end bodies)"),
    ("start_rotation", "rad", "the start rotation control"),
)
HISTORY_COLUMNS = tuple(name for name, _, _ in HISTORY)
# columns added after the kernel ran (the stage index; topology from the snapshots)
DERIVED_HISTORY = (
    ("stage", "1", "index of the protocol stage"),
    ("link", "turns", "Lk of the open rod"),
    ("twist", "turns", "Tw of the open rod"),
    ("writhe", "turns", "Wr of the open rod"),
    ("link_escapes", "1", "cumulative count of link escapes"),
)
# the unit of every history column as stored ("1": dimensionless, a count or an index)
HISTORY_UNITS = {name: unit for name, unit, _ in HISTORY + DERIVED_HISTORY}


def rotation_put_in(history: dict) -> np.ndarray:
    """(S,) rotation [rad] the two clamps have put in at each history row: end rotation minus
    start rotation (0 for a history recorded before the start rotation was). Φa = this × a0/L0;
    turns = this / 2π."""
    start = history.get("start_rotation", 0.0)
    return np.asarray(history["end_rotation"]) - np.asarray(start)


@dataclass
class RunResult:
    """One run. Arrays are (N, 3) per point, SI units.

    positions (n+1, 3), directors (n, 3, 3) with rows d1 d2 d3, radii (n,) current radii,
    rest_lengths (n,). history maps column name → (S,) array, with "stage" (index of the
    protocol stage) and, when computed, "link", "twist", "writhe" (turns). snapshot_positions
    (K, n+1, 3) and snapshot_d1 (K, n, 3) are the rod at the history rows `snapshot_rows`
    (K,) (None: one snapshot per history row, K = S; see `snapshot_history_rows`).
    velocities (n+1, 3) [m/s] and angular_velocities (n, 3) [rad/s, material frame: components
    on d1 d2 d3] complete the final state, so that a run can go on from it exactly (None: not
    known, e.g. a store written before they were; such a state is taken at rest).
    clamp_frames (2, 3, 3): the start and end clamps' frames (rows d1 d2 d3) before their
    rotation controls, i.e. what the clamps hold at zero rotation (None: not known).
    """

    status: str
    message: str
    positions: np.ndarray
    directors: np.ndarray
    radii: np.ndarray
    rest_lengths: np.ndarray
    history: dict[str, np.ndarray]
    snapshot_positions: np.ndarray
    snapshot_d1: np.ndarray
    diagnostics: dict = field(default_factory=dict)
    stage_ends: list[int] = field(default_factory=list)  # history row closing each stage
    # (positions, directors) at the end of each stage, for splitting a continuation run;
    # not stored
    stage_states: list = field(default_factory=list, repr=False)
    snapshot_rows: np.ndarray | None = None  # history row of each snapshot; None: all rows
    velocities: np.ndarray | None = None
    angular_velocities: np.ndarray | None = None
    clamp_frames: np.ndarray | None = None

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def history_frame(self):
        """The history as a pandas DataFrame, one row per sampled time, one column per
        quantity (a copy; `history` stays the dict of arrays). Units: `.attrs["units"]`."""
        import pandas as pd

        frame = pd.DataFrame({name: np.asarray(column) for name, column in self.history.items()})
        frame.attrs["units"] = {name: history_unit(name) for name in frame.columns}
        return frame

    def __repr__(self) -> str:
        # the default dataclass repr prints every array (85 734 characters for 60 elements)
        rows = len(self.history.get("time", ()))
        parts = [f"status={self.status!r}", f"elements={len(self.rest_lengths)}",
                 f"history={rows} rows × {len(self.history)} columns",
                 f"snapshots={len(self.snapshot_positions)}"]
        if rows:
            parts.append(f"t_end={float(self.history['time'][-1]):.4g} s")
            parts.append(f"turns={float(rotation_put_in(self.history)[-1]) / (2 * np.pi):.4g}")
            for key in ("link", "twist", "writhe"):
                if key in self.history and len(self.history[key]):
                    parts.append(f"{key}={float(self.history[key][-1]):.4g}")
            if "link_escapes" in self.history and self.history["link_escapes"][-1]:
                parts.append(f"link_escapes={int(self.history['link_escapes'][-1])}")
        wall = self.diagnostics.get("wall_time")
        if wall is not None:
            parts.append(f"wall_time={float(wall):.3g} s")
        message = self.message if len(self.message) <= 80 else self.message[:77] + "..."
        parts.append(f"message={message!r}")
        return f"RunResult({', '.join(parts)})"

    @property
    def snapshot_history_rows(self) -> np.ndarray:
        """(K,) the history row each snapshot was taken at."""
        if self.snapshot_rows is not None:
            return np.asarray(self.snapshot_rows, dtype=np.int64)
        return np.arange(len(self.snapshot_positions), dtype=np.int64)

    @property
    def rest_radius(self) -> float:
        return float(self.diagnostics.get("rest_radius", np.nan))

    @property
    def end_rotation_turns(self) -> np.ndarray:
        return self.history["end_rotation"] / (2 * np.pi)

    # the run's final values, so that `result.link` replaces `result.history["link"][-1]`
    def _final(self, name: str) -> float:
        """The last history row's `name`; NaN if the history has no such column (link, twist
        and writhe with output.topology: false) or no rows."""
        column = self.history.get(name)
        return float(column[-1]) if column is not None and len(column) else math.nan

    @property
    def link(self) -> float:
        """Lk at the run's end [turns], of the open rod (= twist + writhe)."""
        return self._final("link")

    @property
    def twist(self) -> float:
        """Tw at the run's end [turns]: the rotation of d1 about the tangent, summed."""
        return self._final("twist")

    @property
    def writhe(self) -> float:
        """Wr at the run's end [turns]."""
        return self._final("writhe")

    @property
    def end_force(self) -> float:
        """Axial force [N] the outside exerts on the end node at the run's end (the load, or
        the reaction of a prescribed displacement)."""
        return self._final("end_force")

    @property
    def end_torque(self) -> float:
        """Axial torque [N m] the outside exerts on the end element at the run's end."""
        return self._final("end_torque")


def history_unit(name: str) -> str:
    """The unit of a history column; a column rodphase does not know is marked "unknown"."""
    return HISTORY_UNITS.get(name, "unknown")
