"""Issue #47 item 3: inputs fuzzed, not only listed.

Hypothesis mutates every shipped scene and sweep file and every `--set` value type, and
checks the contract of bad input: the config loads, or it is refused with ConfigError naming
the key, and the CLI says one `error:` line with exit 2; never another exception, never NaN
or inf accepted where a number must be finite. The same for the store: truncated,
bit-flipped and foreign-schema HDF5 files through `classify`, `plot`, resume and the API.

Seeded and bounded: derandomize=True (the same examples on every run, no example database),
max_examples fixed per test, deadline off; the whole file takes about 20-30 s on 2 cores and
compiles no kernel (nothing here simulates).
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from fakes import fake_run  # tests/fakes.py: pytest puts tests/ on sys.path
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import rodphase
from rodphase import api, runner
from rodphase import config as C
from rodphase import store as S
from rodphase.cli import main
from rodphase.scenes import SCENES

SCENE_FILES = sorted((C.PACKAGE_CONFIGS / "scenes").glob("*.yaml"))
SWEEP_FILES = sorted(C.PACKAGE_CONFIGS.glob("*.yaml"))
SHIPPED = [(p, "scene") for p in SCENE_FILES] + [(p, "sweep") for p in SWEEP_FILES]


def fuzz(max_examples: int):
    """Seeded (derandomize), bounded, no deadline: the same examples on every machine."""
    return settings(max_examples=max_examples, derandomize=True, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                           HealthCheck.function_scoped_fixture],
                    print_blob=True)


# ---------------------------------------------------------------- values of every YAML type

# text that YAML or float() read as a number, a special float, a bool or nothing
TRICKY_TEXT = ["nan", ".nan", "NaN", "inf", "-inf", ".inf", "-.inf", "1e400", "-1e400", "1.0e6",
               "0x10", "0o17", "1_000", "yes", "off", "~", "null", "", " ", "auto", "all",
               "1e-400", "+3", "3.0.0", "∞", "#", "a#b", "x.h5#run", "[1, 2]", "{a: 1}"]
scalars = st.one_of(
    st.none(), st.booleans(),
    st.integers(-5, 5), st.integers(-10**6, 10**6), st.integers(),
    st.floats(), st.floats(-10, 10),
    st.sampled_from([0, 1, -1, 4, 5000, 5001, 1e308, -1e308, 1e-320, 0.5, 2.0, 3.0, 3.5]),
    st.sampled_from(TRICKY_TEXT), st.text(max_size=6),
)
# a list or a mapping as often as a scalar: a key given a container where a scalar belongs
# (`scene: []`) is the mutation that found the first bug
values = st.one_of(
    scalars, st.lists(scalars, max_size=3), st.dictionaries(st.text(max_size=4), scalars,
                                                            max_size=2),
    st.recursive(scalars, lambda inner: st.lists(inner, max_size=3)
                 | st.dictionaries(st.text(max_size=4), inner, max_size=2), max_leaves=5))


def schema_paths() -> list[tuple]:
    """Every scene key the schema knows, as a path."""
    return [("scene",), ("description",), ("initial_state",)] + [
        (section,) for section in C.SCENE_SCHEMA] + [
        (section, key) for section, fields in C.SCENE_SCHEMA.items() for key in fields]


def node_paths(node, prefix=()) -> list[tuple]:
    """Every node of a YAML tree (mapping keys and list indices) as a path."""
    out = [prefix] if prefix else []
    if isinstance(node, dict):
        for k, v in node.items():
            out += node_paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += node_paths(v, prefix + (i,))
    return out


def mutate(data, path: tuple, op: str, value):
    """`data` with the node at `path` set to `value` ("set") or deleted ("delete"); the
    mappings on the way are made if missing (a mutation may add a key)."""
    node = data
    for part in path[:-1]:
        if isinstance(node, dict):
            node = node.setdefault(part, {})
        elif isinstance(node, list) and isinstance(part, int) and part < len(node):
            node = node[part]
        else:
            return data  # a path through a scalar: nothing to mutate there
        if not isinstance(node, (dict, list)):
            return data
    last = path[-1]
    if isinstance(node, dict):
        if op == "delete":
            node.pop(last, None)
        else:
            node[last] = value
    elif isinstance(node, list) and isinstance(last, int) and last < len(node):
        if op == "delete":
            del node[last]
        else:
            node[last] = value
    return data


def finite_everywhere(node, where="") -> None:
    """No NaN or inf anywhere in a validated config."""
    if isinstance(node, dict):
        for k, v in node.items():
            finite_everywhere(v, f"{where}.{k}" if where else str(k))
    elif isinstance(node, (list, tuple)):
        for i, v in enumerate(node):
            finite_everywhere(v, f"{where}[{i}]")
    elif isinstance(node, float):
        assert math.isfinite(node), f"{where} = {node} accepted"


def dotted(path: tuple) -> str:
    return ".".join(str(p) for p in path)


def load(path: Path, kind: str, overrides=()) -> list:
    """The validated parts (scene; or sweep and scene) of a config file; ConfigError if not."""
    if kind == "sweep":
        return list(C.load_sweep(path, overrides, SCENES))
    return [C.load_scene(path, overrides, SCENES)]


def contract(path: Path, kind: str, overrides=(), sets=()) -> C.ConfigError | None:
    """Loads with finite numbers everywhere, or ConfigError naming a key; the CLI agrees:
    exit 0, or exit 2 with exactly one line on stderr, an `error:` line naming that key."""
    error = None
    try:
        parts = load(path, kind, overrides)
    except C.ConfigError as exc:
        error = exc
        assert isinstance(exc.path, str) and exc.path.strip(), repr(exc)
        assert "\n" not in str(exc), str(exc)
    else:
        for part in parts:
            finite_everywhere(part.plain())
        runner.check_memory(parts[-1]) if kind == "scene" else None
    out = CliRunner().invoke(main, ["config", str(path), *[f"--set={s}" for s in sets]])
    if error is None:
        assert out.exit_code == 0, (out.output, out.exception)
        # (a warning may go to stderr: rod.elements below what the rod needs)
        assert "error:" not in out.stderr and "Traceback" not in out.stderr, out.stderr
    else:
        assert out.exit_code == 2, (out.output, out.exception)
        lines = out.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: "), out.stderr
        assert error.path in lines[0], (lines[0], error.path)
    return error


# ---------------------------------------------------------------- the shipped files, mutated

@fuzz(max_examples=200)
@given(data=st.data())
def test_mutated_shipped_files_load_or_are_refused_by_key(tmp_path_factory, data):
    source, kind = data.draw(st.sampled_from(SHIPPED), label="file")
    raw = yaml.safe_load(source.read_text())
    inside = raw["sweep"] if kind == "sweep" else raw
    known = node_paths(inside) + (schema_paths() if kind == "scene" else [
        ("scene",), ("set",), ("axes",), ("sampler",), ("samples",), ("seed",), ("columns",),
        ("axes", "twist_density"), ("axes", "extension"), ("axes", "force_multiple"),
        ("axes", "twist_density_current"), ("set", "rod.elements")])
    top = sorted({p[:1] for p in known}, key=str)
    target = data.draw(st.sampled_from(top) | st.sampled_from(known)
                       | st.tuples(st.text(max_size=5)), label="path")
    op = data.draw(st.sampled_from(["set", "set", "set", "delete"]), label="op")
    value = data.draw(values, label="value")
    inside = mutate(inside, target, op, value)
    if kind == "sweep":
        raw["sweep"] = inside
    folder = tmp_path_factory.mktemp("mutated")
    path = folder / source.name
    path.write_text(yaml.safe_dump(raw if kind == "sweep" else inside, allow_unicode=True),
                    encoding="utf-8")
    contract(path, kind)


# every top-level key of every shipped scene, given a value of every YAML type (in memory: a
# few milliseconds for all), beside the random mutations above
TYPE_SAMPLES = [None, True, 0, -1, 2.5, float("nan"), float("inf"), "", "x", "nan", [], [1.0],
                {}, {"a": 1}, {"elements": []}]


@pytest.mark.filterwarnings("ignore::rodphase.config.ResolutionWarning")  # a valid, coarse rod
@pytest.mark.parametrize("source", SCENE_FILES, ids=lambda p: p.stem)
def test_every_top_level_key_of_every_shipped_scene_takes_every_type(source):
    raw = yaml.safe_load(source.read_text())
    for key in sorted(set(raw) | {"scene", "description", "initial_state"} | set(C.SCENE_SCHEMA)):
        for value in TYPE_SAMPLES:
            try:
                finite_everywhere(C.validate_scene({**raw, key: value}, SCENES).plain())
            except C.ConfigError as exc:
                assert exc.path.strip() and "\n" not in str(exc), (key, value, str(exc))


@fuzz(max_examples=40)
@given(top=values)
def test_a_file_that_is_not_a_mapping_or_has_a_strange_top_is_refused(tmp_path_factory, top):
    path = tmp_path_factory.mktemp("top") / "odd.yaml"
    path.write_text(yaml.safe_dump(top), encoding="utf-8")
    for kind in ("scene", "sweep"):
        try:
            load(path, kind)
        except C.ConfigError:
            pass


# ---------------------------------------------------------------- --set of every value type

SET_KEYS = [dotted(p) for p in schema_paths()] + [
    "sweep.samples", "sweep.seed", "sweep.sampler", "sweep.axes.twist_density",
    "sweep.axes.extension", "sweep.set", "sweep.set.rod.elements", "rod.length.x", "sweep",
    "rod.elements.0", "initial_state"]


@fuzz(max_examples=150)
@given(data=st.data())
def test_set_values_of_every_type_load_or_are_refused_by_key(data):
    source, kind = data.draw(st.sampled_from(SHIPPED), label="file")
    key = data.draw(st.sampled_from(SET_KEYS) | st.text(max_size=6), label="key")
    text = data.draw(st.sampled_from(TRICKY_TEXT) | st.text(max_size=8)
                     | values.map(lambda v: yaml.safe_dump(v, default_flow_style=True,
                                                           width=10**6).strip()
                                  .removesuffix("...").strip()), label="value")
    item = f"{key}={text}"
    if "\n" in item or "\x00" in item or item.startswith("-"):
        return  # not one command-line word as a shell passes it
    try:
        overrides = [C.parse_override(item)]
    except C.ConfigError as exc:
        assert exc.path.strip()
        out = CliRunner().invoke(main, ["config", str(source), f"--set={item}"])
        assert out.exit_code == 2 and len(out.stderr.splitlines()) == 1, out.output
        return
    contract(source, kind, overrides, sets=[item])


# ---------------------------------------------------------------- the cases found (regression)

@pytest.mark.parametrize("value", [[], {}, ["twist_under_load"], {"a": 1}, 3, None, True])
def test_a_scene_name_that_is_a_list_or_a_mapping_is_one_error_line(tmp_path, value):
    """800 random mutations found `scene: []` ending in TypeError (unhashable type: 'list')
    and a 30-line traceback from `rodphase run FILE -o x.h5`."""
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump({"scene": value, "rod": {"elements": 20}}))
    with pytest.raises(C.ConfigError) as caught:
        C.load_scene(path, [], SCENES)
    assert caught.value.path == "scene" and "twist_under_load" in caught.value.allowed
    out = CliRunner().invoke(main, ["run", str(path), "-o", str(tmp_path / "x.h5")])
    assert out.exit_code == 2, out.output
    assert out.stderr.splitlines() == [str(out.stderr.splitlines()[0])]
    assert out.stderr.startswith("error: scene: ") and "allowed: one of" in out.stderr
    assert not (tmp_path / "x.h5").exists()


@pytest.mark.parametrize("raw, path", [
    ({"description": float("nan")}, "description"),
    ({"description": [1.0]}, "description"),
    ({"": 1}, "''"),
    ({"rod\nx": 1}, "'rod\\nx'"),
    ({None: 1}, "None"),
    ({"rod": {3: 1}}, "rod.3"),
])
def test_fuzzer_finds_kept_a_nan_description_and_named_odd_keys_on_one_line(raw, path):
    with pytest.raises(C.ConfigError) as caught:
        C.validate_scene({"scene": "twist_under_load", **raw}, SCENES)
    assert caught.value.path == path and "\n" not in str(caught.value)


@pytest.mark.parametrize("value", ["nan", "[]", "3", "''", "null"])
def test_a_sweep_scene_section_set_to_a_scalar_is_refused_by_name(value):
    """Found by the fuzzer: `rodphase config fig3_adaptive --set loading=nan` ended in
    AttributeError ('str' object has no attribute 'pop') where the axes clear their keys;
    and `loading: []` (or 0, or '') was taken for an empty section."""
    overrides = [C.parse_override(f"loading={value}")]
    if value == "null":
        C.load_sweep("fig3_adaptive", overrides, SCENES)  # an empty section: the defaults
        return
    with pytest.raises(C.ConfigError) as caught:
        C.load_sweep("fig3_adaptive", overrides, SCENES)
    assert caught.value.path == "loading" and "a mapping of" in caught.value.allowed
    out = CliRunner().invoke(main, ["config", "fig3_adaptive", f"--set=loading={value}"])
    assert out.exit_code == 2 and out.stderr.startswith("error: loading: "), out.output


def test_a_set_value_yaml_cannot_read_is_one_line():
    with pytest.raises(C.ConfigError) as caught:
        C.parse_override("scene=\x1f")
    assert caught.value.path == "scene" and "\n" not in str(caught.value)
    assert "special characters are not allowed" in caught.value.allowed


# ---------------------------------------------------------------- the store, damaged

QUICK_SWEEP, QUICK_SCENE = C.load_sweep("quick", [], SCENES)
QUICK_TEXT = C.to_yaml(sweep=QUICK_SWEEP, scene=QUICK_SCENE)
QUICK_HASH = C.config_hash(QUICK_SWEEP, QUICK_SCENE)


def writer(path, replace=False):
    return S.open_store(path, config_text=QUICK_TEXT, config_hash=QUICK_HASH, version="0.1.0",
                        kind="sweep", replace=replace)


@pytest.fixture(scope="module")
def good_store(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("good") / "good.h5"
    with writer(path) as store:
        for i, status in enumerate(("ok", "ok", "unstable")):
            store.write_run(f"run-{i:05d}", {"twist_density": 0.5 * i, "extension": 1.1},
                            fake_run(status, seed=i), {"wall_time": 0.1})
    with S.edit_store(path) as store:
        from rodphase.tabulate import classify_store

        classify_store(store)
    return path


def _foreign(path: Path, how: str, draw) -> None:
    """Change a good store's schema the way another program or an old rodphase might."""
    with h5py.File(path, "r+") as f:
        run = f["runs"][sorted(f["runs"])[draw(st.integers(0, 2))]]
        if how == "drop file attribute":
            del f.attrs[draw(st.sampled_from(sorted(f.attrs)))]
        elif how == "file attribute of another type":
            key = draw(st.sampled_from(sorted(f.attrs)))
            f.attrs[key] = draw(st.sampled_from([np.float64("nan"), 99, b"\xff\xfe", "x",
                                                 np.arange(3)]))
        elif how == "drop a run's member":
            del run[draw(st.sampled_from(sorted(run)))]
        elif how == "drop a run attribute":
            del run.attrs[draw(st.sampled_from(sorted(run.attrs)))]
        elif how == "run attribute of another type":
            key = draw(st.sampled_from(sorted(run.attrs)))
            run.attrs[key] = draw(st.sampled_from([np.float64("nan"), 7, "{", "[]", b"\xff"]))
        elif how == "array of another shape":
            name = draw(st.sampled_from(["positions", "directors", "radii", "rest_lengths"]))
            del run[name]
            run[name] = draw(st.sampled_from([np.zeros(0), np.zeros((2, 2)), np.array(["x"],
                                                                                     dtype="S1")]))
        elif how == "history column dropped":
            history = run["history"]
            del history[draw(st.sampled_from(sorted(history)))]
        elif how == "/runs replaced":
            del f["runs"]
            f["runs"] = np.arange(3)
        elif how == "classification damaged":
            if "classification" in f:
                table = f["classification"]
                del table[draw(st.sampled_from(sorted(table)))]
        elif how == "run group empty":
            f["runs"].create_group("run-99999")


