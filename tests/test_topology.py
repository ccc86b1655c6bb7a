"""Link, twist and writhe: exact cases, Lk = Tw + Wr, symmetries, Fuller's helix, degeneracies."""

import numpy as np
import pytest

from rodphase import topology
from rodphase.topology import link, topology_history, twist, writhe

# Round-off bound for sums of O(n^2) solid angles of O(1) size: measured residuals are
# 1e-15..1e-13 for a few hundred segments, so 1e-9 leaves four orders of margin while still
# catching any real discretisation or closure error (those are >= 1e-7 here).
ROUNDOFF = 1e-9


# --------------------------------------------------------------------------- curve builders


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _transport(u, t0, t1):
    """Minimal rotation taking unit t0 to unit t1, applied to u (normal to t0)."""
    c = np.dot(t0, t1)
    return u - np.dot(u, t1) / (1.0 + c) * (t0 + t1)


def _rotate(u, t, angle):
    return np.cos(angle) * u + np.sin(angle) * np.cross(t, u)


def _signed_angle(a, b, axis):
    return np.arctan2(np.dot(np.cross(a, b), axis), np.dot(a, b))


def closed_ribbon(points, extra_turns, tilt=0.0):
    """d1 for a closed polygon: parallel transport, its holonomy spread evenly, plus turns.

    `tilt` adds a component along the tangent, which the functions must project away.
    """
    n = len(points)
    t = _unit(np.roll(points, -1, axis=0) - points)
    seed = np.cross(t[0], [0.3, 0.5, 0.8])
    u = np.empty((n, 3))
    u[0] = _unit(seed)
    for i in range(1, n):
        u[i] = _unit(_transport(u[i - 1], t[i - 1], t[i]))
    holonomy = _signed_angle(u[0], _transport(u[n - 1], t[n - 1], t[0]), t[0])
    angles = (2 * np.pi * extra_turns + holonomy) * np.arange(n) / n
    d1 = np.array([_rotate(u[i], t[i], angles[i]) for i in range(n)])
    return d1 + tilt * t


def fourier_knot(seed, n=400, modes=3):
    rng = np.random.default_rng(seed)
    s = np.linspace(0, 2 * np.pi, n, endpoint=False)
    p = np.zeros((n, 3))
    for m in range(1, modes + 1):
        a, b = rng.normal(size=(2, 3)) / m
        p += np.outer(np.cos(m * s), a) + np.outer(np.sin(m * s), b)
    return p


def trefoil(n=400):
    s = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.stack(
        [np.sin(s) + 2 * np.sin(2 * s), np.cos(s) - 2 * np.cos(2 * s), -np.sin(3 * s)], axis=1
    )


def helix_with_leads(radius, pitch_angle, turns, per_turn, lead_length, lead_segments=None):
    """Circular helix about z, tangent at `pitch_angle` to the axis, with straight leads.

    The leads run parallel to the axis from both ends, on the same line (both ends sit at
    azimuth 0 for whole turns), so the open curve with its extensions is closed through
    infinity. d1 is the Frenet normal (towards the axis), kept constant along the leads.
    """
    c = radius / np.tan(pitch_angle)  # rise per radian
    th = np.linspace(0, 2 * np.pi * turns, round(turns * per_turn) + 1)
    h = np.stack([radius * np.cos(th), radius * np.sin(th), c * th], axis=1)
    ds = np.hypot(radius, c) * (th[1] - th[0])
    nl = int(np.ceil(lead_length / ds)) if lead_segments is None else lead_segments
    lo = h[0] - np.outer(np.arange(nl, 0, -1) * ds, [0, 0, 1.0])
    hi = h[-1] + np.outer(np.arange(1, nl + 1) * ds, [0, 0, 1.0])
    pts = np.vstack([lo, h, hi])
    mid_th = 0.5 * (th[1:] + th[:-1])
    frenet = -np.stack([np.cos(mid_th), np.sin(mid_th), 0 * mid_th], axis=1)
    d1 = np.vstack(
        [
            np.repeat([[-1.0, 0, 0]], nl, axis=0),
            frenet,
            np.repeat([-np.array([np.cos(th[-1]), np.sin(th[-1]), 0])], nl, axis=0),
        ]
    )
    return pts, d1


def straight_ribbon(turns, n=120, length=1.0, tilt=0.0):
    pts = np.zeros((n + 1, 3))
    pts[:, 2] = np.linspace(0, length, n + 1)
    ang = 2 * np.pi * turns * np.arange(n) / (n - 1)
    d1 = np.stack([np.cos(ang), np.sin(ang), np.full(n, tilt)], axis=1)
    return pts, d1


