"""``abb-gym convert-agent``: rewrite a pickled agent you trust in the safe format.

    abb-gym convert-agent runs/old_run                      # in place (pickles kept beside)
    abb-gym convert-agent runs/old_run --remove-pickles     # ... and the pickles removed
    abb-gym convert-agent logs/ppo/abb_gym-RunUpSpeed-v0_1 --out agents/zoo_run
    abb-gym convert-agent model.zip --env abb_gym/RunUpSpeed-v0 \\
        --env-kwargs scene=yoshida_odd control_interval=0.05 --out agents/mine

The source is an abb-gym agent folder of the first format (model.zip, vecnormalize.pkl), an
rl_zoo3 run folder, or a plain SB3 model.zip (with the vecnormalize.pkl beside it, if any; it
records no environment, so --env and --env-kwargs say which one it was trained on).  Reading
it unpickles it, which runs any code it contains: running this command on it states that you
trust it (a one-line warning names the files).  The new folder holds data only
(policy.safetensors, vecnormalize.json, optimizer.safetensors, config.yml, agent.yml) and
loads anywhere without --trust-pickle.
"""
from __future__ import annotations

import argparse


def register(sub) -> None:
    p = sub.add_parser("convert-agent", help="rewrite a pickled agent you trust in the safe "
                                             "format (safetensors + JSON)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("source", help="agent folder (model.zip), rl_zoo3 run folder or model.zip")
    p.add_argument("--out", default=None,
                   help="the new agent folder (default: the source folder itself, for an "
                        "abb-gym folder)")
    p.add_argument("--env", default=None, help="environment id of a plain SB3 model.zip")
    p.add_argument("--env-kwargs", nargs="+", default=None, metavar="KEY=VALUE",
                   help="environment keywords a plain SB3 model was trained with, e.g. "
                        "scene=yoshida_odd control_interval=0.05")
    p.add_argument("--algo", default=None, choices=["ppo", "ppo_lstm", "sac", "tqc"],
                   help="algorithm of a plain SB3 model.zip (default ppo)")
    p.add_argument("--remove-pickles", action="store_true",
                   help="delete model.zip and vecnormalize.pkl once converted in place")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..configuration import parse_assignments
    from ..rl.legacy import convert_agent, find_pickled
    from .outputs import output_folder
    if not args.source.strip():
        raise ValueError(f"source must be an agent folder or a model.zip (got {args.source!r})")
    if args.out is not None and not args.out.strip():  # not read as "in place" or as "here"
        raise ValueError(f"--out must be a folder path (got {args.out!r})")
    agent = find_pickled(args.source)
    if agent is None:
        raise ValueError(f"{args.source!r} is not a pickled agent (an abb-gym folder with "
                         f"model.zip, an rl_zoo3 run folder, or an SB3 model.zip)")
    env_kwargs = parse_assignments(args.env_kwargs, "--env-kwargs")
    if agent.kind == "sb3" and args.env is None:
        raise ValueError("--env: a plain SB3 model.zip records no environment id; name it")
    if agent.kind != "sb3" and (args.env is not None or args.env_kwargs or args.algo):
        raise ValueError(f"--env, --env-kwargs and --algo describe a plain SB3 model.zip; "
                         f"{args.source!r} is an {agent.kind} agent, which records them")
    if args.out is not None:
        out = output_folder(args.out, "--out")
    elif agent.kind == "abb-gym":
        out = output_folder(agent.source, "source")
    else:
        raise ValueError(f"--out: {args.source!r} is an {agent.kind} model, converted into a "
                         f"new agent folder; name it")
    if args.remove_pickles and out.resolve() != agent.source.resolve():
        raise ValueError("--remove-pickles removes the pickles of a folder converted in place "
                         "(without --out)")
    folder = convert_agent(agent.source, out, trust=True, env_id=args.env,
                           env_kwargs=env_kwargs if agent.kind == "sb3" else None,
                           algo=args.algo, remove_pickles=args.remove_pickles)
    print(f"wrote the safe agent folder {folder} (policy.safetensors, agent.yml, ...); load "
          f"it as ppo:{folder}")
    return 0
