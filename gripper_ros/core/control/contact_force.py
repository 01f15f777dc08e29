"""Force stage for rigid and compliant objects of unknown stiffness: no contact spike (no ROS).

The plant seen from the finger. Through the lead screw the motor is a mass, a damper and a
force source on the finger (eqs. 9-12), in finger coordinates:

    m_r x'' = K_stall e - c_r x' - F,     m_r = J / (lever rho),  c_r = (b_m + k_t k_b / R) /
    (lever rho),  K_stall = k_t / (lever R)

(``lever`` = eta p N1/N2, the motor torque per newton, eq. 12; ``rho`` = p / 2 pi, the travel per
motor radian, eq. 10; the electrical lag L/R = 0.1 ms is left out here and kept in the plant).
Table I gives ``m_r`` = 546 kg, ``c_r`` = 485 N s/m, ``K_stall`` = 1.391 N/V. An object is a
Kelvin-Voigt contact ``F = k d + c d'``; its *damping ratio* is taken against the contact mode
with the reflected mass, ``zeta = c / (2 sqrt(k m_r))``, so ``omega_n = sqrt(k / m_r)``: 0.43
rad/s at 1e2 N/m, 428 rad/s at 1e8 N/m. A rigid object is the paper's contact (the finger stops
dead and the force is the motor's, eq. 13).

Why the approach speed is the whole problem. A finger arriving at speed ``v`` puts ``c v`` on the
object at once (the damper, whatever the motor does) and the momentum ``m_r v`` into the spring,
``v sqrt(k m_r)``: the free impact peaks at ``h(zeta) v sqrt(k m_r)`` with ``h = max(1, 2 zeta)``.
No controller acts before the object is touched, so the contact speed must satisfy that bound
for the stiffest object it may meet. This stage designs the contact speed for a *design*
stiffness ``k_d`` and damping ratio ``zeta_d`` (``tuning.design_*``) and an impact share
``beta`` of the setpoint (``tuning.impact_force_fraction``, below the loss watch's fraction so
that the impact alone never arms it):

    v_c = alpha F_sp,   alpha = beta / (h(zeta_d) sqrt(k_d m_r)).

What it does each force sample, knowing neither the stiffness nor the exact width:

1. Feed-forward ``V_ff = F_sp / K_stall``: stalled against any object it holds ``F_sp``.
2. A speed servo ``Kv (v_ref - v)``, with the finger speed from successive positions.
3. Before contact, ``v_ref = s(gap) + v_c`` with ``gap`` the distance to the face of the *widest*
   object the request allows and ``s(r)`` a braking profile at the deceleration ``a`` that ends
   in a first-order approach of time constant ``tau`` (:meth:`speed_profile_mps`). The finger
   reaches that face at ``v_c`` and crosses the tolerance band at ``v_c``. The output is never
   above ``V_ff``, so a rigid object met anywhere gets at most ``F_sp`` (the paper's contact);
   braking is not limited. Past the face of the narrowest object with nothing touched the
   object is narrower than requested, or absent: the motor gets ``V_ff`` (NO_OBJECT quickly).
4. From the first force sample above ``tuning.contact_force_n`` on, the same servo tracks
   ``v_ref = s((F_sp - F) / k_hat)``: the finger moves towards the compression that gives
   ``F_sp`` on a spring of stiffness ``k_hat = min(F / d, k_d)`` (``d`` the travel since
   contact; rigid contact gives ``d = 0``, hence ``k_d``; within a tolerance the cap is the
   band design stiffness). With ``tau = 1 / (alpha k_d)`` the
   reference is continuous at contact (``v_c (1 - F / F_sp)``) and, on a spring of any
   stiffness ``k = k_hat``, the force approaches ``F_sp`` first-order with time constant ``tau``
   (plus the object's own creep ``c / k``); a soft object is compressed along the braking
   profile instead, at up to full voltage. A moving setpoint adds its rate over ``k_hat`` to
   the reference (low-passed over ``tuning.setpoint_rate_time_constant_s``), so the force
   follows a ramp without the first-order loop's lag; a constant setpoint adds exactly 0.
5. ``Kv`` is chosen each sample from ``k_hat`` for a closed-loop damping ratio
   ``tuning.damping_ratio`` of ``m_r s^2 + (D + c_r) s + k (1 + K_stall Kp) + D / tau``
   (``D = K_stall Kv``), the spring mode with the servo and the force reference acting on it.
   On a rigid object the speed is 0 and the servo term is a force gain ``Kv / (k_d tau)``.
6. A small integral on the force error trims model error (friction, a stall gain that is not
   1.391 N/V); it integrates only the error the loop leaves standing, with the finger at rest
   in contact and the error decaying much slower than the loop's rate ``1 / tau_k``.

Everything is clamped to the motor's +-24 V. The per-sample cost is two square roots.

The per-sample work is compiled (``contact_*`` kernels over one :data:`CONTACT_DTYPE` record,
shared with the force stage's kernel); :class:`ContactForceController` computes the design
numbers at construction and is the Python façade over the kernels.
"""
from __future__ import annotations