# --------------------------------------------------------------------------- exact cases


@pytest.mark.parametrize("turns", [0, 1, 3, -2, 2.5])
def test_straight_ribbon(turns):
    pts, d1 = straight_ribbon(turns, tilt=0.4)  # tilt: d1 not normal to the axis
    assert twist(pts, d1) == pytest.approx(turns, abs=ROUNDOFF)
    assert writhe(pts) == pytest.approx(0.0, abs=ROUNDOFF)
    assert link(pts, d1) == pytest.approx(turns, abs=ROUNDOFF)


def test_straight_ribbon_finite_extension():
    # With extensions of length X = 100 L the edge's winding seen from the truncated axis
    # is off by ~(offset / X)^2 per turn: 1.5e-10 measured for 3 turns; bound at 1e-8.
    pts, d1 = straight_ribbon(3)
    assert link(pts, d1, extension=100.0) == pytest.approx(3.0, abs=1e-8)


@pytest.mark.parametrize("curve", ["trefoil", 0, 1, 2, 3])
@pytest.mark.parametrize("extra", [0, 2, -3])
def test_closed_link_is_integer_and_sum(curve, extra):
    pts = trefoil() if curve == "trefoil" else fourier_knot(curve)
    d1 = closed_ribbon(pts, extra, tilt=0.2)
    lk = link(pts, d1, closed=True)
    tw = twist(pts, d1, closed=True)
    wr = writhe(pts, closed=True)
    # Lk of two closed polygons is an integer up to round-off (measured < 1e-14).
    assert abs(lk - round(lk)) < 1e-6
    assert lk == pytest.approx(tw + wr, abs=ROUNDOFF)
    # One more turn of d1 adds exactly one to Lk and Tw and leaves Wr alone.
    d1b = closed_ribbon(pts, extra + 1, tilt=0.2)
    assert link(pts, d1b, closed=True) - lk == pytest.approx(1.0, abs=ROUNDOFF)
    assert twist(pts, d1b, closed=True) - tw == pytest.approx(1.0, abs=ROUNDOFF)


def test_trefoil_writhe_value():
    # A smooth trefoil of this (1,2,3) Fourier shape has writhe ~3.4 in magnitude; the point
    # is only a sanity check that a knotted curve has large writhe (sign: handedness).
    assert abs(writhe(trefoil(), closed=True)) > 2.5


def test_open_curve_sum_rule():
    # Infinite extensions close the ribbon through infinity, so Lk = Tw + Wr holds to
    # round-off for an open curve too (measured ~1e-14). Finite extensions X = 100 L break it
    # by ~offset * L / X: measured 6e-11..2.4e-7 on such curves; bounded at 1e-6.
    rng = np.random.default_rng(7)
    s = np.linspace(0, 1, 301)
    pts = np.zeros((301, 3))
    for c in range(3):
        for m in range(1, 5):
            pts[:, c] += rng.normal() / m * np.sin(np.pi * m * s + rng.uniform(0, 2 * np.pi))
    seg = np.diff(pts, axis=0)
    mid = 0.5 * (pts[1:] + pts[:-1])
    d1 = np.cross(seg, np.array([0.2, -0.4, 1.0]) + 0.3 * np.sin(7 * mid))
    lk, tw, wr = link(pts, d1), twist(pts, d1), writhe(pts)
    assert lk == pytest.approx(tw + wr, abs=ROUNDOFF)
    length = np.linalg.norm(seg, axis=1).sum()
    lkf, wrf = link(pts, d1, extension=100 * length), writhe(pts, extension=100 * length)
    assert lkf == pytest.approx(tw + wrf, abs=1e-6)


# --------------------------------------------------------------------------- symmetries


def _all(pts, d1, closed):
    return np.array(
        [link(pts, d1, closed=closed), twist(pts, d1, closed=closed), writhe(pts, closed=closed)]
    )


def test_planar_curves_have_zero_writhe():
    s = np.linspace(0, 2 * np.pi, 300, endpoint=False)
    r = 1 + 0.3 * np.cos(3 * s) + 0.2 * np.sin(5 * s)
    closed = np.stack([r * np.cos(s), r * np.sin(s), 0 * s], axis=1)
    assert writhe(closed, closed=True) == pytest.approx(0.0, abs=ROUNDOFF)
    u = np.linspace(0, 3, 200)
    open_ = np.stack([u, np.sin(3 * u), 0 * u], axis=1)  # end tangents also in the plane
    assert writhe(open_) == pytest.approx(0.0, abs=ROUNDOFF)


