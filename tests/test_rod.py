"""The rod engine against analytic mechanics, invariances and conservation.

Each tolerance says why it is that number. Rods are coarse and runs short so the file takes
seconds once numba's cache is warm.
"""

import dataclasses
import math
import re
import warnings

import numpy as np
import pytest

from rodphase import config as C
from rodphase.rod import (
    Contact,
    Controls,
    Ends,
    Problem,
    Rod,
    Solver,
    Stage,
    constant,
    hairpin_state,
    ramp,
    simulate,
    stable_time_step,
    straight_state,
    time_step,
)
from rodphase.rod import kernel as K
from rodphase.rod.contact import (
    DASHPOT_ROWS,
    add_contact_forces,
    build_pairs,
    contact_forces,
    contact_forces_in,
    near_pairs,
)
from rodphase.rod.simulate import _rod_arrays
from rodphase.scenes import SCENES, build
from rodphase.theory import greenhill_clamped_moment

FREE = Ends(start_held=(False,) * 3, start_frame_held=False)


def brute_force_pairs(x, exclusion, cutoff):
    """All pairs within `cutoff` by the O(n²) definition; the reference the grid is tested
    against (a test's reference, so it lives here and not in the package)."""
    mid = 0.5 * (x[:, 1:] + x[:, :-1])
    n = mid.shape[1]
    found = set()
    for i in range(n):
        for j in range(i + exclusion + 1, n):
            if np.sum((mid[:, i] - mid[:, j]) ** 2) < cutoff * cutoff:
                found.add((i, j))
    return found

def relax(problem, until=60.0):
    problem.stages = (Stage(until, until_equilibrium=True),)
    return simulate(problem)


def test_static_stretch_of_an_incompressible_rod():
    # The discrete rod under an end force is uniformly stretched and the discrete law is the
    # continuum one, F = E A0 (1 - 1/e); the 0.5 % of the issue is far above what equilibrium
    # at tolerance 1e-6 leaves (~1e-6), so a wrong factor of e anywhere fails it.
    rod = Rod(length=1.0, radius=0.025, elements=20)
    for fraction in (0.1, 0.3):
        force = fraction * rod.youngs_modulus * rod.area
        problem = Problem(rod=rod, state=straight_state(rod),
                          controls=Controls(end_force=ramp(0, 0.2, 0, force)),
                          solver=Solver(damping=40.0, hold_tolerance=1e-6))
        result = relax(problem, 10.0)
        assert result.ok, result.message
        expected = 1.0 / (1.0 - fraction)
        assert result.positions[-1, 2] / rod.length == pytest.approx(expected, rel=5e-3)
        # incompressible: the radius follows a0 / sqrt(e)
        assert result.radii == pytest.approx(rod.radius / math.sqrt(expected), rel=5e-3)
        # the end force reported is the load the end carries
        assert result.history["end_force"][-1] == pytest.approx(force, rel=1e-3)


def cantilever_tip(n):
    rod = Rod(length=1.0, radius=0.01, elements=n)
    bending = rod.bending_stiffness
    load = 3e-3 * bending  # tip deflection 1e-3 L: geometric nonlinearity ~1e-6, negligible
    problem = Problem(rod=rod, state=straight_state(rod),
                      controls=Controls(end_force=constant(load), force_direction=(1, 0, 0)),
                      solver=Solver(damping=1.2, hold_tolerance=1e-7, history_interval=10.0))
    result = relax(problem, 100.0)
    assert result.ok, result.message
    shear = 4 * rod.shear_modulus * rod.area / 3
    exact = load / (3 * bending) + load / shear  # Timoshenko with the rod's own S1
    return result.positions[-1, 0] / exact - 1.0


def test_cantilever_tip_deflection_converges_at_second_order():
    # Euler-Bernoulli/Timoshenko tip deflection within 2 % (issue) at 20 elements; measured
    # 0.09 %. The clamp is a spring over the half element beyond the first frame, so the
    # error falls ~4x per doubling of n: we ask for > 3x (a first-order clamp gives 2x).
    e10, e20 = cantilever_tip(10), cantilever_tip(20)
    assert abs(e20) < 0.02
    assert abs(e10) / abs(e20) > 3.0


greenhill_critical_moment = greenhill_clamped_moment


def test_greenhill_reference_values():
    # The numbers: M_c L / B = 8.9868 at T = 0 and 20.9835 at T L²/B = 100.
    assert greenhill_critical_moment(1e-6, 1.0, 1.0) == pytest.approx(8.9868, abs=2e-3)
    assert greenhill_critical_moment(100.0, 1.0, 1.0) == pytest.approx(20.9835, abs=2e-3)


def lateral_growth(rod, tension, turns, stretch):
    state = straight_state(rod, twist_turns=turns)
    state.x[2] *= stretch  # start at the static stretch so no axial wave is excited
    s = np.linspace(0.0, 1.0, rod.elements + 1)
    state.v[0] = 1e-6 * np.sin(np.pi * s)
    state.v[1] = 1e-6 * np.sin(2 * np.pi * s)
    problem = Problem(rod=rod, state=state, ends=Ends(end_held=(True, True, False), end_frame_held=True),
                      controls=Controls(end_force=constant(tension)),
                      solver=Solver(damping=0.1, history_interval=0.5), stages=(Stage(12.0),))
    result = simulate(problem)
    lateral = np.linalg.norm(result.snapshot_positions[:, :, :2], axis=2).max(axis=1)
    return lateral, result


