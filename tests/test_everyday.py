"""Everyday use (issue 15, "the tools RL users already use"): training speed independent of
the import order, registration that matches real episodes, confidence intervals that stay
inside the possible values, a study's CSV next to its chart, a trained agent on a single
environment, the open-source files, TensorBoard logging."""
from __future__ import annotations

import csv
import json
import math
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

import abb_gym
from abb_gym._threads import SHORT_SPIN
from abb_gym.envs import ENV_IDS, episode_steps
from abb_gym.evaluation import studies
from abb_gym.evaluation.evaluate import METRICS, NONNEGATIVE, SHARES, summarise
from abb_gym.evaluation.statistics import mean_ci

REPO = Path(__file__).resolve().parents[1]
RUNUP_IDS = ("abb_gym/RunUpTorque-v0", "abb_gym/RunUpSpeed-v0")


# ------------------------------------------------------------- import order and OpenMP
PROBE = """
import json, os, sys
if sys.argv[1] == "torch-first":
    import torch
    import abb_gym
else:
    import abb_gym
    import torch
import gymnasium as gym, numba, numpy as np
from abb_gym._threads import ADJUSTED
env = gym.make_vec("abb_gym/RunUpSpeed-v0", num_envs=2, vectorization_mode="vector_entry_point")
env.reset(seed=0)
env.step(np.zeros((2, 1), np.float32))
print(json.dumps({"layer": numba.threading_layer(), "torch_threads": torch.get_num_threads(),
                  "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY"),
                  "gomp_spincount": os.environ.get("GOMP_SPINCOUNT"),
                  "adjusted": ADJUSTED}))
"""


def _fresh_env(**extra: str) -> dict[str, str]:
    """The environment of a fresh shell: this process set OMP_WAIT_POLICY and GOMP_SPINCOUNT
    on import."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT", "NUMBA_THREADING_LAYER")}
    env.update(extra)
    return env


def _probe(order: str, **env: str) -> dict:
    out = subprocess.run([sys.executable, "-c", PROBE, order], capture_output=True, text=True,
                         env=_fresh_env(**env), timeout=600, cwd=REPO)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_torch_first_gets_no_spinning_openmp_threads():
    """torch imported first: its OpenMP runtime read no wait policy and busy-waits, so numba
    leaves OpenMP (workqueue) and torch runs one intra-op thread; nothing spins."""
    pytest.importorskip("torch")
    got = _probe("torch-first")
    assert got["omp_wait_policy"] == "PASSIVE"
    assert got["layer"] == "workqueue"
    assert got["torch_threads"] == 1
    assert got["adjusted"]["numba_threading_layer"] == "workqueue"


def test_abb_gym_first_changes_only_the_wait_policy_and_its_spin():
    pytest.importorskip("torch")
    got = _probe("abb-first")
    assert got["omp_wait_policy"] == "PASSIVE"
    assert got["gomp_spincount"] == SHORT_SPIN
    assert got["adjusted"] == {"OMP_WAIT_POLICY": "PASSIVE", "GOMP_SPINCOUNT": SHORT_SPIN}


def test_a_spin_count_set_by_the_user_is_kept():
    pytest.importorskip("torch")
    got = _probe("abb-first", GOMP_SPINCOUNT="0")
    assert got["omp_wait_policy"] == "PASSIVE"
    assert got["gomp_spincount"] == "0"
    assert got["adjusted"] == {"OMP_WAIT_POLICY": "PASSIVE"}


def test_a_wait_policy_set_by_the_user_is_respected():
    pytest.importorskip("torch")
    got = _probe("torch-first", OMP_WAIT_POLICY="ACTIVE")
    assert got["omp_wait_policy"] == "ACTIVE"
    assert got["gomp_spincount"] is None
    assert got["adjusted"] == {}
    assert got["torch_threads"] != 1 or os.cpu_count() == 1


TIMING = """
import sys, time
if sys.argv[1] == "torch-first":
    import torch
    import abb_gym
else:
    import abb_gym
    import torch
import gymnasium as gym, numpy as np
from stable_baselines3 import PPO
from abb_gym.rl.vec_env import NativeVecEnv
venv = NativeVecEnv(gym.make_vec("abb_gym/RunUpSpeed-v0", num_envs=8,
                                 vectorization_mode="vector_entry_point"))
