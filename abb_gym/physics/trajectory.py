"""The result of :func:`~abb_gym.physics.simulate.simulate`: :class:`Trajectory`, a state
history sampled in time, and the layout of the first-order state vector it holds
(:func:`state_names`: rotor centre x, y, rotor angle, ball angles, then their speeds)."""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .scene import Scene

__all__ = ["Trajectory", "PlanarStates", "state_names"]


def state_names(n_balls: int) -> list[str]:
    """Names of the entries of the first-order state vector."""
    q = ["x", "y", "rotor_angle"] + [f"ball_angle[{i}]" for i in range(n_balls)]
    v = ["x_velocity", "y_velocity", "rotor_speed"] + [f"ball_speed[{i}]" for i in range(n_balls)]
    return q + v


class PlanarStates:
    """Accessors of a state history whose first two columns are the rotor centre (x, y)."""

    states: np.ndarray

    @property
    def x(self) -> np.ndarray:
        """Rotor-centre deflection x (the trajectory's length unit)."""
        return self.states[:, 0]

    @property
    def y(self) -> np.ndarray:
        """Rotor-centre deflection y (the trajectory's length unit)."""
        return self.states[:, 1]

    @property
    def whirl_radius(self) -> np.ndarray:
        """W_r = sqrt(x^2 + y^2) (the trajectory's length unit)."""
        return np.hypot(self.states[:, 0], self.states[:, 1])


@dataclass
class Trajectory(PlanarStates):
    """Result of :func:`simulate`; arrays are sampled at ``t`` [s]; lengths in m.

    ``ball_angles`` are relative to the rotor, measured from the imbalance, unwrapped [rad].
    """

    scene: Scene
    t: np.ndarray
    states: np.ndarray
    method: str
    step: float | None  # largest RK4 step taken [s] (None for solve_ivp methods)
    wall_time: float
    work: int
    motor_torque: np.ndarray | None = None
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def n_balls(self) -> int:
        return self.scene.ball_count

    @property
    def _nq(self) -> int:
        return 3 + self.n_balls

    @property
    def rotor_angle(self) -> np.ndarray:
        """Rotor angle psi [rad]."""
        return self.states[:, 2]

    @property
    def rotor_speed(self) -> np.ndarray:
        """Rotor speed psi' [rad/s]."""
        return self.states[:, self._nq + 2]

    @property
    def ball_angles(self) -> np.ndarray:
        """Ball angles relative to the rotor from the imbalance, unwrapped, shape (T, n) [rad]."""
        return self.states[:, 3:self._nq]

    @property
    def ball_speeds(self) -> np.ndarray:
        """Ball angular speeds relative to the rotor, shape (T, n) [rad/s]."""
        return self.states[:, self._nq + 3:]

    @property
    def whirl_ratio(self) -> np.ndarray:
        """W_r / e with e = ``scene.reference_length`` (Yoshida's plots) [-]."""
        return self.whirl_radius / self.scene.reference_length

    def summary(self, settle_window: float = 0.5) -> dict[str, Any]:
        """Headline numbers: peak whirl and its time, final and residual whirl, ball angles."""
        wr = self.whirl_ratio
        k = int(np.argmax(wr))
        tail = self.t >= self.t[-1] - settle_window
        return {
            "scene": self.scene.name,
            "method": self.method,
            "peak_whirl_ratio": float(wr[k]),
            "peak_time_s": float(self.t[k]),
            "residual_whirl_ratio": float(np.mean(wr[tail])),
            "final_speed_rad_s": float(self.rotor_speed[-1]),
            "final_ball_angles_deg": [float(v) for v in np.degrees(self.ball_angles[-1])],
            "wall_time_s": self.wall_time,
        }

    def to_dict(self) -> dict[str, Any]:
        d = {"scene": self.scene.to_dict(), "method": self.method, "step": self.step,
             "t": self.t.tolist(), "x": self.x.tolist(), "y": self.y.tolist(),
             "rotor_angle": self.rotor_angle.tolist(), "rotor_speed": self.rotor_speed.tolist(),
             "ball_angles": self.ball_angles.tolist(), "whirl_radius": self.whirl_radius.tolist(),
             "summary": self.summary()}
        if self.motor_torque is not None:
            d["motor_torque"] = self.motor_torque.tolist()
        return d

    def to_json(self, path=None) -> str:
        text = json.dumps(self.to_dict())
        if path is not None:
            with open(path, "w") as fh:
                fh.write(text)
        return text
