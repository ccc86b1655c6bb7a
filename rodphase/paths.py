"""One column of the phase map as one path: the straight branch from its static onset, one
dynamic run across the jump and through the rest of the column.

A column is the samples of one load (one extension) at increasing twist. Along it the rod is
first straight, and the straight rod is an equilibrium at every twist: stable up to the
onset θ_c, which the model's own stiffness gives (rod/onset.py: the Cholesky test of the
lateral block, milliseconds at n = 80). So the path is:

1. θ_c of the column, from the factorization (no dynamics).
2. Every sample below s·θ_c (s = loading.quasi_static_below) runs alone, as an independent
   sweep runs it: started on the straight branch at its own twist and held, a few hundred
   steps. Such a run is the same run, bit for bit, as the independent sweep's.
3. The samples from s·θ_c on are one continuation run (scenes.twist_under_load with
   twist_targets): it starts on the straight branch at s·θ_c, twists across the onset,
   where the rod jumps (snaps into a plectoneme or a solenoid) under the scene's damping, and
   goes on twisting to each sample's twist and holding there until a stable equilibrium.
   The samples share one twist ramp instead of each ramping from s·θ_c.
4. A run a guard stops (the 135° resolution guard, the 45° shear guard) keeps the samples it
   finished; the rest of the column goes on as a new path from the straight branch at twice
   the elements, up to solver.refine_up_to. A sample that still stops the path at the most
   elements runs alone, as the independent sweep runs it (refined and slowed down as its
   solver keys allow), and the path resumes from the straight branch above it.

Why the branches past the jump are followed dynamically rather than by Newton continuation:
the kernel's settled plectonemes and solenoids are not isolated equilibria with frictionless
contact (rod/static.py, its docstring: neutral sliding modes, a creeping solenoid). A static
corrector converges there only beside those soft modes (static.solve_beside_soft_modes), and
they are how the shape takes up twist: a static path in twist fails after 0 to 0.1 of Φa in
steps of 0.005, and where it runs it costs 10-30 times what the kernel's ramp and hold cost
per unit of twist (docs/history/performance.md, "A twist continuation beside the soft modes"). The
onset, where the branch does have an isolated equilibrium, is static.

Each sample's result records its place on the path (diagnostics["path"]): the column, its
rank in the column, θ_c, how it was reached, and the elements of the run it came from.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from . import config
from .result import RunResult, rotation_put_in
from .runner import REFINABLE_GUARDS, finished_holds, run_scene, split_continuation
from .units import TURN

# how a sample of a path was computed (diagnostics["path"]["reached"])
REACHED_ALONE = "own run, on the straight branch"
REACHED_PATH = "path"
REACHED_FALLBACK = "own run, after the path failed there"


@dataclasses.dataclass
class Column:
    """The samples of one column, in increasing twist: their scenes (validated) and twists
    [turns, ascending]."""

    index: int
    scenes: list
    targets: list[float]


def onset_of(cfg) -> float:
    """θ_c [turns] of the column's straight rod (the scene's rod, its load's extension),
    relative accuracy 1e-6."""
    from .rod.onset import straight_onset_turns
    from .scenes import rod_from

    return straight_onset_turns(rod_from(cfg), config.straight_extension(cfg), tolerance=1e-6)


def reached_samples(result: RunResult) -> int:
    """How many samples of a continuation run finished their hold (runner.finished_holds)."""
    return len(finished_holds(result))


# |Wr| [turns] past which a path has left the straight branch: a straight rod writhes by
# < 1e-3 turns (its frozen round-off), a loop by about one
JUMP_WRITHE = 0.1


def jump_turns(run: RunResult) -> float | None:
    """The twist [turns put in] at which a path run left the straight branch: its first
    history row writhing by more than JUMP_WRITHE (None: it never did). Against θ_c this is
    the protocol's overshoot of the static onset at its twist rate."""
    writhe = run.history.get("writhe")
    if writhe is None or not len(writhe):
        return None
    left = np.flatnonzero(np.abs(writhe) > JUMP_WRITHE)
    if not len(left):
        return None
    return float(rotation_put_in(run.history)[left[0]] / TURN)


