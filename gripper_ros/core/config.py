"""The one reader of ``config/gripper.yaml`` (Table I plant, Table II gains, sensor, supervisor).

Everything numeric the package uses comes through :func:`load_config`; nodes turn these values
into ROS parameter defaults. A bad file stops with a :class:`ConfigError` naming the key.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field, fields, MISSING, replace
import enum
import functools
import math
import os
from pathlib import Path

import yaml

PACKAGE_NAME = 'gripper_ros'
CONFIG_FILE_NAME = 'gripper.yaml'


class ConfigError(ValueError):
    """A configuration file is missing, unreadable or holds a bad value (message names the key)."""


@dataclass(frozen=True)
class PlantParams:
    """Table I, SI units."""

    inertia_kg_m2: float
    damping_n_m_s_per_rad: float
    gear_ratio: float
    resistance_ohm: float
    inductance_h: float
    pitch_m: float
    torque_constant_n_m_per_a: float
    back_emf_v_s_per_rad: float
    efficiency: float
    max_travel_m: float
    gravity_mps2: float
    voltage_limit_v: float
    contact_substep_s: float

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

    stiffness_n_per_m: float
    damping_n_s_per_m: float
    static_friction: float             # mu_s between pad and object (per pad)
    kinetic_friction: float            # mu_k while the object slides; <= mu_s
    pad_length_m: float                # the object is out once it has slid this far
    after_lift_s: float                # fast mode plays a lift out this long after it ends
    # Cattaneo-Mindlin pre-sliding of each pad (core/physics/hold.py): its initial tangential
    # stiffness; 0 = rigid pads, the Coulomb law alone.
    pad_tangential_stiffness_n_per_m: float
    # The arm's lift-off (core/physics/hold.py): the weight passes from the support to the pads
    # over this long; 0 = all at once.
    lift_off_s: float
    # The normal chain (core/physics/contact_chain.py): each finger's bending stiffness at its pad
    # and each pad's Hertz stiffness (F = k_p delta^1.5); 0 = a rigid finger, no pad: the object
    # alone, as in the paper.
    finger_stiffness_n_per_m: float
    pad_normal_stiffness_n_per_m1_5: float


@dataclass(frozen=True)
class ForceSensorParams:
    supply_v: float
    measuring_resistor_ohm: float
    fsr_resistance_at_1n_ohm: float
    open_resistance_ohm: float
    activation_force_n: float


@dataclass(frozen=True)
class SensorNoiseParams:
    """Measurement noise of the simulated position and force sensors (all 0 = ideal sensors).

    Gaussian noise of the given standard deviation, then rounding to the quantum (an ADC or
    encoder step); the noise of a sample is a function of ``seed`` and the sample's instant,
    so a run is reproducible and a repeated reading of one instant reads the same.
    """

    position_noise_m: float
    position_quantum_m: float
    force_noise_n: float
    force_quantum_n: float
    seed: int

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

    shear_resolution_n: float
    shear_noise_n: float
    shear_bandwidth_hz: float
    shear_latency_s: float
    displacement_resolution_m: float
    displacement_noise_m: float
    displacement_bandwidth_hz: float
    displacement_latency_s: float

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


@dataclass(frozen=True)
class LoadGripParams:
    """The load-tracking grip's settings (core/control/load_grip.py)."""

    grip_margin: float
    mu_start: float
    mu_safety: float
    touch_force_n: float
    slip_speed_mps: float
    slip_window_s: float
    slip_rest_s: float
    min_samples: int
    release_rate_n_per_s: float
    overload_slip_s: float


@dataclass(frozen=True)
class GeometryParams:
    """The base and fingers as the robot description draws them (core/description.py).

    The closing axis is x: the fixed finger's pad face is at +max_travel_m/2, the moving
    finger's at -max_travel_m/2 when fully open.
    """

    finger_thickness_m: float          # along the closing axis, behind the pad face
    finger_width_m: float              # across the closing axis
    finger_length_m: float             # from the top of the base to the fingertip
    base_height_m: float               # from the mounting face to the top of the base
    base_width_m: float                # across the closing axis (its length spans the travel)
    base_mass_kg: float                # the base with motor and lead screw, a solid box
    finger_mass_kg: float              # each finger with its pad, a solid box


@dataclass(frozen=True)
class PidGains:
    kc: float
    ki: float = 0.0
    kd: float = 0.0


@dataclass(frozen=True)
class DmcTuning:
    horizon: int
    control_horizon: int
    move_suppression: float


