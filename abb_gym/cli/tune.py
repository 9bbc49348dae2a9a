"""``abb-gym tune-baselines``: tune the dwell and speed-reduction baselines of a scene on the
training distribution and store them in configs/baselines/<scene>.yaml (used afterwards by
every ``baseline:NAME`` policy)."""
from __future__ import annotations

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
    p.add_argument("--dry-run", action="store_true", help="print, do not write the YAML")
    add_executor_arguments(p)
    p.set_defaults(func=run)


def run(args) -> int:
    import yaml
    from ..baselines.tuner import SPACES, tune
    for name in ("candidates", "refine", "episodes"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name} must be >= 1 (got {getattr(args, name)})")
    result = tune(args.scene, tuple(args.family or SPACES), args.candidates, args.refine,
                  args.episodes, args.seed, args.preset, _executor(args),
                  write=not args.dry_run)
    print(yaml.safe_dump(result, sort_keys=False))
    return 0
