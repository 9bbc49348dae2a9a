"""The environment step's arrays travel to the compiled kernel packed in one StructRef
(abb_gym.envs.kernel.StepArrays): the kernel must work on the buffers' own memory, and the
entry-point cache must tell packs of different array types apart."""
import numpy as np
import pytest
from numba import njit

from abb_gym.envs import kernel as K
from abb_gym.envs.setup import Buffers, EnvSetup


@njit
def _act_of(packed):
    return packed.act


@njit
def _g_of(packed):
    return packed.bg


@pytest.fixture(scope="module")
def bufs():
    return Buffers(EnvSetup("speed", "yoshida_odd", "train"), 3, kernel="generic")


def test_pack_holds_the_buffers_arrays_not_copies(bufs):
    """A value written into a buffer after packing is what the kernel reads: the environment
    writes its actions in place between steps (a copy would step on stale actions)."""
    packed, nb, spec = bufs.kernel_args()
    assert isinstance(packed, K.StepArrays) and nb == 2 and spec == bufs.spec
    assert len(bufs.step_arrays()) == len(K.STEP_ARRAYS)
    bufs.act[2, 0] = 0.625
    assert _act_of(packed)[2, 0] == 0.625
    assert np.shares_memory(_act_of(packed), bufs.act)
    assert np.shares_memory(_g_of(packed), bufs.blocks.g)


def test_entry_points_are_keyed_by_the_packed_types(bufs):
    """Two packs that differ only in one array's dtype get different entry points (an entry
    point trusts its argument types: reusing one would read float32 memory as float64)."""
    arrays = list(bufs.step_arrays())
    _, nb, spec = bufs.kernel_args()
    key = K.step_serial._key((K.pack_step_arrays(*arrays), nb, spec))
    assert K.step_serial._key((K.pack_step_arrays(*arrays), nb, spec)) == key
    arrays[K.STEP_ARRAYS.index("act")] = bufs.act.astype(np.float32)
    assert K.step_serial._key((K.pack_step_arrays(*arrays), nb, spec)) != key
