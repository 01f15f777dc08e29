"""grip_study: the load-tracking grip, announced and not, against the fixed laws, over arm motions.

    ros2 run gripper_ros grip_study [--masses 0.2,0.5,1,2] [--frictions 0.4,0.6,0.9]
                                    [--unannounced-only] [--plot docs/grip_study.png] [--jobs N]
                                    [--instant-masses 0.5,1,1.5,2] [--instant-steps 3,4,5,6]
                                    [--instant-frictions 0.4,0.6,0.9] [--no-instant]
                                    [--plot-step docs/grip_step.png [--step-before CSV]]
                                    [--step-csv CSV]

Every object is grasped headless (the graph's supervisor and contact stage, compiled) and held
through each arm motion; its mass and pad friction (mu_k = 0.8 mu_s) are unknown to the
load-tracking grip, which the arm either tells its planned acceleration ahead of the motion
(announced, ``arm/planned_acceleration``) or not; the fixed laws are told the mass (true, or 25 %
low) with the configured mu_s. Per law, over the cases 24 V can hold at static friction
(m (g + A) <= 2 mu_s F_24V): losses, slip, the grip's mean margin over the slip limit m (g + a) /
(2 mu_s) while lifted (the mean of the cases' and the largest case's), and overload calls. The
cases beyond are counted apart, with how many were said to be overloaded and before the fall.

Then the instant steps: the whole weight m (g + A) lands on the pads at once (lift-off 0), the
load-tracking grip announced and not, each figure beside its bound: announced, the grip the
plan asks for before the lift (the most 24 V gives, the weight being unknown) against 24 V's
rise to it; unannounced, the least slip any grip that reacts gives (rising from the touch at
24 V the instant the weight lands, :func:`instant_slip_bound_m`). ``--plot-step`` draws force
and slip around one such step (2 kg, mu_s 0.6, 5 m/s^2), announced and not, beside the series
``--step-before`` holds (written by ``--step-csv`` with another build's core); either leaves
the studies out.
"""
from __future__ import annotations

import argparse
import math
import sys

from gripper_ros.apps.common import load_config_or_report, negative_option, with_values
from gripper_ros.core.config import ConfigError
from gripper_ros.core.runtime.engine import add_engine_arguments, options_problem
from gripper_ros.text import one_line
import numpy as np

PROFILES = (('static', 'step:0'), ('step 2', 'step:2'), ('step 5', 'step:5'),
            ('pick-and-place 3', 'pick-and-place:3'), ('pick-and-place 6', 'pick-and-place:6'),
            ('shake 3 @ 2 Hz', 'shake:3,2'))
"""The arm's motions of the study: (label, --profile text)."""
LAWS = (('load-tracking, announced', 'load_tracking', 1.0, True),
        ('load-tracking, unannounced', 'load_tracking', 1.0, False),
        ('friction, true mass', 'friction', 1.0, False),
        ('friction, mass 25 % low', 'friction', 0.75, False))
"""(label, law, declared mass / true mass, the arm announces its motion)."""
WIDTH_M = 0.05
KINETIC_SHARE = 0.8
LIFT_DELAY_S = 0.2
LIFT_DURATION_S = 1.2              # a pick-and-place: 0.4 s up, across, down
DEFAULT_LIFT_OFF_S = 0.1           # a hand's loading phase (Johansson and Westling 1984)
INSTANT_MASSES = '0.5,1,1.5,2'
INSTANT_FRICTIONS = '0.4,0.6,0.9'
INSTANT_STEPS = '3,4,5,6'
INSTANT_LAWS = LAWS[:2]
"""The load-tracking grip, announced and not: the laws of the instant steps."""
STEP_FIGURE = (2.0, 0.6, 5.0)
"""The figure's step: 2 kg at mu_s 0.6 through an instant 5 m/s^2 step (mass, mu_s, A)."""
STEP_WINDOW_S = (-0.01, 0.15)
"""The figure's window around the lift (s)."""
STEP_DECIMATE = 2
"""The figure keeps every this many force samples (0.2 ms)."""


