"""Packaging: the wheel carries everything a checkout has.

``test_wheel_installed_outside_the_checkout`` builds the wheel, installs it in a fresh virtual
environment in a temporary folder (no access to the checkout), and from there makes every
environment id, evaluates a shipped agent and a tuned baseline with ``abb-gym evaluate``, and
checks that the tuned parameters were used.  It takes a few minutes (installs and a cold numba
compile), so it runs with ``--runwheel`` (``make test`` and CI pass it).
"""
from __future__ import annotations

import json
import re
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]


def _declared_packages() -> list[str]:
    import tomllib
    data = tomllib.loads((REPO / "pyproject.toml").read_text())
    return data["tool"]["setuptools"]["packages"]


def test_every_subpackage_is_declared_in_pyproject():
    on_disk = sorted(".".join(p.parent.relative_to(REPO).parts)
                     for p in (REPO / "abb_gym").rglob("__init__.py"))
    declared = _declared_packages()
    assert set(on_disk) <= set(declared), f"add to pyproject packages: {set(on_disk) - set(declared)}"
    data = _declared_packages()
    assert "abb_gym._shipped.configs" in data and "abb_gym._shipped.agents" in data


def test_every_shipped_data_folder_is_a_declared_package():
    # setuptools installs a file only as data of a declared package, and warns ("Package would
    # be ignored") for every folder of data that is not one: each folder under configs/ and
    # agents/trained/ that holds files is declared, with the files it holds
    import tomllib
    setuptools = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    declared = set(setuptools["packages"])
    roots = {"abb_gym._shipped.configs": REPO / "configs",
             "abb_gym._shipped.agents": REPO / "agents" / "trained"}
    patterns = setuptools["package-data"]["*"]
    for package, root in roots.items():
        assert setuptools["package-dir"][package] == str(root.relative_to(REPO))
        for folder in [root, *(p for p in root.rglob("*") if p.is_dir())]:
            files = [f for f in folder.iterdir() if f.is_file()]
            if not files:
                continue
            name = ".".join([package, *folder.relative_to(root).parts])
            assert name in declared, f"add {name} to pyproject packages"
            shipped = [f.name for f in files if any(f.match(pat) for pat in patterns)]
            assert shipped, f"{folder}: no file matches the package-data patterns {patterns}"


def test_resources_find_the_checkouts_files_and_user_folders_come_first(tmp_path, monkeypatch):
    from abb_gym import load_scene, resources
    assert resources.shipped_folder("scenes") == REPO / "configs" / "scenes"
    assert "yoshida_odd" in resources.names("scenes")
    assert resources.find("agents", "runup_speed_yoshida_odd") == \
        REPO / "agents" / "trained" / "runup_speed_yoshida_odd"
    user = tmp_path / "mine"
    (user / "scenes").mkdir(parents=True)
    text = (REPO / "configs" / "scenes" / "yoshida_odd.yaml").read_text()
    (user / "scenes" / "my_drive.yaml").write_text(text.replace("name: yoshida_odd",
                                                                "name: my_drive"))
    monkeypatch.setenv(resources.ENV_VAR, str(user))
    assert "my_drive" in resources.names("scenes") and "yoshida_odd" in resources.names("scenes")
    assert load_scene("my_drive").name == "my_drive"
    assert resources.find("scenes", "../scenes/x") is None and resources.find("scenes", "") is None


def _run(cmd, cwd, env, timeout=900):
    res = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert res.returncode == 0, f"{cmd} failed:\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}"
    return res.stdout


