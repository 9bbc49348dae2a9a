"""Names of the integration methods (no compiled code: the command line lists them without
loading numba).  The methods themselves: :mod:`abb_gym.physics.integrators` (compiled) and
:func:`abb_gym.physics.simulate.simulate` (those and scipy's ``solve_ivp``)."""
from __future__ import annotations

__all__ = ["METHOD_RK4", "METHOD_DOPRI5", "METHOD_ROS2", "METHOD_ETDRK4", "METHOD_IDS",
           "FIXED_STEP", "COMPILED_METHODS", "SCIPY_METHODS", "METHODS", "PRECISIONS"]

# integer ids the compiled kernels branch on
METHOD_RK4 = 0
METHOD_DOPRI5 = 1
METHOD_ROS2 = 2
METHOD_ETDRK4 = 3
METHOD_IDS = {"rk4": METHOD_RK4, "dopri5": METHOD_DOPRI5, "etdrk4": METHOD_ETDRK4,
              "ros2": METHOD_ROS2}
FIXED_STEP = ("rk4", "etdrk4", "ros2")

COMPILED_METHODS = tuple(METHOD_IDS)
SCIPY_METHODS = ("DOP853", "Radau", "RK45", "LSODA", "BDF")
METHODS = COMPILED_METHODS + SCIPY_METHODS

# arithmetic of the batched RK4 blocks (:mod:`abb_gym.physics.batch`, "Precision")
PRECISIONS = ("float64", "float32")
