"""The perf map of compiled functions and the profile command (benchmarks.kernel_profile)."""
import shutil
import weakref

import numpy as np
import pytest
from numba import njit

from abb_gym.benchmarks import kernel_profile as kp


def test_readable_name_takes_the_python_name_out_of_numbas_symbol():
    symbol = ("_ZN7abb_gym7physics5model19accelerations_blockB4v130B64c8tJTIeFIjxB2IKSgI4Crv"
              "SCKg1MMbCQQPKkLTj8gMEI8QhUCzB0wCxNAA_3d_3dE5ArrayIdLi1E1C7mutable7alignedE")
    assert kp.readable_name(symbol) == "abb_gym.physics.model.accelerations_block"
    assert kp.readable_name("NRT_decref") == "NRT_decref"
    assert kp.readable_name("_PyEval_EvalFrameDefault") == "_PyEval_EvalFrameDefault"


class _Gone:
    pass


def test_perf_map_names_a_function_compiled_in_this_process(tmp_path):
    """Also with a dead weak proxy among the collector's objects (asking one for its class
    raises ReferenceError; a test run with torch loaded holds some)."""
    gone = _Gone()
    dead_proxy = [weakref.proxy(gone)]
    del gone

    @njit(cache=False)
    def profiled_square_sum(a):
        total = 0.0
        for v in a:
            total += v * v
        return total

    assert profiled_square_sum(np.arange(4.0)) == 14.0
    path, count = kp.write_perf_map(tmp_path / "perf-test.map")
    assert count >= 1
    entries = [line.split(" ", 2) for line in path.read_text().splitlines()]
    starts = [int(start, 16) for start, _, _ in entries]
    assert starts == sorted(starts)
    mine = [(int(start, 16), int(size, 16)) for start, size, name in entries
            if kp.readable_name(name).endswith("profiled_square_sum")]
    assert mine, "the freshly compiled function is not in the map"
    start, size = mine[0]
    assert start > 0 and 0 < size <= 1 << 22
    assert len(dead_proxy) == 1  # (kept alive through the map's walk)


@pytest.mark.parametrize("kwargs, field", [({"envs": 0}, "envs"), ({"seconds": 0.1}, "seconds"),
                                           ({"precision": "float16"}, "precision"),
                                           ({"scene": "no_such_scene"}, "scene"),
                                           ({"integrator": "euler"}, "integrator")])
def test_profile_names_the_bad_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        kp.profile(**kwargs)


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("perf") is None, reason="needs Linux perf")
def test_profile_of_a_small_vector_env_names_the_right_hand_side():
    result = kp.profile(envs=64, seconds=2.0, top=40)
    names = [name for _, name in result["functions"]]
    assert "abb_gym.physics.model.accelerations_block" in names
    assert "env-steps/s while profiled" in result["rate"]
