"""abb-gym: Gymnasium environments and a simulator for automatic ball balancers.

``import abb_gym`` registers the environment ids and nothing heavier: the simulator's names
(:func:`simulate`, :func:`load_scene`, ...) load numba and the compiled kernels on first use,
so that the import and ``abb-gym --help`` stay under half a second (``abb-gym bench speed``
measures both).
"""
from typing import TYPE_CHECKING

from ._lazy import lazy_names
from ._threads import quiet_openmp

# idle OpenMP workers (numba's, torch's) otherwise spin after each parallel environment step
# and slow PPO training 4-9x, whichever of torch and abb_gym is imported first (see
# abb_gym._threads); before numba loads
quiet_openmp()

from . import envs  # noqa: E402  registers the environment ids (abb_gym.envs.tasks)

if TYPE_CHECKING:
    from .physics import (MotorDrive, Scene, SceneError, SimulationError, SpeedProfile,
                          Trajectory, list_scenes, load_scene, simulate)

__version__ = "0.2.0"
__all__ = ["MotorDrive", "Scene", "SceneError", "SimulationError", "SpeedProfile", "Trajectory",
           "list_scenes", "load_scene", "simulate", "envs", "__version__"]

__getattr__, __dir__ = lazy_names(__name__, {name: "physics" for name in __all__
                                            if name not in ("envs", "__version__")})
