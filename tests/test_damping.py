"""The stiff dissipative terms taken implicitly (issue #13): the contact dashpot per pair and
the axial Kelvin–Voigt damping along the rod. Small rods, short runs: seconds once numba's
cache is warm.
"""

import dataclasses

import numpy as np
import pytest

from rodphase.rod import (
    Contact,
    Ends,
    Problem,
    Rod,
    Solver,
    Stage,
    hairpin_state,
    simulate,
    stable_time_step,
    straight_state,
    time_step,
)
from rodphase.rod.contact import DASHPOT_ROWS, add_contact_forces, apply_dashpots, contact_forces
from rodphase.scenes import measured_curvature

RADIUS = 0.01


def crossing_segments(gap, count=1):
    """Segment 0 along x at z = 0 and `count` segments along y above it, each `gap` above
    touching (negative: overlapping). Nodes (3, 2 + 2·count); pairs (2, count)."""
    nodes = [[-0.5, 0, 0], [0.5, 0, 0]]
    for k in range(count):
        xk = -0.3 + 0.6 * k / (count - 1) if count > 1 else 0.0
        nodes += [[xk, -0.5, 2 * RADIUS + gap], [xk, 0.5, 2 * RADIUS + gap]]
    x = np.ascontiguousarray(np.array(nodes, float).T)
    # element 2k+1 joins the two halves of the pair list's partners: skip it (pairs only)
    pairs = np.array([[0] * count, [2 + 2 * k for k in range(count)]], dtype=np.int64)
    return x, pairs


def normal_speed(v, s=0.5, t=0.5, i=0, j=2):
    """Normal (z) relative velocity of element i's point s against element j's point t."""
    return ((1 - s) * v[2, i] + s * v[2, i + 1]) - ((1 - t) * v[2, j] + t * v[2, j + 1])


def kinetic(v, inv_mass):
    return 0.5 * np.sum(np.sum(v * v, axis=0) / inv_mass)


def test_implicit_dashpot_never_reverses_a_pair_far_above_the_explicit_bound():
    # Approaching at 1 m/s, overlap tiny (spring negligible). The explicit dashpot force
    # c·v_n over a kick changes v_n by c·dt·w·v_n (w = Σ weight²/m = 4·(1/4)/m = 1/m here):
    # above c·dt·w = 2 it reverses and grows (unstable); at 1e3 the implicit impulse must
    # leave v_n of the same sign and below 1/(1 + 1e3) of it.
    x, pairs = crossing_segments(-1e-9)
    v = np.zeros_like(x)
    v[2, 2:] = -0.5
    v[2, :2] = 0.5
    inv_mass = np.full(x.shape[1], 1.0 / 0.01)  # 10 g nodes
    dt = 1e-4
    c = 1e3 / (dt * inv_mass[0])
    k = np.full(3, 1e-6)
    damping = np.full(3, c)
    before = normal_speed(v)
    assert before == pytest.approx(1.0)

    explicit = np.zeros_like(x)
    add_contact_forces(x, v, np.full(3, RADIUS), pairs, 1, k, damping, 1.0, 0.0, 1e-4, 0.0,
                       explicit)
    after_explicit = normal_speed(v + dt * explicit * inv_mass)
    assert after_explicit < -100 * before  # the explicit kick reverses it, 1000-fold

    force = np.zeros_like(x)
    dashpots = np.zeros((DASHPOT_ROWS, 4))
    touching, _, _, _, noted = contact_forces(x, v, np.full(3, RADIUS), pairs, 1, k, damping,
                                              1.0, 0.0, 1e-4, 0.0, force, dashpots, True)
    assert touching == noted == 1
    assert np.abs(force).max() < 1e-12  # only the (negligible) spring is a force
    w = v.copy()
    apply_dashpots(w, inv_mass, dashpots, noted, dt)
    after = normal_speed(w)
    assert 0.0 < after <= before / (1.0 + 1e3) * (1 + 1e-12)
    # momentum is conserved (the impulse is internal) and kinetic energy only falls
    assert np.sum(w / inv_mass, axis=1) == pytest.approx(np.sum(v / inv_mass, axis=1), abs=1e-12)
    assert kinetic(w, inv_mass) < kinetic(v, inv_mass)


