"""The load-tracking grip: an object of unknown mass and friction held with the least force.

As a human does (Johansson and Westling 1984): close to a light touch, then let the grip force
follow the load the pads feel, ``F_sp(t) = k F_load(t) / (2 mu_est)``, with a margin ``k`` of
1.2-1.4 over the slip limit, and raise it at once when the object slips.

* ``F_load`` is the sum of the two pads' shear readings (``core/physics/pad_sensor.py``); the grip
  force it is divided by passes through the shear channel's latency and bandwidth first.
* ``mu_est`` starts at a conservative ``mu_start`` and is measured from the incipient slip:
  while the object is stuck each pad's displacement follows Cattaneo-Mindlin, ``delta = b +
  3 mu F / (2 k_t) [1 - (1 - Q / (mu F))^(2/3)]`` (``core/physics/hold.py``), with the pads' own
  tangential stiffness ``k_t`` and an offset ``b`` left by any earlier slip. For each ``mu`` of
  a grid the law keeps the running mean and variance of ``delta - delta_CM(Q, F, mu)`` over
  the samples since the last slip; the ``mu`` whose residual varies least is the estimate, once
  the grid tells the candidates apart (the grip's own rise and the arm's motion sweep ``Q /
  F``). It is used times ``mu_safety`` (< 1), so that a noisy estimate errs towards force.
  Once measured, a later fit only raises it.
* A slip is the displacement growing faster than ``slip_speed_mps`` over ``slip_window_s``
  with the pads near the friction believed: ``mu_est`` becomes what the pads carry as it is
  seen, ``Q / F`` (kinetic friction, a lower bound of the static one), when that is lower or
  nothing was measured yet, so ``F_sp`` jumps to ``k`` times the force at once. That reading
  floors every later fit, and the estimate that slipped caps it.
* Until ``mu`` is measured the grip relaxes at ``release_rate_n_per_s`` towards the grip of
  the most friction expected (after a slip, of the friction it showed); the incipient slip
  this brings on is what the fit reads. The grip never goes below the touch force.
* Overload: when the load needs more than ``max_force_n`` at the friction the fit measured
  (static, margin 1, without ``mu_safety``), or the object slides no slower after
  ``overload_slip_s`` with the grip at ``max_force_n`` than when it got there (a slide that
  slows stops, and then static friction holds it), the law says so (``overload_ns``) while
  the object is still between the pads.
* An announced motion (the arm's plan, :func:`plan_announce`: from each breakpoint's instant
  on, its upward acceleration ``a``): the grip rises in parallel with the load it will bring,
  as a hand's does with its own arm's motion (Flanagan and Wing 1993, 1997), and is there when
  the load comes. The mass is the load read over ``g + a`` as the pads' shear channel reads it
  (its latency and bandwidth); a coming breakpoint counts from as long before its instant as
  24 V needs to raise the grip from the force now to what that load needs
  (:func:`rise_time_s`: the motor's current, L / R, on a rigid contact; the finger's travel
  on a compliant one), two samples more (:func:`plan_load_ratio`). A lift of an object not
  yet weighed (the pads carry nothing, so nothing tells its weight) is met the same way with
  the most 24 V gives, held until the pads' reading of the weight has settled. A known fall
  lowers the grip first-order, as fast as the force stage follows without undershoot
  (:func:`fall_time_s`), to what the friction believed needs, and only below that at the
  release rate, once the force has caught up. The margin is :data:`ANNOUNCED_MARGIN`, and
  after a slip the friction believed is at least ``mu_safety`` times the most ``Q / F`` the
  pads were read to carry (a stuck pad carries at most ``mu_s F``, and so does the channel's
  reading of it): static friction, not the slide's kinetic reading. The slip reflex stays
  for what was not announced.
* A slide the pads carry nothing of (a frictionless object) raises the grip to the most at
  once; not slowing there, it is an overload at the friction it read.
* Unannounced, a grip within :data:`TOP_RESERVE` of the most 24 V gives is the most.
* The grip falls at ``release_rate_n_per_s``, a light one in proportion to itself
  (:data:`RELEASE_TIME_S`), so that the force stage, which leads a falling setpoint by its
  rate, keeps it above the slip limit. No plan: the law above, exactly.

The supervisor runs :func:`law_step` each tick for a grasp of unknown mass
(``core/supervision/machine.py``, ``_track_load``); one grasp and hold of the study is
:func:`gripper_ros.studies.grip_runs.simulate_load_grip`.
"""
from __future__ import annotations

