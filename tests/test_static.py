"""The static solver (rod/static.py) against analytic statics: a cantilever under a tip load
(Timoshenko beam: bending and shear), the incompressible rod's static stretch, and a
perturbed twisted rod's return to its straight equilibrium."""

import numpy as np
import pytest

from rodphase.rod import static
from rodphase.rod.model import Controls, Ends, Problem, Rod, constant, straight_state
from rodphase.rod.onset import LOADED_ENDS, StraightBranch
from rodphase.rod.simulate import static_model_of

CANTILEVER = Ends(start_held=(True,) * 3, start_frame_held=True, end_held=(False,) * 3,
                  end_frame_held=False)


def cantilever_tip(n: int) -> tuple[float, float]:
    """(tip deflection solved, Timoshenko's PL³/3B + PL/S) under a tip load 1e-3·3B/L² across
    the rod (deflection ~1e-3 L: the linear regime, the geometric nonlinearity ~1e-6)."""
    rod = Rod(length=1.0, radius=0.025, elements=n, incompressible=False)
    load = 1e-3 * 3 * rod.bending_stiffness / rod.length**2
    problem = Problem(rod=rod, state=straight_state(rod), ends=CANTILEVER,
                      controls=Controls(end_force=constant(load), force_direction=(1.0, 0.0, 0.0)))
    solution = static.solve(static_model_of(problem), problem.state.x, problem.state.Q,
                            force_scale=load, tolerance=1e-8)
    assert solution.success, solution.message
    timoshenko = (load * rod.length**3 / (3 * rod.bending_stiffness)
                  + load * rod.length / rod.shear_stiffness)
    return solution.x[0, -1], timoshenko


def test_a_cantilever_deflects_as_a_timoshenko_beam_at_second_order():
    # measured errors 0.50 %, 0.125 %, 0.031 % at n = 10, 20, 40: slope 2 ± 0.05, and the
    # n = 40 error under 0.05 % (the linear regime's geometric error is ~1e-6)
    errors = [abs(solved / analytic - 1) for solved, analytic in map(cantilever_tip, (10, 20, 40))]
    slope = np.polyfit(np.log([10, 20, 40]), np.log(errors), 1)[0]
    assert slope == pytest.approx(-2.0, abs=0.05)
    assert errors[-1] < 5e-4


def test_a_loaded_incompressible_rod_stretches_to_its_analytic_extension():
    # F = E·A0·(1 − 1/e) for the paper's incompressible law: from the unstretched rod, Newton
    # finds e = 1.25 for F = E·A0/5 to 1e-10 (uniform stretch: no discretisation error)
    rod = Rod(length=1.0, radius=0.025, elements=12)
    force = rod.axial_stiffness * (1 - 1 / 1.25)
    problem = Problem(rod=rod, state=straight_state(rod), ends=LOADED_ENDS,
                      controls=Controls(end_force=constant(force)))
    solution = static.solve(static_model_of(problem), problem.state.x, problem.state.Q,
                            force_scale=force)
    assert solution.success, solution.message
    assert solution.x[2, -1] == pytest.approx(1.25, rel=1e-10)


def test_a_disturbed_twisted_rod_below_its_onset_returns_to_the_straight_branch():
    # 0.8 of the onset at L/L0 = 1.15: the nodes moved laterally by 1 % of a radius and the
    # frames turned by 1e-3 rad at random; Newton returns to the uniform state to 1e-9 m
    rod = Rod(length=1.0, radius=0.025, elements=24)
    branch = StraightBranch(rod, 1.15)
    problem = branch.problem(0.8 * branch.onset_turns(1e-4))
    x, Q = problem.state.x, problem.state.Q
    rng = np.random.default_rng(5)
    mode = np.zeros((rod.elements + 1, 3))
    mode[1:-1, :2] = rng.standard_normal((rod.elements - 1, 2))
    x_moved, Q_moved = static.displaced(x, Q, mode, rng.standard_normal((rod.elements, 3)) * 4,
                                        2.5e-4)
    model = static_model_of(problem)
    solution = static.solve(model, x_moved, Q_moved, force_scale=rod.buckling_force)
    assert solution.success, solution.message
    assert np.abs(solution.x - x).max() < 1e-9
    assert np.abs(solution.Q - Q).max() < 1e-9