venv.reset()
venv.step(np.zeros((8, 1), np.float32))  # loads the compiled kernel
model = PPO("MlpPolicy", venv, seed=0, device="cpu", n_steps=256, batch_size=256)
t0 = time.perf_counter()
model.learn(4096)
print(time.perf_counter() - t0)
"""


@pytest.mark.slow
def test_training_speed_does_not_depend_on_the_import_order():
    """SB3 PPO on the native vector env: torch first was 8x slower before abb_gym._threads
    (66 s against 8 s for learn(2048) with default PPO settings on 2 cores)."""
    pytest.importorskip("stable_baselines3")

    def seconds(order: str) -> float:
        out = subprocess.run([sys.executable, "-c", TIMING, order], capture_output=True,
                             text=True, env=_fresh_env(), timeout=1200, cwd=REPO)
        assert out.returncode == 0, out.stderr[-2000:]
        return float(out.stdout.strip().splitlines()[-1])

    # best of two each: a loaded machine only ever makes a run slower
    abb_first = min(seconds("abb-first") for _ in range(2))
    torch_first = min(seconds("torch-first") for _ in range(2))
    assert torch_first < 2.0 * abb_first, (torch_first, abb_first)


# ------------------------------------------------------------------------- registration
@pytest.mark.parametrize("env_id", RUNUP_IDS)
def test_made_spec_is_the_real_episode(env_id):
    """Nothing scene-dependent is registered; the made environment's spec is exact."""
    assert gym.spec(env_id).max_episode_steps is None
    assert gym.spec(env_id).reward_threshold is None  # documented: no "solved" level
    env = gym.make(env_id)
    setup = env.unwrapped.setup
    assert env.spec.max_episode_steps == setup.max_steps == episode_steps(env_id) == 850
    env = gym.make(env_id, scene="spannan_cfrp")
    assert env.spec.max_episode_steps == episode_steps(env_id, scene="spannan_cfrp") == 6350


def test_episodes_end_at_the_spec_and_longer_scenes_are_not_cut():
    env = gym.make("abb_gym/RunUpSpeed-v0", control_interval=0.1, preset="nominal")
    limit = env.spec.max_episode_steps
    assert limit == episode_steps("abb_gym/RunUpSpeed-v0", control_interval=0.1) == 85
    env.reset(seed=0)
    for k in range(1, limit + 1):
        _, _, terminated, truncated, _ = env.step(np.zeros(1, np.float32))
        if terminated or truncated:
            break
    assert truncated and not terminated and k == limit
    # the default scene's 850 steps must not cut a scene whose episodes last 6350
    env = gym.make("abb_gym/RunUpSpeed-v0", scene="spannan_cfrp", preset="nominal")
    env.reset(seed=0)
    for _ in range(900):
        _, _, terminated, truncated, _ = env.step(np.zeros(1, np.float32))
        assert not (terminated or truncated)
    vec = gym.make_vec("abb_gym/RunUpSpeed-v0", num_envs=2,
                       vectorization_mode="vector_entry_point", scene="spannan_cfrp")
    assert vec.unwrapped.setup.backstop == 0  # no registered number reaches the kernel
    vec.close()


def test_dwell_registration_and_explicit_limits():
    assert gym.spec("abb_gym/DwellProfile-v0").max_episode_steps == 2
    assert episode_steps("abb_gym/DwellProfile-v0") == 1
    env = gym.make("abb_gym/RunUpSpeed-v0", max_episode_steps=5)
    env.reset(seed=0)
    for _ in range(5):
        _, _, _, truncated, _ = env.step(np.zeros(1, np.float32))
    assert truncated
    with pytest.raises(ValueError, match="env_id"):
        episode_steps("CartPole-v1")


# ----------------------------------------------------------------- confidence intervals
def test_confidence_intervals_of_nonnegative_metrics_stay_at_or_above_zero():
    """A skewed sample (mostly zeros, one large value) has a t-interval reaching below 0."""
    skewed = [0.0] * 9 + [50.0]
    mean, low, high, n = mean_ci(skewed)
    assert low < 0.0  # the unclipped interval: what the check below guards against
    episodes = [{key: (value > 0 if key in SHARES else value) for key in METRICS}
                for value in skewed]
    summary = summarise(episodes)
    assert set(NONNEGATIVE) >= {"run_up_time", "residual_vibration", "peak_whirl",
                                "drive_energy", "time_above_band"}
    for key in NONNEGATIVE:
        assert summary[key]["ci_low"] == 0.0, key
        assert summary[key]["ci_high"] == pytest.approx(high)
        assert summary[key]["mean"] == pytest.approx(mean)
    assert summary["return"]["ci_low"] < 0.0  # a return may be negative: not clipped
    rng = np.random.default_rng(0)
    for _ in range(200):
        values = rng.exponential(1.0, size=int(rng.integers(2, 12))) * (rng.random() < 0.5)
        _, low, high, _ = mean_ci(values, nonnegative=True)
        assert low >= 0.0 and high >= low


