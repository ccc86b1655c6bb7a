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
import itertools
import json
import math
import os
import sys
from pathlib import Path

if __name__ == "__main__":
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

from rodphase.studytools import write_block

sys.path.insert(0, str(Path(__file__).resolve().parent))
import crosscheck_pyelastica as X  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
IMG = ROOT / "docs" / "img"
OUT = ROOT / "out" / "twist_into_writhe"
PAGE = ROOT / "docs" / "explanation" / "twist-into-writhe.md"

STEP_SAMPLE = 0.5  # s: the references' sampling; rodphase's 0.1-s rows are resampled to it

# One change at a time from the mapped settings (as-run twist, mapped contact, no holder
# bodies, rodphase's own time step). Each: (name, what changes, run options).
ROWS = {
    "solenoid": [
        ("mapped", "the example's settings mapped (the cross-check's run)", {}),
        ("no_thinning", "thinning force off (`contact.thinning_force=false`)",
         {"extra_sets": [("contact.thinning_force", False)]}),
        ("no_thinning_dt", "thinning force off, at the example's dt (2.5e-5 s)",
         {"extra_sets": [("contact.thinning_force", False)], "dt": "example"}),
        ("no_thinning_stiff", "thinning force off, contact spring ×10",
         {"extra_sets": [("contact.thinning_force", False), ("contact.stiffness", 10.0)]}),
        ("no_thinning_drag", "thinning force off, drag ×2",
         {"extra_sets": [("contact.thinning_force", False), ("solver.damping", 4.0)],
          "rotation_damping": str(2 * X.rotational_damping_equivalent("solenoid"))}),
        ("no_thinning_stiff_clamp", "thinning force off, contact spring ×10, clamp as PyElastica's",
         {"clamp": "pyelastica", "extra_sets": [("contact.thinning_force", False), ("contact.stiffness", 10.0)]}),
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
        ("rotation_damping_x2", "rotational damping ×2 (drag as mapped)",
         {"rotation_damping": str(2 * X.rotational_damping_equivalent("solenoid"))}),
        ("rotation_damping_half", "rotational damping ×½ (drag as mapped)",
         {"rotation_damping": str(0.5 * X.rotational_damping_equivalent("solenoid"))}),
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
# where "final" Wr and end height are read: the PlectonemesCase reference loses 2 turns of link
# around its bare start clamp at 46.3 s (docs/reproduction.md), so it is read before that
READ_AT = {"solenoid": None, "plectoneme": 45.0}
REFERENCES = {
    "solenoid": [("PyElastica 1.0", "crosscheck_solenoid.npz"),
                 ("PyElastica 1.0, dt 1e-4 s, twist prescribed as run", "crosscheck_solenoid_dt1e-4.npz"),
                 ("PyElastica 1.0 + thinning force (dt 1e-4 s, as run)", "crosscheck_solenoid_thinning.npz"),
                 ("PyElastica 1.0 with rodphase's contact law: split + thinning (dt 1e-4 s, as run)",
                  "crosscheck_solenoid_rodphase_law.npz"),
                 ("PyElastica 1.0 with rodphase's contact law, the example's dt and twist",
                  "crosscheck_solenoid_rodphase_law_dt_example.npz"),
                 ("PyElastica 1.0, rodphase's uniform stand-in for the kick (dt 1e-4 s, to 72 s)",
                  "crosscheck_solenoid_uniform_kick.npz")],
    "plectoneme": [("PyElastica 1.0", "crosscheck_plectoneme.npz")],
}


def row_path(case: str, name: str, out: Path = OUT) -> Path:
    return out / f"{case}_{name}.npz"


def run_row(case: str, name: str, out: Path = OUT, final_time: float | None = None) -> dict:
    options = dict(next(o for n, _, o in ROWS[case] if n == name))
    out.mkdir(parents=True, exist_ok=True)
    return X.run_rodphase(
        case, contact="example", dt=options.pop("dt", "auto"), twist="as-run", kick=options.pop("kick", "load"),
        rotation_damping=options.pop("rotation_damping", "example"), out=row_path(case, name, out),
        bodies=options.pop("bodies", "none"), kick_scale=options.pop("kick_scale", 1.0),
        final_time=final_time or FINAL_TIME[case], **options)


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
    steps = writhe_steps(ts[during], ws[during]) if during.sum() >= 3 else []  # a smoke test's moment
    link = r["link"]
    # a loop slipping over a bare clamp takes 2 turns of link in one sample (docs/reproduction.md)
    escapes = int(np.sum(np.diff(link) < -1.0))
    status = info.get("status", "ok")
    if status != "ok":
        status = f"unstable at {t[-1]:.1f} s"
    at = READ_AT[case] if READ_AT[case] is not None else t[-1]
    return {"onset": X.onset(t, wr), "steps": steps, "final_writhe": float(np.interp(at, t, wr)),
            "read_at": float(at),
            "escapes": escapes, "end_time": float(t[-1]),
            "final_end": float(np.interp(at, t, end)), "time": t, "writhe": wr, "end": end,
            "phase": info.get("phase", ""), "status": status}


def step_text(m: dict) -> str:
    if not m["steps"]:
        return "none"
    return ", ".join(f"{s['to_value']:.2f} @ {s['at']:.1f}" for s in m["steps"])


def table(case: str, out: Path = OUT) -> tuple[str, dict]:
    """Markdown table of the rows, PyElastica's first, and the measurements by row name."""
    lines = ["| code / change | status | link escapes | onset [s] | steps | Wr after each step (turns @ s) | "
             f"{'final' if READ_AT[case] is None else f'at {READ_AT[case]:g} s:'} Wr | end height [m] | "
             "Δ Wr vs PyElastica | Δ end vs PyElastica |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    found = {}
    base = None
    for label, file in REFERENCES[case]:
        p = DATA / file
        if p.exists():
            found[label] = measure(p, case)
            base = base or found[label]
    for name, label, _ in ROWS[case]:
        p = row_path(case, name, out)
        if p.exists():
            found[f"rodphase: {label}"] = measure(p, case)
    for label, m in found.items():
        dw = f"{100 * (m['final_writhe'] / base['final_writhe'] - 1):+.0f} %" if base else "–"
        de = f"{100 * (m['final_end'] / base['final_end'] - 1):+.0f} %" if base else "–"
        onset = "none" if math.isnan(m["onset"]) else f"{m['onset']:.1f}"
        lines.append(f"| {label} | {m['status']} | {m['escapes']} | {onset} | {len(m['steps'])} | {step_text(m)} | "
                     f"{m['final_writhe']:.2f} | {m['final_end']:.3f} | {dw} | {de} |")
    return "\n".join(lines), found


FIGURE_TIMES = {"solenoid": (59.0, 83.0), "plectoneme": (5.0, 50.0)}  # s: where the loops form
FIGURE_ROWS = ("mapped", "no_thinning", "clamp_pyelastica", "pyelastica_like", "damping_x2")
REFERENCE_STYLES = [dict(lw=2.8, color="k"), dict(lw=1.6, color="0.55", ls="--"),
                    dict(lw=1.6, color="0.35", ls=":"), dict(lw=1.6, color="0.7", ls="-."),
                    dict(lw=2.0, color="0.45", ls="--"), dict(lw=1.4, color="0.25", ls=(0, (1, 3))),
                    dict(lw=1.2, color="0.6", ls=(0, (5, 1, 1, 1)))]


def figure(case: str, found: dict, png: Path) -> None:
    """Wr(t) and the free end's height, PyElastica's runs in black and grey, rodphase's in colour
    (the rows of FIGURE_ROWS; the table has them all)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = X.settings(case)
    labels = {label: name for name, label, _ in ROWS[case]}
    fig, (axw, axe) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    refs = itertools.cycle(REFERENCE_STYLES)
    for label, m in found.items():
        name = labels.get(label.removeprefix("rodphase: "))
        if label.startswith("rodphase: "):
            if name not in FIGURE_ROWS:
                continue
            style = dict(lw=1.3)
        else:
            style = next(refs)
        tag = "" if m["status"] == "ok" else f" [{m['status']}]"
        axw.plot(m["time"], m["writhe"], label=label + tag, **style)
        axe.plot(m["time"], m["end"], **style)
    axe.set_xlim(*FIGURE_TIMES[case])
    axe.set_xlabel("t [s] (twist ends at "
                   f"{c['time_start_twist'] + c['time_twist']:.0f} s, then the end is clamped)")
    axw.set_ylabel("Wr [turns]")
    axe.set_ylabel("free end's height [m]")
    axw.set_title(f"{case.capitalize()}sCase: PyElastica 1.0 (black, grey) and rodphase (colour)")
    axw.legend(fontsize=6.5, loc="upper left")
    for ax in (axw, axe):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=100)
    plt.close(fig)


# ------------------------------------------------------------------ Fig 2a, 2b: rodphase's own scenes

FIG2 = {"fig2a": "fig2a_plectoneme", "fig2b": "fig2b_solenoid"}


def run_fig2(name: str) -> Path:
    """rodphase's shipped Fig 2 scene: Φa (rest) and Wr over its twist ramp."""
    from rodphase import config as C
    from rodphase.analysis import stage_rows, twist_density
    from rodphase.runner import run_scene
    from rodphase.scenes import SCENES

    r = run_scene(C.load_scene(FIG2[name], [], SCENES))
    rows = stage_rows(r, "twist")
    path = OUT / f"{name}_rodphase.npz"
    OUT.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, phi=twist_density(r)[rows], writhe=r.history["writhe"][rows],
                        info=json.dumps({"status": r.status, "scene": FIG2[name]}))
    return path


def fig2_steps(name: str) -> list[dict]:
    """Steps of Wr(Φa) in rodphase's Fig 2 scene, Φa resampled every 0.1 turn of twist
    (the cross-check's 0.5 s at 0.2 turns/s), as for the PyElastica cases."""
    from rodphase import units
    from rodphase.analysis import writhe_steps

    r = np.load(OUT / f"{name}_rodphase.npz")
    dphi = 0.1 * units.TURN * X.BASE_RADIUS / X.BASE_LENGTH  # Φa of 0.1 turn: 0.0157
    grid = np.arange(r["phi"][0], r["phi"][-1], dphi)
    return writhe_steps(grid, np.interp(grid, r["phi"], r["writhe"]))


# ------------------------------------------------------------------ Fig 4a: the pull

# run name -> the solenoid_loss scene's --set keys: the paper's 13 turns, the scene's 10.2, and 13
# with nothing beyond the clamps, as PyElastica's example (a loop can slip over a bare clamp)
FIG4A_RUNS = {
    "13.0": [("loading.twist_density", 2.042)],
    "10.2": [("loading.twist_density", 1.6)],
    "13.0, bare clamps": [("loading.twist_density", 2.042), ("ends.start_body", "none"),
                          ("ends.end_body", "none")],
}
# m of ΔU between writhe samples (2 s of the 5 mm/s pull): a turn comes off over 20–40 mm of ΔU,
# so finer samples split it into rises under the 0.3-turn threshold (at 2.5 mm: no step found
# in rodphase's 10.2-turn pull, at 5 mm one of its two, at 10 mm both, measured)
DU_SAMPLE = 0.01
FORCE_WINDOW = 0.01  # m of ΔU: the force is a 10 mm running mean before its drops are found
FORCE_DROP = 1.0  # F_C: a drop of the smoothed force counts when deeper (studies/figures.py)


def fig4a_path(turns: str) -> Path:
    return OUT / f"fig4a_rodphase_{turns.replace(', ', '_').replace(' ', '_')}.npz"


def run_fig4a_rodphase(turns: str) -> Path:
    """rodphase's shipped Fig 4a scene (solenoid_loss) at `turns`: ΔU, F/F_C, Wr of the pull."""
    from rodphase import config as C
    from rodphase.analysis import stage_rows
    from rodphase.runner import run_scene
    from rodphase.scenes import SCENES
    from rodphase.studytools import machine

    cfg = C.load_scene("solenoid_loss", FIG4A_RUNS[turns], SCENES)
    r = run_scene(cfg)
    h = r.history
    rows = np.where(stage_rows(r, "pull"))[0]
    fc = C.buckling_force(cfg)
    path = fig4a_path(turns)
    OUT.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        path, du=h["end_displacement"][rows] - h["end_displacement"][rows[0]],
        force=h["end_force"][rows] / fc, writhe=h["writhe"][rows], link=h["link"],
        link_time=h["time"], pull_start=h["time"][rows[0]],
        info=json.dumps({"status": r.status, "turns": turns, "sets": FIG4A_RUNS[turns],
                         "F_C": fc, "wall_time": r.diagnostics["wall_time"], "machine": machine()},
                        default=str))
    print(f"fig4a rodphase {turns} turns: {r.status}, wall {r.diagnostics['wall_time']:.0f} s -> {path}")
    return path


def fig4a_pyelastica(path: Path) -> dict:
    """ΔU, F/F_C and Wr of the pull in the PyElastica reference (case solenoid_pull).

    The end node is held, so the puller's force is what holds it against the rod: minus the
    node's internal force minus the contact force on it, i.e. −(internal + external − 300 N)
    along the axis, the 300 N of EndpointForces counted as the puller's."""
    r = np.load(path)
    c = json.loads(str(r["info"]))["settings"]  # the run's own (its turns may differ)
    t_pull = c["time_start_twist"] + c["time_twist"] + c["time_relax"]
    t = r["force_time"]
    pull = t >= t_pull
    y = r["end_position_all"][:, 1]
    force = -(r["internal_end"][:, 1] + r["external_end"][:, 1] - c["force"])
    fc = math.pi**2 * X.E * math.pi * X.BASE_RADIUS**4 / 4 / X.BASE_LENGTH**2  # 3.028 N
    du = y[pull] - y[pull][0]
    tw = r["time"] >= t_pull
    du_w = np.interp(r["time"][tw], t, y) - y[pull][0]
    return {"du": du, "force": force[pull] / fc, "du_writhe": du_w, "writhe": r["writhe"][tw],
            "link_start": float(np.interp(t_pull, r["time"], r["link"])), "turns": float(c["turns"]),
            "final_time": float(t[-1]),
            "complete": bool(t[-1] >= c.get("final_time_requested", c["final_time"]) - 0.1)}



def fig4a_rodphase_example(path: Path) -> dict:
    """ΔU, F/F_C and Wr of the pull in rodphase run with the example's settings (the
    crosscheck's `rodphase solenoid_pull --twist nominal`): the reaction of the held end is the
    history's end_force, the writhe the reference's estimator on 0.1-s snapshots."""
    r = np.load(path)
    info = json.loads(str(r["info"]))
    labels = [s["label"] for s in info.get("stages", [])] if "stages" in info else None
    pull = r["stage"] == (max(r["stage"]) if labels is None else labels.index("pull"))
    t = r["time"]
    fc = math.pi**2 * X.E * math.pi * X.BASE_RADIUS**4 / 4 / X.BASE_LENGTH**2
    u = r["end_displacement"][pull] - r["end_displacement"][pull][0]
    t0 = t[pull][0]
    return {"du": u, "force": r["end_force"][pull] / fc,
            "writhe": np.interp(t[pull], t, r["writhe"]),
            "link_start": float(np.interp(t0, t, r["link"]))}


def fig4a_measure(du, force, du_w, writhe) -> dict:
    from rodphase.analysis import sawtooth_drops, smooth, writhe_steps

    step = float(np.median(np.diff(du)))
    window = max(1, int(round(FORCE_WINDOW / step)))
    fs = smooth(force, window)
    drops = sawtooth_drops(du, fs, window, min_drop=FORCE_DROP, merge=0.03)
    grid = np.arange(0.0, du_w[-1] + 1e-12, DU_SAMPLE)
    w = np.interp(grid, du_w, writhe)
    losses = writhe_steps(grid, w, direction=-1) if len(grid) >= 3 else []
    return {"smoothed": fs, "drops": drops, "losses": losses,
            "writhe_start": float(writhe[0]), "writhe_end": float(writhe[-1])}


def fig4a(png: Path) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = {}
    ref = DATA / "crosscheck_solenoid_pull.npz"
    if ref.exists():
        pe = fig4a_pyelastica(ref)
        tag = "" if pe["complete"] else f" (to ΔU {pe['du'][-1]:.2f} m)"
        runs[f"PyElastica 1.0, example's settings, 13 turns{tag}"] = (
            pe["du"], pe["force"], pe["du_writhe"], pe["writhe"], pe["link_start"])
    ref10 = DATA / "crosscheck_solenoid_pull_10.npz"
    if ref10.exists():
        pe = fig4a_pyelastica(ref10)
        tag = "" if pe["complete"] else f" (to ΔU {pe['du'][-1]:.2f} m)"
        runs[f"PyElastica 1.0, example's settings, 10.2 turns{tag}"] = (
            pe["du"], pe["force"], pe["du_writhe"], pe["writhe"], pe["link_start"])
    for turns, file in (("13", "fig4a_rodphase_example_13.npz"), ("10.19", "fig4a_rodphase_example_10.npz")):
        p = OUT / file
        if p.exists():
            rp = fig4a_rodphase_example(p)
            runs[f"rodphase, example's settings (as PyElastica's), {turns} turns"] = (
                rp["du"], rp["force"], rp["du"], rp["writhe"], rp["link_start"])
    for turns in FIG4A_RUNS:
        p = fig4a_path(turns)
        if p.exists():
            r = np.load(p)
            count, *rest = turns.split(", ")
            label = ", ".join([f"rodphase solenoid_loss, {count} turns"] + rest)
            link = float(np.interp(r["pull_start"], r["link_time"], r["link"])) if "link" in r.files else math.nan
            runs[label] = (r["du"], r["force"], r["du"], r["writhe"], link)
    fig, (axf, axw) = plt.subplots(2, 1, figsize=(7.5, 7), sharex=True)
    lines = ["| run | Lk at the pull's start | force drops > 1 F_C (F_C @ ΔU m) | "
             "writhe-loss steps ≥ 0.3 turns (turns @ ΔU m) | Wr start → end | F start → end (F_C, 10 mm mean) |",
             "|---|---|---|---|---|---|"]
    for label, (du, f, du_w, w, link) in runs.items():
        m = fig4a_measure(du, f, du_w, w)
        drops = ", ".join(f"{d['peak_y'] - d['bottom_y']:.1f} @ {d['peak_x']:.3f}" for d in m["drops"]) or "none"
        losses = ", ".join(f"{s['gain']:.2f} @ {s['at']:.3f}" for s in m["losses"]) or "none"
        lines.append(f"| {label} | {link:.2f} | {len(m['drops'])}: {drops} | {len(m['losses'])}: {losses} | "
                     f"{m['writhe_start']:.2f} → {m['writhe_end']:.2f} | "
                     f"{m['smoothed'][0]:.1f} → {m['smoothed'][-1]:.1f} |")
        if label.startswith("rodphase solenoid_loss, 13.0"):
            continue  # in the table; its line lies under the example-settings 13-turn one
        base, = axf.plot(du, m["smoothed"], lw=1.5, label=label)
        axf.plot(du, f, lw=0.4, alpha=0.35, color=base.get_color())
        for d in m["drops"]:
            axf.annotate("", (d["bottom_x"], d["bottom_y"]), (d["peak_x"], d["peak_y"]),
                         arrowprops={"arrowstyle": "->", "color": base.get_color(), "lw": 1.2})
        axw.plot(du_w, w, lw=1.5, color=base.get_color(), label=label)
    axf.set_ylabel("end force F/F_C (thin: raw; thick: 10 mm mean)")
    axw.set_ylabel("Wr [turns]")
    axw.set_xlabel("end displacement ΔU [m] (pulled at 5 mm/s, end rotation held)")
    axf.legend(fontsize=7)
    axf.set_title("Fig 4a: a solenoid at 99 F_C pulled, PyElastica 1.0 and rodphase")
    for ax in (axf, axw):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("rows", help="run rodphase's rows of CASE (skips those already in out/)")
    a.add_argument("case", choices=sorted(ROWS))
    a.add_argument("--only", nargs="*", default=None, help="row names")
    a.add_argument("--again", action="store_true", help="run rows already stored")
    a.add_argument("--final-time", type=float, default=None, help="stop early (s; a smoke test)")
    a.add_argument("--out", type=Path, default=OUT, help="directory of the rows' records")
    b = sub.add_parser("table", help="print the table of CASE and draw its figure")
    b.add_argument("case", choices=sorted(ROWS))
    b.add_argument("--png", type=Path, default=None)
    b.add_argument("--out", type=Path, default=OUT, help="directory of the rows' records")
    b.add_argument("--write", type=Path, default=None, help=f"write the table into its block of this page ({PAGE.relative_to(ROOT)})")
    f = sub.add_parser("fig4a", help="the pulled solenoid: rodphase's runs (if missing) and the figure")
    f.add_argument("--run", action="store_true", help="run rodphase's 13- and 10.2-turn pulls again")
    f.add_argument("--png", type=Path, default=None)
    f.add_argument("--write", type=Path, default=None, help="write the table into its block of this page")
    g = sub.add_parser("fig2", help="steps of Wr(Φa) in rodphase's Fig 2a and 2b scenes")
    g.add_argument("--run", action="store_true", help="run the scenes again")
    g.add_argument("--write", type=Path, default=None, help="write the counts into their block of this page")
    args = ap.parse_args(argv)
    if args.cmd == "fig2":
        lines = ["| figure | rodphase scene | steps ≥ 0.3 turns | rise, Wr after it, Φa (rest) |",
                 "|---|---|---|---|"]
        for name in FIG2:
            if args.run or not (OUT / f"{name}_rodphase.npz").exists():
                run_fig2(name)
            steps = fig2_steps(name)
            lines.append(f"| {name} | `{FIG2[name]}` | {len(steps)} | " + (", ".join(
                f"+{st['gain']:.2f} to {st['to_value']:.2f} @ Φa {st['at']:.3f}" for st in steps) or "none")
                + " |")
        print("\n".join(lines))
        if args.write:
            write_block(args.write, "fig2-steps", "\n".join(lines))
        return 0
    if args.cmd == "fig4a":
        for turns in FIG4A_RUNS:
            if args.run or not fig4a_path(turns).exists():
                run_fig4a_rodphase(turns)
        for case, file in (("solenoid_pull", "fig4a_rodphase_example_13.npz"),
                           ("solenoid_pull_10", "fig4a_rodphase_example_10.npz")):
            if args.run or not (OUT / file).exists():
                # the example's settings mapped, the 13 (10.19) turns put in as PyElastica's pull run
                X.run_rodphase(case, contact="example", dt="auto", twist="nominal", kick="load",
                               rotation_damping="example", out=OUT / file)
        text = fig4a(args.png or IMG / "twist_into_writhe_fig4a.png")
        print(text)
        if args.write:
            write_block(args.write, "fig4a-table", text)
        return 0
    if args.cmd == "rows":
        for name, label, _ in ROWS[args.case]:
            if args.only and name not in args.only:
                continue
            if row_path(args.case, name, args.out).exists() and not args.again:
                print(f"{name}: stored ({row_path(args.case, name, args.out)})")
                continue
            print(f"{name}: {label}", flush=True)
            run_row(args.case, name, args.out, args.final_time)
        return 0
    if args.cmd == "table":
        text, found = table(args.case, args.out)
        print(text)
        if args.write:
            write_block(args.write, f"{args.case}-table", text)
        figure(args.case, found, args.png or IMG / f"twist_into_writhe_{args.case}.png")
        return 0
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
