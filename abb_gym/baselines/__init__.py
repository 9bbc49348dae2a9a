"""Hand-designed run-up baselines: literature speed profiles (:mod:`.profiles`)."""
from .profiles import FAMILIES, build

__all__ = ["FAMILIES", "build"]
