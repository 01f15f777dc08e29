"""The one reader of ``config/gripper.yaml`` (Table I plant, Table II gains, sensor, supervisor).

Everything numeric the package uses comes through :func:`load_config`; nodes turn these values
into ROS parameters. A bad file stops with a :class:`ConfigError` naming the key.

The dataclasses below are the schema: each key is declared once, with :func:`key`, giving its
meaning, bounds, rule, unit, what a file without it means and whether it may change at run
time. The bounds table, the reader's checks, the known keys, the ROS parameter descriptors and
the bounds listed at the end of the shipped file all come from these declarations
(:data:`SCHEMA`). Checks that tie keys together follow the dataclass of their keys.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field, fields, MISSING, replace
import enum
import functools
import math
import os
from pathlib import Path
import sys
import typing

import yaml

PACKAGE_NAME = 'gripper_ros'
CONFIG_FILE_NAME = 'gripper.yaml'


class ConfigError(ValueError):
    """A configuration file is missing, unreadable or holds a bad value (message names the key)."""


# ------------------------------------------------------------------ the schema of one key
POSITIVE = '> 0'
"""A key's rule: the value must be > 0 (the rule of a key that names none)."""
NONNEGATIVE = '>= 0'
"""A key's rule: the value must be >= 0."""

SHIPPED = None
"""A key's ``absent``: a file without the key means the shipped file's value."""

REQUIRED = type('Required', (), {'__repr__': lambda self: 'REQUIRED'})()
"""A key's ``absent``: a file must give the key."""

UNITS = {'_n_m_s_per_rad': 'N m s/rad', '_n_m_per_a': 'N m/A', '_v_s_per_rad': 'V s/rad',
         '_n_per_m1_5': 'N/m^1.5', '_n_s_per_m': 'N s/m', '_v_per_n_s': 'V/(N s)',
         '_v_s_per_m': 'V s/m', '_n_per_m': 'N/m', '_n_per_s': 'N/s', '_v_per_n': 'V/N',
         '_kg_m2': 'kg m^2', '_mps2': 'm/s^2', '_mps': 'm/s', '_ohm': 'ohm', '_hz': 'Hz',
         '_kg': 'kg', '_s': 's', '_m': 'm', '_n': 'N', '_v': 'V', '_h': 'H'}
"""A key name's suffix -> its unit (the longest suffix that fits wins; none: no unit)."""


def unit_of(name: str) -> str:
    """Return the unit a key's name ends in (``timeout_s`` -> ``s``), '' if none."""
    return max(((suffix, unit) for suffix, unit in UNITS.items() if name.endswith(suffix)),
               key=lambda item: len(item[0]), default=('', ''))[1]


class Key(typing.NamedTuple):
    """One config key: its meaning, bounds, rule, unit, absence and run-time-ness."""

    doc: str                                  # one line: what the value is
    bounds: tuple[float, float] | None        # [low, high]; None only for a choice
    rule: str = POSITIVE                      # POSITIVE or NONNEGATIVE, checked before bounds
    integer: bool = False                     # a whole number
    choices: type[enum.Enum] | None = None    # the value is one of these enum values
    absent: object = REQUIRED                 # what a file without it means (SHIPPED, a value)
    runtime: bool = True                      # False: fixed at start-up (doc says why)
    unit: str | None = None                   # None: from the name's suffix (SCHEMA)
    open_high: bool = False                   # the high bound itself is refused
    why: str = ''                             # said after the bounds a value lies outside

    @property
    def low_open(self) -> bool:
        return self.rule == POSITIVE and self.bounds is not None and self.bounds[0] == 0

    def interval(self) -> str:
        """Return the bounds as text: ``[0, 1)``, ``(0, 10]``."""
        low, high = self.bounds
        return (f'{"(" if self.low_open else "["}{low:g}, {high:g}'
                f'{")" if self.open_high else "]"}')

    def holds(self, value: float) -> bool:
        """Return whether ``value`` lies within the bounds."""
        low, high = self.bounds
        return low <= value <= high and not (self.open_high and value == high)

    @property
    def description(self) -> str:
        """Return the one-line description: the doc, then the bounds and unit, or the choices."""
        if self.choices is not None:
            return f'{self.doc} ({" | ".join(c.value for c in self.choices)})'
        if self.bounds is None:
            return self.doc
        return f'{self.doc} ({self.interval()}{" " + self.unit if self.unit else ""})'


def key(doc: str, *, bounds: tuple[float, float] | None = None, rule: str = POSITIVE,
        integer: bool = False, choices: type[enum.Enum] | None = None, absent=REQUIRED,
        runtime: bool = True, unit: str | None = None, open_high: bool = False, why: str = '',
        default=MISSING):
    """Declare a config key as a dataclass field (``default``: what a law without it has)."""
    if default is not MISSING and absent is REQUIRED:
        absent = default
    return field(default=default, metadata={'key': Key(
        doc, bounds, rule, integer, choices, absent, runtime, unit, open_high, why)})


def part(at: str | None = None):
    """Declare a field holding a dataclass of keys, read from the file's section ``at``.

    ``at`` defaults to the field's name; two parts may share one section (its gains and its
    DMC tuning both under ``mpc_pd``).
    """
    return field(metadata={'part': at})


