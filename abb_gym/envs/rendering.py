"""Rendering of a balancer environment with matplotlib.

One frame has two panels:

* left, the machine seen along the shaft (fixed frame): the housing clearance (dashed circle),
  the recent orbit of the rotor centre (magnified so that the clearance fills the panel), the
  race drawn around the current rotor centre, the balls on it at their angles, and a red
  marker at the angle of the primary imbalance;
* right, the rotor speed over the episode (normalised by the operating speed) with the
  operating speed as a dashed line and the normalised whirl radius on a second axis.

``"rgb_array"`` renders into an off-screen Agg canvas and returns an ``(H, W, 3)`` uint8 array.
``"human"`` shows the same figure in a window when a display is available (an interactive
matplotlib backend and, on Linux, ``$DISPLAY`` or ``$WAYLAND_DISPLAY``); without one it draws
off-screen and warns once.
"""
from __future__ import annotations

import math
import os
import sys

import numpy as np

__all__ = ["Renderer", "display_available"]

#: top of the strip along the bottom of the figure that holds the legends [figure fraction]
LEGEND_TOP = 0.15
_NON_INTERACTIVE = {"agg", "pdf", "ps", "svg", "cairo", "template", "pgf"}


def display_available() -> bool:
    """True when a window can be shown (an interactive backend and a display)."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                 or os.environ.get("WAYLAND_DISPLAY")):
        return False
    try:
        import matplotlib
        backend = matplotlib.get_backend().lower()
    except Exception:  # pragma: no cover - matplotlib missing
        return False
    return backend not in _NON_INTERACTIVE and "inline" not in backend


class Renderer:
    """Draws frames of one environment; ``mode`` is "rgb_array" or "human"."""

    def __init__(self, scene, operating_speed: float, episode_length: float, mode: str,
                 width: int = 720, height: int = 360, orbit_points: int = 200):
        self.scene = scene
        self.operating_speed = operating_speed
        self.episode_length = episode_length
        self.mode = mode
        self.orbit_points = orbit_points
        self.window = mode == "human" and display_available()
        self.warned = False
        dpi = 80
        if self.window:
            import matplotlib.pyplot as plt
            self._plt = plt
            plt.ion()
            self.fig = plt.figure(figsize=(width / dpi, height / dpi), dpi=dpi)
        else:
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            from matplotlib.figure import Figure
            self._plt = None
            self.fig = Figure(figsize=(width / dpi, height / dpi), dpi=dpi)
            FigureCanvasAgg(self.fig)
        self._build()

    def _build(self) -> None:
        sc = self.scene
        fig = self.fig
        # the bottom strip (below LEGEND_TOP) holds the legends, outside both panels
        self.ax_orbit = fig.add_axes((0.02, LEGEND_TOP + 0.02, 0.44, 0.91 - LEGEND_TOP))
        self.ax_speed = fig.add_axes((0.56, LEGEND_TOP + 0.13, 0.36, 0.78 - LEGEND_TOP))
        ax = self.ax_orbit
        ax.set_aspect("equal")
        ax.set_xlim(-1.25, 1.25)
        ax.set_ylim(-1.25, 1.25)
        ax.set_xticks([])
        ax.set_yticks([])
        th = np.linspace(0, 2 * np.pi, 129)
        (clearance,) = ax.plot(np.cos(th), np.sin(th), "k--", lw=0.8,
                               label="housing clearance")
        ax.set_title(f"{sc.name}: orbit / clearance {sc.housing_clearance * 1e3:.3g} mm",
                     fontsize=9)
        (self.orbit_line,) = ax.plot([], [], color="tab:blue", lw=0.8,
                                     label="orbit of the rotor centre")
        # the race is drawn with radius 0.35 of the panel (not to scale)
        self.race_r = 0.35
        (self.race_line,) = ax.plot([], [], color="0.4", lw=1.2, label="race (not to scale)")
        (self.balls_line,) = ax.plot([], [], "o", color="tab:green", ms=8, mec="k",
                                     label=f"balls ({sc.ball_count})")
        (self.imb_line,) = ax.plot([], [], "s", color="tab:red", ms=7, mec="k",
                                   label="angle of the imbalance")
        (self.centre_line,) = ax.plot([], [], "+", color="k", ms=8, label="rotor centre")
        self.legend_orbit = fig.legend(
            handles=[self.balls_line, self.imb_line, self.centre_line, self.race_line,
                     self.orbit_line, clearance],
            loc="lower center", bbox_to_anchor=(0.24, 0.0), ncol=2, fontsize=7,
            frameon=False, handlelength=1.6, columnspacing=1.0, labelspacing=0.3,
            borderaxespad=0.2)
        ax2 = self.ax_speed
        ax2.set_xlim(0, self.episode_length)
        ax2.set_ylim(-0.05, 1.3)
        operating = ax2.axhline(1.0, color="k", ls=":", lw=0.8, label="operating speed")
        ax2.set_xlabel("time [s]", fontsize=9)
        ax2.set_ylabel("speed / operating speed", fontsize=9, color="tab:blue")
        ax2.tick_params(labelsize=8)
        (self.speed_line,) = ax2.plot([], [], color="tab:blue", lw=1.2, label="rotor speed")
        self.ax_whirl = ax2.twinx()
        self.ax_whirl.set_ylim(0, 1.05)
        self.ax_whirl.set_ylabel("whirl / clearance", fontsize=9, color="tab:orange")
        self.ax_whirl.tick_params(labelsize=8)
        (self.whirl_line,) = self.ax_whirl.plot([], [], color="tab:orange", lw=0.8,
                                                label="whirl radius (right axis)")
        self.legend_speed = fig.legend(
            handles=[self.speed_line, operating, self.whirl_line], loc="lower center",
            bbox_to_anchor=(0.74, 0.0), ncol=2, fontsize=7, frameon=False, handlelength=1.6,
            columnspacing=1.0, labelspacing=0.3, borderaxespad=0.2)
        # time, speed and whirl now: the speed panel's title, clear of both drawings
        self.text = ax2.set_title("", fontsize=8)

    def draw(self, state: np.ndarray, trace: np.ndarray) -> np.ndarray | None:
        """Draw one frame: ``state`` is the model state, ``trace`` rows (t, x, y, w) so far."""
        sc = self.scene
        nq = state.shape[0] // 2
        clear = sc.housing_clearance
        x, y, th = state[0] / clear, state[1] / clear, state[2]
        tail = trace[-self.orbit_points:]
        self.orbit_line.set_data(tail[:, 1] / clear, tail[:, 2] / clear)
        ang = np.linspace(0, 2 * np.pi, 65)
        self.race_line.set_data(x + self.race_r * np.cos(ang), y + self.race_r * np.sin(ang))
        ph = state[3:nq]
        self.balls_line.set_data(x + self.race_r * np.cos(th + ph),
                                 y + self.race_r * np.sin(th + ph))
        self.imb_line.set_data([x + 0.6 * self.race_r * math.cos(th)],
                               [y + 0.6 * self.race_r * math.sin(th)])
        self.centre_line.set_data([x], [y])
        t = trace[:, 0]
        self.speed_line.set_data(t, trace[:, 3] / self.operating_speed)
        self.whirl_line.set_data(t, np.hypot(trace[:, 1], trace[:, 2]) / clear)
        now = t[-1] if len(t) else 0.0
        self.text.set_text(f"t = {now:.2f} s   speed = {state[nq + 2]:.1f} rad/s   "
                           f"whirl = {math.hypot(state[0], state[1]) * 1e3:.3g} mm")
        if self.window:
            self.fig.canvas.draw_idle()
            self.fig.canvas.flush_events()
            self._plt.pause(0.001)
            return None
        self.fig.canvas.draw()
        rgba = np.asarray(self.fig.canvas.buffer_rgba())
        if self.mode == "human":
            if not self.warned:
                from gymnasium import logger
                logger.warn("render_mode='human' has no display here; frames are drawn "
                            "off-screen (use render_mode='rgb_array' to get them)")
                self.warned = True
            return None
        return rgba[:, :, :3].copy()

    def close(self) -> None:
        if self.window and self._plt is not None:
            self._plt.close(self.fig)
        self.fig = None