@dataclass(frozen=True)
class PositionControlParams:
    sample_time_s: float
    pd: PidGains
    pid: PidGains
    mpc_pd: PidGains
    mpc_pd_dmc: DmcTuning
    mpc_pd_braking_voltage_v: float     # ours: braking-governor planning voltage
    speed_limit_pole: float             # ours: discrete pole of the speed under a move's limit


@dataclass(frozen=True)
class ContactForceTuning:
    """The contact-aware force stage (gripper_ros/core/control/contact_force.py), ours."""

    design_stiffness_n_per_m: float      # stiffest object the contact speed is designed for
    design_damping_ratio: float          # ... and its damping ratio (against the reflected mass)
    band_design_stiffness_n_per_m: float  # ... within a width tolerance band
    impact_force_fraction: float         # impact at the contact speed <= this x F_sp (in (0, 1))
    braking_deceleration_mps2: float     # the speed profiles' deceleration
    contact_force_n: float               # contact once the measured force exceeds this
    untouched_overtravel_m: float        # past the narrowest face by this, untouched: V_ff
    force_gain_v_per_n: float            # extra Kp on the force error after contact
    damping_ratio: float                 # of the closed loop on the estimated spring
    servo_sample_gain: float             # most of a speed error the servo corrects per sample
    max_damping_v_s_per_m: float         # speed-servo gain cap
    integral_gain_v_per_n_s: float       # model-error trim, only while at rest in contact
    integral_speed_band_mps: float       # "at rest": |finger speed| below this ...
    integral_rate_fraction: float        # ... and |de/dt| tau_k below this x |e|
    # a moving setpoint's rate, low-passed over this, leads the speed reference (0 = no filter)
    setpoint_rate_time_constant_s: float


@dataclass(frozen=True)
class ForceControlParams:
    paper_sample_time_s: float
    pi_paper: PidGains
    mpc_pi_paper: PidGains
    mpc_pi_paper_dmc: DmcTuning
    sample_time_s: float
    closed_loop_pole: float
    mpc_pi_dmc: DmcTuning
    contact_aware: ContactForceTuning


class ForceLaw(enum.Enum):
    """How the grasp's force setpoint follows from mass, friction and acceleration."""

    FRICTION = 'friction'   # k m (g + a) / (2 mu_s): each of the two pads holds mu_s F
    PAPER = 'paper'         # eq. 23 as printed, mu_s m (g + a)


@dataclass(frozen=True)
class SupervisorParams:
    friction_coefficient: float
    acceleration_mps2: float
    position_tolerance_fraction: float
    sensor_voltage_threshold_v: float
    force_settle_band_fraction: float
    force_settle_hold_s: float
    timeout_s: float
    no_object_margin_m: float
    # Loss watch and release.
    hold_watch_s: float                # force loop keeps holding and watching before HOLDING
    lost_force_fraction: float         # OBJECT_LOST: force below this x F_sp after a grip ...
    lost_force_hold_s: float           # ... for this long
    release_tolerance_m: float         # release done within this of the open position ...
    release_settle_s: float            # ... for this long
    position_switch_speed_mps: float   # switch 1 also needs |speed| <= this (0: paper's)
    width_tolerance_m: float           # default +- on a request's width (Franka's epsilon)
    force_settle_horizon_s: float      # settled: |e| + this x |dF/dt| within the band ...
    force_settle_speed_mps: float      # ... and the finger slower than this (0: no bound)
    force_law: ForceLaw
    grip_safety_factor: float          # k of the friction law (>= 1)
    # The move (srv/Move, control_msgs ParallelGripperCommand).
    move_default_speed_mps: float      # a move's speed when the request gives none
    move_tolerance_m: float            # reached_goal: at rest within this of the width
    move_rest_speed_mps: float         # "at rest": |finger speed| at most this
    move_stall_force_fraction: float   # stalled at once: at rest, pressing with this share
    move_stall_timeout_s: float        # stalled: at rest short of the width this long
    # joint_commands, a position servo
    servo_lead_s: float                # the reference leads a changing stream by rate x this
    servo_rate_window_s: float         # ... its rate over at least this; changing: within it


@dataclass(frozen=True)
class GripperConfig:
    plant: PlantParams
    contact: ContactParams
    force_sensor: ForceSensorParams
    position: PositionControlParams
    force: ForceControlParams
    supervisor: SupervisorParams
    sensor_noise: SensorNoiseParams
    pad_sensor: PadSensorParams
    load_grip: LoadGripParams
    geometry: GeometryParams
    source: str
    data: dict = field(default_factory=dict, compare=False, hash=False, repr=False)
    """The mapping the values were read from (what a bag records, what re-runs start from)."""


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