def _floats(text: str, name: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(',')]
    except ValueError:
        raise ValueError(f'--{name} must be numbers separated by commas, got {text!r}') from None
    for v in values:
        if not (math.isfinite(v) and v > 0.0):
            raise ValueError(f'--{name} values must be finite and > 0, got {v!r}')
    return values


def _case(config, case: dict) -> dict:
    from gripper_ros.core.physics.hold import Lift, parse_profile
    from gripper_ros.studies.grip_runs import simulate_load_grip
    profile, accel, hz = parse_profile(case['profile'])
    lift = Lift(accel, LIFT_DELAY_S, LIFT_DURATION_S, profile, hz)
    run = simulate_load_grip(config, WIDTH_M, case['mass_kg'], case['mu_s'],
                             KINETIC_SHARE * case['mu_s'], lift, case['law'],
                             case['mass_kg'] * case['declared'],
                             stiffness_n_per_m=case.get('stiffness_n_per_m', 0.0),
                             damping_n_s_per_m=case.get('damping_n_s_per_m', 0.0),
                             announce=case['announce'])
    return {**case, 'outcome': run.outcome, 'slip_m': run.slip_m, 'lost_s': run.lost_s,
            'overload_s': run.overload_s, 'mean_margin': run.mean_margin,
            'max_margin': run.max_margin, 'peak_ratio': run.contact_peak_ratio,
            'within': holdable(config, case['mass_kg'], case['mu_s'], accel), 'note': run.note,
            'landed_force_n': run.landed_force_n}


def holdable(config, mass_kg: float, mu_s: float, accel_mps2: float) -> bool:
    """Tell whether 24 V holds ``mass_kg`` at static friction through ``accel_mps2`` upward.

    The load at its most, m (g + A), within the two pads' static capacity 2 mu_s F_24V.
    """
    return mass_kg * (config.plant.gravity_mps2 + accel_mps2) <= \
        2.0 * mu_s * config.plant.max_force_n


def study_cases(masses, frictions, stiffness_n_per_m=0.0, damping_n_s_per_m=0.0,
                laws=LAWS) -> list[dict]:
    """Every (law, mass, friction, profile) of the study, as keyword dicts."""
    return [{'label': label, 'law': law, 'declared': declared, 'announce': announce,
             'mass_kg': m, 'mu_s': mu, 'profile': text, 'profile_label': name,
             'stiffness_n_per_m': stiffness_n_per_m, 'damping_n_s_per_m': damping_n_s_per_m}
            for label, law, declared, announce in laws for m in masses for mu in frictions
            for name, text in PROFILES]


def instant_cases(masses, frictions, steps, laws=INSTANT_LAWS) -> list[dict]:
    """Every (law, mass, friction, step) of the instant steps, as keyword dicts."""
    return [{'label': label, 'law': law, 'declared': declared, 'announce': announce,
             'mass_kg': m, 'mu_s': mu, 'profile': f'step:{a:g}', 'profile_label': f'step {a:g}'}
            for label, law, declared, announce in laws for m in masses for mu in frictions
            for a in steps]


def instant_slip_bound_m(config, mass_kg: float, mu_s: float, mu_k: float,
                         accel_mps2: float) -> float:
    """Return the least slip of an instant step a grip that reacts can give (inf: lost).

    The weight ``W = m (g + A)`` lands on the touch ``F0``; the best reaction raises the grip
    at once, as fast as 24 V can, ``F(t) = F_24V - (F_24V - F0) exp(-t / tau)`` (tau = L / R,
    the stalled motor's current). The object slides against kinetic friction, ``m x'' = W -
    2 mu_k F(t)``: ``v(t) = -c t + b (1 - exp(-t / tau))`` with ``c = (2 mu_k F_24V - W) / m``
    and ``b = 2 mu_k (F_24V - F0) tau / m``, until ``v`` is 0 again, having slid ``x(t) =
    -c t^2 / 2 + b (t - tau (1 - exp(-t / tau)))``; it never stops for ``c <= 0``.
    """
    plant = config.plant
    top, f0 = plant.max_force_n, config.load_grip.touch_force_n
    tau = plant.inductance_h / plant.resistance_ohm
    weight = mass_kg * (plant.gravity_mps2 + accel_mps2)
    if weight <= 2.0 * mu_s * f0:
        return 0.0
    c = (2.0 * mu_k * top - weight) / mass_kg
    if c <= 0.0:
        return math.inf
    b = 2.0 * mu_k * (top - f0) * tau / mass_kg

    def speed(t):
        return -c * t + b * -math.expm1(-t / tau)

    lo, hi = tau, b / c + tau                       # v > 0 at tau, v < 0 past b / c
    while speed(lo) <= 0.0:
        lo *= 0.5
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if speed(mid) > 0.0 else (lo, mid)
    t = 0.5 * (lo + hi)
    return -0.5 * c * t * t + b * (t + tau * math.expm1(-t / tau))


