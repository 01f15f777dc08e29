"""How the plant's simulated time runs against the world: realtime, fast, or a world's /clock.

Before each tick the plant asks its pacing one question (:meth:`Pacing.gate`): may the tick of
simulated time ``t_next_ns`` be published now, after a wait of wall time, or only after an
event? One class a time mode (:class:`gripper_ros.wire.TimeMode`):

- :class:`RealtimePacing`: paced to the wall clock by ``real_time_factor``, never ahead of it;
  ticks shorter than :data:`QUANTUM_S` of wall time go out in bursts, one wake a quantum;
  behind by up to :data:`MAX_LAG_S` it catches up at the loop's own pace, behind by more it
  starts afresh from now rather than rushing.
- :class:`FastPacing`: as fast as the loop goes while something needs simulated time (a request
  runs, a lift plays out), then time stands still until the next request. Deterministic.
- :class:`ClockPacing` (``use_sim_time``): in step with the time a world simulator publishes on
  ``/clock`` (Gazebo, MuJoCo, Isaac): a tick is published once the world's time has reached it,
  so the gripper runs at whatever pace the world runs, its time held while the world's stands
  still, and its stamps are the world's time. It starts at the world's time of its first
  ``/clock``.

What every mode shares is here too: ``sim/pause`` and the budget of a ``sim/step``, which
advances time now whatever the mode, and the achieved real-time factor that ``sim/status``
reports. No ROS: the node (``nodes/plant_simulator_node.py``) turns a wait into a timer and the
world's clock into :meth:`ClockPacing.take_world_time`.
"""
from __future__ import annotations

import enum
import math
import time
from typing import Callable

from gripper_ros.wire import FORCE_SAMPLE_S, TimeMode

NOW = 0.0
""":meth:`Pacing.gate`: publish the tick now."""
HELD = None
""":meth:`Pacing.gate`: not before an event (``sim/resume``, ``sim/step``, the world's time)."""
IDLE = math.inf
""":meth:`Pacing.gate`, fast mode: nothing needs simulated time; it stands still until a
request."""

MAX_LAG_S = 0.1
"""Realtime: behind the wall clock by up to this (the process was not scheduled for a while, a
bag closed), simulated time catches up at the loop's own pace; behind by more (a real stall),
pacing starts afresh from now rather than rushing, and the achieved real-time factor shows the
loss."""
QUANTUM_S = 0.002
"""Realtime: the plant wakes at most once per this much wall time. A tick due sooner after the
current one waits until the wall clock is this far past the current one, then the ticks due by
then go out back to back: simulated time lags the wall clock by up to one quantum (a command
waits up to one quantum longer), and the process sleeps once a quantum instead of once a tick
(ten thousand a second while the force stage holds)."""
SLEEP_LIMIT_S = QUANTUM_S
"""Realtime: a wait up to this long (every wait between the force stage's short ticks) is
slept in place; a longer one is the node's timer. A timer re-armed, fired and cancelled once a
quantum costs the executor more CPU than the wait it makes; sleeping in place keeps other
callbacks waiting for at most a quantum, as a drain's slice of the intra-process bus does."""
MAX_STEP_S = 600.0
"""sim/step: the most simulated time one request may ask for (duration_s)."""
MAX_STEP_TICKS = round(MAX_STEP_S / FORCE_SAMPLE_S)
"""sim/step: the most ticks one request may ask for (MAX_STEP_S of force samples)."""
RTF_WARN_FRACTION = 0.95
"""Realtime: warn (throttled) when the achieved real-time factor falls below this x target."""
RTF_WARN_PERIOD_S = 10.0
RTF_WARN_GRACE_S = 3.0
"""No pace warning this soon after start: the first ticks wait for the peers' discovery."""
WORLD_STILL_S = 0.5
"""Following /clock: the world's time counts as standing still (paused) once it has not moved
for this much wall time. Gazebo publishes /clock every physics step (1 ms by default), paused
too; MuJoCo after every step, not at all while paused."""
BEHIND_WARN_S = 0.1
"""Following /clock: warn (throttled) when the gripper's time is this far behind the world's."""


def step_problem(ticks: int, duration_s: float) -> str:
    """Say why a ``sim/step`` of ``ticks`` or ``duration_s`` is refused ('' when it is not)."""
    if not math.isfinite(duration_s) or duration_s < 0.0:
        return f'duration_s must be finite and >= 0, got {duration_s!r}'
    if (ticks > 0) == (duration_s > 0.0):
        return f'give exactly one of ticks ({ticks}) and duration_s ({duration_s:g}) > 0'
    if duration_s > MAX_STEP_S:
        return f'duration_s must be <= {MAX_STEP_S:g} s, got {duration_s:g}'
    if ticks > MAX_STEP_TICKS:
        return f'ticks must be <= {MAX_STEP_TICKS}, got {ticks}'
    return ''


