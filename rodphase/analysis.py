"""Measurements on rod shapes and histories: contact partners, coil geometry, bursts.

Pure functions: arrays in ((N, 3) points, one per row, SI units), numbers or arrays out; no
I/O, no plotting, no simulation. `rodphase.classify` builds its alignment on `partners`, and
studies/figures.py builds the numbers of docs/explanation/validation.md on the rest.

The reference for the definitions is Charles, Gazzola & Mahadevan, "Topology, geometry and
mechanics of strongly stretched and twisted filaments" (PRL 2019): "the paper" below.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from . import units
from .result import rotation_put_in

__all__ = [
    "bursts", "coil_height", "free_coil_height", "helix_axis", "local_alignment",
    "partner_signs", "partners", "plectoneme_turns", "sawtooth_drops", "smooth",
    "solenoid_geometry", "stage_rows", "twist_density", "writhe_steps",
]


def _positive(name, value):
    v = float(value)
    if not (math.isfinite(v) and v > 0.0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return v


def _nodes(points) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 2:
        raise ValueError(f"points must have shape (n+1, 3) with n >= 1, got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("points must be finite")
    return p


# ------------------------------------------------------------------ contact partners


def partners(points, radius, rest_length=None, epsilon=0.2, min_separation=None,
             separation=5.0) -> np.ndarray:
    """Each element's partner in the paper's classifier (-1: none), shape (n,).

    The paper's rule (its Fig 3 classifier): for element i of a rod with nodes `points`
    (n+1, 3), the partner is the element k nearest in space, by midpoint distance, among
    those far along the rod, |k − i| > min_separation (by default `separation`·n·a/L0, the
    paper's 5 rest radii of arc, with the rest radius a = `radius` and L0 = `rest_length`,
    which defaults to the polyline length), and
    within contact range, |x_k − x_i| < (2 + epsilon)·a. Both conditions are strict; of
    equally near candidates the lower index wins. This is the one definition of "partner"
    that the alignment classifier and every coil measurement use.
    """
    p = _nodes(points)
    a = _positive("radius", radius)
    eps = float(epsilon)
    if not (math.isfinite(eps) and eps > -2.0):
        raise ValueError(f"epsilon must be a finite number > -2, got {epsilon!r}")
    e = np.diff(p, axis=0)
    n = e.shape[0]
    if min_separation is None:
        L0 = (
            np.linalg.norm(e, axis=1).sum()
            if rest_length is None
            else _positive("rest_length", rest_length)
        )
        if not L0 > 0.0:
            raise ValueError("points have zero length; give rest_length")
        radii = float(separation)
        if not (math.isfinite(radii) and radii >= 0.0):
            raise ValueError(f"separation must be a finite number >= 0, got {separation!r}")
        gap = radii * n * a / L0
    else:
        gap = float(min_separation)
        if not (math.isfinite(gap) and gap >= 0.0):
            raise ValueError(f"min_separation must be a finite number >= 0, got {min_separation!r}")

    partner = np.full(n, -1, dtype=np.int64)
    x = 0.5 * (p[1:] + p[:-1])
    cutoff = (2.0 + eps) * a
    pairs = cKDTree(x).query_pairs(cutoff, output_type="ndarray")
    if len(pairs) == 0:
        return partner
    i, k = pairs[:, 0], pairs[:, 1]
    d = np.linalg.norm(x[k] - x[i], axis=1)
    # query_pairs includes the boundary; the paper's conditions are both strict.
    keep = (np.abs(k - i) > gap) & (d < cutoff)
    i, k, d = i[keep], k[keep], d[keep]
    # Each pair serves both of its elements: take the nearest partner of every element.
    src = np.concatenate([i, k])
    dst = np.concatenate([k, i])
    dist = np.concatenate([d, d])
    order = np.lexsort((dst, dist, src))  # by element, then distance, ties to lower index
    src, dst = src[order], dst[order]
    first = np.ones(src.shape[0], dtype=bool)
    first[1:] = src[1:] != src[:-1]
    partner[src[first]] = dst[first]
    return partner


def partner_signs(points, partner) -> np.ndarray:
    """sign(e_i · e_k) of each element i and its partner k = partner[i] (NaN where k = -1):
    +1 parallel (neighbouring solenoid turns), −1 antiparallel (plectoneme strands)."""
    e = np.diff(np.asarray(points, dtype=np.float64), axis=0)
    partner = np.asarray(partner)
    signs = np.full(partner.shape[0], np.nan)
    has = partner >= 0
    signs[has] = np.sign(np.einsum("ij,ij->i", e[has], e[partner[has]]))
    return signs


def local_alignment(points, radius, rest_length=None, epsilon=0.2) -> np.ndarray:
    """Per element, sign(e_i · e_k) with its partner k (NaN: no partner); the paper's
    alignment is the mean over the elements that have one (`np.nanmean`)."""
    return partner_signs(points, partners(points, radius, rest_length, epsilon))


# ------------------------------------------------------------------ coil geometry


def helix_axis(points) -> np.ndarray:
    """Unit axis of a helix-like polyline (N, 3): the direction along which its unit tangents
    vary least (the eigenvector of their covariance with the smallest eigenvalue; a helix's
    tangents sweep a cone about its axis), oriented from the first point towards the last."""
    p = np.asarray(points, dtype=np.float64)
    t = np.diff(p, axis=0)
    t /= np.linalg.norm(t, axis=1)[:, None]
    _, vectors = np.linalg.eigh(np.cov(t.T))
    axis = vectors[:, 0]
    return axis if axis @ (p[-1] - p[0]) >= 0 else -axis


def coil_height(points) -> float:
    """End-to-end distance along the helix axis [m] (the muscle's length, paper Fig 4c)."""
    p = np.asarray(points, dtype=np.float64)
    return float((p[-1] - p[0]) @ helix_axis(p))


def solenoid_geometry(points, radius, rest_length) -> dict:
    """Turns, pitch and contour length per turn of the solenoidal part of a rod (paper Fig 4a:
    the solenoid "uncoils by one pitch" per force drop).

    A solenoid element's partner lies in the neighbouring turn, so |k − i| is the number of
    elements per turn and |x_k − x_i| the pitch [m] (adjacent turns touch). Elements paired in
    parallel with |k − i| within 25 % of the median are the coil; the straight tails, which
    run along the coil's axis and touch its first turns, are left out. Returns {} when fewer
    than 8 elements pair in parallel, else elements (first, last of the coil),
    elements_per_turn, turns, pitch [m] and contour_per_turn [m].
    """
    points = np.asarray(points, dtype=np.float64)
    partner = partners(points, radius, rest_length)
    sign = partner_signs(points, partner)
    coil = np.where((sign > 0) & (partner >= 0))[0]
    if len(coil) < 8:
        return {}
    sep = np.abs(partner[coil] - coil)
    per_turn = float(np.median(sep))
    coil = coil[np.abs(sep - per_turn) < 0.25 * per_turn]
    x = 0.5 * (points[1:] + points[:-1])
    lengths = np.linalg.norm(np.diff(points, axis=0), axis=1)
    pitch = float(np.median(np.linalg.norm(x[partner[coil]] - x[coil], axis=1)))
    # the longest stretch of coil elements (gaps of up to 3 elements bridged): the tails that
    # touch the first turns form stretches of their own
    breaks = np.where(np.diff(coil) > 3)[0]
    runs = np.split(coil, breaks + 1)
    coil = max(runs, key=len)
    turns = len(coil) / per_turn  # every coil element has a partner in a neighbouring turn
    return {"elements": [int(coil.min()), int(coil.max())], "elements_per_turn": per_turn,
            "turns": float(turns),
            "pitch": pitch, "contour_per_turn": float(per_turn * np.median(lengths[coil]))}


def plectoneme_turns(points, radius, rest_length) -> dict:
    """Supercoil turns of the plectonemic part (paper Fig 2: writhe per plectoneme turn).

    Along one strand (elements i with an antiparallel partner k > i), the turning of the
    inter-strand vector x_k − x_i about the local plectoneme axis (e_i − e_k) is summed; one
    supercoil turn is one full revolution. Returns strand_elements and turns (≥ 0).
    """
    points = np.asarray(points, dtype=np.float64)
    partner = partners(points, radius, rest_length)
    sign = partner_signs(points, partner)
    x = 0.5 * (points[1:] + points[:-1])
    e = np.diff(points, axis=0)
    e /= np.linalg.norm(e, axis=1)[:, None]
    strand = [i for i in range(len(sign)) if sign[i] < 0 and partner[i] > i]
    total, previous = 0.0, None
    for i in strand:
        k = partner[i]
        axis = e[i] - e[k]
        axis /= np.linalg.norm(axis)
        d = x[k] - x[i]
        d -= axis * (d @ axis)
        d /= np.linalg.norm(d)
        if previous is not None:
            p = previous - axis * (previous @ axis)
            p /= np.linalg.norm(p)
            total += math.atan2(axis @ np.cross(p, d), p @ d)
        previous = d
    return {"strand_elements": len(strand), "turns": abs(total) / units.TURN}


def free_coil_height(helix_radius, pitch, loops, twist_density0, factor):
    """Height [m] of an unloaded coil without contact as the fibre radius grows by `factor`
    with a·κ3⁰ fixed (the paper's Fig 4c muscle, its exact no-contact reference).

    With no load the equilibrium is the rest shape: a helix of the annealed curvature
    K = R/(R² + c²) (c = pitch/2π) and torsion τ = κ3⁰/f − ω, where κ3⁰ = `twist_density0`
    [rad/m] is the initial material twist density (the rest twist, scaled by 1/f) and
    ω = κ3⁰ − τ0 the rate at which the material frame turns relative to the Frenet frame
    (fixed by the annealed (κ1, κ2), which do not change). The fibre length is
    loops·2π·√(R² + c²); the height is length·τ/√(K² + τ²).
    """
    c = pitch / units.TURN
    k = helix_radius / (helix_radius**2 + c**2)
    tau0 = c / (helix_radius**2 + c**2)
    omega = twist_density0 - tau0
    tau = twist_density0 / factor - omega
    length = loops * units.TURN * math.hypot(helix_radius, c)
    return length * tau / np.hypot(k, tau)


# ------------------------------------------------------------------ histories


def twist_density(result) -> np.ndarray:
    """The paper's Φa = θ·a0/L0 [rad] at every history row of a RunResult, θ the rotation
    the clamps have put in, a0 and L0 the rest radius and length."""
    d = result.diagnostics
    return units.twist_density_for_rotation(rotation_put_in(result.history), d["rest_radius"],
                                            d["rest_length"])


def stage_rows(result, label_start: str) -> np.ndarray:
    """Boolean mask of the history rows of the stages whose label starts with `label_start`."""
    labels = [s["label"] for s in result.diagnostics["stages"]]
    wanted = [i for i, lab in enumerate(labels) if lab.startswith(label_start)]
    return np.isin(np.asarray(result.history["stage"]), wanted)


def smooth(y, width: int) -> np.ndarray:
    """Centred running mean of `y` over `width` rows (edges use the rows available)."""
    width = max(1, int(width))
    kernel = np.ones(width)
    num = np.convolve(y, kernel, "same")
    den = np.convolve(np.ones_like(y), kernel, "same")
    return num / den


def bursts(x, y, width: int, min_gain: float = 0.1, contrast: float = 1.5) -> list[dict]:
    """Steps of y along x (the paper's stepwise writhe growth, Fig 2 and 4b).

    The rate dy/dx, smoothed over `width` rows, splits at its local minima (over ±width
    rows) into segments; a segment is a burst when its peak rate is more than `contrast`
    times the rate at both ends and y gains at least `min_gain` over it. Returns each
    burst's start ("from"), end ("to"), peak position ("at") in units of x, its "gain" in
    units of y, and its first and last row ("rows").
    """
    rate = smooth(np.gradient(y, x), width)
    n = len(rate)
    minima = sorted({0, n - 1} | {i for i in range(1, n - 1)
                                  if rate[i] == rate[max(0, i - width):i + width + 1].min()})
    out = []
    for a, b in zip(minima[:-1], minima[1:]):
        if b - a < 2:
            continue
        peak = a + int(np.argmax(rate[a:b]))
        gain = float(y[b] - y[a])
        if gain >= min_gain and rate[peak] > contrast * max(rate[a], rate[b], 1e-12):
            out.append({"from": float(x[a]), "to": float(x[b]), "at": float(x[peak]),
                        "gain": gain, "rows": [int(a), int(b)]})
    return out


STEP_MIN = 0.3  # turns: half the writhe of one solenoid loop (0.6–0.85 turns), well above noise
STEP_CONTRAST = 1.5  # a step's peak rate over the rate at both of its ends


def writhe_steps(x, y, min_step: float = STEP_MIN, contrast: float = STEP_CONTRAST,
                 width: int = 1, direction: int = +1) -> list[dict]:
    """The steps in which y (writhe, turns) changes along x (twist, time or end displacement):
    the paper's "twist into writhe in steps" (Fig 2a, 2b) and "loses a turn per drop" (Fig 4a),
    counted rather than described (issue #49).

    y is read as increments between consecutive samples (rodphase's cross-check resamples both
    codes every 0.5 s, 0.08–0.1 turns of twist: `studies/twist_into_writhe.py`), so that a
    step one or two samples long is not smeared into its neighbours. The increments' rates
    split at their local minima (over ±`width` intervals) into segments; a segment is a step
    when its peak rate exceeds `contrast` (1.5) times the rate of the two minima that bound it
    and y gains at least `min_step` (0.3 turns: half a solenoid loop's writhe) between them.
    So a smooth ramp, however steep, has no steps; a staircase of n rises ≥ 0.3 turns
    separated by slower stretches has n; a collapse (one fast rise of several loops with no
    slower stretch inside) is one. `direction` −1 counts steps of loss (Fig 4a's writhe under
    the pull).

    Returns, per step: "from", "to" (x where it starts and ends: the bounding minima), "at"
    (the middle of its fastest interval), "gain" (turns, > 0 for either direction: the change
    between the bounding minima, so it includes any slower growth up to the next minimum),
    "to_value" (y at its end) and "rows" (the first and last sample of it).
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if direction not in (1, -1):
        raise ValueError(f"direction must be +1 or -1, got {direction!r}")
    if len(x) != len(y) or len(x) < 3:
        raise ValueError(f"x and y must have the same length >= 3, got {len(x)} and {len(y)}")
    if np.any(np.diff(x) <= 0):
        raise ValueError("x must increase")
    rate = direction * np.diff(y) / np.diff(x)  # one per interval
    m = len(rate)
    width = max(1, int(width))
    minima = sorted({0, m - 1} | {k for k in range(1, m - 1)
                                  if rate[k] == rate[max(0, k - width):k + width + 1].min()})
    out = []
    for a, b in zip(minima[:-1], minima[1:]):
        if b - a < 2:
            continue
        # the step: the intervals strictly between the two bounding minima
        first, last = a + 1, b  # samples: from the start of interval a+1 to the end of b-1
        peak = a + 1 + int(np.argmax(rate[a + 1:b]))
        gain = direction * float(y[last] - y[first])
        floor = max(rate[a], rate[b], 1e-12)
        if gain >= min_step and rate[peak] > contrast * floor:
            out.append({"from": float(x[first]), "to": float(x[last]),
                        "at": float(0.5 * (x[peak] + x[peak + 1])), "gain": gain,
                        "to_value": float(y[last]), "rows": [int(first), int(last)]})
    return out


def sawtooth_drops(x, y, window: int, min_drop: float = 1.0, merge: float = 0.03) -> list[dict]:
    """Drops of a sawtooth y(x) (the end force of a pulled solenoid, paper Fig 4a).

    A drop starts at a local maximum of y (over ±`window` rows) and ends at the minimum of y
    before y climbs back above that peak; it counts when y falls by more than `min_drop`.
    Drops whose peaks are closer than `merge` in x merge into the deeper one. Returns each
    drop's peak and bottom as rows and as (x, y): peak_row, bottom_row, peak_x, peak_y,
    bottom_x, bottom_y.
    """
    x, y = np.asarray(x), np.asarray(y)
    drops: list[dict] = []
    for i in range(window, len(y) - window):
        if y[i] < y[i - window:i + window + 1].max():
            continue
        back = np.where(y[i + 1:] > y[i])[0]
        end = i + 1 + (back[0] if len(back) else len(y) - i - 1)
        k = i + int(np.argmin(y[i:end]))
        if y[i] - y[k] < min_drop:
            continue
        drop = {"peak_row": i, "bottom_row": k, "peak_x": float(x[i]), "peak_y": float(y[i]),
                "bottom_x": float(x[k]), "bottom_y": float(y[k])}
        if drops and drop["peak_x"] - drops[-1]["peak_x"] < merge:
            if drop["peak_y"] - drop["bottom_y"] > drops[-1]["peak_y"] - drops[-1]["bottom_y"]:
                drops[-1] = drop
            continue
        drops.append(drop)
    return drops
