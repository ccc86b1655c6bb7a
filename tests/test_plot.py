"""Plots: each kind writes a non-empty image from synthetic data, or draws into a caller's
axes and writes nothing; it returns the figure; bad input is named."""

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

from rodphase import plot
from rodphase.result import HISTORY_COLUMNS, RunResult

PNG_MAGIC = b"\x89PNG"


def is_png(path):
    return path.exists() and path.stat().st_size > 1000 and path.read_bytes()[:4] == PNG_MAGIC


def writes_png(fig, path):
    """A figure function called with a path returns its Figure and writes that file."""
    return isinstance(fig, Figure) and is_png(path)


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
    fig = plot.phase_map(sweep_table(), tmp_path / "phase.png", experiments=experiments,
                         title="quick sweep")
    assert writes_png(fig, tmp_path / "phase.png")


def test_the_return_runs_holds_are_drawn_small_and_named(tmp_path):
    # rodphase boundaries --hysteresis stores the holds of its return runs (params `load`)
    # beside the runs that placed the lines: states reached by turning back, drawn small
    table = sweep_table().assign(load=[np.nan, np.nan, 0.0, 0.0, np.nan, np.nan])
    fig = plot.phase_map(table, tmp_path / "returns.png")
    ax = fig.axes[0]
    sizes = {tuple(c.get_offsets()[0]): c.get_sizes()[0] for c in ax.collections
             if len(c.get_offsets()) == 1 and len(c.get_sizes())}
    assert sizes[(1.02, 0.6)] > 2 * sizes[(1.2, 0.9)]  # a map run against a return hold
    labels = [t.get_text() for t in fig.legends[0].get_texts()] if fig.legends else \
        [t.get_text() for t in ax.get_legend().get_texts()]
    assert "small: turned back" in labels
    assert writes_png(fig, tmp_path / "returns.png")


def test_phase_map_all_straight_and_failed(tmp_path):
    table = pd.DataFrame({"twist_density": [0.0, 0.2, 0.4], "extension": [1.0, 1.1, 1.2],
                          "status": ["ok", "ok", "unstable"], "alignment": [np.nan] * 3,
                          "phase": ["straight", "straight", None]})
    assert writes_png(plot.phase_map(table, tmp_path / "straight.png"), tmp_path / "straight.png")


def test_phase_map_names_missing_columns(tmp_path):
    with pytest.raises(ValueError, match="extension"):
        plot.phase_map(pd.DataFrame({"twist_density": [0.1]}), tmp_path / "x.png")


def test_topology_curves(tmp_path):
    result = fake_result()
    assert writes_png(plot.topology_curves(result, tmp_path / "topo.png"), tmp_path / "topo.png")
    fig = plot.topology_curves(result.history, tmp_path / "topo2.png", rest_radius=0.025,
                               rest_length=1.0)
    assert writes_png(fig, tmp_path / "topo2.png")


def test_topology_curves_names_missing_keys(tmp_path):
    with pytest.raises(ValueError, match=r"link.*twist.*writhe"):
        plot.topology_curves(fake_result(topology=False), tmp_path / "topo.png")


def test_force_displacement(tmp_path):
    result = fake_result()
    assert writes_png(plot.force_displacement(result.history, tmp_path / "fd.png"),
                      tmp_path / "fd.png")
    history = {k: v for k, v in result.history.items() if k != "writhe"}
    assert writes_png(plot.force_displacement(history, tmp_path / "fd1.png", stage=1),
                      tmp_path / "fd1.png")


def test_shape_grid(tmp_path):
    straight = np.column_stack([np.zeros(41), np.zeros(41), np.linspace(0, 1.1, 41)])
    shapes = [("straight", straight, 0.025), ("solenoid", helix(turns=8), 0.02),
              ("tilted", helix() @ np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0.0]]), 0.025)]
    assert writes_png(plot.shape_grid(shapes, tmp_path / "shapes.png"), tmp_path / "shapes.png")


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
    assert isinstance(control_response(history, tmp_path / "r.png"), Figure)
    assert (tmp_path / "r.png").stat().st_size > 5_000
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
    assert writes_png(plot.hat_curve(result, tmp_path / "hat.png"), tmp_path / "hat.png")
    # the escape markers of the Lk/Tw/Wr plot
    result = fake_result(rows=24)
    result.history["link_escapes"] = (np.arange(24) >= 12).astype(float)
    result.history["link"] = result.history["link"] - 2 * result.history["link_escapes"]
    assert writes_png(plot.topology_curves(result, tmp_path / "escape.png"),
                      tmp_path / "escape.png")


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
    fig = plot.phase_path({"pull": table}, tmp_path / "path.png", background=sweep_table())
    assert writes_png(fig, tmp_path / "path.png")


