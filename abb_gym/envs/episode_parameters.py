"""The episode parameters, each declared once.

An episode is the environment's nominal scene changed in the parameters below.  Each is
declared once here, as an :class:`EpisodeParameter`; from that declaration come

* the preset's ``randomize`` field of the same name (its range, unit and bounds:
  :class:`abb_gym.envs.config.Randomization` is built from :data:`PARAMETERS`);
* the draw (uniform over the range, in the order declared here, one ``rng.random`` call per
  episode: :mod:`abb_gym.envs.episodes`) and, for the parameters marked ``per_event``, the
  draws of each redistribution of the laundry (:mod:`abb_gym.envs.redistribution`);
* the reset option of the same name (and its alternative units), checked with the bounds
  given here;
* the column of the episode table, the key of the reset ``info`` and the attribute of
  :class:`~abb_gym.envs.episodes.Episode`;
* the machine change it makes (:mod:`abb_gym.physics.variants`: the change of the same name in
  :data:`~abb_gym.physics.variants.CHANGES`, which also gives its nominal value), or its place
  in the initial state;
* the corners of the preset's ranges that are checked when an environment is made (the
  stiffness of its RK4 steps, a machine that exists);
* the table in the environments' documentation (:func:`doc_table`).

A new randomised parameter is one more :class:`EpisodeParameter` here (appended: the draws of
the existing ones stay where they are, so presets that leave it off draw the same episodes)
and its physics use (a change in :mod:`abb_gym.physics.variants`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

from ..physics import variants

__all__ = ["EpisodeParameter", "OptionUnit", "PARAMETERS", "BY_NAME", "RESET_OPTIONS",
           "doc_table", "randomize_fields", "machine_changes"]

PI = math.pi


@dataclass(frozen=True)
class OptionUnit:
    """A reset option that sets a parameter in other units: ``option`` [``unit``] >= ``lower``
    gives the parameter's value ``to_value(scene, option)``."""

    name: str
    unit: str
    lower: float | None
    to_value: Callable[[Any, float], float]


@dataclass(frozen=True)
class EpisodeParameter:
    """One episode parameter (module docstring).

    ``name``: table column, info key (``info_key`` where it differs), reset option and, for a
    ``machine`` parameter, the machine change of that name.
    ``randomize``: the preset's ``randomize`` field (range of the drawn number; default the
    parameter's name) and ``range_spec`` its declaration
    (:func:`abb_gym.configuration.declare` keywords);
    ``from_drawn(scene, u)`` maps a drawn number onto the parameter (default: itself).
    ``nominal(scene)``: the value when the preset does not randomise it (default, for a
    ``machine`` parameter, the machine change's nominal value).
    ``option_lower``/``option_inclusive``: the reset option's bound (None: any finite number);
    ``option_units``: alternative options, mutually exclusive with the main one.
    ``per_ball``: one value per ball.  ``angle``: reduced to [-pi, pi].
    ``machine``: it is the machine change of the same name
    (:data:`abb_gym.physics.variants.CHANGES`); False for a parameter of the initial state
    (phase, ball angles).
    ``step_corner``: the RK4 step depends on it (the preset's corners are checked);
    ``machine_check``: a value may not be a machine (checked at its corners and as an option).
    ``per_event``: drawn again at each redistribution of the laundry.  ``factor``: a factor on
    a scene value (nominal 1), which a training curriculum may narrow towards 1
    (:mod:`abb_gym.rl.curriculum`).
    """

    name: str
    unit: str
    doc: str
    range_spec: dict
    nominal: Callable[[Any], Any] | None = None
    randomize: str = ""
    from_drawn: Callable[[Any, Any], Any] | None = None
    option_lower: float | None = 0.0
    option_inclusive: bool = True
    option_units: tuple[OptionUnit, ...] = ()
    per_ball: bool = False
    angle: bool = False
    machine: bool = False
    step_corner: bool = False
    machine_check: bool = False
    per_event: bool = False
    factor: bool = False
    info_key: str = ""
    extra: dict = field(default_factory=dict)

    def __post_init__(self):
        # frozen: the defaults that come from the name and the machine change are set here
        if not self.randomize:
            object.__setattr__(self, "randomize", self.name)
        if self.machine and self.name not in variants.CHANGES:
            raise ValueError(f"episode parameter {self.name!r} is declared a machine change, "
                             f"but abb_gym.physics.variants.CHANGES has none of that name "
                             f"(it has {list(variants.CHANGES)})")
        if self.nominal is None:
            if not self.machine:
                raise ValueError(f"episode parameter {self.name!r}: give its nominal value "
                                 f"(only a machine change has one by default)")
            object.__setattr__(self, "nominal", variants.CHANGES[self.name].nominal)

    @property
    def key(self) -> str:
        """The key of the reset ``info``."""
        return self.info_key or self.name

    def drawn(self, scene: Any, u):
        """The parameter from the uniform numbers ``u`` mapped onto the range already."""
        return u if self.from_drawn is None else self.from_drawn(scene, u)


