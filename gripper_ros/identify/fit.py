"""Identify the plant (Table I) from recorded runs: a linear seed, then output-error least squares.

What the signals can tell. With the motor voltage applied and the measured current ``i``, motor
speed ``w``, finger position ``x`` and contact force ``F``, the plant (``L i' = e - R i - k_b w``,
``J w' = k_t i - b w - lever F``, ``x' = rho w``, rigid contact ``F = k_t i / lever``) depends on
``k_t``, ``J``, ``b`` and ``eta`` (in ``lever = eta p N1/N2``) only through ``k_t / J``,
``b / J`` and ``k_t / lever``: scaling all four together changes no signal. So the fit's
parameters are ``theta = (R, k_b, k_t/J, b/J, k_t/lever, L)``; ``k_t`` stays as configured and
``J``, ``b``, ``eta`` follow from ``theta``; pitch and gear ratio are geometry (fixed). What is
reported are the identifiable combinations (:data:`COMBINATIONS`), each a function of the plant
keys, so a user's tools can recompute any of them from the ``plant`` keys.

Method.

1. Seed (:func:`linear_seed`): least squares on the exact zero-order-hold form of the model
   with the electrical pole taken as instantaneous (samples held ``>= SEED_MIN_HOLD_TAU_E``
   electrical time constants): ``w[n] = a w[n-1] + c e[n]`` (``a = exp(-T/tau_m)``,
   ``c = K (1 - a)``), ``i[n] = (e[n] - k_b w[n]) / R`` and, in rigid contact, ``F[n] = (k_t /
   lever) i[n]``.
2. Output error (:func:`identify`): ``scipy.optimize.least_squares`` on the package's own
   compiled plant (:func:`gripper_ros.core.physics.plant.plant_step`, so the voltage limit and
   contact are in the model) driven by the recorded voltages over the first ``1 - HELD_OUT_SHARE``
   of each run; residuals per channel divided by the channel's spread, then (``REWEIGHTINGS``)
   by the channel's own residual RMS, so that a precise sensor counts for what it is worth.
   Standard errors from the
   Jacobian, ``cov = s^2 (J^T J)^-1``, carried to the combinations by their gradients.
3. A parameter whose 10 % change moves the simulated channels by less than
   ``EXCITED_SENSITIVITY`` of their spread is not excited: it stays at its configured value and
   a warning names it.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace
import math

from gripper_ros.core.config import GripperConfig, parse_config, PlantParams
from gripper_ros.core.physics.force_sensor import FsrVoltageDivider
from gripper_ros.core.physics.plant import GraspObject, GripperPlant, plant_place
from gripper_ros.identify.replay import run_plant
from gripper_ros.wire import TICK_LAYOUT
import numpy as np
from scipy.optimize import least_squares

HELD_OUT_SHARE = 0.3            # the last 30 % of each run's time is kept out of the fit (NRMSE)
MIN_FREE_SAMPLES = 50           # fewer free-motion samples identify nothing
SEED_MIN_HOLD_TAU_E = 20.0      # seed samples: held at least this many electrical time constants
RIGID_FORCE_SHARE = 0.05        # rigid-contact samples for the seed: force above this x the peak
EXCITED_SENSITIVITY = 1e-4      # RMS change of normalised outputs for a 10 % parameter change
REWEIGHTINGS = 1                # fits again with each channel weighed by its residual's RMS
RESIDUAL_FLOOR = 1e-9           # a channel's residual RMS as a share of its spread, at least
SEGMENT_FORCE_SHARE = 0.05      # a segment starts where the force rises past this x its peak
MIN_SEGMENT_TICKS = 5           # a shorter segment joins the one before
RIGID_STIFFNESS_N_PER_M = 1e7   # an object recorded rigid that yields more than F / this is not
CHANNELS = ('position_m', 'speed_rad_s', 'current_a', 'force_n')
"""The measured signals fitted, as the loop's PlantTick names them."""

PARAMETERS = ('resistance_ohm', 'back_emf_v_s_per_rad', 'torque_per_inertia',
              'damping_per_inertia', 'torque_per_lever', 'inductance_h')
