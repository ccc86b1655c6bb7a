"""Store → per-run table: final shape classified by loop alignment, topology, extension."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd

from . import units
from .classify import PHASES, alignment, phase, unseen_coil
from .result import rotation_put_in


def summarize(result, *, epsilon=0.2, plectoneme_below=-0.5, solenoid_above=0.5,
              separation=5.0) -> dict:
    """One row of the table from a RunResult (ok or not); `separation` (rest radii of arc)
    is the classifier's partner separation (classify.alignment)."""
    d = result.diagnostics
    rest_length = float(d.get("rest_length", np.nan))
    radius = float(d.get("rest_radius", np.nan))
    row = {"status": result.status, "wall_time": float(d.get("wall_time", np.nan)),
           "steps": int(d.get("steps", 0)), "elements": int(d.get("elements", 0))}
    if result.status == "error" or not len(result.history.get("time", [])):
        return row | {"alignment": np.nan, "phase": "failed"}
    value = alignment(result.positions, radius, rest_length=rest_length, epsilon=epsilon,
                      separation=separation)
    row["alignment"] = value
    # a hold that ran out of time still has a shape (status says it crept); a blow-up has not
    shaped = result.status in ("ok", "not_converged")
    row["phase"] = phase(value, plectoneme_below, solenoid_above) if shaped else "failed"
    h = result.history
    row["end_rotation_turns"] = float(h["end_rotation"][-1] / (2 * np.pi))
    # twist density with rest length and radius, and of the straight stretched rod
    # (L = e L0, a = a0/√e, e from the applied load): papers use either
    row["phi_a_rest"] = float(units.twist_density_for_rotation(rotation_put_in(h)[-1], radius,
                                                               rest_length))
    e_load = units.extension_under_load(d.get("youngs_modulus", np.nan), radius,
                                        float(h["applied_force"][-1]), d.get("law", "paper"))
    row["phi_a_current"] = units.current_twist_density(row["phi_a_rest"], e_load)
    row["final_extension"] = float((rest_length + h["end_displacement"][-1]) / rest_length)
    row["end_force"] = float(h["end_force"][-1])
    for key in ("link", "twist", "writhe"):
        if key in h:
            row[key] = float(h[key][-1])
    row["unseen_coil"] = unseen_coil(row["phase"], row.get("writhe", np.nan))
    return row


# what the store's own table already holds for every run
_RUN_COLUMNS = ("status", "wall_time", "steps")


def classify_table(store, run_ids=None, **thresholds) -> pd.DataFrame:
    """Classify every run of an open store (or those of `run_ids`): one row per run, run_id
    and what the classification adds (the parameters, status and timings are the store's;
    see Store.table), with each run's distance to the straight rod's onset where its scene
    has one (onset_columns). Nothing is written."""
    rows = []
    for run_id in sorted(store.run_ids() if run_ids is None else run_ids):
        row = summarize(store.read_run(run_id), **thresholds)
        rows.append({"run_id": run_id} | {k: v for k, v in row.items() if k not in _RUN_COLUMNS})
    table = pd.DataFrame(rows)
    from .config import stored_config

    return onset_columns(table, stored_config(store.attrs.get("config_yaml", "")))


