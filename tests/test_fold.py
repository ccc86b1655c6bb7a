"""Fold contact (contact.fold_forces): a loop tighter than the rod cannot close through itself.

Nodes k and k + q inside the contact exclusion (2 <= q <= exclusion) are held apart by the
chord of a circle of the rod's radius a over the rest arc between them,
d_min(s) = 2a·sin(min(s/2a, π/2)). The tests check it against what it is derived from:
loops of radius >= a feel nothing (Schur's comparison theorem: no curve bent at most 1/a has
a shorter chord over half a turn), tighter ones are pushed open, the forces are the exact
gradient of the spring energy (so they balance, and conserve energy without damping), and a
brute-force scan over every node pair with its own bound, without the kernel's skip of pairs
that no tight node separates, pushes the same pairs.
"""

import math

import numpy as np
import pytest

from rodphase.rod.contact import fold_forces

A = 0.025  # m, the paper's rod radius


def _fold(x, exclusion, radius=A, stiffness=1.0, rest=None):
    """fold_forces on (3, n+1) positions (rest lengths: the current ones unless given);
    returns (touching, worst, at, energy, force)."""
    n = x.shape[1] - 1
    if rest is None:
        rest = np.linalg.norm(np.diff(x, axis=1), axis=0)
    force = np.zeros_like(x)
    lengths = np.linalg.norm(np.diff(x, axis=1), axis=0)
    out = fold_forces(x, np.full(n, radius), lengths, rest, exclusion, np.full(n, stiffness),
                      1.0, np.empty(exclusion + 1), np.empty(n + 1, dtype=np.int64), force)
    return (*out, force)


def _brute_force(x, exclusion, rest, radius=A, stiffness=1.0):
    """Every node pair 2 <= q <= exclusion with the bound of its own rest arc: the
    definition, written plainly. Returns (pairs pushed, forces, the rest arc of each)."""
    n = x.shape[1] - 1
    force = np.zeros_like(x)
    arcs = []
    for q in range(2, min(exclusion, n) + 1):
        for k in range(n + 1 - q):
            d = x[:, k + q] - x[:, k]
            dist = np.linalg.norm(d)
            arc = rest[k:k + q].sum()
            d_min = 2 * radius * math.sin(min(arc / (2 * radius), math.pi / 2))
            if 0 < dist < d_min:
                arcs.append(arc)
                f = stiffness * (d_min - dist) / dist * d
                force[:, k] -= f
                force[:, k + q] += f
    return len(arcs), force, arcs


def _circle_polygon(radius_of_curve, element, count):
    """`count` elements of length `element` whose nodes lie on a circle, in x-y."""
    step = 2 * math.asin(element / (2 * radius_of_curve))
    phi = step * np.arange(count + 1)
    return np.stack([radius_of_curve * np.cos(phi), radius_of_curve * np.sin(phi),
                     np.zeros_like(phi)])


@pytest.mark.parametrize("element", [0.3 * A, 0.5 * A, 0.8 * A])
def test_loops_of_the_rods_own_radius_or_wider_feel_nothing(element):
    # Nodes on a circle of radius R: the chord over q elements, 2R·sin(q·asin(l/2R)), is
    # never shorter than d_min of the q·l of rest arc when R >= a and q·l <= πa (Schur; for
    # the polygon, asin(l/2R) >= l/2R). So no pair within half a turn is pushed, exactly
    # (zero, not small). The exclusion rounds πa up to whole elements, and past πa d_min
    # is 2a, which the far nodes of a loop of radius a are closer than (as the regular
    # contact would also say): those are pushed at R = a, and nothing at 1.2a.
    exclusion = math.ceil(math.pi * A / element)
    for curve in (1.0 * A, 1.2 * A, 3.0 * A, 50.0 * A):
        count = min(60, int(2 * math.pi * curve / element) - 1)
        x = _circle_polygon(curve, element, count)
        rest = np.full(count, element)
        touching, worst, _, energy, force = _fold(x, exclusion, rest=rest)
        expected_touching, _, arcs = _brute_force(x, exclusion, rest)
        assert touching == expected_touching
        assert all(arc > math.pi * A for arc in arcs), (curve, arcs)
        if curve > A:
            assert touching == 0 and worst == 0.0 and energy == 0.0 and not force.any()


@pytest.mark.parametrize("element", [0.3 * A, 0.5 * A])
def test_a_loop_tighter_than_the_rod_is_pushed_open(element):
    # A loop of radius 0.6a: nodes less than πa of arc apart are closer than the chord of a
    # radius-a circle over the same arc (up to 0.8a closer, past the 0.5a penetration
    # limit that fails a run), and every pushed node is pushed away from the loop's centre.
    exclusion = math.ceil(math.pi * A / element)
    x = _circle_polygon(0.6 * A, element, int(2 * math.pi * 0.6 * A / element) - 1)
    touching, worst, _, energy, force = _fold(x, exclusion)
    assert touching > 0 and energy > 0.0 and worst > 0.5
    pushed = np.linalg.norm(force, axis=0) > 0
    radial = np.sum(force[:2, pushed] * x[:2, pushed], axis=0)
    assert (radial > 0).all()