"""theta: what the output-error fit adjusts (see the module docstring)."""

FITTED_PLANT_KEYS = ('resistance_ohm', 'back_emf_v_s_per_rad', 'inductance_h', 'inertia_kg_m2',
                     'damping_n_m_s_per_rad', 'efficiency')
FIXED_PLANT_KEYS = ('torque_constant_n_m_per_a', 'gear_ratio', 'pitch_m', 'max_travel_m',
                    'gravity_mps2', 'voltage_limit_v', 'contact_substep_s')
NOT_SEPARABLE = ('torque_constant_n_m_per_a, inertia_kg_m2, damping_n_m_s_per_rad and '
                 'efficiency: scaling all four together changes no signal, so k_t stays as '
                 'configured and the other three are given for it')


COMBINATIONS = {
    'resistance_ohm': ('ohm', lambda p: p.resistance_ohm),
    'back_emf_v_s_per_rad': ('V s/rad', lambda p: p.back_emf_v_s_per_rad),
    'torque_per_inertia': ('1/(A s^2)', lambda p: p.torque_constant_n_m_per_a / p.inertia_kg_m2),
    'damping_per_inertia': ('1/s', lambda p: p.damping_n_m_s_per_rad / p.inertia_kg_m2),
    'stall_force_per_volt_n': ('N/V', lambda p: p.stall_force_per_volt_n),
    'free_speed_per_volt_mps': ('m/(s V)', lambda p: p.free_speed_per_volt_mps),
    'mechanical_time_constant_s': ('s', lambda p: p.mechanical_time_constant_s),
    'reflected_mass_kg': ('kg', lambda p: p.reflected_mass_kg),
    'reflected_damping_n_s_per_m': ('N s/m', lambda p: p.damping_n_m_s_per_rad / (
        p.force_lever_m * p.travel_per_rad_m)),
    'electrical_time_constant_s': ('s', lambda p: p.inductance_h / p.resistance_ohm),
}
"""Identifiable combinations: name -> (unit, value from PlantParams). The stall force per volt
is k_t N2 / (eta p N1 R_a); the free speed per volt and the mechanical time constant are the
position transfer function's gain and pole; the reflected mass and damping are J and b seen at
the finger."""

COMBINATION_NEEDS = {'stall_force_per_volt_n': ('torque_per_lever', 'resistance_ohm'),
                     'reflected_mass_kg': ('torque_per_lever', 'torque_per_inertia'),
                     'reflected_damping_n_s_per_m': ('torque_per_lever', 'damping_per_inertia'),
                     'electrical_time_constant_s': ('inductance_h', 'resistance_ohm')}
"""Combinations that need a parameter not every experiment excites."""


class IdentifyError(ValueError):
    """Data that cannot be identified (the message is one line and says why)."""


@dataclass
class Run:
    """One recorded run: per tick the voltage applied over the interval that ended then."""

    name: str
    t_ns: np.ndarray
    voltage_v: np.ndarray
    measured: dict                  # channel -> array (NaN where absent)
    object_width_m: float = 0.0
    stiffness_n_per_m: float = 0.0
    damping_n_s_per_m: float = 0.0
    left_out: np.ndarray | None = field(default=None, repr=False)   # ticks not fitted

    @property
    def fit_end(self) -> int:
        """First index of the held-out part: the last ``HELD_OUT_SHARE`` of the run's time."""
        t0, t1 = int(self.t_ns[0]), int(self.t_ns[-1])
        cut = t0 + round((t1 - t0) * (1.0 - HELD_OUT_SHARE))
        return max(2, int(np.searchsorted(self.t_ns, cut, side='right')))


