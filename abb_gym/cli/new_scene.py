"""``abb-gym new-scene NAME``: write a commented scene file for your own machine.

Every field of a scene under its YAML section, each with its unit, allowed range, meaning
and flat name (generated from the declarations: :mod:`abb_gym.physics.scene_template`), and
the values of ``--from`` (default ``yoshida_odd``), so the file loads as written::

    abb-gym new-scene my_drive --from yoshida_odd     # writes scenes/my_drive.yaml
    abb-gym simulate --scene scenes/my_drive.yaml      # or: abb-gym --configs . simulate --scene my_drive

The file goes to ``scenes/NAME.yaml`` in the current folder (the layout ``--configs .``
searches) unless ``--out`` names a file or a folder; an existing file is replaced only with
``--force``.
"""
from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["register", "run"]


def register(sub) -> None:
    p = sub.add_parser("new-scene", help="write a commented scene file for your own machine",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("name", help="the scene's name (also its file name)")
    p.add_argument("--from", dest="base", default="yoshida_odd",
                   help="scene whose values the file starts from (name or YAML path)")
    p.add_argument("--out", default=None,
                   help="file or folder to write (default: scenes/NAME.yaml here)")
    p.add_argument("--force", action="store_true", help="replace an existing file")
    p.set_defaults(func=run)


def run(args) -> int:
    from .._files import write_text
    from ..physics.scene import load_scene
    from ..physics.scene_template import check_scene_name, scene_template
    from .outputs import output_file
    name = check_scene_name(args.name)
    if args.out is not None and not args.out.strip():  # not read as "here"
        raise ValueError(f"--out must be a file or folder path (got {args.out!r})")
    text = scene_template(name, args.base)
    out = Path("scenes") / f"{name}.yaml" if args.out is None else Path(args.out)
    if args.out is not None and (out.is_dir() or args.out.endswith(("/", "\\"))):
        out = out / f"{name}.yaml"
    if out.exists() and not args.force:
        raise ValueError(f"--out {str(out)!r} exists; use --force to replace it")
    output_file(out, "--out")
    write_text(out, text)
    load_scene(out)  # what was written loads (a failure here is a bug: a traceback-free line)
    print(f"wrote {out}: every field of a scene, with the values of {args.base!r} (edit them; "
          f"check with: abb-gym simulate --scene {out})")
    return 0
