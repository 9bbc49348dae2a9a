"""Full training of the shipped agents' configs (opt-in: ``pytest --runslow``, minutes each).

Each config in ``configs/ppo/`` is trained with its own budget and seed 0; the final test-set
evaluation must reach the operating speed in every episode and beat the plain default ramp
(no dwell) on residual vibration.  The shipped agents themselves were trained with
``abb-gym train --config <name> --seed 0`` (see agents/README.md).
"""
from __future__ import annotations

import pytest

pytest.importorskip("stable_baselines3")

from abb_gym.rl import load_config, train  # noqa: E402
from abb_gym.rl.config import configs_dir  # noqa: E402

CONFIGS = sorted(p.stem for p in configs_dir().glob("*.yml"))


@pytest.mark.slow
@pytest.mark.parametrize("name", CONFIGS)
def test_full_training(name, tmp_path):
    from abb_gym.evaluation.evaluate import evaluate
    cfg = load_config(name)
    res = train(cfg, seed=0, run_dir=tmp_path / name, progress=False)
    s = res.evaluation
    assert s["at_speed"]["mean"] == 1.0                  # every run-up completed
    scene = cfg.env_kwargs.get("scene", "yoshida_odd")
    base = evaluate(cfg.env_id, scene, "baseline:ramp", episodes=s["episodes"],
                    seed=cfg.eval_seed).summary()
    assert s["residual_vibration"]["mean"] < base["residual_vibration"]["mean"]
