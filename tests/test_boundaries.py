"""Boundaries as lines (issue #45): the onset from the model's static stability, the
plectoneme–solenoid boundary by bracketing with runs, the triple point between them."""

import math

import numpy as np
import pandas as pd
import pytest
import yaml
from click.testing import CliRunner

import rodphase
from rodphase import boundaries as B
from rodphase.cli import main


def level(probes, low=1.0, high=1.3, twist=2.0):
    lv = B.Level(0, twist, low, high)
    lv.probes.update(probes)
    return lv


# ---------------------------------------------------------------- bracketing, pure

def test_a_level_bisects_between_its_last_plectoneme_and_first_solenoid():
    lv = level({1.0: "plectoneme", 1.3: "solenoid"})
    assert lv.has_boundary() is True and lv.bracket() == (1.0, 1.3)
    assert lv.next_probe(0.005) == pytest.approx(1.15)
    lv.probes[1.15] = "solenoid"
    assert lv.bracket() == (1.0, 1.15) and lv.next_probe(0.005) == pytest.approx(1.075)
    lv.probes[1.075] = "plectoneme"
    row = lv.row()
    assert (row["extension_low"], row["extension_high"]) == (1.075, 1.15)
    assert row["extension"] == pytest.approx(1.1125) and row["note"] == ""
    assert lv.next_probe(0.1) is None  # narrower than the tolerance: done
    # with workers to spare, the widest gap is split in more parts in one round
    wide = level({1.0: "plectoneme", 1.3: "solenoid"})
    assert wide.next_probes(0.005, 2) == pytest.approx([1.1, 1.2])
    assert wide.next_probes(0.5, 2) == []


def test_a_mixed_run_counts_on_the_plectoneme_side_and_widens_the_band():
    # near the triple point the runs below the first solenoid are often mixed: the boundary
    # is where solenoids begin, and the mixed runs under it are its band
    lv = level({1.0: "plectoneme", 1.3: "solenoid", 1.15: "mixed"})
    assert lv.bracket() == (1.15, 1.3) and lv.next_probe(0.01) == pytest.approx(1.225)
    lv.probes.update({1.225: "mixed", 1.26: "solenoid"})
    row = lv.row()
    assert (row["extension_low"], row["extension_high"]) == (1.225, 1.26)
    assert row["mixed_width"] == pytest.approx(1.26 - 1.15) and "2 mixed" in row["note"]
    # a level whose low end is already mixed (high twist, no load) still brackets
    assert level({1.0: "mixed", 1.3: "solenoid"}).has_boundary() is True


def test_a_failed_probe_is_stepped_around_and_counted():
    lv = level({1.0: "plectoneme", 1.3: "solenoid", 1.15: "failed"})
    assert lv.next_probe(0.01) == pytest.approx(1.225)  # equal sides: the upper one
    lv.probes[1.225] = "solenoid"
    assert lv.next_probe(0.01) == pytest.approx(1.075)  # (1.0, 1.15) is now the widest gap
    assert lv.row()["failed"] == 1 and "failed" in lv.row()["note"]
    # where the model fails (Fig 3's corner) a bracket holding three failed runs is left as
    # it is, and its row says so, instead of spending runs on failures
    corner = level({1.0: "plectoneme", 1.3: "solenoid", 1.1: "failed", 1.15: "failed",
                    1.2: "failed"})
    assert corner.next_probe(0.01) is None
    assert "left this wide" in corner.row()["note"] and corner.row()["failed"] == 3


def test_a_solenoid_below_a_plectoneme_is_flagged_not_hidden():
    lv = level({1.0: "plectoneme", 1.05: "solenoid", 1.1: "plectoneme", 1.3: "solenoid"})
    row = lv.row()
    assert row["non_monotone"] and "solenoid below a plectoneme" in row["note"]


def test_a_level_without_a_boundary_and_the_triple_point_between_levels():
    below = level({1.0: "plectoneme", 1.1: "mixed"}, high=1.1, twist=1.5)
    above = level({1.0: "plectoneme", 1.2: "solenoid"}, high=1.2, twist=2.0)
    unknown = level({1.0: "plectoneme", 1.3: "failed"}, twist=1.7)
    assert below.has_boundary() is False and above.has_boundary() is True
    assert unknown.has_boundary() is None and level({1.0: "plectoneme"}).has_boundary() is None
    assert B.triple_gap([above, below, unknown]) == (below, above)
    assert B.triple_gap([above]) is None


