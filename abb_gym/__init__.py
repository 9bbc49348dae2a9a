"""abb-gym: Gymnasium environments and a simulator for automatic ball balancers.

``import abb_gym`` registers the environment ids and nothing heavier: the simulator's names
(:func:`simulate`, :func:`load_scene`, ...) load numba and the compiled kernels on first use,
so that the import and ``abb-gym --help`` stay under half a second (README "Compiled kernels
and the first start").
"""
import importlib
from typing import TYPE_CHECKING, Any

from ._threads import quiet_openmp

# idle OpenMP workers (numba's, torch's) otherwise spin after each parallel environment step
# and slow PPO training 4-9x, whichever of torch and abb_gym is imported first (see
# abb_gym._threads); before numba loads
quiet_openmp()

from . import envs  # noqa: E402  registers abb_gym/RunUpTorque-v0, RunUpSpeed-v0, DwellProfile-v0

if TYPE_CHECKING:
    from .physics import (MotorDrive, Scene, SceneError, SimulationError, SpeedProfile,
                          Trajectory, list_scenes, load_scene, simulate)

__version__ = "0.1.0"
__all__ = ["MotorDrive", "Scene", "SceneError", "SimulationError", "SpeedProfile", "Trajectory",
           "list_scenes", "load_scene", "simulate", "envs", "__version__"]

_PHYSICS = frozenset(__all__) - {"envs", "__version__"}


def __getattr__(name: str) -> Any:
    if name in _PHYSICS:
        value = getattr(importlib.import_module(".physics", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | _PHYSICS)
