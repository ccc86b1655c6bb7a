"""Figures: phase map, Lk/Tw/Wr curves, force–displacement, rod shapes, movies.

Every figure function takes data (a DataFrame, arrays, a history dict or a RunResult),
draws into the axes it is given (`ax=`, or `axes=` for several panels) or else into a new
figure of its own, saves that figure when it is given a `path`, and returns the Figure. So
`phase_map(table, "map.png")` writes a file, and `phase_map(table, ax=ax)` draws into one
panel of a notebook's figure and writes nothing. Nothing here simulates or opens HDF5 files.

Figures of their own are built on matplotlib's Agg canvas directly (no pyplot): no global
figure registry to leak, and no dependence on the user's backend or display. Into the
user's axes the style (STYLE) applies to what is drawn, not to the axes already made.
"""

from __future__ import annotations

import itertools
import shutil
from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd
from matplotlib import animation
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from mpl_toolkits.mplot3d import proj3d
from mpl_toolkits.mplot3d.art3d import Line3DCollection

from . import units
from .boundaries import left_wide, onset_twist
from .result import RunResult, rotation_put_in

DPI = 200
STYLE = {
    "font.size": 10,
    "axes.labelsize": 11,
    "axes.titlesize": 11,
    "legend.fontsize": 9,
    "xtick.labelsize": 9,
    "ytick.labelsize": 9,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "savefig.dpi": DPI,
}
# Okabe–Ito colours: distinguishable with the common colour-vision deficiencies
BLACK, BLUE, VERMILLION, GREEN = "#000000", "#0072B2", "#D55E00", "#009E73"
# PuOr is a ColorBrewer colourblind-safe diverging map: orange = plectoneme (−1),
# purple = solenoid (+1); NaN alignment (no contacts: straight) is drawn grey
ALIGNMENT_CMAP = matplotlib.colormaps["PuOr"].with_extremes(bad="0.6")
PHASE_MARKERS = {"straight": "o", "plectoneme": "s", "solenoid": "^", "mixed": "D"}
OTHER_MARKER = "P"
EXPERIMENT_MARKERS = ("h", "p", "*", "X", "8", "v")
TWIST_DENSITY_LABEL = r"twist density $\Phi a = \theta a_0 / L_0$ (rad)"


def _figure(**kwargs) -> Figure:
    fig = Figure(layout="constrained", **kwargs)
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI)
    return path


def _root(artist) -> Figure:
    """The top-level Figure that holds `artist`, an axes or a (sub)figure."""
    fig = artist if isinstance(artist, Figure) else artist.figure
    while getattr(fig, "figure", fig) is not fig:
        fig = fig.figure
    return fig


def _axes(ax, figsize):
    """(figure, axes) to draw into: the caller's `ax` (and its (sub)figure) when given, else
    a new figure of `figsize` with one axes."""
    if ax is not None:
        return ax.figure, ax
    fig = _figure(figsize=figsize)
    return fig, fig.add_subplot()


def _done(fig: Figure, path) -> Figure:
    """Save the whole figure when a path is given; return the top-level Figure."""
    fig = _root(fig)
    if path is not None:
        _save(fig, path)
    return fig


# figure sizes (inches) of a journal's single column and full page width
SIZES = {"column": (3.4, 3.2), "page": (7.0, 4.6)}


def _twist_axis(table: pd.DataFrame, twist: str) -> pd.Series:
    """The phase map's vertical values: column `twist`, completed from the sample's own
    parameters where the run left it empty (a run that failed before it had a shape still
    has the Φa and L/L0 it was sampled at; dropping it would hide the failure)."""
    y = table[twist].astype(float) if twist in table else pd.Series(np.nan, index=table.index)
    e = table["extension"].astype(float) if "extension" in table else None
    rest = table.get("twist_density")
    current = table.get("twist_density_current")
    if twist == "phi_a_current":
        fill = current if current is not None else (
            units.current_twist_density(rest.astype(float), e)
            if rest is not None and e is not None else None)
    else:  # phi_a_rest, or the rest-axis parameter itself
        fill = rest if rest is not None and twist != "twist_density" else (
            units.rest_twist_density(current.astype(float), e)
            if current is not None and e is not None else None)
    return y.fillna(fill.astype(float)) if fill is not None else y


def sweep_caption(config: dict, table: pd.DataFrame | None = None) -> str:
    """One line saying what a phase map was computed with: the scene, the resolution, the
    rod and material, the load, the protocol, the sampler, and the runs by status. `config`
    is a store's resolved config (its config_yaml attribute, parsed)."""
    def section(parent, name):  # a file from elsewhere may hold anything there
        value = parent.get(name) if isinstance(parent, dict) else None
        return value if isinstance(value, dict) else {}

    scene, sweep = section(config, "scene"), section(config, "sweep")
    rod, material = section(scene, "rod"), section(scene, "material")
    loading, solver = section(scene, "loading"), section(scene, "solver")
    parts = [f"{scene.get('scene', '?')}: {rod.get('elements', '?')} elements",
             f"L0 {rod.get('length', float('nan')):g} m, a0 {rod.get('radius', float('nan')):g} m",
             f"E {material.get('youngs_modulus', float('nan')):.3g} Pa"
             + (", incompressible" if material.get("incompressible") else "")]
    axes = sweep.get("axes", {})
    if "force_multiple" not in axes and "extension" not in axes:
        if loading.get("force_multiple") is not None:
            parts.append(f"load {loading['force_multiple']:g} F_C")
        elif loading.get("extension") is not None:
            parts.append(f"L/L0 {loading['extension']:g}")
    slower = solver.get("slow_down_to") or 0
    parts.append(f"twisted at {loading.get('twist_rate', float('nan')):g} turns/s"
                 + (f" (down to {slower:g} where a guard stopped it)" if slower else "") + ", "
                 f"holds ≤ {solver.get('hold_max_time', float('nan')):g} s to equilibrium "
                 f"(tolerance {solver.get('hold_tolerance', float('nan')):g}), "
                 f"damping {solver.get('damping', float('nan')):g}/s")
    if sweep and sweep.get("sampler") == "boundaries":
        bracket = sweep.get("boundary") or {}
        parts.append(f"runs placed by bracketing (rodphase boundaries, tolerance "
                     f"{bracket.get('tolerance', 0.01):g} in L/L0)")
    elif sweep:
        parts.append(f"{sweep.get('samples', '?')} {sweep.get('sampler', '?')} samples, "
                     f"seed {sweep.get('seed', '?')}")
    if table is not None and "status" in table:
        counts = table["status"].value_counts()
        parts.append(", ".join(f"{n} {s}" for s, n in counts.items()))
    return "; ".join(parts)