@pytest.mark.parametrize("closed", [True, False])
def test_mirror_flips_signs(closed):
    if closed:
        pts = fourier_knot(5)
        d1 = closed_ribbon(pts, 2)
    else:
        pts, d1 = helix_with_leads(1.0, 0.7, 3, 60, 2.0)
        d1 = d1 + 0.1 * np.cos(np.arange(len(d1)))[:, None] * np.array([0, 0, 1.0])
    flip = np.array([-1.0, 1.0, 1.0])
    base = _all(pts, d1, closed)
    mirrored = _all(pts * flip, d1 * flip, closed)
    assert np.all(np.abs(base) > 0.1)  # a non-trivial case
    np.testing.assert_allclose(mirrored, -base, atol=ROUNDOFF)


@pytest.mark.parametrize("closed", [True, False])
def test_rigid_motion_and_scale_invariance(closed):
    if closed:
        pts = fourier_knot(6)
        d1 = closed_ribbon(pts, -1, tilt=0.3)
    else:
        pts, d1 = helix_with_leads(0.5, 1.0, 2, 80, 1.0)
    base = _all(pts, d1, closed)
    rng = np.random.default_rng(11)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1  # a proper rotation
    moved = 3.7 * pts @ q.T + np.array([10.0, -4.0, 2.5])
    # Round-off only (measured <= 2e-15).
    np.testing.assert_allclose(_all(moved, d1 @ q.T, closed), base, atol=ROUNDOFF)


# --------------------------------------------------------------------------- Fuller's helix


@pytest.mark.parametrize("psi", [0.3, 0.8, 1.2])
def test_helix_writhe_and_frenet_twist_per_turn(psi):
    per_turn = 200
    three = helix_with_leads(1.0, psi, 3, per_turn, 2.0)
    four = helix_with_leads(1.0, psi, 4, per_turn, 2.0)
    # Per turn by difference, so that the two junctions with the leads cancel. The polygon's
    # error is O((2 pi / per_turn)^2): measured at most 4.4e-5 at 200 points per turn.
    wr_turn = writhe(four[0]) - writhe(three[0])
    tw_turn = twist(*four) - twist(*three)
    assert wr_turn == pytest.approx(1 - np.cos(psi), abs=1e-4)
    assert tw_turn == pytest.approx(np.cos(psi), abs=1e-4)
    # Coaxial leads close the ribbon through infinity: Lk is exactly the number of turns.
    for turns, (pts, d1) in ((3, three), (4, four)):
        assert link(pts, d1) == pytest.approx(turns, abs=ROUNDOFF)
        assert twist(pts, d1) + writhe(pts) == pytest.approx(turns, abs=ROUNDOFF)


def test_helix_writhe_total():
    # The whole open helix: its polygon's tangents sweep one segment less than the full
    # turns, so Fuller gives Wr = (N - 1/per_turn)(1 - cos psi), up to N times the O(h^2)
    # per-turn error above: measured 1.4e-4 for 3 turns at 200 points per turn.
    psi, turns, per_turn = 0.9, 3, 200
    pts, _ = helix_with_leads(1.0, psi, turns, per_turn, 2.0)
    expected = (turns - 1.0 / per_turn) * (1 - np.cos(psi))
    assert writhe(pts) == pytest.approx(expected, abs=2e-4)


# --------------------------------------------------------------------------- degeneracies


def test_repeated_points_are_skipped():
    pts, d1 = helix_with_leads(1.0, 0.8, 2, 50, 1.0)
    ref = _all(pts, d1, False)
    # Duplicate a few nodes; the zero-length segments get arbitrary (even zero) normals.
    idx = [0, 10, 57, len(pts) - 1]
    pts2 = np.insert(pts, idx, pts[idx], axis=0)
    d2 = np.insert(d1, [min(i, len(d1)) for i in idx], 0.0, axis=0)
    got = _all(pts2, d2, False)
    np.testing.assert_allclose(got, ref, atol=ROUNDOFF)


def test_hairpin_and_degenerate_inputs_are_finite():
    hairpin = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [1, 0, 0], [0, 0, 0], [-1, 0, 0.0]])
    d1 = np.tile([0.0, 1.0, 0.0], (5, 1))
    d1[2] = [0.0, 0.0, 1.0]
    for extension in (None, 10.0):
        vals = [
            link(hairpin, d1, extension=extension),
            twist(hairpin, d1),
            writhe(hairpin, extension=extension),
        ]
        assert np.all(np.isfinite(vals))
    # d1 along the tangent, a single point repeated, all points equal.
    along = np.tile([1.0, 0, 0], (5, 1))
    assert np.all(np.isfinite(_all(hairpin, along, False)))
    same = np.zeros((4, 3))
    assert np.all(_all(same, np.ones((3, 3)), False) == 0.0)
    # Hairpin with a gap: a U turn whose two rays point the same way (ill-posed closure).
    u = np.array([[0, 0, 0], [1, 0, 0], [1, 0.1, 0], [0, 0.1, 0.0]])
    assert np.all(np.isfinite(_all(u, np.tile([0, 0, 1.0], (3, 1)), False)))


