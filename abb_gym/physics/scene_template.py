"""A commented scene file for a new machine: ``abb-gym new-scene NAME``.

The template is generated from the declarations on :class:`~abb_gym.physics.scene.Scene`
(the YAML path, unit, allowed range and meaning of every field), so it lists every field the
loader accepts and cannot drift from it.  Its values are those of a base scene (default
``yoshida_odd``), so the file loads as a valid scene as written; an engineer then replaces the
values by their machine's.
"""
from __future__ import annotations

import dataclasses
import re
from typing import Any

from ..configuration import bounds_text
from .scene import _SPECS, Scene, load_scene

__all__ = ["scene_template", "check_scene_name"]

#: a scene name is also its file name: letters, digits, ``_``, ``-`` and ``.``, no path
NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,99}$")
#: written at the top level, before the sections
TOP_LEVEL = ("name", "description", "source")
COMMENT_COLUMN = 36


def check_scene_name(name: Any) -> str:
    """``name`` if it can name a scene and its file, else a ValueError saying what can."""
    if not isinstance(name, str) or not NAME_PATTERN.match(name) or name.endswith(
            (".yaml", ".yml")):
        raise ValueError(f"scene name must be letters, digits, '_', '-' or '.', starting with "
                         f"a letter or digit, at most 100 characters and without .yaml "
                         f"(got {name!r:.80})")
    return name


def _scalar(value: Any) -> str:
    """One YAML scalar or flow list, as the loader reads it back."""
    import yaml
    if isinstance(value, tuple):
        value = list(value)
        if value and all(v == value[0] for v in value):
            value = value[0]  # one number for every ball
    if isinstance(value, float):
        return _float(value)
    if isinstance(value, list) and all(isinstance(v, float) for v in value):
        return "[" + ", ".join(_float(v) for v in value) + "]"
    return yaml.safe_dump(value, default_flow_style=True, width=10 ** 6).strip() \
        .removesuffix("\n...").strip()


def _float(value: float) -> str:
    """The shortest text that reads back as ``value``, with a dot in the mantissa (YAML 1.1
    reads ``1e-07`` as text)."""
    text = repr(value)
    mantissa, e, exponent = text.partition("e")
    if e and "." not in mantissa:
        text = f"{mantissa}.0e{exponent}"
    return text


def _comment(name: str) -> str:
    spec = _SPECS[name]
    unit = "" if spec.unit in ("", "-") else f"[{spec.unit}] "
    rng = bounds_text(spec).replace(f" [{spec.unit}]", "")
    each = ", each ball (one value or a list of one per ball)" if spec.per_ball else ""
    return f"# {unit}{rng}{each}: {spec.doc} ({name})"


def scene_template(name: str, base: str | Scene = "yoshida_odd") -> str:
    """The text of a scene file ``name`` with every field of :class:`Scene` under its YAML
    section, each commented with its unit, allowed range, meaning and flat name, and the
    values of ``base`` (a scene name, path or Scene)."""
    check_scene_name(name)
    scene = load_scene(base) if not isinstance(base, Scene) else base
    values = {f.name: getattr(scene, f.name) for f in dataclasses.fields(scene)}
    values.update(name=name, description=f"a new machine, from the scene {scene.name!r}",
                  source=f"abb-gym new-scene {name} --from {scene.name}: replace every "
                         f"value by your machine's")
    lines = [
        f"# Scene {name!r}: every field of a scene, with the values of {scene.name!r}.",
        "# Replace the values by your machine's; each comment gives the field's unit, its "
        "allowed range,",
        "# what it is and its flat name (accepted by load_scene(..., FIELD=VALUE), "
        "--set FIELD=VALUE and",
        "# the stability-map axes, as is the YAML path SECTION.KEY).  SI units, angles in "
        "radians.",
        "# support.stiffness / support.damping (one value) may replace the _x and _y pairs.",
        "# Check it: abb-gym simulate --scene THIS_FILE.yaml",
    ]
    for key in TOP_LEVEL:
        lines.append(f"{key}: {_scalar(values[key])}")
    sections: dict[str, list[str]] = {}  # in the order of their first declared field
    for field, spec in _SPECS.items():
        if field in TOP_LEVEL:
            continue
        head, _, key = (spec.yaml or field).partition(".")
        if not key:  # a field declared without a section: at the top level
            lines.append(_line(field, head, values[field], ""))
            continue
        sections.setdefault(head, []).append(_line(field, key, values[field], "  "))
    for head, body in sections.items():
        lines += [f"{head}:", *body]
    return "\n".join(lines) + "\n"


def _line(field: str, key: str, value: Any, indent: str) -> str:
    text = f"{indent}{key}: {_scalar(value)}"
    return f"{text.ljust(COMMENT_COLUMN)} {_comment(field)}"
