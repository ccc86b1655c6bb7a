"""Alignment classifier on ideal shapes: solenoid, plectoneme, straight, half-and-half."""

import math

import numpy as np
import pytest

from rodphase.classify import PHASES, alignment, phase, phase_code

A = 0.025  # rest radius a (m), the paper's a = 0.025 L0 with L0 = 1 m
GAP = 2.05 * A  # centreline distance of touching strands, just outside 2a


# --------------------------------------------------------------------------- shape builders


def resample(dense, ds):
    """Polyline through `dense` with equal segments close to ds (elements no longer than a)."""
    seg = np.linalg.norm(np.diff(dense, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    n = int(np.ceil(s[-1] / ds))
    t = np.linspace(0.0, s[-1], n + 1)
    return np.stack([np.interp(t, s, dense[:, c]) for c in range(3)], axis=1)


def line(p, q, n=50):
    return np.linspace(p, q, n)


def helix(center, radius, pitch, turns, phase0=0.0, z0=0.0, n_per_turn=400):
    th = phase0 + np.linspace(0, 2 * np.pi * turns, int(n_per_turn * turns) + 1)
    return np.stack(
        [
            center[0] + radius * np.cos(th),
            center[1] + radius * np.sin(th),
            z0 + pitch * (th - phase0) / (2 * np.pi),
        ],
        axis=1,
    )


def chain(*pieces):
    out = [pieces[0]]
    for p in pieces[1:]:
        assert np.allclose(out[-1][-1], p[0]), "pieces must join"
        out.append(p[1:])
    return np.vstack(out)


def solenoid_piece(center, turns, z0, radius=3 * A):
    """Tight coil: neighbouring turns GAP apart along the axis."""
    return helix(center, radius, GAP, turns, z0=z0)


def plectoneme_piece(axis_xy, turns, z0, pitch=12 * A, loop_height=4 * A):
    """Two strands GAP apart wound about a vertical axis, joined by an end loop on top.

    Strand A climbs, the loop turns over, strand B comes back down on the opposite side, so
    the two strands are antiparallel. The superhelical pitch 12a keeps each strand's next
    turn (12a) and the other strand half a turn later (6a) well beyond contact range.
    """
    r = GAP / 2
    up = helix(axis_xy, r, pitch, turns, z0=z0)
    top = up[-1]
    v = np.array([top[0] - axis_xy[0], top[1] - axis_xy[1], 0.0]) / r
    phi = np.linspace(0, np.pi, 200)
    loop = (
        np.array([axis_xy[0], axis_xy[1], top[2]])
        + np.outer(r * np.cos(phi), v)
        + np.outer(loop_height * np.sin(phi), [0, 0, 1.0])
    )
    down = helix(axis_xy, r, pitch, turns, phase0=np.pi, z0=z0)[::-1]
    return up, loop, down


def ideal_solenoid(turns=6):
    R = 3 * A
    coil = solenoid_piece((0.0, 0.0), turns, 0.0)
    lead_in = line(coil[0] - [0, 0, 10 * A], coil[0])
    lead_out = line(coil[-1], coil[-1] + [0, 0, 10 * A])
    assert np.isclose(coil[0][0], R)
    return resample(chain(lead_in, coil, lead_out), 0.5 * A)


def ideal_plectoneme(turns=3):
    up, loop, down = plectoneme_piece((0.0, 0.0), turns, 0.0)
    # Leads splay out and down from the two strand ends, away from each other.
    lead_in = line(up[0] + [10 * A, 0, -10 * A], up[0])
    lead_out = line(down[-1], down[-1] + [-10 * A, 0, -10 * A])
    return resample(chain(lead_in, up, loop, down, lead_out), 0.5 * A)


def half_and_half():
    """A solenoid low on the rod, a plectoneme higher up, joined by a straight run."""
    R = 3 * A
    lead_in = line([R, 0, -10 * A], [R, 0, 0])
    coil = solenoid_piece((0.0, 0.0), 5, 0.0)
    bridge = line(coil[-1], [R, 0, 25 * A])
    # Plectoneme axis placed so that strand A starts where the bridge ends.
    up, loop, down = plectoneme_piece((R - GAP / 2, 0.0), 3.5, 25 * A)
    lead_out = line(down[-1], down[-1] + [-15 * A, 0, 5 * A])
    return resample(chain(lead_in, coil, bridge, up, loop, down, lead_out), 0.5 * A)


# --------------------------------------------------------------------------- shapes
# The ideal shapes have every contact of a single kind, so their alignment is +-1 up to a
# few elements at the ends of the coils (leads, loop ends). 0.9 is the spec's bound; the
# measured values are recorded next to each check.


def test_solenoid():
    pts = ideal_solenoid()
    assert np.linalg.norm(np.diff(pts, axis=0), axis=1).max() <= A  # contact resolution
    value = alignment(pts, A)
    assert value > 0.9  # measured 1.0
    assert phase(value) == "solenoid"


def test_plectoneme():
    pts = ideal_plectoneme()
    value = alignment(pts, A)
    assert value < -0.9  # measured -1.0
    assert phase(value) == "plectoneme"


def test_straight_rod():
    pts = np.zeros((101, 3))
    pts[:, 2] = np.linspace(0, 1, 101)
    value = alignment(pts, A)
    assert math.isnan(value)
    assert phase(value) == "straight"


def test_half_and_half_is_mixed():
    pts = half_and_half()
    value = alignment(pts, A)
    # About as many parallel (coil) as antiparallel (strand) contacts: measured -0.03.
    assert abs(value) < 0.5
    assert phase(value) == "mixed"


def test_index_gap_and_overrides():
    pts = ideal_solenoid()
    n = len(pts) - 1
    # A gap longer than the rod leaves no candidate pairs.
    assert math.isnan(alignment(pts, A, min_separation=n))
    # No gap at all: neighbours along the rod (parallel) dominate every element.
    assert alignment(pts, A, min_separation=0) == pytest.approx(1.0)
    # The default gap uses the polyline length; a rest length twice as long halves it.
    length = np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()
    assert alignment(pts, A, rest_length=2 * length) == alignment(pts, A)
    # An epsilon too small to reach the next turn (2.05a apart) finds nothing.
    assert math.isnan(alignment(pts, A, epsilon=0.0))


def test_opposite_rod_direction_gives_same_alignment():
    pts = ideal_plectoneme()
    assert alignment(pts[::-1], A) == pytest.approx(alignment(pts, A))


# --------------------------------------------------------------------------- labels


@pytest.mark.parametrize(
    "value, label",
    [
        (math.nan, "straight"),
        (-1.0, "plectoneme"),
        (-0.51, "plectoneme"),
        (-0.5, "mixed"),
        (0.0, "mixed"),
        (0.5, "mixed"),
        (0.51, "solenoid"),
        (1.0, "solenoid"),
    ],
)
def test_phase_thresholds(value, label):
    assert phase(value) == label


def test_phase_custom_thresholds():
    assert phase(0.2, plectoneme_below=-0.1, solenoid_above=0.1) == "solenoid"
    assert phase(0.0, plectoneme_below=0.0, solenoid_above=0.0) == "mixed"


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"plectoneme_below": -1.5}, r"plectoneme_below must be a number in \[-1, 1\], got -1.5"),
        ({"solenoid_above": 2}, r"solenoid_above must be a number in \[-1, 1\], got 2"),
        ({"solenoid_above": math.nan}, "solenoid_above"),
        ({"plectoneme_below": 0.6, "solenoid_above": 0.4}, "must not exceed solenoid_above"),
    ],
)
def test_phase_threshold_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        phase(0.0, **kwargs)