# --------------------------------------------------------------------------- into given axes


@pytest.fixture
def no_files(tmp_path, monkeypatch):
    """Run in an empty folder and fail on any save: drawing into axes writes nothing."""
    monkeypatch.chdir(tmp_path)

    def refuse(*args, **kwargs):
        raise AssertionError("a plot given axes and no path must not save")

    monkeypatch.setattr(Figure, "savefig", refuse)
    yield
    assert list(tmp_path.iterdir()) == []


def user_figure(nrows=1, ncols=2, **kwargs):
    fig = Figure(figsize=(8, 3), layout="constrained")
    return fig, fig.subplots(nrows, ncols, squeeze=False, **kwargs).ravel()


def points(ax):
    return sum(len(c.get_offsets()) for c in ax.collections)


def test_topology_curves_into_axes(no_files):
    fig, (left, right) = user_figure()
    out = plot.topology_curves(fake_result(), ax=right, title="run 3")
    assert out is fig and right in out.axes
    assert len(right.lines) == 4  # Lk, Tw, Wr and the zero line
    assert len(left.lines) == 0 and right.get_title() == "run 3"
    assert right.get_legend() is not None


def test_phase_map_into_axes(no_files):
    fig, (left, right) = user_figure()
    out = plot.phase_map(sweep_table(), ax=left)
    assert out is fig
    # 4 classified ok runs, 1 creeping run drawn by its shape ("?") and with a dot, 1 failed
    assert points(left) == 4 + 1 + 1 + 1
    assert len(out.axes) == 3  # the two panels and the colour bar
    assert left.get_legend() is not None and not out.legends  # the legend stays in its axes
    assert points(right) == 0


def test_phase_path_into_axes(no_files):
    from rodphase.tabulate import path_table

    fig, (ax, _) = user_figure()
    table = path_table(fake_result(rows=12), every=2)
    out = plot.phase_path({"pull": table, "twist": table}, ax=ax)
    assert out is fig and len(ax.lines) == 2
    assert points(ax) == 2 * len(table)


def test_force_displacement_into_axes(no_files):
    fig, (ax, _) = user_figure()
    out = plot.force_displacement(fake_result().history, ax=ax)
    assert out is fig and len(ax.lines) == 1
    assert len(out.axes) == 3  # writhe on a twin of ax
    twin = [a for a in out.axes if a is not ax and a.get_shared_x_axes().joined(a, ax)]
    assert len(twin) == 1 and len(twin[0].lines) == 1


def test_control_response_into_axes(no_files):
    t = np.linspace(0, 1, 30)
    history = {"radius_factor": np.r_[np.ones(5), np.linspace(1, 2, 25)],
               "end_displacement": -0.01 * t, "writhe": 0.2 * t, "twist": -0.3 * t}
    fig, (ax, _) = user_figure()
    out = plot.control_response(history, ax=ax)
    assert out is fig and len(ax.lines) == 1 and len(out.axes) == 3
    # from the last row before the control moves: rows 5..29 (row 5 is the ramp's 1.0)
    assert len(ax.lines[0].get_xdata()) == 25


def test_hat_curve_into_axes(no_files):
    result = fake_result(rows=24)
    h = result.history
    turns = np.repeat([0.0, 1.0, -1.0, 0.0], 6)
    h["end_rotation"] = 2 * np.pi * turns
    h["stage"] = np.repeat(np.arange(4), 6)
    h["applied_force"] = np.full(24, 75.0)
    h["end_torque"] = np.tanh(turns)
    result.diagnostics.update(youngs_modulus=1e6, stages=[{"label": s} for s in
                                                         ("load", "up", "down", "back")])
    fig, (top, bottom) = user_figure(nrows=2, ncols=1)
    out = plot.hat_curve(result, axes=(top, bottom))
    assert out is fig and len(out.axes) == 2
    assert len(top.lines) == 3  # up, down, back (not the load stage)
    assert len(bottom.lines) == 3 + 4  # the branches and ± two buckling moments


def test_shape_grid_into_axes(no_files):
    fig = Figure(figsize=(6, 3))
    axes = [fig.add_subplot(1, 2, k + 1, projection="3d") for k in range(2)]
    out = plot.shape_grid([("a", helix(), 0.025), ("b", helix(turns=8), 0.02)], axes=axes)
    assert out is fig and len(out.axes) == 2
    for ax, label in zip(axes, "ab"):
        assert ax.get_title() == label
        (tube,) = ax.collections
        assert len(tube.get_edgecolor()) == 40  # one coloured segment per element
    with pytest.raises(ValueError, match="2 axes for 1 rods"):
        plot.shape_grid([("a", helix(), 0.025)], axes=axes)


