"""rodphase against the stored PyElastica 1.0 run of the authors' SolenoidsCase example
(studies/crosscheck_pyelastica.py, docs/history/crosscheck.md)."""

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
REF = ROOT / "tests" / "data" / "crosscheck_solenoid.npz"
sys.path.insert(0, str(ROOT / "studies"))

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def runs():
    import crosscheck_pyelastica as cc

    from rodphase.runner import run

    sets = cc.rodphase_sets("solenoid", contact="example", dt="auto", rotation_damping="example")
    problem = cc.build_problem("solenoid", sets, twist="as-run", kick="load", reference=REF)
    return np.load(REF), run(problem, topology=True)


def test_solenoid_before_buckling_matches_reference(runs):
    ref, result = runs
    h = result.history
    x_end = result.snapshot_positions[:, -1, 2]            # rodphase's axis is z, PyElastica's y
    for t in (9.0, 30.0, 60.0):                            # loading, twisting, just before onset
        assert np.interp(t, h["time"], x_end) == pytest.approx(
            np.interp(t, ref["time"], ref["end_position"][:, 1]), abs=1e-6)
        assert np.interp(t, h["time"], h["link"]) == pytest.approx(
            np.interp(t, ref["time"], ref["link"]), abs=1e-3)
        assert abs(np.interp(t, h["time"], h["writhe"])) < 0.01


def onset(t, wr):
    """First time |Wr| exceeds half a turn."""
    return t[np.argmax(np.abs(wr) > 0.5)]


def test_solenoid_final_state_matches_reference(runs):
    from rodphase import classify

    ref, result = runs
    h = result.history
    assert result.status == "ok"
    assert h["link"][-1] == pytest.approx(ref["link"][-1], abs=0.01)     # 11 turns, none escaped
    for points in (result.positions, ref["final_positions"]):
        assert classify.phase(classify.alignment(points, 0.025, rest_length=1.0)) == "solenoid"
    # known gaps (docs/history/crosscheck.md): onset 2.4 s later, 0.9 turn more writhe
    assert abs(onset(h["time"], h["writhe"]) - onset(ref["time"], ref["writhe"])) < 4.0
    assert abs(h["writhe"][-1] - ref["writhe"][-1]) < 1.3


# ------------------------------------------------- PyElastica's contact loop, rewritten (issue #49)


def _contact_state(name, rng, jitter):
    x = np.load(ROOT / "tests" / "data" / f"crosscheck_{name}.npz")["final_positions"].T.copy()
    x = x + rng.normal(scale=jitter, size=x.shape)
    n = x.shape[1] - 1
    edges = np.diff(x, axis=1)
    lengths = np.linalg.norm(edges, axis=0)
    radius = np.sqrt(np.pi * 0.025**2 / n / lengths / np.pi)  # PyElastica's thinned radius
    return x, radius, lengths, edges / lengths, rng.normal(scale=1e-2, size=x.shape)


def test_rewritten_contact_loop_is_pyelasticas_bit_for_bit():
    # the study's scalar loop (thinning 0) against PyElastica 1.0's own, on touching
    # solenoids and plectonemes jittered by up to a sixth of the radius
    pytest.importorskip("elastica", reason="PyElastica is the bench extra (make bench-extra)")
    import crosscheck_pyelastica as cc
    from elastica._contact_functions import _calculate_contact_forces_self_rod

    rng = np.random.default_rng(49)
    for name in ("solenoid", "plectoneme"):
        for jitter in (0.0, 0.001, 0.004):
            x, radius, lengths, tangents, v = _contact_state(name, rng, jitter)
            theirs, ours = np.zeros_like(x), np.zeros_like(x)
            _calculate_contact_forces_self_rod(x[:, :-1], radius, lengths, tangents, v, theirs, 1e4, 10.0)
            cc.self_contact_with_thinning(x[:, :-1], radius, lengths, tangents, v, ours, 1e4, 10.0, 0.0)
            assert np.abs(theirs).max() > 1.0  # the state is in contact
            assert np.array_equal(ours, theirs), (name, jitter)


