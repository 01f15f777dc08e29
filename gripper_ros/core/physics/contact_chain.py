"""Flexible fingers and nonlinear pads: the normal contact as a series chain (no ROS).

The gripping force passes through the moving finger, its pad, the object, the other pad and the
fixed finger, all in series, so all of them carry the same force ``F`` and their compressions
add up to the finger's travel past the object's face, ``u = x - x_c``:

    u = 2 F / k_f + 2 (F / k_p)^(2/3) + d_o(F)

* each finger bends as a cantilever loaded at its pad, linear with stiffness ``k_f = 3 E I /
  L^3`` (Euler-Bernoulli; ``contact.finger_stiffness_n_per_m``);
* each pad is a rubber dome pressed on the object, Hertz's law ``F = k_p delta^(3/2)`` with ``k_p
  = 4/3 E* sqrt(R)`` (H. Hertz, "Ueber die Beruehrung fester elastischer Koerper", J. reine
  angew. Math. 92, 1882; K. L. Johnson, Contact Mechanics, 1985, eq. 4.22;
  ``contact.pad_normal_stiffness_n_per_m1_5``): soft at touch, stiffening as it is pressed;
* the object is rigid (``d_o = 0``) or Kelvin-Voigt, ``F = k_o d_o + c_o d_o'``.

The fingers and pads are massless next to the motor's 546 kg reflected to the finger, so the
chain is quasi-static: one scalar equation per instant. The plant's contact kernels
(:mod:`gripper_ros.core.physics.contact`) solve it each sub-step implicitly (:func:`chain_solve`):
the object's damper by backward Euler, the motor's response to the force by the trapezoidal rule
over the exact zero-order-hold model, which leaves one equation in the pad's compression,
increasing and convex, solved by Newton's method kept inside a shrinking bracket.
"""
from __future__ import annotations

import math

import numba

PADS_IN_CHAIN = 2              # both fingers bend and both pads are pressed, in series
HERTZ_EXPONENT = 1.5           # F = k_p delta^1.5 (Hertz)
NEWTON_MAX_ITERATIONS = 60
NEWTON_RELATIVE_TOLERANCE = 1e-13
NEWTON_ABSOLUTE_TOLERANCE_M = 1e-16

# A plausible finger and pad, for the sweep's flexible kinds (contact_sweep --fingers). Finger:
# a cantilever 60 mm long, 20 mm wide and 10 mm thick, printed in PLA (E = 3.5 GPa, datasheet
# figure for printed PLA), or machined 6 mm thick in aluminium 6061 (E = 69 GPa).
PRINTED_FINGER = {'youngs_modulus_pa': 3.5e9, 'length_m': 0.06, 'width_m': 0.02,
                  'thickness_m': 0.010}
ALUMINIUM_FINGER = {'youngs_modulus_pa': 69e9, 'length_m': 0.06, 'width_m': 0.02,
                    'thickness_m': 0.006}
# Pad: a rubber dome of 20 mm radius, E = 3 MPa (about Shore 60A), incompressible (nu = 0.5),
# on a flat object.
RUBBER_DOME_PAD = {'youngs_modulus_pa': 3.0e6, 'poisson_ratio': 0.5, 'radius_m': 0.02}


def cantilever_stiffness_n_per_m(youngs_modulus_pa: float, length_m: float, width_m: float,
                                 thickness_m: float) -> float:
    """Return ``3 E I / L^3``, a rectangular cantilever's stiffness at its free end."""
    second_moment_m4 = width_m * thickness_m ** 3 / 12.0
    return 3.0 * youngs_modulus_pa * second_moment_m4 / length_m ** 3


def hertz_pad_stiffness_n_per_m1_5(youngs_modulus_pa: float, poisson_ratio: float,
                                   radius_m: float) -> float:
    """Return ``k_p = 4/3 E* sqrt(R)`` of an elastic dome on a rigid flat (Hertz)."""
    return 4.0 / 3.0 * youngs_modulus_pa / (1.0 - poisson_ratio ** 2) * math.sqrt(radius_m)


def chain_compression_m(force_n: float, finger_stiffness_n_per_m: float,
                        pad_stiffness_n_per_m1_5: float, object_stiffness_n_per_m: float = 0.0
                        ) -> float:
    """Return the static travel past the object's face at which the chain carries ``force_n``.

    ``2 F / k_f + 2 (F / k_p)^(2/3) + F / k_o``; a stiffness of 0 is a rigid part (no term).
    """
    u = 0.0
    if finger_stiffness_n_per_m > 0.0:
        u += PADS_IN_CHAIN * force_n / finger_stiffness_n_per_m
    if pad_stiffness_n_per_m1_5 > 0.0:
        u += PADS_IN_CHAIN * (force_n / pad_stiffness_n_per_m1_5) ** (1.0 / HERTZ_EXPONENT)
    if object_stiffness_n_per_m > 0.0:
        u += force_n / object_stiffness_n_per_m
    return u


@numba.njit(cache=True)
def chain_solve(travel_m, compliance_m_per_n, pad_stiffness_n_per_m1_5, pad_guess_m):
    """Return ``(F, delta)``: the chain's force and each pad's compression for a travel.

    Solves ``2 delta + C F = travel`` with ``F = k_p delta^1.5`` (``k_p`` = 0: no pad, ``delta``
    = 0 and ``F = travel / C``), where ``C`` > 0 is the linear compliance in series with the
    pads. No travel (<= 0): no force. The left side is increasing and convex in ``delta``, so
    Newton's method from any start lands right of the root and then descends to it; the
    iterate is also kept inside the bracket ``[0, travel / 2]`` that each evaluation narrows
    (bisection if a step would leave it). ``pad_guess_m`` (the last sub-step's) starts it.
    """
    if not travel_m > 0.0:
        return 0.0, 0.0
    if pad_stiffness_n_per_m1_5 == 0.0:
        return travel_m / compliance_m_per_n, 0.0
    two = float(PADS_IN_CHAIN)
    ck = compliance_m_per_n * pad_stiffness_n_per_m1_5
    lo = 0.0
    hi = travel_m / two
    delta = pad_guess_m if 0.0 < pad_guess_m < hi else hi
    for _ in range(NEWTON_MAX_ITERATIONS):
        root = math.sqrt(delta)
        residual = two * delta + ck * delta * root - travel_m
        if residual > 0.0:
            hi = delta
        else:
            lo = delta
        step = residual / (two + HERTZ_EXPONENT * ck * root)
        new = delta - step
        if not lo <= new <= hi:
            new = 0.5 * (lo + hi)
        done = abs(new - delta) <= NEWTON_RELATIVE_TOLERANCE * new + \
            NEWTON_ABSOLUTE_TOLERANCE_M
        delta = new
        if done:
            break
    return pad_stiffness_n_per_m1_5 * delta * math.sqrt(delta), delta