def test_twisting_the_straight_branch_further_lands_on_its_equilibrium_at_the_new_rotation():
    # The predictor of a continuation step: the straight rod at 0.5 of its onset, twisted
    # further by 0.3 turns, is the straight equilibrium that onset.straight_equilibrium
    # builds at 0.5·onset + 0.3 turns on its own (frames to round-off, 1e-12), and its loads
    # under that rotation vanish to round-off (1e-9 of the buckling force: E·A·1e-16 is
    # ~1e-10 of it at this radius); left untwisted they would not (the clamp's couple).
    from rodphase.rod.onset import straight_equilibrium
    from rodphase.units import TURN

    rod = Rod(length=1.0, radius=0.025, elements=24)
    turns = 0.5 * StraightBranch(rod, 1.15).onset_turns(1e-4)
    before = straight_equilibrium(rod, 1.15, turns)
    after = straight_equilibrium(rod, 1.15, turns + 0.3)
    x, Q = static.twisted_further(before.state.x, before.state.Q, 0.3 * TURN)
    assert np.abs(x - after.state.x).max() == 0.0
    assert np.abs(Q - after.state.Q).max() < 1e-12
    model = static_model_of(after)
    scale = rod.buckling_force
    assert static.residual_norm(model, static.loads(model, x, Q)) < 1e-9 * scale
    untwisted = static.residual_norm(model, static.loads(model, before.state.x, before.state.Q))
    assert untwisted > 1e-3 * scale


def coil_in_contact(n: int = 48, pitch_over_diameter: float = 0.97):
    """A clamped, loaded rod laid as a three-loop helix whose pitch is 3 % short of touching
    (neighbouring loops overlap by about 3 % of the diameter): a state in self-contact built
    without the kernel. Returns (problem, static model with contact)."""
    from rodphase.rod.model import Contact, state_from
    from rodphase.scenes import helix_state

    a = 0.01
    x, directors, length = helix_state(0.05, pitch_over_diameter * 2 * a, 3.0, n, 1, 0.0)
    rod = Rod(length=length, radius=a, elements=n)
    state = state_from(x, directors)
    problem = Problem(rod=rod, state=state, ends=LOADED_ENDS,
                      controls=Controls(end_force=constant(rod.buckling_force)),
                      contact=Contact(enabled=True))
    return problem, static_model_of(problem, contact=True)


def test_self_contact_at_rest_is_the_kernels_pair_law_and_conserves_momentum():
    # neighbouring loops overlap: the forces are the pair springs k·δ (no dashpot, no
    # friction at rest); they are internal, so they sum to zero force and zero moment about
    # the origin (to round-off of the largest force: 1e-12)
    problem, model = coil_in_contact()
    force = static.contact_force(model, problem.state.x)
    largest = np.linalg.norm(force, axis=0).max()
    assert largest > 0.01 * problem.rod.buckling_force  # the loops do press on each other
    assert np.abs(force.sum(axis=1)).max() < 1e-12 * largest * problem.rod.elements
    moment = np.cross(problem.state.x.T, force.T).sum(axis=0)
    assert np.abs(moment).max() < 1e-12 * largest * problem.rod.length * problem.rod.elements
    # without contact the static model sees none of it
    plain = static.loads(static_model_of(problem), problem.state.x, problem.state.Q)
    touched = static.loads(model, problem.state.x, problem.state.Q)
    assert np.abs(touched - plain).max() > 0.01 * problem.rod.buckling_force


@pytest.mark.parametrize("case", ["coil", "fold", "body"])
def test_the_stiffness_with_contact_matches_plain_central_differences_of_the_loads(case):
    # the contact columns are coloured (nodes that reach no common node are perturbed
    # together) and the rod's are banded: together they must equal one column at a time of
    # the loads with contact, up to the differences' round-off (1e-9 of the largest entry);
    # a coil's pairs, a fold's springs and an end body's push (its reaction on the end node)
    if case == "coil":
        problem, model = coil_in_contact(n=36)
    else:
        problem = cornered_rod(case)
        model = static_model_of(problem, contact=True)
        if case == "fold":
            # one element of the far leg 2 % longer: the thinnest, whose radius bounds every
            # fold (contact.fold_forces), unique (equal lengths are the min's kink)
            problem.state.x[0, 31:] += 0.02 * problem.rod.element_length
    x, Q = problem.state.x, problem.state.Q
    K = static.stiffness_matrix(model, x, Q)
    pairs = static.candidate_pairs(model, x)
    N, m = model.unknowns, model.positions
    plain = np.empty((N, N))
    for j in range(N):
        du = np.zeros(N)
        du[j] = 1e-6 * model.length_scale if j < m else 1e-6
        xp, Qp = static.step_along(model, x, Q, du)
        xm, Qm = static.step_along(model, x, Q, -du)
        plain[:, j] = -(static.loads(model, xp, Qp, pairs)
                        - static.loads(model, xm, Qm, pairs)) / (2 * du[j])
    contact = static.contact_stiffness(model, x)
    assert np.abs(contact).max() > 0.01 * np.abs(plain).max()  # contact is a large part
    assert np.abs(K - plain).max() < 1e-9 * np.abs(plain).max()