def test_greenhill_buckling_onset_within_two_percent():
    # A twisted rod under tension T L²/B = 100 between two clamps (the loaded end slides
    # axially) is stable at 0.98 M_c and unstable at 1.02 M_c: the onset is within the 2 %
    # the issue asks, at 50 elements. A thin rod (a = L/100) keeps shear and stretch
    # corrections (~0.5 %) inside that band; they are included through B_eff = B/e², L = e L0.
    rod = Rod(length=1.0, radius=0.01, elements=50)
    bending = rod.bending_stiffness
    tension = 100 * bending / rod.length**2
    stretch = 1.0 / (1.0 - tension / (rod.youngs_modulus * rod.area))
    m_c = greenhill_critical_moment(tension, stretch * rod.length, bending / stretch**2)
    for fraction, grows in ((0.98, False), (1.02, True)):
        # the twist moment of the discrete rod is C κ3 / e³ with κ3 = θ / L0
        theta = fraction * m_c * rod.length / rod.twist_stiffness * stretch**3
        lateral, result = lateral_growth(rod, tension, theta / (2 * math.pi), stretch)
        measured = result.history["end_torque"][1]
        assert measured == pytest.approx(fraction * m_c, rel=2e-3)  # the moment is what we set
        if grows:
            assert lateral.max() > 1e-3, lateral  # from ~1e-7 to millimetres: buckled
        else:
            assert lateral.max() < 1e-5, lateral  # stays at the scale of the initial kick
            assert result.ok


def _greenhill_hold(fraction, probe):
    # the rod of the onset test above, twisted to fraction × the clamped Greenhill moment and
    # held until equilibrium with the scenes' damping (20/s) and tolerance (1e-3)
    rod = Rod(length=1.0, radius=0.01, elements=50)
    bending = rod.bending_stiffness
    tension = 100 * bending / rod.length**2
    stretch = 1.0 / (1.0 - tension / (rod.youngs_modulus * rod.area))
    m_c = greenhill_critical_moment(tension, stretch * rod.length, bending / stretch**2)
    theta = fraction * m_c * rod.length / rod.twist_stiffness * stretch**3
    state = straight_state(rod, twist_turns=theta / (2 * math.pi))
    state.x[2] *= stretch
    problem = Problem(rod=rod, state=state, ends=Ends(end_held=(True, True, False), end_frame_held=True),
                      controls=Controls(end_force=constant(tension)),
                      solver=Solver(damping=20.0, hold_tolerance=1e-3, history_interval=0.1,
                                    stability_probe=probe),
                      stages=(Stage(30.0, until_equilibrium=True),))
    result = simulate(problem)
    # the history's rows and the final state: a hold may end before its first row
    shapes = np.concatenate([result.snapshot_positions, result.positions[None]])
    lateral = np.linalg.norm(shapes[:, :, :2], axis=2).max(axis=1)
    return result, lateral, result.diagnostics["stages"][0]


def test_a_hold_keeps_a_stable_straight_rod_and_leaves_an_unstable_one():
    # The straight twisted rod is an equilibrium at any twist; the residual test alone ends
    # the hold there even above the onset (checked: probe off at 1.01 M_c ends `ok`, straight).
    # With the stability probe (a seeded lateral displacement of 0.1 radius = 1e-3 m; accepted
    # once its projection on the probe shape has decayed below a tenth) the rod is kept
    # straight at 0.99 M_c (lateral < half the probe: measured 3e-4 m, the soft mode's rest
    # within the residual tolerance) and leaves the straight state at 1.01 M_c (grows past 3
    # probe sizes, to centimetres).
    unprobed, lateral, _ = _greenhill_hold(1.01, probe=False)
    assert unprobed.ok and lateral[-1] < 1e-6
    kept, lateral, stage = _greenhill_hold(0.99, probe=True)
    assert kept.ok, kept.message
    assert stage["probes"] >= 1 and stage["probes_left"] == 0
    assert lateral[-1] < 5e-4
    left, lateral, stage = _greenhill_hold(1.01, probe=True)
    assert stage["probes_left"] >= 1
    assert lateral.max() > 1e-2, lateral.max()


def test_prescribed_end_rotation_is_applied_exactly():
    # PyElastica's examples apply ~0.9x the asked rotation (damping after the boundary
    # condition). Here the clamp frame is set from the table, so the twist moment after a
    # ramp of k turns must be C (2 pi k / L0) / e³ to the accuracy of equilibrium (1e-4),
    # independent of damping.
    rod = Rod(length=1.0, radius=0.025, elements=30)
    turns = 0.5
    force = 50 * rod.buckling_force  # tension keeps it straight: 0.5 turns is far below onset
    stretch = 1.0 / (1.0 - force / (rod.youngs_modulus * rod.area))
    for damping in (2.0, 50.0):
        state = straight_state(rod)
        state.x[2] *= stretch
        problem = Problem(rod=rod, state=state,
                          ends=Ends(end_held=(True, True, False), end_frame_held=True),
                          controls=Controls(end_force=constant(force),
                                            end_rotation=ramp(0, 1.0, 0, 2 * math.pi * turns)),
                          solver=Solver(damping=damping, hold_tolerance=1e-6, history_interval=0.05),
                          stages=(Stage(1.0), Stage(30.0, until_equilibrium=True)))
        result = simulate(problem)
        assert result.ok, result.message
        assert result.history["end_rotation"][-1] == pytest.approx(2 * math.pi * turns, abs=1e-12)
        expected = rod.twist_stiffness * 2 * math.pi * turns / rod.length / stretch**3
        assert result.history["end_torque"][-1] == pytest.approx(expected, rel=1e-4)
        # and the element frames carry exactly that twist, uniformly
        d1 = result.directors[:, 0]
        angles = np.unwrap(np.arctan2(d1[:, 1], d1[:, 0]))
        spacing = np.diff(angles)
        assert spacing == pytest.approx(2 * math.pi * turns / rod.elements, rel=1e-4)


