"""The curriculum over the training machines (abb_gym.rl.curriculum): the share of each range
grows linearly from `start` to 1 at `full_at`, the ranges narrow around the nominal factor,
the training environment's ranges follow it rollout by rollout and are the preset's again
afterwards, and bad settings name the field."""
from __future__ import annotations

import pytest

pytest.importorskip("stable_baselines3")

from abb_gym.envs.config import Randomization  # noqa: E402
from abb_gym.rl.config import TrainConfig, TrainConfigError  # noqa: E402
from abb_gym.rl.env_factory import make_sb3_env  # noqa: E402
from abb_gym.rl.curriculum import CurriculumCallback, fraction, narrowed  # noqa: E402

SPEED = "abb_gym/RunUpSpeed-v0"


def test_the_share_grows_linearly_to_one_at_full_at():
    assert fraction(0.0, 0.2, 0.5) == 0.2
    assert fraction(0.25, 0.2, 0.5) == pytest.approx(0.6)
    assert fraction(0.5, 0.2, 0.5) == 1.0
    assert fraction(0.9, 0.2, 0.5) == 1.0


def test_ranges_narrow_around_the_nominal_factor():
    rz = Randomization(critical_speed_scale=(0.7, 1.3), ball_drag_scale=(1.2, 2.0),
                       support_damping_scale=None, imbalance_ratio=(0.2, 0.9))
    out = narrowed(rz, 0.5, ["critical_speed_scale", "ball_drag_scale",
                             "support_damping_scale"])
    assert out.critical_speed_scale == pytest.approx((0.85, 1.15))
    assert out.ball_drag_scale == pytest.approx((1.2, 1.6))  # nominal 1 clipped to 1.2
    assert out.support_damping_scale is None
    assert out.imbalance_ratio == (0.2, 0.9)  # not listed: unchanged
    assert narrowed(rz, 1.0, ["critical_speed_scale"]).critical_speed_scale == (0.7, 1.3)
    assert narrowed(rz, 0.0, ["critical_speed_scale"]).critical_speed_scale == (1.0, 1.0)


@pytest.mark.parametrize("value, match", [
    ({"fields": ["imbalance_ratio"]}, r"curriculum.fields' must name some of .*imbalance_ratio"),
    ({"fields": []}, r"curriculum.fields' must be a non-empty list"),
    ({"start": 1.5}, r"curriculum: field 'start' must be in \[0, 1\]"),
    ({"full_at": 0.0}, r"curriculum: field 'full_at' must be in \(0, 1\]"),
    ({"stages": 3}, r"unknown field\(s\) \['stages'\]"),
    (0.5, r"'curriculum' must be a mapping"),
])
def test_bad_curriculum_settings_name_the_field(value, match):
    entry = {"n_envs": 2, "policy": "BoundedMlpPolicy",
             "env_kwargs": {"scene": "yoshida_odd", "preset": "varied"}}
    with pytest.raises(TrainConfigError, match=match):
        TrainConfig.from_mapping(SPEED, entry, "x.yml", {"curriculum": value})


def _training_env():
    return make_sb3_env(SPEED, 2, {"scene": "yoshida_odd", "preset": "varied",
                                   "control_interval": 0.05})


def _ranges_seen(venv, field: str, callback, n_steps: int, steps: int) -> list:
    """The ``randomize`` range ``field`` of the training environment at the start of each
    rollout of a short PPO run (2 sub-environments) with ``callback``."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback, CallbackList

    setup, seen = venv.unwrapped.setup, []

    class Spy(BaseCallback):
        def _on_rollout_start(self):
            seen.append(getattr(setup.config.randomize, field))

        def _on_step(self):
            return True

    model = PPO("MlpPolicy", venv, n_steps=n_steps, batch_size=2 * n_steps, n_epochs=1, seed=0)
    model.learn(steps, callback=CallbackList([callback, Spy()]))
    return seen


def test_the_training_ranges_follow_the_curriculum_and_come_back():
    venv = _training_env()
    setup = venv.unwrapped.setup
    full = setup.config.randomize.critical_speed_scale
    settings = {"fields": ["critical_speed_scale"], "start": 0.0, "full_at": 1.0}
    seen = _ranges_seen(venv, "critical_speed_scale", CurriculumCallback(settings, 256), 64, 256)
    assert seen[0] == (1.0, 1.0)  # at progress 0 with start 0: the nominal machine only
    widths = [hi - lo for lo, hi in seen]
    assert widths == sorted(widths) and 0 < widths[-1] < full[1] - full[0]
    # two rollouts of 128 steps: progress 0 and 0.5
    assert len(seen) == 2
    assert seen[1] == pytest.approx((1 - 0.5 * (1 - full[0]), 1 + 0.5 * (full[1] - 1)))
    assert setup.config.randomize.critical_speed_scale == full  # the preset's again


@pytest.mark.parametrize("value, match", [
    ({"share": 0.3}, r"field 'oversample.randomize' is missing"),
    ({"share": 1.0, "randomize": {"imbalance_ratio": [1.0, 1.6]}},
     r"oversample: field 'share' must be in \(0, 1\)"),
    ({"randomize": []}, r"'oversample.randomize' must be a non-empty mapping"),
    ({"randomize": {"imbalance_ratio": [1.0, 1.6]}, "every": 2}, r"unknown field\(s\) \['every'\]"),
    ([0.3], r"'oversample' must be a mapping"),
])
def test_bad_oversample_settings_name_the_field(value, match):
    entry = {"n_envs": 2, "policy": "BoundedMlpPolicy",
             "env_kwargs": {"scene": "yoshida_odd", "preset": "varied"}}
    with pytest.raises(TrainConfigError, match=match):
        TrainConfig.from_mapping(SPEED, entry, "x.yml", {"oversample": value})


def test_oversampled_rollouts_draw_from_their_ranges_and_come_back():
    """About ``share`` of the rollouts draw their episodes from the oversampled ranges, the
    rest from the preset's, by a generator of the training seed; a range the preset would
    refuse is refused by name before any step; the preset's ranges come back at the end."""
    from abb_gym.envs.config import PresetError
    from abb_gym.rl.curriculum import OversampleCallback

    venv = _training_env()
    setup = venv.unwrapped.setup
    full = setup.config.randomize.imbalance_ratio

    def learn(settings, seed):
        return _ranges_seen(venv, "imbalance_ratio", OversampleCallback(settings, seed), 16,
                            32 * 40)

    settings = {"share": 0.3, "randomize": {"imbalance_ratio": [1.0, 1.2]}}
    first = learn(settings, 7)
    assert len(first) == 40 and set(first) == {full, (1.0, 1.2)}
    assert 4 <= first.count((1.0, 1.2)) <= 20  # 0.3 x 40 = 12 expected
    assert learn(settings, 7) == first  # the same seed, the same rollouts
    assert setup.config.randomize.imbalance_ratio == full  # the preset's again
    with pytest.raises(PresetError, match="imbalance_ratio"):
        learn({"share": 0.3, "randomize": {"imbalance_ratio": [1.2, 1.0]}}, 7)
