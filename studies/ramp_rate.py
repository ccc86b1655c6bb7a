#!/usr/bin/env python
"""Fig 3's twist ramp faster: labels and cost at several twist rates against a fine reference.

    python studies/ramp_rate.py [--samples 40] [--rates 0.5,1,2,4] [--jobs 2] [--write docs/history/performance.md]
        [--out out/ramp] [--set KEY=VALUE ...]

Most of a Fig 3 sweep's steps are in the twist ramp (81 % of 40 M at 0.5 turns/s, issue #16).
A faster ramp costs fewer steps but can overshoot the onset (a dynamic buckling lags the
quasi-static one) and settle into another branch. This runs the first --samples points of
configs/fig3_paper.yaml (the random sampler draws the same first points for any count) at each
rate, and once at the scene's rate with the finer reference settings (n = 140, safety 0.25),
then reports per rate: steps summed over the runs (a measure of work that does not depend on
the machine or its load), the runs' own times summed, the sweep's wall time, statuses, and label agreement with the
reference point by point. Stores go to --out (out/ramp/) and are resumed when rerun; `--set`
applies to every sweep, the reference too (after its own settings: a smoke test makes them
all coarse).

Since 2026-12-03 the config starts its runs on the straight branch (loading.quasi_static_below
0.8), so the rate variants ramp from 0.8 of the buckling twist; the reference keeps the whole
protocol. The table in docs/history/performance.md was measured before, with the whole protocol in
every row (to repeat it, add "loading.quasi_static_below=0" to each rate's sets in main()).
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import sys
from pathlib import Path

import numpy as np

from rodphase.studytools import classified_sweep, machine, same_points, sweep_table, write_block

ROOT = Path(__file__).resolve().parents[1]
CONFIG = "fig3_paper"
REFERENCE_SET = ["rod.elements=140", "solver.safety=0.25", "loading.quasi_static_below=0"]


def sweep(path: Path, sets: list[str], samples: int, jobs: int) -> float:
    """Run (or resume) one sweep and classify it; returns its wall time in seconds (NaN for a
    store that existed: the sweep's own time is in the table written then)."""
    resumed = path.exists()  # its wall time would be the resume's, not the sweep's
    wall = classified_sweep(CONFIG, path, [f"sweep.samples={samples}"] + sets, jobs)
    return float("nan") if resumed else wall


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=40)
    parser.add_argument("--rates", default="0.5,1,2,4", help="turns/s, comma-separated")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--write", type=Path, action="append", default=[])
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "ramp", help="folder of the stores")
    parser.add_argument("--set", dest="sets", action="append", default=[],
                        help="KEY=VALUE for every sweep (repeatable)")
    args = parser.parse_args(argv)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    rates = [float(r) for r in args.rates.split(",")]

    ref_path = out / f"reference_{args.samples}.h5"
    walls = {"reference": sweep(ref_path, REFERENCE_SET + args.sets, args.samples, args.jobs)}
    for rate in rates:
        path = out / f"rate_{rate:g}_{args.samples}.h5"
        walls[rate] = sweep(path, [f"loading.twist_rate={rate:g}"] + args.sets, args.samples,
                            args.jobs)

    ref = sweep_table(ref_path)
    rows = ["| twist rate [turns/s] | runs | steps [M] | run time [s] | sweep wall [s] | statuses | "
            "labels as the reference | disagreeing points (Φa, L/L0: this → reference) |",
            "|---|---|---|---|---|---|---|---|"]
    for name in ["reference"] + rates:
        path = ref_path if name == "reference" else out / f"rate_{name:g}_{args.samples}.h5"
        t = sweep_table(path)
        cpu = float(np.nansum(t["wall_time"]))  # each run's own time in its worker
        statuses = ", ".join(f"{k} {v}" for k, v in t["status"].value_counts().sort_index().items())
        if not same_points(t, ref):
            raise SystemExit(f"{path}: its points are not the reference's")
        agree = (t["phase"].to_numpy() == ref["phase"].to_numpy())
        differ = "; ".join(f"{a['twist_density']:.2f}, {a['extension']:.3f}: {a['phase']} → "
                           f"{b['phase']}" for (_, a), (_, b), ok in
                           zip(t.iterrows(), ref.iterrows(), agree) if not ok) or "—"
        label = ("reference (0.5, n = 140, safety 0.25)" if name == "reference" else f"{name:g}")
        rows.append(f"| {label} | {len(t)} | {t['steps'].sum() / 1e6:.2f} | {cpu:.0f} | "
                    f"{walls[name]:.0f} | {statuses} | {int(agree.sum())}/{len(t)} | {differ} |")
    m = machine()
    note = (f"Machine: {m['cpu']}, {m['nproc']} CPUs, load at the end "
            + " ".join(f"{v:.2f}" for v in m["load"]) + ".")
    text = "\n".join(rows) + (
        f"\n\nFirst {args.samples} points of `{CONFIG}` (n = 80 unless refined), `--jobs "
        f"{args.jobs}`; run time is the sum of the runs' own wall_time in their workers (a "
        f"busy machine inflates it; steps do not depend on load). "
        f"{note}")
    print(text)
    for target in args.write:
        write_block(target, "ramp_rate", text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