def test_energy_is_conserved_without_damping():
    # The plain quadratic law (incompressible=False) is hyperelastic; position Verlet then
    # keeps the energy within O(dt²) of its start, with no drift. 1e-4 relative over 1e4 steps
    # is the bound; a first-order error or a wrong torque sign gives > 1e-2.
    rod = Rod(length=1.0, radius=0.025, elements=30, incompressible=False)
    state = straight_state(rod)
    s = np.linspace(0.0, 1.0, rod.elements + 1)
    state.v[0] = 0.01 * np.sin(np.pi * s)
    state.v[1] = 0.005 * np.sin(2 * np.pi * s)
    state.w[2] = 0.5 * np.sin(np.pi * (np.arange(rod.elements) + 0.5) / rod.elements)
    problem = Problem(rod=rod, state=state, ends=FREE,
                      solver=Solver(damping=0.0, rotational_damping=0.0, safety=0.25,
                                    history_interval=1e-9))
    dt, _ = time_step(problem)
    problem.stages = (Stage(10_000 * dt),)
    result = simulate(problem)
    h = result.history
    energy = h["stretch_energy"] + h["bend_energy"] + h["kinetic_energy"]
    assert len(energy) >= 10_000
    assert abs(energy[-1] - energy[0]) / energy[0] < 1e-4
    assert np.ptp(energy) / energy[0] < 1e-3


def test_rod_at_rest_stays_at_rest():
    rod = Rod(length=1.0, radius=0.025, elements=25)
    problem = Problem(rod=rod, state=straight_state(rod, axis=(1.0, 2.0, -0.5)), ends=FREE,
                      stages=(Stage(0.2),))
    result = simulate(problem)
    assert np.abs(result.positions - straight_state(rod, axis=(1.0, 2.0, -0.5)).positions).max() < 1e-12


def bent_state(rod, seed=0, amplitude=1.0):
    """Random strains of order `amplitude` × (0.4 shear/stretch, 0.1 rad per element)."""
    rng = np.random.default_rng(seed)
    state = straight_state(rod)
    state.x += amplitude * 0.01 * rng.standard_normal(state.x.shape)
    from scipy.spatial.transform import Rotation

    for i in range(rod.elements):
        state.Q[:, :, i] = (Rotation.from_rotvec(amplitude * 0.1 * rng.standard_normal(3)).as_matrix()
                            @ state.Q[:, :, i])
    state.v[:] = amplitude * 0.1 * rng.standard_normal(state.v.shape)
    state.w[:] = amplitude * rng.standard_normal(state.w.shape)
    return state


def loads(problem, state):
    a = _rod_arrays(problem)
    n = problem.rod.elements
    force, torque = np.zeros((3, n + 1)), np.zeros((3, n))
    K.internal_loads(state.x, state.v, state.Q, state.w, a["rest_length"], a["rest_voronoi"],
                     a["inertia"], a["shear_stiffness"], a["bend_stiffness"], a["rest_curvature"],
                     a["rest_shear"], np.zeros(n - 1), True, 1.0, 1.0, 1.0, 1.0, 0.0,
                     force, torque, np.ones(n), np.ones(n), np.zeros(4), np.zeros((K.N_WORK, n)))
    return force, torque


def test_rigid_motion_rotates_forces_and_leaves_material_torques():
    # Objectivity: rotating and translating the whole configuration (positions, frames and
    # velocities) rotates the nodal forces and leaves the material-frame torques unchanged,
    # to round-off (1e-9 relative to forces of order 1e2 N).
    from scipy.spatial.transform import Rotation

    rod = Rod(length=1.0, radius=0.025, elements=12)
    problem = Problem(rod=rod, state=straight_state(rod))
    state = bent_state(rod)
    R = Rotation.from_rotvec([0.3, -1.1, 0.7]).as_matrix()
    moved = state.copy()
    moved.x = R @ state.x + np.array([[1.0], [-2.0], [0.5]])
    moved.v = R @ state.v
    moved.Q = np.einsum("rci,dc->rdi", state.Q, R)  # directors rotate: d' = R d
    f0, t0 = loads(problem, state)
    f1, t1 = loads(problem, moved)
    scale = np.abs(f0).max()
    assert np.abs(R @ f0 - f1).max() < 1e-9 * scale
    assert np.abs(t0 - t1).max() < 1e-9 * np.abs(t0).max()
    # internal forces are balanced (momentum conservation)
    assert np.abs(f0.sum(axis=1)).max() < 1e-9 * scale


def test_grid_finds_exactly_the_pairs_of_the_all_pairs_search():
    rng = np.random.default_rng(3)
    for n in (10, 80, 300):
        steps = rng.standard_normal((n, 3))
        steps /= np.linalg.norm(steps, axis=1)[:, None]
        x = np.vstack([np.zeros(3), np.cumsum(0.01 * steps, axis=0)]).T.copy()
        pairs, count = build_pairs(x, 3, 0.05, np.empty((2, 4), dtype=np.int64))
        found = {(int(i), int(j)) for i, j in pairs[:, :count].T}
        assert found == brute_force_pairs(x, 3, 0.05)


