"""The supervisor's outcome messages: a template per event, filled with the kernel's numbers.

Text is not made in compiled code. When the state machine (:mod:`.machine`) ends or answers a
request it writes the event that did it and the numbers of that instant, by name, into its
:data:`MESSAGE_DTYPE` record; :func:`format_message` fills that event's template from
:data:`MESSAGES`. A template reads the record's fields and the values :data:`MESSAGE_VALUES`
derives from them (and the plant's ``travel_m`` and ``voltage_limit_v``, and ``text``: a
message given from Python, for a stop or a fault).
"""
from __future__ import annotations

from gripper_ros.core.config import PlantParams
from gripper_ros.wire import Phase
import numpy as np

MESSAGE_DTYPE = np.dtype(
    [('t_ns', 'i8'), ('start_ns', 'i8'),
     ('since_ns', 'i8'),                   # the force low (LOST_FORCE) or at rest (STALLED) since
     ('into_ns', 'i8'),                    # how long after HOLDING (after_holding) or the start
     ('after_holding', 'b1'), ('bad_position', 'b1'), ('bad_force', 'b1'),
     ('request_kind', 'i4'),               # SENSOR_FAULT: the request's code, 0: the hold
     ('phase', 'i4'),                      # GRASP_TIMEOUT: the phase it was in
     ('position_m', 'f8'), ('force_n', 'f8'), ('sensor_voltage_v', 'f8'),
     ('position_setpoint_m', 'f8'),        # the expected face, the open position, the goal
     ('width_tolerance_m', 'f8'), ('farthest_face_m', 'f8'),
     ('lost_force_fraction', 'f8'), ('force_setpoint_n', 'f8'), ('floor_n', 'f8'),
     ('hold_position_m', 'f8'), ('margin_m', 'f8'), ('timeout_s', 'f8'),
     ('short_of_goal_m', 'f8'), ('max_effort_n', 'f8'),
     ('need_n', 'f8'), ('max_force_n', 'f8'), ('load_n', 'f8'), ('friction_coefficient', 'f8')],
    align=True)
"""The numbers of the current message, by name; each event writes the fields its text reads."""

_MOST_GRIP = ('the most {voltage_limit_v:g} V holds is {max_force_n:.2f} N; gripping with '
              '{force_n:.2f} N, at most that, while the object stays')
_WHERE = ('finger at {position_m:.5f} m (opening {opening_m:.5f} m, goal {goal_opening_m:.5f} m),'
          ' force {force_n:.3f} N, after {elapsed_s:.3f} s')
_STALLED = 'stalled {short_of_goal_mm:.2f} mm short of the goal, '

MESSAGES = {
    'SENSOR_FAULT': ('fault at t={t_s:.4f} s ({elapsed_s:.4f} s into the {what}): {bad}; '
                     'no controller drives the motor from here on'),
    'NO_OBJECT': ('no object: the finger passed the expected face ({position_setpoint_m:.4f} m'
                  '{tolerance}) by {past_face_mm:.2f} mm without contact'),
    'LOST_FORCE': ('object lost at {at}, {into}: force {force_n:.3f} N has been below '
                   '{lost_force_fraction:g} x the setpoint {force_setpoint_n:.3f} N = '
                   '{floor_n:.3f} N for {low_ms:.2f} ms (since t={since_s:.4f} s); finger at '
                   '{position_m:.5f} m'),
    'LOST_MOVED_ON': ('object lost at {at}, {into}: the finger moved on {moved_on_mm:.2f} mm '
                      'past the held position {hold_position_m:.5f} m (margin {margin_mm:g} '
                      'mm); force {force_n:.3f} N'),
    'HELD': 'holding {force_n:.3f} N (setpoint {force_setpoint_n:.3f} N) at {position_m:.5f} m',
    'OVERLOADED': ('overloaded at {at} ({into}): the load {load_n:.2f} N needs {need_n:.2f} N '
                   'of grip at the measured friction {friction_coefficient:.3f}, '
                   + _MOST_GRIP),
    'OVERLOADED_SLIDING': ('overloaded at {at} ({into}): the object slides on, no slower, with'
                           ' the grip at its most: kinetic friction ({friction_coefficient:.3f}'
                           ' measured) is short of the load; ' + _MOST_GRIP),
    'GRASP_TIMEOUT': ('not settled within {timeout_s:g} s of simulated time (phase '
                      '{phase_name}, position {position_m:.5f} m, force {force_n:.3f} N)'),
    'RELEASED': ('released: finger at {position_m:.5f} m (open position '
                 '{position_setpoint_m:.5f} m, opening {opening_m:.5f} m) after '
                 '{elapsed_s:.3f} s'),
    'RELEASE_TIMEOUT': ('release not done within {timeout_s:g} s of simulated time (finger at '
                        '{position_m:.5f} m)'),
    'MOVED': 'moved: ' + _WHERE,
    'STALLED_PRESSING': (_STALLED + 'pressing with {force_n:.3f} N at the effort limit '
                         '{max_effort_n:.3f} N: ' + _WHERE),
    'STALLED_AT_REST': _STALLED + 'at rest for {rest_s:.3f} s: ' + _WHERE,
    'MOVE_TIMEOUT': 'move not done within {timeout_s:g} s of simulated time: ' + _WHERE,
    'STOP': '{text}',
    'CANCEL': '{text}',
    'FAULT': '{text}',
}
"""Each answering event's text (by the event's name in :class:`.machine.Event`):
:data:`MESSAGE_DTYPE` fields and :data:`MESSAGE_VALUES` by name."""

