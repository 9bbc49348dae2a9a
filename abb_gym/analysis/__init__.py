"""Equilibria and stability of automatic ball balancers at constant speed.

Modules (each documents its equations, units and the decisions taken where a source and the
physics notes disagree):

* :mod:`.groups` - Lu & Hung's dimensionless groups (:class:`Groups`), from a Scene or from
  Rezaee & Fathi's parameters, and back to a Scene.
* :mod:`.lu_hung` - closed forms of Lu & Hung (2008) eqs. 14-36: existence ``n eta >= 1``,
  allowed ball range, two- and three-ball positions, unbalanced branches, saddle-nodes.
* :mod:`.rotating_frame` - the n-ball system in the rotating frame (race eccentricity
  included): all equilibria, exact linearisation, eigenvalues with the balanced family's
  structural zeros removed, family stability (union and per member).
* :mod:`.spannan` - Spannan (2021): averaged stationary states with eccentricity and
  orthotropy (4.30-4.67), averaged stability matrices (row-4 misprint fixed), border speed
  (4.74), beta_min (4.75), one ball (A.7), capacity (2.3).
* :mod:`.maps` - stability maps over any two parameters (PNG + CSV, overlays, processes).
* :mod:`.timedomain` - the same questions answered by :func:`abb_gym.simulate`.

The Rezaee & Fathi spring-and-rod balancer is a different model: see
:mod:`abb_gym.physics.rezaee_fathi`.
"""
from . import lu_hung, maps, rotating_frame, spannan, timedomain
from .groups import GROUP_FIELDS, Groups
from .lu_hung import (allowed_ball_range, balance_exists, saddle_node_speeds,
                      three_ball_positions, two_ball_positions, unbalanced_branches)
from .maps import StabilityMap, onset_speed, stability_map
from .rotating_frame import (Equilibrium, FamilyStability, balanced_family, eigenvalues,
                             equilibria, family_stability, jacobian, unbalanced_equilibria)
from .spannan import (SpannanParameters, averaged_eigenvalues, averaged_matrices,
                      border_speed, capacity, eigenvalue_border, minimum_drag,
                      one_ball_border_speed)
from .timedomain import clumped_whirl, run_from_equilibrium, settle

__all__ = [
    "Groups", "GROUP_FIELDS",
    "balance_exists", "allowed_ball_range", "two_ball_positions", "three_ball_positions",
    "unbalanced_branches", "saddle_node_speeds",
    "Equilibrium", "FamilyStability", "equilibria", "unbalanced_equilibria", "balanced_family",
    "family_stability", "jacobian", "eigenvalues",
    "SpannanParameters", "averaged_matrices", "averaged_eigenvalues", "eigenvalue_border",
    "border_speed", "minimum_drag", "one_ball_border_speed", "capacity",
    "StabilityMap", "stability_map", "onset_speed",
    "settle", "run_from_equilibrium", "clumped_whirl",
    "lu_hung", "rotating_frame", "spannan", "maps", "timedomain",
]