SHIPPED = None
"""In :data:`ADDED_LATER`: a file without the key means the shipped file's value."""

ADDED_LATER: dict[str, float | None] = {
    # key (dotted) or whole section a file may lack (it predates them) -> what its absence
    # means: the shipped value (SHIPPED), or the number that turns the feature off; any other
    # key is required. The shipped config/gripper.yaml is the one home of every value.
    'contact.static_friction': SHIPPED, 'contact.kinetic_friction': SHIPPED,
    'contact.pad_length_m': SHIPPED, 'contact.after_lift_s': SHIPPED,
    'contact.pad_tangential_stiffness_n_per_m': 0.0,     # rigid pads: the Coulomb law alone
    'contact.lift_off_s': 0.0,                            # the weight lands at once
    'contact.finger_stiffness_n_per_m': 0.0,              # rigid fingers ...
    'contact.pad_normal_stiffness_n_per_m1_5': 0.0,       # ... and no pad: the paper's contact
    'position_control.speed_limit_pole': SHIPPED,
    'force_control.contact_aware.setpoint_rate_time_constant_s': SHIPPED,
    'supervisor.hold_watch_s': SHIPPED, 'supervisor.lost_force_fraction': SHIPPED,
    'supervisor.lost_force_hold_s': SHIPPED, 'supervisor.release_tolerance_m': SHIPPED,
    'supervisor.release_settle_s': SHIPPED,
    'supervisor.position_switch_speed_mps': 0.0,          # the paper's switch: position alone
    'supervisor.width_tolerance_m': 0.0,                  # trust the width
    'supervisor.force_settle_horizon_s': 0.0,             # settled: the band alone
    'supervisor.force_settle_speed_mps': 0.0,             # no speed bound
    'supervisor.force_law': SHIPPED, 'supervisor.grip_safety_factor': SHIPPED,
    'supervisor.move_default_speed_mps': SHIPPED, 'supervisor.move_tolerance_m': SHIPPED,
    'supervisor.move_rest_speed_mps': SHIPPED, 'supervisor.move_stall_force_fraction': SHIPPED,
    'supervisor.move_stall_timeout_s': SHIPPED,
    'supervisor.servo_lead_s': SHIPPED, 'supervisor.servo_rate_window_s': SHIPPED,
    'sensor_noise': 0.0,                                  # ideal sensors
    'pad_sensor': SHIPPED,
    'load_grip': SHIPPED,
    'geometry': SHIPPED,
}


@functools.cache
def _shipped_data() -> dict:
    return yaml.safe_load(shipped_config_path().read_text(encoding='utf-8'))


def _absent_value(where: str, key: str):
    """Return what a file without ``where.key`` means, or MISSING if it must have it."""
    dotted = f'{where}.{key}'
    meaning = ADDED_LATER.get(dotted, ADDED_LATER.get(where.split('.')[0], MISSING))
    if meaning is not SHIPPED:
        return meaning
    data = _shipped_data()
    for part in dotted.split('.'):
        data = data[part]
    return data


def _with_absent(section: dict, where: str, keys) -> dict:
    """Return ``section`` with each of ``keys`` it lacks filled in as :data:`ADDED_LATER` says."""
    filled = dict(section)
    for key in keys:
        if key not in filled:
            value = _absent_value(where, key)
            if value is not MISSING:
                filled[key] = value
    return filled


def shipped_config() -> GripperConfig:
    """Return the shipped config/gripper.yaml, read once (what a component without one uses)."""
    return _shipped_config()


@functools.cache
def _shipped_config() -> GripperConfig:
    return load_config(shipped_config_path())


MAX_HORIZON = 2000
"""Most samples of a DMC step-response model: its matrices, their build when a parameter
changes and its work every tick grow with it (the shipped horizons are 700 and 100)."""

