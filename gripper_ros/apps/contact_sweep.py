"""contact_sweep: peak contact force, losses and time to a steady hold over the object envelope.

    ros2 run gripper_ros contact_sweep [--quick | --compliant | --fingers]
                                      [--exact-only | --band-only]
                                      [--band-design-stiffness N_PER_M] [--hold-s S]
                                      [--jobs N | --scheduler tcp://HOST:8786] [--quiet]
                                      [--force-controller contact_aware|pi|mpc_pi]
                                      [--plot FILE.png] [--json] [--config FILE]

Each grasp runs the node graph's logic without ROS (:mod:`gripper_ros.core.runtime.headless`,
bit-identical to the graph), through the batch engine (:mod:`gripper_ros.core.runtime.engine`:
local worker processes, or a Dask cluster with ``--scheduler``; the table is the same either way),
then holds on for ``--hold-s`` (default 1 s) with the plant and the
force stage running, to check that HOLDING was only declared once the force had settled.

The envelope (default): rigid contact (the paper's eq. 13) and Kelvin-Voigt objects
``F = k d + c d'`` with ``k`` in decades from 1e2 to 1e8 N/m and damping ratios ``zeta`` of
0.01, 0.1 and 1, where ``zeta = c / (2 sqrt(k m_r))`` is taken against the contact mode with
the motor inertia reflected to the finger (``m_r = J / (eta p N1/N2 p / 2 pi)`` = 546 kg, Table
I); widths over the travel and masses from 0.1 kg to the heaviest 24 V can hold, at the exact
width; then a reduced grid at uncertain widths, the object placed at the widest face, at the
expected face and at the narrowest face of a +-1 mm and a +-5 mm tolerance, and 2 % of the
tolerance past the widest. An object that would be squashed flat before it pushes back with F_sp
(``F_sp / k >= width``) cannot be held by any gripper and is left out (counted).

``--fingers``: the same contact stage on flexible fingers and nonlinear pads
(:mod:`gripper_ros.core.physics.contact_chain`): a printed finger, a rubber-dome pad, and both,
each on rigid and Kelvin-Voigt objects from 1e2 to 1e8 N/m, at damping ratios 0.01 and 1, narrow to
wide, light to the heaviest, at the exact width; then the uncertain-width grid above.

For each grasp: the outcome, the peak contact force (including between samples) over the grasp
and the continued hold as a multiple of the setpoint, the force range over the continued hold,
the time from request to the HOLDING answer and two floors for it at the held position (the
object's face plus the compression ``F_sp / k``): the minimum time to bring the finger from
fully open to rest there under +-24 V (:mod:`gripper_ros.apps.position_limit`; a spring that
helps braking can let a grasp beat it) and the minimum time to reach it at all (24 V
throughout: a true lower bound).
"""
from __future__ import annotations

import argparse
import dataclasses
from dataclasses import asdict, dataclass
import functools
import json
import math
import multiprocessing
import sys
import time

from gripper_ros.apps.common import load_config_or_report
from gripper_ros.wire import FORCE_SAMPLE_S

WIDTHS_M = (0.005, 0.02, 0.05, 0.08, 0.11, 0.14)
MASSES_KG = (0.1, 0.5, 1.0, 2.0, None)          # None: the heaviest 24 V can hold
STIFFNESSES_N_PER_M = (1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8)
DAMPING_RATIOS = (0.01, 0.1, 1.0)
# uncertain widths: a reduced grid, the object placed 0, 0.02, 1 and 2 tolerances into the band
BAND_TOLERANCES_M = (0.001, 0.005)
BAND_PLACEMENTS = (0.0, 0.02, 1.0, 2.0)         # x tolerance past the widest face
BAND_STIFFNESSES_N_PER_M = (1e2, 1e4, 1e6, 1e8)
BAND_DAMPING_RATIOS = (0.01, 1.0)
BAND_WIDTHS_M = (0.05,)
BAND_MASSES_KG = (0.1, 1.0, None)
# the former sweep's compliant kinds (--compliant): name, k N/m, c N s/m
COMPLIANT_OBJECTS = (('stiff', 1.0e5, 50.0), ('soft', 1.0e3, 5.0))
# --quick: the reduced grid of test/test_contact_sweep.py
QUICK_STIFFNESSES_N_PER_M = (1e2, 1e4, 1e6, 1e8)
QUICK_DAMPING_RATIOS = (0.01, 1.0)
QUICK_WIDTHS_M = (0.005, 0.14)
QUICK_MASSES_KG = (0.1, None)
# held out of --quick (tune's default check): the envelope's inside, none of its corners
HOLDOUT_STIFFNESSES_N_PER_M = (1e3, 1e5, 1e7)
HOLDOUT_DAMPING_RATIOS = (0.1,)
HOLDOUT_WIDTHS_M = (0.02, 0.08)
HOLDOUT_MASSES_KG = (0.5, 2.0)
# --fingers: the chain kinds (name, finger k_f N/m, pad k_p N/m^1.5; core/physics/contact_chain.py)
# over objects of the quick grid's kinds, at these widths and masses
FINGER_WIDTHS_M = (0.005, 0.05, 0.14)
FINGER_MASSES_KG = (0.1, 1.0, None)
DEFAULT_HOLD_S = 1.0
FLOOR_POSITION_ROUND_M = 1e-5                   # floors are computed on this grid of positions