# ------------------------------------------------------------------ the keys
@dataclass(frozen=True)
class PlantParams:
    """Table I, SI units."""

    inertia_kg_m2: float = key('J_m, equivalent inertia at the motor', bounds=(1e-7, 1.0))
    damping_n_m_s_per_rad: float = key('b_m, equivalent viscous damping at the motor',
                                       bounds=(1e-7, 10.0))
    gear_ratio: float = key('N1/N2, the gear ratio', bounds=(0.01, 1000.0))
    resistance_ohm: float = key('R_a, armature resistance', bounds=(1e-3, 1000.0))
    inductance_h: float = key('L_a, armature inductance', bounds=(1e-7, 1.0))
    pitch_m: float = key('p, lead screw pitch', bounds=(1e-4, 0.1))
    torque_constant_n_m_per_a: float = key('k_t, motor torque constant', bounds=(1e-4, 10.0))
    back_emf_v_s_per_rad: float = key('k_b, back-EMF constant', bounds=(1e-4, 10.0))
    efficiency: float = key('eta, lead screw efficiency', bounds=(0.0, 1.0))
    max_travel_m: float = key('L_ls, travel of the moving finger', bounds=(1e-3, 1.0))
    gravity_mps2: float = key('g, gravity', bounds=(0.1, 100.0))
    voltage_limit_v: float = key('motor nominal voltage, the command limit',
                                 bounds=(0.1, 1000.0))
    contact_substep_s: float = key('sub-step that locates a contact event inside a step',
                                   bounds=(1e-7, 1e-3))

    @property
    def force_lever_m(self) -> float:
        """Return eta p N1/N2: motor torque per newton of gripping force (eq. 12)."""
        return self.efficiency * self.pitch_m * self.gear_ratio

    @property
    def travel_per_rad_m(self) -> float:
        """Return p / (2 pi): finger travel per motor radian (eq. 10)."""
        return self.pitch_m / (2.0 * math.pi)

    @property
    def stall_force_per_volt_n(self) -> float:
        """DC gain of eq. 13: gripping force per volt with the finger stalled."""
        return self.torque_constant_n_m_per_a / (self.force_lever_m * self.resistance_ohm)

    @property
    def reflected_mass_kg(self) -> float:
        """Return J / (eta p N1/N2 p / 2 pi): the motor inertia seen from the finger."""
        return self.inertia_kg_m2 / (self.force_lever_m * self.travel_per_rad_m)

    @property
    def max_force_n(self) -> float:
        """Largest steady gripping force the voltage limit allows."""
        return self.stall_force_per_volt_n * self.voltage_limit_v

    @property
    def free_speed_per_volt_mps(self) -> float:
        """DC gain of eq. 9 times p/2pi: steady finger speed per volt in free motion."""
        return self.torque_constant_n_m_per_a * self.travel_per_rad_m / (
            self.damping_n_m_s_per_rad * self.resistance_ohm
            + self.torque_constant_n_m_per_a * self.back_emf_v_s_per_rad)

    @property
    def mechanical_time_constant_s(self) -> float:
        """Time constant of the finger's speed under a held voltage in free motion.

        ``J_m / (b_m + k_t k_b / R_a)``, the armature inductance neglected.
        """
        return self.inertia_kg_m2 / (
            self.damping_n_m_s_per_rad
            + self.torque_constant_n_m_per_a * self.back_emf_v_s_per_rad / self.resistance_ohm)

    @property
    def max_free_speed_mps(self) -> float:
        """Steady finger speed at the voltage limit in free motion (the fastest a move goes)."""
        return self.free_speed_per_volt_mps * self.voltage_limit_v


@dataclass(frozen=True)
class ContactParams:
    """Default object contact: normal (stiffness, damping) and tangential (pad friction)."""

    stiffness_n_per_m: float = key("object stiffness; 0 = the paper's inelastic contact",
                                   bounds=(0.0, 1e10), rule=NONNEGATIVE)
    damping_n_s_per_m: float = key('object damping (Kelvin-Voigt)', bounds=(0.0, 1e7),
                                   rule=NONNEGATIVE)
    static_friction: float = key('mu_s between pad and object (per pad)', bounds=(0.0, 2.0),
                                 absent=SHIPPED)
    kinetic_friction: float = key('mu_k while the object slides; <= mu_s', bounds=(0.0, 2.0),
                                  absent=SHIPPED)
    pad_length_m: float = key('the object is out once it has slid this far',
                              bounds=(1e-4, 1.0), absent=SHIPPED)
    after_lift_s: float = key('fast mode plays a lift out this long after it ends',
                              bounds=(0.0, 60.0), rule=NONNEGATIVE, absent=SHIPPED)
    pad_tangential_stiffness_n_per_m: float = key(
        "each pad's initial tangential (Cattaneo-Mindlin) stiffness; 0 = rigid pads",
        bounds=(0.0, 1e10), rule=NONNEGATIVE, absent=0.0)
    lift_off_s: float = key('the weight passes from the support to the pads over this long',
                            bounds=(0.0, 10.0), rule=NONNEGATIVE, absent=0.0)
    finger_stiffness_n_per_m: float = key(
        "each finger's bending stiffness at its pad; 0 = a rigid finger",
        bounds=(0.0, 1e10), rule=NONNEGATIVE, absent=0.0)
    pad_normal_stiffness_n_per_m1_5: float = key(
        "each pad's Hertz stiffness, F = k_p delta^1.5; 0 = no pad",
        bounds=(0.0, 1e12), rule=NONNEGATIVE, absent=0.0)


def _kinetic_friction_at_most_static(config: GripperConfig) -> None:
    contact = config.contact
    if contact.kinetic_friction > contact.static_friction:
        raise ConfigError('"contact.kinetic_friction" must be <= "contact.static_friction" '
                          f'({contact.static_friction!r}), got {contact.kinetic_friction!r}')


@dataclass(frozen=True)
class ForceSensorParams:
    supply_v: float = key('FSR divider supply voltage', bounds=(0.1, 100.0))
    measuring_resistor_ohm: float = key('R_m of the divider', bounds=(1.0, 1e12))
    fsr_resistance_at_1n_ohm: float = key('R_fsr = this / F once activated', bounds=(1.0, 1e12))
    open_resistance_ohm: float = key('R_fsr below the activation force', bounds=(1.0, 1e12))
    activation_force_n: float = key('the FSR conducts above this force', bounds=(1e-6, 100.0))