BOUNDS: dict[str, tuple[float, float]] = {
    # key (dotted, or the leaf name of every key so named): [low, high], both allowed; the
    # key's own rule (> 0, >= 0, a whole number) and the cross-field checks apply as well (the
    # keys with a range of their own, such as closed_loop_pole in [0, 1), are checked there)
    'plant.inertia_kg_m2': (1e-7, 1.0),
    'plant.damping_n_m_s_per_rad': (1e-7, 10.0),
    'plant.gear_ratio': (0.01, 1000.0),
    'plant.resistance_ohm': (1e-3, 1000.0),
    'plant.inductance_h': (1e-7, 1.0),
    'plant.pitch_m': (1e-4, 0.1),
    'plant.torque_constant_n_m_per_a': (1e-4, 10.0),
    'plant.back_emf_v_s_per_rad': (1e-4, 10.0),
    'plant.efficiency': (0.0, 1.0),
    'plant.max_travel_m': (1e-3, 1.0),
    'plant.gravity_mps2': (0.1, 100.0),
    'plant.voltage_limit_v': (0.1, 1000.0),
    'plant.contact_substep_s': (1e-7, 1e-3),
    'contact.stiffness_n_per_m': (0.0, 1e10),
    'contact.damping_n_s_per_m': (0.0, 1e7),
    'contact.static_friction': (0.0, 2.0),
    'contact.kinetic_friction': (0.0, 2.0),
    'contact.pad_length_m': (1e-4, 1.0),
    'contact.after_lift_s': (0.0, 60.0),
    'contact.pad_tangential_stiffness_n_per_m': (0.0, 1e10),
    'contact.lift_off_s': (0.0, 10.0),
    'contact.finger_stiffness_n_per_m': (0.0, 1e10),
    'contact.pad_normal_stiffness_n_per_m1_5': (0.0, 1e12),
    'force_sensor.supply_v': (0.1, 100.0),
    'force_sensor.measuring_resistor_ohm': (1.0, 1e12),
    'force_sensor.fsr_resistance_at_1n_ohm': (1.0, 1e12),
    'force_sensor.open_resistance_ohm': (1.0, 1e12),
    'force_sensor.activation_force_n': (1e-6, 100.0),
    'position_control.sample_time_s': (1e-3, 0.1),
    'position_control.mpc_pd_braking_voltage_v': (0.0, 1000.0),
    'force_control.paper_sample_time_s': (5e-5, 0.01),
    'force_control.sample_time_s': (5e-5, 0.01),
    'kc': (0.0, 1e6),
    'ki': (0.0, 1e6),
    'kd': (0.0, 1e6),
    'horizon': (1, MAX_HORIZON),
    'control_horizon': (1, MAX_HORIZON),
    'move_suppression': (1e-6, 1e6),
    'force_control.contact_aware.design_stiffness_n_per_m': (1.0, 1e10),
    'force_control.contact_aware.design_damping_ratio': (1e-3, 10.0),
    'force_control.contact_aware.band_design_stiffness_n_per_m': (1.0, 1e10),
    'force_control.contact_aware.braking_deceleration_mps2': (1e-4, 10.0),
    'force_control.contact_aware.contact_force_n': (1e-9, 10.0),
    'force_control.contact_aware.untouched_overtravel_m': (1e-9, 0.01),
    'force_control.contact_aware.force_gain_v_per_n': (0.0, 1000.0),
    'force_control.contact_aware.damping_ratio': (1e-3, 10.0),
    'force_control.contact_aware.servo_sample_gain': (1e-3, 1.0),
    'force_control.contact_aware.setpoint_rate_time_constant_s': (0.0, 1.0),
    'force_control.contact_aware.max_damping_v_s_per_m': (1.0, 1e9),
    'force_control.contact_aware.integral_gain_v_per_n_s': (0.0, 1000.0),
    'force_control.contact_aware.integral_speed_band_mps': (1e-7, 1.0),
    'force_control.contact_aware.integral_rate_fraction': (1e-3, 1.0),
    'supervisor.friction_coefficient': (0.01, 2.0),
    'supervisor.acceleration_mps2': (0.0, 100.0),
    'supervisor.position_tolerance_fraction': (1e-6, 0.5),
    'supervisor.sensor_voltage_threshold_v': (1e-6, 100.0),
    'supervisor.force_settle_band_fraction': (1e-6, 0.5),
    'supervisor.force_settle_hold_s': (1e-6, 10.0),
    'supervisor.timeout_s': (0.01, 3600.0),
    'supervisor.no_object_margin_m': (1e-6, 0.1),
    'supervisor.hold_watch_s': (0.0, 10.0),
    'supervisor.lost_force_hold_s': (1e-6, 10.0),
    'supervisor.release_tolerance_m': (1e-6, 0.1),
    'supervisor.release_settle_s': (0.0, 10.0),
    'supervisor.position_switch_speed_mps': (0.0, 1.0),
    'supervisor.width_tolerance_m': (0.0, 0.1),
    'supervisor.force_settle_horizon_s': (0.0, 100.0),
    'supervisor.force_settle_speed_mps': (0.0, 1.0),
    'supervisor.grip_safety_factor': (0.0, 10.0),
    'supervisor.move_default_speed_mps': (1e-6, 10.0),
    'supervisor.move_tolerance_m': (1e-6, 0.1),
    'supervisor.move_rest_speed_mps': (1e-6, 1.0),
    'supervisor.move_stall_timeout_s': (1e-3, 60.0),
    'supervisor.servo_lead_s': (0.0, 10.0),
    'supervisor.servo_rate_window_s': (1e-3, 1.0),
    'sensor_noise.position_noise_m': (0.0, 0.01),
    'sensor_noise.position_quantum_m': (0.0, 0.01),
    'sensor_noise.force_noise_n': (0.0, 100.0),
    'sensor_noise.force_quantum_n': (0.0, 100.0),
    'sensor_noise.seed': (0, 2 ** 63 - 1),
    'pad_sensor.shear_resolution_n': (0.0, 10.0),
    'pad_sensor.shear_noise_n': (0.0, 10.0),
    'pad_sensor.shear_bandwidth_hz': (0.0, 1e6),
    'pad_sensor.shear_latency_s': (0.0, 1.0),
    'pad_sensor.displacement_resolution_m': (0.0, 0.01),
    'pad_sensor.displacement_noise_m': (0.0, 0.01),
    'pad_sensor.displacement_bandwidth_hz': (0.0, 1e6),
    'pad_sensor.displacement_latency_s': (0.0, 1.0),
    'load_grip.grip_margin': (1.0, 10.0),
    'load_grip.mu_start': (0.01, 2.0),
    'load_grip.mu_safety': (1e-3, 1.0),
    'load_grip.touch_force_n': (1e-3, 100.0),
    'load_grip.slip_speed_mps': (1e-6, 1.0),
    'load_grip.slip_window_s': (1e-4, 1.0),
    'load_grip.slip_rest_s': (0.0, 1.0),
    'load_grip.min_samples': (1, 100000),
    'load_grip.release_rate_n_per_s': (1e-3, 1e6),
    'load_grip.overload_slip_s': (1e-4, 10.0),
    'geometry.finger_thickness_m': (1e-4, 1.0),
    'geometry.finger_width_m': (1e-4, 1.0),
    'geometry.finger_length_m': (1e-4, 1.0),
    'geometry.base_height_m': (1e-4, 1.0),
    'geometry.base_width_m': (1e-4, 1.0),
    'geometry.base_mass_kg': (1e-4, 100.0),
    'geometry.finger_mass_kg': (1e-4, 100.0),
}
"""Physically sensible bounds of every number in the config (``config/gripper.yaml`` lists
them at its end; ``test_config`` ties that list to this table)."""


