"""abb-gym: Gymnasium environments and a simulator for automatic ball balancers."""
import os

# numba's OpenMP threads otherwise spin after each parallel environment step and slow a torch
# policy in the same process 5-20x (measured during PPO training); set before numba loads
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from ._jit_cache import flush_if_sources_changed  # noqa: E402

flush_if_sources_changed()  # before any compiled module loads a stale cache

from .physics import (MotorDrive, Scene, SceneError, SimulationError, SpeedProfile, Trajectory,
                      list_scenes, load_scene, simulate)  # noqa: E402
from . import envs  # noqa: E402  registers abb_gym/RunUpTorque-v0, RunUpSpeed-v0, DwellProfile-v0

__version__ = "0.1.0"
__all__ = ["MotorDrive", "Scene", "SceneError", "SimulationError", "SpeedProfile", "Trajectory",
           "list_scenes", "load_scene", "simulate", "envs", "__version__"]