import math

from gripper_ros.core.config import ContactForceTuning, PlantParams
from gripper_ros.core.control.pid import (LAW_CONTACT_INPUT, law_error, LAW_MATH_DOMAIN,
                                          LAW_NUMBERS, LAW_OK, LAW_ZERO_DIVISION, py_max, py_min)
from gripper_ros.core.records import (as_record, copy_fields, face_kernel, FLOATS, record_view,
                                      RecordPair, set_fields)
import numba
import numpy as np


def impact_factor(damping_ratio: float) -> float:
    """Bound the free-impact peak of a Kelvin-Voigt contact per ``v sqrt(k m)``: max(1, 2 zeta)."""
    return max(1.0, 2.0 * damping_ratio)


CONTACT_DTYPE = np.dtype([
    # design numbers (constant after construction)
    ('dt_s', 'f8'),
    ('stall_force_per_volt_n', 'f8'),
    ('reflected_mass_kg', 'f8'),
    ('reflected_damping_n_s_per_m', 'f8'),
    ('contact_speed_mps_per_n', 'f8'),
    ('time_constant_s', 'f8'),
    ('band_speed_mps_per_n', 'f8'),
    ('two_a', 'f8'),                         # 2 x braking deceleration (m/s^2)
    ('z2m', 'f8'),                           # zeta^2 m_r
    ('spring_factor', 'f8'),                 # 1 + K_stall Kp
    ('two_zeta_sqrt_m', 'f8'),               # 2 zeta_d sqrt(m_r)
    ('kappa_over_dt', 'f8'),                 # servo sample gain / dt (1/s)
    ('low', 'f8'), ('high', 'f8'),           # output_limits (V)
    ('approach_gain_v_s_per_m', 'f8'),
    ('cap_k', 'f8'), ('cap_tau', 'f8'), ('cap_kv', 'f8'),                # capped loop, exact
    ('band_k', 'f8'), ('band_tau', 'f8'), ('band_kv', 'f8'),             # ... within a band
    ('max_travel_m', 'f8'),
    # tuning (ContactForceTuning fields used per sample)
    ('contact_force_n', 'f8'),
    ('untouched_overtravel_m', 'f8'),
    ('integral_speed_band_mps', 'f8'),
    ('integral_rate_fraction', 'f8'),
    ('integral_gain_v_per_n_s', 'f8'),
    ('force_gain_v_per_n', 'f8'),
    ('design_stiffness_n_per_m', 'f8'),
    ('max_damping_v_s_per_m', 'f8'),
    # state
    ('has_prev_position', 'u1'),             # 0: no previous position (None)
    ('prev_position_m', 'f8'),
    ('has_contact', 'u1'),                   # 0: not touched yet (None)
    ('contact_position_m', 'f8'),
    ('prev_force_n', 'f8'),
    ('has_prev_setpoint', 'u1'),             # 0: the stage's first sample
    ('prev_setpoint_n', 'f8'),
    ('setpoint_rate_n_per_s', 'f8'),         # low-passed
    ('rate_share', 'f8'),                    # 1 - exp(-dt / setpoint_rate_time_constant_s)
    ('integral', 'f8'),                      # the integral term (V)
    # the last output's terms (ContactForceTerms)
    ('feedforward_v', 'f8'), ('force_v', 'f8'), ('damping_v', 'f8'), ('integral_v', 'f8'),
    ('stiffness_n_per_m', 'f8'), ('damping_gain_v_s_per_m', 'f8'), ('speed_ref_mps', 'f8'),
    ('in_contact', 'u1'), ('output_v', 'f8'),
], align=True)
"""One contact-aware force stage: design numbers, state and last terms (1-element array)."""


