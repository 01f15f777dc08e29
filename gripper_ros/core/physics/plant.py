"""Two-finger parallel gripper plant: brushed DC motor driving a lead screw (paper eqs. 1-13).

State ``[i_a (A), omega (rad/s), x (m)]`` where ``x`` is the moving finger's travel from fully
open (eq. 10: ``x = p/(2 pi) theta``). :class:`GripperPlant` is the Python face; the model is
compiled (numba) and lives in one module a concept:

* :mod:`~gripper_ros.core.physics.motor_zoh`: the motor and screw discretised exactly (zero-order
  hold, matrix exponential) at whatever hold time a controller asks for, and its two caches;
* :mod:`~gripper_ros.core.physics.contact`: rigid, compliant (Kelvin-Voigt) and chained
  (flexible fingers, Hertz pads) contact with the object, the open end stop, a slipping object;
* :mod:`~gripper_ros.core.physics.integration`: one step of a held voltage through them
  (:func:`plant_step`);
* :mod:`~gripper_ros.core.physics.events`: injected faults and the lift of a held object
  (:mod:`gripper_ros.core.physics.hold`'s friction model), each at an exact simulated instant;
* :mod:`~gripper_ros.core.physics.plant_pads`: the four pad channels sampled while the object
  is held;
* :mod:`~gripper_ros.core.physics.readout`: what the sensors and motor report, the wire's tick,
  the held object's state;
* :mod:`~gripper_ros.core.physics.plant_records`: the plant's one record, which every kernel
  takes.

Here: the kernels that place the finger and the object, the warm-up, and the facade. The names
other modules use (``__all__``) are importable from here.
"""
from __future__ import annotations

from dataclasses import fields, replace
import functools
import math

from gripper_ros.core.config import (ChannelSpec, ContactParams, object_contact, PadSensorParams,
                                     PlantParams)
from gripper_ros.core.physics.contact import (chain_untouched, CONTACT_COMPLIANT, CONTACT_FREE,
                                              CONTACT_OPEN_STOP, CONTACT_RIGID, CONTACT_STATES,
                                              ContactState, GraspObject, refresh_contact_state,
                                              use_object)
from gripper_ros.core.physics.events import (check_fault, clear_fault_state,
                                             DEFAULT_SLIP_TIME_CONSTANT_S, plant_begin_hold,
                                             plant_cancel_fault, plant_drive_load,
                                             plant_fault_scheduled, plant_scenario_in_progress,
                                             plant_schedule_fault, ScheduledFault)
from gripper_ros.core.physics.force_sensor import FsrVoltageDivider
from gripper_ros.core.physics.hold import (ANNOUNCE_ROWS, check_finite_nonnegative,
                                           hold_plan, HoldModel, HoldState, Lift, ObjectState)
from gripper_ros.core.physics.integration import plant_step
from gripper_ros.core.physics.motor_zoh import force_model, free_model
from gripper_ros.core.physics.pad_sensor import CHANNEL_DTYPE, make_channel
from gripper_ros.core.physics.plant_pads import PAD_CHANNELS, PAD_DTYPE
from gripper_ros.core.physics.plant_records import (fill_params, PARAMS_DTYPE, PLANT_DTYPE,
                                                    STATE_DTYPE)
from gripper_ros.core.physics.readout import (_object_state, OBJECT_STATE_DTYPE,
                                              plant_hold_record, plant_read_tick, plant_sample,
                                              PlantSample)
from gripper_ros.core.records import (as_record, compile_face_kernels, copy_fields, face_kernel,
                                      RecordField)
from gripper_ros.wire import FaultKind
import numba
import numpy as np

__all__ = ['check_fault', 'ContactState', 'DEFAULT_SLIP_TIME_CONSTANT_S', 'FaultKind',
           'GraspObject', 'GripperPlant', 'HoldState', 'Lift', 'OBJECT_STATE_DTYPE',
           'ObjectState', 'PARAMS_DTYPE', 'PLANT_DTYPE', 'plant_begin_hold', 'plant_cancel_fault',
           'plant_drive_load', 'plant_fault_scheduled', 'plant_hold_record', 'plant_place',
           'plant_read_tick', 'plant_sample', 'plant_scenario_in_progress',
           'plant_schedule_fault', 'plant_step', 'PlantSample', 'ScheduledFault', 'STATE_DTYPE']

_new_tuple = tuple.__new__


# ----------------------------------------------------------------------------- placing
@numba.njit(cache=True, inline='always')
def _motor_off(s):
    """Zero the motor's current, speed and voltage, and the step's peak force."""
    s.i = 0.0
    s.w = 0.0
    s.voltage = 0.0
    s.peak = 0.0


