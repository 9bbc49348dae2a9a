"""Agent files that cannot run code, and pickled agents that load only when trusted.

A pickle runs whatever its author wrote when it is read, and a manifest an attacker rewrites
with the new fingerprints is no obstacle.  Each payload here creates a file when unpickled (as
a real one would do worse); every test shows that no command creates it:

* ``vecnormalize.pkl`` and ``model.zip`` (SB3 unpickles the ``:serialized:`` entries of its
  ``data``) of an agent folder in abb-gym's first format, behind a re-fingerprinted manifest,
  through ``evaluate``, ``render`` and ``train --init-from`` (and ``load_policy``): refused in
  one line that names ``abb-gym convert-agent``;
* the same folder trusted explicitly (``--trust-pickle``, ``ABB_GYM_TRUST_PICKLE``) loads with
  one warning line naming the files, and scores exactly as the shipped safe agent; converted
  once, it loads without trust;
* an rl_zoo3 run folder and a plain SB3 ``model.zip`` follow the same rule;
* a network of another environment behind a re-fingerprinted manifest (another shipped
  agent's, or one recorded for RunUpTorque whose sizes fit a RunUpSpeed agent) is refused by
  name, not evaluated as a speed agent because the sizes fit.
"""
from __future__ import annotations

import base64
import json
import pickle
import os
import shutil
import re
import subprocess
import sys
import zipfile
from collections import OrderedDict
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip("stable_baselines3")
pytest.importorskip("torch")

from abb_gym.cli import main  # noqa: E402
from abb_gym.rl import load_policy, make_native_env, trained_dir  # noqa: E402
from abb_gym.rl.agent_files import MANIFEST, AgentError, file_fingerprint  # noqa: E402

SPEED_ID = "abb_gym/RunUpSpeed-v0"
SPEED = "runup_speed_yoshida_odd"
DWELL = "dwell_profile_yoshida_odd"
PICKLES = ("model.zip", "vecnormalize.pkl", "best_model.zip", "best_vecnormalize.pkl")


class Payload:
    """Unpickling this creates the file ``path``: what an attacker's code would do first."""

    def __init__(self, path: Path):
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


def _sb3_model_and_statistics(name: str):
    """The shipped agent ``name`` as an SB3 PPO model and VecNormalize (what its first-format
    files held)."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from abb_gym.rl import load_config, make_sb3_env
    from abb_gym.rl.networks import policy_class

    src = trained_dir() / name
    cfg = load_config(src / "config.yml")
    venv = make_sb3_env(cfg.env_id, 1, cfg.env_kwargs)
    vn = VecNormalize(venv, **cfg.normalize)
    safe = load_policy(src)
    vn.obs_rms.mean = safe.vecnormalize.mean.copy()
    vn.obs_rms.var = safe.vecnormalize.var.copy()
    model = PPO(policy_class(cfg.policy), vn, device="cpu", **cfg.ppo_kwargs())
    model.policy.load_state_dict(safe.model.policy.state_dict())
    return model, vn, cfg


def pickled_copy(dest: Path, name: str = SPEED) -> Path:
    """A shipped agent in abb-gym's first format: model.zip, vecnormalize.pkl and a format-1
    manifest, as ``abb-gym train`` wrote it before the safe format."""
    src, folder = trained_dir() / name, dest / name
    if (src / "model.zip").exists():  # a checkout whose agents are still in that format
        shutil.copytree(src, folder)
        return folder
    shutil.copytree(src, folder, ignore=shutil.ignore_patterns("*.safetensors", "*.json",
                                                               MANIFEST))
    model, vn, cfg = _sb3_model_and_statistics(name)
    for prefix in ("", "best_"):  # the final and the best model, as training wrote them
        model.save(folder / f"{prefix}model.zip")
        vn.save(str(folder / f"{prefix}vecnormalize.pkl"))
    vn.venv.close()
    shipped = yaml.safe_load((src / MANIFEST).read_text())
    manifest = {"format": 1, "env_id": shipped["env_id"], "scene": shipped["scene"],
                "observation": shipped["observation"], "action_size": shipped["action_size"],
                "vecnormalize": True,
                "files": {f: file_fingerprint(folder / f) for f in PICKLES}}
    (folder / MANIFEST).write_text(yaml.safe_dump(manifest, sort_keys=False))
    return folder


def retag(folder: Path, name: str) -> None:
    """Record ``name``'s current fingerprint in the manifest, as an attacker would."""
    path = folder / MANIFEST
    data = yaml.safe_load(path.read_text())
    data["files"][name] = file_fingerprint(folder / name)
    path.write_text(yaml.safe_dump(data, sort_keys=False))


