"""Sampling, scheduling and resume: a sweep config → runs in parallel → the HDF5 store.

Workers only simulate and return results; the parent process alone writes the store, one
whole run at a time, so a killed sweep loses at most the runs in flight and rerunning the
same command resumes.
"""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import logging
import math
import os
import re
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from . import config as C
from ._version import __version__
from .result import RunResult
from .runner import (
    compile_kernel,
    cpu_seconds,
    keep_snapshots,
    run_scene,
    snapshot_policy,
    split_continuation,
)

log = logging.getLogger(__name__)

# ---------------------------------------------------------------- samplers

def _random(axes: dict, samples: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.random((samples, len(axes)))


def _lhs(axes: dict, samples: int, seed: int) -> np.ndarray:
    from scipy.stats import qmc

    return qmc.LatinHypercube(d=len(axes), seed=np.random.default_rng(seed)).random(samples)


def _sobol(axes: dict, samples: int, seed: int) -> np.ndarray:
    """The first `samples` points of a scrambled Sobol sequence: random (the scrambling is
    seeded), and spread over the box far more evenly than independent draws, so that no
    corner of a 200-point map is left empty. Any count is allowed: the first N points of the
    sequence keep its low discrepancy, though only powers of two balance it exactly."""
    import warnings

    from scipy.stats import qmc

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*balance properties.*")
        return qmc.Sobol(d=len(axes), scramble=True,
                         seed=np.random.default_rng(seed)).random(samples)


def _grid(axes: dict, samples: int, seed: int) -> np.ndarray:
    per_axis = max(1, math.ceil(samples ** (1.0 / len(axes)) - 1e-9))
    ticks = np.linspace(0.0, 1.0, per_axis) if per_axis > 1 else np.array([0.5])
    return np.array(list(itertools.product(ticks, repeat=len(axes))))


def _paths(axes: dict, samples: int, seed: int, columns: int | None = None) -> np.ndarray:
    """Random columns with random twists in each: the loads (the axis that is not a twist)
    are the first `columns` points of a scrambled Sobol sequence (random, evenly spread),
    and each column's twists are stratified at random: its share of the samples, one in
    each equal slice of the twist axis, uniform within the slice. Column by column, in
    increasing load; the samples split as evenly as they can (the first columns take one
    more). `columns` defaults to the square root of `samples`."""
    names = list(axes)
    twist = next(i for i, name in enumerate(names) if name.startswith("twist_density"))
    count = columns if columns is not None else max(1, round(math.sqrt(samples)))
    rng = np.random.default_rng(seed)
    loads = np.sort(_sobol({"load": None}, count, seed)[:, 0])
    rows = []
    for c, load in enumerate(loads):
        m = samples // count + (c < samples % count)
        for u in (np.arange(m) + rng.random(m)) / m:
            row = [load, load]
            row[twist] = u
            rows.append(row)
    return np.array(rows).reshape(-1, len(names))


SAMPLERS: dict[str, Callable] = {"random": _random, "lhs": _lhs, "sobol": _sobol, "grid": _grid,
                                 "continuation": _grid, "adaptive": _lhs, "paths": _paths,
                                 # the boundaries sampler places its runs by bracketing
                                 # (boundaries.boundary_rounds); its grid only checks the box
                                 "boundaries": _grid}


def sample_points(sweep) -> list[dict[str, float]]:
    """The sweep's samples in the axes' own units, in a fixed order (same seed → same list)."""
    names = list(sweep.axes)
    try:
        sampler = SAMPLERS[sweep.sampler]
        if sweep.sampler == "paths":
            unit = sampler(sweep.axes, sweep.samples, sweep.seed, sweep.get("columns"))
        else:
            unit = sampler(sweep.axes, sweep.samples, sweep.seed)
    except KeyError:
        raise C.ConfigError("sweep.sampler", sweep.sampler, "one of " + ", ".join(SAMPLERS)) from None
    points = []
    for row in unit:
        point = {}
        for name, u in zip(names, row):
            lo, hi = sweep.axes[name]
            point[name] = float(lo + u * (hi - lo))
        points.append(point)
    return points


def scene_for(scene, point: dict[str, float]):
    """The base scene with one sample's axis values written into it, validated again."""
    overrides = [(C.AXES[name][1], value) for name, value in point.items()]
    return C.validate_scene(C.apply_overrides(scene.plain(), overrides))


# ---------------------------------------------------------------- jobs

@dataclass
class Job:
    """One simulation: one sample, or (continuation) several samples sharing one twist ramp."""

    run_ids: list[str]
    params: list[dict]
    scene: C.Frozen  # the validated scene: workers use it as it is, without validating again
    twist_targets: list[float] | None = None  # turns, ascending, one per run id
    column: object | None = None  # the paths sampler's column (paths.Column): run as a path
    # a scene builder registered at run time (not one of rodphase's): the workers are other
    # processes that never saw the registration, so the job carries it
    builder: Callable | None = None


@contextmanager
def single_threaded_numba():
    """One level of parallelism: the pool owns the cores, numba uses one thread per worker."""
    import numba

    previous = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(previous)


def execute(job: Job) -> list[tuple[str, dict, RunResult | None, str]]:
    """Worker entry point: one (run_id, params, result or None, error text) per sample."""
    if job.builder is not None:
        from .scenes import SCENES

        SCENES[job.scene["scene"]] = job.builder  # the latest definition, in a reused worker too
    with single_threaded_numba():
        try:
            if job.column is not None:
                from .paths import run_column

                results = run_column(job.column)
            else:
                result = run_scene(job.scene, twist_targets=job.twist_targets)
        except Exception:  # a bug, not a physical failure: keep the sweep going, record it
            error = traceback.format_exc(limit=4)
            return [(rid, p, None, error) for rid, p in zip(job.run_ids, job.params)]
    policy = snapshot_policy(job.scene, "final")
    if job.column is not None:
        return [(rid, p, keep_snapshots(r, policy), "")
                for rid, p, r in zip(job.run_ids, job.params, results)]
    if job.twist_targets is None:
        return [(job.run_ids[0], job.params[0], keep_snapshots(result, policy), "")]
    incompressible = job.scene["material"]["incompressible"]
    return [(rid, p, keep_snapshots(_shared(split_continuation(result, k, incompressible),
                                            len(job.run_ids)), policy), "")
            for k, (rid, p) in enumerate(zip(job.run_ids, job.params))]


def _shared(sample: RunResult, share: int) -> RunResult:
    """A continuation sample whose wall time is its share of the run's (as a path's samples'
    are, paths._tagged), so that a store's wall times add up to the work done; the run's own
    is kept as diagnostics["run_wall_time"]."""
    wall = float(sample.diagnostics.get("wall_time", 0.0))
    diagnostics = dict(sample.diagnostics, run_wall_time=wall, wall_time=wall / share)
    return dataclasses.replace(sample, diagnostics=diagnostics)


@dataclass
class Prepared:
    """A finished run as a worker hands it back to the parent: its part file, built in the
    worker (store.run_image), and what the parent reports. Building the HDF5 objects of a
    run is most of what storing it costs: done in the workers it is spread over the cores,
    and the parent, which alone writes the store, only writes bytes."""

    status: str
    message: str
    wall_time: float  # s, the simulation's
    image: bytes

    @property
    def ok(self) -> bool:
        return self.status == "ok"


def execute_batch(jobs: list[Job], config_hash: str | None = None) -> list[tuple]:
    """Worker entry point for a task of one or more jobs: every job's outcomes, in order.
    With the store's config_hash, each finished run comes back as its part file (Prepared)."""
    from .store import run_image

    outcomes = []
    for job in jobs:
        for run_id, params, result, error in execute(job):
            if result is not None and config_hash is not None:
                wall = result.diagnostics.get("wall_time", 0.0)
                try:
                    result = Prepared(result.status, result.message, wall,
                                      run_image(run_id, params, result, {"wall_time": wall},
                                                config_hash))
                except Exception:  # the parent's write_run meets it again and says why
                    log.debug("building %s in the worker failed", run_id, exc_info=True)
            outcomes.append((run_id, params, result, error))
    return outcomes


def error_result(scene_plain: dict, message: str) -> RunResult:
    n = scene_plain["rod"]["elements"]
    empty = np.zeros((0,))
    return RunResult(status="error", message=message, positions=np.zeros((n + 1, 3)),
                     directors=np.zeros((n, 3, 3)), radii=np.zeros(n), rest_lengths=np.zeros(n),
                     history={"time": empty}, snapshot_positions=np.zeros((0, n + 1, 3)),
                     snapshot_d1=np.zeros((0, n, 3)), diagnostics={})


def plan(sweep, scene) -> list[Job]:
    """Every job of the sweep, each sample's scene checked before anything runs.

    The continuation sampler groups the grid by everything but the twist density: each
    group is one run that twists through its twist densities in order, relaxing to
    equilibrium at each, so k samples cost about one run.
    """
    builder = _registered_builder(scene.scene)
    points = sample_points(sweep)
    checked = []
    for index, point in enumerate(points):
        try:
            cfg = scene_for(scene, point)
        except C.ConfigError as exc:
            raise C.ConfigError(f"sample {index} ({_describe(point)}): {exc.path}", exc.value,
                                exc.allowed) from None
        checked.append((f"run-{index:05d}", dict(point), cfg))
    if sweep.sampler not in ("continuation", "paths"):
        return [Job([rid], [p], cfg, builder=builder) for rid, p, cfg in checked]
    twist_axis = next((a for a in ("twist_density", "twist_density_current") if a in sweep.axes),
                      None)
    if twist_axis is None:
        raise C.ConfigError("sweep.sampler", sweep.sampler, "a sweep with a twist density axis")
    if sweep.sampler == "paths":
        _check_paths_scene(scene, checked)
    groups: dict[tuple, list] = {}
    for rid, point, cfg in checked:
        key = tuple(sorted((k, v) for k, v in point.items() if k != twist_axis))
        groups.setdefault(key, []).append((rid, point, cfg))
    jobs = []
    for index, members in enumerate(groups.values()):
        members.sort(key=lambda m: m[1][twist_axis])
        targets = [C.twist_turns(m[2]) for m in members]
        column = None
        if sweep.sampler == "paths":
            from .paths import Column

            column = Column(index, [m[2] for m in members], targets)
        jobs.append(Job([m[0] for m in members], [m[1] for m in members], members[0][2],
                        twist_targets=targets, column=column, builder=builder))
    return jobs


def _check_paths_scene(scene, checked) -> None:
    """Refuse, before anything runs, a scene the paths sampler cannot follow: a path is the
    straight start's branch (loading.quasi_static_below > 0, and what the straight start
    needs), then twist at fixed load (scene twist_under_load)."""
    from .scenes import check_straight_start

    if scene.scene != "twist_under_load":
        raise C.ConfigError("scene", scene.scene, "twist_under_load with sweep.sampler: paths "
                            "(a path is twist at a fixed load)")
    for _, point, cfg in checked:
        if cfg.loading.quasi_static_below <= 0:
            raise C.ConfigError("loading.quasi_static_below", cfg.loading.quasi_static_below,
                                "> 0 with sweep.sampler: paths (a path starts on the straight "
                                "branch below its static onset)")
        check_straight_start(cfg)


def _registered_builder(name: str) -> Callable | None:
    """The builder of a scene registered at run time, or None for a shipped scene (every
    worker has those)."""
    from . import scenes

    builder = scenes.SCENES.get(name)
    return None if builder is None or builder.__module__ == scenes.__name__ else builder


def _describe(point: dict) -> str:
    return ", ".join(f"{k}={v:.4g}" for k, v in point.items())


# ---------------------------------------------------------------- execution

# s a Dask sweep waits for a lost scheduler to answer again, or for a worker once all left
RECONNECT_TIMEOUT = 120.0
MAX_RECONNECT_TIMEOUT = 7 * 24 * 3600.0


@dataclass
class SweepReport:
    total: int
    skipped: int
    done: int
    failed: int
    wall: float  # s, the runs only; compiling is compile_time
    failures: list[tuple[str, str, str]]  # run_id, status, message
    compile_time: float = 0.0  # s spent compiling (or loading the cached kernel) first
    stopped_by: str | None = None  # SIGINT or SIGTERM if a signal stopped the sweep


def run_sweep(sweep, scene, out_path: str, *, jobs: int = 1, backend: str = "loky",
              scheduler: str | None = None, retry_failed: bool = False, replace: bool = False,
              progress: bool = True, echo: Callable[[str], None] = print,
              reconnect_timeout: float = RECONNECT_TIMEOUT,
              rounds_of: Callable | None = None,
              lines: Callable[[str], None] | None = None) -> SweepReport:
    """Run every missing sample of the sweep into the store at `out_path` (resuming).

    `rounds_of(store)`, if given, yields the rounds of jobs instead of the sampler (each
    round is run into the store before the next is made: boundaries.boundary_rounds).

    Each finished run is durable in the store as soon as it arrives (see store.py). SIGINT and
    SIGTERM stop the sweep: the workers are killed, what finished is kept, and the report's
    `stopped_by` names the signal. A full disk raises StoreFull with every stored run intact.
    With replace=True a store of another config is replaced, once the first run is stored.

    On Dask, a scheduler that is lost (killed, restarted, unreachable) is waited for and
    reconnected to for `reconnect_timeout` seconds, and so is a worker once every worker has
    left; the runs in flight are sent again. Past that, ClusterLost says what was lost and
    how many runs are stored.

    `lines`: where a progress line goes every PROGRESS_EVERY seconds (runs finished, failed,
    elapsed, an estimate of what is left), for a sweep without a terminal to draw the bar
    on (nohup, batch jobs, CI); None: none."""
    from .store import open_store

    # before the store is made or anything compiled: a command that refuses to start
    # creates nothing on disk
    _check_backend(backend, scheduler, reconnect_timeout)
    text = C.to_yaml(sweep=sweep, scene=scene)
    digest = C.config_hash(sweep, scene)
    report = SweepReport(0, 0, 0, 0, 0.0, [])
    with stop_on_signals() as stop:
        try:
            # a scheduler that does not answer is refused before the store exists
            with contextlib.ExitStack() as stack:
                pool = (stack.enter_context(_pool(backend, scheduler, jobs, reconnect_timeout))
                        if scheduler else None)
                C.make_output_folder(out_path)
                # the lock and the config check come next: a second writer or another
                # config's file is refused before anything is compiled or simulated
                store = stack.enter_context(open_store(
                    out_path, config_text=text, config_hash=digest, version=__version__,
                    kind="sweep", replace=replace, earlier=C.earlier_hashes(sweep, scene)))
                if backend == "loky":
                    echo("Compiling the kernel (once; numba caches it on disk) ...")
                    cpu = cpu_seconds()
                    with interruptible():
                        report.compile_time = compile_kernel()
                    echo(f"  ready in {report.compile_time:.1f} s "
                         f"(CPU {cpu_seconds() - cpu:.1f} s)")
                start = time.perf_counter()
                try:
                    if pool is None:
                        pool = stack.enter_context(
                            _pool(backend, scheduler, jobs, reconnect_timeout))
                    _run_rounds(sweep, scene, store, pool, retry_failed, progress, report,
                                echo, out_path, rounds_of, lines)
                except ClusterLost as exc:
                    exc.stored = len(store.run_ids())
                    exc.total = max(report.total, exc.stored)
                    raise
                finally:
                    report.wall = time.perf_counter() - start
        except Interrupted:
            pass
        report.stopped_by = stop.signal_name
    return report


def _run_rounds(sweep, scene, store, pool, retry_failed, progress, report, echo, out_path,
                rounds_of=None, lines=None):
    if rounds_of is not None:
        rounds = rounds_of(store)
    elif sweep.sampler == "adaptive":
        rounds = adaptive_rounds(sweep, scene, store)
    else:
        rounds = [plan(sweep, scene)]
    for all_jobs in rounds:
        finished = store.done_ids(include_failed=not retry_failed)
        todo = [j for j in all_jobs if not set(j.run_ids) <= finished]
        total = sum(len(j.run_ids) for j in all_jobs)
        skipped = total - sum(len(j.run_ids) for j in todo)
        report.total += total
        report.skipped += skipped
        shared = (f" in {len(todo)} continuation run(s)" if sweep.sampler == "continuation"
                  else f" along {len(todo)} path(s)" if sweep.sampler == "paths" else "")
        echo(f"Launching {total - skipped} of {total} runs{shared} {pool.where} with "
             f"{pool.workers} worker(s)" + (f"; {skipped} already in {out_path}" if skipped else ""))
        _run_jobs(store, longest_first(todo), pool, progress, report, lines)


# seconds a hold is guessed to take when ordering jobs (most end well before their limit)
HOLD_GUESS = 2.0


def longest_first(jobs: list[Job]) -> list[Job]:
    """The jobs in decreasing order of expected work (elements × steps, a hold counted as
    HOLD_GUESS seconds), equal ones in sampling order. Started first, the long runs do not
    end the sweep on one worker while the others idle (a Fig 3 run's work grows with its
    twist beyond the buckling onset, from nothing to a tenth of the sweep's time). The order
    changes no result: each run is the same whichever worker runs it, and when."""
    from .rod.simulate import time_step
    from .scenes import build

    def work(job: Job) -> float:
        try:
            extra = {} if job.twist_targets is None else {"twist_targets": job.twist_targets}
            problem = build(job.scene, **extra)
            dt, _ = time_step(problem)
        except Exception:  # it fails again in its worker, which records why; start it first
            return math.inf
        seconds = sum(min(stage.duration, HOLD_GUESS) if stage.until_equilibrium
                      else stage.duration for stage in problem.stages)
        return problem.rod.elements * seconds / dt

    return sorted(jobs, key=work, reverse=True)


# a job whose worker died is run again this many times before it is recorded as an error
WORKER_DEATH_RETRIES = 1


def _run_jobs(store, todo: list[Job], pool, progress: bool, report: SweepReport,
              lines: Callable[[str], None] | None = None) -> None:
    """Run jobs on the pool, a bounded number of tasks at a time; the parent stores each
    finished run the moment it arrives, so finished results never pile up in memory and a
    kill loses only the runs in flight. Short runs go several to a task (see _Batches)."""
    bar = _progress(sum(len(j.run_ids) for j in todo), progress)
    pace = _ProgressLines(sum(len(j.run_ids) for j in todo), report, lines)
    waiting = list(reversed(todo))  # pop() takes them in sampling order
    running: dict = {}  # future -> task (a list of jobs)
    deaths: dict[int, int] = {}  # id(job) -> times its worker died under it
    batches = _Batches(pool.workers)
    config_hash = store.attrs["config_hash"]
    try:
        while waiting or running:
            while waiting and len(running) < pool.window:
                task = [waiting.pop() for _ in range(min(len(waiting),
                                                         batches.size(len(waiting))))]
                running[pool.submit(task, config_hash)] = task
            outage = None
            try:
                with interruptible():
                    done = pool.finished(list(running))
            except Outage as exc:
                outage, done = exc, ()
            for future in done:
                task = running.pop(future)
                try:
                    arrived = pool.result(future)
                except ClusterLost:
                    raise
                except Outage as exc:  # the scheduler went while the result was fetched
                    outage = exc
                    running[future] = task
                    break
                except Exception as exc:
                    outage = pool.outage(exc)
                    if outage:  # not the task's failure: the scheduler went as it arrived
                        running[future] = task
                        break
                    died = pool.worker_died(exc)
                    if died and len(task) > 1:
                        # which job killed it is unknown: each goes again on its own
                        log.warning("a worker died under a task of %d jobs (%s): running "
                                    "them again one by one", len(task), died)
                        waiting.extend(reversed(task))
                        continue
                    job = task[0]
                    if died and deaths.get(id(job), 0) < WORKER_DEATH_RETRIES:
                        log.warning("a worker died under %s (%s): running it again",
                                    ", ".join(job.run_ids), died)
                        deaths[id(job)] = deaths.get(id(job), 0) + 1
                        waiting.append(job)  # run it again first
                        continue
                    what = (f"the worker process died while running this job ({died}), "
                            f"{deaths.get(id(job), 0) + 1} time(s); it may need more memory "
                            "than the machine has, or crashed the interpreter") if died else (
                            f"the job failed in its worker: {type(exc).__name__}: {exc}")
                    arrived = [(rid, p, None, what) for j in task
                               for rid, p in zip(j.run_ids, j.params)]
                scenes = {rid: j.scene for j in task for rid in j.run_ids}
                for run_id, params, result, error in arrived:
                    if result is None:
                        result = error_result(scenes[run_id], error)
                    if isinstance(result, Prepared):
                        store.write_part(run_id, result.image)
                        batches.note(result.wall_time)
                    else:
                        store.write_run(run_id, params, result,
                                        {"wall_time": result.diagnostics.get("wall_time", 0.0)})
                    log.info("stored %s: %s", run_id, result.status)
                    if result.ok:
                        report.done += 1
                    else:
                        report.failed += 1
                        report.failures.append((run_id, result.status,
                                                result.message.splitlines()[-1]
                                                if result.message else ""))
                    bar.update(1)
                    bar.set_postfix(done=report.done, failed=report.failed, refresh=False)
            pace.tick()
            if outage is not None:
                # the runs in flight are lost with the scheduler: send them again once it is
                # back (none of them was stored or counted, so none is counted twice)
                lost = [job for task in running.values() for job in task]
                running.clear()
                waiting.extend(reversed(lost))
                in_flight = sum(len(j.run_ids) for j in lost)
                log.warning("%s; the %d run(s) in flight will be sent again", outage, in_flight)
                with interruptible():
                    pool.recover(outage, in_flight=in_flight)
                batches.workers = pool.workers
            _stop.check()
    finally:
        bar.close()


class _Batches:
    """How many jobs go into one task. A task costs the parent and the pool a few
    milliseconds whatever it holds (submission, a round trip, pickling the scene); a run of
    a few milliseconds (continuation, tiny rods) would cost more around it than inside it.
    So jobs go several to a task once the runs are seen to be short: enough for about
    TASK_SECONDS of simulation, never more than MAX_JOBS (a killed worker loses a task's
    runs), and never so many that the jobs left would not keep every worker busy."""

    TASK_SECONDS = 0.25
    MAX_JOBS = 32

    def __init__(self, workers: int):
        self.workers = workers
        self.seconds: list[float] = []  # the last runs' simulation times

    def note(self, wall_time: float) -> None:
        self.seconds = (self.seconds + [wall_time])[-64:]

    def size(self, left: int) -> int:
        if len(self.seconds) < 2 * self.workers:
            return 1  # nothing known yet: longest first means the first runs are the longest
        typical = max(float(np.median(self.seconds)), 1e-4)
        fits = int(self.TASK_SECONDS / typical)
        return max(1, min(fits, self.MAX_JOBS, left // (4 * self.workers)))


# ---------------------------------------------------------------- pools

class _LocalPool:
    """Worker processes on this machine (loky, as joblib uses), fed a few jobs at a time."""

    def __init__(self, jobs: int):
        self.workers = jobs
        self.window = 2 * jobs  # enough that no worker waits for the parent
        self.where = "locally"
        self._executor = None

    def _get(self):
        from joblib.externals.loky import get_reusable_executor

        if self._executor is None:
            _quiet_resource_tracker()
        # a broken executor (a worker died) is replaced by a new one here
        self._executor = get_reusable_executor(
            max_workers=self.workers, initializer=_worker_start, initargs=(os.getpid(),),
            env={"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"})
        return self._executor

    def submit(self, task, config_hash=None):
        return self._get().submit(execute_batch, task, config_hash)

    def finished(self, futures):
        from concurrent.futures import FIRST_COMPLETED, wait

        # a timeout keeps the parent responsive to signals while the workers compute
        return wait(futures, timeout=0.5, return_when=FIRST_COMPLETED).done

    def result(self, future):
        return future.result()

    def outage(self, exc) -> Outage | None:
        return None  # the workers are this process's children: there is no connection to lose

    def worker_died(self, exc) -> str:
        from concurrent.futures.process import BrokenProcessPool

        if isinstance(exc, BrokenProcessPool):
            return str(exc).splitlines()[0][:200]
        return ""

    def close(self, kill: bool) -> None:
        if self._executor is not None and kill:
            self._executor.shutdown(wait=True, kill_workers=True)


class Outage(Exception):
    """The Dask scheduler was lost: the futures in flight are gone (the sweep sends them
    again once the pool has recovered)."""


class ClusterLost(Exception):
    """The Dask scheduler, or every worker, stayed away longer than the sweep waits.
    `stored` and `total` (set by run_sweep) count the runs in the store and in the sweep."""

    def __init__(self, what: str):
        super().__init__(what)
        self.what = what
        self.stored = 0
        self.total = 0


class _DaskPool:
    """A Dask client fed a few jobs at a time, that rides out a lost scheduler (it connects
    again to the same address) and a cluster whose workers all left, for `patience` s each."""

    CHECK_EVERY = 2.0  # s between asking the scheduler how many workers it has
    RESULT_SLICE, MAX_RESULT_SLICE = 1.0, 30.0  # s a result's fetch waits before a check

    def __init__(self, client, cluster, where: str, address: str | None = None,
                 patience: float = 0.0):
        self._quiet = _QuietDistributed()
        self.client, self.cluster, self.where = client, cluster, where
        _drop_cut_gathers(client)
        self.address, self.patience = address, patience
        self._seen = False  # a worker was there at some time (counted, or a job came back)
        self._count_workers()
        self._checked = time.monotonic()
        self._alone_since: float | None = None  # when the last worker left

    def _count_workers(self) -> int:
        info = self.client.scheduler_info().get("workers", {})
        threads = sum(w.get("nthreads", 1) for w in info.values())
        if threads:  # keep the window of the last cluster seen while it has none
            self.workers, self._seen = threads, True
        elif not hasattr(self, "workers"):
            self.workers = 1
        self.window = 2 * self.workers
        return threads

    def submit(self, task, config_hash=None):
        return self.client.submit(execute_batch, task, config_hash, pure=False)

    def finished(self, futures):
        from concurrent.futures import CancelledError

        from dask.distributed import wait

        if self.client.status not in ("running", "newly-created"):
            raise Outage(f"lost the Dask scheduler at {self.address}")
        try:
            done = wait(futures, timeout=0.5, return_when="FIRST_COMPLETED").done
        except TimeoutError:
            done = set()
        except CancelledError:  # FuturesCancelledError
            # the client cancels every future when its connection to the scheduler drops
            raise Outage(f"lost the Dask scheduler at {self.address}") from None
        if any(f.cancelled() for f in done):
            # the client cancels every future when its connection to the scheduler drops
            raise Outage(f"lost the Dask scheduler at {self.address}")
        if done:
            # a job came back, so a worker was there, even if it joined and left between two
            # counts (the message then says it left, not that none ever joined)
            self._seen = True
        if time.monotonic() - self._checked > self.CHECK_EVERY:
            self._check_workers()
        return done

    def result(self, future):
        """A finished future's runs. Its data lives on the worker that ran it: if that worker
        leaves before the data is fetched, the scheduler runs the task again and the fetch
        waits for it, for ever if no worker is left. So the fetch is retried in slices, the
        workers counted in between (ClusterLost once none came back within `patience` s);
        a slice grows each time, so that a large result on a slow link still arrives."""
        wait_for = self.RESULT_SLICE
        while True:
            try:
                return future.result(timeout=wait_for)
            except TimeoutError:
                log.debug("the result of %s not fetched within %g s", future.key, wait_for)
                self._check_workers()
                wait_for = min(2 * wait_for, self.MAX_RESULT_SLICE)

    def _check_workers(self) -> None:
        self._checked = time.monotonic()
        try:
            threads = self._count_workers()
        except (OSError, TimeoutError) as exc:
            log.debug("asking the scheduler for its workers: %s", _first_line(exc))
            raise Outage(f"lost the Dask scheduler at {self.address}") from None
        if threads:
            if self._alone_since is not None:
                log.warning("%d worker thread(s) in the cluster again", threads)
            self._alone_since = None
            return
        what = ("every worker left the Dask cluster at {} and none came back" if self._seen
                else "no worker joined the Dask cluster at {}").format(self.address or "(local)")
        if self._alone_since is None:
            self._alone_since = time.monotonic()
            log.warning("%s: waiting up to %g s for one", what, self.patience)
        elif time.monotonic() - self._alone_since > self.patience:
            raise ClusterLost(f"{what} within {self.patience:g} s")

    def recover(self, outage: Outage, in_flight: int) -> None:
        """Connect again to the scheduler's address within `patience` s (it may be
        restarting), or raise ClusterLost."""
        from dask.distributed import Client

        if self.address is None:  # a local cluster's scheduler lives in this process
            raise ClusterLost(f"{outage} ({in_flight} run(s) in flight not stored)")
        log.warning("%s: waiting up to %g s for it to answer again", outage, self.patience)
        with contextlib.suppress(Exception):
            self.client.close(timeout=2)
        deadline = time.monotonic() + self.patience
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise ClusterLost(f"lost the Dask scheduler at {self.address}, which did not "
                                  f"answer again within {self.patience:g} s ({in_flight} "
                                  "run(s) in flight were not stored)")
            try:
                self.client = Client(self.address, timeout=max(1.0, min(remaining, 5.0)))
                break
            except (OSError, TimeoutError) as exc:
                log.debug("connecting again: %s", _first_line(exc))
                time.sleep(min(0.5, max(0.0, deadline - time.monotonic())))
        log.warning("connected again to the Dask scheduler at %s", self.address)
        _drop_cut_gathers(self.client)
        self._count_workers()
        self._checked, self._alone_since = time.monotonic(), None

    def outage(self, exc) -> Outage | None:
        """An Outage if a future's failure is the lost scheduler's, not the job's."""
        from concurrent.futures import CancelledError

        from distributed.comm import CommClosedError

        if (isinstance(exc, (CancelledError, CommClosedError))
                or self.client.status not in ("running", "newly-created")):
            return Outage(f"lost the Dask scheduler at {self.address}")
        return None

    def worker_died(self, exc) -> str:
        from distributed import KilledWorker

        # Dask has already retried the task on other workers (allowed-failures)
        return str(exc).splitlines()[0][:200] if isinstance(exc, KilledWorker) else ""

    def close(self, kill: bool) -> None:
        # a client whose scheduler is gone would wait for it for the default 30 s
        with contextlib.suppress(Exception):
            self.client.close(timeout=2 if kill else None)
        if self.cluster is not None:
            self.cluster.close()
        self._quiet.restore()


class _QuietDistributed:
    """Dask's client logs every lost connection and every failed reconnection attempt with a
    traceback; the sweep says what happened in one line of its own instead. With -vv
    (rodphase at DEBUG) Dask's lines are left as they are."""

    NAMES = ("distributed.client", "distributed.core", "distributed.comm", "distributed.utils",
             "distributed.batched", "distributed.worker")

    def __init__(self):
        self.levels = {}
        if log.getEffectiveLevel() <= logging.DEBUG:
            return
        for name in self.NAMES:
            logger = logging.getLogger(name)
            self.levels[name] = logger.level
            logger.setLevel(logging.CRITICAL + 1)

    def restore(self) -> None:
        for name, level in self.levels.items():
            logging.getLogger(name).setLevel(level)
        self.levels = {}


def _drop_cut_gathers(client) -> None:
    """A result fetch that timed out (_DaskPool.result) leaves the client's inner gather
    waiting; when the client closes, that gather ends with Dask's AllExit, which nobody
    awaits any more, and asyncio would log it with a traceback after the sweep's last line.
    Those, and only those, are dropped on the client's event loop."""
    from distributed.client import AllExit

    loop = client.loop.asyncio_loop

    def handler(loop, context):
        if not isinstance(context.get("exception"), AllExit):
            loop.default_exception_handler(context)

    loop.set_exception_handler(handler)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return (text.splitlines()[0] if text else type(exc).__name__)[:160]


def _worker_start(parent_pid: int) -> None:
    """In each worker as it starts: die with the parent. A killed parent (SIGKILL, OOM) runs
    no cleanup, and loky workers busy in a long run were seen outliving it by many minutes."""
    if sys.platform.startswith("linux"):
        import ctypes

        PR_SET_PDEATHSIG = 1
        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent_pid:  # the parent died before the line above took effect
        os._exit(1)


def _quiet_resource_tracker() -> None:
    """Start loky's resource tracker with its stderr on /dev/null, unless it already runs.

    The tracker is a helper process that outlives the workers and inherits the parent's
    stderr (fd 2). When a stop kills the workers it can print a KeyError traceback about a
    semaphore it no longer knows (joblib issue #1091), after a stop that was clean: a
    user who pressed Ctrl-C would read it as a crash. What it tracks is cleaned up all
    the same."""
    try:
        from joblib.externals.loky.backend import resource_tracker
    except ImportError:  # another joblib layout: its tracker starts as it always did
        return
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            resource_tracker.ensure_running()
    finally:
        os.dup2(saved, 2)
        os.close(saved)


@contextmanager
def _pool(backend: str, scheduler: str | None, jobs: int,
          patience: float = 0.0) -> Iterator:
    pool = _LocalPool(jobs) if backend == "loky" else _dask_pool(scheduler, jobs, patience)
    clean = False
    try:
        yield pool
        clean = True
    finally:
        pool.close(kill=not clean)


SCHEDULER_ADDRESS = re.compile(r"^(?:(?:tcp|tls|ws|wss|ucx|inproc)://)?[\w.\-]+:\d{1,5}/?$|"
                               r"^(?:(?:tcp|tls)://)?\[[0-9a-fA-F:]+\]:\d{1,5}/?$")
SCHEDULER_TIMEOUT = 10  # s to reach a Dask scheduler before saying it cannot be reached


def _check_backend(backend: str, scheduler: str | None,
                   reconnect_timeout: float = RECONNECT_TIMEOUT) -> None:
    """The backend and scheduler as given, checked without contacting anything."""
    if backend not in ("loky", "dask"):
        raise C.ConfigError("--backend", backend, "loky or dask")
    if scheduler and backend != "dask":
        raise C.ConfigError("--scheduler", scheduler, "only with --backend dask")
    if scheduler and not SCHEDULER_ADDRESS.match(scheduler):
        raise C.ConfigError("--scheduler", scheduler,
                            "a Dask scheduler address such as tcp://host:8786")
    if (isinstance(reconnect_timeout, bool) or not isinstance(reconnect_timeout, (int, float))
            or not 0 <= reconnect_timeout <= MAX_RECONNECT_TIMEOUT):
        raise C.ConfigError("--reconnect-timeout", reconnect_timeout,
                            f"seconds from 0 to {MAX_RECONNECT_TIMEOUT}")


def _dask_pool(scheduler: str | None, jobs: int, patience: float = 0.0) -> _DaskPool:
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise C.ConfigError("--backend", "dask",
                            "installed first: pip install 'rodphase[dask]'") from None
    if scheduler:
        try:
            client = Client(scheduler, timeout=SCHEDULER_TIMEOUT)
        except (OSError, TimeoutError) as exc:
            raise C.ConfigError("--scheduler", scheduler,
                                f"a Dask scheduler that answers within {SCHEDULER_TIMEOUT} s "
                                f"(connecting failed: {str(exc).splitlines()[0][:120]})") from None
        return _DaskPool(client, None, f"on Dask at {scheduler} (dashboard "
                         f"{client.dashboard_link or 'off'})", scheduler, patience)
    try:  # the dashboard's plotting library: Dask's optional dependency, not rodphase's
        import bokeh  # noqa: F401

        dashboard = "127.0.0.1:0"  # a free port on loopback
    except ImportError:
        dashboard = None
    cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True,
                           host="127.0.0.1", dashboard_address=dashboard)
    client = Client(cluster)
    link = client.dashboard_link if dashboard else "off: pip install bokeh for one"
    return _DaskPool(client, cluster, f"on a local Dask cluster (dashboard {link})", None,
                     patience)


# ---------------------------------------------------------------- signals

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Interrupted(Exception):
    """SIGINT or SIGTERM arrived: the sweep stops, keeping what finished."""


class _Stop:
    signal_name: str | None = None  # the signal that asked the sweep to stop
    interruptible: int = 0  # > 0 where raising at once is safe (waiting, compiling)

    def check(self) -> None:
        """Raise Interrupted if a stop was asked for (call at safe points)."""
        if self.signal_name:
            raise Interrupted(self.signal_name)


_stop = _Stop()


@contextmanager
def stop_on_signals() -> Iterator[_Stop]:
    """SIGINT (Ctrl-C) and SIGTERM (batch systems, docker stop) stop the sweep at the next safe
    point: at once while waiting for workers or compiling, never inside a store write (an
    exception raised inside h5py's C callbacks leaves it in a broken state). Outside the main
    thread (no signals there), a no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield _Stop()
        return

    def handler(signum, frame):
        _stop.signal_name = signal.Signals(signum).name
        for s in STOP_SIGNALS:  # a second Ctrl-C must not break the clean stop
            signal.signal(s, signal.SIG_IGN)
        if _stop.interruptible:
            raise Interrupted(_stop.signal_name)

    _stop.signal_name, _stop.interruptible = None, 0
    previous = {s: signal.signal(s, handler) for s in STOP_SIGNALS}
    try:
        yield _stop
    finally:
        for s, old in previous.items():
            signal.signal(s, old)
        # read inside the block; left set, a later _run_jobs of this process would stop at once
        _stop.signal_name, _stop.interruptible = None, 0


@contextmanager
def interruptible() -> Iterator[None]:
    """A stretch of pure waiting or compiling, where a stop may be raised at once."""
    _stop.check()
    _stop.interruptible += 1
    try:
        yield
    finally:
        _stop.interruptible -= 1


def adaptive_rounds(sweep, scene, store) -> Iterator[list[Job]]:
    """Adaptive sampling: a Latin-hypercube third of the budget, then rounds that put new
    samples at the midpoints of the longest Delaunay edges joining points of different
    phases (the boundaries), until the budget is spent or no boundary is left. Deterministic
    for a given seed and results, so a rerun into the same file resumes the same rounds."""
    from scipy.spatial import Delaunay

    from .tabulate import summarize

    names = list(sweep.axes)
    lo = np.array([sweep.axes[k][0] for k in names])
    span = np.array([sweep.axes[k][1] - sweep.axes[k][0] for k in names])
    first = max(4, sweep.samples // 3)
    builder = _registered_builder(scene.scene)
    unit = list(_lhs(sweep.axes, first, sweep.seed))
    rng = np.random.default_rng(sweep.seed + 1)
    phases: dict[str, str] = {}
    while True:
        jobs = []
        for index, u in enumerate(unit):
            point = {k: float(v) for k, v in zip(names, lo + np.asarray(u) * span)}
            cfg = scene_for(scene, point)
            jobs.append(Job([f"run-{index:05d}"], [point], cfg, builder=builder))
        yield jobs
        for job in jobs:
            rid = job.run_ids[0]
            if rid not in phases:
                # a hold that ran out of time still has an informative shape; a blow-up has not
                phases[rid] = summarize(store.read_run(rid))["phase"]
        remaining = sweep.samples - len(unit)
        if remaining <= 0:
            return
        labelled = [(np.asarray(u), phases[f"run-{i:05d}"]) for i, u in enumerate(unit)
                    if phases[f"run-{i:05d}"] != "failed"]
        size = min(remaining, max(2, first // 2))
        if len(labelled) < len(names) + 2:
            # too few usable points to triangulate: widen the coarse pass instead
            unit.extend(rng.random((size, len(names))))
            continue
        pts = np.array([p for p, _ in labelled])
        tri = Delaunay(pts)
        edges = set()
        for simplex in tri.simplices:
            for a in range(len(simplex)):
                for b in range(a + 1, len(simplex)):
                    i, j = sorted((int(simplex[a]), int(simplex[b])))
                    if labelled[i][1] != labelled[j][1]:
                        edges.add((i, j))
        if not edges:
            return
        ranked = sorted(edges, key=lambda e: -np.linalg.norm(pts[e[0]] - pts[e[1]]))
        for i, j in ranked[:size]:
            jitter = 0.05 * np.linalg.norm(pts[i] - pts[j]) * rng.standard_normal(len(names))
            unit.append(np.clip(0.5 * (pts[i] + pts[j]) + jitter, 0.0, 1.0))


# s between two progress lines of a sweep without a terminal (the bar's stand-in in a log)
PROGRESS_EVERY = 30.0


class _ProgressLines:
    """'12 of 40 runs finished (1 failed), 3 min 20 s elapsed, about 7 min 50 s left' every
    PROGRESS_EVERY seconds through `say`, counting this round's runs."""

    def __init__(self, total: int, report: SweepReport, say: Callable[[str], None] | None):
        self.total, self.report, self.say = total, report, say
        self.first = report.done + report.failed
        self.start = self.last = time.perf_counter()

    def tick(self) -> None:
        now = time.perf_counter()
        if self.say is None or not self.total or now - self.last < PROGRESS_EVERY:
            return
        self.last = now
        finished = self.report.done + self.report.failed - self.first
        elapsed = now - self.start
        left = (f", about {_duration(elapsed / finished * (self.total - finished))} left"
                if 0 < finished < self.total else "")
        self.say(f"{finished} of {self.total} runs finished ({self.report.failed} failed), "
                 f"{_duration(elapsed)} elapsed{left}")


def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    if seconds < 60:
        return f"{seconds} s"
    if seconds < 3600:
        return f"{seconds // 60} min {seconds % 60} s"
    return f"{seconds // 3600} h {seconds % 3600 // 60} min"


def _progress(total: int, enabled: bool):
    from tqdm import tqdm

    return tqdm(total=total, disable=not enabled or total == 0, unit="run", dynamic_ncols=True)
