"""rl-baselines3-zoo and the PPO config format (``abb_gym/rl/config.py``, ``abb_gym/rl/zoo.py``).

* rl_zoo3 trains every shipped ``configs/ppo/*.yml`` unchanged, with the hyperparameters and
  the policy ``abb-gym train`` reads from the same file (skipped, with the reason, only when
  rl_zoo3 is not importable: the ``zoo`` extra brings it, and the ``test`` extra includes it);
* :func:`zoo_problems` (the zoo's rules, checked without the zoo) passes every shipped config
  and names the key of each problem in a first-wave file;
* the shipped agents were trained with exactly the shipped configs: their ``config.yml``
  (first-wave format, fingerprinted, never edited) reads as the same :class:`TrainConfig`
  as ``configs/ppo/<name>.yml``, so retraining from either is the same run.
"""
from __future__ import annotations

import math

import os
import pickle
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

pytest.importorskip("stable_baselines3")
pytest.importorskip("torch")

import abb_gym  # noqa: E402
from abb_gym.rl import load_config, trained_dir  # noqa: E402
from abb_gym.rl.config import (ABB_GYM_SECTION, TrainConfig, TrainConfigError,  # noqa: E402
                               configs_dir, resolve_policy_kwargs)
from abb_gym.rl.zoo import zoo_problems  # noqa: E402

CONFIGS = sorted(configs_dir().glob("*.yml"))
AGENTS = sorted(d for d in trained_dir().glob("*") if (d / "config.yml").exists())
SPEED = "abb_gym/RunUpSpeed-v0"


def _entries():
    for f in CONFIGS:
        data = yaml.safe_load(f.read_text())
        for env_id in (k for k in data if not str(k).startswith("_")):
            yield pytest.param(f, env_id, id=f"{f.stem}[{env_id}]")


# ------------------------------------------------------------------- format, without the zoo
def test_shipped_configs_are_in_the_zoo_format():
    assert CONFIGS, "configs/ppo has no configs"
    for f in CONFIGS:
        assert zoo_problems(f) == [], f.name


@pytest.mark.parametrize("change, match", [
    ({"policy": "BoundedMlpPolicy"}, r"'policy': 'BoundedMlpPolicy' is not an SB3 policy "
                                     r"name .* import path: abb_gym.rl.networks.BoundedMlpPolicy"),
    ({"policy": "abb_gym.rl.networks.NoSuchPolicy"}, r"'policy': rl_zoo3 cannot import"),
    ({"policy": "no_such_package.Policy"}, r"cannot import the class .*no_such_package"),
    ({"policy_kwargs": {"net_arch": [8], "activation_fn": "Tanh"}},
     r"'policy_kwargs.activation_fn' is the string 'Tanh' in a mapping"),
    ({"policy_kwargs": "dict(activation_fn=os.system)"}, r"policy_kwargs: 'os.system' is not "
                                                          r"allowed"),
    ({"eval_freq": 100}, r"'eval_freq' under the environment id: .* move it to the _abb_gym"),
    ({"tensorboard_log": "tb"}, r"'tensorboard_log' under .* passes its own tensorboard_log"),
    ({"shaping": {"observation": "sync_amplitude"}},
     r"'shaping' under the environment id: .* move it to the _abb_gym section"),
    ({"algo": "sac"}, r"'algo' under the environment id: .* move it to the _abb_gym section"),
    ({"seed": 3}, r"'seed' under the environment id: rl_zoo3 sets it from its command line"),
    ({"learning_rate": "exp_1e-3"}, r"'learning_rate': rl_zoo3 reads a string only as "
                                    r"lin_<start>"),
    ({"bogus": 1}, r"'bogus' is neither an rl_zoo3 key nor a PPO keyword"),
    ({"normalize": 3}, r"'normalize' must be true, false, a mapping or a zoo string"),
    ({"env_kwargs": "scene=x"}, r"'env_kwargs' must be a mapping"),
])
def test_zoo_problems_name_the_key(change, match):
    data = yaml.safe_load((configs_dir() / "runup_speed_yoshida_odd.yml").read_text())
    data[SPEED].update(change)
    problems = zoo_problems(data)
    assert len(problems) == 1, problems
    assert problems[0].startswith(f"{SPEED}: ")
    import re
    assert re.search(match, problems[0]), problems[0]