def test_phase_codes():
    assert [phase_code(p) for p in PHASES] == [0, 1, 2, 3]
    assert PHASES == ("straight", "plectoneme", "solenoid", "mixed")
    with pytest.raises(ValueError, match="phase must be one of"):
        phase_code("knot")


@pytest.mark.parametrize(
    "args, kwargs, match",
    [
        ((np.zeros((5, 2)), A), {}, "points must have shape"),
        ((np.zeros((1, 3)), A), {}, "points must have shape"),
        ((np.ones((4, 3)) * np.arange(4)[:, None], 0.0), {}, "radius must be"),
        ((np.ones((4, 3)) * np.arange(4)[:, None], A), {"rest_length": -1}, "rest_length"),
        ((np.ones((4, 3)) * np.arange(4)[:, None], A), {"min_separation": -1}, "min_separation"),
        ((np.ones((4, 3)) * np.arange(4)[:, None], A), {"epsilon": -3}, "epsilon"),
    ],
)
def test_alignment_validation(args, kwargs, match):
    with pytest.raises(ValueError, match=match):
        alignment(*args, **kwargs)


def test_a_coil_tighter_than_the_partner_separation_is_flagged_not_hidden():
    # A solenoid of loop radius 0.6a and pitch 2.05a (turns touching): each turn is 4.3a of
    # arc, shorter than the classifier's 5a partner separation, so neighbouring turns are
    # never partners and the two-turns-apart ones are 4.1a away (beyond 2.2a): alignment NaN,
    # "straight". Its writhe is several turns (an open helix of 6 turns, measured 3.10), so
    # the table flags it; a straight rod (Wr 0) and a real solenoid are not flagged.
    from rodphase.classify import unseen_coil
    from rodphase.topology import writhe

    coil = resample(chain(line((0.0, 0.0, -10 * A), (0.6 * A, 0.0, 0.0)),
                          helix((0.0, 0.0), 0.6 * A, GAP, 6),
                          line(helix((0.0, 0.0), 0.6 * A, GAP, 6)[-1], (0.0, 0.0, 6 * GAP + 10 * A))),
                    0.2 * A)
    value = alignment(coil, A)
    assert math.isnan(value) and phase(value) == "straight"
    turns = writhe(coil)
    assert abs(turns) > 2.0
    assert unseen_coil("straight", turns)
    assert not unseen_coil("straight", 0.0)
    assert not unseen_coil("solenoid", turns)
    assert not unseen_coil("straight", float("nan"))


def test_a_smaller_partner_separation_sees_the_coil_the_papers_cannot():
    # The same 0.6a-radius coil as above: each turn is 4.3a of arc. With the partner
    # separation at 4 rest radii (below a turn), neighbouring turns 2.05a apart become
    # partners and run parallel: a solenoid (+1). A plectoneme's strands are partners far
    # along the rod whatever the separation, so 4 leaves it antiparallel (−1); a separation
    # above a turn's arc (5, the paper's) still hides the coil.
    coil = resample(chain(line((0.0, 0.0, -10 * A), (0.6 * A, 0.0, 0.0)),
                          helix((0.0, 0.0), 0.6 * A, GAP, 6),
                          line(helix((0.0, 0.0), 0.6 * A, GAP, 6)[-1], (0.0, 0.0, 6 * GAP + 10 * A))),
                    0.2 * A)
    assert math.isnan(alignment(coil, A, separation=5.0))
    assert alignment(coil, A, separation=4.0) == pytest.approx(1.0, abs=0.05)
    assert phase(alignment(coil, A, separation=4.0)) == "solenoid"
    assert alignment(ideal_plectoneme(), A, separation=4.0) < -0.9
    with pytest.raises(ValueError, match="separation"):
        alignment(coil, A, separation=-1.0)
