"""abb-gym: Gymnasium environments and a simulator for automatic ball balancers."""
from .physics import (MotorDrive, Scene, SceneError, SimulationError, SpeedProfile, Trajectory,
                      list_scenes, load_scene, simulate)
from . import envs  # noqa: E402,F401  registers abb_gym/RunUpTorque-v0, RunUpSpeed-v0, DwellProfile-v0

__version__ = "0.1.0"
__all__ = ["MotorDrive", "Scene", "SceneError", "SimulationError", "SpeedProfile", "Trajectory",
           "list_scenes", "load_scene", "simulate", "__version__"]
