"""The runs of the feedback-gap study (:mod:`abb_gym.rl.comparison`): each agent is compared on
its own held-out machines, with its own reward, against baselines tuned on its training
preset; the training section reads every shipped agent's cost and curves.  The whole study,
oracle included, runs end to end in ``tests/test_agents_scripts.py``."""
from __future__ import annotations

import pytest
import yaml

pytest.importorskip("stable_baselines3")

from abb_gym.rl import trained_dir  # noqa: E402
from abb_gym.rl.comparison import (agent_setting, preset_configs, scaled_residual,  # noqa: E402
                                   training_section, tuned_families)


def test_each_agent_is_compared_on_its_own_held_out_machines():
    plain = agent_setting("runup_speed_yoshida_odd")
    assert (plain.preset, plain.train_preset, plain.configs) == ("test", "train", None)
    assert plain.env_kwargs == {"reward": {"residual": 6.0}}
    assert (plain.env_id, plain.scene) == ("abb_gym/RunUpSpeed-v0", "yoshida_odd")
    varied = agent_setting("runup_speed_yoshida_odd_varied")
    assert (varied.preset, varied.train_preset) == ("varied_test", "varied")
    assert varied.configs.name == "varied"
    # only the families tuned on varied: no fallback to parameters tuned on another preset
    assert tuned_families(varied, ["knots", "speed_dwell", "retry"]) == ["knots", "retry"]
    assert tuned_families(plain, ["knots", "speed_dwell"]) == ["knots", "speed_dwell"]
    assert agent_setting("runup_speed_yoshida_odd_varied", "test").preset == "test"
    with pytest.raises(ValueError, match="tune-baselines --scene yoshida_odd --preset nowhere"):
        preset_configs("nowhere", "yoshida_odd")


def test_a_scaled_residual_weight_keeps_the_other_weights():
    assert scaled_residual({"reward": {"residual": 6.0, "time": 1.0}, "x": 1}, 3.0) == {
        "reward": {"residual": 18.0, "time": 1.0}, "x": 1}
    from abb_gym.envs.config import RewardWeights
    assert scaled_residual({}, 2.0) == {"reward": {"residual": 2.0 * RewardWeights().residual}}


def test_training_section_has_every_agents_cost_and_curves(tmp_path):
    from abb_gym.plots import plot_training_curves
    agents = sorted(d.name for d in trained_dir().iterdir() if (d / "model.zip").exists())
    readme = tmp_path / "agents" / "README.md"
    readme.parent.mkdir()
    png = tmp_path / "agents" / "results" / "training_curves.png"
    text = training_section(agents, png, readme)
    rows = [line for line in text.splitlines() if line.startswith("| `")]
    assert [r.split("`")[1] for r in rows] == agents
    for row, agent in zip(rows, agents):
        run = yaml.safe_load((trained_dir() / agent / "config.yml").read_text())["_run"]
        assert f"{run['wall_time_s']:.0f} s" in row
    assert "](results/training_curves.png)" in text
    assert png.stat().st_size > 20_000
    with pytest.raises(ValueError, match="lacks the column"):
        plot_training_curves({"x": {"timesteps": [1.0], "return": [0.0]}}, tmp_path / "x.png")
    with pytest.raises(ValueError, match="no training curves"):
        plot_training_curves({}, tmp_path / "x.png")