class Pacing:
    """The time mode's gate, the pause, a sim/step's budget and the achieved real-time factor.

    ``monotonic`` is the wall clock (seconds); a test may pass its own.
    """

    mode: TimeMode
    runs_unasked = True
    """Simulated time runs with no request (0 V when nobody commands): realtime and /clock."""

    def __init__(self, t_ns: int, real_time_factor: float = 1.0,
                 monotonic: Callable[[], float] = time.monotonic):
        self.monotonic = monotonic
        self.real_time_factor = real_time_factor
        self.paused = False
        self._budget: tuple[str, int] | None = None     # ('ticks', n) or ('until', t_ns)
        now = monotonic()
        self._window = (now, t_ns, 0.0)                  # start of the window; last achieved
        self._last_warning = now - RTF_WARN_PERIOD_S + RTF_WARN_GRACE_S

    # ------------------------------------------------------------------ the gate
    def gate(self, t_ns: int, t_next_ns: int, needs_time: Callable[[], bool]) -> float | None:
        """Say when the tick of ``t_next_ns`` (the current one is ``t_ns``) may be published.

        :data:`NOW`, a wait in wall seconds, :data:`HELD` or :data:`IDLE`. A running sim/step
        advances now in every mode, and a pause holds; ``needs_time()`` tells fast mode whether
        a request or its scenario still needs simulated time.
        """
        if self._budget is not None:
            return NOW
        if self.paused:
            return HELD
        return self._gate(t_ns, t_next_ns, needs_time)

    def _gate(self, t_ns: int, t_next_ns: int, needs_time: Callable[[], bool]) -> float | None:
        raise NotImplementedError

    def restart(self, t_ns: int) -> None:
        """Count the pace afresh from simulated time ``t_ns`` (a resume, a step, a factor)."""

    @property
    def held(self) -> bool:
        """Simulated time is held by something other than the loop: a pause (or the world)."""
        return self.paused

    @property
    def target_factor(self) -> float:
        """The real-time factor aimed at, 0 where the pace is not the wall clock's."""
        return 0.0

    def pause_refusal(self) -> str:
        """Say why sim/pause, sim/resume and sim/step are refused in this mode ('' if not)."""
        return ''

    @property
    def started(self) -> bool:
        """Simulated time has begun (following /clock: once the world's first time came)."""
        return True

    # ------------------------------------------------------------------ sim/step
    @property
    def stepping(self) -> bool:
        """A sim/step is running."""
        return self._budget is not None

    def start_step(self, ticks: int, duration_s: float, t_ns: int) -> None:
        """Run a sim/step (checked by :func:`step_problem`) from simulated time ``t_ns``."""
        self._budget = ('ticks', ticks) if ticks else ('until', t_ns + round(duration_s * 1e9))

    def spend(self, t_ns: int) -> bool:
        """Count a tick of ``t_ns`` published during a sim/step; True when it ends the step."""
        kind, value = self._budget
        if kind == 'ticks':
            value -= 1
            self._budget = (kind, value)
        return value <= 0 if kind == 'ticks' else t_ns >= value

    def end_step(self, t_ns: int) -> None:
        """End the sim/step (done or cut short) at ``t_ns``: pacing goes on from there."""
        self._budget = None
        self.restart(t_ns)

    # ------------------------------------------------------------------ the pace achieved
    def achieved(self, t_ns: int) -> tuple[float, float, bool]:
        """Close the window at simulated time ``t_ns``: (factor, wall s, time advanced).

        The factor achieved is simulated seconds per wall second since the last call.
        """
        now = self.monotonic()
        wall0, sim0, _ = self._window
        elapsed = now - wall0
        factor = (t_ns - sim0) * 1e-9 / elapsed if elapsed > 0.0 else 0.0
        self._window = (now, t_ns, factor)
        return factor, elapsed, t_ns > sim0

    @property
    def last_factor(self) -> float:
        """The factor of the last closed window."""
        return self._window[2]

    def pace_warning(self, t_ns: int, factor: float, elapsed_s: float) -> str:
        """Say, throttled, that the loop cannot keep the pace it should ('' when it does)."""
        return ''

    def _throttled(self, message: str) -> str:
        now = self.monotonic()
        if now - self._last_warning <= RTF_WARN_PERIOD_S:
            return ''
        self._last_warning = now
        return message