def _failed_label(statuses: pd.Series) -> str:
    """'failed (1 error, 2 unstable)': how the failed runs failed, by status (unstable: a
    guard stopped the run, its message says where and why; error: an exception), so that a
    reader of the figure tells them apart without the table."""
    counts = statuses.astype(str).value_counts().sort_index()
    return "failed (" + ", ".join(f"{count} {name}" for name, count in counts.items()) + ")"


def phase_map(table: pd.DataFrame, path=None, *, experiments: pd.DataFrame | None = None,
              title: str | None = None, twist: str = "twist_density", caption: str | None = None,
              size: tuple[float, float] | str | None = None, ax=None,
              onset: pd.DataFrame | None = None,
              lines: pd.DataFrame | None = None) -> Figure:
    """Morphological phase map (paper Fig. 3) of a sweep table.

    x = extension L/L0 ("extension"), y = twist density Φa (column `twist`: "twist_density",
    or "phi_a_rest" / "phi_a_current" of the classified table), as the paper's Fig 3 has it:
    pulling at a fixed end rotation is then a horizontal path; colour =
    "alignment" (−1 plectoneme … +1 solenoid, NaN grey), marker = "phase"; runs whose hold
    ran out of time ("not_converged") are drawn by their shape with a black dot; runs that
    failed otherwise are small black crosses. `experiments` (columns twist_density,
    extension, kind ∈ {plectoneme, solenoid}, optional series) are overlaid in black:
    hollow for plectoneme onsets, solid for solenoid onsets, one marker shape per series.
    Into a given `ax` the legend goes inside the axes (a figure legend would sit over the
    caller's other panels) and the colour bar takes its room from `ax`. `caption` is a line
    under the figure (the sweep's parameters); `size` is (width, height) in inches or
    "column" / "page" (a journal's single column, full width). `onset` (tabulate.onset_lines)
    draws the straight rod's buckling twist: the model's own (solid), the sheared clamped
    Greenhill twist (its n → ∞ limit, dotted blue) and the unsheared one (dashed), on the
    same twist axis. `lines` (a boundaries table, rodphase.boundaries.lines, in the rest
    Φa) draws the traced plectoneme–solenoid boundary with its bracket as a band and the
    triple point with its error bars (boundary_lines).
    """
    if "extension" not in table.columns:
        raise ValueError(f"phase_map needs the column 'extension'; the table has "
                         f"{list(table.columns)}")
    y = _twist_axis(table, twist)
    if y.isna().all():
        raise ValueError(f"phase_map needs twist values in '{twist}' (or the sample's "
                         f"twist_density / twist_density_current); the table has "
                         f"{list(table.columns)}")
    table = table.assign(extension=table["extension"].astype(float)).drop(
        columns=["twist_density"], errors="ignore").assign(twist_density=y)
    n = len(table)
    status = table["status"] if "status" in table else pd.Series(["ok"] * n, index=table.index)
    phase = table["phase"] if "phase" in table else pd.Series(["?"] * n, index=table.index)
    phase = phase.fillna("?").astype(str)
    alignment = (table["alignment"] if "alignment" in table
                 else pd.Series(np.nan, index=table.index)).astype(float)
    ok = status.isin(["ok", "not_converged"])  # both have a shape to classify
    creeping = status == "not_converged"
    norm = Normalize(-1.0, 1.0)

    own = ax is None
    figsize = SIZES.get(size, size) if isinstance(size, str) or size else (5.6, 4.6)
    if isinstance(size, str) and size not in SIZES:
        raise ValueError(f"size {size!r}: one of {', '.join(SIZES)}, or (width, height) inches")
    small = figsize[0] < 4.5
    with matplotlib.rc_context(STYLE | ({"font.size": 8, "axes.labelsize": 8,
                                          "legend.fontsize": 7, "xtick.labelsize": 7,
                                          "ytick.labelsize": 7} if small else {})):
        fig, ax = _axes(ax, figsize)
        handles = []
        # the holds of `rodphase boundaries --hysteresis`'s return runs (params `load`) are
        # states reached by turning back: drawn small, so that the map's own runs stand out
        returning = (table["load"].notna() if "load" in table
                     else pd.Series(False, index=table.index)).to_numpy()
        sizes = np.where(returning, 0.35, 1.0) * (24 if small else 42)
        names = list(PHASE_MARKERS) + sorted(set(phase[ok]) - set(PHASE_MARKERS))
        for name in names:
            rows = ok & (phase == name)
            if not rows.any():
                continue
            marker = PHASE_MARKERS.get(name, OTHER_MARKER)
            ax.scatter(table.loc[rows, "extension"], table.loc[rows, "twist_density"],
                       c=alignment[rows], cmap=ALIGNMENT_CMAP, norm=norm, marker=marker,
                       s=sizes[rows.to_numpy()],
                       edgecolors="0.25", linewidths=0.5, plotnonfinite=True, zorder=2)
            face = "0.6" if name == "straight" else "0.9"  # straight is the grey of NaN
            handles.append(Line2D([], [], ls="", marker=marker, ms=7, mfc=face, mec="0.25",
                                  label=name if name != "?" else "unclassified"))
        if returning.any():
            handles.append(Line2D([], [], ls="", marker="o", ms=4, mfc="0.9", mec="0.25",
                                  label="small: turned back"))
        if creeping.any():
            ax.scatter(table.loc[creeping, "extension"], table.loc[creeping, "twist_density"],
                       marker=".", s=6, c="black", zorder=3)
            handles.append(Line2D([], [], ls="", marker=".", ms=4, color="black",
                                  label=f"not converged ({int(creeping.sum())})"))
        if (~ok).any():
            ax.scatter(table.loc[~ok, "extension"], table.loc[~ok, "twist_density"], marker="x",
                       s=18, c="black", linewidths=0.9, zorder=3)
            handles.append(Line2D([], [], ls="", marker="x", ms=5, color="black",
                                  label=_failed_label(status[~ok])))
        if "unseen_coil" in table and table["unseen_coil"].fillna(False).astype(bool).any():
            blind = table["unseen_coil"].fillna(False).astype(bool)
            ax.scatter(table.loc[blind, "extension"], table.loc[blind, "twist_density"],
                       marker="o", s=90 if not small else 50, facecolors="none",
                       edgecolors="crimson", linewidths=1.2, zorder=3)
            handles.append(Line2D([], [], ls="", marker="o", ms=8, mfc="none", mec="crimson",
                                  label=f"straight, |Wr| > 0.5 ({int(blind.sum())})"))
        if experiments is not None and len(experiments):
            handles += _experiments(ax, experiments)
        if onset is not None and len(onset):
            reading = "current" if twist == "phi_a_current" else "rest"
            n = onset.attrs.get("elements")
            # the sheared line is the model's n → ∞ limit and close to it (0.2 % for the
            # paper's rod at n = 160): dotted, in colour, over the solid model line, so that
            # both stay visible
            for column, style, colour, label in (
                    ("model", "-", "0.15", "onset, model" + (f" n = {n}" if n else "")),
                    ("sheared", ":", BLUE, "Greenhill, sheared (analytic)"),
                    ("greenhill", "--", "0.15", "Greenhill, unsheared")):
                if f"{column}_{reading}" not in onset:  # a caller's table with fewer lines
                    continue
                handles += ax.plot(*_smooth(onset["extension"], onset[f"{column}_{reading}"]),
                                   style, color=colour, lw=1.0 if style != ":" else 1.4,
                                   zorder=1, label=label)

        if lines is not None and len(lines) and twist != "phi_a_current":
            handles += boundary_lines(ax, lines)

        ax.set_ylabel(TWIST_DENSITY_LABEL if twist != "phi_a_current" else
                      r"twist density $\Phi a$ of the stretched rod (rad)")
        ax.set_xlabel(r"extension $L/L_0$")
        if title:
            ax.set_title(title)
        bar = fig.colorbar(ScalarMappable(norm, ALIGNMENT_CMAP), ax=ax,
                           ticks=[-1, -0.5, 0, 0.5, 1], aspect=30, pad=0.02)
        bar.set_label("loop alignment")
        end_size = 6.5 if small else 8
        bar.ax.text(0.5, -0.02, "plectoneme", transform=bar.ax.transAxes, ha="center",
                    va="top", fontsize=end_size)
        bar.ax.text(0.5, 1.02, "solenoid", transform=bar.ax.transAxes, ha="center",
                    va="bottom", fontsize=end_size)
        if handles and own:
            fig.legend(handles=handles, loc="outside upper center",
                       ncols=legend_columns([h.get_label() for h in handles], figsize[0],
                                            7 if small else 9),
                       frameon=False, handletextpad=0.3, columnspacing=1.2)
        elif handles:
            ax.legend(handles=handles, frameon=False, fontsize=7, handletextpad=0.3)
        if caption:
            import textwrap

            width = int(figsize[0] * (17 if small else 15))  # characters per line
            fig.supxlabel("\n".join(textwrap.wrap(caption, width)), fontsize=6.5, color="0.3",
                          ha="center")
        return _done(fig, path)