def plant_in_statistics(folder: Path, marker: Path) -> None:
    for name in ("vecnormalize.pkl", "best_vecnormalize.pkl"):
        if (folder / name).exists():
            (folder / name).write_bytes(pickle.dumps(Payload(marker)))
            retag(folder, name)


def plant_in_model(folder: Path, marker: Path) -> None:
    for name in ("model.zip", "best_model.zip"):
        if (folder / name).exists():
            _plant_in_zip(folder, marker, name)


def _plant_in_zip(folder: Path, marker: Path, name: str) -> None:
    """Replace every pickled entry of model.zip's ``data`` (the policy class, the spaces, the
    schedules: SB3 reads each ``:serialized:`` entry with cloudpickle, unless the loader
    passes that entry as a custom object) with the payload."""
    path = folder / name
    with zipfile.ZipFile(path) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    data = json.loads(members["data"])
    payload = base64.b64encode(pickle.dumps(Payload(marker))).decode()
    for entry in data.values():
        if isinstance(entry, dict) and ":serialized:" in entry:
            entry[":serialized:"] = payload
    members["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(path, "w") as zf:
        for n, content in members.items():
            zf.writestr(n, content)
    if (folder / MANIFEST).exists():
        retag(folder, name)


def commands(folder: Path, tmp_path: Path) -> list[list[str]]:
    """Every command that reads an agent folder: evaluate, render, train --init-from."""
    return [["evaluate", "--policy", f"ppo:{folder}", "--episodes", "1",
             "--out", str(tmp_path / "eval")],
            ["evaluate", "--policy", f"replay:ppo:{folder}", "--episodes", "1",
             "--out", str(tmp_path / "eval")],
            ["render", "--policy", f"ppo:{folder}", "--steps", "2",
             "--out", str(tmp_path / "video.gif")],
            ["train", "--config", "runup_speed_yoshida_odd", "--init-from", str(folder),
             "-n", "64", "--n-envs", "1", "--hyperparams", "n_steps=64", "batch_size=64",
             "--eval-freq", "0", "--checkpoint-freq", "0", "--no-progress",
             "--out", str(tmp_path / "run")]]


def refused_without_running(argv: list[str], marker: Path, capsys) -> str:
    code = main(argv)
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert not marker.exists(), f"{argv[0]} ran the pickle's code"
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, (argv, code, err)
    assert "abb-gym convert-agent" in lines[0] and "--trust-pickle" in lines[0], lines[0]
    return lines[0]


# --------------------------------------------------------------------------- finding 1
def test_a_pickle_planted_in_the_statistics_runs_nowhere(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("ABB_GYM_TRUST_PICKLE", raising=False)
    folder, marker = pickled_copy(tmp_path), tmp_path / "created_by_the_payload"
    plant_in_statistics(folder, marker)
    for argv in commands(folder, tmp_path):
        line = refused_without_running(argv, marker, capsys)
        assert "vecnormalize.pkl" in line
    with pytest.raises(AgentError, match="convert-agent"):
        load_policy(folder)
    assert not marker.exists()


def test_the_agents_evaluation_script_runs_no_planted_pickle(tmp_path, capsys, monkeypatch):
    """``agents/evaluate.py DIR`` reads agents through the same loader."""
    import importlib.util
    monkeypatch.delenv("ABB_GYM_TRUST_PICKLE", raising=False)
    folder, marker = pickled_copy(tmp_path), tmp_path / "created_by_the_payload"
    plant_in_statistics(folder, marker)
    plant_in_model(folder, marker)
    spec = importlib.util.spec_from_file_location(
        "agents_evaluate", Path(__file__).resolve().parents[1] / "agents" / "evaluate.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    assert script.main([str(folder), "--episodes", "2", "--out", str(tmp_path / "out")]) != 0
    assert not marker.exists()
    assert "convert-agent" in capsys.readouterr().err
    # --trust-pickle trusts them, as abb-gym's flag does: the planted code runs on loading
    script.main([str(folder), "--episodes", "2", "--oracle-budget", "0",
                 "--machine-oracle-budget", "0", "--baselines", "--pages", str(tmp_path / "p"),
                 "--out", str(tmp_path / "out2"), "--trust-pickle"])
    assert marker.exists()
    monkeypatch.delenv("ABB_GYM_TRUST_PICKLE", raising=False)


# --------------------------------------------------------------------------- finding 2
def test_a_pickle_planted_in_the_model_runs_nowhere(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("ABB_GYM_TRUST_PICKLE", raising=False)
    folder, marker = pickled_copy(tmp_path), tmp_path / "created_by_the_payload"
    plant_in_model(folder, marker)
    for argv in commands(folder, tmp_path):
        assert "model.zip" in refused_without_running(argv, marker, capsys)
    # a plain SB3 model.zip, alone or beside its statistics, and the file named directly
    lone = tmp_path / "lone"
    lone.mkdir()
    shutil.copy(folder / "model.zip", lone / "model.zip")
    for target in (lone, lone / "model.zip", folder / "model.zip"):
        refused_without_running(["evaluate", "--policy", f"ppo:{target}", "--episodes", "1",
                                 "--out", str(tmp_path / "eval")], marker, capsys)
    assert not marker.exists()


def test_the_shipped_agents_hold_no_pickle():
    for folder in trained_dir().iterdir():
        files = {p.name for p in folder.iterdir()}
        assert {"policy.safetensors", "vecnormalize.json", MANIFEST} <= files, folder.name
        assert not {n for n in files if n.endswith((".zip", ".pkl"))}, folder.name
        assert yaml.safe_load((folder / MANIFEST).read_text())["format"] == 2


# --------------------------------------------------------------------------- finding 6
def _model_file(folder: Path) -> str:
    return "policy.safetensors" if (folder / "policy.safetensors").exists() else "model.zip"


def _record_as_torque_network(folder: Path) -> str:
    """The speed agent's own network recorded as a RunUpTorque one (env id and action kind in
    its metadata, as a RunUpTorque agent's file records them): the sizes fit (6 observations,
    1 action), so only what the file records can tell.  No RunUpTorque agent ships."""
    from safetensors import safe_open
    from safetensors.torch import save_file
    path = folder / "policy.safetensors"
    with safe_open(str(path), "pt") as fh:
        meta, tensors = dict(fh.metadata()), {k: fh.get_tensor(k) for k in fh.keys()}
    save_file(tensors, str(path), metadata={**meta, "env_id": "abb_gym/RunUpTorque-v0",
                                            "action_kind": "torque"})
    return "RunUpTorque"


def _copy_dwell_network(folder: Path) -> str:
    """The shipped DwellProfile agent's network (3 actions, another size)."""
    name = _model_file(folder)
    shutil.copy(trained_dir() / DWELL / name, folder / name)
    return "DwellProfile"


@pytest.mark.parametrize("plant", [_record_as_torque_network, _copy_dwell_network],
                         ids=["torque-sizes-fit", "dwell-agent"])
def test_another_agents_network_is_refused_by_its_env_id_and_action_kind(plant, tmp_path,
                                                                         capsys):
    """Another environment's network in a RunUpSpeed agent, the manifest re-fingerprinted."""
    folder = tmp_path / SPEED
    shutil.copytree(trained_dir() / SPEED, folder)
    other = plant(folder)
    retag(folder, _model_file(folder))
    with pytest.raises(AgentError) as err:
        load_policy(folder)
    msg = str(err.value)
    assert other in msg and "RunUpSpeed" in msg and "another agent's" in msg, msg
    assert main(["evaluate", "--policy", f"ppo:{folder}", "--episodes", "1",
                 "--out", str(tmp_path / "eval")]) == 2
    assert other in capsys.readouterr().err


def test_a_network_of_another_action_kind_is_named(tmp_path):
    """The action kind is checked on its own: a network recorded for the torque action in a
    folder of the same env id is refused naming the kind."""
    from safetensors import safe_open
    from safetensors.torch import save_file
    folder = tmp_path / SPEED
    shutil.copytree(trained_dir() / SPEED, folder)
    path = folder / "policy.safetensors"
    with safe_open(str(path), "pt") as fh:
        meta, tensors = dict(fh.metadata()), {k: fh.get_tensor(k) for k in fh.keys()}
    save_file(tensors, str(path), metadata={**meta, "action_kind": "torque"})
    retag(folder, "policy.safetensors")
    with pytest.raises(AgentError, match=r"policy for action_kind 'torque', but the agent "
                                         r"folder's is 'speed'"):
        load_policy(folder)


# --------------------------------------------------------------------------- trusted pickles
def test_trusted_pickles_load_with_one_warning_and_score_as_the_safe_agent(tmp_path, capsys,
                                                                           monkeypatch):
    monkeypatch.delenv("ABB_GYM_TRUST_PICKLE", raising=False)
    folder = pickled_copy(tmp_path)
    common = ["--episodes", "2", "--seed", "3", "--env-kwargs", "control_interval=0.05"]
    # in a process of its own: stderr as a user sees it (pytest records warnings)
    proc = subprocess.run([sys.executable, "-m", "abb_gym.cli", "evaluate", "--policy",
                           f"ppo:{folder}", "--trust-pickle", *common,
                           "--out", str(tmp_path / "pickled")], capture_output=True, text=True,
                          env={k: v for k, v in os.environ.items()
                               if k != "ABB_GYM_TRUST_PICKLE"}, timeout=600)
    assert proc.returncode == 0, proc.stderr
    err = [line for line in proc.stderr.strip().splitlines()
           if not line.startswith("abb-gym: compiling")]  # a cold kernel cache says so
    assert len(err) == 1 and "warning: loading pickled agent files" in err[0], err
    assert str(folder / "model.zip") in err[0] and str(folder / "vecnormalize.pkl") in err[0]
    assert main(["evaluate", "--policy", f"ppo:{SPEED}", *common,
                 "--out", str(tmp_path / "safe")]) == 0
    pickled, safe = (json.loads((tmp_path / d / "evaluation.json").read_text())["policies"][0]
                     for d in ("pickled", "safe"))
    assert [{k: v for k, v in e.items() if k != "policy"} for e in pickled["episodes"]] == \
        [{k: v for k, v in e.items() if k != "policy"} for e in safe["episodes"]]
    # the environment variable trusts them too
    monkeypatch.setenv("ABB_GYM_TRUST_PICKLE", "1")
    with pytest.warns(UserWarning, match="loading pickled agent files"):
        assert load_policy(folder).env_id == SPEED_ID


def test_convert_agent_makes_a_folder_that_loads_without_trust(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("ABB_GYM_TRUST_PICKLE", raising=False)
    folder = pickled_copy(tmp_path)
    with pytest.warns(UserWarning, match=r"loading pickled agent files.*model.zip"):
        assert main(["convert-agent", str(folder), "--remove-pickles"]) == 0
    assert not (folder / "model.zip").exists() and not (folder / "vecnormalize.pkl").exists()
    converted, shipped = load_policy(folder), load_policy(SPEED)
    assert converted.reward_weights == shipped.reward_weights
    assert converted.reward_weights["residual"] == 6.0   # the agent's evaluation weights
    obs = np.random.default_rng(0).normal(size=(64, 6)).astype(np.float32)
    np.testing.assert_array_equal(converted.predict(obs), shipped.predict(obs))
    # only pickled agents are converted; an empty --out is refused
    assert main(["convert-agent", str(folder)]) == 2
    assert "is not a pickled agent" in capsys.readouterr().err


# --------------------------------------------------------------------------- rl_zoo3, plain SB3
def zoo_run(dest: Path, name: str = SPEED) -> Path:
    """An rl_zoo3 run folder as ``python -m rl_zoo3.train`` writes it (rl_zoo3's
    ``ExperimentManager.save_trained_model`` and ``_save_config``: yaml.dump of an
    OrderedDict)."""
    from abb_gym.rl.config import configs_dir
    model, vn, cfg = _sb3_model_and_statistics(name)
    env_name = SPEED_ID.replace("/", "-")
    run = dest / "logs" / "ppo" / f"{env_name}_1"
    params = run / env_name
    params.mkdir(parents=True)
    model.save(run / f"{env_name}.zip")
    vn.save(str(params / "vecnormalize.pkl"))
    vn.venv.close()
    entry = yaml.safe_load((configs_dir() / f"{name}.yml").read_text())[SPEED_ID]
    with open(params / "config.yml", "w") as fh:
        yaml.dump(OrderedDict(sorted(entry.items())), fh)
    args = OrderedDict([("algo", "ppo"), ("env", SPEED_ID), ("env_kwargs", None),
                        ("eval_env_kwargs", None), ("seed", 0), ("n_timesteps", -1)])
    with open(params / "args.yml", "w") as fh:
        yaml.dump(args, fh)
    return run


def test_an_rl_zoo3_run_folder_loads_when_trusted_and_converts(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("ABB_GYM_TRUST_PICKLE", raising=False)
    run, marker = zoo_run(tmp_path), tmp_path / "never"
    assert "!!python/object/apply:collections.OrderedDict" in (
        run / SPEED_ID.replace("/", "-") / "args.yml").read_text()
    refused_without_running(["evaluate", "--policy", f"ppo:{run}", "--episodes", "1",
                             "--out", str(tmp_path / "eval")], marker, capsys)
    with pytest.warns(UserWarning, match="loading pickled agent files"):
        pol = load_policy(run, trust_pickle=True)
    assert pol.env_id == SPEED_ID and pol.policy_env["control_interval"] == 0.05
    assert pol.observation_names == load_policy(SPEED).observation_names
    assert pol.reward_weights["residual"] == 6.0
    out = tmp_path / "converted"
    assert main(["convert-agent", str(run), "--out", str(out)]) == 0
    converted, shipped = load_policy(out), load_policy(SPEED)
    obs = np.random.default_rng(1).normal(size=(64, 6)).astype(np.float32)
    np.testing.assert_array_equal(converted.predict(obs), shipped.predict(obs))
    assert yaml.safe_load((out / "config.yml").read_text())["_run"]["converted_from"][
        "kind"] == "rl_zoo3"


def test_a_plain_sb3_model_needs_trust_and_its_environment(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("ABB_GYM_TRUST_PICKLE", raising=False)
    model, vn, _ = _sb3_model_and_statistics(SPEED)
    plain = tmp_path / "plain"
    plain.mkdir()
    model.save(plain / "model.zip")
    vn.save(str(plain / "vecnormalize.pkl"))
    vn.venv.close()
    with pytest.warns(UserWarning, match="loading pickled agent files"):
        pol = load_policy(plain / "model.zip", env_id=SPEED_ID, trust_pickle=True)
    assert pol.policy_env == {} and pol.observation_names is None   # it records nothing
    assert main(["evaluate", "--policy", f"ppo:{plain}", "--trust-pickle", "--episodes", "1",
                 "--env-kwargs", "control_interval=0.05", "--out", str(tmp_path / "e")]) == 0
    assert main(["convert-agent", str(plain / "model.zip"), "--out", str(tmp_path / "c")]) == 2
    assert "--env" in capsys.readouterr().err
    assert main(["convert-agent", str(plain / "model.zip"), "--env", SPEED_ID,
                 "--env-kwargs", "scene=yoshida_odd", "control_interval=0.05",
                 "'reward={residual: 6}'".strip("'"), "--out", str(tmp_path / "c")]) == 0
    converted = load_policy(tmp_path / "c")
    assert converted.policy_env["control_interval"] == 0.05
    assert converted.reward_weights["residual"] == 6.0
    obs = np.random.default_rng(2).normal(size=(64, 6)).astype(np.float32)
    np.testing.assert_array_equal(converted.predict(obs), load_policy(SPEED).predict(obs))
    env = make_native_env(SPEED_ID, 1, {"scene": "yoshida_odd", "preset": "test",
                                        "control_interval": 0.05})
    converted.reset(env, np.ones(1, bool))  # its recorded layout is the environment's
    env.close()


def _conversion_table() -> dict[str, float]:
    """docs/agent-files.md's table: each shipped agent's return before conversion (the
    pickled original, 16 episodes, seed 0, its own test preset, residual weight 2)."""
    text = (Path(__file__).resolve().parents[1] / "docs" / "agent-files.md").read_text()
    rows = re.findall(r"^\| (\w+) \| (-?\d+\.\d{6}) \| (-?\d+\.\d{6}) \|$", text, re.M)
    assert len(rows) >= 6, rows
    return {name: float(before) for name, before, _ in rows}


@pytest.mark.parametrize("name", sorted(_conversion_table()))
def test_converted_agents_score_as_their_pickled_originals_to_the_digit(name):
    """The safe files score what the pickles did, to the table's six decimals."""
    from abb_gym.evaluation.evaluate import evaluate
    from abb_gym.rl.comparison import agent_setting
    setting = agent_setting(name)
    result = evaluate(setting.env_id, setting.scene, f"ppo:{name}", 16, 0, setting.preset,
                      reward={"residual": 2.0})
    mean = float(np.mean([e["return"] for e in result.episodes]))
    assert round(mean, 6) == pytest.approx(_conversion_table()[name], abs=1.5e-6)
