"""Twist into writhe in steps (issue #49): rodphase against the authors' code, one change at a time.

    python studies/twist_into_writhe.py rows solenoid      # rodphase's rows (minutes each)
    python studies/twist_into_writhe.py rows plectoneme
    python studies/twist_into_writhe.py table solenoid     # table + docs/img/twist_into_writhe_solenoid.png
    python studies/twist_into_writhe.py fig4a              # the pulled 13-turn solenoid, both codes

The PyElastica references are the cached records of studies/crosscheck_pyelastica.py in
tests/data (`crosscheck_solenoid.npz`, `crosscheck_solenoid_thinning.npz`,
`crosscheck_plectoneme.npz`, `crosscheck_solenoid_pull.npz`); rodphase's rows are run here
with that module's mapping of the examples' settings, one setting changed per row.

Steps are counted by `rodphase.analysis.writhe_steps` on Wr resampled every
`STEP_SAMPLE` seconds (the references' 0.5 s), with its stated threshold.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

if __name__ == "__main__":
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import crosscheck_pyelastica as X  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
IMG = ROOT / "docs" / "img"
OUT = ROOT / "out" / "twist_into_writhe"

STEP_SAMPLE = 0.5  # s: the references' sampling; rodphase's 0.1-s rows are resampled to it

# One change at a time from the mapped settings (as-run twist, mapped contact, no holder
# bodies, rodphase's own time step). Each: (name, what changes, run options).
ROWS = {
    "solenoid": [
        ("mapped", "the example's settings mapped (the cross-check's run)", {}),
        ("no_thinning", "thinning force off (`contact.thinning_force=false`)",
         {"extra_sets": [("contact.thinning_force", False)]}),
        ("no_fold", "fold contact off (`contact.fold=false`)",
         {"extra_sets": [("contact.fold", False)]}),
        ("clamp_pyelastica", "clamp as PyElastica's (rigid end elements: n−2 elements, L−2l)",
         {"clamp": "pyelastica"}),
        ("kick_none", "no kick", {"kick": "none"}),
        ("kick_x10", "kick load ×10", {"kick_scale": 10.0}),
        ("stiff_x10", "contact spring ×10 (rodphase's default, 10)",
         {"extra_sets": [("contact.stiffness", 10.0)]}),
        ("dashpot_0", "contact dashpot 0", {"extra_sets": [("contact.damping_ratio", 0.0)]}),
        ("damping_x2", "drag ×2 (4 /s, rotation 2× too)",
         {"extra_sets": [("solver.damping", 4.0)], "rotation_damping": str(2 * X.rotational_damping_equivalent("solenoid"))}),
        ("damping_half", "drag ×½ (1 /s, rotation ½ too)",
         {"extra_sets": [("solver.damping", 1.0)], "rotation_damping": str(0.5 * X.rotational_damping_equivalent("solenoid"))}),
        ("pyelastica_like", "thinning off + fold off + clamp as PyElastica's",
         {"clamp": "pyelastica", "extra_sets": [("contact.thinning_force", False), ("contact.fold", False)]}),
    ],
    "plectoneme": [
        ("mapped", "the example's settings mapped (holder bodies on, as the cross-check ships)",
         {"bodies": "rod"}),
        ("no_thinning", "thinning force off", {"bodies": "rod", "extra_sets": [("contact.thinning_force", False)]}),
        ("no_fold", "fold contact off", {"bodies": "rod", "extra_sets": [("contact.fold", False)]}),
        ("clamp_pyelastica", "clamp as PyElastica's (n−2 elements, L−2l)", {"bodies": "rod", "clamp": "pyelastica"}),
        ("pyelastica_like", "thinning off + fold off + clamp as PyElastica's",
         {"bodies": "rod", "clamp": "pyelastica",
          "extra_sets": [("contact.thinning_force", False), ("contact.fold", False)]}),
    ],
}
FINAL_TIME = {"solenoid": 85.0, "plectoneme": 60.0}  # the shape is settled by then in both codes
REFERENCES = {
    "solenoid": [("PyElastica 1.0", "crosscheck_solenoid.npz"),
                 ("PyElastica 1.0 + thinning force", "crosscheck_solenoid_thinning.npz")],
    "plectoneme": [("PyElastica 1.0", "crosscheck_plectoneme.npz")],
}


def row_path(case: str, name: str) -> Path:
    return OUT / f"{case}_{name}.npz"


def run_row(case: str, name: str) -> dict:
    options = dict(next(o for n, _, o in ROWS[case] if n == name))
    OUT.mkdir(parents=True, exist_ok=True)
    return X.run_rodphase(
        case, contact="example", dt="auto", twist="as-run", kick=options.pop("kick", "load"),
        rotation_damping=options.pop("rotation_damping", "example"), out=row_path(case, name),
        bodies=options.pop("bodies", "none"), kick_scale=options.pop("kick_scale", 1.0),
        final_time=FINAL_TIME[case], **options)


# ------------------------------------------------------------------ measurements


def resampled(t, y, step=STEP_SAMPLE):
    grid = np.arange(math.ceil(t[0] / step) * step, t[-1] + 1e-9, step)
    return grid, np.interp(grid, t, y)


def measure(path: Path, case: str) -> dict:
    """Onset, steps of Wr(t) during the twist and their writhe, final Wr and end height."""
    from rodphase.analysis import writhe_steps

    r = np.load(path)
    info = json.loads(str(r["info"]))
    t, wr = r["time"], r["writhe"]
    end = r["end_position"][:, 1]  # PyElastica's axis (y); rodphase's records are mapped to it
    if info.get("clamp") == "pyelastica":
        # the emulated rod lacks the two rigid end elements: put PyElastica's back, each one
        # stretched element long as the straight rod's elements are before buckling
        n = X.settings(case)["n_elem"]
        stretch = end[0] / (X.BASE_LENGTH * (n - 2) / n) if end[0] > 0.5 else 1.0
        end = end + 2 * X.BASE_LENGTH / n * stretch
    c = X.settings(case)
    twist_end = c["time_start_twist"] + c["time_twist"]
    ts, ws = resampled(t, wr)
    during = ts <= twist_end + 1.0
    steps = writhe_steps(ts[during], ws[during])
    return {"onset": X.onset(t, wr), "steps": steps, "final_writhe": float(wr[-1]),
            "final_end": float(end[-1]), "time": t, "writhe": wr,
            "phase": info.get("phase", ""), "status": info.get("status", "ok")}


def step_text(m: dict) -> str:
    if not m["steps"]:
        return "none"
    return ", ".join(f"{s['to_value']:.2f} @ {s['at']:.1f}" for s in m["steps"])


def table(case: str) -> tuple[str, dict]:
    """Markdown table of the rows, PyElastica's first, and the measurements by row name."""
    lines = ["| code / change | onset [s] | steps | Wr after each step (turns @ s) | final Wr | "
             "end height [m] | Δ final Wr vs PyElastica | Δ end vs PyElastica |",
             "|---|---|---|---|---|---|---|---|"]
    found = {}
    base = None
    for label, file in REFERENCES[case]:
        p = DATA / file
        if p.exists():
            found[label] = measure(p, case)
            base = base or found[label]
    for name, label, _ in ROWS[case]:
        p = row_path(case, name)
        if p.exists():
            found[f"rodphase: {label}"] = measure(p, case)
    for label, m in found.items():
        dw = f"{100 * (m['final_writhe'] / base['final_writhe'] - 1):+.0f} %" if base else "–"
        de = f"{100 * (m['final_end'] / base['final_end'] - 1):+.0f} %" if base else "–"
        lines.append(f"| {label} | {m['onset']:.1f} | {len(m['steps'])} | {step_text(m)} | "
                     f"{m['final_writhe']:.2f} | {m['final_end']:.3f} | {dw} | {de} |")
    return "\n".join(lines), found