def check_run(run: Run) -> Run:
    """Refuse (IdentifyError) a run without the signals or too short to identify anything."""
    n = len(run.t_ns)
    if not np.all(np.isfinite(run.voltage_v)):
        raise IdentifyError(f'{run.name}: the recorded motor voltage has non-finite samples')
    missing = [c for c in ('position_m', 'speed_rad_s', 'current_a')
               if c not in run.measured or not np.isfinite(run.measured[c]).any()]
    if missing:
        raise IdentifyError(f'{run.name}: no {", ".join(missing)} recorded; identification '
                            f'needs the voltage, position, speed and current')
    if n < MIN_FREE_SAMPLES or np.count_nonzero(
            np.abs(run.measured['speed_rad_s']) > 0.0) < MIN_FREE_SAMPLES:
        raise IdentifyError(f'{run.name}: too short to identify anything: {n} ticks, '
                            f'{np.count_nonzero(np.abs(run.measured["speed_rad_s"]) > 0.0)} in '
                            f'motion (at least {MIN_FREE_SAMPLES} needed)')
    if np.ptp(run.voltage_v) == 0.0:
        raise IdentifyError(f'{run.name}: the voltage never changes; nothing is excited')
    return run


# ------------------------------------------------------------------ parameters <-> plant keys
def theta_of(p: PlantParams) -> np.ndarray:
    """Return the fit's parameters of a plant (see :data:`PARAMETERS`)."""
    return np.array([p.resistance_ohm, p.back_emf_v_s_per_rad,
                     p.torque_constant_n_m_per_a / p.inertia_kg_m2,
                     p.damping_n_m_s_per_rad / p.inertia_kg_m2,
                     p.torque_constant_n_m_per_a / p.force_lever_m, p.inductance_h])


def plant_of(theta, base: PlantParams) -> PlantParams:
    """Return the plant keys of ``theta``, ``k_t`` and geometry from ``base``."""
    r, kb, alpha, beta, g, ind = (float(v) for v in theta)
    kt = base.torque_constant_n_m_per_a
    inertia = kt / alpha
    return replace(base, resistance_ohm=r, back_emf_v_s_per_rad=kb, inductance_h=ind,
                   inertia_kg_m2=inertia, damping_n_m_s_per_rad=beta * inertia,
                   efficiency=kt / (g * base.pitch_m * base.gear_ratio))


def combinations(p: PlantParams) -> dict[str, float]:
    """Every identifiable combination of a plant (name -> value)."""
    return {name: float(f(p)) for name, (_, f) in COMBINATIONS.items()}


# ------------------------------------------------------------------ simulation
def touching(run: Run) -> np.ndarray:
    """Tell, per tick, whether the measured force says the finger touches the object."""
    force = run.measured.get('force_n')
    if force is None or not np.isfinite(force).any():
        return np.zeros(len(run.t_ns), bool)
    peak = float(np.nanmax(np.abs(force)))
    return np.nan_to_num(force, nan=0.0) > SEGMENT_FORCE_SHARE * peak if peak > 0.0 else \
        np.zeros(len(run.t_ns), bool)


def yield_while_touching_m(run: Run, plant: PlantParams) -> float:
    """Return how far the measured speed carried the finger while it touched the object."""
    on = touching(run)
    both = np.flatnonzero(on[1:] & on[:-1]) + 1
    w = run.measured['speed_rad_s']
    dt_s = np.diff(run.t_ns)[both - 1] * 1e-9
    return plant.travel_per_rad_m * float(np.nansum(0.5 * np.abs(w[both] + w[both - 1]) * dt_s))


def leave_out_compliant_contact(run: Run, plant: PlantParams) -> tuple[Run, str]:
    """Return the run with the contact of an object recorded rigid that yielded left out.

    A rigid object stops the finger; one that lets it travel more than ``F /``
    :data:`RIGID_STIFFNESS_N_PER_M` while it is touched is compliant, of a stiffness the bag does
    not give, and no model of its contact is right: those ticks are left out (the model starts
    again from the measurement after each), and the second value says so (else '').
    """
    if run.stiffness_n_per_m != 0.0 or run.object_width_m <= 0.0:
        return run, ''
    travel_m = yield_while_touching_m(run, plant)
    peak_n = float(np.nanmax(np.abs(run.measured['force_n']))) if np.isfinite(
        run.measured.get('force_n', np.array([math.nan]))).any() else 0.0
    if not travel_m > peak_n / RIGID_STIFFNESS_N_PER_M:
        return run, ''
    on = touching(run)
    measured = {c: np.where(on, math.nan, v) for c, v in run.measured.items()}
    return replace(run, measured=measured, object_width_m=0.0, left_out=on), (
        f'{run.name}: the finger moved {travel_m * 1e3:.3g} mm while it touched an object the '
        f'bag records as rigid (a rigid one lets it move at most {peak_n:.3g} N / '
        f'{RIGID_STIFFNESS_N_PER_M:g} N/m = {peak_n / RIGID_STIFFNESS_N_PER_M * 1e3:.2g} mm): '
        f'the contact was compliant, of a stiffness the bag does not give, so its '
        f'{int(on.sum())} ticks in contact are left out of the fit')