@pytest.mark.slow  # long: 18 s of CPU
def test_near_list_holds_exactly_the_candidates_within_the_margin():
    # Random walk with element length 0.01 and radius 0.01: many candidate pairs, a few near.
    # The near list must be the candidates whose capsule gap is below the margin, computed
    # here independently by sampling both segments at 401 points (spacing 2.5e-5 m, so the
    # sampled gap is off by < 1e-8 m; pairs within 1e-6 m of the margin are skipped), and it
    # must keep the candidate list's order.
    rng = np.random.default_rng(5)
    n = 200
    steps = rng.standard_normal((n, 3))
    steps /= np.linalg.norm(steps, axis=1)[:, None]
    x = np.vstack([np.zeros(3), np.cumsum(0.01 * steps, axis=0)]).T.copy()
    radius = 0.01 * (0.8 + 0.4 * rng.random(n))
    pairs, count = build_pairs(x, 3, 0.06, np.empty((2, 8), dtype=np.int64))
    margin = 0.004
    near = np.empty_like(pairs)
    n_near = near_pairs(x, radius, pairs, count, margin, near)
    u = np.linspace(0.0, 1.0, 401)
    expected = []
    for i, j in pairs[:, :count].T:
        a = x[:, i][:, None] + u * (x[:, i + 1] - x[:, i])[:, None]
        b = x[:, j][:, None] + u * (x[:, j + 1] - x[:, j])[:, None]
        gap = np.sqrt(((a[:, :, None] - b[:, None, :]) ** 2).sum(axis=0)).min() - radius[i] - radius[j]
        if abs(gap - margin) > 1e-6:  # skip the borderline
            expected.append(((int(i), int(j)), gap < margin))
    listed = [(int(i), int(j)) for i, j in near[:, :n_near].T]
    assert listed == [pq for pq in map(tuple, pairs[:, :count].T.tolist()) if pq in set(listed)]
    assert 0 < n_near < count
    for pair, is_near in expected:
        assert (pair in listed) == is_near, pair


def test_the_near_list_changes_no_force_while_a_plectoneme_forms():
    # The force loop runs over the near list (gap < its margin, which starts at near_skin and
    # adapts to the rod's speed), rebuilt when gaps could have closed by the margin. If a pair
    # that comes into contact were missed, the run would differ from one whose near list is
    # the whole candidate list (near_skin far larger than the rod). The touching pairs enter
    # either list in candidate order, so the sums run in the same order: bit-identical.
    cfg = C.load_scene("twist_under_load", [("rod.elements", 40), ("loading.twist_density", 0.75),
                                            ("loading.twist_rate", 2.0), ("solver.hold_until", "time"),
                                            ("solver.hold_max_time", 1.5)], SCENES)
    problem = build(cfg)
    runs = {}
    for near_skin in (0.01, 1e3):
        contact = dataclasses.replace(problem.contact, near_skin=near_skin)
        runs[near_skin] = simulate(dataclasses.replace(problem, contact=contact))
    tight, everything = runs[0.01], runs[1e3]
    assert tight.ok and everything.ok
    assert tight.history["contacts"][-1] >= 5  # the plectoneme touches itself (9 pairs)
    assert np.array_equal(tight.positions, everything.positions)
    assert np.array_equal(tight.history["contacts"], everything.history["contacts"])
    # the tight list really was rebuilt as the rod moved, the loose one only with the grid
    assert tight.diagnostics["near_rebuilds"] > 5 * everything.diagnostics["near_rebuilds"]


def test_contact_force_is_a_balanced_normal_spring():
    # Two crossing segments overlapping by delta: forces equal and opposite, along the line
    # of closest approach, magnitude k delta (no relative velocity, so no dashpot).
    x = np.array([[-0.5, 0.5, 0.0, 0.0], [0.0, 0.0, -0.5, 0.5], [0.0, 0.0, 0.015, 0.015]]).T
    x = np.ascontiguousarray(np.array([[-0.5, 0, 0], [0.5, 0, 0], [0, -0.5, 0.015],
                                       [0, 0.5, 0.015]]).T)
    v = np.zeros_like(x)
    radius = np.full(3, 0.01)
    pairs = np.array([[0], [2]])
    force = np.zeros_like(x)
    touching, depth, _, _ = add_contact_forces(x, v, radius, pairs, 1, np.full(3, 1e4), np.zeros(3),
                                            1.0, 0.0, 1e-4, 0.0, force)
    assert touching == 1 and depth == pytest.approx(0.5)
    assert force[:, :2].sum(axis=1) == pytest.approx([0, 0, -1e4 * 0.005])
    assert force[:, 2:].sum(axis=1) == pytest.approx([0, 0, 1e4 * 0.005])


def test_segments_pushed_together_do_not_interpenetrate():
    # A rod folded into a hairpin is squeezed shut by a lateral end force while its clamped
    # arm holds: with the default contact stiffness (10 E per unit length) the overlap stays
    # under 5 % of the radius, the bound.
    rod = Rod(length=1.0, radius=0.025, elements=60)
    n = rod.elements
    # hairpin: up along +z, a half circle of radius 2a, back along -z (gap 4a - 2a = 2a)
    from rodphase.scenes import measured_curvature

    state = hairpin_state(rod, 2.0 * rod.radius)
    directors = state.directors
    push = 2.0  # N towards the other arm: a line load of about 2 N over the arm's contact
    problem = Problem(rod=rod, state=state, contact=Contact(enabled=True),
                      controls=Controls(end_force=constant(push), force_direction=(-1, 0, 0)),
                      rest_curvature=measured_curvature(directors, np.full(n, rod.length / n)),
                      solver=Solver(damping=20.0, hold_tolerance=1e-4, history_interval=0.05),
                      stages=(Stage(10.0, until_equilibrium=True),))
    result = simulate(problem)
    assert result.status in ("ok", "not_converged"), result.message
    assert result.history["contacts"].max() > 0
    assert result.diagnostics["max_penetration"] < 0.05