FOREIGN = ["drop file attribute", "file attribute of another type", "drop a run's member",
           "drop a run attribute", "run attribute of another type", "array of another shape",
           "history column dropped", "/runs replaced", "classification damaged",
           "run group empty"]
ALLOWED = (S.StoreError, C.ConfigError)


def through_everything(path: Path, out: Path, plot: bool) -> None:
    """classify, plot, resume and the API on a damaged store: success, or one `error:` line
    with exit 2 (CLI) and StoreError or ConfigError (Python); never another exception."""
    for args in (["classify", str(path)],) + ((
            ["plot", str(path), "--kind", "phase", "--no-theory", "-o", str(out / "p.png")],
            ["plot", str(path), "--kind", "topology", "-o", str(out / "t.png")]) if plot else ()):
        result = CliRunner().invoke(main, args)
        assert result.exit_code in (0, 2), (args, result.output, result.exception)
        if result.exit_code == 2:
            lines = result.stderr.splitlines()
            assert len(lines) == 1 and lines[0].startswith("error: "), (args, result.stderr)
    try:  # resume: the same config's writer
        with writer(path) as store:
            store.write_run("run-00010", {}, fake_run(), {})
    except ALLOWED:
        pass
    for call in (lambda: rodphase.table(path), lambda: rodphase.histories(path),
                 lambda: api.classify_file(path)):
        try:
            call()
        except ALLOWED:
            pass
    try:
        with rodphase.open(path) as store:
            for rid in store.run_ids():
                store.read_run(rid)
                store.run_params(rid)
    except ALLOWED:
        pass


