"""Fold contact (contact.fold_forces): a loop tighter than the rod cannot close through itself.

Pairs of elements inside the contact exclusion are held apart by the chord of a circle of
the rod's radius a over the arc between them, d_min(s) = 2a·sin(min(s/2a, π/2)). The tests
check it against what it is derived from: polygons on circles of radius ≥ a feel nothing
(Schur's comparison theorem: no curve bent at most 1/a has a shorter chord), tighter ones
are pushed open, the forces balance, and the O(n) "tight node" pre-test that skips most
pairs never skips one that a brute-force scan over every pair would push.
"""

import math

import numpy as np
import pytest

from rodphase.rod.contact import closest_parameters, fold_forces

A = 0.025  # m, the paper's rod radius


def _fold(x, radius, exclusion, stiffness=1.0):
    """fold_forces on (3, n+1) positions; returns (touching, worst, at, energy, force)."""
    n = x.shape[1] - 1
    lengths = np.linalg.norm(np.diff(x, axis=1), axis=0)
    force = np.zeros_like(x)
    out = fold_forces(x, np.full(n, radius) if np.isscalar(radius) else radius, lengths,
                      exclusion, np.full(n, stiffness), 1.0, np.empty(n + 1),
                      np.empty(n + 1, dtype=np.int64), force)
    return (*out, force)


def _brute_force(x, radius, exclusion, stiffness=1.0):
    """Every pair 2 <= j - i <= exclusion, no pre-test: the definition, written plainly.
    Returns (pairs pushed, forces, the arc between each pushed pair's closest points)."""
    n = x.shape[1] - 1
    seg = np.diff(x, axis=1)
    lengths = np.linalg.norm(seg, axis=0)
    force = np.zeros_like(x)
    touching = 0
    arcs = []
    for i in range(n):
        for j in range(i + 2, min(n - 1, i + exclusion) + 1):
            u, w, r = seg[:, i], seg[:, j], x[:, i] - x[:, j]
            s, t = closest_parameters(*r, *u, *w, 1 / lengths[i] ** 2, 1 / lengths[j] ** 2)
            d = r + s * u - t * w
            dist = np.linalg.norm(d)
            arc = lengths[i + 1:j].sum() + (1 - s) * lengths[i] + t * lengths[j]
            d_min = 2 * radius * math.sin(min(arc / (2 * radius), math.pi / 2))
            if 0 < dist < d_min:
                touching += 1
                arcs.append(arc)
                f = stiffness * (d_min - dist) / dist * d
                force[:, i] += (1 - s) * f
                force[:, i + 1] += s * f
                force[:, j] -= (1 - t) * f
                force[:, j + 1] -= t * f
    return touching, force, arcs


def _circle_polygon(radius_of_curve, element, count):
    """`count` elements of length `element` tangent to a circle of radius `radius_of_curve`
    (the capsules' axes touch it at their midpoints; the nodes lie just outside), in x-y."""
    step = 2 * math.atan(element / (2 * radius_of_curve))
    nodes = radius_of_curve / math.cos(step / 2)
    phi = step * np.arange(count + 1)
    return np.stack([nodes * np.cos(phi), nodes * np.sin(phi), np.zeros_like(phi)])


@pytest.mark.parametrize("element", [0.3 * A, 0.5 * A, 0.8 * A])
def test_loops_of_the_rods_own_radius_or_wider_feel_nothing(element):
    # A polygon wrapped round a circle of radius R (its segments tangent to it, as the
    # capsules of a loop of centre-line radius R are). By Schur's comparison no chord over
    # an arc s <= πa is shorter than d_min(s) if R >= a: no pair within half a turn is
    # pushed, exactly (zero, not small). Past πa of arc d_min is the regular contact's 2a,
    # and a loop of radius a (whose far strands are closer than 2a, overlapping as the
    # regular contact would also say) is pushed there; at 1.2a it is not.
    exclusion = math.ceil(math.pi * A / element)
    for curve in (1.0 * A, 1.2 * A, 3.0 * A, 50.0 * A):
        count = min(60, int(2 * math.pi * curve / element) - 1)
        x = _circle_polygon(curve, element, count)
        touching, worst, _, energy, force = _fold(x, A, exclusion)
        expected_touching, expected, arcs = _brute_force(x, A, exclusion)
        assert touching == expected_touching
        assert all(arc > math.pi * A for arc in arcs), (curve, arcs)
        if curve > A:
            assert touching == 0 and worst == 0.0 and energy == 0.0 and not force.any()


