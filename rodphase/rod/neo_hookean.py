"""Internal loads of a conservative incompressible law: one neo-Hookean strain energy.

The paper's incompressible law (Gazzola 2018: the force S(σ − σ0)/e, the couple
B(κ − κ0)/ε³) is not the gradient of any energy: an undamped rod gains energy under it
(issue #13). Here forces and couples are the exact derivatives of one discrete energy, so
position Verlet conserves it to O(dt²) without drift.

Strain energy per unit rest length, with λ the stretch of the centreline (the element's
dilatation e = |x_{i+1} − x_i| / l0, or the Voronoi domain's ε at a domain):

    W = EA0/6·(λ² + 2/λ − 3)  +  ½·S·(σ1² + σ2²)  +  ½·EI0·b(λ)·(κ1² + κ2²)  +  ½·GJ0·κ3²/λ
    b(λ) = (1 + 2λ⁻³) / (3λ)

(κ − κ0 and σ − σ0 in place of κ and σ; κ per unit rest length, the kernel's). Derivation,
from an incompressible neo-Hookean solid, w = μ/2·(I1 − 3) per unit reference volume,
E = 3μ, a cylinder of rest radius a0 stretched by λ (radius a0/√λ, so A = A0/λ, I = I0/λ²):

- Stretch: I1 = λ² + 2/λ, so A0·w = EA0/6·(λ² + 2/λ − 3); tension dW/dλ = EA0/3·(λ − λ⁻²)
  (= μA0(λ − λ⁻²), the exact uniaxial one; slope EA0 at λ = 1, as the paper's EA0(1 − 1/λ)).
- Bending: a fibre at rest distance Y from the neutral axis sits at Y/√λ and is stretched
  by λ(1 − κ_c·Y/√λ), κ_c = κ/λ the current curvature, i.e. by λ + δ with δ = −κY/√λ.
  Expanding each fibre's uniaxial energy u(λ) = μ/2(λ² + 2/λ − 3) to second order, the
  linear term integrates to zero over the section and u'' = μ(1 + 2λ⁻³) leaves
  ½·μ(1 + 2λ⁻³)·κ²·∫Y²/λ dA0 = ½·EI0·b(λ)·κ². b(1) = 1 and b'(1) = −3, as the paper's 1/λ³
  to first order in the stretch. (The fibre model neglects the lateral stresses of the
  bent section: a strain energy all the same, which is what conservation needs.)
- Twist: extension plus torsion, r = R/√λ, θ = Θ + ψz, z = λZ, is an exact incompressible
  deformation; F has the θz entry rψλ, so I1 = λ² + 2/λ + r²ψ²λ² = λ² + 2/λ + R²ψ²λ. With Φ =
  ψλ the twist per unit rest length (the kernel's κ3), the twist energy is
  ∫ μ/2·R²Φ²/λ dA0 = ½·GJ0·Φ²/λ and the torque GJ0·Φ/λ (the Cauchy stress σ_θz = μrψλ²
  integrated over the current section gives the same, μJ0ψ). The torque (π/2)μa0⁴Φ/λ³ of
  issue #13 is μ·J·ψ with the current J = J0/λ² *and* the current twist ψ = Φ/λ: that is the
  paper's couple B/ε³, not the neo-Hookean one; this law uses GJ0·Φ/λ.

The moduli at λ = 1 are the rod's own (EA0, EI0, GJ0 with the configured G, the paper's
2E/3, and the shear S = 4GA0/3), so both laws agree to first order in the strain and differ
only in how the stiffnesses follow a finite stretch. The shear energy keeps its rest
stiffness; rest_shear[2] is not used (the axial strain is λ − 1, measured along the
centreline, not along d3). The rotary inertia keeps its rest value ρJ0·l0 (with ρJ0/λ the
kinetic energy would depend on the configuration, and rotary inertia does not change
equilibria). The contact radius still thins as a0/√e, as for the paper's law.

Derivatives. With t_i = x_{i+1} − x_i and θ_j = D0_j·κ_j the rotation vector of
R_j = Q_j Q_{j+1}ᵀ, a body rotation δφ of Q_j changes θ_j by −J_l⁻¹(θ)δφ and one of Q_{j+1}
by J_r⁻¹(θ)δψ, J⁻¹ = I ∓ ½[θ]× + β[θ]×², β(θ) = 1/θ² − (1 + cosθ)/(2θ sinθ). With the couple
c = ∂W/∂θ the torques are
    on Q_j:      c + ½ θ×c + β θ×(θ×c),
    on Q_{j+1}: −c + ½ θ×c − β θ×(θ×c);
the paper's law keeps the first two terms (β θ×(θ×c) is O(θ²) of c). The Voronoi dilatation
ε_j = (l_j + l_{j+1})/(2 D0_j) puts ∂W_j/∂ε_j / (2 D0_j) into the tension of both elements.
"""