def test_a_time_step_above_the_bound_is_caught_and_recorded():
    rod = Rod(length=1.0, radius=0.025, elements=30)
    bound = stable_time_step(rod, Contact())
    problem = Problem(rod=rod, state=bent_state(rod, amplitude=0.01), ends=Ends(),
                      solver=Solver(dt=3.0 * bound, damping=0.0), stages=(Stage(2000 * 3 * bound),))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = simulate(problem)
    assert any("above the stable bound" in str(w.message) for w in caught)
    assert result.status == "unstable"
    assert "dt = " in result.message and "stable bound" in result.message
    assert result.diagnostics["dt"] == pytest.approx(3 * bound)
    # nothing is written as if it were a result: history stops where the guard tripped
    assert result.diagnostics["steps"] < 2000


@pytest.mark.parametrize("degrees, stops", [(50.0, True), (40.0, False)])
def test_an_element_sheared_past_45_degrees_stops_the_run_there(degrees, stops):
    # A straight rod whose element 7 has its frame turned about d1 by `degrees` off its
    # tangent: past 45° the shear guard stops the run at the first check (a rod model does
    # not describe it, and the ribbon d1 then lies near the centreline, whose twist about
    # it can wrap); at 40° it runs on, the shear relaxing.
    rod = Rod(length=1.0, radius=0.025, elements=20)
    state = straight_state(rod)
    positions, directors = state.positions, state.directors.copy()  # (n, 3, 3): d1 d2 d3
    angle = math.radians(degrees)
    d2, d3 = directors[7, 1].copy(), directors[7, 2].copy()
    directors[7, 1] = math.cos(angle) * d2 - math.sin(angle) * d3
    directors[7, 2] = math.sin(angle) * d2 + math.cos(angle) * d3
    from rodphase.rod.model import state_from

    problem = Problem(rod=rod, state=state_from(positions, directors), ends=Ends(),
                      solver=Solver(check_interval=1), stages=(Stage(1e-3),))
    result = simulate(problem)
    if stops:
        assert result.status == "unstable" and result.diagnostics["guard"] == "shear"
        found = re.search(r"sheared by more than 45° .* at element (\d+) \(value ([0-9.]+); "
                          r"the element stretched to l/l0 = ([0-9.]+), the rod's largest ([0-9.]+) at "
                          r"element (\d+)\)", result.message)
        assert found, result.message
        assert int(found.group(1)) == 7
        # the angle in rad, printed to 3 digits; the first check is one step in
        assert math.degrees(float(found.group(2))) == pytest.approx(degrees, abs=1.0)
        # the stretch is the final state's, to the 3 digits printed
        stretch = np.linalg.norm(result.positions[8] - result.positions[7]) / rod.element_length
        assert float(found.group(3)) == pytest.approx(stretch, abs=5e-4 * stretch)
        lengths = np.linalg.norm(np.diff(result.positions, axis=0), axis=1) / rod.element_length
        assert float(found.group(4)) == pytest.approx(lengths.max(), abs=5e-4 * lengths.max())
        assert int(found.group(5)) == int(np.argmax(lengths))
    else:
        assert result.ok, result.message


def test_automatic_time_step_is_stable_over_many_steps():
    # The plain quadratic law: the incompressible law of the paper is not hyperelastic (its
    # 1/e and 1/e³ factors do work), so without any damping large random strains can grow
    # for physical-model reasons, which says nothing about the time step.
    rod = Rod(length=1.0, radius=0.025, elements=40, incompressible=False)
    # strains of a few per cent in every mode, the highest included; 2e4 steps undamped
    problem = Problem(rod=rod, state=bent_state(rod, seed=2, amplitude=0.05), ends=FREE,
                      solver=Solver(damping=0.0, rotational_damping=0.0))
    dt, bound = time_step(problem)
    assert dt == pytest.approx(0.5 * bound)
    problem.stages = (Stage(20_000 * dt),)
    problem.solver = Solver(damping=0.0, rotational_damping=0.0, history_interval=100 * dt)
    result = simulate(problem)
    assert result.ok, result.message
    h = result.history
    energy = h["stretch_energy"] + h["bend_energy"] + h["kinetic_energy"]
    assert energy.max() < 1.05 * energy[0]  # bounded: no instability growing underneath


