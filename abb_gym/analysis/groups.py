"""Dimensionless groups of the constant-speed balancer (Lu & Hung 2008, eq. 9, extended).

Lu & Hung scale lengths by the disk eccentricity ``e``, time by ``w_n = sqrt(K/M)`` and masses
by the total mass ``M``.  Their groups, plus three extensions that the shipped scenes need:

{table}

The ranges keep the linear algebra finite: beyond them (``mu = 5e-324``, ``zeta = 1e308``)
the eigenvalue problems are singular or overflow, so a group outside its range is a
ValueError naming it.  The ball count is a scene's (at most 64); the family sampling of
:func:`abb_gym.analysis.rotating_frame.balanced_family` bounds its work separately.

The speed ratio ``Omega = w / w_n`` is an argument of every analysis, not a group.

Scale invariance (recorded decision).  Only ``eta``, ``mu/delta = m_d e/(M d)`` (equivalently
the ball-to-total mass ratio ``m_b/M = mu eta/delta``), the damping ratios, ``spin`` and
``E/d`` change the dynamics: choosing a different length ``e`` multiplies ``mu`` and ``delta``
(and ``E/e``) by the same factor and only rescales the amplitudes.  :meth:`Groups.from_scene`
therefore needs a length; it uses the scene's ``rotor_eccentricity`` unless told otherwise.
(The scene ``lu_hung_odd3`` is built for ``mu = 0.9, delta = 20``, i.e. ``e = d/20 = 0.5 mm``;
with its rotor eccentricity 0.4757 mm it maps to ``mu = 0.946, delta = 21.02`` - the same
system, ``mu/delta = 0.045`` in both.)

The mass balance ``mu (1 + n eta/delta) <= 1`` is not enforced: Rezaee & Fathi's convention
``mu_d = 1 - mbar`` violates it slightly and their results are reproduced with it.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..physics.scene import Scene

__all__ = ["Groups", "GROUP_FIELDS", "DEFINITIONS"]

# name -> (lower bound, lower bound inclusive, per-ball allowed)
# group -> (lower bound, lower bound included, upper bound (included), one value per ball)
_BOUNDS = {
    "eta": (0.0, False, 1e6, True),
    "mu": (1e-6, True, 1e6, False),
    "delta": (1e-6, True, 1e9, False),
    "zeta": (0.0, True, 1e6, False),
    "zeta_b": (0.0, True, 1e6, True),
    "spin": (0.0, True, 1e3, True),
    "race_eccentricity": (0.0, True, 1e6, False),
    "race_angle": (None, True, None, False),
}
MAX_BALLS = 64  # the largest ball_count of a Scene
GROUP_FIELDS = ("n_balls",) + tuple(_BOUNDS)

#: name -> (formula, unit, meaning) of every group, of ``eta_total`` and of the speed ratio
#: ``Omega`` (the module docstring's table and the stability maps' axis labels)
DEFINITIONS = {
    "n_balls": ("n", "-", "number of balls"),
    "eta": ("m_b d / (m_d e)", "-", "one ball's imbalance over the rotor's (one number, or "
                                    "one per ball)"),
    "mu": ("m_d / M", "-", "imbalanced disk mass over the total mass"),
    "delta": ("d / e", "-", "race radius over the disk eccentricity"),
    "zeta": ("C / (2 M w_n)", "-", "support damping ratio (stationary damper)"),
    "zeta_b": ("C_B / (2 m_b w_n)", "-", "race damping ratio of a ball (one or one per ball); "
                                        "the drag torque is C_B d^2 beta'"),
    "spin": ("J_b / (m_b r_b^2)", "-", "rolling-ball spin inertia factor (0 for Lu & Hung's "
                                      "point masses, 0.4 for a solid rolling sphere)"),
    "race_eccentricity": ("E / e", "-", "offset of the race centre from the rotor centre"),
    "race_angle": ("gamma", "rad", "direction of that offset, from the imbalance"),
    "eta_total": ("sum eta_i", "-", "the balls' total imbalance over the rotor's"),
    "Omega": ("w / w_n", "-", "rotor speed over the undamped natural frequency "
                              "w_n = sqrt(K/M)"),
}


def _range_text(name: str) -> str:
    if name == "n_balls":
        return f"1 .. {MAX_BALLS}"
    lo, incl, hi, _ = _BOUNDS[name]
    if lo is None:
        return "finite"
    return f"{'[' if incl else '('}{lo:g}, {hi:g}]"


def _table() -> str:
    import textwrap
    rows = [(name, f"{DEFINITIONS[name][0]}: {DEFINITIONS[name][2]}"
             + ("" if DEFINITIONS[name][1] == "-" else f" [{DEFINITIONS[name][1]}]"),
             _range_text(name)) for name in GROUP_FIELDS]
    widths = (18, 59, 14)
    rule = "  ".join("=" * w for w in widths)
    lines = [rule, "  ".join(h.ljust(w) for h, w in zip(("group", "definition", "range"),
                                                          widths)).rstrip(), rule]
    for name, text, rng in rows:
        wrapped = textwrap.wrap(text, widths[1])
        lines.append(f"{name:<18}  {wrapped[0]:<59}  {rng}".rstrip())
        lines.extend(f"{'':<18}  {more}".rstrip() for more in wrapped[1:])
    return "\n".join([*lines, rule])


__doc__ = __doc__.replace("{table}", _table())


def _check(name: str, value: Any) -> float:
    lo, incl, hi, _ = _BOUNDS[name]
    if isinstance(value, (bool, np.bool_, bytes)):  # True is not a number here
        raise ValueError(f"group {name!r} must be a number (got {value!r:.80})")
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"group {name!r} must be a number (got {value!r:.80})") from None
    if not math.isfinite(v):
        raise ValueError(f"group {name!r} must be finite (got {v})")
    if (lo is not None and (v < lo or (v == lo and not incl))) or (hi is not None and v > hi):
        low = "" if lo is None else f"{'>=' if incl else '>'} {lo:g}"
        high = "" if hi is None else f"<= {hi:g}"
        raise ValueError(f"group {name!r} must be {' and '.join(t for t in (low, high) if t)} "
                         f"(got {v:g})")
    return v


@dataclass(frozen=True)
class Groups:
    """Dimensionless groups of one balancer (see the module docstring for each field).

    Defaults are the set the physics note fitted to Lu & Hung's Fig. 5 (mu = 0.9, delta = 20,
    zeta = zeta_b = 0.1) with the paper's eta = 0.4 and three point-mass balls.
    """

    eta: float | tuple[float, ...] = 0.4
    n_balls: int = 3
    mu: float = 0.9
    delta: float = 20.0
    zeta: float = 0.1
    zeta_b: float | tuple[float, ...] = 0.1
    spin: float | tuple[float, ...] = 0.0
    race_eccentricity: float = 0.0
    race_angle: float = 0.0

    def __post_init__(self) -> None:
        n = self.n_balls
        if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, np.integer)) or n < 1 \
                or n > MAX_BALLS:
            raise ValueError(f"group 'n_balls' must be an integer in [1, {MAX_BALLS}] (got "
                             f"{n!r:.80})")
        object.__setattr__(self, "n_balls", int(n))
        for name, (_, _, _, per_ball) in _BOUNDS.items():
            v = getattr(self, name)
            if per_ball and isinstance(v, (list, tuple, np.ndarray)):
                vals = tuple(_check(name, x) for x in v)
                if len(vals) == 1:
                    vals = vals[0]
                elif len(vals) != n:
                    raise ValueError(f"group {name!r} has {len(vals)} values; it needs one or "
                                     f"n_balls = {n}")
                elif len(set(vals)) == 1:
                    vals = vals[0]
                object.__setattr__(self, name, vals)
            else:
                object.__setattr__(self, name, _check(name, v))

    # ------------------------------------------------------------------ per-ball views
    def per_ball(self, name: str) -> np.ndarray:
        """A per-ball group (``eta``, ``zeta_b``, ``spin``) as an array of length n_balls."""
        v = getattr(self, name)
        if isinstance(v, tuple):
            return np.asarray(v, dtype=float)
        return np.full(self.n_balls, float(v))

    @property
    def identical_balls(self) -> bool:
        """True when every per-ball group is the same for all balls."""
        return not any(isinstance(getattr(self, k), tuple) for k in ("eta", "zeta_b", "spin"))

    @property
    def eta_total(self) -> float:
        """Sum of the ball imbalances over the rotor imbalance, sum eta_i [-]."""
        return float(np.sum(self.per_ball("eta")))

    @property
    def ball_mass_ratio(self) -> np.ndarray:
        """m_b,i / M = mu eta_i / delta per ball [-]."""
        return self.mu * self.per_ball("eta") / self.delta

    @property
    def can_balance(self) -> bool:
        """Whether a perfectly balanced state exists (E = 0): the largest ball imbalance minus
        the others must not exceed 1 and the sum must reach 1 (n eta >= 1 for equal balls)."""
        eta = self.per_ball("eta")
        return bool(eta.sum() >= 1.0 - 1e-12 and 2 * eta.max() - eta.sum() <= 1.0 + 1e-12)

    def replace(self, **changes: Any) -> "Groups":
        """A copy with some groups changed.  ``eta_total`` sets eta = eta_total / n_balls
        (the total ball mass, hence M, stays the same when n_balls changes with it)."""
        changes = dict(changes)
        if "eta_total" in changes:
            total = _check("eta", changes.pop("eta_total"))
            n = changes.get("n_balls", self.n_balls)
            # a ball count that is no count (0, 2.5, "x") is refused by __post_init__, naming
            # it: no int() that truncates, no division by zero here
            valid = isinstance(n, (int, np.integer)) and not isinstance(n, (bool, np.bool_)) \
                and n >= 1
            changes["eta"] = total / int(n) if valid else total
        elif "n_balls" in changes and isinstance(self.eta, tuple) and "eta" not in changes:
            raise ValueError("changing 'n_balls' of groups with per-ball eta needs a new 'eta' "
                             "or 'eta_total'")
        if "n_balls" in changes:
            for k in ("zeta_b", "spin"):
                if isinstance(getattr(self, k), tuple) and k not in changes:
                    changes[k] = float(np.mean(getattr(self, k)))
        unknown = sorted(set(changes) - set(GROUP_FIELDS))
        if unknown:
            raise ValueError(f"unknown group(s) {unknown}; allowed: {list(GROUP_FIELDS)} and "
                             f"'eta_total'")
        return dataclasses.replace(self, **changes)

    def with_ball_count(self, n: int) -> "Groups":
        """The balancer with ``n`` balls of the same total ball mass (eta_total kept)."""
        return self.replace(n_balls=n, eta_total=self.eta_total)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_scene(cls, scene: Scene, length_scale: float | None = None) -> "Groups":
        """Groups of a :class:`~abb_gym.physics.scene.Scene` (isotropic support required).

        ``length_scale`` [m] is Lu & Hung's ``e`` (default: ``scene.rotor_eccentricity``; it only
        rescales mu, delta and amplitudes, see the module docstring).  Time scale
        ``w_n = sqrt(k/M)`` with M the total mass.  Ball spin inertia enters as ``spin``; rolling
        resistance is not part of the constant-speed linear model and is ignored (it is a
        set-valued friction law at rest).  Raises ValueError for an orthotropic support or a
        scene without primary imbalance.
        """
        if scene.support_stiffness_x != scene.support_stiffness_y or \
                scene.support_damping_x != scene.support_damping_y:
            raise ValueError(
                f"scene {scene.name!r}: support_stiffness_x/_y and support_damping_x/_y must be "
                f"equal for the rotating-frame groups (orthotropic supports: use "
                f"abb_gym.analysis.spannan)")
        if scene.imbalance <= 0:
            raise ValueError(f"scene {scene.name!r}: field 'rotor_eccentricity' must be > 0 for "
                             f"the Lu & Hung groups (they are relative to the rotor imbalance)")
        try:
            e = scene.rotor_eccentricity if length_scale is None else float(length_scale)
        except (TypeError, ValueError, OverflowError):
            e = math.nan
        if not (math.isfinite(e) and e > 0):
            raise ValueError(f"length_scale must be > 0 [m] (got {length_scale!r:.80})")
        big_m = scene.total_mass
        k = scene.support_stiffness_x
        wn = math.sqrt(k / big_m)
        a = scene.arrays()
        m_d = scene.imbalance / e          # the mass that carries U0 at radius e
        r = scene.race_radius
        eta = tuple(a["ball_mass"] * r / scene.imbalance)
        zeta_b = tuple(a["ball_drag"] / (2.0 * a["ball_mass"] * wn))
        try:
            return cls(eta=eta, n_balls=scene.ball_count, mu=m_d / big_m, delta=r / e,
                       zeta=scene.support_damping_x / (2.0 * big_m * wn), zeta_b=zeta_b,
                       spin=tuple(a["ball_inertia_factor"]),
                       race_eccentricity=scene.race_eccentricity / e,
                       race_angle=scene.race_eccentricity_angle)
        except ValueError as exc:  # a group out of its range: say where it came from
            raise ValueError(f"scene {scene.name!r} with length_scale e = {e:g} m: {exc}") \
                from None

    @classmethod
    def from_rezaee_fathi(cls, mbar: float, epsbar: float, zeta: float, beta: float,
                          n_balls: int = 3, mu_d: float | None = None,
                          race_radius: float = 1.0) -> "Groups":
        """The conventional balancer of Rezaee & Fathi (2015) in Lu & Hung's groups.

        mbar = m_b/M, epsbar = e/lambda, beta = c_r/(2 m_b w_n), race radius R/lambda
        (1 in the paper).  mu_d = m_d/M defaults to the paper's 1 - mbar (the physics note
        recommends 1 - n mbar; thresholds move by about 0.01).  Map (note part C):
        mu = mu_d, eta = mbar R/(mu_d epsbar), delta = R/epsbar, zeta_b = beta.
        """
        mu = 1.0 - mbar if mu_d is None else mu_d
        return cls(eta=mbar * race_radius / (mu * epsbar), n_balls=n_balls, mu=mu,
                   delta=race_radius / epsbar, zeta=zeta, zeta_b=beta)

    def to_scene(self, name: str = "from_groups", natural_frequency: float = 100.0,
                 total_mass: float = 0.1, length_scale: float = 5e-4,
                 ball_radius: float | None = None) -> Scene:
        """A physical :class:`Scene` with these groups (for :func:`abb_gym.simulate`).

        ``natural_frequency`` w_n [rad/s], ``total_mass`` M [kg] and ``length_scale`` e [m]
        fix the units; the rest follows: d = delta e, m_b = mu eta M/delta, k = M w_n^2,
        C = 2 zeta M w_n, C_B = 2 zeta_b m_b w_n, U0 = mu M e.  The default ball radius is
        d/10 (it only matters through ``spin``).
        """
        for label, v in (("natural_frequency", natural_frequency), ("total_mass", total_mass),
                         ("length_scale", length_scale)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{label} must be > 0 (got {v!r})")
        e, big_m, wn = float(length_scale), float(total_mass), float(natural_frequency)
        d = self.delta * e
        m_b = self.mu * self.per_ball("eta") * big_m / self.delta
        rotor_mass = big_m - float(m_b.sum())
        if rotor_mass <= 0:
            raise ValueError(f"groups give ball mass {m_b.sum():g} kg >= total_mass "
                             f"{big_m:g} kg; increase delta or decrease mu*eta")
        u0 = self.mu * big_m * e
        return Scene(
            name=name, rotor_mass=rotor_mass, rotor_eccentricity=u0 / rotor_mass,
            rotor_polar_inertia=big_m * d * d, support_stiffness_x=big_m * wn * wn,
            support_stiffness_y=big_m * wn * wn, support_damping_x=2 * self.zeta * big_m * wn,
            support_damping_y=2 * self.zeta * big_m * wn, race_radius=d,
            ball_count=self.n_balls, ball_mass=tuple(m_b),
            ball_radius=(d / 10.0 if ball_radius is None else ball_radius,) * self.n_balls,
            ball_drag=tuple(2 * self.per_ball("zeta_b") * m_b * wn),
            ball_inertia_factor=tuple(self.per_ball("spin")),
            ball_rolling_resistance=(0.0,) * self.n_balls,
            ball_angles0=(0.0,) * self.n_balls,
            race_eccentricity=self.race_eccentricity * e, race_eccentricity_angle=self.race_angle,
            drive_torque_limit=1.0, drive_max_acceleration=10.0 * wn,
            drive_operating_speed=2.0 * wn, housing_clearance=1e3 * e,
            description="generated from dimensionless groups", source="abb_gym.analysis.groups")
