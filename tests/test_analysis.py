"""Measurements of rodphase.analysis against shapes whose answers are known by construction:
an ideal helix (axis, pitch, radius, turns), a two-strand plectoneme (supercoil turns), a
hairpin and a tight coil (partners, alignment −1 and +1), a staircase (bursts), and a
brute-force partner search written here from the paper's rule."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from rodphase import analysis as A
from rodphase.classify import alignment

a = 0.025  # rest radius (m)
GAP = 2.05 * a  # centreline distance of touching strands: inside the (2 + 0.2)·a range


def helix(radius, pitch, turns, per_turn):
    """Ideal helix about +z, `per_turn` equal elements a turn, starting on the +x axis."""
    th = np.linspace(0.0, 2 * np.pi * turns, int(round(per_turn * turns)) + 1)
    return np.column_stack([radius * np.cos(th), radius * np.sin(th), pitch * th / (2 * np.pi)])


def rotation(seed=3):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def length(p):
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def brute_partners(p, radius, rest_length, epsilon=0.2):
    """The paper's rule, element by element: nearest k with |k − i| > 5·n·a/L0 and
    |x_k − x_i| < (2 + ε)·a, ties to the lower index."""
    x = 0.5 * (p[1:] + p[:-1])
    n = len(x)
    gap = 5.0 * n * radius / rest_length
    out = np.full(n, -1)
    for i in range(n):
        d = np.linalg.norm(x - x[i], axis=1)
        ok = (np.abs(np.arange(n) - i) > gap) & (d < (2 + epsilon) * radius)
        if ok.any():
            k = np.flatnonzero(ok)
            out[i] = k[np.argmin(d[k])]  # argmin takes the first (lowest) of equal minima
    return out


# --------------------------------------------------------------------------- partners


def hairpin(depth=20 * a, ds=0.4 * a):
    """Two straight legs GAP apart joined by a half circle: down one leg, up the other."""
    r = GAP / 2
    m = int(round(depth / ds))
    down = np.column_stack([np.full(m + 1, -r), np.zeros(m + 1), np.linspace(0, -depth, m + 1)])
    k = int(round(np.pi * r / ds))
    phi = np.linspace(np.pi, 2 * np.pi, k + 1)
    turn = np.column_stack([r * np.cos(phi), np.zeros(k + 1), -depth + r * np.sin(phi)])
    up = down[::-1] * [-1, 1, 1]
    return np.vstack([down, turn[1:], up[1:]])


def test_hairpin_strands_pair_antiparallel():
    p = hairpin()
    n = len(p) - 1
    partner = A.partners(p, a, length(p))
    paired = np.flatnonzero(partner >= 0)
    assert len(paired) > 0.7 * n  # all but the ends and the turn
    # mirror symmetry: each element pairs with its mirror image across the hairpin
    assert np.array_equal(partner[paired], n - 1 - paired)
    assert np.all(A.local_alignment(p, a, length(p))[paired] == -1.0)
    assert alignment(p, a, rest_length=length(p)) == -1.0


def test_tight_helix_pairs_parallel_one_turn_apart():
    per_turn = 40
    p = helix(3 * a, GAP, 4, per_turn)
    partner = A.partners(p, a, length(p))
    i = np.arange(len(partner))
    assert np.all(partner >= 0)
    assert np.array_equal(np.abs(partner - i), np.full(len(i), per_turn))
    assert alignment(p, a, rest_length=length(p)) == 1.0


def test_straight_rod_has_no_partner():
    p = np.column_stack([np.zeros(41), np.zeros(41), np.linspace(0, 1, 41)])
    assert np.all(A.partners(p, a, 1.0) == -1)
    assert np.all(np.isnan(A.local_alignment(p, a, 1.0)))
    assert math.isnan(alignment(p, a, rest_length=1.0))


@pytest.mark.parametrize("seed", range(4))
def test_partners_match_the_rule_element_by_element(seed):
    # a crumpled random walk: many candidates per element, partners in every direction
    rng = np.random.default_rng(seed)
    steps = rng.normal(size=(300, 3))
    p = np.cumsum(0.5 * a * steps / np.linalg.norm(steps, axis=1)[:, None], axis=0)
    p = p * 0.3 + 0.7 * p.mean(axis=0)  # squeeze: most elements find someone in range
    L0 = length(p)
    expected = brute_partners(p, a, L0)
    assert (expected >= 0).sum() > 50
    assert np.array_equal(A.partners(p, a, L0), expected)
    # and the classifier's alignment is the mean sign over exactly these partners
    e = np.diff(p, axis=0)
    has = expected >= 0
    signs = np.sign(np.einsum("ij,ij->i", e[has], e[expected[has]]))
    assert alignment(p, a, rest_length=L0) == signs.mean()


def test_min_separation_overrides_the_gap():
    p = hairpin()
    assert np.all(A.partners(p, a, min_separation=len(p)) == -1)


# --------------------------------------------------------------------------- coil geometry


def test_helix_axis_pitch_radius_and_turns():
    """A helix of radius 3a, pitch 2.05a (touching turns), 5 turns of 40 elements, tilted.

    Tolerances: the axis, the pitch and the turns are exact for the discrete helix (its unit
    tangents have a constant component along the axis; an element's partner is the one
    exactly a turn later, a pitch away), so they hold to round-off. The radius comes from
    the contour per turn, which for 40 chords is the perimeter of an inscribed polygon,
    2πR·(1 − (π/40)²/6 + …): 1.0e-3 short; we allow 1.5e-3.
    """
    radius, per_turn, turns = 3 * a, 40, 5
    R = rotation()
    p = helix(radius, GAP, turns, per_turn) @ R.T + [0.1, -0.2, 0.3]
    axis = A.helix_axis(p)
    assert np.allclose(axis, R @ [0, 0, 1.0], atol=1e-12)
    assert np.allclose(A.helix_axis(p[::-1]), -axis, atol=1e-12)  # first → last point
    assert A.coil_height(p) == pytest.approx(turns * GAP, rel=1e-12)

    g = A.solenoid_geometry(p, a, length(p))
    assert g["elements_per_turn"] == per_turn
    assert g["turns"] == pytest.approx(turns, rel=1e-12)
    assert g["elements"] == [0, len(p) - 2]
    assert g["pitch"] == pytest.approx(GAP, rel=1e-12)
    chord = np.linalg.norm(p[1] - p[0])
    assert g["contour_per_turn"] == pytest.approx(per_turn * chord, rel=1e-12)
    recovered = math.sqrt(g["contour_per_turn"] ** 2 - g["pitch"] ** 2) / (2 * np.pi)
    assert recovered == pytest.approx(radius, rel=1.5e-3)
    assert abs(recovered / radius - 1) > 0.5e-3  # the polygon's shortfall, as stated


def test_solenoid_geometry_leaves_out_straight_tails():
    coil = helix(3 * a, GAP, 4, 40)
    tail = np.column_stack([np.full(30, 3 * a), np.zeros(30), -np.arange(30, 0, -1) * 0.4 * a])
    p = np.vstack([tail, coil])
    g = A.solenoid_geometry(p, a, length(p))
    assert g["elements"][0] >= 30 and g["turns"] == pytest.approx(4, abs=0.05)


def test_solenoid_geometry_of_no_coil_is_empty():
    assert A.solenoid_geometry(hairpin(), a, length(hairpin())) == {}


def plectoneme(turns, per_turn=80, pitch=12 * a):
    """Two strands GAP apart wound `turns` times about +z, strand A up and strand B down the
    opposite side, joined on top by a half loop: an ideal plectoneme of `turns` supercoil
    turns (the inter-strand vector revolves `turns` times from the bottom to the top)."""
    r = GAP / 2
    up = helix(r, pitch, turns, per_turn)
    top = up[-1]
    v = np.array([top[0], top[1], 0.0]) / r
    phi = np.linspace(0, np.pi, 21)
    loop = (np.array([0.0, 0.0, top[2]]) + np.outer(r * np.cos(phi), v)
            + np.outer(4 * a * np.sin(phi), [0, 0, 1.0]))
    down = -up[::-1] * [1, 1, -1]  # half a turn round: (x, y) → (−x, −y), same heights
    return np.vstack([up, loop[1:], down[1:]])


@pytest.mark.parametrize("turns", [2, 3.5])
def test_plectoneme_turns_of_an_ideal_plectoneme(turns):
    """Tolerance: 0.08 turns short, none over. Near the loop the index gap (5a of contour,
    27 elements here, more than the loop's 20) pushes the last strand elements' partners
    down the other strand, off the same height, so the inter-strand vector there lags the
    supercoil: measured 0.05 turns short at 2 and 3.5 turns."""
    p = plectoneme(turns)
    L0 = length(p)
    assert alignment(p, a, rest_length=L0) == -1.0
    m = A.plectoneme_turns(p, a, L0)
    assert turns - 0.08 < m["turns"] < turns
    assert m["strand_elements"] == pytest.approx(80 * turns, abs=10)


# --------------------------------------------------------------------------- histories


def staircase(x, at=(1.0, 2.0, 3.0), slope=0.02, width=0.03):
    return slope * x + sum(0.5 * (1 + np.tanh((x - c) / width)) for c in at)


def test_bursts_on_a_staircase():
    x = np.linspace(0, 4, 801)
    y = staircase(x)
    found = A.bursts(x, y, width=5)
    assert [b["at"] for b in found] == pytest.approx([1.0, 2.0, 3.0], abs=0.005)  # a row
    for b in found:
        assert b["from"] < b["at"] < b["to"]
        # each step of 1 plus the background slope over the burst's span
        assert b["gain"] == pytest.approx(1 + 0.02 * (b["to"] - b["from"]), abs=1e-3)
        assert (x[b["rows"][0]], x[b["rows"][1]]) == (b["from"], b["to"])


def test_no_bursts_on_a_ramp():
    x = np.linspace(0, 4, 801)
    assert A.bursts(x, 0.5 * x, width=5) == []


def test_smooth_keeps_a_constant_and_averages():
    assert np.allclose(A.smooth(np.full(10, 2.0), 3), 2.0)
    assert A.smooth(np.array([0.0, 3.0, 0.0]), 3)[1] == 1.0


def test_sawtooth_drops():
    x = np.linspace(0, 3, 301)
    y = 10 * x - 2.5 * np.floor(x + 0.5)  # drops of 2.5 at x = 0.5, 1.5, 2.5
    drops = A.sawtooth_drops(x, y, window=5, min_drop=1.0, merge=0.03)
    assert [d["peak_x"] for d in drops] == pytest.approx([0.49, 1.49, 2.49])
    assert [d["peak_y"] - d["bottom_y"] for d in drops] == pytest.approx([2.4] * 3)
    assert A.sawtooth_drops(x, y, window=5, min_drop=3.0) == []


def test_free_coil_height():
    # unchanged radius: the annealed helix itself, loops × pitch tall
    h = A.free_coil_height(0.02, 0.05, 4, 30.0, np.array([1.0, 1.5]))
    assert h[0] == pytest.approx(4 * 0.05, rel=1e-12)
    # the torsion τ = κ3⁰/f − ω vanishes at f = κ3⁰/ω: a flat coil, height 0
    c = 0.05 / (2 * np.pi)
    omega = 30.0 - c / (0.02**2 + c**2)
    assert A.free_coil_height(0.02, 0.05, 4, 30.0, 30.0 / omega) == pytest.approx(0, abs=1e-15)


def fake_run():
    history = {"end_rotation": np.linspace(0, 4 * np.pi, 5), "start_rotation": np.full(5, 1.0),
               "stage": np.array([0, 0, 1, 2, 2])}
    diagnostics = {"rest_radius": 0.02, "rest_length": 2.0,
                   "stages": [{"label": "load"}, {"label": "twist"}, {"label": "twist on"}]}
    return SimpleNamespace(history=history, diagnostics=diagnostics)


def test_twist_density_and_stage_rows():
    r = fake_run()
    expected = (np.linspace(0, 4 * np.pi, 5) - 1.0) * 0.02 / 2.0
    assert np.allclose(A.twist_density(r), expected, rtol=1e-15)
    assert A.stage_rows(r, "twist").tolist() == [False, False, True, True, True]
    assert A.stage_rows(r, "load").tolist() == [True, True, False, False, False]


# ------------------------------------------------- writhe steps (issue #49), at the cross-check's sampling


def _sampled(y_of_t, t0=60.0, t1=80.0, dt=0.5, noise=0.0, seed=0):
    t = np.arange(t0, t1 + 1e-9, dt)
    rng = np.random.default_rng(seed)
    return t, y_of_t(t) + noise * rng.standard_normal(len(t))


def test_writhe_steps_counts_a_staircase_of_loops():
    # four loops of 0.7, 0.6, 0.5, 0.5 turns 2-3 s apart (PyElastica's SolenoidsCase), each
    # over ~1 s, on a slow drift, with 0.01 turn of noise: four steps, each its own gain
    at, gains = (66.0, 67.3, 69.4, 74.0), (0.7, 0.6, 0.5, 0.5)
    t, wr = _sampled(lambda t: 0.005 * (t - 60) + sum(g * 0.5 * (1 + np.tanh((t - c) / 0.3))
                                                       for c, g in zip(at, gains)), noise=0.01)
    steps = A.writhe_steps(t, wr)
    assert len(steps) == 4
    assert [s["at"] for s in steps] == pytest.approx(at, abs=0.6)
    assert [s["gain"] for s in steps] == pytest.approx(gains, abs=0.15)


def test_writhe_steps_sees_a_collapse_as_one_step():
    # 2.2 turns in ~1.5 s, no slower stretch inside: one step of the whole gain
    t, wr = _sampled(lambda t: 2.2 * 0.5 * (1 + np.tanh((t - 69.0) / 0.6)), noise=0.01)
    steps = A.writhe_steps(t, wr)
    assert len(steps) == 1
    assert steps[0]["gain"] == pytest.approx(2.2, abs=0.15)
    assert steps[0]["to_value"] == pytest.approx(2.2, abs=0.05)


def test_writhe_steps_finds_none_on_smooth_ramps():
    # a steady conversion, slow or fast (up to 0.5 turns per sample), noisy or not: no step
    for slope in (0.05, 0.3, 1.0):
        for noise in (0.0, 0.01):
            t, wr = _sampled(lambda t: slope * (t - 60), noise=noise, seed=3)
            assert A.writhe_steps(t, wr) == [], (slope, noise)


def test_writhe_steps_ignores_rises_below_the_threshold_and_counts_losses():
    t, wr = _sampled(lambda t: sum(0.2 * 0.5 * (1 + np.tanh((t - c) / 0.3)) for c in (64, 68, 72)))
    assert A.writhe_steps(t, wr) == []  # 0.2 < 0.3 turns
    assert len(A.writhe_steps(t, wr, min_step=0.15)) == 3
    t, wr = _sampled(lambda t: 4.0 - sum(0.65 * 0.5 * (1 + np.tanh((t - c) / 0.3)) for c in (64, 72)))
    losses = A.writhe_steps(t, wr, direction=-1)
    assert len(losses) == 2 and losses[-1]["to_value"] == pytest.approx(2.7, abs=0.05)
    with pytest.raises(ValueError, match="direction"):
        A.writhe_steps(t, wr, direction=0)