def test_implicit_dashpots_of_a_node_in_many_contacts_only_take_energy_out():
    # One segment under five crossing ones, all pressing on its nodes at c·dt·w = 1e4: the
    # explicit sum of five such dashpots is the instability of dense contact (a plectoneme).
    # Pair by pair (Gauss–Seidel) each impulse removes energy, so the total does too, and the
    # momentum of the system is kept.
    x, pairs = crossing_segments(-1e-9, count=5)
    rng = np.random.default_rng(3)
    v = rng.standard_normal(x.shape)
    inv_mass = np.full(x.shape[1], 100.0)
    dt = 1e-4
    damping = np.full(x.shape[1] - 1, 1e4 / (dt * 100.0))
    dashpots = np.zeros((DASHPOT_ROWS, 5))
    force = np.zeros_like(x)
    _, _, _, _, noted = contact_forces(x, v, np.full(x.shape[1] - 1, RADIUS), pairs, 5,
                                       np.full(x.shape[1] - 1, 1e-6), damping, 1.0, 0.0, 1e-4,
                                       0.0, force, dashpots, True)
    assert noted == 5
    energies = [kinetic(v, inv_mass)]
    w = v.copy()
    for k in range(noted):
        apply_dashpots(w, inv_mass, dashpots[:, k:k + 1], 1, dt)
        energies.append(kinetic(w, inv_mass))
    assert np.all(np.diff(energies) <= 1e-15 * energies[0])
    assert energies[-1] < energies[0]
    assert np.sum(w / inv_mass, axis=1) == pytest.approx(np.sum(v / inv_mass, axis=1), abs=1e-9)


@pytest.mark.parametrize("ratio", [0.5, 5.0, 100.0])
def test_two_colliding_segments_lose_energy_monotonically(ratio):
    # Two free crossing segments meet at 0.1 m/s and bounce (spring k, dashpot ratio ζ of
    # critical for the pair's reduced mass), stepped as the kernel does: spring force, kick,
    # the dashpot impulses, drift, at dt = 0.05/ω of the pair spring. The energy (kinetic +
    # ½kδ²) never rises by more than the explicit spring's entry error (the step on which
    # the capsules first overlap stores up to ~(ω·dt)² of the energy; 2·(ω·dt)² bounds it,
    # measured 1.1e-3 of it) and ends
    # lower; at ζ = 100, c·dt·w = 10, five times the explicit dashpot's limit.
    x, pairs = crossing_segments(1e-4)
    mass = 0.01
    inv_mass = np.full(4, 1.0 / mass)
    k = 1e3
    w_pair = 1.0 / mass  # four nodes at weight ½: Σ (½)²/m = 1/m
    c = 2.0 * ratio * np.sqrt(k / w_pair)
    dt = 0.05 / np.sqrt(k * w_pair)
    v = np.zeros_like(x)
    v[2, 2:] = -0.05
    v[2, :2] = 0.05
    radius = np.full(3, RADIUS)
    dashpots = np.zeros((DASHPOT_ROWS, 1))
    energies, speeds = [], []
    for _ in range(1000):
        force = np.zeros_like(x)
        _, _, _, spring_energy, noted = contact_forces(
            x, v, radius, pairs, 1, np.full(3, k), np.full(3, c), 1.0, 0.0, 1e-4, 0.0, force,
            dashpots, True)
        energies.append(kinetic(v, inv_mass) + spring_energy)
        v += dt * force * inv_mass
        apply_dashpots(v, inv_mass, dashpots, noted, dt)
        speeds.append(normal_speed(v))
        x += dt * v
    energies = np.array(energies)
    assert np.diff(energies).max() <= 2 * (0.05**2) * energies[0]
    assert energies[-1] < energies[0] * (0.9 if ratio == 0.5 else 1e-3)
    # they separate again or come to rest touching; never do they pass through each other
    assert min(speeds) >= -0.1 - 1e-12
    assert x[2, 2] - x[2, 0] > RADIUS


