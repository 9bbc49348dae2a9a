"""numba's caches of abb-gym's compiled kernels (see :mod:`abb_gym._jit_cache` and
:mod:`abb_gym.kernels`); no code."""
