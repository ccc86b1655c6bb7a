"""The straight rod's onset from the model's own stiffness (rod/onset.py, rod/static.py).

Checked against the clamped Greenhill twist in its limit (unshearable, inextensible, n → ∞,
with the convergence order of the discretisation), against an independent static solve of
the paper's rod (issue #32), against the eigenvalues of the whole non-symmetric stiffness,
and for the symmetries it must have.
"""

import math

import numpy as np
import pandas as pd
import pytest

from rodphase.rod import kernel as k
from rodphase.rod import onset, static
from rodphase.rod.model import Rod
from rodphase.rod.simulate import static_model_of
from rodphase.theory import greenhill_clamped_moment, straight_rod_buckling_turns

E, A0, L0 = 1.0e6, 0.025, 1.0


def paper_rod(n: int) -> Rod:
    return Rod(length=L0, radius=A0, elements=n)


def stiff_rod(n: int, factor: float = 1e4) -> Rod:
    """The paper's rod made unshearable and inextensible by `factor` (compressible: the plain
    quadratic law, so that the stretch does not thin it)."""
    base = paper_rod(n)
    return Rod(length=L0, radius=A0, elements=n, incompressible=False,
               shear_stiffness_given=factor * base.shear_stiffness,
               axial_stiffness_given=factor * base.axial_stiffness)


def greenhill_turns(rod: Rod, tension: float) -> float:
    e = 1.0 + tension / rod.axial_stiffness
    moment = greenhill_clamped_moment(tension, e * L0, rod.bending_stiffness)
    return moment * e * L0 / rod.twist_stiffness / (2 * math.pi)


def test_the_onset_converges_to_the_clamped_greenhill_twist_at_second_order():
    # T = 25 F_C on a rod 1e4 times stiffer in shear and stretch than the paper's: the
    # clamped Greenhill twist is its n → ∞ limit. Measured errors -0.86 %, -0.21 %, -0.054 %
    # at n = 20, 40, 80: second order (the centred differences of the rod), slope 2 ± 0.1,
    # and the n = 80 error under 0.1 % (the shear and stretch left at 1e-4 move it ~1e-5).
    tension = 25 * math.pi**2 * paper_rod(20).bending_stiffness / L0**2
    errors = []
    for n in (20, 40, 80):
        rod = stiff_rod(n)
        e = 1.0 + tension / rod.axial_stiffness
        errors.append(abs(onset.straight_onset_turns(rod, e) / greenhill_turns(rod, tension) - 1))
    slope = np.polyfit(np.log([20, 40, 80]), np.log(errors), 1)[0]
    assert slope == pytest.approx(-2.0, abs=0.1)
    assert errors[-1] < 1e-3


def test_the_paper_rod_buckles_below_the_unsheared_greenhill_twist():
    # Issue #32's independent Newton solve on this project's force routines: 8.4345 turns at
    # L/L0 = 1.15, n = 80 (5 digits quoted), and 0.973 / 0.922 / 0.854 of the unsheared clamped
    # Greenhill twist at L/L0 = 1.05 / 1.15 / 1.30 (3 digits quoted). Shear lowers it.
    rod = paper_rod(80)
    assert onset.straight_onset_turns(rod, 1.15) == pytest.approx(8.4345, abs=6e-5)
    for e, ratio in ((1.05, 0.973), (1.15, 0.922), (1.30, 0.854)):
        force = rod.axial_stiffness * (1 - 1 / e)
        greenhill = straight_rod_buckling_turns(force, E, 2 * E / 3, A0, L0)
        assert onset.straight_onset_turns(rod, e) / greenhill == pytest.approx(ratio, abs=6e-4)


def test_resolution_moves_the_paper_rods_onset_by_little():
    # the same rod at 80 and 160 elements: 0.22 % apart (issue #32 measured 0.2 %)
    assert onset.straight_onset_turns(paper_rod(160), 1.15) == pytest.approx(
        onset.straight_onset_turns(paper_rod(80), 1.15), rel=3e-3)