@pytest.fixture(scope="module")
def settled_solenoid():
    """Fig 2b's solenoid at 64 elements, held until the kernel's equilibrium test passed:
    (problem, result, static model with contact, x, Q, force scale)."""
    from rodphase import config as C
    from rodphase.rod.simulate import force_scale
    from rodphase.runner import run
    from rodphase.scenes import SCENES, build

    overrides = [("rod.elements", 64), ("loading.force_multiple", 90),
                 ("loading.twist_density", 1.55), ("loading.twist_rate", 1.0),
                 ("solver.hold_max_time", 8.0)]
    problem = build(C.load_scene("twist_under_load", overrides, SCENES))
    result = run(problem)
    assert result.status == "ok", result.message
    model = static_model_of(problem, controls=problem.stages[-1].controls, contact=True)
    x = np.ascontiguousarray(result.positions.T)
    Q = np.ascontiguousarray(np.transpose(result.directors, (1, 2, 0)))
    return problem, result, model, x, Q, force_scale(problem)


def test_a_solenoid_the_kernel_settled_is_an_equilibrium_of_the_static_loads_with_contact(
        settled_solenoid):
    # the static loads of its final state (self-contact included) are the residual the kernel
    # measured there (the same pieces composed; 1 % covers the kernel taking it at its last
    # check, up to 50 steps before the end), and without contact they would not be
    problem, result, model, x, Q, scale = settled_solenoid
    measured = result.history["residual"][-1]
    static_residual = static.residual_norm(model, static.loads(model, x, Q)) / scale
    assert result.history["contacts"][-1] > 10
    assert abs(static_residual - measured) < 0.01 * measured, (static_residual, measured)
    no_contact = static_model_of(problem, controls=problem.stages[-1].controls)
    assert static.residual_norm(no_contact, static.loads(no_contact, x, Q)) / scale > 0.1


def test_newton_beside_the_two_softest_modes_converges_from_the_kernels_settled_solenoid(
        settled_solenoid):
    # The kernel's hold ends at a residual of 1e-3 of the force scale; plain Newton stalls
    # there (rod/static.py's docstring). With the two eigen-directions of the mass-weighted
    # stiffness nearest zero left out, the rest converges to 1e-8 (measured: 9 steps, 8
    # stiffnesses, 8.3e-9; the
    # tolerance is the solver's default, far above the finite-difference stiffness's noise
    # of ~1e-10 of the loads), the state moves by little (measured 0.015 radii: the shape,
    # hence its label, is the kernel's; 0.1 leaves room for round-off in the path taken),
    # and what is left lies along the two soft modes only: a force (measured 1.8e-4 of the
    # scale) that remains because no equilibrium is isolated there, on modes whose
    # eigenvalues are at most 1e-5 of the largest singular value (measured 278 and 1.1 s⁻²
    # against 7e7).
    _, result, model, x, Q, scale = settled_solenoid
    solution = static.solve_beside_soft_modes(model, x, Q, soft_modes=2, force_scale=scale)
    assert solution.success, solution.message
    assert solution.residual < 1e-8 and solution.iterations <= 20, solution
    assert np.abs(solution.x - x).max() < 0.1 * 0.025
    assert 1e-6 < solution.soft_residual < 2e-3, solution.soft_residual
    # recomputed apart from the solver: the loads at the state it returns are that soft force
    full = static.residual_norm(model, static.loads(model, solution.x, solution.Q)) / scale
    assert abs(full - solution.soft_residual) < 1e-7, (full, solution.soft_residual)
    root_mass = np.sqrt(static.masses(model, x))
    A = static.stiffness_matrix(model, x, Q) / root_mass[:, None] / root_mass[None, :]
    assert np.abs(solution.soft_values).max() < 1e-5 * np.linalg.norm(A, 2), solution.soft_values
    with pytest.raises(ValueError, match="soft_modes"):
        static.solve_beside_soft_modes(model, x, Q, soft_modes=0, force_scale=scale)


def test_a_continuation_step_in_twist_reuses_the_corrector_factorization(settled_solenoid):
    # One step of a twist continuation from the corrected solenoid: the end turned by
    # 0.005 in Φa (0.032 turns), the predictor spreading that twist along the rod
    # (static.twisted_further), then the corrector started from the previous state's
    # factorization. Measured: 9 Newton steps of which 3 formed a stiffness (the others
    # reused one: chord steps), residual 7e-9 outside the soft modes, writhe up by 0.005 of
    # the 0.032 turns of link added. A state this close is the regime a continuation runs
    # in; with 5× the step the corrector on this solenoid fails at the fourth step
    # (docs/history/performance.md, "A twist continuation beside the soft modes").
    import dataclasses

    from rodphase import topology
    from rodphase.rod import kernel
    from rodphase.units import TURN, turns_for_twist_density

    problem, _, model, x, Q, scale = settled_solenoid
    start = static.solve_beside_soft_modes(model, x, Q, soft_modes=2, force_scale=scale)
    assert start.success, start.message
    added = turns_for_twist_density(0.005, problem.rod.radius, problem.rod.length)
    now = model.now.copy()
    now[kernel.T_END_ROTATION] += added * TURN
    turned = dataclasses.replace(model, now=now)
    x_predicted, Q_predicted = static.twisted_further(start.x, start.Q, added * TURN)
    unpredicted = static.residual_norm(turned, static.loads(turned, start.x, start.Q))
    predicted = static.residual_norm(turned, static.loads(turned, x_predicted, Q_predicted))
    assert predicted < 0.05 * unpredicted, (predicted, unpredicted)
    step = static.solve_beside_soft_modes(turned, x_predicted, Q_predicted, soft_modes=2,
                                          force_scale=scale,
                                          factorization=start.factorization)
    assert step.success, step.message
    assert step.factorizations < step.iterations, step  # chord steps were taken
    gained = topology.writhe(step.x.T) - topology.writhe(start.x.T)
    assert 0.0 < gained < added, (gained, added)