@dataclass(frozen=True)
class SweepCase:
    """One object and one request."""

    contact: str                     # 'rigid', or the compliant kind's name
    stiffness_n_per_m: float         # 0 = rigid
    damping_ratio: float             # against the contact mode with the reflected mass
    damping_n_s_per_m: float
    width_m: float                   # requested
    object_width_m: float            # placed
    width_tolerance_m: float
    mass_kg: float
    finger: str = ''                 # the chain kind ('': the configured fingers and pads)
    finger_stiffness_n_per_m: float = 0.0
    pad_stiffness_n_per_m1_5: float = 0.0


@dataclass
class SweepRow:
    contact: str
    stiffness_n_per_m: float
    damping_ratio: float
    damping_n_s_per_m: float
    width_m: float
    object_width_m: float
    width_tolerance_m: float
    mass_kg: float
    outcome: str
    force_setpoint_n: float
    peak_force_n: float
    peak_ratio: float
    time_to_hold_s: float            # request to the HOLDING answer (inf if not held)
    hold_min_ratio: float            # force range over the continued hold / F_sp (nan: none)
    hold_max_ratio: float
    hold_drift_m: float              # how far the finger moved on during the continued hold
    held_position_m: float           # the object's face plus F_sp / k
    approach_floor_s: float          # minimum time to rest at the held position (10 ms)
    arrival_floor_s: float           # minimum time to reach it at all (24 V throughout)
    band_offset_m: float             # how far past the widest allowed face the object is
    finger: str = ''                 # the chain kind ('': the configured fingers and pads)

    @property
    def settled(self) -> bool:
        """Return True if HOLDING and the continued hold stayed within the settle band."""
        return self.outcome == 'HOLDING' and math.isfinite(self.hold_min_ratio)


def max_mass_kg(config) -> float:
    """Return the heaviest object (to 10 g) whose force setpoint 24 V can hold."""
    return math.floor(100.0 * config.plant.max_force_n / _force_setpoint_n(config, 1.0)
                      * (1 - 1e-12)) / 100.0


def _force_setpoint_n(config, mass_kg: float) -> float:
    """Return the configured force law's setpoint for ``mass_kg`` (what the supervisor asks)."""
    from gripper_ros.core.supervision.requests import force_setpoint_n
    sup, p = config.supervisor, config.plant
    return force_setpoint_n(mass_kg, sup.friction_coefficient, p.gravity_mps2,
                            sup.acceleration_mps2, sup.force_law, sup.grip_safety_factor)


def _compliant(config, k: float, zeta: float) -> tuple[str, float, float, float]:
    return (f'{k:.0e}', k, zeta, 2.0 * zeta * math.sqrt(k * config.plant.reflected_mass_kg))


def _kinds(config, stiffnesses, damping_ratios):
    return [('rigid', 0.0, 0.0, 0.0)] + [_compliant(config, k, z) for k in stiffnesses
                                         for z in damping_ratios]


def build_cases(config, *, kinds, widths, masses, tolerances=(0.0,),
                placements=(0.0,)) -> tuple[list[SweepCase], int]:
    """Return the grid's cases and how many objects were left out as squashed flat."""
    cases, excluded = [], 0
    heaviest = max_mass_kg(config)
    for name, k, zeta, c in kinds:
        for w in widths:
            for m in masses:
                m = heaviest if m is None else m
                for tol in tolerances:
                    for place in (placements if tol > 0.0 else (0.0,)):
                        obj_w = w + tol - place * tol       # 0 tolerances in: the widest
                        if k > 0.0 and _force_setpoint_n(config, m) / k >= obj_w:
                            excluded += 1
                            continue
                        cases.append(SweepCase(name, k, zeta, c, w, obj_w, tol, m))
    return cases, excluded