def test_the_lateral_test_agrees_with_the_eigenvalues_of_the_whole_stiffness():
    # The onset is where the lateral block's symmetric part stops being positive definite. The
    # whole non-symmetric stiffness must agree: every eigenvalue of M⁻¹K has a positive real
    # part at 0.999 of it, and a pair (the two helical modes, together) is negative at 1.001.
    rod = paper_rod(40)
    branch = onset.StraightBranch(rod, 1.15)
    critical = branch.onset_turns()
    for factor, growing in ((0.999, 0), (1.001, 2)):
        problem = branch.problem(factor * critical)
        model = static_model_of(problem)
        verdict = static.stability(model, problem.state.x, problem.state.Q)
        assert verdict.unstable_modes == growing
        assert verdict.stable == (growing == 0)
    assert branch.lowest(0.99 * critical) > 0 > branch.lowest(1.01 * critical)


def test_the_straight_twisted_rod_is_an_equilibrium_and_its_mirror_buckles_alike():
    rod = paper_rod(30)
    branch = onset.StraightBranch(rod, 1.2)
    problem = branch.problem(3.0)
    model = static_model_of(problem)
    loads = static.loads(model, problem.state.x, problem.state.Q)
    # the uniform state is the discrete equilibrium to round-off: the axial force is E·A0·
    # (1 − 1/e) ~ 400 N, its round-off ~1e-13 of it
    assert np.abs(loads).max() < 1e-9 * rod.axial_stiffness
    # turning the other way is the mirror image: the same onset to the bisection's 1e-6
    critical = branch.onset_turns()
    assert branch.stable(-0.999 * critical) and not branch.stable(-1.001 * critical)


def test_the_coloured_stiffness_is_the_dense_one():
    # columns taken REACH + 1 blocks apart at once must give exactly the one-at-a-time matrix
    rod = paper_rod(16)
    problem = onset.StraightBranch(rod, 1.1).problem(1.5)
    rng = np.random.default_rng(3)
    problem.state.x[:2, 1:-1] += 1e-3 * rng.standard_normal((2, rod.elements - 1))
    model = static_model_of(problem)
    coloured = static.stiffness_matrix(model, problem.state.x, problem.state.Q)
    dense = static.stiffness_matrix(model, problem.state.x, problem.state.Q, dense=True)
    assert np.array_equal(coloured, dense)


def test_the_neo_hookean_straight_branch_balances_its_twist_and_buckles_as_its_eigenvalues_say():
    # The conservative law's twisted rod lengthens under a fixed load (its twist energy
    # GJ0·Φ²/(2e) falls as it stretches: the Poynting effect of twisted wires, which the
    # paper's law lacks), so its straight branch is found at another stretch: there the loads
    # vanish, and the lateral test agrees with the whole stiffness's eigenvalues as for the
    # paper's law. Its onset lies below the paper law's (measured -1.1 % at L/L0 = 1.001 and
    # -18 % at 1.15, where it has lengthened to 1.31 L0 at the onset).
    neo = Rod(length=L0, radius=A0, elements=30, law="neo_hookean")
    branch = onset.StraightBranch(neo, 1.15)
    critical = branch.onset_turns()
    for factor, growing in ((0.999, 0), (1.001, 2)):
        problem = branch.problem(factor * critical)
        model = static_model_of(problem)
        model = static.StaticModel(**{**model.__dict__, "now": branch.model.now.copy()})
        model.now[k.T_END_ROTATION] = 2 * math.pi * factor * critical
        assert np.abs(static.loads(model, problem.state.x, problem.state.Q)).max() < 1e-8
        assert problem.state.x[2, -1] > 1.2 * L0  # lengthened by its twist
        assert static.stability(model, problem.state.x, problem.state.Q).unstable_modes == growing
    assert critical < onset.straight_onset_turns(paper_rod(30), 1.15)


def _hold_near_the_onset(factor: float, static_stability: bool):
    from rodphase import config as C
    from rodphase import runner
    from rodphase.scenes import SCENES, build, rod_from

    base = [("rod.elements", 40), ("loading.force_multiple", None), ("loading.extension", 1.15),
            ("loading.twist_density", None), ("loading.quasi_static_below", 0.9)]
    cfg = C.load_scene("twist_under_load", base, SCENES)
    turns = factor * onset.straight_onset_turns(rod_from(cfg), 1.15)
    cfg = C.load_scene("twist_under_load", base + [("loading.twist_turns", turns),
                                                   ("solver.static_stability", static_stability)],
                       SCENES)
    result = runner.run(build(cfg), topology=True)
    assert result.status == "ok", result.message
    return result, result.diagnostics["stages"][-1]