import math

from gripper_ros.core.config import GripperConfig, LoadGripParams
from gripper_ros.core.physics.hold import presliding_m
from gripper_ros.core.records import as_record, copy_fields, face_kernel
import numba
import numpy as np

MU_GRID = np.round(np.arange(0.20, 1.2001, 0.01), 2)
"""The friction coefficients the estimator tells apart."""
HISTORY_ROWS = 4
"""The law's history: displacements, shears, forces as the shear channel reads them, forces."""
NEIGHBOURS = 5
"""An estimate is believed once the candidates this many grid steps away fit clearly worse."""
NEIGHBOUR_SIGNIFICANCE = 25.0
"""How much worse, in units of noise variance / samples (a 5-sigma difference)."""
SEPARATION_NOISES = 20.0
"""The whole grid must span this many noise variances: the load and grip have moved."""
STUCK_HEADROOM = 1.1
"""A stuck pad carrying Q / F has mu_s at least this much above it (the slip test's model)."""
SLIP_SHARE = 0.7
"""A fast displacement is a slip only while the pads carry this share of mu_est F or more."""
SATURATED = 0.98
"""A slip with the grip at this share of the most 24 V holds is watched for an overload."""
RELEASE_TIME_S = 0.05
"""A light grip lets go no faster than its own size in this long: the force stage follows a
falling setpoint about 1.3 ms late, so a faster fall would leave a grip of a newton or two below
the slip limit before the setpoint is there."""
ANNOUNCED_MARGIN = 1.15
"""The grip's margin over the slip limit while the arm announces its motion: it covers the
pads' noise and the fit's error, not a rise of the load nobody told (a hand's margin is
smaller for its own arm's motion than for a load it must react to)."""
ANTICIPATION_S = 0.01
"""A breakpoint of the plan acts as planned when it arrives this long before its stamp: more
than the lead of any rise on a rigid contact (:func:`rise_time_s`, under 1 ms at 24 V)."""
NOISE_SIGMAS = 5.0
"""A mean shear reading beyond this many of its noise sigmas is load the pads carry."""
TOP_RESERVE = 1.5
"""Unannounced, a grip above the most 24 V gives over this goes to the most at once: what is
left above it is less than a load step of (TOP_RESERVE - 1) g needs, and a slide begun near the
top may find kinetic friction at the most short of the load."""
PLAN_ROWS = 1024
"""The most breakpoints of an announced plan kept at once (the oldest go first); a lift's
whole plan (``hold.ANNOUNCE_ROWS``) fits."""
PLAN_DTYPE = np.dtype([('t_ns', np.int64), ('accel_mps2', np.float64)], align=True)
"""One breakpoint of the arm's announced plan: from ``t_ns`` on its upward acceleration."""
LEAST_SUPPORT = 0.1
"""A downward acceleration is taken as leaving at least this share of g on the pads."""

