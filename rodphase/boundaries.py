"""The phase diagram's answer as lines: the straight rod's onset, the plectoneme–solenoid
boundary and the triple point, each with its bracket (issue #45).

The onset Φa_c(L/L0) comes from the model's own static stability (rod/onset.py): no dynamics.
The plectoneme–solenoid boundary comes from runs of the scene's own dynamic protocol placed
by bracketing. It runs nearly along the twist axis (solenoids win above an extension), so it
is traced along lines of constant twist Φa ("levels"): on a level, the rod is buckled below
the extension e*(Φa) where the onset line reaches Φa and straight above it. A level starts
in its middle (or, once a neighbour has a boundary, either side of that one) and searches
until a plectoneme lies below a solenoid (Level.search): that bracket bisection narrows to
`tolerance` in L/L0. A level whose top, just below e*, is still a plectoneme has none: the
plectoneme gives way to the straight rod directly. Between the highest level without a
boundary and the lowest with one lies the triple point, where the boundary meets the onset;
new levels bisect that gap down to `twist_tolerance` in Φa. With `hysteresis`, return runs
twist past the onset and back (hysteresis_jobs).

What near the triple point is normal is kept, not hidden: a `mixed` run counts on the
plectoneme side, and the mixed runs between the last plectoneme and the first solenoid are
the band it reports (`mixed_width`); a failed run inside a bracket is stepped around (the
next probe takes the wider side) and counted; a hold that ran out of time keeps its label;
a solenoid below a plectoneme on one level is flagged `non_monotone`.

Every run is an ordinary run of the store (its id is its point; its params:
twist_density, extension, and where it was placed: `level`, the level's index; `step`, its
place in that level's bracketing), so
classify, plot, resume and Dask treat it as any sweep's. The rounds are a function of the
sweep and of the labels of the runs already stored: a killed trace resumes the same rounds.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from . import config

KINDS = ("onset", "plectoneme_solenoid", "triple_point", "restraighten")

# columns of the boundaries table (unit, meaning): what --csv writes and the store keeps
COLUMNS = {
    "kind": ("", "onset, plectoneme_solenoid, triple_point or restraighten"),
    "extension": ("1", "L/L0 of the boundary point (the bracket's middle)"),
    "twist_density": ("1", "Phi*a = theta*a0/L0 of the boundary point"),
    "extension_low": ("1", "L/L0 bracket, low side"),
    "extension_high": ("1", "L/L0 bracket, high side"),
    "twist_density_low": ("1", "Phi*a bracket, low side"),
    "twist_density_high": ("1", "Phi*a bracket, high side"),
    "mixed_width": ("1", "L/L0 from the lowest mixed run above the last plectoneme to the "
                    "first solenoid (0: no mixed run there)"),
    "failed": ("1", "runs on this level that failed or did not converge"),
    "non_monotone": ("", "a solenoid below a plectoneme on this level"),
    "greenhill_sheared": ("1", "the sheared clamped Greenhill Phi*a (the model's n -> inf)"),
    "greenhill": ("1", "the unsheared clamped Greenhill Phi*a"),
    "note": ("", "what to know about this row"),
}


@dataclass(frozen=True)
class Settings:
    """How finely to trace: `tolerance` the width in L/L0 of a plectoneme–solenoid bracket,
    `twist_tolerance` the width in Φa of the triple point's bracket, `levels` the twist
    levels the first round spreads over the box, `onset_points` the extensions the onset
    line is computed at (relative accuracy `onset_tolerance` in Φa)."""

    # widths of the brackets: ±0.005 in L/L0 and ±0.05 in Φa about their middles, the
    # issue's targets; the 200-point map's points are ~0.02 in L/L0 apart
    tolerance: float = 0.01
    twist_tolerance: float = 0.1
    levels: int = 6
    onset_points: int = 41
    onset_tolerance: float = 1e-4
    # --hysteresis: loads along the onset line, and the step down in twist between the holds
    # of the return, a fraction of the load's onset twist (the restraighten bracket's width)
    hysteresis_loads: int = 6
    hysteresis_step: float = 0.025

    @classmethod
    def of(cls, sweep) -> Settings:
        given = dict(sweep.get("boundary") or {})
        return cls(**{k: given[k] for k in ("tolerance", "twist_tolerance", "levels",
                                            "hysteresis_loads", "hysteresis_step") if k in given})


def check_traceable(sweep) -> None:
    """Refuse, before anything runs, a sweep whose axes the method cannot trace."""
    if set(sweep.axes) != {"twist_density", "extension"}:
        raise config.ConfigError("sweep.axes", dict(sweep.axes),
                            "twist_density and extension (the axes boundaries are traced in)")


# ---------------------------------------------------------------- the onset line (static)

def onset_line(scene, sweep, settings: Settings) -> pd.DataFrame:
    """The model's onset over the box's extensions: rows of kind `onset`, with the sheared and
    unsheared clamped Greenhill twists beside it. Raises ConfigError for a scene whose straight
    rod has no onset here (not clamped and loaded, not the paper's law)."""
    from .tabulate import onset_lines

    lo, hi = sweep.axes["extension"]
    extensions = np.linspace(lo, hi, settings.onset_points)
    lines = onset_lines(scene.plain(), extensions)
    if lines is None:
        raise config.ConfigError("sweep.scene", scene.scene,
                            "a scene whose rod is clamped, loaded at its end and turned there, "
                            "under the paper's law (the onset is that rod's)")
    phi = lines["model_rest"].to_numpy()
    return pd.DataFrame({
        "kind": "onset", "extension": extensions, "twist_density": phi,
        "extension_low": extensions, "extension_high": extensions,
        "twist_density_low": phi * (1 - settings.onset_tolerance),
        "twist_density_high": phi * (1 + settings.onset_tolerance),
        "greenhill_sheared": lines["sheared_rest"].to_numpy(),
        "greenhill": lines["greenhill_rest"].to_numpy(),
        "note": "",
    })


def onset_twist(table: pd.DataFrame, extension):
    """Φa_c at `extension` (scalar or array) from the onset rows of a boundaries table (its
    NaN rows, where the rod was too coarse to answer, left out), interpolated linearly."""
    onset = table[(table["kind"] == "onset") & table["twist_density"].notna()]
    return np.interp(extension, onset["extension"], onset["twist_density"])


def onset_extension(onset: pd.DataFrame, twist: float) -> float:
    """e*(Φa): the extension at which the onset line reaches `twist` (it rises with the
    extension); inf above the box (the rod buckles at every extension of it), the box's
    lowest below it (straight everywhere)."""
    ok = onset["twist_density"].notna()
    e, phi = onset["extension"][ok].to_numpy(), onset["twist_density"][ok].to_numpy()
    if twist >= phi[-1]:
        return math.inf
    return float(np.interp(twist, phi, e)) if twist > phi[0] else float(e[0])


def check_box(onset: pd.DataFrame, sweep) -> None:
    """Refuse a box with no buckled state in it: the twist axis stays below the onset."""
    top = sweep.axes["twist_density"][1]
    lowest = float(onset["twist_density"].min())
    if not top > lowest:
        raise config.ConfigError("sweep.axes.twist_density", list(sweep.axes["twist_density"]),
                            f"a range that reaches the straight rod's onset (Phi*a {lowest:.3g} "
                            "at the box's lowest extension): below it every run stays straight "
                            "and there is no boundary to trace")


def check_settings(onset: pd.DataFrame, settings: Settings) -> None:
    """Refuse a tolerance finer than the runs can tell apart: within classify.ONSET_BAND of
    the onset a run's label depends on how it was pushed (docs/explanation/
    reproducibility.md), and the highest run of a level sits `tolerance` below the onset,
    so `tolerance` must clear that band's width in L/L0 (through the onset's slope), and
    `twist_tolerance` its width in Φa."""
    from .classify import ONSET_BAND

    ok = onset["twist_density"].notna()
    e, phi = onset["extension"][ok].to_numpy(), onset["twist_density"][ok].to_numpy()
    slope = np.abs(np.gradient(phi, e))
    band_extension = float(np.max(2 * ONSET_BAND * phi / np.maximum(slope, 1e-12)))
    band_twist = float(2 * ONSET_BAND * phi.max())
    if settings.tolerance < band_extension:
        raise config.ConfigError("sweep.boundary.tolerance", settings.tolerance,
                                 f"at least {band_extension:.2g} in L/L0: a finer bracket is "
                                 "inside the onset's band, where a run's label depends on how "
                                 "it was pushed")
    if settings.twist_tolerance < band_twist:
        raise config.ConfigError("sweep.boundary.twist_tolerance", settings.twist_tolerance,
                                 f"at least {band_twist:.2g} in Phi*a: a finer bracket is inside "
                                 "the onset's band, where a run's label depends on how it was "
                                 "pushed")


# ---------------------------------------------------------------- bracketing (dynamic)

BUCKLED = ("plectoneme", "solenoid", "mixed")
# failed runs inside one bracket after which it is not narrowed further
MAX_FAILED = 3


@dataclass
class Level:
    """One line of constant twist: its probes (extension → label) and what they bracket."""

    index: int
    twist: float
    low: float  # the box's lowest extension
    high: float  # just below e*: the highest extension that still buckles
    probes: dict[float, str] = field(default_factory=dict)
    # where a neighbouring level found its boundary: the search starts around it
    guess: float | None = None

    def first_probes(self, tolerance: float) -> list[float]:
        """Where the level starts: a tolerance either side of the guess (a boundary runs
        nearly along the twist axis, so a neighbour's is close), or, with none, the middle of
        the level. Its top and the box's lowest extension, where runs are slowest (dense
        plectonemes and the corner settle slowly), are run only if the search needs them."""
        if self.guess is None:
            return [0.5 * (self.low + self.high)]
        return sorted({max(self.low, self.guess - tolerance), min(self.high, self.guess + tolerance)})

    def search(self, tolerance: float) -> float | None:
        """The next extension while there is no bracket yet, or None. With no solenoid, the
        level's top (the last extension to buckle): a plectoneme there means no boundary on
        this level; a failed top is stepped under, half way to the highest buckled run.
        With solenoids and nothing buckled below the lowest, down from it: half way to the
        box's lowest extension (no guess), or twice as far as the last step (from a guess);
        the lowest extension itself once the step reaches it. MAX_FAILED failed runs end the
        search."""
        points = self.ordered()
        if sum(1 for _, p in points if p not in BUCKLED + ("straight",)) >= MAX_FAILED:
            return None
        if not any(p == "solenoid" for _, p in points):
            if self.high not in self.probes:
                return self.high
            # the top failed (or stayed straight): between it and the highest buckled run
            buckled = [e for e, p in points if p in BUCKLED]
            if self.probes[self.high] in BUCKLED or not buckled:
                return None
            a = max(buckled)
            b = min(e for e, p in points if p not in BUCKLED and e > a)
            return 0.5 * (a + b) if b - a > tolerance else None
        lowest = points[0][0]
        if self.guess is None:
            below = 0.5 * (self.low + lowest)
        else:
            below = lowest - tolerance * 2 ** sum(1 for e, _ in points if e < self.high)
        if below - self.low < 0.5 * tolerance:
            below = self.low
        return below if below not in self.probes and below < lowest else None

    def ordered(self) -> list[tuple[float, str]]:
        return sorted(self.probes.items())

    def bracket(self) -> tuple[float, float] | None:
        """(a, b): the lowest solenoid b that has a plectoneme or mixed run below it, and the
        highest such run a below b; None without one. A mixed run counts on the low side:
        the boundary is where solenoids begin, and the mixed runs below it are its band."""
        points = self.ordered()
        below = [e for e, p in points if p in ("plectoneme", "mixed")]
        solenoids = [e for e, p in points if p == "solenoid" and below and e > min(below)]
        if not solenoids:
            return None
        b = min(solenoids)
        return max(e for e in below if e < b), b

    def has_boundary(self) -> bool | None:
        """True: a solenoid on the level (the boundary lies at or below it); False: the top
        buckled (plectoneme, mixed) and no solenoid: the plectoneme meets the straight rod;
        None: the top not yet run, or failed, or straight."""
        if any(p == "solenoid" for p in self.probes.values()):
            return True
        if self.probes.get(self.high) in ("plectoneme", "mixed"):
            return False
        return None

    def next_probes(self, tolerance: float, count: int = 1) -> list[float]:
        """The extensions of the level's next round, or none once its bracket is narrower
        than tolerance. With a guess (a neighbour's boundary) inside a bracket still wider
        than tolerance, half a tolerance either side of it: the boundary runs nearly along
        the twist axis, so the bracket most often closes at once. Otherwise `count`
        extensions that split the gap next_probe would halve into count + 1 equal parts (one
        round of the trace can use every worker when few levels are left)."""
        middle = self.next_probe(tolerance)
        bracket = self.bracket()
        if middle is not None and bracket is not None and self.guess is not None:
            a, b = bracket
            near = [e for e in (self.guess - 0.5 * tolerance, self.guess + 0.5 * tolerance)
                    if a + 0.25 * tolerance < e < b - 0.25 * tolerance and e not in self.probes]
            if near:
                return near
        if middle is None or count <= 1 or bracket is None:
            return [] if middle is None else [middle]
        a, b = bracket
        inside = [e for e, _ in self.ordered() if a <= e <= b]
        left = max(e for e in inside if e < middle)
        right = min(e for e in inside if e > middle)
        return [left + (right - left) * i / (count + 1) for i in range(1, count + 1)]

    def next_probe(self, tolerance: float) -> float | None:
        """The next extension to run, or None once the bracket is narrower than tolerance
        (without a bracket yet: search). A failed (or straight) probe inside the bracket
        splits it, and the widest gap with a labelled shape at one end at least is narrowed
        next. A bracket that already holds
        MAX_FAILED failed runs is left as it is (the model fails there: Fig 3's corner, where
        the paper's law leaves its range) and says so in its row."""
        bracket = self.bracket()
        if bracket is None:
            return self.search(tolerance)
        a, b = bracket
        inside = [e for e, _ in self.ordered() if a <= e <= b]
        if sum(1 for e in inside if self.probes[e] not in BUCKLED) >= MAX_FAILED:
            return None
        gaps = [(r - q, q, r) for q, r in zip(inside[:-1], inside[1:])
                if self.probes[q] in BUCKLED or self.probes[r] in BUCKLED]
        width, left, right = max(gaps)
        return 0.5 * (left + right) if width > tolerance else None

    def row(self) -> dict | None:
        bracket = self.bracket()
        if bracket is None:
            return None
        a, b = bracket
        points = self.ordered()
        plectonemes = [e for e, p in points if p == "plectoneme" and e < b]
        start = max(plectonemes) if plectonemes else self.low
        mixed = [e for e, p in points if p == "mixed" and start < e < b]
        failed = sum(1 for _, p in points if p not in BUCKLED + ("straight",))
        monotone = not any(p == "solenoid" and any(q == "plectoneme" and f > e
                                                   for f, q in points) for e, p in points)
        notes = []
        if mixed:
            notes.append(f"{len(mixed)} mixed run(s) below the first solenoid")
        if failed:
            notes.append(f"{failed} run(s) on this level failed"
                         + ("; the bracket is left this wide" if b - a > 0 and
                            self.next_probe(0.0) is None else ""))
        if not monotone:
            notes.append("a solenoid below a plectoneme on this level")
        return {"kind": "plectoneme_solenoid", "extension": 0.5 * (a + b),
                "twist_density": self.twist, "extension_low": a, "extension_high": b,
                "twist_density_low": self.twist, "twist_density_high": self.twist,
                "mixed_width": (b - min(mixed)) if mixed else 0.0,
                "failed": failed, "non_monotone": not monotone, "note": "; ".join(notes)}


def run_id(twist: float, extension: float) -> str:
    """A run's id from its point: the same point is the same run, whichever level or round
    asks for it (and whichever version of the rounds, so that a resumed trace never reads a
    stored run as another point's)."""
    return f"phi{twist:.6f}-ext{extension:.6f}"


def _level(index: int, twist: float, onset: pd.DataFrame, sweep, settings: Settings) -> Level:
    lo, hi = sweep.axes["extension"]
    star = onset_extension(onset, twist)
    # the highest extension that still buckles, a quarter bracket below e*: the run there
    # must not be a marginal straight rod (check_settings keeps that clear of the onset's
    # band), and near the triple point, where the solenoids are a sliver under the onset,
    # it must not be far below e* either
    return Level(index, twist, lo, min(hi, star - 0.25 * settings.tolerance))


def slice_middles(lo: float, hi: float, count: int) -> np.ndarray:
    """The middles of `count` equal slices of [lo, hi]: neither edge."""
    return lo + (hi - lo) * (np.arange(count) + 0.5) / count


def first_levels(onset: pd.DataFrame, sweep, settings: Settings) -> list[Level]:
    """`settings.levels` twists, each in the middle of an equal slice of the twist range from
    the onset at the box's lowest extension to the box's top (neither edge: no buckled
    state at the first, and the second is the box's corner, where a rod is most twisted and
    stretched and its runs are the slowest and the likeliest to fail)."""
    lowest = float(onset["twist_density"].iloc[0])
    top = sweep.axes["twist_density"][1]
    twists = slice_middles(lowest, top, settings.levels)
    return [_level(i, float(t), onset, sweep, settings) for i, t in enumerate(twists)]


def boundary_rounds(sweep, scene, store, settings: Settings | None = None,
                    onset: pd.DataFrame | None = None, workers: int = 1) -> Iterator[list]:
    """The rounds of runs that trace the plectoneme–solenoid boundary and the triple point:
    each yielded list of Jobs is run into `store` before the next is made from the labels
    (as sweep.adaptive_rounds). Deterministic for a sweep, `workers` and the labels stored
    (a run's id is its point, so a trace resumed with other workers reuses what it can)."""
    from .sweep import Job, _registered_builder, scene_for
    from .tabulate import summarize

    settings = settings or Settings.of(sweep)
    onset = onset if onset is not None else onset_line(scene, sweep, settings)
    builder = _registered_builder(scene.scene)
    levels = [lv for lv in first_levels(onset, sweep, settings) if lv.high > lv.low]
    steps: dict[int, int] = {}

    def job(level: Level, extension: float):
        step = steps.get(level.index, 0)
        steps[level.index] = step + 1
        point = {"twist_density": level.twist, "extension": float(extension)}
        rid = run_id(level.twist, extension)
        return rid, level, extension, Job([rid], [point | {"level": float(level.index),
                                                            "step": float(step)}],
                                          scene_for(scene, point), builder=builder)

    pending = [job(lv, e) for lv in levels for e in lv.first_probes(settings.tolerance)]
    while pending:
        unique = {rid: j for rid, *_, j in pending}  # two levels may ask for one point
        yield list(unique.values())
        for rid, level, extension, _ in pending:
            level.probes[extension] = summarize(store.read_run(rid))["phase"]
        guide(levels, settings.tolerance)
        active = [lv for lv in levels if lv.next_probe(settings.tolerance) is not None]
        # few levels left: split their gaps in more parts, so that every worker has a run
        count = max(1, workers // max(len(active), 1))
        pending = [job(lv, e) for lv in active
                   for e in lv.next_probes(settings.tolerance, count)]
        # the triple point: between the highest level without a boundary and the lowest with
        # one (both known), a new level halves the gap until it is below twist_tolerance
        gap = triple_gap(levels)
        if gap is not None and gap[1].twist - gap[0].twist > settings.twist_tolerance:
            twist = 0.5 * (gap[0].twist + gap[1].twist)
            new = _level(len(levels), twist, onset, sweep, settings)
            bracket = gap[1].bracket()
            new.guess = 0.5 * sum(bracket) if bracket else None
            # a level of unknown state (a failed end) between the two is not run again
            if new.high > new.low and all(abs(lv.twist - twist) > 1e-9 for lv in levels):
                levels.append(new)
                pending += [job(new, e) for e in new.first_probes(settings.tolerance)]


def guide(levels: list[Level], tolerance: float) -> None:
    """Give every level still open the boundary of the nearest level (in twist) whose bracket
    is already narrower than tolerance, as its guess."""
    done = [lv for lv in levels if (b := lv.bracket()) is not None and b[1] - b[0] <= tolerance]
    for lv in levels:
        if done and all(lv is not d for d in done):
            nearest = min(done, key=lambda d: abs(d.twist - lv.twist))
            lv.guess = 0.5 * sum(nearest.bracket())


def triple_gap(levels: list[Level]) -> tuple[Level, Level] | None:
    """(below, above): the highest level with no boundary under the lowest level with one,
    once every level up to it is known; None otherwise."""
    known = sorted((lv for lv in levels if lv.has_boundary() is not None), key=lambda v: v.twist)
    without = [lv for lv in known if lv.has_boundary() is False]
    with_ = [lv for lv in known if lv.has_boundary() is True]
    if not without or not with_:
        return None
    below = max(without, key=lambda v: v.twist)
    above = [lv for lv in with_ if lv.twist > below.twist]
    return (below, min(above, key=lambda v: v.twist)) if above else None


# ---------------------------------------------------------------- hysteresis (dynamic)
# The paper's runs only twist up. Turned back, a buckled rod stays buckled below the onset
# until its last loop pops out: between that twist and the onset, straight and buckled
# states coexist. One run per load finds it: twisted past the onset (HYSTERESIS_OVER of
# it: the straight rod is unstable there, and the hold's stability probe buckles it), then
# turned back in steps of hysteresis_step of the onset twist, held to a stable equilibrium
# at each (the scene's own hold), down to HYSTERESIS_FLOOR of it.
HYSTERESIS_OVER = 1.05
HYSTERESIS_FLOOR = 0.3


def hysteresis_extensions(sweep, settings: Settings) -> np.ndarray:
    """The loads of the return runs: `hysteresis_loads` extensions, each in the middle of an
    equal slice of the box's extension axis."""
    return slice_middles(*sweep.axes["extension"], settings.hysteresis_loads)


def return_twists(critical: float, settings: Settings) -> list[float]:
    """Φa of the holds of one return run: past the onset `critical`, then down from it in
    steps of hysteresis_step·critical to HYSTERESIS_FLOOR·critical."""
    count = int(round((1 - HYSTERESIS_FLOOR) / settings.hysteresis_step))
    return [HYSTERESIS_OVER * critical] + [critical * (1 - k * settings.hysteresis_step)
                                           for k in range(1, count + 1)]


def hysteresis_jobs(sweep, scene, onset: pd.DataFrame, settings: Settings) -> list:
    """One continuation Job per load (sweep.Job with twist targets up, then down): each hold
    is a stored run, id `return-ext…-phi…` (its point), params twist_density, extension,
    `load` (the load's index) and `step` (the hold's place on the return, 0 = past the
    onset)."""
    from .sweep import Job, _registered_builder, scene_for
    from .units import turns_for_twist_density

    builder = _registered_builder(scene.scene)
    jobs = []
    for index, extension in enumerate(hysteresis_extensions(sweep, settings)):
        twists = return_twists(float(onset_twist(onset, extension)), settings)
        cfg = scene_for(scene, {"twist_density": twists[0], "extension": float(extension)})
        targets = [turns_for_twist_density(t, cfg.rod.radius, cfg.rod.length) for t in twists]
        ids = [f"return-ext{extension:.6f}-phi{t:.6f}" for t in twists]
        params = [{"twist_density": t, "extension": float(extension), "load": float(index),
                   "step": float(k)} for k, t in enumerate(twists)]
        jobs.append(Job(ids, params, cfg, twist_targets=targets, builder=builder))
    return jobs


def restraighten_rows(runs: pd.DataFrame) -> list[dict]:
    """One `restraighten` row per load of a classified table's return runs: the twist at which
    the buckled rod came back straight is bracketed by the lowest hold that stayed buckled
    and the next one down, which was straight. A load whose rod did not buckle past the onset,
    or stayed buckled down to the floor, or whose holds failed, says so in its note. A hold
    counts as buckled when it is labelled so or writhes by more than paths.JUMP_WRITHE."""
    if "load" not in runs:
        return []
    from .paths import JUMP_WRITHE

    rows = []
    for _, group in runs[runs["load"].notna()].groupby("load"):
        group = group.sort_values("step")
        extension = float(group["extension"].iloc[0])
        # a shape the classifier reads as straight but that writhes is buckled: the tightest
        # solenoids (above L/L0 ~ 1.165 for the paper's rod) have turns shorter than its
        # partner separation
        writhe = (group["writhe"] if "writhe" in group else pd.Series(np.nan, group.index))
        coiled = np.abs(writhe.to_numpy(float)) > JUMP_WRITHE
        phases = ["solenoid" if p == "straight" and c else p
                  for p, c in zip(group["phase"], coiled)]
        twists = group["twist_density"].to_numpy(float)
        row = {"kind": "restraighten", "extension": extension, "extension_low": extension,
               "extension_high": extension, "twist_density": np.nan,
               "twist_density_low": np.nan, "twist_density_high": np.nan,
               "failed": sum(p not in BUCKLED + ("straight",) for p in phases), "note": ""}
        if phases[0] not in BUCKLED:
            row["note"] = (f"the rod did not buckle at Phi*a {twists[0]:.4g}, past the onset "
                           f"({phases[0]})")
        else:
            down = list(zip(twists[1:], phases[1:]))
            straight = next((k for k, (_, p) in enumerate(down) if p == "straight"), None)
            before = down[:straight] if straight is not None else down
            if any(p not in BUCKLED for _, p in before):
                row["note"] = "a hold of the return failed before the rod came back straight"
            elif straight is None:
                row["twist_density_high"] = down[-1][0] if down else twists[0]
                row["twist_density_low"] = 0.0
                row["note"] = f"still buckled at the lowest hold (Phi*a {row['twist_density_high']:.4g})"
            else:
                high = down[straight - 1][0] if straight else twists[0]
                low = down[straight][0]
                row.update(twist_density=0.5 * (low + high), twist_density_low=low,
                           twist_density_high=high)
        rows.append(row)
    return rows


# ---------------------------------------------------------------- the lines from the runs

def levels_from_store(table: pd.DataFrame, onset: pd.DataFrame, sweep,
                      settings: Settings) -> list[Level]:
    """The levels again from a classified table of the trace's runs (params level, step)."""
    lo, _ = sweep.axes["extension"]
    levels: dict[int, Level] = {}
    for row in table.itertuples(index=False):
        if not np.isfinite(getattr(row, "level", np.nan)):
            continue
        index = int(row.level)
        if index not in levels:
            levels[index] = _level(index, float(row.twist_density), onset, sweep, settings)
        levels[index].probes[float(row.extension)] = row.phase
    return [levels[k] for k in sorted(levels)]


def lines(onset: pd.DataFrame, levels: list[Level], settings: Settings,
          returns: list[dict] = ()) -> pd.DataFrame:
    """The boundaries table: the onset rows, one plectoneme_solenoid row per level with a
    bracket, the triple point's row (when the trace found both sides of it) and the
    `returns` (restraighten_rows)."""
    rows = [onset]
    traced = [r for lv in sorted(levels, key=lambda v: v.twist) if (r := lv.row()) is not None]
    if traced:
        rows.append(pd.DataFrame(traced))
    gap = triple_gap(levels)
    if gap is not None:
        below, above = gap
        e_low = onset_extension(onset, below.twist)
        bracket = above.bracket()
        e_high = bracket[1] if bracket else onset_extension(onset, above.twist)
        e_low, e_high = sorted((e_low, e_high))
        rows.append(pd.DataFrame([{
            "kind": "triple_point", "extension": 0.5 * (e_low + e_high),
            "twist_density": 0.5 * (below.twist + above.twist),
            "extension_low": e_low, "extension_high": e_high,
            "twist_density_low": below.twist, "twist_density_high": above.twist,
            "note": ("between the highest twist whose plectoneme meets the straight rod and "
                     "the lowest with a plectoneme-solenoid boundary")}]))
    if returns:
        rows.append(pd.DataFrame(list(returns)))
    table = pd.concat(rows, ignore_index=True)
    for name in COLUMNS:
        if name not in table:
            table[name] = np.nan if name not in ("note", "kind") else ""
    table["note"] = table["note"].fillna("")
    return table[list(COLUMNS)]


def left_wide(rows: pd.DataFrame) -> pd.Series:
    """Which rows of a boundaries table are brackets that failed runs left wide (MAX_FAILED
    of them on the level: the model fails there, as in Fig 3's corner): no point of the line,
    for the claims, the predicted labels and the plot alike."""
    if "failed" not in rows:
        return pd.Series(False, index=rows.index)
    return (rows["kind"] == "plectoneme_solenoid") & (rows["failed"].fillna(0) >= MAX_FAILED)


def predict_phase(table: pd.DataFrame, twist, extension) -> np.ndarray:
    """The labels the lines of a boundaries table predict at points (Φa, L/L0) (arrays of
    one shape): straight below the onset; above it, a solenoid from the plectoneme–solenoid
    boundary's extension at that twist on (the line between its points, its end points held
    beyond them; a bracket failed runs left wide is not one of them) and a plectoneme below
    it, and below the triple point's twist (or with no boundary traced) a plectoneme
    everywhere."""
    twist, extension = np.broadcast_arrays(np.asarray(twist, float), np.asarray(extension, float))
    critical = onset_twist(table, extension)
    ps = table[table["kind"] == "plectoneme_solenoid"].sort_values("twist_density")
    ps = ps[~left_wide(ps)]
    out = np.where(twist < critical, "straight", "plectoneme").astype(object)
    if len(ps):
        boundary = np.interp(twist, ps["twist_density"], ps["extension"])
        triple = table[table["kind"] == "triple_point"]
        lowest = (float(triple["twist_density"].iloc[0]) if len(triple)
                  else float(ps["twist_density"].iloc[0]))
        solenoid = (twist >= critical) & (twist >= lowest) & (extension >= boundary)
        out[solenoid] = "solenoid"
    return out


def claims(table: pd.DataFrame, above: float = 1.1) -> dict:
    """The paper's two claims as numbers: the onset's slope and intercept at high extension
    (L/L0 > `above`) with their standard errors, and the extension from which solenoids win
    (the lowest plectoneme–solenoid boundary point whose bracket failed runs did not leave
    wide, ± its half bracket)."""
    out: dict = {}
    onset = table[(table["kind"] == "onset") & (table["extension"] > above)
                  & table["twist_density"].notna()]
    if len(onset) >= 3:
        (slope, intercept), cov = np.polyfit(onset["extension"], onset["twist_density"], 1,
                                             cov=True)
        out["onset_slope"], out["onset_intercept"] = float(slope), float(intercept)
        out["onset_slope_error"], out["onset_intercept_error"] = map(float, np.sqrt(np.diag(cov)))
    ps = table[table["kind"] == "plectoneme_solenoid"]
    ps = ps[~left_wide(ps)]  # says nothing of where solenoids begin
    if len(ps):
        first = ps.loc[ps["extension"].idxmin()]
        out["solenoids_from"] = float(first["extension"])
        out["solenoids_from_error"] = float(0.5 * (first["extension_high"]
                                                   - first["extension_low"]))
    return out


def column_units() -> dict[str, tuple[str, str]]:
    return dict(COLUMNS)


# ---------------------------------------------------------------- one call: trace a box

@dataclass
class Trace:
    """What `trace` found: the boundaries table (columns COLUMNS), the paper's claims as
    numbers (claims), the sweep's report (None for the onset alone) and the CPU seconds the
    onset line took."""

    table: pd.DataFrame
    claims: dict
    report: object | None
    onset_seconds: float
    hysteresis_report: object | None = None  # the return runs' (--hysteresis), timed apart


def sweep_for_boundaries(sweep_file, overrides=(), settings: dict | None = None):
    """(sweep, scene) of a sweep file (or shipped name) set to trace boundaries: the sampler
    `boundaries`, its `samples` only the 2 x 2 grid that checks the box's corners, and the
    settings given (tolerance, twist_tolerance, levels) under sweep.boundary."""
    from .scenes import SCENES

    extra = [("sweep.sampler", "boundaries"), ("sweep.samples", 4)]
    extra += [(f"sweep.boundary.{k}", v) for k, v in (settings or {}).items() if v is not None]
    sweep, scene = config.load_sweep(str(sweep_file), list(overrides) + extra, SCENES)
    check_traceable(sweep)
    return sweep, scene


def trace(sweep, scene, output: str | None, *, only_onset: bool = False,
          hysteresis: bool = False, jobs: int = 1, backend: str = "loky",
          scheduler: str | None = None, progress: bool = False, echo=print,
          replace: bool = False) -> Trace:
    """The boundaries of the box of `sweep` for its scene: the onset line (static, always),
    and unless `only_onset` the plectoneme–solenoid boundary and the triple point, traced by
    runs into the store at `output` (resumed like any sweep) where the table is kept too.
    With `hysteresis`, then the return runs (hysteresis_jobs) into the same store, timed
    apart; a store's return runs give `restraighten` rows whenever the lines are made."""
    import time

    from .sweep import run_sweep

    settings = Settings.of(sweep)
    cpu = time.process_time()
    onset = onset_line(scene, sweep, settings)
    onset_seconds = time.process_time() - cpu
    check_box(onset, sweep)
    check_settings(onset, settings)
    if only_onset:
        table = lines(onset, [], settings)
        return Trace(table, claims(table), None, onset_seconds)
    report = run_sweep(sweep, scene, output, jobs=jobs, backend=backend, scheduler=scheduler,
                       progress=progress, echo=echo, replace=replace,
                       rounds_of=lambda store: boundary_rounds(sweep, scene, store, settings,
                                                               onset, workers=jobs))
    if report.stopped_by:
        return Trace(lines(onset, [], settings), {}, report, onset_seconds)
    returns = None
    if hysteresis:
        returns = run_sweep(sweep, scene, output, jobs=jobs, backend=backend,
                            scheduler=scheduler, progress=progress, echo=echo,
                            rounds_of=lambda store: iter([hysteresis_jobs(sweep, scene, onset,
                                                                          settings)]))
        if returns.stopped_by:
            return Trace(lines(onset, [], settings), {}, report, onset_seconds, returns)
    from ._version import __version__
    from .store import open_store
    from .tabulate import classify_table

    with open_store(output, config_text=config.to_yaml(sweep=sweep, scene=scene),
                    config_hash=config.config_hash(sweep, scene), version=__version__,
                    kind="sweep") as store:
        runs = store.table(classify_table(store))  # params, status and labels
        table = lines(onset, levels_from_store(runs, onset, sweep, settings), settings,
                      restraighten_rows(runs))
        store.write_boundaries(table, column_units(), dataclasses.asdict(settings))
    return Trace(table, claims(table), report, onset_seconds, returns)


def summary(trace_: Trace) -> str:
    """The boundaries as a short text table and the paper's claims, for a terminal."""
    t = trace_.table
    out = []
    onset = t[t["kind"] == "onset"]
    picks = onset.iloc[np.linspace(0, len(onset) - 1, min(6, len(onset))).round().astype(int)]
    out.append("onset (the model's own stability):  L/L0  Phi*a_c   (sheared, unsheared Greenhill)")
    for r in picks.itertuples():
        out.append(f"  {r.extension:6.3f}  {r.twist_density:7.4f}   ({r.greenhill_sheared:.4f}, "
                   f"{r.greenhill:.4f})")
    ps = t[t["kind"] == "plectoneme_solenoid"]
    if len(ps):
        out.append("plectoneme-solenoid boundary:  Phi*a   L/L0 [bracket]   note")
        for r in ps.itertuples():
            out.append(f"  {r.twist_density:6.3f}  {r.extension:.4f} [{r.extension_low:.4f}, "
                       f"{r.extension_high:.4f}]  {r.note}")
    elif trace_.report is not None:
        out.append("plectoneme-solenoid boundary: none in the box (no twist level has a "
                   "plectoneme under a solenoid below the onset)")
    tp = t[t["kind"] == "triple_point"]
    for r in tp.itertuples():
        out.append(f"triple point: L/L0 {r.extension:.3f} [{r.extension_low:.3f}, "
                   f"{r.extension_high:.3f}], Phi*a {r.twist_density:.3f} "
                   f"[{r.twist_density_low:.3f}, {r.twist_density_high:.3f}]")
    back = t[t["kind"] == "restraighten"]
    if len(back):
        out.append("restraighten (turned back from past the onset):  L/L0  Phi*a [bracket]"
                   "   onset   note")
        for r, c in zip(back.itertuples(), onset_twist(t, back["extension"])):
            out.append(f"  {r.extension:6.3f}  {r.twist_density:6.3f} [{r.twist_density_low:.3f}, "
                       f"{r.twist_density_high:.3f}]   {c:.3f}   {r.note}")
    c = trace_.claims
    if "onset_slope" in c:
        out.append(f"onset at high extension: Phi*a_c = ({c['onset_slope']:.3f} ± "
                   f"{c['onset_slope_error']:.3f}) L/L0 + ({c['onset_intercept']:.3f} ± "
                   f"{c['onset_intercept_error']:.3f})")
    if "solenoids_from" in c:
        out.append(f"solenoids win from L/L0 = {c['solenoids_from']:.4f} ± "
                   f"{c['solenoids_from_error']:.4f}")
    return "\n".join(out)