def test_zoo_problems_of_missing_entries():
    assert "'n_timesteps' is missing" in " ".join(zoo_problems({SPEED: {"policy": "MlpPolicy"}}))
    assert "'policy' is missing" in " ".join(zoo_problems({SPEED: {"n_timesteps": 10}}))
    assert "no entry for this environment id" in zoo_problems({SPEED: {}}, "abb_gym/X-v0")[0]
    assert "no environment id entry" in zoo_problems({ABB_GYM_SECTION: {}})[0]
    assert "must be a mapping of hyperparameters" in zoo_problems({SPEED: [1]})[0]


def test_project_keys_belong_in_their_section():
    data = yaml.safe_load((configs_dir() / "runup_speed_yoshida_odd.yml").read_text())
    entry, extra = data[SPEED], data[ABB_GYM_SECTION]
    with pytest.raises(TrainConfigError, match=r"field 'tensorboard_log' belongs in the "
                                               r"_abb_gym section"):
        TrainConfig.from_mapping(SPEED, {**entry, "tensorboard_log": "tb"}, "f.yml", extra)
    with pytest.raises(TrainConfigError, match=r"unknown key\(s\) \['n_steps'\] in _abb_gym"):
        TrainConfig.from_mapping(SPEED, entry, "f.yml", {**extra, "n_steps": 64})
    with pytest.raises(TrainConfigError, match=r"\['eval_freq'\] given both under the "
                                               r"environment id and in _abb_gym"):
        TrainConfig.from_mapping(SPEED, {**entry, "eval_freq": 5}, "f.yml", extra)
    cfg = TrainConfig.from_mapping(SPEED, entry, "f.yml", {**extra, "tensorboard_log": "tb"})
    assert cfg.ppo_kwargs()["tensorboard_log"] == "tb"
    assert cfg.to_file_data()[ABB_GYM_SECTION]["tensorboard_log"] == "tb"
    # overrides go to the section they belong to, and the result is still zoo-readable
    changed = cfg.with_overrides(n_steps=64, eval_freq=7, tensorboard_log="tb2")
    data = changed.to_file_data()
    assert data[SPEED]["n_steps"] == 64 and "eval_freq" not in data[SPEED]
    assert data[ABB_GYM_SECTION]["eval_freq"] == 7
    assert data[ABB_GYM_SECTION]["tensorboard_log"] == "tb2"
    assert zoo_problems(data) == []


# ----------------------------------------------------------------- the shipped agents' configs
def test_agents_are_found():
    assert len(AGENTS) >= 4, AGENTS


@pytest.mark.parametrize("folder", AGENTS, ids=lambda d: d.name)
def test_shipped_agent_config_is_its_shipped_config(folder):
    """The agent's config.yml (first-wave format, or the current one for agents trained since)
    and the shipped file it was trained from (``_run.config_source``) are the same config, key
    for key."""
    data = yaml.safe_load((folder / "config.yml").read_text())
    old = load_config(folder / "config.yml")
    new = load_config(Path(data["_run"]["config_source"]).stem, old.env_id)
    assert old.to_file_data() == new.to_file_data()
    assert resolve_policy_kwargs(old.policy_kwargs) == resolve_policy_kwargs(new.policy_kwargs)
    kw_old, kw_new = old.ppo_kwargs(), new.ppo_kwargs()
    assert kw_old.keys() == kw_new.keys()
    for key in kw_old:
        a, b = kw_old[key], kw_new[key]
        if callable(a):  # schedules
            assert [a(p) for p in (1.0, 0.5, 0.0)] == [b(p) for p in (1.0, 0.5, 0.0)], key
        else:
            assert a == b, key
    # rl_zoo3 cannot read a first-wave file (agents trained before the _abb_gym section);
    # what abb-gym train writes now, it can
    if "_abb_gym" in data:
        assert zoo_problems(data) == []
    else:
        assert zoo_problems(data)
    assert zoo_problems(old.to_file_data()) == []