def bounds_of(name: str) -> tuple[float, float] | None:
    """Return the [low, high] of dotted key ``name`` (by its full name, else its leaf)."""
    return BOUNDS.get(name) or BOUNDS.get(name.rsplit('.', 1)[-1])


def bounds_text() -> str:
    """Return the bounds as the comment block at the end of ``config/gripper.yaml``."""
    lines = ['# Bounds (gripper_ros/core/config.py BOUNDS): every value must lie in [low, high];',
             "# a key's own rule (> 0, a whole number) and the cross-field checks apply too."]
    lines += [f'#   {key}: [{low:g}, {high:g}]' for key, (low, high) in BOUNDS.items()]
    return '\n'.join(lines) + '\n'


def known_keys() -> dict:
    """Every key a config file may hold, as nested sections (a leaf is None)."""
    def leaves(cls, extra=frozenset()):
        return dict.fromkeys([f.name for f in fields(cls)] + sorted(extra))
    gains, dmc = leaves(PidGains), leaves(DmcTuning)
    return {
        'plant': leaves(PlantParams), 'contact': leaves(ContactParams),
        'force_sensor': leaves(ForceSensorParams),
        'position_control': {'sample_time_s': None, 'pd': gains, 'pid': gains,
                             'mpc_pd': {**gains, **dmc}, 'mpc_pd_braking_voltage_v': None,
                             'speed_limit_pole': None},
        'force_control': {'paper_sample_time_s': None, 'pi_paper': gains,
                          'mpc_pi_paper': {**gains, **dmc}, 'sample_time_s': None,
                          'closed_loop_pole': None, 'mpc_pi': dmc,
                          'contact_aware': leaves(ContactForceTuning)},
        'supervisor': leaves(SupervisorParams),
        'sensor_noise': leaves(SensorNoiseParams), 'pad_sensor': leaves(PadSensorParams),
        'load_grip': leaves(LoadGripParams), 'geometry': leaves(GeometryParams),
    }


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