@fuzz(max_examples=20)
@given(data=st.data())
def test_damaged_stores_are_read_or_refused_in_one_line(good_store, tmp_path_factory, data):
    folder = tmp_path_factory.mktemp("damaged")
    path = folder / "s.h5"
    shutil.copy(good_store, path)
    kind = data.draw(st.sampled_from(["truncate", "flip", "foreign"]), label="damage")
    blob = bytearray(path.read_bytes())
    if kind == "truncate":
        path.write_bytes(blob[:data.draw(st.integers(0, len(blob) - 1), label="length")])
    elif kind == "flip":
        for _ in range(data.draw(st.integers(1, 8), label="flips")):
            at = data.draw(st.integers(0, len(blob) - 1))
            blob[at] ^= 1 << data.draw(st.integers(0, 7))
        path.write_bytes(bytes(blob))
    else:
        _foreign(path, data.draw(st.sampled_from(FOREIGN), label="how"), data.draw)
    through_everything(path, folder, plot=data.draw(st.integers(0, 5), label="plot") == 0)


def test_a_store_whose_config_attribute_is_not_text_still_draws(good_store, tmp_path):
    """Found by the fuzzer: config_yaml holding a float ended `plot` in AttributeError."""
    path = tmp_path / "s.h5"
    shutil.copy(good_store, path)
    with h5py.File(path, "r+") as f:
        f.attrs["config_yaml"] = np.float64("nan")
    out = CliRunner().invoke(main, ["plot", str(path), "--kind", "phase", "--no-theory", "-o",
                                    str(tmp_path / "p.png")])
    assert out.exit_code == 0, (out.output, out.exception)
    assert C.stored_config(3.0) == {} and C.stored_config(None) == {}


