"""The environment step's arrays travel to the compiled kernel packed in one StructRef
(abb_gym.envs.kernel.StepArrays): the kernel must work on the buffers' own memory, in the
order of its parameters, the entry-point cache must tell packs of different array types
apart, and the literal ball count and effects must reach the equations (the specialised
kernel)."""
import ast
import inspect
import textwrap
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from numba import njit, types

import abb_gym

from abb_gym.envs import kernel as K
from abb_gym.envs.buffers import Buffers
from abb_gym.envs.setup import EnvSetup


@njit
def _fields(a):
    """The pack's fields read by name in compiled code, in the order of STEP_ARRAYS."""
    return (a.order, a.act, a.s, a.p, a.b, a.d, a.st_rows, a.cfg, a.obs, a.out, a.trace,
            a.active, a.bs, a.bp, a.bb, a.bd, a.bk, a.btmp, a.blam, a.bcoef, a.bwork, a.bf,
            a.bg, a.bact)


@pytest.fixture(scope="module")
def bufs():
    return Buffers(EnvSetup("abb_gym/RunUpSpeed-v0", "yoshida_odd", "train"), 3, kernel="generic")


def test_pack_holds_the_buffers_arrays_not_copies(bufs):
    """A value written into a buffer after packing is what the kernel reads: the environment
    writes its actions in place between steps (a copy would step on stale actions)."""
    packed, nb, spec = bufs.kernel_args()
    assert isinstance(packed, K.StepArrays) and nb == 2 and spec == bufs.spec
    bufs.act[2, 0] = 0.625
    assert _fields(packed)[K.STEP_ARRAYS.index("act")][2, 0] == 0.625


@pytest.mark.parametrize("wrapper, kernel", [("_step_serial_packed", "_step_serial"),
                                             ("_step_parallel_packed", "_step_parallel")])
def test_the_kernel_unpacks_in_the_buffers_order(bufs, monkeypatch, wrapper, kernel):
    """The wrapper hands the kernel, parameter by parameter, the buffer array of that name (two
    arrays of one type swapped would compile and run on the wrong data): its Python body runs
    here with the kernel replaced by a recorder."""
    arrays = bufs.step_arrays()
    assert len(arrays) == len(K.STEP_ARRAYS)
    # the kernel's parameters are the pack's fields, in order ("st" is the field "st_rows")
    params = list(inspect.signature(getattr(K, kernel).py_func).parameters)
    assert params == [("st" if n == "st_rows" else n) for n in K.STEP_ARRAYS] + ["nb", "spec"]
    packed, nb, spec = bufs.kernel_args()
    # the pack's fields as compiled code reads them, by name
    fields = SimpleNamespace(**dict(zip(K.STEP_ARRAYS, _fields(packed))))
    seen = []
    monkeypatch.setattr(K, kernel, lambda *args: seen.append(args))
    getattr(K, wrapper).py_func(fields, nb, spec)
    (args,) = seen
    assert args[-2:] == (nb, spec) and len(args) == len(arrays) + 2
    for name, mine, theirs in zip(K.STEP_ARRAYS, args, arrays):
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


def _calls_with_literal_beside_star_arguments(tree) -> list[str]:
    """Calls in compiled (``njit``-decorated) functions that pass one of the specialised
    kernels' literal arguments (``nb``, ``spec``, ``method``) beside star arguments."""
    literal = {"nb", "spec", "method"}
    found = []
    for fn in ast.walk(tree):
        if not isinstance(fn, ast.FunctionDef) or not any(
                "njit" in ast.unparse(d) for d in fn.decorator_list):
            continue
        for call in ast.walk(fn):
            if isinstance(call, ast.Call) and any(isinstance(a, ast.Starred) for a in call.args) \
                    and any(isinstance(a, ast.Name) and a.id in literal for a in call.args):
                found.append(f"{fn.name}: {ast.unparse(call)}")
    return found


def test_numba_drops_literal_types_in_a_star_call():
    """Why the rule below: an argument typed as a literal reaches a callee as a literal when
    passed by itself, and as a plain integer when the call has star arguments (numba builds one
    tuple of them).  The specialised kernels get their ball count and effects as literals; a
    star call on the way compiles every function below it as the general kernel."""
    @njit
    def callee(x, y, nb):
        return x + y + nb

    @njit
    def pair(a):
        return (a, a)

    @njit
    def star(a, nb):
        return callee(*pair(a), nb)

    @njit
    def plain(a, nb):
        x, y = pair(a)
        return callee(x, y, nb)

    star.compile((types.float64, types.literal(2)))
    assert [str(s[2]) for s in callee.signatures] == ["int64"]
    plain.compile((types.float64, types.literal(3)))
    assert "Literal[int](3)" in [str(s[2]) for s in callee.signatures]
    # and the check below sees exactly that call
    source = textwrap.dedent(inspect.getsource(star.py_func))
    assert _calls_with_literal_beside_star_arguments(ast.parse(source)) == [
        "star: callee(*pair(a), nb)"]


def test_no_compiled_call_passes_a_literal_argument_beside_star_arguments():
    """The environment step passed its arrays as star arguments from 2026-11-23 to 2026-11-24:
    the literal ball count and effects became plain integers on the way, and the environments
    ran the general kernel at its speed while counting as specialised (the vector environment
    at 1024: 330,000 instead of 845,000 env-steps/s)."""
    package = Path(abb_gym.__file__).parent
    found = []
    for path in sorted(package.rglob("*.py")):
        found += [f"{path.relative_to(package)}: {c}"
                  for c in _calls_with_literal_beside_star_arguments(ast.parse(path.read_text()))]
    assert found == []


@pytest.mark.parametrize("n_envs, one_lane", [(1, True), (3, False), (4, False), (64, False)])
def test_blocks_of_one_lane_tell_the_kernel_so(n_envs, one_lane):
    """Buffers whose blocks have one lane add SPEC_ONE_LANE to the literal effect bits (the
    lane count then compiles as the constant 1); wider blocks keep the scene's effects only."""
    from abb_gym.physics import model as mdl
    setup = EnvSetup("abb_gym/RunUpSpeed-v0", "yoshida_odd", "train")
    b = Buffers(setup, n_envs, kernel="generic")
    assert (b.blocks.lanes == 1) == one_lane
    assert b.spec == setup.spec | (mdl.SPEC_ONE_LANE if one_lane else 0)
    assert setup.spec & mdl.SPEC_ONE_LANE == 0
    lanes = njit(lambda s, spec: mdl.lanes_of(s, spec))
    block = np.zeros((10, 8))
    assert lanes(block, setup.spec) == 8
    assert lanes(block, setup.spec | mdl.SPEC_ONE_LANE) == 1


def test_the_compile_notice_names_the_effects_in_words():
    from abb_gym.physics import model as mdl
    from abb_gym.physics.specialise import Specialised
    spec = mdl.SPEC_ROLL | mdl.SPEC_ONE_LANE
    assert mdl.describe_spec(spec) == "36 (rolling resistance, one lane)"
    assert mdl.describe_spec(0) == "0 (none)"
    fn = Specialised(njit(lambda x, nb, spec: x), literal=(1, 2), names=("balls", mdl.EFFECTS))
    assert fn._describe(1, 2) == "balls = 2"
    assert fn._describe(2, spec) == "effects = 36 (rolling resistance, one lane)"