def envelope_cases(config, exact: bool = True, band: bool = True
                   ) -> tuple[list[SweepCase], int]:
    """Return the default grid: the envelope at exact widths, then the uncertain widths."""
    cases, excluded = [], 0
    if exact:
        cases, excluded = build_cases(config, kinds=_kinds(config, STIFFNESSES_N_PER_M,
                                                           DAMPING_RATIOS),
                                      widths=WIDTHS_M, masses=MASSES_KG)
    if band:
        band, band_excluded = build_cases(
            config, kinds=_kinds(config, BAND_STIFFNESSES_N_PER_M, BAND_DAMPING_RATIOS),
            widths=BAND_WIDTHS_M, masses=BAND_MASSES_KG, tolerances=BAND_TOLERANCES_M,
            placements=BAND_PLACEMENTS)
        cases += band
        excluded += band_excluded
    return cases, excluded


def quick_cases(config) -> tuple[list[SweepCase], int]:
    """Return the reduced exact-width grid (corners of the envelope) the tests run."""
    return build_cases(config, kinds=_kinds(config, QUICK_STIFFNESSES_N_PER_M,
                                            QUICK_DAMPING_RATIOS),
                       widths=QUICK_WIDTHS_M, masses=QUICK_MASSES_KG)


def holdout_cases(config) -> tuple[list[SweepCase], int]:
    """Return the envelope's inside at the exact width: objects none of :func:`quick_cases` is.

    Rigid and 1e3, 1e5, 1e7 N/m at a damping ratio of 0.1, 20 and 80 mm, 0.5 and 2 kg.
    """
    return build_cases(config, kinds=_kinds(config, HOLDOUT_STIFFNESSES_N_PER_M,
                                            HOLDOUT_DAMPING_RATIOS),
                       widths=HOLDOUT_WIDTHS_M, masses=HOLDOUT_MASSES_KG)


def compliant_cases(config, widths=WIDTHS_M, masses=MASSES_KG) -> tuple[list[SweepCase], int]:
    """Return rigid plus the former sweep's stiff (1e5 N/m) and soft (1e3 N/m) objects."""
    m_r = config.plant.reflected_mass_kg
    kinds = [('rigid', 0.0, 0.0, 0.0)] + [(name, k, c / (2.0 * math.sqrt(k * m_r)), c)
                                          for name, k, c in COMPLIANT_OBJECTS]
    return build_cases(config, kinds=kinds, widths=widths, masses=masses)


def finger_kinds() -> tuple[tuple[str, float, float], ...]:
    """Return the chain kinds: (name, finger stiffness N/m, pad stiffness N/m^1.5)."""
    from gripper_ros.core.physics.contact_chain import (cantilever_stiffness_n_per_m,
                                                        hertz_pad_stiffness_n_per_m1_5,
                                                        PRINTED_FINGER, RUBBER_DOME_PAD)
    finger = cantilever_stiffness_n_per_m(**PRINTED_FINGER)
    pad = hertz_pad_stiffness_n_per_m1_5(**RUBBER_DOME_PAD)
    return (('finger', finger, 0.0), ('pad', 0.0, pad), ('finger+pad', finger, pad))


def finger_cases(config, widths=FINGER_WIDTHS_M, masses=FINGER_MASSES_KG, exact: bool = True,
                 band: bool = True) -> tuple[list[SweepCase], int]:
    """Return each chain kind over the quick grid's objects at ``widths`` x ``masses``.

    ``band``: and over the default envelope's uncertain-width grid.
    """
    grid, excluded = [], 0
    if exact:
        grid, excluded = build_cases(config, kinds=_kinds(config, QUICK_STIFFNESSES_N_PER_M,
                                                          QUICK_DAMPING_RATIOS),
                                     widths=widths, masses=masses)
    if band:
        banded, band_excluded = envelope_cases(config, exact=False, band=True)
        grid += banded
        excluded += band_excluded
    cases = [dataclasses.replace(c, finger=name, finger_stiffness_n_per_m=finger,
                                 pad_stiffness_n_per_m1_5=pad)
             for name, finger, pad in finger_kinds() for c in grid]
    return cases, excluded * len(finger_kinds())


def with_chain(config, case: SweepCase):
    """Return ``config`` with the case's fingers and pads (unchanged for a configured case)."""
    if not case.finger:
        return config
    contact = dataclasses.replace(config.contact,
                                  finger_stiffness_n_per_m=case.finger_stiffness_n_per_m,
                                  pad_normal_stiffness_n_per_m1_5=case.pad_stiffness_n_per_m1_5)
    return dataclasses.replace(config, contact=contact)


def rigid_cases(config, widths=WIDTHS_M, masses=MASSES_KG) -> tuple[list[SweepCase], int]:
    return build_cases(config, kinds=[('rigid', 0.0, 0.0, 0.0)], widths=widths, masses=masses)