@dataclass(frozen=True)
class SensorNoiseParams:
    """Measurement noise of the simulated position and force sensors (all 0 = ideal sensors).

    Gaussian noise of the given standard deviation, then rounding to the quantum (an ADC or
    encoder step); the noise of a sample is a function of ``seed`` and the sample's instant,
    so a run is reproducible and a repeated reading of one instant reads the same.
    """

    position_noise_m: float = key('1 sigma of the position noise', bounds=(0.0, 0.01),
                                  rule=NONNEGATIVE, absent=0.0)
    position_quantum_m: float = key('position rounded to this step', bounds=(0.0, 0.01),
                                    rule=NONNEGATIVE, absent=0.0)
    force_noise_n: float = key('1 sigma of the force noise', bounds=(0.0, 100.0),
                               rule=NONNEGATIVE, absent=0.0)
    force_quantum_n: float = key('force rounded to this step', bounds=(0.0, 100.0),
                                 rule=NONNEGATIVE, absent=0.0)
    seed: int = key('seed of the noise', bounds=(0, 2 ** 63 - 1), rule=NONNEGATIVE,
                    integer=True, absent=0)

    @classmethod
    def ideal(cls) -> SensorNoiseParams:
        """Return no noise and no quantisation: the ideal sensors."""
        return cls(0.0, 0.0, 0.0, 0.0, 0)

    @property
    def enabled(self) -> bool:
        return any((self.position_noise_m, self.position_quantum_m, self.force_noise_n,
                    self.force_quantum_n))