def test_a_hold_just_past_the_onset_does_not_end_on_the_unstable_straight_rod():
    # At 1.006 of the model's onset (n = 40, L/L0 = 1.15) the unstable pair grows over
    # seconds and the probe's three sine modes do not see it: without the static test the hold
    # ends straight (the defect of issue #32, measured Wr 0.0); with it the candidate is found
    # unstable, pushed along its growing mode, and the rod snaps into a coil (measured
    # Wr 1.447 turns). Below the onset (0.98) the test passes the straight rod.
    blind, _ = _hold_near_the_onset(1.006, static_stability=False)
    assert abs(blind.history["writhe"][-1]) < 0.01
    seen, report = _hold_near_the_onset(1.006, static_stability=True)
    assert report["static_unstable"] >= 1
    assert abs(seen.history["writhe"][-1]) > 1.0
    assert any("unstable by the model's stiffness" in note for note in seen.diagnostics["notes"])
    below, report = _hold_near_the_onset(0.98, static_stability=True)
    assert (report["static_tests"], report["static_unstable"]) == (1, 0)
    assert abs(below.history["writhe"][-1]) < 0.01


def test_the_phase_maps_onset_lines_are_the_models_and_greenhills():
    # the lines `rodphase plot --kind phase` draws, from a store's resolved scene config: the
    # model's onset at the scene's resolution, the sheared Greenhill line just above it (the
    # model's n → ∞ limit: measured 0.3 % / 1.2 % above at n = 40) and the unsheared one above
    # both, in rest Φa
    from rodphase import config as C
    from rodphase import plot as P
    from rodphase.scenes import SCENES
    from rodphase.tabulate import onset_lines

    scene = C.load_scene("twist_under_load", [("rod.elements", 40)], SCENES).plain()
    lines = onset_lines({"scene": scene}, [1.05, 1.15])
    turns = onset.straight_onset_turns(paper_rod(40), 1.15, tolerance=1e-4)
    assert lines["model_rest"].iloc[1] == pytest.approx(turns * 2 * math.pi * A0 / L0, rel=2e-4)
    assert (lines["greenhill_rest"] > lines["sheared_rest"]).all()
    assert (lines["sheared_rest"] > lines["model_rest"]).all()
    assert lines["sheared_rest"].iloc[1] == pytest.approx(
        onset.sheared_greenhill_turns(paper_rod(40), 1.15) * 2 * math.pi * A0 / L0)
    assert lines["model_current"].iloc[1] == pytest.approx(lines["model_rest"].iloc[1] / 1.15**1.5)
    assert lines["sheared_current"].iloc[1] == pytest.approx(
        lines["sheared_rest"].iloc[1] / 1.15**1.5)
    # a rod not clamped at both ends under a load has no such line
    free = {**scene, "ends": {**scene["ends"], "end_rotation": "free"}}
    assert onset_lines({"scene": free}, [1.1]) is None
    table = pd.DataFrame({"extension": [1.05, 1.15], "twist_density": [0.5, 2.0],
                          "phase": ["straight", "solenoid"], "alignment": [np.nan, 1.0],
                          "status": ["ok", "ok"]})
    figure = P.phase_map(table, onset=lines)
    drawn = [line.get_label() for line in figure.axes[0].get_lines()]
    labels = ["onset, model n = 40", "Greenhill, sheared (analytic)", "Greenhill, unsheared"]
    assert drawn == labels
    # and the legend says which is which
    legend = [text.get_text() for text in figure.legends[0].get_texts()]
    assert set(labels) <= set(legend)


def test_the_onset_study_runs_small_and_writes_its_block(tmp_path):
    # studies/onset_study.py (make onset-study) at one extension: its table goes into the docs
    # block (n = 80: G = E/3 doubles the onset twist, which 40 elements cannot resolve)
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "studies"))
    import onset_study

    docs = tmp_path / "doc.md"
    docs.write_text("a\n<!-- onset_study:begin -->\nold\n<!-- onset_study:end -->\nb\n")
    assert onset_study.main(["--elements", "80", "--extensions", "1.3", "--write",
                             "--docs", str(docs), "--figure", str(tmp_path / "f.png")]) == 0
    text = docs.read_text()
    assert "old" not in text and "| 1.30 |" in text and (tmp_path / "f.png").exists()
    lines = onset_study.study(80, [1.3])
    # stiffer shear raises the onset towards Greenhill; G = E/3 raises it further
    paper = lines["paper (G = 2E/3)"][0]
    assert paper < lines["shear x 10"][0] < lines["shear x 100"][0] < lines["G = E/3"][0]