GRIP_DTYPE = np.dtype([
    ('k_margin', np.float64),
    ('mu_start', np.float64),
    ('mu_safety', np.float64),
    ('touch_force_n', np.float64),
    ('max_force_n', np.float64),
    ('tangential_stiffness_n_per_m', np.float64),
    ('slip_speed_mps', np.float64),
    ('window', np.int64),              # samples over which the slip speed is measured
    ('rest', np.int64),                # samples below it that end a slip
    ('overload_samples', np.int64),    # slipping this long at the most 24 V gives: overload
    ('min_samples', np.int64),         # before an estimate is believed
    ('separation', np.float64),        # residual variance the grid must span (m^2)
    ('dt_s', np.float64),
    ('release_rate_n_per_s', np.float64),
    ('mu_est', np.float64),
    ('force_setpoint_n', np.float64),
    ('slipping', np.uint8),
    ('mu_at_slip', np.float64),
    ('slipping_saturated', np.int64),  # samples slipping with the grip at its most
    ('quiet', np.int64),
    ('head', np.int64),
    ('filled', np.int64),
    ('count', np.int64),
    ('slips', np.int64),
    ('estimated', np.uint8),
    ('overload_ns', np.int64),         # -1: never
    ('overload_need_n', np.float64),
    ('mu_bound', np.float64),          # the most Q / F a slip showed: mu_s is at least this
    ('mu_ceiling', np.float64),        # the least estimate a slip proved too high
    ('normal_delay', np.int64),        # the shear channel's latency, in samples
    ('normal_alpha', np.float64),      # ... and its low-pass step share (1: none)
    ('normal_filtered', np.float64),   # the grip force as that channel would read it
    ('normal_primed', np.uint8),
    ('overload_mu', np.float64),       # the friction the overload was judged at
    ('saturated_speed_mps', np.float64),  # the slide's speed as the grip reached its most
    ('slide_not_slowing', np.uint8),   # at its most the grip did not slow the slide
    ('gravity_mps2', np.float64),
    ('plan_count', np.int64),          # breakpoints of the arm's announced plan (0: none)
    ('plan_filtered', np.float64),     # g + a announced, as the shear channel would read it
    ('plan_primed', np.uint8),
    ('electrical_time_s', np.float64),  # L / R: the stalled motor's force follows its current
    ('reflected_mass_kg', np.float64),  # the motor's inertia as the finger feels it
    ('settle_band', np.float64),       # a grip is there within this share of it
    ('shear_floor_n', np.float64),     # a mean shear reading the noise stays below
    ('channel_settle_ns', np.int64),   # the shear channel reads a step within the band after it
    ('contact_position_m', np.float64),  # where the finger first felt the object (NaN: not yet)
    ('contact_force_n', np.float64),   # ... and the force then
    ('stiffness_n_per_m', np.float64),  # the contact's, force gained over travel (inf: rigid)
    ('mu_carried', np.float64),        # the most Q / F the pads were read to carry: mu_s >= it
    ('loaded_ns', np.int64),           # the first sample the pads read a load (-1: none yet)
    ('slide_mu', np.float64),          # Q / F as the last slip was seen
    ('lead_s', np.float64),            # the lead of the rise the plan asks for now (0: none)
    ('pregrip_until_ns', np.int64),    # an unweighed lift's grip stays at its most until then
    ('fall_time_s', np.float64),       # a known fall: first order, no faster than this
    ('most_lead_ns', np.int64),        # no rise on this contact needs a longer lead
], align=True)
"""The law's settings and state."""


def make_law(params: LoadGripParams, max_force_n: float, tangential_stiffness_n_per_m: float,
             dt_s: float, displacement_noise_m: float, displacement_resolution_m: float,
             shear_latency_s: float = 0.0, shear_bandwidth_hz: float = 0.0,
             gravity_mps2: float = 9.81, *, electrical_time_s: float = 0.0,
             reflected_mass_kg: float = 0.0, settle_band: float = 0.02,
             shear_noise_n: float = 0.0, shear_resolution_n: float = 0.0,
             fall_time_s: float = math.inf):
    """Return the law's (record, displacement history, residual sums) for samples ``dt_s``.

    The grip force it divides the shear by passes through the shear channel's latency and
    bandwidth first, so that their ratio is not skewed while the grip moves. The plant's
    ``electrical_time_s`` (L / R) and ``reflected_mass_kg`` bound how fast 24 V raises the grip
    (:func:`rise_time_s`), to within ``settle_band`` of it; the shear channel's noise and
    resolution, which load reading is carried load. ``fall_time_s``: a fall the law knows is
    safe approaches its grip first-order, no faster (inf: only at the release rate).
    """
    rec = np.zeros(1, GRIP_DTYPE)
    r = rec[0]
    r['k_margin'] = params.grip_margin
    copy_fields(r, params, ('mu_start', 'mu_safety', 'touch_force_n', 'slip_speed_mps',
                            'min_samples', 'release_rate_n_per_s'))
    r['max_force_n'] = max_force_n
    r['tangential_stiffness_n_per_m'] = tangential_stiffness_n_per_m
    r['window'] = max(1, round(params.slip_window_s / dt_s))
    r['rest'] = max(1, round(params.slip_rest_s / dt_s))
    r['overload_samples'] = max(1, round(params.overload_slip_s / dt_s))
    noise_var = displacement_noise_m ** 2 + displacement_resolution_m ** 2 / 12.0
    r['separation'] = SEPARATION_NOISES * noise_var
    r['dt_s'] = dt_s
    r['mu_est'] = params.mu_start
    r['force_setpoint_n'] = params.touch_force_n
    r['overload_ns'] = -1
    r['mu_ceiling'] = math.inf
    r['normal_delay'] = min(round(shear_latency_s / dt_s), int(r['window']))
    r['normal_alpha'] = 1.0 if shear_bandwidth_hz == 0.0 else \
        -math.expm1(-2.0 * math.pi * shear_bandwidth_hz * dt_s)
    r['gravity_mps2'] = gravity_mps2
    r['electrical_time_s'] = electrical_time_s
    r['reflected_mass_kg'] = reflected_mass_kg
    r['settle_band'] = settle_band
    # the mean of the two pads' readings: each with its noise and its rounding
    r['shear_floor_n'] = NOISE_SIGMAS * math.sqrt(
        (shear_noise_n ** 2 + shear_resolution_n ** 2 / 12.0) / 2.0)
    tau_s = 0.0 if shear_bandwidth_hz == 0.0 else 1.0 / (2.0 * math.pi * shear_bandwidth_hz)
    r['channel_settle_ns'] = round((tau_s * math.log(1.0 / settle_band) + dt_s) * 1e9)
    r['contact_position_m'] = math.nan
    r['stiffness_n_per_m'] = math.inf
    r['loaded_ns'] = -1
    r['pregrip_until_ns'] = -1
    r['fall_time_s'] = fall_time_s
    _most_lead(rec)
    history = np.zeros((HISTORY_ROWS, int(r['window']) + 1))
    sums = np.zeros((2, MU_GRID.size))
    return rec, history, sums


