"""Episodes: what each environment draws, and the rows of many environments reset at once.

An episode is the nominal scene changed in its episode parameters (each declared once in
:mod:`abb_gym.envs.episode_parameters`: imbalance and phase, initial ball angles, race drag,
rolling resistance, critical speed, support damping, fluid temperature), drawn from the
preset's ``randomize`` ranges or given as reset options.  With a noisy synchronous-vibration
observation it also draws the key of its sensor noise (:mod:`abb_gym.physics.sensors`); with
redistribution of the laundry, the imbalances of the redistributions to come
(:mod:`abb_gym.envs.redistribution`).

* :func:`draw` takes one environment's values from its own generator in a fixed order, with
  one ``rng.random`` call (the numbers ``rng.uniform`` would give one by one: ``low + (high -
  low) u``), then the noise key (``rng.integers``, only when the observation is noisy), then
  the redistributions' draws (only when the laundry redistributes), then applies the reset
  options.  A randomised parameter added later takes its number after the existing ones, so
  presets that leave it off draw the same episodes as before.
* :func:`prepare` computes what resetting many rows at once writes: the packed parameters
  (:func:`abb_gym.physics.variants.packed_variants`), the initial state, the drive rows and
  the bookkeeping of the compiled step, with numpy over the rows plus one compiled call for
  the stiff rates that set each episode's integration step; it changes nothing, so a reset
  it rejects leaves every row as it was.  :func:`commit` then writes it
  (``EnvSetup.reset_rows`` does both).  The single environment resets through the same
  functions with one row, so a single environment and a sub-environment of the vector
  environment stay alike bit for bit.
* :class:`EpisodeTable` keeps the values of every row; :class:`Episode` is one row's view,
  whose Scene is built only when asked for (building and validating a Scene costs ~0.3 ms, the
  reset of a row without it a few microseconds).

**Angles** (the parameters declared ``angle``, given or drawn) are reduced to [-pi, pi] with
the exact IEEE remainder: an angle and the same angle plus any multiple of 2 pi (as floats:
``1e16`` and ``np.mod(1e16, 2 pi)``) give the same machine bit for bit, and the compiled
sin/cos, accurate to ``|x| <= 1.6e6`` rad (:mod:`abb_gym.physics.elementary`), never see a
huge one.  Angles already in [-pi, pi] (every shipped scene and preset) are left as they are.

**Stiff episodes.**  Under RK4 an episode's step is bounded by its stiff rate (the ball drag
and rolling resistance, :func:`abb_gym.physics.steps.default_step`).  An episode whose
stiff rate forces a step more than :data:`MAX_STIFFNESS` times shorter than the step its
rotation needs (``ball_drag_scale=1e6`` on yoshida_odd: a 2e-9 s step, 5 million RK4 steps and
seconds of work per control interval) is refused with a ValueError that says what to use
(``integrator="etdrk4"``, which integrates the drag exactly at the ordinary step, or smaller
scales): at reset for reset options, and when the environment is made for a preset whose
``randomize`` ranges allow such an episode, so that an automatic reset never fails.  An
explicit ``integration_step`` is the user's choice and is not checked.  The check takes the
corners of every range the step depends on (the parameters declared with ``step_corner``).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Mapping, Sequence

import numpy as np

from ..physics import drive_law as dl
from ..physics import model as mdl
from ..physics import runup, sensors, variants
from ..physics.scene import Scene
from ..physics.steps import default_step, stiff_rates
from . import redistribution
from .config import PresetError
from .episode_parameters import BY_NAME, PARAMETERS, RESET_OPTIONS, machine_changes
from .layout import (N_ST, S_ACC, S_AOP, S_AREF, S_DTMAX, S_MARK, S_NKEY, S_NSEG,
                     S_PEN_RATE, S_PEN_TERM, S_UBEST, S_USCALE, S_XS, S_YS)

__all__ = ["RESET_OPTIONS", "MAX_STIFFNESS", "Episode", "EpisodeTable", "Pending", "draw",
           "draw_rows", "prepare", "commit", "check_preset_stiffness", "check_preset_machines",
           "reduce_angle", "draw_ball_angles", "NOISE_KEY"]

# Largest ratio of the step an episode's rotation needs to the step its stiff rate forces on
# RK4 (module docstring).  The shipped scenes and presets need at most 15 (washer's rolling
# resistance; yoshida_odd about 2; tests/test_env_inputs.py keeps a margin of 5).  A ratio of
# 100 already costs a hundred times the ordinary work (on yoshida_odd about 1 ms per control
# interval of one environment, 1 s per episode); far beyond it the work grows without bound.
MAX_STIFFNESS = 100.0

TWO_PI = 2.0 * math.pi
#: the draws' entry of the sensor noise key
NOISE_KEY = "noise_key"


def reduce_angle(angle):
    """``angle`` [rad] (a float or an array) reduced to [-pi, pi] by the exact IEEE remainder
    modulo the float 2 pi; angles already in [-pi, pi] come back unchanged, bit for bit."""
    if np.ndim(angle) == 0:
        return math.remainder(float(angle), TWO_PI)
    a = np.asarray(angle, float)
    out = a.copy()
    # only the angles outside [-pi, pi] change (math.remainder returns the others as they
    # are), so only they pay for the Python loop: the drawn ones never do
    far = np.abs(a) > math.pi
    if far.any():
        out[far] = [math.remainder(v, TWO_PI) for v in a[far]]
    return out


class Episode:
    """Parameters of one episode: every episode parameter by its name, in its unit
    (:data:`~abb_gym.envs.episode_parameters.PARAMETERS`), the integration step bound
    ``integration_step`` [s], the rotor's rest position ``static_deflection`` (x, y) [m], the
    key of the sensor noise ``noise_key`` and, with redistribution, the imbalances of the
    redistributions to come ``redistributions`` ((count, 2): imbalance [kg m], phase
    [rad])."""

    def __init__(self, nominal: Scene, values: Mapping[str, Any], integration_step: float,
                 static_deflection: tuple[float, float] = (0.0, 0.0), noise_key: int = 0,
                 redistributions: np.ndarray | None = None):
        self.nominal = nominal
        self.values = dict(values)
        self.integration_step = integration_step
        self.static_deflection = static_deflection
        self.noise_key = noise_key
        self.redistributions = (np.zeros((0, 2)) if redistributions is None
                                else redistributions)

    def __getattr__(self, name: str) -> Any:
        values = self.__dict__.get("values")
        if values is not None and name in values:
            return values[name]
        raise AttributeError(name)

    def __repr__(self) -> str:
        text = ", ".join(f"{k}={v!r}" for k, v in self.values.items())
        return f"Episode({text}, integration_step={self.integration_step!r})"

    @cached_property
    def scene(self) -> Scene:
        """The episode as a Scene (built on first use)."""
        return variants.variant_scene(self.nominal, **machine_changes(self.values))

    def as_info(self) -> dict[str, Any]:
        info: dict[str, Any] = {}
        for par in PARAMETERS:
            v = self.values[par.name]
            info[par.key] = v.copy() if isinstance(v, np.ndarray) else v
        info["integration_step"] = self.integration_step
        info["static_deflection"] = np.array(self.static_deflection)
        return info


class EpisodeTable:
    """The current episode of every row (arrays over rows, one per episode parameter;
    :meth:`episode` gives one row)."""

    def __init__(self, scene: Scene, n: int, events: int = 0):
        self.scene = scene
        self.started = np.zeros(n, dtype=bool)
        self.values: dict[str, np.ndarray] = {}
        for par in PARAMETERS:
            nominal = par.nominal(scene)
            self.values[par.name] = (np.tile(np.asarray(nominal, float), (n, 1)) if par.per_ball
                                     else np.full(n, float(nominal)))
        self.noise_key = np.zeros(n, dtype=np.int64)
        self.integration_step = np.zeros(n)
        self.reference_length = np.full(n, scene.reference_length)
        self.static_deflection = np.tile(np.array(variants.rotor.static_deflection(scene)),
                                         (n, 1))
        self.redistributions = np.zeros((n, events, 2))

    def __getattr__(self, name: str) -> np.ndarray:
        values = self.__dict__.get("values")
        if values is not None and name in values:
            return values[name]
        raise AttributeError(name)

    def episode(self, i: int) -> Episode | None:
        """Row ``i``'s episode (None before its first reset)."""
        if not self.started[i]:
            return None
        values = {name: (v[i].copy() if v.ndim == 2 else float(v[i]))
                  for name, v in self.values.items()}
        return Episode(self.scene, values, float(self.integration_step[i]),
                       (float(self.static_deflection[i, 0]),
                        float(self.static_deflection[i, 1])),
                       int(self.noise_key[i]), self.redistributions[i].copy())

    def info(self, rows) -> dict[str, np.ndarray]:
        """The episode parameters of ``rows`` as arrays over all rows (0 elsewhere): the keys
        of :meth:`Episode.as_info`."""
        rows = np.asarray(rows, dtype=np.int64)
        n = self.started.shape[0]
        out: dict[str, np.ndarray] = {}
        for par in PARAMETERS:
            values = self.values[par.name]
            arr = np.zeros_like(values)
            arr[rows] = values[rows]
            out[par.key] = arr
        arr = np.zeros_like(self.integration_step)
        arr[rows] = self.integration_step[rows]
        out["integration_step"] = arr
        sag = np.zeros((n, 2))
        sag[rows] = self.static_deflection[rows]
        out["static_deflection"] = sag
        return out


