"""The error of a bad agent folder or file, shared by the modules that read them
(:mod:`abb_gym.rl.agent_files`, :mod:`abb_gym.rl.policy_files`, :mod:`abb_gym.rl.legacy`)."""
from __future__ import annotations

from ..configuration import ConfigError

__all__ = ["AgentError"]


class AgentError(ConfigError):
    """An agent folder is incomplete or inconsistent, or one of its files cannot be read
    (the message names the file); a ``ValueError``, which ``abb-gym`` prints as one line."""
