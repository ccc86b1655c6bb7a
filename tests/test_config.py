"""Config validation: every broken input names its key, exits 2, and shows no traceback."""

import math
import re

import pytest
import yaml
from click.testing import CliRunner

from rodphase import config as C
from rodphase.cli import main
from rodphase.scenes import SCENES, build

SCENE = {"scene": "twist_under_load", "rod": {"elements": 20}}
SWEEP = {"sweep": {"scene": "twist_under_load", "axes": {"twist_density": [0.0, 1.0]},
                   "samples": 2}}


def with_(base, path, value):
    return C.apply_overrides(base, [(path, value)])


BROKEN_SCENES = [
    (with_(SCENE, "rod.radius", -0.01), "rod.radius"),
    (with_(SCENE, "rod.length", 0), "rod.length"),
    (with_(SCENE, "rod.elements", 2.5), "rod.elements"),
    (with_(SCENE, "rod.elements", 1), "rod.elements"),
    (with_(SCENE, "rod.density", float("nan")), "rod.density"),
    (with_(SCENE, "rod.radiuss", 0.02), "rod.radiuss"),
    (with_(SCENE, "material.youngs_modulus", "soft"), "material.youngs_modulus"),
    (with_(SCENE, "material.shear_modulus", -1.0), "material.shear_modulus"),
    (with_(SCENE, "ends.start", "glued"), "ends.start"),
    (with_(SCENE, "loading.extension", 0.9), "loading.extension"),
    (with_(with_(SCENE, "loading.extension", 1.1), "loading.force_multiple", 25), "loading."),
    (with_(SCENE, "loading.twist_rate", 0), "loading.twist_rate"),
    (with_(SCENE, "physics.self_contact", "yes"), "physics.self_contact"),
    (with_(SCENE, "physics.gravity", [0, 0]), "physics.gravity"),
    (with_(SCENE, "solver.safety", 1.5), "solver.safety"),
    (with_(SCENE, "solver.dt", -1e-5), "solver.dt"),
    (with_(SCENE, "solver.hold_until", "forever"), "solver.hold_until"),
    (with_(SCENE, "output.history_interval", 0), "output.history_interval"),
    (with_(SCENE, "rod.radius", 0.6), "rod.radius"),
    (with_(SCENE, "loading.force", 1e9), "loading"),
    (with_(SCENE, "scene", "no_such_scene"), "scene"),
    (with_(SCENE, "agent.first", 0.8), "agent.last"),
    ({"scene": "twist_under_load", "rods": {}}, "rods"),
]

BROKEN_SWEEPS = [
    (with_(SWEEP, "sweep.axes.twist_density", [1.0, 1.0]), "sweep.axes.twist_density"),
    (with_(SWEEP, "sweep.axes.extension", [0.8, 1.2]), "sweep.axes.extension"),
    (with_(SWEEP, "sweep.axes.extension", [1.0, 5.0]), "sweep.axes.extension"),
    (with_(SWEEP, "sweep.axes.stretch", [1.0, 1.2]), "sweep.axes.stretch"),
    (with_(SWEEP, "sweep.samples", 0), "sweep.samples"),
    (with_(SWEEP, "sweep.sampler", "halton"), "sweep.sampler"),
    (with_(SWEEP, "sweep.seed", -1), "sweep.seed"),
    (with_(SWEEP, "sweep.axes", {}), "sweep.axes"),
    ({"sweep": {"axes": {"twist_density": [0, 1]}}}, "sweep.scene"),
]


def run_cli(args):
    return CliRunner().invoke(main, args, catch_exceptions=False)


@pytest.mark.parametrize("data, key", BROKEN_SCENES)
def test_broken_scene_exits_2_naming_the_key(tmp_path, data, key):
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(data))
    result = run_cli(["run", str(path), "-o", str(tmp_path / "out.h5")])
    assert result.exit_code == 2, result.output
    assert result.output.startswith("error: ")
    assert key in result.output
    assert "allowed" in result.output
    assert "Traceback" not in result.output
    assert not (tmp_path / "out.h5").exists()  # nothing written for a config that never ran


