"""``abb-gym tune-baselines``: tune the baseline families of a scene on the training
distribution and write them to ``--out`` (default ``baselines/<scene>.yaml`` in the current
folder).  ``baseline:NAME`` policies use a ``baselines/<scene>.yaml`` of a configuration folder
(``--configs DIR`` or ``$ABB_GYM_CONFIGS``) before the shipped one, so::

    abb-gym tune-baselines --scene yoshida_odd --out my_configs/baselines
    abb-gym --configs my_configs evaluate --scene yoshida_odd --policy baseline:speed_dwell

The file is named after the scene's ``name`` (the name ``baseline:NAME`` looks it up by),
also when ``--scene`` is a YAML path.  An existing file is replaced only with ``--force``.

The objective is the environment's return, or, with ``--spec``, an engineer's specification:
the least mean residual vibration among the profiles that meet every requirement
(:mod:`abb_gym.baselines.specification`; ranked feasibility first), e.g.::

    abb-gym tune-baselines --scene yoshida_odd --family ramp --family speed_dwell \\
        --spec "peak_whirl<=20,run_up<=5" --out my_configs/baselines
"""
from __future__ import annotations

import argparse

from ..execution.cli import add_executor_arguments
from ..envs import tasks
from .evaluate import _executor


# the baseline families by name: abb_gym.baselines.families.FAMILY_NAMES, spelled out here
# because the command line is built before numba loads (tests/test_registry.py holds the two
# together)
FAMILIES = ("ramp", "speed_dwell", "accel_dwell", "decel_dwell", "speed_reduction", "knots",
            "retry", "resonance_dwell", "retry_at_spin", "redistribute_low")


def register(sub) -> None:
    p = sub.add_parser("tune-baselines", help="tune the baseline families of a scene (CMA-ES)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", default="yoshida_odd", help="scene name or YAML path")
    p.add_argument("--family", action="append", choices=FAMILIES,
                   help="families to tune (repeatable; default all)")
    p.add_argument("--env", default=tasks.DEFAULT_ENV_ID, choices=tasks.task_ids(open_loop=True),
                   help="environment whose return is the objective")
    p.add_argument("--spec", default=None, metavar="REQUIREMENTS",
                   help="minimise the mean residual vibration under requirements instead of "
                        "maximising the return, e.g. 'peak_whirl<=20,run_up<=5' (metrics: "
                        "peak_whirl [W_r/e], run_up [s], residual [W_r/e], at_speed and "
                        "balanced [share]; at_speed>=1 unless given)")
    p.add_argument("--budget", type=int, default=240,
                   help="candidates per family (CMA-ES evaluations)")
    p.add_argument("--popsize", type=int, default=None,
                   help="CMA-ES population (default: cma's 4 + 3 ln d)")
    p.add_argument("--restarts", type=int, default=0,
                   help="further CMA-ES searches per family, each from a random point with a "
                        "doubled population (IPOP), each of --budget candidates")
    p.add_argument("--from-tuned", action="store_true",
                   help="the first search refines the tuned parameters that baseline:NAME "
                        "uses now (so the result is never worse on these episodes)")
    p.add_argument("--episodes", type=int, default=24, help="training episodes per candidate")
    p.add_argument("--seed", type=int, default=20_000, help="seed of the episodes and of CMA-ES")
    p.add_argument("--preset", default="train", help="environment preset of the objective")
    p.add_argument("--env-kwargs", nargs="+", default=None, metavar="KEY=VALUE",
                   help="environment keywords of the objective, e.g. 'reward={residual: 6}' "
                        "(the reward an agent was trained with)")
    p.add_argument("--out", default=None,
                   help="file or folder to write (default: baselines/<scene>.yaml here)")
    p.add_argument("--force", action="store_true", help="replace an existing --out file")
    p.add_argument("--dry-run", action="store_true", help="print, do not write the YAML")
    add_executor_arguments(p)
    p.set_defaults(func=run)