def test_contact_forces_are_the_gradient_of_the_contact_energy():
    # With the radius a0/sqrt(e) of an incompressible rod, the overlap depends on element
    # lengths too; the forces (no dashpot) must be -dU/dx of U = sum k delta^2 / 2, else
    # contact does work on a stretching rod. Central differences, relative error 1e-6
    # (step 1e-7 m on overlaps of ~1e-3 m: truncation ~1e-8, round-off ~1e-9).
    rng = np.random.default_rng(5)
    n = 30
    rest = 0.01
    a0 = 0.025
    s = np.arange(n + 1) * rest
    x = np.vstack([0.02 * np.cos(s / 0.02 * 1.0), 0.02 * np.sin(s / 0.02), 0.005 * s / rest])
    x += 1e-4 * rng.standard_normal(x.shape)
    x = np.ascontiguousarray(x)

    def energy_and_force(pos):
        lengths = np.linalg.norm(np.diff(pos, axis=1), axis=0)
        radius = a0 / np.sqrt(lengths / rest)
        pairs, count = build_pairs(pos, 3, 0.2, np.empty((2, 8), dtype=np.int64))
        force = np.zeros_like(pos)
        out = add_contact_forces(pos, np.zeros_like(pos), radius, pairs, count, np.full(n, 1e4),
                                 np.zeros(n), 1.0, 0.0, 1e-4, 1.0, force)
        return out[3], force, out[0]

    energy, force, touching = energy_and_force(x)
    assert touching > 10 and energy > 0
    h = 1e-7
    numeric = np.zeros_like(x)
    for c in range(3):
        for i in range(n + 1):
            xp, xm = x.copy(), x.copy()
            xp[c, i] += h
            xm[c, i] -= h
            numeric[c, i] = -(energy_and_force(xp)[0] - energy_and_force(xm)[0]) / (2 * h)
    assert np.abs(force - numeric).max() < 1e-6 * np.abs(force).max()


def test_contact_forces_with_kept_buffers_match_fresh_ones():
    # The kernel hands contact_forces_in per-element buffers it keeps from step to step; what
    # they hold from an earlier call (another shape, another rod) must not leak into the forces.
    rng = np.random.default_rng(7)
    n = 30
    s = np.arange(n + 1) * 0.01
    x = np.ascontiguousarray(np.vstack([0.02 * np.cos(s / 0.02), 0.02 * np.sin(s / 0.02),
                                        0.005 * s / 0.01]))
    x += 1e-4 * rng.standard_normal(x.shape)
    v = 1e-3 * rng.standard_normal(x.shape)
    radius = np.full(n, 0.025)
    pairs, count = build_pairs(x, 3, 0.2, np.empty((2, 8), dtype=np.int64))
    k, c = np.full(n, 1e4), np.full(n, 3.0)
    for implicit in (False, True):
        fresh_force = np.zeros_like(x)
        fresh_dash = np.zeros((DASHPOT_ROWS, count))
        fresh = contact_forces(x, v, radius, pairs, count, k, c, 1.0, 0.2, 1e-4, 1.0,
                               fresh_force, fresh_dash, implicit)
        work = rng.standard_normal((5, n))  # stale contents
        kept_force = np.zeros_like(x)
        kept_dash = np.zeros((DASHPOT_ROWS, count))
        kept = contact_forces_in(x, v, radius, pairs, count, k, c, 1.0, 0.2, 1e-4, 1.0,
                                 kept_force, kept_dash, implicit, work[:3], work[3], work[4])
        assert fresh[0] > 10 and fresh == kept
        assert np.array_equal(fresh_force, kept_force)
        assert np.array_equal(fresh_dash, kept_dash)


def test_prescribed_end_displacement_records_the_reaction_force():
    # Pulling the end by 10 % of L0 (displacement control) must need F = E A0 (1 - 1/e)
    # with e = 1.1: the recorded reaction, to the equilibrium tolerance (1e-4 relative).
    rod = Rod(length=1.0, radius=0.025, elements=20)
    pull = 0.1
    problem = Problem(rod=rod, state=straight_state(rod), ends=Ends(end_held=(True, True, True)),
                      controls=Controls(end_displacement=ramp(0, 0.5, 0, pull)),
                      solver=Solver(damping=40.0, hold_tolerance=1e-6),
                      stages=(Stage(0.5), Stage(10.0, until_equilibrium=True)))
    result = simulate(problem)
    assert result.ok, result.message
    assert result.positions[-1, 2] == pytest.approx(1.0 + pull, abs=1e-12)  # exact, held
    expected = rod.youngs_modulus * rod.area * (1 - 1 / (1 + pull))
    assert result.history["end_force"][-1] == pytest.approx(expected, rel=1e-4)
    assert result.history["end_displacement"][-1] == pytest.approx(pull, abs=1e-9)


def test_modulus_ramp_shortens_a_loaded_rod_as_the_law_says():
    # Constant load F; E ramps to 2E. Equilibrium extension then follows
    # F = 2 E A0 (1 - 1/e), within the equilibrium tolerance.
    rod = Rod(length=1.0, radius=0.025, elements=20)
    force = 0.2 * rod.youngs_modulus * rod.area
    problem = Problem(rod=rod, state=straight_state(rod),
                      controls=Controls(end_force=constant(force), stiffness=ramp(0, 1.0, 1.0, 2.0)),
                      solver=Solver(damping=40.0, hold_tolerance=1e-6),
                      stages=(Stage(1.0), Stage(10.0, until_equilibrium=True)))
    result = simulate(problem)
    assert result.ok, result.message
    e = 1 / (1 - force / (2 * rod.youngs_modulus * rod.area))
    assert result.positions[-1, 2] == pytest.approx(e, rel=1e-4)


def twist_of(result):
    """Twist per unit rest length of the element frames about a straight rod's axis [rad/m]."""
    d1 = result.directors[:, 0]
    angles = np.unwrap(np.arctan2(d1[:, 1], d1[:, 0]))
    return np.diff(angles) / (result.rest_lengths[0])