def figure(case: str, found: dict, png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = X.settings(case)
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for label, m in found.items():
        style = dict(lw=2.5, color="k") if label == "PyElastica 1.0" else dict(lw=1.2)
        if "PyElastica" in label and label != "PyElastica 1.0":
            style = dict(lw=2.0, color="0.5", ls="--")
        ax.plot(m["time"], m["writhe"], label=label, **style)
    start = c["time_start_twist"] + c["time_twist"] * 0.7
    ax.set_xlim(start, c["time_start_twist"] + c["time_twist"] + 5)
    ax.set_xlabel("t [s] (twist at 0.2 turns/s nominal until "
                  f"{c['time_start_twist'] + c['time_twist']:.0f} s)")
    ax.set_ylabel("Wr [turns]")
    ax.set_title(f"{case.capitalize()}sCase: writhe, PyElastica 1.0 and rodphase, one change at a time")
    ax.legend(fontsize=7, loc="upper left")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("rows", help="run rodphase's rows of CASE (skips those already in out/)")
    a.add_argument("case", choices=sorted(ROWS))
    a.add_argument("--only", nargs="*", default=None, help="row names")
    a.add_argument("--again", action="store_true", help="run rows already stored")
    b = sub.add_parser("table", help="print the table of CASE and draw its figure")
    b.add_argument("case", choices=sorted(ROWS))
    b.add_argument("--png", type=Path, default=None)
    args = ap.parse_args(argv)
    if args.cmd == "rows":
        for name, label, _ in ROWS[args.case]:
            if args.only and name not in args.only:
                continue
            if row_path(args.case, name).exists() and not args.again:
                print(f"{name}: stored ({row_path(args.case, name)})")
                continue
            print(f"{name}: {label}", flush=True)
            run_row(args.case, name)
        return 0
    if args.cmd == "table":
        text, found = table(args.case)
        print(text)
        figure(args.case, found, args.png or IMG / f"twist_into_writhe_{args.case}.png")
        return 0
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
