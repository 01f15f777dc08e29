"""Small dense linear algebra whose results are the same bits on every CPU.

BLAS and LAPACK (numpy's ``@``, ``np.dot``, ``np.linalg``, scipy's ``expm``, and numba's
``np.dot``, which calls BLAS too) pick their kernels by the CPU they run on: OpenBLAS sums a dot
product in a different order on an AVX-512 core than on an AVX2 one, so the last bits of a DMC
gain or a ZOH model, and every tick after them, depend on the machine. The core's models are
small (3 x 3 to 5 x 5, a DMC gain of a few hundred columns), so it does its linear algebra here:
plain loops in one fixed order, compiled by numba without fast-math, which neither reorders
floating-point sums nor fuses a multiply and an add. The compiled functions therefore give
exactly the interpreted ones' IEEE results (``f.py_func``), whatever the CPU or numba's target.
"""
from __future__ import annotations

import math

from gripper_ros.core.records import face_kernel, FLOATS, FLOATS_2D
import numba
import numpy as np

# Higham (2005), "The scaling and squaring method for the matrix exponential revisited":
# the largest 1-norm for which the [m/m] Pade approximant is accurate to double precision.
PADE_THETA_3 = 1.495585217958292e-2
PADE_THETA_5 = 2.539398330063230e-1
PADE_THETA_7 = 9.504178996162932e-1
PADE_THETA_9 = 2.097847961257068e0
PADE_THETA_13 = 5.371920351148152e0

_PADE_3 = np.array([120.0, 60.0, 12.0, 1.0])
_PADE_5 = np.array([30240.0, 15120.0, 3360.0, 420.0, 30.0, 1.0])
_PADE_7 = np.array([17297280.0, 8648640.0, 1995840.0, 277200.0, 25200.0, 1512.0, 56.0, 1.0])
_PADE_9 = np.array([17643225600.0, 8821612800.0, 2075673600.0, 302702400.0, 30270240.0,
                    2162160.0, 110880.0, 3960.0, 90.0, 1.0])
_PADE_13 = np.array([64764752532480000.0, 32382376266240000.0, 7771770303897600.0,
                     1187353796428800.0, 129060195264000.0, 10559470521600.0, 670442572800.0,
                     33522128640.0, 1323241920.0, 40840800.0, 960960.0, 16380.0, 182.0, 1.0])


@numba.njit(cache=True)
def dot(x, y):
    """Return sum_k x[k] y[k], summed from k = 0 up."""
    total = 0.0
    for k in range(x.shape[0]):
        total += x[k] * y[k]
    return total


@numba.njit(cache=True)
def matvec_into(a, x, out):
    """``out[i] = sum_j a[i, j] x[j]`` (each sum from j = 0 up); returns ``out``."""
    for i in range(a.shape[0]):
        total = 0.0
        for j in range(a.shape[1]):
            total += a[i, j] * x[j]
        out[i] = total
    return out


@face_kernel(FLOATS_2D, FLOATS)
@numba.njit(cache=True)
def matvec(a, x):
    """Return ``a x`` as a new vector."""
    return matvec_into(a, x, np.empty(a.shape[0]))


@face_kernel(FLOATS_2D, FLOATS_2D)
@numba.njit(cache=True)
def matmul(a, b):
    """Return ``a b``; each entry summed over the inner index from 0 up."""
    n, m = a.shape
    p = b.shape[1]
    if b.shape[0] != m:
        raise ValueError('matmul: inner dimensions differ')
    out = np.empty((n, p))
    for i in range(n):
        for j in range(p):
            total = 0.0
            for k in range(m):
                total += a[i, k] * b[k, j]
            out[i, j] = total
    return out


@face_kernel(FLOATS_2D, FLOATS_2D)
@numba.njit(cache=True)
def solve(a, b):
    """Return X with ``a X = b`` (b 2-D): Gaussian elimination with partial pivoting.

    The pivot is the first row of largest magnitude in its column; a zero pivot (a singular
    matrix) raises ValueError.
    """
    n = a.shape[0]
    if a.shape[1] != n or b.shape[0] != n:
        raise ValueError('solve: a must be square with as many rows as b')
    m = a.copy()
    x = b.copy()
    cols = x.shape[1]
    for c in range(n):
        pivot = c
        biggest = abs(m[c, c])
        for r in range(c + 1, n):
            if abs(m[r, c]) > biggest:
                biggest = abs(m[r, c])
                pivot = r
        if biggest == 0.0:
            raise ValueError('solve: the matrix is singular')
        if pivot != c:
            for j in range(n):
                m[c, j], m[pivot, j] = m[pivot, j], m[c, j]
            for j in range(cols):
                x[c, j], x[pivot, j] = x[pivot, j], x[c, j]
        for r in range(c + 1, n):
            f = m[r, c] / m[c, c]
            if f != 0.0:
                for j in range(c, n):
                    m[r, j] -= f * m[c, j]
                for j in range(cols):
                    x[r, j] -= f * x[c, j]
    for c in range(n - 1, -1, -1):
        for j in range(cols):
            total = x[c, j]
            for k in range(c + 1, n):
                total -= m[c, k] * x[k, j]
            x[c, j] = total / m[c, c]
    return x


