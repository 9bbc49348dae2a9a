"""The vector environment's compiled reads of its rows (abb_gym.envs.step_rows) against the
numpy expressions they replace, and the step's action checks through them."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from hypothesis.extra import numpy as hnp

from abb_gym.envs.layout import O_FCODE, O_REWARD, O_TERM, O_TRUNC, TERM_COLUMNS
from abb_gym.envs.step_rows import check_actions, read_step

from test_envs_vector import make_vec

N_COLUMNS = max(O_FCODE, O_REWARD, O_TERM, O_TRUNC, *TERM_COLUMNS) + 1


@settings(max_examples=200, deadline=None)
@given(a=hnp.arrays(st.sampled_from([np.float32, np.float64]),
                    hnp.array_shapes(min_dims=2, max_dims=2, max_side=40),
                    elements=st.floats(-3.0, 3.0, width=32) | st.sampled_from(
                        [np.nan, np.inf, -np.inf, 1.0, -1.0])))
def test_check_actions_finds_the_first_non_finite_entry_and_any_outside(a):
    bad, outside = check_actions(a)
    finite = np.isfinite(a)
    if finite.all():
        assert bad == -1
        assert outside == bool((np.abs(a) > 1.0).any())
    else:
        first = int(np.flatnonzero(~finite.ravel())[0])
        assert bad == first
        # (the caller raises; the flag covers the entries before the bad one)
        assert outside == bool((np.abs(a.ravel()[:first]) > 1.0).any())


@settings(max_examples=100, deadline=None)
@given(rows=st.integers(1, 300), seed=st.integers(0, 2**32 - 1),
       p_flag=st.sampled_from([0.0, 0.05, 1.0]))
def test_read_step_equals_the_numpy_column_reads(rows, seed, p_flag):
    rng = np.random.default_rng(seed)
    out = rng.normal(size=(rows, N_COLUMNS))
    for col in (O_TERM, O_TRUNC, O_FCODE):
        out[:, col] = np.where(rng.random(rows) < p_flag, rng.integers(1, 4, rows), 0.0)
    got = read_step(out)
    terminated = out[:, O_TERM] != 0.0
    truncated = out[:, O_TRUNC] != 0.0
    assert got.terminated.dtype == np.bool_ and np.array_equal(got.terminated, terminated)
    assert np.array_equal(got.truncated, truncated)
    assert np.array_equal(got.done, terminated | truncated)
    assert np.array_equal(got.reward, out[:, O_REWARD])
    assert got.terms.shape == (len(TERM_COLUMNS), rows)
    for k, col in enumerate(TERM_COLUMNS):
        assert np.array_equal(got.terms[k], out[:, col])
    assert got.any_done is bool((terminated | truncated).any())
    assert got.any_failed is bool((out[:, O_FCODE] != 0.0).any())
    # fresh arrays: the caller's reward and flags do not alias the rows
    got.reward[:] = 7.0
    assert not np.shares_memory(got.reward, out) and not np.shares_memory(got.terms, got.reward)


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.int64])
def test_vector_step_takes_each_action_dtype_alike_and_names_a_bad_entry(dtype):
    """float32, float64 and whole-number actions step the same sub-environments alike, and a
    non-finite entry is named by its index with nothing stepped."""
    vecs = {}
    for kind in (np.float64, dtype):
        vec = make_vec("abb_gym/RunUpSpeed-v0", 3)
        vec.reset(seed=4)
        vecs[kind] = vec.step(np.array([[1], [0], [-2]], dtype=kind))
    (o1, r1, *_), (o2, r2, *_) = vecs[np.float64], vecs[dtype]
    assert np.array_equal(o1, o2) and np.array_equal(r1, r2)
    if dtype != np.int64:
        vec = make_vec("abb_gym/RunUpSpeed-v0", 3)
        vec.reset(seed=4)
        states = vec.unwrapped.states
        with pytest.raises(ValueError, match=r"entry \(2, 0\) is not"):
            vec.step(np.array([[0.5], [0.2], [np.inf]], dtype=dtype))
        assert np.array_equal(vec.unwrapped.states, states)
