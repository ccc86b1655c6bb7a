#!/usr/bin/env python
"""CPU µs per step of the two incompressible laws (material.law), interleaved in one process.

    python benchmarks/bench_laws.py [--rounds 7] [--steps 20000] [--elements 150]

Each round times `simulate` once per law and case, alternating, with the process's CPU time
(time.process_time), so that a machine shared with other work slows both laws alike. Cases as
in bench_interleaved.py: "free", the straight rod twisted to Φa 0.3 without contact, and
"contact", a plectoneme (made once with the paper's law, then the same state for both laws)
held under its load and twist with self-contact. Prints medians and spread per law and case
and the ratio neo_hookean/paper of the medians.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import time

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = "1"

from rodphase import config as C  # noqa: E402
from rodphase.rod import simulate, time_step  # noqa: E402
from rodphase.rod.model import Stage, constant, state_from  # noqa: E402
from rodphase.scenes import SCENES, build  # noqa: E402

LAWS = ("paper", "neo_hookean")


def problem_for(case: str, law: str, elements: int, state):
    contact = case == "contact"
    over = [("rod.elements", elements), ("loading.twist_rate", 1.0), ("material.law", law),
            ("loading.twist_density", 1.0 if contact else 0.3), ("physics.self_contact", contact)]
    problem = build(C.load_scene("twist_under_load", over, SCENES))
    if contact:
        problem = dataclasses.replace(problem, state=state_from(*state))
    return problem


def timed(problem, steps: int) -> float:
    dt, _ = time_step(problem)
    # the state carries its twist already; its end frames are the clamps (no further turn)
    controls = dataclasses.replace(problem.stages[-1].controls, end_rotation=constant(0.0))
    stage = Stage((steps - 0.5) * dt, until_equilibrium=False, label="timed", controls=controls)
    p = dataclasses.replace(problem, stages=[stage])
    p.state = p.state.copy()
    t0 = time.process_time()
    r = simulate(p, max_steps=steps)
    return 1e6 * (time.process_time() - t0) / r.diagnostics["steps"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--elements", type=int, default=150)
    args = parser.parse_args()
    over = [("rod.elements", args.elements), ("loading.twist_rate", 1.0),
            ("loading.twist_density", 1.0), ("solver.hold_max_time", 2.0)]
    made = simulate(build(C.load_scene("twist_under_load", over, SCENES)))
    state = (made.positions, made.directors)
    problems = {(case, law): problem_for(case, law, args.elements, state)
                for case in ("free", "contact") for law in LAWS}
    for p in problems.values():
        timed(p, 200)  # compile or load the cache
    times: dict = {key: [] for key in problems}
    for _ in range(args.rounds):
        for key, p in problems.items():
            times[key].append(timed(p, args.steps))
    for case in ("free", "contact"):
        medians = {}
        for law in LAWS:
            t = times[case, law]
            medians[law] = statistics.median(t)
            print(f"{case:8s} {law:12s} {medians[law]:7.2f} µs/step  (min {min(t):.2f}, "
                  f"max {max(t):.2f}, {args.rounds} rounds of {args.steps} steps)")
        print(f"{case:8s} ratio neo_hookean/paper {medians['neo_hookean'] / medians['paper']:.3f}")
    print(f"contacts at the end of the plectoneme's making: {made.history['contacts'][-1]:.0f}")


if __name__ == "__main__":
    main()