def run_segments(run: Run, plant: PlantParams) -> list[tuple[int, int, bool]]:
    """Split a run where the model's state is read again from the measurement.

    A segment starts at the run's start and where the measured force rises into contact; the
    model starts each one from the measured speed and current, the finger at the object's face
    when a rigid object is touched. So no drift of a long open-loop run decides when a slow
    approach meets the object. Returns (start, end, placed at the face) per segment; one shorter
    than ``MIN_SEGMENT_TICKS`` joins the one before.
    """
    n = len(run.t_ns)
    on = touching(run)
    cuts = set(np.flatnonzero(on[1:] & ~on[:-1]) + 1)
    if run.left_out is not None:        # the model starts again after a part left out
        cuts |= set(np.flatnonzero(run.left_out[:-1] & ~run.left_out[1:]) + 1)
    starts = [0]
    for c in sorted(int(c) for c in cuts if c > 0):
        if c - starts[-1] >= MIN_SEGMENT_TICKS and n - c >= MIN_SEGMENT_TICKS:
            starts.append(c)
    rigid = run.stiffness_n_per_m == 0.0 and run.object_width_m > 0.0
    x_c = plant.max_travel_m - run.object_width_m
    return [(a, b, bool(rigid and on[a] and run.measured['position_m'][a] > x_c - 1e-3))
            for a, b in zip(starts, starts[1:] + [n])]


def _approaches(parts: list) -> list[bool]:
    """Tell, per segment, whether it ends where the next one starts at a rigid object's face."""
    return [not part[2] and after[2] for part, after in zip(parts, parts[1:] + [(0, 0, False)])]


def simulate(run: Run, plant_params: PlantParams, config: GripperConfig,
             x0s=None) -> np.ndarray:
    """Simulate the package's plant (ideal sensors) under the run's voltages, segment by segment.

    Each segment (:func:`run_segments`) starts from its first tick's measured speed and current,
    at the face, before it as far as the speed carried the finger, or at the first position
    ``x0s[0]`` (the run's first segment; default and later ones: the recorded position, within
    the travel). Columns in :data:`CHANNELS` order.
    """
    plant = GripperPlant(plant_params, FsrVoltageDivider(config.force_sensor), config.contact)
    m = run.measured
    x_c = plant_params.max_travel_m - run.object_width_m
    out = np.zeros((len(run.t_ns), len(CHANNELS)))
    tick = np.zeros(1, TICK_LAYOUT.dtype)
    parts = run_segments(run, config.plant)
    for (a, b, at_face), approach in zip(parts, _approaches(parts)):
        if run.left_out is not None and run.left_out[a]:
            out[a:b] = math.nan                             # left out: nothing to compare
            continue
        # a segment that ends on the face, the model meets it where the next one starts: in
        # between it moves free (no open-loop drift decides when a slow approach touches)
        plant_place(plant.kernel, 0.0, 0.0, 0.0)           # open: any object may be placed
        plant.set_object(GraspObject(0.0 if approach else run.object_width_m,
                                     run.stiffness_n_per_m, run.damping_n_s_per_m))
        if at_face:
            x0 = x_c
        elif approach:
            x0 = _approach_start_m(run, a, b, plant_params)
        elif a > 0 or x0s is None or not len(x0s):
            x0 = min(max(float(m['position_m'][a]), 0.0), x_c if run.stiffness_n_per_m == 0.0
                     else plant_params.max_travel_m)
        else:
            x0 = float(x0s[0])
        plant.t_ns = int(run.t_ns[a])
        plant_place(plant.kernel, x0, 0.0 if at_face else float(m['speed_rad_s'][a]),
                    float(m['current_a'][a]))
        run_plant(plant.kernel, run.t_ns[a:b], run.voltage_v[a:b], out[a:b], tick)
    return out


