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
           "narrowed", "CurriculumCallback"]

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


def _callback_class():
    BaseCallback = _callback_base()

    class _Curriculum(BaseCallback):
        def __init__(self, settings, total_timesteps, verbose):
            super().__init__(verbose)
            self.settings = dict(settings)
            self.total = max(int(total_timesteps), 1)
            self.full = None
            self.fraction = None

        def _setup(self):
            return self.training_env.unwrapped.unwrapped.setup

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

        def _on_step(self) -> bool:
            return True

        def _on_training_end(self) -> None:
            setup = self._setup()
            setup.config = dataclasses.replace(setup.config, randomize=self.full)

    return _Curriculum