@dataclass(frozen=True)
class ChannelSpec:
    """A channel's resolution, noise (1 sigma), bandwidth (Hz, 0 = none) and latency (s)."""

    resolution: float
    noise: float
    bandwidth_hz: float
    latency_s: float

    def __post_init__(self):
        for name in ('resolution', 'noise', 'bandwidth_hz', 'latency_s'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                    not math.isfinite(value) or value < 0.0:
                raise ValueError(f'pad sensor {name} must be a finite number >= 0, '
                                 f'got {value!r}')


@dataclass(frozen=True)
class PadSensorParams:
    """Each pad's shear and displacement sensing (core/physics/pad_sensor.py)."""

    shear_resolution_n: float = key('shear read-out step', bounds=(0.0, 10.0),
                                    rule=NONNEGATIVE, absent=SHIPPED)
    shear_noise_n: float = key('1 sigma of the shear noise', bounds=(0.0, 10.0),
                               rule=NONNEGATIVE, absent=SHIPPED)
    shear_bandwidth_hz: float = key('first-order bandwidth of the shear; 0 = none',
                                    bounds=(0.0, 1e6), rule=NONNEGATIVE, absent=SHIPPED)
    shear_latency_s: float = key('delay of the shear', bounds=(0.0, 1.0), rule=NONNEGATIVE,
                                 absent=SHIPPED)
    displacement_resolution_m: float = key('pad displacement read-out step',
                                           bounds=(0.0, 0.01), rule=NONNEGATIVE,
                                           absent=SHIPPED)
    displacement_noise_m: float = key('1 sigma of the displacement noise', bounds=(0.0, 0.01),
                                      rule=NONNEGATIVE, absent=SHIPPED)
    displacement_bandwidth_hz: float = key(
        'first-order bandwidth of the displacement; 0 = none', bounds=(0.0, 1e6),
        rule=NONNEGATIVE, absent=SHIPPED)
    displacement_latency_s: float = key('delay of the displacement', bounds=(0.0, 1.0),
                                        rule=NONNEGATIVE, absent=SHIPPED)

    @property
    def shear(self):
        """The shear channel's :class:`ChannelSpec`."""
        return ChannelSpec(self.shear_resolution_n, self.shear_noise_n,
                           self.shear_bandwidth_hz, self.shear_latency_s)

    @property
    def displacement(self):
        """The displacement channel's :class:`ChannelSpec`."""
        return ChannelSpec(self.displacement_resolution_m, self.displacement_noise_m,
                           self.displacement_bandwidth_hz, self.displacement_latency_s)


_BELOW_THE_LOAD = '(a grip that knowingly holds less than the load)'


@dataclass(frozen=True)
class LoadGripParams:
    """The load-tracking grip's settings (core/control/load_grip.py)."""

    grip_margin: float = key('F_sp = this x F_load / (2 mu_est)', bounds=(1.0, 10.0),
                             absent=SHIPPED, why=_BELOW_THE_LOAD)
    mu_start: float = key('mu_est before a fit: the least friction expected',
                          bounds=(0.01, 2.0), absent=SHIPPED)
    mu_safety: float = key('the fitted friction is believed times this', bounds=(1e-3, 1.0),
                           absent=SHIPPED)
    touch_force_n: float = key('the grip closes to this force first', bounds=(1e-3, 100.0),
                               absent=SHIPPED)
    slip_speed_mps: float = key('a pad displacement faster than this is a slip',
                                bounds=(1e-6, 1.0), absent=SHIPPED)
    slip_window_s: float = key('a slip: the slip speed over this long', bounds=(1e-4, 1.0),
                               absent=SHIPPED)
    slip_rest_s: float = key('a slip ends after this long below the slip speed',
                             bounds=(0.0, 1.0), absent=SHIPPED)
    min_samples: int = key('stuck samples before a friction fit is believed',
                           bounds=(1, 100000), integer=True, absent=SHIPPED)
    release_rate_n_per_s: float = key('the grip falls no faster (it rises at once)',
                                      bounds=(1e-3, 1e6), absent=SHIPPED)
    overload_slip_s: float = key("slipping this long at the voltage limit's grip: overload",
                                 bounds=(1e-4, 10.0), absent=SHIPPED)


@dataclass(frozen=True)
class GeometryParams:
    """The base and fingers as the robot description draws them (core/description.py).

    The closing axis is x: the fixed finger's pad face is at +max_travel_m/2, the moving
    finger's at -max_travel_m/2 when fully open.
    """

    finger_thickness_m: float = key('finger along the closing axis, behind the pad face',
                                    bounds=(1e-4, 1.0), absent=SHIPPED)
    finger_width_m: float = key('finger across the closing axis', bounds=(1e-4, 1.0),
                                absent=SHIPPED)
    finger_length_m: float = key('finger from the top of the base to the fingertip',
                                 bounds=(1e-4, 1.0), absent=SHIPPED)
    base_height_m: float = key('base from the mounting face to its top', bounds=(1e-4, 1.0),
                               absent=SHIPPED)
    base_width_m: float = key('base across the closing axis', bounds=(1e-4, 1.0),
                              absent=SHIPPED)
    base_mass_kg: float = key('the base with motor and lead screw, a solid box',
                              bounds=(1e-4, 100.0), absent=SHIPPED)
    finger_mass_kg: float = key('each finger with its pad, a solid box', bounds=(1e-4, 100.0),
                                absent=SHIPPED)


_GAIN_BOUNDS = (0.0, 1e6)


@dataclass(frozen=True)
class PidGains:
    kc: float = key('proportional gain', bounds=_GAIN_BOUNDS, rule=NONNEGATIVE)
    ki: float = key('integral gain; absent: none', bounds=_GAIN_BOUNDS, rule=NONNEGATIVE,
                    default=0.0)
    kd: float = key('derivative gain; absent: none', bounds=_GAIN_BOUNDS, rule=NONNEGATIVE,
                    default=0.0)


MAX_HORIZON = 2000
"""Most samples of a DMC step-response model: its matrices, their build when a parameter
changes and its work every tick grow with it (the shipped horizons are 700 and 100)."""


@dataclass(frozen=True)
class DmcTuning:
    horizon: int = key('samples of the step-response model', bounds=(1, MAX_HORIZON),
                       integer=True)
    control_horizon: int = key('future moves planned; <= horizon', bounds=(1, MAX_HORIZON),
                               integer=True)
    move_suppression: float = key('weight on the planned moves', bounds=(1e-6, 1e6))


@dataclass(frozen=True)
class PositionControlParams:
    sample_time_s: float = key('position loop period', bounds=(1e-3, 0.1))
    pd: PidGains = part()
    pid: PidGains = part()
    mpc_pd: PidGains = part()
    mpc_pd_dmc: DmcTuning = part('mpc_pd')
    mpc_pd_braking_voltage_v: float = key(
        "braking governor's planning voltage (ours); <= plant.voltage_limit_v",
        bounds=(0.0, 1000.0), rule=NONNEGATIVE)
    speed_limit_pole: float = key(
        "discrete pole of the finger speed under a move's limit (ours)", bounds=(0.0, 1.0),
        rule=NONNEGATIVE, open_high=True, absent=SHIPPED)


def _speed_limit_pole_below_the_open_loop_one(config: GripperConfig) -> None:
    position = config.position
    speed_pole = math.exp(-position.sample_time_s / config.plant.mechanical_time_constant_s)
    if not position.speed_limit_pole < speed_pole:
        raise ConfigError('"position_control.speed_limit_pole" must be in [0, '
                          f'{speed_pole:.6g}) (the open-loop pole of the finger speed over one '
                          f'sample; slower than that never reaches the limit), '
                          f'got {position.speed_limit_pole!r}')


def _braking_voltage_within_the_limit(config: GripperConfig) -> None:
    if config.position.mpc_pd_braking_voltage_v > config.plant.voltage_limit_v:
        raise ConfigError('"position_control.mpc_pd_braking_voltage_v" must be <= '
                          '"plant.voltage_limit_v", '
                          f'got {config.position.mpc_pd_braking_voltage_v!r}')


@dataclass(frozen=True)
class ContactForceTuning:
    """The contact-aware force stage (gripper_ros/core/control/contact_force.py), ours."""

    design_stiffness_n_per_m: float = key('stiffest object the contact speed is designed for',
                                          bounds=(1.0, 1e10))
    design_damping_ratio: float = key('damping ratio of that object (against the reflected mass)',
                                      bounds=(1e-3, 10.0))
    band_design_stiffness_n_per_m: float = key('design stiffness within a width tolerance band',
                                               bounds=(1.0, 1e10))
    impact_force_fraction: float = key('impact at the contact speed <= this x F_sp',
                                       bounds=(0.0, 1.0), open_high=True)
    braking_deceleration_mps2: float = key("the speed profiles' deceleration",
                                           bounds=(1e-4, 10.0))
    contact_force_n: float = key('contact once the measured force exceeds this',
                                 bounds=(1e-9, 10.0))
    untouched_overtravel_m: float = key('past the narrowest face by this, untouched: V_ff',
                                        bounds=(1e-9, 0.01))
    force_gain_v_per_n: float = key('extra Kp on the force error after contact',
                                    bounds=(0.0, 1000.0), rule=NONNEGATIVE)
    damping_ratio: float = key('of the closed loop on the estimated spring',
                               bounds=(1e-3, 10.0))
    servo_sample_gain: float = key('most of a speed error the servo corrects per sample',
                                   bounds=(1e-3, 1.0))
    max_damping_v_s_per_m: float = key('speed-servo gain cap', bounds=(1.0, 1e9))
    integral_gain_v_per_n_s: float = key('model-error trim, only while at rest in contact',
                                         bounds=(0.0, 1000.0), rule=NONNEGATIVE)
    integral_speed_band_mps: float = key('the trim runs only below this finger speed',
                                         bounds=(1e-7, 1.0))
    integral_rate_fraction: float = key('the trim runs only while |de/dt| tau_k < this x |e|',
                                        bounds=(1e-3, 1.0))
    setpoint_rate_time_constant_s: float = key(
        "a moving setpoint's rate, low-passed over this, leads the speed reference; 0 = raw",
        bounds=(0.0, 1.0), rule=NONNEGATIVE, absent=SHIPPED)


@dataclass(frozen=True)
class ForceControlParams:
    paper_sample_time_s: float = key("the paper's force loop period", bounds=(5e-5, 0.01))
    pi_paper: PidGains = part()
    mpc_pi_paper: PidGains = part()
    mpc_pi_paper_dmc: DmcTuning = part('mpc_pi_paper')
    sample_time_s: float = key(
        'force loop period; plant_simulator samples the pads and the supervisor sizes the '
        "load-tracking grip's windows at it too, so it is fixed at start-up (set it for all "
        'three nodes with --params-file or config_file)', bounds=(5e-5, 0.01), runtime=False)
    closed_loop_pole: float = key('both closed-loop poles of the discrete PI (ours)',
                                  bounds=(0.0, 1.0), rule=NONNEGATIVE, open_high=True,
                                  why='for a stable loop')
    mpc_pi_dmc: DmcTuning = part('mpc_pi')
    contact_aware: ContactForceTuning = part()


def _control_horizon_within_the_horizon(config: GripperConfig) -> None:
    for where, dmc in (('position_control.mpc_pd', config.position.mpc_pd_dmc),
                       ('force_control.mpc_pi_paper', config.force.mpc_pi_paper_dmc),
                       ('force_control.mpc_pi', config.force.mpc_pi_dmc)):
        if dmc.control_horizon > dmc.horizon:
            raise ConfigError(f'"{where}.control_horizon" must be <= "{where}.horizon" '
                              f'({dmc.horizon}), got {dmc.control_horizon}')


class ForceLaw(enum.Enum):
    """How the grasp's force setpoint follows from mass, friction and acceleration."""

    FRICTION = 'friction'   # k m (g + a) / (2 mu_s): each of the two pads holds mu_s F
    PAPER = 'paper'         # eq. 23 as printed, mu_s m (g + a)


@dataclass(frozen=True)
class SupervisorParams:
    friction_coefficient: float = key('mu_s assumed by the setpoint', bounds=(0.01, 2.0))
    acceleration_mps2: float = key("a, the arm's acceleration in the setpoint",
                                   bounds=(0.0, 100.0), rule=NONNEGATIVE)
    position_tolerance_fraction: float = key('switch 1: |x - x_sp| within this x x_sp',
                                             bounds=(1e-6, 0.5))
    sensor_voltage_threshold_v: float = key('switch 2: rise of the FSR voltage',
                                            bounds=(1e-6, 100.0))
    force_settle_band_fraction: float = key('settled: |F - F_sp| within this x F_sp',
                                            bounds=(1e-6, 0.5))
    force_settle_hold_s: float = key('settled: within the band every tick this long',
                                     bounds=(1e-6, 10.0))
    timeout_s: float = key('simulated-time budget of a grasp', bounds=(0.01, 3600.0))
    no_object_margin_m: float = key('NO_OBJECT once the finger passes the face by this',
                                    bounds=(1e-6, 0.1))
    hold_watch_s: float = key('the force loop holds and watches this long before HOLDING',
                              bounds=(0.0, 10.0), rule=NONNEGATIVE, absent=SHIPPED)
    lost_force_fraction: float = key('OBJECT_LOST: force below this x F_sp after a grip',
                                     bounds=(0.0, 1.0), open_high=True, absent=SHIPPED)
    lost_force_hold_s: float = key('OBJECT_LOST: the force that low this long',
                                   bounds=(1e-6, 10.0), absent=SHIPPED)
    release_tolerance_m: float = key('release done within this of the open position',
                                     bounds=(1e-6, 0.1), absent=SHIPPED)
    release_settle_s: float = key('release done: within its tolerance this long',
                                  bounds=(0.0, 10.0), rule=NONNEGATIVE,
                                  absent=SHIPPED)
    position_switch_speed_mps: float = key("switch 1 also needs |speed| <= this; 0: paper's",
                                           bounds=(0.0, 1.0), rule=NONNEGATIVE, absent=0.0)
    width_tolerance_m: float = key("default +- on a request's width; 0: trust the width",
                                   bounds=(0.0, 0.1), rule=NONNEGATIVE, absent=0.0)
    force_settle_horizon_s: float = key('settled: |e| + this x |dF/dt| in the band; 0: the band',
                                        bounds=(0.0, 100.0), rule=NONNEGATIVE, absent=0.0)
    force_settle_speed_mps: float = key('settled: also the finger slower than this; 0: no bound',
                                        bounds=(0.0, 1.0), rule=NONNEGATIVE, absent=0.0)
    force_law: ForceLaw = key('how the force setpoint follows from the load',
                              choices=ForceLaw, absent=SHIPPED)
    grip_safety_factor: float = key('k of the friction law', bounds=(1.0, 10.0),
                                    absent=SHIPPED, why=_BELOW_THE_LOAD)
    move_default_speed_mps: float = key("a move's speed when the request gives none",
                                        bounds=(1e-6, 10.0), absent=SHIPPED)
    move_tolerance_m: float = key('reached_goal: at rest within this of the width',
                                  bounds=(1e-6, 0.1), absent=SHIPPED)
    move_rest_speed_mps: float = key('"at rest": |finger speed| at most this',
                                     bounds=(1e-6, 1.0), absent=SHIPPED)
    move_stall_force_fraction: float = key(
        'stalled at once: at rest, pressing with this share of the effort',
        bounds=(0.0, 1.0), absent=SHIPPED, why='(a force above the effort limit is never '
                                               'reached)')
    move_stall_timeout_s: float = key('stalled: at rest short of the width this long',
                                      bounds=(1e-3, 60.0), absent=SHIPPED)
    servo_lead_s: float = key("a stream's setpoints are this old as they come: the reference "
                              'leads the newest by its motion over this (0: none)',
                              bounds=(0.0, 10.0), rule=NONNEGATIVE, absent=SHIPPED)
    servo_rate_window_s: float = key('a stream changes while a setpoint comes within this; the '
                                     'reference moves on from the newest this long at most',
                                     bounds=(1e-3, 1.0), absent=SHIPPED)
    servo_fit_memory_s: float = key("a stream's velocity and acceleration: a quadratic fit to "
                                    'its setpoints weighted by exp(-age / this)',
                                    bounds=(1e-3, 10.0), absent=SHIPPED)


def _move_default_speed_above_rest(config: GripperConfig) -> None:
    sup, plant = config.supervisor, config.plant
    if not sup.move_rest_speed_mps < sup.move_default_speed_mps:
        raise ConfigError('"supervisor.move_default_speed_mps" must be above '
                          f'"supervisor.move_rest_speed_mps" = {sup.move_rest_speed_mps!r} '
                          f'(and so must the free speed at "plant.voltage_limit_v", '
                          f'{plant.max_free_speed_mps:.6g} m/s), got '
                          f'{sup.move_default_speed_mps!r}')


@dataclass(frozen=True)
class GripperConfig:
    plant: PlantParams = part()
    contact: ContactParams = part()
    force_sensor: ForceSensorParams = part()
    position: PositionControlParams = part('position_control')
    force: ForceControlParams = part('force_control')
    supervisor: SupervisorParams = part()
    sensor_noise: SensorNoiseParams = part()
    pad_sensor: PadSensorParams = part()
    load_grip: LoadGripParams = part()
    geometry: GeometryParams = part()
    source: str
    data: dict = field(default_factory=dict, compare=False, hash=False, repr=False)
    """The mapping the values were read from (what a bag records, what re-runs start from)."""


CROSS_CHECKS = (_kinetic_friction_at_most_static, _speed_limit_pole_below_the_open_loop_one,
                _control_horizon_within_the_horizon, _braking_voltage_within_the_limit,
                _move_default_speed_above_rest)
"""The checks that tie keys together, in this order, after every key met its own bounds."""


def default_config_path() -> Path:
    """Return ``$GRIPPER_ROS_CONFIG`` if set, else :func:`shipped_config_path`."""
    env = os.environ.get('GRIPPER_ROS_CONFIG')
    return Path(env) if env else shipped_config_path()


def shipped_config_path() -> Path:
    """Return the installed ``share/gripper_ros/config/gripper.yaml``, else the tree's copy."""
    try:
        from ament_index_python.packages import get_package_share_directory
        installed = Path(get_package_share_directory(PACKAGE_NAME)) / 'config' / CONFIG_FILE_NAME
        if installed.is_file():
            return installed
    except (ImportError, LookupError, ValueError, OSError):
        pass
    return Path(__file__).resolve().parents[2] / 'config' / CONFIG_FILE_NAME


# ------------------------------------------------------------------ what the keys give
def _walk(cls, prefix: str = ''):
    """Yield ``(dotted, name, Key)`` of every key under dataclass ``cls``, in file order."""
    hints = typing.get_type_hints(cls)
    for f in fields(cls):
        if 'key' in f.metadata:
            yield prefix + f.name, f.name, f.metadata['key']
        elif 'part' in f.metadata:
            yield from _walk(hints[f.name], f'{prefix}{f.metadata["part"] or f.name}.')


SCHEMA: dict[str, Key] = {
    dotted: spec if spec.unit is not None else spec._replace(unit=unit_of(name))
    for dotted, name, spec in _walk(GripperConfig)}
"""Every key a config file may hold (dotted) -> its :class:`Key`, in the order of the file."""

ADDED_LATER: dict[str, float | None] = {
    dotted: spec.absent for dotted, spec in SCHEMA.items() if spec.absent is not REQUIRED}
"""Keys a file may lack (it predates them) -> what their absence means: :data:`SHIPPED` (the
shipped file's value, the one home of every value) or the value that turns the feature off."""

BOUNDS: dict[str, tuple[float, float]] = {
    dotted: spec.bounds for dotted, spec in SCHEMA.items() if spec.bounds is not None}
"""Every number's [low, high] (``Key.open_high`` and a > 0 rule refuse an end); the shipped
file lists them at its end (:func:`bounds_text`)."""


def numbers_of(cls) -> tuple[str, ...]:
    """Return the names of the number keys of dataclass ``cls`` (not its choices or parts)."""
    return tuple(f.name for f in fields(cls)
                 if 'key' in f.metadata and f.metadata['key'].choices is None)


def bounds_of(name: str) -> tuple[float, float] | None:
    """Return the [low, high] of dotted key ``name``, None if it is no number of the file."""
    return BOUNDS.get(name)


BOUNDS_HEADER = '# Bounds (gripper_ros/core/config.py):'


def bounds_text() -> str:
    """Return the bounds as the comment block at the end of ``config/gripper.yaml``."""
    lines = [f'{BOUNDS_HEADER} every value must lie within them, a round',
             "# bracket's end excluded; the checks that tie keys together apply too. Written by",
             '# python3 -m gripper_ros.core.config --write-bounds FILE.']
    lines += [f'#   {dotted}: {spec.interval()}' for dotted, spec in SCHEMA.items()
              if spec.bounds is not None]
    return '\n'.join(lines) + '\n'


def with_bounds_text(text: str) -> str:
    """Return a config file's ``text`` with its bounds block (at its end) as the schema says."""
    start = text.find(BOUNDS_HEADER)
    if start < 0:
        start = text.find('# Bounds (')
    return (text[:start] if start >= 0 else text.rstrip('\n') + '\n\n') + bounds_text()


def nested(names) -> dict:
    """Return dotted ``names`` as nested sections, a leaf None: ``a.b`` -> ``{a: {b: None}}``."""
    tree: dict = {}
    for dotted in names:
        *sections, leaf = dotted.split('.')
        node = tree
        for section in sections:
            if not isinstance(node.get(section), dict):     # a name that is also a section
                node[section] = {}
            node = node[section]
        node.setdefault(leaf, None)
    return tree


def known_keys() -> dict:
    """Every key a config file may hold, as nested sections (a leaf is None)."""
    return nested(SCHEMA)


def _optional(section: str) -> bool:
    """Return whether a file may lack ``section`` (every key of it may be absent)."""
    return all(spec.absent is not REQUIRED for dotted, spec in SCHEMA.items()
               if dotted.startswith(section + '.'))


@functools.cache
def _shipped_data() -> dict:
    return yaml.safe_load(shipped_config_path().read_text(encoding='utf-8'))


def _absent_value(dotted: str):
    """Return what a file without key ``dotted`` means, or MISSING if it must have it."""
    meaning = SCHEMA[dotted].absent
    if meaning is REQUIRED:
        return MISSING
    if meaning is not SHIPPED:
        return meaning
    section, key = dotted_section(_shipped_data(), dotted)
    return section[key]


def shipped_config() -> GripperConfig:
    """Return the shipped config/gripper.yaml, read once (what a component without one uses)."""
    return _shipped_config()


@functools.cache
def _shipped_config() -> GripperConfig:
    return load_config(shipped_config_path())


def dotted_section(data: dict, dotted: str, source: str = 'the config') -> tuple[dict, str]:
    """Return the section of ``data`` that holds key ``dotted``, and the key's last part.

    The one walk of a dotted key (``force_control.sample_time_s``) into nested sections;
    ConfigError names a part the mapping lacks, where, and what that section holds.
    """
    parts = dotted.split('.')
    node = data
    for depth, part in enumerate(parts):
        if not isinstance(node, dict) or part not in node:
            where = '.'.join(parts[:depth])
            has = ', '.join(sorted(node)) if isinstance(node, dict) else 'no keys'
            raise ConfigError(f'unknown config key "{dotted}" in {source} '
                              f'({where or "the top level"} has: {has})')
        if depth < len(parts) - 1:
            node = node[part]
    return node, parts[-1]


def flatten(data: dict, prefix: str = '') -> dict[str, object]:
    """Flatten nested sections to dotted keys: ``{'a': {'b': 1}}`` -> ``{'a.b': 1}``."""
    out = {}
    for key, value in data.items():
        name = f'{prefix}{key}'
        if isinstance(value, dict):
            out.update(flatten(value, name + '.'))
        else:
            out[name] = value
    return out


def find_unknown(data: dict, known: dict, where: str = '') -> tuple[str, str] | None:
    """Return the first name of ``data`` that ``known`` lacks (a typo) and a hint, or None.

    ``data`` and ``known`` are nested sections (:func:`nested`). The hint is the closest known
    name of the same section (``did you mean "supervisor.timeout_s"?``), or that section's
    known names when none is close.
    """
    import difflib
    for key, value in data.items():
        name = f'{where}{key}'
        if key not in known:
            close = difflib.get_close_matches(str(key), [str(k) for k in known], n=1)
            return name, (f'did you mean "{where}{close[0]}"?' if close else
                          f'known here: {", ".join(known)}')
        if isinstance(known[key], dict) and isinstance(value, dict):
            found = find_unknown(value, known[key], name + '.')
            if found is not None:
                return found
    return None


def refuse_unknown(data: dict, known: dict, what: str = 'key') -> None:
    """Refuse a name nobody reads (:func:`find_unknown`): ConfigError naming it and a hint.

    ``what`` names what the names are: a config file's keys, a node's parameters.
    """
    found = find_unknown(data, known)
    if found is not None:
        raise ConfigError(f'unknown {what} "{found[0]}"; {found[1]}')


def _section(data: dict, key: str, where: str) -> dict:
    value = data.get(key)
    if not isinstance(value, dict):
        raise ConfigError(f'{where}: missing section "{key}"')
    return value


def _number(section: dict, name: str, spec: Key) -> float:
    if name.rsplit('.', 1)[-1] not in section:
        raise ConfigError(f'missing key "{name}"')
    value = section[name.rsplit('.', 1)[-1]]
    if isinstance(value, str) and _reads_as_number(value):
        raise ConfigError(f'"{name}" must be a number, got the text {value!r}: YAML reads a '
                          'float only with a dot and a signed exponent (write 1.0e-3, not '
                          '1e-3)')
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f'"{name}" must be a number, got {value!r}')
    value = float(value)
    if not math.isfinite(value):
        raise ConfigError(f'"{name}" must be finite, got {value!r}')
    if spec.rule == POSITIVE and value <= 0.0:
        raise ConfigError(f'"{name}" must be > 0, got {value!r}')
    if spec.rule == NONNEGATIVE and value < 0.0:
        raise ConfigError(f'"{name}" must be >= 0, got {value!r}')
    if not spec.holds(value):
        why = f' {spec.why}' if spec.why else ''
        raise ConfigError(f'"{name}" must be in {spec.interval()}{why}, got {value!r}')
    if spec.integer:
        if value != int(value):
            raise ConfigError(f'"{name}" must be a whole number, got {value!r}')
        return int(value)
    return value