import numpy as np

from ._jit import FASTMATH as _FASTMATH
from ._jit import njit
from .rotation import log_factor

N_WORK = 17  # rows of the scratch array internal_loads_neo_hookean needs, each of length n


@njit(cache=True, inline="always")
def bend_factor(lam):
    """b(λ) = (1 + 2λ⁻³)/(3λ) and its derivative."""
    inv = 1.0 / lam
    inv3 = inv * inv * inv
    return (inv + 2.0 * inv3 * inv) / 3.0, -(inv * inv + 8.0 * inv3 * inv * inv) / 3.0


@njit(cache=True, inline="always")
def log_correction(theta2, s2, cos_th):
    """β(θ) = 1/θ² − (1 + cosθ)/(2θ sinθ), the [θ]×² coefficient of the inverse Jacobian
    of the rotation vector, from θ², sin²θ and cosθ."""
    if theta2 < 0.09:
        # 1/12 + θ²/720 + θ⁴/30240 + θ⁶/1209600: the next term is θ⁸/4.8e7, < 2e-11 of β
        # for θ < 0.3, where the closed form loses up to 3 digits to cancellation
        return 1.0 / 12.0 + theta2 * (1.0 / 720.0 + theta2 * (
            1.0 / 30240.0 + theta2 / 1209600.0))
    theta = np.sqrt(theta2)
    return 1.0 / theta2 - (1.0 + cos_th) / (2.0 * theta * np.sqrt(s2))


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def voronoi_rotation(A, j, B, k):
    """Half the skew part (a0, a1, a2) of R = A_j B_kᵀ (sinθ times its axis) and cosθ, for
    frames A[:, :, j] and B[:, :, k]."""
    r01 = A[0, 0, j] * B[1, 0, k] + A[0, 1, j] * B[1, 1, k] + A[0, 2, j] * B[1, 2, k]
    r10 = A[1, 0, j] * B[0, 0, k] + A[1, 1, j] * B[0, 1, k] + A[1, 2, j] * B[0, 2, k]
    r02 = A[0, 0, j] * B[2, 0, k] + A[0, 1, j] * B[2, 1, k] + A[0, 2, j] * B[2, 2, k]
    r20 = A[2, 0, j] * B[0, 0, k] + A[2, 1, j] * B[0, 1, k] + A[2, 2, j] * B[0, 2, k]
    r12 = A[1, 0, j] * B[2, 0, k] + A[1, 1, j] * B[2, 1, k] + A[1, 2, j] * B[2, 2, k]
    r21 = A[2, 0, j] * B[1, 0, k] + A[2, 1, j] * B[1, 1, k] + A[2, 2, j] * B[1, 2, k]
    r00 = A[0, 0, j] * B[0, 0, k] + A[0, 1, j] * B[0, 1, k] + A[0, 2, j] * B[0, 2, k]
    r11 = A[1, 0, j] * B[1, 0, k] + A[1, 1, j] * B[1, 1, k] + A[1, 2, j] * B[1, 2, k]
    r22 = A[2, 0, j] * B[2, 0, k] + A[2, 1, j] * B[2, 1, k] + A[2, 2, j] * B[2, 2, k]
    return 0.5 * (r21 - r12), 0.5 * (r02 - r20), 0.5 * (r10 - r01), 0.5 * (r00 + r11 + r22 - 1.0)


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def frame_rotation(A, B):
    """voronoi_rotation for two (3, 3) frames."""
    r01 = A[0, 0] * B[1, 0] + A[0, 1] * B[1, 1] + A[0, 2] * B[1, 2]
    r10 = A[1, 0] * B[0, 0] + A[1, 1] * B[0, 1] + A[1, 2] * B[0, 2]
    r02 = A[0, 0] * B[2, 0] + A[0, 1] * B[2, 1] + A[0, 2] * B[2, 2]
    r20 = A[2, 0] * B[0, 0] + A[2, 1] * B[0, 1] + A[2, 2] * B[0, 2]
    r12 = A[1, 0] * B[2, 0] + A[1, 1] * B[2, 1] + A[1, 2] * B[2, 2]
    r21 = A[2, 0] * B[1, 0] + A[2, 1] * B[1, 1] + A[2, 2] * B[1, 2]
    trace = (A[0, 0] * B[0, 0] + A[0, 1] * B[0, 1] + A[0, 2] * B[0, 2] + A[1, 0] * B[1, 0]
             + A[1, 1] * B[1, 1] + A[1, 2] * B[1, 2] + A[2, 0] * B[2, 0] + A[2, 1] * B[2, 1]
             + A[2, 2] * B[2, 2])
    return 0.5 * (r21 - r12), 0.5 * (r02 - r20), 0.5 * (r10 - r01), 0.5 * (trace - 1.0)


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def spring_couple(a0, a1, a2, cos_th, factor, rest_voronoi, lam, d0, d1, d2, b0, b1, b2, out):
    """The bend-twist spring of one Voronoi domain (or clamp half element) of rest length
    rest_voronoi and stretch lam, given its rotation (a, cosθ, θ/sinθ) and κ − κ0 = d.

    out[0:3] = c + β θ×(θ×c), out[3:6] = ½ θ×c (see the module docstring for the signs),
    out[6] the energy, out[7] ∂energy/∂λ; b0, b1, b2 the rest stiffnesses EI1, EI2, GJ.
    """
    b, db = bend_factor(lam)
    inv = 1.0 / lam
    m0 = b * b0 * d0
    m1 = b * b1 * d1
    m2 = inv * b2 * d2
    out[6] = 0.5 * (m0 * d0 + m1 * d1 + m2 * d2) * rest_voronoi
    out[7] = 0.5 * (db * (b0 * d0 * d0 + b1 * d1 * d1) - inv * inv * b2 * d2 * d2) * rest_voronoi
    t0 = a0 * factor
    t1 = a1 * factor
    t2 = a2 * factor
    u0 = t1 * m2 - t2 * m1
    u1 = t2 * m0 - t0 * m2
    u2 = t0 * m1 - t1 * m0
    s2 = a0 * a0 + a1 * a1 + a2 * a2
    beta = log_correction(s2 * factor * factor, s2, cos_th)
    out[0] = m0 + beta * (t1 * u2 - t2 * u1)
    out[1] = m1 + beta * (t2 * u0 - t0 * u2)
    out[2] = m2 + beta * (t0 * u1 - t1 * u0)
    out[3] = 0.5 * u0
    out[4] = 0.5 * u1
    out[5] = 0.5 * u2


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def internal_loads_neo_hookean(x, v, Q, w, rest_length, rest_voronoi, inertia, shear_stiffness,
                               bend_stiffness, rest_curvature, rest_shear, local_mask,
                               f_shear, f_bend, f_inertia, f_twist, local_twist,
                               force, torque, dilatation, lengths, energies, work, spring):
    """Forces on nodes and torques on elements (material frame): −∂W/∂x and the rotational
    derivatives of the energy of the module docstring, plus the gyroscopic (Jω) × ω.

    Same arrays as kernel.internal_loads (energies[0] stretch and shear, energies[1] bend and
    twist, energies[2:4] the smallest neighbour cosine and where); work is (N_WORK, n)
    scratch and spring (8,) scratch.
    """
    n = rest_length.shape[0]
    nl0, nl1, nl2 = work[0], work[1], work[2]  # shear part of ∂W/∂t, lab frame
    sym0, sym1, sym2 = work[3], work[4], work[5]  # c + β θ×(θ×c) per Voronoi domain
    anti0, anti1, anti2 = work[6], work[7], work[8]  # ½ θ×c
    tension = work[9]  # ∂W/∂l_i [N]: the force along the tangent
    density = work[10]
    ka0, ka1, ka2 = work[11], work[12], work[13]
    cos_ = work[14]
    factor = work[15]
    axial = work[16]  # ∂W_j/∂ε_j / 2 at the Voronoi domains (to both elements' tension)

    for i in range(n):
        t0 = x[0, i + 1] - x[0, i]
        t1 = x[1, i + 1] - x[1, i]
        t2 = x[2, i + 1] - x[2, i]
        length = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        inv_l0 = 1.0 / rest_length[i]
        lam = length * inv_l0
        lengths[i] = length
        dilatation[i] = lam
        qt0 = Q[0, 0, i] * t0 + Q[0, 1, i] * t1 + Q[0, 2, i] * t2
        qt1 = Q[1, 0, i] * t0 + Q[1, 1, i] * t1 + Q[1, 2, i] * t2
        qt2 = Q[2, 0, i] * t0 + Q[2, 1, i] * t1 + Q[2, 2, i] * t2
        s0 = qt0 * inv_l0 - rest_shear[0, i]
        s1 = qt1 * inv_l0 - rest_shear[1, i]
        n0 = f_shear * shear_stiffness[0, i] * s0
        n1 = f_shear * shear_stiffness[1, i] * s1
        ea = f_shear * shear_stiffness[2, i]
        inv = 1.0 / lam
        density[i] = (ea / 6.0 * (lam * lam + 2.0 * inv - 3.0)
                      + 0.5 * (n0 * s0 + n1 * s1)) * rest_length[i]
        tension[i] = ea / 3.0 * (lam - inv * inv)
        nl0[i] = Q[0, 0, i] * n0 + Q[1, 0, i] * n1
        nl1[i] = Q[0, 1, i] * n0 + Q[1, 1, i] * n1
        nl2[i] = Q[0, 2, i] * n0 + Q[1, 2, i] * n1
        # the shear couple (Q t) × n with n = (n0, n1, 0); gyroscopic (Jω) × ω
        j0 = f_inertia * inertia[0, i] * w[0, i]
        j1 = f_inertia * inertia[1, i] * w[1, i]
        j2 = f_inertia * inertia[2, i] * w[2, i]
        torque[0, i] = -qt2 * n1 + j1 * w[2, i] - j2 * w[1, i]
        torque[1, i] = qt2 * n0 + j2 * w[0, i] - j0 * w[2, i]
        torque[2, i] = qt0 * n1 - qt1 * n0 + j0 * w[1, i] - j1 * w[0, i]
    stretch_energy = 0.0
    for i in range(n):
        stretch_energy += density[i]

    for j in range(n - 1):
        ka0[j], ka1[j], ka2[j], cos_[j] = voronoi_rotation(Q, j, Q, j + 1)
    worst_cos = 1.0
    worst_at = -1
    for j in range(n - 1):
        factor[j] = log_factor(ka0[j] * ka0[j] + ka1[j] * ka1[j] + ka2[j] * ka2[j], cos_[j])
        if cos_[j] < worst_cos:
            worst_cos = cos_[j]
            worst_at = j
    energies[2] = worst_cos
    energies[3] = worst_at
    bend_energy = 0.0
    for j in range(n - 1):
        f = factor[j] / rest_voronoi[j]
        eps = 0.5 * (lengths[j] + lengths[j + 1]) / rest_voronoi[j]
        spring_couple(ka0[j], ka1[j], ka2[j], cos_[j], factor[j], rest_voronoi[j], eps,
                      ka0[j] * f - rest_curvature[0, j], ka1[j] * f - rest_curvature[1, j],
                      ka2[j] * f - (f_twist * rest_curvature[2, j] + local_mask[j] * local_twist),
                      f_bend * bend_stiffness[0, j], f_bend * bend_stiffness[1, j],
                      f_bend * bend_stiffness[2, j], spring)
        sym0[j] = spring[0]
        sym1[j] = spring[1]
        sym2[j] = spring[2]
        anti0[j] = spring[3]
        anti1[j] = spring[4]
        anti2[j] = spring[5]
        bend_energy += spring[6]
        # ∂ε/∂l = 1/(2 D0) for both elements of the domain
        axial[j] = 0.5 * spring[7] / rest_voronoi[j]
    for i in range(n):
        acc0 = 0.0
        acc1 = 0.0
        acc2 = 0.0
        pull = tension[i]
        if i < n - 1:
            acc0 += sym0[i] + anti0[i]
            acc1 += sym1[i] + anti1[i]
            acc2 += sym2[i] + anti2[i]
            pull += axial[i]
        if i > 0:
            j = i - 1
            acc0 += anti0[j] - sym0[j]
            acc1 += anti1[j] - sym1[j]
            acc2 += anti2[j] - sym2[j]
            pull += axial[j]
        torque[0, i] += acc0
        torque[1, i] += acc1
        torque[2, i] += acc2
        # ∂W/∂t_i: the shear part plus (∂W/∂l_i) t̂_i
        p = pull / lengths[i]
        nl0[i] += p * (x[0, i + 1] - x[0, i])
        nl1[i] += p * (x[1, i + 1] - x[1, i])
        nl2[i] += p * (x[2, i + 1] - x[2, i])

    force[0, 0] = nl0[0]
    force[1, 0] = nl1[0]
    force[2, 0] = nl2[0]
    for i in range(1, n):
        force[0, i] = nl0[i] - nl0[i - 1]
        force[1, i] = nl1[i] - nl1[i - 1]
        force[2, i] = nl2[i] - nl2[i - 1]
    force[0, n] = -nl0[n - 1]
    force[1, n] = -nl1[n - 1]
    force[2, n] = -nl2[n - 1]
    energies[0] = stretch_energy
    energies[1] = bend_energy


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def clamp_couple_neo_hookean(A, B, element, x, rest_length, rest0, rest1, rest2, b0, b1, b2,
                             left, torque, force, energies, out):
    """The clamp spring between frames A and B (rows d1 d2 d3) over half of `element`, whose
    stretch it takes: the torque on the element (its frame is A if `left`, else B), the
    axial force of the spring's stretch dependence on the element's two nodes, the energy
    into energies[1]. out (8,): as spring_couple; returns the cosine between the frames."""
    a0, a1, a2, cos_th = frame_rotation(A, B)
    half = 0.5 * rest_length[element]
    factor = log_factor(a0 * a0 + a1 * a1 + a2 * a2, cos_th)
    t0 = x[0, element + 1] - x[0, element]
    t1 = x[1, element + 1] - x[1, element]
    t2 = x[2, element + 1] - x[2, element]
    length = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    f = factor / half
    spring_couple(a0, a1, a2, cos_th, factor, half, length / rest_length[element],
                  a0 * f - rest0, a1 * f - rest1, a2 * f - rest2, b0, b1, b2, out)
    sign = 1.0 if left else -1.0
    for c in range(3):
        torque[c, element] += sign * out[c] + out[3 + c]
    energies[1] += out[6]
    # ∂W/∂t = ∂W/∂λ · t̂ / l0: on node element (+) and element + 1 (−)
    p = out[7] / (rest_length[element] * length)
    force[0, element] += p * t0
    force[1, element] += p * t1
    force[2, element] += p * t2
    force[0, element + 1] -= p * t0
    force[1, element + 1] -= p * t1
    force[2, element + 1] -= p * t2
    return cos_th
