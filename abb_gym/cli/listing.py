"""``abb-gym list``: what there is to run, by the names the other commands take.

Scenes (``--scene``), environment presets (``--preset``), the registered environment ids
(``gym.make``, ``--env``; from the task registry, :mod:`abb_gym.envs.tasks`), the baselines
(``--policy baseline:NAME``) and the trained agents (``--policy ppo:NAME``), each with one
line about it.  User folders (``--configs DIR``, ``$ABB_GYM_CONFIGS``) come first on the
search path and are listed with the shipped files.  ``abb-gym list scenes`` lists one kind.
"""
from __future__ import annotations

import argparse

__all__ = ["register", "run", "KINDS"]

KINDS = ("scenes", "presets", "envs", "baselines", "agents")


def register(sub) -> None:
    p = sub.add_parser("list", help="list scenes, presets, environment ids, baselines and "
                                    "agents", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("kind", nargs="?", choices=KINDS, default=None,
                   help="list only this kind (default: all)")
    p.set_defaults(func=run)


def _first_line(text: object, limit: int = 90) -> str:
    line = " ".join(str(text or "").split())
    return line if len(line) <= limit else line[:limit - 3] + "..."


def _yaml_field(kind: str, name: str, key: str) -> str:
    """``key`` of the YAML file ``name`` of ``kind``, or a note saying why it is missing (a
    broken user file is listed, not fatal)."""
    from .. import resources
    from ..configuration import read_yaml
    try:
        return _first_line(read_yaml(resources.find(kind, name), kind).get(key, ""))
    except (ValueError, OSError) as exc:
        return f"(cannot be read: {_first_line(exc, 60)})"


def _scenes() -> list[tuple[str, str]]:
    from .. import resources
    return [(name, _yaml_field("scenes", name, "description"))
            for name in resources.names("scenes")]


def _presets() -> list[tuple[str, str]]:
    from .. import resources
    return [(name, _yaml_field("envs", name, "description")) for name in resources.names("envs")]


def _envs() -> list[tuple[str, str]]:
    from ..envs.tasks import TASKS
    return [(task.env_id, f"{task.summary} (scene {task.default_scene}, preset "
                          f"{task.default_preset})") for task in TASKS.values()]


def _baselines() -> list[tuple[str, str]]:
    from ..baselines.families import FAMILY_NAMES, build_family
    from ..baselines.loader import BASELINE_NAMES
    rows = []
    for name in BASELINE_NAMES:
        if name in FAMILY_NAMES:
            kind = "closed loop" if build_family(name).closed_loop else "open-loop profile"
            rows.append((f"baseline:{name}", f"{kind}, tuned per scene where a baselines file "
                                             f"has it"))
        else:
            rows.append((f"baseline:{name}", "oracle of the laundry task (SpinRedistribute)"))
    return rows


def _agents() -> list[tuple[str, str]]:
    from .. import resources
    rows = []
    for name in resources.names("agents"):
        folder = resources.find("agents", name)
        manifest = folder / "agent.yml"
        if manifest.is_file():
            from ..configuration import read_yaml
            try:
                data = read_yaml(manifest, "agent manifest")
                text = f"{data.get('algo', '?')} on {data.get('env_id', '?')}, scene " \
                       f"{data.get('scene', '?')}"
            except ValueError as exc:
                text = f"(manifest cannot be read: {_first_line(exc, 60)})"
        else:
            text = "saved before manifests (model.zip): abb-gym convert-agent makes it safe"
        rows.append((f"ppo:{name}", text))
    return rows


SECTIONS = {
    "scenes": ("scenes (--scene NAME; abb-gym new-scene NAME writes your own)", _scenes),
    "presets": ("environment presets (--preset NAME)", _presets),
    "envs": ("environment ids (gym.make(ID), --env ID)", _envs),
    "baselines": ("baselines (--policy NAME)", _baselines),
    "agents": ("trained agents (--policy NAME)", _agents),
}


def run(args) -> int:
    kinds = [args.kind] if args.kind else list(KINDS)
    for k, kind in enumerate(kinds):
        title, rows = SECTIONS[kind][0], SECTIONS[kind][1]()
        if k:
            print()
        print(f"{title}:")
        width = max((len(name) for name, _ in rows), default=0)
        for name, text in rows:
            print(f"  {name.ljust(width)}  {text}".rstrip())
        if not rows:
            print("  (none)")
    return 0