def test_a_level_starts_in_its_middle_and_searches_only_as_far_as_it_must():
    # no guess: the middle first; the top (the last extension to buckle) only without a
    # solenoid, the box's lowest extension (the slowest runs) only if the halving reaches it
    lv = level({})
    assert lv.first_probes(0.01) == [pytest.approx(1.15)]
    lv.probes[1.15] = "plectoneme"
    assert lv.next_probe(0.01) == 1.3 and lv.has_boundary() is None
    lv.probes[1.3] = "plectoneme"
    assert lv.has_boundary() is False and lv.next_probe(0.01) is None
    lv = level({1.15: "solenoid"})
    assert lv.has_boundary() is True and lv.next_probe(0.01) == pytest.approx(1.075)
    lv = level({1.008: "solenoid"})
    assert lv.next_probe(0.01) == 1.0  # within half a tolerance of the lowest: that one
    assert level({1.0: "solenoid"}).next_probe(0.01) is None  # below the box: nothing to find
    # a top that failed (the model's corner) is stepped under, towards the highest plectoneme
    lv = level({1.15: "plectoneme", 1.3: "failed"})
    assert lv.next_probe(0.01) == pytest.approx(1.225) and lv.has_boundary() is None


def test_a_neighbours_boundary_is_tried_first_and_steps_widen_from_it():
    lv = level({}, twist=1.6)
    lv.guess = 1.137
    assert lv.first_probes(0.01) == pytest.approx([1.127, 1.147])
    lv.probes.update({1.127: "solenoid", 1.147: "solenoid"})
    assert lv.next_probe(0.01) == pytest.approx(1.127 - 0.04)  # twice as far each time
    # inside a wide bracket the guess is tried half a tolerance either side
    wide = level({1.0: "plectoneme", 1.3: "solenoid"}, twist=1.6)
    wide.guess = 1.137
    assert wide.next_probes(0.01, 2) == pytest.approx([1.132, 1.142])
    # guide hands the nearest finished level's boundary to the open ones
    done = level({1.135: "plectoneme", 1.14: "solenoid"}, twist=2.0)
    far = level({1.2: "plectoneme", 1.28: "solenoid"}, twist=2.4)
    open_ = level({1.0: "plectoneme", 1.3: "solenoid"}, twist=1.7)
    B.guide([far, done, open_], 0.01)
    assert open_.guess == pytest.approx(1.1375) and done.guess is None


def lines_table():
    onset = pd.DataFrame({"kind": "onset", "extension": [1.0, 1.1, 1.2, 1.3],
                          "twist_density": [0.2, 1.0, 1.5, 2.0]})
    ps = pd.DataFrame({"kind": "plectoneme_solenoid", "extension": [1.13, 1.14],
                       "twist_density": [1.4, 2.4]})
    tp = pd.DataFrame({"kind": ["triple_point"], "extension": [1.14], "twist_density": [1.2]})
    return pd.concat([onset, ps, tp], ignore_index=True)


def test_the_lines_predict_the_label_of_any_point():
    table = lines_table()
    twist = np.array([0.5, 0.9, 1.1, 2.0, 2.0, 1.2, 2.4])
    extension = np.array([1.2, 1.05, 1.05, 1.12, 1.16, 1.15, 1.139])
    assert list(B.predict_phase(table, twist, extension)) == [
        "straight",    # below the onset
        "plectoneme",  # above the onset, below the triple point's twist
        "plectoneme",
        "plectoneme",  # under the boundary (1.135 at 2.0)
        "solenoid",    # over it
        "straight",    # 1.2 < the onset at 1.15 (1.25)
        "plectoneme"]  # just under the boundary's end point, held beyond it
    only_onset = table[table["kind"] == "onset"]
    assert list(B.predict_phase(only_onset, [0.1, 2.0], [1.05, 1.2])) == ["straight", "plectoneme"]


def returns(phases, twists, extension=1.1, load=0):
    return pd.DataFrame({"load": float(load), "step": np.arange(len(phases), dtype=float),
                         "extension": extension, "twist_density": twists, "phase": phases})


