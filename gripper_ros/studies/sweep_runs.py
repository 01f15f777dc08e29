"""The contact sweep: the object envelope, its grids of cases, and the grasps over them.

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
fully open to rest there under +-24 V (:mod:`gripper_ros.studies.position_floor`; a spring that
helps braking can let a grasp beat it) and the minimum time to reach it at all (24 V
throughout: a true lower bound).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
import functools
import math

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
# the compliant kinds of --compliant: name, stiffness N/m, damping N s/m
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


def _grid(config, stiffnesses, damping_ratios, **grid) -> tuple[list[SweepCase], int]:
    """:func:`build_cases` over rigid and the Kelvin-Voigt objects of these k and zeta."""
    return build_cases(config, kinds=_kinds(config, stiffnesses, damping_ratios), **grid)


def _joined(*grids) -> tuple[list[SweepCase], int]:
    """Return the cases of ``grids`` one after another, and all they left out."""
    return [c for cases, _ in grids for c in cases], sum(excluded for _, excluded in grids)


def band_cases(config) -> tuple[list[SweepCase], int]:
    """Return the uncertain widths: the object placed 0, 0.02, 1 and 2 tolerances into the band."""
    return _grid(config, BAND_STIFFNESSES_N_PER_M, BAND_DAMPING_RATIOS, widths=BAND_WIDTHS_M,
                 masses=BAND_MASSES_KG, tolerances=BAND_TOLERANCES_M, placements=BAND_PLACEMENTS)


def envelope_cases(config, exact: bool = True, band: bool = True
                   ) -> tuple[list[SweepCase], int]:
    """Return the default grid: the envelope at exact widths, then the uncertain widths."""
    return _joined(*([_grid(config, STIFFNESSES_N_PER_M, DAMPING_RATIOS, widths=WIDTHS_M,
                            masses=MASSES_KG)] if exact else []),
                   *([band_cases(config)] if band else []))


def quick_cases(config) -> tuple[list[SweepCase], int]:
    """Return the reduced exact-width grid (corners of the envelope) the tests run."""
    return _grid(config, QUICK_STIFFNESSES_N_PER_M, QUICK_DAMPING_RATIOS, widths=QUICK_WIDTHS_M,
                 masses=QUICK_MASSES_KG)


def holdout_cases(config) -> tuple[list[SweepCase], int]:
    """Return the envelope's inside at the exact width: objects none of :func:`quick_cases` is.

    Rigid and 1e3, 1e5, 1e7 N/m at a damping ratio of 0.1, 20 and 80 mm, 0.5 and 2 kg.
    """
    return _grid(config, HOLDOUT_STIFFNESSES_N_PER_M, HOLDOUT_DAMPING_RATIOS,
                 widths=HOLDOUT_WIDTHS_M, masses=HOLDOUT_MASSES_KG)


def compliant_cases(config, widths=WIDTHS_M, masses=MASSES_KG) -> tuple[list[SweepCase], int]:
    """Return rigid plus the stiff (1e5 N/m) and soft (1e3 N/m) objects of ``--compliant``."""
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
    grid, excluded = _joined(
        *([_grid(config, QUICK_STIFFNESSES_N_PER_M, QUICK_DAMPING_RATIOS, widths=widths,
                 masses=masses)] if exact else []),
        *([band_cases(config)] if band else []))
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
    from gripper_ros.studies.position_floor import minimum_rest_times_s
    return minimum_rest_times_s(config, setpoints_m, config.position.sample_time_s)


def case_keywords(case: SweepCase, force_controller, hold_s: float, config=None) -> dict:
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
    position_m = g.series.ticks['position_m']
    if held and position_m[hold].size:
        lo, hi = g.hold_force_range_n()
        drift = float(max(abs(position_m[hold].max() - position_m[hold.start - 1]),
                          abs(position_m[hold].min() - position_m[hold.start - 1])))
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
    results = simulate_grasps(config, [case_keywords(c, force_controller, hold_s, config)
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
