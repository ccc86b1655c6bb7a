"""Where the straight, stretched and twisted rod loses stability: the model's own onset.

The straight rod clamped at both ends, its end free to slide along the axis under a constant
load and turned by θ, is an equilibrium at every θ: stretched uniformly to the load's
extension e and twisted uniformly (every element alike, the clamp springs included). It is
stable up to the twist θ_c at which a pair of helical modes crosses zero stiffness. That θ_c
is found here from the discrete model's own stiffness (rod/static.py), so it carries
everything the model has: shear, extensibility, the 1/e and 1/e³ factors of the law, the
clamps' half elements and the resolution. The clamped Greenhill twist (theory.py) is its
limit for an unshearable, inextensible rod and n → ∞ (tests/test_onset.py); the sheared
clamped Greenhill twist (sheared_greenhill_turns) is its n → ∞ limit for the paper's rod
as it is, shear and stretch included (tests/test_theory_shear.py).

On the straight branch the lateral unknowns (node displacements across the axis, frame
rotations about d1 and d2) decouple to first order from the axial and twist ones, and the
critical pair lives in that lateral block: θ_c is where the symmetric part of its
mass-scaled stiffness stops being positive definite. (The whole stiffness's symmetric part
stops being so at ~0.7 θ_c through an axial–twist coupling of the paper's law, which is no
instability: rod/static.py.) The test checks that this agrees with the eigenvalues of the
non-symmetric stiffness.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import scipy.linalg
from scipy.optimize import brentq

from ..units import TURN
from . import kernel as k
from . import static
from .model import Controls, Ends, Problem, Rod, RodState, constant, straight_state

# the twist_under_load ends: clamped start; the end held across the axis, free along it,
# its frame turned by the rotation control
LOADED_ENDS = Ends(start_held=(True, True, True), start_frame_held=True,
                   end_held=(True, True, False), end_frame_held=True)


def straight_equilibrium(rod: Rod, extension: float, turns: float,
                         ends: Ends = LOADED_ENDS, force: float | None = None) -> Problem:
    """The straight rod stretched to `extension` (each element e·l0 long) and twisted uniformly
    by `turns`, as a Problem: its clamp reference is the untwisted frame and its end rotation
    control carries the turns (as the quasi-static start of twist_under_load builds it). The
    end force (default: the one the law needs for that extension untwisted) does not enter
    the stiffness of the straight state except through e. Under the paper's law the state is
    the equilibrium at every twist; under a conservative law the twist also lengthens the rod
    (StraightBranch.problem solves for the stretch that balances the force then)."""
    twisted: RodState = straight_state(rod, axis=ends.axis, twist_turns=turns)
    twisted.x *= extension
    untwisted = np.ascontiguousarray(straight_state(rod, axis=ends.axis).Q[:, :, 0])
    axial = rod.axial_stiffness
    # the end force in equilibrium with the stretch: the paper's law E·A0·(1 − 1/e) (per
    # current area, A0/e), the neo-Hookean one E·A0/3·(e − 1/e²); compressible: E·A0·(e − 1)
    if force is not None:
        pass
    elif not rod.incompressible:
        force = axial * (extension - 1.0)
    elif rod.law == "neo_hookean":
        force = axial / 3.0 * (extension - extension**-2)
    else:
        force = axial * (1.0 - 1.0 / extension)
    controls = Controls(end_force=constant(force), end_rotation=constant(TURN * turns))
    return Problem(rod=rod, state=twisted, ends=ends, controls=controls,
                   clamp_reference=(untwisted, untwisted.copy()))


class StraightBranch:
    """The straight equilibria of one rod at one extension, θ the parameter: the static model
    is built once, and each twist only turns the frames and the end rotation control."""

    def __init__(self, rod: Rod, extension: float, ends: Ends = LOADED_ENDS):
        from .simulate import static_model_of  # simulate drives the kernel; it imports static

        self.rod, self.extension, self.ends = rod, extension, ends
        self.model = static_model_of(straight_equilibrium(rod, extension, 0.0, ends))
        model = self.model
        axis = np.abs(np.asarray(ends.axis, float))
        along = int(np.argmax(axis))
        if not np.isclose(axis[along], 1.0):
            raise ValueError(f"ends.axis {tuple(ends.axis)}: the onset needs a rod along x, y "
                             "or z")
        # the lateral unknowns, in rod order so that their block is banded (an unknown
        # reaches static.REACH blocks): positions across the axis, rotations about d1 and d2
        m = model.positions
        n = (model.unknowns - m) // 3
        keep = np.concatenate([np.flatnonzero(model.free[0] != along),
                               m + 3 * np.arange(n), m + 3 * np.arange(n) + 1])
        order, self.width = static.rod_order(model.block_of[keep])
        self.lateral = keep[order]

    def problem(self, turns: float) -> Problem:
        """The straight equilibrium at `turns` under the end force of `extension` untwisted."""
        base = straight_equilibrium(self.rod, self.extension, turns, self.ends)
        if self.rod.law == "paper":
            return base  # its twist does not load the axis: the same stretch at every twist
        # a conservative law's twist energy GJ0·Φ²/(2e) falls as the rod stretches: twisted,
        # it lengthens under the same force (the Poynting effect of twisted wires)
        force = float(self.model.now[k.T_END_FORCE])
        now = self.model.now.copy()
        now[k.T_END_ROTATION] = TURN * turns
        model = dataclasses.replace(self.model, now=now)
        n = self.rod.elements
        end = int(np.flatnonzero(model.free[1] == n)[0])  # node n's one free component

        def unbalanced(e: float) -> float:
            state = straight_equilibrium(self.rod, e, turns, self.ends, force).state
            return float(static.loads(model, state.x, state.Q)[end])

        e = brentq(unbalanced, 0.5, 2.0 * self.extension, xtol=1e-14, rtol=1e-13)
        return straight_equilibrium(self.rod, e, turns, self.ends, force)

    def lateral_band(self, turns: float) -> np.ndarray:
        """The symmetric part of the mass-scaled lateral stiffness at `turns`, in LAPACK's
        upper banded storage ((width + 1, N): row width − d holds diagonal d)."""
        state = self.problem(turns).state
        now = self.model.now.copy()
        now[k.T_END_ROTATION] = TURN * turns
        model = dataclasses.replace(self.model, now=now)
        K = static.stiffness_matrix(model, state.x, state.Q, columns=self.lateral)
        A, _ = static.mass_weighted(model, state.x, K, self.lateral)
        return static.symmetric_band(A, self.width)

    def stable(self, turns: float) -> bool:
        """The lateral block's symmetric part is positive definite: its banded Cholesky
        factorization exists."""
        try:
            scipy.linalg.cholesky_banded(self.lateral_band(turns), check_finite=False)
            return True
        except np.linalg.LinAlgError:
            return False

    def lowest(self, turns: float) -> float:
        """The smallest eigenvalue [1/s²] of that symmetric part: > 0 below the onset."""
        return float(scipy.linalg.eig_banded(self.lateral_band(turns), eigvals_only=True,
                                             select="i", select_range=(0, 0),
                                             check_finite=False)[0])

    def _limit_turns(self) -> float:
        """The most twist [turns] this resolution can answer for: neighbouring elements
        turned by 160°. The matrix log's branch cut is at 180°, and no stiffness found that
        close to it means anything (the kernel's own resolution guard stops a run at 135°)."""
        return (8.0 * math.pi / 9.0) * self.rod.elements / TURN

    def onset_turns(self, tolerance: float = 1e-6, near: float | None = None) -> float:
        """θ_c [turns], relative accuracy `tolerance`: bisection on the Cholesky test (a
        factorization costs a twentieth of an eigenvalue; the stiffness dominates). `near`
        [turns]: a close guess (a neighbouring load's onset, scaled), tried first within 1 %
        (half the tests along a line of onsets); the wide bracket if it misses."""
        limit = self._limit_turns()
        if near is not None and 1.01 * near <= limit:
            lo, hi = 0.99 * near, 1.01 * near
            if self.stable(lo) and not self.stable(hi):
                return self._bisect(lo, hi, tolerance)
        # bracketed around the unsheared clamped Greenhill twist: the model's onset lies at
        # 0.6-0.97 of it for the paper's rod (shear), and the bracket widens for any other,
        # up to the twist this resolution can answer for
        guess = greenhill_turns(self.rod, self.extension)
        hi = min(1.05 * guess, limit)
        lo = 0.7 * guess if 0.7 * guess < hi else 0.5 * hi
        while not self.stable(lo):
            if lo < 1e-6 * guess:  # unstable untwisted (compressed past Euler): no onset
                raise ValueError(f"the straight rod is unstable without twist at L/L0 = "
                                 f"{self.extension:g}")
            lo, hi = 0.5 * lo, lo
        while self.stable(hi):
            if hi >= limit:
                needed = math.ceil(TURN * 1.05 * guess / (8.0 * math.pi / 9.0))
                raise ValueError(
                    f"at least {needed} elements: still stable at {limit:.3g} turns (160° "
                    f"between neighbouring elements of {self.rod.elements}), below the onset's "
                    f"twist (about {guess:.3g} turns unsheared) at L/L0 = {self.extension:g}")
            lo, hi = hi, min(1.5 * hi, limit)
        return self._bisect(lo, hi, tolerance)

    def _bisect(self, lo: float, hi: float, tolerance: float) -> float:
        """The onset between a stable `lo` and an unstable `hi` [turns], to `tolerance`."""
        while hi - lo > tolerance * hi:
            mid = 0.5 * (lo + hi)
            if self.stable(mid):
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi)


