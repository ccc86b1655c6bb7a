"""Plots: each kind writes a non-empty image from synthetic data; bad input is named."""

import numpy as np
import pandas as pd
import pytest

from rodphase import plot
from rodphase.result import HISTORY_COLUMNS, RunResult

PNG_MAGIC = b"\x89PNG"


def is_png(path):
    return path.exists() and path.stat().st_size > 1000 and path.read_bytes()[:4] == PNG_MAGIC


def helix(n=40, turns=3.0, radius=0.05, length=1.0):
    s = np.linspace(0, 1, n + 1)
    angle = 2 * np.pi * turns * s
    return np.column_stack([radius * np.cos(angle), radius * np.sin(angle), length * s])


def fake_result(rows=12, topology=True):
    history = {name: np.linspace(0, 1, rows) for name in HISTORY_COLUMNS}
    history["end_rotation"] = np.linspace(0, 2 * np.pi * 6, rows)
    history["stage"] = np.arange(rows) // 6
    if topology:
        history["link"] = history["end_rotation"] / (2 * np.pi)
        history["writhe"] = np.clip(history["link"] - 3, 0, None)
        history["twist"] = history["link"] - history["writhe"]
    positions = helix()
    return RunResult(status="ok", message="completed", positions=positions,
                     directors=np.tile(np.eye(3), (40, 1, 1)), radii=np.full(40, 0.025),
                     rest_lengths=np.full(40, 1 / 40), history=history,
                     snapshot_positions=np.stack([helix(turns=t) for t in range(rows)]),
                     snapshot_d1=np.zeros((rows, 40, 3)),
                     diagnostics={"rest_radius": 0.025, "rest_length": 1.0})


def sweep_table():
    return pd.DataFrame({
        "run_id": ["a", "b", "c", "d", "e", "f"],
        "twist_density": [0.1, 0.6, 0.9, 1.2, 0.7, 1.4],
        "extension": [1.05, 1.02, 1.2, 1.15, 1.1, 1.25],
        "status": ["ok", "ok", "ok", "ok", "unstable", "not_converged"],
        "alignment": [np.nan, -0.9, 0.95, 0.1, np.nan, np.nan],
        "phase": ["straight", "plectoneme", "solenoid", "mixed", None, None],
    })


def test_phase_map(tmp_path):
    experiments = pd.DataFrame({"twist_density": [0.5, 0.9], "extension": [1.05, 1.2],
                                "kind": ["plectoneme", "solenoid"]})
    out = plot.phase_map(sweep_table(), tmp_path / "phase.png", experiments=experiments,
                         title="quick sweep")
    assert is_png(out)


def test_phase_map_all_straight_and_failed(tmp_path):
    table = pd.DataFrame({"twist_density": [0.0, 0.2, 0.4], "extension": [1.0, 1.1, 1.2],
                          "status": ["ok", "ok", "unstable"], "alignment": [np.nan] * 3,
                          "phase": ["straight", "straight", None]})
    assert is_png(plot.phase_map(table, tmp_path / "straight.png"))


def test_phase_map_names_missing_columns(tmp_path):
    with pytest.raises(ValueError, match="extension"):
        plot.phase_map(pd.DataFrame({"twist_density": [0.1]}), tmp_path / "x.png")


def test_topology_curves(tmp_path):
    result = fake_result()
    assert is_png(plot.topology_curves(result, tmp_path / "topo.png"))
    assert is_png(plot.topology_curves(result.history, tmp_path / "topo2.png",
                                       rest_radius=0.025, rest_length=1.0))


def test_topology_curves_names_missing_keys(tmp_path):
    with pytest.raises(ValueError, match=r"link.*twist.*writhe"):
        plot.topology_curves(fake_result(topology=False), tmp_path / "topo.png")


