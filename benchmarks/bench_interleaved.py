#!/usr/bin/env python
"""Kernel cost of two versions of the code, interleaved: CPU µs per step at n = 150.

    python benchmarks/bench_interleaved.py OLD_ROOT NEW_ROOT [--rounds 7] [--steps 20000]
                                        [--elements 150 [300 ...]]

OLD_ROOT and NEW_ROOT are directories holding a `rodphase` package (e.g. `git archive main
rodphase | tar -x -C /tmp/old` and the work tree). Each round runs one subprocess per version
and case, alternating, so that a machine shared with other work slows both alike; each
subprocess warms the kernel first (numba compiles or loads its cache) and times only
`simulate` with the process's CPU time (time.process_time), not wall time. Two cases:
"contact", a 150-element plectoneme held under its load and twist with self-contact (the
state is made once by OLD's code, then both versions start from it), and "free", the straight
rod twisted below its buckling onset without contact; `--cases` adds "straight", the free
rod with self-contact switched on (no pair ever touches), "moving", the same
plectoneme with the damping of PyElastica's PlectonemesCase (2/s, no speed-dependent drag), in
which the strands keep moving, and "explicit", the held plectoneme with the contact dashpot
in the force (as benchmarks/bench_kernel.py runs it) instead of the scene's implicit one. Prints medians and spread (min-max) per
version and case, and the ratio new/old of the medians. `--elements` runs the same cases at
other n (each n has its own plectoneme state, made once by OLD's code).

`--pairs N` measures finer: one long-lived process per version and case, warmed once, and N
timed blocks of --steps steps alternating between the two (old first in even pairs); it
prints the median of the paired ratios new/old with its quartiles, and the ratio of the
fastest blocks. On a shared 2-core machine whose speed drifts by 20 % within minutes, the
rounds' medians above disagreed by 5-10 % between runs of the same code, and 40-120 pairs
of 20,000 steps put the ratio within about 1 % (2026-12-06, issue #27's 3 % rule; the same
code against itself: 0.98-1.00).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = "1"

STATE = "/tmp/rodphase_bench_state_{n}.npz"

CHILD = r"""
import dataclasses, json, sys, time
import numpy as np
from rodphase import config as C
from rodphase.rod import simulate, time_step
from rodphase.rod.model import Stage, constant, state_from
from rodphase.scenes import SCENES, build

case, steps, state_path, elements = sys.argv[1], int(sys.argv[2]), sys.argv[3], int(sys.argv[4])
over = [("rod.elements", elements), ("loading.twist_rate", 1.0)]
if case == "make":
    over += [("loading.twist_density", 1.0), ("solver.hold_max_time", 2.0)]
    r = simulate(build(C.load_scene("twist_under_load", over, SCENES)))
    np.savez(state_path, positions=r.positions, directors=r.directors)
    print(json.dumps({"contacts": float(r.history["contacts"][-1])}))
    sys.exit()
contact = case in ("contact", "moving", "explicit")
over += [("loading.twist_density", 1.0 if contact else 0.3),
         ("physics.self_contact", case != "free")]
if case == "moving":  # PyElastica's PlectonemesCase damping (2/s, no drag): the strands move
    over += [("solver.damping", 2.0), ("solver.quadratic_drag", 0.0)]
if case == "explicit":  # the contact dashpot in the force, as bench_kernel.py times it
    over += [("contact.dashpot", "explicit")]
problem = build(C.load_scene("twist_under_load", over, SCENES))
if contact:
    saved = np.load(state_path)
    problem = dataclasses.replace(problem, state=state_from(saved["positions"], saved["directors"]))
def timed(n):
    dt, _ = time_step(problem)
    # the state carries the twist already; its end frames are the clamps (no further turn)
    controls = dataclasses.replace(problem.stages[-1].controls, end_rotation=constant(0.0))
    stage = Stage((n - 0.5) * dt, until_equilibrium=False, label="timed", controls=controls)
    p = dataclasses.replace(problem, stages=[stage])
    t0 = time.process_time()
    r = simulate(p, max_steps=n)
    return time.process_time() - t0, r
