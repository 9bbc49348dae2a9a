"""abb-gym: Gymnasium environments and a simulator for automatic ball balancers."""
from .physics import (MotorDrive, Scene, SceneError, SimulationError, SpeedProfile, Trajectory,
                      list_scenes, load_scene, simulate)

__version__ = "0.1.0"
__all__ = ["MotorDrive", "Scene", "SceneError", "SimulationError", "SpeedProfile", "Trajectory",
           "list_scenes", "load_scene", "simulate", "__version__"]