@numba.njit(cache=True)
def _norm_1(a):
    """Return the largest column sum of magnitudes."""
    best = 0.0
    for j in range(a.shape[1]):
        total = 0.0
        for i in range(a.shape[0]):
            total += abs(a[i, j])
        if total > best:
            best = total
    return best


@numba.njit(cache=True)
def _combine(terms, coef, start):
    """Return ``sum_k coef[start + 2k] terms[k]``: the even (or odd) half of a Pade sum."""
    n = terms.shape[1]
    out = np.zeros((n, n))
    for k in range(terms.shape[0]):
        c = coef[start + 2 * k]
        for i in range(n):
            for j in range(n):
                out[i, j] += c * terms[k, i, j]
    return out


@numba.njit(cache=True)
def _powers(a, count):
    """Return I, A^2, A^4, ...: ``count`` even powers of ``a``."""
    n = a.shape[0]
    out = np.zeros((count, n, n))
    for i in range(n):
        out[0, i, i] = 1.0
    if count > 1:
        a2 = matmul(a, a)
        out[1] = a2
        for k in range(2, count):
            out[k] = matmul(out[k - 1], a2)
    return out


@numba.njit(cache=True)
def _pade_quotient(u, v):
    """Solve ``(V - U) R = V + U`` for R, the Pade approximant of exp."""
    return solve(v - u, v + u)


@numba.njit(cache=True)
def _pade_low(a, coef):
    """Return the [m/m] approximant, m in 3, 5, 7, 9 (``coef``: its m + 1 coefficients)."""
    even = _powers(a, (coef.shape[0] + 1) // 2)
    u = matmul(a, _combine(even, coef, 1))
    v = _combine(even, coef, 0)
    return _pade_quotient(u, v)


@numba.njit(cache=True)
def _pade_13(a):
    """Return the [13/13] approximant, evaluated as in Higham (2005), eq. 10.3."""
    b = _PADE_13
    n = a.shape[0]
    eye = np.eye(n)
    a2 = matmul(a, a)
    a4 = matmul(a2, a2)
    a6 = matmul(a4, a2)
    u_inner = matmul(a6, b[13] * a6 + b[11] * a4 + b[9] * a2)
    u = matmul(a, u_inner + b[7] * a6 + b[5] * a4 + b[3] * a2 + b[1] * eye)
    v = matmul(a6, b[12] * a6 + b[10] * a4 + b[8] * a2) + b[6] * a6 + b[4] * a4 \
        + b[2] * a2 + b[0] * eye
    return _pade_quotient(u, v)


@face_kernel(FLOATS_2D)
@numba.njit(cache=True)
def expm(a):
    """Matrix exponential by scaling and squaring with Pade approximants (Higham 2005).

    The degree is the lowest of 3, 5, 7, 9 whose bound covers ``a``'s 1-norm, else 13 on
    ``a / 2^s``, squared ``s`` times; halving and the count ``s`` are exact.
    """
    if a.shape[0] != a.shape[1]:
        raise ValueError('expm: the matrix must be square')
    for value in a.flat:
        if not math.isfinite(value):
            raise ValueError('expm: the matrix must be finite')
    norm = _norm_1(a)
    if norm <= PADE_THETA_3:
        return _pade_low(a, _PADE_3)
    if norm <= PADE_THETA_5:
        return _pade_low(a, _PADE_5)
    if norm <= PADE_THETA_7:
        return _pade_low(a, _PADE_7)
    if norm <= PADE_THETA_9:
        return _pade_low(a, _PADE_9)
    squarings = 0
    scale = 1.0
    while norm * scale > PADE_THETA_13:
        scale *= 0.5
        squarings += 1
    r = _pade_13(a * scale)
    for _ in range(squarings):
        r = matmul(r, r)
    return r
