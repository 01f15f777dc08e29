"""bench_controllers: the cost of one controller step, against the paper's 100 us force sampling.

    ros2 run gripper_ros bench_controllers                  # 20000 timed steps each
    ros2 run gripper_ros bench_controllers --steps 50000 --json

Times, in ONE process run (so that the ratios compare figures taken under the same machine
load), ``step(setpoint, measurement)`` of the controllers the nodes run, built exactly as the
nodes build them (:func:`gripper_ros.core.control.factories.make_force_controller` /
:func:`~gripper_ros.core.control.factories.make_position_controller` from
:func:`gripper_ros.core.config.load_config`): PI and MPC-PI (force, at the force sampling time),
PD and MPC-PD (position, at 10 ms); and a bare baseline, a Python call returning ``a * k + b``,
timed the same way. Beside them, ``GripperPlant.step(voltage, dt)`` of the simulated plant the
nodes run (:func:`gripper_ros.core.control.factories.make_plant`): a 0.1 ms force-loop step holding
a rigid and a compliant (1e5 N/m, 50 N s/m) object under the contact-aware force stage (and the
rigid one lifted, 20 g held by pad friction: the hold physics included), and a 10 ms position-loop
step of free motion under PD; there the controller runs outside the timed region.

Each step is timed on its own with ``time.perf_counter_ns()`` around the call (the baseline
carries the same timer overhead, so ``x base`` is the controller's cost in units of a trivial
Python call). The loop is closed around each controller's discrete plant model (exact ZOH,
updated outside the timed region) and the setpoint alternates every ``--period`` steps, so the
controllers work on realistic, changing signals. ``--warmup`` steps precede the timed ones.
Reported: median and 99th percentile in us, both as multiples of the baseline, and as a
fraction of the paper's 100 us force sampling time (and of the controller's own sampling time).

The cost of a tick through the node graph, of which a controller step is one part, is what
``bench_graph`` measures (docs/BENCHMARKS.md).
"""
from __future__ import annotations

import argparse
import gc
import json
import os
import platform
import sys
import time

from gripper_ros.wire import FORCE_SAMPLE_S
import numpy as np

FORCE_BUDGET_US = FORCE_SAMPLE_S * 1e6   # the paper's force sampling time, 0.1 ms


def _baseline_call(a: float, b: float) -> float:
    return a * 0.5 + b


class _Baseline:
    """The reference: a bare Python call doing one float multiply-add.

    ``ctrl.step`` binds to it directly, so one call, as for the controllers' bound ``step``
    methods.
    """

    step = staticmethod(_baseline_call)


def _time_steps(ctrl, plant_step, setpoints, warmup: int, steps: int) -> np.ndarray:
    """Per-call ns of ctrl.step over a closed loop; plant_step runs outside the timed region."""
    clock = time.perf_counter_ns
    step = ctrl.step
    y = 0.0
    out = np.empty(steps, dtype=np.int64)
    n_sp = len(setpoints)
    for k in range(warmup + steps):
        sp = setpoints[k % n_sp]
        t0 = clock()
        u = step(sp, y)
        t1 = clock()
        if k >= warmup:
            out[k - warmup] = t1 - t0
        y = plant_step(u)
    return out


class _ContactAware:
    """The contact-aware force stage holding a rigid object (finger at rest on the face).

    Its ``step`` also takes position and face; the one extra call is included in its figure.
    """

    def __init__(self, ctrl, position_m: float = 0.1):
        self.step = lambda sp, y: ctrl.step(sp, y, position_m, position_m)


def _force_plant(config, dt_s: float):
    from gripper_ros.core.control.factories import make_plant
    a, b = make_plant(config).discrete_force_model(dt_s)
    state = [0.0]

    def step(u: float) -> float:
        state[0] = a * state[0] + b * u
        return state[0]
    return step


def _position_plant(config):
    from gripper_ros.core.control.factories import make_plant
    ad, bd = make_plant(config).discrete_free_model(config.position.sample_time_s)
    x = np.zeros(3)
    lim = config.plant.max_travel_m

    def step(u: float) -> float:
        x[:] = ad @ x + bd * u
        if not 0.0 <= x[2] <= lim:          # keep the finger inside its travel
            x[2] = min(max(x[2], 0.0), lim)
            x[1] = 0.0
        return float(x[2])
    return step