def _refuse_unknown(data: dict, known: dict, where: str = '') -> None:
    """Refuse a key the package does not read (a typo), naming it and the closest known one."""
    import difflib
    for key, value in data.items():
        name = f'{where}{key}'
        if key not in known:
            close = difflib.get_close_matches(str(key), [str(k) for k in known], n=1)
            hint = f'; did you mean "{where}{close[0]}"?' if close else \
                f'; known here: {", ".join(known)}'
            raise ConfigError(f'unknown key "{name}"{hint}')
        if isinstance(known[key], dict) and isinstance(value, dict):
            _refuse_unknown(value, known[key], name + '.')


def _section(data: dict, key: str, where: str) -> dict:
    value = data.get(key)
    if not isinstance(value, dict):
        raise ConfigError(f'{where}: missing section "{key}"')
    return value


def _number(section: dict, key: str, where: str, *, positive: bool = False,
            nonnegative: bool = False, integer: bool = False) -> float:
    name = f'{where}.{key}'
    if key not in section:
        raise ConfigError(f'missing key "{name}"')
    value = section[key]
    if isinstance(value, str) and _reads_as_number(value):
        raise ConfigError(f'"{name}" must be a number, got the text {value!r}: YAML reads a '
                          'float only with a dot and a signed exponent (write 1.0e-3, not '
                          '1e-3)')
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f'"{name}" must be a number, got {value!r}')
    value = float(value)
    if not math.isfinite(value):
        raise ConfigError(f'"{name}" must be finite, got {value!r}')
    if positive and value <= 0.0:
        raise ConfigError(f'"{name}" must be > 0, got {value!r}')
    if nonnegative and value < 0.0:
        raise ConfigError(f'"{name}" must be >= 0, got {value!r}')
    bounds = bounds_of(name)
    if bounds is not None and not bounds[0] <= value <= bounds[1]:
        raise ConfigError(f'"{name}" must be in [{bounds[0]:g}, {bounds[1]:g}], '
                          f'got {value!r}')
    if integer:
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


def _choice(section: dict, key: str, where: str, choices: type[enum.Enum]) -> enum.Enum:
    name = f'{where}.{key}'
    if key not in section:
        raise ConfigError(f'missing key "{name}"')
    value = section[key]
    known = ', '.join(repr(c.value) for c in choices)
    if not isinstance(value, str):
        raise ConfigError(f'"{name}" must be one of {known}, got {value!r}')
    try:
        return choices(value)
    except ValueError:
        raise ConfigError(f'"{name}" must be one of {known}, got {value!r}') from None


def _build(cls, section: dict, where: str, **rules):
    kwargs = {}
    section = _with_absent(section, where, [f.name for f in fields(cls)])
    for f in fields(cls):
        opts = rules.get(f.name, {'positive': True})
        if f.name not in section and f.default is not MISSING:   # a gain a law does not have
            kwargs[f.name] = f.default
            continue
        if 'choices' in opts:
            kwargs[f.name] = _choice(section, f.name, where, opts['choices'])
        else:
            kwargs[f.name] = _number(section, f.name, where, **opts)
    return cls(**kwargs)


def _gains(section: dict, key: str, where: str) -> PidGains:
    return _build(PidGains, _section(section, key, where), f'{where}.{key}',
                  kc={'nonnegative': True}, ki={'nonnegative': True}, kd={'nonnegative': True})


def _dmc(section: dict, where: str) -> DmcTuning:
    return _build(DmcTuning, section, where,
                  horizon={'positive': True, 'integer': True},
                  control_horizon={'positive': True, 'integer': True},
                  move_suppression={'positive': True})


_CONTACT_RULES = {name: {'nonnegative': True} for name in (
    'stiffness_n_per_m', 'damping_n_s_per_m', 'after_lift_s', 'pad_tangential_stiffness_n_per_m',
    'lift_off_s', 'finger_stiffness_n_per_m', 'pad_normal_stiffness_n_per_m1_5')}


