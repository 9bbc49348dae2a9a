"""A curriculum over the machines of a training preset: from similar machines to the full range.

On the ``varied`` presets every episode is another machine (critical speed, ball drag, rolling
resistance, support damping).  With a curriculum, training starts on machines close to the
nominal one and widens the ranges as it goes: each listed ``randomize`` range ``[lo, hi]``
becomes

    [n + f (lo - n), n + f (hi - n)],   f = start + (1 - start) min(1, progress / full_at)

with ``n`` the nominal factor 1 (clipped into the range), ``progress`` the share of
``n_timesteps`` done, so ``f`` grows linearly from ``start`` to 1 at ``full_at`` and the
ranges stay the preset's from there on.  The ranges change at the start of each rollout (the
first episode of each sub-environment, drawn when training sets up, has the preset's ranges),
and are the preset's again when training ends; the held-out evaluations always use their own
preset.  Only the scale factors take part: the
imbalance and the angles are the task itself, not its difficulty.

Config: ``_abb_gym: {curriculum: {fields: [critical_speed_scale], start: 0.2, full_at: 0.5}}``
(:class:`CurriculumSettings`; :mod:`abb_gym.rl.config`).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

from ..configuration import build_section, declare
from ..envs.episode_parameters import PARAMETERS

__all__ = ["CURRICULUM_FIELDS", "CurriculumSettings", "curriculum_settings", "fraction",
           "narrowed", "CurriculumCallback", "OversampleSettings", "oversample_settings",
           "OversampleCallback"]

#: the ``randomize`` fields a curriculum may narrow: the episode parameters that are factors
#: on a scene value, nominal 1 (:mod:`abb_gym.envs.episode_parameters`)
CURRICULUM_FIELDS = tuple(par.randomize for par in PARAMETERS if par.factor)


@dataclass(frozen=True)
class CurriculumSettings:
    """Settings of the curriculum (the ``_abb_gym.curriculum`` mapping)."""

    fields: Any = declare(CURRICULUM_FIELDS, kind="any",
                          doc=f"randomize fields to narrow, some of {list(CURRICULUM_FIELDS)}")
    start: float = declare(0.2, ge=0.0, le=1.0, doc="share of each range at the start")
    full_at: float = declare(0.5, gt=0.0, le=1.0,
                             doc="share of n_timesteps after which the ranges are full")


def curriculum_settings(value: Any, where: str, error: type[ValueError]
                        ) -> dict[str, Any] | None:
    """The validated ``curriculum`` mapping (None: none); ``error`` names the field."""
    settings = build_section(CurriculumSettings, value, "curriculum", where, error,
                             "a mapping {fields: [...], start: S, full_at: F}")
    if settings is None:
        return None
    names = settings.fields
    if isinstance(names, str) or not isinstance(names, Sequence) or not names:
        raise error(f"{where}: field 'curriculum.fields' must be a non-empty list, some of "
                    f"{list(CURRICULUM_FIELDS)} (got {names!r})")
    bad = [n for n in names if n not in CURRICULUM_FIELDS]
    if bad:
        raise error(f"{where}: field 'curriculum.fields' must name some of "
                    f"{list(CURRICULUM_FIELDS)} (got {bad})")
    return {"fields": list(dict.fromkeys(names)), "start": float(settings.start),
            "full_at": float(settings.full_at)}


def fraction(progress: float, start: float, full_at: float) -> float:
    """Share ``f`` of each range at training progress ``progress`` in [0, 1]."""
    return start + (1.0 - start) * min(1.0, max(0.0, progress) / full_at)


def narrowed(randomize: Any, f: float, fields: Sequence[str]) -> Any:
    """``randomize`` (a :class:`abb_gym.envs.config.Randomization`) with each of ``fields``
    narrowed to share ``f`` of its range around the nominal 1 (see the module docstring)."""
    changes = {}
    for name in fields:
        rng = getattr(randomize, name)
        if rng is None:
            continue
        lo, hi = float(rng[0]), float(rng[1])
        n = min(max(1.0, lo), hi)
        changes[name] = (n + f * (lo - n), n + f * (hi - n))
    return dataclasses.replace(randomize, **changes)


def _callback_base():
    from stable_baselines3.common.callbacks import BaseCallback
    return BaseCallback


def CurriculumCallback(settings: Mapping[str, Any], total_timesteps: int, verbose: int = 0):
    """The SB3 callback that narrows the training environment's ranges (built lazily: SB3 is
    imported on first use).  ``settings``: :func:`curriculum_settings`' mapping."""
    return _callback_class()(settings, int(total_timesteps), verbose)