@pytest.mark.parametrize("element", [0.3 * A, 0.5 * A])
def test_a_loop_tighter_than_the_rod_is_pushed_open(element):
    # A loop of radius 0.6a: its strands less than πa of arc apart, inside the exclusion,
    # are closer than the chord of a radius-a circle over the same arc (up to 1.4a closer,
    # past the 0.5a penetration limit that fails a run), and the forces point outwards
    # from the loop's centre on every node they act on.
    exclusion = math.ceil(math.pi * A / element)
    x = _circle_polygon(0.6 * A, element, int(2 * math.pi * 0.6 * A / element) - 1)
    touching, worst, at, energy, force = _fold(x, A, exclusion)
    assert touching > 0 and energy > 0.0
    assert worst > 0.5
    pushed = np.linalg.norm(force, axis=0) > 0
    radial = np.sum(force[:2, pushed] * x[:2, pushed], axis=0)
    assert (radial > 0).all()


def test_fold_forces_balance_and_do_not_turn_the_rod():
    # Equal and opposite pair forces: zero net force and zero net moment about the origin,
    # to round-off (1e-12 of the largest force times the rod's size).
    rng = np.random.default_rng(3)
    x = _random_curve(rng, 60, 0.5 * A, tightest=0.4 * A)
    touching, _, _, _, force = _fold(x, A, 7)
    assert touching > 0
    scale = np.abs(force).max()
    assert np.abs(force.sum(axis=1)).max() < 1e-12 * scale * 60
    moment = np.cross(x.T, force.T).sum(axis=0)
    assert np.abs(moment).max() < 1e-12 * scale * np.abs(x).max() * 60


def _random_curve(rng, n, element, tightest):
    """A random space curve of n equal elements whose curvature wanders up to 1/tightest."""
    x = np.zeros((3, n + 1))
    t = np.array([0.0, 0.0, 1.0])
    normal = np.array([1.0, 0.0, 0.0])
    curvature = 0.0
    for i in range(n):
        x[:, i + 1] = x[:, i] + element * t
        curvature = np.clip(curvature + rng.normal(0, 0.5 / tightest), 0, 1 / tightest)
        axis = np.cross(t, normal)
        axis /= np.linalg.norm(axis)
        angle = curvature * element
        t = t * math.cos(angle) + np.cross(axis, t) * math.sin(angle)
        t /= np.linalg.norm(t)
        twist = rng.normal(0, 0.6)
        normal = normal - t * (normal @ t)
        normal /= np.linalg.norm(normal)
        normal = normal * math.cos(twist) + np.cross(t, normal) * math.sin(twist)
    return x


@pytest.mark.parametrize("seed", range(12))
def test_the_tight_node_pre_test_never_skips_a_pushed_pair(seed):
    # Random curves whose curvature wanders between 0 and up to 3/a: whatever pairs the
    # brute-force scan over every pair pushes, fold_forces pushes too, with the same
    # forces to round-off (they differ only in the order of the sums).
    rng = np.random.default_rng(seed)
    element = rng.uniform(0.3, 0.9) * A
    exclusion = math.ceil(math.pi * A / element)
    x = _random_curve(rng, 80, element, tightest=rng.uniform(0.33, 2.0) * A)
    touching, _, _, _, force = _fold(x, A, exclusion)
    expected_touching, expected, _ = _brute_force(x, A, exclusion)
    assert touching == expected_touching
    np.testing.assert_allclose(force, expected, rtol=0, atol=1e-12 * max(1.0, np.abs(expected).max()))


def test_a_straight_rod_costs_one_pass_and_feels_nothing():
    x = np.zeros((3, 41))
    x[2] = np.linspace(0, 1, 41)
    touching, worst, _, energy, force = _fold(x, A, 40)
    assert touching == 0 and worst == 0.0 and not force.any()