def object_contact(stiffness_n_per_m: float, damping_n_s_per_m: float) -> ContactParams:
    """Return the contact a file giving only the object's stiffness and damping means."""
    return _build(ContactParams, {'stiffness_n_per_m': stiffness_n_per_m,
                                  'damping_n_s_per_m': damping_n_s_per_m}, 'contact',
                  **_CONTACT_RULES)


def parse_config(data: dict, source: str = '<dict>') -> GripperConfig:
    """Validate a loaded YAML mapping into a :class:`GripperConfig`."""
    if not isinstance(data, dict):
        raise ConfigError(f'{source}: top level must be a mapping')
    _refuse_unknown(data, known_keys())
    plant = _build(PlantParams, _section(data, 'plant', source), 'plant')
    contact = _build(ContactParams, _section(data, 'contact', source), 'contact',
                     **_CONTACT_RULES)
    if contact.kinetic_friction > contact.static_friction:
        raise ConfigError('"contact.kinetic_friction" must be <= "contact.static_friction" '
                          f'({contact.static_friction!r}), got {contact.kinetic_friction!r}')
    sensor = _build(ForceSensorParams, _section(data, 'force_sensor', source), 'force_sensor')
    pos = _with_absent(_section(data, 'position_control', source), 'position_control',
                       ('speed_limit_pole',))
    mpc_pd = _section(pos, 'mpc_pd', 'position_control')
    position = PositionControlParams(
        sample_time_s=_number(pos, 'sample_time_s', 'position_control', positive=True),
        pd=_gains(pos, 'pd', 'position_control'),
        pid=_gains(pos, 'pid', 'position_control'),
        mpc_pd=_gains(pos, 'mpc_pd', 'position_control'),
        mpc_pd_dmc=_dmc(mpc_pd, 'position_control.mpc_pd'),
        mpc_pd_braking_voltage_v=_number(pos, 'mpc_pd_braking_voltage_v', 'position_control',
                                         nonnegative=True),
        speed_limit_pole=_number(pos, 'speed_limit_pole', 'position_control', nonnegative=True))
    frc = _section(data, 'force_control', source)
    force = ForceControlParams(
        paper_sample_time_s=_number(frc, 'paper_sample_time_s', 'force_control', positive=True),
        pi_paper=_gains(frc, 'pi_paper', 'force_control'),
        mpc_pi_paper=_gains(frc, 'mpc_pi_paper', 'force_control'),
        mpc_pi_paper_dmc=_dmc(_section(frc, 'mpc_pi_paper', 'force_control'),
                              'force_control.mpc_pi_paper'),
        sample_time_s=_number(frc, 'sample_time_s', 'force_control', positive=True),
        closed_loop_pole=_number(frc, 'closed_loop_pole', 'force_control', nonnegative=True),
        mpc_pi_dmc=_dmc(_section(frc, 'mpc_pi', 'force_control'), 'force_control.mpc_pi'),
        contact_aware=_build(ContactForceTuning, _section(frc, 'contact_aware', 'force_control'),
                             'force_control.contact_aware',
                             force_gain_v_per_n={'nonnegative': True},
                             integral_gain_v_per_n_s={'nonnegative': True},
                             setpoint_rate_time_constant_s={'nonnegative': True}))
    if not force.contact_aware.impact_force_fraction < 1.0:
        raise ConfigError('"force_control.contact_aware.impact_force_fraction" must be in (0, 1), '
                          f'got {force.contact_aware.impact_force_fraction!r}')
    if not force.closed_loop_pole < 1.0:
        raise ConfigError('"force_control.closed_loop_pole" must be in [0, 1) for a stable loop, '
                          f'got {force.closed_loop_pole!r}')
    speed_pole = math.exp(-position.sample_time_s / plant.mechanical_time_constant_s)
    if not position.speed_limit_pole < speed_pole:
        raise ConfigError('"position_control.speed_limit_pole" must be in [0, '
                          f'{speed_pole:.6g}) (the open-loop pole of the finger speed over one '
                          f'sample; slower than that never reaches the limit), '
                          f'got {position.speed_limit_pole!r}')
    for where, dmc in (('position_control.mpc_pd', position.mpc_pd_dmc),
                       ('force_control.mpc_pi_paper', force.mpc_pi_paper_dmc),
                       ('force_control.mpc_pi', force.mpc_pi_dmc)):
        if dmc.control_horizon > dmc.horizon:
            raise ConfigError(f'"{where}.control_horizon" must be <= "{where}.horizon" '
                              f'({dmc.horizon}), got {dmc.control_horizon}')
    if position.mpc_pd_braking_voltage_v > plant.voltage_limit_v:
        raise ConfigError('"position_control.mpc_pd_braking_voltage_v" must be <= '
                          f'"plant.voltage_limit_v", got {position.mpc_pd_braking_voltage_v!r}')
    sup = _build(SupervisorParams, _section(data, 'supervisor', source), 'supervisor',
                 acceleration_mps2={'nonnegative': True}, hold_watch_s={'nonnegative': True},
                 release_settle_s={'nonnegative': True},
                 position_switch_speed_mps={'nonnegative': True},
                 width_tolerance_m={'nonnegative': True},
                 force_settle_horizon_s={'nonnegative': True},
                 force_settle_speed_mps={'nonnegative': True},
                 force_law={'choices': ForceLaw})
    if not sup.grip_safety_factor >= 1.0:
        raise ConfigError('"supervisor.grip_safety_factor" must be >= 1 (a grip that knowingly '
                          f'holds less than the load), got {sup.grip_safety_factor!r}')
    if not sup.lost_force_fraction < 1.0:
        raise ConfigError('"supervisor.lost_force_fraction" must be in (0, 1), '
                          f'got {sup.lost_force_fraction!r}')
    if not sup.move_stall_force_fraction <= 1.0:
        raise ConfigError('"supervisor.move_stall_force_fraction" must be in (0, 1] (a force '
                          'above the effort limit is never reached), '
                          f'got {sup.move_stall_force_fraction!r}')
    sup = replace(sup, move_default_speed_mps=move_default_speed_mps(sup, plant))
    if not sup.move_rest_speed_mps < sup.move_default_speed_mps:
        raise ConfigError('"supervisor.move_default_speed_mps" must be above '
                          f'"supervisor.move_rest_speed_mps" = {sup.move_rest_speed_mps!r} '
                          f'(and so must the free speed at "plant.voltage_limit_v", '
                          f'{plant.max_free_speed_mps:.6g} m/s), got '
                          f'{sup.move_default_speed_mps!r}')
    noise_rules = {f.name: {'nonnegative': True} for f in fields(SensorNoiseParams)}
    noise_rules['seed'] = {'nonnegative': True, 'integer': True}
    noise = _build(SensorNoiseParams, _section(data, 'sensor_noise', source)
                   if 'sensor_noise' in data else {}, 'sensor_noise', **noise_rules)
    if noise.seed >= 2 ** 63:
        raise ConfigError(f'"sensor_noise.seed" must be < 2**63, got {noise.seed!r}')
    pads = _build(PadSensorParams, _section(data, 'pad_sensor', source)
                  if 'pad_sensor' in data else {}, 'pad_sensor',
                  **{f.name: {'nonnegative': True} for f in fields(PadSensorParams)})
    grip = _build(LoadGripParams, _section(data, 'load_grip', source)
                  if 'load_grip' in data else {}, 'load_grip',
                  min_samples={'positive': True, 'integer': True})
    if not 1.0 <= grip.grip_margin:
        raise ConfigError('"load_grip.grip_margin" must be >= 1 (a grip that knowingly holds '
                          f'less than the load), got {grip.grip_margin!r}')
    if not grip.mu_safety <= 1.0:
        raise ConfigError(f'"load_grip.mu_safety" must be in (0, 1], got {grip.mu_safety!r}')
    geometry = _build(GeometryParams, _section(data, 'geometry', source)
                      if 'geometry' in data else {}, 'geometry')
    return GripperConfig(plant, contact, sensor, position, force, sup, noise, pads, grip,
                         geometry, source, copy.deepcopy(data))


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


def load_config(path: str | os.PathLike | None = None) -> GripperConfig:
    """Load and validate the YAML file (default: the package's ``config/gripper.yaml``)."""
    file_path = Path(path) if path is not None else default_config_path()
    try:
        text = file_path.read_text(encoding='utf-8')
    except OSError as exc:
        raise ConfigError(f'cannot read config file {file_path}: {exc.strerror}') from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f'config file {file_path} is not UTF-8 text (byte {exc.start}): '
                          'is it a YAML file?') from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f'config file {file_path} is not valid YAML: {exc}') from None
    except RecursionError:
        raise ConfigError(f'config file {file_path} is nested too deeply to be a gripper '
                          'config') from None
    return parse_config(data, str(file_path))