def _ranges_callback_base():
    """The SB3 callback base of both range callbacks: the training environment's setup, and
    its preset's ``randomize`` (``self.full``) restored when training ends."""
    BaseCallback = _callback_base()

    class _Ranges(BaseCallback):
        full = None

        def _setup(self):
            return self.training_env.unwrapped.unwrapped.setup

        def _on_step(self) -> bool:
            return True

        def _on_training_end(self) -> None:
            setup = self._setup()
            setup.config = dataclasses.replace(setup.config, randomize=self.full)

    return _Ranges


def _callback_class():
    class _Curriculum(_ranges_callback_base()):
        def __init__(self, settings, total_timesteps, verbose):
            super().__init__(verbose)
            self.settings = dict(settings)
            self.total = max(int(total_timesteps), 1)
            self.fraction = None

        def _on_training_start(self) -> None:
            self.full = self._setup().config.randomize
            self._apply()

        def _on_rollout_start(self) -> None:
            self._apply()

        def _apply(self) -> None:
            s = self.settings
            f = fraction(self.num_timesteps / self.total, s["start"], s["full_at"])
            if f == self.fraction:
                return
            setup = self._setup()
            setup.config = dataclasses.replace(
                setup.config, randomize=narrowed(self.full, f, s["fields"]))
            self.fraction = f
            self.logger.record("curriculum/fraction", f)

    return _Curriculum


# --------------------------------------------------------------------------- oversampling
@dataclass(frozen=True)
class OversampleSettings:
    """Settings of hard-case oversampling (the ``_abb_gym.oversample`` mapping)."""

    share: float = declare(0.25, gt=0.0, lt=1.0,
                           doc="share of the rollouts whose new episodes draw from "
                               "``randomize``")
    randomize: Any = declare(None, kind="any",
                             doc="randomize ranges of those episodes, over the preset's "
                                 "(e.g. {imbalance_ratio: [1.0, 1.6]})")


def oversample_settings(value: Any, where: str, error: type[ValueError]
                        ) -> dict[str, Any] | None:
    """The validated ``oversample`` mapping (None: none); ``error`` names the field.  The
    ranges themselves are checked as a preset's when training sets up (before any step)."""
    settings = build_section(OversampleSettings, value, "oversample", where, error,
                             "a mapping {share: S, randomize: {FIELD: [LO, HI]}}",
                             required={"randomize": "the ranges of the oversampled episodes"})
    if settings is None:
        return None
    if not isinstance(settings.randomize, Mapping) or not settings.randomize:
        raise error(f"{where}: field 'oversample.randomize' must be a non-empty mapping of "
                    f"randomize fields to ranges (got {settings.randomize!r})")
    return {"share": float(settings.share), "randomize": dict(settings.randomize)}


def OversampleCallback(settings: Mapping[str, Any], seed: int | None, verbose: int = 0):
    """The SB3 callback that draws a share of the rollouts from other ranges (built lazily:
    SB3 is imported on first use).  ``settings``: :func:`oversample_settings`' mapping.

    Why: a rare situation that decides an episode's return (on SpinRedistribute, a drive
    that has spent all its redistributions on loads beyond the balls' capacity) is met a few
    times in a million steps of the training preset, and a network fed its observations
    extrapolates there.  At the start of each rollout, with probability ``share`` (from a
    generator seeded by the training seed), the episodes that begin during it draw from the
    preset's ranges with ``randomize`` over them; the rest from the preset's own.  The
    held-out evaluations always use their own preset."""
    return _oversample_class()(settings, seed, verbose)


def _oversample_class():
    import numpy as np

    class _Oversample(_ranges_callback_base()):
        def __init__(self, settings, seed, verbose):
            super().__init__(verbose)
            self.settings = dict(settings)
            self.rng = np.random.default_rng(None if seed is None else [int(seed), 46])
            self.hard = None

        def _on_training_start(self) -> None:
            from ..envs.config import load_preset
            setup = self._setup()
            self.full = setup.config.randomize
            # a preset's override: merged over its randomize section and checked as one
            self.hard = load_preset(setup.config,
                                    randomize=self.settings["randomize"]).randomize

        def _on_rollout_start(self) -> None:
            hard = bool(self.rng.random() < self.settings["share"])
            setup = self._setup()
            setup.config = dataclasses.replace(setup.config,
                                               randomize=self.hard if hard else self.full)
            self.logger.record("oversample/hard", float(hard))

    return _Oversample