def _approach_start_m(run: Run, a: int, b: int, plant: PlantParams) -> float:
    """Return where a segment that ends on a rigid object's face starts.

    As far from the face as the measured speed carried the finger: a slow approach meets the
    face when the speed says, not when a noisy first position reading would have it.
    """
    w = run.measured['speed_rad_s'][a:b]
    dt_s = np.diff(run.t_ns[a:b + 1]) * 1e-9
    travel_rad = float(np.sum(0.5 * (w[:-1] + w[1:]) * dt_s[:-1]) + 0.5 * w[-1] * dt_s[-1])
    return max(0.0, plant.max_travel_m - run.object_width_m - plant.travel_per_rad_m *
               travel_rad)


def _placements(runs: list[Run], plant: PlantParams) -> tuple[list, list, list]:
    """Each fitted segment start's first guess and bounds (the measured position, the travel)."""
    start, lower, upper = [], [], []
    for run in runs:
        end = plant.max_travel_m - (run.object_width_m if run.stiffness_n_per_m == 0.0 else 0.0)
        for a in _fitted_starts(run, plant):
            x0 = float(run.measured['position_m'][a])
            start.append(min(max(x0, 0.0), end) if math.isfinite(x0) else 0.0)
            lower.append(0.0)
            upper.append(end)
    return start, lower, upper


def _fitted_starts(run: Run, plant: PlantParams) -> list[int]:
    """Return the first ticks of the segments whose first position is fitted: the run's first.

    (Later segments start at the face, before it as the speed says, or after a part left out
    at the measured position.)
    """
    parts = run_segments(run, plant)
    return [a for (a, _, at_face), approach in zip(parts[:1], _approaches(parts))
            if not at_face and not approach]


# ------------------------------------------------------------------ the linear seed
@dataclass
class Seed:
    """The linear fit on the exact ZOH form; NaN where the data had nothing for a term."""

    sample_time_s: float
    pole: float                    # a = exp(-T / tau_m)
    gain: float                    # c = K (1 - a), rad/s per V
    resistance_ohm: float
    back_emf_v_s_per_rad: float
    torque_per_lever: float        # k_t / lever, N per A (rigid contact)
    samples: int
    electrical_time_constant_s: float = math.nan   # L/R, from samples shorter than it x 20

    @property
    def mechanical_time_constant_s(self) -> float:
        return -self.sample_time_s / math.log(self.pole)

    @property
    def speed_per_volt_rad_s(self) -> float:
        return self.gain / (1.0 - self.pole)

    def theta(self, base: PlantParams) -> np.ndarray:
        """Return theta from the seed; the configured value where the seed has none."""
        out = theta_of(base)
        r, kb = self.resistance_ohm, self.back_emf_v_s_per_rad
        if math.isfinite(r) and r > 0.0 and math.isfinite(kb):
            out[0], out[1] = r, kb
        r, kb = out[0], out[1]
        if 0.0 < self.pole < 1.0 and self.gain > 0.0:
            inv_tau = 1.0 / self.mechanical_time_constant_s
            alpha = self.speed_per_volt_rad_s * r * inv_tau
            beta = inv_tau - alpha * kb / r
            if alpha > 0.0 and beta > 0.0:
                out[2], out[3] = alpha, beta
        if math.isfinite(self.torque_per_lever) and self.torque_per_lever > 0.0:
            out[4] = self.torque_per_lever
        if math.isfinite(self.electrical_time_constant_s) and \
                self.electrical_time_constant_s > 0.0:
            out[5] = self.electrical_time_constant_s * r
        return out


