"""PPO pipeline: configs, a short end-to-end run (train, save, load, evaluate), frozen
normalisation, action repeat and environment checks of a loaded policy.

The end-to-end smoke test trains a few thousand steps through ``abb-gym train`` (well under a
minute on a 2-core machine).  Full training runs are opt-in (``--runslow``), see
``test_rl_slow.py``.
"""
from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip("stable_baselines3")
pytest.importorskip("torch")

from abb_gym.cli import main as cli_main  # noqa: E402
from abb_gym.envs.config import RewardWeights  # noqa: E402
from abb_gym.evaluation.registry import resolve  # noqa: E402
from abb_gym.rl import (PPOPolicy, load_config, load_policy, make_native_env,  # noqa: E402
                        run_episodes, summarise)
from abb_gym.rl.config import TrainConfig, configs_dir  # noqa: E402
from abb_gym.rl.env_factory import eval_env_kwargs  # noqa: E402
from abb_gym.rl.zoo import zoo_problems  # noqa: E402

SPEED = "abb_gym/RunUpSpeed-v0"

SMOKE = {SPEED: {
    "n_envs": 4, "n_timesteps": 2048, "policy": "BoundedMlpPolicy",
    "normalize": {"norm_obs": True, "norm_reward": True},
    "n_steps": 128, "batch_size": 128, "n_epochs": 2, "gamma": 0.99,
    "learning_rate": "lin_3.0e-4",
    "policy_kwargs": {"net_arch": [16, 16], "activation_fn": "Tanh",
                      "action_mean_init": 0.5},
    "env_kwargs": {"scene": "yoshida_odd", "preset": "train", "control_interval": 0.05,
                   "reward": {"residual": 3.0}},
    "eval_freq": 1024, "eval_episodes": 4, "eval_seed": 5, "checkpoint_freq": 1024,
}}


@pytest.fixture(scope="module")
def smoke_run(tmp_path_factory, train_config):
    root = tmp_path_factory.mktemp("ppo")
    with pytest.MonkeyPatch.context() as mp:
        # the run's temporary folder, to see that training leaves nothing there
        mp.setattr(tempfile, "tempdir", str(tmp_path_factory.mktemp("tempdir")))
        mp.delenv("SB3_LOGDIR", raising=False)
        assert train_config(SMOKE, root, seed=3) == 0
        (root / "tempdir_after.txt").write_text("\n".join(os.listdir(tempfile.tempdir)))
    return root / "run"


def test_training_leaves_no_folder_in_the_temporary_directory(smoke_run):
    # SB3's default logger made an empty tempdir/SB3-<time> folder per run (886 of them in
    # this machine's /tmp)
    left = (smoke_run.parent / "tempdir_after.txt").read_text().split()
    assert not [name for name in left if name.startswith("SB3-")], left


def test_every_shipped_config_loads():
    files = sorted(configs_dir().glob("*.yml"))
    assert files, "configs/ppo has no configs"
    for f in files:
        data = yaml.safe_load(f.read_text())
        for env_id in (k for k in data if not k.startswith("_")):
            cfg = load_config(f, env_id)
            assert cfg.n_envs >= 1 and cfg.n_timesteps >= 1
            cfg.ppo_kwargs()
            kw = eval_env_kwargs(cfg)
            # a held-out preset (test, or the one the config names, e.g. varied_test for
            # varied), never the training one; the training's reward shaping and
            # randomisation are not carried over (a config may set eval reward weights for
            # model selection)
            assert kw["preset"] == cfg.eval_env_kwargs.get("preset", "test")
            assert kw["preset"] != cfg.env_kwargs.get("preset", "train")
            assert kw.get("reward") == cfg.eval_env_kwargs.get("reward")
            assert kw.get("randomize") == cfg.eval_env_kwargs.get("randomize")


