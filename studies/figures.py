"""Run the paper's scenes and draw their figures: `python studies/figures.py --out DIR`.

Each figure is one or two shipped scenes (rodphase/configs/scenes/). Its runs go to
DIR/<fig>.h5 (one group per run, readable with `rodphase plot`), its pictures to
DIR/<fig>.png (the paper's panel) and DIR/<fig>_shape.png (rod snapshots), and the numbers
that docs/explanation/validation.md quotes to DIR/<fig>.json. `--only fig2a,fig4a` picks some;
`--set key=value` applies to every scene (e.g. --set rod.elements=60 for a quick look);
`--replot` redraws from existing .h5 files without simulating.

    fig2a  Lk, Tw, Wr vs Φa at 25 F_C: a plectoneme           (fig2a_plectoneme)
    fig2b  the same at 90 F_C, L/L0 ≈ 1.16: a solenoid        (fig2b_solenoid)
    fig4a  a solenoid at 99 F_C pulled by ΔU: force sawtooth  (solenoid_loss)
    fig4b  116 F_C, E ramped up: ΔU and ΔWr in steps          (stiffening)
    fig4c  coiled muscle, radius ×2: homo- vs heterochiral    (muscle, both chiralities)
    figS9  an active agent relaxes the tension locally        (active_agent)
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from rodphase import __version__, units
from rodphase import config as C
from rodphase.analysis import (
    bursts,
    coil_height,
    free_coil_height,
    local_alignment,
    plectoneme_turns,
    sawtooth_drops,
    smooth,
    solenoid_geometry,
    stage_rows,
)
from rodphase.analysis import twist_density as phi_a
from rodphase.result import rotation_put_in
from rodphase.scenes import SCENES

# figure → [(run id, scene, overrides)]
FIGURES: dict[str, list[tuple[str, str, list]]] = {
    "fig2a": [("run", "fig2a_plectoneme", [])],
    "fig2b": [("run", "fig2b_solenoid", [])],
    "fig4a": [("run", "solenoid_loss", [])],
    "fig4b": [("run", "stiffening", [])],
    "fig4c": [("homochiral", "muscle", [("muscle.chirality", "homochiral")]),
              ("heterochiral", "muscle", [("muscle.chirality", "heterochiral")])],
    "figS9": [("run", "active_agent", [])],
    "figS3": [("run", "figS3_escape", [])],
}
DPI = 130  # documentation figures stay well under 300 kB
TURN = units.TURN


# ------------------------------------------------------------------ running

def _simulate(scene_plain: dict):
    import numba

    from rodphase.runner import run_scene

    numba.set_num_threads(1)
    return run_scene(scene_plain)


def run_figure(name: str, out: Path, sets: list, jobs: int) -> tuple[dict, float]:
    """Simulate every run of a figure, write DIR/<name>.h5; return ({run id: result}, wall)."""
    from rodphase.store import open_store

    cfgs = {rid: C.load_scene(scene, list(over) + list(sets), SCENES)
            for rid, scene, over in FIGURES[name]}
    start = time.perf_counter()
    plains = [cfg.plain() for cfg in cfgs.values()]
    if jobs > 1 and len(plains) > 1:
        with ProcessPoolExecutor(max_workers=min(jobs, len(plains))) as pool:
            results = list(pool.map(_simulate, plains))
    else:
        results = [_simulate(p) for p in plains]
    wall = time.perf_counter() - start
    path = out / f"{name}.h5"
    if path.exists():
        path.unlink()
    kind = "run" if len(cfgs) == 1 else "sweep"
    with open_store(path, config_text=C.to_yaml(**cfgs), config_hash=C.config_hash(*cfgs.values()),
                    version=__version__, kind=kind) as store:
        for rid, result in zip(cfgs, results):
            store.write_run(rid, {}, result, {"wall_time": result.diagnostics["wall_time"]})
    return dict(zip(cfgs, results)), wall


def read_figure(name: str, out: Path) -> tuple[dict, float]:
    from rodphase.store import read_store

    with read_store(out / f"{name}.h5") as store:
        results = {rid: store.read_run(rid) for rid, _, _ in FIGURES[name]}
    return results, float(sum(r.diagnostics["wall_time"] for r in results.values()))


def scene_cfg(name: str, rid: str, sets: list):
    for r, scene, over in FIGURES[name]:
        if r == rid:
            return C.load_scene(scene, list(over) + list(sets), SCENES)
    raise KeyError(rid)


# ------------------------------------------------------------------ measurements
# (the measurements themselves live in rodphase.analysis, where they are tested)

def to_builtin(value):
    if isinstance(value, dict):
        return {k: to_builtin(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_builtin(v) for v in value]
    if isinstance(value, (np.floating, float)):
        return None if not math.isfinite(float(value)) else round(float(value), 5)
    if isinstance(value, np.integer):
        return int(value)
    return value


# ------------------------------------------------------------------ drawing

def new_figure(width: float, height: float, ncols: int = 1, nrows: int = 1):
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from rodphase import plot as P

    matplotlib.rcParams.update(P.STYLE)
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False)
    return fig, axes.ravel()


def save(fig, path: Path) -> Path:
    fig.savefig(path, dpi=DPI)
    return path


def shapes(path: Path, items: list[tuple[str, np.ndarray, float]], ncols: int = 6) -> Path:
    from rodphase import plot as P

    P.DPI, old = DPI, P.DPI
    try:
        return P.shape_grid(items, path, ncols=ncols)
    finally:
        P.DPI = old


def snapshot_at(result, row: int, label: str, radius: float | None = None):
    return (label, result.snapshot_positions[row], radius or result.rest_radius)


# ------------------------------------------------------------------ Fig 2

def figure2(name: str, results: dict, out: Path, sets: list) -> dict:
    from rodphase import plot as P
    from rodphase.classify import alignment

    r = results["run"]
    cfg = scene_cfg(name, "run", sets)
    h = r.history
    a, L0 = r.diagnostics["rest_radius"], r.diagnostics["rest_length"]
    phi = phi_a(r)
    twist = stage_rows(r, "twist")
    onset_row = int(np.argmax((h["writhe"] > 0.05) & twist))
    # L/L0 of the straight loaded rod: just before it buckles (the load ramp is not settled)
    e = 1.0 + h["end_displacement"][max(onset_row - 5, 0)] / L0
    onset = float(phi[onset_row])
    rows = np.where(twist)[0]
    width = max(1, int(round(0.3 / np.median(np.diff(h["time"])))))  # 0.3 s
    steps = bursts(phi[rows], h["writhe"][rows], width)
    final = len(h["time"]) - 1
    value = alignment(r.positions, a, rest_length=L0)
    geometry = (solenoid_geometry(r.positions, a, L0) if value > 0
                else plectoneme_turns(r.positions, a, L0))
    turns_in = float(h["end_rotation"][-1] / TURN)
    m = {
        "status": r.status, "message": r.message,
        "load_F_C": float(h["applied_force"][-1] / C.buckling_force(cfg)),
        "extension_loaded": float(e),
        "onset_phi_a_rest": onset, "onset_phi_a_current": units.current_twist_density(onset, e),
        "kirchhoff_onset_current": 1.5 * math.sqrt(h["applied_force"][-1] / C.buckling_force(cfg))
        * math.pi * a / L0,
        "steps": steps,
        "final": {k: float(h[k][final]) for k in ("link", "twist", "writhe")},
        "turns_put_in": turns_in,
        "link_error": float(h["link"][final] - turns_in),
        "link_min_minus_put_in": float(np.min(h["link"] - h["end_rotation"] / TURN)),
        "alignment": value,
        "end_to_end_over_L0": float(1.0 + h["end_displacement"][final] / L0),
        "final_residual": float(r.diagnostics["stages"][-1]["residual"]),
        "loops": geometry,
        "wall_time": r.diagnostics["wall_time"],
    }
    if geometry.get("turns"):
        m["writhe_per_turn"] = m["final"]["writhe"] / geometry["turns"]

    fig, (ax,) = new_figure(5.2, 3.7)
    keep = twist | stage_rows(r, "hold")
    ax.plot(phi[keep], h["link"][keep], color=P.BLACK, lw=1.8, label="link $Lk$")
    ax.plot(phi[keep], h["twist"][keep], color=P.BLUE, lw=1.6, ls="--", label="twist $Tw$")
    ax.plot(phi[keep], h["writhe"][keep], color=P.VERMILLION, lw=1.6, ls="-.", label="writhe $Wr$")
    ax.axvline(onset, color="0.6", lw=0.8, ls=":")
    ax.annotate(f"onset $\\Phi a$ = {onset:.2f}\n(stretched rod: {m['onset_phi_a_current']:.2f})",
                (onset, 0.55 * h["link"][final]), xytext=(-6, 0), textcoords="offset points",
                ha="right", fontsize=8, color="0.3")
    ax.set_xlabel(r"twist density $\Phi a$ (rest length and radius)")
    top = ax.secondary_xaxis("top", functions=(lambda v: units.current_twist_density(v, e),
                                               lambda v: units.rest_twist_density(v, e)))
    top.set_xlabel(r"$\Phi a$ of the stretched rod", fontsize=9)
    ax.set_ylabel("turns")
    ax.text(0.98, 0.03, f"{m['load_F_C']:.0f} $F_C$, $L/L_0$ = {e:.3f}\nfinal alignment "
            f"{m['alignment']:+.2f}", transform=ax.transAxes, ha="right", va="bottom", fontsize=9)
    ax.legend(frameon=False, loc="upper left")
    save(fig, out / f"{name}.png")

    # shapes: just after onset, two between, and the final one
    targets = onset + np.array([0.01, 0.33, 0.67]) * (phi[rows[-1]] - onset)
    picks = [int(rows[np.argmin(np.abs(phi[rows] - v))]) for v in targets] + [final]
    shapes(out / f"{name}_shape.png",
           [snapshot_at(r, p, f"Φa {phi[p]:.2f}\nWr {h['writhe'][p]:.2f}") for p in picks])
    return m


# ------------------------------------------------------------------ Fig 4a

def figure4a(results: dict, out: Path, sets: list) -> dict:
    from rodphase import plot as P

    r = results["run"]
    cfg = scene_cfg("fig4a", "run", sets)
    fc = C.buckling_force(cfg)
    h = r.history
    pull = stage_rows(r, "pull")
    rows = np.where(pull)[0]
    u = h["end_displacement"][rows] - h["end_displacement"][rows[0]]
    force = h["end_force"][rows] / fc
    dt_row = float(np.median(np.diff(h["time"][rows])))
    window = max(1, int(round(0.01 / (cfg.pull.rate * dt_row))))  # 10 mm of ΔU
    fs = smooth(force, window)
    writhe = h["writhe"][rows]
    # sawtooth drops: a local maximum of the smoothed force (over ±10 mm) followed by a fall
    # of more than 1 F_C before it climbs back above the peak; drops closer than 30 mm merge
    drops = [{"peak_dU": d["peak_x"], "peak_F_C": d["peak_y"], "bottom_dU": d["bottom_x"],
              "bottom_F_C": d["bottom_y"],
              "writhe_lost": float(writhe[d["peak_row"]] - writhe[d["bottom_row"]])}
             for d in sawtooth_drops(u, fs, window, min_drop=1.0, merge=0.03)]
    losses = bursts(u, -writhe, window)
    start = solenoid_geometry(r.snapshot_positions[rows[0]], r.rest_radius, r.diagnostics["rest_length"])
    peaks = [d["peak_dU"] for d in drops]
    m = {
        "status": r.status, "message": r.message,
        "load_F_C": float(cfg.loading.force_multiple),
        "pull_rate": cfg.pull.rate, "pull_distance": cfg.pull.distance,
        "force_start_F_C": float(fs[0]), "force_end_F_C": float(fs[-1]),
        "force_noise_F_C": float(np.std(force - fs)),
        "drops": drops,
        "sawtooth_period": float(np.mean(np.diff(peaks))) if len(peaks) > 1 else None,
        "writhe_loss_bursts": losses,
        "slope_F_C_per_m_first_rise": float(np.polyfit(u[u < 0.04], fs[u < 0.04], 1)[0]),
        "writhe_start": float(writhe[0]), "writhe_end": float(writhe[-1]),
        "solenoid_at_start": start,
        "wall_time": r.diagnostics["wall_time"],
    }
    if start:
        m["contour_minus_pitch"] = start["contour_per_turn"] - start["pitch"]

    fig, (ax,) = new_figure(5.6, 3.8)
    ax.plot(u, force, color="0.75", lw=0.6, label="end force (raw)")
    ax.plot(u, fs, color=P.BLACK, lw=1.8, label="end force (10 mm mean)")
    for d in drops:
        ax.annotate("", (d["bottom_dU"], d["bottom_F_C"]), (d["peak_dU"], d["peak_F_C"]),
                    arrowprops={"arrowstyle": "->", "color": P.BLUE, "lw": 1.2})
    ax.set_xlabel(r"end displacement $\Delta U$ (m)")
    ax.set_ylabel(r"end force $F/F_C$")
    twin = ax.twinx()
    twin.spines["right"].set_visible(True)
    twin.plot(u, writhe, color=P.VERMILLION, lw=1.4, ls="--", label="writhe $Wr$")
    twin.set_ylabel("writhe $Wr$ (turns)", color=P.VERMILLION)
    twin.tick_params(axis="y", colors=P.VERMILLION)
    handles = ax.get_legend_handles_labels()[0] + twin.get_legend_handles_labels()[0]
    ax.legend(handles=handles, frameon=False, loc="upper left", fontsize=8)
    title = f"solenoid at {m['load_F_C']:.0f} $F_C$ pulled at {1e3 * cfg.pull.rate:g} mm/s"
    if start:
        title += f"; pitch {start['pitch'] * 100:.1f} cm"
    ax.set_title(title, fontsize=10)
    save(fig, out / "fig4a.png")

    picks = [rows[int(np.argmin(np.abs(u - x)))] for x in np.linspace(0, u[-1], 5)]
    shapes(out / "fig4a_shape.png",
           [snapshot_at(r, p, f"ΔU {h['end_displacement'][p] - h['end_displacement'][rows[0]]:.2f} m")
            for p in picks])
    return m


# ------------------------------------------------------------------ Fig 4b

def figure4b(results: dict, out: Path, sets: list) -> dict:
    from rodphase import plot as P

    r = results["run"]
    cfg = scene_cfg("fig4b", "run", sets)
    h = r.history
    rows = np.where(stage_rows(r, "stiffen") | stage_rows(r, "hold stiff"))[0]
    x = h["stiffness_factor"][rows]
    u = h["end_displacement"][rows] - h["end_displacement"][rows[0]]
    dwr = h["writhe"][rows] - h["writhe"][rows[0]]
    dtw = h["twist"][rows] - h["twist"][rows[0]]
    grow = np.where(stage_rows(r, "stiffen"))[0]
    width = max(1, int(round(1.0 / np.median(np.diff(h["time"][grow])))))  # 1 s of the ramp
    steps = bursts(h["stiffness_factor"][grow], h["writhe"][grow], width)
    for s in steps:
        a, b = grow[s["rows"][0]], grow[s["rows"][1]]
        s["dU"] = float(h["end_displacement"][b] - h["end_displacement"][a])
    before = rows[0]
    m = {
        "status": r.status, "message": r.message,
        "load_F_C": float(cfg.loading.force_multiple),
        "phi_a": float(cfg.loading.twist_density),
        "writhe_before": float(h["writhe"][before]),
        "alignment_before": float(np.nanmean(local_alignment(
            r.snapshot_positions[before], r.rest_radius, r.diagnostics["rest_length"]))),
        "factor": float(cfg.stiffen.factor),
        "dU_end": float(u[-1]), "dWr_end": float(dwr[-1]), "dTw_end": float(dtw[-1]),
        "steps": steps,
        "wall_time": r.diagnostics["wall_time"],
    }

    fig, (ax1, ax2) = new_figure(5.2, 4.6, nrows=2)
    ax1.plot(x, 1e2 * u, color=P.BLACK, lw=1.8)
    ax1.set_ylabel(r"end displacement $\Delta U$ (cm)")
    ax2.plot(x, dwr, color=P.VERMILLION, lw=1.6, ls="-.", label=r"$\Delta Wr$")
    ax2.plot(x, dtw, color=P.BLUE, lw=1.4, ls="--", label=r"$\Delta Tw$")
    ax2.set_ylabel("turns")
    ax2.set_xlabel(r"Young's modulus $E/E_0$ (G = 2E/3 follows)")
    ax2.legend(frameon=False, loc="center right")
    for j, s in enumerate(steps):
        for ax in (ax1, ax2):
            ax.axvspan(s["from"], s["to"], color=P.GREEN, alpha=0.10 + 0.08 * (j % 2), lw=0)
            ax.axvline(s["at"], color=P.GREEN, lw=0.8, ls=":")
    ax1.set_title(f"{m['load_F_C']:.0f} $F_C$, $\\Phi a$ = {m['phi_a']:g}: E ramped "
                  f"×{m['factor']:g} in {cfg.stiffen.time:g} s\n(shaded: writhe bursts, dotted: "
                  "their peaks)", fontsize=9)
    save(fig, out / "fig4b.png")

    picks = [rows[int(np.argmin(np.abs(x - v)))] for v in np.linspace(1.0, x.max(), 5)]
    shapes(out / "fig4b_shape.png",
           [snapshot_at(r, p, f"E/E0 {h['stiffness_factor'][p]:.2f}") for p in picks])
    return m


# ------------------------------------------------------------------ Fig 4c

def figure4c(results: dict, out: Path, sets: list) -> dict:
    from rodphase import plot as P

    m: dict = {}
    curves = {}
    for rid, r in results.items():
        cfg = scene_cfg("fig4c", rid, sets)
        h = r.history
        fibre = float(np.sum(r.rest_lengths))
        rows = np.where(stage_rows(r, "grow") | stage_rows(r, "hold"))[0]
        first = np.where(stage_rows(r, "grow"))[0][0] - 1
        f = h["radius_factor"][rows]
        height = np.array([coil_height(r.snapshot_positions[i]) for i in rows])
        h0 = coil_height(r.snapshot_positions[first])
        contraction = 1.0 - height / h0
        tw0 = float(h["twist"][first])
        kappa30 = tw0 * TURN / fibre
        coil = (cfg.muscle.helix_radius, cfg.muscle.pitch, cfg.muscle.loops, kappa30)
        analytic = 1.0 - free_coil_height(*coil, f) / free_coil_height(*coil, np.ones(1))
        dtw = h["twist"][rows] - tw0
        dwr = h["writhe"][rows] - h["writhe"][first]
        dlk = h["link"][rows] - h["link"][first]
        touch = np.where(h["contacts"][rows] > 0)[0]
        onset = int(touch[0]) if len(touch) else None
        untwist = -dtw / fibre  # turns per metre of fibre
        pre = slice(0, onset if onset else len(rows))
        slope = (float(np.polyfit(untwist[pre], contraction[pre], 1)[0])
                 if np.ptp(untwist[pre]) > 0 else math.nan)
        m[rid] = {
            "status": r.status, "message": r.message,
            "fibre_length": fibre, "initial_height": h0,
            "initial_twist_density_turns_per_m": tw0 / fibre,
            "initial": {k: float(h[k][first]) for k in ("link", "twist", "writhe")},
            "contact_onset_radius_factor": float(f[onset]) if onset is not None else None,
            "contraction_at_onset": float(contraction[onset]) if onset is not None else None,
            "analytic_contraction_at_onset": float(analytic[onset]) if onset is not None else None,
            "contraction_max": float(contraction.max()),
            "contraction_final": float(contraction[-1]),
            "analytic_final_without_contact": float(analytic[-1]),
            "slope_contraction_per_untwist": slope,
            "dTw": float(dtw[-1]), "dWr": float(dwr[-1]), "dLk": float(dlk[-1]),
            "end_displacement_z": float(h["end_displacement"][rows[-1]] - h["end_displacement"][first]),
            "max_penetration": float(r.diagnostics["max_penetration"]),
            "wall_time": r.diagnostics["wall_time"],
        }
        curves[rid] = dict(f=f, c=contraction, a=analytic, tw=dtw, wr=dwr, lk=dlk, x=untwist,
                           onset=onset)

    colours = {"homochiral": P.BLUE, "heterochiral": P.VERMILLION}
    fig, (ax1, ax2, ax3) = new_figure(11.0, 3.6, ncols=3)
    for rid, cv in curves.items():
        col = colours.get(rid, P.BLACK)
        ax1.plot(cv["f"], 100 * cv["c"], color=col, lw=1.8, label=rid)
        ax1.plot(cv["f"], 100 * cv["a"], color=col, lw=0.9, ls=":")
        ax3.plot(cv["x"], 100 * cv["c"], color=col, lw=1.8, label=rid)
        if cv["onset"] is not None:
            o = cv["onset"]
            ax1.plot(cv["f"][o], 100 * cv["c"][o], "o", color=col, ms=7, mfc="white", mew=1.6)
            ax3.plot(cv["x"][o], 100 * cv["c"][o], "o", color=col, ms=7, mfc="white", mew=1.6)
        style = {"homochiral": "-", "heterochiral": "--"}.get(rid, "-")
        ax2.plot(cv["f"], cv["tw"], color=P.BLUE, ls=style, lw=1.5)
        ax2.plot(cv["f"], cv["wr"], color=P.VERMILLION, ls=style, lw=1.5)
        ax2.plot(cv["f"], cv["lk"], color=P.BLACK, ls=style, lw=1.0)
    ax1.axhline(0, color="0.8", lw=0.8, zorder=0)
    measured = np.concatenate([100 * cv["c"] for cv in curves.values()])
    ax1.set_ylim(min(measured.min(), 0) - 8, max(measured.max(), 0) + 15)
    ax1.set_xlabel(r"fibre radius $a/a_0$ ($a\,\kappa_3^0$ fixed)")
    ax1.set_ylabel("contraction of the coil (%)")
    ax1.set_title("dotted: free coil, no contact (exact)\nopen circle: onset of self-contact",
                  fontsize=8)
    ax1.legend(frameon=False, fontsize=8)
    from matplotlib.lines import Line2D

    ax2.legend(handles=[Line2D([], [], color=P.BLUE, label=r"$\Delta Tw$"),
                        Line2D([], [], color=P.VERMILLION, label=r"$\Delta Wr$"),
                        Line2D([], [], color=P.BLACK, lw=1.0, label=r"$\Delta Lk$"),
                        Line2D([], [], color="0.4", ls="-", label="homochiral"),
                        Line2D([], [], color="0.4", ls="--", label="heterochiral")],
               frameon=False, fontsize=8, ncols=2)
    ax2.axhline(0, color="0.8", lw=0.8, zorder=0)
    ax2.set_xlabel(r"fibre radius $a/a_0$")
    ax2.set_ylabel("change (turns)")
    ax3.axhline(0, color="0.8", lw=0.8, zorder=0)
    ax3.set_xlabel(r"fibre untwist $-\Delta Tw/L$ (turns/m)")
    ax3.set_ylabel("contraction (%)")
    save(fig, out / "fig4c.png")

    items = []
    for rid, r in results.items():
        h = r.history
        for v in (1.0, 1.5, 2.0):
            i = int(np.argmin(np.abs(h["radius_factor"] - v) + (h["stage"] == 0)))
            items.append((f"{rid[:6]}. a/a0 {h['radius_factor'][i]:.1f}", r.snapshot_positions[i],
                          r.rest_radius * h["radius_factor"][i]))
    shapes(out / "fig4c_shape.png", items, ncols=6)
    return m


# ------------------------------------------------------------------ Fig S9

def figureS9(results: dict, out: Path, sets: list) -> dict:
    from rodphase import plot as P

    r = results["run"]
    cfg = scene_cfg("figS9", "run", sets)
    h = r.history
    L0 = r.diagnostics["rest_length"]
    n = cfg.rod.elements
    seg = (int(round(cfg.agent.first * n)), int(round(cfg.agent.last * n)))
    stages = []
    items = []
    for k, row in enumerate(r.stage_ends):
        label = r.diagnostics["stages"][k]["label"]
        signs = local_alignment(r.snapshot_positions[row], r.rest_radius, L0)
        paired = np.where(~np.isnan(signs))[0]
        stages.append({
            "label": label, "phi_a": float(phi_a(r)[row]),
            **{k2: float(h[k2][row]) for k2 in ("link", "twist", "writhe")},
            "alignment": float(np.nanmean(signs)) if len(paired) else None,
            "paired_elements": [int(paired.min()), int(paired.max())] if len(paired) else None,
            "parallel_elements": int(np.sum(signs > 0)), "antiparallel_elements": int(np.sum(signs < 0)),
            "pattern": "".join("." if np.isnan(s) else ("+" if s > 0 else "-") for s in signs),
        })
        if label in ("twist to agent", "hold agent", "twist on", "hold"):
            items.append((f"{label}\nWr {h['writhe'][row]:.2f}", r.snapshot_positions[row], r.rest_radius))
    m = {"status": r.status, "message": r.message, "segment_elements": list(seg),
         "pull_F_C": float(cfg.agent.pull_multiple), "load_F_C": float(cfg.loading.force_multiple),
         "stages": stages, "wall_time": r.diagnostics["wall_time"]}
    shapes(out / "figS9_shape.png", items, ncols=4)

    fig, (ax,) = new_figure(5.6, 3.6)
    t = h["time"]
    ax.plot(t, h["link"], color=P.BLACK, lw=1.8, label="$Lk$")
    ax.plot(t, h["twist"], color=P.BLUE, lw=1.5, ls="--", label="$Tw$")
    ax.plot(t, h["writhe"], color=P.VERMILLION, lw=1.5, ls="-.", label="$Wr$")
    previous = 0.0
    for k, row in enumerate(r.stage_ends):
        label = r.diagnostics["stages"][k]["label"]
        if label in ("agent on", "hold agent"):
            ax.axvspan(previous, t[row], color=P.GREEN, alpha=0.15, lw=0)
        previous = t[row]
    ax.set_xlabel("time (s)  (shaded: the agent switches on and the rod settles)")
    ax.set_ylabel("turns")
    ax.set_title(f"{m['load_F_C']:.0f} $F_C$; agent pulls {m['pull_F_C']:.0f} $F_C$ over "
                 f"{cfg.agent.first:g}–{cfg.agent.last:g} $L_0$ at $\\Phi a$ = "
                 f"{cfg.agent.at_twist_density:g}", fontsize=9)
    ax.legend(frameon=False, loc="upper left")
    save(fig, out / "figS9.png")
    return m


def figureS3(results: dict, out: Path, sets: list) -> dict:
    """Link escape: Lk, Tw, Wr against Φa with each escape (time, ΔLk) marked."""
    from rodphase import plot as P
    from rodphase.runner import link_escapes

    r = results["run"]
    h = r.history
    jumps = link_escapes(h)
    rows = np.flatnonzero(jumps)
    phi = phi_a(r)
    events = [{"time": float(h["time"][i]), "phi_a": float(phi[i]),
               "delta_link": float(jumps[i])} for i in rows]
    P.topology_curves(r, out / "figS3.png", title="Fig S3: a loop slips over the sliding end")
    shapes(out / "figS3_shape.png",
           [snapshot_at(r, max(int(i) - 1, 0), f"before escape {k + 1}") for k, i in enumerate(rows[:3])]
           + [snapshot_at(r, int(i), f"after escape {k + 1}") for k, i in enumerate(rows[:3])],
           ncols=max(2, min(len(rows), 3)))
    turns = rotation_put_in(h)[-1] / TURN
    return {"events": events, "turns_put_in": float(turns), "final_link": float(h["link"][-1]),
            "link_lost": float(turns - h["link"][-1]), "escape_count": len(events)}


DRAW = {"fig2a": lambda res, out, sets: figure2("fig2a", res, out, sets),
        "fig2b": lambda res, out, sets: figure2("fig2b", res, out, sets),
        "fig4a": figure4a, "fig4b": figure4b, "fig4c": figure4c, "figS9": figureS9,
        "figS3": figureS3}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out", help="output folder")
    parser.add_argument("--only", default="", help="comma-separated figures: " + ", ".join(FIGURES))
    parser.add_argument("--jobs", type=int, default=1,
                        help="processes for a figure with several runs (fig4c); figures run one by one")
    parser.add_argument("--set", dest="sets", action="append", default=[],
                        help="key=value applied to every scene")
    parser.add_argument("--replot", action="store_true", help="redraw from DIR/<fig>.h5, no simulation")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    chosen = [f for f in args.only.split(",") if f] or list(FIGURES)
    unknown = sorted(set(chosen) - set(FIGURES))
    if unknown:
        parser.error(f"unknown figure(s) {unknown}; choose from {', '.join(FIGURES)}")
    try:
        sets = [C.parse_override(s) for s in args.sets]
        for name in chosen:  # check every config before the first long run
            for rid, _, _ in FIGURES[name]:
                scene_cfg(name, rid, sets)
    except C.ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for name in chosen:
        print(f"{name}: running {', '.join(s for _, s, _ in FIGURES[name])} ...", flush=True)
        start = time.perf_counter()
        if args.replot:  # the wall time recorded is then the simulations' own
            results, wall = read_figure(name, out)
        else:
            results, _ = run_figure(name, out, sets, args.jobs)
            wall = time.perf_counter() - start
        metrics = DRAW[name](results, out, sets)
        metrics = {"figure": name, "wall_time_total": wall, "cpu": os.cpu_count(),
                   "settings": args.sets, **metrics}
        (out / f"{name}.json").write_text(json.dumps(to_builtin(metrics), indent=1))
        statuses = ", ".join(f"{rid}: {res.status}" for rid, res in results.items())
        print(f"{name}: {wall:.0f} s wall ({statuses}); wrote {out / name}.h5, .png, "
              f"_shape.png, .json", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