def kernel_residual(problem: Problem) -> float:
    """The kernel's residual (largest free nodal force or torque per length, over the force
    scale) at problem.state, as its first history row records it (one step run)."""
    import dataclasses

    from rodphase.rod.model import Stage
    from rodphase.rod.simulate import clamp_reference, simulate, time_step

    dt, _ = time_step(problem)
    once = dataclasses.replace(
        problem, clamp_reference=clamp_reference(problem), stages=(Stage(dt),),
        contact=dataclasses.replace(problem.contact, sleep=False),
        solver=dataclasses.replace(problem.solver, history_interval=dt, check_interval=1))
    return float(simulate(once).history["residual"][0])


def polyline_state(points):
    """A rod state along the polyline through `points` (n+1, 3) in the x-z plane: d3 along
    each element, d1 = +y."""
    from rodphase.rod.model import state_from

    t = np.diff(points, axis=0)
    t /= np.linalg.norm(t, axis=1)[:, None]
    d1 = np.tile([0.0, 1.0, 0.0], (len(t), 1))
    return state_from(points, np.stack([d1, np.cross(t, d1), t], axis=1))


@pytest.mark.parametrize("piece", ["fold", "body"])
def test_folds_and_end_bodies_at_rest_are_the_kernels(piece):
    # "fold": a rod turned by a right angle at one node: the nodes either side of the corner
    # are 1.34 a apart, inside the 1.63 a a fold of the rod's radius allows, so the fold
    # springs push them apart. "body": the rod leaves the clamp across the axis for 1.9 a,
    # then runs down beside the start's end body (radius a on the axis), its nodes
    # overlapping the body by 0.1 a. Each at rest in its own shape (rest curvature = its
    # curvature), so that contact is the only load: the static model's residual must be
    # the one the kernel measures at that state (the same pieces composed: 1e-9), and
    # without the piece under test it must not be
    import dataclasses

    from rodphase.rod.simulate import force_scale

    problem = cornered_rod(piece)
    state = problem.state
    model = static_model_of(problem, contact=True)
    scale = force_scale(problem)
    static_residual = static.residual_norm(model, static.loads(model, state.x, state.Q)) / scale
    measured = kernel_residual(problem)
    assert measured > 0.01  # contact pushes, far beyond the round-off of the rest shape
    assert abs(static_residual - measured) < 1e-9 * measured, (static_residual, measured)
    without = (dataclasses.replace(model, fold=False) if piece == "fold" else
               dataclasses.replace(model, ends=model.ends._replace(start_body=False)))
    bare = static.residual_norm(without, static.loads(without, state.x, state.Q)) / scale
    assert bare < 1e-6 * measured


def cornered_rod(piece: str) -> Problem:
    """The states of the test above, at rest in their own shape."""
    import dataclasses

    from rodphase.rod.model import Contact
    from rodphase.scenes import measured_curvature

    n, a = 40, 0.02
    l0 = 0.95 * a
    corner = 20 if piece == "fold" else 2
    points = np.zeros((n + 1, 3))
    for i in range(n + 1):
        if piece == "fold":  # up along z, then along x
            points[i] = [0, 0, i * l0] if i <= corner else [(i - corner) * l0, 0, corner * l0]
        else:  # along x to 1.9 a, then down along -z beside the body
            points[i] = [i * l0, 0, 0] if i <= corner else [corner * l0, 0, -(i - corner) * l0]
    rod = Rod(length=n * l0, radius=a, elements=n)
    state = polyline_state(points)
    problem = Problem(rod=rod, state=state,
                      ends=dataclasses.replace(CANTILEVER, start_body=piece == "body"),
                      contact=Contact(enabled=True, fold=piece == "fold"),
                      force_scale=rod.buckling_force,
                      rest_curvature=measured_curvature(state.directors, np.full(n, l0)))
    return problem
