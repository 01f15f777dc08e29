"""grip_study: the load-tracking grip, announced and not, against the fixed laws, over arm motions.

    ros2 run gripper_ros grip_study [--masses 0.2,0.5,1,2] [--frictions 0.4,0.6,0.9]
                                    [--unannounced-only] [--plot docs/grip_study.png] [--jobs N]

Every object is grasped headless (the graph's supervisor and contact stage, compiled) and held
through each arm motion; its mass and pad friction (mu_k = 0.8 mu_s) are unknown to the
load-tracking grip, which the arm either tells its planned acceleration ahead of the motion
(announced, ``arm/planned_acceleration``) or not; the fixed laws are told the mass (true, or 25 %
low) with the configured mu_s. Per law, over the cases 24 V can hold at static friction
(m (g + A) <= 2 mu_s F_24V): losses, slip, the grip's mean margin over the slip limit m (g + a) /
(2 mu_s) while lifted (the mean of the cases' and the largest case's), and overload calls. The
cases beyond are counted apart, with how many were said to be overloaded and before the fall.
"""
from __future__ import annotations

import argparse
import math
import sys

from gripper_ros.apps.common import load_config_or_report, negative_option, with_values
from gripper_ros.core.config import ConfigError
from gripper_ros.core.runtime.engine import add_engine_arguments, options_problem

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
            'within': holdable(config, case['mass_kg'], case['mu_s'], accel), 'note': run.note}


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
    add_engine_arguments(p)
    p.add_argument('--config', default=None, help='YAML parameter file (default: installed)')
    args = p.parse_args(argv)
    try:
        masses = _floats(args.masses, 'masses')
        frictions = _floats(args.frictions, 'frictions')
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
    if args.plot:
        plot_pick_and_place(config, args.plot)
        print(f'figure: {args.plot}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