ContactForceTerms = record_view(
    'ContactForceTerms', CONTACT_DTYPE,
    ('feedforward_v', 'force_v', 'damping_v', 'integral_v', 'stiffness_n_per_m',
     'damping_gain_v_s_per_m', 'speed_ref_mps', 'in_contact', 'output_v'),
    'The parts of the last output, for logging and tests (``stiffness_n_per_m``, k_hat since '
    'contact, is inf before contact).', stiffness_n_per_m=math.inf)


@numba.njit(cache=True)
def contact_reset_terms(c):
    """Zero the last output's terms (``stiffness`` inf: nothing touched)."""
    s = as_record(c)
    set_fields(s, ('feedforward_v', 'force_v', 'damping_v', 'integral_v',
                   'damping_gain_v_s_per_m', 'speed_ref_mps', 'output_v'), 0.0)
    s.stiffness_n_per_m = math.inf
    s.in_contact = 0


@face_kernel(CONTACT_DTYPE, bool, float)
@numba.njit(cache=True)
def contact_reset(c, has_position, position_m):
    """Start a new force stage at ``position_m`` (speed 0; ``has_position`` 0: unknown)."""
    s = as_record(c)
    s.has_prev_position = 1 if has_position else 0
    s.prev_position_m = position_m if has_position else 0.0
    s.has_contact = 0
    s.prev_force_n = 0.0
    s.has_prev_setpoint = 0
    s.setpoint_rate_n_per_s = 0.0
    s.integral = 0.0
    contact_reset_terms(s)


@face_kernel(CONTACT_DTYPE, float, float)
@numba.njit(cache=True)
def contact_speed_mps(c, force_setpoint_n, width_tolerance_m):
    """Return the speed at which the finger meets the object (see the façade's method)."""
    s = as_record(c)
    return (s.band_speed_mps_per_n if width_tolerance_m > 0.0
            else s.contact_speed_mps_per_n) * force_setpoint_n


@face_kernel(CONTACT_DTYPE, float)
@numba.njit(cache=True)
def contact_loop_time_constant_s(c, stiffness_n_per_m):
    """Return (code, tau_k): see :meth:`ContactForceController.loop_time_constant_s`."""
    s = as_record(c)
    if stiffness_n_per_m < 0.0:
        return LAW_MATH_DOMAIN, 0.0
    root = math.sqrt(stiffness_n_per_m)
    if root == 0.0:
        return LAW_ZERO_DIVISION, 0.0
    b = s.two_zeta_sqrt_m / root
    radicand = 1.0 + b * s.kappa_over_dt
    if radicand < 0.0:
        return LAW_MATH_DOMAIN, 0.0
    if 2.0 * b == 0.0:
        return LAW_ZERO_DIVISION, 0.0
    rate = (math.sqrt(radicand) - 1.0) / (2.0 * b)
    if rate == 0.0:
        return LAW_ZERO_DIVISION, 0.0
    return LAW_OK, py_max(s.time_constant_s, 1.0 / rate)


