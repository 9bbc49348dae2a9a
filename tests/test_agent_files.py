"""Agent folders are complete and self-consistent, or loading fails with one line.

Every test works on a copy of a shipped agent in a temporary folder, corrupts it, and checks
that :func:`abb_gym.rl.load_policy` (and ``abb-gym evaluate --policy ppo:COPY``) refuses it
with one :class:`~abb_gym.rl.agent_files.AgentError` line naming the file: a missing, foreign,
truncated, empty, random or mistyped file, a directory in a file's place, and invalid YAML.
The hypothesis test draws such corruptions (and manifests rewritten to match them) at random.
Nothing is unpickled: a pickle written in a file's place is refused like any other bytes
(the planted payloads are in tests/test_safe_agents.py).
"""
from __future__ import annotations

import json
import pickle
import re
import shutil
import tempfile
import tomllib
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip("stable_baselines3")
pytest.importorskip("torch")

from abb_gym.cli import main  # noqa: E402
from abb_gym.rl import load_policy, make_native_env, trained_dir  # noqa: E402
from abb_gym.rl.env_factory import observation_kwargs  # noqa: E402
from abb_gym.rl.agent_files import (MANIFEST, AgentError, check_folder,  # noqa: E402
                                    file_fingerprint, write_manifest)

REPO = Path(__file__).resolve().parents[1]
SPEED = "runup_speed_yoshida_odd"
SHIPPED = sorted(d.name for d in trained_dir().iterdir() if (d / MANIFEST).is_file())
BINARIES = ("policy.safetensors", "vecnormalize.json")
FILES = BINARIES + ("config.yml", MANIFEST)


def size(name: str, agent: str = SPEED) -> int:
    """Bytes of a shipped agent's file (the messages quote sizes; retraining changes them)."""
    return (trained_dir() / agent / name).stat().st_size


def copy_agent(dest: Path, name: str = SPEED) -> Path:
    folder = dest / "copy"
    shutil.copytree(trained_dir() / name, folder)
    return folder


@pytest.fixture
def agent(tmp_path) -> Path:
    return copy_agent(tmp_path)


def load_error(folder: Path, **kwargs) -> str:
    """The message of the AgentError that loading ``folder`` raises (one line)."""
    with pytest.raises(AgentError) as info:
        load_policy(folder, **kwargs)
    msg = str(info.value)
    assert "\n" not in msg, msg
    return msg


def retag(folder: Path, name: str) -> None:
    """Record ``name``'s current fingerprint in the manifest, as a hand-edited manifest
    would: loading must then catch the bad file by reading it."""
    path = folder / MANIFEST
    data = yaml.safe_load(path.read_text())
    data["files"][name] = file_fingerprint(folder / name)
    path.write_text(yaml.safe_dump(data, sort_keys=False))


@pytest.mark.parametrize("missing", ["epsilon", "clip_obs", "norm_obs", "obs_rms", "format"])
def test_statistics_missing_a_field_are_one_error_naming_it(agent, missing):
    path = agent / "vecnormalize.json"
    data = json.loads(path.read_text())
    del data[missing]
    path.write_text(json.dumps(data))
    retag(agent, "vecnormalize.json")
    msg = load_error(agent)
    assert "vecnormalize.json" in msg and (missing in msg or "statistics file" in msg), msg


# --------------------------------------------------------------------------- shipped agents
def test_every_shipped_agent_has_a_current_manifest(tmp_path):
    assert len(SHIPPED) >= 4
    for name in SHIPPED:
        files = check_folder(trained_dir() / name)
        penv = files.run["policy_env"]
        assert files.manifest["env_id"] == files.run["env_id"]
        assert files.manifest["vecnormalize"] is True and files.norm_path is not None
        env = make_native_env(files.env_id, 1, {"scene": penv["scene"], "preset": "test",
                                                **observation_kwargs(penv)})
        assert files.observation_names == list(env.unwrapped.setup.obs_names)
        env.close()
        # writing the manifest again over the shipped files gives the shipped manifest
        folder = copy_agent(tmp_path / name, name)
        write_manifest(folder)
        assert yaml.safe_load((folder / MANIFEST).read_text()) == files.manifest