def _time_plant_steps(plant, dt_s: float, control, setpoints, warmup: int,
                      steps: int) -> np.ndarray:
    """Per-call ns of plant.step(voltage, dt_s); control(setpoint, sample) runs untimed."""
    clock = time.perf_counter_ns
    step = plant.step
    u = 0.0
    out = np.empty(steps, dtype=np.int64)
    n_sp = len(setpoints)
    for k in range(warmup + steps):
        t0 = clock()
        s = step(u, dt_s)
        t1 = clock()
        if k >= warmup:
            out[k - warmup] = t1 - t0
        u = control(setpoints[(k + 1) % n_sp], s)
    return out


def _holding_plant(config, stiffness_n_per_m: float, damping_n_s_per_m: float,
                   width_m: float = 0.05, lifted_mass_kg: float = 0.0):
    """Build a plant with the finger at rest on an object, driven by the contact-aware stage.

    ``lifted_mass_kg`` > 0: the object is lifted off its support at once and held by friction
    (the hold physics runs every step).
    """
    from gripper_ros.core.control.factories import make_force_controller, make_plant
    from gripper_ros.wire import ForceControllerKind
    from gripper_ros.core.physics.plant import GraspObject, Lift
    plant = make_plant(config)
    lift = Lift(0.0) if lifted_mass_kg > 0.0 else None
    plant.set_object(GraspObject(width_m, stiffness_n_per_m, damping_n_s_per_m,
                                 mass_kg=lifted_mass_kg), lift=lift)
    plant.touch_object()
    if lift is not None:
        plant.begin_hold(plant.t_ns)
    ctrl = make_force_controller(config, ForceControllerKind.CONTACT_AWARE)
    face = plant.contact_position_m

    def control(sp: float, s) -> float:
        return ctrl.step(sp, s.force_n, s.position_m, face)
    return plant, control


def _free_plant(config):
    """Build a plant with nothing between the fingers, driven by the PD position controller."""
    from gripper_ros.core.control.factories import make_plant, make_position_controller
    from gripper_ros.wire import PositionControllerKind
    plant = make_plant(config)
    ctrl = make_position_controller(config, PositionControllerKind.PD)

    def control(sp: float, s) -> float:
        return ctrl.step(sp, s.position_m)
    return plant, control


def measure(steps: int = 20000, warmup: int = 2000, period: int = 2000,
            config_file: str | None = None, disable_gc: bool = False) -> dict:
    from gripper_ros.core.config import load_config
    from gripper_ros.core.control.factories import make_force_controller, make_position_controller
    from gripper_ros.wire import ForceControllerKind, PositionControllerKind
    config = load_config(config_file or None)
    f_dt = config.force.sample_time_s
    p_dt = config.position.sample_time_s
    f_sp = np.repeat([1.0, 5.0], period)               # N
    p_sp = np.repeat([0.10, 0.05], period)             # m finger travel
    cases = [
        ('baseline (a*k+b call)', _Baseline(), lambda u: u * 1e-3, f_sp, None),
        ('PI (force)', make_force_controller(config, ForceControllerKind.PI),
         _force_plant(config, f_dt), f_sp, f_dt),
        ('MPC-PI (DMC over PI, force)', make_force_controller(config, ForceControllerKind.MPC_PI),
         _force_plant(config, f_dt), f_sp, f_dt),
        ('contact-aware (force, default)',
         _ContactAware(make_force_controller(config, ForceControllerKind.CONTACT_AWARE)),
         _force_plant(config, f_dt), f_sp, f_dt),
        ('PD (position)', make_position_controller(config, PositionControllerKind.PD),
         _position_plant(config), p_sp, p_dt),
        ('MPC-PD (DMC over PD, position)',
         make_position_controller(config, PositionControllerKind.MPC_PD),
         _position_plant(config), p_sp, p_dt),
    ]
    was_enabled = gc.isenabled()
    if disable_gc:
        gc.disable()
    rows = []
    try:
        for name, ctrl, plant, sps, dt in cases:
            rows.append(_row(name, _time_steps(ctrl, plant, sps, warmup, steps), dt))
        plant_cases = [
            ('plant step, force, rigid', _holding_plant(config, 0.0, 0.0), f_dt, f_sp),
            ('plant step, force, compliant', _holding_plant(config, 1e5, 50.0), f_dt, f_sp),
            ('plant step, force, rigid, lifted',
             _holding_plant(config, 0.0, 0.0, lifted_mass_kg=0.02), f_dt, f_sp),
            ('plant step, position, free', _free_plant(config), p_dt, p_sp),
        ]
        for name, (plant, control), dt, sps in plant_cases:
            rows.append(_row(name, _time_plant_steps(plant, dt, control, sps, warmup, steps),
                             dt))
    finally:
        if disable_gc and was_enabled:
            gc.enable()
    base = rows[0]
    for r in rows:
        r['median_x_base'] = r['median_us'] / base['median_us']
        r['p99_x_base'] = r['p99_us'] / base['p99_us']
        r['median_of_100us'] = r['median_us'] / FORCE_BUDGET_US
        r['p99_of_100us'] = r['p99_us'] / FORCE_BUDGET_US
        r['p99_of_own_sample'] = None if r['sample_time_us'] is None else \
            r['p99_us'] / r['sample_time_us']
    return {'steps': steps, 'warmup': warmup, 'period': period, 'gc_disabled': disable_gc,
            'timer_resolution_ns': time.get_clock_info('perf_counter').resolution * 1e9,
            'machine': {'python': platform.python_version(), 'numpy': np.__version__,
                        'cpus': os.cpu_count(), 'load_avg': list(os.getloadavg())},
            'rows': rows}