def onset_columns(table: pd.DataFrame, config: dict) -> pd.DataFrame:
    """`table` with `onset_ratio` (a run's final Φa over the model's onset Φa_c at its load
    and its own elements) and `near_onset` (classify.near_onset of it), for the runs of a
    scene whose straight rod has an onset (loaded_rod). Φa_c costs 0.02-0.25 s a run (n =
    40-160), so it is computed only for runs whose Φa is within classify.ONSET_SCREEN of the
    sheared clamped Greenhill twist, the same rod's n → ∞ limit; a run further out is not
    near without it (ratio NaN)."""
    from .classify import ONSET_SCREEN, near_onset
    from .rod.onset import sheared_greenhill_turns, straight_onset_turns

    rod = loaded_rod(config)
    needed = {"phi_a_rest", "end_force", "elements"}
    if rod is None or table.empty or not needed <= set(table.columns):
        return table
    to_phi = units.TURN * rod.radius / rod.length
    ratios = np.full(len(table), np.nan)
    for i, row in enumerate(table.itertuples(index=False)):
        phi = float(row.phi_a_rest)
        e = units.extension_under_load(rod.youngs_modulus, rod.radius, float(row.end_force),
                                       rod.law) if np.isfinite(row.end_force) else np.nan
        if not (np.isfinite(phi) and np.isfinite(e) and e > 1.0 and row.elements > 0):
            continue
        try:
            estimate = sheared_greenhill_turns(rod, e) * to_phi
        except ValueError:
            continue
        if abs(abs(phi) / estimate - 1.0) > ONSET_SCREEN:
            continue
        try:
            own = dataclasses.replace(rod, elements=int(row.elements))
            ratios[i] = abs(phi) / (straight_onset_turns(own, e, tolerance=1e-6) * to_phi)
        except ValueError:  # too few elements to resolve the onset
            continue
    return table.assign(onset_ratio=ratios, near_onset=[near_onset(r) for r in ratios])


# (unit, meaning) of every column a table of rodphase can have: the classification group's
# datasets carry them as attributes, and the CSV's metadata file lists them ("1":
# dimensionless, a count or an index; "": text)
COLUMNS = {
    "run_id": ("", "the run's name, key into /runs"),
    "status": ("", "ok, unstable, not_converged or error (docs/reference/statuses.md)"),
    "message": ("", "what ended the run, and what to change if it failed"),
    "wall_time": ("s", "wall-clock time of the run"),
    "steps": ("1", "time steps taken"),
    "elements": ("1", "elements of the run that gave the shape (more if refined)"),
    "twist_density": ("1", "sampled twist density, the paper's Phi*a = theta*a0/L0"),
    "twist_density_current": ("1", "sampled Phi*a of the stretched straight rod"),
    "extension": ("1", "sampled extension L/L0 (set by the load of the incompressible rod)"),
    "force_multiple": ("F_C", "sampled load in multiples of F_C = pi^2 E I / L0^2"),
    "alignment": ("1", "loop alignment in [-1, 1]; NaN: no element has a contact partner"),
    "phase": ("", "straight, plectoneme, solenoid, mixed, or failed (no shape)"),
    "end_rotation_turns": ("turns", "final end rotation"),
    "phi_a_rest": ("1", "final Phi*a = theta*a0/L0 of the turns the clamps put in"),
    "phi_a_current": ("1", "final Phi*a of the stretched straight rod (rest value / e^1.5)"),
    "final_extension": ("1", "final L/L0 of the end"),
    "end_force": ("N", "final axial end force"),
    "link": ("turns", "final Lk"),
    "twist": ("turns", "final Tw"),
    "writhe": ("turns", "final Wr"),
    "onset_ratio": ("1", "final Phi*a over the model's onset at the run's load and elements "
                    "(NaN: more than 3 % from the onset, or no onset in the scene)"),
    "near_onset": ("", "|onset_ratio - 1| < 0.002: the label is the stability push's, the "
                   "static onset is the answer (classify.near_onset)"),
    "unseen_coil": ("", "labelled straight but |Wr| > 0.5 turn: a coil too tight for the "
                    "classifier's 5-radii partner separation (classify.unseen_coil)"),
}


def column_units(columns) -> dict[str, tuple[str, str]]:
    """(unit, meaning) of each of `columns`; a column rodphase does not know is "unknown"."""
    return {str(c): COLUMNS.get(str(c), ("unknown", "")) for c in columns}


