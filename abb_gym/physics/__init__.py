"""Physics of the rotor with an automatic ball balancer: scenes, equations, drives, integrators.

The names below load on first use, numba and the compiled modules with them, so that a light
submodule (:mod:`~abb_gym.physics.methods`) and ``abb-gym --help`` need neither.
"""
import sys
import types
from typing import TYPE_CHECKING, Any

from .._lazy import lazy_names

if TYPE_CHECKING:
    from .drives import MotorDrive, SpeedProfile
    from .scene import Scene, SceneError, list_scenes, load_scene
    from .simulate import SimulationError, simulate
    from .trajectory import Trajectory

__all__ = ["MotorDrive", "SpeedProfile", "Scene", "SceneError", "list_scenes", "load_scene",
           "SimulationError", "Trajectory", "simulate"]

_HOME = {"MotorDrive": "drives", "SpeedProfile": "drives", "Scene": "scene",
         "SceneError": "scene", "list_scenes": "scene", "load_scene": "scene",
         "SimulationError": "simulate", "Trajectory": "trajectory", "simulate": "simulate"}


__getattr__, __dir__ = lazy_names(__name__, _HOME)


class _Package(types.ModuleType):
    """This package, whose ``simulate`` stays the function.

    Importing a submodule binds it on its package, so the first import of the module
    :mod:`abb_gym.physics.simulate` (by anything) would make ``abb_gym.physics.simulate`` the
    module instead of the function it exports, as an eager ``from .simulate import simulate``
    used to rebind it."""

    def __setattr__(self, name: str, value: Any) -> None:
        if isinstance(value, types.ModuleType) and _HOME.get(name) == name:
            value = getattr(value, name)
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
