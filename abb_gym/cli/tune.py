"""``abb-gym tune-baselines``: tune the baseline families of a scene on the training
distribution and write them to ``--out`` (default ``baselines/<scene>.yaml`` in the current
folder).  ``baseline:NAME`` policies use a ``baselines/<scene>.yaml`` of a configuration folder
(``--configs DIR`` or ``$ABB_GYM_CONFIGS``) before the shipped one, so::

    abb-gym tune-baselines --scene yoshida_odd --out my_configs/baselines
    abb-gym evaluate --configs my_configs --scene yoshida_odd --policy baseline:speed_dwell

An existing file is replaced only with ``--force``.
"""
from __future__ import annotations

from pathlib import Path

from ..execution.cli import add_executor_arguments
from .evaluate import _executor


def register(sub) -> None:
    from ..baselines.tuner import SPACES
    p = sub.add_parser("tune-baselines", help="tune the baseline families of a scene",
                       description=__doc__)
    p.add_argument("--scene", default="yoshida_odd")
    p.add_argument("--family", action="append", choices=sorted(SPACES),
                   help="families to tune (repeatable; default all)")
    p.add_argument("--candidates", type=int, default=24, help="first-stage samples per family")
    p.add_argument("--refine", type=int, default=16, help="second-stage samples per family")
    p.add_argument("--episodes", type=int, default=24, help="training episodes per candidate")
    p.add_argument("--seed", type=int, default=20_000)
    p.add_argument("--preset", default="train")
    p.add_argument("--out", default=None,
                   help="file or folder to write (default: baselines/<scene>.yaml here)")
    p.add_argument("--force", action="store_true", help="replace an existing --out file")
    p.add_argument("--dry-run", action="store_true", help="print, do not write the YAML")
    add_executor_arguments(p)
    p.set_defaults(func=run)


def run(args) -> int:
    import yaml
    from ..baselines.tuner import SPACES, tune
    for name in ("candidates", "refine", "episodes"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name} must be >= 1 (got {getattr(args, name)})")
    out = None if args.dry_run else (args.out or f"baselines/{args.scene}.yaml")
    if out is not None and Path(out).exists() and not Path(out).is_dir() and not args.force:
        raise ValueError(f"{out!r} exists; pass --force to replace it")
    result = tune(args.scene, tuple(args.family or SPACES), args.candidates, args.refine,
                  args.episodes, args.seed, args.preset, _executor(args), out=out,
                  force=args.force)
    print(yaml.safe_dump(result, sort_keys=False))
    return 0