def straight_start_turns(rod: Rod, extension: float, target: float, fraction: float, *,
                         ends: Ends = LOADED_ENDS) -> float:
    """The twist [turns] a run started on the straight branch starts at: `target`, or
    `fraction` of the onset θ_c if that is less (with the target's sign). A target whose
    straight rod is still stable at target/fraction needs no θ_c (target < fraction·θ_c
    then): one test, and none at all for no twist, so that a rod too coarse to resolve its
    onset can still start a small twist."""
    if target == 0.0:
        return 0.0
    branch = StraightBranch(_perfect(rod), extension, ends)
    above = abs(target) / fraction
    if above <= branch._limit_turns() and branch.stable(above):
        return target
    onset = branch.onset_turns(1e-4)
    return math.copysign(min(abs(target), fraction * onset), target)


def straight_onset_turns(rod: Rod, extension: float, *, ends: Ends = LOADED_ENDS,
                         tolerance: float = 1e-6, near: float | None = None) -> float:
    """θ_c [turns]: the end rotation at which the straight rod of `rod` (its own elements,
    stiffnesses and law; no imperfection), stretched to `extension` and clamped as `ends`
    hold it, loses stability. Relative accuracy `tolerance` in θ; `near`: a close guess
    (StraightBranch.onset_turns)."""
    return StraightBranch(_perfect(rod), extension, ends).onset_turns(tolerance, near)