timed(200)  # compile or load the cache
if len(sys.argv) > 5:  # --pairs: a timed block for each line read
    for _ in sys.stdin:
        cpu, r = timed(steps)
        print(json.dumps({"us_per_step": 1e6 * cpu / r.diagnostics["steps"]}), flush=True)
    sys.exit()
cpu, r = timed(steps)
print(json.dumps({"us_per_step": 1e6 * cpu / r.diagnostics["steps"], "steps": r.diagnostics["steps"],
                  "contacts": float(r.history["contacts"][-1]), "status": r.status,
                  "near_rebuilds": r.diagnostics.get("near_rebuilds", 0)}))
"""


def run(root: str, case: str, steps: int, n: int = 150) -> dict:
    env = dict(os.environ, PYTHONPATH=root)
    out = subprocess.run([sys.executable, "-c", CHILD, case, str(steps), STATE.format(n=n), str(n)],
                         env=env, cwd="/",
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def paired(old: str, new: str, case: str, steps: int, n: int, pairs: int) -> None:
    """N alternating blocks in two long-lived processes; the paired ratios' median."""
    def start(root):
        return subprocess.Popen([sys.executable, "-c", CHILD, case, str(steps), STATE.format(n=n),
                                 str(n), "pairs"], env=dict(os.environ, PYTHONPATH=root),
                                cwd="/", stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)

    def block(proc):
        proc.stdin.write("go\n")
        proc.stdin.flush()
        return json.loads(proc.stdout.readline())["us_per_step"]

    procs = {"old": start(old), "new": start(new)}
    times = {"old": [], "new": []}
    for k in range(pairs):
        for version in (("old", "new") if k % 2 == 0 else ("new", "old")):
            times[version].append(block(procs[version]))
    for proc in procs.values():
        proc.stdin.close()
        proc.wait()
    ratios = [b / a for a, b in zip(times["old"], times["new"])]
    q1, _, q3 = statistics.quantiles(ratios, n=4)
    print(f"{case}@{n:<4d} old median {statistics.median(times['old']):.2f} µs/step, "
          f"new {statistics.median(times['new']):.2f}; paired new/old: median "
          f"{statistics.median(ratios):.3f} (quartiles {q1:.3f}-{q3:.3f}), fastest blocks "
          f"{min(times['new']) / min(times['old']):.3f} ({pairs} pairs)", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old")
    parser.add_argument("new")
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--cases", default="contact,free",
                        help="comma-separated: contact, free, straight, moving, explicit")
    parser.add_argument("--elements", type=int, nargs="+", default=[150],
                        help="rod elements n (each case is run at each n)")
    parser.add_argument("--pairs", type=int, default=0,
                        help="alternate N timed blocks between two long-lived processes per "
                        "case instead of --rounds of fresh ones (see the docstring)")
    args = parser.parse_args()
    cases = [f"{c}@{n}" for n in args.elements for c in args.cases.split(",")]
    for n in args.elements:
        if not os.path.exists(STATE.format(n=n)):
            print(f"making the plectoneme state at n = {n}:", run(args.old, "make", 0, n))
    if args.pairs:
        for case in cases:
            name, n = case.split("@")
            paired(args.old, args.new, name, args.steps, int(n), args.pairs)
        return
    times = {(v, c): [] for v in ("old", "new") for c in cases}
    for r in range(args.rounds):
        order = ("old", "new") if r % 2 == 0 else ("new", "old")
        for case in cases:
            name, n = case.split("@")
            for version in order:
                res = run(getattr(args, version), name, args.steps, int(n))
                times[version, case].append(res["us_per_step"])
                print(f"round {r} {case:11s} {version}: {res['us_per_step']:.2f} µs/step "
                      f"({res['steps']} steps, {res['contacts']:.0f} contacts, "
                      f"near list rebuilt on {res['near_rebuilds'] / res['steps']:.0%} of steps, "
                      f"{res['status']})",
                      flush=True)
    for case in cases:
        med = {}
        for version in ("old", "new"):
            t = times[version, case]
            med[version] = statistics.median(t)
            print(f"{case:11s} {version}: median {med[version]:.2f} µs/step, "
                  f"spread {min(t):.2f}-{max(t):.2f} ({len(t)} runs)")
        print(f"{case:11s} new/old: {med['new'] / med['old']:.3f}")


if __name__ == "__main__":
    main()
