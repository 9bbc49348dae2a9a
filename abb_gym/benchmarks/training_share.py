"""How much of a training run is the simulator: the wall time of the training environment's
steps and resets against the whole ``model.learn``.

    python -m abb_gym.benchmarks.training_share [CONFIG] [--steps N]

Trains ``CONFIG`` (default ``runup_speed_yoshida_odd_varied``) for ``N`` environment steps
(default 131 072: 16 rollouts of the shipped config, after one untimed rollout that compiles
or loads the kernels) without evaluations or checkpoints, with
the training's own settings (one torch thread), and times every call of the SB3 adapter's
``step_wait`` and ``reset`` (:class:`abb_gym.rl.vec_env.NativeVecEnv`: the compiled vector
step, the adapter's info split and the autoresets) and every gradient update (the
algorithm's ``train``: all epochs over one rollout).  The rest is the rollouts' own work:
policy forward passes, the rollout buffer, VecNormalize.  Needs the training extra.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from typing import Sequence

__all__ = ["training_share"]


def training_share(config: str = "runup_speed_yoshida_odd_varied", steps: int = 131_072,
                   seed: int = 0) -> dict[str, float]:
    """Train ``config`` for ``steps`` env steps; returns the wall time of ``learn`` [s], the
    time in the environment and in the gradient updates [s], their shares, and env-steps/s."""
    from ..rl.algorithms import algorithm_class
    from ..rl.config import load_config
    from ..rl.train import train
    from ..rl.vec_env import NativeVecEnv

    spent = {"env": 0.0, "update": 0.0}
    cfg = load_config(config).with_overrides(n_timesteps=int(steps), eval_freq=0,
                                             checkpoint_freq=0)
    algo = algorithm_class(cfg.algo)
    originals = {(NativeVecEnv, name, "env"): getattr(NativeVecEnv, name)
                 for name in ("step_wait", "reset")}
    originals[(algo, "train", "update")] = algo.train

    def timed(fn, part):
        def wrapper(self, *args, **kwargs):
            t0 = time.perf_counter()
            try:
                return fn(self, *args, **kwargs)
            finally:
                spent[part] += time.perf_counter() - t0
        return wrapper

    with tempfile.TemporaryDirectory() as tmp:
        # one untimed rollout first: a kernel compiled (or loaded) on the first step would
        # count as simulator time (spannan_cfrp_varied measured 64 % instead of 16 %)
        train(cfg.with_overrides(n_timesteps=1), seed=seed, run_dir=tmp, progress=False,
              final_eval=False)
    try:
        for (owner, name, part), fn in originals.items():
            setattr(owner, name, timed(fn, part))
        with tempfile.TemporaryDirectory() as tmp:
            res = train(cfg, seed=seed, run_dir=tmp, progress=False, final_eval=False)
    finally:
        for (owner, name, _), fn in originals.items():
            setattr(owner, name, fn)
    return {"learn_s": res.wall_time_s, "env_s": spent["env"],
            "env_share": spent["env"] / res.wall_time_s, "update_s": spent["update"],
            "update_share": spent["update"] / res.wall_time_s, "env_steps": res.env_steps,
            "env_steps_per_s": res.env_steps_per_s}


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m abb_gym.benchmarks.training_share",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("config", nargs="?", default="runup_speed_yoshida_odd_varied")
    ap.add_argument("--steps", type=int, default=131_072)
    args = ap.parse_args(argv)
    if args.steps < 1:
        ap.error(f"--steps must be >= 1 (got {args.steps})")
    r = training_share(args.config, args.steps)
    print(f"{args.config}: {r['env_steps']} env steps in {r['learn_s']:.1f} s "
          f"({r['env_steps_per_s']:.0f} env-steps/s); the environment {r['env_s']:.1f} s "
          f"= {100 * r['env_share']:.0f} % of training, the gradient updates "
          f"{r['update_s']:.1f} s = {100 * r['update_share']:.0f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