@pytest.mark.parametrize("key, value, match", [
    ("n_envs", 0, r"'n_envs' must be an integer in \[1, 65536\] \(got 0\)"),
    ("n_timesteps", "many", r"'n_timesteps' must be an integer in \[1, 1e\+11\]"),
    ("learning_rate", "lin_x", r"'learning_rate' must be > 0 \(got 'x'\)"),
    ("learning_rate", -1.0, r"'learning_rate' must be > 0 \(got -1.0\)"),
    ("policy", "CnnPolicy", r"'policy' must be one of \['MlpPolicy', 'BoundedMlpPolicy'"),
    ("normalize", 3, "'normalize' must be true, false or a mapping"),
    ("bogus_key", 1, r"unknown key\(s\) \['bogus_key'\]"),
    ("policy_kwargs", {"activation_fn": "Nope"}, "activation_fn must name a torch.nn"),
    ("eval_episodes", 0, r"'eval_episodes' must be an integer in \[1, 1e\+06\]"),
    # rl_zoo3 passes its own tensorboard_log to PPO: the key belongs in _abb_gym
    ("tensorboard_log", "tb", r"field 'tensorboard_log' belongs in the _abb_gym section"),
])
def test_config_errors_name_the_field(key, value, match):
    raw = dict(SMOKE[SPEED], **{key: value})
    with pytest.raises(ValueError, match=match):
        TrainConfig.from_mapping(SPEED, raw)


def test_config_file_errors(tmp_path):
    with pytest.raises(ValueError, match="unknown PPO config"):
        load_config("no_such_config")
    f = tmp_path / "two.yml"
    f.write_text(yaml.safe_dump({SPEED: {}, "abb_gym/RunUpTorque-v0": {}}))
    with pytest.raises(ValueError, match="choose one with --env"):
        load_config(f)
    with pytest.raises(ValueError, match="unknown environment id"):
        TrainConfig.from_mapping("abb_gym/Nope-v0", {})
    cfg = load_config(f, SPEED)
    assert cfg.with_overrides(n_envs=2, env_kwargs={"scene": "spannan_cfrp"}).n_envs == 2


def test_smoke_run_writes_the_run_folder(smoke_run):
    for name in ("policy.safetensors", "optimizer.safetensors", "vecnormalize.json",
                 "config.yml", "evaluations.csv", "evaluations.npz", "evaluation.json",
                 "best_policy.safetensors", "best_vecnormalize.json", "agent.yml"):
        assert (smoke_run / name).exists(), name
    # no pickle anywhere in the run folder, checkpoints included
    assert not [p for p in smoke_run.rglob("*") if p.suffix in (".zip", ".pkl")]
    checkpoints = list((smoke_run / "checkpoints").glob("ppo_*_steps"))
    assert checkpoints and all((c / "policy.safetensors").is_file()
                               and (c / "vecnormalize.json").is_file() for c in checkpoints)
    conf = yaml.safe_load((smoke_run / "config.yml").read_text())
    run = conf["_run"]
    assert run["env_id"] == SPEED and run["seed"] == 3
    assert run["env_steps"] >= 2048 and run["env_steps_per_s"] > 0 and run["wall_time_s"] > 0
    assert run["policy_env"]["control_interval"] == 0.05
    assert run["eval_env_kwargs"]["preset"] == "test"
    ev = json.loads((smoke_run / "evaluation.json").read_text())
    assert ev["summary"]["episodes"] == 4
    npz = np.load(smoke_run / "evaluations.npz")
    assert npz["results"].shape[1] == 4
    # the run's config.yml trains again as it is (zoo style, keyed by the env id), with
    # abb-gym train and, although SMOKE is in the first-wave format, with rl_zoo3
    assert load_config(smoke_run / "config.yml").n_timesteps == 2048
    assert zoo_problems(smoke_run / "config.yml") == []
    # the manifest fingerprints the final and the best model and statistics
    manifest = yaml.safe_load((smoke_run / "agent.yml").read_text())
    assert set(manifest["files"]) == {"policy.safetensors", "optimizer.safetensors",
                                      "vecnormalize.json", "best_policy.safetensors",
                                      "best_optimizer.safetensors", "best_vecnormalize.json"}
    assert manifest["env_id"] == SPEED and manifest["scene"] == "yoshida_odd"
    assert manifest["action_kind"] == "speed" and manifest["algo"] == "ppo"
    # the weights of its held-out evaluation: the test preset's with the config's residual
    # (the unit of length is recorded only where a preset sets one)
    expected = {**RewardWeights().__dict__, **run["eval_env_kwargs"].get("reward", {})}
    assert manifest["reward_weights"] == {k: v for k, v in expected.items() if v is not None}
    best = load_policy(smoke_run, best=True)
    assert best.observation_names == manifest["observation"]["names"]


