"""A teacher's demonstrations cloned into the policy before PPO starts (behaviour cloning).

Some decisions are too rare for PPO's exploration to find.  On SpinRedistribute the drive must
hold the distribution speed for seconds, read the vibration and, for a load too large for
the balancer, stop the drum for the tumble time: a random walk of Gaussian actions almost
never does all of that, so PPO settles on the open-loop run-up (observed: return -3.7 after
400k steps, the same as the tuned open loop, never one redistribution).  Starting PPO from a
policy that already acts like a hand rule (a "kickstart") puts the rare behaviour into the
first rollouts; PPO then improves on the rule where the reward says so (thresholds, timing,
the use of the phase and of signals the rule ignores).

What :func:`clone` does, in this order:

1. runs the teacher (any ``--policy`` spec: ``baseline:redistribute_low``, ...) on
   ``episodes`` episodes of the training environment (its own seeds, far from the test
   set's), recording the observations, the teacher's actions and the rewards;
2. feeds the observations and the discounted returns to the training environment's
   ``VecNormalize`` statistics, as training would (so PPO starts from normalisation
   statistics of the states the clone will visit);
3. fits the policy's action mean to the teacher's actions (mean squared error, Adam), and
   the value function to the normalised discounted returns, for ``epochs`` passes;
4. sets the exploration noise ``log_std`` (a clone should explore around the teacher, not
   far from it).

The actor and the value function are fitted on the same normalised observations PPO uses.
The config: ``_abb_gym: {imitate: {policy: baseline:redistribute_low, episodes: 256,
epochs: 30, log_std: -1.5}}`` (:class:`ImitationSettings`; :mod:`abb_gym.rl.config`).
A hand-written loop rather than the ``imitation`` library: that library pins older
Gymnasium releases than abb-gym's, and the fit here is a few lines of torch.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..configuration import build_section, declare

__all__ = ["ImitationSettings", "imitation_settings", "demonstrations", "clone",
           "DEMO_SEED"]

#: first seed of the demonstration episodes (the test sets start at 1000, training at 0)
DEMO_SEED = 50_000_000


@dataclass(frozen=True)
class ImitationSettings:
    """Settings of the cloning (the ``_abb_gym.imitate`` mapping)."""

    policy: str = declare(kind="text", doc="the teacher: a --policy spec (e.g. "
                                           "baseline:redistribute_low)")
    episodes: int = declare(256, kind="integer", ge=1, le=100_000,
                            doc="demonstration episodes")
    epochs: int = declare(30, kind="integer", ge=1, le=10_000,
                          doc="passes over the demonstrations")
    log_std: float = declare(-1.5, ge=-10.0, le=2.0,
                             doc="exploration noise log std after cloning")
    learning_rate: float = declare(1e-3, gt=0.0, le=1.0, doc="Adam's step of the fit")


def imitation_settings(value: Any, where: str, error: type[ValueError]) -> dict[str, Any] | None:
    """The validated ``imitate`` mapping (None: no cloning); ``error`` names the field."""
    settings = build_section(ImitationSettings, value, "imitate", where, error,
                             "a mapping {policy: SPEC, episodes: N, epochs: N, log_std: X}",
                             {"policy": "the teacher, e.g. baseline:redistribute_low"})
    if settings is None:
        return None
    if not settings.policy.strip():
        raise error(f"{where}: field 'imitate.policy' must name a policy (got '')")
    return {"policy": settings.policy, "episodes": settings.episodes, "epochs": settings.epochs,
            "log_std": settings.log_std, "learning_rate": settings.learning_rate}


def demonstrations(teacher: str, env_id: str, env_kwargs: dict, episodes: int,
                   chunk: int = 32) -> dict[str, np.ndarray]:
    """``episodes`` episodes of ``teacher`` on the environment ``env_id`` with ``env_kwargs``
    (seeds :data:`DEMO_SEED` + k): arrays ``obs`` (steps, obs), ``actions`` (steps, act),
    ``rewards`` (steps,) and ``episode`` (steps,), each episode's steps in order."""
    import gymnasium as gym

    from ..evaluation.registry import resolve

    scene = env_kwargs.get("scene")
    obs_list, act_list, rew_list, ep_list = [], [], [], []
    for start in range(0, episodes, chunk):
        n = min(chunk, episodes - start)
        env = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point",
                           info_level="full", **env_kwargs)
        policy = resolve(teacher, env_id, scene)
        obs, info = env.reset(seed=[DEMO_SEED + start + k for k in range(n)])
        policy.reset(env, np.ones(n, bool))
        done = np.zeros(n, bool)
        while not done.all():
            act = np.asarray(policy.act(obs, info), dtype=np.float32).reshape(n, -1)
            nxt, reward, term, trunc, info = env.step(act)
            live = np.flatnonzero(~done)
            obs_list.append(obs[live])
            act_list.append(np.clip(act[live], -1.0, 1.0))
            rew_list.append(reward[live])
            ep_list.append(start + live)
            done |= term | trunc
            obs = nxt
        env.close()
    order = np.argsort(np.concatenate(ep_list), kind="stable")
    return {"obs": np.concatenate(obs_list)[order], "actions": np.concatenate(act_list)[order],
            "rewards": np.concatenate(rew_list)[order],
            "episode": np.concatenate(ep_list)[order]}