def legend_columns(labels: list[str], width: float, fontsize: float) -> int:
    """How many legend columns of `labels` fit across a figure `width` inches wide: the
    widest label at ~0.55 em a character plus its marker and spacing (~3.5 em) per column,
    at most four."""
    em = fontsize / 72.0  # inches
    column = (0.55 * max(len(label) for label in labels) + 3.5) * em
    return max(1, min(4, len(labels), int(0.95 * width // column)))


def boundary_lines(ax, lines: pd.DataFrame) -> list:
    """Draw a boundaries table's plectoneme–solenoid boundary (the brackets' middles joined,
    the brackets as a band), the twist at which a rod turned back comes straight again
    (--hysteresis; dashed, the band up to the onset shaded: both states coexist there) and
    the triple point (error bars: its brackets) on `ax`; return the legend handles."""
    handles = []
    ps = lines[lines["kind"] == "plectoneme_solenoid"].sort_values("twist_density")
    wide = left_wide(ps)
    if wide.any():
        handles.append(ax.errorbar(
            ps.loc[wide, "extension"], ps.loc[wide, "twist_density"],
            xerr=[ps.loc[wide, "extension"] - ps.loc[wide, "extension_low"],
                  ps.loc[wide, "extension_high"] - ps.loc[wide, "extension"]],
            fmt="none", ecolor=VERMILLION, elinewidth=1.0, capsize=3, ls=":", zorder=4,
            label="bracket left wide (failed runs)"))
    ps = ps[~wide]
    if len(ps):
        ax.fill_betweenx(ps["twist_density"], ps["extension_low"], ps["extension_high"],
                         color=VERMILLION, alpha=0.25, lw=0, zorder=1)
        handles += ax.plot(ps["extension"], ps["twist_density"], "-", color=VERMILLION, lw=1.4,
                           marker="|", ms=6, zorder=4, label="plectoneme–solenoid, traced")
    back = lines[lines["kind"] == "restraighten"].dropna(subset=["twist_density"])
    back = back.sort_values("extension")
    if len(back):
        critical = onset_twist(lines, back["extension"])
        handles.append(ax.fill_between(back["extension"], back["twist_density"], critical,
                                       color="0.5", alpha=0.15, lw=0, zorder=1,
                                       label="straight and buckled coexist"))
        handles.append(ax.errorbar(
            back["extension"], back["twist_density"],
            yerr=[back["twist_density"] - back["twist_density_low"],
                  back["twist_density_high"] - back["twist_density"]],
            fmt="--", color="0.25", lw=1.2, capsize=2, zorder=4,
            label="turned back: straight again"))
    tp = lines[lines["kind"] == "triple_point"]
    for row in tp.itertuples():
        handles.append(ax.errorbar(
            [row.extension], [row.twist_density],
            xerr=[[row.extension - row.extension_low], [row.extension_high - row.extension]],
            yerr=[[row.twist_density - row.twist_density_low],
                  [row.twist_density_high - row.twist_density]],
            fmt="*", ms=11, color="black", mfc="gold", elinewidth=1.0, capsize=2, zorder=5,
            label="triple point"))
    return handles


def _smooth(x, y, points: int = 200):
    """A cubic spline through the finite (x, y) (a line known at a few points: its chords
    would cut inside a curved line), or the points themselves when there are too few."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    keep = np.isfinite(x) & np.isfinite(y)
    x, first = np.unique(x[keep], return_index=True)  # a one-load sweep: one x, many times
    y = y[keep][first]
    if len(x) < 4:
        return x, y
    from scipy.interpolate import CubicSpline

    fine = np.linspace(x[0], x[-1], points)
    return fine, CubicSpline(x, y)(fine)


def phase_path(paths: dict[str, pd.DataFrame], path=None, *,
               background: pd.DataFrame | None = None, title: str | None = None,
               ax=None) -> Figure:
    """Protocols drawn as paths through the phase diagram (L/L0 horizontal, Φa = θ·a0/L0
    vertical), one line per named path table (`tabulate.path_table`), its points marked by
    the phase of the rod there; `background` (a classified sweep table) is drawn faintly."""
    with matplotlib.rc_context(STYLE):
        fig, ax = _axes(ax, (5.6, 4.4))
        if background is not None and len(background):
            column = "twist_density" if "twist_density" in background else "phi_a_rest"
            for name, marker in PHASE_MARKERS.items():
                rows = background["phase"] == name
                ax.scatter(background.loc[rows, "extension"], background.loc[rows, column],
                           marker=marker, s=18, c="0.85", edgecolors="0.7", linewidths=0.4,
                           zorder=1)
        colours = [BLACK, BLUE, VERMILLION, "0.45"]
        handles = []
        for k, (name, table) in enumerate(paths.items()):
            colour = colours[k % len(colours)]
            ax.plot(table["extension"], table["twist_density"], color=colour, lw=1.2, zorder=2)
            handles.append(Line2D([], [], color=colour, lw=1.2, label=name))
            for phase_name, marker in PHASE_MARKERS.items():
                rows = table["phase"] == phase_name
                ax.scatter(table.loc[rows, "extension"], table.loc[rows, "twist_density"],
                           marker=marker, s=16, facecolors=colour, edgecolors="white",
                           linewidths=0.3, zorder=3)
        for phase_name, marker in PHASE_MARKERS.items():
            handles.append(Line2D([], [], ls="", marker=marker, ms=5, mfc="0.3", mec="white",
                                  label=phase_name))
        ax.set_xlabel(r"extension $L/L_0$")
        ax.set_ylabel(TWIST_DENSITY_LABEL)
        ax.legend(handles=handles, frameon=False, fontsize=7, loc="best")
        if title:
            ax.set_title(title)
        return _done(fig, path)


def _experiments(ax, experiments: pd.DataFrame) -> list:
    """Overlay experimental transitions in black; return their legend handles."""
    series = (experiments["series"].astype(str) if "series" in experiments
              else pd.Series(["experiment"] * len(experiments), index=experiments.index))
    kind = experiments["kind"].astype(str)
    handles = []
    for i, name in enumerate(dict.fromkeys(series)):
        marker = EXPERIMENT_MARKERS[i % len(EXPERIMENT_MARKERS)]
        for k, face in (("plectoneme", "none"), ("solenoid", "black")):
            rows = (series == name) & (kind == k)
            ax.scatter(experiments.loc[rows, "extension"], experiments.loc[rows, "twist_density"],
                       marker=marker, s=40, facecolors=face, edgecolors="black", linewidths=1.0,
                       zorder=4)
        handles.append(Line2D([], [], ls="", marker=marker, ms=7, mfc="none", mec="black",
                              label=name))
    handles.append(Line2D([], [], ls="", marker="o", ms=6, mfc="none", mec="black",
                          label="exp. plectoneme (hollow)"))
    handles.append(Line2D([], [], ls="", marker="o", ms=6, mfc="black", mec="black",
                          label="exp. solenoid (solid)"))
    return handles


def topology_curves(result_or_dict: RunResult | dict, path=None, *,
                    rest_radius: float | None = None, rest_length: float | None = None,
                    title: str | None = None, ax=None) -> Figure:
    """Link, twist and writhe (turns) against twist density Φa (paper Fig. 2).

    Φa = end rotation (rad) × rest radius / rest length. A RunResult supplies both lengths
    (from its diagnostics); a plain history dict needs `rest_radius` and `rest_length` (m).
    """
    labels = []
    if isinstance(result_or_dict, RunResult):
        history = result_or_dict.history
        diag = result_or_dict.diagnostics
        labels = [s.get("label", "") for s in diag.get("stages", [])]
        rest_radius = rest_radius or diag.get("rest_radius")
        rest_length = rest_length or diag.get("rest_length",
                                               float(np.sum(result_or_dict.rest_lengths)))
        status = result_or_dict.status
    else:
        history, status = result_or_dict, "ok"
    missing = [k for k in ("end_rotation", "link", "twist", "writhe") if k not in history]
    if missing:
        raise ValueError(f"topology_curves needs history columns {missing}; run with topology "
                         "on (link, twist and writhe are computed from the snapshots)")
    if not all(v and np.isfinite(v) for v in (rest_radius, rest_length)):
        raise ValueError("topology_curves needs rest_radius and rest_length (m) to compute "
                         "Φa; pass them for a plain history dict")
    turned = rotation_put_in(history)
    phi_a = units.twist_density_for_rotation(turned, rest_radius, rest_length)

    with matplotlib.rc_context(STYLE):
        fig, ax = _axes(ax, (5.0, 3.6))
        ax.plot(phi_a, history["link"], color=BLACK, lw=1.8, label="link $Lk$")
        ax.plot(phi_a, history["twist"], color=BLUE, lw=1.6, ls="--", label="twist $Tw$")
        ax.plot(phi_a, history["writhe"], color=VERMILLION, lw=1.6, ls="-.",
                label="writhe $Wr$")
        ax.axhline(0.0, color="0.8", lw=0.8, zorder=0)
        _shade_stages(ax, phi_a, history, labels)
        if "link_escapes" in history:
            # link escape events (a loop slipping over an end): where the counter steps,
            # with the link lost or gained beyond what the clamps put in
            steps = np.flatnonzero(np.diff(history["link_escapes"], prepend=0.0) > 0)
            surplus = np.asarray(history["link"]) - turned / (2 * np.pi)
            for k, row in enumerate(steps):
                jump = surplus[row] - surplus[max(row - 1, 0)]
                ax.axvline(phi_a[row], color="0.5", lw=0.8, ls=":", zorder=0,
                           label="link escape" if k == 0 else None)
                ax.annotate(f"$\\Delta Lk$ = {jump:+.1f}", (phi_a[row], history["link"][row]),
                            xytext=(3, 6), textcoords="offset points", fontsize=7, color="0.3")
        ax.set_xlabel(TWIST_DENSITY_LABEL)
        ax.set_ylabel("turns")
        ax.legend(frameon=False)
        heading = title or ""
        if status != "ok":
            heading = f"{heading} (status: {status})".strip()
        if heading:
            ax.set_title(heading)
        return _done(fig, path)


def _shade_stages(ax, x: np.ndarray, history: dict, labels: list[str]) -> None:
    """Alternate light bands over the x range each protocol stage covers, named inside the
    top edge, when two or more stages cover a range (a continuation, a hat curve); a stage
    that keeps x fixed (a hold at constant twist) covers none."""
    if "stage" not in history or not len(x):
        return
    stage = np.asarray(history["stage"])
    spans = []
    for k in np.unique(stage):
        lo, hi = float(np.min(x[stage == k])), float(np.max(x[stage == k]))
        if hi - lo > 1e-9 * max(1.0, abs(hi)):
            spans.append((int(k), lo, hi))
    if len(spans) < 2:
        return
    for shaded, (k, lo, hi) in enumerate(spans):
        if shaded % 2 == 0:
            ax.axvspan(lo, hi, color="0.94", lw=0, zorder=-1)
        ax.text(0.5 * (lo + hi), 0.99, labels[k] if k < len(labels) else f"stage {k}",
                transform=ax.get_xaxis_transform(), ha="center", va="top", fontsize=7,
                color="0.45")


def force_displacement(history: dict | RunResult, path=None, *, stage: int | None = None,
                       title: str | None = None, ax=None) -> Figure:
    """End force against end displacement ΔU (paper Fig. 4a), with writhe on a twin axis of
    `ax` if the history has it. `stage` keeps only the rows of that protocol stage; ΔU is measured
    from the first row kept.
    """
    if isinstance(history, RunResult):
        history = history.history
    missing = [k for k in ("end_force", "end_displacement") if k not in history]
    if missing:
        raise ValueError(f"force_displacement needs history columns {missing}")
    rows = (np.asarray(history["stage"]) == stage if stage is not None
            else np.ones(len(history["end_force"]), dtype=bool))
    displacement = np.asarray(history["end_displacement"])[rows]
    displacement = displacement - displacement[0] if len(displacement) else displacement
    force = np.asarray(history["end_force"])[rows]

    with matplotlib.rc_context(STYLE):
        fig, ax = _axes(ax, (5.0, 3.6))
        lines = ax.plot(displacement, force, color=BLACK, lw=1.8, label="end force $F$")
        ax.set_xlabel(r"end displacement $\Delta U$ (m)")
        ax.set_ylabel(r"end force $F$ (N)")
        if "writhe" in history:
            twin = ax.twinx()
            twin.spines["right"].set_visible(True)
            lines += twin.plot(displacement, np.asarray(history["writhe"])[rows],
                               color=VERMILLION, lw=1.4, ls="--", label="writhe $Wr$")
            twin.set_ylabel("writhe $Wr$ (turns)", color=VERMILLION)
            twin.tick_params(axis="y", colors=VERMILLION)
            kept = np.asarray(history["writhe"])[rows]
            if len(kept) and np.ptp(kept) < 0.01:
                # a writhe that does not change: autoscaling would blow round-off up into a
                # signal, so show half a turn around it
                middle = float(np.mean(kept))
                twin.set_ylim(middle - 0.5, middle + 0.5)
            ax.legend(handles=lines, frameon=False)
        if title:
            ax.set_title(title)
        return _done(fig, path)


def hat_curve(result: RunResult, path=None, *, title: str | None = None,
              axes=None) -> Figure:
    """The hat curve: extension L/L0 and end torque against the turns put in, at constant
    force, one colour per protocol stage (up, down, back), with the buckling moments of the
    straight rod (clamped Greenhill, and 2√(BF) of a long rod) for the stretched rod
    (B/e², length e·L0 of the incompressible law). `axes`: the (extension, torque) pair of
    axes to draw into (default: a new figure, the two panels one above the other)."""
    from .theory import stretched_rod_buckling_moments

    h, d = result.history, result.diagnostics
    turns = rotation_put_in(h) / (2 * np.pi)
    length, radius = d["rest_length"], d["rest_radius"]
    extension = 1.0 + np.asarray(h["end_displacement"]) / length
    force = float(np.max(h["applied_force"]))
    _, greenhill, long_rod = stretched_rod_buckling_moments(force, d["youngs_modulus"], radius,
                                                            length)
    labels = [s["label"] for s in d.get("stages", [])]
    stage = np.asarray(h["stage"])
    colours = [BLACK, BLUE, VERMILLION, "0.5"]
    def spread(values: np.ndarray) -> float:
        return float(np.ptp(values)) if len(values) else 0.0

    drawn = [k for k, label in enumerate(labels) if label != "load"
             and spread(turns[stage == k]) > 0.0]
    if not drawn:
        # a run that is not turned under its load (a sweep's sample started on the straight
        # branch holds only) would give empty axes: say so instead
        raise ValueError(
            "a run whose end is turned under a constant load, as scene hat_curve does (this "
            f"run's stages {', '.join(labels) or '(none)'} turn it by "
            f"{spread(turns):.3g} turns): rodphase run hat_curve -o hat.h5")

    with matplotlib.rc_context(STYLE):
        if axes is None:
            fig = _figure(figsize=(5.0, 5.2))
            top, bottom = fig.subplots(2, 1, sharex=True)
        else:
            top, bottom = axes
            fig = top.figure
        for k, label in enumerate(labels):
            if label == "load":
                continue
            rows = stage == k
            colour = colours[k % len(colours)]
            top.plot(turns[rows], extension[rows], color=colour, lw=1.5, label=label)
            bottom.plot(turns[rows], h["end_torque"][rows], color=colour, lw=1.5)
        for sign in (1, -1):
            bottom.axhline(sign * greenhill, color="0.4", lw=0.9, ls="--",
                           label="clamped Greenhill $M_c$" if sign > 0 else None)
            bottom.axhline(sign * long_rod, color="0.6", lw=0.9, ls=":",
                           label=r"$2\sqrt{BF}$" if sign > 0 else None)
        top.set_ylabel(r"extension $L/L_0$")
        bottom.set_ylabel("end torque (N m)")
        bottom.set_xlabel("turns put in")
        top.legend(frameon=False, fontsize=8)
        bottom.legend(frameon=False, fontsize=8)
        top.set_title(title or f"hat curve at F = {force:.3g} N")
        return _done(fig, path)


# --- rod shapes ---------------------------------------------------------------------------

def control_response(history: dict | RunResult, path=None, *, title: str | None = None,
                     ax=None) -> Figure:
    """Response to a material control (paper Fig 4b, 4c): end displacement ΔU and the changes
    ΔWr, ΔTw against the control that moves (stiffness factor E/E0, else radius factor a/a0),
    from the first row where it starts to move; ΔWr and ΔTw on a twin axis of `ax`."""
    history = history.history if isinstance(history, RunResult) else history
    control = next((k for k in ("stiffness_factor", "radius_factor")
                    if np.ptp(np.asarray(history.get(k, [1.0]))) > 0), None)
    if control is None:
        raise ValueError("neither stiffness_factor nor radius_factor changes in this history")
    x = np.asarray(history[control])
    start = max(int(np.argmax(x != x[0])) - 1, 0)
    label = {"stiffness_factor": r"stiffness $E/E_0$", "radius_factor": r"radius $a/a_0$"}[control]
    with matplotlib.rc_context(STYLE):
        fig, ax = _axes(ax, (5.2, 3.6))
        u = np.asarray(history["end_displacement"])
        ax.plot(x[start:], 1e3 * (u[start:] - u[start]), color=BLACK, lw=1.8,
                label=r"end displacement $\Delta U$")
        ax.set_xlabel(label)
        ax.set_ylabel(r"$\Delta U$ (mm)")
        handles = ax.get_legend_handles_labels()[0]
        if "writhe" in history:
            twin = ax.twinx()
            for key, colour, style, name in (("writhe", VERMILLION, "-.", r"$\Delta Wr$"),
                                             ("twist", BLUE, "--", r"$\Delta Tw$")):
                y = np.asarray(history[key])
                twin.plot(x[start:], y[start:] - y[start], color=colour, ls=style, lw=1.5,
                          label=name)
            twin.set_ylabel("turns")
            handles += twin.get_legend_handles_labels()[0]
        ax.legend(handles=handles, frameon=False, loc="best")
        if title:
            ax.set_title(title)
        return _done(fig, path)


def _upright(positions: np.ndarray, axis: np.ndarray | None = None) -> np.ndarray:
    """Rotate points so that `axis` (default: first node → last node) points up (+z)."""
    if axis is None:
        axis = positions[-1] - positions[0]
    norm = np.linalg.norm(axis)
    if norm == 0:
        return positions
    a, z = axis / norm, np.array([0.0, 0.0, 1.0])
    v, c = np.cross(a, z), float(a @ z)
    if c < -1 + 1e-12:  # pointing down: half turn about x
        rotation = np.diag([1.0, -1.0, -1.0])
    else:  # Rodrigues' formula for the rotation taking a onto z
        vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
        rotation = np.eye(3) + vx + vx @ vx / (1 + c)
    return positions @ rotation.T


def _box(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre and per-axis half widths of the box holding `points`."""
    lo, hi = points.reshape(-1, 3).min(axis=0), points.reshape(-1, 3).max(axis=0)
    return (lo + hi) / 2, np.maximum(hi - lo, 1e-9) / 2


# Rod views are laid out by hand: mplot3d axes are always square, so a tall thin rod in a
# square axes wastes most of a figure. Each view gets a square axes as tall as its cell,
# overlapping its neighbours with a transparent background, and the cell is only as wide as
# the rod needs at the common scale.
VIEW_HEIGHT = 3.2  # inch
TITLE_HEIGHT = 0.3  # inch
VIEW = {"elev": 15, "azim": -60}


def _rod_axes(fig: Figure, centre_x: float, bottom: float, centre: np.ndarray,
              half: np.ndarray, zoom: float = 1.0):
    """A square 3D axes VIEW_HEIGHT tall, centred at `centre_x` (inch), `bottom` (inch)."""
    w, h = fig.get_size_inches()
    rect = ((centre_x - VIEW_HEIGHT / 2) / w, bottom / h, VIEW_HEIGHT / w, VIEW_HEIGHT / h)
    ax = fig.add_axes(rect, projection="3d", computed_zorder=False)
    return _rod_view(ax, centre, half, zoom)


def _rod_view(ax, centre: np.ndarray, half: np.ndarray, zoom: float = 1.0):
    """Set a 3D axes to show the box `centre` ± `half` at equal scale, in the common view."""
    for setter, c, d in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre, half):
        setter(c - d, c + d)
    # equal scale on all three axes; orthographic so a tube is equally thick near and far
    ax.set_box_aspect(tuple(half), zoom=zoom)  # a copy: mplot3d scales the array in place
    ax.set_proj_type("ortho")
    ax.view_init(**VIEW)
    ax.set_axis_off()
    ax.set_facecolor("none")
    return ax


def _fit_view(half: np.ndarray) -> tuple[float, float]:
    """Zoom that fits the box of half widths `half` in a VIEW_HEIGHT square, and the cell
    width (inch) it then needs. Measured on a probe figure: mplot3d sizes the box by rules
    of its own (the norm of the box aspect) that are simpler to measure than to restate."""
    probe = Figure(figsize=(VIEW_HEIGHT, VIEW_HEIGHT))
    FigureCanvasAgg(probe)
    ax = _rod_axes(probe, VIEW_HEIGHT / 2, 0.0, np.zeros(3), half)
    probe.canvas.draw()
    corners = np.array(list(itertools.product(*[(-d, d) for d in half])))
    x, y, _ = proj3d.proj_transform(*corners.T, ax.get_proj())
    width, height = np.ptp(ax.transData.transform(np.column_stack([x, y])), axis=0) / probe.dpi
    zoom = 0.96 * VIEW_HEIGHT / max(width, height)
    cell = float(np.clip(zoom * width + 0.15, 1.0, VIEW_HEIGHT))
    return zoom, round(cell * 75) / 75  # whole pixel pairs at 150 dpi, as MP4 encoders want


def _line_width(fig: Figure, ax, radius: float) -> float:
    """Line width (points) that draws a tube of `radius` (m) at the axes' data scale.

    mplot3d has no data-scaled line widths: measure the screen length of one metre along
    the vertical (orthographic view, so the scale is the same everywhere). Needs a drawn
    figure, so that the axes have their final size.
    """
    centre = np.array([np.mean(ax.get_xlim()), np.mean(ax.get_ylim()), np.mean(ax.get_zlim())])
    ends = np.array([centre, centre + [0.0, 0.0, 1.0]])
    x, y, _ = proj3d.proj_transform(ends[:, 0], ends[:, 1], ends[:, 2], ax.get_proj())
    pixels = ax.transData.transform(np.column_stack([x, y]))
    points_per_metre = np.linalg.norm(pixels[1] - pixels[0]) * 72 / fig.dpi
    return max(0.8, 2 * radius * points_per_metre)


def _rod_segments(ax, positions: np.ndarray):
    """Segments sorted far to near in the current view, so near strands hide far ones
    (mplot3d draws a collection in order and does not sort lines by depth)."""
    segments = np.stack([positions[:-1], positions[1:]], axis=1)
    mid = segments.mean(axis=1)
    _, _, depth = proj3d.proj_transform(mid[:, 0], mid[:, 1], mid[:, 2], ax.get_proj())
    order = np.argsort(depth)[::-1]
    # colour by arc length so the eye can follow one strand through a braid
    return segments[order], order / max(len(segments) - 1, 1)


def _draw_rod(ax, positions, width, collection=None):
    segments, order = _rod_segments(ax, positions)
    colours = matplotlib.colormaps["viridis"](order)
    if collection is None:
        collection = Line3DCollection(segments, colors=colours, linewidths=width,
                                      capstyle="round")
        ax.add_collection3d(collection)
    else:
        collection.set_segments(segments)
        collection.set_color(colours)
    return collection


PARAM_NAMES = {"extension": "L/L0", "twist_density": "Φa", "force_multiple": "F/F_C",
               "twist_density_current": "Φa (stretched rod)"}


def params_text(params: dict) -> str:
    """A run's sampled parameters in the paper's symbols: "L/L0 1.12, Φa 0.8"."""
    return ", ".join(f"{PARAM_NAMES.get(k, k)} {v:.3g}" if isinstance(v, float)
                     else f"{PARAM_NAMES.get(k, k)} {v}" for k, v in params.items())


def run_label(row) -> str:
    """A shape panel's label: the run's parameters, then its phase (or status)."""
    params = {k: row[k] for k in PARAM_NAMES if k in row and row[k] == row[k]}
    phase = row.get("phase") if isinstance(row.get("phase"), str) else row.get("status", "")
    return f"{params_text(params) or row.name}\n{phase}"


def shape_panels(table, most: int = 12) -> list[str]:
    """Up to `most` runs for a shape grid chosen by parameter, not by id: with a
    classification, as many of each phase as fit, each phase's spread over its twist
    densities; else evenly over the runs in order of twist."""
    twist = next((c for c in ("twist_density", "twist_density_current", "force_multiple")
                  if c in table), None)
    ordered = table.sort_values(twist) if twist else table
    if "phase" not in ordered:
        picks = np.unique(np.linspace(0, len(ordered) - 1, min(most, len(ordered))).astype(int))
        return list(ordered["run_id"].iloc[picks])
    groups = [g for _, g in ordered.groupby(ordered["phase"].fillna("failed"), sort=False)]
    share = max(1, most // max(len(groups), 1))
    chosen = []
    for group in groups:
        picks = np.unique(np.linspace(0, len(group) - 1, min(share, len(group))).astype(int))
        chosen += list(group["run_id"].iloc[picks])
    return chosen[:most]


def shape_grid(results: list[tuple[str, np.ndarray, float]], path=None, *, ncols: int = 6,
               axes=None) -> Figure:
    """Final rod shapes, one small 3D view each, drawn as tubes of the given radius.

    `results` holds (label, positions (n+1, 3) in m, radius in m). Each rod is turned so that
    its end-to-end axis points up; all views share one scale so sizes compare. Without
    `axes` the views are laid out side by side, `ncols` a row, each cell as wide as the rods
    need; `axes` is instead one 3D axes per rod (projection="3d") to draw into, each
    titled with its label.
    """
    if not results:
        raise ValueError("shape_grid needs at least one (label, positions, radius)")
    shapes = [_upright(np.asarray(p, float)) for _, p, _ in results]
    pad = 1.5 * max(r for _, _, r in results)
    # one box for all views, the two lateral axes alike so no direction looks squashed
    half = np.max([_box(p)[1] for p in shapes], axis=0) + pad
    half[:2] = half[:2].max()
    if axes is not None:
        return _shapes_into(results, shapes, half, list(axes), path)
    ncols = min(ncols, len(results))
    nrows = -(-len(results) // ncols)
    zoom, cell_w = _fit_view(half)
    lines = max(str(label).count("\n") + 1 for label, _, _ in results)
    cell_h = VIEW_HEIGHT + TITLE_HEIGHT * lines
    key_h = 0.45  # inches for the colour key under the views
    width = max(cell_w * ncols, 2.4)

    with matplotlib.rc_context(STYLE):
        fig = Figure(figsize=(width, cell_h * nrows + key_h))
        FigureCanvasAgg(fig)
        height = cell_h * nrows + key_h
        views = []
        for i, ((label, _, radius), shape) in enumerate(zip(results, shapes)):
            row, col = divmod(i, ncols)
            centre_x = (col + 0.5) * cell_w + 0.5 * (width - cell_w * ncols)
            bottom = key_h + (nrows - 1 - row) * cell_h
            ax = _rod_axes(fig, centre_x, bottom, _box(shape)[0], half, zoom)
            fig.text(centre_x / width, (bottom + VIEW_HEIGHT) / height, label, ha="center",
                     va="bottom", fontsize=8 if lines > 1 else 9)
            views.append((ax, shape, radius))
        # the colour along each rod is its arc length: a key, so a strand can be followed
        key = fig.add_axes([0.5 - 0.6 / width, 0.2 * key_h / height, 1.2 / width,
                            0.2 * key_h / height])
        fig.colorbar(ScalarMappable(Normalize(0, 1), matplotlib.colormaps["viridis"]),
                     cax=key, orientation="horizontal", ticks=[])
        key.text(-0.04, 0.5, "start", transform=key.transAxes, ha="right", va="center",
                 fontsize=7)
        key.text(1.04, 0.5, "end", transform=key.transAxes, ha="left", va="center", fontsize=7)
        key.set_title("colour: arc length", fontsize=7, pad=2)
        fig.canvas.draw()  # final axes sizes, for the line widths
        for ax, shape, radius in views:
            _draw_rod(ax, shape, _line_width(fig, ax, radius))
        return _done(fig, path)


def _shapes_into(results, shapes, half, axes, path) -> Figure:
    """shape_grid into the caller's 3D axes (one per rod)."""
    if len(axes) != len(results):
        raise ValueError(f"shape_grid got {len(axes)} axes for {len(results)} rods")
    if any(getattr(ax, "name", "") != "3d" for ax in axes):
        raise ValueError("shape_grid draws into 3D axes: make them with projection='3d'")
    fig = _root(axes[0])
    with matplotlib.rc_context(STYLE):
        for ax, (label, _, _), shape in zip(axes, results, shapes):
            _rod_view(ax, _box(shape)[0], half)
            ax.set_title(label, fontsize=9)
        # the tube widths need the axes' final sizes: lay out without rendering pixels
        fig.draw_without_rendering()
        for ax, (_, _, radius), shape in zip(axes, results, shapes):
            _draw_rod(ax, shape, _line_width(fig, ax, radius))
        return _done(fig, path)


def movie(snapshot_positions: np.ndarray, radius: float, path, fps: int = 10, *,
          times: np.ndarray | None = None, twist_density: np.ndarray | None = None,
          max_frames: int = 200, height: float | None = None) -> Path:
    """Animate a rod (S, n+1, 3) with fixed axes over all frames.

    Writes MP4 if ffmpeg is on PATH and `path` does not end in .gif, else a GIF (Pillow) next
    to `path` with the suffix .gif. Returns the path written. At most `max_frames` evenly
    spaced frames are kept (GIFs grow with every frame). `times` (s) and `twist_density`
    (the paper's Φa of each frame) label the frames; `height` (inches at 150 dpi) scales the
    picture.
    """
    frames = np.asarray(snapshot_positions, float)
    if frames.ndim != 3 or frames.shape[0] == 0:
        raise ValueError(f"movie needs snapshots of shape (S, n+1, 3) with S > 0, got "
                         f"{frames.shape}")
    keep = np.unique(np.linspace(0, len(frames) - 1, min(max_frames, len(frames))).astype(int))
    axis = frames[0, -1] - frames[0, 0]  # one rotation for every frame: the camera stays put
    frames = np.stack([_upright(f, axis) for f in frames[keep]])
    centre, half = _box(frames)
    half += 1.5 * radius
    half[:2] = half[:2].max()
    path = Path(path)
    use_mp4 = shutil.which("ffmpeg") is not None and path.suffix.lower() != ".gif"
    path = path if use_mp4 or path.suffix.lower() == ".gif" else path.with_suffix(".gif")
    path.parent.mkdir(parents=True, exist_ok=True)

    with matplotlib.rc_context(STYLE):
        zoom, width = _fit_view(half)
        width = max(width, 2.4 if twist_density is not None else 1.6)  # room for the label
        fig = Figure(figsize=(width, VIEW_HEIGHT + TITLE_HEIGHT))
        FigureCanvasAgg(fig)
        ax = _rod_axes(fig, width / 2, 0.0, centre, half, zoom)
        label = fig.text(0.5, 1.0, "", ha="center", va="top")
        fig.canvas.draw()
        collection = _draw_rod(ax, frames[0], _line_width(fig, ax, radius))

        def update(i):
            _draw_rod(ax, frames[i], None, collection)
            text = f"t = {times[keep[i]]:.3g} s" if times is not None else f"frame {keep[i]}"
            if twist_density is not None:
                text += f", Φa = {twist_density[keep[i]]:.3g}"
            label.set_text(text)
            return collection, label

        anim = animation.FuncAnimation(fig, update, frames=len(frames), blit=False)
        writer = (animation.FFMpegWriter(fps=fps) if use_mp4
                  else animation.PillowWriter(fps=fps))
        # the layout is in inches; a size asked for scales the pixels
        scale = 1.0 if height is None else height / (VIEW_HEIGHT + TITLE_HEIGHT)
        anim.save(path, writer=writer, dpi=150 * scale)
    return path
