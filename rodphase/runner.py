"""One run in one place: build a scene, simulate it, refine it if it was under-resolved,
and account for its link. The CLI, the Python API, the sweep workers and the figure scripts
all run a scene through `run_scene` (a Problem built in Python through `run`), so they give
the same result for the same config; the engine (rodphase.rod) knows nothing of topology.
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings

import numpy as np

from . import config
from .result import RunResult, rotation_put_in
from .rod.model import Problem
from .rod.simulate import clamp_reference, current_radii

# A change of link between two history rows that the clamps did not put in, larger than this
# (turns), is an escape: link moves in whole crossings (a strand passing around an end changes
# Lk by ±2, through the closure), while Lk = Tw + Wr and the clamp bookkeeping hold to 1e-6.
ESCAPE_THRESHOLD = 0.5
# Lk − turns put in − escapes, turns, beyond which a run is not `ok`: the open-ribbon closure
# with slightly bent end tangents leaves up to 6e-3 (measured, a plectoneme at 5× the rate).
LINK_TOLERANCE = 0.05


def _link_jumps(history: dict) -> np.ndarray:
    """Per history row, the change of link beyond what the clamps put in, where it is larger
    than ESCAPE_THRESHOLD (else 0): link_escapes before consecutive rows are merged."""
    turns_in = rotation_put_in(history) / (2 * np.pi)
    surplus = np.diff(history["link"] - turns_in, prepend=history["link"][:1] - turns_in[:1])
    return np.where(np.abs(surplus) > ESCAPE_THRESHOLD, surplus, 0.0)


def link_escapes(history: dict) -> np.ndarray:
    """Per history row, the link (turns) that left or entered the rod since the row before,
    beyond what the two clamps put in; 0 where nothing escaped. Needs both frames held.

    Jumps in consecutive rows are one escape, booked at the last of them: a strand that passes
    around an end between two rows' snapshots crosses the closure in two halves (Fig S3 with
    sleeping contact: −1.001 and −0.998 turns, 0.05 s apart, where a −2.0 came in one row
    before)."""
    return _merged(_link_jumps(history))


def _merged(jumps: np.ndarray) -> np.ndarray:
    """The jumps with each run of consecutive nonzero rows summed into its last row."""
    jumps = jumps.copy()
    for row in range(1, len(jumps)):
        if jumps[row] != 0.0 and jumps[row - 1] != 0.0:
            jumps[row] += jumps[row - 1]
            jumps[row - 1] = 0.0
    return jumps


def _signed_angle(a: np.ndarray, b: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Angle (rad) from a to b about `axis`, row by row, after projecting both on its normal plane."""
    a = a - np.sum(a * axis, axis=1)[:, None] * axis
    b = b - np.sum(b * axis, axis=1)[:, None] * axis
    return np.arctan2(np.sum(axis * np.cross(a, b), axis=1), np.sum(a * b, axis=1))


def clamp_twist(problem: Problem, start_frame, end_frame, history, positions, d1) -> np.ndarray:
    """Turns of twist between each held clamp and the frame of the element next to it."""
    from scipy.spatial.transform import Rotation

    extra = np.zeros(len(positions))
    axis = np.asarray(problem.ends.axis, float)
    axis = axis / np.linalg.norm(axis)
    if problem.ends.start_frame_held:
        t0 = positions[:, 1] - positions[:, 0]
        t0 /= np.linalg.norm(t0, axis=1)[:, None]
        clamp = Rotation.from_rotvec(history["start_rotation"][:, None] * axis).apply(start_frame[0])
        extra += _signed_angle(clamp, d1[:, 0], t0)
    if problem.ends.end_frame_held:
        t1 = positions[:, -1] - positions[:, -2]
        t1 /= np.linalg.norm(t1, axis=1)[:, None]
        clamp = Rotation.from_rotvec(history["end_rotation"][:, None] * axis).apply(end_frame[0])
        extra += _signed_angle(d1[:, -1], clamp, t1)
    return extra / (2 * np.pi)