def instant_bounds(config, rows: list[dict]) -> list[str]:
    """Return the instant steps' bounds, each beside the figure the study found."""
    plant = config.plant
    top, f0 = plant.max_force_n, config.load_grip.touch_force_n
    tau = plant.inductance_h / plant.resistance_ohm
    band = config.supervisor.force_settle_band_fraction
    rise_s = tau * math.log((top - f0) / (band * top))
    lead_s = rise_s + 2.0 * config.force.sample_time_s
    out = []
    announced = [r for r in rows if r['announce'] and r['within']]
    if announced:
        landed = min(r['landed_force_n'] for r in announced)
        hold = min(2.0 * r['mu_s'] * r['landed_force_n'] /
                   (r['mass_kg'] * (plant.gravity_mps2 + float(r['profile'][5:])))
                   for r in announced)
        out.append(f'announced: the weight is unknown until it lands, so the grip is the most, '
                   f'{top:.2f} N, asked for {lead_s * 1e3:.2f} ms before the lift (24 V raises '
                   f'the {f0:g} N touch to within {band:.0%} of it in {rise_s * 1e3:.2f} ms '
                   f'at least, L/R = {tau * 1e3:.3f} ms; two samples more); the grip as it '
                   f'landed: at least {landed:.2f} N (bound {(1 - band) * top:.2f} N), '
                   f'{hold:.2f}x the weight at static friction: slip 0 is the bound')
    unannounced = [r for r in rows if not r['announce'] and r['within']]
    if unannounced:
        bounds = [instant_slip_bound_m(config, r['mass_kg'], r['mu_s'],
                                       KINETIC_SHARE * r['mu_s'], float(r['profile'][5:]))
                  for r in unannounced]
        falls = sum(math.isinf(b) for b in bounds)
        held = [(b, r) for b, r in zip(bounds, unannounced) if math.isfinite(b)]
        worst_b, worst_r = max(held, key=lambda p: p[0]) if held else (math.nan, None)
        lost_beyond = sum(r['outcome'] == 'OBJECT_LOST'
                          for b, r in zip(bounds, unannounced) if math.isinf(b))
        out.append(f'unannounced: the least slip any grip that reacts gives (from the touch at '
                   f'24 V the instant the weight lands): at most {worst_b * 1e3:.3f} mm where '
                   f'kinetic friction at 24 V can stop it'
                   + (f' ({worst_r["mass_kg"]:g} kg, mu_s {worst_r["mu_s"]:g}, '
                      f'{worst_r["profile_label"]}: {worst_r["slip_m"] * 1e3:.3f} mm slid)'
                      if worst_r else '')
                   + f'; {falls} case(s) beyond it, m (g + A) > 2 mu_k x {top:.2f} N: lost once '
                   f'they slide ({lost_beyond} lost)')
    return out


