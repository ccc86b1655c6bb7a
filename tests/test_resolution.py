"""Resolution from the rod: rod.elements: auto follows the rod's slenderness and twist, a
given count is kept (with a warning below what the scene needs), and refinement limits follow
the count (issue #46)."""

import math
import warnings

import pytest
import yaml

import rodphase
from rodphase import config as C


def elements(name="twist_under_load", **settings):
    with warnings.catch_warnings():
        warnings.simplefilter("error", C.ResolutionWarning)  # none of these may warn
        return rodphase.load(name, settings).rod.elements


def test_the_shipped_scenes_and_sweeps_keep_their_counts_for_the_papers_rod():
    # stated as element lengths now (0.4 and 0.5 rest radii, the demo 0.625), the same counts
    assert elements() == 100 and elements("fig2b_solenoid") == 100 and elements("hat_curve") == 80
    for sweep, count, limit in (("fig3_paper", 80, 160), ("quick", 64, 128)):
        _, scene = rodphase.load_sweep(sweep)
        assert scene.rod.elements == count and scene.rod.elements_from == "auto"
        assert C.refine_limit(scene) == limit


@pytest.mark.parametrize("change, expected", [
    ({}, 80),                                  # the paper's rod: L0/a0 = 40, two elements a radius
    ({"rod.radius": 0.0125}, 160),             # radius x 1/2: twice as slender
    ({"rod.radius": 0.05}, 40),                # radius x 2
    ({"rod.length": 2.0}, 160),                # length x 2
    ({"material.youngs_modulus": 1.0e7}, 80),  # E x 10: the same geometry (dt follows E)
])
def test_auto_follows_the_rods_slenderness(change, expected):
    settings = {"rod.element_length": 0.5, "loading.twist_density": 1.0} | change
    assert elements(**settings) == expected


def test_auto_follows_the_twist_when_it_needs_more():
    # 40 turns over the paper's rod: 90° per element needs 160 elements, more than 80
    twist = {"rod.element_length": 0.5, "loading.twist_density": None}
    assert elements(**twist, **{"loading.twist_turns": 40}) == 160
    assert elements(**twist, **{"loading.twist_turns": 10}) == 80


def test_auto_is_recomputed_when_a_resolved_config_changes_the_rod():
    cfg = rodphase.load("twist_under_load", {"rod.element_length": 0.5})
    again = C.validate_scene(C.apply_overrides(cfg.plain(), [("rod.radius", 0.0125)]))
    assert again.rod.elements == 160 and again.rod.elements_from == "auto"
    given = C.validate_scene(C.apply_overrides(cfg.plain(), [("rod.elements", 300)]))
    assert given.rod.elements == 300 and given.rod.elements_from == "given"
    back = C.validate_scene(C.apply_overrides(given.plain(), [("rod.elements", "auto")]))
    assert back.rod.elements == 80 and back.rod.elements_from == "auto"


def test_a_given_count_is_kept_and_warned_about_below_what_the_rod_needs():
    thin = {"rod.radius": 0.0125, "rod.elements": 60, "loading.twist_density": 1.0}
    with pytest.warns(C.ResolutionWarning, match=r"rod\.elements = 60 is below the 80 "):
        cfg = rodphase.load("twist_under_load", thin)
    assert cfg.rod.elements == 60 and cfg.rod.elements_from == "given"
    # the twist too: 30 turns at 120° an element at most needs 90
    with pytest.warns(C.ResolutionWarning, match=r"below the 90 .*30 turns"):
        rodphase.load("twist_under_load", {"rod.elements": 60, "loading.twist_turns": 30,
                                           "loading.twist_density": None})
    # no contact: the radius sets no length (Greenhill's rod, 100 elements of 2.9 radii)
    assert elements("helical_buckling") == 100


def test_a_sweep_below_the_rods_resolution_says_so_once(tmp_path, capsys):
    # every one of the 4 samples is validated before launch, and each is below the rod's
    # resolution: the CLI's warning hook says so in one line
    import rodphase.cli as cli
    from rodphase.sweep import plan

    data = {"sweep": {"scene": "twist_under_load",
                      "set": {"rod.radius": 0.0125, "rod.elements": 60},
                      "axes": {"twist_density": [0.2, 0.4], "extension": [1.05, 1.1]},
                      "sampler": "grid", "samples": 4, "seed": 1}}
    path = tmp_path / "thin.yaml"
    path.write_text(yaml.safe_dump(data))
    saved = warnings.showwarning
    try:
        with warnings.catch_warnings():
            cli._warn_once_per_key()
            sweep, scene = rodphase.load_sweep(path)
            assert len(plan(sweep, scene)) == 4
    finally:
        warnings.showwarning = saved
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("warning:")]
    assert len(lines) == 1 and "rod.elements = 60 is below the 80" in lines[0], lines


def test_refinements_double_the_scenes_count_not_the_refined_ones():
    cfg = rodphase.load("twist_under_load", {"rod.elements": 48, "solver.refinements": 2})
    assert C.refine_limit(cfg) == 192
    assert C.refine_limit(rodphase.load("twist_under_load", {"solver.refine_up_to": 150})) == 150
    assert C.refine_limit(rodphase.load("twist_under_load")) == 100


@pytest.mark.slow
@pytest.mark.parametrize("change", [{"rod.radius": 0.0125}, {"rod.radius": 0.05},
                                    {"rod.length": 2.0}, {"material.youngs_modulus": 1.0e7}])
def test_other_filaments_run_past_their_onset_at_the_resolution_auto_picks(change):
    # each rod twisted to 1.25 x its straight rod's onset at L/L0 = 1.1 from a quasi-static
    # start: a buckled shape, reached with the elements auto chose, and no guard tripped
    from rodphase.rod.onset import straight_onset_turns
    from rodphase.scenes import rod_from
    from rodphase.tabulate import summarize

    settings = {"rod.element_length": 0.5, "loading.force_multiple": None,
                "loading.extension": 1.1, "loading.quasi_static_below": 0.8,
                "loading.twist_rate": 1.0, "solver.hold_max_time": 10.0} | change
    probe = rodphase.load("twist_under_load", settings | {"loading.twist_density": 0.5})
    onset = straight_onset_turns(rod_from(probe), C.straight_extension(probe))
    phi = 1.25 * onset * 2 * math.pi * probe.rod.radius / probe.rod.length
    cfg = rodphase.load("twist_under_load", settings | {"loading.twist_density": phi})
    result = rodphase.run(cfg)
    assert result.status in ("ok", "not_converged"), result.message
    assert summarize(result)["phase"] != "straight"
    assert result.diagnostics["elements"] == cfg.rod.elements