def linear_seed(runs: list[Run], base: PlantParams) -> Seed:
    """Least squares on the exact ZOH form, electrical pole instantaneous (module docstring)."""
    tau_e = base.inductance_h / base.resistance_ohm
    rows_w, rows_i, rows_f, dts = [], [], [], []
    for run in runs:
        dt_ns = np.diff(run.t_ns)
        dts.append(dt_ns)
    dt_all = np.concatenate(dts)
    values, counts = np.unique(dt_all, return_counts=True)
    long_enough = values * 1e-9 >= SEED_MIN_HOLD_TAU_E * tau_e
    if not long_enough.any():
        raise IdentifyError('no samples held long enough for the seed (every hold is shorter '
                            f'than {SEED_MIN_HOLD_TAU_E:g} electrical time constants)')
    period_ns = int(values[long_enough][np.argmax(counts[long_enough])])
    for run in runs:
        m = run.measured
        w, i, e, f = m['speed_rad_s'], m['current_a'], run.voltage_v, m['force_n']
        dt_ns = np.diff(run.t_ns)
        held = np.flatnonzero(dt_ns * 1e-9 >= SEED_MIN_HOLD_TAU_E * tau_e) + 1
        rows_i.append(np.column_stack((e[held], -w[held], i[held])))
        free = np.flatnonzero((dt_ns == period_ns) & (w[1:] != 0.0) & (w[:-1] != 0.0)) + 1
        rows_w.append(np.column_stack((w[free - 1], e[free], w[free])))
        if np.isfinite(f).any():
            peak = np.nanmax(np.abs(f))
            # in rigid contact the force follows the current at once: any period will do
            rigid = np.flatnonzero((w == 0.0) & (f > RIGID_FORCE_SHARE * peak) & (i > 0.0))
            rows_f.append(np.column_stack((i[rigid], f[rigid])))
    a_w = np.concatenate(rows_w)
    a_i = np.concatenate(rows_i)
    a_w = a_w[np.isfinite(a_w).all(axis=1)]             # ticks left out are NaN
    a_i = a_i[np.isfinite(a_i).all(axis=1)]
    if len(a_w) < MIN_FREE_SAMPLES:
        raise IdentifyError(f'too short to identify anything: {len(a_w)} free-motion samples '
                            f'at the sampling period (at least {MIN_FREE_SAMPLES} needed)')
    (pole, gain), *_ = np.linalg.lstsq(a_w[:, :2], a_w[:, 2], rcond=None)
    (inv_r, kb_over_r), *_ = np.linalg.lstsq(a_i[:, :2], a_i[:, 2], rcond=None)
    g = math.nan
    if rows_f:
        a_f = np.concatenate(rows_f)
        if len(a_f):
            g = float(a_f[:, 0] @ a_f[:, 1] / (a_f[:, 0] @ a_f[:, 0]))
    r, kb = 1.0 / inv_r, kb_over_r / inv_r
    return Seed(period_ns * 1e-9, float(pole), float(gain), r, kb, g, len(a_w),
                _electrical_seed(runs, r, kb, period_ns))


def _electrical_seed(runs: list[Run], r: float, kb: float, period_ns: int) -> float:
    """Return L/R from the samples at the shortest period (NaN: none, or the fit has no sense).

    Over a sample ``T`` the current tends to ``u = (e - k_b w) / R`` (``w`` the mean of its
    ends): ``i[n] - u[n] = a (i[n-1] - u[n])``, ``a = exp(-T R / L)``, by least squares.
    """
    dts = np.concatenate([np.diff(run.t_ns) for run in runs])
    if not dts.size or dts.min() >= period_ns:
        return math.nan
    short = int(dts.min())
    xs, ys = [], []
    for run in runs:
        m = run.measured
        n = np.flatnonzero(np.diff(run.t_ns) == short) + 1
        u = (run.voltage_v[n] - kb * 0.5 * (m['speed_rad_s'][n] + m['speed_rad_s'][n - 1])) / r
        xs.append(m['current_a'][n - 1] - u)
        ys.append(m['current_a'][n] - u)
    x, y = np.concatenate(xs), np.concatenate(ys)
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < MIN_FREE_SAMPLES or not x[ok] @ x[ok] > 0.0:
        return math.nan
    a = float(x[ok] @ y[ok] / (x[ok] @ x[ok]))
    return -short * 1e-9 / math.log(a) if 0.0 < a < 1.0 else math.nan