REQUEST_WORDS = {1: 'grasp', 2: 'release', 3: 'move'}
"""What a message calls each request kind (``PendingRequest`` codes)."""

MESSAGE_VALUES = {
    't_s': lambda m: m['t_ns'] * 1e-9,
    'elapsed_s': lambda m: (m['t_ns'] - m['start_ns']) * 1e-9,
    'at': lambda m: f"t={m['t_s']:.4f} s",
    'into': lambda m: (f"{m['into_ns'] * 1e-9:.4f} s after HOLDING" if m['after_holding'] else
                       f"{m['into_ns'] * 1e-9:.4f} s into the grasp"),
    'since_s': lambda m: m['since_ns'] * 1e-9,
    'low_ms': lambda m: (m['t_ns'] - m['since_ns']) * 1e-9 * 1e3,
    'rest_s': lambda m: (m['t_ns'] - m['since_ns']) * 1e-9,
    'what': lambda m: REQUEST_WORDS[m['request_kind']] if m['request_kind'] else 'hold',
    'bad': lambda m: '; '.join(
        ([f"finger position sensor (joint state) reads {m['position_m']!r} m"]
         if m['bad_position'] else [])
        + ([f"force sensor reads force {m['force_n']!r} N, voltage {m['sensor_voltage_v']!r} V "
            '(sensor dropout)'] if m['bad_force'] else [])),
    'tolerance': lambda m: (f" + {m['width_tolerance_m'] * 1e3:g} mm tolerance"
                            if m['width_tolerance_m'] else ''),
    'past_face_mm': lambda m: (m['position_m'] - m['farthest_face_m']) * 1e3,
    'moved_on_mm': lambda m: (m['position_m'] - m['hold_position_m']) * 1e3,
    'margin_mm': lambda m: m['margin_m'] * 1e3,
    'phase_name': lambda m: Phase(m['phase']).name,
    'opening_m': lambda m: m['travel_m'] - m['position_m'],
    'goal_opening_m': lambda m: m['travel_m'] - m['position_setpoint_m'],
    'short_of_goal_mm': lambda m: abs(m['short_of_goal_m']) * 1e3,
}
"""What the message texts derive from the record's numbers (and the plant's ``travel_m`` and
``voltage_limit_v``), by name."""


class _MessageNumbers(dict):
    """A message record's numbers by name; a derived value is computed when a text reads it."""

    def __missing__(self, name: str):
        value = self[name] = MESSAGE_VALUES[name](self)
        return value


def format_message(event: str, record, plant: PlantParams, text: str = '') -> str:
    """Return the text of the message ``event`` gave, from its record's numbers.

    ``event`` is the event's name ('' for none: no message); ``text`` a text given from Python.
    """
    if not event:
        return ''
    try:
        template = MESSAGES[event]
    except KeyError:
        raise ValueError(f'no message for the event {event!r}') from None
    numbers = _MessageNumbers({name: record[name].item() for name in MESSAGE_DTYPE.names},
                              text=text, travel_m=plant.max_travel_m,
                              voltage_limit_v=plant.voltage_limit_v)
    return template.format_map(numbers)