def _show(value: Any) -> str:
    """A short one-line picture of a given option (arrays by shape, long text cut)."""
    if isinstance(value, np.ndarray) and value.size > 4:
        return f"an array of shape {value.shape}"
    text = " ".join(repr(value).split())
    return text if len(text) <= 80 else text[:77] + "..."


def _is_number(value: Any) -> bool:
    """True for a real number (Python or NumPy, or a 0-d numeric array); not for bools or text,
    which ``float()`` would take as 1.0 or parse."""
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    return isinstance(value, (int, float, np.integer, np.floating)) \
        and not isinstance(value, (bool, np.bool_))


def _opt_number(name: str, value: Any, lo: float | None, unit: str, inclusive: bool = True
                ) -> float:
    if not _is_number(value):
        raise ValueError(f"reset option {name!r} must be a number [{unit}] (got "
                         f"{_show(value)})")
    v = float(value)
    if not math.isfinite(v) or (lo is not None and (v < lo or (v == lo and not inclusive))):
        rng = "finite" if lo is None else f"{'>=' if inclusive else '>'} {lo:g}"
        raise ValueError(f"reset option {name!r} must be {rng} [{unit}] (got {_show(value)})")
    return v


def _opt_angles(name: str, given: Any, nb: int) -> np.ndarray:
    try:
        a = np.asarray(given)
        ok = a.dtype.kind in "fiu"
        a = a.astype(float) if ok else a
    except (TypeError, ValueError):  # ragged or unreadable
        ok = False
    if ok and a.ndim == 0:
        a = np.full(nb, float(a))
    if not ok or a.shape != (nb,) or not np.all(np.isfinite(a)):
        raise ValueError(f"reset option {name!r} must be {nb} finite angles [rad] "
                         f"(got {_show(given)})")
    return a.copy()