@pytest.mark.parametrize("data, key", BROKEN_SWEEPS)
def test_broken_sweep_exits_2_naming_the_key(tmp_path, data, key):
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(data))
    result = run_cli(["sweep", str(path), "-o", str(tmp_path / "out.h5"), "--quiet"])
    assert result.exit_code == 2, result.output
    assert key in result.output and "Traceback" not in result.output


def test_unknown_key_suggests_the_closest(tmp_path):
    with pytest.raises(C.ConfigError, match="did you mean 'radius'"):
        C.validate_scene(with_(SCENE, "rod.raduis", 0.02), SCENES)


def test_bad_set_override_exits_2(tmp_path):
    result = run_cli(["run", "twist_under_load", "-o", str(tmp_path / "o.h5"), "--set", "rod.elements"])
    assert result.exit_code == 2 and "key.path=value" in result.output
    result = run_cli(["run", "twist_under_load", "-o", str(tmp_path / "o.h5"), "--set", "rod.elements=-3"])
    assert result.exit_code == 2 and "rod.elements" in result.output


def test_yaml_exponent_without_sign_is_a_number():
    # PyYAML reads 1.0e6 as a string; configs written that way must still work
    cfg = C.validate_scene(with_(SCENE, "material.youngs_modulus", "1.0e6"), SCENES)
    assert cfg.material.youngs_modulus == 1.0e6


def test_unit_mapping_matches_the_paper():
    cfg = C.validate_scene(with_(with_(SCENE, "loading.extension", 1.16), "loading.twist_density", 1.2),
                           SCENES)
    area = math.pi * 0.025**2
    assert C.load_force(cfg) == pytest.approx(1e6 * area * (1 - 1 / 1.16))
    assert C.twist_turns(cfg) == pytest.approx(1.2 * 1.0 / 0.025 / (2 * math.pi))
    assert C.shear_modulus(cfg) == pytest.approx(2e6 / 3)  # G = 2E/3 as the paper states
    cfg = C.validate_scene(with_(SCENE, "loading.force_multiple", 25), SCENES)
    assert C.load_force(cfg) == pytest.approx(25 * math.pi**2 * 1e6 * math.pi * 0.025**4 / 4)


def test_every_shipped_scene_validates_and_builds():
    for path in sorted((C.PACKAGE_CONFIGS / "scenes").glob("*.yaml")):
        cfg = C.load_scene(path, [("rod.elements", 20)], SCENES)
        problem = build(cfg)
        assert problem.stages and problem.rod.elements == 20


def test_every_shipped_sweep_validates():
    for path in sorted(C.PACKAGE_CONFIGS.glob("*.yaml")):
        sweep, scene = C.load_sweep(path, [], SCENES)
        assert sweep.samples >= 1 and scene.scene in SCENES


def test_config_is_read_only():
    cfg = C.validate_scene(SCENE, SCENES)
    with pytest.raises(TypeError):
        cfg.rod["radius"] = 1.0


def test_twist_density_of_the_stretched_rod():
    # Φa with L = e L0 and a = a0/√e: the same end rotation reads e^1.5 smaller
    cfg = C.validate_scene(with_(with_(SCENE, "loading.extension", 1.16),
                                 "loading.twist_density_current", 1.2), SCENES)
    assert C.twist_turns(cfg) == pytest.approx(1.2 * 1.16**1.5 / 0.025 / (2 * math.pi))
    with pytest.raises(C.ConfigError, match="only one of"):
        C.validate_scene(with_(with_(SCENE, "loading.twist_density", 1.0),
                               "loading.twist_density_current", 1.2), SCENES)