def _row(name: str, ns: np.ndarray, dt_s: float | None) -> dict:
    return {'name': name, 'median_us': float(np.median(ns)) / 1e3,
            'p99_us': float(np.percentile(ns, 99)) / 1e3,
            'mean_us': float(ns.mean()) / 1e3, 'max_us': float(ns.max()) / 1e3,
            'sample_time_us': None if dt_s is None else dt_s * 1e6}


def format_report(rep: dict) -> str:
    lines = [f'bench_controllers: {rep["steps"]} timed steps each after {rep["warmup"]} warm-up, '
             f'setpoint alternating every {rep["period"]} steps, closed loop, gc '
             f'{"off" if rep["gc_disabled"] else "on"}; Python {rep["machine"]["python"]}, '
             f'numpy {rep["machine"]["numpy"]}, load average '
             f'{" ".join(f"{x:.2f}" for x in rep["machine"]["load_avg"])} on '
             f'{rep["machine"]["cpus"]} CPUs',
             f'{"controller":<32s} {"median us":>9s} {"p99 us":>8s} {"x base":>7s} '
             f'{"p99 x b":>7s} {"med/100us":>9s} {"p99/100us":>9s} {"p99/own ts":>10s}']
    for r in rep['rows']:
        own = '' if r['p99_of_own_sample'] is None else f'{100 * r["p99_of_own_sample"]:9.3f}%'
        lines.append(f'{r["name"]:<32s} {r["median_us"]:9.2f} {r["p99_us"]:8.2f} '
                     f'{r["median_x_base"]:7.1f} {r["p99_x_base"]:7.1f} '
                     f'{100 * r["median_of_100us"]:8.2f}% {100 * r["p99_of_100us"]:8.2f}% '
                     f'{own:>10s}')
    lines.append('x base: multiple of the baseline call (same timer overhead included); '
                 "/100us: fraction of the paper's 0.1 ms force sampling time; own ts: of the "
                 "controller's own sampling time (force 0.1 ms, position 10 ms); plant step: "
                 'GripperPlant.step over one such period. A tick through the node graph: '
                 'bench_graph.')
    return '\n'.join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='bench_controllers', description=__doc__.splitlines()[0])
    p.add_argument('--steps', type=int, default=20000, help='timed steps per controller')
    p.add_argument('--warmup', type=int, default=2000, help='untimed steps before them')
    p.add_argument('--period', type=int, default=2000, help='steps between setpoint changes')
    p.add_argument('--no-gc', action='store_true', help='disable the garbage collector')
    p.add_argument('--config', default='', help='YAML parameter file (default: installed)')
    p.add_argument('--json', action='store_true', help='JSON on stdout instead of the table')
    p.add_argument('--json-file', default='', help='also write the JSON here')
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(sys.argv[1:] if argv is None else argv)
    if args.steps < 1 or args.warmup < 0 or args.period < 1:
        print('bench_controllers: --steps and --period must be >= 1, --warmup >= 0',
              file=sys.stderr)
        return 2
    from gripper_ros.core.config import ConfigError
    try:
        rep = measure(args.steps, args.warmup, args.period, args.config, args.no_gc)
    except ConfigError as exc:
        print(f'bench_controllers: {exc}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    text = json.dumps(rep, indent=1)
    if args.json_file:
        with open(args.json_file, 'w') as f:
            f.write(text + '\n')
    print(text if args.json else format_report(rep))
    return 0


if __name__ == '__main__':
    sys.exit(main())