def _random_curve(rng, n, element, tightest, loosest=math.inf, torsion=None):
    """A random space curve of n equal elements whose curvature wanders between 1/loosest
    and 1/tightest, its normal turning at random (or at `torsion` [1/m] on average)."""
    x = np.zeros((3, n + 1))
    t = np.array([0.0, 0.0, 1.0])
    normal = np.array([1.0, 0.0, 0.0])
    low, high = 1 / loosest, 1 / tightest
    curvature = low if loosest == math.inf else rng.uniform(low, high)
    step = 0.5 / tightest if loosest == math.inf else 0.2 * (high - low)
    for i in range(n):
        x[:, i + 1] = x[:, i] + element * t
        curvature = np.clip(curvature + rng.normal(0, step), low, high)
        axis = np.cross(t, normal)
        axis /= np.linalg.norm(axis)
        angle = curvature * element
        t = t * math.cos(angle) + np.cross(axis, t) * math.sin(angle)
        t /= np.linalg.norm(t)
        twist = rng.normal(0, 0.6) if torsion is None else rng.normal(torsion, torsion) * element
        normal = normal - t * (normal @ t)
        normal /= np.linalg.norm(normal)
        normal = normal * math.cos(twist) + np.cross(t, normal) * math.sin(twist)
    return x


@pytest.mark.parametrize("seed", range(8))
def test_fold_forces_are_the_gradient_of_their_energy(seed):
    # Random folded curves (curvature up to 1/(0.4a)): each force component against a
    # central difference of the spring energy Σ ½k(d_min − d)², h = 1e-7 of a radius.
    # The energy is piecewise quadratic in d, so the difference is exact to O(h²) away from
    # a pair switching on; 1e-6 of the largest force allows for the round-off of E/h.
    rng = np.random.default_rng(seed)
    element = 0.5 * A
    exclusion = math.ceil(math.pi * A / element)
    x = _random_curve(rng, 40, element, tightest=0.4 * A)
    rest = np.full(40, element)
    stiffness = 1e3
    touching, _, _, _, force = _fold(x, exclusion, stiffness=stiffness, rest=rest)
    assert touching > 0
    h = 1e-7 * A
    numeric = np.zeros_like(x)
    for c in range(3):
        for k in range(x.shape[1]):
            plus, minus = x.copy(), x.copy()
            plus[c, k] += h
            minus[c, k] -= h
            e_plus = _fold(plus, exclusion, stiffness=stiffness, rest=rest)[3]
            e_minus = _fold(minus, exclusion, stiffness=stiffness, rest=rest)[3]
            numeric[c, k] = -(e_plus - e_minus) / (2 * h)
    np.testing.assert_allclose(force, numeric, rtol=0, atol=1e-6 * np.abs(force).max())


def test_fold_forces_balance_and_do_not_turn_the_rod():
    # Central pair forces: zero net force and zero net moment, to round-off (1e-12 of the
    # largest force times the number of nodes, and times the rod's size for the moment).
    rng = np.random.default_rng(3)
    x = _random_curve(rng, 60, 0.5 * A, tightest=0.4 * A)
    touching, _, _, _, force = _fold(x, 7)
    assert touching > 0
    scale = np.abs(force).max()
    assert np.abs(force.sum(axis=1)).max() < 1e-12 * scale * 60
    moment = np.cross(x.T, force.T).sum(axis=0)
    assert np.abs(moment).max() < 1e-12 * scale * np.abs(x).max() * 60


def _assert_pushes_what_the_scan_pushes(x, exclusion, rest):
    """The kernel's pushed pairs and forces are the brute-force scan's, to round-off (the
    sums run in another order: 1e-12 of the largest force)."""
    touching, _, _, _, force = _fold(x, exclusion, rest=rest)
    expected_touching, expected, _ = _brute_force(x, exclusion, rest)
    assert touching == expected_touching
    np.testing.assert_allclose(force, expected, rtol=0,
                               atol=1e-12 * max(1.0, np.abs(expected).max()))


@pytest.mark.parametrize("seed", range(6))
def test_the_kernel_pushes_what_a_scan_of_every_pair_pushes(seed):
    # Uniform rest lengths: the per-q bound is each pair's own, so the pushed pairs and the
    # forces are the brute-force scan's (to round-off: the sums run in another order).
    # Uneven rest lengths: the kernel's bound (the shortest arc of q elements) is the more
    # permissive, so it pushes a subset of what the scan pushes, and never more.
    rng = np.random.default_rng(seed)
    element = rng.uniform(0.3, 0.9) * A
    exclusion = math.ceil(math.pi * A / element)
    x = _random_curve(rng, 80, element, tightest=rng.uniform(0.33, 2.0) * A)
    _assert_pushes_what_the_scan_pushes(x, exclusion, np.full(80, element))
    uneven = element * rng.uniform(0.9, 1.1, 80)
    touching, *_ = _fold(x, exclusion, rest=uneven)
    assert touching <= _brute_force(x, exclusion, uneven)[0]


@pytest.mark.parametrize("seed", range(12))
def test_the_tight_node_skip_holds_on_loops_near_the_rods_own_radius(seed):
    # The skip (pairs with no node turning faster than 0.8 of a radius-a circle are not
    # looked at) is thinnest where the rod is bent at about 1/a everywhere, a tight
    # solenoid: curves whose curvature stays within 5 % of a value between 0.7/a and
    # 1.3/a, with torsion, against the scan of every pair. (Bent harder, the curves of the
    # test above check it too.)
    rng = np.random.default_rng(100 + seed)
    element = rng.uniform(0.2, 0.9) * A
    exclusion = math.ceil(math.pi * A / element)
    bend = rng.uniform(0.7, 1.3) / A
    x = _random_curve(rng, 60, element, tightest=1 / (1.05 * bend), loosest=1 / (0.95 * bend),
                      torsion=rng.uniform(0, 3) / A)
    _assert_pushes_what_the_scan_pushes(x, exclusion, np.full(60, element))


def test_a_straight_rod_feels_nothing():
    x = np.zeros((3, 41))
    x[2] = np.linspace(0, 1, 41)
    touching, worst, _, energy, force = _fold(x, 40)
    assert touching == 0 and worst == 0.0 and not force.any()