def _uniform(lo_hi: Sequence[float], u):
    lo, hi = float(lo_hi[0]), float(lo_hi[1])
    return lo + (hi - lo) * u


def draw_ball_angles(setup: Any, rng: np.random.Generator) -> np.ndarray:
    """Initial ball angles [rad], one per ball, drawn as the preset draws them (uniform in its
    ``randomize.ball_angles`` range) from ``rng``: the balls of a machine started somewhere else
    (:func:`abb_gym.baselines.oracle.balls_elsewhere`).  ValueError if the preset fixes the
    angles (``ball_angles: null``): then there is nowhere else to start them."""
    span = setup.config.randomize.ball_angles
    if span is None:
        raise ValueError(f"preset {setup.config.name!r} fixes the initial ball angles "
                         f"(randomize.ball_angles is null): there is nowhere else to start the "
                         f"balls")
    return _uniform(span, rng.random(setup.scene.ball_count))


def _check_options(options: Any) -> None:
    allowed = [*RESET_OPTIONS, redistribution.OPTION]
    if options is not None and not isinstance(options, Mapping):
        raise ValueError(f"options must be a dict with keys from {allowed} (got "
                         f"{_show(options)})")
    if options:
        unknown = sorted(set(options) - set(allowed), key=str)  # keys of any type
        if unknown:
            raise ValueError(f"unknown reset option(s) {unknown}; allowed: {allowed}")


