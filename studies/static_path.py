#!/usr/bin/env python
"""A twist continuation of one Fig 3 column with the static corrector, against the kernel.

    python studies/static_path.py [--elements 64] [--force-multiple 25] [--start 0.9]
        [--stop 1.0] [--step 0.005] [--soft-modes 2] [--compare 1.0 ...]
        [--write docs/history/performance.md]

The kernel runs the scene (scenes/twist_under_load.yaml at the given elements and load,
twisted at 1 turn/s to Φa = --start, held at most 8 s: the state tests/test_static.py
settles) once. From its final state the path steps the end rotation by --step in Φa: each
step spreads the added twist along the rod (static.twisted_further) and corrects with
static.solve_beside_soft_modes, starting from the previous step's factorization (chord
steps). The path stops at --stop or at the first step the corrector fails, which is where
the static branch ends and the kernel would have to take over (a jump, or a creep the soft
modes carry). At each --compare twist the kernel also runs the scene there on its own, and
the two states are compared: alignment (the paper's label), writhe, largest node distance
[radii]. A --compare twist the path did not reach is run by the kernel from the path's last
state instead (a twist ramp at the scene's rate from its end rotation, then the scene's hold:
the hybrid in which the kernel takes over where the corrector stops), and compared alike.

Printed (and with --write, the block static_path of that file): per step the Newton steps,
stiffnesses formed, residual outside and along the soft modes, their eigenvalues, alignment,
writhe and CPU time; then the comparisons. CPU time is `time.process_time` after numba's
compile (the first corrector solve is not timed into the path).
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from rodphase import classify, topology
from rodphase import config as C
from rodphase.rod import kernel, static
from rodphase.rod.model import RodState
from rodphase.rod.simulate import clamp_reference, force_scale, static_model_of
from rodphase.runner import run
from rodphase.scenes import SCENES, build, twist_stages
from rodphase.studytools import machine, write_block
from rodphase.units import TURN, turns_for_twist_density

# turns/s: the twist rate of tests/test_static.py's settled states, and of the kernel's
# ramp where it takes over from the path
RATE = 1.0


def scene_at(elements: int, force_multiple: float, phi: float):
    """(config, problem) of the scene at twist Φa = phi."""
    overrides = [("rod.elements", elements), ("loading.force_multiple", force_multiple),
                 ("loading.twist_density", phi), ("loading.twist_rate", RATE),
                 ("solver.hold_max_time", 8.0)]
    cfg = C.load_scene("twist_under_load", overrides, SCENES)
    return cfg, build(cfg)


def settled(problem):
    """The kernel's final state (x (3, n+1), Q (3, 3, n)), its status and CPU seconds."""
    started = time.process_time()
    result = run(problem)
    cpu = time.process_time() - started
    x = np.ascontiguousarray(result.positions.T)
    Q = np.ascontiguousarray(np.transpose(result.directors, (1, 2, 0)))
    return x, Q, result.status, cpu


def taken_over(cfg, problem, x: np.ndarray, Q: np.ndarray, rotation: float):
    """The kernel from the static state (x, Q) at end rotation `rotation` [rad]: the scene's
    twist ramp (scenes.twist_stages, at its rate) to its twist, then its hold (the clamps as
    the scene's own run has them). Returns settled(...) of that run."""
    twist = twist_stages(cfg, C.load_force(cfg), rotation / TURN, C.twist_turns(cfg))
    hold = problem.stages[-1]
    state = RodState(0.0, x.copy(), np.zeros_like(x), Q.copy(), np.zeros((3, Q.shape[2])))
    return settled(dataclasses.replace(problem, state=state, stages=(twist, hold),
                                       clamp_reference=clamp_reference(problem)))