def _discounted(rewards: np.ndarray, episode: np.ndarray, gamma: float) -> np.ndarray:
    """The discounted return from each step to its episode's end."""
    out = np.zeros_like(rewards, dtype=float)
    running = 0.0
    for k in range(len(rewards) - 1, -1, -1):
        if k == len(rewards) - 1 or episode[k + 1] != episode[k]:
            running = 0.0
        running = rewards[k] + gamma * running
        out[k] = running
    return out


def clone(model: Any, env: Any, settings: dict[str, Any], env_id: str, env_kwargs: dict,
          gamma: float) -> dict[str, Any]:
    """Clone the teacher of ``settings`` into ``model``'s policy (module docstring); ``env``:
    the training environment (a ``VecNormalize`` is fed the demonstrations' statistics).
    Returns the record kept in the run's ``_run.imitate``."""
    import torch
    from stable_baselines3.common.vec_env import VecNormalize

    demo = demonstrations(settings["policy"], env_id, env_kwargs, settings["episodes"])
    obs, actions = demo["obs"].astype(np.float64), demo["actions"]
    returns = _discounted(demo["rewards"], demo["episode"], gamma)
    if isinstance(env, VecNormalize):
        if env.norm_obs:
            env.obs_rms.update(obs)
            obs = env.normalize_obs(obs)
        if env.norm_reward:
            env.ret_rms.update(returns)
            returns = returns / np.sqrt(env.ret_rms.var + env.epsilon)
    policy = model.policy
    x = torch.as_tensor(np.asarray(obs, np.float32))
    a = torch.as_tensor(np.asarray(actions, np.float32))
    v = torch.as_tensor(np.asarray(returns, np.float32)).reshape(-1, 1)
    params = [p for name, p in policy.named_parameters() if name != "log_std"]
    optimizer = torch.optim.Adam(params, lr=settings["learning_rate"])
    generator = torch.Generator().manual_seed(0)
    batch = 256
    policy.set_training_mode(True)
    for _ in range(settings["epochs"]):
        for idx in torch.randperm(len(x), generator=generator).split(batch):
            features = policy.extract_features(x[idx])
            latent_pi, latent_vf = policy.mlp_extractor(features)
            mean = policy.action_net(latent_pi)
            value = policy.value_net(latent_vf)
            loss = torch.mean((mean - a[idx]) ** 2) + 0.5 * torch.mean((value - v[idx]) ** 2)
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
    policy.set_training_mode(False)
    with torch.no_grad():
        features = policy.extract_features(x)
        latent_pi, _ = policy.mlp_extractor(features)
        error = float(torch.mean((policy.action_net(latent_pi) - a) ** 2))
        policy.log_std.fill_(settings["log_std"])
    return {"policy": settings["policy"], "episodes": settings["episodes"],
            "steps": int(len(x)), "epochs": settings["epochs"],
            "action_mse": round(error, 6), "log_std": settings["log_std"]}