def _reads_as_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _choice(section: dict, name: str, choices: type[enum.Enum]) -> enum.Enum:
    if name.rsplit('.', 1)[-1] not in section:
        raise ConfigError(f'missing key "{name}"')
    value = section[name.rsplit('.', 1)[-1]]
    known = ', '.join(repr(c.value) for c in choices)
    if not isinstance(value, str):
        raise ConfigError(f'"{name}" must be one of {known}, got {value!r}')
    try:
        return choices(value)
    except ValueError:
        raise ConfigError(f'"{name}" must be one of {known}, got {value!r}') from None


def _build(cls, section: dict, where: str):
    """Return dataclass ``cls`` read from the file's ``section`` (at dotted ``where``)."""
    hints = typing.get_type_hints(cls)
    kwargs = {}
    for f in fields(cls):
        name = f'{where}.{f.name}'
        if 'part' in f.metadata:
            at = f.metadata['part'] or f.name
            kwargs[f.name] = _build(hints[f.name], _section(section, at, where), f'{where}.{at}')
            continue
        spec = SCHEMA[name]
        if f.name not in section:
            absent = _absent_value(name)
            if absent is not MISSING:
                section = {**section, f.name: absent}
        if spec.choices is not None:
            kwargs[f.name] = _choice(section, name, spec.choices)
        else:
            kwargs[f.name] = _number(section, name, spec)
    return cls(**kwargs)


