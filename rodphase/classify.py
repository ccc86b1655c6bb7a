"""Shape classification by loop alignment (Charles, Gazzola & Mahadevan, PRL 2019).

For each element i, k is the nearest element that is far along the rod but within contact
range in space; alignment is the mean of sign(e_i . e_k) over the elements that have such a
k. Plectoneme strands are antiparallel (-> -1), neighbouring solenoid turns parallel (-> +1).
"""

from __future__ import annotations

import math

import numpy as np

from .analysis import partner_signs, partners

__all__ = ["ONSET_BAND", "PHASES", "UNSEEN_COIL_WRITHE", "alignment", "near_onset", "phase",
           "phase_code", "unseen_coil"]

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


#: |Φa/Φa_c − 1| below which a run's label is decided by the stability push, not by the
#: physics: the band around the straight rod's onset Φa_c (the model's own, rod/onset.py, at
#: the run's load and elements) inside which a run is flagged `near_onset`. Measured on
#: twist_under_load at n = 80 (quasi-static start, holds probed): at L/L0 = 1.217 the run
#: ended straight or a solenoid depending on the push's size (0.05, 0.1, 0.2 rest radii) at
#: Φa/Φa_c − 1 = ±3e-4 (its dynamic state is that close to the perfect rod's onset: the
#: imperfection and the ramp), and as the static test says (straight below, buckled above)
#: for all three sizes at ±1e-3 and beyond; the band is twice that.
ONSET_BAND = 2e-3

#: |Φa/Φa_sheared − 1| within which a table computes a run's model onset at all (tabulate.
#: onset_columns): the sheared clamped Greenhill twist is the model's n → ∞ limit, and the
#: model's onset lies below it by 0.03-0.2 % at n = 80 for L/L0 1.02-1.1, 2.2 % at L/L0 1.6,
#: 3.0 % at n = 40 and L/L0 1.3 (more twist per element, further below); twice that is
#: the screen.
ONSET_SCREEN = 0.06


def near_onset(onset_ratio: float, band: float = ONSET_BAND) -> bool:
    """A run at `onset_ratio` = Φa/Φa_c is within `band` of the straight rod's onset: its
    label (straight, or the buckled shape it fell into) is what the stability push made of a
    marginal rod. The static test is the answer there: the rod is straight below Φa_c and
    buckles above it. NaN (not computed: far from the onset, or no onset) is not near."""
    return bool(math.isfinite(onset_ratio) and abs(onset_ratio - 1.0) < band)


def phase_code(name) -> int:
    """Integer code of a phase name (its index in PHASES)."""
    try:
        return PHASES.index(name)
    except ValueError:
        raise ValueError(f"phase must be one of {PHASES}, got {name!r}") from None