def draw(setup: Any, rng: np.random.Generator, options: Mapping[str, Any] | None
         ) -> dict[str, Any]:
    """One environment's episode values: every episode parameter by name (numbers; the
    ball angles an array), the noise key (:data:`NOISE_KEY`) and the redistributions' draws
    (:data:`abb_gym.envs.redistribution.DRAWS`, with redistribution): the preset's random
    draws from ``rng`` (:func:`_preset_draws`), then ``options`` (:data:`RESET_OPTIONS`) in
    their place."""
    sc = setup.scene
    drawn = _preset_draws(setup, [rng])
    values: dict[str, Any] = {}
    for name, column in drawn.items():
        values[name] = (column[0].copy() if column.ndim > 1 else column[0].item())
    _check_options(options)
    if options:
        for par in PARAMETERS:
            names = [n for n in (par.name, *(u.name for u in par.option_units))
                     if n in options]
            if len(names) > 1:
                raise ValueError(f"reset options {names[0]!r} and {names[1]!r} exclude each "
                                 f"other")
            if not names:
                continue
            name = names[0]
            if par.per_ball:
                value: Any = _opt_angles(name, options[name], sc.ball_count)
            elif name == par.name:
                value = _opt_number(name, options[name], par.option_lower, par.unit,
                                    par.option_inclusive)
            else:
                unit = next(u for u in par.option_units if u.name == name)
                value = unit.to_value(sc, _opt_number(name, options[name], unit.lower,
                                                      unit.unit))
            values[par.name] = value
            if par.machine_check:
                # the machine with the changes given so far (the later ones nominal, as
                # their own checks come after)
                _check_machine_option(sc, f"reset option {name!r}", values, par)
        if redistribution.OPTION in options:
            redistribution.apply_option(setup, values, options[redistribution.OPTION])
    redistribution.start_at_rest(setup, values, bool(options) and "ball_angles" in options)
    for par in PARAMETERS:
        if par.angle:
            # angles far beyond 2 pi: the same machine as their remainder (module docstring)
            values[par.name] = reduce_angle(values[par.name])
        elif not par.per_ball:
            values[par.name] = float(values[par.name])
    values[NOISE_KEY] = int(values[NOISE_KEY])
    return values


def _check_machine_option(scene: Scene, where: str, values: Mapping[str, Any],
                          checked: Any) -> None:
    """A machine-checked option: the machine with the machine-checked parameters up to
    ``checked`` (in declaration order) at their current values must exist."""
    changes = {}
    for par in PARAMETERS:
        if par.machine_check:
            changes[par.name] = values[par.name]
        if par is checked:
            break
    variants.check_machine(scene, where, ValueError, **changes)


def _no_options(options: Sequence[Any] | None) -> bool:
    return options is None or all(o is None or (isinstance(o, Mapping) and not o)
                                  for o in options)


def draw_rows(setup: Any, rngs: Sequence[np.random.Generator],
              options: Sequence[Mapping[str, Any] | None] | None = None
              ) -> dict[str, np.ndarray]:
    """:func:`draw` for many environments, row ``k`` from ``rngs[k]`` with ``options[k]``, as
    arrays over rows (the ball angles rows x balls).

    Without reset options (the autoreset of a vector environment) the values are mapped onto
    the preset's ranges for all rows at once (:func:`_preset_draws`, which :func:`draw`
    reads too); each generator still gives its own draws in the same order, so every seeded
    episode is unchanged.  With options, row by row through :func:`draw`."""
    if not _no_options(options):
        values = [draw(setup, rng, None if options is None else options[k])
                  for k, rng in enumerate(rngs)]
        return {name: np.array([v[name] for v in values]) for name in values[0]}
    values = _preset_draws(setup, rngs)
    redistribution.start_at_rest(setup, values)
    return values


