"""Physics of the rotor with an automatic ball balancer: scenes, equations, drives, integrators."""
from .drives import MotorDrive, SpeedProfile
from .scene import Scene, SceneError, list_scenes, load_scene
from .simulate import SimulationError, Trajectory, simulate

__all__ = ["MotorDrive", "SpeedProfile", "Scene", "SceneError", "list_scenes", "load_scene",
           "SimulationError", "Trajectory", "simulate"]