def test_the_twist_of_restraightening_is_bracketed_by_the_return_holds():
    twists = [1.05, 0.975, 0.95, 0.925, 0.9]
    table = pd.concat([
        returns(["plectoneme", "plectoneme", "solenoid", "straight", "straight"], twists),
        returns(["plectoneme", "mixed", "plectoneme", "solenoid", "solenoid"], twists, load=1),
        returns(["straight", "straight", "straight", "straight", "straight"], twists, load=2),
        returns(["plectoneme", "failed", "straight", "straight", "straight"], twists, load=3)])
    rows = {int(k): r for k, r in enumerate(B.restraighten_rows(table))}
    assert (rows[0]["twist_density_low"], rows[0]["twist_density_high"]) == (0.925, 0.95)
    assert rows[0]["twist_density"] == pytest.approx(0.9375) and rows[0]["note"] == ""
    assert rows[1]["twist_density_high"] == 0.9 and "still buckled" in rows[1]["note"]
    assert np.isnan(rows[2]["twist_density"]) and "did not buckle" in rows[2]["note"]
    assert np.isnan(rows[3]["twist_density"]) and "failed" in rows[3]["note"]
    assert all(r["kind"] == "restraighten" for r in rows.values())
    assert B.restraighten_rows(table.drop(columns="load")) == []
    # a tight coil the classifier reads as straight still writhes: buckled
    coil = returns(["straight", "straight", "straight"], [1.05, 0.9, 0.8])
    coil["writhe"] = [2.5, 1.2, 0.0005]
    (row,) = B.restraighten_rows(coil)
    assert (row["twist_density_low"], row["twist_density_high"]) == (0.8, 0.9)


def test_the_return_runs_twist_past_the_onset_then_back_in_holds():
    settings = B.Settings(hysteresis_loads=2, hysteresis_step=0.1)
    assert B.return_twists(1.0, settings) == pytest.approx(
        [1.05, 0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3])
    sweep, scene = B.sweep_for_boundaries("fig3_paper", [("rod.element_length", 1.0)])
    onset = pd.DataFrame({"kind": "onset", "extension": [1.0, 1.3],
                          "twist_density": [0.2, 2.0]})
    jobs = B.hysteresis_jobs(sweep, scene, onset, settings)
    assert [job.params[0]["extension"] for job in jobs] == pytest.approx([1.075, 1.225])
    first = jobs[0]
    assert first.twist_targets[0] > first.twist_targets[1] > first.twist_targets[-1] > 0
    assert len(set(first.run_ids)) == len(first.run_ids) == 8
    assert all(p["load"] == 0 and p["step"] == k for k, p in enumerate(first.params))


# ---------------------------------------------------------------- the onset line, static

@pytest.mark.slow  # long: 31 s of CPU (62 s wall at load 4 on 2 cores)
def test_the_onset_line_is_the_models_own_stability_to_its_tolerance():
    from rodphase.rod.onset import StraightBranch
    from rodphase.scenes import rod_from

    sweep, scene = B.sweep_for_boundaries("fig3_paper", [("rod.element_length", 1.0)])
    settings = B.Settings(onset_points=5)
    onset = B.onset_line(scene, sweep, settings)
    assert list(onset["extension"]) == pytest.approx([1.0, 1.075, 1.15, 1.225, 1.3])
    to_turns = scene.rod.length / (2 * math.pi * scene.rod.radius)
    rod = rod_from(scene)
    for row in onset.iloc[1:].itertuples():
        branch = StraightBranch(rod, row.extension)
        # the target: the line to ±0.5 % in Phi*a against the model's own stability
        assert branch.stable(0.995 * row.twist_density * to_turns)
        assert not branch.stable(1.005 * row.twist_density * to_turns)
        assert row.greenhill_sheared >= row.twist_density  # the n -> inf limit lies above
    assert B.onset_extension(onset, 0.0) == 1.0 and B.onset_extension(onset, 99.0) == math.inf


def test_only_onset_answers_from_the_cli_and_writes_the_csv(tmp_path):
    csv = tmp_path / "onset.csv"
    result = CliRunner().invoke(main, ["boundaries", "fig3_paper", "-o", str(tmp_path / "x.h5"),
                                       "--only", "onset", "--csv", str(csv),
                                       "--set", "rod.element_length=1.0"])
    assert result.exit_code == 0, result.output
    assert "onset at high extension: Phi*a_c = (" in result.output
    table = pd.read_csv(csv)
    for column in ("kind", "extension", "twist_density", "extension_low", "extension_high",
                   "twist_density_low", "twist_density_high"):
        assert column in table
    assert set(table["kind"]) == {"onset"} and len(table) == 41
    assert not (tmp_path / "x.h5").exists()  # the onset alone stores nothing


def sweep_yaml(tmp_path, axes, scene="twist_under_load", name="box.yaml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump({"sweep": {"scene": scene, "axes": axes,
                                              "set": {"rod.elements": 40}}}))
    return path


