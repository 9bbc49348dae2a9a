"""Environment presets: ``configs/envs/<name>.yaml`` plus keyword overrides, validated.

A preset fixes everything about an environment except the machine (the scene) and the
action type.  Presets shipped in ``configs/envs/``:

===========  ================================================================================
preset       use
===========  ================================================================================
train        default; randomised imbalance (inside the balancing capacity), phase, ball
             positions, race drag and rolling resistance
test         evaluation; wider ranges, imbalance up to 1.3 x the balancing capacity
nominal      no randomisation: the scene exactly as loaded (reproduces ``simulate``)
varied       machines that differ in what decides the best run-up, unobserved: critical speed
             +-30 % (load mass), imbalance, ball drag, rolling resistance, support damping;
             the synchronous vibration is observed (``configs/envs/varied.yaml`` says why)
varied_test  held-out evaluation of ``varied``: wider ranges, imbalance beyond the capacity
===========  ================================================================================

Fields (declared once on :class:`EnvConfig` and its sections; ``null`` where a
scene-derived default exists):

{table}

A ``randomize`` entry is ``[lo, hi]`` (uniform, drawn from the environment's ``np_random``),
one number (fixed), or ``null`` (the scene's value).  A preset may name a ``base`` preset whose
fields it overrides.  Keyword arguments override any field; the nested sections ``reward``,
``dwell``, ``randomize``, ``sync_vibration`` and ``redistribution`` are merged key by key
(``randomize={"imbalance_ratio": None}`` switches one entry off,
``sync_vibration={"enabled": True}`` adds the synchronous vibration to the observation).
Errors name the field and the allowed range.

**Critical speed.**  ``randomize.critical_speed_scale`` s scales the scene's critical speeds
``sqrt(k / M)`` through the supported mass, as a load does (laundry in a drum, sample tubes in
a centrifuge rotor): ``M' = M / s^2``, the difference carried by the rotor (its mass becomes
``M' - sum m_i``, its polar inertia scales with that mass, a load spread like the rotor), the
support unchanged.  The imbalance is drawn on its own (``imbalance_ratio``), so the load's
eccentricity is ``U0 / rotor mass``.  s in [0.7, 1.3] means M' in [0.59, 2.04] M.  The preset
is refused when a corner of the range leaves no rotor mass (s too large) or, under gravity,
sags the rotor onto the housing clearance (s too small).

**Time in the observation.**  ``observe_time: false`` leaves the time fraction out of the
observation (every later entry moves up by one).  The episode's time limit still applies, so
the observation is then not Markov near the end of an episode: a policy cannot tie its action
to the clock (the clocked RunUpTorque agents learnt "late means behind" from it), but it
cannot foresee the truncation penalty either (a clock-less RunUpTorque agent learnt to stay
at rest: docs/what-was-tried.md).

**Frame stack.**  ``frame_stack: k`` (> 1) returns the last k observations, oldest first,
concatenated into one flat ``Box`` of ``k x obs_dim`` (a policy with memory that SB3's
``MlpPolicy`` takes as it is); at reset the first observation fills all k frames
(gymnasium's ``FrameStackObservation`` with ``padding_type="reset"``, flattened).  It is done
natively, so the single and the vector environment (autoreset included) stack alike.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, fields, make_dataclass
from typing import Any, Mapping

from .. import resources
from ..physics.methods import PRECISIONS
from ..configuration import (ConfigError, build, check, declare, fields_table, locate,
                             read_yaml, specs)
from .episode_parameters import randomize_fields

__all__ = ["EnvConfig", "RewardWeights", "DwellRanges", "Randomization", "SyncVibration",
           "Redistribution", "load_preset", "load_task_preset",
           "list_presets", "presets_dir", "PRESET_FIELDS", "PresetError", "INTEGRATORS",
           "PRECISIONS"]

Range = tuple[float, float]
INTEGRATORS = ("rk4", "etdrk4")
#: largest ``redistribution.max_count`` (the compiled step keeps the drawn redistributions in
#: each row's bookkeeping: :mod:`abb_gym.envs.layout`)
MAX_REDISTRIBUTIONS = 8
PI = math.pi


class PresetError(ConfigError):
    """An environment preset or keyword override is invalid (names the field and range)."""


def presets_dir():
    """Folder of the shipped environment presets (``configs/envs``)."""
    return resources.shipped_folder("envs")


def list_presets() -> list[str]:
    """Names of the environment presets on the search path."""
    return resources.names("envs")


@dataclass(frozen=True)
class RewardWeights:
    vibration: float = declare(1.0, ge=0.0, le=1e6, doc="weight of the vibration term")
    time: float = declare(1.0, ge=0.0, le=1e6, doc="weight of the time-to-speed term")
    effort: float = declare(0.1, ge=0.0, le=1e6, doc="weight of the control-effort term")
    residual: float = declare(2.0, ge=0.0, le=1e6,
                              doc="weight of the terminal residual-vibration term")
    failure: float = declare(10.0, ge=0.0, le=1e6, doc="fixed part of the failure penalty")
    length_scale: float | None = declare(None, unit="m", gt=0.0, le=10.0, nullable=True,
                                         doc="vibration and residual in this unit of length; "
                                             "null = the machine's reference amplitudes")


@dataclass(frozen=True)
class DwellRanges:
    # floor: a ramp of 5e-324 x the drive's acceleration has an infinite run-up time, and the
    # dwell durations (multiples of it) become inf or NaN
    runup_acceleration: float = declare(0.5, ge=1e-3, le=1.0,
                                        doc="DwellProfile ramp acceleration / "
                                            "drive_max_acceleration")
    speed_range: Range = declare((0.5, 1.5), kind="range", ge=0.0, le=100.0,
                                 doc="dwell start speed / lower critical speed")
    time_range: Range = declare((0.0, 0.25), kind="range", ge=0.0, le=100.0,
                                doc="dwell duration / nominal run-up time")
    accel_range: Range = declare((-1.0, 1.0), kind="range", ge=-10.0, le=10.0,
                                 doc="dwell acceleration / ramp acceleration")


def _randomization_class() -> type:
    """:class:`Randomization`, one field per episode parameter (declared once in
    :mod:`abb_gym.envs.episode_parameters`, in draw order)."""
    cls = make_dataclass(
        "Randomization",
        [(name, Any, declare(None, **spec)) for name, spec in randomize_fields()], frozen=True)
    cls.__module__ = __name__  # pickles as abb_gym.envs.config.Randomization
    return cls


#: The ``randomize`` section: each episode parameter's range (``[lo, hi]``, one number, or
#: null for the scene's value); its fields come from the declarations of
#: :mod:`abb_gym.envs.episode_parameters`.
Randomization = _randomization_class()


@dataclass(frozen=True)
class SyncVibration:
    enabled: bool = declare(False, kind="flag",
                            doc="observe the synchronous (1x) vibration: amplitude and phase "
                                "from the rotor's reference mark (abb_gym.envs.base)")
    lag: float = declare(0.1, unit="s", ge=0.0, le=100.0,
                         doc="time constant of the tracking filter's low-pass (0: the "
                             "demodulated sample at the interval end)")
    noise: float = declare(0.0, ge=0.0, le=100.0,
                           doc="read-out noise: standard deviation of each component of the "
                               "measured vector / A_v (the vibration scale)")


@dataclass(frozen=True)
class Redistribution:
    enabled: bool = declare(False, kind="flag",
                            doc="the laundry redistributes when the drum tumbles "
                                "(abb_gym.envs.redistribution; SpinRedistribute-v0)")
    tumble_speed: float | None = declare(None, unit="rad/s", gt=0.0, le=1e4, nullable=True,
                                         doc="drum speed below which the laundry tumbles; "
                                             "null = 0.8 sqrt(g / R), R the race radius")
    tumble_time: float = declare(4.0, unit="s", gt=0.0, le=1e3,
                                 doc="an unbroken stay below the tumble speed this long "
                                     "redistributes the laundry")
    max_count: int = declare(4, kind="integer", ge=0, le=MAX_REDISTRIBUTIONS,
                             doc="redistributions drawn per episode; tumbling after the last "
                                 "one leaves the laundry where it lies")


_SECTIONS = {"reward": RewardWeights, "dwell": DwellRanges, "randomize": Randomization,
             "sync_vibration": SyncVibration, "redistribution": Redistribution}


@dataclass(frozen=True)
class EnvConfig:
    """A validated environment preset (see the module docstring for every field)."""

    name: str = declare("custom", kind="text", doc="preset name")
    description: str = declare("", kind="text", doc="what the preset is for")
    # the bounds of the scene's drive_operating_speed, which it replaces (at 5e-324 rad/s the
    # vibration scale, a whirl amplitude at that speed, is 0 and the observation NaN)
    operating_speed: float | None = declare(None, unit="rad/s", ge=1e-3, le=1e5, nullable=True,
                                            doc="target speed; null = the scene's")
    control_interval: float = declare(0.01, unit="s", ge=1e-5, le=10.0,
                                      doc="time between agent decisions")
    episode_length: float | None = declare(None, unit="s", gt=0.0, le=1e5, nullable=True,
                                           doc="time limit (truncation); null = automatic")
    # > 0: the residual is the mean vibration over this window (at 0, a mean over nothing:
    # NaN); any positive time is at least one control interval
    settle_time: float = declare(1.0, unit="s", gt=0.0, le=1e4,
                                 doc="an unbroken stay in the band this long completes the "
                                     "run-up (the settling window)")
    at_speed_tolerance: float = declare(0.002, gt=0.0, le=0.5,
                                        doc="the operating band: at speed when |w - w_op| "
                                            "<= tol w_op (abb_gym.physics.runup)")
    overspeed: float = declare(1.2, gt=1.0, le=10.0,
                               doc="RunUpTorque trips when |w| > overspeed w_op")
    vibration_filter_time: float = declare(0.05, unit="s", gt=0.0, le=1e3,
                                           doc="time constant of the filtered vibration "
                                               "amplitude")
    balance_tolerance: float = declare(0.1, gt=0.0, le=10.0,
                                       doc="info['balanced']: residual within tol x U0 of "
                                           "the best")
    integrator: str = declare("rk4", kind="choice", choices=INTEGRATORS,
                              doc="compiled fixed-step method (etdrk4: exact stiff drag)")
    precision: str = declare("float64", kind="choice", choices=PRECISIONS,
                             doc="arithmetic of the vector environment's step: float32 (rk4 "
                                 "only) is faster from 64 sub-environments, less accurate")
    integration_step: float | None = declare(None, unit="s", ge=1e-7, le=1.0, nullable=True,
                                             doc="step bound; null = default_step of each "
                                                 "episode")
    reward: RewardWeights = declare(RewardWeights(), kind="any", doc="reward weights")
    dwell: DwellRanges = declare(DwellRanges(), kind="any", doc="DwellProfile action ranges")
    randomize: Randomization = declare(Randomization(), kind="any",
                                       doc="per-episode randomisation")
    sync_vibration: SyncVibration = declare(SyncVibration(), kind="any",
                                            doc="the synchronous vibration observation")
    redistribution: Redistribution = declare(Redistribution(), kind="any",
                                             doc="redistribution of the laundry when the drum "
                                                 "tumbles")
    observe_time: bool = declare(True, kind="flag",
                                 doc="observe the time fraction t / episode_length; false: "
                                     "an observation without it (a policy that cannot act on "
                                     "the clock)")
    frame_stack: int = declare(1, kind="integer", ge=1, le=64,
                               doc="observe the last k observations (module docstring); 1: "
                                   "the current one only")

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dictionary (YAML/JSON-safe; ranges as lists)."""
        out: dict[str, Any] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in _SECTIONS:
                v = {g.name: (list(x) if isinstance(x := getattr(v, g.name), tuple) else x)
                     for g in fields(v)}
            out[f.name] = v
        return out


