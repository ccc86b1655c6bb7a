#!/usr/bin/env python
"""Fig 3 under one change of physics or protocol at a time, point by point against the map as
it ships: the paper's claims of issue #29 item 4 (shear, G, damping, friction, the law), and
the contact thinning force that item 1 found behind the map's failures.

    python studies/map_variants.py VARIANT [VARIANT ...] [--samples 200] [--jobs 2]
        [--out out/variants] [--write docs/history/fig3-corner.md] [--figure docs/img/X.png]
        [--set KEY=VALUE ...]

Each variant is the shipped configs/fig3_paper.yaml with a few keys set (VARIANTS below); the
sweeps share the config's scrambled Sobol points, so the i-th run of each is the same
(Φa, L/L0), and a label that differs from the default's is a label the change moved. The
default sweep is run too (or resumed: stores go to --out and are resumed when rerun). Per
variant the table gives the phase counts, failures, labels as the default's, the points that
moved, and the cost (steps summed over the runs: a measure of work the machine's load does
not change; and the runs' own times). `--write` puts the table into a document between
`<!-- map_variants_NAME:begin/end -->` markers, NAME the variants joined by "_"; `--figure`
draws the maps side by side. `--set` applies to every sweep (a smoke test makes them small).
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


def _shear_stiffness() -> float:
    """The shipped scene's shear stiffness S = 4GA0/3 [N] (G = 2E/3), from the engine."""
    from rodphase import config as C
    from rodphase.scenes import SCENES, rod_from

    return rod_from(C.load_scene("twist_under_load", [], SCENES)).shear_stiffness


def variants() -> dict[str, tuple[str, list[str]]]:
    """name → (what it changes, its --set items)."""
    s = _shear_stiffness()
    return {
        "shear_x10": ("shear stiffness × 10", [f"material.shear_stiffness={10 * s!r}"]),
        "shear_x100": ("shear stiffness × 100", [f"material.shear_stiffness={100 * s!r}"]),
        "g_e3": ("G = E/3", ["material.shear_modulus=333333.3333333333"]),
        "damping_half": ("damping 10/s", ["solver.damping=10"]),
        "damping_twice": ("damping 40/s", ["solver.damping=40"]),
        "no_drag": ("no quadratic drag", ["solver.quadratic_drag=0"]),
        "friction_0.2": ("friction μ = 0.2", ["physics.friction=0.2"]),
        "friction_0.5": ("friction μ = 0.5", ["physics.friction=0.5"]),
        # the contact spring's pull along thinning elements, which PyElastica's contact has
        # not (docs/history/fig3-corner.md, "The four against the authors' code")
        "no_thinning": ("no contact thinning force", ["contact.thinning_force=false"]),
        # the straight start is the paper law's; this law starts from rest
        "neo_hookean": ("neo-Hookean law", ["material.law=neo_hookean",
                                            "loading.quasi_static_below=0"]),
    }


def sweep(path: Path, sets: list[str], samples: int, jobs: int) -> None:
    """Run (or resume) one sweep of CONFIG and classify it."""
    classified_sweep(CONFIG, path, [f"sweep.samples={samples}"] + sets, jobs)


def compare(default, table) -> tuple[int, list[str]]:
    """(labels as the default's, the points that moved: 'Φa, L/L0: default → this')."""
    if not same_points(table, default):
        raise SystemExit("a variant's points are not the default's")
    same = table["phase"].to_numpy() == default["phase"].to_numpy()
    moved = [f"{a['twist_density']:.2f}, {a['extension']:.3f}: {a['phase']} → {b['phase']}"
             for (_, a), (_, b), ok in zip(default.iterrows(), table.iterrows(), same) if not ok]
    return int(same.sum()), moved


def row(label: str, table, agree: int | None, moved: list[str]) -> str:
    counts = table["phase"].value_counts()
    phases = ", ".join(f"{name} {int(counts.get(name, 0))}" for name in
                       ("straight", "plectoneme", "solenoid", "mixed", "failed"))
    statuses = ", ".join(f"{k} {v}" for k, v in table["status"].value_counts().sort_index().items())
    listed = "; ".join(moved[:12]) + (f"; … ({len(moved) - 12} more)" if len(moved) > 12 else "")
    same = "—" if agree is None else f"{agree}/{len(table)}"
    return (f"| {label} | {phases} | {statuses} | {same} | {listed or '—'} | "
            f"{table['steps'].sum() / 1e6:.2f} | {float(np.nansum(table['wall_time'])):.0f} |")


def draw(path: Path, tables: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rodphase import plot as P

    fig, axes = plt.subplots(1, len(tables), figsize=(4.6 * len(tables), 4.2), squeeze=False)
    for ax, (label, table) in zip(axes[0], tables.items()):
        P.phase_map(table, ax=ax, title=label)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"written {path}")


def main(argv=None) -> int:
    known = variants()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("variants", nargs="+", choices=sorted(known), metavar="VARIANT",
                        help="one or more of: " + ", ".join(known))
    parser.add_argument("--samples", type=int, default=200)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "variants",
                        help="folder of the stores")
    parser.add_argument("--write", type=Path, action="append", default=[])
    parser.add_argument("--figure", type=Path)
    parser.add_argument("--set", dest="sets", action="append", default=[],
                        help="KEY=VALUE for every sweep (repeatable)")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)

    default_path = args.out / f"default_{args.samples}.h5"
    sweep(default_path, args.sets, args.samples, args.jobs)
    default = sweep_table(default_path)
    tables = {"as it ships": default}
    rows = ["| map | phases | statuses | labels as the default's | points that moved (Φa, "
            "L/L0: default → this) | steps [M] | run time [s] |",
            "|---|---|---|---|---|---|---|", row("as it ships", default, None, [])]
    for name in args.variants:
        label, sets = known[name]
        path = args.out / f"{name}_{args.samples}.h5"
        sweep(path, sets + args.sets, args.samples, args.jobs)
        table = sweep_table(path)
        agree, moved = compare(default, table)
        rows.append(row(label, table, agree, moved))
        tables[label] = table
    m = machine()
    text = "\n".join(rows) + (
        f"\n\nThe first {args.samples} points of `{CONFIG}` (n = 80, refined to 160 where a guard "
        f"asks), each map with its one change (`studies/map_variants.py "
        f"{' '.join(args.variants)}`); run time is the sum of the runs' own wall_time in their "
        f"workers (a busy machine inflates it; steps do not depend on load). Machine: "
        f"{m['cpu']}, {m['nproc']} CPUs, load at the end "
        + " ".join(f"{v:.2f}" for v in m["load"]) + ".")
    print(text)
    for target in args.write:
        write_block(target, "map_variants_" + "_".join(args.variants), text)
    if args.figure:
        draw(args.figure, tables)
    return 0


if __name__ == "__main__":
    sys.exit(main())