@face_kernel(PLANT_DTYPE, bool)
@numba.njit(cache=True)
def _reset(k, open_fingers):
    """Motor at rest; optionally the finger back at the fully-open stop."""
    pl = as_record(k)
    s = pl.state
    p = pl.params
    _motor_off(s)
    if open_fingers:
        s.x = 0.0
    s.contact = CONTACT_OPEN_STOP if s.x <= 0.0 else CONTACT_FREE
    s.impact_energy_lost_j = 0.0
    refresh_contact_state(s, p)


@face_kernel(PLANT_DTYPE)
@numba.njit(cache=True)
def _touch_object(k):
    """Put the finger at rest just touching the object, motor off."""
    pl = as_record(k)
    s = pl.state
    _motor_off(s)
    s.x = s.x_c
    s.contact = CONTACT_RIGID if s.stiffness_n_per_m == 0.0 and not \
        pl.params.chain else CONTACT_COMPLIANT
    chain_untouched(s)


@face_kernel(PLANT_DTYPE, float, float, float, float, float, float, float)
@numba.njit(cache=True)
def _set_object(k, width_m, stiffness, damping, mass_kg, static_friction, kinetic_friction,
                pad_length_m):
    """Place a validated object (the hold record is already the object's)."""
    pl = as_record(k)
    s = pl.state
    p = pl.params
    use_object(s, p, width_m, stiffness, damping, mass_kg, static_friction, kinetic_friction,
               pad_length_m)
    pl.hold.live = 0
    clear_fault_state(s, pl.sensor)
    refresh_contact_state(s, p)


@face_kernel(PLANT_DTYPE, float, float)
@numba.njit(cache=True)
def _use_default_object(k, stiffness, damping):
    """Place a new plant's object: width 0 (nothing), the contact defaults' stiffness."""
    pl = as_record(k)
    use_object(pl.state, pl.params, 0.0, stiffness, damping, 0.0, 0.0, 0.0, 0.0)


@face_kernel(PLANT_DTYPE, float, float, float)
@numba.njit(cache=True)
def plant_place(k, x, w, i):
    """Put the finger at travel ``x`` with motor speed ``w`` and current ``i`` (a run's start)."""
    pl = as_record(k)
    s = pl.state
    s.x = x
    s.w = w
    s.i = i
    refresh_contact_state(s, pl.params)


@face_kernel(PLANT_DTYPE, float, int)
@numba.njit(cache=True)
def _step_and_sample(k, voltage_v, duration_ns):
    plant_step(k, voltage_v, duration_ns)
    return plant_sample(k)


@functools.cache
def _load_physics() -> None:
    """Load (or compile) every physics kernel, once per process, at the first plant.

    A kernel's first call loads its machine code from numba's cache (tens of ms; seconds when
    it must compile): done here, a node's first lift or fault does not stall its loop.
    """
    compile_face_kernels(__package__)