def with_topology(result: RunResult, problem: Problem) -> RunResult:
    """Add Lk, Tw and Wr (turns) of every snapshot to the history, the clamps' share of the
    twist included; with both frames held, count link escapes (history `link_escapes`, the
    run's notes) and stop calling a run ok whose link the turns put in and the escapes do
    not account for (guard `link`)."""
    if not len(result.snapshot_positions):
        return result
    topology_columns(result, problem)
    return account_link(result, problem)


def topology_columns(result: RunResult, problem: Problem) -> None:
    """Lk, Tw and Wr (turns) of every snapshot into the history (one snapshot per row)."""
    from .topology import topology_history

    history = result.history
    positions, d1 = result.snapshot_positions, result.snapshot_d1
    lk, tw, wr = topology_history(positions, d1)
    # The clamps sit half an element beyond the end frames; the twist over those halves
    # belongs to the rod, so that a rod clamped at both ends carries Lk = turns put in.
    start_frame, end_frame = clamp_reference(problem)
    extra = clamp_twist(problem, start_frame, end_frame, history, positions, d1)
    history["link"], history["twist"], history["writhe"] = lk + extra, tw + extra, wr


def account_link(result: RunResult, problem: Problem) -> RunResult:
    """The link bookkeeping of with_topology, on a history that has its link column."""
    history, notes = result.history, result.diagnostics.setdefault("notes", [])
    status, message = result.status, result.message
    if problem.ends.start_frame_held and problem.ends.end_frame_held:
        jumps = _link_jumps(history)
        escapes = _merged(jumps)
        history["link_escapes"] = np.cumsum(np.abs(escapes) > 0).astype(float)
        events = [{"time": float(history["time"][i]), "delta_link": float(escapes[i])}
                  for i in np.flatnonzero(escapes)]
        if events:
            notes.append(f"link left the rod {len(events)} time(s) (ΔLk "
                         + ", ".join(f"{e['delta_link']:+.2f} at t = {e['time']:.3g} s"
                                     for e in events) + ")")
        # A run continued from a stored state starts with the link it was left with, which
        # need not be the turns its own clamps counted: there the check is relative to the
        # first row; any other run (one started twisted too) must account for all its link.
        surplus = history["link"] - rotation_put_in(history) / (2 * np.pi)
        baseline = surplus[0] if problem.continued else 0.0
        # row by row, so that an escape booked at its last row is accounted at its first
        unaccounted = float(np.max(np.abs(surplus - baseline - np.cumsum(jumps))))
        if unaccounted > LINK_TOLERANCE and status in ("ok", "not_converged"):
            status = "unstable"
            result.diagnostics["guard"] = "link"
            message = (f"the stored link differs from the turns put in by {unaccounted:.3g} "
                       f"turns with no escape to explain it (tolerance {LINK_TOLERANCE} "
                       "turns): the twist was not carried by the rod as put in. Lower "
                       "loading.twist_rate or use more rod.elements.")
    result.status, result.message = status, message
    return result


def keep_snapshots(result: RunResult, policy) -> RunResult:
    """The result with only the snapshots `policy` keeps: "all", "final" (the last one), or
    an integer k (every k-th history row and the last). Lk, Tw and Wr are computed from every
    snapshot before this, so the history keeps them all; only the stored shapes thin out."""
    count = len(result.snapshot_positions)
    if policy == "all" or count == 0:
        return result
    rows = result.snapshot_history_rows
    if policy == "final":
        keep = np.array([count - 1])
    else:
        keep = np.unique(np.append(np.arange(0, count, int(policy)), count - 1))
    result.snapshot_positions = result.snapshot_positions[keep]
    result.snapshot_d1 = result.snapshot_d1[keep]
    result.snapshot_rows = rows[keep]
    return result


def snapshot_policy(cfg, default: str):
    """output.snapshots of a config, its "auto" resolved to `default` ("all" for a single
    run, "final" for a sweep)."""
    policy = cfg.output.snapshots
    return default if policy == "auto" else policy


def run(problem: Problem, *, max_steps: int | None = None, topology: bool = False) -> RunResult:
    """Simulate a Problem (see rodphase.rod.simulate) and, with `topology`, account for its
    link (see with_topology)."""
    from .rod import simulate

    result = simulate(problem, max_steps=max_steps)
    return with_topology(result, problem) if topology else result


