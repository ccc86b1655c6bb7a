"""A stored-looking run for tests of the store, the summaries and the CLI around them."""

import numpy as np

from rodphase.result import HISTORY_COLUMNS, RunResult


def fake_run(status="ok", n=8, rows=6, seed=0) -> RunResult:
    """A stored-looking run of a straight rod along z (nothing simulated)."""
    rng = np.random.default_rng(seed)
    history = {name: rng.normal(size=rows) for name in HISTORY_COLUMNS}
    history["time"] = np.linspace(0.0, 1.0, rows)
    history["stage"] = np.zeros(rows)
    for key in ("link", "twist", "writhe"):
        history[key] = rng.normal(size=rows)
    positions = np.zeros((n + 1, 3))
    positions[:, 2] = np.linspace(0.0, 1.05, n + 1)
    return RunResult(
        status=status, message="completed" if status == "ok" else "unstable at t = 1 s",
        positions=positions, directors=np.tile(np.eye(3), (n, 1, 1)), radii=np.full(n, 0.025),
        rest_lengths=np.full(n, 1.0 / n), history=history,
        snapshot_positions=positions[None].copy(), snapshot_d1=np.tile([1.0, 0, 0], (1, n, 1)),
        snapshot_rows=np.array([rows - 1]),
        diagnostics={"steps": 100, "wall_time": 0.1, "rest_radius": 0.025, "rest_length": 1.0,
                     "youngs_modulus": 1e6, "elements": n, "notes": [],
                     "stages": [{"label": "hold 0"}]},
        stage_ends=[rows - 1])