def object_contact(stiffness_n_per_m: float, damping_n_s_per_m: float) -> ContactParams:
    """Return the contact a file giving only the object's stiffness and damping means."""
    return _build(ContactParams, {'stiffness_n_per_m': stiffness_n_per_m,
                                  'damping_n_s_per_m': damping_n_s_per_m}, 'contact')


def parse_config(data: dict, source: str = '<dict>') -> GripperConfig:
    """Validate a loaded YAML mapping into a :class:`GripperConfig`."""
    if not isinstance(data, dict):
        raise ConfigError(f'{source}: top level must be a mapping')
    refuse_unknown(data, known_keys())
    hints = typing.get_type_hints(GripperConfig)
    parts = {}
    for f in fields(GripperConfig):
        if 'part' in f.metadata:
            at = f.metadata['part'] or f.name
            section = {} if at not in data and _optional(at) else _section(data, at, source)
            parts[f.name] = _build(hints[f.name], section, at)
    config = GripperConfig(**parts, source=source, data=copy.deepcopy(data))
    config = replace(config, supervisor=replace(
        config.supervisor,
        move_default_speed_mps=move_default_speed_mps(config.supervisor, config.plant)))
    for check in CROSS_CHECKS:
        check(config)
    return config


def move_default_speed_mps(sup: SupervisorParams, plant: PlantParams) -> float:
    """Return the speed of a move without one: the configured one, at most the plant's free speed.

    The free speed at ``plant.voltage_limit_v`` is the fastest a move goes, so a plant slower
    than the configured default (an identified one, say) moves at its free speed.
    """
    return min(sup.move_default_speed_mps, plant.max_free_speed_mps)


