"""Where abb-gym finds its configuration files and trained agents.

Two kinds of folder are searched, user folders first:

* **user folders**: the folders named by the environment variable ``ABB_GYM_CONFIGS``
  (several separated by ``os.pathsep``) and those added with :func:`add_user_folder` (the
  command line's ``--configs DIR``).  Each may hold any of the subfolders below; a file there
  adds a name or replaces a shipped one of the same name.
* **the shipped folder**: the repository's ``configs/`` and ``agents/trained/``, which the
  wheel installs as package data of ``abb_gym._shipped`` (found with ``importlib.resources``),
  so an installed package has every scene, preset, tuned baseline and agent a checkout has.

==============  =====================================  =====================================
kind            file                                   what
==============  =====================================  =====================================
``scenes``      ``scenes/<name>.yaml``                 machines (:func:`abb_gym.load_scene`)
``envs``        ``envs/<name>.yaml``                   environment presets
``baselines``   ``baselines/<scene>.yaml``             tuned baseline parameters
``ppo``         ``ppo/<name>.yml``                     PPO training configurations
``spring_rod``  ``spring_rod/<name>.yaml``             spring-and-rod balancer parameters
``agents``      ``agents/<name>/agent.yml`` (+ files)  trained agents (``ppo:NAME``)
==============  =====================================  =====================================

Nothing here writes: commands that produce files (``tune-baselines``, ``train``) write where
their ``--out`` says, never into the shipped folder.
"""
from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

__all__ = ["ENV_VAR", "TRUST_PICKLE_ENV", "KINDS", "shipped_folder", "user_folders", "add_user_folder",
           "search_path", "find", "names", "is_shipped", "is_agent_folder"]

ENV_VAR = "ABB_GYM_CONFIGS"
#: the environment variable that trusts pickled agent files (``--trust-pickle``; see
#: :mod:`abb_gym.rl.agent_files`): read by the agent loaders, in worker processes too
TRUST_PICKLE_ENV = "ABB_GYM_TRUST_PICKLE"
KINDS = ("scenes", "envs", "baselines", "ppo", "spring_rod", "agents")
SUFFIXES = {"scenes": (".yaml", ".yml"), "envs": (".yaml", ".yml"),
            "baselines": (".yaml", ".yml"), "ppo": (".yml", ".yaml"),
            "spring_rod": (".yaml", ".yml"), "agents": ("",)}
_EXTRA_USER_FOLDERS: list[Path] = []


def shipped_folder(kind: str) -> Path:
    """The shipped folder of ``kind`` (package data of a wheel, or the checkout's)."""
    _check_kind(kind)
    packaged = resources.files("abb_gym") / "_shipped"
    if packaged.is_dir():
        base = Path(str(packaged))
        return base / ("agents" if kind == "agents" else f"configs/{kind}")
    repo = Path(__file__).resolve().parents[1]
    return repo / ("agents/trained" if kind == "agents" else f"configs/{kind}")


def user_folders() -> list[Path]:
    """User folders in search order: ``$ABB_GYM_CONFIGS`` entries, then added ones."""
    env = [Path(p) for p in os.environ.get(ENV_VAR, "").split(os.pathsep) if p.strip()]
    return env + [p for p in _EXTRA_USER_FOLDERS if p not in env]


def add_user_folder(folder: str | os.PathLike) -> Path:
    """Search ``folder`` (before the shipped files) for the rest of this process."""
    text = os.fspath(folder) if isinstance(folder, os.PathLike) else folder
    if not isinstance(text, str) or not text.strip():  # Path("") is ".", the current folder
        raise ValueError(f"configuration folder must be a path (got {text!r:.80})")
    path = Path(text).expanduser()
    try:
        is_dir = path.is_dir()
    except (OSError, ValueError):  # a name the system refuses
        is_dir = False
    if not is_dir:
        raise ValueError(f"configuration folder {text[:200]!r} is not a directory")
    if path not in _EXTRA_USER_FOLDERS:
        _EXTRA_USER_FOLDERS.append(path)
    return path


def search_path(kind: str) -> list[Path]:
    """The folders searched for ``kind``, user folders first."""
    _check_kind(kind)
    return [u / kind for u in user_folders()] + [shipped_folder(kind)]


def find(kind: str, name: str) -> Path | None:
    """The first file (or, for agents, folder) named ``name`` of ``kind``, or None."""
    if not name or name != Path(name).name or name in (".", ".."):
        return None
    for folder in search_path(kind):
        for suffix in SUFFIXES[kind]:
            candidate = folder / f"{name}{suffix}"
            if kind == "agents":
                if is_agent_folder(candidate):
                    return candidate
            elif candidate.is_file():
                return candidate
    return None


def names(kind: str) -> list[str]:
    """Every name of ``kind`` on the search path, sorted."""
    found: set[str] = set()
    for folder in search_path(kind):
        if not folder.is_dir():
            continue
        if kind == "agents":
            found.update(p.name for p in folder.iterdir() if is_agent_folder(p))
        else:
            found.update(p.stem for p in folder.iterdir()
                         if p.is_file() and p.suffix in SUFFIXES[kind])
    return sorted(found)


def is_agent_folder(folder: Path) -> bool:
    """True if ``folder`` holds an agent: its manifest (``agent.yml``), or the ``model.zip``
    of a folder saved before manifests (:mod:`abb_gym.rl.agent_files`)."""
    return (folder / "agent.yml").is_file() or (folder / "model.zip").is_file()


def is_shipped(path: str | os.PathLike) -> bool:
    """True if ``path`` lies in a shipped folder (which must never be written)."""
    p = Path(path).resolve()
    for kind in KINDS:
        root = shipped_folder(kind).resolve()
        if p == root or root in p.parents:
            return True
    return False


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS} (got {kind!r})")
