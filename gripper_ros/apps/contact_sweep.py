"""contact_sweep: peak contact force over many objects, beside the approach-time floor.

    ros2 run gripper_ros contact_sweep [--plot FILE.png] [--json] [--compliant]
                                      [--force-controller contact_aware|pi|mpc_pi]

Each grasp runs the node graph's logic without ROS (:mod:`gripper_ros.core.headless`, bit-identical
to the graph). For every object it reports the outcome, the peak contact force (including
between samples) as a multiple of the setpoint, the time from request to a steady hold and the
floors for that time: the minimum time to bring the finger from fully open to rest at the
object's face under +-24 V (:mod:`gripper_ros.apps.position_limit`), and the minimum time to reach
the face at all (24 V throughout). A rigid object stops the finger dead (the paper's contact
model), so a grasp that touches at a few mm/s may beat the first floor, never the second.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict, dataclass

from gripper_ros.core.config import ConfigError, load_config

WIDTHS_M = (0.005, 0.02, 0.05, 0.08, 0.11, 0.14)
MASSES_KG = (0.1, 0.5, 1.0, 2.0, 3.0)
COMPLIANT_OBJECTS = (('stiff', 1.0e5, 50.0), ('soft', 1.0e3, 5.0))   # name, k N/m, c N s/m


@dataclass
class SweepRow:
    width_m: float
    mass_kg: float
    contact: str
    outcome: str
    force_setpoint_n: float
    peak_force_n: float
    peak_ratio: float
    time_to_hold_s: float
    approach_floor_s: float      # minimum time to bring the finger to rest at the face (10 ms)
    arrival_floor_s: float       # minimum time to reach the face at all (full voltage throughout)


def arrival_floors_s(config, setpoints_m, dt_s: float = 1.0e-4) -> list[float]:
    """Minimum time for the finger to reach each of ``setpoints_m`` from rest, at any speed:
    full voltage all the way (one run, read at each crossing). A true lower bound for any grasp
    under the limit; a rigid object that stops the finger dead (the paper's contact) lets a
    grasp beat the at-rest floor, never this."""
    from gripper_ros.core.controllers import make_plant
    plant = make_plant(config)
    limit = config.plant.voltage_limit_v
    sample = plant.sample()
    floors = {}
    for setpoint_m in sorted(set(setpoints_m)):
        while sample.position_m < setpoint_m:
            sample = plant.step(limit, dt_s)
        floors[setpoint_m] = sample.t_s
    return [floors[s] for s in setpoints_m]


def sweep(config, widths=WIDTHS_M, masses=MASSES_KG, compliant: bool = False,
          force_controller: str | None = None) -> list[SweepRow]:
    from gripper_ros.core.supervisor import Outcome, RequestError
    from gripper_ros.core.headless import simulate_grasp
    from gripper_ros.apps.position_limit import minimum_time_floor

    floors = {w: minimum_time_floor(config, config.plant.max_travel_m - w,
                                    config.position.sample_time_s).rest_time_s for w in widths}
    arrivals = dict(zip(widths, arrival_floors_s(
        config, [config.plant.max_travel_m - w for w in widths])))
    kinds = {} if force_controller is None else {'force_controller': force_controller}
    objects = [('rigid', 0.0, 0.0)] + (list(COMPLIANT_OBJECTS) if compliant else [])
    rows = []
    for name, k, c in objects:
        for w in widths:
            for m in masses:
                try:
                    g = simulate_grasp(config, w, m, stiffness_n_per_m=k, damping_n_s_per_m=c,
                                       **kinds)
                except RequestError:
                    continue            # beyond what 24 V can hold: refused, not swept
                held = g.outcome is Outcome.HOLDING
                rows.append(SweepRow(w, m, name, g.outcome.name, g.force_setpoint_n,
                                     g.peak_contact_force_n,
                                     g.peak_contact_force_n / g.force_setpoint_n,
                                     g.duration_s if held else math.inf, floors[w],
                                     arrivals[w]))
    return rows


def format_rows(rows: list[SweepRow]) -> str:
    lines = [f'{"width mm":>8s} {"mass kg":>7s} {"contact":>7s} {"outcome":>9s} {"F_sp N":>7s} '
             f'{"peak N":>7s} {"peak/F_sp":>9s} {"hold s":>7s} {"rest s":>7s} {"reach s":>7s}']
    for r in rows:
        lines.append(f'{r.width_m * 1e3:8.0f} {r.mass_kg:7.2f} {r.contact:>7s} {r.outcome:>9s} '
                     f'{r.force_setpoint_n:7.3f} {r.peak_force_n:7.3f} {r.peak_ratio:9.3f} '
                     f'{r.time_to_hold_s:7.2f} {r.approach_floor_s:7.2f} '
                     f'{r.arrival_floor_s:7.2f}')
    lines.append('rest s: minimum time to bring the finger to rest at the face under +-24 V '
                 '(10 ms samples); reach s: minimum time to reach it at any speed (24 V '
                 'throughout)')
    return '\n'.join(lines)


def plot(rows: list[SweepRow], path: str) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    for contact in sorted({r.contact for r in rows}):
        sel = [r for r in rows if r.contact == contact]
        ax1.scatter([r.width_m * 1e3 for r in sel], [r.peak_ratio for r in sel], label=contact)
        held = [r for r in sel if math.isfinite(r.time_to_hold_s)]
        ax2.scatter([r.approach_floor_s for r in held], [r.time_to_hold_s for r in held],
                    label=contact)
    ax1.axhline(1.10, color='r', ls='--', label='1.10 x setpoint')
    ax1.set_xlabel('object width (mm)')
    ax1.set_ylabel('peak contact force / setpoint')
    ax1.legend()
    lim = max([r.time_to_hold_s for r in rows if math.isfinite(r.time_to_hold_s)] + [1.0])
    ax2.plot([0, lim], [0, lim], 'k:', label='floor')
    ax2.set_xlabel('at-rest approach floor (s)')
    ax2.set_ylabel('request to steady hold (s)')
    ax2.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    from gripper_ros.core.controllers import ForceControllerKind
    parser = argparse.ArgumentParser(prog='contact_sweep', description=__doc__.splitlines()[0])
    parser.add_argument('--config', help='YAML parameter file (default: installed)')
    parser.add_argument('--compliant', action='store_true',
                        help='also a stiff (1e5 N/m) and a soft (1e3 N/m) compliant object')
    parser.add_argument('--force-controller', choices=[k.value for k in ForceControllerKind],
                        help='force stage (default: the graph\'s default, contact_aware); pi or '
                             'mpc_pi show the paper structure on compliant objects')
    parser.add_argument('--plot', help='write the sweep as PNG')
    parser.add_argument('--json', action='store_true')
    args = parser.parse_args(argv)
    try:
        config = load_config(args.config)
    except ConfigError as exc:
        print(f'contact_sweep: {exc}', file=sys.stderr)
        return 2
    rows = sweep(config, compliant=args.compliant, force_controller=args.force_controller)
    if args.json:
        print(json.dumps([asdict(r) for r in rows], indent=1,
                         default=lambda v: None if isinstance(v, float) and math.isinf(v) else v))
    else:
        print(format_rows(rows))
    if args.plot:
        plot(rows, args.plot)
        print(f'figure: {args.plot}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