def law_for(config: GripperConfig):
    """Return :func:`make_law`'s arrays for ``config``: the law a supervisor runs.

    Sampled at the force stage's period, with the pads' tangential stiffness and sensing as
    configured, at most the force 24 V holds, the plant's electrical time constant and
    reflected mass, the force stage's settle band as "there" and its fastest fall
    (:func:`fall_time_s`).
    """
    pads = config.pad_sensor
    plant = config.plant
    return make_law(config.load_grip, plant.max_force_n,
                    config.contact.pad_tangential_stiffness_n_per_m,
                    config.force.sample_time_s, pads.displacement_noise_m,
                    pads.displacement_resolution_m, pads.shear.latency_s,
                    pads.shear.bandwidth_hz, plant.gravity_mps2,
                    electrical_time_s=plant.inductance_h / plant.resistance_ohm,
                    reflected_mass_kg=plant.reflected_mass_kg,
                    settle_band=config.supervisor.force_settle_band_fraction,
                    shear_noise_n=pads.shear_noise_n,
                    shear_resolution_n=pads.shear_resolution_n,
                    fall_time_s=fall_time_s(config))


def fall_time_s(config: GripperConfig) -> float:
    """Return the time constant of the fastest first-order fall the force stage follows.

    The contact stage leads a moving setpoint by its rate, low-passed over
    ``setpoint_rate_time_constant_s`` (``tau``), through its servo gain: on a rigid contact
    the force runs ``T_L = K_stall Kv / k_d`` times that rate ahead of the setpoint (5.8 ms
    shipped). A fall ``F_sp = b + g exp(-t / T)`` then leaves the force ``g [exp(-t / T)
    (1 - T_L / (T - tau)) + T_L / (T - tau) exp(-t / tau)]`` above ``b``: never below it for
    ``T >= tau + T_L``.
    """
    from gripper_ros.core.control.contact_force import ContactForceController
    tuning = config.force.contact_aware
    stage = ContactForceController(config.plant, tuning, config.force.sample_time_s).record[0]
    lead_s = stage['stall_force_per_volt_n'] * stage['cap_kv'] / stage['cap_k']
    return tuning.setpoint_rate_time_constant_s + lead_s