def _check_episode_memory(args, env_kwargs) -> None:
    """The episodes of one candidate run as the sub-environments of one vector environment
    with their histories: ``--episodes 1e12`` would fill the memory (or hang building the
    episode list) long before the first candidate; refused here, naming the option."""
    from ..envs.buffers import check_memory
    from ..evaluation.evaluate import make_env
    env = make_env(args.env, args.scene, args.preset, 1, **env_kwargs)
    try:
        check_memory(env.unwrapped.setup, args.episodes, args.episodes)
    except ValueError as exc:
        raise ValueError(f"--episodes {args.episodes}: the episodes of one candidate run as "
                         f"one vector environment; {exc}") from None
    finally:
        env.close()


def run(args) -> int:
    import yaml
    from ..baselines.tuner import tune
    from ..physics.scene import load_scene
    for name in ("budget", "episodes"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name} must be >= 1 (got {getattr(args, name)})")
    if args.popsize is not None and not 2 <= args.popsize <= args.budget:
        # a population beyond the budget is never evaluated (and 1e12 would not fit)
        raise ValueError(f"--popsize must be >= 2 and <= --budget = {args.budget} (got "
                         f"{args.popsize})")
    if args.seed < 0:
        raise ValueError(f"--seed must be >= 0 (got {args.seed})")
    if not 0 <= args.restarts <= 100:
        raise ValueError(f"--restarts must be from 0 to 100 (got {args.restarts})")
    spec = None
    if args.spec is not None:
        from ..baselines.specification import Specification
        spec = Specification.parse(args.spec)
    from ..baselines.tuner import check_tuned_path, tuned_path
    from ..configuration import parse_assignments
    from ..evaluation.evaluate import check_inputs
    from . import check_env_kwargs
    scene_name = load_scene(args.scene).name  # the tuned file's name (tuner.tuned_path)
    env_kwargs = check_env_kwargs(parse_assignments(args.env_kwargs, "--env-kwargs"),
                                  "--env-kwargs")
    # the environment every task makes, once here (preset, keywords, stiffness)
    check_inputs(args.env, args.scene, args.preset, args.seed, **env_kwargs)
    _check_episode_memory(args, env_kwargs)
    executor = _executor(args)  # its options checked before any file or folder is made
    if args.out is not None and not args.out.strip():  # not read as "no --out"
        raise ValueError(f"--out must be a file or folder path (got {args.out!r})")
    out = None if args.dry_run else (f"baselines/{scene_name}.yaml" if args.out is None
                                     else args.out)
    if out is not None:
        from .outputs import output_file
        target = tuned_path(out, scene_name)
        check_tuned_path(target, args.force)
        output_file(target, "--out")
    families = tuple(args.family or FAMILIES)
    start = _tuned_starts(scene_name, families) if args.from_tuned else None
    result = tune(args.scene, families, args.budget, args.episodes,
                  args.seed, args.preset, executor, out=out, force=args.force,
                  popsize=args.popsize, env_id=args.env, env_kwargs=env_kwargs,
                  restarts=args.restarts, start=start, spec=spec)
    print(yaml.safe_dump(result, sort_keys=False))
    if spec is not None:
        for fam, row in result["families"].items():
            state = "meets" if row["feasible"] else "does NOT meet"
            print(f"{fam}: {state} {spec} (mean residual {row['mean_residual_vibration']:g} "
                  f"W_r/e, peak {row['mean_peak_whirl']:g} W_r/e, run-up "
                  f"{row['mean_run_up_time']:g} s)")
    return 0


def _tuned_starts(scene: str, families: tuple[str, ...]) -> dict:
    """``--from-tuned``: each family's parameters as ``baseline:NAME`` finds them now."""
    from ..baselines.baseline_policy import tuned_file, tuned_parameters
    starts = {fam: tuned_parameters(scene, fam) for fam in families}
    missing = [fam for fam, params in starts.items() if params is None]
    if missing:
        where = tuned_file(scene) or "no baselines file on the configuration path"
        raise ValueError(f"--from-tuned: no tuned parameters of {', '.join(missing)} for "
                         f"{scene} ({where})")
    return starts
