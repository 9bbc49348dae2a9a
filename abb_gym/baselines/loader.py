"""``baseline:NAME``: the policy of a baseline by name (the ``abb_gym.policies`` entry point).

A name is a family (:data:`abb_gym.baselines.families.FAMILY_NAMES`: its tuned parameters
where the scene has them, :mod:`abb_gym.baselines.baseline_policy`) or ``laundry_oracle``
(:mod:`abb_gym.baselines.laundry`).
"""
from __future__ import annotations

from typing import Any

from .baseline_policy import FAMILY_NAMES, _LazyBaseline
from .laundry import ORACLE_NAME, LaundryOracle

__all__ = ["load_baseline", "BASELINE_NAMES"]

#: every name ``baseline:NAME`` takes
BASELINE_NAMES = (*FAMILY_NAMES, ORACLE_NAME)


def load_baseline(name: str, env_id: str | None = None, scene: Any = None, **_: Any):
    """The policy of ``baseline:NAME`` (module docstring)."""
    if name == ORACLE_NAME:
        return LaundryOracle()
    if name not in FAMILY_NAMES:
        raise ValueError(f"unknown baseline {name!r}; available: {', '.join(BASELINE_NAMES)}")
    return _LazyBaseline(name, scene)