def summarise(rows: list[dict], laws=LAWS) -> list[str]:
    """Return the study's table: a line per law, within what 24 V holds, then the cases beyond.

    ``margin mean``: the mean of the cases' mean margins; ``margin worst``: the largest case's.
    """
    out = [f'{"law":28s} {"cases":>5s} {"lost":>4s} {"refused":>7s} {"slip mm max":>11s} '
           f'{"margin mean":>11s} {"margin worst":>12s} {"overload said":>13s}']
    for label, *_ in laws:
        mine = [r for r in rows if r['label'] == label and r['within']]
        held = [r for r in mine if r['outcome'] in ('HOLDING', 'OBJECT_LOST')]
        lost = sum(r['outcome'] == 'OBJECT_LOST' for r in mine)
        refused = sum(r['outcome'] == 'REFUSED' for r in mine)
        kept = [r for r in held if r['outcome'] == 'HOLDING']
        slips = [r['slip_m'] * 1e3 for r in held]
        means = [r['mean_margin'] for r in kept if math.isfinite(r['mean_margin'])]
        said = sum(math.isfinite(r['overload_s']) for r in mine)
        out.append(f'{label:28s} {len(mine):5d} {lost:4d} {refused:7d} '
                   f'{max(slips, default=math.nan):11.3f} '
                   f'{sum(means) / len(means) if means else math.nan:11.3f} '
                   f'{max(means, default=math.nan):12.3f} {said:13d}')
    for label, law, _, _ in laws:
        if law != 'load_tracking':
            continue
        mine = [r for r in rows if r['label'] == label and r['within'] and
                r['outcome'] in ('HOLDING', 'OBJECT_LOST')]
        held = [r for r in mine if r['outcome'] == 'HOLDING']
        for what, key, among in (('slip', 'slip_m', mine),
                                 ('mean margin', 'mean_margin', held)):
            worst = max(among, key=lambda r: r[key], default=None)
            if worst is not None:
                out.append(f'{label}, largest {what}: {worst["mass_kg"]:g} kg, mu_s '
                           f'{worst["mu_s"]:g}, {worst["profile_label"]}: slip '
                           f'{worst["slip_m"] * 1e3:.3f} mm, margin mean '
                           f'{worst["mean_margin"]:.3f}')
    for label, law, _, _ in laws:
        if law != 'load_tracking':
            continue
        beyond = [r for r in rows if r['label'] == label and not r['within']]
        lost = [r for r in beyond if r['outcome'] == 'OBJECT_LOST']
        warned = [r for r in lost if math.isfinite(r['overload_s']) and
                  r['overload_s'] < r['lost_s']]
        said = sum(math.isfinite(r['overload_s']) for r in beyond)
        out.append(f'beyond 24 V at static friction ({label}): {len(beyond)} cases, '
                   f'{len(lost)} lost, {len(warned)} of them said overloaded before they fell; '
                   f'overload said in {said} of {len(beyond)}')
    return out


def fastest_grip_rise_s(config, stiffness_n_per_m: float, rise_n: float) -> float:
    """Return the least time in which 24 V adds ``rise_n`` of grip on a spring of that stiffness.

    The grip rises only as the finger compresses the object by ``rise_n / k``, and the finger
    moves as the motor's inertia seen through the screw, ``m_r``, driven by at most the 24 V stall
    force: accelerating then braking at ``F_24V / m_r`` covers it in ``2 sqrt(rise m_r / (k
    F_24V))`` (drag and the object's damping only add to it).
    """
    return 2.0 * math.sqrt(rise_n * config.plant.reflected_mass_kg /
                           (stiffness_n_per_m * config.plant.max_force_n))


def soft_object_bound(config, masses, frictions, stiffness_n_per_m: float) -> str:
    """Return the line that says how fast 24 V can raise the grip on this object."""
    g = config.plant.gravity_mps2
    need_n = min(config.load_grip.grip_margin * max(masses) * g / (2.0 * min(frictions)),
                 config.plant.max_force_n)
    rise_n = need_n - config.load_grip.touch_force_n
    return (f'on {stiffness_n_per_m:g} N/m: from the {config.load_grip.touch_force_n:g} N touch '
            f'to {need_n:.2f} N (k m g / (2 mu_s), the heaviest, least friction) takes at least '
            f'{fastest_grip_rise_s(config, stiffness_n_per_m, rise_n):.3f} s at '
            f'{config.plant.voltage_limit_v:g} V ({rise_n / stiffness_n_per_m * 1e3:.2f} mm of '
            f'travel, finger mass {config.plant.reflected_mass_kg:.0f} kg through the screw); the '
            f'lift-off hands the weight over in {config.contact.lift_off_s:g} s')