def axial_bar(eta, elements=20):
    """A fixed-free straight bar (plain quadratic law, no damping but η) in its first axial
    mode of the discrete chain, and that mode's ω [rad/s]."""
    rod = Rod(length=1.0, radius=0.025, elements=elements, incompressible=False)
    state = straight_state(rod)
    n = rod.elements
    mass = rod.density * rod.area * rod.element_length
    m = np.full(n + 1, mass)
    m[0] = m[-1] = 0.5 * mass
    stiffness = rod.axial_stiffness / rod.element_length
    K = np.zeros((n + 1, n + 1))
    for i in range(n):
        K[i:i + 2, i:i + 2] += stiffness * np.array([[1, -1], [-1, 1]])
    K, m = K[1:, 1:], m[1:]  # node 0 clamped
    scaled = K / np.sqrt(np.outer(m, m))
    values, vectors = np.linalg.eigh(scaled)
    omega = float(np.sqrt(values[0]))
    shape = vectors[:, 0] / np.sqrt(m)
    state.v[2, 1:] = 0.01 * shape / np.abs(shape).max()
    problem = Problem(rod=rod, state=state,
                      solver=Solver(damping=0.0, rotational_damping=0.0, history_interval=1e-3,
                                    strain_rate_damping=eta))
    return problem, omega


def test_strain_rate_damping_decays_an_axial_mode_at_the_kelvin_voigt_rate():
    # Kelvin–Voigt with η: the damping matrix is η·K, so a mode of frequency ω has
    # ζ = ω·η/2 and its energy decays as exp(−2ζω·t) = exp(−ω²η·t). With η = 1e-3 s and the
    # first mode of this bar (ω ≈ 50 rad/s, ζ ≈ 0.025), over 1 s, the fit of log energy
    # (one mode, exactly: no other mode is started) must be within 1 % of ω²η (measured
    # 0.13 %): backward Euler changes the rate by O(ω·dt·ζ) ~ 1e-3, and 1 % leaves room
    # for the fit's ripple at 2ω; a dashpot on the wrong length or a lost factor 2 is off
    # by far more.
    eta = 1e-3
    problem, omega = axial_bar(eta)
    problem.stages = (Stage(1.0),)
    result = simulate(problem)
    assert result.status == "ok", result.message
    h = result.history
    energy = h["stretch_energy"] + h["kinetic_energy"]
    slope = np.polyfit(h["time"], np.log(energy), 1)[0]
    assert -slope == pytest.approx(omega**2 * eta, rel=0.01)
    # and off it is off: the undamped bar keeps its energy
    problem, _ = axial_bar(0.0)
    problem.stages = (Stage(0.2),)
    h = simulate(problem).history
    energy = h["stretch_energy"] + h["kinetic_energy"]
    assert np.ptp(energy) / energy[0] < 1e-3


def test_strain_rate_damping_is_stable_far_above_the_explicit_limit():
    # An explicit axial viscosity η is stable only for η < ~2/(ω_ax²·dt) ~ dt here; at
    # 100 dt backward Euler must stay finite and only take energy out of a clamped rod
    # thrown about by random velocities on every node (tangents turn, so the sweep's
    # couplings are not all 1; the clamped node's kicked velocity must not leak into it).
    # Axial velocities alone are then gone within the run; in 3-D bending and shear are
    # undamped (no other damping), so the energy must only not rise beyond the sampling
    # wobble of the undamped run (kinetic and potential energy half a step apart, ~2 %).
    rod = Rod(length=1.0, radius=0.025, elements=24)
    rng = np.random.default_rng(0)
    for axial_only in (True, False):
        state = straight_state(rod)
        if axial_only:
            state.v[2, 1:] = 0.05 * rng.standard_normal(rod.elements)
        else:
            state.v[:, 1:] = 0.05 * rng.standard_normal((3, rod.elements))
        probe = Problem(rod=rod, state=state, solver=Solver(history_interval=1e-9))
        dt, bound = time_step(probe)
        problem = dataclasses.replace(
            probe, solver=Solver(damping=0.0, rotational_damping=0.0, history_interval=5 * dt,
                                 strain_rate_damping=100 * dt), stages=(Stage(2000 * dt),))
        result = simulate(problem)
        assert result.status == "ok", result.message
        h = result.history
        energy = h["stretch_energy"] + h["bend_energy"] + h["kinetic_energy"]
        assert np.all(np.isfinite(energy))
        assert energy.max() < 1.05 * energy[0] and energy[-1] < energy[0]
        if axial_only:
            assert energy[-1] < 1e-6 * energy[0]