def _perfect(rod: Rod) -> Rod:
    return dataclasses.replace(rod, rest_curvature=(0.0, 0.0, 0.0))


def greenhill_turns(rod: Rod, extension: float) -> float:
    """The unsheared clamped Greenhill twist [turns] of the rod stretched to `extension` under
    the paper's law (theory.stretched_greenhill_turns: the sheared twist at S = ∞)."""
    return _clamped_greenhill_turns(rod, extension, math.inf)


def sheared_greenhill_turns(rod: Rod, extension: float) -> float:
    """The clamped Greenhill twist [turns] of the rod stretched to `extension` under the
    paper's law, with its shear stiffness (theory.sheared_greenhill_turns): the n → ∞ limit
    of straight_onset_turns for the paper's law (tests/test_theory_shear.py)."""
    return _clamped_greenhill_turns(rod, extension, rod.shear_stiffness)


def _clamped_greenhill_turns(rod: Rod, extension: float, shear: float) -> float:
    """theory.sheared_greenhill_turns of `rod` stretched to `extension` by the tension of its
    law, with shear stiffness `shear` [N] (math.inf: unshearable)."""
    from ..theory import sheared_greenhill_turns as turns

    tension = rod.axial_stiffness * (1.0 - 1.0 / extension)
    return turns(tension, extension, rod.length, rod.bending_stiffness, rod.twist_stiffness,
                 shear)


def compile_static() -> None:
    """Compile the static functions a hold's stability test, the straight start and the
    phase map's onset line call (and write them to numba's disk cache), on a tiny rod: what
    runner.compile_kernel's second process runs while the kernel compiles, so that a sweep's
    workers load them instead of each compiling them at its first hold."""
    from .simulate import static_model_of

    branch = StraightBranch(Rod(length=1.0, radius=0.025, elements=8), 1.05)
    problem = branch.problem(0.5)
    model = static_model_of(problem)
    static.stability(model, problem.state.x, problem.state.Q)
    branch.stable(0.5)
    static.solve(model, problem.state.x, problem.state.Q, force_scale=1.0, max_iterations=1)