def test_radius_growth_keeps_a_times_rest_twist():
    # A free rod with intrinsic twist k3 relaxes to twist k3; doubling its radius with
    # a k3 fixed (the paper's muscle model) leaves it with twist k3/2 (to 1e-4 relative).
    k3 = 5.0
    rod = Rod(length=1.0, radius=0.02, elements=20, rest_curvature=(0.0, 0.0, k3))
    problem = Problem(rod=rod, state=straight_state(rod),
                      ends=Ends(start_held=(True, True, True), start_frame_held=True),
                      controls=Controls(radius=ramp(0, 1.0, 1.0, 2.0)),
                      solver=Solver(damping=40.0, hold_tolerance=1e-7),
                      stages=(Stage(1.0), Stage(20.0, until_equilibrium=True)))
    result = simulate(problem)
    assert result.ok, result.message
    assert twist_of(result) == pytest.approx(k3 / 2, rel=1e-4)
    assert result.radii == pytest.approx(2 * rod.radius, rel=1e-3)


def test_growing_rod_does_not_touch_its_own_neighbours():
    # A straight rod whose radius triples with contact on: capsules a few elements apart
    # along the rod overlap once a > l, and must stay excluded at the grown radius (the
    # exclusion is set from the largest radius of any stage), so nothing ever touches.
    rod = Rod(length=1.0, radius=0.02, elements=40)
    problem = Problem(rod=rod, state=straight_state(rod),
                      ends=Ends(start_held=(True, True, True), start_frame_held=True),
                      controls=Controls(radius=ramp(0, 0.5, 1.0, 3.0)),
                      contact=Contact(enabled=True), stages=(Stage(0.6),))
    result = simulate(problem)
    assert result.ok, result.message
    assert result.history["contacts"].max() == 0
    assert np.abs(result.positions[:, :2]).max() < 1e-9  # no spurious push off the z axis


def test_a_slow_oscillation_is_not_taken_for_a_settled_shape():
    # A lightly damped cantilever swinging about its deflected shape (tip amplitude 1 cm,
    # 5 % of its length) with the settle window set to exactly its period: consecutive
    # window means then agree (checked below, so the test's premise holds), but the shape
    # is not at rest, and the spread within the window must keep the hold going.
    rod = Rod(length=0.2, radius=0.01, elements=10)
    load = 3 * rod.bending_stiffness * 0.01 / rod.length**3  # static tip deflection ≈ 1 cm
    solver = Solver(damping=0.02, rotational_damping=0.02, hold_tolerance=1e-3, history_interval=1e-3)

    def swing(stage, **settle):
        problem = Problem(rod=rod, state=straight_state(rod),
                          controls=Controls(end_force=constant(load), force_direction=(1, 0, 0)),
                          solver=dataclasses.replace(solver, **settle), stages=(stage,))
        return simulate(problem)

    free = swing(Stage(3.0))
    tip = free.snapshot_positions[:, -1, 0]
    t = free.history["time"]
    up = np.where((tip[:-1] < tip.mean()) & (tip[1:] >= tip.mean()))[0]
    period = float(np.mean(np.diff(t[up])))
    windows = [tip[(t >= a) & (t < a + period)].mean() for a in t[up[:4]]]
    assert np.ptp(windows) < 0.2 * solver.hold_tolerance * rod.length  # means agree: premise
    assert np.std(tip) > 10 * solver.hold_tolerance * rod.length  # yet it swings
    held = swing(Stage(3.0, until_equilibrium=True), settle_window=period)
    assert held.status == "not_converged"
    assert not held.diagnostics["stages"][0]["settled"]


def test_local_rest_twist_over_a_segment():
    # An "active agent" adding rest twist over nodes 5..15 of a free rod: the frames inside
    # the segment twist by exactly that density, those outside do not.
    rod = Rod(length=1.0, radius=0.02, elements=20)
    extra = 3.0
    problem = Problem(rod=rod, state=straight_state(rod),
                      ends=Ends(start_held=(True, True, True), start_frame_held=True),
                      controls=Controls(local_twist=constant(extra), segment=(5, 15)),
                      solver=Solver(damping=40.0, hold_tolerance=1e-7),
                      stages=(Stage(20.0, until_equilibrium=True),))
    result = simulate(problem)
    assert result.ok, result.message
    density = twist_of(result)  # Voronoi j sits at node j+1: nodes 6..14 are j = 5..13
    inside = np.arange(5, 14)
    outside = np.r_[np.arange(0, 4), np.arange(15, 19)]
    assert density[inside] == pytest.approx(extra, rel=1e-4)
    assert np.abs(density[outside]).max() < 1e-4 * extra


def test_intrinsic_curvature_relaxes_to_a_circular_arc():
    # A free rod with rest curvature k1 about d1 relaxes to an arc of radius 1/k1: all its
    # nodes lie on that circle (to 1e-4 of the radius: equilibrium tolerance).
    k1 = 2.0
    rod = Rod(length=1.0, radius=0.01, elements=40, rest_curvature=(k1, 0.0, 0.0))
    problem = Problem(rod=rod, state=straight_state(rod),
                      ends=Ends(start_held=(True, True, True), start_frame_held=True),
                      solver=Solver(damping=1.2, hold_tolerance=1e-6),  # ~critical for the first mode
                      stages=(Stage(60.0, until_equilibrium=True),))
    result = simulate(problem)
    assert result.ok, result.message
    p = result.positions
    # the arc lies in the plane normal to d1 (x); fit its centre on the normal through node 0
    yz = p[:, 1:]
    assert np.abs(p[:, 0]).max() < 1e-9
    centre = np.array([yz[0, 0] + np.sign(yz[-1, 0] - yz[0, 0]) / k1, 0.0])
    r = np.linalg.norm(yz - centre, axis=1)
    assert r == pytest.approx(1 / k1, rel=1e-3)