def test_given_axes_and_path_saves_the_callers_figure(tmp_path):
    fig, (ax, _) = user_figure()
    out = plot.topology_curves(fake_result(), tmp_path / "both.png", ax=ax)
    assert out is fig and writes_png(out, tmp_path / "both.png")


def test_figure_in_a_subfigure_returns_the_top_figure(no_files):
    fig = Figure(figsize=(8, 3))
    ax = fig.subfigures(1, 2)[1].add_subplot()
    assert plot.topology_curves(fake_result(), ax=ax) is fig


def test_a_failed_run_is_drawn_where_it_was_sampled_in_either_twist_reading(no_files):
    # an `error` run has no classified Φa; it must still appear (a black cross) at the Φa
    # and L/L0 it was sampled at, also in the stretched-rod reading (it was dropped there)
    table = sweep_table().assign(phi_a_current=lambda t: t.twist_density / t.extension**1.5)
    table.loc[4, ["status", "phi_a_current"]] = ["error", np.nan]
    for twist, expected in (("twist_density", 0.7), ("phi_a_current", 0.7 / 1.1**1.5)):
        fig = plot.phase_map(table, twist=twist)
        crosses = [c for c in fig.axes[0].collections
                   if c.get_offsets().shape[0] == 1 and c.get_facecolor().size
                   and np.allclose(c.get_offsets()[0], [1.1, expected])]
        assert crosses, twist
        legend = [t.get_text() for t in fig.legends[0].get_texts()]
        assert "failed (1 error)" in legend and "not converged (1)" in legend


def test_the_failed_legend_counts_each_way_of_failing(no_files):
    # a guard's stop (unstable) and an exception (error) are different stories for a reader
    table = sweep_table()
    table.loc[[1, 2], "status"] = "unstable"
    table.loc[4, "status"] = "error"
    legend = [t.get_text() for t in plot.phase_map(table).legends[0].get_texts()]
    assert "failed (1 error, 2 unstable)" in legend, legend


def test_phase_map_caption_and_journal_sizes(no_files):
    config = {"scene": {"scene": "twist_under_load", "rod": {"elements": 64, "length": 1.0,
                                                             "radius": 0.025},
                        "material": {"youngs_modulus": 1e6, "incompressible": True},
                        "loading": {"twist_rate": 1.0, "force_multiple": None},
                        "solver": {"hold_max_time": 8.0, "hold_tolerance": 1e-3,
                                   "damping": 20.0}},
              "sweep": {"axes": {"twist_density": [0, 2.4], "extension": [1, 1.3]},
                        "sampler": "random", "samples": 6, "seed": 1}}
    caption = plot.sweep_caption(config, sweep_table())
    assert "64 elements" in caption and "6 random samples" in caption
    assert "4 ok" in caption and "1 unstable" in caption and "F_C" not in caption
    fig = plot.phase_map(sweep_table(), caption=caption, size="column")
    assert tuple(fig.get_size_inches()) == plot.SIZES["column"]
    assert "64 elements" in fig._supxlabel.get_text()
    with pytest.raises(ValueError, match="column"):
        plot.phase_map(sweep_table(), size="poster")


def test_stages_are_shaded_and_a_flat_writhe_is_not_magnified(no_files):
    result = fake_result(rows=12)  # stages 0 and 1 both turn the end: two bands
    result.diagnostics["stages"] = [{"label": "twist 0"}, {"label": "twist 1"}]
    fig = plot.topology_curves(result)
    texts = {t.get_text() for t in fig.axes[0].texts}
    assert {"twist 0", "twist 1"} <= texts and len(fig.axes[0].patches) == 1
    history = dict(fake_result().history, writhe=np.full(12, 1e-13) * np.arange(12))
    twin = plot.force_displacement(history).axes[1]
    assert twin.get_ylim()[1] - twin.get_ylim()[0] == pytest.approx(1.0)


def test_vtk_export_holds_the_rod_its_radius_and_arc_length(tmp_path):
    from rodphase.export import node_radii, write_vtk, write_vtk_series

    positions, radii = helix(n=10), np.linspace(0.02, 0.03, 10)
    text = write_vtk(tmp_path / "rod.vtk", positions, radii).read_text().splitlines()
    start = text.index("POINTS 11 double") + 1
    np.testing.assert_allclose(np.loadtxt(text[start:start + 11]), positions, rtol=1e-9)
    assert text[text.index("LINES 1 12") + 1] == "11 " + " ".join(map(str, range(11)))
    start = text.index("SCALARS radius double 1") + 2
    np.testing.assert_allclose(np.array(text[start:start + 11], float), node_radii(radii))
    assert node_radii(radii)[0] == 0.02 and node_radii(radii)[-1] == 0.03
    start = text.index("SCALARS arc_length double 1") + 2
    arc = np.array(text[start:start + 11], float)
    assert arc[0] == 0.0 and arc[-1] == 1.0 and np.all(np.diff(arc) > 0)
    files = write_vtk_series(tmp_path / "frames" / "rod", np.stack([positions] * 3), radii)
    assert [f.name for f in files] == ["rod_0000.vtk", "rod_0001.vtk", "rod_0002.vtk"]
    with pytest.raises(ValueError, match="element radii"):
        write_vtk(tmp_path / "bad.vtk", positions, radii[:5])