def plot_pick_and_place(config, path: str, mass_kg: float = 0.6, mu_s: float = 0.3) -> None:
    """Draw grip, load and slip over a pick-and-place: load-tracking and the wrong-mass law."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from gripper_ros.core.physics.hold import Lift
    from gripper_ros.studies.grip_runs import simulate_load_grip
    from gripper_ros.wire import LiftProfile
    lift = Lift(3.0, LIFT_DELAY_S, LIFT_DURATION_S, LiftProfile.PICK_AND_PLACE)
    fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    reference = None
    for law, declared, announce, name in (
            ('load_tracking', 1.0, True, 'load-tracking, announced'),
            ('load_tracking', 1.0, False, 'load-tracking, unannounced'),
            ('friction', 0.75, False, 'friction law, mass 25 % low')):
        run = simulate_load_grip(config, WIDTH_M, mass_kg, mu_s, KINETIC_SHARE * mu_s, lift,
                                 law, mass_kg * declared, decimate=10, announce=announce)
        rows = run.rows
        t = (rows[:, 0] - rows[0, 0]) * 1e-9
        limit = rows[:, 3] / (2.0 * mu_s)
        axes[0].plot(t, rows[:, 1], label=f'{name}: grip F')
        axes[1].plot(t, rows[:, 1] / limit.clip(min=1e-9), label=name)
        axes[2].plot(t, rows[:, 5] * 1e3, label=name)
        if reference is None:                          # the load-tracking run lasts it all
            reference = (t, limit, rows[:, 3])
    t, limit, load = reference
    axes[0].plot(t, limit, 'k--', label='slip limit m (g + a) / (2 mu_s)')
    axes[0].plot(t, load, 'k:', label='load m (g + a)')
    axes[0].set_ylabel('N')
    axes[1].set_ylabel('grip / slip limit')
    axes[1].set_ylim(0.0, 3.0)
    axes[1].axhline(1.0, color='k', lw=0.5)
    axes[2].set_ylabel('slip mm')
    axes[2].set_xlabel('s after HOLDING')
    for ax in axes:
        ax.legend(fontsize=7)
    fig.suptitle(f'pick-and-place +-3 m/s^2, {mass_kg:g} kg, mu_s {mu_s:g}')
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


STEP_COLUMNS = ('announced', 't_ms', 'force_n', 'force_setpoint_n', 'load_n', 'slip_mm')
"""The step figure's series, as ``--step-csv`` writes them (t from the lift)."""


def step_series(config) -> np.ndarray:
    """Return the figure's step, announced and not, as rows of :data:`STEP_COLUMNS`."""
    from gripper_ros.apps.common import with_values
    from gripper_ros.core.physics.hold import Lift
    from gripper_ros.studies.grip_runs import simulate_load_grip
    from gripper_ros.wire import LiftProfile
    mass, mu_s, accel = STEP_FIGURE
    config = with_values(config, {'contact.lift_off_s': 0.0})
    lift = Lift(accel, LIFT_DELAY_S, LIFT_DURATION_S, LiftProfile.STEP)
    out = []
    for announce in (True, False):
        rows = simulate_load_grip(config, WIDTH_M, mass, mu_s, KINETIC_SHARE * mu_s, lift,
                                  'load_tracking', decimate=1, announce=announce).rows
        t_ms = (rows[:, 0] - rows[0, 0]) * 1e-6 - LIFT_DELAY_S * 1e3
        keep = np.flatnonzero((t_ms >= STEP_WINDOW_S[0] * 1e3) &
                              (t_ms <= STEP_WINDOW_S[1] * 1e3))[::STEP_DECIMATE]
        out.append(np.column_stack([np.full(keep.size, float(announce)), t_ms[keep],
                                    rows[keep, 1], rows[keep, 2], rows[keep, 3],
                                    rows[keep, 5] * 1e3]))
    return np.concatenate(out)