# the guards whose runs more elements can mend (solver.refine_up_to)
REFINABLE_GUARDS = ("resolution", "shear")
# With solver.refine_from "trip", a run stopped by one of them goes on at twice the elements
# from its snapshot this long before the trip, not from the start: the runaway that trips the
# 45° shear guard builds over about half a second (Fig 3's top edge: 19° 0.4 s after the snap
# began, 45° later), and a second before it the rod is still resolved.
REFINE_BACK = 1.0  # s
# the guards a slower twist can mend (solver.slow_down_to), when they stop a run while an end
# turns and more elements did not help: the clamp outrunning the rod's end frame, twist
# piling up at the turning end faster than it spreads (the resolution guard at a fast ramp),
# and the shear of the rod between a plectoneme growing next to the loaded end and that end.
# At Fig 3's triple point (Phi*a 1.92, L/L0 1.13, n = 160) the largest stretch there grew
# from 1.28 to 1.64 in 5 s of a 0.5 turns/s ramp, and stayed at 1.27 at 0.25 turns/s, where
# the run ends a plectoneme; neither 320 elements nor a step 0.4 times as long mends all such
# runs (docs/history/fig3-corner.md, "The triple point's failures").
SLOWABLE_GUARDS = ("clamp_lag", "resolution", "shear")


