"""The algorithms that train a policy, by rl_zoo3's ``--algo`` name, and the policy names.

=============  ==================================  ============================================
``--algo``     class                               chosen by
=============  ==================================  ============================================
``ppo``        ``stable_baselines3.PPO``           any policy without memory (the default)
``ppo_lstm``   ``sb3_contrib.RecurrentPPO``        a policy with memory (``MlpLstmPolicy``,
                                                   ``abb_gym.rl.networks.BoundedMlpLstmPolicy``)
``sac``        ``stable_baselines3.SAC``           ``_abb_gym.algo: sac`` (or the started policy)
``tqc``        ``sb3_contrib.TQC``                 ``_abb_gym.algo: tqc`` (or the started policy)
=============  ==================================  ============================================

The algorithm follows from the policy (:func:`algorithm_of`), as rl_zoo3's ``--algo
ppo_lstm`` follows from a recurrent policy, so a config file needs no key of its own for it;
only the off-policy algorithms, whose own squashed-Gaussian ``MlpPolicy`` says nothing of the
algorithm, are named by ``_abb_gym.algo`` (:mod:`abb_gym.rl.config`).  The classes are
imported on first use (:func:`algorithm_class`): SB3 and sb3-contrib are the training extra.
"""
from __future__ import annotations

import inspect

__all__ = ["POLICY_NAMES", "SB3_POLICY_ALIASES", "ALGORITHMS", "OFF_POLICY",
           "RECURRENT_POLICIES", "STARTED_POLICIES", "algorithm_of", "import_class",
           "algorithm_class", "algorithm_keywords"]

#: SB3's and sb3-contrib's names for their own policies (``PPO.policy_aliases``,
#: ``RecurrentPPO.policy_aliases``)
SB3_POLICY_ALIASES = ("MlpPolicy", "CnnPolicy", "MultiInputPolicy", "MlpLstmPolicy",
                      "CnnLstmPolicy", "MultiInputLstmPolicy")
POLICY_NAMES = {"MlpPolicy": "MlpPolicy",
                "BoundedMlpPolicy": "abb_gym.rl.networks.BoundedMlpPolicy",
                "abb_gym.rl.networks.BoundedMlpPolicy": "abb_gym.rl.networks.BoundedMlpPolicy",
                "MlpLstmPolicy": "MlpLstmPolicy",
                "abb_gym.rl.networks.BoundedMlpLstmPolicy":
                    "abb_gym.rl.networks.BoundedMlpLstmPolicy",
                "abb_gym.rl.networks.StartedSACPolicy": "abb_gym.rl.networks.StartedSACPolicy",
                "abb_gym.rl.networks.StartedTQCPolicy": "abb_gym.rl.networks.StartedTQCPolicy"}
#: the algorithms, by rl_zoo3's ``--algo`` name: (module, class)
ALGORITHMS = {"ppo": ("stable_baselines3", "PPO"), "ppo_lstm": ("sb3_contrib", "RecurrentPPO"),
              "sac": ("stable_baselines3", "SAC"), "tqc": ("sb3_contrib", "TQC")}
#: off-policy algorithms: their own squashed-Gaussian ``MlpPolicy``, chosen by ``_abb_gym.algo``
OFF_POLICY = ("sac", "tqc")
#: policies with memory (an LSTM), trained by RecurrentPPO; every other one by PPO
RECURRENT_POLICIES = ("MlpLstmPolicy", "abb_gym.rl.networks.BoundedMlpLstmPolicy")
#: the off-policy algorithms' policies with an initial action mean, and their algorithm
STARTED_POLICIES = {"abb_gym.rl.networks.StartedSACPolicy": "sac",
                    "abb_gym.rl.networks.StartedTQCPolicy": "tqc"}


def algorithm_of(policy: str, algo: str | None = None) -> str:
    """rl_zoo3's ``--algo`` name of the algorithm that trains ``policy``: ``algo`` if given
    (the ``_abb_gym.algo`` key: ``sac`` or ``tqc``), else ``ppo_lstm`` (sb3-contrib's
    RecurrentPPO) for a recurrent policy and ``ppo`` for any other."""
    if algo is not None:
        return algo
    name = POLICY_NAMES.get(policy, policy)
    if name in STARTED_POLICIES:
        return STARTED_POLICIES[name]
    return "ppo_lstm" if name in RECURRENT_POLICIES else "ppo"


def import_class(module: str, name: str, what: str) -> type:
    """Class ``name`` of ``module`` (part of the training extra); an ``ImportError`` saying
    what needs which package and how to install it, if it is missing."""
    import importlib
    try:
        return getattr(importlib.import_module(module), name)
    except ImportError as exc:
        package = module.split(".")[0].replace("_", "-")
        raise ImportError(f"{what} needs {package}: pip install -c constraints.txt "
                          f"'abb-gym[train]' ({exc})") from exc


def algorithm_class(algo: str) -> type:
    """The SB3 (or sb3-contrib) class of ``algo`` (a key of :data:`ALGORITHMS`); an
    ``ImportError`` naming the package if it is missing."""
    module, name = ALGORITHMS[algo]
    return import_class(module, name, f"{name} ({algo})")


def algorithm_keywords(algo: str = "ppo") -> set[str]:
    """The keyword arguments of ``algo``'s constructor that a config entry may set (those
    the trainer passes itself left out)."""
    params = set(inspect.signature(algorithm_class(algo).__init__).parameters)
    return params - {"self", "policy", "env", "policy_kwargs", "seed", "device",
                     "_init_setup_model", "verbose"}