def _preset_draws(setup: Any, rngs: Sequence[np.random.Generator]) -> dict[str, np.ndarray]:
    """The preset's random draws of every row, as arrays over rows (:func:`draw_rows`'
    layout): row ``k`` takes one ``rngs[k].random`` call for the randomised parameters (in
    the order of :data:`~abb_gym.envs.episode_parameters.PARAMETERS`; the nominal values for
    the others), then the noise key if the observation is noisy, then the redistributions'
    draws if the laundry redistributes; angles reduced to [-pi, pi]."""
    sc = setup.scene
    rz = setup.config.randomize
    nb = sc.ball_count
    n = len(rngs)
    values: dict[str, np.ndarray] = {}
    for par in PARAMETERS:
        nominal = par.nominal(sc)
        values[par.name] = (np.tile(np.asarray(nominal, dtype=float), (n, 1)) if par.per_ball
                            else np.full(n, float(nominal)))
    randomised = [par for par in PARAMETERS if getattr(rz, par.randomize) is not None]
    count = sum(nb if par.per_ball else 1 for par in randomised)
    if count and n:
        u = np.array([rng.random(count) for rng in rngs])
        k = 0
        for par in randomised:
            width = nb if par.per_ball else 1
            drawn = u[:, k:k + nb] if par.per_ball else u[:, k]
            values[par.name] = par.drawn(sc, _uniform(getattr(rz, par.randomize), drawn))
            k += width
    sync = setup.config.sync_vibration
    if sync.enabled and sync.noise > 0.0:
        key = np.array([int(rng.integers(0, sensors.KEY_BOUND)) for rng in rngs],
                       dtype=np.int64)
    else:
        key = np.zeros(n, dtype=np.int64)
    for par in PARAMETERS:
        if par.angle:
            values[par.name] = reduce_angle(values[par.name])
    values[NOISE_KEY] = key
    values.update(redistribution.draws(setup, rngs))
    return values


def _rk4_steps(setup: Any, p: np.ndarray, b: np.ndarray, values: Mapping[str, Any],
               where: str, error: type[ValueError] = ValueError) -> np.ndarray:
    """The RK4 step of each packed episode [s] (``values``: the episodes' parameters, arrays
    over the rows of ``p``); raises ``error`` if the stiffest needs a step more than
    :data:`MAX_STIFFNESS` times shorter than its rotation alone does (module docstring)."""
    n = p.shape[0]
    varied = variants.rates_vary(machine_changes(values))
    rate = stiff_rates(p, b, setup.max_speed)
    step = np.broadcast_to(np.asarray(_steps(setup, p, "rk4", rate, varied), float), (n,))
    needed = np.broadcast_to(np.asarray(_steps(setup, p, "rk4", np.zeros(n) if varied else 0.0,
                                               varied), float), (n,))
    k = int(np.argmax(needed / step))
    if needed[k] > MAX_STIFFNESS * step[k]:
        raise error(_stiff_message(setup, values, k, step[k], needed[k], where, varied))
    return step


def _stiff_message(setup: Any, values: Mapping[str, Any], k: int, step: float, needed: float,
                   where: str, varied: bool) -> str:
    per = setup.control_interval / step
    sc = setup.scene

    def shown(par) -> str:
        return f"{par.name}={float(np.asarray(values[par.name])[k]):g}"

    corners = [par for par in PARAMETERS if par.step_corner]
    # the drag and rolling resistance always; the machine's mass and damping when they vary;
    # any other parameter where it differs from the scene
    own = [par for par in corners if par.name not in variants.RATE_CHANGES
           and (not par.machine_check
                or float(np.asarray(values[par.name])[k]) != par.nominal(sc))]
    machine = " and ".join(shown(par) for par in own)
    if varied:
        machine += ", " + " and ".join(shown(par) for par in corners
                                       if par.name in variants.RATE_CHANGES)
    return (f"{where}: an episode with {machine} is too stiff for integrator='rk4': its ball "
            f"drag and rolling resistance force a {step:.3g} s step at the top speed "
            f"{setup.max_speed:.4g} rad/s (from operating_speed = {setup.operating_speed:.4g} "
            f"rad/s) ({per:.3g} RK4 steps per {setup.control_interval:g} s control interval, "
            f"{needed / step:.3g} x shorter than the {needed:.3g} s its rotation needs; at most "
            f"{MAX_STIFFNESS:g} x is allowed); use integrator='etdrk4' (integrates the stiff "
            f"drag exactly at the ordinary step) or smaller scales")


