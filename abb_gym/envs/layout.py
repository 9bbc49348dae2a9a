"""Array layouts shared by the compiled environment step and its Python side.

Every environment keeps its state in preallocated arrays with one row per environment
(:class:`abb_gym.envs.setup.Buffers`); these are their columns.

* ``cfg`` (``N_CFG``): constants of the environment (``C_*``), the same for every row;
* ``st`` (``N_ST``): per-environment episode bookkeeping (``S_*``);
* ``out`` (``N_OUT``): per-step outputs (``O_*``): reward terms, flags, whirl, balance;
* ``trace`` (``T_*``): the recorded history, one row per control interval.
"""
from __future__ import annotations

from ..physics.runup import N_ACC
from .config import MAX_REDISTRIBUTIONS

# ---------------------------------------------------------------- cfg: environment constants
(C_KIND, C_DT, C_WOP, C_BAND, C_OVERSPEED, C_TLIM, C_AMAX, C_CLEAR, C_VSCALE, C_FILT,
 C_SETTLE, C_NMAX, C_BACKSTOP, C_TREF, C_WV, C_WT, C_WE, C_WR, C_WF, C_NACT,
 C_SPEED_LO, C_SPEED_HI, C_VIB_HI, C_BAL_TOL, C_TEP, C_METHOD) = range(26)
# the synchronous vibration (abb_gym.physics.sensors): on (1) or off (0), the tracking
# filter's time constant [s], the read-out noise [m] (standard deviation per component)
(C_SYNC, C_SYNC_LAG, C_SYNC_NOISE) = range(26, 29)
# every step's info shows the residual imbalance (info_level "full": 1) or only an episode's
# last (0): the step measures it only when shown
C_INFO_FULL = 29
# redistribution of the laundry (abb_gym.envs.redistribution): on (1) or off (0), the tumble
# speed [rad/s], the tumble time [s], the redistributions drawn per episode
(C_REDIST, C_TUMBLE_SPEED, C_TUMBLE_TIME, C_REDIST_MAX) = range(30, 34)
# the observation's layout (abb_gym.envs.observation): entry slot k is written at offset
# cfg[C_OBS + k] of the observation row, or not at all at -1
C_OBS = 34
(OBS_SPEED, OBS_VIB_X, OBS_VIB_Y, OBS_VIB_AMP, OBS_TIME, OBS_ACTION, OBS_SYNC, OBS_REDIST,
 OBS_BALLS) = range(9)
N_OBS_SLOTS = 9
N_CFG = C_OBS + N_OBS_SLOTS
# ---------------------------------------------------------------- st: per-environment state
# S_ACC .. S_ACC + runup.N_ACC - 1: the run-up metrics accumulator (abb_gym.physics.runup)
(S_K, S_FILT, S_PEAK, S_DONE, S_TERM, S_TRUNC, S_AREF, S_AOP, S_USCALE, S_UBEST, S_DTMAX,
 S_NSEG, S_J, S_PEN_RATE, S_PEN_TERM, S_XS, S_YS, S_ACT) = range(18)
S_ACC = S_ACT + 3  # up to three action entries
# after the accumulator: the synchronous demodulator's reference-mark offset th_mark [rad] (the
# imbalance's angle from the mark), its filter state [m], the episode's noise key (an integer
# < 2^53)
(S_MARK, S_ZX, S_ZY, S_NKEY) = range(S_ACC + N_ACC, S_ACC + N_ACC + 4)
# redistribution of the laundry: the time spent below the tumble speed so far [s], the
# redistributions so far, then each redistribution's imbalance [kg m] and phase from the
# reference mark [rad] (drawn at reset), MAX_REDISTRIBUTIONS pairs
(S_TUMBLE, S_NREDIST) = range(S_NKEY + 1, S_NKEY + 3)
S_REDIST = S_NKEY + 3
N_ST = S_REDIST + 2 * MAX_REDISTRIBUTIONS
# ---------------------------------------------------------------- out: per-step outputs
(O_REWARD, O_VIB, O_TIME, O_EFFORT, O_RESID, O_FAIL, O_TERM, O_TRUNC, O_FCODE, O_FTIME,
 O_FINDEX, O_R, O_RDYN, O_IMB, O_BAL, O_ACTFLAG, O_STEPS, O_WINT, O_WMAX, O_WXS,
 O_WYS, O_WDMAX) = range(22)
N_OUT = 22
# ---------------------------------------------------------------- trace: per-interval history
# one row per control interval (row k: the state at t = k dt) when a history is recorded
(T_T, T_X, T_Y, T_W, T_VIB, T_VIBMAX) = range(6)
T_BALLS = 6  # ball angles from here on
TERM_NAMES = ("vibration", "time", "effort", "residual", "failure")
TERM_COLUMNS = (O_VIB, O_TIME, O_EFFORT, O_RESID, O_FAIL)

FAIL_NONE = 0
FAIL_NUMERICAL = 1
FAIL_CLEARANCE = 2
FAIL_OVERSPEED = 3

ACT_OK = 0
ACT_CLIPPED = 1
ACT_NONFINITE = 2
