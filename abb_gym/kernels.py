"""Compiled kernels ahead of time: ``abb-gym build-kernels`` and the caches in the wheel.

numba compiles every kernel on its first call (the general kernels of ``simulate`` and the
environments take 20-50 s each, a kernel specialised on a scene as long) and keeps the result
in its on-disk cache, ``abb_gym/_kernels`` (:mod:`abb_gym._jit_cache`), keyed by the content
of the compiled modules and by the CPU.  :func:`build` makes those calls once, in one go and with a progress
bar, so that the caches hold:

* the general kernels: ``simulate`` with every compiled method, the single environment, the
  native vector environment and batch simulation (one compilation serves every scene and
  every action type);
* the kernels specialised on the default scene (``yoshida_odd``) for the speed-profile and
  torque actions: vectorised for the vector environments of the training configurations, and
  on one lane for the single environment, which takes them whenever they need no compiling
  (it runs more steps per second than the general kernel on one lane; ``abb-gym bench
  speed`` measures both).

The wheel ships these caches (``make wheel`` runs :func:`build` first), so a fresh install on
a machine of the same CPU type starts without compiling; on another CPU, or for another
scene's vectorised kernel, numba compiles on first use and says so on stderr while it runs
(:func:`abb_gym.physics.specialise.compile_notice`).  A site-packages folder that is not
writable cannot serve its caches either (numba needs its cache folder writable): numba's
per-user cache is used, and the kernels compile there once.
"""
from __future__ import annotations

import time
from typing import Callable

__all__ = ["build", "warm_up_steps"]


def _simulate():
    from .physics import MotorDrive, SpeedProfile, simulate
    for method in ("rk4", "etdrk4", "dopri5", "ros2"):
        simulate("yoshida_odd", SpeedProfile.ramp(40.0, 130.0), 0.01, method=method)
    simulate("yoshida_odd", MotorDrive.constant_torque(0.1), 0.01)


def _env(kind: str) -> Callable[[], None]:
    def run():
        import gymnasium as gym
        from . import envs  # noqa: F401  (registers the ids)
        env = gym.make(kind)
        env.reset(seed=0)
        env.step(env.action_space.sample())
    return run


def _vector(kind: str, kernel: str, num_envs: int) -> Callable[[], None]:
    def run():
        import gymnasium as gym
        import numpy as np
        from . import envs  # noqa: F401
        env = gym.make_vec(kind, num_envs=num_envs, vectorization_mode="vector_entry_point",
                           kernel=kernel)
        env.reset(seed=0)
        env.step(env.action_space.sample())
        env.step(np.zeros(env.action_space.shape))  # float64 actions (envs.step_rows)
    return run


def _batch():
    import numpy as np
    from .physics import SpeedProfile, batch, load_scene
    scene = load_scene("yoshida_odd")
    inputs = batch.run_inputs([scene, scene], SpeedProfile.ramp(40.0, 130.0), 1.0, 130.0)
    s0 = inputs[0]
    batch.run_batch(s0, np.array([0.0, 0.01]), *inputs[1:],
                    np.empty((len(s0), 2, s0.shape[1])), np.zeros((len(s0), 4)))


def warm_up_steps() -> list[tuple[str, Callable[[], None]]]:
    """The calls :func:`build` makes, with a label each."""
    from .envs.tasks import DWELL_PROFILE, RUN_UP_SPEED, RUN_UP_TORQUE
    speed, torque, dwell = RUN_UP_SPEED.env_id, RUN_UP_TORQUE.env_id, DWELL_PROFILE.env_id
    return [
        ("simulate (general kernel, every method)", _simulate),
        ("single environment (general kernel)", _env(speed)),
        ("single environment, torque and dwell", lambda: (_env(torque)(), _env(dwell)())),
        ("vector environment (general kernel)", _vector(speed, "generic", 4)),
        ("batch simulation (general kernel)", _batch),
        ("vector environment, yoshida_odd speed (vectorised)", _vector(speed, "specialised", 32)),
        ("single environment, yoshida_odd speed and torque (specialised)",
         lambda: (_vector(speed, "specialised", 1)(), _vector(torque, "specialised", 1)())),
        ("vector environment, yoshida_odd torque (vectorised)",
         _vector(torque, "specialised", 32)),
    ]


def build(progress: bool = True, steps: list[tuple[str, Callable[[], None]]] | None = None,
          desc: str = "abb-gym kernels") -> list[tuple[str, float]]:
    """Compile (or load) every kernel of ``steps`` (default :func:`warm_up_steps`: all of
    them) into numba's cache, with a bar named ``desc``; returns ``(label, seconds)`` per
    step."""
    import os
    from .progress import ProgressBar
    quiet = os.environ.get("ABB_GYM_QUIET")
    os.environ["ABB_GYM_QUIET"] = "1"  # the bar says what is compiling
    done = []
    try:
        bar = ProgressBar(warm_up_steps() if steps is None else steps, desc=desc,
                          unit="kernel", disable=not progress)
        for label, call in bar:
            bar.set_postfix_str(label)
            start = time.perf_counter()
            call()
            done.append((label, time.perf_counter() - start))
    finally:
        if quiet is None:
            os.environ.pop("ABB_GYM_QUIET", None)
        else:
            os.environ["ABB_GYM_QUIET"] = quiet
    return done
