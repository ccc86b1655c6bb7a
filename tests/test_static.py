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
