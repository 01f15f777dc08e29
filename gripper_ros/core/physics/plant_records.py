"""The plant's record: everything the plant's kernels read and write, in one numpy record.

``GripperPlant.kernel`` is a 1-element :data:`PLANT_DTYPE` array (a compiled caller passes its
record): the state (:data:`STATE_DTYPE`), the constants (:data:`PARAMS_DTYPE`), the object's hold
(:data:`gripper_ros.core.physics.hold.HOLD_DTYPE`), the sensor
(:data:`gripper_ros.core.physics.force_sensor.SENSOR_DTYPE`, the record the plant's
:class:`~gripper_ros.core.physics.force_sensor.FsrVoltageDivider` views), the faults fired since
``set_object`` (rows ``(kind, t_ns)``), the table of discretisations
(:mod:`gripper_ros.core.physics.motor_zoh`) and the pad channels with their delay lines
(:mod:`gripper_ros.core.physics.plant_pads`). One record, not a tuple of arrays: a kernel call
passes one pointer, where each array of a tuple costs numba a reference count in and out of
every call it does not inline.
"""
from __future__ import annotations

from gripper_ros.core.config import ContactParams, PlantParams
from gripper_ros.core.physics.contact_chain import PADS_IN_CHAIN
from gripper_ros.core.physics.force_sensor import SENSOR_DTYPE
from gripper_ros.core.physics.hold import HOLD_DTYPE
from gripper_ros.core.physics.motor_zoh import DISC_COEFFICIENTS, DISC_KEYS, DISC_TABLE_SIZE
from gripper_ros.core.physics.plant_pads import PAD_CHANNELS, PAD_DTYPE
from gripper_ros.core.records import copy_fields
import numpy as np

MAX_FIRED_FAULTS = 16         # fired faults kept since set_object (the oldest are dropped)

PARAMS_DTYPE = np.dtype([
    ('rho', np.float64),                   # p / (2 pi), m per motor rad (eq. 10)
    ('lever', np.float64),                 # eta p N1/N2, N m of torque per N of force (eq. 12)
    ('tau_e', np.float64),                 # L / R (s)
    ('kt', np.float64),
    ('kb', np.float64),
    ('resistance_ohm', np.float64),
    ('inductance_h', np.float64),
    ('inertia_kg_m2', np.float64),
    ('damping_n_m_s_per_rad', np.float64),
    ('max_travel_m', np.float64),
    ('h', np.float64),                     # contact_substep_s
    ('h_ns', np.int64),
    ('limit_v', np.float64),
    ('reach_feedback', np.float64),        # k_t k_b / R + b (free-reach bound)
    ('after_lift_ns', np.int64),           # contact.after_lift_s in ns
    ('two', np.float64),                   # 2.0 read at run time: w ** two is Python's w ** 2
    ('pad_dt_ns', np.int64),               # the pad channels' sample period
    # flexible fingers and Hertz pads in series with the object (core/physics/contact_chain.py)
    ('chain', np.uint8),                   # 1: either is on; every contact is a chain
    ('finger_compliance_m_per_n', np.float64),   # 2 / k_f, both fingers (0: rigid)
    ('pad_stiffness_n_per_m1_5', np.float64),    # k_p of each pad (0: no pad)
], align=True)
"""The plant's constants (Table I and derived), as one record."""