def test_seams_gravity_shear_modulus_and_frozen_attributes():
    # physics.gravity reaches every stage's controls (it was validated and then dropped)
    from rodphase.rod import Rod
    from rodphase.scenes import SCENES, build

    cfg = C.load_scene("twist_under_load", [("physics.gravity", [0, 0, -9.81])], SCENES)
    problem = build(cfg)
    assert all(s.controls.gravity == (0.0, 0.0, -9.81) for s in problem.stages)
    cfg = C.load_scene("solenoid_loss", [("physics.gravity", [0, 0, -9.81])], SCENES)
    assert build(cfg).stages[-1].controls.gravity == (0.0, 0.0, -9.81)
    # the engine's default G is 2E/3 of the rod's own E, not of 1 MPa
    assert Rod(length=1.0, radius=0.02, elements=4, youngs_modulus=1e7).shear_modulus == \
        pytest.approx(2e7 / 3)
    # a loaded config cannot be changed by attribute (it was accepted and ignored)
    with pytest.raises(TypeError):
        cfg.rod.elements = 40


def test_a_stage_of_zero_length_is_skipped_not_the_end_of_the_run():
    from rodphase.rod import simulate
    from rodphase.scenes import SCENES, build

    cfg = C.load_scene("twist_under_load", [("rod.elements", 16), ("loading.force_ramp_time", 0),
                                            ("loading.twist_density", 0.05),
                                            ("solver.hold_max_time", 0.5)], SCENES)
    result = simulate(build(cfg))
    labels = [s["label"] for s in result.diagnostics["stages"]]
    assert labels == ["load", "twist 0", "hold 0"]
    assert result.diagnostics["stages"][0]["steps"] == 0
    assert result.diagnostics["stages"][1]["steps"] > 0  # the twist ran (was: 0 steps, "ok")
    assert result.history["end_rotation"][-1] == pytest.approx(0.05 / 0.025)


@pytest.mark.parametrize("text, words", [
    ("scene: twist_under_load\nrod: {elements: 40}\nrod: {elements: 60}\n", "given twice"),
    ("scene: twist_under_load\nrod: {elements: 020}\n", "leading zero"),
    ("a: &x [1, 2]\nb: *x\n", "aliases are not allowed"),
    ("just some prose that is not a config\n", "a YAML mapping"),
])
def test_configs_that_yaml_would_accept_silently_are_refused(tmp_path, text, words):
    path = tmp_path / "scene.yaml"
    path.write_text(text)
    with pytest.raises(C.ConfigError, match=words):
        C.read_yaml(path)


def test_a_binary_config_and_an_octal_override_are_named(tmp_path):
    path = tmp_path / "scene.yaml"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff\xfe")
    with pytest.raises(C.ConfigError, match="not UTF-8"):
        C.read_yaml(path)
    with pytest.raises(C.ConfigError, match="leading zeros"):
        C.parse_override("rod.elements=020")


def test_a_history_interval_that_would_not_fit_is_refused_before_simulating():
    from rodphase.rod import simulate

    # a snapshot per step of a 200-element rod over a 1000 s hold: ~5e11 bytes
    cfg = C.load_scene("twist_under_load", [("output.history_interval", 1e-9),
                                            ("rod.elements", 200),
                                            ("solver.hold_max_time", 1000)], SCENES)
    result = simulate(build(cfg))
    assert result.status == "unstable" and result.diagnostics["steps"] == 0
    assert "output.history_interval" in result.message


def test_files_that_are_not_rodphase_stores_get_one_error_line(tmp_path):
    import h5py

    runner = CliRunner()
    text = tmp_path / "notes.h5"
    text.write_text("not hdf5")
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["data"] = [1, 2, 3]
    for command in (["classify", str(text)], ["classify", str(foreign)],
                    ["plot", str(text), "-o", str(tmp_path / "x.png")],
                    ["plot", str(foreign), "-o", str(tmp_path / "x.png")]):
        result = runner.invoke(main, command)
        assert result.exit_code == 2, (command, result.output)
        assert "error:" in result.output and "rodphase" in result.output
        assert "Traceback" not in result.output


