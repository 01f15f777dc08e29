"""The core's results are the same bits whatever the CPU's BLAS kernels, C library or numba.

OpenBLAS picks its kernels by the CPU (``OPENBLAS_CORETYPE`` forces another kind, as a machine of
that kind would run): a core that summed through BLAS gave other last bits on another CPU. The
core's linear algebra (:mod:`gripper_ros.core.linalg`) is held here to closed forms, to its own
interpreted code (the IEEE operations in the order written, ``NUMBA_DISABLE_JIT``), and a whole
grasp to the same bytes under other BLAS kernels and under the C library's code for CPUs
without FMA.
"""
from __future__ import annotations

import math
import os
from pathlib import Path
import subprocess
import sys

from gripper_ros.core import linalg
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]

MODELS = r"""
import hashlib
from gripper_ros.core import linalg
from gripper_ros.core.control import dmc
from gripper_ros.core.config import load_config

from gripper_ros.core.physics.motor_zoh import (DISC_COMPLIANT, DISC_LOADED, discretise,
                                                raw_constants)
import numpy as np
config = load_config()
raw = raw_constants(config.plant)
h = hashlib.sha256()
for dt_s in (1e-5, 1e-4, 1e-2):
    h.update(discretise(raw, DISC_LOADED, dt_s, 0.0, 0.0, 0.0).tobytes())
    h.update(discretise(raw, DISC_COMPLIANT, dt_s, 1e5, 50.0, 0.02).tobytes())
step = np.linspace(0.0, 1.0, 40) ** 1.5
h.update(dmc.dmc_gain(step, 10, 0.3).tobytes())
rng = np.random.default_rng(7)
a, b = rng.standard_normal((6, 6)), rng.standard_normal((6, 2))
h.update(linalg.solve(a, b).tobytes() + linalg.expm(a).tobytes() + linalg.matmul(a, b).tobytes())
print(h.hexdigest())
"""

GRASP = r"""
import hashlib
from gripper_ros.core.config import load_config
from gripper_ros.core.runtime.headless import simulate_grasp
from gripper_ros.core.physics.hold import Lift
config = load_config()
h = hashlib.sha256()
for kw in (dict(width_m=0.05, mass_kg=1.69),
           dict(width_m=0.05, mass_kg=0.0, object_mass_kg=0.6, static_friction=0.3,
                kinetic_friction=0.24, lift=Lift(acceleration_mps2=3.0, lift_off_s=0.1))):
    g = simulate_grasp(config, **kw)
    h.update(str(g.outcome).encode())
    for name in ('stamp_ns', 'position_m', 'force_n', 'motor_voltage_v', 'sensor_voltage_v'):
        h.update(g.series.ticks[name].tobytes())
    h.update(g.series.tick_states['phase'].tobytes())
print(h.hexdigest())
"""


def _run(script: str, **env) -> str:
    """Run ``script`` in a fresh interpreter with ``env`` added; its one line of output."""
    done = subprocess.run([sys.executable, '-c', script], cwd=ROOT, capture_output=True,
                          text=True, timeout=300, env={**os.environ, **env})
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout.strip().splitlines()[-1]


def _cpu_has(flag: str) -> bool:
    try:
        return flag in Path('/proc/cpuinfo').read_text().split()
    except OSError:
        return False


# --- closed forms ---------------------------------------------------------------------------

def test_expm_of_a_diagonal_matrix_is_the_exponentials_of_its_entries():
    d = np.array([-25.0, -3.0, 0.0, 0.5, 7.0])
    got = np.diag(linalg.expm(np.diag(d)))
    assert np.allclose(got, np.exp(d), rtol=1e-14, atol=0.0)
    assert np.count_nonzero(linalg.expm(np.diag(d)) - np.diag(got)) == 0