@pytest.mark.parametrize("damage", ["diagnostics NaN", "diagnostics dropped", "positions text",
                                    "history column dropped"])
def test_a_damaged_run_is_one_error_line_naming_the_file_and_run(good_store, tmp_path, damage):
    """Found by the fuzzer: a run attribute of another type ended `classify` in TypeError
    (json.loads of a float, exit 1, a traceback); a missing one in h5py's KeyError text."""
    path = tmp_path / "s.h5"
    shutil.copy(good_store, path)
    with h5py.File(path, "r+") as f:
        run = f["runs/run-00001"]
        if damage == "diagnostics NaN":
            run.attrs["diagnostics"] = np.float64("nan")
        elif damage == "diagnostics dropped":
            del run.attrs["diagnostics"]
        elif damage == "positions text":
            del run["positions"]
            run["positions"] = np.array([b"x"])
        else:
            del run["history/time"]
    out = CliRunner().invoke(main, ["classify", str(path)])
    assert out.exit_code == 2, (out.output, out.exception)
    assert out.stderr.count("\n") == 1 and out.stderr.startswith(f"error: {path}: run run-00001")
    assert "the file is damaged or was not written by rodphase" in out.stderr
    with pytest.raises(S.NotAStore, match="run run-00001 cannot be read"):
        with rodphase.open(path) as store:
            for rid in store.run_ids():
                store.read_run(rid)