def test_movie_frames_say_time_and_twist_density(tmp_path):
    frames = np.stack([helix(turns=t) for t in range(3)])
    out = plot.movie(frames, 0.025, tmp_path / "rod.gif", fps=5, times=np.arange(3) * 0.5,
                     twist_density=np.array([0.0, 0.4, 0.8]), height=1.5)
    from PIL import Image

    with Image.open(out) as gif:
        assert gif.n_frames == 3 and gif.size[1] == pytest.approx(1.5 * 150, abs=2)


def _known_boundary(seed=0, samples=2000):
    # points at ten bin centres between L/L0 1.0 and 1.3 (within a bin a sloped line would
    # blur the bracket), a straight point at each end of the range (the bin edges), random
    # Φa: straight below Φa_c = 2·L/L0 − 1, a plectoneme above
    rng = np.random.default_rng(seed)
    ext = np.r_[1.0, 1.3, rng.choice(1.015 + 0.03 * np.arange(10), samples)]
    phi = np.r_[0.0, 0.0, rng.uniform(0.0, 2.6, samples)]
    return pd.DataFrame({"extension": ext, "phi_a_rest": phi, "status": "ok",
                         "alignment": np.where(phi < 2 * ext - 1, np.nan, -0.9),
                         "phase": np.where(phi < 2 * ext - 1, "straight", "plectoneme")})


def test_the_critical_twist_of_a_known_boundary_and_its_fit():
    from rodphase.tabulate import critical_twist

    points = critical_twist(_known_boundary(), "phi_a_rest")
    assert len(points) == 10
    # 200 random Φa per bin over [0, 2.6]: the bracket is ~0.03 wide, its midpoint on the line
    assert np.allclose(points["critical"], 2 * points["extension"] - 1, atol=0.05)
    slope, intercept, r2, used, above = points.attrs["fit"]
    assert used == 7 and above == 1.1
    assert slope == pytest.approx(2.0, abs=0.1) and intercept == pytest.approx(-1.0, abs=0.1)
    assert r2 > 0.99
    # a bin where a straight run lies above a buckled one brackets nothing and is left out
    overshoot = pd.concat([_known_boundary(), pd.DataFrame(
        {"extension": [1.015], "phi_a_rest": [2.5], "status": "ok", "alignment": [np.nan],
         "phase": ["straight"]})], ignore_index=True)
    assert len(critical_twist(overshoot, "phi_a_rest")) == 9
    # fewer than three bins above 1.1: points but no fit
    assert critical_twist(_known_boundary(), "phi_a_rest", above=1.25).attrs["fit"] is None


def test_the_phase_map_draws_traced_boundaries_and_a_legend_that_fits(no_files):
    # a boundaries table (boundaries.lines' columns): the plectoneme-solenoid line with its
    # brackets as a band, the triple point with its error bars; the legend's columns are as
    # many as fit across the figure, so that no entry is cut at its edges
    table = _known_boundary(samples=100)
    lines = pd.DataFrame({
        "kind": ["plectoneme_solenoid", "plectoneme_solenoid", "triple_point"],
        "extension": [1.12, 1.11, 1.13], "twist_density": [2.0, 2.4, 1.9],
        "extension_low": [1.115, 1.105, 1.12], "extension_high": [1.125, 1.115, 1.14],
        "twist_density_low": [2.0, 2.4, 1.85], "twist_density_high": [2.0, 2.4, 1.95]})
    fig = plot.phase_map(table, twist="phi_a_rest", lines=lines)
    legend = fig.legends[0]
    assert {"plectoneme–solenoid, traced", "triple point"} <= {t.get_text() for t in
                                                              legend.get_texts()}
    traced = [line for line in fig.axes[0].get_lines()
              if line.get_label() == "plectoneme–solenoid, traced"][0]
    assert list(traced.get_ydata()) == [2.0, 2.4]  # in twist order
    fig.canvas.draw()
    box = legend.get_window_extent()
    width = fig.get_window_extent().width
    assert box.x0 >= 0 and box.x1 <= width
    assert plot.legend_columns(["a" * 60] * 6, 5.6, 9) == 1
    assert plot.legend_columns(["short"] * 6, 5.6, 9) == 4