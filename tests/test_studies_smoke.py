"""Every study of studies/ run small (issue #27: a script nothing runs or tests rots).

Each test runs one study as its make target does, but coarse and short (a few dozen elements,
one or two points, fractions of a second of hold), and checks that it wrote what it writes
(its files, its Markdown block, its table) with sane content. The physics is not checked
here: the studies measure it at full size, the other tests check it. A study that pins
thread counts in the environment when imported, or drives `rodphase` commands, runs in its
own process; the others are imported by path and called, which shares numba's loaded
kernels. All of them together took 41-47 s on a shared 2-core AMD EPYC with numba's cache
warm, 60 % of it in ramp_rate and straight_start: each of their sweeps is a `rodphase sweep`
process with a worker process of its own, and each process imports numpy, scipy and numba.

Run small elsewhere: studies/onset_study.py by tests/test_onset.py
(test_the_onset_study_runs_small_and_writes_its_block), studies/robustness.py by
tests/test_robustness.py (its cases, one parametrized row each).
"""

import importlib.util
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

# the long tier (make test-all): the studies run small took 74 s of CPU together
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
STUDIES = ROOT / "studies"
BENCHMARKS = ROOT / "benchmarks"
# studies run small by other test modules (module: what names the study there)
ELSEWHERE = {"onset_study": "test_onset.py", "robustness": "test_robustness.py"}