# ------------------------------------------------------------------ output error
@dataclass
class Identified:
    """The result: the identified plant, its combinations with standard errors, the checks."""

    plant: PlantParams
    base: GripperConfig
    seed: Seed
    fitted: list[str]
    not_excited: list[str]
    combinations: dict[str, float]
    stderr: dict[str, float]
    nrmse: dict[str, dict[str, float]]          # run -> channel -> held-out NRMSE
    warnings: list[str] = field(default_factory=list)
    simulated: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    cost: float = 0.0
    iterations: int = 0

    def config_data(self) -> dict:
        """Return the base configuration with the identified plant keys (for ``--config``)."""
        data = copy.deepcopy(self.base.data)
        for key in FITTED_PLANT_KEYS:
            data['plant'][key] = float(getattr(self.plant, key))
        data.pop('sensor_noise', None)        # the model, not the sensors it was seen through
        return data

    def config(self) -> GripperConfig:
        return parse_config(self.config_data(), 'identified')


def _scales(runs: list[Run]) -> dict[str, float]:
    """Each channel's spread over the fit parts (0: not fitted)."""
    out = {}
    for c in CHANNELS:
        vals = np.concatenate([r.measured[c][:r.fit_end] for r in runs])
        vals = vals[np.isfinite(vals)]
        out[c] = float(np.std(vals)) if vals.size > 1 else 0.0
    return out


def _residuals(runs, scales, config, base_theta, free, values, part):
    """Weighted residuals; ``values`` = log theta[free], then the segments' first positions."""
    theta = base_theta.copy()
    theta[free] = np.exp(values[:free.size])
    plant = plant_of(theta, config.plant)
    out = []
    placed = free.size
    for run in runs:
        count = len(_fitted_starts(run, config.plant))
        x0s = values[placed:placed + count] if values.size > free.size else None
        placed += count
        sim = simulate(run, plant, config, x0s)
        rows = slice(0, run.fit_end) if part == 'fit' else slice(run.fit_end, None)
        for j, c in enumerate(CHANNELS):
            if scales[c] > 0.0:
                rec = run.measured[c][rows]
                r = (sim[rows, j] - rec) / scales[c]
                out.append(np.where(np.isfinite(r), r, 0.0))
    return np.concatenate(out)


def nrmse(simulated: np.ndarray, recorded: np.ndarray, span: float | None = None) -> float:
    """RMS error over ``span`` (default the recorded range); NaN samples left out.

    NaN for a flat channel.
    """
    ok = np.isfinite(recorded) & np.isfinite(simulated)
    if span is None:
        span = float(np.ptp(recorded[ok])) if ok.sum() else 0.0
    if ok.sum() < 2 or not span > 0.0:
        return math.nan
    err = simulated[ok] - recorded[ok]
    return float(np.sqrt(np.mean(err ** 2)) / span)