class RealtimePacing(Pacing):
    """Paced to the wall clock by ``real_time_factor``, never ahead of it.

    ``sleep`` waits in place (seconds); a test may pass its own, with its ``monotonic``.
    """

    mode = TimeMode.REALTIME

    def __init__(self, t_ns: int, real_time_factor: float = 1.0,
                 monotonic: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep):
        super().__init__(t_ns, real_time_factor, monotonic)
        self.sleep = sleep
        self.restart(t_ns)

    def restart(self, t_ns: int) -> None:
        """Pacing counts from here: simulated time ``t_ns`` = wall time now."""
        self._wall_anchor = self.monotonic()
        self._sim_anchor_ns = t_ns

    def _lead_s(self, t_next_ns: int) -> float:
        """Wall seconds until simulated time ``t_next_ns`` may be published."""
        wall_s = self.monotonic() - self._wall_anchor
        return (t_next_ns - self._sim_anchor_ns) * 1e-9 / self.real_time_factor - wall_s

    def _gate(self, t_ns: int, t_next_ns: int, needs_time: Callable[[], bool]) -> float:
        lead_s = self._lead_s(t_next_ns)
        if lead_s < -MAX_LAG_S:                 # fell behind (a stall): no burst to catch up
            self.restart(t_ns)
            lead_s = self._lead_s(t_next_ns)
        if lead_s <= 0.0:
            return NOW
        lead_s = max(lead_s, self._lead_s(t_ns) + QUANTUM_S)    # a short tick: a quantum on
        if lead_s > SLEEP_LIMIT_S:
            return lead_s
        self.sleep(lead_s)
        return NOW

    @property
    def target_factor(self) -> float:
        return self.real_time_factor

    def pace_warning(self, t_ns: int, factor: float, elapsed_s: float) -> str:
        if self.paused or factor >= RTF_WARN_FRACTION * self.real_time_factor or \
                elapsed_s <= 0.5:
            return ''
        return self._throttled(f'the graph cannot keep pace: achieved real-time factor '
                               f'{factor:.2f} against {self.real_time_factor:g} over the last '
                               f'{elapsed_s:.1f} s')


class FastPacing(Pacing):
    """As fast as the loop goes while something needs simulated time, else still."""

    mode = TimeMode.FAST
    runs_unasked = False

    def _gate(self, t_ns: int, t_next_ns: int, needs_time: Callable[[], bool]) -> float:
        return NOW if needs_time() else IDLE


class WorldTime(enum.Enum):
    """What a new time from the world's /clock means to :class:`ClockPacing`."""

    START = 'start'      # the first: the simulation starts at it
    ON = 'on'            # later than the last
    BACK = 'back'        # earlier than the last (the world was reset)


class ClockPacing(Pacing):
    """In step with a world's /clock: a tick is due once the world's time has reached it.

    The node hands over every change of its ROS clock (rclpy's TimeSource sets it from /clock
    under ``use_sim_time``) with :meth:`take_world_time`. Before the first, nothing is due: the
    plant starts at the world's time of the first. A world whose time went back (a reset) is
    followed again once its time passes the gripper's.
    """

    mode = TimeMode.SIM_TIME

    def __init__(self, t_ns: int, real_time_factor: float = 1.0,
                 monotonic: Callable[[], float] = time.monotonic):
        super().__init__(t_ns, real_time_factor, monotonic)
        self.world_ns: int | None = None        # the world's newest time
        self._moved = monotonic()               # wall time of its last move forward

    def take_world_time(self, world_ns: int) -> WorldTime:
        """Take the world's time ``world_ns`` (it changed); say what it means."""
        previous, self.world_ns = self.world_ns, world_ns
        if previous is None:
            self._moved = self.monotonic()
            return WorldTime.START
        if world_ns < previous:
            return WorldTime.BACK
        self._moved = self.monotonic()
        return WorldTime.ON

    def _gate(self, t_ns: int, t_next_ns: int, needs_time: Callable[[], bool]) -> float | None:
        return NOW if self.world_ns is not None and t_next_ns <= self.world_ns else HELD

    @property
    def started(self) -> bool:
        """The world's first time has come: the simulation runs from it."""
        return self.world_ns is not None

    @property
    def held(self) -> bool:
        """No world time yet, or the world's has stood still for :data:`WORLD_STILL_S`."""
        return self.world_ns is None or \
            self.monotonic() - self._moved > WORLD_STILL_S

    def pause_refusal(self) -> str:
        return 'simulated time follows /clock (use_sim_time): pause or step the world instead'

    def behind_s(self, t_ns: int) -> float:
        """How far the gripper's time ``t_ns`` is behind the world's (s; 0 before it starts)."""
        return 0.0 if self.world_ns is None else max(0, self.world_ns - t_ns) * 1e-9

    def pace_warning(self, t_ns: int, factor: float, elapsed_s: float) -> str:
        behind_s = self.behind_s(t_ns)
        if behind_s < BEHIND_WARN_S or self.held:
            return ''
        return self._throttled(f"the graph cannot keep the world's pace: {behind_s:.2f} s "
                               f'behind /clock (achieved real-time factor {factor:.2f} over '
                               f'the last {elapsed_s:.1f} s)')


PACINGS = {cls.mode: cls for cls in (RealtimePacing, FastPacing, ClockPacing)}
"""The pacing of each time mode."""


def make_pacing(mode: TimeMode, t_ns: int, real_time_factor: float = 1.0,
                monotonic: Callable[[], float] = time.monotonic) -> Pacing:
    """Return the pacing of time mode ``mode``, starting at simulated time ``t_ns``."""
    return PACINGS[mode](t_ns, real_time_factor, monotonic)