PRESET_FIELDS = tuple(f.name for f in fields(EnvConfig))


def _doc_rows() -> dict[str, Any]:
    rows: dict[str, Any] = {}
    for name, spec in specs(EnvConfig).items():
        if name in _SECTIONS:
            rows.update({f"{name}.{key}": sub for key, sub in specs(_SECTIONS[name]).items()})
        elif name not in ("name", "description"):
            rows[name] = spec
    return rows


__doc__ = __doc__.replace("{table}", fields_table(_doc_rows()))


def _section(name: str, raw: Any, where: str):
    cls = _SECTIONS[name]
    if raw is None:
        raw = {}
    if isinstance(raw, cls):
        return raw
    if not isinstance(raw, Mapping):
        raise PresetError(f"{where}: field {name!r} must be a mapping with keys "
                          f"{[f.name for f in fields(cls)]} (got {raw!r})")
    allowed = [f.name for f in fields(cls)]
    unknown = sorted(set(raw) - set(allowed), key=str)  # keys may be numbers or None
    if unknown:
        raise PresetError(f"{where}: unknown key(s) {unknown} in {name!r}; allowed: {allowed}")
    table = specs(cls)
    return cls(**{key: check(where, f"{name}.{key}", v, table[key], PresetError)
                  for key, v in raw.items()})