STATE_DTYPE = np.dtype([
    ('t_ns', np.int64),                    # simulated time, integer ns
    ('t_now_s', np.float64),               # time of the piece being integrated (slip capacity)
    ('i', np.float64),                     # armature current (A)
    ('w', np.float64),                     # motor speed (rad/s)
    ('x', np.float64),                     # finger travel from fully open (m)
    ('voltage', np.float64),               # applied (clipped) armature voltage (V)
    ('contact', np.int64),                 # contact.CONTACT_* code (ContactState)
    ('peak', np.float64),                  # largest force in the step (N)
    ('impact_energy_lost_j', np.float64),
    ('width_m', np.float64),               # the object (GraspObject's fields)
    ('stiffness_n_per_m', np.float64),
    ('damping_n_s_per_m', np.float64),
    ('mass_kg', np.float64),
    ('static_friction', np.float64),
    ('kinetic_friction', np.float64),
    ('pad_length_m', np.float64),
    ('x_c', np.float64),                   # travel at which the finger touches the object
    ('compliant_one_step_s', np.float64),
    ('has_slip', np.uint8),                # an OBJECT_SLIPPING fault is acting
    ('slip_t_f_s', np.float64),
    ('slip_f_0_n', np.float64),
    ('slip_tau_s', np.float64),
    ('fault_kind', np.int64),              # FaultKind scheduled, NONE = none
    ('fault_at_ns', np.int64),
    ('fault_time_constant_s', np.float64),
    ('fired_count', np.int64),             # rows of the fired-faults array in use
    ('disc_count', np.int64),              # entries of the discretisation table in use
    ('disc_next', np.int64),               # the entry a miss overwrites once it is full
    ('disc_last', np.int64),               # the entry last found (looked at first)
    ('pads_resting', np.uint8),            # the pad channels read 0: nothing is held
    ('chain_force_n', np.float64),         # the chain's force (contact_chain.py)
    ('chain_object_m', np.float64),        # the object's own compression d_o in the chain
    ('chain_pad_m', np.float64),           # each pad's compression (Newton's next start)
], align=True)
"""The plant's mutable state: mechanics, object, slip, scheduled fault, table bookkeeping."""


PLANT_DTYPE = np.dtype([
    ('state', STATE_DTYPE), ('params', PARAMS_DTYPE), ('hold', HOLD_DTYPE),
    ('sensor', SENSOR_DTYPE),
    ('fired', np.int64, (MAX_FIRED_FAULTS, 2)),          # (kind, t_ns) of each fault fired
    ('disc_keys', np.float64, (DISC_TABLE_SIZE, DISC_KEYS)),
    ('disc_coef', np.float64, (DISC_TABLE_SIZE, DISC_COEFFICIENTS)),
    ('pads', PAD_DTYPE, (PAD_CHANNELS,)),
], align=True)
"""The whole plant in one record: what :class:`~gripper_ros.core.physics.plant.GripperPlant`
holds."""


def fill_params(r, params: PlantParams, contact: ContactParams) -> None:
    """Write the plant's constants into ``r`` (a :data:`PARAMS_DTYPE` record)."""
    p = params
    copy_fields(r, p, {'rho': 'travel_per_rad_m', 'lever': 'force_lever_m',
                       'kt': 'torque_constant_n_m_per_a', 'kb': 'back_emf_v_s_per_rad',
                       'h': 'contact_substep_s', 'limit_v': 'voltage_limit_v'})
    copy_fields(r, p, ('resistance_ohm', 'inductance_h', 'inertia_kg_m2', 'damping_n_m_s_per_rad',
                       'max_travel_m'))
    r['tau_e'] = p.inductance_h / p.resistance_ohm
    r['h_ns'] = max(1, round(p.contact_substep_s * 1e9))
    # Free-reach bound (integration._free_step_is_safe): |omega'| <= (k_t I + b W) / J.
    r['reach_feedback'] = (p.torque_constant_n_m_per_a * p.back_emf_v_s_per_rad
                           / p.resistance_ohm + p.damping_n_m_s_per_rad)
    r['after_lift_ns'] = round(contact.after_lift_s * 1e9)
    r['two'] = 2.0
    finger_k = contact.finger_stiffness_n_per_m
    r['finger_compliance_m_per_n'] = PADS_IN_CHAIN / finger_k if finger_k > 0.0 else 0.0
    copy_fields(r, contact, {'pad_stiffness_n_per_m1_5': 'pad_normal_stiffness_n_per_m1_5'})
    r['chain'] = 1 if finger_k > 0.0 or contact.pad_normal_stiffness_n_per_m1_5 > 0.0 else 0