def classify_store(store, **thresholds) -> pd.DataFrame:
    """Classify every run of a store open for writing, store the classification in it and
    return the store's whole table (parameters, status, timings and the classification).

    The stored classification describes itself: each run's sampled parameters and status
    stand beside its labels, and every column carries its unit (attribute `units`)."""
    labels = classify_table(store, **thresholds)
    runs = store.table(labels.iloc[0:0])  # parameters and status, without the labels
    keep = ["run_id"] + [c for c in runs.columns
                         if c not in labels.columns and c not in ("message", "wall_time", "steps")]
    described = runs[keep].merge(labels, on="run_id", how="right")
    store.write_classification(described, units=column_units(described.columns))
    return store.table()


def path_table(result, *, every: int = 1, epsilon=0.2, plectoneme_below=-0.5,
               solenoid_above=0.5) -> pd.DataFrame:
    """One run's protocol as a path through the phase diagram: per history row (every
    `every`-th), time, stage, extension L/L0 of the end, the paper's Φa = θ·a0/L0 of the turns
    put in so far, writhe if computed, and the snapshot's alignment and phase."""
    d, h = result.diagnostics, result.history
    rest_length, radius = float(d["rest_length"]), float(d["rest_radius"])
    # the history rows that have a snapshot (a run may keep only some), every `every`-th
    kept = result.snapshot_history_rows
    picks = np.arange(0, len(kept), max(int(every), 1))
    rows = kept[picks]
    turned = rotation_put_in(h)
    values = [alignment(result.snapshot_positions[i], radius, rest_length=rest_length,
                        epsilon=epsilon) for i in picks]
    table = pd.DataFrame({
        "time": h["time"][rows], "stage": h["stage"][rows],
        "extension": 1.0 + h["end_displacement"][rows] / rest_length,
        "twist_density": units.twist_density_for_rotation(turned, radius, rest_length)[rows],
        "alignment": values,
        "phase": [phase(v, plectoneme_below, solenoid_above) for v in values],
    })
    if "writhe" in h:
        table["writhe"] = h["writhe"][rows]
    return table


def loaded_rod(config: dict):
    """The Rod of a resolved config's scene (a store's config or its `scene` section) when
    its straight rod has an onset that rod/onset.py computes: clamped at the start, held
    across the axis and turned at the end under an end force, incompressible under the
    paper's law; else None."""
    from .rod.model import Rod

    scene = config.get("scene") if isinstance(config.get("scene"), dict) else config
    try:
        rod_cfg, material, ends = scene["rod"], scene["material"], scene["ends"]
        loaded = (ends["start"] == "clamped" and ends["end_axial"] == "force"
                  and ends["end_lateral"] == "held" and ends["end_rotation"] == "held")
        shear = material.get("shear_modulus")
        rod = Rod(length=float(rod_cfg["length"]), radius=float(rod_cfg["radius"]),
                  elements=int(rod_cfg["elements"]),
                  youngs_modulus=float(material["youngs_modulus"]),
                  shear_modulus=None if shear in (None, "auto") else float(shear),
                  incompressible=bool(material.get("incompressible", True)),
                  law=material.get("law", "paper"),
                  bend_stiffness_given=material.get("bend_stiffness"),
                  twist_stiffness_given=material.get("twist_stiffness"),
                  shear_stiffness_given=material.get("shear_stiffness"),
                  axial_stiffness_given=material.get("axial_stiffness"))
    except (KeyError, TypeError, ValueError):
        return None
    if not loaded or not rod.incompressible or rod.law != "paper":
        return None
    return rod


