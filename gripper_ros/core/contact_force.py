"""Force stage for rigid *and* compliant objects: no contact spike on either (no ROS).

Why the paper's PI is not enough. On the paper's rigid contact the finger stalls and force is
the motor current (eq. 13): a first-order loop with L/R = 0.1 ms, which our PI settles in
0.35 ms. On a compliant object the force is the spring's, ``F = k d``, and the motor must move
the finger to change it: the spring and the motor inertia reflected through the lead screw form
a lightly damped mode,

    omega_n^2 = k * lever * rho / J,       zeta = b_m / (2 sqrt(k * lever * rho * J)),

(``lever`` = eta p N1/N2, the motor torque per newton, eq. 12; ``rho`` = p / 2 pi, the travel per
motor radian, eq. 10). With Table I: 13.5 rad/s and zeta = 0.033 at k = 1e5 N/m (stiff), 1.35
rad/s and zeta = 0.33 at 1e3 N/m (soft). A PI with the rigid loop's integral gain drives that
mode unstable (`contact_sweep --compliant --force-controller pi`: peaks 1.7-6.1x the setpoint
and the finger bounces off), and any approach speed ``v`` is turned into
a force ``~ v k / omega_n`` (7400 N per m/s at 1e5 N/m): 10 mm/s gives 74 N.

What this controller does, each force sample, knowing neither the stiffness nor the damping:

1. Feed-forward ``V_ff = F_sp / K_stall`` (``K_stall`` = 1.391 N/V, the stall force per volt):
   stalled against any object, rigid or compliant, this voltage holds exactly ``F_sp``.
2. Before contact, a speed reference ``v_ref = gap / tau + v_min``, with ``gap`` the distance to
   the expected face and ``v_min`` proportional to ``F_sp``, tracked by the damping term: the
   finger arrives at the face at ``v_min`` (tens of um/s for light objects), so that the
   impact adds little force. Past the expected face with nothing touched (a narrower object,
   or none) the reference is dropped and the motor gets exactly ``V_ff``: safe on any rigid
   object, and NO_OBJECT is found quickly instead of after a crawl.
3. After contact, force feedback ``Kp (F_sp - F)`` (stable on the rigid electrical loop: its
   discrete pole ``a - b Kp`` stays inside the unit circle) plus velocity damping ``-Kv v``,
   with ``Kv`` chosen each sample from the stiffness estimated as ``F / d`` (``d`` the travel
   since contact) so that the spring mode has damping ratio ``zeta``; rigid contact gives
   ``v = 0`` and the damping has nothing to do.
4. A small integral on the force error corrects model error (a real motor's friction, a stall
   gain that is not 1.391 N/V); it integrates only while the finger is at rest in contact, so it
   cannot wind up during a slow compression.

The velocity comes from successive position samples (exact in simulation; a real gripper would
use the motor encoder's speed). Everything is clamped to the motor's +-24 V.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from gripper_ros.core.config import ContactForceTuning, PlantParams


@dataclass
class ContactForceTerms:
    """The parts of the last output, for logging and tests."""

    feedforward_v: float = 0.0
    force_v: float = 0.0
    damping_v: float = 0.0
    integral_v: float = 0.0
    stiffness_n_per_m: float = math.inf   # estimate since contact (inf: rigid or none yet)
    damping_gain_v_s_per_m: float = 0.0
    speed_ref_mps: float = 0.0
    in_contact: bool = False
    output_v: float = 0.0


class ContactForceController:
    """``step(force_setpoint_n, force_n, position_m, face_m)`` once per ``dt_s``."""

    def __init__(self, plant: PlantParams, tuning: ContactForceTuning, dt_s: float):
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise ValueError(f'dt_s must be finite and > 0, got {dt_s!r}')
        self.plant = plant
        self.tuning = tuning
        self.dt_s = dt_s
        self.stall_force_per_volt_n = plant.stall_force_per_volt_n
        # motor torque per (m/s of finger speed) of damping gain, and spring torque per (N/m)
        self._torque_per_speed_gain = (plant.torque_constant_n_m_per_a / plant.resistance_ohm
                                       * plant.travel_per_rad_m)
        self._spring_to_motor = plant.force_lever_m * plant.travel_per_rad_m
        self.output_limits = (-plant.voltage_limit_v, plant.voltage_limit_v)
        self.terms = ContactForceTerms()
        self.reset()

    def reset(self, position_m: float | None = None) -> None:
        """A new force stage; ``position_m`` is where the finger is now (speed taken as 0)."""
        self._prev_position_m = position_m
        self._contact_position_m: float | None = None
        self._integral_v = 0.0
        self.terms = ContactForceTerms()

    def damping_gain_for(self, stiffness_n_per_m: float, force_gain_v_per_n: float) -> float:
        """Kv (V per m/s) giving the spring mode damping ratio ``tuning.damping_ratio``."""
        t = self.tuning
        if not math.isfinite(stiffness_n_per_m):
            return t.max_damping_v_s_per_m
        spring = stiffness_n_per_m * self._spring_to_motor * (
            1.0 + self.stall_force_per_volt_n * force_gain_v_per_n)   # the P gain stiffens it
        needed = 2.0 * t.damping_ratio * math.sqrt(spring * self.plant.inertia_kg_m2) \
            - self.plant.damping_n_m_s_per_rad
        return min(max(needed, 0.0) / self._torque_per_speed_gain, t.max_damping_v_s_per_m)

    def step(self, force_setpoint_n: float, force_n: float, position_m: float,
             face_m: float) -> float:
        """Motor voltage for the coming sample. ``face_m``: the object's expected face."""
        for name, value in (('force_setpoint_n', force_setpoint_n), ('force_n', force_n),
                            ('position_m', position_m), ('face_m', face_m)):
            if not math.isfinite(value):
                raise ValueError(f'non-finite input {name}={value!r}')
        t = self.tuning
        prev = self._prev_position_m
        speed = 0.0 if prev is None else (position_m - prev) / self.dt_s
        self._prev_position_m = position_m
        feedforward = force_setpoint_n / self.stall_force_per_volt_n
        in_contact = force_n > t.contact_force_fraction * force_setpoint_n
        terms = ContactForceTerms(feedforward_v=feedforward, in_contact=in_contact)
        low, high = self.output_limits
        if not in_contact and self._contact_position_m is None:
            # approach: track a speed that falls with the gap to the expected face and arrives
            # there at v_min. Past that face with nothing touched the object is narrower than
            # requested, or absent: go on at the stall voltage of F_sp (safe on any rigid
            # object), so that NO_OBJECT is found in a fraction of a second, not after a crawl.
            v_min = t.contact_speed_mps_per_n * force_setpoint_n
            past_face_untouched = position_m > face_m and force_n <= 0.0
            v_ref = math.inf if past_face_untouched else \
                max(face_m - position_m, 0.0) / t.approach_time_constant_s + v_min
            kv = t.max_damping_v_s_per_m
            # never more than the feed-forward: a rigid face met at any speed then stalls the
            # motor at exactly F_sp (the paper's contact); braking is not limited
            output = min(feedforward + kv * (v_ref - speed), feedforward)
            terms.speed_ref_mps = v_ref
            terms.damping_gain_v_s_per_m = kv
            terms.damping_v = output - feedforward
        else:
            if self._contact_position_m is None:
                self._contact_position_m = position_m
                # the backward difference still holds the approach speed; a rigid face has
                # just stopped the finger dead, and damping that stale speed would pull it off
                speed = 0.0
            travel = position_m - self._contact_position_m
            stiffness = force_n / travel if travel > t.min_travel_for_stiffness_m else math.inf
            kp = t.force_gain_v_per_n
            kv = self.damping_gain_for(stiffness, kp)
            error = force_setpoint_n - force_n
            at_rest = abs(speed) <= t.integral_speed_band_mps
            integral = self._integral_v + (t.integral_gain_v_per_n_s * error * self.dt_s
                                           if at_rest else 0.0)
            output = feedforward + kp * error + integral - kv * speed
            terms.force_v, terms.damping_v = kp * error, -kv * speed
            terms.stiffness_n_per_m, terms.damping_gain_v_s_per_m = stiffness, kv
            if low <= output <= high:          # anti-windup: keep the integral only unsaturated
                self._integral_v = integral
            terms.integral_v = self._integral_v
        output = min(max(output, low), high)
        terms.output_v = output
        self.terms = terms
        return output