@numba.njit(cache=True)
def law_step(g, history, sums, grid, t_ns, shear_n, displacement_m, force_n, plan, position_m):
    """Take one sample of the pads (mean shear, mean displacement), the grip and the finger.

    The finger's position gives the contact's stiffness (how fast 24 V raises the grip).
    ``history`` (4 x window + 1) keeps the last displacements, shears, forces as the shear
    channel reads them and forces as given; ``plan`` the arm's announced breakpoints
    (:func:`plan_announce`). Returns the force setpoint.
    """
    measured_n = force_n
    _contact(g, measured_n, position_m)
    n = history.shape[1]
    head = g.head
    old = (head + 1) % n
    history[3, head] = force_n
    delayed = history[3, (head - g.normal_delay) % n] if g.filled > g.normal_delay else \
        history[3, (head - g.filled) % n]
    if g.normal_primed:
        g.normal_filtered += g.normal_alpha * (delayed - g.normal_filtered)
    else:
        g.normal_filtered = delayed
        g.normal_primed = 1
    force_n = g.normal_filtered
    history[0, head] = displacement_m
    history[1, head] = shear_n
    history[2, head] = force_n
    g.head = old
    if g.filled < n:
        g.filled += 1
    load_n = 2.0 * shear_n if shear_n > 0.0 else 0.0
    grip_n = force_n if force_n > 0.0 else 0.0
    planned = g.plan_count > 0
    speed = 0.0
    bare = False
    if g.filled == n:
        # what the pads' own shear explains of the displacement (Cattaneo-Mindlin at the
        # friction believed) is not a slip: a load that jumps moves the object that far
        # the friction believed, but never less than the pads are seen to carry stuck
        grip_old = history[2, old] if history[2, old] > 0.0 else 0.0
        mu = g.mu_est / g.mu_safety
        for carried in (shear_n / grip_n if grip_n > 0.0 else 0.0,
                        history[1, old] / grip_old if grip_old > 0.0 else 0.0):
            if STUCK_HEADROOM * carried > mu:
                mu = STUCK_HEADROOM * carried
        k_t = g.tangential_stiffness_n_per_m
        sheared = presliding_m(shear_n, grip_n, mu, k_t) - presliding_m(
            history[1, old], grip_old, mu, k_t)
        moved = displacement_m - history[0, old]
        speed = (moved - sheared) / ((n - 1) * g.dt_s)
        # the object runs down the pads and they carry nothing of it: no friction holds it
        # (it moves further than the pads' whole partial slip at the most friction expected)
        bare = grip_n > 0.0 and shear_n <= g.shear_floor_n and \
            (k_t <= 0.0 or moved > 1.5 * grid[-1] * grip_n / k_t)
    felt = shear_n / grip_n if grip_n > 0.0 else 0.0
    # a slip: the object runs down the pads while they carry near all friction gives (a load
    # that jumps moves it fast too, but within the pads' shear, at a small Q / F)
    reference = g.mu_at_slip if g.slipping else g.mu_est
    if speed > g.slip_speed_mps and (felt >= SLIP_SHARE * reference or bare):
        if not g.slipping:
            estimated_before = g.estimated == 1 or g.slips > 0
            g.slips += 1
            g.mu_at_slip = g.mu_est
            g.slide_mu = felt
            if g.estimated and g.mu_est < g.mu_ceiling:
                g.mu_ceiling = g.mu_est
            if felt > g.mu_bound:
                g.mu_bound = felt
            g.estimated = 0                            # measure it again once it sticks
            # kinetic friction, a lower bound of mu_s, read as the slip is seen (later
            # samples of the slip lag the grip's rise and would read less); it replaces the
            # conservative start, which it betters
            if felt < g.mu_est or not estimated_before:
                g.mu_est = felt if felt > grid[0] else grid[0]
        g.slipping = 1
        g.quiet = 0
        if grip_n >= SATURATED * g.max_force_n:
            # at its most, the grip either slows the slide (kinetic friction beyond the load:
            # it stops, and static friction holds it) or it does not: an overload
            # (its speed measured over a window wholly at the most, then overload_samples on)
            g.slipping_saturated += 1
            if g.slipping_saturated == g.window:
                g.saturated_speed_mps = speed
            elif g.slipping_saturated >= g.window + g.overload_samples:
                if speed >= g.saturated_speed_mps:
                    g.slide_not_slowing = 1
                else:
                    g.slipping_saturated = 0           # slowing: watch again from here
        g.count = 0
        for j in range(sums.shape[1]):
            sums[0, j] = 0.0
            sums[1, j] = 0.0
    elif g.slipping:
        g.quiet += 1
        if g.quiet >= g.rest:
            g.slipping = 0
            g.slipping_saturated = 0
            if planned:
                # stuck again: mu_s is at least what the pads were read to carry (the most
                # Q / F before the slip began), not only the kinetic friction the slide read
                floor = g.mu_safety * g.mu_carried
                if floor > g.mu_ceiling:
                    floor = g.mu_ceiling
                if floor > g.mu_est:
                    g.mu_est = floor
    elif grip_n > 0.0 and load_n > 0.0:
        g.count += 1
        best, lo, hi = -1, math.inf, 0.0
        for j in range(grid.shape[0]):
            e = displacement_m - presliding_m(shear_n, grip_n, grid[j],
                                              g.tangential_stiffness_n_per_m)
            sums[0, j] += e
            sums[1, j] += e * e
            mean = sums[0, j] / g.count
            var = sums[1, j] / g.count - mean * mean
            if var < lo:
                lo, best = var, j
            if var > hi:
                hi = var
        if g.count >= g.min_samples and 0 < best < grid.shape[0] - 1 and \
                hi - lo > g.separation and \
                _distinct(sums, g.count, best, g.separation / SEPARATION_NOISES):
            # a fit below what a slip showed the pads carrying is wrong: mu_s >= mu_k >= it;
            # once measured, only a slip lowers the estimate (a later fit that drifts down
            # without one has seen an undetected creep, not less friction)
            least = g.mu_bound
            if planned and g.mu_carried > least:
                least = g.mu_carried                   # mu_s >= what the pads carried stuck
            fitted = g.mu_safety * (grid[best] if grid[best] > least else least)
            if fitted > g.mu_ceiling:                  # it slipped there before
                fitted = g.mu_ceiling
            if not g.estimated or fitted > g.mu_est:
                g.mu_est = fitted
            g.estimated = 1
    if not g.slipping and grip_n >= g.touch_force_n and shear_n > g.shear_floor_n:
        # stuck, a pad carries at most mu_s F: so does the channel's reading of both
        carried = (shear_n - g.shear_floor_n) / grip_n
        if carried > g.mu_carried:
            g.mu_carried = carried
    first_load = load_n > 0.0 and g.loaded_ns == -1
    # Not yet measured: the grip relaxes (at the release rate) towards the least friction's
    # grip; the incipient slip it brings on is what measures mu. After a slip it relaxes no
    # further than the friction that slip showed.
    mu = g.mu_est if g.estimated or g.slipping or g.slips > 0 or load_n == 0.0 else grid[-1]
    # judged at the friction the pads showed: the fit itself while stuck (static), what a
    # slip carried while it slides (kinetic)
    mu_seen = g.mu_est / g.mu_safety if g.estimated else g.mu_est
    need_n = load_n / (2.0 * mu_seen)
    # an announced motion: the load it will bring, from the mass the pads' load shows, met
    # as early as 24 V needs to raise the grip there; a lift of an object not yet weighed,
    # with the most 24 V gives, until the pads have read its weight
    margin = ANNOUNCED_MARGIN if planned and ANNOUNCED_MARGIN < g.k_margin else g.k_margin
    ahead = load_n
    pregrip = False
    g.lead_s = 0.0
    if planned:
        ahead = load_n * plan_load_ratio(g, plan, t_ns, load_n, measured_n, margin, mu)
        if g.loaded_ns == -1 and not first_load:
            lift_ns = _lift_coming(g, plan, t_ns, measured_n)
            if lift_ns != -1:
                until_ns = lift_ns + g.channel_settle_ns + round(g.normal_delay * g.dt_s * 1e9)
                if until_ns > g.pregrip_until_ns:
                    g.pregrip_until_ns = until_ns
        elif first_load and t_ns < g.pregrip_until_ns:
            g.pregrip_until_ns = t_ns + g.channel_settle_ns     # read within the band then
        pregrip = t_ns < g.pregrip_until_ns
    if first_load:
        g.loaded_ns = t_ns
    setpoint = margin * ahead / (2.0 * mu)
    near_top = not planned and (g.estimated or g.slips > 0) and \
        setpoint * TOP_RESERVE > g.max_force_n      # what it needs, not where it relaxes from
    if setpoint < g.touch_force_n:
        setpoint = g.touch_force_n                     # never below the touch
    rate = g.release_rate_n_per_s
    if g.force_setpoint_n < rate * RELEASE_TIME_S:
        rate = g.force_setpoint_n / RELEASE_TIME_S     # a light grip in proportion
    lowest = g.force_setpoint_n - rate * g.dt_s
    if planned:
        # the load to come is known: the grip falls at once to what the friction believed
        # needs for it, and only below that (to find the friction) at the release rate
        believed = margin * ahead / (2.0 * g.mu_est)
        if believed < setpoint:
            believed = setpoint
        if measured_n < (1.0 - g.settle_band) * g.force_setpoint_n and lowest < believed:
            # the force stage has not caught up with the grip asked (it leads a fall): no
            # release below what the friction believed needs until it has
            lowest = believed if believed < g.force_setpoint_n else g.force_setpoint_n
        fall = g.force_setpoint_n - (g.force_setpoint_n - believed) * g.dt_s / g.fall_time_s
        if fall < lowest:
            lowest = fall
    if g.slipping:
        lowest = g.force_setpoint_n                    # a slip never lowers the grip
    if setpoint < lowest:
        setpoint = lowest                              # let go slowly, as a hand does
    if near_top or pregrip or (g.slipping and g.slide_mu < grid[0]):
        setpoint = g.max_force_n                       # (a slide the pads read no friction of)
    if setpoint > g.max_force_n:
        setpoint = g.max_force_n
    if g.overload_ns == -1 and ((g.estimated and need_n > g.max_force_n) or
                                g.slide_not_slowing):
        g.overload_ns = t_ns
        g.overload_need_n = need_n
        # a slide: the friction it was read to carry, which may be below the grid's least
        g.overload_mu = g.slide_mu if g.slide_not_slowing and g.slide_mu < mu_seen else mu_seen
    g.force_setpoint_n = setpoint
    return setpoint