# ----------------------------------------------------------------------------- the facade
class GripperPlant:
    """Exact-discretised motor + lead screw + contact. Call :meth:`step` with a held voltage.

    The state lives in one numpy record (:attr:`kernel`, a 1-element :data:`PLANT_DTYPE`
    array); every step and reading runs the compiled kernels of the modules named above. This
    class validates and formats.
    """

    def __init__(self, params: PlantParams, sensor: FsrVoltageDivider,
                 contact: ContactParams | None = None, pads: PadSensorParams | None = None,
                 pad_dt_s: float = 0.0, pad_seed: int = 0):
        """Build the plant; ``pads`` sensed every ``pad_dt_s`` (None: exact pad readings).

        ``pad_seed`` seeds the pads' noise, again at each :meth:`set_object`.
        """
        self.params = params
        self.sensor = sensor
        self.pads = pads
        ideal = ChannelSpec(0.0, 0.0, 0.0, 0.0)
        self._pad_specs = (ideal,) * PAD_CHANNELS if pads is None else (
            pads.shear, pads.shear, pads.displacement, pads.displacement)
        self._pad_dt_s = float(pad_dt_s) if pads is not None else 1.0
        self._pad_seed = int(pad_seed)
        self._fresh_pads = None                 # the pad channels as set_object starts them
        self.contact_defaults = contact or object_contact(0.0, 0.0)
        default = self.contact_defaults
        self._object_record = np.zeros(1, OBJECT_STATE_DTYPE)   # _object_state writes it
        self._lift: Lift | None = None
        self.kernel = np.zeros(1, PLANT_DTYPE)
        """The plant's record (state, constants, hold, sensor, fired faults, discretisations,
        pad channels), as a 1-element array."""
        record = self.kernel[0]
        record['hold']['state'] = HoldState.NONE
        fill_params(record['params'], params, self.contact_defaults)
        record['sensor'] = sensor.record[0]
        sensor.record = self.kernel['sensor']          # the sensor's face views the plant's
        if pads is not None:
            record['params']['pad_dt_ns'] = round(self._pad_dt_s * 1e9)
        self._seed_pads()
        _use_default_object(self.kernel, float(default.stiffness_n_per_m),
                            float(default.damping_n_s_per_m))
        self.reset()
        _load_physics()

    # ----------------------------------------------------------------- records for callers
    @property
    def _s(self) -> np.void:
        """The state record (looked up each time: a deep copy of the plant has its own)."""
        return self.kernel[0]['state']

    @property
    def _h(self) -> np.void:
        """The hold record."""
        return self.kernel[0]['hold']

    def snapshot(self) -> tuple:
        """Return a copy of the whole state (for :meth:`restore` after a refused change)."""
        return self.kernel.copy(), self._lift

    def restore(self, saved: tuple) -> None:
        """Put back a :meth:`snapshot` (the record stays the same array)."""
        record, self._lift = saved
        self.kernel[...] = record

    # ----------------------------------------------------------------- set-up
    def reset(self, open_fingers: bool = True) -> None:
        """Motor at rest; optionally the finger back at the fully-open stop. Time keeps running."""
        _reset(self.kernel, bool(open_fingers))

    def touch_object(self) -> None:
        """Put the finger at rest just touching the object, motor off (force-loop studies)."""
        _touch_object(self.kernel)

    def set_object(self, obj: GraspObject, lift: Lift | None = None) -> None:
        """Place an object (its fixed-finger face is the fixed finger; the other face at x_c).

        ``lift``: how the arm will lift it once the grasp holds (None = it stays on its support).
        Bad values raise ValueError naming the field, and change nothing.
        """
        if not (math.isfinite(obj.width_m) and 0.0 <= obj.width_m < self.params.max_travel_m):
            raise ValueError(f'object width must be in [0, {self.params.max_travel_m}) m, '
                             f'got {obj.width_m!r}')
        for name in ('stiffness_n_per_m', 'damping_n_s_per_m', 'mass_kg', 'static_friction',
                     'kinetic_friction', 'pad_length_m'):
            check_finite_nonnegative('object', name, getattr(obj, name))
        if lift is not None and not isinstance(lift, Lift):
            raise ValueError(f'lift must be a Lift or None, got {lift!r}')
        hold = self._hold_model_for(obj, lift)
        if self._s['x'] > self.params.max_travel_m - obj.width_m:
            raise ValueError('the finger is already past the new object surface; open first')
        if hold is None:
            self._h['has_hold'] = 0
            self._h['state'] = HoldState.NONE
        else:
            self.kernel[0]['hold'] = hold.record[0]
            self._h['has_hold'] = 1
        self._lift = lift
        self._seed_pads()
        _set_object(self.kernel, float(obj.width_m), float(obj.stiffness_n_per_m),
                    float(obj.damping_n_s_per_m), float(obj.mass_kg),
                    float(obj.static_friction), float(obj.kinetic_friction),
                    float(obj.pad_length_m))

    def _seed_pads(self) -> None:
        """Fresh pad channels (each its own noise stream from the seed), resting at 0."""
        if self._fresh_pads is None:
            self._fresh_pads = np.zeros(PAD_CHANNELS, PAD_DTYPE)
            for i, spec in enumerate(self._pad_specs):
                record, _ = make_channel(spec, self._pad_dt_s,
                                         (self._pad_seed * PAD_CHANNELS + i) % 2 ** 64)
                copy_fields(self._fresh_pads[i], record[0], CHANNEL_DTYPE.names)
        self.kernel[0]['pads'] = self._fresh_pads
        self._s['pads_resting'] = 0

    def configured_friction(self, obj: GraspObject) -> GraspObject:
        """Return ``obj`` with the configured pad friction instead of its own.

        ``contact.static_friction`` and ``contact.kinetic_friction``: what a request that asks
        for the defaults (``SetObject.default_friction``) places.
        """
        d = self.contact_defaults
        return replace(obj, static_friction=d.static_friction,
                       kinetic_friction=d.kinetic_friction)

    def _hold_model_for(self, obj: GraspObject, lift: Lift | None) -> HoldModel | None:
        """Build the hold of ``obj``, its friction as given (ValueError)."""
        if obj.width_m == 0.0:
            return None
        d = self.contact_defaults
        mu_s, mu_k = obj.static_friction, obj.kinetic_friction
        if mu_k > mu_s:
            raise ValueError(f'object kinetic_friction {mu_k!r} must be <= its static_friction '
                             f'{mu_s!r}')
        pad_m = obj.pad_length_m or d.pad_length_m
        if not pad_m > 0.0:
            raise ValueError(f'object pad_length_m must be > 0 (0 = the contact default '
                             f'{d.pad_length_m!r}), got {pad_m!r}')
        lift_off_s = lift.lift_off_or(d.lift_off_s) if lift is not None else d.lift_off_s
        return HoldModel(obj.mass_kg, mu_s, mu_k, pad_m, self.params.gravity_mps2, lift,
                         d.pad_tangential_stiffness_n_per_m, lift_off_s)

    @property
    def object(self) -> GraspObject:  # noqa: A003 - the public attribute name
        """What lies between the fingers now (a slipping object's width shrinks)."""
        s = self._s
        return GraspObject(**{f.name: float(s[f.name]) for f in fields(GraspObject)})

    # ----------------------------------------------------------------- holding a lifted object
    def begin_hold(self, t_ns: int, grasp_mass_kg: float = 0.0) -> None:
        """Start the lift's clock: the grasp was declared HOLDING at simulated time ``t_ns``.

        ``grasp_mass_kg`` is the object's mass if the object did not give one. A lift instant
        already past when this is called takes effect at the plant's present time. Nothing
        between the fingers: no effect. ValueError (nothing changes) for a bad value or when
        the object has already left its support.
        """
        if isinstance(t_ns, bool) or not isinstance(t_ns, int) or t_ns < 0:
            raise ValueError(f'hold t_ns must be an integer >= 0, got {t_ns!r}')
        mass = check_finite_nonnegative('hold', 'grasp_mass_kg', grasp_mass_kg)
        if plant_begin_hold(self.kernel, t_ns, mass):
            raise ValueError(f'the object is already off its support '
                             f'({HoldState(int(self._h["state"])).name}); '
                             'place an object again before a new hold')

    @property
    def lift(self) -> Lift | None:
        """The lift given with the object (None: it stays on its support)."""
        return self._lift

    @property
    def _hold(self) -> HoldModel | None:
        """The object's tangential hold (a view of the plant's hold record), if any."""
        return HoldModel.view(self.kernel['hold'], self._lift) if self._h['has_hold'] else None

    @property
    def hold_state(self) -> HoldState:
        """What the held object does now (cheap: for a per-step check)."""
        return HoldState(int(self._h['state'])) if self._h['has_hold'] else HoldState.NONE

    def lift_plan(self) -> list[tuple[int, float]]:
        """Return the begun lift's breakpoints (t_ns, upward m/s^2), as its arm announces them.

        Empty without a lift whose clock has started (:func:`hold_plan`).
        """
        times = np.zeros(ANNOUNCE_ROWS, np.int64)
        accels = np.zeros(ANNOUNCE_ROWS)
        n = hold_plan(self.kernel['hold'], times, accels)
        return [(int(times[i]), float(accels[i])) for i in range(n)]

    @property
    def object_state(self) -> ObjectState:
        """The grasped object's hold: state, slip, load against the static capacity, loss time."""
        _object_state(self.kernel, self._object_record)
        values = {name: self._object_record[0][name].item() for name in OBJECT_STATE_DTYPE.names}
        values['state'] = HoldState(values['state'])
        values['lost_ns'] = None if values['lost_ns'] == -1 else values['lost_ns']
        return ObjectState(**values)

    def drive_load(self, accel_mps2: float) -> None:
        """Set the arm's upward acceleration from now on (a live arm: ``sim/load_acceleration``).

        The load on the pads becomes ``m (g + a)``; an object still on its support leaves it; a
        lift profile still running stops. ValueError (nothing changes) for a non-finite value or
        when no grasp holds an object.
        """
        if isinstance(accel_mps2, bool) or not isinstance(accel_mps2, (int, float)) or \
                not math.isfinite(accel_mps2):
            raise ValueError(f'load acceleration must be a finite number, got {accel_mps2!r}')
        if plant_drive_load(self.kernel, float(accel_mps2)):
            raise ValueError('no grasp holds an object: a load acceleration applies only after '
                             'HOLDING, while the object is between the pads')

    # ----------------------------------------------------------------- fault injection
    def schedule_fault(self, kind, at_ns: int,
                       time_constant_s: float = DEFAULT_SLIP_TIME_CONSTANT_S) -> ScheduledFault:
        """Fire ``kind`` at simulated time ``at_ns`` (>= now; replaces a scheduled one)."""
        kind, tau = check_fault(kind, 0.0, time_constant_s, self.object.rigid)
        plant_schedule_fault(self.kernel, int(kind), int(at_ns), float(tau))
        return self.scheduled_fault

    @property
    def scheduled_fault(self) -> ScheduledFault | None:
        """The fault to fire (None: none scheduled, or it has fired)."""
        s = self._s
        if s['fault_kind'] == FaultKind.NONE:
            return None
        return ScheduledFault(FaultKind(int(s['fault_kind'])), int(s['fault_at_ns']),
                              float(s['fault_time_constant_s']))

    @property
    def fired_faults(self) -> list[tuple[FaultKind, int]]:
        """(kind, t_ns) of each fault fired since set_object."""
        rows = self.kernel[0]['fired'][:int(self._s['fired_count'])]
        return [(FaultKind(int(kind)), int(at_ns)) for kind, at_ns in rows]

    def cancel_fault(self) -> None:
        """Drop a scheduled fault that has not fired (its effects, once fired, stay)."""
        plant_cancel_fault(self.kernel)

    @property
    def sensor_dropped_out(self) -> bool:
        return self.sensor.dropped_out

    # ----------------------------------------------------------------- state read-outs
    t_ns = RecordField(int, at='_s', doc='Simulated time in integer nanoseconds: exact, the '
                       "lockstep's tick key.")

    @property
    def t_s(self) -> float:
        return self.t_ns * 1e-9

    impact_energy_lost_j = RecordField(at='_s', doc='Kinetic energy lost in arrivals on a rigid '
                                       'face or the open stop since the reset.')
    contact_position_m = RecordField(writable=False, field='x_c', at='_s',
                                     doc='Finger travel at which it touches the object.')

    @property
    def contact_state(self) -> ContactState:
        return CONTACT_STATES[self._s['contact']]

    # ----------------------------------------------------------------- model facts
    def position_transfer_function(self) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 11, X(s)/E_a(s), as (numerator, denominator) polynomial coefficients in s."""
        p = self.params
        num = np.array([p.torque_constant_n_m_per_a * p.pitch_m / (2.0 * math.pi)])
        mech = np.polymul([p.inertia_kg_m2, p.damping_n_m_s_per_rad],
                          [p.inductance_h, p.resistance_ohm])
        den = np.polymul(np.polyadd(mech, [p.torque_constant_n_m_per_a * p.back_emf_v_s_per_rad]),
                         [1.0, 0.0])
        return num, den

    def force_transfer_function(self) -> tuple[np.ndarray, np.ndarray]:
        """Eq. 13, F_gr(s)/E_a(s) with the finger stalled, as (numerator, denominator)."""
        p = self.params
        return (np.array([p.torque_constant_n_m_per_a / p.force_lever_m]),
                np.array([p.inductance_h, p.resistance_ohm]))

    def discrete_free_model(self, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Exact ZOH model of free motion: ``s[k+1] = Ad s[k] + Bd e[k]``, s = [i, omega, x]."""
        return free_model(self.params, dt_s)

    def discrete_force_model(self, dt_s: float) -> tuple[float, float]:
        """Exact ZOH of eq. 13: ``F[k+1] = a F[k] + b e[k]`` on a rigid object."""
        return force_model(self.params, dt_s)

    # ----------------------------------------------------------------- simulation
    def sample(self) -> PlantSample:
        """Return what the sensors and motor report now."""
        return _new_tuple(PlantSample, plant_sample(self.kernel))

    def step(self, voltage_v: float, duration_s: float) -> PlantSample:
        """Hold ``voltage_v`` (clipped to the supply, the H-bridge limit) for ``duration_s``."""
        if not 0.0 < duration_s < math.inf:
            raise ValueError(f'duration must be finite and > 0, got {duration_s!r}')
        duration_ns = round(duration_s * 1e9)
        if duration_ns <= 0:
            raise ValueError(f'duration must be at least 1 ns, got {duration_s!r}')
        if not -math.inf < voltage_v < math.inf:
            raise ValueError(f'voltage must be finite, got {voltage_v!r}')
        return _new_tuple(PlantSample, _step_and_sample(self.kernel, float(voltage_v),
                                                        duration_ns))