def _anchors(origin: Problem, first: RunResult, stage: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes 0 and n where stage `stage` holds them from: at the start of the last stage up to
    it that has its own clock (or of the run), as simulate takes them."""
    own = [j for j in range(stage + 1) if j == 0 or origin.stages[j].controls is not None][-1]
    positions = origin.state.positions if own == 0 else first.stage_states[own - 1][0]
    return positions[0].copy(), positions[-1].copy()


def refined_from_trip(first: RunResult, origin: Problem, problem: Problem, topology: bool,
                      max_steps: int | None = None) -> RunResult | None:
    """The run `first` (stopped by a refinable guard) gone on with `problem`, the same scene
    with twice first's elements, from first's last snapshot at least REFINE_BACK before the
    trip, resampled (rodphase.resample.doubled). `origin` is the scene's problem as first
    started it (its initial state and stages). The history is first's up to that row, then
    the new run's; the shapes and the final state are the new run's (stage_states keep
    first's before the resumed stage, at first's elements). None if there is no such
    snapshot (the trip came too early to save anything)."""
    from .resample import doubled
    from .rod.model import state_from
    from .rod.simulate import Resume, simulate

    times = first.history["time"]
    rows = first.snapshot_history_rows
    tripped = float(first.diagnostics["final_time"])
    before = np.flatnonzero(times[rows] <= tripped - REFINE_BACK)
    if not len(before):
        return None
    snapshot = int(before[-1])
    row = int(rows[snapshot])
    at = float(times[row])
    stage = int(first.history["stage"][row])
    stage_start = (origin.state.time if stage == 0
                   else float(first.diagnostics["stages"][stage - 1]["end_time"]))
    start_position, end_position = _anchors(origin, first, stage)
    positions, directors = doubled(first.snapshot_positions[snapshot],
                                   first.snapshot_d1[snapshot])
    woke = first.diagnostics.get("contact_woke_at")
    resume = Resume(stage=stage, stage_start=stage_start, start_position=start_position,
                    end_position=end_position, initial_end=origin.state.positions[-1],
                    contact_awake=woke is not None and woke <= at)
    # the clamps hold what they held at zero rotation in the run from the start
    problem.clamp_reference = clamp_reference(problem)
    problem.state = state_from(positions, directors, time=at)
    second = simulate(problem, max_steps=max_steps, resume=resume)
    if topology and len(second.snapshot_positions):
        topology_columns(second, problem)
    history = {name: np.concatenate([first.history[name][:row + 1], second.history[name]])
               for name in second.history if name in first.history}
    diagnostics = dict(second.diagnostics)
    diagnostics["stages"] = first.diagnostics["stages"][:stage] + second.diagnostics["stages"]
    # the steps and wall time are this attempt's own (second's); run_scene adds up every
    # attempt's, first's whole run included
    diagnostics["refined_at"] = at
    if resume.contact_awake:  # the fine run started awake: contact woke in the coarse one
        diagnostics["contact_woke_at"] = woke
    diagnostics["notes"] = list(second.diagnostics.get("notes", [])) + [
        f"went on at {problem.rod.elements} elements from the state at t = {at:.4g} s "
        f"({REFINE_BACK:g} s or more before the trip at {tripped:.4g} s), resampled; the "
        "shapes before it are not kept"]
    merged = dataclasses.replace(
        second, history=history, diagnostics=diagnostics,
        snapshot_rows=second.snapshot_history_rows + row + 1,
        stage_ends=first.stage_ends[:stage] + [e + row + 1 for e in second.stage_ends],
        stage_states=first.stage_states[:stage] + second.stage_states)
    if topology and "link" in history:
        merged = account_link(merged, problem)
    return merged


def run_scene(scene, *, topology: bool | None = None,
              twist_targets: list[float] | None = None) -> RunResult:
    """Build and simulate one scene: a validated config (used as it is) or a plain mapping
    (validated first). Never raises for a failed run: a run that goes unstable comes back
    with that status. A run stopped by the 135° resolution guard or the 45° shear guard is run
    again with twice the elements, up to solver.refine_up_to (from a second before the trip
    with solver.refine_from "trip", see refined_from_trip); one still stopped while an end
    turns is run again at half the twist rate, down to solver.slow_down_to (see
    SLOWABLE_GUARDS); `twist_targets` (turns) makes it a continuation."""
    from .scenes import SCENES, build

    cfg = scene if isinstance(scene, config.Frozen) else config.validate_scene(scene, SCENES)
    extra = {} if twist_targets is None else {"twist_targets": twist_targets}
    want_topology = cfg.output.topology if topology is None else topology

    stored = None
    if cfg.get("initial_state") is not None:
        from .restart import read_state

        stored = read_state(cfg.initial_state)

    def once(cfg):
        problem = build(cfg, **extra)
        if stored is not None:
            from .restart import continue_from

            problem = continue_from(problem, stored)
        return problem, run(problem, max_steps=cfg.solver.max_steps, topology=want_topology)

    # every simulation this run makes, in order: what it cost and how it ended, so that the
    # run's steps, wall time and message account for all of them (issue #46)
    attempts: list[dict] = []

    def attempted(result: RunResult, cfg, start: str) -> RunResult:
        d = result.diagnostics
        attempts.append({"elements": int(d.get("elements", cfg.rod.elements)),
                         "twist_rate": float(cfg.loading.twist_rate), "start": start,
                         "status": result.status, "guard": d.get("guard"),
                         "steps": int(d.get("steps", 0)),
                         "wall_time": float(d.get("wall_time", 0.0))})
        return result

    def refined(cfg) -> tuple[Problem, RunResult, list[int]]:
        """The run of `cfg`, refined as solver.refine_up_to allows: (its problem as it
        started, its result, the element counts tried)."""
        tried = [cfg.rod.elements]
        limit = config.refine_limit(cfg)  # of the scene's rod, not of a refined one
        refine_from = cfg.solver.refine_from
        origin, result = once(cfg)
        attempted(result, cfg, "start")
        # A rod turned by > 135° between neighbouring frames needs more elements, not a
        # smaller step, and so does one sheared by > 45° (a snap into a loop as tight as the
        # rod, at Fig 3's top edge: at n = 80 15 of 200 points, at n = 140 1 of 40): with
        # solver.refine_up_to, run it again with twice as many (up to that number): with
        # solver.refine_from "trip" from a second before the trip (refined_from_trip), else,
        # or if the trip came sooner, from the start. A run started from a stored state has
        # the stored rod's elements and cannot refine; a continuation refines from the start.
        while (result.diagnostics.get("guard") in REFINABLE_GUARDS and stored is None
               and min(2 * tried[-1], limit) > tried[-1]):
            elements = min(2 * tried[-1], limit)
            cfg = config.validate_scene(
                config.apply_overrides(cfg.plain(), [("rod.elements", elements)]), SCENES)
            resumed = None
            if refine_from == "trip" and elements == 2 * tried[-1] and not extra:
                resumed = refined_from_trip(result, origin, build(cfg), want_topology,
                                            cfg.solver.max_steps)
            if resumed is not None:
                result = attempted(resumed, cfg, f"t = {resumed.diagnostics['refined_at']:.4g} s")
            else:
                result = attempted(once(cfg)[1], cfg, "start")
            tried.append(elements)
        if len(tried) > 1:
            result.diagnostics["refined_from"] = tried[:-1]
            result.diagnostics["notes"].append(
                f"under-resolved at {', '.join(map(str, tried[:-1]))} elements; this is the "
                f"run with {tried[-1]} (solver.refine_up_to = {cfg.solver.refine_up_to}, "
                f"solver.refinements = {cfg.solver.refinements})")
        return origin, result, tried

    origin, result, tried = refined(cfg)
    rates = [cfg.loading.twist_rate]
    floor = cfg.solver.slow_down_to
    while (floor > 0 and stored is None and not extra
           and result.diagnostics.get("guard") in SLOWABLE_GUARDS
           and result.diagnostics.get("stages")
           and _turning(origin, len(result.diagnostics["stages"]) - 1)
           and rates[-1] / 2 >= floor * (1 - 1e-9)):
        stopped = (f"the {result.diagnostics['guard']} guard stopped it at "
                   f"{result.diagnostics['elements']} elements while an end turned at "
                   f"{rates[-1]:g} turns/s")
        rates.append(rates[-1] / 2)
        slower = config.apply_overrides(cfg.plain(), [("loading.twist_rate", rates[-1])])
        origin, result, more = refined(config.validate_scene(slower, SCENES))
        tried += more
        result.diagnostics["notes"].append(
            f"{stopped}; this is the run at {rates[-1]:g} turns/s, from the start "
            f"(solver.slow_down_to = {floor:g})")
    if len(rates) > 1:
        result.diagnostics["twist_rates_tried"] = rates
    return _accounted(result, attempts, cfg)


def _accounted(result: RunResult, attempts: list[dict], cfg) -> RunResult:
    """`result` with its steps and wall time summed over every attempt (the kept run's own
    are in its last attempt), the attempts listed, and a failed run's advice trimmed of what
    was already tried: more elements up to solver.refine_up_to, a slower twist down to
    solver.slow_down_to."""
    d = result.diagnostics
    if len(attempts) > 1:
        d["attempts"] = attempts
        d["steps"] = sum(a["steps"] for a in attempts)
        d["wall_time"] = sum(a["wall_time"] for a in attempts)
        d["us_per_step"] = 1e6 * d["wall_time"] / max(d["steps"], 1)
    if result.status != "unstable" or len(attempts) < 2:
        return result
    most = max(a["elements"] for a in attempts)
    slowest = min(a["twist_rate"] for a in attempts)
    tried = (f"Already tried: {len(attempts)} attempts, up to {most} elements "
             f"(solver.refine_up_to, solver.refinements)")
    if slowest < attempts[0]["twist_rate"]:
        tried += (f" and down to {slowest:g} turns/s (solver.slow_down_to = "
                  f"{cfg.solver.slow_down_to:g})")
    message = result.message
    if slowest < attempts[0]["twist_rate"]:
        message = message.replace("lower loading.twist_rate (turns/s)",
                                  f"a twist rate below {slowest:g} turns/s (solver.slow_down_to)")
    message = message.replace("use more rod.elements", f"more than {most} elements "
                              "(solver.refinements)")
    message = message.replace("Use more rod.elements", f"More than {most} elements "
                              "(solver.refinements)")
    return dataclasses.replace(result, message=f"{message} {tried}.")


def finished_holds(result: RunResult) -> list[int]:
    """The stage index of each sample's hold that a continuation run finished (converged or
    not), in sample order: a hold a guard stopped the run in was not finished, and its
    sample not reached."""
    stages = result.diagnostics.get("stages", [])
    holds = [i for i, st in enumerate(stages) if st.get("sample") is not None]
    if result.status == "unstable" and holds and holds[-1] == len(stages) - 1:
        holds.pop()
    return holds


def split_continuation(result: RunResult, k: int, incompressible: bool = True) -> RunResult:
    """The k-th sample of a continuation run: the state where its hold ended, the history up
    to there, and the status of that hold (or of the run, if it stopped before)."""
    from dataclasses import replace

    stages = result.diagnostics.get("stages", [])
    holds = finished_holds(result)
    index = holds[k] if k < len(holds) else None
    if index is None:
        return replace(result, status=result.status if result.status != "ok" else "error",
                       message=f"the continuation stopped before sample {k}: {result.message}",
                       history={key: v[:0] for key, v in result.history.items()},
                       snapshot_positions=result.snapshot_positions[:0],
                       snapshot_d1=result.snapshot_d1[:0], stage_states=[])
    row = result.stage_ends[index] + 1
    positions, directors = result.stage_states[index]
    hold = stages[index]
    lengths = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    radius_factor = float(result.history["radius_factor"][row - 1]) if row > 0 else 1.0
    status = "ok" if hold["equilibrium"] else "not_converged"
    message = ("completed" if status == "ok" else
               f"hold {k} did not reach equilibrium (residual {hold['residual']:.2g})")
    diagnostics = dict(result.diagnostics, continuation_sample=k,
                       final_time=hold["end_time"])
    return replace(result, status=status, message=message, positions=positions,
                   directors=directors,
                   radii=current_radii(result.diagnostics["rest_radius"], incompressible,
                                       result.rest_lengths, lengths, radius_factor),
                   history={key: v[:row] for key, v in result.history.items()},
                   snapshot_positions=result.snapshot_positions[:row],
                   snapshot_d1=result.snapshot_d1[:row], diagnostics=diagnostics,
                   stage_ends=result.stage_ends[:index + 1], stage_states=[],
                   # the velocities at the hold's end are not kept (a hold ends near rest):
                   # the run's final ones would belong to a later sample
                   velocities=None, angular_velocities=None)


def _turning(problem: Problem, stage: int) -> bool:
    """Whether stage `stage` of `problem` turns an end: its rotation tables move."""
    controls = problem.stages[stage].controls or problem.controls
    return any(len(set(table[1])) > 1
               for table in (controls.end_rotation, controls.start_rotation))


def cpu_seconds() -> float:
    """CPU seconds of this process and of the child processes it has waited for (the
    compile helper of compile_kernel), user and system."""
    total = time.process_time()
    try:
        import resource
    except ImportError:  # not on Windows
        return total
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return total + children.ru_utime + children.ru_stime


def compile_kernel() -> float:
    """Run a tiny problem through every compiled function a run uses, in this process, and
    return the seconds it took. numba writes the machine code to its disk cache, so workers
    started afterwards load it instead of each compiling the same kernel at once (the first
    sweep on a fresh install spent most of its time so).

    On an empty cache the topology (about a fifth of the compiling) and the static functions
    of the hold's stability test (rod/onset.compile_static) compile in a second process
    meanwhile, into the same disk cache, and load from there when needed: the kernel is one
    function and compiles on one core, so the other one would otherwise wait."""
    import subprocess
    import sys
    from pathlib import Path

    from . import scenes, topology

    start = time.perf_counter()
    helper = None
    if sys.executable and not topology.history_compiled():
        root = str(Path(topology.__file__).resolve().parent.parent)
        try:
            helper = subprocess.Popen(
                [sys.executable, "-c", f"import sys; sys.path.insert(0, {root!r}); "
                 "from rodphase.topology import compile_history; compile_history(); "
                 "from rodphase.rod.onset import compile_static; compile_static()"],
                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        except OSError:  # no second process here: the topology compiles below, in this one
            helper = None
    try:
        with warnings.catch_warnings():  # 8 elements on purpose: a tiny rod compiles the same
            warnings.simplefilter("ignore", config.ResolutionWarning)
            cfg = config.validate_scene({"scene": "twist_under_load", "rod": {"elements": 8},
                                    "loading": {"force_multiple": 25, "force_ramp_time": 1e-3,
                                                "twist_density": 0.1, "twist_rate": 100.0},
                                    "solver": {"hold_max_time": 1e-3, "stability_probe": True}},
                                   scenes.SCENES)
        problem = scenes.build(cfg)
        result = run(problem)
        if helper is not None:
            helper.wait()  # if it failed, with_topology compiles here, as it did before
        with_topology(result, problem)
    finally:
        if helper is not None and helper.poll() is None:  # interrupted
            helper.kill()
            helper.wait()
    return time.perf_counter() - start


# Peak memory of a run over the bytes of its snapshots (positions and d1, float64): the
# kernel's chunks and their concatenation, the topology of every snapshot (tangents, the
# closure, Tw and Wr working arrays), the thinned copies and the store's write. Measured:
# twist_under_load at 20 elements with a snapshot every step (150 657 snapshots, 148 MB)
# peaked 1324 MB above the same run's peak with history_interval 0.05 s, a factor of 8.9.
PEAK_OVER_SNAPSHOTS = 10.0


def available_memory() -> float:
    """Bytes this process can still allocate: the least of the memory the system has
    available (/proc/meminfo MemAvailable), the room under the address-space limit (ulimit
    -v) and the room under the cgroup's memory limit; inf where none of these is known."""
    import resource
    from pathlib import Path

    room = [math.inf]
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                room.append(float(line.split()[1]) * 1024)
    except OSError:
        pass
    try:
        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft != resource.RLIM_INFINITY:
            size = 0.0
            for line in Path("/proc/self/status").read_text().splitlines():
                if line.startswith("VmSize:"):
                    size = float(line.split()[1]) * 1024
            room.append(max(soft - size, 0.0))
    except (OSError, ValueError):
        pass
    for limit, used in (("memory.max", "memory.current"),
                        ("memory/memory.limit_in_bytes", "memory/memory.usage_in_bytes")):
        try:
            cap = Path("/sys/fs/cgroup", limit).read_text().strip()
            if cap != "max" and float(cap) < 2**60:
                room.append(max(float(cap) - float(Path("/sys/fs/cgroup", used).read_text()),
                                0.0))
                break
        except (OSError, ValueError):
            continue
    return min(room)


