"""The observation, declared once: its entries, their sizes, bounds, names and definitions.

An observation is a flat ``Box`` of float32: what a drive with a vibration sensor measures,
every entry normalised and clipped to its bounds.  Each entry is declared once here as an
:class:`Entry`; from the declarations come

* the observation space (size, bounds) and the names (:func:`layout`);
* the compiled writer's layout: each entry's offset in the observation row, written into the
  environment's constants (``cfg[C_OBS + entry.slot]``, -1 for an entry left out), which
  :func:`abb_gym.envs.kernel._observe` reads;
* the policy <-> environment contract: the preset fields that change the layout
  (:data:`LAYOUT_FIELDS`), which a trained agent must match;
* the table in the environments' documentation (:func:`doc_table`).

``A_v`` is the steady whirl amplitude at resonance of the same rotor without balls, with the
scene's imbalance (a fixed scale per environment), ``c`` the housing clearance, ``w_op`` the
operating speed.  The entries appear in the order below; an entry that is left out moves
every later one up.  With ``frame_stack: k`` the observation is the last k of these rows,
oldest first.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

__all__ = ["Entry", "ENTRIES", "LAYOUT_FIELDS", "Layout", "layout", "doc_table", "N_SLOTS"]


@dataclass(frozen=True)
class Entry:
    """One observation entry: ``size(setup)`` numbers (0: left out), named ``names(setup)``,
    bounded by ``bounds(setup)`` (lists of lows and highs), written by the compiled writer at
    slot ``slot``; ``fields``: the preset fields (and environment keywords) that decide
    whether and how it appears."""

    name: str
    slot: int
    definition: str
    bounds_doc: str
    size: Callable[[Any], int]
    names: Callable[[Any], list[str]]
    bounds: Callable[[Any], tuple[list[float], list[float]]]
    fields: tuple[str, ...] = ()


def _one(name: str) -> Callable[[Any], list[str]]:
    return lambda setup: [name]


def _vibration_bounds(setup: Any) -> tuple[list[float], list[float]]:
    vb = setup.vibration_bound
    return [-vb], [vb]


ENTRIES: tuple[Entry, ...] = (
    Entry("rotor_speed", 0, "w / w_op", "[0, 1]; RunUpTorque [-overspeed, overspeed]",
          size=lambda setup: 1, names=_one("rotor_speed"),
          bounds=lambda setup: tuple([v] for v in setup.actions.speed_bounds(setup.config))),
    Entry("vibration_x", 1, "(x - x_rest) / A_v, housing displacement, fixed frame",
          "[-c/A_v, c/A_v]", size=lambda setup: 1, names=_one("vibration_x"),
          bounds=_vibration_bounds),
    Entry("vibration_y", 2, "(y - y_rest) / A_v", "[-c/A_v, c/A_v]", size=lambda setup: 1,
          names=_one("vibration_y"), bounds=_vibration_bounds),
    Entry("vibration_amplitude", 3, "filtered vibration radius / A_v", "[0, c/A_v]",
          size=lambda setup: 1, names=_one("vibration_amplitude"),
          bounds=lambda setup: ([0.0], [setup.vibration_bound])),
    Entry("time_fraction", 4, "t / episode_length; only with ``observe_time`` (default on)",
          "[0, 1]", size=lambda setup: 1 if setup.config.observe_time else 0,
          names=_one("time_fraction"), bounds=lambda setup: ([0.0], [1.0]),
          fields=("observe_time",)),
    Entry("last_action", 5, "the last action after clipping (one entry per action)",
          "[-1, 1]", size=lambda setup: setup.n_actions,
          names=lambda setup: [f"last_action[{a}]" for a in range(setup.n_actions)],
          bounds=lambda setup: ([-1.0] * setup.n_actions, [1.0] * setup.n_actions)),
    Entry("sync_vibration", 6, "``sync_amplitude`` (synchronous 1x vibration amplitude / A_v), "
          "then ``sync_cos``, ``sync_sin`` (its phase from the rotor's reference mark); only "
          "with ``sync_vibration.enabled``", "[0, c/A_v], [-1, 1], [-1, 1]",
          size=lambda setup: 3 if setup.config.sync_vibration.enabled else 0,
          names=lambda setup: ["sync_amplitude", "sync_cos", "sync_sin"],
          bounds=lambda setup: ([0.0, -1.0, -1.0], [setup.vibration_bound, 1.0, 1.0]),
          fields=("sync_vibration",)),
    Entry("redistributions", 7, "redistributions of the laundry so far / "
          "``redistribution.max_count``; only with ``redistribution.enabled``", "[0, 1]",
          size=lambda setup: 1 if setup.config.redistribution.enabled else 0,
          names=_one("redistributions"), bounds=lambda setup: ([0.0], [1.0]),
          fields=("redistribution",)),
    Entry("ball_angles", 8, "cos, sin(ball_angle[i]) for each ball (from the imbalance); "
          "only with ``observe_balls=True``", "[-1, 1]",
          size=lambda setup: 2 * setup.scene.ball_count if setup.observe_balls else 0,
          names=lambda setup: [f"{fn}(ball_angle[{k}])" for k in range(setup.scene.ball_count)
                               for fn in ("cos", "sin")],
          bounds=lambda setup: ([-1.0] * (2 * setup.scene.ball_count),
                                [1.0] * (2 * setup.scene.ball_count)),
          fields=("observe_balls",)),
)

#: slots of the compiled writer (``cfg[C_OBS + slot]`` holds the entry's offset)
N_SLOTS = len(ENTRIES)
assert [e.slot for e in ENTRIES] == list(range(N_SLOTS))

#: the preset fields (and environment keywords) that change the observation's layout, and so
#: the contract between a trained policy and its environment (``frame_stack`` repeats it)
LAYOUT_FIELDS: tuple[str, ...] = tuple(dict.fromkeys(
    [f for e in ENTRIES for f in e.fields if f != "observe_balls"] + ["frame_stack"]))


@dataclass(frozen=True)
class Layout:
    """One environment's observation: ``offsets[slot]`` (-1: left out), one frame's size
    ``frame_dim``, its names and bounds, and the stacked observation's (``frame_stack``)."""

    offsets: tuple[int, ...]
    frame_dim: int
    frame_names: tuple[str, ...]
    low: tuple[float, ...]
    high: tuple[float, ...]
    frame_stack: int

    @property
    def obs_dim(self) -> int:
        return self.frame_stack * self.frame_dim

    @property
    def names(self) -> list[str]:
        """Every entry's name; with a frame stack "name@t-2" is the entry two control steps
        back (frames oldest first)."""
        k = self.frame_stack
        if k == 1:
            return list(self.frame_names)
        return [n if k - 1 - j == 0 else f"{n}@t-{k - 1 - j}"
                for j in range(k) for n in self.frame_names]


def layout(setup: Any) -> Layout:
    """The observation of an environment (:class:`~abb_gym.envs.setup.EnvSetup` ``setup``)."""
    offsets = []
    names: list[str] = []
    low: list[float] = []
    high: list[float] = []
    for entry in ENTRIES:
        size = entry.size(setup)
        if size == 0:
            offsets.append(-1)
            continue
        offsets.append(len(names))
        names += entry.names(setup)
        lo, hi = entry.bounds(setup)
        low += lo
        high += hi
    return Layout(tuple(offsets), len(names), tuple(names), tuple(low), tuple(high),
                  int(setup.config.frame_stack))


def doc_table() -> str:
    """A Markdown table of the entries (the environments' documentation)."""
    rows = ["| Entry | Definition | Bounds |", "|---|---|---|"]
    rows += [f"| {e.name} | {e.definition} | {e.bounds_doc} |" for e in ENTRIES]
    return "\n".join(rows)