def test_implicit_dashpot_leaves_the_time_step_to_the_springs():
    rod = Rod(length=1.0, radius=0.025, elements=100)
    explicit = stable_time_step(rod, Contact(enabled=True, damping_ratio=1.0))
    implicit = stable_time_step(rod, Contact(enabled=True, damping_ratio=1.0, dashpot="implicit"))
    undamped = stable_time_step(rod, Contact(enabled=True, damping_ratio=0.0))
    assert implicit == undamped > explicit


def hairpin(rod, closing_speed):
    """(state, ends): the rod folded at its middle round a half circle of radius 2a, arms
    along z a gap of 2a apart (capsule surfaces), moving towards each other; ends free."""
    n = rod.elements
    r_bend = 2.0 * rod.radius
    straight = (rod.length - np.pi * r_bend) / 2
    state = hairpin_state(rod, r_bend)
    pts, directors = state.positions, state.directors
    arm = pts[:, 2] < straight
    state.v[0, arm & (pts[:, 0] < r_bend)] = 0.5 * closing_speed
    state.v[0, arm & (pts[:, 0] > r_bend)] = -0.5 * closing_speed
    # at rest in this shape but for the arms' motion: the bend is its rest curvature
    curvature = measured_curvature(directors, np.full(n, rod.length / n))
    return state, Ends(start_held=(False,) * 3, start_frame_held=False), curvature


def test_with_both_off_the_new_paths_change_no_bit():
    # dashpot implicit at ratio 0 adds impulses of exactly 0.0: the run must be bit-identical
    # to the explicit one at ratio 0 (the explicit default itself is pinned by
    # benchmarks/reference_positions.py against the code before these terms existed).
    rod = Rod(length=0.6, radius=0.025, elements=24, youngs_modulus=1e4)
    state, ends, curvature = hairpin(rod, 1.0)
    runs = []
    for dashpot in ("explicit", "implicit"):
        problem = Problem(rod=rod, state=state.copy(), ends=ends, rest_curvature=curvature,
                          contact=Contact(enabled=True, damping_ratio=0.0, dashpot=dashpot),
                          solver=Solver(history_interval=0.005), stages=(Stage(0.3),))
        runs.append(simulate(problem))
    a, b = runs
    assert a.history["contacts"].max() > 0
    assert np.array_equal(a.positions, b.positions)
    assert np.array_equal(a.history["kinetic_energy"], b.history["kinetic_energy"])


def test_a_hairpin_snapping_shut_is_stable_with_a_dashpot_the_explicit_step_cannot_take():
    # The arms hit each other at 2 m/s with the dashpot at ζ = 5 and η = 1e-3 s, at the
    # step the springs alone allow (the explicit dashpot at ζ = 5 would need a step 6×
    # shorter): stable, and the capsules stay apart to the default's penetration bound.
    rod = Rod(length=1.2, radius=0.025, elements=48, youngs_modulus=1e5)
    state, ends, curvature = hairpin(rod, 2.0)
    problem = Problem(rod=rod, state=state, ends=ends, rest_curvature=curvature,
                      contact=Contact(enabled=True, damping_ratio=5.0, dashpot="implicit"),
                      solver=Solver(history_interval=0.005, strain_rate_damping=1e-3),
                      stages=(Stage(0.3),))
    result = simulate(problem)
    assert result.status == "ok", result.message
    assert result.history["contacts"].max() > 0
    assert result.diagnostics["max_penetration"] < 0.1
    assert result.history["kinetic_energy"][-1] < 1e-3 * result.history["kinetic_energy"][0]


def test_an_unknown_dashpot_names_the_valid_ones():
    with pytest.raises(ValueError, match="explicit, implicit"):
        Contact(enabled=True, dashpot="Implicit")
