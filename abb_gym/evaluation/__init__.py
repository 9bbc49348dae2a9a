"""Scoring run-ups: metrics from time histories, and (with the environments) the
policy-versus-baseline evaluation."""
from .metrics import (best_residual_imbalance, no_ball_amplitude, nonsynchronous_whirl,
                      residual_imbalance, runup_metrics, trajectory_metrics)

__all__ = ["best_residual_imbalance", "no_ball_amplitude", "nonsynchronous_whirl",
           "residual_imbalance", "runup_metrics", "trajectory_metrics"]