@pytest.mark.parametrize("axes, words", [
    ({"twist_density": [0.0, 0.1], "extension": [1.05, 1.3]}, "reaches the straight rod's onset"),
    ({"force_multiple": [10, 50], "twist_density": [0.5, 2.0]}, "twist_density and extension"),
    ({"extension": [1.05, 1.3]}, "twist_density and extension"),
])
def test_a_box_the_method_cannot_trace_is_refused_in_one_line(tmp_path, axes, words):
    result = CliRunner().invoke(main, ["boundaries", str(sweep_yaml(tmp_path, axes)), "-o",
                                       str(tmp_path / "x.h5")])
    assert result.exit_code == 2, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and words in errors[0]
    assert not (tmp_path / "x.h5").exists()


def test_sweep_refuses_the_boundaries_sampler_and_bad_settings_are_named(tmp_path):
    path = sweep_yaml(tmp_path, {"twist_density": [0.5, 2.0], "extension": [1.05, 1.3]})
    result = CliRunner().invoke(main, ["sweep", str(path), "-o", str(tmp_path / "x.h5"),
                                       "--set", "sweep.sampler=boundaries"])
    assert result.exit_code == 2 and "rodphase boundaries" in result.output
    result = CliRunner().invoke(main, ["boundaries", str(path), "-o", str(tmp_path / "x.h5"),
                                       "--tolerance", "0"])
    assert result.exit_code == 2 and "sweep.boundary.tolerance" in result.output
    # finer than the onset's band (where a label depends on the push): refused before a run
    result = CliRunner().invoke(main, ["boundaries", str(path), "-o", str(tmp_path / "x.h5"),
                                       "--tolerance", "2e-4"])
    assert result.exit_code == 2 and "onset's band" in result.output, result.output
    assert not (tmp_path / "x.h5").exists()
    result = CliRunner().invoke(main, ["boundaries", str(path), "-o", str(tmp_path / "x.h5"),
                                       "--only", "onset", "--hysteresis"])
    assert result.exit_code == 2 and "--hysteresis" in result.output


# ---------------------------------------------------------------- a whole trace, small

SMALL = {"tolerance": 0.04, "levels": 2, "twist_tolerance": 0.5, "hysteresis_loads": 1,
         "hysteresis_step": 0.1}


def small_box(tmp_path):
    # the demo's protocol at 40 elements, two levels and a coarse bracket
    path = tmp_path / "lines.yaml"
    path.write_text(yaml.safe_dump({"sweep": {
        "scene": "twist_under_load",
        "set": {"rod.element_length": 1.0, "loading.quasi_static_below": 0.8,
                "loading.twist_rate": 1.0, "solver.hold_max_time": 8},
        "axes": {"twist_density": [0.0, 2.2], "extension": [1.03, 1.25]},
        "boundary": SMALL}}))
    return path


@pytest.mark.slow
def test_a_small_trace_finds_a_boundary_stores_its_runs_and_resumes(tmp_path):
    # every run it places is an ordinary stored run, the table is kept in the store, and
    # the same call again launches nothing and gives the same lines
    sweep, scene = B.sweep_for_boundaries(small_box(tmp_path), [])
    out = str(tmp_path / "lines.h5")
    first = B.trace(sweep, scene, out, jobs=2, echo=lambda text: None, hysteresis=True)
    kinds = set(first.table["kind"])
    assert {"onset", "restraighten"} <= kinds
    # turned back, the rod comes straight below its onset (straight and buckled coexist
    # between): the bracket is one return step wide
    (back,) = first.table[first.table["kind"] == "restraighten"].itertuples()
    onset = first.table[first.table["kind"] == "onset"]
    critical = np.interp(back.extension, onset["extension"], onset["twist_density"])
    assert back.twist_density_low < back.twist_density < back.twist_density_high < critical
    assert back.twist_density_high - back.twist_density_low == pytest.approx(0.1 * critical)
    with rodphase.open(out) as store:
        stored = store.boundaries()
        runs = store.table()
    assert stored is not None and len(stored) == len(first.table)
    assert {"level", "step", "twist_density", "extension"} <= set(runs.columns)
    returns = first.hysteresis_report
    assert (first.report.done + first.report.failed + returns.done + returns.failed
            == len(runs) > 0)
    again = B.trace(sweep, scene, out, jobs=2, echo=lambda text: None, hysteresis=True)
    assert again.report.skipped == again.report.total
    assert again.hysteresis_report.skipped == again.hysteresis_report.total
    assert again.report.total + again.hysteresis_report.total == len(runs)
    pd.testing.assert_frame_equal(again.table, first.table)
    ps = first.table[first.table["kind"] == "plectoneme_solenoid"]
    assert np.all(ps["extension_high"] - ps["extension_low"] <= 0.04 + 1e-12)