def snapshot_estimate(cfg, twist_targets: list[float] | None = None) -> tuple[float, int, float]:
    """(snapshots, nodes, seconds of protocol) a run of `cfg` may take at most: one snapshot
    per history row, every stage (a hold too) run to its full duration at the smaller time
    step (contact awake), at the scene's elements (a run refined by solver.refine_up_to
    takes more; it is rare, and counting it always would refuse sweeps that fit)."""
    from .rod.simulate import time_step
    from .scenes import build

    extra = {} if twist_targets is None else {"twist_targets": twist_targets}
    problem = build(cfg, **extra)
    dt, _ = time_step(problem)
    every = max(1, int(round(cfg.output.history_interval / dt)))
    rows = sum(math.ceil(s.duration / dt) for s in problem.stages) / every
    return rows, problem.rod.elements + 1, sum(s.duration for s in problem.stages)


def check_memory(cfg, *, twist_targets: list[float] | None = None, share: int = 1,
                 where: str = "") -> None:
    """Refuse (ConfigError on output.history_interval) a run whose snapshots would not fit in
    memory, before anything is simulated or any store made: its work would be lost at its
    end. `share`: runs that are in memory at once (the sweep's workers)."""
    rows, nodes, seconds = snapshot_estimate(cfg, twist_targets)
    snapshot_bytes = rows * (2 * nodes - 1) * 3 * 8  # positions (nodes) and d1 (elements)
    peak = PEAK_OVER_SNAPSHOTS * snapshot_bytes
    room = available_memory() / max(int(share), 1)
    if peak <= room:
        return
    interval = cfg.output.history_interval
    least = interval * peak / room
    shared = f" per worker ({share} at once)" if share > 1 else ""
    raise config.ConfigError(
        f"{where}output.history_interval", interval,
        f"at least {least:.3g} s: {interval:g} s asks for up to {rows:.3g} snapshots × {nodes} "
        f"nodes × 48 bytes = {snapshot_bytes / 2**20:.0f} MiB over {seconds:.4g} s of "
        f"protocol, about {peak / 2**20:.0f} MiB at the run's peak, and "
        f"{room / 2**20:.0f} MiB are available{shared}")


def check_jobs_memory(jobs, workers: int) -> None:
    """check_memory for every job of a sweep (rodphase.sweep.plan), `workers` of them in
    memory at once; the error names the first sample that would not fit."""
    for job in jobs:
        check_memory(job.scene, twist_targets=job.twist_targets, share=workers,
                     where=f"{job.run_ids[0]}: ")
