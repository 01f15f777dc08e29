"""The motor and lead screw discretised exactly (zero-order hold), and the two caches of it.

State ``[i_a (A), omega (rad/s), x (m)]`` (paper eqs. 1-11) under a voltage held over ``dt_s``:
the matrix exponential is computed in Python (:func:`discretise`, with
:func:`gripper_ros.core.linalg.expm`) and kept twice: in a dict shared by every plant of the
process (a sweep builds many), and in each plant's table of the kernel buffers (keys ``(kind,
dt_s, k, c, x_c)``, :data:`DISC_COEFFICIENTS` coefficients each), which the kernels search; a
table miss calls :func:`discretise` in object mode, so every coefficient is the one the Python
plant used.
"""
from __future__ import annotations

import math

from gripper_ros.core.config import PlantParams
from gripper_ros.core.linalg import expm
import numba
import numpy as np

MAX_CACHED_DISCRETISATIONS = 256

# Discretisation kinds (column 0 of the table's keys).
DISC_FREE = 0
DISC_COMPLIANT = 1
DISC_LOADED = 2
DISC_TABLE_SIZE = 64          # entries of the plant's table (a grasp uses about 8)
DISC_COEFFICIENTS = 15        # one entry's coefficients, in one of the two layouts below
DISC_KEYS = 5                 # one entry's key: kind, dt_s, stiffness, damping, x_c
# DISC_FREE and DISC_COMPLIANT: rows i, omega, x of the augmented Ad (over [i, omega, x, 1],
# so the contact's affine term is exact), then Bd. AFF_WX is omega's row, x's column.
(AFF_II, AFF_IW, AFF_IX, AFF_I1, AFF_WI, AFF_WW, AFF_WX, AFF_W1, AFF_XI, AFF_XW, AFF_XX,
 AFF_X1, AFF_IE, AFF_WE, AFF_XE) = range(DISC_COEFFICIENTS)
# DISC_LOADED: Ad (3 x 3) row by row, then Bd's rows over the inputs (voltage E, load force F).
(LD_II, LD_IW, LD_IX, LD_WI, LD_WW, LD_WX, LD_XI, LD_XW, LD_XX, LD_IE, LD_IF, LD_WE, LD_WF,
 LD_XE, LD_XF) = range(DISC_COEFFICIENTS)


# ----------------------------------------------------------------------------- discretisation
# Exact ZOH coefficients, shared by all plants (a sweep builds many):
# (constants, kind, dt_s, k, c, x_c) -> DISC_COEFFICIENTS coefficients.
_DISCRETISATIONS: dict[tuple, np.ndarray] = {}


def discretise(raw: tuple, kind: int, dt_s: float, stiffness: float, damping: float,
               x_c: float) -> np.ndarray:
    """Exact ZOH over ``dt_s`` (:func:`linalg.expm`), flat.

    In the layout ``AFF_*`` (free, compliant) or ``LD_*`` (loaded: a held voltage and load force
    in N). ``raw`` = (R, L, k_b, k_t, J, b, rho, lever).
    """
    key = (raw, kind, dt_s, stiffness, damping, x_c)
    cached = _DISCRETISATIONS.get(key)
    if cached is not None:
        return cached
    r, ind, kb, kt, inertia, b, rho, lever = raw
    a_free = np.array([[-r / ind, -kb / ind, 0.0],
                       [kt / inertia, -b / inertia, 0.0],
                       [0.0, rho, 0.0]])
    b0 = 1.0 / ind
    if kind == DISC_LOADED:
        m = np.zeros((5, 5))
        m[:3, :3] = a_free * dt_s
        m[0, 3] = b0 * dt_s
        m[1, 4] = -lever / inertia * dt_s
        phi = expm(m)
        out = np.concatenate((phi[:3, :3].ravel(), phi[:3, 3:5].ravel()))
    else:
        a = np.zeros((4, 4))
        a[:3, :3] = a_free
        if kind == DISC_COMPLIANT:
            a[1, 1] -= lever * damping * rho / inertia
            a[1, 2] -= lever * stiffness / inertia
            a[1, 3] += lever * stiffness * x_c / inertia
        m = np.zeros((5, 5))
        m[:4, :4] = a * dt_s
        m[0, 4] = b0 * dt_s
        phi = expm(m)
        out = np.concatenate((phi[:3, :4].ravel(), phi[:3, 4]))
    if len(_DISCRETISATIONS) > 4 * MAX_CACHED_DISCRETISATIONS:
        _DISCRETISATIONS.clear()
    _DISCRETISATIONS[key] = out
    return out