def test_load_policy_freezes_normalisation(smoke_run):
    pol = load_policy(smoke_run, env_id=SPEED)
    vn = pol.vecnormalize
    assert vn.training is False and vn.norm_reward is False
    mean = vn.mean.copy()
    env = make_native_env(SPEED, 2, dict(scene="yoshida_odd", preset="test",
                                         control_interval=0.05))
    obs, info = env.reset(seed=0)
    pol.reset(env, np.ones(2, bool))
    for _ in range(5):
        a = pol.act(obs, info)
        assert a.shape == (2, 1) and a.dtype == np.float32 and np.all(np.abs(a) <= 1)
        obs, *_ , info = env.step(a)
    np.testing.assert_array_equal(vn.mean, mean)
    saved = json.loads((smoke_run / "vecnormalize.json").read_text())
    np.testing.assert_array_equal(saved["obs_rms"]["mean"], mean)
    with pytest.raises(ValueError, match="trained on abb_gym/RunUpSpeed-v0"):
        load_policy(smoke_run, env_id="abb_gym/RunUpTorque-v0")


def test_evaluate_through_the_policy_registry(smoke_run):
    # the lead's evaluation resolves ppo:PATH through the loader abb_gym.rl registers;
    # its test environments use the default 10 ms interval: the 50 ms agent holds each
    # action for 5 steps
    pol = resolve(f"ppo:{smoke_run}", SPEED, "yoshida_odd")
    assert isinstance(pol, PPOPolicy)
    rows = run_episodes(pol, SPEED, episodes=2, seed=0, scene="yoshida_odd")
    s = summarise(rows)
    assert s["episodes"] == 2 and np.isfinite(s["return"]["mean"])
    assert pol._repeat == 5
    from abb_gym.evaluation.evaluate import evaluate
    res = evaluate(SPEED, "yoshida_odd", f"ppo:{smoke_run}", episodes=2, seed=0)
    assert [e["return"] for e in res.episodes] == pytest.approx([r["return"] for r in rows])


def test_action_repeat_holds_actions(smoke_run):
    pol = load_policy(smoke_run)
    env = make_native_env(SPEED, 2, dict(scene="yoshida_odd", preset="test"))  # 10 ms
    obs, info = env.reset(seed=1)
    pol.reset(env, np.ones(2, bool))
    acts = []
    for _ in range(10):
        a = pol.act(obs, info)
        acts.append(a.copy())
        obs, *_ , info = env.step(a)
    for k in range(1, 5):
        np.testing.assert_array_equal(acts[k], acts[0])
    np.testing.assert_array_equal(acts[6], acts[5])
    assert not np.array_equal(acts[5], acts[0])  # decided again on the new observation


def test_policy_rejects_a_mismatched_environment(smoke_run):
    pol = load_policy(smoke_run)
    env = make_native_env(SPEED, 1, dict(scene="yoshida_odd", observe_balls=True))
    with pytest.raises(ValueError, match="observation shape"):
        pol.reset(env, np.ones(1, bool))
    pol = load_policy(smoke_run)
    env = make_native_env(SPEED, 1, dict(scene="yoshida_odd", control_interval=0.02))
    with pytest.raises(ValueError, match="control_interval"):
        pol.reset(env, np.ones(1, bool))
    pol = load_policy(smoke_run)
    env = make_native_env("abb_gym/RunUpTorque-v0", 1, dict(scene="yoshida_odd",
                                                            control_interval=0.05))
    with pytest.raises(ValueError, match="action kind"):
        pol.reset(env, np.ones(1, bool))
    with pytest.raises(ValueError, match="no PPO agent"):
        load_policy(Path(smoke_run) / "nothing_here")


def test_train_command_reports_bad_input(capsys):
    assert cli_main(["train", "--config", "no_such_config"]) == 2
    assert "unknown PPO config" in capsys.readouterr().err