@pytest.mark.wheel
def test_wheel_installed_outside_the_checkout(tmp_path):
    # as `make wheel`: compile the kernels into abb_gym/_kernels first, so the wheel ships them
    _run([sys.executable, "-m", "abb_gym.cli", "build-kernels", "--quiet"], cwd=REPO,
         env=os.environ, timeout=1800)
    dist = tmp_path / "dist"
    # -v shows the build backend's output: a clean build prints no setuptools warning (the
    # licence as a TOML table and "Package would be ignored" for each data folder did)
    log = _run([sys.executable, "-m", "pip", "wheel", str(REPO), "--no-deps", "-v", "-w",
                str(dist)], cwd=tmp_path, env=os.environ)
    for warning in ("Warning:", "Package would be ignored", "deprecated"):
        assert warning not in log, f"the wheel build warns ({warning!r}):\n{log[-3000:]}"
    # the metadata a package index shows
    import zipfile
    with zipfile.ZipFile(next(dist.glob("abb_gym-*.whl"))) as whl:
        meta = next(whl.read(n).decode() for n in whl.namelist() if n.endswith("/METADATA"))
        assert "License-Expression: MIT" in meta and "Author: The abb-gym contributors" in meta
        assert any(n.endswith("licenses/LICENSE") for n in whl.namelist())
        assert "Classifier: Topic :: Scientific/Engineering :: Physics" in meta
    wheel = next(dist.glob("abb_gym-*.whl"))
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", str(venv)], cwd=tmp_path, env=os.environ)
    py = venv / "bin" / "python"
    # NUMBA_CACHE_DIR would send the caches elsewhere: the installed package's must serve
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "VIRTUAL_ENV", "NUMBA_CACHE_DIR")}
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    _run([str(py), "-m", "pip", "install", "-q", "-c", str(REPO / "constraints.txt"),
          f"{wheel}[train]"], cwd=tmp_path, env=env, timeout=1500)
    work = tmp_path / "elsewhere"
    work.mkdir()
    where = "import abb_gym._kernels as k, os; print(os.path.dirname(k.__file__))"
    site = _run([str(py), "-c", where], cwd=work, env=env).strip().splitlines()[-1]
    def cache_files():
        # name, size and time of every cache file: a recompiled kernel rewrites its index and
        # its .nbc (under the same name when an index was stale)
        return {p.name: (p.stat().st_size, p.stat().st_mtime_ns)
                for p in Path(site).iterdir() if p.suffix in (".nbi", ".nbc")}
    shipped = cache_files()
    assert any(n.endswith(".nbc") for n in shipped), \
        f"the wheel ships no compiled kernels in {site}"
    script = textwrap.dedent("""
        import json, gymnasium as gym, numpy as np, abb_gym
        from abb_gym import resources
        assert "site-packages" in str(resources.shipped_folder("scenes")), resources.shipped_folder("scenes")
        out = {"scenes": abb_gym.list_scenes(), "agents": resources.names("agents"), "ids": [],
               "kernels": {},
               "preset_baselines": sorted(str(p.relative_to(resources.shipped_folder("baselines").parent))
                                          for p in resources.shipped_folder("baselines").parent.glob("*/baselines/*.yaml"))}
        # the tasks on the default scene, whose kernels the wheel ships (abb_gym.kernels)
        for env_id in [t for t in abb_gym.envs.ENV_IDS
                       if abb_gym.envs.tasks.get(t).default_scene == "yoshida_odd"]:
            env = gym.make(env_id)
            env.reset(seed=0)
            env.step(env.action_space.sample())
            out["ids"].append(env_id)
            out["kernels"][env_id] = env.unwrapped._bufs.kernel
        print(json.dumps(out))
    """)
    made = json.loads(_run([str(py), "-c", script], cwd=work, env=env).strip().splitlines()[-1])
    assert set(made["scenes"]) == {p.stem for p in (REPO / "configs" / "scenes").glob("*.yaml")}
    assert set(made["agents"]) == {p.name for p in (REPO / "agents" / "trained").iterdir()
                                   if (p / "agent.yml").exists()}
    from abb_gym.envs import ENV_IDS, tasks
    assert made["ids"] == [t for t in ENV_IDS if tasks.get(t).default_scene == "yoshida_odd"]
    assert len(made["ids"]) == 3
    # a fresh process finds the one-lane specialised kernels the wheel ships for the default
    # scene's speed and torque actions in the on-disk cache (abb_gym.kernels); DwellProfile
    # runs the speed action's kernel (the same effects; the action kind is a run-time value)
    assert made["kernels"] == dict.fromkeys(made["ids"], "specialised"), made["kernels"]
    # baselines tuned on other presets (configs/<preset>/baselines: agents/evaluate.py's)
    assert made["preset_baselines"] == sorted(
        str(p.relative_to(REPO / "configs")) for p in (REPO / "configs").glob("*/baselines/*.yaml"))
    assert made["preset_baselines"]
    _run([str(venv / "bin" / "abb-gym"), "evaluate", "--env", "abb_gym/RunUpSpeed-v0",
          "--scene", "yoshida_odd", "--policy", "ppo:runup_speed_yoshida_odd",
          "--policy", "baseline:speed_dwell", "--episodes", "16", "--seed", "0",
          "--env-kwargs", "reward={residual: 2.0}", "--workers", "1",
          "--out", str(work / "eval")], cwd=work, env=env)
    data = json.loads((work / "eval" / "evaluation.json").read_text())
    names = [p["policy"] for p in data["policies"]]
    assert names[0] == "ppo:runup_speed_yoshida_odd", names
    # the installed agent scores as its pickled original did, to the digit (docs/agent-files.md)
    table = (REPO / "docs" / "agent-files.md").read_text()
    before = float(re.search(r"^\| runup_speed_yoshida_odd \| (-?\d+\.\d{6}) \|", table,
                             re.M).group(1))
    returns = [e["return"] for e in data["policies"][0]["episodes"]]
    assert round(sum(returns) / len(returns), 6) == pytest.approx(before, abs=1.5e-6)
    tuned = yaml.safe_load((REPO / "configs" / "baselines" / "yoshida_odd.yaml").read_text())
    want = tuned["families"]["speed_dwell"]["params"]
    assert "(tuned)" in names[1], names
    assert data["policies"][1]["params"] == pytest.approx(want)
    # nothing was compiled: every kernel these calls used came from the wheel
    assert cache_files() == shipped


def test_compiled_modules_have_distinct_file_names():
    # numba names a cache file after the module's file name, the function and its line, and
    # abb_gym/_kernels is one flat folder (abb_gym/_jit_cache.py): two compiled modules of the
    # same file name could overwrite each other's caches
    from abb_gym import _jit_cache
    compiled = [p for p in (REPO / "abb_gym").rglob("*.py")
                if _jit_cache._IMPORTS_NUMBA.search(p.read_bytes())]
    names = [p.name for p in compiled]
    assert len(compiled) > 5 and len(set(names)) == len(names), sorted(names)


def test_compiled_functions_are_cached_in_the_package_stamped_by_content():
    # numba chose abb-gym's locator for a real kernel: its caches go to abb_gym/_kernels (so
    # the wheel ships them), stamped with the content of every compiled module rather than
    # the file's time (an installed wheel gives the sources new times; the wheel test checks
    # that nothing recompiles there)
    import os
    from abb_gym import _jit_cache
    from abb_gym.physics import batch
    if os.environ.get("NUMBA_CACHE_DIR") or not os.access(_jit_cache.KERNELS, os.W_OK):
        pytest.skip("NUMBA_CACHE_DIR set or package folder not writable")
    cache = batch.advance_block._cache
    assert cache._cache_path == str(_jit_cache.KERNELS)
    assert cache._impl.locator.get_source_stamp() == _jit_cache.sources_fingerprint()