def held_position_m(config, case: SweepCase) -> float:
    """Return where the finger rests when the object pushes back with F_sp."""
    face = config.plant.max_travel_m - case.object_width_m
    if case.finger:
        from gripper_ros.core.physics.contact_chain import chain_compression_m
        return face + chain_compression_m(_force_setpoint_n(config, case.mass_kg),
                                          case.finger_stiffness_n_per_m,
                                          case.pad_stiffness_n_per_m1_5, case.stiffness_n_per_m)
    if case.stiffness_n_per_m > 0.0:
        face += _force_setpoint_n(config, case.mass_kg) / case.stiffness_n_per_m
    return face


def arrival_floors_s(config, setpoints_m, dt_s: float = FORCE_SAMPLE_S) -> list[float]:
    """Return the minimum time for the finger to reach each of ``setpoints_m`` from rest.

    At any speed: full voltage all the way (one run, read at each crossing). A true lower bound
    for any grasp under the limit; a rigid object that stops the finger dead (the paper's
    contact) lets a grasp beat the at-rest floor, never this. A setpoint at or past the full
    travel (a chain compressed past it, which the free finger never reaches) has none (nan).
    """
    from gripper_ros.core.control.factories import make_plant
    plant = make_plant(config)
    limit = config.plant.voltage_limit_v
    sample = plant.sample()
    floors = {}
    for setpoint_m in sorted(set(setpoints_m)):
        if setpoint_m >= config.plant.max_travel_m:
            floors[setpoint_m] = math.nan
            continue
        while sample.position_m < setpoint_m:
            sample = plant.step(limit, dt_s)
        floors[setpoint_m] = sample.t_s
    return [floors[s] for s in setpoints_m]


def _rest_floors_s(config, setpoints_m: list[float]) -> list[float]:
    from gripper_ros.apps.position_limit import minimum_rest_times_s
    return minimum_rest_times_s(config, setpoints_m, config.position.sample_time_s)


def _case_keywords(case: SweepCase, force_controller, hold_s: float, config=None) -> dict:
    """Return :func:`simulate_grasp`'s keywords for one case of the sweep.

    A chain kind's case carries its own config (``config`` with its fingers and pads).
    """
    kinds = {} if force_controller is None else {'force_controller': force_controller}
    if case.finger:
        kinds['config'] = with_chain(config, case)
    return dict(width_m=case.width_m, mass_kg=case.mass_kg, object_width_m=case.object_width_m,
                stiffness_n_per_m=case.stiffness_n_per_m,
                damping_n_s_per_m=case.damping_n_s_per_m,
                width_tolerance_m=case.width_tolerance_m, hold_s=hold_s, **kinds)


def grasp_summary(case: dict, g):
    """One grasp's figures (runs in the worker: only these come back); None when refused."""
    from gripper_ros.core.supervision.requests import RequestError
    if isinstance(g, RequestError):
        return None                 # beyond what 24 V can hold: refused, not swept
    f_sp = g.force_setpoint_n
    held = g.outcome.name == 'HOLDING'
    lo, hi, drift = math.nan, math.nan, math.nan
    hold = g.continued_hold
    if held and g.position_m[hold].size:
        lo, hi = g.hold_force_range_n()
        drift = float(max(abs(g.position_m[hold].max() - g.position_m[hold.start - 1]),
                          abs(g.position_m[hold].min() - g.position_m[hold.start - 1])))
    return (g.outcome.name, f_sp, g.peak_contact_force_n,
            g.time_to_answer_s if held else math.inf, lo / f_sp, hi / f_sp, drift)