@face_kernel(CONTACT_DTYPE, float, float)
@numba.njit(cache=True)
def contact_damping_gain_for(c, stiffness_n_per_m, time_constant_s):
    """Return (code, Kv): see :meth:`ContactForceController.damping_gain_for`."""
    s = as_record(c)
    tau = time_constant_s
    k = py_min(stiffness_n_per_m, s.design_stiffness_n_per_m)
    if tau == 0.0:
        return LAW_ZERO_DIVISION, 0.0
    q = 2.0 * s.z2m / tau
    c_r = s.reflected_damping_n_s_per_m
    disc = q * q + 4.0 * s.z2m * (k * s.spring_factor - c_r / tau)
    x = q + math.sqrt(disc) if disc > 0.0 else q
    return LAW_OK, py_min(py_max(x - c_r, 0.0) / s.stall_force_per_volt_n,
                          s.max_damping_v_s_per_m)


@face_kernel(CONTACT_DTYPE, float, float)
@numba.njit(cache=True)
def contact_speed_profile_mps(c, distance_m, time_constant_s):
    """Return (code, speed): see :meth:`ContactForceController.speed_profile_mps`."""
    s = as_record(c)
    tau = time_constant_s
    r = abs(distance_m)
    linear_m = 0.5 * s.two_a * tau * tau
    if r <= linear_m:
        if tau == 0.0:
            return LAW_ZERO_DIVISION, 0.0
        v = r / tau
    else:
        radicand = s.two_a * (r - 0.5 * linear_m)
        if radicand < 0.0:
            return LAW_MATH_DOMAIN, 0.0
        v = math.sqrt(radicand)
    return LAW_OK, (v if distance_m >= 0.0 else -v)