def test_friction_opposes_sliding_with_coulomb_magnitude():
    x = np.ascontiguousarray(np.array([[-0.5, 0, 0], [0.5, 0, 0], [0, -0.5, 0.015],
                                       [0, 0.5, 0.015]]).T)
    v = np.zeros_like(x)
    v[0, 2:] = 0.1  # the upper segment slides along +x
    radius = np.full(3, 0.01)
    force = np.zeros_like(x)
    add_contact_forces(x, v, radius, np.array([[0], [2]]), 1, np.full(3, 1e4), np.zeros(3),
                       1.0, 0.3, 1e-4, 0.0, force)
    normal = 1e4 * 0.005
    assert force[0, 2:].sum() == pytest.approx(-0.3 * normal)  # on the slider, against +x
    assert force[0, :2].sum() == pytest.approx(0.3 * normal)
    assert force[2, 2:].sum() == pytest.approx(normal)


def test_friction_with_several_pairs_leaves_the_normal_springs_alone():
    # Regression: the friction coefficient once overwrote the stiffness scale for the pairs
    # after the first; the same overlapping pair listed twice must give twice the force.
    x = np.ascontiguousarray(np.array([[-0.5, 0, 0], [0.5, 0, 0], [0, -0.5, 0.015],
                                       [0, 0.5, 0.015]]).T)
    v = np.zeros_like(x)
    v[0, 2:] = 0.1
    force = np.zeros_like(x)
    add_contact_forces(x, v, np.full(3, 0.01), np.array([[0, 0], [2, 2]]), 2, np.full(3, 1e4),
                       np.zeros(3), 1.0, 0.3, 1e-4, 0.0, force)
    assert force[2, :2].sum() == pytest.approx(-2 * 1e4 * 0.005)


def test_a_hold_that_runs_out_of_time_says_which_test_failed_and_by_how_much():
    # A rod released bent and held for far too short a time: the message names each unmet
    # criterion with its value and threshold (not "residual 5e-4 ... tolerance 1e-3").
    rod = Rod(length=1.0, radius=0.025, elements=10)
    state = straight_state(rod)
    state.x[0] += 0.02 * np.sin(np.pi * np.linspace(0, 1, 11))
    problem = Problem(rod=rod, state=state, ends=Ends(end_held=(True, True, True)),
                      solver=Solver(hold_tolerance=1e-6, settle_window=0.02),
                      stages=(Stage(0.01, until_equilibrium=True, label="hold"),))
    result = simulate(problem)
    assert result.status == "not_converged"
    assert "residual force" in result.message and "needs < 1e-06" in result.message
    assert "window" in result.message and "solver.hold_max_time" in result.message


def test_a_fixed_dt_above_the_bound_is_named_not_blamed_on_resolution():
    # drag off (else the run is refused up front): a solver.dt 10x the bound blows up in some
    # guard; the message names solver.dt and the guard is "time_step", so a sweep with
    # refine_up_to does not rerun the rod at 2n, 4n, ... elements.
    from rodphase.runner import run_scene

    cfg = C.load_scene("twist_under_load", [("rod.elements", 16), ("solver.quadratic_drag", 0),
                                            ("solver.refine_up_to", 64)], SCENES)
    rod = build(cfg).rod
    bound = stable_time_step(rod, build(cfg).contact)
    scene = C.apply_overrides(cfg.plain(), [("solver.dt", 10 * bound)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = run_scene(scene)
    assert result.status == "unstable"
    assert result.diagnostics["guard"] == "time_step" and "solver.dt" in result.message
    assert "refined_from" not in result.diagnostics and result.diagnostics["elements"] == 16


def test_the_contact_thinning_force_is_the_only_axial_contact_load_between_parallel_strands():
    # A hairpin whose two straight legs overlap by 0.01 m (bend radius 0.8 a): the pair
    # springs between the parallel legs push along their common normal, across the legs, so
    # on the legs' nodes any load along the legs is the thinning force, k·δ·a/(2l) along each
    # element of an incompressible rod (Contact.thinning_force; issue #29). Off, none is left
    # (round-off of the 8.7 kN normal loads: 1e-11 N measured); on, several newtons (5.6 N
    # measured at the middle of the legs, where neighbouring elements' pulls mostly cancel).
    # Through static_model_of, the path the kernel's settings take, and in a short run.
    from rodphase.rod import static
    from rodphase.rod.simulate import static_model_of

    rod = Rod(length=1.0, radius=0.025, elements=40)
    state = hairpin_state(rod, 0.8 * rod.radius)
    straight = (rod.length - math.pi * 0.8 * rod.radius) / 2
    legs = (state.x[2] > 0.1) & (state.x[2] < straight - 0.05)
    axial, ends = {}, {}
    for flag in (True, False):
        problem = Problem(rod=rod, state=state, stages=(Stage(2e-4),),
                          contact=Contact(enabled=True, thinning_force=flag, sleep=False))
        model = static_model_of(problem, contact=True)
        assert model.thinning_force is flag
        force = static.contact_force(model, np.ascontiguousarray(state.x))
        assert np.abs(force[0][legs]).max() > 1e3  # the legs pressed apart
        axial[flag] = np.abs(force[2][legs]).max()
        ends[flag] = simulate(problem).positions
    assert axial[False] < 1e-8 and axial[True] > 1.0, axial
    assert not np.array_equal(ends[True], ends[False])  # the kernel takes the setting too