def _capacity(scene: Any, ratio):
    return ratio * scene.balancing_capacity


#: Every episode parameter, in the order of the draws (append new ones at the end).
PARAMETERS: tuple[EpisodeParameter, ...] = (
    EpisodeParameter(
        "imbalance", "kg m", "primary imbalance U0 (the load's), drawn as a ratio of the "
        "balancing capacity sum m_i R", randomize="imbalance_ratio",
        range_spec=dict(kind="range", gt=0.0, le=100.0, nullable=True,
                        doc="imbalance / balancing capacity (sum m_i R)"),
        from_drawn=_capacity,
        option_units=(OptionUnit("imbalance_ratio", "-", 0.0, _capacity),),
        machine=True, per_event=True),
    EpisodeParameter(
        "imbalance_phase", "rad", "angle of the imbalance at t = 0 (fixed frame) and from the "
        "rotor's reference mark", nominal=lambda sc: 0.0,
        range_spec=dict(kind="range", unit="rad", ge=-2 * PI, le=2 * PI, nullable=True,
                        doc="angle of the imbalance at t = 0 (fixed frame)"),
        option_lower=None, angle=True, per_event=True),
    EpisodeParameter(
        "ball_angles", "rad", "each ball's initial angle from the imbalance",
        nominal=lambda sc: np.asarray(sc.ball_angles0, dtype=float),
        range_spec=dict(kind="range", unit="rad", ge=-2 * PI, le=2 * PI, nullable=True,
                        doc="each ball's initial angle from the imbalance"),
        option_lower=None, per_ball=True, angle=True, info_key="initial_ball_angles"),
    EpisodeParameter(
        "ball_drag_scale", "-", "factor on the scene's race drag",
        range_spec=dict(kind="range", gt=0.0, le=1e3, nullable=True,
                        doc="factor on the scene's ball_drag"),
        option_inclusive=False, machine=True, step_corner=True, factor=True),
    EpisodeParameter(
        "rolling_resistance_scale", "-", "factor on the scene's rolling resistance",
        range_spec=dict(kind="range", ge=0.0, le=1e3, nullable=True,
                        doc="factor on the scene's ball_rolling_resistance"),
        machine=True, step_corner=True, factor=True),
    EpisodeParameter(
        "critical_speed_scale", "-", "factor s on the critical speeds, through the supported "
        "mass M / s^2 (a load)",
        range_spec=dict(kind="range", gt=0.0, le=10.0, nullable=True,
                        doc="factor s on the critical speeds, through the supported mass "
                            "M / s^2 (a load; module docstring)"),
        option_inclusive=False, machine=True, step_corner=True, machine_check=True,
        factor=True),
    EpisodeParameter(
        "support_damping_scale", "-", "factor on the scene's support damping (both axes)",
        range_spec=dict(kind="range", ge=0.0, le=1e3, nullable=True,
                        doc="factor on the scene's support damping (both axes)"),
        machine=True, step_corner=True, machine_check=True, factor=True),
    EpisodeParameter(
        "fluid_temperature", "K", "temperature of the balancer fluid (its viscosity; scenes "
        "with a fluid preset that has a temperature law)",
        range_spec=dict(kind="range", unit="K", ge=250.0, le=400.0, nullable=True,
                        doc="temperature of the balancer fluid (a wash temperature; scenes "
                            "with an oil of Spannan's Table 6.1)"),
        option_lower=250.0, machine=True, step_corner=True, machine_check=True),
)

BY_NAME: dict[str, EpisodeParameter] = {par.name: par for par in PARAMETERS}


def machine_changes(values: Mapping[str, Any]) -> dict[str, Any]:
    """The machine changes (:mod:`abb_gym.physics.variants`) among the episode ``values``
    (parameter name -> value; those it lacks are left out)."""
    return {par.name: values[par.name] for par in PARAMETERS
            if par.machine and par.name in values}

#: Every reset option: each parameter's name and its alternative units.
RESET_OPTIONS: tuple[str, ...] = tuple(
    name for par in PARAMETERS for name in (par.name, *(u.name for u in par.option_units)))


def randomize_fields() -> list[tuple[str, dict]]:
    """The preset's ``randomize`` fields: (name, declaration keywords), in draw order."""
    return [(par.randomize, par.range_spec) for par in PARAMETERS]


def doc_table() -> str:
    """A Markdown table of the episode parameters (the environments' documentation)."""
    rows = ["| Parameter | Unit | Preset range (``randomize``) | Reset option(s) | Meaning |",
            "|---|---|---|---|---|"]
    for par in PARAMETERS:
        options = ", ".join(f"``{n}``" for n in (par.name, *(u.name for u in par.option_units)))
        rows.append(f"| {par.key} | {par.unit} | ``{par.randomize}`` | {options} | "
                    f"{par.doc}{'; redrawn at each redistribution' if par.per_event else ''} |")
    return "\n".join(rows)