def test_thinning_term_is_internal_and_lengthens_the_touching_elements():
    import crosscheck_pyelastica as cc

    rng = np.random.default_rng(0)
    x, radius, lengths, tangents, v = _contact_state("solenoid", rng, 0.0)
    plain, thinned = np.zeros_like(x), np.zeros_like(x)
    cc.self_contact_with_thinning(x[:, :-1], radius, lengths, tangents, v, plain, 1e4, 10.0, 0.0)
    cc.self_contact_with_thinning(x[:, :-1], radius, lengths, tangents, v, thinned, 1e4, 10.0, 1.0)
    extra = thinned - plain
    assert np.abs(extra).max() > 1.0
    assert np.allclose(extra.sum(axis=1), 0.0, atol=1e-9)  # no net force
    # its power on the element lengths, Σ (f_{i+1} − f_i)·t_i, is positive: it stretches them
    assert np.sum((extra[:, 1:] - extra[:, :-1]) * tangents) > 0


def _contact_energy(cc, x, volume):
    """Σ ½ k γ² over PyElastica's pairs, the radii thinned from the element lengths."""
    edges = np.diff(x, axis=1)
    lengths = np.linalg.norm(edges, axis=0)
    radius = np.sqrt(volume / lengths / np.pi)
    n = len(lengths)
    energy = 0.0
    for i in range(n):
        skip = int(1 + np.ceil(0.8 * np.pi * radius[i] / lengths[i]))
        for j in range(i - skip, -1, -1):
            d = cc._closest(x[:, :-1], edges, i, j)[:3]
            gamma = radius[i] + radius[j] - np.linalg.norm(d)
            if gamma > 0:
                energy += 0.5 * 1e4 * gamma**2
    return energy


def test_split_and_thinning_make_the_spring_the_gradient_of_the_contact_energy():
    # rodphase's contact law: closest-point split + thinning = −∂(Σ ½kγ²)/∂x; PyElastica's
    # equal split without thinning is not (that is what the SolenoidsCase rows compare)
    import crosscheck_pyelastica as cc

    rng = np.random.default_rng(1)
    x, radius, lengths, tangents, _ = _contact_state("solenoid", rng, 0.0)
    volume = np.pi * 0.025**2 / (x.shape[1] - 1)
    still = np.zeros_like(x)
    forces = {}
    for name, thinning, split in (("rodphase", 1.0, True), ("pyelastica", 0.0, False)):
        f = np.zeros_like(x)
        cc.self_contact_with_thinning(x[:, :-1], radius, lengths, tangents, still, f, 1e4, 0.0,
                                      thinning, split)
        forces[name] = f
    touched = np.argsort(-np.linalg.norm(forces["rodphase"], axis=0))[:6]
    h = 1e-7
    errors = {"rodphase": 0.0, "pyelastica": 0.0}
    for node in touched:
        for k in range(3):
            up, down = x.copy(), x.copy()
            up[k, node] += h
            down[k, node] -= h
            grad = (_contact_energy(cc, up, volume) - _contact_energy(cc, down, volume)) / (2 * h)
            for name in errors:
                errors[name] = max(errors[name], abs(forces[name][k, node] + grad))
    scale = np.abs(forces["rodphase"][:, touched]).max()
    assert errors["rodphase"] < 1e-4 * scale
    assert errors["pyelastica"] > 0.05 * scale


# ------------------------------------------------- steps of twist into writhe (issue #49)


def _steps_every_half_second(t, wr, until):
    from rodphase.analysis import writhe_steps

    grid = np.arange(np.ceil(t[0] / 0.5) * 0.5, until + 1e-9, 0.5)
    return writhe_steps(grid, np.interp(grid, t, wr))