# --------------------------------------------------------------------------- study CSV
def test_study_chart_has_its_csv_next_to_it(tmp_path):
    rows = [{"dwell": "constant speed", "dwell_accel": 0.0, "dwell_time_s": 0.4,
             "settling_period_s": 0.8},
            {"dwell": "constant speed", "dwell_accel": 0.0, "dwell_time_s": 0.6,
             "settling_period_s": math.nan},
            {"dwell": "constant acceleration", "dwell_accel": 20.0, "dwell_time_s": 0.4,
             "settling_period_s": 0.7}]
    png = studies.plot_settling_study(rows, tmp_path / "sub" / "settling_period.png")
    table = png.with_suffix(".csv")
    assert png.is_file() and table.is_file()
    with open(table, newline="") as fh:
        back = list(csv.DictReader(fh))
    assert [r["dwell_time_s"] for r in back] == ["0.4", "0.6", "0.4"]
    assert list(back[0]) == list(rows[0])
    assert math.isnan(float(back[1]["settling_period_s"]))
    pos = [{"profile": "no profile", "ball_mass_g": 1.0, "ball_drag_Ns_m": 0.5,
            "ball_angle_deg": -170.0},
           {"profile": "dwell 0.5 s", "ball_mass_g": 1.0, "ball_drag_Ns_m": 0.5,
            "ball_angle_deg": -185.0}]
    png = studies.plot_ball_position_study(pos, tmp_path / "ball_position.png")
    with open(png.with_suffix(".csv"), newline="") as fh:
        assert [float(r["ball_angle_deg"]) for r in csv.DictReader(fh)] == [-170.0, -185.0]
    with pytest.raises(ValueError, match="without rows"):
        studies.write_csv([], tmp_path / "empty.csv")


