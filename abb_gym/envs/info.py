"""The ``info`` dictionary of the environments, built in one place for single and vector.

:func:`step_info` reads one row (the single environment: scalars) or every row (the vector
environment: arrays, to which :func:`masked` adds gymnasium's ``_key`` masks).  The keys
are documented in :mod:`abb_gym.envs.base` (Info).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..physics import runup
from .step_rows import StepRows, read_step
from .layout import (O_BAL, O_FCODE, O_IMB, O_R, O_RDYN, S_ACC, S_K, S_NREDIST, S_PEAK,
                     TERM_COLUMNS, TERM_NAMES)

__all__ = ["step_info", "masked"]

# key -> (buffer, column, conversion): the one definition of every per-step key
#   "value": the entry; "bool": entry != 0; "times_dt": entry x control interval [s];
#   "per_length": entry / the episode's reference length (Yoshida's W_r / e);
#   "finite": the entry is not NaN;
#   "or_inf": the entry, inf where the accumulator holds NaN (not reached / not measured: info
#   holds no NaN, so that equal runs give equal infos)
STEP_KEYS = {
    "time": ("st", S_K, "times_dt"),
    "rotor_speed": ("s", "rotor_speed", "value"),
    "whirl_radius": ("out", O_R, "value"),
    "whirl_ratio": ("out", O_R, "per_length"),
    "vibration_radius": ("out", O_RDYN, "value"),
    "peak_whirl_radius": ("st", S_PEAK, "value"),
    "ball_angles": ("s", "ball_angles", "value"),
    "first_at_speed": ("st", S_ACC + runup.R_FIRST, "or_inf"),
    "run_up_time": ("st", S_ACC + runup.R_ENTRY, "or_inf"),
    "at_speed": ("st", S_ACC + runup.R_ENTRY, "finite"),
    "time_at_speed": ("st", S_ACC + runup.R_STAY, "value"),
    "settled": ("st", S_ACC + runup.R_SETTLED, "bool"),
    "peak_speed": ("st", S_ACC + runup.R_PEAK_SPEED, "value"),
    "time_above_band": ("st", S_ACC + runup.R_OVER_T, "value"),
    "balanced": ("out", O_BAL, "bool"),
    "residual_imbalance_ratio": ("out", O_IMB, "value"),
    "redistributions": ("st", S_NREDIST, "value"),
}


_TERMS = tuple(zip(TERM_NAMES, TERM_COLUMNS))


def _state_column(name: str, nq: int):
    return nq + 2 if name == "rotor_speed" else slice(3, nq)


def _terms_and_failure(setup, out, st, s, read: StepRows | None = None) -> dict[str, Any]:
    """The lean keys: ``reward_terms`` and, on a failure, ``failure`` (all rows: from
    ``read``, what :func:`~abb_gym.envs.step_rows.read_step` read of ``out``, if given)."""
    if out.ndim == 1:
        # one row: one tolist() instead of six numpy scalar reads (the single
        # environment's lean info 2.5 -> 1.8 us a step)
        row = out.tolist()
        info: dict[str, Any] = {"reward_terms": {name: row[col] for name, col in _TERMS}}
        code = row[O_FCODE]
        if code:
            info["failure"] = setup.failure_message(int(code), out, st, s)
        return info
    rows = read if read is not None else read_step(out)
    info = {"reward_terms": dict(zip(TERM_NAMES, rows.terms))}
    if rows.any_failed:
        code = out[:, O_FCODE]
        msgs = np.full(code.shape[0], None, dtype=object)
        for i in np.flatnonzero(code):
            msgs[i] = setup.failure_message(int(code[i]), out[i], st[i], s[i])
        info["failure"] = msgs
    return info


def step_info(setup, out: np.ndarray, st: np.ndarray, s: np.ndarray, ref_len,
              level: str = "full", done=None, read: StepRows | None = None) -> dict[str, Any]:
    """The per-step keys from the buffers ``out``, ``st``, ``s``: pass one row (1-D views:
    the single environment gets Python scalars) or every row (2-D: arrays over rows).

    ``level`` "full": every key; "lean": ``reward_terms`` (and ``failure``) only, plus every
    key when an episode ends (``done``: bool, or a bool array over rows), so that the final
    info of an episode always carries its run-up metrics.  ``read``: every row's
    :func:`~abb_gym.envs.step_rows.read_step` of ``out``, if the caller has it."""
    info = _terms_and_failure(setup, out, st, s, read)
    # a Python bool for one row: np.any on it costs more than the rest of the lean info
    if level == "lean" and not (done if isinstance(done, bool) else np.any(done)):
        return info
    nq = 3 + setup.scene.ball_count
    dt = setup.control_interval
    single = out.ndim == 1
    # one row: Python lists (much cheaper to read than numpy scalars); all rows: columns
    bufs = {"out": out.tolist(), "st": st.tolist()} if single else {"out": out.T, "st": st.T}
    for key, (buf, col, conv) in STEP_KEYS.items():
        if buf == "s":
            c = _state_column(col, nq)
            v = s[..., c].copy() if isinstance(c, slice) or not single else float(s[c])
        else:
            v = bufs[buf][col]
            if not single:
                v = v.copy()
        if conv == "bool":
            v = v != 0.0
        elif conv == "finite":
            v = (v == v)  # not NaN
        elif conv == "or_inf":
            v = (math.inf if v != v else v) if single else np.where(v != v, np.inf, v)
        elif conv == "times_dt":
            v = v * dt
        elif conv == "per_length":
            v = v / ref_len
        info[key] = v
    # the accumulator's derived values: residual over the settling window so far [m] and the
    # peak vibration before the settled entry [m] (abb_gym.physics.runup)
    res_int = bufs["st"][S_ACC + runup.R_RES_INT]
    res_t = bufs["st"][S_ACC + runup.R_RES_T]
    peak = bufs["st"][S_ACC + runup.R_PEAK]
    peak_entry = bufs["st"][S_ACC + runup.R_PEAK_ENTRY]
    if single:
        info["residual_vibration"] = res_int / res_t if res_t > 0.0 else math.inf
        info["peak_vibration"] = peak if math.isnan(peak_entry) else peak_entry
    else:
        with np.errstate(invalid="ignore", divide="ignore"):
            info["residual_vibration"] = np.where(res_t > 0.0, res_int / res_t, np.inf)
        info["peak_vibration"] = np.where(np.isnan(peak_entry), peak, peak_entry)
    return info


def masked(info: dict[str, Any], mask: np.ndarray,
           masks: dict[str, np.ndarray] | None = None) -> dict[str, Any]:
    """Add gymnasium's ``_key`` masks: ``masks[key]`` where given, else ``mask``
    (``failure`` is masked by the rows that failed)."""
    masks = masks or {}
    out: dict[str, Any] = {}
    for key, value in info.items():
        if isinstance(value, dict):
            value = masked(value, mask)
        out[key] = value
        if key == "failure" and getattr(value, "dtype", None) == object:
            # the failure messages (None where a row did not fail), not the reward term of
            # the same name, a float array masked like its siblings.  (Elementwise in C: a
            # list comprehension cost 90 us a step at 1024 rows.  Applied to the float
            # term, the comparison cost 65 us of the lean step's 110 us at 1024 rows, and
            # marked every row valid after a partial reset.)
            out["_failure"] = np.not_equal(value, None)
        else:
            out["_" + key] = masks.get(key, mask).copy()
    return out