@face_kernel(CONTACT_DTYPE, float, float, float, float, float, FLOATS)
@numba.njit(cache=True)
def contact_step(c, force_setpoint_n, force_n, position_m, face_m, width_tolerance_m, numbers):
    """Return (code, voltage) for the coming sample (``code`` LAW_OK unless refused)."""
    if not (math.isfinite(force_setpoint_n) and math.isfinite(force_n)
            and math.isfinite(position_m) and math.isfinite(face_m)
            and math.isfinite(width_tolerance_m)):
        numbers[0] = force_setpoint_n
        numbers[1] = force_n
        numbers[2] = position_m
        numbers[3] = face_m
        numbers[4] = width_tolerance_m
        return LAW_CONTACT_INPUT, 0.0
    s = as_record(c)
    speed = (position_m - s.prev_position_m) / s.dt_s if s.has_prev_position else 0.0
    s.has_prev_position = 1
    s.prev_position_m = position_m
    prev_force_n = s.prev_force_n
    s.prev_force_n = force_n
    if s.has_prev_setpoint:
        raw_rate = (force_setpoint_n - s.prev_setpoint_n) / s.dt_s
        s.setpoint_rate_n_per_s += s.rate_share * (raw_rate - s.setpoint_rate_n_per_s)
    s.has_prev_setpoint = 1
    s.prev_setpoint_n = force_setpoint_n
    feedforward = force_setpoint_n / s.stall_force_per_volt_n
    s.feedforward_v = feedforward
    low, high = s.low, s.high
    if not s.has_contact and force_n > s.contact_force_n:
        # the object was touched during the last sample; the travel into it starts here
        s.has_contact = 1
        s.contact_position_m = position_m
    if not s.has_contact:
        s.in_contact = 0
        v_c = contact_speed_mps(s, force_setpoint_n, width_tolerance_m)
        if position_m > face_m + width_tolerance_m + s.untouched_overtravel_m:
            # past the narrowest object's face, nothing touched: narrower than allowed, or
            # absent. The stall voltage of F_sp is safe on any rigid object and finds
            # NO_OBJECT in a fraction of a second instead of after a crawl.
            output = feedforward
            v_ref = math.inf
        else:
            gap = face_m - width_tolerance_m - position_m
            v_ref, accel_ref = v_c, 0.0
            if gap > 0.0:
                tau = s.time_constant_s
                r_lin = 0.5 * s.two_a * tau ** 2
                if gap <= r_lin:
                    profile = gap / tau
                    accel_ref = -speed / tau
                else:
                    profile = math.sqrt(s.two_a * (gap - 0.5 * r_lin))
                    accel_ref = -0.5 * s.two_a * speed / profile
                v_ref += profile
            kv = s.approach_gain_v_s_per_m
            # the force the free finger needs to follow v_ref (drag and deceleration), the
            # servo for the rest; never more than the feed-forward: a rigid face met at any
            # speed then stalls the motor at F_sp at most (the paper's contact); braking is
            # not limited
            output = py_min(kv * (v_ref - speed) + (
                s.reflected_damping_n_s_per_m * v_ref
                + s.reflected_mass_kg * accel_ref) / s.stall_force_per_volt_n,
                feedforward)
        s.speed_ref_mps = v_ref
        s.damping_gain_v_s_per_m = s.approach_gain_v_s_per_m
        s.damping_v = output - feedforward
        s.force_v = 0.0
        s.stiffness_n_per_m = math.inf
    else:
        s.in_contact = 1
        travel = position_m - s.contact_position_m
        # F / d, at most the stiffness the contact speed was designed for and at least the
        # softest spring that can give F_sp within the travel; no travel (rigid contact)
        # is k_d's loop, the only one whose speed reference is a safe force gain there
        if width_tolerance_m > 0.0 and travel > 0.0:
            k_cap, tau_cap, kv_cap = s.band_k, s.band_tau, s.band_kv
        else:
            k_cap, tau_cap, kv_cap = s.cap_k, s.cap_tau, s.cap_kv
        k_soft = force_setpoint_n / s.max_travel_m
        error = force_setpoint_n - force_n
        if force_n >= k_cap * travel:
            stiffness, tau_k, kv = k_cap, tau_cap, kv_cap
        else:
            if travel == 0.0:
                return LAW_ZERO_DIVISION, 0.0
            stiffness = py_max(force_n / travel, k_soft)
            code, tau_k = contact_loop_time_constant_s(s, stiffness)
            if code != LAW_OK:
                return code, 0.0
            code, kv = contact_damping_gain_for(s, stiffness, tau_k)
            if code != LAW_OK:
                return code, 0.0
        if stiffness == 0.0:
            return LAW_ZERO_DIVISION, 0.0
        code, v_ref = contact_speed_profile_mps(s, error / stiffness, tau_k)
        if code != LAW_OK:
            return code, 0.0
        # a moving setpoint: compress the spring at the speed that moves the force with it
        # (exactly 0 for a constant setpoint)
        v_ref += s.setpoint_rate_n_per_s / stiffness
        # trim only the error the loop leaves standing: the finger at rest and the error
        # decaying slower than integral_rate_fraction of the loop's own rate 1 / tau_k (a
        # stiff object is compressed at a few um/s, so rest alone would integrate the ramp)
        standing = abs(speed) <= s.integral_speed_band_mps and \
            abs(force_n - prev_force_n) * tau_k <= \
            s.integral_rate_fraction * abs(error) * s.dt_s
        integral = s.integral + (s.integral_gain_v_per_n_s * error * s.dt_s
                                 if standing else 0.0)
        force_v = s.force_gain_v_per_n * error
        damping_v = kv * (v_ref - speed)
        output = feedforward + force_v + integral + damping_v
        if low <= output <= high:          # anti-windup: keep the integral only unsaturated
            s.integral = integral
        s.force_v = force_v
        s.damping_v = damping_v
        s.stiffness_n_per_m = stiffness
        s.damping_gain_v_s_per_m = kv
        s.speed_ref_mps = v_ref
    s.integral_v = s.integral
    output = py_min(py_max(output, low), high)
    s.output_v = output
    return LAW_OK, output


