"""Shape classification by loop alignment (Charles, Gazzola & Mahadevan, PRL 2019).

For each element i, k is the nearest element that is far along the rod but within contact
range in space; alignment is the mean of sign(e_i . e_k) over the elements that have such a
k. Plectoneme strands are antiparallel (-> -1), neighbouring solenoid turns parallel (-> +1).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["PHASES", "alignment", "phase", "phase_code"]

#: Phase names; their index is the integer code used for storage.
PHASES = ("straight", "plectoneme", "solenoid", "mixed")


def _positive(name, value):
    v = float(value)
    if not (math.isfinite(v) and v > 0.0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return v


def alignment(points, radius, rest_length=None, epsilon=0.2, min_separation=None) -> float:
    """The paper's alignment of a rod with nodes `points` (n+1, 3) and rest radius `radius`.

    Elements i and k count as neighbours when their midpoints are closer than
    (2 + epsilon) * radius and |k - i| > min_separation, by default 5 n radius / rest_length
    (rest_length defaults to the polyline length of `points`). Each element takes its
    nearest such neighbour. Returns NaN when no element has one (a straight or open shape).
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 2:
        raise ValueError(f"points must have shape (n+1, 3) with n >= 1, got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("points must be finite")
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
        gap = 5.0 * n * a / L0
    else:
        gap = float(min_separation)
        if not (math.isfinite(gap) and gap >= 0.0):
            raise ValueError(f"min_separation must be a finite number >= 0, got {min_separation!r}")

    x = 0.5 * (p[1:] + p[:-1])
    cutoff = (2.0 + eps) * a
    pairs = cKDTree(x).query_pairs(cutoff, output_type="ndarray")
    if len(pairs) == 0:
        return math.nan
    i, k = pairs[:, 0], pairs[:, 1]
    d = np.linalg.norm(x[k] - x[i], axis=1)
    # query_pairs includes the boundary; the paper's conditions are both strict.
    keep = (np.abs(k - i) > gap) & (d < cutoff)
    if not np.any(keep):
        return math.nan
    i, k, d = i[keep], k[keep], d[keep]
    # Each pair serves both of its elements: take the nearest partner of every element.
    src = np.concatenate([i, k])
    dst = np.concatenate([k, i])
    dist = np.concatenate([d, d])
    order = np.lexsort((dst, dist, src))  # by element, then distance, ties to lower index
    src, dst = src[order], dst[order]
    first = np.ones(src.shape[0], dtype=bool)
    first[1:] = src[1:] != src[:-1]
    src, dst = src[first], dst[first]
    signs = np.sign(np.einsum("ij,ij->i", e[src], e[dst]))
    return float(signs.mean())


def _threshold(name, value):
    v = float(value)
    if not (math.isfinite(v) and -1.0 <= v <= 1.0):
        raise ValueError(f"{name} must be a number in [-1, 1], got {value!r}")
    return v


def phase(alignment, plectoneme_below=-0.5, solenoid_above=0.5) -> str:
    """Phase name for an alignment value: NaN is "straight".

    "plectoneme" below `plectoneme_below`, "solenoid" above `solenoid_above`, "mixed" in
    between. Both thresholds lie in [-1, 1] with plectoneme_below <= solenoid_above.
    """
    lo = _threshold("plectoneme_below", plectoneme_below)
    hi = _threshold("solenoid_above", solenoid_above)
    if lo > hi:
        raise ValueError(
            f"plectoneme_below ({plectoneme_below!r}) must not exceed solenoid_above "
            f"({solenoid_above!r})"
        )
    value = float(alignment)
    if math.isnan(value):
        return "straight"
    if value < lo:
        return "plectoneme"
    if value > hi:
        return "solenoid"
    return "mixed"


def phase_code(name) -> int:
    """Integer code of a phase name (its index in PHASES)."""
    try:
        return PHASES.index(name)
    except ValueError:
        raise ValueError(f"phase must be one of {PHASES}, got {name!r}") from None