def sweep(config, cases: list[SweepCase], force_controller: str | None = None,
          hold_s: float = DEFAULT_HOLD_S, jobs: int = 1, *, scheduler=None,
          progress=None, rest_floors: bool = True) -> list[SweepRow]:
    """Grasp every case with its floors; refused requests are dropped.

    ``jobs``, ``scheduler``, ``progress`` (called with the number of grasps done): the engine's.
    ``rest_floors`` False leaves the rest floor out (nan): it costs a linear programme per
    held position, and the chain kinds' compressions give nearly every case its own.
    """
    from gripper_ros.core.runtime.headless import map_cases, simulate_grasps
    if scheduler is not None and not isinstance(scheduler, str):
        jobs = max(1, sum(scheduler.nthreads().values()))
    positions = [round(held_position_m(config, c) / FLOOR_POSITION_ROUND_M)
                 * FLOOR_POSITION_ROUND_M for c in cases]
    distinct = sorted(set(positions))
    parts = max(1, min(jobs, len(distinct)))     # one ordered search per worker
    share = -(-len(distinct) // parts)
    chains = [distinct[i:i + share] for i in range(0, len(distinct), share)]
    rest = dict(zip(distinct, (f for chain in map_cases(
        functools.partial(_rest_floors_s, config), chains, jobs, scheduler=scheduler)
        for f in chain))) if rest_floors else dict.fromkeys(distinct, math.nan)
    reach = dict(zip(distinct, arrival_floors_s(config, distinct)))
    results = simulate_grasps(config, [_case_keywords(c, force_controller, hold_s, config)
                                       for c in cases], jobs, summarize=grasp_summary,
                              scheduler=scheduler, progress=progress)
    rows = []
    for case, x_m, res in zip(cases, positions, results):
        if res is None:
            continue
        outcome, f_sp, peak, t_hold, lo, hi, drift = res
        rows.append(SweepRow(
            case.contact, case.stiffness_n_per_m, case.damping_ratio, case.damping_n_s_per_m,
            case.width_m, case.object_width_m, case.width_tolerance_m, case.mass_kg, outcome,
            f_sp, peak, peak / f_sp, t_hold, lo, hi, drift, x_m, rest[x_m], reach[x_m],
            case.width_m + case.width_tolerance_m - case.object_width_m, case.finger))
    return rows


def band_speed_mps(config, force_setpoint_n: float) -> float:
    """Return the contact-aware stage's speed across a tolerance band."""
    from gripper_ros.core.control.contact_force import ContactForceController
    ctrl = ContactForceController(config.plant, config.force.contact_aware,
                                  config.force.sample_time_s)
    return ctrl.contact_speed_mps(force_setpoint_n, width_tolerance_m=1.0)


def summary(config, rows: list[SweepRow], excluded: int, hold_s: float,
            elapsed_s: float | None = None, jobs: int | str = 1) -> str:
    """Return the verdict: worst peak, losses, the continued hold, time to hold vs floor."""
    sup = config.supervisor
    band = sup.force_settle_band_fraction
    exact = [r for r in rows if r.width_tolerance_m == 0.0]
    banded = [r for r in rows if r.width_tolerance_m > 0.0]
    lines = [f'contact_sweep: {len(rows)} grasps ({len(exact)} at the exact width, '
             f'{len(banded)} within a tolerance)'
             + (f' in {elapsed_s:.0f} s wall on ' + (f'{jobs} process(es)' if isinstance(
                 jobs, int) else f'the cluster at {jobs}') if elapsed_s else '')
             + f'; {excluded} objects left out: squashed flat before F_sp (F_sp / k >= width)']
    if not rows:
        return '\n'.join(lines)
    for part, sel in (('at the exact width', exact), ('within a tolerance', banded)):
        if sel:
            worst = max(sel, key=lambda r: r.peak_ratio)
            lines.append(f'worst peak {part}: {worst.peak_ratio:.4f} x F_sp '
                         f'({_describe(worst)}); limit 1.10')
    chain = {name: (finger_n_per_m, pad_n_per_m1_5)
             for name, finger_n_per_m, pad_n_per_m1_5 in finger_kinds()}
    for finger in sorted({r.finger for r in rows if r.finger}):
        sel = [r for r in rows if r.finger == finger]
        worst = max(sel, key=lambda r: r.peak_ratio)
        lost = sum(r.outcome == 'OBJECT_LOST' for r in sel)
        finger_n_per_m, pad_n_per_m1_5 = chain.get(finger, (math.nan, math.nan))
        lines.append(f'  {finger} (k_f {finger_n_per_m:.3g} N/m, k_p {pad_n_per_m1_5:.3g} '
                     f'N/m^1.5): {len(sel)} grasps, worst peak {worst.peak_ratio:.4f} x F_sp '
                     f'({_describe(worst)}), {lost} lost')
    counts = {}
    for r in rows:
        counts[r.outcome] = counts.get(r.outcome, 0) + 1
    lines.append('outcomes: ' + ', '.join(f'{k} {v}' for k, v in sorted(counts.items())))
    lost = [r for r in rows if r.outcome == 'OBJECT_LOST']
    lines.append(f'objects lost: {len(lost)}'
                 + ''.join(f'\n  {_describe(r)}' for r in lost))
    held = [r for r in rows if r.outcome == 'HOLDING']
    if held and hold_s > 0.0:
        dev = max(max(abs(r.hold_min_ratio - 1.0), abs(r.hold_max_ratio - 1.0)) for r in held)
        out = [r for r in held if max(abs(r.hold_min_ratio - 1.0),
                                      abs(r.hold_max_ratio - 1.0)) > band]
        drift = max(r.hold_drift_m for r in held)
        lines.append(f'continued hold of {hold_s:g} s after HOLDING: {len(held) - len(out)} of '
                     f'{len(held)} stay within the {band * 100:g} % band (worst deviation '
                     f'{dev * 100:.3f} %), the finger moves on at most {drift * 1e3:.3f} mm '
                     f'(loss watch: {sup.no_object_margin_m * 1e3:g} mm)')
        for r in out:
            lines.append(f'  out of band: {_describe(r)}')
    not_held = [r for r in exact if r.outcome != 'HOLDING']
    for r in not_held:
        lines.append(f'  not held at the exact width: {r.outcome}: {_describe(r)}')
    lines.append('time to hold at the exact width, minus the floors (s), per contact:')
    lines.append(f'  {"contact":>7s} {"zeta":>5s} {"n":>3s} {"held":>4s} '
                 f'{"- rest: median":>14s} {"max":>6s} {"- reach: min":>12s} {"max hold s":>10s}')
    for key in sorted({(r.finger, r.stiffness_n_per_m, r.damping_ratio) for r in exact}):
        sel = [r for r in exact if (r.finger, r.stiffness_n_per_m, r.damping_ratio) == key]
        ok = [r for r in sel if math.isfinite(r.time_to_hold_s)]
        over_rest = sorted(r.time_to_hold_s - r.approach_floor_s for r in ok)
        over_reach = [r.time_to_hold_s - r.arrival_floor_s for r in ok]
        name = f'{key[0]} {sel[0].contact}' if key[0] else sel[0].contact
        if ok:
            lines.append(f'  {name:>7s} {key[2]:5.2f} {len(sel):3d} {len(ok):4d} '
                         f'{_figure(over_rest[len(over_rest) // 2], 14)} '
                         f'{_figure(over_rest[-1], 6)} '
                         f'{min(over_reach):12.2f} {max(r.time_to_hold_s for r in ok):10.2f}')
        else:
            lines.append(f'  {name:>7s} {key[2]:5.2f} {len(sel):3d}    0')
    if banded:
        per_n = band_speed_mps(config, 1.0)
        lines.append('within a tolerance: the band is crossed at the band speed '
                     f'({per_n * 1e6:.3g} um/s per N of F_sp); time to hold minus the rest '
                     'floor at the real face vs the crossing time:')
        for r in banded:
            crossing_s = r.band_offset_m / (per_n * r.force_setpoint_n)
            t = (f'{r.time_to_hold_s - r.approach_floor_s:8.2f}'
                 if math.isfinite(r.time_to_hold_s) else f'{"-":>8s}')
            lines.append(f'  {_describe(r):64s} {r.outcome:>11s} peak {r.peak_ratio:6.4f} '
                         f'{t} s, crossing {crossing_s:9.1f} s')
    return '\n'.join(lines)


def _figure(value: float, width: int) -> str:
    """Return ``value`` to two decimals in ``width`` characters, '-' if not computed (nan)."""
    return f'{"-":>{width}s}' if math.isnan(value) else f'{value:{width}.2f}'


def _describe(r: SweepRow) -> str:
    kind = 'rigid' if r.stiffness_n_per_m == 0.0 else \
        f'k {r.stiffness_n_per_m:.0e} N/m zeta {r.damping_ratio:g}'
    if r.finger:
        kind = f'{r.finger}, {kind}'
    where = f'{r.width_m * 1e3:g} mm'
    if r.width_tolerance_m:
        where += (f' +-{r.width_tolerance_m * 1e3:g} mm, placed {r.object_width_m * 1e3:g} mm')
    return f'{kind}, {where}, {r.mass_kg:g} kg'


def format_rows(rows: list[SweepRow]) -> str:
    fingers = any(r.finger for r in rows)        # a column of the chain kind, if any
    lead = f'{"fingers":>10s} ' if fingers else ''
    lines = [lead + f'{"k N/m":>7s} {"zeta":>5s} {"width":>6s} {"+-mm":>4s} {"placed":>6s} '
             f'{"kg":>5s} {"outcome":>11s} {"F_sp N":>7s} {"peak/F_sp":>9s} '
             f'{"hold min":>8s} {"hold max":>8s} {"hold s":>7s} {"rest s":>7s} {"reach s":>7s}']
    for r in rows:
        k = 'rigid' if r.stiffness_n_per_m == 0.0 else f'{r.stiffness_n_per_m:.0e}'
        lines.append(
            (f'{r.finger:>10s} ' if fingers else '')
            + f'{k:>7s} {r.damping_ratio:5.2f} {r.width_m * 1e3:6.0f} '
            f'{r.width_tolerance_m * 1e3:4.0f} {r.object_width_m * 1e3:6.1f} {r.mass_kg:5.2f} '
            f'{r.outcome:>11s} {r.force_setpoint_n:7.3f} {r.peak_ratio:9.4f} '
            f'{r.hold_min_ratio:8.4f} {r.hold_max_ratio:8.4f} {r.time_to_hold_s:7.2f} '
            f'{r.approach_floor_s:7.2f} {r.arrival_floor_s:7.2f}')
    lines.append('width, placed: requested and real object width (mm); hold min/max: force over '
                 'the continued hold / F_sp; rest s: minimum time to bring the finger to rest at '
                 'the held position (face + F_sp / k) under +-24 V (10 ms samples); reach s: '
                 'minimum time to reach it at any speed (24 V throughout)')
    return '\n'.join(lines)


def plot(config, rows: list[SweepRow], path: str) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    exact = [r for r in rows if r.width_tolerance_m == 0.0]
    banded = [r for r in rows if r.width_tolerance_m > 0.0]
    fig, axes = plt.subplots(1, 3 if banded else 2, figsize=(16 if banded else 11, 4.5))
    ax1, ax2 = axes[0], axes[1]
    rigid_x = min([r.stiffness_n_per_m for r in rows if r.stiffness_n_per_m > 0.0] + [1e2]) / 10
    zetas = sorted({r.damping_ratio for r in exact if r.stiffness_n_per_m > 0.0})
    markers = dict(zip(zetas, 'o^sDv'))
    for z in zetas:
        sel = [r for r in exact if r.stiffness_n_per_m > 0.0 and r.damping_ratio == z]
        ax1.scatter([r.stiffness_n_per_m for r in sel], [r.peak_ratio for r in sel],
                    marker=markers[z], s=14, label=f'zeta {z:g}')
        held = [r for r in sel if math.isfinite(r.time_to_hold_s)]
        ax2.scatter([r.stiffness_n_per_m for r in held],
                    [r.time_to_hold_s - r.approach_floor_s for r in held], marker=markers[z],
                    s=14, label=f'zeta {z:g}')
    rigid = [r for r in exact if r.stiffness_n_per_m == 0.0]
    ax1.scatter([rigid_x] * len(rigid), [r.peak_ratio for r in rigid], c='k', s=14, label='rigid')
    ax2.scatter([rigid_x] * len(rigid), [r.time_to_hold_s - r.approach_floor_s for r in rigid],
                c='k', s=14, label='rigid')
    ax1.axhline(1.10, color='r', ls='--', label='1.10 x setpoint')
    for ax in (ax1, ax2):
        ax.set_xscale('log')
        ax.set_xlabel('object stiffness (N/m); rigid at the left')
        ax.legend(fontsize=8)
    ax1.set_ylabel('peak contact force / setpoint')
    ax1.set_title('exact width: peak force')
    ax2.set_ylabel('time to hold - rest floor at the held position (s)')
    ax2.set_title('exact width: time to a steady hold')
    if banded:
        ax3 = axes[2]
        per_n = band_speed_mps(config, 1.0)
        floor_s = 0.01                      # at the widest face: no crossing, drawn here
        for tol in sorted({r.width_tolerance_m for r in banded}):
            sel = [r for r in banded if r.width_tolerance_m == tol]
            crossing = [max(r.band_offset_m / (per_n * r.force_setpoint_n), floor_s)
                        for r in sel]
            held = [(x, r) for x, r in zip(crossing, sel) if math.isfinite(r.time_to_hold_s)]
            ax3.scatter([x for x, _ in held],
                        [max(r.time_to_hold_s - r.approach_floor_s, floor_s) for _, r in held],
                        s=14, label=f'+-{tol * 1e3:g} mm, held')
            missed = [x for x, r in zip(crossing, sel) if not math.isfinite(r.time_to_hold_s)]
            ax3.scatter(missed, [config.supervisor.timeout_s] * len(missed), marker='x', s=20,
                        label=f'+-{tol * 1e3:g} mm, TIMEOUT')
        top = max(crossing_s for crossing_s in [r.band_offset_m / (per_n * r.force_setpoint_n)
                                                for r in banded] + [10.0])
        ax3.plot([floor_s, top], [floor_s, top], 'k:', label='crossing time')
        ax3.axhline(config.supervisor.timeout_s, color='r', ls='--', label='timeout')
        ax3.set_xscale('log')
        ax3.set_yscale('log')
        ax3.set_xlabel('distance into the band / band speed (s)')
        ax3.set_ylabel('time to hold - rest floor at the real face (s)')
        ax3.set_title('uncertain width: the band is crossed at v_c')
        ax3.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> int:
    from gripper_ros.core.control.factories import ForceControllerKind
    parser = argparse.ArgumentParser(prog='contact_sweep', description=__doc__.splitlines()[0])
    parser.add_argument('--config', help='YAML parameter file (default: installed)')
    grid = parser.add_mutually_exclusive_group()
    grid.add_argument('--quick', action='store_true',
                      help='the reduced exact-width grid the tests run (corners of the envelope)')
    grid.add_argument('--fingers', action='store_true',
                      help='flexible fingers and nonlinear pads: a printed finger, a rubber-dome '
                           'pad and both (core/physics/contact_chain.py) on rigid and '
                           'compliant objects, at the exact width and within a tolerance')
    grid.add_argument('--compliant', action='store_true',
                      help='only rigid, stiff (1e5 N/m) and soft (1e3 N/m) objects at the exact '
                           'width (the former sweep)')
    part = parser.add_mutually_exclusive_group()
    part.add_argument('--exact-only', action='store_true',
                      help='leave out the uncertain-width grid')
    part.add_argument('--band-only', action='store_true',
                      help='only the uncertain-width grid')
    parser.add_argument('--band-design-stiffness', type=float, metavar='N_PER_M',
                        help='cross tolerance bands at the speed designed for this stiffness '
                             '(default: force_control.contact_aware.band_design_stiffness_n_per_m'
                             '); objects stiffer than it are met harder')
    parser.add_argument('--hold-s', type=float, default=DEFAULT_HOLD_S,
                        help='continued hold after HOLDING, checked against the settle band '
                             '(default %(default)s s)')
    engine = parser.add_mutually_exclusive_group()
    engine.add_argument('--jobs', type=int, default=multiprocessing.cpu_count(),
                        help='local worker processes (default: one per CPU; 1 = this process)')
    engine.add_argument('--scheduler', metavar='tcp://HOST:8786',
                        help='run the grasps on the Dask cluster of this scheduler (started with '
                             '`dask scheduler` and `dask worker` on each machine)')
    parser.add_argument('--quiet', action='store_true',
                        help='no progress bar (it is shown only on a terminal anyway)')
    parser.add_argument('--force-controller', choices=[k.value for k in ForceControllerKind],
                        help="force stage (default: the graph's default, contact_aware); pi or "
                             'mpc_pi show the paper structure on compliant objects')
    parser.add_argument('--plot', help='write the sweep as PNG')
    parser.add_argument('--json', action='store_true')
    args = parser.parse_args(argv)
    band_k = args.band_design_stiffness
    if not (math.isfinite(args.hold_s) and args.hold_s >= 0.0) or (
            band_k is not None and not (math.isfinite(band_k) and band_k > 0.0)):
        print('contact_sweep: --hold-s must be finite and >= 0 and '
              '--band-design-stiffness finite and > 0', file=sys.stderr)
        return 2
    from gripper_ros.core.runtime.engine import jobs_problem
    if args.scheduler is None and jobs_problem(args.jobs):
        print(f'contact_sweep: --{jobs_problem(args.jobs)}', file=sys.stderr)
        return 2
    if args.scheduler is not None:
        from gripper_ros.core.runtime.engine import check_address
        try:
            check_address(args.scheduler)
        except ValueError as exc:
            print(f'contact_sweep: {exc}', file=sys.stderr)
            return 2
    config = load_config_or_report('contact_sweep', args.config)
    if config is None:
        return 2
    if band_k is not None:
        tuning = dataclasses.replace(config.force.contact_aware,
                                     band_design_stiffness_n_per_m=band_k)
        config = dataclasses.replace(config, force=dataclasses.replace(config.force,
                                                                       contact_aware=tuning))
    if args.quick:
        cases, excluded = quick_cases(config)
    elif args.compliant:
        cases, excluded = compliant_cases(config)
    elif args.fingers:
        cases, excluded = finger_cases(config, exact=not args.band_only,
                                       band=not args.exact_only)
    else:
        cases, excluded = envelope_cases(config, exact=not args.band_only,
                                         band=not args.exact_only)
    from gripper_ros.core.runtime.engine import EngineError
    from gripper_ros.progress import progress_bar
    start = time.monotonic()
    try:
        with progress_bar(len(cases), 'contact_sweep', quiet=args.quiet) as bar:
            rows = sweep(config, cases, args.force_controller, args.hold_s, args.jobs,
                         scheduler=args.scheduler, progress=bar.update,
                         rest_floors=not args.fingers)
    except EngineError as exc:
        print(f'contact_sweep: {exc}', file=sys.stderr)
        return 2
    elapsed_s = time.monotonic() - start
    if args.json:
        print(json.dumps([{k: None if isinstance(v, float) and not math.isfinite(v) else v
                           for k, v in asdict(r).items()} for r in rows], indent=1))
    else:
        print(summary(config, rows, excluded, args.hold_s, elapsed_s,
                      args.scheduler or args.jobs))
        print()
        print(format_rows(rows))
    if args.plot:
        plot(config, rows, args.plot)
        print(f'figure: {args.plot}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