class ContactForceController:
    """``step(force_setpoint_n, force_n, position_m, face_m, width_tolerance_m)`` per ``dt_s``.

    The design numbers, the state and the last terms live in the 1-element
    :data:`CONTACT_DTYPE` array ``record`` (the force stage's kernel works on the same one).
    """

    def __init__(self, plant: PlantParams, tuning: ContactForceTuning, dt_s: float):
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise ValueError(f'dt_s must be finite and > 0, got {dt_s!r}')
        self.plant = plant
        self.tuning = tuning
        self.dt_s = dt_s
        self._numbers = np.zeros(LAW_NUMBERS)
        self.record = r = np.zeros(1, CONTACT_DTYPE)
        s = r[0]
        t = tuning
        lever_rho = plant.force_lever_m * plant.travel_per_rad_m
        self.stall_force_per_volt_n = plant.stall_force_per_volt_n
        self.reflected_mass_kg = plant.reflected_mass_kg
        self.reflected_damping_n_s_per_m = (
            plant.damping_n_m_s_per_rad + plant.torque_constant_n_m_per_a
            * plant.back_emf_v_s_per_rad / plant.resistance_ohm) / lever_rho
        self.contact_speed_mps_per_n = t.impact_force_fraction / (
            impact_factor(t.design_damping_ratio)
            * math.sqrt(t.design_stiffness_n_per_m * self.reflected_mass_kg))
        self.time_constant_s = 1.0 / (self.contact_speed_mps_per_n * t.design_stiffness_n_per_m)
        self.band_speed_mps_per_n = self.contact_speed_mps_per_n * math.sqrt(
            t.design_stiffness_n_per_m / t.band_design_stiffness_n_per_m)
        s['dt_s'] = dt_s
        s['rate_share'] = 1.0 if t.setpoint_rate_time_constant_s == 0.0 else \
            -math.expm1(-dt_s / t.setpoint_rate_time_constant_s)
        copy_fields(s, self, ('stall_force_per_volt_n', 'reflected_mass_kg',
                              'reflected_damping_n_s_per_m', 'contact_speed_mps_per_n',
                              'time_constant_s', 'band_speed_mps_per_n'))
        s['two_a'] = 2.0 * t.braking_deceleration_mps2
        # damping-gain quadratic, X = D + c_r:  X^2 - 2 q X - 4 z^2 m (k (1 + K Kp) - c_r / tau),
        # q = 2 z^2 m / tau
        s['z2m'] = t.damping_ratio ** 2 * self.reflected_mass_kg
        s['spring_factor'] = 1.0 + self.stall_force_per_volt_n * t.force_gain_v_per_n
        # worst object damping over its stiffness, c / k = 2 zeta_d sqrt(m_r / k), and the
        # sample-gain bound on 1 / tau_k (see loop_time_constant_s)
        s['two_zeta_sqrt_m'] = 2.0 * t.design_damping_ratio * math.sqrt(self.reflected_mass_kg)
        s['kappa_over_dt'] = t.servo_sample_gain / dt_s
        self.output_limits = (-plant.voltage_limit_v, plant.voltage_limit_v)
        s['max_travel_m'] = plant.max_travel_m
        copy_fields(s, t, ('contact_force_n', 'untouched_overtravel_m', 'integral_speed_band_mps',
                           'integral_rate_fraction', 'integral_gain_v_per_n_s',
                           'force_gain_v_per_n', 'design_stiffness_n_per_m',
                           'max_damping_v_s_per_m'))
        approach = self.damping_gain_for(t.design_stiffness_n_per_m)
        s['approach_gain_v_s_per_m'] = approach
        # the loop on a spring at the stiffness cap (rigid contact too), computed once: at an
        # exact width the design's, within a tolerance the band design's
        k_band = min(t.band_design_stiffness_n_per_m, t.design_stiffness_n_per_m)
        tau_band = self.loop_time_constant_s(k_band)
        s['cap_k'], s['cap_tau'], s['cap_kv'] = (t.design_stiffness_n_per_m, self.time_constant_s,
                                                 approach)
        s['band_k'], s['band_tau'] = k_band, tau_band
        s['band_kv'] = self.damping_gain_for(k_band, tau_band)
        self.reset()

    output_limits = RecordPair('low', 'high')

    terms = property(lambda self: ContactForceTerms.of(self.record),
                     doc='The parts of the last output, for logging and tests.')

    def _checked(self, code: int, value: float) -> float:
        if code != LAW_OK:
            raise law_error(code, self._numbers)
        return value

    def reset(self, position_m: float | None = None) -> None:
        """Start a new force stage; ``position_m`` is where the finger is now (speed 0)."""
        contact_reset(self.record, position_m is not None,
                      0.0 if position_m is None else float(position_m))

    def contact_speed_mps(self, force_setpoint_n: float, width_tolerance_m: float = 0.0
                          ) -> float:
        """Return the speed at which the finger meets the object.

        ``alpha F_sp`` at an exact width; within a tolerance the band's speed, designed for
        ``tuning.band_design_stiffness_n_per_m``.
        """
        return contact_speed_mps(self.record, float(force_setpoint_n), float(width_tolerance_m))

    def loop_time_constant_s(self, stiffness_n_per_m: float) -> float:
        """Return ``tau_k``, the force loop's time constant on a spring of this stiffness.

        ``tau`` unless the object's damper would make the speed servo too fast to sample: with
        the reference ``(F_sp - F) / (k tau_k)`` a damper ``c`` feeds the speed back through
        the force with gain ``c / (k tau_k)``, so the servo (about ``4 / tau_k`` per second,
        see :meth:`damping_gain_for`) corrects ``4 dt / tau_k (1 + c / (k tau_k))`` of a speed
        error per sample. That must stay below ``tuning.servo_sample_gain`` for the most damped
        object of this stiffness, ``c / k = 2 zeta_d sqrt(m_r / k)``: a quadratic in
        ``1 / tau_k``.
        """
        return self._checked(*contact_loop_time_constant_s(self.record,
                                                           float(stiffness_n_per_m)))

    def damping_gain_for(self, stiffness_n_per_m: float, time_constant_s: float | None = None
                         ) -> float:
        """Return Kv (V per m/s) for the loop damping ratio ``tuning.damping_ratio``.

        On a spring of this stiffness, with the force reference's time constant (default
        ``tau``).
        """
        tau = self.time_constant_s if time_constant_s is None else time_constant_s
        return self._checked(*contact_damping_gain_for(self.record, float(stiffness_n_per_m),
                                                       float(tau)))

    def speed_profile_mps(self, distance_m: float, time_constant_s: float | None = None
                          ) -> float:
        """Return the speed to cover ``distance_m`` and stop there.

        ``r / tau`` up to ``a tau^2``, beyond it the braking parabola ``sqrt(2 a (r - a tau^2 /
        2))`` (deceleration ``a``; the two meet with the same speed and deceleration); odd in r.
        """
        tau = self.time_constant_s if time_constant_s is None else time_constant_s
        return self._checked(*contact_speed_profile_mps(self.record, float(distance_m),
                                                        float(tau)))

    def step(self, force_setpoint_n: float, force_n: float, position_m: float,
             face_m: float, width_tolerance_m: float = 0.0) -> float:
        """Return the motor voltage for the coming sample.

        ``face_m``: the expected object's face; the object may be up to ``width_tolerance_m``
        wider or narrower.
        """
        return self._checked(*contact_step(self.record, float(force_setpoint_n), float(force_n),
                                           float(position_m), float(face_m),
                                           float(width_tolerance_m), self._numbers))