def test_the_wheel_ships_the_manifests():
    # every agent folder is a data package of its own (pyproject.toml); the package-data
    # patterns that apply to it must take each of an agent's files
    from fnmatch import fnmatch
    data = tomllib.loads((REPO / "pyproject.toml").read_text())
    globs = data["tool"]["setuptools"]["package-data"]["*"]
    for name in FILES:
        assert any(fnmatch(name, pattern) for pattern in globs), name


def test_an_intact_copy_loads_and_checks_the_observation_layout(agent):
    pol = load_policy(agent)
    assert pol.observation_names[0] == "rotor_speed"
    assert pol.vecnormalize.mean.shape == (6,)
    env = make_native_env("abb_gym/RunUpSpeed-v0", 1,
                          {"scene": "yoshida_odd", "preset": "test", "control_interval": 0.05})
    pol.reset(env, np.ones(1, bool))  # the recorded layout is the environment's
    pol = load_policy(agent)
    pol.observation_names[1] = "vibration_y"  # as if fitted on another layout
    with pytest.raises(ValueError, match=r"observation entry 1 .* 'vibration_x'"):
        pol.reset(env, np.ones(1, bool))
    env.close()


# --------------------------------------------------------------------------- missing files
@pytest.mark.parametrize("name, match", [
    ("vecnormalize.json", r"vecnormalize.json' is missing: the agent was trained on normalised"),
    ("config.yml", r"config.yml' does not exist"),
    (MANIFEST, r"has no agent.yml"),
    ("policy.safetensors", r"policy.safetensors' is missing"),
])
def test_a_missing_file_is_refused(agent, name, match):
    (agent / name).unlink()
    assert pytest.raises(AgentError, load_policy, agent).match(match)
    assert name in load_error(agent)


def test_a_manifest_without_normalisation_refuses_a_statistics_file(agent):
    data = yaml.safe_load((agent / MANIFEST).read_text())
    data["vecnormalize"] = False
    del data["files"]["vecnormalize.json"]
    (agent / MANIFEST).write_text(yaml.safe_dump(data))
    assert "does not belong to this agent" in load_error(agent)
    (agent / "vecnormalize.json").unlink()
    assert load_policy(agent).vecnormalize is None


# --------------------------------------------------------------------------- foreign files
def _foreign(name: str, donor: str) -> str:
    """What the manifest check says of ``donor``'s ``name`` in the SPEED agent's folder: its
    size differs, or (the same size) its fingerprint."""
    if size(name, donor) != size(name):
        return rf"{name}' has {size(name, donor)} bytes, agent.yml records {size(name)}"
    return rf"{name}' is not the file the agent was saved with"


@pytest.mark.parametrize("name, donor, match", [
    ("vecnormalize.json", "runup_speed_spannan_cfrp",
     _foreign("vecnormalize.json", "runup_speed_spannan_cfrp")),
    ("vecnormalize.json", "dwell_profile_yoshida_odd",
     _foreign("vecnormalize.json", "dwell_profile_yoshida_odd")),
    ("policy.safetensors", "dwell_profile_yoshida_odd",
     _foreign("policy.safetensors", "dwell_profile_yoshida_odd")),
    ("config.yml", "dwell_profile_yoshida_odd", r"records env id .*RunUpSpeed.*DwellProfile"),
    ("config.yml", "runup_speed_spannan_cfrp", r"records scene 'yoshida_odd', config.yml "
                                               r"'spannan_cfrp'"),
    (MANIFEST, "runup_speed_spannan_cfrp", r"records scene 'spannan_cfrp'"),
])
def test_another_agents_file_is_refused(agent, name, donor, match):
    shutil.copy(trained_dir() / donor / name, agent / name)
    assert pytest.raises(AgentError, load_policy, agent).match(match)