def test_study_command_writes_the_csv(tmp_path, capsys):
    from abb_gym.cli import main
    assert main(["study", "settling", "--out", str(tmp_path)]) == 0
    with open(tmp_path / "settling_period.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 12 and "settling_period_s" in rows[0]


# ---------------------------------------------------------- a trained agent, one env
def test_load_policy_acts_on_a_single_environment():
    pytest.importorskip("stable_baselines3")
    from abb_gym.rl import load_policy, run_episodes
    policy = load_policy("runup_speed_yoshida_odd")
    env = gym.make("abb_gym/RunUpSpeed-v0", preset="test")
    obs, info = env.reset(seed=0)
    policy.reset(env)
    total, steps = 0.0, 0
    while True:
        action = policy.act(obs, info)
        assert action.shape == env.action_space.shape
        obs, reward, terminated, truncated, info = env.step(action)
        total += reward
        steps += 1
        if terminated or truncated:
            break
    # the same episode as the vector path of the evaluation
    record = run_episodes(policy, "abb_gym/RunUpSpeed-v0", episodes=1, seed=0,
                          scene="yoshida_odd", preset="test")[0]
    assert steps == record["steps"]
    assert total == pytest.approx(record["return"], rel=1e-9)


# ---------------------------------------------------------------- open-source files
def _pyproject() -> dict:
    return tomllib.loads((REPO / "pyproject.toml").read_text())["project"]


def test_license_file_matches_pyproject():
    project = _pyproject()
    declared = project["license"]
    declared = declared["text"] if isinstance(declared, dict) else declared
    text = (REPO / "LICENSE").read_text()
    assert declared == "MIT"
    assert text.startswith("MIT License\n")
    assert "Permission is hereby granted, free of charge" in text
    assert re.search(r"Copyright \(c\) \d{4} \S", text)


def test_citation_file_is_valid_and_current():
    cff = yaml.safe_load((REPO / "CITATION.cff").read_text())
    project = _pyproject()
    assert cff["cff-version"] == "1.2.0"
    for key in ("message", "title", "authors", "type"):
        assert cff[key], key
    assert all("name" in a or "family-names" in a for a in cff["authors"])
    assert str(cff["version"]) == project["version"] == abb_gym.__version__
    assert cff["license"] == "MIT"


def test_changelog_lists_the_current_version():
    text = (REPO / "CHANGELOG.md").read_text()
    assert text.startswith("# Changelog")
    assert "## [Unreleased]" in text
    assert re.search(rf"^## \[{re.escape(_pyproject()['version'])}\] - \d{{4}}-\d\d-\d\d$",
                     text, re.MULTILINE)


# -------------------------------------------------------------------------- TensorBoard
def test_config_accepts_tensorboard_log_and_rejects_non_paths(tmp_path):
    pytest.importorskip("stable_baselines3")
    from abb_gym.rl.config import TrainConfigError, load_config
    cfg = load_config("runup_speed_yoshida_odd")
    assert cfg.with_overrides(tensorboard_log=str(tmp_path)).ppo_kwargs()["tensorboard_log"] \
        == str(tmp_path)
    with pytest.raises(TrainConfigError, match="tensorboard_log"):
        cfg.with_overrides(tensorboard_log=5)
    from abb_gym.rl.train import check_tensorboard_log
    (tmp_path / "f").write_text("")
    with pytest.raises(ValueError, match="is a file"):
        check_tensorboard_log(tmp_path / "f")
    assert check_tensorboard_log(None) is None


def test_train_writes_tensorboard_events(tmp_path):
    pytest.importorskip("stable_baselines3")
    pytest.importorskip("tensorboard")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
    from abb_gym.rl import load_config, train
    cfg = load_config("runup_speed_yoshida_odd").with_overrides(
        n_timesteps=512, n_envs=4, n_steps=64, batch_size=64, n_epochs=1, eval_freq=0,
        checkpoint_freq=0)
    res = train(cfg, seed=3, run_dir=tmp_path / "run", progress=False, final_eval=False,
                tensorboard_log=tmp_path / "tb")
    runs = sorted(p.name for p in (tmp_path / "tb").iterdir())
    assert runs == ["runup_speed_yoshida_odd_s3_1"]
    events = EventAccumulator(str(tmp_path / "tb" / runs[0]))
    events.Reload()
    assert "train/value_loss" in events.Tags()["scalars"]
    meta = yaml.safe_load((res.run_dir / "config.yml").read_text())["_run"]
    assert Path(meta["tensorboard_log"]).name == "tb"


def test_train_command_has_a_tensorboard_option():
    import argparse
    from abb_gym.cli.train import add_train_arguments
    parser = argparse.ArgumentParser()
    add_train_arguments(parser)
    try:
        args = parser.parse_args(["--config", "runup_speed_yoshida_odd",
                                  "--tensorboard-log", "tb"])
    except SystemExit:
        pytest.fail("abb-gym train has no --tensorboard-log option")
    assert args.tensorboard_log == "tb"


# ------------------------------------------------------------- a light import
LIGHT = """
import sys
import abb_gym, abb_gym.physics.methods
from abb_gym.cli import build_parser
parser = build_parser()
for action in parser._actions:
    for sub in (getattr(action, "choices", None) or {}).values():
        if hasattr(sub, "format_help"):
            sub.format_help()
import gymnasium as gym
assert "abb_gym/RunUpSpeed-v0" in gym.registry
print(sorted(m for m in ("numba", "scipy", "torch", "matplotlib", "abb_gym.physics.model")
             if m in sys.modules))
"""


def test_import_and_every_help_load_no_numba_scipy_torch_or_matplotlib():
    """``import abb_gym`` registers the ids and ``abb-gym [COMMAND] --help`` builds every
    parser without numba (0.2-0.3 s of the 0.5 s budget), scipy, torch or matplotlib; the
    simulator's names load them on first use (docs/getting-started.md, "The first start
    compiles")."""
    out = subprocess.run([sys.executable, "-c", LIGHT], capture_output=True, text=True,
                         env=_fresh_env(), timeout=600, cwd=REPO)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "[]"


def test_the_simulators_names_load_on_first_use_and_stay_the_functions():
    """``abb_gym.simulate`` is the function, also after the module of the same name was
    imported first (importing a submodule binds it on its package)."""
    code = ("import abb_gym.physics.simulate as m, abb_gym, abb_gym.physics as ph; "
            "import types; from abb_gym.physics import simulate; "
            "print(callable(simulate), simulate is abb_gym.simulate is ph.simulate, "
            "isinstance(m, types.ModuleType), abb_gym.load_scene('yoshida_odd').name)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=_fresh_env(), timeout=600, cwd=REPO)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["True", "True", "False", "yoshida_odd"]
