"""Closed-form references that figures compare against (no simulation here).

The tests check these against the literature's numbers; the kernel never uses them (the
quasi-static start of the twist_under_load scene uses the straight rod's buckling twist).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from . import units


def greenhill_clamped_moment(tension: float, length: float, bending: float) -> float:
    """Smallest axial moment M [N m] at which a straight rod clamped at both ends, under
    tension T [N], buckles (the clamped Greenhill problem): the first root of
    u1·u2·sin(u1 − u2) = (u1 − u2)·sin u1·sin u2 with u = L·(M ± √(M² − 4BT))/(4B).
    M_c·L/B = 8.9868 at T = 0 and 20.9835 at T·L²/B = 100; M_c → 2√(BT) for long rods.
    The unshearable limit of sheared_greenhill_clamped_moment (S = ∞, which reduces it to
    these expressions exactly).
    """
    return sheared_greenhill_clamped_moment(tension, length, bending, math.inf)


def sheared_greenhill_clamped_moment(tension: float, length: float, bending: float,
                                     shear: float) -> float:
    """Smallest axial moment M [N m] at which a straight Cosserat rod of shear stiffness
    S = `shear` [N] (per radian of shear angle), clamped at both ends under tension T [N],
    buckles: the first root of

        u1·u2·sin(u1 − u2) = (1 − T/S)·(u1 − u2)·sin u1·sin u2,
        u = L·(M ± √(M² − 4BT'))/(4B),   T' = T·(1 − T/S),

    which is the clamped Greenhill equation (greenhill_clamped_moment) at S = ∞. Shear
    lowers M_c: T' < T in the u's, and the factor 1 − T/S < 1.

    Why. Take the rod straight along z, length L, twisting moment M, and linearise in a
    lateral displacement r(s) and the tilt d(s) of the director d3 (d3 ≈ ẑ + d; a
    shearable rod's d3 need not follow the tangent ẑ + r'). With no distributed load the
    force N = T·ẑ + F is constant (F: an unknown lateral reaction). The Cosserat law gives
    the part of N normal to d3, N − (N·d3)·d3, as S times the shear angle r' − d:
    F = T·d + S·(r' − d); the moment is m = M·d3 + B·d3 × d3', i.e. m⊥ = M·d + B·ẑ × d'.
    The lateral moment balance m' + x' × N = 0 reads M·d' + B·ẑ × d'' − T·ẑ × r' + ẑ × F = 0
    and, with r' = (1 − T/S)·d + F/S,

        M·d' + B·ẑ × d'' − T'·ẑ × d + (1 − T/S)·ẑ × F = 0:

    the unsheared equation for the tilt, with T' for T and a scaled reaction. In complex
    form (w = d_x + i·d_y) its solutions are w = a·e^{ik1 s} + b·e^{ik2 s} + c, with
    B·k² − M·k + T' = 0 (k·L/2 = u1, u2) and c = (1 − T/S)·F/T' = F/T. The clamps hold
    the frames (d = 0 at s = 0, L) and the ends' lateral places (∫r' ds = 0, i.e.
    (1 − T/S)·∫d ds = −L·F/S: ∫w ds + L·c·T/(S − T) = 0). With ∫e^{iks} ds =
    L·e^{iu}·sin u/u the three conditions on (a, b, c) have the rows (1, 1, 1),
    (e^{2iu1}, e^{2iu2}, 1) and (e^{iu1}·sin u1/u1, e^{iu2}·sin u2/u2, 1/(1 − T/S)); their
    determinant is −2i·e^{i(u1+u2)}·[sin(u1 − u2)/(1 − T/S) − (u1 − u2)·sin u1·sin u2/(u1·u2)],
    zero on the equation above. Below M = 2√(BT') the u's are complex and it has no root.

    The paper's law (rod/kernel.py) is this Cosserat law: its force S·σ/e with σ = Q·∂x/∂ŝ −
    d3 per rest length ŝ is S·(r' − d) + T·d across the axis, so S is the rod's shear
    stiffness 4GA0/3 at every stretch (the e of σ cancels the 1/e). Needs T < S.
    """
    if not shear > 0.0:
        raise ValueError(f"shear stiffness must be > 0 N; got {shear:g}")
    if tension >= shear:
        raise ValueError(f"tension {tension:g} N at or above the shear stiffness {shear:g} N: "
                         "the sheared clamped Greenhill equation needs T < S")
    # the equation is 0/0 at T = 0 itself; T·L²/B = 1e-9 moves M_c by ~1e-10 relative
    tension = max(tension, 1e-9 * bending / length**2)
    kept = 1.0 - tension / shear  # exactly 1 when S = ∞
    effective = tension * kept  # T' = T·(1 − T/S)

    def f(m):
        d = np.sqrt(np.maximum(m * m - 4 * bending * effective, 0.0))
        u1, u2 = length * (m + d) / (4 * bending), length * (m - d) / (4 * bending)
        # both sides vanish like u2² as T → 0; dividing by it keeps the root well conditioned
        return (u1 * u2 * np.sin(u1 - u2) - kept * (u1 - u2) * np.sin(u1) * np.sin(u2)) / u2**2

    lo = 2 * math.sqrt(bending * effective) * (1 + 1e-9) + 1e-9
    grid = np.linspace(lo, lo + 40 * bending / length, 4000)
    values = f(grid)  # the first sign change brackets the smallest root
    change = np.flatnonzero((values[:-1] == 0) | (np.sign(values[:-1]) != np.sign(values[1:])))
    if not len(change):
        raise ValueError(f"no clamped Greenhill root for T = {tension:g} N, L = {length:g} m")
    i = change[0]
    return brentq(lambda m: float(f(m)), grid[i], grid[i + 1])


def stretched_rod_buckling_moments(force: float, youngs_modulus: float, radius: float,
                                   length: float) -> tuple[float, float, float]:
    """(e, clamped Greenhill M_c, 2√(B·F)) for the incompressible rod of rest radius `radius`
    and rest length `length` stretched by an axial force: e = 1/(1 − F/(E·A0)), and the
    straight stretched rod has length e·L0 and bending stiffness B/e² (I = I0/e²)."""
    bending = youngs_modulus * units.second_moment_of_area(radius)
    e = units.extension_under_load(youngs_modulus, radius, force)
    return (e, greenhill_clamped_moment(force, e * length, bending / e**2),
            long_rod_buckling_moment(force, bending / e**2))


def long_rod_buckling_moment(tension: float, bending: float) -> float:
    """M_c = 2√(B·T) [N m], the buckling moment of a long rod under tension."""
    return 2.0 * math.sqrt(bending * tension)


def straight_rod_buckling_turns(force: float, youngs_modulus: float, shear_modulus: float,
                                radius: float, length: float) -> float:
    """Turns of end rotation at which the straight incompressible rod of rest radius `radius`
    and rest length `length`, stretched by `force` [N] and clamped at both ends, buckles by
    the clamped Greenhill criterion (the paper's law: B = E·I0/e², G·J = G·J0/e² at
    L = e·L0): θ_c = M_c·e·L0/(G·J0/e²) = M_c·e³·L0/(G·J0), in turns θ_c/2π."""
    e = units.extension_under_load(youngs_modulus, radius, force)
    second = units.second_moment_of_area(radius)
    return stretched_greenhill_turns(force, e, length, youngs_modulus * second,
                                     shear_modulus * 2.0 * second)


def stretched_greenhill_turns(tension: float, extension: float, length: float, bending: float,
                              twist: float) -> float:
    """The clamped Greenhill twist [turns] of a rod of rest length `length`, rest bending and
    twist stiffnesses `bending`, `twist` [N m²], stretched to `extension` e by `tension` [N]
    with the paper's incompressible thinning (B/e², C/e² at length e·L0), unshearable:
    θ_c = M_c(T, e·L0, B/e²)·e·L0/(C/e²). sheared_greenhill_turns at S = ∞."""
    return sheared_greenhill_turns(tension, extension, length, bending, twist, math.inf)


def sheared_greenhill_turns(tension: float, extension: float, length: float, bending: float,
                            twist: float, shear: float) -> float:
    """The clamped Greenhill twist [turns] of a shearable rod of rest length `length`, rest
    bending and twist stiffnesses `bending`, `twist` [N m²] and shear stiffness `shear` [N],
    stretched to `extension` e by `tension` [N] under the paper's law: B/e², C/e² at length
    e·L0, and S unchanged (its force's 1/e cancels the e of its shear strain per rest
    length: sheared_greenhill_clamped_moment), θ_c = M_c(T, e·L0, B/e², S)·e·L0/(C/e²)."""
    e = extension
    moment = sheared_greenhill_clamped_moment(tension, e * length, bending / e**2, shear)
    return moment * e * length / (twist / e**2) / units.TURN