@numba.njit(cache=True)
def _contact(g, force_n, position_m):
    """Estimate the contact's stiffness: the force gained since the first touch over the travel.

    A rigid object stops the finger dead (no travel: ``inf``); the estimate is taken once the
    grip has gained half the touch force, so that a sensor's noise does not make it.
    """
    if not (force_n > 0.0) or math.isnan(position_m):
        return
    if math.isnan(g.contact_position_m):
        g.contact_position_m = position_m
        g.contact_force_n = force_n
        return
    travel = position_m - g.contact_position_m
    gained = force_n - g.contact_force_n
    if travel > 0.0 and gained >= 0.5 * g.touch_force_n:
        g.stiffness_n_per_m = gained / travel
        _most_lead(g)


@face_kernel(GRIP_DTYPE)
@numba.njit(cache=True)
def _most_lead(g):
    """Bound every lead on this contact: the rise from nothing to the most (``most_lead_ns``).

    The electrical rise's log is at most ln(1 / band), the travel's at most the whole 24 V
    force over k: a breakpoint further ahead needs nothing yet.
    """
    g = as_record(g)
    t = g.electrical_time_s * math.log(1.0 / g.settle_band) + 2.0 * g.dt_s
    if g.stiffness_n_per_m < math.inf and g.reflected_mass_kg > 0.0:
        t += 2.0 * math.sqrt(g.reflected_mass_kg / g.stiffness_n_per_m)
    g.most_lead_ns = round(t * 1e9)