def test_a_figure_the_data_cannot_make_is_an_error_line(tmp_path):
    # `plot --kind response` on a run with no material ramp (was a ValueError traceback)
    runner = CliRunner()
    out = tmp_path / "run.h5"
    result = runner.invoke(main, ["run", "twist_under_load", "-o", str(out), "--set",
                                  "rod.elements=8", "--set", "loading.twist_density=0.01",
                                  "--set", "solver.hold_max_time=0.05", "--set",
                                  "loading.force_ramp_time=0.05"])
    assert result.exit_code in (0, 1), result.output
    result = runner.invoke(main, ["plot", str(out), "--kind", "response", "-o", str(tmp_path / "r.png")])
    assert result.exit_code == 2 and "error: --kind response" in result.output


def _tiny_sweep(tmp_path, **sweep_keys):
    data = {"sweep": {"scene": "twist_under_load",
                      "axes": {"twist_density": [0.2, 1.0], "extension": [1.0, 1.2]},
                      "samples": 2, **sweep_keys}}
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize("where, key", [("--set", "loading.twist_density"),
                                        ("--set", "loading.twist_turns"),
                                        ("--set", "loading.force_multiple"),
                                        ("sweep.set", "loading.extension")])
def test_a_value_that_a_sweep_axis_would_replace_is_refused(tmp_path, where, key):
    if where == "--set":
        args = ["--set", f"{key}=1.0"]
        path = _tiny_sweep(tmp_path)
    else:
        args = []
        path = _tiny_sweep(tmp_path, set={key: 1.1})
    result = run_cli(["sweep", str(path), "-o", str(tmp_path / "o.h5"), "--quiet", *args])
    assert result.exit_code == 2, result.output
    assert result.output.startswith(f"error: {where.replace('--set', '--set ')}"
                                    f"{'' if where == '--set' else '.'}{key}")
    assert "axis" in result.output and not (tmp_path / "o.h5").exists()


@pytest.mark.parametrize("args, words", [
    (["--backend", "dask", "--scheduler", "not an address"], "tcp://host:8786"),
    (["--scheduler", "tcp://127.0.0.1:8786"], "only with --backend dask"),
])
def test_a_scheduler_address_is_checked_before_anything_runs(tmp_path, args, words):
    result = run_cli(["sweep", str(_tiny_sweep(tmp_path)), "-o", str(tmp_path / "o.h5"),
                      "--quiet", *args])
    assert result.exit_code == 2 and result.output.startswith("error: --scheduler")
    assert words in result.output and "Compiling" not in result.output