def _merge(base: dict[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        if k in _SECTIONS and isinstance(v, Mapping) and isinstance(out.get(k), Mapping):
            out[k] = {**out[k], **v}
        else:
            out[k] = v
    return out


def _read_preset(name_or_path: str | os.PathLike, seen: tuple[str, ...] = ()) -> dict[str, Any]:
    path = locate("envs", name_or_path, "environment preset", PresetError)
    raw = dict(read_yaml(path, "preset", PresetError))
    raw.setdefault("name", path.stem)
    base = raw.pop("base", None)
    if base is not None:
        if str(base) in seen:
            raise PresetError(f"preset {raw['name']!r}: circular 'base' chain {seen + (base,)}")
        parent = _read_preset(base, seen + (str(base),))
        parent.pop("name", None)
        parent.pop("description", None)
        raw = _merge(parent, raw)
    return raw


def load_preset(preset: str | os.PathLike | Mapping[str, Any] | EnvConfig = "train",
                **overrides: Any) -> EnvConfig:
    """Resolve a preset (name, path, mapping or EnvConfig) and keyword overrides."""
    if isinstance(preset, EnvConfig):
        raw = preset.to_dict()
    elif isinstance(preset, Mapping):
        raw = dict(preset)
        base = raw.pop("base", None)
        if base is not None:
            parent = _read_preset(base)
            raw = _merge(parent, raw)
    elif isinstance(preset, (str, os.PathLike)):
        raw = _read_preset(preset)
    else:
        raise PresetError(f"preset must be a name, a path, a mapping or an EnvConfig (got "
                          f"{preset!r}); available: {', '.join(list_presets())}")
    raw = _merge(raw, overrides)
    where = f"environment preset {raw.get('name', 'custom')!r}"
    unknown = sorted(set(raw) - set(PRESET_FIELDS), key=str)  # keys may be numbers or None
    if unknown:
        raise PresetError(f"{where}: unknown field(s) {unknown}; allowed: {list(PRESET_FIELDS)}"
                          f" (plus the environment keywords scene, preset, observe_balls, "
                          f"render_mode, max_episode_steps, record_history, info_level; and "
                          f"num_envs, kernel of the vector environment)")
    values = {k: (_section(k, v, where) if k in _SECTIONS else v) for k, v in raw.items()}
    if values.get("name") is None:
        values["name"] = "custom"
    if values.get("description") is None:
        values["description"] = ""
    cfg = build(EnvConfig, values, where, PresetError)
    if cfg.precision == "float32" and cfg.integrator != "rk4":
        raise PresetError(f"{where}: field 'precision' = 'float32' needs integrator = 'rk4' "
                          f"(got integrator = {cfg.integrator!r}); allowed with "
                          f"{cfg.integrator!r}: 'float64'")
    if cfg.episode_length is not None and cfg.episode_length <= cfg.control_interval:
        raise PresetError(f"{where}: field 'episode_length' must be > control_interval = "
                          f"{cfg.control_interval:g} s (got {cfg.episode_length:g} s)")
    return cfg


def load_task_preset(task: Any, preset: Any, overrides: Mapping[str, Any] | None
                     ) -> EnvConfig:
    """``preset`` with the keyword ``overrides``, then the fields that ``task`` (a
    :class:`~abb_gym.envs.tasks.Task`) fixes; an override that contradicts the task is
    refused by name."""
    overrides = dict(overrides or {})
    cfg = load_preset(preset, **overrides)
    if not task.settings:
        return cfg
    for key, value in task.settings.items():
        given = overrides.get(key)
        pairs = (value.items() if isinstance(value, Mapping) else [(None, value)])
        for sub, want in pairs:
            path = key if sub is None else f"{key}.{sub}"
            asked = given if sub is None else (given.get(sub) if isinstance(given, Mapping)
                                               else None)
            if asked is not None and asked != want:
                raise PresetError(f"environment preset {cfg.name!r}: field {path!r} = "
                                  f"{asked!r} contradicts {task.env_id}, which fixes it to "
                                  f"{want!r}")
    return load_preset(cfg, **task.settings)
