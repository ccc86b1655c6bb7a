"""Run a Problem through its stages with the compiled kernel and collect a RunResult.

This is the only place that converts between the public (N, 3) arrays and the kernel's
(3, N) layout, picks the time step, and turns kernel status codes into messages.
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings

import numpy as np

from ..result import HISTORY_COLUMNS, RunResult
from . import kernel as k
from . import static
from .model import Controls, Ends, Problem, RodState, Table, stable_time_step


def _table_arrays(tables: list[Table], shift: float):
    width = max(len(t[0]) for t in tables)
    times = np.zeros((len(tables), width))
    values = np.zeros((len(tables), width))
    counts = np.zeros(len(tables), dtype=np.int64)
    for row, (ts, vs) in enumerate(tables):
        m = len(ts)
        times[row, :m] = np.asarray(ts, float) + shift
        values[row, :m] = vs
        times[row, m:] = times[row, m - 1]
        values[row, m:] = values[row, m - 1]
        counts[row] = m
    return times, values, counts


def _table_extreme(table: Table, pick) -> float:
    return float(pick(table[1]))


def _all_controls(problem: Problem) -> list[Controls]:
    return [problem.controls] + [s.controls for s in problem.stages if s.controls is not None]


def time_step(problem: Problem, *, asleep: bool = False) -> tuple[float, float]:
    """(dt, stable bound) for the problem: the user's dt or safety × the bound over all stages;
    with `asleep`, for the part of the run before contact wakes (the bound of a rod without
    contact, see Contact.sleep)."""
    controls = _all_controls(problem)
    stiff = max(_table_extreme(c.stiffness, max) for c in controls)
    grow = min(_table_extreme(c.radius, min) for c in controls)
    contact = dataclasses.replace(problem.contact, enabled=False) if asleep else problem.contact
    bound = stable_time_step(problem.rod, contact, stiff, grow)
    dt = problem.solver.dt if problem.solver.dt is not None else problem.solver.safety * bound
    return dt, bound


def _rod_arrays(problem: Problem):
    rod = problem.rod
    n = rod.elements
    if n < 2:
        raise ValueError(f"rod.elements: {n} (allowed: at least 2)")
    l0 = np.full(n, rod.element_length)
    d0 = 0.5 * (l0[1:] + l0[:-1])
    area = rod.area
    i1 = rod.second_moment
    mass = rod.density * area * l0
    node_mass = np.zeros(n + 1)
    node_mass[:-1] += 0.5 * mass
    node_mass[1:] += 0.5 * mass
    inertia = np.empty((3, n))
    inertia[0] = inertia[1] = rod.density * i1 * l0
    inertia[2] = rod.density * 2 * i1 * l0
    shear = np.empty((3, n))
    shear[0] = shear[1] = rod.shear_stiffness
    shear[2] = rod.axial_stiffness
    bend = np.empty((3, n - 1))
    bend[0] = bend[1] = rod.bending_stiffness
    bend[2] = rod.twist_stiffness
    curvature = np.tile(np.asarray(rod.rest_curvature, float)[:, None], (1, n - 1))
    if problem.rest_curvature is not None:
        extra = np.asarray(problem.rest_curvature, float)
        if extra.shape != (n - 1, 3):
            raise ValueError(f"rest_curvature must be ({n - 1}, 3); got {extra.shape}")
        curvature = curvature + extra.T
    rest_shear = np.zeros((3, n))
    rest_radius = np.full(n, rod.radius)
    c = problem.contact
    contact_k = c.stiffness * rod.youngs_modulus * l0
    contact_c = 2.0 * c.damping_ratio * np.sqrt(contact_k * mass)
    return dict(rest_length=l0, rest_voronoi=d0, node_mass=node_mass, inertia=inertia,
                shear_stiffness=shear, bend_stiffness=bend, rest_curvature=curvature,
                rest_shear=rest_shear, rest_radius=rest_radius, contact_k=contact_k,
                contact_c=contact_c)


def _kernel_inputs(problem: Problem, ends: Ends, dt: float, history_every: int,
                   until_equilibrium: bool, equilibrium_after: float, controls: Controls,
                   start_position, end_position, start_frame, end_frame, asleep: bool):
    """The kernel's Boundary and Settings for one stage, field by field (see rod/kernel.py);
    `asleep`: contact computed but not applied, the run stopping at its first touch
    (settings.sleep)."""
    rod, contact, solver = problem.rod, problem.contact, problem.solver
    axis = np.asarray(ends.axis, float)
    fdir = np.asarray(controls.force_direction, float)
    first, last = controls.segment
    boundary = k.Boundary(
        start_held=np.asarray(ends.start_held, dtype=np.int64),
        start_frame_held=bool(ends.start_frame_held),
        end_held=np.asarray(ends.end_held, dtype=np.int64),
        end_frame_held=bool(ends.end_frame_held),
        start_position=start_position, end_position=end_position,
        start_frame=start_frame, end_frame=end_frame,
        axis=axis / np.linalg.norm(axis),
        force_direction=fdir / np.linalg.norm(fdir),
        start_body=bool(ends.start_body), end_body=bool(ends.end_body),
        body_radius=float(ends.body_radius * rod.radius),
        segment_first=int(first), segment_last=int(last),
        gravity=np.asarray(controls.gravity, dtype=float).copy(),
    )
    # Neighbours along the rod closer than `exclusion` radii always overlap as capsules; they
    # are excluded at the largest radius any stage grows to, or a growing rod (the muscle)
    # would push apart elements a few apart along it as if they touched.
    grown = max(_table_extreme(c.radius, max) for c in _all_controls(problem))
    c_axial = math.sqrt(rod.wave_moduli[0] / rod.density)
    scale = solver.settle_scale if solver.settle_scale is not None else rod.length
    settings = k.Settings(
        dt=float(dt),
        incompressible=bool(rod.incompressible),
        damping=float(solver.damping),
        damping_rotation=float(rotational_damping_auto(rod) if solver.rotational_damping is None
                               else solver.rotational_damping),
        quadratic_drag=float(solver.quadratic_drag),
        strain_rate_damping=float(solver.strain_rate_damping),
        drag_radius=float(rod.radius),
        contact=bool(contact.enabled and not asleep),
        implicit_dashpot=contact.dashpot == "implicit",
        fold=bool(contact.fold),
        thinning_force=bool(contact.thinning_force),
        sleep=bool(asleep),
        exclusion=int(max(1, math.ceil(contact.exclusion * rod.radius * grown / rod.element_length))),
        friction=float(contact.friction),
        slip_speed=float(contact.slip_speed),
        skin=float(contact.skin * rod.radius),
        near_skin=float(contact.near_skin * rod.radius),
        penetration_limit=float(contact.penetration_limit),
        speed_limit=float(solver.speed_limit if solver.speed_limit is not None else c_axial),
        history_every=int(history_every),
        check_every=int(solver.check_interval),
        stop_at_equilibrium=bool(until_equilibrium),
        equilibrium_after=float(equilibrium_after),
        hold_tolerance=float(solver.hold_tolerance),
        force_scale=float(force_scale(problem)),
        length_scale=float(rod.length),
        settle_window=float(solver.settle_window),
        settle_distance=float(solver.hold_tolerance * scale),
        probe=bool(solver.stability_probe),
        probe_size=float(solver.probe_size * rod.radius),
        probe_return=float(solver.probe_return),
        probe_leave=float(solver.probe_leave),
    )
    return boundary, settings


def control_values(controls: Controls, t: float, shift: float = 0.0) -> np.ndarray:
    """(N_TABLES,) the control values at time t (tables start at `shift`), as the kernel reads
    them: piecewise linear, constant beyond both ends of each table."""
    return np.array([np.interp(t, np.asarray(ts, float) + shift, np.asarray(vs, float))
                     for ts, vs in controls.tables()])


def static_model_of(problem: Problem, controls: Controls | None = None, time: float = math.inf,
                    ends: Ends | None = None, shift: float = 0.0,
                    contact: bool = False) -> static.StaticModel:
    """The static view (rod/static.py) of `problem` under `controls` (default the problem's)
    at `time` (default: their final values), with its ends (default the problem's), the same
    rod arrays and boundary the kernel gets; with `contact`, its self-contact too (if the
    problem has it enabled) as the kernel's settings give it."""
    controls = controls if controls is not None else problem.controls
    ends = ends if ends is not None else problem.ends
    n = problem.rod.elements
    start_frame, end_frame = clamp_reference(problem)
    x = problem.state.x
    boundary, settings = _kernel_inputs(problem, ends, 1.0, 1, False, 0.0, controls,
                                        x[:, 0].copy(), x[:, n].copy(), start_frame, end_frame,
                                        False)
    rod = k.RodProperties(local_mask=_local_mask(n, controls.segment), **_rod_arrays(problem))
    return static.static_model(rod, boundary, control_values(controls, time, shift),
                               incompressible=settings.incompressible,
                               neo_hookean=problem.rod.law != "paper",
                               contact=contact and problem.contact.enabled,
                               fold=settings.fold, exclusion=settings.exclusion,
                               skin=settings.skin, thinning_force=settings.thinning_force)


def clamp_frames(state: RodState) -> tuple[np.ndarray, np.ndarray]:
    """Frames at the two rod ends, half an element beyond the end elements' centres.

    Extrapolated with the rotation between the two outermost elements at each end, so a
    uniformly bent or twisted initial rod is clamped without a jump (exact for a helix).
    """
    from scipy.spatial.transform import Rotation

    Q = state.Q
    n = Q.shape[2]
    if n < 2:
        return Q[:, :, 0].copy(), Q[:, :, -1].copy()
    # Q_{j+1} = exp(−[θ]) Q_j with exp([θ]) = Q_j Q_{j+1}ᵀ
    theta0 = Rotation.from_matrix(Q[:, :, 0] @ Q[:, :, 1].T).as_rotvec()
    theta1 = Rotation.from_matrix(Q[:, :, n - 2] @ Q[:, :, n - 1].T).as_rotvec()
    start = Rotation.from_rotvec(0.5 * theta0).as_matrix() @ Q[:, :, 0]
    end = Rotation.from_rotvec(-0.5 * theta1).as_matrix() @ Q[:, :, n - 1]
    return start, end


def clamp_reference(problem: Problem) -> tuple[np.ndarray, np.ndarray]:
    """(start, end) clamp frames at zero rotation control: the problem's own, or those of its
    initial state."""
    if problem.clamp_reference is not None:
        # C order, as clamp_frames gives them: another layout would compile the kernel again
        start, end = problem.clamp_reference
        return (np.ascontiguousarray(start, dtype=float),
                np.ascontiguousarray(end, dtype=float))
    return clamp_frames(problem.state)


SNAPSHOT_LIMIT = 2e9  # bytes of snapshots one run may keep in memory

def current_radii(rest_radius: float, incompressible: bool, rest_lengths: np.ndarray,
                  lengths: np.ndarray, radius_factor: float = 1.0) -> np.ndarray:
    """(n,) element radii of a deformed rod: the rest radius × the growth factor, thinned as
    a0/√e by the stretch e = l/l0 when the rod is incompressible."""
    # a compressible rod's radius does not follow the stretch, but it is still one per element
    thinning = np.sqrt(rest_lengths / lengths) if incompressible else np.ones(len(lengths))
    return rest_radius * radius_factor * thinning


def _stage_entry(stage, label: str, steps: int, end_time: float, code: int,
                 info: np.ndarray) -> dict:
    """One stage's report (diagnostics["stages"]) from the kernel's status code and info."""
    return {"label": label, "sample": stage.sample, "steps": int(steps),
            "end_time": float(end_time),
            "equilibrium": code == k.S_EQUILIBRIUM,
            "settled": bool(code == k.S_EQUILIBRIUM and info[k.D_SETTLED]),
            "residual": float(info[k.D_RESIDUAL]),
            "probes": int(info[k.D_PROBES]),
            "probes_left": int(info[k.D_PROBES_LEFT]),
            "settle_motion": float(info[k.D_SETTLE_MOTION])}


def _unmet_criteria(solver, settings, info) -> str:
    """Which of the hold's equilibrium tests failed at its end, each with value and threshold."""
    tol = solver.hold_tolerance
    failed = []
    residual, kinetic = info[k.D_RESIDUAL], info[k.D_KINETIC]
    if residual >= tol:
        failed.append(f"residual force {residual:.2g} of the force scale (needs < {tol:g})")
    if kinetic >= tol * tol:
        failed.append(f"kinetic energy {kinetic:.2g} of force scale × L0 (needs < {tol * tol:g})")
    window = settings.settle_window
    if window > 0:
        motion = info[k.D_SETTLE_MOTION]
        if not np.isfinite(motion):
            failed.append(f"the shape had no two full {window:g} s windows to compare")
        elif motion >= settings.settle_distance:
            failed.append(f"the window-mean shape moved {1e3 * motion:.3g} mm per {window:g} s "
                          f"(needs < {1e3 * settings.settle_distance:.3g} mm)")
    undecided = int(info[k.D_PROBES] - info[k.D_PROBES_LEFT])
    if undecided > 0 and not failed:
        failed.append("the stability probe of the last equilibrium neither decayed nor grew "
                      f"(size {settings.probe_size:.3g} m; marginally stable)")
    elif undecided > 0:
        failed.append("a stability probe was still undecided")
    return "; ".join(failed) + "." if failed else "no test failed at the last check."


def rotational_damping_auto(rod) -> float:
    """40·√(G/ρ)/L0 [1/s]: see Solver.rotational_damping."""
    return 40.0 * math.sqrt(rod.wave_moduli[1] / rod.density) / rod.length


def force_scale(problem: Problem) -> float:
    """The force that residuals are measured against: the largest end load, at least F_C."""
    if problem.force_scale is not None:
        return problem.force_scale
    controls = [problem.controls] + [s.controls for s in problem.stages if s.controls is not None]
    load = max(max(abs(v) for v in c.end_force[1]) for c in controls)
    return max(load, problem.rod.buckling_force)


def probe_shape(n: int, axis, seed: int) -> np.ndarray:
    """(3, n+1) direction of the stability probe: lateral to `axis`, the first three sine
    modes along the rod with seeded normal coefficients in both lateral directions, zero at
    both end nodes (held or not), largest node displacement 1. Low modes are where a rod under
    tension loses stability first (Euler, Greenhill); a generic combination of them has a
    component on whichever one goes unstable."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    rng = np.random.default_rng(seed)
    coefficients = rng.standard_normal((3, 2))
    s = np.linspace(0.0, 1.0, n + 1)
    shape = np.zeros((n + 1, 3))
    for m, (a, b) in enumerate(coefficients, start=1):
        shape += np.sin(m * np.pi * s)[:, None] * (a * e1 + b * e2)[None, :]
    shape /= np.linalg.norm(shape, axis=1).max()
    return np.ascontiguousarray(shape.T)


def _local_mask(n: int, segment: tuple[int, int]) -> np.ndarray:
    mask = np.zeros(n - 1)
    first, last = segment
    if last > first:
        # Voronoi domain j sits at node j+1: the interior nodes of the segment
        mask[max(first, 0):max(min(last - 1, n - 1), 0)] = 1.0
    return mask


def _refused(problem: Problem, dt: float, bound: float, message: str) -> RunResult:
    state = problem.state
    n = problem.rod.elements
    history = {name: np.zeros(0) for name in HISTORY_COLUMNS}
    history["stage"] = np.zeros(0, dtype=np.int64)
    return RunResult(status="unstable", message=message, positions=state.positions,
                     directors=state.directors, radii=np.full(n, problem.rod.radius),
                     rest_lengths=np.full(n, problem.rod.element_length), history=history,
                     snapshot_positions=np.zeros((0, n + 1, 3)), snapshot_d1=np.zeros((0, n, 3)),
                     diagnostics={"dt": dt, "dt_bound": bound, "steps": 0, "wall_time": 0.0,
                                  "us_per_step": 0.0, "rest_radius": problem.rod.radius,
                                  "rest_length": problem.rod.length, "elements": n,
                                  "youngs_modulus": problem.rod.youngs_modulus, "stages": []})


@dataclasses.dataclass(frozen=True)
class Resume:
    """Where a run goes on from inside its protocol (the runner's refinement of a run that went
    under-resolved): problem.state, at its own time, lies in stage `stage`, which started at
    `stage_start` (run clock) with its held anchors at `start_position` and `end_position`
    (nodes 0 and n, (3,)); `initial_end` is node n at the run's start (the end displacement
    is counted from it), and `contact_awake` says contact had woken already."""

    stage: int
    stage_start: float
    start_position: np.ndarray
    end_position: np.ndarray
    initial_end: np.ndarray
    contact_awake: bool


def simulate(problem: Problem, *, max_steps: int | None = None,
             resume: Resume | None = None) -> RunResult:
    """Advance `problem.state` through `problem.stages` and return a RunResult.

    With `resume`, the run goes on from inside stage resume.stage (see Resume): the stages
    before it are not run, and the result holds the history, stage reports and stage states
    from there on only.

    A stage with `until_equilibrium` ends early once the largest free nodal force (and
    torque per element length) is below solver.hold_tolerance × force scale and the kinetic
    energy below hold_tolerance² × force scale × L0, or (with solver.settle_window > 0) once the
    shape averaged over a window has moved by less than hold_tolerance × L0 since the previous
    window (the stage report says `settled`); if it never gets there the run's status is
    `not_converged`. A guard (non-finite state, runaway velocity, penetration) stops the
    run with status `unstable` and a message saying when, where, and what to change.

    The run is: checks that refuse it before any step (_refusal), then each stage prepared
    (_StagePlan), run by one or more kernel calls (_run_stage), recorded (_Record) and judged
    (_verdict), and the record collected into the result (_collect).
    """
    dt, bound = time_step(problem)
    notes: list[str] = []
    refused = _refusal(problem, dt, bound, notes)
    if refused is not None:
        return refused
    clock = _Clock.of(problem, dt, bound, resume)
    arrays = _rod_arrays(problem)
    state: RodState = problem.state.copy()
    n = problem.rod.elements
    initial_end = state.x[:, n].copy() if resume is None else np.asarray(resume.initial_end, float)
    frames = clamp_reference(problem)
    record = _Record(notes=notes)
    verdict = ("ok", "completed", None)
    wall0 = time.perf_counter()
    budget = max_steps if max_steps is not None else np.iinfo(np.int64).max
    held = None  # the held anchors (nodes 0 and n) of the last stage, on the run clock
    for index, stage in enumerate(problem.stages):
        if resume is not None and index < resume.stage:
            continue
        plan = _StagePlan.of(problem, stage, index, state, resume, held)
        held = plan.start_position, plan.end_position
        n_steps = int(math.ceil(plan.left / clock.step()[0] - 1e-9))
        if n_steps <= 0:
            # a stage of zero length (e.g. no load ramp) has nothing to do; it keeps its place
            # in the report so that stage indices and labels stay aligned
            nothing = np.zeros(k.N_INFO)
            nothing[[k.D_RESIDUAL, k.D_SETTLE_MOTION]] = np.nan
            record.end_stage(state, _stage_entry(stage, plan.label, 0, state.time,
                                                 k.S_COMPLETED, nothing))
            continue
        n_steps = min(n_steps, budget - record.steps)
        if n_steps <= 0:
            break
        outcome = _run_stage(problem, plan, state, clock, record, arrays, n_steps, budget,
                             initial_end, frames)
        record.end_stage(state, _stage_entry(stage, plan.label, outcome.steps, state.time,
                                             outcome.code, outcome.info))
        if outcome.static_tests:
            record.stage_report[-1].update(static_tests=outcome.static_tests,
                                           static_unstable=outcome.static_unstable)
        verdict, stop = _verdict(problem, plan, outcome, clock, state, verdict,
                                 record.steps >= budget, budget)
        if stop:
            break
    return _collect(problem, state, record, arrays, frames, clock, verdict,
                    time.perf_counter() - wall0)


def _refusal(problem: Problem, dt: float, bound: float, notes: list[str]) -> RunResult | None:
    """The refused result of a run that must not start (a step that would blow up unseen,
    snapshots that would not fit), else None; a risky user step is noted and warned of."""
    n = problem.rod.elements
    if problem.solver.dt is not None and dt > bound:
        note = (f"solver.dt = {dt:.3g} s is above the stable bound {bound:.3g} s for "
                f"{n} elements; the run will likely go unstable")
        warnings.warn(note, stacklevel=3)
        notes.append(note)
        if problem.solver.quadratic_drag > 0.0:
            # The speed-dependent drag caps speeds near 1/(drag·dt): an explicit instability
            # then rings without ever tripping the guard, so such a run is never started.
            return _refused(problem, dt, bound, f"{note}; with solver.quadratic_drag > 0 the "
                            "guard cannot see the blow-up, so the run was not started. Use "
                            "solver.dt: auto, a dt below the bound, or quadratic_drag: 0.")
    history_every = max(1, int(round(problem.solver.history_interval / dt)))
    rows = sum(math.ceil(s.duration / dt) for s in problem.stages) / history_every
    snapshot_bytes = rows * (2 * n + 1) * 3 * 8
    if snapshot_bytes > SNAPSHOT_LIMIT:
        # refuse before simulating: the snapshots would not fit, and the run would be lost
        # at its end (MemoryError) after all its steps
        return _refused(problem, dt, bound, (
            f"output.history_interval = {problem.solver.history_interval:g} s asks for "
            f"{rows:.3g} snapshots ({snapshot_bytes / 1e9:.3g} GB) for this protocol; allowed: "
            f"at most {SNAPSHOT_LIMIT / 1e9:g} GB, i.e. history_interval >= "
            f"{problem.solver.history_interval * snapshot_bytes / SNAPSHOT_LIMIT:.3g} s"))
    return None


@dataclasses.dataclass
class _Clock:
    """The run's time step. Sleeping contact (Contact.sleep): until the rod first touches
    itself the run takes the step of a rod without contact (1.6x longer for the paper's rod
    at 80 elements); from the step of that touch on, the step with contact. A user's dt is
    both."""

    dt: float
    bound: float
    sleeps: bool
    asleep: bool
    dt_asleep: float
    bound_asleep: float
    woke_at: float | None = None

    @classmethod
    def of(cls, problem: Problem, dt: float, bound: float, resume: Resume | None) -> _Clock:
        sleeps = problem.contact.enabled and problem.contact.sleep
        asleep = sleeps and not (resume is not None and resume.contact_awake)
        dt_asleep, bound_asleep = time_step(problem, asleep=True) if sleeps else (dt, bound)
        return cls(dt, bound, sleeps, asleep, dt_asleep, bound_asleep)

    def step(self) -> tuple[float, float]:
        """(dt, its stable bound) [s] now."""
        return (self.dt_asleep, self.bound_asleep) if self.asleep else (self.dt, self.bound)

    def wake(self, t: float) -> None:
        self.asleep = False
        self.woke_at = t


@dataclasses.dataclass
class _Record:
    """What the run has gathered so far: the kernel's history rows and snapshots per call,
    the stage ends, states and reports, the contact list's counters and the notes."""

    notes: list[str]
    rows_h: list = dataclasses.field(default_factory=list)
    rows_x: list = dataclasses.field(default_factory=list)
    rows_d: list = dataclasses.field(default_factory=list)
    stage_ids: list = dataclasses.field(default_factory=list)
    stage_ends: list = dataclasses.field(default_factory=list)
    stage_states: list = dataclasses.field(default_factory=list)
    stage_report: list = dataclasses.field(default_factory=list)
    steps: int = 0
    rebuilds: int = 0
    near_rebuilds: int = 0
    max_pairs: int = 0
    max_penetration: float = 0.0

    def add_call(self, steps: int, info: np.ndarray, hist, snap_x, snap_d, rows: int,
                 index: int) -> None:
        """One kernel call's rows (of stage `index`) and counters."""
        self.steps += steps
        self.rebuilds += int(info[k.D_REBUILDS])
        self.near_rebuilds += int(info[k.D_NEAR_REBUILDS])
        self.max_pairs = max(self.max_pairs, int(info[k.D_MAX_PAIRS]))
        self.max_penetration = max(self.max_penetration, float(info[k.D_MAX_PENETRATION]))
        self.rows_h.append(hist[:rows])
        self.rows_x.append(snap_x[:rows])
        self.rows_d.append(snap_d[:rows])
        self.stage_ids.append(np.full(rows, index))

    def end_stage(self, state: RodState, report: dict) -> None:
        self.stage_ends.append(sum(len(r) for r in self.rows_h) - 1)
        self.stage_states.append((state.positions, state.directors))
        self.stage_report.append(report)


@dataclasses.dataclass
class _StagePlan:
    """One stage as the kernel runs it: its controls and their clock, its ends and held
    anchors, and the time left in it."""

    stage: object
    index: int
    label: str
    controls: Controls
    shift: float  # s, the stage clock's zero on the run clock (0 for the run's controls)
    settled: float  # s, run clock: when every control has reached its last value
    ends: Ends
    start_position: np.ndarray
    end_position: np.ndarray
    tables: tuple
    stage_end: float  # s, run clock
    left: float  # s

    @classmethod
    def of(cls, problem: Problem, stage, index: int, state: RodState, resume: Resume | None,
           held) -> _StagePlan:
        resuming = resume is not None and index == resume.stage
        # A stage's own controls run on the stage clock; the problem's on the run clock.
        own = stage.controls is not None
        controls = stage.controls if own else problem.controls
        t0 = resume.stage_start if resuming else state.time
        shift = t0 if own else 0.0
        tables = controls.tables()
        settled = shift + max(max(tb[0]) for tb in tables)
        ends = stage.ends if stage.ends is not None else problem.ends
        # Held components stay where the stage finds them, plus the displacement control,
        # when the stage has its own clock; on the run clock they are held from the start.
        n = problem.rod.elements
        if resuming:
            start_position = np.array(resume.start_position, dtype=float)
            end_position = np.array(resume.end_position, dtype=float)
        elif own or index == 0:
            start_position = state.x[:, 0].copy()
            end_position = state.x[:, n].copy()
        else:
            start_position, end_position = held
        left = t0 + stage.duration - state.time if resuming else stage.duration
        return cls(stage, index, stage.label or f"stage {index}", controls, shift, settled,
                   ends, start_position, end_position, _table_arrays(tables, shift),
                   t0 + stage.duration, left)


@dataclasses.dataclass
class _Outcome:
    """How a stage's kernel calls ended: the last call's status code and info, its settings
    and step, the stage's steps and the static stability tests made."""

    code: int
    info: np.ndarray
    settings: object
    step_dt: float
    step_bound: float
    steps: int
    static_tests: int
    static_unstable: int


def _run_stage(problem: Problem, plan: _StagePlan, state: RodState, clock: _Clock,
               record: _Record, arrays: dict, n_steps: int, budget: int,
               initial_end: np.ndarray, frames) -> _Outcome:
    """Run one stage from `state` (advanced in place): one kernel call, or more when sleeping
    contact wakes within it (the next call goes on from the same time with contact on and
    its own step) or when the model's stiffness finds a probed equilibrium unstable (pushed
    along its growing mode, the hold goes on)."""
    n = problem.rod.elements
    stage, index = plan.stage, plan.index
    start_frame, end_frame = frames
    stage_steps = 0
    first_call = True
    rod_properties = k.RodProperties(local_mask=_local_mask(n, plan.controls.segment), **arrays)
    probe = probe_shape(n, plan.ends.axis, problem.solver.probe_seed + index)
    static_tests, static_unstable = 0, 0
    info = np.zeros(k.N_INFO)
    while True:
        step_dt, step_bound = clock.step()
        history_every = max(1, int(round(problem.solver.history_interval / step_dt)))
        boundary, settings = _kernel_inputs(problem, plan.ends, step_dt, history_every,
                                            stage.until_equilibrium, plan.settled,
                                            plan.controls, plan.start_position,
                                            plan.end_position, start_frame, end_frame,
                                            clock.asleep)
        if not first_call:
            n_steps = int(math.ceil((plan.stage_end - state.time) / step_dt - 1e-9))
            n_steps = min(n_steps, budget - record.steps)
            if n_steps <= 0:  # woke at the stage's very end
                code = k.S_COMPLETED
                break
        capacity = n_steps // history_every + 2
        hist = np.zeros((capacity, k.N_HISTORY))
        snap_x = np.zeros((capacity, 3, n + 1))
        snap_d = np.zeros((capacity, 3, n))
        info = np.zeros(k.N_INFO)
        arguments = (state.x, state.v, state.Q, state.w, float(state.time), int(n_steps),
                     rod_properties, boundary, settings, k.ControlTables(*plan.tables), probe,
                     k.Output(hist, snap_x, snap_d, info))
        # the law is a specialization of advance (see its docstring): the paper's is called
        # exactly as before the option existed
        if problem.rod.law == "paper":
            code, steps, t_end, rows = k.advance(*arguments)
        else:
            code, steps, t_end, rows = k.advance(*arguments, True)
        state.time = t_end
        stage_steps += steps
        hist[:rows, k.H_END_DISPLACEMENT] += ((plan.end_position - initial_end) @ boundary.axis
                                              + problem.end_displacement_offset)
        record.add_call(steps, info, hist, snap_x, snap_d, rows, index)
        if (code == k.S_EQUILIBRIUM and settings.probe and problem.solver.static_stability
                and rows and hist[rows - 1, k.H_CONTACTS] == 0):
            # the kernel's probe passed; the model's own stiffness has the last word
            static_tests += 1
            verdict = static.stability(
                static_model_of(problem, plan.controls, state.time, plan.ends, plan.shift),
                state.x, state.Q)
            if not verdict.stable and state.time < plan.stage_end:
                static_unstable += 1
                record.notes.append(
                    f"{plan.label}: the equilibrium at t = {state.time:.4g} s was unstable by "
                    f"the model's stiffness ({verdict.unstable_modes} growing modes, lowest "
                    f"ω² = {verdict.lowest:.3g} s⁻²); pushed by {settings.probe_size:.3g} m "
                    "along the most unstable one")
                state.x[:], state.Q[:] = static.displaced(
                    state.x, state.Q, verdict.mode, verdict.mode_rotation, settings.probe_size)
                state.v[:] = 0.0
                state.w[:] = 0.0
                first_call = False
                continue
        if code != k.S_WAKE:
            break
        clock.wake(t_end)
        first_call = False
    return _Outcome(code, info, settings, step_dt, step_bound, stage_steps, static_tests,
                    static_unstable)


def _verdict(problem: Problem, plan: _StagePlan, outcome: _Outcome, clock: _Clock,
             state: RodState, verdict: tuple, out_of_steps: bool, budget: int):
    """The run's (status, message, guard) after a stage, and whether the run stops there: a
    guard stops it as unstable, a hold that did not settle leaves it not converged, and so
    does the step budget."""
    status, message, guard = verdict
    code, info = outcome.code, outcome.info
    n = problem.rod.elements
    if code in k.GUARDS:
        guard, guard_words, unit, advice = k.GUARDS[code]
        where = int(info[k.D_WHERE])
        if problem.solver.dt is not None and clock.dt > clock.bound:
            # an explicit step above its bound blows up in whatever guard it meets first
            # (often the 135° one): name the step, and do not let a sweep refine the rod
            guard = "time_step"
            advice = (f"solver.dt = {clock.dt:.3g} s is {clock.dt / clock.bound:.3g} times the "
                      f"stable bound {clock.bound:.3g} s for {n} elements: use solver.dt: auto "
                      "or a dt below the bound.")
        value = f"value {info[k.D_VALUE]:.3g}"
        if code == k.S_SHEAR and 0 <= where < n:
            # a sheared element is usually a stretched one too; how far says whether the
            # law's range is at stake (docs/history/fig3-corner.md, "Where the corner's failures
            # get their energy": 1.8-2.1 at Fig 3's five trips)
            stretch = (np.linalg.norm(np.diff(state.x, axis=1), axis=0)
                       / problem.rod.element_length)
            most = int(np.argmax(stretch))
            value += (f"; the element stretched to l/l0 = {stretch[where]:.3g}, the rod's "
                      f"largest {stretch[most]:.3g} at element {most}")
        message = (f"unstable in {plan.label} at t = {state.time:.4g} s: {guard_words} at "
                   f"{unit} {where} ({value}); dt = {outcome.step_dt:.3g} "
                   f"s, stable bound {outcome.step_bound:.3g} s. {advice}")
        return ("unstable", message, guard), True
    if plan.stage.until_equilibrium and code != k.S_EQUILIBRIUM and status == "ok":
        status = "not_converged"
        message = f"{plan.label} did not reach equilibrium in {plan.stage.duration:g} s: " + \
            _unmet_criteria(problem.solver, outcome.settings, info) + \
            " Hold longer (solver.hold_max_time) or damp more (solver.damping)."
    if out_of_steps:
        if status == "ok":
            status = "not_converged"
            message = f"stopped after max_steps = {budget} steps in {plan.label}"
        return (status, message, guard), True
    return (status, message, guard), False


def _collect(problem: Problem, state: RodState, record: _Record, arrays: dict, frames,
             clock: _Clock, verdict: tuple, wall: float) -> RunResult:
    """The RunResult of a finished (or stopped) run: its record in the public (N, 3) layout,
    the final state and the diagnostics."""
    rod = problem.rod
    n = rod.elements
    status, message, guard = verdict
    hist = np.concatenate(record.rows_h) if record.rows_h else np.zeros((0, k.N_HISTORY))
    history = {name: hist[:, col].copy() for col, name in enumerate(HISTORY_COLUMNS)}
    history["stage"] = (np.concatenate(record.stage_ids) if record.stage_ids
                        else np.zeros(0, dtype=np.int64))
    snapshot_positions = (np.transpose(np.concatenate(record.rows_x), (0, 2, 1))
                          if record.rows_x else np.zeros((0, n + 1, 3)))
    snapshot_d1 = (np.transpose(np.concatenate(record.rows_d), (0, 2, 1)) if record.rows_d
                   else np.zeros((0, n, 3)))
    lengths = np.linalg.norm(np.diff(state.x, axis=1), axis=0)
    rest = arrays["rest_length"]
    radius_factor = float(hist[-1, k.H_RADIUS_FACTOR]) if len(hist) else 1.0
    radii = current_radii(rod.radius, rod.incompressible, rest, lengths, radius_factor)
    diagnostics = {
        "dt": clock.dt, "dt_bound": clock.bound, "steps": record.steps, "wall_time": wall,
        # sleeping contact: the step before it woke, and when it woke (None: it never did)
        "dt_asleep": clock.dt_asleep if clock.sleeps else None,
        "contact_woke_at": clock.woke_at,
        "us_per_step": 1e6 * wall / max(record.steps, 1), "rebuilds": record.rebuilds,
        "near_rebuilds": record.near_rebuilds, "max_pairs": record.max_pairs,
        "max_penetration": record.max_penetration, "final_time": state.time,
        "rest_radius": rod.radius, "rest_length": rod.length, "elements": n,
        "youngs_modulus": rod.youngs_modulus,
        "force_scale": force_scale(problem), "stages": record.stage_report,
        "notes": record.notes, "guard": guard,
    }
    if rod.law != "paper":
        diagnostics["law"] = rod.law  # what tabulate's extension of the applied load needs
    start_frame, end_frame = frames
    return RunResult(status=status, message=message, positions=state.positions,
                     directors=state.directors, radii=radii, rest_lengths=rest.copy(),
                     history=history, snapshot_positions=snapshot_positions,
                     snapshot_d1=snapshot_d1, diagnostics=diagnostics,
                     stage_ends=record.stage_ends, stage_states=record.stage_states,
                     velocities=np.ascontiguousarray(state.v.T),
                     angular_velocities=np.ascontiguousarray(state.w.T),
                     clamp_frames=np.stack([start_frame, end_frame]))
