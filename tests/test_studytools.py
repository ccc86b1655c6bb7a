"""The helpers the scripts of benchmarks/ and studies/ share (rodphase/studytools.py)."""

import numpy as np
import pandas as pd

from rodphase.studytools import boundary_error, machine, same_points, write_block


def test_write_block_replaces_only_its_own_block(tmp_path):
    doc = tmp_path / "doc.md"
    doc.write_text("intro\n<!-- a:begin -->\nold a\n<!-- a:end -->\nmiddle\n"
                   "<!-- b:begin -->\nold b\n<!-- b:end -->\nend\n")
    write_block(doc, "a", "new a\n| 1 |")
    assert doc.read_text() == ("intro\n<!-- a:begin -->\nnew a\n| 1 |\n<!-- a:end -->\nmiddle\n"
                               "<!-- b:begin -->\nold b\n<!-- b:end -->\nend\n")


def test_write_block_appends_a_block_the_file_lacks_and_creates_the_file(tmp_path):
    doc = tmp_path / "new.md"
    write_block(doc, "c", "table")
    write_block(doc, "c", "table 2")
    assert doc.read_text() == "\n<!-- c:begin -->\ntable 2\n<!-- c:end -->\n"


def test_same_points_compares_the_first_rows_on_the_shared_axes():
    a = pd.DataFrame({"twist_density": [0.1, 0.2, 0.3], "extension": [1.0, 1.1, 1.2]})
    b = pd.DataFrame({"twist_density": [0.1, 0.2], "extension": [1.0, 1.1]})
    assert same_points(a, b) and same_points(b, a)
    assert same_points(a, b[["twist_density"]])
    assert not same_points(a, b.assign(extension=[1.0, 1.2]))


def test_machine_names_the_cores_and_the_load():
    m = machine()
    assert m["nproc"] >= 1 and len(m["load"]) == 3 and m["cpu"]


def test_boundary_error_is_the_share_of_reference_points_the_nearest_sample_gets_wrong():
    # a boundary at x = 0.5: the samples put it at x = 0.75 (their midpoint), so the
    # reference points at x = 0.6 and 0.7 (2 of 5) are called straight; a failed sample
    # nearer to them is not used
    reference = pd.DataFrame({"x": [0.1, 0.3, 0.6, 0.7, 0.9], "y": 0.0,
                              "phase": ["straight"] * 2 + ["plectoneme"] * 3})
    samples = pd.DataFrame({"x": [0.5, 1.0, 0.65], "y": 0.0,
                            "phase": ["straight", "plectoneme", "failed"]})
    error = boundary_error(reference, samples, ("x", "y"), np.zeros(2), np.ones(2))
    assert error == 2 / 5