def test_an_agent_observing_the_sync_vibration_is_evaluated_with_it(tmp_path):
    """An agent trained with the synchronous-vibration observation and a frame stack carries
    both into its held-out evaluation environment and into `evaluate` (policy.env_kwargs),
    also inside `replay:`; an environment without them is refused naming the field."""
    from abb_gym.evaluation.evaluate import evaluate
    conf = {SPEED: dict(SMOKE[SPEED], n_timesteps=512, eval_freq=10_000, checkpoint_freq=10_000,
                        env_kwargs=dict(SMOKE[SPEED]["env_kwargs"],
                                        sync_vibration={"enabled": True, "lag": 0.05},
                                        frame_stack=2))}
    cfg = tmp_path / "sync.yml"
    cfg.write_text(yaml.safe_dump(conf))
    run = tmp_path / "run"
    assert cli_main(["train", "--config", str(cfg), "--seed", "1", "--out", str(run),
                     "--no-progress"]) == 0
    penv = yaml.safe_load((run / "config.yml").read_text())["_run"]["policy_env"]
    assert penv["sync_vibration"]["enabled"] is True and penv["frame_stack"] == 2
    pol = load_policy(run, env_id=SPEED)
    assert pol.env_kwargs["frame_stack"] == 2
    for spec in (f"ppo:{run}", f"replay:ppo:{run}"):
        result = evaluate(SPEED, "yoshida_odd", spec, episodes=2, seed=0)
        assert len(result.episodes) == 2
    env = make_native_env(SPEED, 1, dict(scene="yoshida_odd", preset="test",
                                         control_interval=0.05, frame_stack=2))
    with pytest.raises(ValueError, match="observation shape|sync_vibration"):
        pol.reset(env)


def test_config_keys_of_mixed_types_and_reserved_env_keywords_are_one_error(tmp_path):
    """A YAML key like 1: or ~: next to text keys, or env_kwargs setting what the trainer sets
    itself (num_envs...), is a TrainConfigError naming it, never a TypeError."""
    from abb_gym.rl.config import TrainConfigError
    mixed = tmp_path / "mixed.yml"
    mixed.write_text(f"{SPEED}:\n  n_envs: 2\n  1: 3\n  ~: 4\n")
    with pytest.raises(TrainConfigError, match="unknown key"):
        load_config(mixed)
    for key in ("num_envs", "vectorization_mode", "wrappers"):
        bad = tmp_path / f"{key}.yml"
        bad.write_text(yaml.safe_dump({SPEED: {"n_envs": 2, "env_kwargs": {key: 3}}}))
        with pytest.raises(TrainConfigError, match=key):
            load_config(bad)


def test_the_training_share_benchmark_times_the_environment_and_puts_it_back():
    from stable_baselines3 import PPO

    from abb_gym.benchmarks.training_share import training_share
    from abb_gym.rl.vec_env import NativeVecEnv
    before = (NativeVecEnv.step_wait, NativeVecEnv.reset, PPO.train)
    r = training_share("runup_speed_yoshida_odd_varied", steps=1024)
    assert r["env_steps"] >= 1024
    assert 0.0 < r["env_s"] < r["learn_s"] and 0.0 < r["env_share"] < 1.0
    assert 0.0 < r["update_s"] < r["learn_s"] and 0.0 < r["update_share"] < 1.0
    assert r["env_share"] + r["update_share"] < 1.0  # the two parts do not overlap
    assert (NativeVecEnv.step_wait, NativeVecEnv.reset, PPO.train) == before


def test_a_frame_stacked_agent_is_evaluated_at_its_own_control_interval(tmp_path, train_config):
    """The frames of a stack are one control interval apart: an agent trained with a stack at
    50 ms must see 50 ms frames in evaluation, not 10 ms ones with its actions held."""
    from abb_gym.evaluation.evaluate import evaluate
    conf = {SPEED: dict(SMOKE[SPEED], n_timesteps=512, eval_freq=10_000,
                        checkpoint_freq=10_000,
                        env_kwargs=dict(SMOKE[SPEED]["env_kwargs"], frame_stack=3))}
    assert train_config(conf, tmp_path, seed=1) == 0
    pol = load_policy(tmp_path / "run")
    assert pol.env_kwargs["control_interval"] == 0.05 and pol.env_kwargs["frame_stack"] == 3
    result = evaluate(SPEED, "yoshida_odd", f"ppo:{tmp_path / 'run'}", episodes=2, seed=0)
    env = make_native_env(SPEED, 1, dict(scene="yoshida_odd", preset="test",
                                         **pol.env_kwargs))
    assert env.unwrapped.setup.control_interval == 0.05
    assert len(result.episodes) == 2