@numba.njit(cache=True)
def rise_time_s(g, from_n, to_n):
    """Return the least time 24 V takes to raise the grip from ``from_n`` to ``to_n``.

    To within the settle band of it (of the most 24 V holds at the most). Two bounds, the
    longer: the motor's current, and with it a stalled motor's force, rises no faster than
    first order towards the 24 V stall force with the time constant L / R; on a contact of
    stiffness k the finger must travel the rise over k, as the motor's inertia seen through
    the screw (``reflected_mass_kg``) pushed by at most that force, accelerating then braking.
    """
    top = g.max_force_n
    goal = (to_n if to_n < top else top) * (1.0 - g.settle_band)
    if goal <= from_n:
        return 0.0
    t = 0.0
    if g.electrical_time_s > 0.0:
        t = g.electrical_time_s * math.log((top - from_n) / (top - goal))
    if g.stiffness_n_per_m < math.inf and g.reflected_mass_kg > 0.0:
        travel = 2.0 * math.sqrt((goal - from_n) * g.reflected_mass_kg /
                                 (g.stiffness_n_per_m * top))
        if travel > t:
            t = travel
    return t


@numba.njit(cache=True, inline='always')
def _lead_ns(g, from_n, to_n):
    """Return how long before a load comes its grip must be asked for: the rise, two samples.

    The setpoint acts from the next sample on, and the load's instant lies between samples.
    """
    return round((rise_time_s(g, from_n, to_n) + 2.0 * g.dt_s) * 1e9)


@numba.njit(cache=True)
def _lift_coming(g, plan, t_ns, force_n):
    """Return the instant the arm lifts the object, not yet weighed, if within the rise, or -1.

    The pads carry nothing yet, so nothing tells its weight: up to what 24 V holds may come,
    and the grip goes to the most from the lead of that rise on (:func:`rise_time_s`). The
    lift's instant is the plan's next breakpoint; once past, its weight reaches the law
    through the shear channel's latency and settling.
    """
    after_ns = g.channel_settle_ns + round(g.normal_delay * g.dt_s * 1e9)
    for i in range(g.plan_count):
        d = plan[i].t_ns - t_ns
        if d > g.most_lead_ns or (d > 0 and d > _lead_ns(g, force_n, g.max_force_n)):
            return -1
        if d >= -after_ns:
            return plan[i].t_ns
    return -1