def test_solenoid_steps_in_both_codes(runs):
    # docs/explanation/twist-into-writhe.md: four steps in each; rodphase's first is two loops
    # (1.33 turns) where PyElastica's is one (0.73), and rodphase ends a loop's worth higher
    ref, result = runs
    theirs = _steps_every_half_second(ref["time"], ref["writhe"], 76.0)
    assert len(theirs) == 4
    assert theirs[0]["gain"] == pytest.approx(0.73, abs=0.1)
    h = result.history
    ours = _steps_every_half_second(h["time"], h["writhe"], 76.0)
    assert len(ours) == 4
    assert ours[0]["gain"] > 1.1
    assert 3.2 < h["writhe"][-1] < 3.7 and 2.4 < ref["writhe"][-1] < 2.7


def test_pulled_solenoid_reference_has_a_sawtooth_after_losing_link():
    # Fig 4a through PyElastica (13 turns nominal, example's settings): two turns of link lost
    # around the bare start clamp during the twist, then force drops each with a writhe step
    tiw_path = ROOT / "studies" / "twist_into_writhe.py"
    import importlib.util

    spec = importlib.util.spec_from_file_location("tiw_for_test", tiw_path)
    tiw = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tiw)
    ref = np.load(ROOT / "tests" / "data" / "crosscheck_solenoid_pull.npz")
    t, link = ref["time"], ref["link"]
    assert np.interp(85.0, t, link) == pytest.approx(11.0, abs=0.01)  # 13 put in, 2 escaped
    pe = tiw.fig4a_pyelastica(ROOT / "tests" / "data" / "crosscheck_solenoid_pull.npz")
    m = tiw.fig4a_measure(pe["du"], pe["force"], pe["du_writhe"], pe["writhe"])
    assert len(m["drops"]) >= 2 and len(m["losses"]) >= 2
    assert m["writhe_start"] == pytest.approx(2.55, abs=0.05)


def test_pulled_solenoid_reference_at_the_scenes_twist_has_a_sawtooth_too():
    # Fig 4a ships at 10.2 turns because both codes show the sawtooth there: PyElastica keeps
    # its link through the twist, then loses coils in steps under the pull
    import importlib.util

    spec = importlib.util.spec_from_file_location("tiw_for_test10", ROOT / "studies" / "twist_into_writhe.py")
    tiw = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tiw)
    path = ROOT / "tests" / "data" / "crosscheck_solenoid_pull_10.npz"
    pe = tiw.fig4a_pyelastica(path)
    assert pe["complete"] and pe["link_start"] == pytest.approx(10.19, abs=0.01)
    m = tiw.fig4a_measure(pe["du"], pe["force"], pe["du_writhe"], pe["writhe"])
    assert len(m["losses"]) >= 2 and len(m["drops"]) >= 2


@pytest.mark.parametrize("case, sawtooth", [("solenoid_pull_10", True), ("solenoid_pull", False)])
def test_rodphase_on_the_pull_settings_has_the_sawtooth_at_10_turns_only(tmp_path, case, sawtooth):
    # the shipped Fig 4a decision (docs/explanation/twist-into-writhe.md): on PyElastica's pull
    # settings rodphase sheds coils in teeth at 10.19 turns and opens like a spring at 13
    import importlib.util

    import crosscheck_pyelastica as cc

    spec = importlib.util.spec_from_file_location(f"tiw_{case}", ROOT / "studies" / "twist_into_writhe.py")
    tiw = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tiw)
    out = tmp_path / f"{case}.npz"
    info = cc.run_rodphase(case, contact="example", dt="auto", twist="nominal", kick="load",
                           rotation_damping="example", out=out)
    assert info["status"] == "ok"
    rp = tiw.fig4a_rodphase_example(out)
    m = tiw.fig4a_measure(rp["du"], rp["force"], rp["du"], rp["writhe"])
    if sawtooth:
        assert len(m["drops"]) >= 2 and len(m["losses"]) >= 2
    else:
        assert m["drops"] == [] and m["losses"] == []