def write_step_csv(series: np.ndarray, path: str) -> None:
    """Write the step's series (:data:`STEP_COLUMNS`) as CSV."""
    np.savetxt(path, series, fmt='%.6g', delimiter=',', header=','.join(STEP_COLUMNS),
               comments='')


def plot_step(series: np.ndarray, path: str, before: np.ndarray | None = None) -> None:
    """Draw force and slip around the step, announced and not, this build beside ``before``."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    mass, mu_s, accel = STEP_FIGURE
    fig, axes = plt.subplots(3, 1, figsize=(8, 9))
    styles = {True: 'tab:blue', False: 'tab:orange'}
    for data, when, line in ((before, 'before', '--'), (series, 'now', '-')):
        if data is None:
            continue
        for announce in (True, False):
            d = data[data[:, 0] == float(announce)]
            name = f'{"announced" if announce else "unannounced"}, {when}'
            for ax in axes[:2]:
                ax.plot(d[:, 1], d[:, 2], line, color=styles[announce],
                        label=f'{name}: grip F')
            axes[2].plot(d[:, 1], d[:, 5], line, color=styles[announce], label=name)
    d = series[series[:, 0] == 1.0]
    for ax in axes[:2]:
        ax.plot(d[:, 1], d[:, 4] / (2.0 * mu_s), 'k:', label='slip limit m (g + a) / (2 mu_s)')
        ax.set_ylabel('N')
    axes[1].set_xlim(-2.0, 10.0)
    axes[1].set_title('the first 10 ms', fontsize=9)
    axes[2].set_ylabel('slip mm')
    for ax in axes:
        ax.axvline(0.0, color='k', lw=0.5)
        ax.set_xlabel('ms after the lift')
        ax.legend(fontsize=7)
    fig.suptitle(f'instant step {accel:g} m/s^2, {mass:g} kg, mu_s {mu_s:g} '
                 f'(mu_k {KINETIC_SHARE * mu_s:g}), lift-off 0')
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog='grip_study', description=__doc__.splitlines()[0])
    p.add_argument('--masses', default='0.2,0.5,1,2', help='kg, comma-separated')
    p.add_argument('--frictions', default='0.4,0.6,0.9', help='mu_s, comma-separated')
    p.add_argument('--unannounced-only', action='store_true',
                   help='run the load-tracking grip only as the arm moves without notice')
    p.add_argument('--stiffness', type=float, default=0.0,
                   help='object contact stiffness N/m (0 = rigid)')
    p.add_argument('--damping', type=float, default=0.0, help='object contact damping N s/m')
    p.add_argument('--lift-off-s', type=float, default=DEFAULT_LIFT_OFF_S,
                   help='the arm takes the weight off the support over this long '
                        f'(default {DEFAULT_LIFT_OFF_S:g} s; 0 = at once)')
    p.add_argument('--plot', default=None, help='write the pick-and-place figure here (PNG)')
    p.add_argument('--instant-masses', default=INSTANT_MASSES,
                   help=f'kg of the instant steps (default {INSTANT_MASSES})')
    p.add_argument('--instant-frictions', default=INSTANT_FRICTIONS,
                   help=f'mu_s of the instant steps (default {INSTANT_FRICTIONS})')
    p.add_argument('--instant-steps', default=INSTANT_STEPS,
                   help=f'm/s^2 of the instant steps (default {INSTANT_STEPS})')
    p.add_argument('--no-instant', action='store_true', help='leave the instant steps out')
    p.add_argument('--plot-step', default=None,
                   help='write the figure of one instant step, announced and not (PNG), and '
                        'leave the studies out')
    p.add_argument('--step-before', default=None, metavar='CSV',
                   help="draw this series (--step-csv's) beside the step, as before")
    p.add_argument('--step-csv', default=None, metavar='CSV',
                   help="write the step's series (CSV) and leave the studies out")
    add_engine_arguments(p)
    p.add_argument('--config', default=None, help='YAML parameter file (default: installed)')
    args = p.parse_args(argv)
    try:
        masses = _floats(args.masses, 'masses')
        frictions = _floats(args.frictions, 'frictions')
        instant = [] if args.no_instant else [
            _floats(getattr(args, f'instant_{name}'), f'instant-{name}')
            for name in ('masses', 'frictions', 'steps')]
    except ValueError as exc:
        print(f'grip_study: {exc}', file=sys.stderr)
        return 2
    negative = negative_option(args, ('stiffness', 'damping', 'lift_off_s'))
    if negative:
        print(f'grip_study: {negative}', file=sys.stderr)
        return 2
    if options_problem(args.jobs, args.scheduler):
        print(f'grip_study: {options_problem(args.jobs, args.scheduler)}', file=sys.stderr)
        return 2
    config = load_config_or_report('grip_study', args.config)
    if config is None:
        return 2
    try:
        config = with_values(config, {'contact.lift_off_s': args.lift_off_s})
    except ConfigError as exc:
        print(f'grip_study: --lift-off-s: {exc}', file=sys.stderr)
        return 2
    import functools
    from gripper_ros.core.runtime.headless import map_cases
    if args.step_csv:
        write_step_csv(step_series(config), args.step_csv)
        print(f'step series: {args.step_csv}')
        return 0
    if args.plot_step:
        before = None
        if args.step_before:
            try:
                before = np.loadtxt(args.step_before, delimiter=',', skiprows=1, ndmin=2)
            except (OSError, ValueError) as exc:
                print(f'grip_study: --step-before: {one_line(exc)}', file=sys.stderr)
                return 2
            if before.shape[1] != len(STEP_COLUMNS):
                print(f'grip_study: --step-before: {len(STEP_COLUMNS)} columns expected '
                      f'({",".join(STEP_COLUMNS)}), got {before.shape[1]}', file=sys.stderr)
                return 2
        series = step_series(config)
        plot_step(series, args.plot_step, before)
        for announce in (True, False):
            d = series[series[:, 0] == float(announce)]
            at = d[np.flatnonzero(d[:, 4] > 0.0)[0]]          # the weight on the pads
            print(f'{"announced" if announce else "unannounced"}: grip {at[2]:.2f} N as the '
                  f'weight lands (slip limit {d[-1, 4] / (2.0 * STEP_FIGURE[1]):.2f} N), slip '
                  f'{d[-1, 5]:.3f} mm')
        print(f'figure: {args.plot_step}')
        return 0
    laws = tuple(law for law in LAWS if not (args.unannounced_only and law[3]))
    rows = map_cases(functools.partial(_case, config),
                     study_cases(masses, frictions, args.stiffness, args.damping, laws),
                     jobs=args.jobs, scheduler=args.scheduler)
    print(f'{len(rows)} grasps: {WIDTH_M * 1e3:g} mm objects of {args.masses} kg, mu_s '
          f'{args.frictions} (mu_k = {KINETIC_SHARE:g} mu_s); arm: '
          + ', '.join(name for name, _ in PROFILES) + '; ' +
          (f'{args.stiffness:g} N/m, {args.damping:g} N s/m' if args.stiffness else 'rigid') +
          f'; lift-off {config.contact.lift_off_s:g} s')
    for line in summarise(rows, laws):
        print(line)
    if args.stiffness > 0.0:
        print(soft_object_bound(config, masses, frictions, args.stiffness))
    if instant:
        instant_config = with_values(config, {'contact.lift_off_s': 0.0})
        instant_laws = tuple(law for law in INSTANT_LAWS
                             if not (args.unannounced_only and law[3]))
        rows = map_cases(functools.partial(_case, instant_config),
                         instant_cases(*instant, laws=instant_laws),
                         jobs=args.jobs, scheduler=args.scheduler)
        print(f'{len(rows)} instant steps: the whole weight at once (lift-off 0); '
              f'{WIDTH_M * 1e3:g} mm objects of {args.instant_masses} kg, mu_s '
              f'{args.instant_frictions} (mu_k = {KINETIC_SHARE:g} mu_s); arm: step '
              f'{args.instant_steps} m/s^2')
        for line in summarise(rows, instant_laws) + instant_bounds(instant_config, rows):
            print(line)
    if args.plot:
        plot_pick_and_place(config, args.plot)
        print(f'figure: {args.plot}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