def shape(x: np.ndarray, radius: float) -> tuple[float, float]:
    """(alignment, writhe [turns]) of the nodes x (3, n+1)."""
    return classify.alignment(x.T, radius), topology.writhe(x.T)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--elements", type=int, default=64)
    parser.add_argument("--force-multiple", type=float, default=25.0)
    parser.add_argument("--start", type=float, default=0.9, help="Φa where the kernel settles")
    parser.add_argument("--stop", type=float, default=1.0, help="Φa where the path ends")
    parser.add_argument("--step", type=float, default=0.005, help="Φa per continuation step")
    parser.add_argument("--soft-modes", type=int, default=2)
    parser.add_argument("--compare", type=float, nargs="*", default=[1.0],
                        help="Φa where the kernel also runs on its own")
    parser.add_argument("--write", type=Path, default=None)
    args = parser.parse_args()

    lines = []

    def say(text: str) -> None:
        print(text, flush=True)
        lines.append(text)

    _, problem = scene_at(args.elements, args.force_multiple, args.start)
    radius = problem.rod.radius
    scale = force_scale(problem)
    model = static_model_of(problem, controls=problem.stages[-1].controls, contact=True)
    x, Q, status, kernel_cpu = settled(problem)
    first = static.solve_beside_soft_modes(model, x, Q, soft_modes=args.soft_modes,
                                           force_scale=scale)
    say(f"Measured on {machine()['cpu']}, load {machine()['load']}; "
        f"n = {args.elements}, {args.force_multiple:g} F_C, {args.soft_modes} soft modes, "
        f"steps of {args.step:g} in Φa.")
    say("")
    say(f"Start Φa {args.start:g}: the kernel's run {status} in {kernel_cpu:.2f} CPU-s, "
        f"alignment {shape(x, radius)[0]:.2f}, writhe {shape(x, radius)[1]:.3f}; corrected "
        f"in {first.iterations} Newton steps ({first.message}), moved "
        f"{np.abs(first.x - x).max() / radius:.3f} radii.")
    say("")
    say("| Φa | Newton steps | stiffnesses | residual outside | along the soft modes | "
        "soft eigenvalues [1/s²] | alignment | writhe | CPU [s] |")
    say("|---|---|---|---|---|---|---|---|---|")
    path = {round(args.start, 6): first.x}
    x, Q, factorization = first.x, first.Q, first.factorization
    reached = model.now[kernel.T_END_ROTATION]  # the end rotation of (x, Q) [rad]
    phi, total = args.start, 0.0
    added = turns_for_twist_density(args.step, radius, problem.rod.length) * TURN  # rad/step
    now = model.now.copy()
    while phi < args.stop - 1e-9:
        phi = round(phi + args.step, 6)
        now[kernel.T_END_ROTATION] += added
        turned = dataclasses.replace(model, now=now.copy())
        started = time.process_time()
        x_predicted, Q_predicted = static.twisted_further(x, Q, added)
        step = static.solve_beside_soft_modes(turned, x_predicted, Q_predicted,
                                              soft_modes=args.soft_modes, force_scale=scale,
                                              factorization=factorization)
        cpu = time.process_time() - started
        total += cpu
        alignment, writhe = shape(step.x, radius)
        values = ", ".join(f"{abs(v):.3g}" for v in step.soft_values)
        say(f"| {phi:.3f} | {step.iterations} | {step.factorizations} | {step.residual:.1e} | "
            f"{step.soft_residual:.1e} | {values} | {alignment:.2f} | {writhe:.3f} | "
            f"{cpu:.2f} |")
        if not step.success:
            say("")
            say(f"The corrector failed at Φa {phi:.3f}: {step.message}.")
            break
        x, Q, factorization = step.x, step.Q, step.factorization
        reached = now[kernel.T_END_ROTATION]
        path[phi] = x
    say("")
    say(f"Path: {len(path) - 1} steps, {total:.2f} CPU-s.")
    say("")
    say("| Φa | kernel's own run: status, CPU [s] | its alignment, writhe | path: how, CPU [s] "
        "| path alignment, writhe | largest node distance [radii] |")
    say("|---|---|---|---|---|---|")
    for target in args.compare:
        cfg, scene = scene_at(args.elements, args.force_multiple, target)
        xk, _, status, cpu = settled(scene)
        ak, wk = shape(xk, radius)
        mine = path.get(round(target, 6))
        how = "static"
        if mine is None:
            mine, _, taken_status, taken_cpu = taken_over(cfg, scene, x, Q, reached)
            how = f"kernel from the last static state ({taken_status}), {taken_cpu:.2f}"
        ap, wp = shape(mine, radius)
        say(f"| {target:g} | {status}, {cpu:.2f} | {ak:.2f}, {wk:.3f} | {how} | {ap:.2f}, "
            f"{wp:.3f} | {np.abs(xk - mine).max() / radius:.2f} |")
    if args.write:
        write_block(args.write, f"static_path_{args.force_multiple:g}", "\n".join(lines))


if __name__ == "__main__":
    main()
