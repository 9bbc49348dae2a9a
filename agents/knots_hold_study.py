#!/usr/bin/env python
"""The tuned ``knots`` profile under a run-up-time budget: shorten its final hold.

The tuned ``knots`` profile of a scene (``configs/baselines/<scene>.yaml``) runs at the drive's
limit to just below the operating band, holds there while the balls settle, then enters.  Its
hold length trades run-up time against residual vibration.  This study scales the hold (the
last knot time) by ``--factors``, scores each variant on the **training** preset (the tuner's
episodes, seed and reward), keeps the variant with the lowest residual whose mean settled
run-up time is within ``--budget`` seconds and that reaches the speed in every episode, and
evaluates only that one on the held-out test set (100 episodes, seed 0, as the agents' tables).

    python agents/knots_hold_study.py --scene spannan_cfrp --budget 36.8

On spannan_cfrp this answers the Honest-benchmark issue's figure (an open-loop profile at
about 0.10 W_r/e within 36.8 s) on the 0.2 % band's settled run-up time, where the tuned
``knots`` itself (0.070 at 44.1 s) spends longer in its hold.
"""
import argparse
import sys

import numpy as np


def score(scene, params, preset: str, episodes: int, seed: int, env_kwargs: dict) -> dict:
    """Summary (:func:`abb_gym.evaluation.evaluate.summarise`) of ``knots`` with ``params``."""
    from abb_gym.baselines.baseline_policy import make_baseline
    from abb_gym.evaluation.evaluate import chunks, run_chunk, summarise
    rows = []
    for chunk in chunks("abb_gym/RunUpSpeed-v0", scene.name, "baseline:knots", episodes, seed,
                        preset, chunk_size=64, **env_kwargs):
        rows += run_chunk(chunk, policy=make_baseline("knots", scene, params=params))[0]
    return summarise(rows)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--scene", default="spannan_cfrp", help="scene with a tuned knots profile")
    p.add_argument("--budget", type=float, default=36.8, help="settled run-up time budget [s]")
    p.add_argument("--factors", type=float, nargs="+",
                   default=[round(f, 2) for f in np.arange(0.30, 1.001, 0.05)],
                   help="factors on the tuned hold length")
    p.add_argument("--test-episodes", type=int, default=100)
    args = p.parse_args(argv)
    from abb_gym import load_scene
    from abb_gym.baselines.baseline_policy import tuned_file, tuned_parameters
    from abb_gym.configuration import read_yaml
    scene = load_scene(args.scene)
    tuned = tuned_parameters(args.scene, "knots")
    if tuned is None:
        print(f"knots_hold_study: error: no tuned knots for {args.scene}", file=sys.stderr)
        return 2
    meta = read_yaml(tuned_file(args.scene), "tuned baselines")
    train = dict(preset=meta["preset"], episodes=meta["episodes"], seed=meta["seed"],
                 env_kwargs=dict(meta.get("env_kwargs") or {}))
    print(f"tuned knots of {args.scene}: {tuned}\ntraining preset {train}\n")
    print("| hold factor | settled run-up [s] | residual W_r/e | at speed |\n|---|---|---|---|")
    best = None
    for f in args.factors:
        params = dict(tuned, knot_times=list(tuned["knot_times"][:-1])
                      + [tuned["knot_times"][-1] * f])
        s = score(scene, params, **train)
        t, r, a = (s[k]["mean"] for k in ("run_up_time", "residual_vibration", "at_speed"))
        print(f"| {f:.2f} | {t:.2f} | {r:.4f} | {a:.2f} |", flush=True)
        if a == 1.0 and t <= args.budget and (best is None or r < best[1]):
            best = (f, r, params)
    if best is None:
        print(f"no variant runs up within {args.budget} s on the training preset")
        return 1
    s = score(scene, best[2], "test", args.test_episodes, 0, train["env_kwargs"])
    rv, ru = s["residual_vibration"], s["run_up_time"]
    print(f"\nchosen on the training preset: hold x{best[0]:.2f}\ntest preset, "
          f"{args.test_episodes} episodes, seed 0: settled run-up {ru['mean']:.2f} s, residual "
          f"{rv['mean']:.3f} [{rv['ci_low']:.3f}, {rv['ci_high']:.3f}] W_r/e, at speed "
          f"{s['at_speed']['mean']:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