def _steps(setup: Any, p: np.ndarray, method: str, rate, varied: bool) -> np.ndarray:
    """:func:`default_step` of each packed episode (``varied``: their masses or support
    damping differ from the scene's)."""
    sc = setup.scene
    if not varied:
        return default_step(sc, setup.max_speed, method, rate=rate)
    crit, other = variants.machine_rates(p)
    return default_step(sc, setup.max_speed, method, rate=rate, critical_speed=crit,
                        other_rate=other)


def _corners(value) -> list[float]:
    return [None] if value is None else [float(v) for v in np.atleast_1d(value)]


def check_preset_machines(setup: Any) -> None:
    """Raise PresetError naming the field if a corner of a machine-checked range of the preset
    (critical speed, support damping, fluid temperature) is not a machine (no rotor mass left,
    a field out of the scene's bounds, or under gravity a static sag beyond the housing
    clearance)."""
    cfg = setup.config
    rz = cfg.randomize
    where = f"environment preset {cfg.name!r}: field 'randomize.%s'"
    # (each parameter on its own: none changes what makes another one valid)
    for par in PARAMETERS:
        if not par.machine_check:
            continue
        for corner in _corners(getattr(rz, par.randomize)):
            if corner is not None:
                variants.check_machine(setup.scene, where % par.randomize, PresetError,
                                       **{par.name: par.drawn(setup.scene, corner)})


def check_preset_stiffness(setup: Any) -> None:
    """Raise PresetError (a ValueError) if the preset's ``randomize`` ranges allow an episode
    too stiff for RK4 (module docstring): checked at the corners of the ranges the step
    depends on (drag, rolling resistance, critical speed, support damping, fluid
    temperature): the stiff rate grows with the drag and rolling-resistance scales and a
    colder fluid, the rotation's step shrinks as the machine gets lighter (a higher critical
    speed) and, with heavy damping, as c / M grows."""
    cfg = setup.config
    if cfg.integrator != "rk4" or cfg.integration_step is not None:
        return
    rz = cfg.randomize
    sc = setup.scene
    pars = [par for par in PARAMETERS if par.step_corner]
    axes = []
    for par in pars:
        span = getattr(rz, par.randomize)
        axes.append([par.nominal(sc)] if span is None
                    else [par.drawn(sc, float(v)) for v in np.atleast_1d(span)])
    corners = np.array(list(itertools.product(*axes)), dtype=float)
    values: dict[str, Any] = {par.name: corners[:, j] for j, par in enumerate(pars)}
    values["imbalance"] = np.full(len(corners), sc.imbalance)
    p, b = variants.packed_variants(sc, len(corners), **machine_changes(values))
    _rk4_steps(setup, p, b, values,
               f"environment preset {cfg.name!r} (its randomize ranges allow it)", PresetError)


@dataclass
class Pending:
    """What :func:`commit` writes into the rows ``rows`` of the buffers and the table: arrays
    over ``rows`` computed by :func:`prepare` (``values``: the episode parameters by name)."""

    rows: np.ndarray
    p: np.ndarray
    b: np.ndarray
    s: np.ndarray
    st: np.ndarray
    d: np.ndarray
    values: dict
    step: np.ndarray
    reference_length: np.ndarray
    key: np.ndarray
    static_deflection: np.ndarray
    redistributions: np.ndarray


