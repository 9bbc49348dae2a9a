"""abb-gym: Gymnasium environments and a simulator for automatic ball balancers."""
from ._jit_cache import flush_if_sources_changed

flush_if_sources_changed()  # before any compiled module loads a stale cache

from .physics import (MotorDrive, Scene, SceneError, SimulationError, SpeedProfile, Trajectory,
                      list_scenes, load_scene, simulate)  # noqa: E402
from . import envs  # noqa: E402  registers abb_gym/RunUpTorque-v0, RunUpSpeed-v0, DwellProfile-v0

__version__ = "0.1.0"
__all__ = ["MotorDrive", "Scene", "SceneError", "SimulationError", "SpeedProfile", "Trajectory",
           "list_scenes", "load_scene", "simulate", "envs", "__version__"]
