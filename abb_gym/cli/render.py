"""``abb-gym render``: one episode of a policy as a video (GIF or MP4).

    abb-gym render --policy baseline:knots --out out/render/knots.gif
    abb-gym render --env abb_gym/RunUpSpeed-v0 --policy ppo:runup_speed_yoshida_odd \\
        --episode 3 --out out/render/speed.mp4 --fps 30

Episode K with --seed S is the machine of test episode K of ``abb-gym evaluate --seed S``.
Policies: ``baseline:NAME``, ``ppo:NAME|PATH``, ``replay:SPEC`` (as for evaluate).  A frame
shows the machine along the shaft (orbit, race, balls, imbalance angle) and the speed and
whirl so far; by default one frame per 1/fps seconds of the run-up (real time), --every N
takes one frame per N control steps instead (fewer frames: a smaller file, a faster video).
Needs the optional extra: pip install 'abb-gym[video]'.
"""
from __future__ import annotations

import argparse
import math
import re
import sys

from ..envs import tasks


def register(sub) -> None:
    p = sub.add_parser("render", help="write one episode of a policy as a GIF or MP4 video",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", default=tasks.DEFAULT_ENV_ID,
                   help=f"environment id (one of {', '.join(tasks.TASKS)})")
    from .evaluate import add_test_set_arguments, add_trust_argument
    add_test_set_arguments(p, "environment preset")
    p.add_argument("--policy", required=True, help="baseline:NAME, ppo:NAME|PATH or replay:SPEC")
    p.add_argument("--episode", type=int, default=0,
                   help="test episode K (the environment reset with seed + K)")
    p.add_argument("--seed", type=int, default=0, help="seed of the test set")
    p.add_argument("--out", default=None,
                   help="the video file, .gif or .mp4 (default "
                        "out/render/<scene>_<policy>_<episode>.gif; folders created)")
    p.add_argument("--fps", type=float, default=25.0, help="frames per second of the video")
    p.add_argument("--every", type=int, default=None, metavar="N",
                   help="one frame per N control steps (default: real time at --fps)")
    p.add_argument("--steps", type=int, default=None, metavar="N",
                   help="stop the episode after N control steps (default: the whole episode)")
    add_trust_argument(p)
    p.set_defaults(func=run)


def default_out(scene: str, policy: str, episode: int) -> str:
    safe = re.sub(r"[^A-Za-z0-9_.-]+", "-", policy).strip("-")
    return f"out/render/{scene}_{safe}_{episode}.gif"


def run(args) -> int:
    from .evaluate import apply_test_set_defaults
    apply_test_set_defaults(args)
    from ..evaluation.video import check_video, render_episode
    from .outputs import output_file
    if args.out is not None and not args.out.strip():  # not read as "the default path"
        raise ValueError(f"--out must be a video file path (got {args.out!r})")
    out = args.out if args.out is not None else default_out(args.scene, args.policy,
                                                            args.episode)
    check_video(out, args.fps)  # suffix, fps and the extra before any folder is made
    output_file(out, "--out")
    task = tasks.get(args.env)
    if task.one_step:
        print(f"abb-gym render: note: a {task.name} episode is one step (its "
              f"whole run-up): the video has two frames, before and after", file=sys.stderr)
    res = render_episode(args.env, args.scene, args.policy, out, episode=args.episode,
                         seed=args.seed, preset=args.preset, fps=args.fps, every=args.every,
                         steps=args.steps)
    m = res["metrics"]
    resid = m["residual_vibration"]
    print(f"wrote {res['path']}: {res['frames']} frames of {res['width']} x {res['height']} at "
          f"{res['fps']:g} fps, one per {res['every']} control step(s); episode {args.episode} "
          f"(seed {m['seed']}): {res['steps']} steps, return {m['return']:.4g}, "
          + (f"residual vibration {resid:.4g} (W/e)" if math.isfinite(resid)
             else "not settled at the operating speed"))
    return 0