def test_expm_of_a_nilpotent_matrix_is_its_finite_series():
    n = np.array([[0.0, 2.0, 3.0], [0.0, 0.0, 4.0], [0.0, 0.0, 0.0]])
    want = np.eye(3) + n + n @ n / 2.0          # N^3 = 0
    assert np.allclose(linalg.expm(n), want, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize('angle', [1e-3, 0.4, 2.0, 40.0])
def test_expm_of_a_rotation_generator_is_the_rotation(angle):
    got = linalg.expm(np.array([[0.0, -angle], [angle, 0.0]]))
    c, s = math.cos(angle), math.sin(angle)
    assert np.allclose(got, [[c, -s], [s, c]], rtol=0.0, atol=2e-14 * max(1.0, angle))


def test_expm_of_the_zoh_block_gives_the_first_order_step_response():
    """exp([[a dt, dt], [0, 0]]) = [[e^{a dt}, (e^{a dt} - 1) / a], [0, 1]]: eq. 13's ZOH."""
    a, dt = -1.0 / 0.0036, 1e-4
    got = linalg.expm(np.array([[a * dt, dt], [0.0, 0.0]]))
    e = math.exp(a * dt)
    assert got[0, 0] == pytest.approx(e, rel=1e-15)
    assert got[0, 1] == pytest.approx((e - 1.0) / a, rel=1e-14)
    assert (got[1, 0], got[1, 1]) == (0.0, 1.0)


def test_solve_recovers_an_exact_integer_solution_and_refuses_a_singular_matrix():
    a = np.array([[2.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 4.0]])
    x = np.array([[1.0, -2.0], [3.0, 0.5], [-1.0, 4.0]])
    assert np.array_equal(linalg.solve(a, a @ x), x)
    with pytest.raises(ValueError, match='singular'):
        linalg.solve(np.array([[1.0, 2.0], [2.0, 4.0]]), np.eye(2))


def test_matmul_dot_and_matvec_sum_in_the_order_written():
    """(1e16 + 1) - 1e16 = 0 summed from the front, as the loop is written; 2 from the back."""
    x = np.array([1e16, 1.0, -1e16, 1.0])
    ones = np.ones(4)
    assert linalg.dot(x, ones) == 1.0
    assert linalg.matvec(x[None, :], ones)[0] == 1.0
    assert linalg.matmul(x[None, :], ones[:, None])[0, 0] == 1.0


def test_expm_refuses_a_matrix_that_is_not_square_or_finite():
    with pytest.raises(ValueError, match='square'):
        linalg.expm(np.zeros((2, 3)))
    with pytest.raises(ValueError, match='finite'):
        linalg.expm(np.array([[np.nan, 0.0], [0.0, 1.0]]))


# --- the same bits everywhere ---------------------------------------------------------------

def test_compiled_models_are_the_interpreted_ieee_operations_bit_for_bit():
    """Numba neither fuses nor reorders: compiled models equal the interpreted code.

    The ZOH models, a DMC gain, expm and solve give the bits of the same code run by the
    interpreter, operation by operation.
    """
    assert _run(MODELS) == _run(MODELS, NUMBA_DISABLE_JIT='1')


def test_a_grasp_gives_the_same_bytes_under_other_cpus_blas_kernels():
    """A grasp run on another CPU's BLAS kernels gives this process's bytes.

    A Table V grasp and a load-tracking pick-and-place, as an SSE3-only (and an AVX2) CPU's
    OpenBLAS would run them.
    """
    here = _run(GRASP)
    assert _run(GRASP, OPENBLAS_CORETYPE='Prescott') == here
    if _cpu_has('avx2'):
        assert _run(GRASP, OPENBLAS_CORETYPE='Haswell') == here


def test_a_grasp_gives_the_same_bytes_on_the_c_librarys_code_for_cpus_without_fma():
    """The C library's exp, log, sin, cos, expm1 and pow have FMA and plain variants.

    glibc chooses them by the CPU. Masking FMA and AVX2 (``GLIBC_TUNABLES``) makes it choose
    what a CPU without them runs; the grasps give this process's bytes.
    """
    assert _run(GRASP, GLIBC_TUNABLES='glibc.cpu.hwcaps=-AVX2,-FMA') == _run(GRASP)
