"""The environment step's arrays travel to the compiled kernel packed in one StructRef
(abb_gym.envs.kernel.StepArrays): the kernel must work on the buffers' own memory, in the
order of STEP_ARRAYS, and the entry-point cache must tell packs of different array types
apart."""
import numpy as np
import pytest

from abb_gym.envs import kernel as K
from abb_gym.envs.setup import Buffers, EnvSetup


@pytest.fixture(scope="module")
def bufs():
    return Buffers(EnvSetup("speed", "yoshida_odd", "train"), 3, kernel="generic")


def test_pack_holds_the_buffers_arrays_not_copies(bufs):
    """A value written into a buffer after packing is what the kernel reads: the environment
    writes its actions in place between steps (a copy would step on stale actions)."""
    packed, nb, spec = bufs.kernel_args()
    assert isinstance(packed, K.StepArrays) and nb == 2 and spec == bufs.spec
    bufs.act[2, 0] = 0.625
    fields = K.step_array_fields(packed)
    assert fields[K.STEP_ARRAYS.index("act")][2, 0] == 0.625


def test_the_kernel_unpacks_in_the_buffers_order(bufs):
    """Every field the kernel unpacks is the buffer array at the same position (two arrays of
    one type swapped would compile and run on the wrong data)."""
    arrays = bufs.step_arrays()
    assert len(arrays) == len(K.STEP_ARRAYS)
    fields = K.step_array_fields(bufs.kernel_args()[0])
    assert len(fields) == len(arrays)
    for name, mine, theirs in zip(K.STEP_ARRAYS, fields, arrays):
        assert mine.shape == theirs.shape and mine.dtype == theirs.dtype, name
        assert theirs.size == 0 or np.shares_memory(mine, theirs), name
        for other in arrays:
            if other is not theirs and other.size and mine.size:
                assert not np.shares_memory(mine, other), name


def test_entry_points_are_keyed_by_the_packed_types(bufs):
    """Two packs that differ only in one array's dtype get different entry points (an entry
    point trusts its argument types: reusing one would read float32 memory as float64)."""
    arrays = list(bufs.step_arrays())
    _, nb, spec = bufs.kernel_args()
    key = K.step_serial._key((K.pack_step_arrays(*arrays), nb, spec))
    assert K.step_serial._key((K.pack_step_arrays(*arrays), nb, spec)) == key
    arrays[K.STEP_ARRAYS.index("act")] = bufs.act.astype(np.float32)
    assert K.step_serial._key((K.pack_step_arrays(*arrays), nb, spec)) != key
