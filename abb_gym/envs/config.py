"""Environment presets: ``configs/envs/<name>.yaml`` plus keyword overrides, validated.

A preset fixes everything about an environment except the machine (the scene) and the
action type.  Presets shipped in ``configs/envs/``:

=========  ================================================================================
preset     use
=========  ================================================================================
train      default; randomised imbalance (inside the balancing capacity), phase, ball
           positions, race drag and rolling resistance
test       evaluation; wider ranges, imbalance up to 1.3 x the balancing capacity
nominal    no randomisation: the scene exactly as loaded (reproduces ``simulate``)
=========  ================================================================================

Fields (unit, allowed range; ``null`` where a scene-derived default exists):

=========================  ========  =====================================================
field                      unit      meaning
=========================  ========  =====================================================
operating_speed            rad/s     target speed; null = the scene's
                                     ``drive_operating_speed``; > 0
control_interval           s         time between agent decisions; > 0 (default 0.01)
episode_length             s         time limit (truncation); null = automatic (see the
                                     environment docstrings); > control_interval
settle_time                s         time at operating speed that completes an episode,
                                     >= 0
at_speed_tolerance         -         "at operating speed" means |w - w_op| <= tol w_op,
                                     in (0, 0.5]
overspeed                  -         RunUpTorque trips (terminates with the failure
                                     penalty) when |w| > overspeed w_op; > 1
vibration_filter_time      s         time constant of the filtered vibration amplitude in
                                     the observation; > 0
balance_tolerance          -         residual imbalance (relative to the imbalance) within
                                     which ``info["balanced"]`` is true; > 0
integrator                 -         compiled fixed-step method: "rk4" or "etdrk4"
                                     (exact stiff ball drag, larger steps at the same
                                     accuracy); both agree with ``simulate`` using it
integration_step           s         step bound; null = ``default_step`` of each episode's
                                     scene for the integrator; > 0
reward.vibration           -         weight of the vibration term, >= 0
reward.time                -         weight of the time-to-speed term, >= 0
reward.effort              -         weight of the control-effort term, >= 0
reward.residual            -         weight of the terminal residual-vibration term, >= 0
reward.failure             -         fixed part of the failure penalty, >= 0
dwell.runup_acceleration   -         DwellProfile ramp acceleration / drive_max_acceleration,
                                     in (0, 1]
dwell.speed_range          -         dwell start speed / lower critical speed, [lo, hi],
                                     0 <= lo <= hi
dwell.time_range           -         dwell duration / nominal run-up time, [lo, hi],
                                     0 <= lo <= hi
dwell.accel_range          -         dwell acceleration / ramp acceleration, [lo, hi],
                                     -10 <= lo <= hi <= 10
randomize.imbalance_ratio  -         imbalance / balancing capacity (sum m_i R); > 0
randomize.imbalance_phase  rad       angle of the imbalance at t = 0 (fixed frame)
randomize.ball_angles      rad       each ball's initial angle from the imbalance
randomize.ball_drag_scale  -         factor on the scene's ball_drag (one per episode), > 0
randomize.rolling_resistance_scale - factor on the scene's ball_rolling_resistance, >= 0
=========================  ========  =====================================================

A ``randomize`` entry is ``[lo, hi]`` (uniform, drawn from the environment's ``np_random``),
one number (fixed), or ``null`` (the scene's value).  A preset may name a ``base`` preset whose
fields it overrides.  Keyword arguments override any field; the nested sections ``reward``,
``dwell`` and ``randomize`` are merged key by key (``randomize={"imbalance_ratio": None}``
switches one entry off).  Errors name the field and the allowed range.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Mapping

import yaml

__all__ = ["EnvConfig", "RewardWeights", "DwellRanges", "Randomization", "load_preset",
           "list_presets", "presets_dir", "PRESET_FIELDS"]

Range = tuple[float, float]


class PresetError(ValueError):
    """An environment preset or keyword override is invalid (names the field and range)."""


def presets_dir() -> Path:
    """Folder of the environment presets: ``$ABB_GYM_CONFIGS/envs`` or ``configs/envs``."""
    root = os.environ.get("ABB_GYM_CONFIGS")
    base = Path(root) if root else Path(__file__).resolve().parents[2] / "configs"
    return base / "envs"


def list_presets() -> list[str]:
    """Names of the shipped environment presets."""
    return sorted(p.stem for p in presets_dir().glob("*.yaml"))


@dataclass(frozen=True)
class RewardWeights:
    vibration: float = 1.0
    time: float = 1.0
    effort: float = 0.1
    residual: float = 2.0
    failure: float = 10.0


@dataclass(frozen=True)
class DwellRanges:
    runup_acceleration: float = 0.5
    speed_range: Range = (0.5, 1.5)
    time_range: Range = (0.0, 0.25)
    accel_range: Range = (-1.0, 1.0)


@dataclass(frozen=True)
class Randomization:
    imbalance_ratio: Range | None = None
    imbalance_phase: Range | None = None
    ball_angles: Range | None = None
    ball_drag_scale: Range | None = None
    rolling_resistance_scale: Range | None = None


@dataclass(frozen=True)
class EnvConfig:
    """A validated environment preset (see the module docstring for every field)."""

    name: str = "custom"
    description: str = ""
    operating_speed: float | None = None
    control_interval: float = 0.01
    episode_length: float | None = None
    settle_time: float = 1.0
    at_speed_tolerance: float = 0.01
    overspeed: float = 1.2
    vibration_filter_time: float = 0.05
    balance_tolerance: float = 0.1
    integrator: str = "rk4"
    integration_step: float | None = None
    reward: RewardWeights = RewardWeights()
    dwell: DwellRanges = DwellRanges()
    randomize: Randomization = Randomization()

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


INTEGRATORS = ("rk4", "etdrk4")
_SECTIONS = {"reward": RewardWeights, "dwell": DwellRanges, "randomize": Randomization}
PRESET_FIELDS = tuple(f.name for f in fields(EnvConfig))

# scalar fields: (unit, lower, lower inclusive, upper, upper inclusive, nullable)
_SCALARS: dict[str, tuple[str, float | None, bool, float | None, bool, bool]] = {
    "operating_speed": ("rad/s", 0.0, False, None, True, True),
    "control_interval": ("s", 0.0, False, None, True, False),
    "episode_length": ("s", 0.0, False, None, True, True),
    "settle_time": ("s", 0.0, True, None, True, False),
    "at_speed_tolerance": ("-", 0.0, False, 0.5, True, False),
    "overspeed": ("-", 1.0, False, None, True, False),
    "vibration_filter_time": ("s", 0.0, False, None, True, False),
    "balance_tolerance": ("-", 0.0, False, None, True, False),
    "integration_step": ("s", 0.0, False, None, True, True),
}
_RANDOM_BOUNDS: dict[str, tuple[str, float | None, bool]] = {
    # name: (unit, lower bound, inclusive)
    "imbalance_ratio": ("-", 0.0, False),
    "imbalance_phase": ("rad", None, True),
    "ball_angles": ("rad", None, True),
    "ball_drag_scale": ("-", 0.0, False),
    "rolling_resistance_scale": ("-", 0.0, True),
}


def _bound_text(lo, lo_incl, hi=None, hi_incl=True, unit="-") -> str:
    parts = []
    if lo is not None:
        parts.append(f"{'>=' if lo_incl else '>'} {lo:g}")
    if hi is not None:
        parts.append(f"{'<=' if hi_incl else '<'} {hi:g}")
    return (" and ".join(parts) if parts else "finite") + f" [{unit}]"


def _number(where: str, value: Any, lo=None, lo_incl=True, hi=None, hi_incl=True,
            unit="-") -> float:
    rng = _bound_text(lo, lo_incl, hi, hi_incl, unit)
    if isinstance(value, bool):
        raise PresetError(f"{where} must be a number {rng} (got {value!r})")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise PresetError(f"{where} must be a number {rng} (got {value!r})") from None
    if not math.isfinite(v) or (lo is not None and (v < lo or (v == lo and not lo_incl))) \
            or (hi is not None and (v > hi or (v == hi and not hi_incl))):
        raise PresetError(f"{where} must be {rng} (got {v:g})")
    return v


def _range(where: str, value: Any, lo=None, lo_incl=True, hi=None, hi_incl=True,
           unit="-") -> Range:
    if isinstance(value, (list, tuple)):
        if len(value) != 2:
            raise PresetError(f"{where} must be [lo, hi] or one number, each "
                              f"{_bound_text(lo, lo_incl, hi, hi_incl, unit)} (got {value!r})")
        a = _number(where + "[0]", value[0], lo, lo_incl, hi, hi_incl, unit)
        b = _number(where + "[1]", value[1], lo, lo_incl, hi, hi_incl, unit)
        if a > b:
            raise PresetError(f"{where} must have lo <= hi (got [{a:g}, {b:g}])")
        return a, b
    v = _number(where, value, lo, lo_incl, hi, hi_incl, unit)
    return v, v


def _section(name: str, raw: Any, where: str):
    cls = _SECTIONS[name]
    if raw is None:
        raw = {}
    if not isinstance(raw, Mapping):
        raise PresetError(f"{where}: field {name!r} must be a mapping with keys "
                          f"{[f.name for f in fields(cls)]} (got {raw!r})")
    allowed = [f.name for f in fields(cls)]
    unknown = sorted(set(raw) - set(allowed))
    if unknown:
        raise PresetError(f"{where}: unknown key(s) {unknown} in {name!r}; allowed: {allowed}")
    values: dict[str, Any] = {}
    for key, v in raw.items():
        label = f"{where}: field '{name}.{key}'"
        if name == "reward":
            values[key] = _number(label, v, 0.0, True)
        elif name == "dwell":
            if key == "runup_acceleration":
                values[key] = _number(label, v, 0.0, False, 1.0, True)
            elif key == "accel_range":
                values[key] = _range(label, v, -10.0, True, 10.0, True)
            else:
                values[key] = _range(label, v, 0.0, True)
        else:
            if v is None:
                values[key] = None
            else:
                unit, lo, incl = _RANDOM_BOUNDS[key]
                values[key] = _range(label, v, lo, incl, unit=unit)
    return values


def _merge(base: dict[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        if k in _SECTIONS and isinstance(v, Mapping) and isinstance(out.get(k), Mapping):
            out[k] = {**out[k], **v}
        else:
            out[k] = v
    return out


def _read_preset(name_or_path: str | os.PathLike, seen: tuple[str, ...] = ()) -> dict[str, Any]:
    text = str(name_or_path)
    path = Path(text)
    if not (text.endswith((".yaml", ".yml")) or path.exists()):
        path = presets_dir() / f"{text}.yaml"
        if not path.exists():
            raise PresetError(f"unknown environment preset {text!r}; available: "
                              f"{', '.join(list_presets())} (or give a path to a YAML file)")
    if not path.exists():
        raise PresetError(f"preset file {str(path)!r} does not exist")
    try:
        raw = yaml.safe_load(path.read_text()) or {}
    except yaml.YAMLError as exc:
        raise PresetError(f"preset file {str(path)!r} is not valid YAML: {exc}") from None
    if not isinstance(raw, Mapping):
        raise PresetError(f"preset file {str(path)!r} must hold a mapping of fields")
    raw = dict(raw)
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
    else:
        raw = _read_preset(preset)
    raw = _merge(raw, overrides)
    where = f"environment preset {raw.get('name', 'custom')!r}"
    unknown = sorted(set(raw) - set(PRESET_FIELDS))
    if unknown:
        raise PresetError(f"{where}: unknown field(s) {unknown}; allowed: {list(PRESET_FIELDS)}"
                          f" (plus the environment keywords scene, preset, observe_balls, "
                          f"render_mode, max_episode_steps)")
    kwargs: dict[str, Any] = {}
    for key, v in raw.items():
        if key in ("name", "description"):
            kwargs[key] = str(v) if v is not None else ""
        elif key == "integrator":
            if v not in INTEGRATORS:
                raise PresetError(f"{where}: field 'integrator' must be one of {INTEGRATORS} "
                                  f"(got {v!r})")
            kwargs[key] = v
        elif key in _SECTIONS:
            kwargs[key] = _SECTIONS[key](**_section(key, v, where))
        else:
            unit, lo, lo_incl, hi, hi_incl, nullable = _SCALARS[key]
            if v is None:
                if not nullable:
                    raise PresetError(f"{where}: field {key!r} must be a number "
                                      f"{_bound_text(lo, lo_incl, hi, hi_incl, unit)} "
                                      f"(got None)")
                kwargs[key] = None
            else:
                kwargs[key] = _number(f"{where}: field {key!r}", v, lo, lo_incl, hi, hi_incl,
                                      unit)
    cfg = EnvConfig(**kwargs)
    if cfg.episode_length is not None and cfg.episode_length <= cfg.control_interval:
        raise PresetError(f"{where}: field 'episode_length' must be > control_interval = "
                          f"{cfg.control_interval:g} s (got {cfg.episode_length:g} s)")
    return cfg
