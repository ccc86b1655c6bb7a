"""A rod's shape at twice the elements (rodphase.resample.doubled), and a refined run that goes
on from a second before its trip instead of from the start (solver.refine_from: trip).

The resampled rod must be the same rod: the old nodes kept, the new ones on a smooth curve
through them, frames orthonormal with d3 on the tangent, and the link of a twisted helix
carried over (the twist about the centreline is what a refined run must not lose). A run
refined from its trip must do the same protocol as one refined from the start: the same turns
put in, its link accounted for, time running on without a gap, and the same final shape.
"""

import numpy as np
import pytest

from rodphase import api
from rodphase.resample import doubled
from rodphase.runner import run_scene
from rodphase.scenes import helix_state
from rodphase.topology import topology_history

A = 0.025


@pytest.fixture(scope="module")
def helix():
    # 3 loops of radius 3a, pitch 2.5a, with 20 rad/m of the fibre's own twist
    return helix_state(3 * A, 2.5 * A, 3.0, 60, 1, 20.0)


def test_the_old_nodes_stay_and_the_new_ones_lie_on_the_curve(helix):
    x, d, _ = helix
    nodes, directors = doubled(x, d[:, 0])
    assert nodes.shape == (121, 3) and directors.shape == (120, 3, 3)
    assert np.array_equal(nodes[0::2], x)
    # the new nodes are on the helix (radius 3a about the z axis through x = -3a) to the
    # spline's error: against the chord's midpoint, which is 3a·(1 - cos(θ/2)) inside (θ the
    # angle about the axis per element), measured 1/500 of that inside, 1/50 at the ends
    radial = np.hypot(nodes[1::2, 0] + 3 * A, nodes[1::2, 1])
    theta = np.arctan2(x[1, 1], x[1, 0] + 3 * A)
    sagitta = 3 * A * (1 - np.cos(theta / 2))
    assert np.max(np.abs(radial - 3 * A)) < 0.05 * sagitta
    assert np.max(np.abs(radial - 3 * A)[5:-5]) < 0.005 * sagitta
    # and the rod turns evenly: old and new nodes alike (within 3 %: the spline's ends)
    t = np.diff(nodes, axis=0)
    t /= np.linalg.norm(t, axis=1)[:, None]
    turn = np.arccos(np.clip(np.sum(t[1:] * t[:-1], axis=1), -1, 1))
    assert np.ptp(turn[5:-5]) < 0.03 * np.mean(turn)


def test_frames_are_orthonormal_unsheared_and_keep_the_link(helix):
    x, d, _ = helix
    nodes, directors = doubled(x, d[:, 0])
    assert np.allclose(np.einsum("nij,nkj->nik", directors, directors), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(directors), 1.0)
    t = np.diff(nodes, axis=0)
    t /= np.linalg.norm(t, axis=1)[:, None]
    assert np.allclose(directors[:, 2], t, atol=1e-12)
    before = topology_history(x[None], d[None, :, 0])
    after = topology_history(nodes[None], directors[None, :, 0])
    # Lk = 7.07 turns; the interpolation moves it by 6e-5 (measured)
    assert after[0][0] == pytest.approx(before[0][0], abs=1e-3)


def test_a_sheared_frame_is_straightened_onto_the_tangent(helix):
    x, d, _ = helix
    tilted = d[:, 0] + 0.4 * d[:, 2]  # d1 with a tangential part, as in a sheared element
    _, directors = doubled(x, tilted)
    t = np.diff(doubled(x, d[:, 0])[0], axis=0)
    t /= np.linalg.norm(t, axis=1)[:, None]
    assert np.allclose(np.sum(directors[:, 0] * t, axis=1), 0.0, atol=1e-12)
    assert np.allclose(directors, doubled(x, d[:, 0])[1], atol=1e-12)


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="n >= 2"):
        doubled(np.zeros((3, 3)), np.zeros((3, 3)))


@pytest.fixture(scope="module")
def refined_pair():
    # Φa = 1.2 on 12 elements at 1 turn/s: 4 rad of twist per element in the end, so the
    # 135° resolution guard stops the run part way through its twist (at t = 5.2 s); refined
    # to 24 elements it completes
    overrides = {"rod.elements": 12, "loading.twist_density": 1.2, "loading.twist_rate": 1.0,
                 "solver.hold_until": "time", "solver.hold_max_time": 0.5,
                 "solver.refine_up_to": 48}
    trip = run_scene(api.load("twist_under_load", overrides))
    start = run_scene(api.load("twist_under_load", {**overrides,
                                                    "solver.refine_from": "start"}))
    return trip, start


def test_a_run_refined_from_its_trip_does_the_same_protocol(refined_pair):
    trip, start = refined_pair
    assert trip.status == start.status == "ok", trip.message
    assert trip.diagnostics["refined_from"] == start.diagnostics["refined_from"]
    assert trip.diagnostics["elements"] == 24 and trip.positions.shape == (25, 3)
    assert trip.diagnostics["refined_at"] > 0
    assert "refined_at" not in start.diagnostics
    # the history runs on without going back, over the same protocol
    time = trip.history["time"]
    assert np.all(np.diff(time) > 0)
    assert time[-1] == pytest.approx(start.history["time"][-1], abs=0.15)
    assert trip.history["end_rotation"][-1] == pytest.approx(start.history["end_rotation"][-1])
    # the link is the turns put in, and the escapes, across the resampling (else the run is
    # not ok: guard link); both runs lose the same 2 turns around an end after it
    turns = trip.history["end_rotation"] / (2 * np.pi)
    row = np.searchsorted(time, trip.diagnostics["refined_at"])
    assert np.max(np.abs(trip.history["link"] - turns)[: row + 5]) < 0.05
    assert trip.history["link_escapes"][-1] == start.history["link_escapes"][-1]
    # and cheaper: the steps before the resume point were taken at the coarser resolution
    assert trip.diagnostics["steps"] < start.diagnostics["steps"]


def test_a_run_refined_from_its_trip_ends_on_the_same_shape(refined_pair):
    trip, start = refined_pair
    # the same extension and writhe (the runs differ by the resampled start, which the twist
    # ramp and the hold damp: measured 2e-5 m and 5e-5 turns; 1e-3 of L0 and of a turn)
    assert trip.history["end_displacement"][-1] == pytest.approx(
        start.history["end_displacement"][-1], abs=1e-3)
    assert trip.history["writhe"][-1] == pytest.approx(start.history["writhe"][-1], abs=1e-3)
    assert trip.history["link"][-1] == pytest.approx(start.history["link"][-1], abs=1e-3)