def test_history_matches_single_frames():
    frames, normals = [], []
    for k in range(4):
        pts, d1 = helix_with_leads(1.0, 0.5 + 0.2 * k, 2, 40, 0.0, lead_segments=12)
        frames.append(pts)
        normals.append(d1)
    lk, tw, wr = topology_history(np.array(frames), np.array(normals))
    for s in range(4):
        np.testing.assert_allclose(
            [lk[s], tw[s], wr[s]], _all(frames[s], normals[s], False), atol=ROUNDOFF
        )


@pytest.mark.slow  # compiles the threaded topology, which no test of `make test` needs (16 s CPU)
@pytest.mark.parametrize("closed", [True, False])
def test_threaded_kernels_match_serial(monkeypatch, closed):
    # Default thresholds keep these sizes on one thread; force the prange kernels (row
    # chunks and one frame per thread). Summation order differs, so round-off only.
    if closed:
        pts = fourier_knot(8, n=150)
        d1 = closed_ribbon(pts, 1, tilt=0.1)
    else:
        pts, d1 = helix_with_leads(1.0, 0.7, 3, 50, 1.0)
    serial = _all(pts, d1, closed)
    hist_serial = np.array(topology_history(pts[None], d1[None], closed=closed))
    monkeypatch.setattr(topology, "PARALLEL_MIN_PAIRS", 0)
    np.testing.assert_allclose(_all(pts, d1, closed), serial, atol=ROUNDOFF)
    frames = np.repeat(pts[None], 3, axis=0)
    normals = np.repeat(d1[None], 3, axis=0)
    hist = np.array(topology_history(frames, normals, closed=closed))
    np.testing.assert_allclose(hist, np.repeat(hist_serial, 3, axis=1), atol=ROUNDOFF)
    np.testing.assert_allclose(hist[:, 0], serial, atol=ROUNDOFF)


def test_bad_shapes_raise():
    pts, d1 = straight_ribbon(1)
    with pytest.raises(ValueError, match="normals must have shape"):
        link(pts, d1[:-1])
    with pytest.raises(ValueError, match="points must have shape"):
        writhe(pts[:, :2])
    with pytest.raises(ValueError, match="extension must be > 0"):
        writhe(pts, extension=-1.0)
    with pytest.raises(ValueError, match="normals_history"):
        topology_history(pts[None], d1[None, :-1])


def test_link_counts_the_rotation_of_both_clamps():
    # A straight rod clamped at both ends whose start turns by -0.3 turns and whose end by
    # +0.45 turns carries Lk = Tw = 0.75 turns, Wr = 0 (it stays straight well below the
    # Greenhill onset). Before the fix the start clamp was taken at its first angle (Lk 0.45).
    # 1e-6: the twist of a straight rod is exact up to the closure's round-off.
    from rodphase.rod import Controls, Ends, Problem, Rod, Solver, Stage, constant, ramp
    from rodphase.rod.model import straight_state
    from rodphase.runner import run

    turn = 2 * np.pi
    rod = Rod(length=1.0, radius=0.025, elements=16)
    ends = Ends(start_held=(True,) * 3, start_frame_held=True, end_held=(True, True, False),
                end_frame_held=True)
    twist = Controls(start_rotation=ramp(0, 1.0, 0, -0.3 * turn), end_rotation=ramp(0, 1.0, 0, 0.45 * turn))
    hold = Controls(start_rotation=constant(-0.3 * turn), end_rotation=constant(0.45 * turn))
    problem = Problem(rod=rod, state=straight_state(rod), ends=ends, solver=Solver(damping=40.0),
                      stages=(Stage(1.0, controls=twist), Stage(0.5, controls=hold)))
    result = run(problem, topology=True)
    assert result.ok, result.message
    h = result.history
    assert h["start_rotation"][-1] == pytest.approx(-0.3 * turn)
    assert h["link"][-1] == pytest.approx(0.75, abs=1e-6)
    assert h["twist"][-1] == pytest.approx(0.75, abs=1e-6)
    assert abs(h["writhe"][-1]) < 1e-6
    turns = (h["end_rotation"] - h["start_rotation"]) / turn
    assert np.max(np.abs(h["link"] - turns)) < 1e-3  # all along the ramp too
    assert h["link_escapes"][-1] == 0
