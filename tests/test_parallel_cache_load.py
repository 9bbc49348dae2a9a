"""A serial wrapper of a parallel kernel, loaded from numba's cache in a fresh process.

numba 0.68 gives a compiled caller the hook that restarts the parallel runtime on load only
when its ``parallel=True`` callee was compiled, not loaded from the cache, in the same process.
A wrapper compiled over a cached callee then aborts the next fresh process that loads it
("LLVM ERROR: Symbol not found: allocate_sched"): ``abb-gym evaluate --scene spannan_cfrp``
did so after ``make setup``.  ``Specialised(..., parallel=True)`` starts the runtime first.

Each case runs the three processes that make the state: the first compiles callee and wrapper,
the wrapper's cache files are deleted, the second compiles the wrapper over the cached callee,
the third loads both.  ``NUMBA_CACHE_DIR`` keeps the package's own cache out of it.
"""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

STAND_IN = textwrap.dedent('''
    import sys
    import numpy as np
    from numba import njit, prange
    from abb_gym.physics.specialise import Specialised

    @njit(cache=True, parallel=True)
    def _fill(x, k):
        for i in prange(x.shape[0]):
            x[i] = i * k

    @njit(cache=True)
    def _wrapper(x, k):
        _fill(x, k)

    step = Specialised(_wrapper, literal=(1,), parallel=sys.argv[1] == "parallel")
    x = np.zeros(1000)
    step(x, 3)
    print("sum", x.sum())
''')


def _three_processes(argv: list[str], cache: Path, wrapper_glob: str, cwd: Path
                     ) -> list[subprocess.CompletedProcess]:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    runs = []
    for k in range(3):
        runs.append(subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True,
                                   timeout=600))
        if k == 0:
            assert runs[0].returncode == 0, runs[0].stderr[-2000:]
            wrappers = list(cache.rglob(wrapper_glob))
            assert wrappers, f"no cache file {wrapper_glob} under {cache}"
            for f in wrappers:
                f.unlink()
    return runs


@pytest.mark.parametrize("parallel", [True, False])
def test_a_wrapper_compiled_over_a_cached_parallel_callee_loads(tmp_path, parallel):
    """With the flag the third process runs; without it, numba's bug aborts it (checked too,
    so that this test shows it still reproduces the failure it guards against)."""
    (tmp_path / "stand_in.py").write_text(STAND_IN)
    flag = "parallel" if parallel else "serial"
    runs = _three_processes([sys.executable, "stand_in.py", flag], tmp_path / "cache",
                            "stand_in._wrapper-*", tmp_path)
    assert runs[1].returncode == 0, runs[1].stderr[-2000:]
    third = runs[2]
    if parallel:
        assert third.returncode == 0, third.stderr[-2000:]
        assert f"sum {3 * 999 * 1000 / 2}" in third.stdout
    else:
        assert third.returncode != 0, (
            "numba loaded the wrapper without its parallel runtime: the bug this guards "
            "against is gone from this numba, and Specialised(parallel=True) may be dropped")
        assert "allocate_sched" in third.stderr or third.returncode < 0


def test_the_environment_kernels_that_call_parallel_code_say_so():
    from abb_gym.envs import kernel
    assert kernel.step_parallel.parallel and not kernel.step_serial.parallel


@pytest.mark.slow
def test_an_evaluation_loads_the_cached_parallel_step_in_a_fresh_process(tmp_path):
    """The failure as users met it, on the general kernel (about a minute: the first process
    compiles it)."""
    script = tmp_path / "evaluate4.py"
    script.write_text(textwrap.dedent('''
        from abb_gym.evaluation.evaluate import evaluate
        r = evaluate("abb_gym/RunUpSpeed-v0", "spannan_cfrp", "baseline:ramp", episodes=4)
        print("run-up", r.summary()["run_up_time"]["mean"])
    '''))
    runs = _three_processes([sys.executable, str(script)], tmp_path / "cache",
                            "kernel._step_parallel_packed-*", tmp_path)
    for run in runs:
        assert run.returncode == 0, run.stderr[-2000:]
    assert runs[2].stdout == runs[0].stdout
