"""Sleeping contact (contact.sleep): until the rod first touches itself or an end body, the run
takes the larger time step of a rod without contact; from the step of that touch on, contact
is awake with its own step.

What must hold, each checked against a run that does not sleep:
- a rod that never touches itself is computed exactly as a rod without contact (same steps,
  bit-identical positions): sleeping adds nothing to the physics;
- a rod that does touch itself wakes at its first touch, misses none (the largest overlap
  is that of the run awake from the start), and ends on the same shape (link, writhe,
  phase), with one report per stage although the stage it woke in ran in two pieces;
- a rod that starts in contact wakes at its first step and runs as if awake from the start.
"""

import numpy as np
import pytest

from rodphase import api
from rodphase.classify import alignment, phase
from rodphase.rod import Contact, Problem, Rod, Stage, simulate
from rodphase.rod.model import state_from
from rodphase.runner import run_scene
from rodphase.scenes import helix_state

A = 0.025  # m, the paper's rod radius


def _run(overrides):
    return run_scene(api.load("twist_under_load", overrides), topology=True)


def test_a_rod_that_never_touches_itself_runs_as_a_rod_without_contact():
    # Φa 0.3 at 25 F_C stays straight: contact never wakes
    base = {"rod.elements": 24, "loading.twist_density": 0.3, "solver.hold_max_time": 1.0}
    asleep = _run(base)
    without = _run({**base, "physics.self_contact": False})
    awake = _run({**base, "contact.sleep": False})
    assert asleep.diagnostics["contact_woke_at"] is None
    assert asleep.diagnostics["dt_asleep"] == without.diagnostics["dt"]
    assert asleep.diagnostics["dt_asleep"] > 1.2 * awake.diagnostics["dt"]
    assert asleep.diagnostics["steps"] == without.diagnostics["steps"]
    assert np.array_equal(asleep.positions, without.positions)
    assert np.array_equal(asleep.directors, without.directors)


@pytest.fixture(scope="module")
def plectoneme_pair():
    # Φa 1.2 at 5 F_C: the rod buckles in the twist ramp and braids; 40 elements, 2 s hold
    base = {"rod.elements": 40, "loading.twist_density": 1.2, "loading.force_multiple": 5,
            "solver.hold_max_time": 2.0}
    return _run(base), _run({**base, "contact.sleep": False})


def test_sleeping_contact_wakes_at_the_first_touch_and_misses_none(plectoneme_pair):
    asleep, awake = plectoneme_pair
    woke = asleep.diagnostics["contact_woke_at"]
    assert woke is not None
    # the run awake from the start first touches within the history interval (0.1 s) before
    # its first row with a touching pair; the runs differ by their steps before it (dt 1.9x
    # larger asleep at n = 40), so the touch may come a little earlier or later (measured:
    # woke at 7.309 s, the awake run's first touching row at 7.300 s)
    first_touch = awake.history["time"][np.argmax(awake.history["contacts"] > 0)]
    assert first_touch - 0.2 <= woke <= first_touch + 0.1
    assert np.all(asleep.history["contacts"][asleep.history["time"] < woke] == 0)
    # a missed touch would grow unopposed until contact woke: the largest overlap would
    # exceed the awake run's
    assert asleep.diagnostics["max_penetration"] <= 1.05 * awake.diagnostics["max_penetration"]
    # the twist stage ran in two pieces (asleep, awake) and is reported once, with both
    assert [s["label"] for s in asleep.diagnostics["stages"]] == ["load", "twist 0", "hold 0"]
    assert sum(s["steps"] for s in asleep.diagnostics["stages"]) == asleep.diagnostics["steps"]


def test_sleeping_contact_ends_on_the_same_plectoneme(plectoneme_pair):
    asleep, awake = plectoneme_pair
    assert asleep.status == awake.status
    # the turns put in are the same, and the holds settle on the same equilibrium; the runs
    # differ by the time-step error of the part before contact, which the hold damps out
    # (measured: 1.3e-4 turns of link, 5e-7 of writhe of
    # 3.33 turns); 1e-3 leaves room for another machine's round-off
    assert asleep.history["link"][-1] == pytest.approx(awake.history["link"][-1], abs=1e-3)
    assert asleep.history["writhe"][-1] == pytest.approx(awake.history["writhe"][-1], abs=1e-3)
    labels = [phase(alignment(r.positions, A, 1.0)) for r in (asleep, awake)]
    assert labels == ["plectoneme", "plectoneme"]
    assert asleep.diagnostics["steps"] < awake.diagnostics["steps"]


def test_a_rod_that_starts_in_contact_wakes_at_its_first_step():
    # a close-wound helix, turns 1.9 radii apart along its axis: pressed together from the start
    n = 60
    x, d, length = helix_state(4 * A, 1.9 * A, 3.0, n, 1, 0.0)
    rod = Rod(length=length, radius=A, elements=n)

    def problem(sleep):
        return Problem(rod=rod, state=state_from(x, d), stages=(Stage(0.01),),
                       contact=Contact(enabled=True, sleep=sleep))

    asleep = simulate(problem(True))
    awake = simulate(problem(False))
    assert asleep.diagnostics["contact_woke_at"] == 0.0
    assert asleep.diagnostics["steps"] == awake.diagnostics["steps"]
    # the state is handed back through half a drift and its undoing: round-off only
    assert np.allclose(asleep.positions, awake.positions, rtol=0, atol=1e-12)