def prepare(setup: Any, table: EpisodeTable, rows, values: Mapping[str, Any]) -> Pending:
    """The start of the episodes of ``rows`` (rotor at rest), computed without changing
    anything: ``values`` holds every episode parameter as an array over ``rows`` (the ball
    angles (R, n)) and, optionally, the noise keys (:data:`NOISE_KEY`, default 0) and the
    redistributions' draws.  Raises ValueError for an episode too stiff for RK4 (module
    docstring)."""
    sc = setup.scene
    nb = sc.ball_count
    nq = 3 + nb
    rows = np.asarray(rows, dtype=np.int64)
    n = len(rows)
    vals: dict[str, np.ndarray] = {}
    for par in PARAMETERS:
        v = np.asarray(values[par.name], float)
        vals[par.name] = v.reshape(n, nb) if par.per_ball else np.broadcast_to(v, (n,)).copy()
    key = (np.zeros(n, dtype=np.int64) if values.get(NOISE_KEY) is None
           else np.asarray(values[NOISE_KEY], np.int64))
    machine = machine_changes(vals)
    p, b = variants.packed_variants(sc, n, **machine)
    step = setup.config.integration_step
    if step is None:
        if setup.config.integrator == "rk4":
            step = _rk4_steps(setup, p, b, vals, "reset", ValueError)
        else:
            step = _steps(setup, p, setup.config.integrator, np.zeros(n),
                          variants.rates_vary(machine))
    step = np.array(np.broadcast_to(np.asarray(step, float), (n,)))
    refs = variants.references(sc, p, setup.operating_speed, **machine)
    sag = refs.static_deflection
    phase = vals["imbalance_phase"]
    s = np.zeros((n, 2 * nq))
    s[:, 0] = sag[:, 0]
    s[:, 1] = sag[:, 1]
    s[:, 2] = phase
    s[:, 3:nq] = vals["ball_angles"]
    st = np.zeros((n, N_ST))
    acc = np.zeros(runup.N_ACC)
    runup.reset(acc)
    st[:, S_ACC:S_ACC + runup.N_ACC] = acc
    st[:, S_XS] = sag[:, 0]
    st[:, S_YS] = sag[:, 1]
    st[:, S_USCALE] = refs.imbalance_scale
    st[:, S_UBEST] = refs.best_residual
    length = setup.reward_length_scale
    a_peak, a_op = ((refs.peak_amplitude, refs.operating_amplitude) if length is None
                    else (np.full(n, length), np.full(n, length)))
    st[:, S_AREF] = a_peak
    st[:, S_AOP] = a_op
    st[:, S_DTMAX] = step
    st[:, S_NSEG] = 1.0
    # the reference mark: the rotor starts with its imbalance at angle `phase` from the
    # fixed x axis and its mark on it, so the imbalance lies `phase` from the mark
    st[:, S_MARK] = phase
    st[:, S_NKEY] = key
    w = setup.config.reward
    clear = sc.housing_clearance
    st[:, S_PEN_RATE] = w.vibration * clear / a_peak + w.time + w.effort * setup.effort_bound
    st[:, S_PEN_TERM] = w.residual * clear / a_op
    events = redistribution.prepare(setup, st, values, n)
    d = np.zeros((n, setup.n_rows, dl.N_DRIVE))
    setup.actions.reset_rows(d, phase, setup)
    extra = mdl.spec_of(p, d) & ~setup.spec
    if extra:
        raise RuntimeError(f"episodes of scene {sc.name!r} need kernel effects {extra} beyond "
                           f"the environment's {setup.spec}")
    return Pending(rows, p, b, s, st, d, vals, step, refs.reference_length, key, sag, events)


def commit(bufs: Any, table: EpisodeTable, pending: Pending) -> None:
    """Write what :func:`prepare` computed into the buffers ``bufs`` and the ``table`` (cannot
    fail: every array has its shape already)."""
    rows = pending.rows
    bufs.p[rows] = pending.p
    bufs.b[rows] = pending.b
    bufs.s[rows] = pending.s
    bufs.st[rows] = pending.st
    bufs.d[rows] = pending.d
    bufs.act[rows] = 0.0
    table.started[rows] = True
    for name, v in pending.values.items():
        table.values[name][rows] = v
    table.noise_key[rows] = pending.key
    table.static_deflection[rows] = pending.static_deflection
    table.integration_step[rows] = pending.step
    table.reference_length[rows] = pending.reference_length
    if table.redistributions.shape[1]:
        table.redistributions[rows] = pending.redistributions