@numba.njit(cache=True)
def _planned_accel(g, plan, t_ns):
    """Return the announced acceleration at ``t_ns`` and the index of the next breakpoint."""
    a = 0.0
    i = 0
    while i < g.plan_count and plan[i].t_ns <= t_ns:
        a = plan[i].accel_mps2
        i += 1
    return a, i


@numba.njit(cache=True)
def plan_range(g, plan, from_ns, to_ns):
    """Return the least and the most announced acceleration over ``[from_ns, to_ns]``."""
    a, i = _planned_accel(g, plan, from_ns)
    lo = a
    hi = a
    while i < g.plan_count and plan[i].t_ns <= to_ns:
        v = plan[i].accel_mps2
        if v < lo:
            lo = v
        if v > hi:
            hi = v
        i += 1
    return lo, hi


@numba.njit(cache=True)
def plan_load_ratio(g, plan, t_ns, load_n, force_n, margin, mu):
    """Return the most load the plan brings, whose grip must rise from now on, over the load read.

    The pads' shear reads ``m (g + a)`` through the channel's latency and bandwidth: the
    announced ``g + a`` passed through the same (``plan_filtered``) gives the mass. A coming
    breakpoint counts once it is no further ahead than 24 V needs to raise the grip from
    ``force_n`` to what it needs (``margin m (g + a) / (2 mu)``, :func:`rise_time_s`); its
    lead is kept in ``lead_s``. A fall counts from its instant on. Once a tick.
    """
    a_read, _ = _planned_accel(g, plan, t_ns - round(g.normal_delay * g.dt_s * 1e9))
    floor = LEAST_SUPPORT * g.gravity_mps2
    read = g.gravity_mps2 + a_read
    if read < floor:
        read = floor
    if g.plan_primed:
        g.plan_filtered += g.normal_alpha * (read - g.plan_filtered)
    else:
        g.plan_filtered = read
        g.plan_primed = 1
    hi, i = _planned_accel(g, plan, t_ns)
    mass_kg = load_n / g.plan_filtered
    horizon_ns = t_ns + g.most_lead_ns
    while i < g.plan_count and plan[i].t_ns <= horizon_ns:
        a = plan[i].accel_mps2
        if a > hi:
            need_n = margin * mass_kg * (g.gravity_mps2 + a) / (2.0 * mu)
            lead_ns = _lead_ns(g, force_n, need_n)
            if plan[i].t_ns - t_ns <= lead_ns:
                hi = a
                g.lead_s = lead_ns * 1e-9
        i += 1
    coming = g.gravity_mps2 + hi
    return (coming if coming > floor else floor) / g.plan_filtered


@face_kernel(GRIP_DTYPE, PLAN_DTYPE, int, float)
@numba.njit(cache=True)
def plan_announce(g, plan, t_ns, accel_mps2):
    """Take the breakpoint (from ``t_ns`` on, ``accel_mps2``): it replaces the plan from there."""
    g = as_record(g)
    n = g.plan_count
    while n > 0 and plan[n - 1].t_ns >= t_ns:
        n -= 1
    if n == plan.shape[0]:                             # full: the oldest breakpoint goes
        for j in range(n - 1):
            plan[j].t_ns = plan[j + 1].t_ns
            plan[j].accel_mps2 = plan[j + 1].accel_mps2
        n -= 1
    plan[n].t_ns = t_ns
    plan[n].accel_mps2 = accel_mps2
    g.plan_count = n + 1


@numba.njit(cache=True)
def _distinct(sums, count, best, noise_var):
    """Tell whether the candidates ``NEIGHBOURS`` grid steps away fit measurably worse.

    Their residual variance must exceed the best's by ``NEIGHBOUR_SIGNIFICANCE`` times what
    the sensor's noise alone would give over ``count`` samples.
    """
    mean = sums[0, best] / count
    low = sums[1, best] / count - mean * mean
    for j in (best - NEIGHBOURS, best + NEIGHBOURS):
        if 0 <= j < sums.shape[1]:
            m = sums[0, j] / count
            if sums[1, j] / count - m * m - low < NEIGHBOUR_SIGNIFICANCE * noise_var / count:
                return False
    return True


ROW_FIELDS = ('t_ns', 'force_n', 'force_setpoint_n', 'load_n', 'capacity_n', 'slip_m',
              'shear_reading_n', 'displacement_reading_m', 'mu_est', 'state')