def test_an_under_resolved_rod_has_no_onset_and_says_why():
    # 16 elements at L/L0 = 1.3: the onset (13 turns at n = 80, the bracket 16.3) would turn
    # elements by ~310°, past the matrix log's branch cut: it says how many are needed
    with pytest.raises(ValueError, match="at least 37 elements"):
        onset.straight_onset_turns(paper_rod(16), 1.3)


def test_a_coarse_sweeps_map_leaves_out_the_onset_it_cannot_resolve():
    # 12 elements cannot resolve the onset at L/L0 = 1.3 (it needs 37): the line is left out
    # there, not the whole figure refused
    from rodphase import config as C
    from rodphase.scenes import SCENES
    from rodphase.tabulate import onset_lines

    scene = C.load_scene("twist_under_load", [("rod.elements", 12)], SCENES).plain()
    lines = onset_lines({"scene": scene}, [1.02, 1.3])
    assert np.isfinite(lines["model_rest"].iloc[0]) and np.isnan(lines["model_rest"].iloc[1])
    assert np.isfinite(lines["greenhill_rest"]).all()


def test_a_rod_compressed_past_euler_has_no_onset_and_says_so():
    # compressed to L/L0 = 0.99 (a plain quadratic rod: E·A0·0.01 = 19.6 N against the
    # clamped Euler load 4π²B/L² = 12.1 N) it buckles untwisted: refused, not looped on
    with pytest.raises(ValueError, match="unstable without twist"):
        onset.straight_onset_turns(Rod(length=L0, radius=A0, elements=20, incompressible=False),
                                   0.99)


def test_a_straight_start_with_given_stiffnesses_is_that_rods_equilibrium():
    # shear × 10 and half the twist stiffness (issue #29's shear study): the start is taken
    # below the onset of the rod with those stiffnesses (its onset, not the paper rod's: half
    # the twist stiffness nearly doubles the turns), on its straight equilibrium: held 0.5 s
    # it neither moves (< 1e-9 L0 at the nodes: round-off of the equilibrium) nor writhes.
    # A given axial stiffness is refused: the start stretches by the load's E·A0 extension.
    from rodphase import config as C
    from rodphase import runner
    from rodphase.scenes import SCENES, build, rod_from

    base_rod = paper_rod(40)
    base = [("rod.elements", 40), ("loading.force_multiple", None), ("loading.extension", 1.15),
            ("loading.twist_density", None), ("loading.quasi_static_below", 0.9),
            ("material.shear_stiffness", 10 * base_rod.shear_stiffness),
            ("material.twist_stiffness", 0.5 * base_rod.twist_stiffness),
            ("solver.hold_until", "time"), ("solver.hold_max_time", 0.5),
            ("rod.imperfection", 0.0)]  # the perfect rod: its straight state is exact
    rod = rod_from(C.load_scene("twist_under_load", base, SCENES))
    own = onset.straight_onset_turns(rod, 1.15, tolerance=1e-4)
    assert own > 1.5 * onset.straight_onset_turns(base_rod, 1.15, tolerance=1e-4)
    turns = 0.85 * own
    cfg = C.load_scene("twist_under_load", base + [("loading.twist_turns", turns)], SCENES)
    problem = build(cfg)
    start = problem.state.positions.copy()
    result = runner.run(problem, topology=True)
    assert result.status == "ok", result.message
    assert result.history["end_rotation"][0] == pytest.approx(turns * 2 * math.pi)
    assert np.abs(result.positions - start).max() < 1e-9 * L0
    assert abs(result.history["writhe"][-1]) < 1e-3
    with pytest.raises(C.ConfigError, match="material.axial_stiffness"):
        build(C.load_scene("twist_under_load", base + [("loading.twist_turns", turns),
                                                      ("material.axial_stiffness", 2000.0)],
                           SCENES))