def test_force_displacement(tmp_path):
    result = fake_result()
    assert is_png(plot.force_displacement(result.history, tmp_path / "fd.png"))
    history = {k: v for k, v in result.history.items() if k != "writhe"}
    assert is_png(plot.force_displacement(history, tmp_path / "fd1.png", stage=1))


def test_shape_grid(tmp_path):
    straight = np.column_stack([np.zeros(41), np.zeros(41), np.linspace(0, 1.1, 41)])
    shapes = [("straight", straight, 0.025), ("solenoid", helix(turns=8), 0.02),
              ("tilted", helix() @ np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0.0]]), 0.025)]
    assert is_png(plot.shape_grid(shapes, tmp_path / "shapes.png"))


def test_movie_gif(tmp_path):
    frames = np.stack([helix(turns=t) for t in np.linspace(0, 3, 5)])
    out = plot.movie(frames, 0.025, tmp_path / "rod.gif", fps=5, times=np.arange(5) * 0.5)
    assert out.suffix == ".gif" and out.read_bytes()[:3] == b"GIF"


def test_movie_falls_back_to_gif_without_ffmpeg(tmp_path, monkeypatch):
    monkeypatch.setattr(plot.shutil, "which", lambda name: None)
    frames = np.stack([helix(turns=t) for t in np.linspace(0, 1, 3)])
    out = plot.movie(frames, 0.025, tmp_path / "rod.mp4")
    assert out == tmp_path / "rod.gif" and out.stat().st_size > 0


def test_control_response_draws_a_radius_ramp(tmp_path):
    from rodphase.plot import control_response

    t = np.linspace(0, 1, 30)
    history = {"radius_factor": np.r_[np.ones(5), np.linspace(1, 2, 25)],
               "stiffness_factor": np.ones(30), "end_displacement": -0.01 * t,
               "writhe": 0.2 * t, "twist": -0.3 * t}
    path = control_response(history, tmp_path / "r.png")
    assert path.stat().st_size > 5_000
    with pytest.raises(ValueError, match="neither"):
        control_response({"radius_factor": np.ones(3), "end_displacement": np.zeros(3)},
                         tmp_path / "x.png")


def test_hat_curve_draws_each_branch_and_marks_escapes(tmp_path):
    result = fake_result(rows=24)
    h = result.history
    turns = np.concatenate([np.zeros(6), np.linspace(0, 3, 6), np.linspace(3, -3, 6),
                            np.linspace(-3, 0, 6)])
    h["end_rotation"] = 2 * np.pi * turns
    h["stage"] = np.repeat(np.arange(4), 6)
    h["applied_force"] = np.full(24, 75.0)
    h["end_torque"] = np.tanh(turns)
    h["end_displacement"] = -0.01 * turns**2
    result.diagnostics.update(youngs_modulus=1e6, stages=[{"label": s} for s in
                                                         ("load", "up", "down", "back")])
    assert is_png(plot.hat_curve(result, tmp_path / "hat.png"))
    # the escape markers of the Lk/Tw/Wr plot
    result = fake_result(rows=24)
    result.history["link_escapes"] = (np.arange(24) >= 12).astype(float)
    result.history["link"] = result.history["link"] - 2 * result.history["link_escapes"]
    assert is_png(plot.topology_curves(result, tmp_path / "escape.png"))


def test_phase_path_draws_a_protocol_through_the_map(tmp_path):
    from rodphase.tabulate import path_table

    result = fake_result(rows=12)
    result.diagnostics.update(rest_radius=0.025, rest_length=1.0)
    table = path_table(result, every=2)
    assert len(table) == 6 and set(table.columns) >= {"extension", "twist_density", "phase"}
    # Φa = (end - start rotation)·a0/L0 row by row
    h = result.history
    expected = (h["end_rotation"] - h["start_rotation"])[::2] * 0.025
    assert np.allclose(table["twist_density"], expected)
    assert is_png(plot.phase_path({"pull": table}, tmp_path / "path.png",
                                  background=sweep_table()))