def free_model(params: PlantParams, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH model of free motion: ``s[k+1] = Ad s[k] + Bd e[k]``, s = [i, omega, x]."""
    c = discretise(raw_constants(params), DISC_FREE, dt_s, 0.0, 0.0, 0.0).tolist()
    return (np.array([c[AFF_II:AFF_I1], c[AFF_WI:AFF_W1], c[AFF_XI:AFF_X1]]),
            np.array(c[AFF_IE:AFF_XE + 1]))


def force_model(params: PlantParams, dt_s: float) -> tuple[float, float]:
    """Exact ZOH of eq. 13: ``F[k+1] = a F[k] + b e[k]`` on a rigid object."""
    a = math.exp(-dt_s / (params.inductance_h / params.resistance_ohm))
    return a, params.stall_force_per_volt_n * (1.0 - a)


def raw_constants(params: PlantParams) -> tuple:
    p = params
    return (p.resistance_ohm, p.inductance_h, p.back_emf_v_s_per_rad,
            p.torque_constant_n_m_per_a, p.inertia_kg_m2, p.damping_n_m_s_per_rad,
            p.travel_per_rad_m, p.force_lever_m)


def _discretise_from_kernel(r, ind, kb, kt, inertia, b, rho, lever, kind, dt_s, stiffness,
                            damping, x_c):
    """:func:`discretise` for the kernels' table (called in object mode on a miss)."""
    return discretise((r, ind, kb, kt, inertia, b, rho, lever), int(kind), dt_s, stiffness,
                      damping, x_c)


@numba.njit(cache=True, inline='always')
def disc_entry(s, p, keys, coef, kind, dt_s):
    """Row of the discretisation table for ``kind`` over ``dt_s`` (computed on a miss)."""
    if kind == DISC_COMPLIANT:
        stiffness = s.stiffness_n_per_m
        damping = s.damping_n_s_per_m
        x_c = s.x_c
    else:
        stiffness = 0.0
        damping = 0.0
        x_c = 0.0
    j = s.disc_last
    if j < s.disc_count and keys[j, 0] == kind and keys[j, 1] == dt_s and \
            keys[j, 2] == stiffness and keys[j, 3] == damping and keys[j, 4] == x_c:
        return j
    for j in range(s.disc_count):
        if keys[j, 0] == kind and keys[j, 1] == dt_s and keys[j, 2] == stiffness and \
                keys[j, 3] == damping and keys[j, 4] == x_c:
            s.disc_last = j
            return j
    return _disc_miss(s, p, keys, coef, kind, dt_s, stiffness, damping, x_c)


@numba.njit(cache=True)
def _disc_miss(s, p, keys, coef, kind, dt_s, stiffness, damping, x_c):
    """Compute a discretisation in Python (:func:`linalg.expm`) and store it in the table."""
    r = p.resistance_ohm
    ind = p.inductance_h
    kb = p.kb
    kt = p.kt
    inertia = p.inertia_kg_m2
    b = p.damping_n_m_s_per_rad
    rho = p.rho
    lever = p.lever
    fkind = float(kind)
    with numba.objmode(out='float64[:]'):
        out = _discretise_from_kernel(r, ind, kb, kt, inertia, b, rho, lever, fkind, dt_s,
                                      stiffness, damping, x_c)
    j = s.disc_next
    keys[j, 0] = kind
    keys[j, 1] = dt_s
    keys[j, 2] = stiffness
    keys[j, 3] = damping
    keys[j, 4] = x_c
    for n in range(DISC_COEFFICIENTS):
        coef[j, n] = out[n]
    s.disc_next = (j + 1) % DISC_TABLE_SIZE
    if s.disc_count < DISC_TABLE_SIZE:
        s.disc_count += 1
    s.disc_last = j
    return j


@numba.njit(cache=True, inline='always')
def advance_zoh(s, p, keys, coef, kind, e, dt_s):
    """Exact ZOH step of free motion (DISC_FREE) or of compressing a Kelvin-Voigt object."""
    c = coef[disc_entry(s, p, keys, coef, kind, dt_s)]
    i = s.i
    w = s.w
    x = s.x
    s.i = c[AFF_II] * i + c[AFF_IW] * w + c[AFF_IX] * x + c[AFF_I1] + c[AFF_IE] * e
    s.w = c[AFF_WI] * i + c[AFF_WW] * w + c[AFF_WX] * x + c[AFF_W1] + c[AFF_WE] * e
    s.x = c[AFF_XI] * i + c[AFF_XW] * w + c[AFF_XX] * x + c[AFF_X1] + c[AFF_XE] * e
