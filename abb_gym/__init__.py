"""abb-gym: Gymnasium environments and a simulator for automatic ball balancers."""
from ._threads import quiet_openmp

# idle OpenMP workers (numba's, torch's) otherwise spin after each parallel environment step
# and slow PPO training 4-9x, whichever of torch and abb_gym is imported first (see
# abb_gym._threads); before numba loads
quiet_openmp()

from ._jit_cache import flush_if_sources_changed, install_locator  # noqa: E402

install_locator()  # compiled kernels are cached in abb_gym/_kernels (shipped in the wheel)
flush_if_sources_changed()  # before any compiled module loads a stale cache

from .physics import (MotorDrive, Scene, SceneError, SimulationError, SpeedProfile, Trajectory,
                      list_scenes, load_scene, simulate)  # noqa: E402
from . import envs  # noqa: E402  registers abb_gym/RunUpTorque-v0, RunUpSpeed-v0, DwellProfile-v0

__version__ = "0.1.0"
__all__ = ["MotorDrive", "Scene", "SceneError", "SimulationError", "SpeedProfile", "Trajectory",
           "list_scenes", "load_scene", "simulate", "envs", "__version__"]