def study(name: str):
    """studies/<name>.py imported by path (studies/ is not a package)."""
    spec = importlib.util.spec_from_file_location(f"rodphase_study_{name}", STUDIES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up by name
    spec.loader.exec_module(module)
    return module


def script(name: str, *args, cwd: Path) -> subprocess.CompletedProcess:
    """studies/<name>.py in its own process, with this checkout's rodphase first on the path."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in env.get("PYTHONPATH", "")
                                                       .split(os.pathsep) if p])
    done = subprocess.run([sys.executable, str(STUDIES / f"{name}.py"), *map(str, args)],
                          cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return done


def block(doc: Path, name: str) -> str:
    """The text of the named Markdown block a study wrote into `doc`."""
    text = doc.read_text()
    assert text.count(f"<!-- {name}:begin -->") == 1, text
    return text.split(f"<!-- {name}:begin -->\n", 1)[1].split(f"\n<!-- {name}:end -->", 1)[0]


@pytest.fixture
def doc(tmp_path):
    """A Markdown file with text around the blocks the studies write."""
    path = tmp_path / "doc.md"
    path.write_text("before\n")
    return path


@pytest.fixture
def restore_numba_threads():
    """Studies that run scenes in this process set numba's thread count to one."""
    import numba

    threads = numba.get_num_threads()
    yield
    numba.set_num_threads(threads)


# ------------------------------------------------------------------ tables in, tables out

def test_critical_twist_fits_the_line_of_a_known_boundary(tmp_path, capsys):
    # make fig3 / make phase: critical Φa per extension bin of a classified sweep, fitted
    # points at the ten bins' centres (within a bin a sloped line would blur the bracket),
    # random Φa, and one straight point at each end of the extension range (the bin edges)
    rng = np.random.default_rng(0)
    ext = np.r_[1.0, 1.3, rng.choice(1.015 + 0.03 * np.arange(10), 2000)]
    phi = np.r_[0.0, 0.0, rng.uniform(0.0, 2.6, 2000)]
    critical = 2.0 * ext - 1.0
    table = pd.DataFrame({"extension": ext, "phi_a_rest": phi,
                          "phase": np.where(phi < critical, "straight", "plectoneme")})
    table.to_csv(tmp_path / "fig3.csv", index=False)
    study("critical_twist").main([str(tmp_path / "fig3.csv"), "--above", "1.1"])
    out = capsys.readouterr().out
    assert len(re.findall(r"^\| 1\.\d{3} \| [\d.]+ \| [\d.]+ \|$", out, re.M)) == 10
    slope, intercept, r2 = map(float, re.search(
        r"Φa_c = ([\d.-]+)·\(L/L0\) \+ ([\d.-]+), R² = ([\d.]+)", out).groups())
    assert slope == pytest.approx(2.0, abs=0.1) and intercept == pytest.approx(-1.0, abs=0.1)
    assert r2 > 0.99


def test_boundary_error_scores_random_and_adaptive_samples(tmp_path, capsys):
    # make boundary-error: the share of a reference grid the nearest samples label wrongly
    def table(twist, ext):
        phase = np.where(twist < 2.0 * ext - 1.0, "straight", "plectoneme")
        return pd.DataFrame({"run_id": [f"run-{i:05d}" for i in range(len(twist))],
                             "twist_density": twist, "extension": ext, "status": "ok",
                             "phase": phase})

    grid = np.meshgrid(np.linspace(0, 2.6, 24), np.linspace(1.0, 1.3, 24))
    rng = np.random.default_rng(1)
    paths = [tmp_path / f"{name}.csv" for name in ("reference", "random", "adaptive")]
    table(grid[0].ravel(), grid[1].ravel()).to_csv(paths[0], index=False)
    table(rng.uniform(0, 2.6, 40), rng.uniform(1.0, 1.3, 40)).to_csv(paths[1], index=False)
    table(rng.uniform(0, 2.6, 30), rng.uniform(1.0, 1.3, 30)).to_csv(paths[2], index=False)
    study("boundary_error").main(*map(str, paths))
    rows = re.findall(r"^\| (\d+) \| ([\d.]*) \| ([\d.]*) \|$", capsys.readouterr().out, re.M)
    assert [int(k) for k, _, _ in rows] == [10, 20, 30, 40]
    errors = [float(e) for _, a, b in rows for e in (a, b) if e]
    assert len(errors) == 7 and all(0.0 <= e < 0.3 for e in errors)


# ------------------------------------------------------------------ runs in this process

def test_hat_curve_measures_a_coarse_hat_curve_run(tmp_path, capsys):
    # make hat-curve: `rodphase run hat_curve`, then the study on its store
    rodphase = str(Path(sys.executable).with_name("rodphase"))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    subprocess.run([rodphase, "run", "hat_curve", "-o", str(tmp_path / "hat.h5"),
                    "--set", "rod.elements=24", "--set", "loading.twist_rate=2"],
                   check=True, capture_output=True, env=env)
    study("hat_curve").main([str(tmp_path / "hat.h5"), "--plot", str(tmp_path / "plots")])
    row = re.search(r"^\| run \| ([\d.]+) \| ([\d.]+) \| ([\d.]+) \|", capsys.readouterr().out,
                    re.M)
    force, extension, torque = map(float, row.groups())
    assert force == pytest.approx(25.0) and 1.0 < extension < 1.1 and torque > 0
    assert (tmp_path / "plots" / "hat_run.png").stat().st_size > 10_000


def test_figures_runs_one_figure_small_and_redraws_it(tmp_path, restore_numba_threads):
    # make figS3 (and make figures, fig2a, ...): the scene's store, its pictures, its numbers
    figures = study("figures")
    small = ["--out", str(tmp_path), "--only", "figS3", "--set", "rod.elements=24",
             "--set", "solver.hold_max_time=0.5"]
    assert figures.main(small) == 0
    for name in ("figS3.h5", "figS3.png", "figS3_shape.png"):
        assert (tmp_path / name).stat().st_size > 1000, name
    numbers = json.loads((tmp_path / "figS3.json").read_text())
    assert numbers["figure"] == "figS3" and numbers["turns_put_in"] > 5
    assert numbers["escape_count"] == len(numbers["events"])
    assert figures.main(small + ["--replot"]) == 0  # from the store, no simulation
    assert json.loads((tmp_path / "figS3.json").read_text())["events"] == numbers["events"]
    with pytest.raises(SystemExit):
        figures.main(["--out", str(tmp_path), "--only", "fig9"])


def test_damping_sweeps_runs_each_command_small(tmp_path, capsys, restore_numba_threads):
    # make damping-sweeps: the same work under each damping variant, one line per variant
    damping = study("damping_sweeps")
    coarse = ["--set", "rod.elements=24", "--set", "solver.refine_up_to=24"]
    assert damping.main(["speed", "--steps", "50", "--rounds", "1", "--set", "rod.elements=48"]) == 0
    assert damping.main(["fig3", "--samples", "1", "--chunk", "1", "--out", str(tmp_path)]
                        + coarse) == 0
    assert damping.main(["demo", "--variants", "default", "--out", str(tmp_path),
                         "--set", "sweep.samples=2"] + coarse) == 0
    # runs studies/figures.py in a process per variant
    assert damping.main(["figures", "--variants", "default", "--only", "figS3", "--out",
                         str(tmp_path), "--set", "rod.elements=24",
                         "--set", "solver.hold_max_time=0.5"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"^default  dt [\d.e-]+ s  µs/step min [\d.]+", out, re.M)
    assert re.search(r"^both     dt [\d.e-]+ s  µs/step min [\d.]+", out, re.M)
    assert re.search(r"^both     1 points: .* phases \{'", out, re.M)
    assert re.search(r"^both     phase differs from default at [01] points", out, re.M)
    assert re.search(r"^default  2 runs: ", out, re.M)
    assert re.search(r"^  figS3 ", out, re.M) and (tmp_path / "default" / "figS3.png").exists()
    with pytest.raises(SystemExit):
        damping.main(["speed", "--variants", "nonesuch"])


def test_self_passage_tells_a_coarse_runs_link_jumps_apart(capsys):
    # make self-passage: a Fig S3-like point (no end bodies) loses link around its end
    assert study("self_passage").main([
        "--twist-density", "1.6", "--extension", "1.04", "--elements", "24", "--interval", "0.01",
        "--set", "ends.start_body=none", "--set", "ends.end_body=none",
        "--set", "loading.twist_rate=1", "--set", "loading.quasi_static_below=0"]) == 0
    out = capsys.readouterr().out
    jumps = int(re.match(r"\w+: (\d+) link jump\(s\)", out).group(1))
    verdicts = re.findall(r"^t = [\d.]+ s: ΔLk [+-][\d.]+, .*: (self-passage|twist wrap|around an "
                          r"end)", out, re.M)
    assert jumps >= 1 and len(verdicts) >= 1


def test_vibration_source_holds_each_variant(capsys):
    # make vibration-source: the settled coil held again under each variant of the model
    assert study("vibration_source").main([
        "--hold", "0.2", "--set", "rod.elements=64", "--set", "loading.twist_density=1.55",
        "--set", "loading.twist_rate=2", "--set", "solver.hold_max_time=0.5"]) == 0
    out = capsys.readouterr().out
    assert "kinetic energy [J] in s 0-0.05, 0.05-0.1, 0.1-0.15, 0.15-0.2" in out
    rows = re.findall(r"^(.+) \| (ok|not_converged|unstable) \| ([^|]+) \|", out, re.M)
    assert [name for name, _, _ in rows] == ["incompressible law (as run)",
                                             "compressible (quadratic) law", "neo-Hookean law",
                                             "no contact dashpot"]
    assert float(rows[0][2].split(",")[0]) > 0


def test_crosscheck_runs_the_first_moments_and_compares(tmp_path, capsys):
    # make crosscheck: the example's settings in rodphase, against the stored PyElastica run
    cc = study("crosscheck_pyelastica")
    assert cc.main(["rodphase", "solenoid", "--final-time", "0.1",
                    "-o", str(tmp_path / "rp.npz")]) == 0
    assert cc.main(["compare", "solenoid", "--rodphase", str(tmp_path / "rp.npz"),
                    "--png", str(tmp_path / "cc.png")]) == 0
    out = capsys.readouterr().out
    assert re.search(r"^\| 0\.1 \| 0\.000 / 0\.000 \|", out, re.M)
    assert (tmp_path / "cc.png").stat().st_size > 10_000
    with pytest.raises(SystemExit):
        cc.main(["rodphase", "trefoil"])


def test_crosscheck_reference_runs_a_moment_of_pyelastica(tmp_path):
    # make crosscheck-reference: hours in PyElastica 1.0 (the bench extra); here 200 steps
    pytest.importorskip("elastica", reason="PyElastica is the bench extra (make bench-extra)")
    cc = study("crosscheck_pyelastica")
    assert cc.main(["reference", "solenoid", "--final-time", "0.005", "--raw",
                    str(tmp_path / "raw.npz"), "-o", str(tmp_path / "reduced.npz")]) == 0
    assert np.load(tmp_path / "reduced.npz")["time"].size >= 1


def test_crosscheck_fig3_runs_a_moment_of_a_failed_point_in_pyelastica(tmp_path):
    # `fig3 PHI EXT`: a Fig 3 point from rest in PyElastica 1.0 (minutes); here the first
    # 0.02 s of the load ramp at the coarsest map resolution
    pytest.importorskip("elastica", reason="PyElastica is the bench extra (make bench-extra)")
    cc = study("crosscheck_pyelastica")
    phi, extension = cc.FIG3_FAILED[2]
    out = tmp_path / "fig3.npz"
    assert cc.main(["fig3", str(phi), str(extension), "--elements", "20", "--final-time", "0.02",
                    "-o", str(out)]) == 0
    r = np.load(out)
    info = json.loads(str(r["info"]))
    assert info["blew_up"] is None and r["time"][-1] == pytest.approx(0.02, abs=info["dt"])
    # the scene's load for L/L0 = e, F = E·A0·(1 − 1/e), and its twist Φa·L0/a0 in turns
    assert info["force"] == pytest.approx(1e6 * np.pi * 0.025**2 * (1 - 1 / extension))
    assert info["turns"] == pytest.approx(phi / 0.025 / (2 * np.pi))
    # the same rod: rodphase's shear stiffness 4GA/3, not PyElastica's 27/28·G·A
    assert info["shear"] == "rodphase"
    assert info["shear_stiffness"] == pytest.approx(4 / 3 * 2e6 / 3 * np.pi * 0.025**2)
    assert np.all(r["max_shear"] < 1.0) and np.all(r["max_stretch"] < 1.01)


# ------------------------------------------------------------------ in their own process

def test_stability_map_bisects_a_few_rods(tmp_path, doc):
    # make stability-map (pins NUMBA_NUM_THREADS when imported: its own process)
    script("stability_map", "--quick", "--steps", "200", "--no-contact", "--json",
           tmp_path / "map.json", "--png", tmp_path / "map.png", "--write", doc, cwd=tmp_path)
    cases = json.loads((tmp_path / "map.json").read_text())["cases"]
    assert {c["n"] for c in cases} == {20, 50}
    assert all(0.3 < c["f_stable"] < 4.0 for c in cases)
    assert (tmp_path / "map.png").stat().st_size > 10_000
    assert "| straight | 20 |" in block(doc, "stability_map")


def test_ramp_rate_compares_a_rate_with_the_reference(tmp_path, doc):
    # make ramp-rate: sweeps through `rodphase sweep`, one point, coarse
    script("ramp_rate", "--samples", "1", "--rates", "4", "--jobs", "1", "--out", tmp_path,
           "--set", "rod.elements=24", "--set", "solver.refine_up_to=24", "--write", doc,
           cwd=tmp_path)
    text = block(doc, "ramp_rate")
    assert re.search(r"^\| reference \(0\.5, n = 140, safety 0\.25\) \| 1 \| ", text, re.M)
    assert re.search(r"^\| 4 \| 1 \| [\d.]+ \| \d+ \| \d+ \| \w+ 1 \| [01]/1 \|", text, re.M)
    assert (tmp_path / "rate_4_1.h5").exists() and (tmp_path / "reference_1.h5").exists()


def test_straight_start_compares_the_two_starts(tmp_path, doc):
    # make straight-start: sweeps through `rodphase sweep`, one point, coarse
    script("straight_start", "--samples", "1", "--rounds", "1", "--jobs", "1", "--out",
           tmp_path, "--reference", tmp_path / "none.h5", "--set", "rod.elements=24",
           "--set", "solver.refine_up_to=24", "--write", doc, cwd=tmp_path)
    text = block(doc, "straight_start")
    for variant in ("0", "0.8"):
        assert re.search(rf"^\| {variant} \| 1 \| [\d.]+ \| \d+ \| \w+ 1 \| [01]/1 \|", text, re.M)


def test_map_variants_compares_a_variant_with_the_default_point_by_point(tmp_path, doc):
    # make study-shear and the others: sweeps through `rodphase sweep`, one point, coarse
    script("map_variants", "shear_x10", "--samples", "1", "--jobs", "1", "--out", tmp_path,
           "--set", "rod.elements=24", "--set", "solver.refine_up_to=24", "--write", doc,
           "--figure", tmp_path / "maps.png", cwd=tmp_path)
    text = block(doc, "map_variants_shear_x10")
    assert re.search(r"^\| as it ships \| straight \d, plectoneme \d, .* \| — \| — \|", text, re.M)
    assert re.search(r"^\| shear stiffness × 10 \| .* \| [01]/1 \| ", text, re.M)
    assert (tmp_path / "shear_x10_1.h5").exists() and (tmp_path / "maps.png").stat().st_size > 5000
    # the variant's store holds the stiffer shear: 10 × the shipped scene's 4GA0/3
    from rodphase import api

    with api.open(tmp_path / "shear_x10_1.h5") as store:
        config = store.attrs["config_yaml"]
    assert "shear_stiffness: 17453" in config


# ------------------------------------------------------------------ every script has a runner

def test_every_study_is_run_small_by_a_test():
    here = Path(__file__).read_text()
    for path in sorted(STUDIES.glob("*.py")):
        name = path.stem
        if name in ELSEWHERE:
            assert f"studies/{name}.py" in (ROOT / "tests" / ELSEWHERE[name]).read_text()
        else:
            assert re.search(rf'study\("{name}"\)|script\("{name}"', here), (
                f"studies/{name}.py has no smoke test in tests/test_studies_smoke.py")


def test_every_benchmark_and_study_is_run_by_a_make_target():
    # issue #27's done criterion is "reachable from a make target or a test"; every one of
    # them has a target, which `make help` lists
    recipes = (ROOT / "Makefile").read_text() + (STUDIES / "figures.mk").read_text()
    run = set(re.findall(r"\$\(BIN\)/python ((?:benchmarks|studies)/\w+\.py)", recipes))
    scripts = {f"{p.parent.name}/{p.name}" for d in (BENCHMARKS, STUDIES) for p in d.glob("*.py")}
    assert scripts - run == set(), "scripts no make target runs"
    assert run - scripts == set(), "make targets that run scripts that do not exist"


def test_static_path_steps_a_coarse_column_and_compares_with_the_kernel(tmp_path, doc):
    # make static-path: the kernel settles a coarse rod, the corrector steps its twist once;
    # the kernel runs both comparison points on its own, and the one past the path's end
    # also from the path's last state (where the kernel takes over)
    script("static_path", "--elements", "24", "--start", "0.9", "--stop", "0.905", "--step",
           "0.005", "--compare", "0.905", "0.95", "--write", doc, cwd=tmp_path)
    text = block(doc, "static_path_25")
    assert "n = 24, 25 F_C, 2 soft modes" in text
    assert re.search(r"^\| 0\.905 \| \d+ \| \d+ \| ", text, re.M)
    assert re.search(r"^\| 0\.905 \| \w+, [\d.]+ \| -?[\d.]+, -?[\d.]+ \| static \| ", text,
                     re.M)
    assert re.search(r"^\| 0\.95 \| \w+, [\d.]+ \| -?[\d.]+, -?[\d.]+ \| kernel from the "
                     r"last static state \(\w+\), [\d.]+ \| ", text, re.M)


def test_hold_budget_splits_a_small_path_maps_work(tmp_path):
    # make hold-budget: a paths map of 4 coarse samples in 2 columns, then the budget
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in env.get("PYTHONPATH", "")
                                                       .split(os.pathsep) if p])
    store = tmp_path / "paths.h5"
    rodphase = str(Path(sys.executable).with_name("rodphase"))  # the installed command
    done = subprocess.run([rodphase, "sweep", "fig3_paths", "-o", store,
                           "--jobs", "1", "--set", "sweep.samples=4", "--set", "sweep.columns=2",
                           "--set", "rod.elements=24", "--set", "solver.refine_up_to=24"],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode in (0, 1), done.stdout[-3000:] + done.stderr[-3000:]
    out = script("hold_budget", store, cwd=tmp_path).stdout
    assert re.search(r"dynamic runs; element-steps: ", out), out
    assert re.search(r"\d+ holds: rod time median [\d.]+ s", out), out


def test_energy_audit_replays_the_last_second_before_a_trip(doc):
    # make energy-audit: a coarse rod twisted far past what 24 elements resolve trips the
    # 135° guard; the audit replays states of the second before it and writes its table
    ea = study("energy_audit")
    assert ea.main(["--point", "1.5", "1.0525", "--samples", "3", "--set", "rod.elements=24",
                    "--set", "solver.refine_up_to=0", "--set", "solver.slow_down_to=0",
                    "--write", str(doc)]) == 0
    text = block(doc, "energy_audit")
    assert "unstable" in text and "135°" in text
    rows = re.findall(r"^\| (\d+\.\d+) \| ([^|]+) \|", text, re.M)
    times = [float(t) for t, _ in rows]
    assert len(rows) == 3 and times == sorted(times) and times[-1] - times[0] <= 1.0
    assert all(float(kinetic) > 0 for _, kinetic in rows)


def test_energy_audit_power_is_what_the_law_adds_to_the_bend_energys_rate():
    # The study's unaccounted power, −(3/2)·Σ (κ−κ0)·B·(κ−κ0)·D0·ε̇/ε⁴, checked against an
    # independent evaluation: the naive twin's bend-twist loads (tests/naive.py, shear and
    # inertia off) give the law's power P = Σ F·v + τ·ω, and V_b = Σ ½·D0·(κ−κ0)·B·(κ−κ0)/ε³
    # is differentiated along the motion (x + h·v, each frame turned by h·ω) by central
    # differences; the audit's claim is P + dV_b/dt = that power. Tolerance θ²/12 of the
    # powers' size: the bend couple is the rotational gradient of V_b only to first order in
    # the rotation θ between neighbouring frames (test_naive_twin.py's gradient test; θ up to
    # 0.34 here: 1 % of the powers). The compressible law (no 1/ε³) adds nothing to the same
    # tolerance, and the incompressible law's power is far outside it: not a tautology.
    import naive as N
    from test_naive_twin import random_rod

    ea = study("energy_audit")
    for seed in range(3):
        props, rod, state, rng = random_rod(seed)
        rod.rest_curvature[:] *= 0.3
        x, v, Q, w = (N.to_twin(a) for a in (state.x, state.v, state.Q, state.w))
        for incompressible in (True, False):
            def bend_energy(x, Q):
                kappa, _ = N.curvatures(Q, rod)
                d = kappa - rod.rest_curvature
                length = np.linalg.norm(np.diff(x, axis=0), axis=1)
                eps = 0.5 * (length[:-1] + length[1:]) / rod.rest_voronoi
                scale = eps ** 3 if incompressible else 1.0
                return float(np.sum(0.5 * rod.rest_voronoi * np.sum(d * d * rod.bend_stiffness, 1)
                                    / scale))

            loads = N.internal_loads(x, v, Q, w, rod, incompressible=incompressible,
                                     f_shear=0.0, f_inertia=0.0)
            power = float(np.sum(loads.force * v) + np.sum(loads.torque * w))
            h = 1e-6

            def along(sign):
                turned = np.array([N.rotation_matrix(-sign * h * w[i]) @ Q[i]
                                   for i in range(len(Q))])
                return bend_energy(x + sign * h * v, turned)

            rate = (along(1) - along(-1)) / (2 * h)
            theta = np.arccos(np.clip(loads.cosines, -1, 1)).max()
            tolerance = theta ** 2 / 12 * (abs(power) + abs(rate))
            expected = (ea.unaccounted_bend_power(x, v, Q, rod.rest_length, rod.bend_stiffness,
                                                  rod.rest_curvature).sum()
                        if incompressible else 0.0)
            assert abs(power + rate - expected) <= tolerance, (seed, incompressible)
            if incompressible:
                assert abs(expected) > 2 * tolerance


def test_energy_audit_stretch_power_is_what_the_law_adds_to_the_stretch_energys_rate():
    # The same check for the stretch-shear law (bend and inertia off): its force and shear
    # couple are the gradient of V_s = Σ ½·l0·(σ−σ0)·S·(σ−σ0) times 1/e, so P + dV_s/dt =
    # Σ (1 − 1/e)·dV_s/dt, the audit's column. Here the law is the exact gradient (no
    # first-order log): the tolerance is the central differences' h² error and round-off,
    # 1e-6 of the powers; the compressible law (no 1/e) leaves 0 to the same tolerance.
    import naive as N
    from test_naive_twin import random_rod

    ea = study("energy_audit")
    for seed in range(3):
        props, rod, state, rng = random_rod(seed)
        x, v, Q, w = (N.to_twin(a) for a in (state.x, state.v, state.Q, state.w))

        def stretch_energy(x, Q):
            return N.internal_loads(x, np.zeros_like(x), Q, np.zeros_like(w), rod,
                                    incompressible=False, f_bend=0.0).stretch_energy

        h = 1e-6
        turned = [np.array([N.rotation_matrix(-sign * h * w[i]) @ Q[i] for i in range(len(Q))])
                  for sign in (1, -1)]
        rate = (stretch_energy(x + h * v, turned[0]) - stretch_energy(x - h * v, turned[1])) / (2 * h)
        expected = ea.unaccounted_stretch_power(x, v, Q, w, rod.rest_length, rod.shear_stiffness,
                                                rod.rest_shear).sum()
        for incompressible in (True, False):
            loads = N.internal_loads(x, v, Q, w, rod, incompressible=incompressible,
                                     f_bend=0.0, f_inertia=0.0)
            power = float(np.sum(loads.force * v) + np.sum(loads.torque * w))
            tolerance = 1e-6 * (abs(power) + abs(rate))
            assert abs(power + rate - (expected if incompressible else 0.0)) <= tolerance, (
                seed, incompressible)
        assert abs(expected) > 1e3 * tolerance


def test_twist_into_writhe_runs_a_row_a_moment_and_tabulates_it(tmp_path, capsys):
    # make twist-into-writhe: rodphase's rows of the SolenoidsCase, one change at a time,
    # against the cached PyElastica references; here one row, 0.1 s of it
    tiw = study("twist_into_writhe")
    assert tiw.main(["rows", "solenoid", "--only", "no_thinning", "--final-time", "0.1",
                     "--out", str(tmp_path)]) == 0
    assert tiw.main(["table", "solenoid", "--out", str(tmp_path), "--png", str(tmp_path / "t.png")]) == 0
    out = capsys.readouterr().out
    assert "| rodphase: thinning force off" in out
    # the stored PyElastica SolenoidsCase: four steps (loops) in its twist
    assert re.search(r"^\| PyElastica 1\.0 \| ok \| 0 \| 66\.0 \| 4 \|", out, re.M)
    assert (tmp_path / "t.png").stat().st_size > 10_000
