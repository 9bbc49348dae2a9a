#!/usr/bin/env python
"""Train PPO on a balancer environment from a zoo-style config (same as ``abb-gym train``).

    python agents/train.py --config runup_speed_yoshida_odd --seed 0
    python agents/train.py --config configs/ppo/dwell_profile_yoshida_odd.yml --seeds 0 1 2

Options: ``python agents/train.py --help``; what a run writes: :mod:`abb_gym.rl.train`.
"""
import sys

if __name__ == "__main__":
    from abb_gym.cli.train import main
    sys.exit(main())