@pytest.mark.slow  # long: two small traces and a kill (~25 s on 2 cores)
def test_a_trace_killed_with_sigkill_resumes_to_the_same_lines(tmp_path):
    from killing import kill_after_runs  # tests/killing.py

    box = small_box(tmp_path)
    whole = B.trace(*B.sweep_for_boundaries(box, []), str(tmp_path / "whole.h5"), jobs=2,
                    echo=lambda text: None)
    killed = tmp_path / "killed.h5"
    # killed once the first round is in the file, workers and all
    finished = kill_after_runs(["boundaries", box, "-o", killed, "--jobs", 2, "--quiet"],
                               killed, 2)
    if len(finished) == whole.report.total:
        pytest.skip("the trace finished before it could be killed")
    again = B.trace(*B.sweep_for_boundaries(box, []), str(killed), jobs=2,
                    echo=lambda text: None)
    assert again.report.skipped >= len(finished) > 0  # every finished run reused
    assert again.report.total == whole.report.total
    pd.testing.assert_frame_equal(again.table, whole.table)


@pytest.mark.slow  # long: ~35 s on 2 cores
def test_another_filaments_boundaries_follow_from_its_rod_alone(tmp_path):
    # a thicker rod with a softer shear (a = 0.02 m, G = 0.5 MPa, L/L0 up to 1.25): nothing
    # set but the rod; its resolution (auto: 100 elements), onset, bracketing and classifier
    # follow from the scene. Its lines are its own: the onset rises faster than the paper
    # rod's (the softer shear lowers the twist stiffness less than the bending's share), and
    # a plectoneme-solenoid boundary and a triple point are found in its box
    sweep, scene = B.sweep_for_boundaries(
        "fig3_paper", [("rod.radius", 0.02), ("material.shear_modulus", 5e5),
                       ("sweep.axes.extension", [1.0, 1.25])],
        {"tolerance": 0.02, "levels": 4, "twist_tolerance": 0.3})
    assert scene.rod.elements == 100
    found = B.trace(sweep, scene, str(tmp_path / "other.h5"), jobs=2, echo=lambda text: None)
    ps = found.table[found.table["kind"] == "plectoneme_solenoid"]
    assert len(ps) >= 1 and np.all(ps["extension_high"] - ps["extension_low"] <= 0.02 + 1e-12)
    assert (found.table["kind"] == "triple_point").sum() == 1
    assert found.claims["onset_slope"] > 5.5  # the paper's rod: 5.16


def test_another_filaments_onset_line_follows_its_own_rod():
    # half the radius: auto takes 160 elements, and the line is that rod's, within a few
    # tenths of a percent of its sheared Greenhill twist (the model's n -> inf limit). In
    # the paper's units it nearly coincides with the paper's rod's: for a long rod
    # Phi*a_c = 2 sqrt(B T) a / C depends on the extension alone (B, T, C ~ a^4, a^2, a^4);
    # the thin rod's lies a little lower (0.3 %), the clamps' finite-length share smaller
    settings = B.Settings(onset_points=3)
    thin_sweep, thin = B.sweep_for_boundaries("fig3_paper", [("rod.radius", 0.0125)])
    assert thin.rod.elements == 160
    line = B.onset_line(thin, thin_sweep, settings).iloc[1:]
    assert np.allclose(line["twist_density"], line["greenhill_sheared"], rtol=0.01)
    assert np.all(line["twist_density"] <= line["greenhill_sheared"])
    paper_sweep, paper = B.sweep_for_boundaries("fig3_paper")
    paper_line = B.onset_line(paper, paper_sweep, settings).iloc[1:]
    assert np.allclose(line["twist_density"], paper_line["twist_density"], rtol=0.01)
    assert np.all(line["twist_density"] < paper_line["twist_density"])


def test_the_same_from_python():
    table = rodphase.trace_boundaries("fig3_paper", only_onset=True, progress=False,
                                       rod__element_length=1.0)
    assert set(table["kind"]) == {"onset"} and len(table) == 41
    claims = table.attrs["claims"]
    assert claims["onset_slope"] > 0 and claims["onset_slope_error"] < 0.1 * claims["onset_slope"]
    with pytest.raises(rodphase.config.ConfigError, match="output"):
        rodphase.trace_boundaries("fig3_paper", progress=False)
    with pytest.raises(rodphase.config.ConfigError, match="hysteresis"):
        rodphase.trace_boundaries("fig3_paper", only_onset=True, hysteresis=True)