def test_another_agents_statistics_are_refused_by_evaluate(agent, tmp_path, capsys):
    shutil.copy(trained_dir() / "runup_speed_spannan_cfrp" / "vecnormalize.json",
                agent / "vecnormalize.json")
    rc = main(["evaluate", "--policy", f"ppo:{agent}", "--episodes", "1",
               "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc == 2 and re.search(_foreign("vecnormalize.json", "runup_speed_spannan_cfrp"), err)
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    (agent / "vecnormalize.json").unlink()
    assert main(["evaluate", "--policy", f"replay:ppo:{agent}", "--episodes", "1",
                 "--out", str(tmp_path / "out")]) == 2
    assert "vecnormalize.json' is missing" in capsys.readouterr().err


# --------------------------------------------------------------------------- corrupt files
def _truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def _dir(path: Path) -> None:
    path.unlink()
    path.mkdir()


CORRUPTIONS = {
    "truncated": _truncate,
    "empty": lambda p: p.write_bytes(b""),
    "random": lambda p: p.write_bytes(np.random.default_rng(0).bytes(p.stat().st_size)),
    "pickled dict": lambda p: p.write_bytes(pickle.dumps({"obs_rms": [0.0] * 6})),
    "json list": lambda p: p.write_text("[1, 2]"),
    "directory": _dir,
    "invalid yaml": lambda p: p.write_text("_run: {env_id: [\n"),
    "a list": lambda p: p.write_text("- 1\n- 2\n"),
}


@pytest.mark.parametrize("name, how, match", [
    ("vecnormalize.json", "truncated",
     rf"vecnormalize.json' has {size('vecnormalize.json') // 2} bytes, agent.yml records "
     rf"{size('vecnormalize.json')}: truncated"),
    ("vecnormalize.json", "empty", r"vecnormalize.json' is empty"),
    ("vecnormalize.json", "random", r"vecnormalize.json' is not the file the agent was saved"),
    ("vecnormalize.json", "pickled dict", r"vecnormalize.json' has \d+ bytes"),
    ("vecnormalize.json", "directory", r"vecnormalize.json' is a directory"),
    ("policy.safetensors", "truncated",
     rf"policy.safetensors' has {size('policy.safetensors') // 2} bytes"),
    ("policy.safetensors", "directory", r"policy.safetensors' is a directory"),
    ("config.yml", "invalid yaml", r"config.yml' is not valid YAML"),
    ("config.yml", "a list", r"config.yml' must hold a mapping of fields \(got list\)"),
    ("config.yml", "directory", r"config.yml' is a directory"),
    (MANIFEST, "invalid yaml", r"agent.yml' is not valid YAML"),
    (MANIFEST, "a list", r"agent.yml' must hold a mapping"),
    (MANIFEST, "empty", r"agent.yml.*'format' must be 2"),
])
def test_a_corrupt_file_is_one_line(agent, name, how, match):
    CORRUPTIONS[how](agent / name)
    msg = load_error(agent)
    assert pytest.raises(AgentError, load_policy, agent).match(match), msg


@pytest.mark.parametrize("name, how, match", [
    ("vecnormalize.json", "truncated", r"cannot be read as normalisation statistics"),
    ("vecnormalize.json", "random", r"cannot be read as normalisation statistics"),
    ("vecnormalize.json", "pickled dict", r"cannot be read as normalisation statistics"),
    ("vecnormalize.json", "json list", r"is not an abb-gym statistics file"),
    ("policy.safetensors", "truncated", r"policy.safetensors' cannot be read as a safetensors"),
    ("policy.safetensors", "random", r"policy.safetensors' cannot be read as a safetensors"),
    ("policy.safetensors", "pickled dict", r"policy.safetensors' cannot be read as a safet"),
])
def test_a_corrupt_file_behind_a_rewritten_manifest_is_one_line(agent, name, how, match):
    CORRUPTIONS[how](agent / name)
    retag(agent, name)
    assert pytest.raises(AgentError, load_policy, agent).match(match)
    load_error(agent)


def test_statistics_of_another_size_are_refused_when_read(agent):
    path = agent / "vecnormalize.json"
    data = json.loads(path.read_text())
    data["obs_rms"]["mean"], data["obs_rms"]["var"] = [0.0] * 8, [1.0] * 8
    path.write_text(json.dumps(data))
    retag(agent, "vecnormalize.json")
    assert "obs_rms.mean must be 6 numbers" in load_error(agent)


def test_write_manifest_refuses_corrupt_files(agent):
    CORRUPTIONS["pickled dict"](agent / "vecnormalize.json")
    with pytest.raises(AgentError, match="cannot be read as normalisation statistics"):
        write_manifest(agent)
    assert yaml.safe_load((agent / MANIFEST).read_text())["files"]["vecnormalize.json"][
        "bytes"] == size("vecnormalize.json")  # the old manifest is left as it was


def test_a_folder_without_a_manifest_says_what_writes_one(agent):
    (agent / MANIFEST).unlink()
    assert "`abb-gym train` and `abb-gym convert-agent` write it" in load_error(agent)
    write_manifest(agent)
    assert load_policy(agent).observation_names[0] == "rotor_speed"


# --------------------------------------------------------------------------- hypothesis
try:
    from hypothesis import HealthCheck, given, settings, strategies as st
except ImportError:  # pragma: no cover - the test extra installs hypothesis
    st = None


def _apply(path: Path, corruption: tuple) -> None:
    kind = corruption[0]
    if kind == "delete":
        path.unlink()
    elif kind == "empty":
        path.write_bytes(b"")
    elif kind == "truncate":
        data = path.read_bytes()
        path.write_bytes(data[: int(corruption[1] * len(data))])
    elif kind == "random":
        path.write_bytes(corruption[1])
    elif kind == "flip":
        data = bytearray(path.read_bytes())
        data[int(corruption[1] * len(data))] ^= corruption[2]
        path.write_bytes(bytes(data))
    elif kind == "directory":
        _dir(path)
    elif kind == "pickle":
        path.write_bytes(pickle.dumps(corruption[1]))
    elif kind == "yaml":
        path.write_text(corruption[1])
    elif kind == "foreign":
        shutil.copy(trained_dir() / corruption[1] / path.name, path)


if st is None:
    def test_any_corrupted_agent_folder_loads_or_fails_with_one_line():
        pytest.skip("needs hypothesis (the test extra)")
else:
    CORRUPTION = st.one_of(
        st.tuples(st.sampled_from(["delete", "empty", "directory"])),
        st.tuples(st.just("truncate"), st.floats(0.0, 0.999)),
        st.tuples(st.just("random"), st.binary(min_size=1, max_size=3000)),
        st.tuples(st.just("flip"), st.floats(0.0, 0.999), st.integers(1, 255)),
        st.tuples(st.just("pickle"), st.sampled_from([{}, {"obs_rms": None}, [1.0, 2.0], "x", None,
                                                      np.zeros(6)])),
        st.tuples(st.just("yaml"), st.sampled_from(["[1, 2]", "a: [", "_run: 3", "", "null",
                                                    "- x", "format: 2\nfiles: {}\n", "\x00",
                                                    "format: 1\nfiles: {}\n"])),
        st.tuples(st.just("foreign"), st.sampled_from([n for n in SHIPPED if n != SPEED])),
    )

    @settings(max_examples=300, deadline=None, database=None,
              suppress_health_check=[HealthCheck.too_slow])
    @given(name=st.sampled_from(FILES), corruption=CORRUPTION, rewrite_manifest=st.booleans())
    def test_any_corrupted_agent_folder_loads_or_fails_with_one_line(name, corruption,
                                                                     rewrite_manifest):
        with tempfile.TemporaryDirectory() as tmp:
            folder = copy_agent(Path(tmp))
            _apply(folder / name, corruption)
            target = folder / name
            retagged = (rewrite_manifest and name in BINARIES and target.is_file()
                        and target.stat().st_size > 0)
            if retagged:
                retag(folder, name)
            try:
                load_policy(folder)
            except AgentError as exc:
                msg = str(exc)
                assert "\n" not in msg
                assert any(f in msg for f in FILES), msg
                if name in BINARIES and not retagged:
                    assert name in msg, msg
                return
            # loading may succeed only where the change is invisible to every check: text the
            # checks do not read, or a binary whose new fingerprint the manifest was given
            assert corruption[0] not in ("delete", "empty", "directory"), corruption
            assert name not in BINARIES or retagged, (name, corruption)