def _with(cfg, **values):
    from .scenes import SCENES

    return config.validate_scene(config.apply_overrides(cfg.plain(), list(values.items())), SCENES)


def _tagged(result: RunResult, column: Column, rank: int, onset: float, reached: str,
            share: int = 1, carried: float = 0.0, jump: float | None = None) -> RunResult:
    """The result with its place on the path in its diagnostics. The store's wall times add
    up to the work: a path run's wall time is shared by its `share` samples, and the wall
    time of path runs that finished no sample (`carried`, s) goes to the next sample. `jump`
    [turns]: where the path run the sample came from left the straight branch (the same
    for all its samples; one below it is still straight)."""
    diagnostics = dict(result.diagnostics)
    diagnostics["path"] = {"column": column.index, "rank": rank, "onset_turns": onset,
                           "reached": reached, "elements": diagnostics.get("elements"),
                           "jump_turns": jump}
    wall = diagnostics.get("wall_time", 0.0)
    if share > 1:
        diagnostics["path"]["run_wall_time"] = wall
        wall /= share
    if carried:
        diagnostics["path"]["wall_time_carried"] = carried
    diagnostics["wall_time"] = wall + carried
    return dataclasses.replace(result, diagnostics=diagnostics)


def run_column(column: Column) -> list[RunResult]:
    """Every sample of the column, in the order of column.targets (see the module doc)."""
    first = column.scenes[0]
    fraction = first.loading.quasi_static_below
    started = time.process_time()
    try:
        onset = onset_of(first)
    except ValueError:
        # the straight rod cannot answer for its onset at this resolution (or is unstable
        # untwisted): each sample runs alone, where the straight start says why if it must
        onset = float("nan")
    # the static part's cost (the bisection on the Cholesky test): a path's cost splits into
    # this and the dynamic runs' wall times
    onset_seconds = time.process_time() - started
    m = len(column.targets)
    results: list[RunResult | None] = [None] * m
    # the samples from fraction·θ_c on make the path; without θ_c (NaN) none does
    rest = [i for i in range(m) if abs(column.targets[i]) >= fraction * onset]
    for i in range(m):
        if i not in rest:
            results[i] = _tagged(run_scene(column.scenes[i]), column, i, onset, REACHED_ALONE)
    incompressible = first.material.incompressible
    elements, most = first.rod.elements, config.refine_limit(first)
    lost = 0.0  # s, the wall time of path runs that finished no sample
    while rest:
        # refinement is this loop's: the run itself must not redo the column from the start
        cfg = _with(first, **{"rod.elements": elements, "solver.refine_up_to": elements,
                              "solver.refinements": 0})
        run = run_scene(cfg, twist_targets=[column.targets[i] for i in rest])
        done = reached_samples(run)
        jump = jump_turns(run)
        if done == 0:
            lost += run.diagnostics.get("wall_time", 0.0)
        for j in range(done):
            sample = split_continuation(run, j, incompressible)
            if run.status == "unstable":  # the guard stopped the run after this sample
                sample.diagnostics["guard"] = None
            results[rest[j]] = _tagged(sample, column, rest[j], onset, REACHED_PATH,
                                       share=done, carried=lost if j == 0 else 0.0, jump=jump)
        lost = 0.0 if done else lost
        if done == len(rest):
            break
        if run.diagnostics.get("guard") in REFINABLE_GUARDS and elements < most:
            elements = min(2 * elements, most)
            rest = rest[done:]
            continue
        stuck = rest[done]
        alone = run_scene(column.scenes[stuck])
        alone.diagnostics.setdefault("notes", []).append(
            f"the path of column {column.index} stopped here at {elements} elements "
            f"({run.message}); this is the sample's own run")
        results[stuck] = _tagged(alone, column, stuck, onset, REACHED_FALLBACK, carried=lost)
        lost = 0.0
        rest = rest[done + 1:]
    return _with_onset_cost(results, onset_seconds)


def _with_onset_cost(results: list[RunResult], seconds: float) -> list[RunResult]:
    """Every sample of the column records the CPU seconds its onset took (once per column)."""
    for result in results:
        result.diagnostics["path"]["onset_cpu_seconds"] = seconds
    return results
