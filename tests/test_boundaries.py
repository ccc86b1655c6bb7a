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


# ---------------------------------------------------------------- a whole trace, small

@pytest.mark.slow
def test_a_small_trace_finds_a_boundary_stores_its_runs_and_resumes(tmp_path):
    # the demo's protocol at 40 elements, two levels and a coarse bracket: every run it
    # places is an ordinary stored run, the table is kept in the store, and the same call
    # again launches nothing and gives the same lines
    path = tmp_path / "lines.yaml"
    path.write_text(yaml.safe_dump({"sweep": {
        "scene": "twist_under_load",
        "set": {"rod.element_length": 1.0, "loading.quasi_static_below": 0.8,
                "loading.twist_rate": 1.0, "solver.hold_max_time": 8},
        "axes": {"twist_density": [0.0, 2.2], "extension": [1.03, 1.25]}}}))
    sweep, scene = B.sweep_for_boundaries(path, [], {"tolerance": 0.04, "levels": 2,
                                                     "twist_tolerance": 0.5})
    out = str(tmp_path / "lines.h5")
    first = B.trace(sweep, scene, out, jobs=2, echo=lambda text: None)
    kinds = set(first.table["kind"])
    assert "onset" in kinds
    with rodphase.open(out) as store:
        stored = store.boundaries()
        runs = store.table()
    assert stored is not None and len(stored) == len(first.table)
    assert {"level", "step", "twist_density", "extension"} <= set(runs.columns)
    assert first.report.done + first.report.failed == len(runs) > 0
    again = B.trace(sweep, scene, out, jobs=2, echo=lambda text: None)
    assert again.report.skipped == again.report.total == len(runs)
    pd.testing.assert_frame_equal(again.table, first.table)
    ps = first.table[first.table["kind"] == "plectoneme_solenoid"]
    assert np.all(ps["extension_high"] - ps["extension_low"] <= 0.04 + 1e-12)


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
