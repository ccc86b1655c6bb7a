#!/usr/bin/env python
"""Where a sweep's work goes: twist ramps against holds, and how the holds end.

    rodphase sweep fig3_paths -o out/paths.h5 --jobs 2
    python studies/hold_budget.py out/paths.h5

Reads the per-stage reports every run stores (docs/reference/data-format.md, `diagnostics.stages`).
A run of the paths sampler is one dynamic run split into its samples, each of which carries
the stage list up to its own hold; the run is counted once (its longest list). Work is in
element-steps (steps × elements: the kernel's cost per step grows with the elements), rod
time in seconds. For the holds: how long they ran, whether they ended at an equilibrium or
at solver.hold_max_time, and how close to solver.hold_tolerance their last residual was (a
hold whose residual creeps down to the tolerance is ended by the slowest mode it has).
"""

from __future__ import annotations

import argparse
from collections import defaultdict

import numpy as np

import rodphase


def stage_lists(path: str) -> dict[str, list[dict]]:
    """One diagnostics dict per dynamic run of the store, grouped: "path runs" (of the paths
    sampler, deduplicated) and "own runs" (every other run)."""
    runs: dict[tuple, dict] = {}
    alone = []
    with rodphase.open(path) as store:
        for run_id in store.run_ids():
            diagnostics = store.read_run(run_id).diagnostics
            where = diagnostics.get("path") or {}
            if where.get("reached") == "path":
                key = (where.get("column"), where.get("elements"), where.get("run_wall_time"))
                if key not in runs or len(diagnostics["stages"]) > len(runs[key]["stages"]):
                    runs[key] = diagnostics
            else:
                alone.append(diagnostics)
    groups = {"path runs": list(runs.values()), "own runs": alone}
    return {name: group for name, group in groups.items() if group}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("store")
    parser.add_argument("--tolerance", type=float, default=1e-3,
                        help="the sweep's solver.hold_tolerance")
    args = parser.parse_args()
    for name, runs in stage_lists(args.store).items():
        print(f"{name}:")
        budget(runs, args.tolerance)


def budget(runs: list[dict], tolerance: float) -> None:
    work = defaultdict(float)
    holds = []  # (element-steps, rod seconds, ended at equilibrium, last residual)
    for diagnostics in runs:
        elements = (diagnostics.get("path") or {}).get("elements") or diagnostics.get("elements")
        for stage in diagnostics["stages"]:
            kind = stage["label"].split()[0]
            work[kind] += stage["steps"] * elements
            if kind == "hold":
                holds.append((stage["steps"] * elements, stage["steps"] * diagnostics["dt"],
                              bool(stage["equilibrium"]), stage["residual"]))
    total = sum(work.values())
    print(f"  {len(runs)} dynamic runs; element-steps: "
          + ", ".join(f"{kind} {value:.3g} ({value / total:.0%})" for kind, value in work.items()))
    if not holds:
        return
    cost, seconds, ended, residual = (np.array(column) for column in zip(*holds))
    print(f"  {len(holds)} holds: rod time median {np.median(seconds):.2f} s, quartiles "
          f"{np.percentile(seconds, 25):.2f}–{np.percentile(seconds, 75):.2f} s, "
          f"longest {seconds.max():.1f} s")
    print(f"  ended at an equilibrium {ended.sum()}, at the time cap {(~ended).sum()} "
          f"({cost[~ended].sum() / cost.sum():.0%} of the hold work)")
    if ended.any():
        print("  of those that ended, last residual within 10 % of the tolerance: "
              f"{(residual[ended] > 0.9 * tolerance).mean():.0%}; within 50 %: "
              f"{(residual[ended] > 0.5 * tolerance).mean():.0%}")
    long = seconds > 2.0
    print(f"  holds longer than 2 s of rod time: {long.sum()}, "
          f"{cost[long].sum() / cost.sum():.0%} of the hold work")

if __name__ == "__main__":
    main()
