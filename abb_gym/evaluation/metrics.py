"""Run-up metrics from sampled time histories (a :class:`Trajectory` or an environment rollout).

All functions take plain arrays so that ``simulate`` trajectories and environment rollouts are
scored by the same code:

=============================  ===========  ====================================================
metric                         unit         definition
=============================  ===========  ====================================================
``time_to_speed``              s            first time the rotor speed reaches 99 % of the
                                            operating speed (NaN if never)
``peak_whirl``                 -            largest W_r / e before the operating speed is reached
``residual_vibration``         -            mean W_r / e over the last ``settle_window`` s
``ball_settling_time``         s            time after reaching the operating speed until every
                                            ball angle stays within ``angle_tol`` of its final
                                            value (NaN if never at speed)
``residual_imbalance``         -            |U0 + sum m_i (E e^(i gam) + R e^(i ph_i))| / U0 at
                                            the end, the imbalance the balls leave uncancelled
                                            (:mod:`abb_gym.physics.rotor`: the scale is U0
                                            unless it is 0)
``balanced``                   bool         residual imbalance within ``balance_tol`` U0 of the
                                            best the balls can reach (unequal balls and race
                                            eccentricity included: :func:`rotor.best_residual`)
``nonsynchronous_whirl``       bool         after the critical speed, some ball slips more than
                                            a full revolution (2 pi) behind the rotor: it
                                            circulates instead of settling
``drive_energy``               J            integral of |T w| dt (when the torque is known)
=============================  ===========  ====================================================
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..physics import rotor
from ..physics.scene import Scene

SPEED_FRACTION = 0.99


def runup_metrics(scene: Scene, t, rotor_speed, whirl_radius, ball_angles,
                  operating_speed: float | None = None, torque=None,
                  settle_window: float = 0.5, angle_tol: float = math.radians(2.0),
                  balance_tol: float = 0.1) -> dict[str, Any]:
    """The metrics of the module docstring for one run of ``scene``."""
    angles = np.asarray(ball_angles, float).reshape(len(t), -1)
    residual = rotor.residual_imbalance(scene, angles[-1])
    scale = rotor.imbalance_scale(scene)
    return metrics_from_arrays(
        t, rotor_speed, np.asarray(whirl_radius, float) / scene.reference_length, angles,
        operating_speed=scene.drive_operating_speed if operating_speed is None
        else operating_speed, critical_speed=scene.critical_speed,
        residual_imbalance=residual / scale,
        balanced=rotor.is_balanced(residual, rotor.best_residual(scene), balance_tol, scale),
        torque=torque, settle_window=settle_window, angle_tol=angle_tol)


def metrics_from_arrays(t, rotor_speed, whirl_ratio, ball_angles, *, operating_speed: float,
                        critical_speed: float, residual_imbalance: float, balanced: bool,
                        torque=None, settle_window: float = 0.5,
                        angle_tol: float = math.radians(2.0)) -> dict[str, Any]:
    """The metrics from sampled histories: time [s], rotor speed [rad/s], W_r / e, ball
    angles [rad] (T, n), and the end-of-run residual imbalance / U0 and balanced flag (which
    the caller computes from the episode's machine)."""
    t = np.asarray(t, float)
    w = np.asarray(rotor_speed, float)
    ratio = np.asarray(whirl_ratio, float)
    angles = np.asarray(ball_angles, float).reshape(len(t), -1)
    reached = np.nonzero(w >= SPEED_FRACTION * operating_speed)[0]
    k_reach = int(reached[0]) if reached.size else None
    t_reach = float(t[k_reach]) if k_reach is not None else math.nan
    runup = ratio[: k_reach + 1] if k_reach is not None else ratio
    tail = t >= t[-1] - settle_window
    settle = math.nan
    if k_reach is not None:
        dev = np.max(np.abs(angles - angles[-1]), axis=1) > angle_tol
        late = np.nonzero(dev[k_reach:])[0]
        settle = 0.0 if late.size == 0 else float(t[k_reach + late[-1]] - t[k_reach])
        if late.size and k_reach + late[-1] == len(t) - 1:
            settle = math.nan  # still moving at the end
    energy = math.nan
    if torque is not None:
        energy = float(np.trapezoid(np.abs(np.asarray(torque, float) * w), t))
    return {
        "time_to_speed": t_reach,
        "peak_whirl": float(runup.max()),
        "residual_vibration": float(np.mean(ratio[tail])),
        "ball_settling_time": settle,
        "residual_imbalance": float(residual_imbalance),
        "balanced": bool(balanced),
        "nonsynchronous_whirl": _slips(t, w, angles, critical_speed, None),
        "drive_energy": energy,
    }


def nonsynchronous_whirl(scene: Scene, t, rotor_speed, ball_angles,
                         window: float | None = None) -> bool:
    """True if, after the rotor passes the critical speed, some ball slips more than a full
    revolution (2 pi) behind the rotor: it orbits slower than the rotor instead of settling
    (Yoshida ch. 5, Spannan's Sommerfeld region).  With ``window`` [s] the slip must happen
    within that time (a faster circulation)."""
    return _slips(t, rotor_speed, ball_angles, scene.critical_speed, window)


def _slips(t, rotor_speed, ball_angles, critical_speed: float, window: float | None) -> bool:
    t = np.asarray(t, float)
    above = np.nonzero(np.asarray(rotor_speed) >= critical_speed)[0]
    if not above.size:
        return False
    start = int(above[0])
    ang = np.asarray(ball_angles, float).reshape(len(t), -1)[start:]
    tt = t[start:]
    if len(tt) < 2:
        return False
    if window is None:
        return bool(np.any(ang[0] - ang.min(axis=0) > 2 * math.pi))
    lag = np.minimum(np.searchsorted(tt, tt + window), len(tt) - 1)
    return bool(np.any(ang - ang[lag] > 2 * math.pi))


def trajectory_metrics(tr, **kwargs) -> dict[str, Any]:
    """:func:`runup_metrics` of a :class:`~abb_gym.physics.simulate.Trajectory`."""
    return runup_metrics(tr.scene, tr.t, tr.rotor_speed, tr.whirl_radius, tr.ball_angles,
                         torque=tr.motor_torque, **kwargs)