def identify(runs: list[Run], config: GripperConfig) -> Identified:
    """Identify the plant of ``runs``; ``config`` gives the fixed keys and the starting point."""
    runs = [check_run(r) for r in runs]
    left_out = [leave_out_compliant_contact(r, config.plant) for r in runs]
    runs = [r for r, _ in left_out]
    seed = linear_seed(runs, config.plant)
    theta0 = seed.theta(config.plant)
    try:
        parse_config(_with_plant(config, plant_of(theta0, config.plant)), 'seed')
    except ValueError:
        theta0 = theta_of(config.plant)             # a seed the reader refuses: start nominal
    scales = _scales(runs)
    everything = np.arange(len(PARAMETERS))
    base_r = _residuals(runs, scales, config, theta0, everything, np.log(theta0), 'fit')
    warnings = [why for _, why in left_out if why]
    not_excited = []
    for j, name in enumerate(PARAMETERS):
        log_values = np.log(theta0)
        log_values[j] += math.log(1.1)
        moved = _residuals(runs, scales, config, theta0, everything, log_values, 'fit') - base_r
        if math.sqrt(np.mean(moved ** 2)) < EXCITED_SENSITIVITY:
            not_excited.append(name)
            warnings.append(f'{name} is not excited by these runs (a 10 % change moves the '
                            f'simulated signals by less than {EXCITED_SENSITIVITY:g} of their '
                            f'spread); it stays at its configured value')
    free = np.array([j for j, n in enumerate(PARAMETERS) if n not in not_excited])
    labels = np.concatenate([np.full(r.fit_end, j) for r in runs
                             for j, c in enumerate(CHANNELS) if scales[c] > 0.0])
    # Each segment's first position is fitted too: a noisy first reading would offset it.
    x_start, x_lower, x_upper = _placements(runs, config.plant)
    start = np.concatenate((np.log(theta0[free]), x_start))
    lower = np.concatenate((np.full(free.size, -np.inf), x_lower))
    upper = np.concatenate((np.full(free.size, np.inf), x_upper))
    nfev = 0
    for _ in range(REWEIGHTINGS + 1):
        result = least_squares(
            lambda lv: _residuals(runs, scales, config, theta0, free, lv, 'fit'),
            start, bounds=(lower, upper), method='trf', x_scale=1.0, diff_step=1e-6,
            xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=200)
        nfev += result.nfev
        start = result.x
        # Weigh each channel by its own residual (the maximum-likelihood weights of sensors
        # with different noise): the precise channels then pin the parameters.
        for j, c in enumerate(CHANNELS):
            if scales[c] > 0.0:
                rms = math.sqrt(float(np.mean(result.fun[labels == j] ** 2)))
                scales[c] *= max(rms, RESIDUAL_FLOOR)
    theta = theta0.copy()
    theta[free] = np.exp(result.x[:free.size])
    plant = plant_of(theta, config.plant)
    # Each channel's own residual variance weighs its rows (noise differs per sensor).
    weights = np.ones(labels.size)
    dof = max(1.0, (result.fun.size - free.size) / result.fun.size)
    for j in np.unique(labels):
        rows = labels == j
        var = max(float(np.mean(result.fun[rows] ** 2)) / dof, 1e-24)
        weights[rows] = 1.0 / math.sqrt(var)
    # (J^T J)^-1 from J's singular values, none dropped: a weakly determined direction keeps
    # its large variance (a truncating pseudo-inverse would call it exact).
    # (a segment start wholly in the held-out part moves nothing: its column is left out)
    used = np.flatnonzero(np.any(result.jac != 0.0, axis=0))
    _, sing, vt = np.linalg.svd(result.jac[:, used] * weights[:, None], full_matrices=False)
    cov_log = np.zeros((result.x.size, result.x.size))
    with np.errstate(divide='ignore', invalid='ignore'):
        cov_log[np.ix_(used, used)] = (vt.T / sing ** 2) @ vt
    combos = combinations(plant)
    stderr = {}
    for name in COMBINATIONS:
        needs = COMBINATION_NEEDS.get(name, ())
        if any(n in not_excited for n in needs):
            stderr[name] = math.nan
            continue
        grad = np.zeros(result.x.size)          # the first positions: no share
        for jj, j in enumerate(free):
            bumped = theta.copy()
            bumped[j] *= math.exp(1e-6)
            grad[jj] = (COMBINATIONS[name][1](plant_of(bumped, config.plant)) - combos[name]) \
                / 1e-6
        stderr[name] = float(math.sqrt(max(0.0, grad @ cov_log @ grad)))
    simulated, table = {}, {}
    placed = free.size
    for run in runs:
        count = len(_fitted_starts(run, config.plant))
        sim = simulate(run, plant, config, result.x[placed:placed + count])
        placed += count
        simulated[run.name] = sim
        held = slice(run.fit_end, None)
        table[run.name] = {c: nrmse(sim[held, j], run.measured[c][held],
                                    float(np.nanmax(run.measured[c]) - np.nanmin(run.measured[c])))
                           for j, c in enumerate(CHANNELS)}
    return Identified(plant, config, seed, [PARAMETERS[j] for j in free], not_excited, combos,
                      stderr, table, warnings, simulated, float(result.cost), nfev)


def _with_plant(config: GripperConfig, plant: PlantParams) -> dict:
    data = copy.deepcopy(config.data)
    for key in FITTED_PLANT_KEYS:
        data['plant'][key] = float(getattr(plant, key))
    return data
