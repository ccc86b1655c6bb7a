"""Critical twist density against extension from a classified sweep (paper Fig 3).

    python studies/critical_twist.py TABLE.csv [--column phi_a_rest] [--above 1.1]

Prints the critical Φa per extension bin and the straight line fitted to the bins above
`--above` (rodphase.tabulate.critical_twist: the midpoint between the largest Φa still
straight and the smallest that buckled; the paper expects Φ_c to grow linearly with L/L0 at
high extension), its slope, intercept and R². `rodphase plot --kind phase` draws the same.
"""

import argparse

import pandas as pd

from rodphase.tabulate import critical_twist


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("table")
    parser.add_argument("--column", default="phi_a_rest",
                        help="phi_a_rest (the paper's Φa = θ·a0/L0) or phi_a_current")
    parser.add_argument("--above", type=float, default=1.1)
    parser.add_argument("--bins", type=int, default=10)
    args = parser.parse_args(argv)
    points = critical_twist(pd.read_csv(args.table), args.column, args.bins, args.above)
    print("| L/L0 | critical Φa | ± |")
    print("|---|---|---|")
    for row in points.itertuples():
        print(f"| {row.extension:.3f} | {row.critical:.3f} | {row.half_gap:.3f} |")
    if points.attrs["fit"] is None:
        print(f"fewer than 3 bracketed bins above L/L0 = {args.above}: no fit")
        return
    slope, intercept, r2, used, _ = points.attrs["fit"]
    print(f"fit above L/L0 = {args.above} ({used} bins, column {args.column}): "
          f"Φa_c = {slope:.3f}·(L/L0) + {intercept:.3f}, R² = {r2:.3f}")


if __name__ == "__main__":
    main()
