"""Critical twist density against extension from a classified sweep (paper Fig 3).

    python studies/critical_twist.py TABLE.csv [--column phi_a_rest] [--above 1.1]

Bins the runs by extension L/L0; in each bin the critical Φa is the midpoint between the
largest Φa still straight and the smallest Φa that buckled (any non-straight phase). A
straight line is fitted to the bins above `--above` (the paper expects Φ_c to grow
linearly with L/L0 at high extension); prints the bins, the slope, intercept and R².
"""

import argparse

import numpy as np
import pandas as pd


def critical_points(table: pd.DataFrame, column: str, bins: int):
    usable = table[table["phase"].isin(["straight", "plectoneme", "solenoid", "mixed"])]
    edges = np.linspace(usable["extension"].min(), usable["extension"].max(), bins + 1)
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        cell = usable[(usable["extension"] >= lo) & (usable["extension"] <= hi)]
        straight = cell[cell["phase"] == "straight"][column]
        buckled = cell[cell["phase"] != "straight"][column]
        if straight.empty or buckled.empty:
            continue
        below, above = straight.max(), buckled.min()
        if below < above:  # a clean bracket; otherwise the bin straddles hysteresis
            rows.append((0.5 * (lo + hi), 0.5 * (below + above), 0.5 * (above - below)))
    return pd.DataFrame(rows, columns=["extension", "critical", "half_gap"])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("table")
    parser.add_argument("--column", default="phi_a_rest",
                        help="phi_a_rest (the paper's Φa = θ·a0/L0) or phi_a_current")
    parser.add_argument("--above", type=float, default=1.1)
    parser.add_argument("--bins", type=int, default=10)
    args = parser.parse_args(argv)
    points = critical_points(pd.read_csv(args.table), args.column, args.bins)
    print("| L/L0 | critical Φa | ± |")
    print("|---|---|---|")
    for row in points.itertuples():
        print(f"| {row.extension:.3f} | {row.critical:.3f} | {row.half_gap:.3f} |")
    fit = points[points["extension"] > args.above]
    if len(fit) < 3:
        print(f"fewer than 3 bracketed bins above L/L0 = {args.above}: no fit")
        return
    slope, intercept = np.polyfit(fit["extension"], fit["critical"], 1)
    model = slope * fit["extension"] + intercept
    r2 = 1 - np.sum((fit["critical"] - model) ** 2) / np.sum(
        (fit["critical"] - fit["critical"].mean()) ** 2)
    print(f"fit above L/L0 = {args.above} ({len(fit)} bins, column {args.column}): "
          f"Φa_c = {slope:.3f}·(L/L0) + {intercept:.3f}, R² = {r2:.3f}")


if __name__ == "__main__":
    main()