def onset_lines(config: dict, extensions) -> pd.DataFrame | None:
    """The straight rod's buckling twist along `extensions` (L/L0) for the scene of a store's
    resolved config (its `scene` section): the model's own onset (rod/onset.py: the perfect
    discrete rod at the scene's resolution, with its shear and stretch), the sheared clamped
    Greenhill twist (the same rod's n → ∞ limit) and the unsheared one, each as the rest
    Φa = θ·a0/L0 (`model_rest`, `sheared_rest`, `greenhill_rest`) and as the stretched rod's
    (`model_current`, `sheared_current`, `greenhill_current`). None for a scene whose
    rod is not clamped at both ends under an end load, or whose resolved config is not there
    (the onset is for that rod only). Where the rod has too few elements to resolve its onset
    the model's line is NaN (left out)."""
    from .rod.onset import greenhill_turns, sheared_greenhill_turns, straight_onset_turns

    rod = loaded_rod(config)
    if rod is None:
        return None
    e = np.asarray(extensions, dtype=float)

    # along the line, each load's onset is first sought near the last one's share of the
    # unsheared Greenhill twist (that share changes slowly with the load)
    share = [None]

    def model_onset(extension: float) -> float:
        greenhill = greenhill_turns(rod, extension)
        near = None if share[0] is None else share[0] * greenhill
        try:
            turns = straight_onset_turns(rod, extension, tolerance=1e-4, near=near)
        except ValueError:  # too few elements to resolve that twist: no line there
            share[0] = None
            return np.nan
        share[0] = turns / greenhill
        return turns

    def sheared_onset(extension: float) -> float:
        try:
            return sheared_greenhill_turns(rod, extension)
        except ValueError:  # tension at or above the shear stiffness: no sheared line there
            return np.nan

    model = np.array([model_onset(v) for v in e])
    sheared = np.array([sheared_onset(v) for v in e])
    greenhill = np.array([greenhill_turns(rod, v) for v in e])
    to_phi = units.TURN * rod.radius / rod.length  # turns -> rest Φa
    lines = pd.DataFrame({"extension": e})
    for name, turns in (("model", model), ("sheared", sheared), ("greenhill", greenhill)):
        lines[f"{name}_rest"] = turns * to_phi
        lines[f"{name}_current"] = units.current_twist_density(turns * to_phi, e)
    lines.attrs["elements"] = rod.elements
    return lines


def critical_twist(table: pd.DataFrame, column: str = "phi_a_rest", bins: int = 10,
                   above: float = 1.1) -> pd.DataFrame:
    """The critical twist against extension of a classified sweep (the paper's Fig 3: "Φ_c
    grows linearly with L/L0" at high extension). The runs with a shape are binned by
    extension into `bins` equal bins; in each, the critical `column` is the midpoint between
    the largest value still straight and the smallest that buckled (any other phase), ± half
    their gap. A bin where a straight run lies above a buckled one (the ramp's overshoot, or
    hysteresis) brackets nothing and is left out. Columns: extension (the bin's centre),
    critical, half_gap. attrs["fit"]: (slope, intercept, R², bins used, above) of the straight
    line through the bins above L/L0 = `above`, or None with fewer than 3 such bins."""
    usable = table[table["phase"].isin(PHASES)]
    rows = []
    if len(usable):
        edges = np.linspace(usable["extension"].min(), usable["extension"].max(), bins + 1)
        for lo, hi in zip(edges[:-1], edges[1:]):
            cell = usable[(usable["extension"] >= lo) & (usable["extension"] <= hi)]
            straight = cell[cell["phase"] == "straight"][column]
            buckled = cell[cell["phase"] != "straight"][column]
            if straight.empty or buckled.empty:
                continue
            below, over = straight.max(), buckled.min()
            if below < over:
                rows.append((0.5 * (lo + hi), 0.5 * (below + over), 0.5 * (over - below)))
    points = pd.DataFrame(rows, columns=["extension", "critical", "half_gap"])
    fit = points[points["extension"] > above]
    points.attrs["fit"] = None
    if len(fit) >= 3:
        slope, intercept = np.polyfit(fit["extension"], fit["critical"], 1)
        model = slope * fit["extension"] + intercept
        r2 = 1 - np.sum((fit["critical"] - model) ** 2) / np.sum(
            (fit["critical"] - fit["critical"].mean()) ** 2)
        points.attrs["fit"] = (float(slope), float(intercept), float(r2), len(fit), above)
    return points