def test_run_checks_its_output_before_simulating(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("a file, not a folder")
    result = run_cli(["run", "twist_under_load", "-o", str(blocker / "out.h5")])
    assert result.exit_code == 2 and result.output.startswith("error: --output")
    assert "Running" not in result.output


def test_config_prints_the_resolved_scene_and_sweep_and_shipped_sweeps_go_by_name(tmp_path):
    result = run_cli(["config", "twist_under_load", "--set", "rod.elements=60"])
    assert result.exit_code == 0
    printed = yaml.safe_load(result.output)["scene"]
    assert printed["rod"]["elements"] == 60 and printed["solver"]["damping"] == 20.0
    assert printed["rod"]["elements_from"] == "given"
    result = run_cli(["config", "quick", "--set", "sweep.samples=3"])
    both = yaml.safe_load(result.output)
    assert both["sweep"]["samples"] == 3 and both["scene"]["rod"]["elements"] == 64
    # by name, and as the README writes it from any folder, not only the checkout
    for name in ("quick", "configs/quick.yaml"):
        sweep, _ = C.load_sweep(name, [], SCENES)
        assert sweep.samples == 24
    with pytest.raises(C.ConfigError, match="shipped sweep: .*quick"):
        C.load_sweep(str(tmp_path / "missing.yaml"), [], SCENES)


def test_one_set_of_defaults_the_engines():
    """A key left out of a config means what the engine's own dataclass says (the schema
    said quadratic_drag 1000, tolerance 1e-3, history 0.1 s, settle 0.5 s where the engine
    said 0, 1e-4, 0.05 s, 0): a Problem from a bare config equals one built in Python."""
    import dataclasses

    from rodphase.rod import Contact, Rod, Solver

    bare = C.validate_scene({"scene": "twist_under_load"}, SCENES)
    problem = build(bare)
    engine = {"Solver": Solver(), "Contact": Contact()}
    for section, fields in C.SCENE_SCHEMA.items():
        for key, (_, default) in fields.items():
            if isinstance(default, C.EngineDefault):
                expected = {f.name: f.default for f in dataclasses.fields(
                    {"Rod": Rod, "Solver": Solver, "Contact": Contact}[default.cls])}[default.field]
                assert bare[section][key] == ("auto" if expected is None else expected), key
    for name in ("quadratic_drag", "hold_tolerance", "history_interval", "settle_window", "safety",
                 "damping", "stability_probe", "probe_size"):
        assert getattr(problem.solver, name) == getattr(engine["Solver"], name), name
    for name in ("stiffness", "damping_ratio", "exclusion", "skin", "near_skin",
                 "penetration_limit", "friction"):
        assert getattr(problem.contact, name) == getattr(engine["Contact"], name), name


def test_engine_keys_are_checked_by_the_engine_fields_own_range():
    """A key backed by an engine field takes its unit and bounds from that field's
    `model.setting` metadata: the default passes, a value just outside either bound is
    refused naming the key, and the unit appears in what is allowed."""
    import dataclasses

    from rodphase.rod import model

    engine_keys = 0
    for section, fields in C.SCENE_SCHEMA.items():
        for key, (check, default) in fields.items():
            if not isinstance(check, C.EngineCheck):
                continue
            engine_keys += 1
            path = f"{section}.{key}"
            spec = {f.name: f for f in dataclasses.fields(getattr(model, check.cls))}[check.field]
            meta = spec.metadata
            assert check(path, default.value()) == default.value()
            if isinstance(spec.default, bool):
                with pytest.raises(C.ConfigError, match="true or false"):
                    check(path, 1)
                continue
            if spec.default is None:
                assert check(path, "auto") == "auto"
            if meta["minimum"] is not None:
                below = meta["minimum"] if meta["strict_min"] else meta["minimum"] - 1e-9
                with pytest.raises(C.ConfigError, match=rf"{path}: .*{re.escape(meta['unit'])}"):
                    check(path, below)
            if meta["maximum"] is not None:
                with pytest.raises(C.ConfigError, match=path):
                    check(path, meta["maximum"] * 1.001 + 1e-9)
    assert engine_keys >= 20  # every solver/contact key and the rod's material is the engine's


class _Tracked(C.Frozen):
    """A config that notes every key read from it."""

    read: set = set()

    def __getitem__(self, key):
        _Tracked.read.add((self._where, key))
        return dict.__getitem__(self, key)

    def get(self, key, default=None):
        _Tracked.read.add((self._where, key))
        return dict.get(self, key, default)


def _tracked(value, where=""):
    if not isinstance(value, dict):
        return value
    out = _Tracked({k: _tracked(v, f"{where}.{k}" if where else k) for k, v in value.items()})
    object.__setattr__(out, "_where", where)
    return out


def test_every_schema_key_is_read_by_some_builder_or_the_runner(monkeypatch):
    """A key that nothing reads is a setting that silently does nothing."""
    import numpy as np

    import rodphase.rod
    from rodphase import runner
    from rodphase.result import RunResult

    _Tracked.read = set()
    validated = []
    monkeypatch.setattr(C, "validate_scene", lambda raw, registered=None: validated.append(
        _tracked(_VALIDATE(raw, registered))) or validated[-1])
    # a run that reports itself under-resolved, so that the runner reads its refinement cap
    monkeypatch.setattr(rodphase.rod, "simulate", lambda problem, **kw: RunResult(
        "unstable", "", None, None, None, None, {}, np.zeros(0), np.zeros(0),
        {"guard": "resolution", "wall_time": 0.0}))
    # the other ways to give the load and the twist, read only when they are set
    others = [(f"loading.{k}", None) for k in ("force_multiple", "force", "extension",
                                                "twist_turns", "twist_density",
                                                "twist_density_current")]
    variants = [[], others + [("loading.extension", 1.1), ("loading.twist_density_current", 0.5)],
                others + [("loading.force", 10.0), ("loading.twist_turns", 2.0)]]
    for path in sorted((C.PACKAGE_CONFIGS / "scenes").glob("*.yaml")):
        for overrides in variants:
            raw = C.apply_overrides(C.read_yaml(path), overrides)
            runner.run_scene(raw)
            # what the run's caller (sweep worker, `run`, the API) reads to store the result
            runner.snapshot_policy(validated[-1], "all")
    every = {(section, key) for section, fields in C.SCENE_SCHEMA.items() for key in fields}
    # how rod.elements is chosen is read by validation itself (config._with_elements)
    assert every - _Tracked.read - C.HASH_OMITTED == set()


_VALIDATE = C.validate_scene


def test_every_command_has_an_example_in_its_help():
    for name, command in main.commands.items():
        result = run_cli([name, "--help"])
        assert result.exit_code == 0 and "Example:" in result.output, name
        assert f"rodphase {name}" in result.output.split("Example:")[1], name


# The config hashes of the shipped configs, as of 6d08ef0, and as of the commit that made the
# implicit dashpot and strain-rate damping the contact scenes' settings (issue #13: a change
# of physics, so their stores from before it are, rightly, not resumed), and as of the commit
# that gave the phase-diagram sweeps the quasi-static straight start (issue #16: another
# protocol, whose stores are not mixed with the old ones), and as of the commit that added fold
# contact (contact.fold, on by default: pairs inside the exclusion no longer pass through each
# other, which changes every solenoid; `contact.fold: false` gives the hashes before it, checked
# below), and as of the commit that let contact sleep until the rod nears itself
# (contact.sleep, on by default: a larger time step before the first touch, so every contact
# run's numbers move at the level of the time-step error; `contact.sleep: false` gives the
# hashes before it, checked below), and as of the commit that let a refined run go on from a
# second before its trip (solver.refine_from: trip; `start` gives the hashes before it), and as
# of the commit that stated the sweeps' resolution as element lengths and doublings (issue
# #46: rod.element_length, solver.refinements; the same counts and runs, but their `set`
# reads otherwise, so a sweep's store from before it is not resumed; the scenes' hashes
# leave out how rod.elements was chosen, C.HASH_OMITTED, and did not move). A
# store is resumed only by a config
# of the same hash, so a new key whose default keeps the old behaviour must register in
# C.HASH_NEUTRAL and leave these unchanged; a change here means every user's store written
# before it can no longer be resumed.
SHIPPED_HASHES = {
    "fig3_adaptive.yaml": "ddbcf4cb915dfe13",
    "fig3_continuation.yaml": "3c05438d2cc66651",
    "fig3_grid.yaml": "952c1ca0a3c6ea73",
    "fig3_paper.yaml": "856bead4248a7535",
    "fig3_paper_adaptive.yaml": "280aaafab74cb165",
    "fig3_paper_reference.yaml": "ab4b7c747c22a508",
    "fig3_paths.yaml": "bf1b3e454a913757",
    "fig3_stretched.yaml": "728c5c286203ada6",
    "hat_forces.yaml": "65ce94d00c6e86e8",
    "quick.yaml": "b6c0ab7f493156ce",
    "scenes/active_agent.yaml": "2c6a23fb08c4a298",
    "scenes/fig2a_plectoneme.yaml": "d157a215205e63c7",
    "scenes/fig2b_solenoid.yaml": "4fc4cd2e22fc19fe",
    "scenes/figS3_escape.yaml": "3a555994f35cc5d5",
    "scenes/hat_curve.yaml": "8015402f4ed8e193",
    "scenes/helical_buckling.yaml": "fb8765b925dc3d83",
    "scenes/muscle.yaml": "d4d4b873aa60ed86",
    "scenes/solenoid_loss.yaml": "cd2fd237e07b16b8",
    "scenes/stiffening.yaml": "39940b5426528e03",
    "scenes/twist_under_load.yaml": "f3c36c55aa151a04",
}


def _shipped_parts(name):
    path = C.PACKAGE_CONFIGS / name
    if name.startswith("scenes/"):
        return (C.load_scene(path, [], SCENES),)
    return C.load_sweep(path, [], SCENES)


def test_shipped_config_hashes_are_stable():
    # the configs' own hashes (engine revision 1: as before the revision was part of it)
    for name, expected in SHIPPED_HASHES.items():
        digest = C.config_hash(*_shipped_parts(name), revision=1)
        assert digest == expected, name


def test_fold_contact_off_gives_the_hashes_from_before_it():
    # the pins of the commit before fold contact, for the scenes (a sweep's hash needs the key
    # in its scene part, which --set does not reach from here), with the later sleeping
    # contact off too
    before = {"scenes/fig2b_solenoid.yaml": "80068e5262ef1e65",
              "scenes/twist_under_load.yaml": "0d98e59a15617bd0"}
    for name, expected in before.items():
        cfg = C.load_scene(C.PACKAGE_CONFIGS / name, [("contact.fold", False),
                                                      ("contact.sleep", False),
                                                      ("solver.refine_from", "start"),
                                                      ("solver.static_stability", False)], SCENES)
        assert C.config_hash(cfg, revision=1) == expected, name


# the scenes' pins before solver.static_stability (issue #32): with it off they hash as before
BEFORE_STATIC_STABILITY = {
    "scenes/active_agent.yaml": "960a406d20b6870b",
    "scenes/fig2a_plectoneme.yaml": "767b034b93fb8a9e",
    "scenes/fig2b_solenoid.yaml": "eb30ae4ee82cfee5",
    "scenes/figS3_escape.yaml": "fddd9828d6ff37da",
    "scenes/hat_curve.yaml": "76ed76ed5be12bf2",
    "scenes/helical_buckling.yaml": "daaf407a7aa38735",
    "scenes/muscle.yaml": "cee164392ae36944",
    "scenes/solenoid_loss.yaml": "20a2073b65584fe6",
    "scenes/stiffening.yaml": "e231548394f45689",
    "scenes/twist_under_load.yaml": "8d0af598de879a32",
}


def test_static_stability_off_gives_the_hashes_from_before_it():
    for name, expected in BEFORE_STATIC_STABILITY.items():
        cfg = C.load_scene(C.PACKAGE_CONFIGS / name, [("solver.static_stability", False)], SCENES)
        assert C.config_hash(cfg, revision=1) == expected, name


def test_this_sessions_keys_at_their_old_behaviour_give_the_hashes_from_before_them():
    # the pins of the commit before contact.sleep and solver.refine_from
    before = {"scenes/fig2b_solenoid.yaml": "47352e348fae4462",
              "scenes/twist_under_load.yaml": "91ca00c16beb833f"}
    for name, expected in before.items():
        cfg = C.load_scene(C.PACKAGE_CONFIGS / name, [("contact.sleep", False),
                                                      ("solver.refine_from", "start"),
                                                      ("solver.static_stability", False)], SCENES)
        assert C.config_hash(cfg, revision=1) == expected, name


def test_a_hash_neutral_key_counts_only_when_it_leaves_its_neutral_value(monkeypatch):
    cfg = C.load_scene(C.PACKAGE_CONFIGS / "scenes" / "fig2b_solenoid.yaml", [], SCENES)
    before = C.config_hash(cfg)
    monkeypatch.setitem(C.HASH_NEUTRAL, ("material", "incompressible"), True)
    assert C.config_hash(cfg) != before  # the key left out: a different blob
    same = C.load_scene(C.PACKAGE_CONFIGS / "scenes" / "fig2b_solenoid.yaml",
                        [("material.incompressible", False)], SCENES)
    assert C.config_hash(same) != C.config_hash(cfg)  # away from its neutral value it counts



@pytest.mark.parametrize("key, bad, bounds", [
    ("twist_density", 3.5, C.TWIST_DENSITY_RANGE),
    ("twist_density_current", -3.2, C.TWIST_DENSITY_RANGE),
    ("extension", 2.5, C.EXTENSION_RANGE), ("force_multiple", 1200.0, C.FORCE_MULTIPLE_RANGE)])
def test_a_control_has_the_same_bounds_as_a_scene_key_and_as_a_sweep_axis(key, bad, bounds):
    # issue #27: one range per control. The sweep axis bounded Phi*a to [-3, 3] while the
    # scene key took any number: a value one refuses, the other must refuse too, saying the
    # same range
    with pytest.raises(C.ConfigError) as as_key:
        C.validate_scene(with_(SCENE, f"loading.{key}", bad), SCENES)
    with pytest.raises(C.ConfigError) as as_axis:
        C.validate_sweep(with_(SWEEP, f"sweep.axes.{key}", [bounds[0], bad])["sweep"])
    assert as_key.value.path == f"loading.{key}"
    assert as_axis.value.path == f"sweep.axes.{key}"
    for error in (as_key.value, as_axis.value):
        assert f"{bounds[0]:g} " in error.allowed and f"<= {bounds[1]:g}" in error.allowed
    if key != "force_multiple":  # (1000 F_C would stretch this rod without bound)
        C.validate_scene(with_(SCENE, f"loading.{key}", bounds[1]), SCENES)  # the bound is in


def test_contact_thinning_force_is_a_checked_key_that_moves_no_hash_at_its_default():
    on = C.load_scene("twist_under_load", [], SCENES)
    assert on.contact.thinning_force is True
    explicit = C.load_scene("twist_under_load", [("contact.thinning_force", True)], SCENES)
    off = C.load_scene("twist_under_load", [("contact.thinning_force", False)], SCENES)
    assert C.config_hash(explicit) == C.config_hash(on) != C.config_hash(off)
    with pytest.raises(C.ConfigError, match="contact.thinning_force"):
        C.load_scene("twist_under_load", [("contact.thinning_force", "sometimes")], SCENES)


def test_a_store_of_an_earlier_engine_revision_is_not_resumed(tmp_path):
    # Every shipped config hashes apart under the current engine revision (its runs are of
    # other physics than revision 1's: the clamp couple of 2026-12-06), and `rodphase run`
    # into a store an earlier rodphase wrote for the same config refuses it (exit 2, one
    # line naming both revisions), where the same command resumes a store of its own
    from rodphase import __version__
    from rodphase.store import open_store

    assert C.ENGINE_REVISION >= 2
    for name in SHIPPED_HASHES:
        parts = _shipped_parts(name)
        assert C.config_hash(*parts) != C.config_hash(*parts, revision=1), name
        assert C.earlier_hashes(*parts)[C.config_hash(*parts, revision=1)] == 1
    cfg = C.load_scene("twist_under_load", [("rod.elements", 8)], SCENES)
    old = tmp_path / "old.h5"
    with open_store(old, config_text=C.to_yaml(scene=cfg), version="0.old", kind="run",
                    config_hash=C.config_hash(cfg, revision=1)):
        pass
    result = CliRunner().invoke(main, ["run", "twist_under_load", "-o", str(old),
                                       "--set", "rod.elements=8"])
    assert result.exit_code == 2, result.output
    lines = [ln for ln in result.output.strip().splitlines() if ln.startswith("error")]
    assert len(lines) == 1 and "earlier rodphase (engine revision 1; this one is " \
        f"{C.ENGINE_REVISION}" in lines[0] and "--force" in lines[0], result.output
    assert "Traceback" not in result.output
    with open_store(tmp_path / "new.h5", config_text=C.to_yaml(scene=cfg), version=__version__,
                    kind="run", config_hash=C.config_hash(cfg),
                    earlier=C.earlier_hashes(cfg)):
        pass
    with open_store(tmp_path / "new.h5", config_text=C.to_yaml(scene=cfg), version=__version__,
                    kind="run", config_hash=C.config_hash(cfg),
                    earlier=C.earlier_hashes(cfg)):
        pass  # its own revision's store opens again (resume)
