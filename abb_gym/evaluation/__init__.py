"""Scoring run-ups: metrics from time histories, and (with the environments) the
policy-versus-baseline evaluation."""
from .metrics import nonsynchronous_whirl, runup_metrics, trajectory_metrics

__all__ = ["nonsynchronous_whirl", "runup_metrics", "trajectory_metrics"]
