"""Phase-boundary error against run count: adaptive vs random sampling of the Fig 3 box.

    python studies/boundary_error.py REFERENCE.csv RANDOM.csv ADAPTIVE.csv

Each CSV is a classified table (`rodphase classify X.h5 --csv X.csv`) over the same box and
axes (the sweep's axis columns, between run_id and status): the reference a dense grid
(configs/fig3_paper_reference.yaml, 24 x 24 by continuation), the others the first k runs of
a random sweep (configs/fig3_paper.yaml) and of an adaptive one
(configs/fig3_paper_adaptive.yaml).
The error of k samples is the fraction of reference points whose phase the nearest of the
k samples (in coordinates scaled to the box) gets wrong: the area misplaced by the
boundary the k samples imply. Prints a Markdown table.
"""

import sys

import pandas as pd

from rodphase.studytools import boundary_error


def axes_of(table: pd.DataFrame) -> list[str]:
    columns = list(table.columns)
    return columns[columns.index("run_id") + 1:columns.index("status")]


def main(reference_csv, random_csv, adaptive_csv) -> None:
    reference = pd.read_csv(reference_csv)
    axes = axes_of(reference)
    reference = reference[reference["phase"] != "failed"]
    lo = reference[axes].min().to_numpy(float)
    span = reference[axes].max().to_numpy(float) - lo
    random = pd.read_csv(random_csv).sort_values("run_id")
    adaptive = pd.read_csv(adaptive_csv).sort_values("run_id")
    for table in (random, adaptive):
        if axes_of(table) != axes:
            sys.exit(f"axes differ: {axes_of(table)} against the reference's {axes}")
    print(f"reference: {len(reference)} points; phases {reference['phase'].value_counts().to_dict()}")
    print("| runs | random: boundary error | adaptive: boundary error |")
    print("|---|---|---|")
    def cell(table, k):
        return f"{boundary_error(reference, table.head(k), axes, lo, span):.3f}" if k <= len(table) else ""

    for k in range(10, max(len(random), len(adaptive)) + 1, 10):
        print(f"| {k} | {cell(random, k)} | {cell(adaptive, k)} |")


if __name__ == "__main__":
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    main(*sys.argv[1:])
