"""Shape classification by loop alignment (Charles, Gazzola & Mahadevan, PRL 2019).

For each element i, k is the nearest element that is far along the rod but within contact
range in space; alignment is the mean of sign(e_i . e_k) over the elements that have such a
k. Plectoneme strands are antiparallel (-> -1), neighbouring solenoid turns parallel (-> +1).
"""

from __future__ import annotations

import math

import numpy as np

from .analysis import partner_signs, partners

__all__ = ["PHASES", "UNSEEN_COIL_WRITHE", "alignment", "phase", "phase_code", "unseen_coil"]

#: Phase names; their index is the integer code used for storage.
PHASES = ("straight", "plectoneme", "solenoid", "mixed")


def alignment(points, radius, rest_length=None, epsilon=0.2, min_separation=None,
              separation=5.0) -> float:
    """The paper's alignment of a rod with nodes `points` (n+1, 3) and rest radius `radius`.

    Elements i and k count as neighbours when their midpoints are closer than
    (2 + epsilon) * radius and |k - i| > min_separation, by default separation·n·radius /
    rest_length: `separation` rest radii of arc, the paper's 5 (rest_length defaults to the
    polyline length of `points`). A coil whose turns are shorter than that many radii of
    arc (the tightest solenoids above L/L0 ≈ 1.165, docs/history/reproduction.md) has no partners
    and reads as straight: a smaller `separation` sees it. Each element takes its
    nearest such neighbour (`rodphase.analysis.partners`). Returns NaN when no element has
    one (a straight or open shape).
    """
    partner = partners(points, radius, rest_length, epsilon, min_separation, separation)
    paired = partner >= 0
    if not np.any(paired):
        return math.nan
    return float(partner_signs(points, partner)[paired].mean())


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


#: |Wr| [turns] above which a shape the classifier calls straight is a coil it cannot see
UNSEEN_COIL_WRITHE = 0.5


def unseen_coil(phase_name: str, writhe: float) -> bool:
    """A final shape labelled straight that writhes by more than UNSEEN_COIL_WRITHE turns: the
    paper's classifier looks for partners at least 5 radii away along the rod, and a solenoid
    whose turns are shorter than that (the tightest coils, above L/L0 ≈ 1.165 at Fig 3's
    loads, docs/history/reproduction.md) has none, so it reads as straight. A straight rod writhes by
    ~0 (its frozen imperfection: < 1e-3 turns); half a turn is a loop."""
    return phase_name == "straight" and math.isfinite(writhe) and abs(writhe) > UNSEEN_COIL_WRITHE


def phase_code(name) -> int:
    """Integer code of a phase name (its index in PHASES)."""
    try:
        return PHASES.index(name)
    except ValueError:
        raise ValueError(f"phase must be one of {PHASES}, got {name!r}") from None