def read_as_notes(config: GripperConfig) -> list[str]:
    """Say, a line each, which values of the file are read otherwise than written (and why)."""
    written = config.data.get('supervisor', {}).get('move_default_speed_mps')
    read = config.supervisor.move_default_speed_mps
    if isinstance(written, (int, float)) and written != read:
        return [f'supervisor.move_default_speed_mps {written:g} m/s is above the free speed at '
                f'plant.voltage_limit_v ({config.plant.voltage_limit_v:g} V), {read:.6g} m/s: '
                'a move without a speed goes at that free speed']
    return []


@functools.lru_cache(maxsize=8)
def _parsed_yaml(text: str):
    return yaml.safe_load(text)


def load_config(path: str | os.PathLike | None = None) -> GripperConfig:
    """Load and validate the YAML file (default: the package's ``config/gripper.yaml``).

    A text read before in this process is not parsed again (a graph's start reads its config
    once per node, 20 ms each); the caller gets a copy of what it parsed to.
    """
    file_path = Path(path) if path is not None else default_config_path()
    try:
        text = file_path.read_text(encoding='utf-8')
    except OSError as exc:
        raise ConfigError(f'cannot read config file {file_path}: {exc.strerror}') from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f'config file {file_path} is not UTF-8 text (byte {exc.start}): '
                          'is it a YAML file?') from None
    try:
        data = copy.deepcopy(_parsed_yaml(text))
    except yaml.YAMLError as exc:
        raise ConfigError(f'config file {file_path} is not valid YAML: {exc}') from None
    except RecursionError:
        raise ConfigError(f'config file {file_path} is nested too deeply to be a gripper '
                          'config') from None
    return parse_config(data, str(file_path))


def main(argv: list[str] | None = None) -> int:
    """Write the bounds block at the end of each config file: ``--write-bounds FILE...``."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) < 2 or args[0] != '--write-bounds':
        print('usage: python3 -m gripper_ros.core.config --write-bounds FILE...', file=sys.stderr)
        return 2
    for name in args[1:]:
        path = Path(name)
        path.write_text(with_bounds_text(path.read_text(encoding='utf-8')), encoding='utf-8')
        print(f'bounds: {path}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
