#!/usr/bin/env python
r"""Fig 3 by two methods, cost against precision: the independent sweep (configs/fig3_paper.yaml,
200 Sobol points, each its own run) and the paths sampler (configs/fig3_paths.yaml, 20 loads ×
10 twists, one path per load: rodphase/paths.py; and 40 loads × 5 twists, which shares less
and balances the two workers better).

    python benchmarks/map_methods.py reference [--samples 60]   # the fine reference, --jobs 2
    python benchmarks/map_methods.py compare [--rounds 2]       # the two maps, interleaved
    python benchmarks/map_methods.py compare --rounds 1 --block map_tolerance --methods \
        "independent;paths;independent, hold tolerance 3e-3;paths, hold tolerance 3e-3"

`reference` runs random points that are in neither map (the Sobol sequence of another seed,
4242) with the paper's protocol step by step (from rest: loading.quasi_static_below = 0), at
n = 140 (refined to 160 where a guard asks), safety 0.25 and half the twist rate (0.25
turns/s): finer, slower and independent of both methods' shortcuts.

`compare` runs the maps one after the other, `--rounds` times, each into a fresh store
(numba's cache warm), and measures for each: wall time, CPU time (user + system of the sweep
and its workers), labels, failed runs, and the boundary error against the reference: the
share of reference points whose label the map's nearest point (in the box scaled to [0, 1]²)
gets wrong (studytools.boundary_error). Writes out/perf/BLOCK.json and, with --write, the
block BLOCK of docs/history/performance.md (--block, default "map_methods"). --methods picks the maps
(METHODS; by default the three above; the hold-tolerance variants ask what a looser
solver.hold_tolerance costs in labels). The machine and its load are printed with it.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import numpy as np
import pandas as pd

from rodphase.studytools import boundary_error, machine, sweep_table, timed_sweep, write_block

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "out" / "perf"
# name: (config, --set items)
METHODS = {"independent": ("configs/fig3_paper.yaml", []),
           "paths": ("configs/fig3_paths.yaml", []),
           "paths, 40 columns": ("configs/fig3_paths.yaml", ["sweep.columns=40"]),
           # the holds end when the residual creeps under the tolerance (docs/history/performance.md,
           # "A twist continuation beside the soft modes"): what a looser one costs in labels
           "independent, hold tolerance 3e-3": ("configs/fig3_paper.yaml",
                                                ["solver.hold_tolerance=3e-3"]),
           "paths, hold tolerance 3e-3": ("configs/fig3_paths.yaml",
                                          ["solver.hold_tolerance=3e-3"])}
DEFAULT_METHODS = ("independent", "paths", "paths, 40 columns")
REFERENCE_SET = ["sweep.seed=4242", "rod.elements=140", "solver.safety=0.25",
                 "loading.quasi_static_below=0", "loading.twist_rate=0.25"]
AXES = ("twist_density", "extension")
BOX = (np.array([0.0, 1.0]), np.array([2.6, 0.3]))  # Fig 3's box: lo, span of (Φa, L/L0)


def reference(samples: int, jobs: int) -> None:
    store = OUT / "map_reference.h5"
    wall, cpu = timed_sweep("configs/fig3_paper.yaml", store,
                            REFERENCE_SET + [f"sweep.samples={samples}"], jobs)
    table = sweep_table(store)
    info = {"wall": wall, "cpu": cpu, "samples": samples, "sets": REFERENCE_SET,
            "phases": table["phase"].value_counts().to_dict(), "machine": machine()}
    (OUT / "map_reference.json").write_text(json.dumps(info, indent=1))
    print(json.dumps(info, indent=1))


def compare(rounds: int, jobs: int, write: bool, methods=DEFAULT_METHODS,
            block: str = "map_methods") -> None:
    ref = sweep_table(OUT / "map_reference.h5")
    ref = ref[ref["phase"] != "failed"]
    rows = []
    before = machine()
    for r in range(rounds):
        for name in methods:
            config, sets = METHODS[name]
            store = OUT / f"map_{name.replace(', ', '_').replace(' ', '_')}_{r}.h5"
            store.unlink(missing_ok=True)
            wall, cpu = timed_sweep(config, store, sets, jobs)
            table = sweep_table(store)
            row = {"method": name, "round": r, "wall": wall, "cpu": cpu,
                   "failed": int((table["phase"] == "failed").sum()),
                   "phases": table["phase"].value_counts().to_dict(),
                   "error": boundary_error(ref, table, AXES, *BOX)}
            rows.append(row)
            print(row, flush=True)
    after = machine()
    (OUT / f"{block}.json").write_text(json.dumps(
        {"rows": rows, "machine_before": before, "machine_after": after,
         "reference": len(ref)}, indent=1))
    frame = pd.DataFrame(rows)
    lines = [f"Measured {machine_line(before, after)}; reference: {len(ref)} points "
             "(out/perf/map_reference.json).", "",
             "| method | round | wall [s] | CPU [s] | failed | boundary error | phases |",
             "|---|---|---|---|---|---|---|"]
    for row in rows:
        phases = ", ".join(f"{k} {v}" for k, v in sorted(row["phases"].items()))
        lines.append(f"| {row['method']} | {row['round']} | {row['wall']:.1f} | "
                     f"{row['cpu']:.1f} | {row['failed']} | {row['error']:.3f} | {phases} |")
    mean = frame.groupby("method")[["wall", "cpu", "error"]].mean()
    lines += ["", "Mean over the rounds (ratio: independent / method):", "",
              "| method | wall [s] | CPU [s] | wall ratio | CPU ratio | boundary error |",
              "|---|---|---|---|---|---|"]
    for name in methods:
        m = mean.loc[name]
        lines.append(f"| {name} | {m['wall']:.1f} | {m['cpu']:.1f} | "
                     f"{mean.loc['independent', 'wall'] / m['wall']:.2f} | "
                     f"{mean.loc['independent', 'cpu'] / m['cpu']:.2f} | {m['error']:.3f} |")
    text = "\n".join(lines)
    print(text)
    if write:
        write_block(ROOT / "docs" / "history" / "performance.md", block, text)


def machine_line(before: dict, after: dict) -> str:
    load = lambda m: " ".join(f"{x:.2f}" for x in m["load"])  # noqa: E731
    return (f"on {before['cpu']}, {before['nproc']} cores, load {load(before)} before and "
            f"{load(after)} after")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("step", choices=["reference", "compare"])
    parser.add_argument("--samples", type=int, default=60, help="reference: points")
    parser.add_argument("--rounds", type=int, default=2, help="compare: rounds")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--write", action="store_true", help="compare: update docs/history/performance.md")
    parser.add_argument("--methods", default=";".join(DEFAULT_METHODS),
                        help="compare: the methods, separated by ';', 'independent' among them "
                        f"(known: {'; '.join(METHODS)})")
    parser.add_argument("--block", default="map_methods",
                        help="compare: the block of docs/history/performance.md and the JSON's name")
    args = parser.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    os.chdir(ROOT)
    if args.step == "reference":
        reference(args.samples, args.jobs)
    else:
        methods = [name.strip() for name in args.methods.split(";") if name.strip()]
        unknown = [name for name in methods if name not in METHODS]
        if unknown or "independent" not in methods:
            parser.error(f"--methods: {args.methods!r} (allowed: names of {list(METHODS)}, "
                         "'independent' among them: the ratios are against it)")
        compare(args.rounds, args.jobs, args.write, methods, args.block)


if __name__ == "__main__":
    main()