# ------------------------------------------------------------------------------ rl_zoo3 itself
def _zoo_env() -> dict[str, str]:
    """The environment of the zoo subprocess: it must import this abb_gym."""
    env = dict(os.environ)
    root = str(Path(abb_gym.__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
    return env


@pytest.mark.parametrize("path, env_id", list(_entries()))
def test_rl_zoo3_trains_the_shipped_config_unchanged(path, env_id, tmp_path):
    pytest.importorskip("rl_zoo3", reason="rl_zoo3 is not installed (pip install -c "
                                          "constraints.txt rl_zoo3): the zoo cannot be run")
    from torch import nn
    from abb_gym.rl.algorithms import OFF_POLICY, algorithm_class
    from abb_gym.rl.networks import policy_class

    cfg = load_config(path, env_id)
    algorithm = algorithm_class(cfg.algo)
    kw = cfg.ppo_kwargs()
    off_policy = cfg.algo in OFF_POLICY
    # the zoo always completes a rollout: -n of one rollout = one rollout and one PPO update;
    # off-policy: four vector steps (no update before learning_starts)
    rollout = cfg.n_envs * 4 if off_policy else kw["n_steps"] * cfg.n_envs
    cmd = [sys.executable, "-m", "rl_zoo3.train", "--algo", cfg.algo, "--env", env_id,
           "--gym-packages", "abb_gym", "-conf", str(path), "-n", str(rollout),
           "-f", str(tmp_path / "logs"), "--seed", "0"]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=tmp_path, env=_zoo_env(), capture_output=True, text=True,
                          timeout=600)
    wall = time.perf_counter() - t0
    assert proc.returncode == 0, (f"{' '.join(cmd)} failed:\n{proc.stdout[-3000:]}\n"
                                  f"{proc.stderr[-3000:]}")
    name = env_id.replace("/", "-")
    run = tmp_path / "logs" / cfg.algo / f"{name}_1"
    model = algorithm.load(run / f"{name}.zip", device="cpu")
    print(f"{path.name}: rl_zoo3 run of {model.num_timesteps} steps in {wall:.1f} s")

    # the hyperparameters abb-gym train reads from the same file
    assert model.num_timesteps == rollout
    assert model.n_envs == cfg.n_envs
    keys = (("batch_size", "gamma", "tau", "learning_starts", "buffer_size", "gradient_steps")
            if off_policy else ("n_steps", "batch_size", "n_epochs", "gamma", "gae_lambda",
                                "ent_coef"))
    for key in keys:
        assert getattr(model, key) == kw[key], key
    schedules = [("learning_rate", model.lr_schedule)]
    if not off_policy:
        schedules.append(("clip_range", model.clip_range))
    for key, schedule in schedules:
        expect = kw[key] if callable(kw[key]) else (lambda p, v=kw[key]: v)
        for p in (1.0, 0.5, 0.1):
            assert schedule(p) == pytest.approx(expect(p)), key
    # the policy abb-gym train builds: class, network, activation, bounded initial mean
    pk = resolve_policy_kwargs(cfg.policy_kwargs)
    expected_class = policy_class(cfg.policy)
    if isinstance(expected_class, str):
        expected_class = algorithm.policy_aliases[expected_class]
    assert type(model.policy) is expected_class
    assert model.policy.net_arch == pk["net_arch"]
    if "activation_fn" in pk:
        assert model.policy.activation_fn is pk["activation_fn"]
    if "action_mean_init" in pk:
        assert model.policy.action_mean_init == pk["action_mean_init"]
        if off_policy:  # the actor's mean layer starts at atanh(action_mean_init)
            assert model.actor.mu.bias.detach().numpy() == pytest.approx(
                math.atanh(pk["action_mean_init"]), abs=0.05)
        else:
            assert isinstance(model.policy.action_net[-1], nn.Tanh)  # the tanh-bounded mean
    # the normalisation and the environment keywords of the file
    with open(run / name / "vecnormalize.pkl", "rb") as fh:
        vn = pickle.load(fh)
    assert (vn.norm_obs, vn.norm_reward) == (cfg.normalize["norm_obs"],
                                             cfg.normalize["norm_reward"])
    assert vn.gamma == kw["gamma"]
    # the zoo writes its config.yml as a Python OrderedDict (written by this test's run)
    saved = yaml.load((run / name / "config.yml").read_text(), Loader=yaml.UnsafeLoader)
    assert dict(saved)["env_kwargs"] == cfg.env_kwargs
