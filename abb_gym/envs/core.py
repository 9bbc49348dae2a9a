"""Shared machinery of the balancer environments: compiled step kernel, observation, reward.

Every environment (single or vector, any action type) keeps its state in a few preallocated
arrays with one row per environment and advances them with **one** compiled call per step:

* :func:`step_serial` (single environments) and :func:`step_parallel` (the native vector
  environment, ``numba.prange`` over environments) both call :func:`_env_step` for each row,
  so a sub-environment of the vector environment and a single environment do the same
  arithmetic and agree bit for bit.
* :func:`_env_step` turns the action into a drive row (torque or speed) or uses the rows the
  Python side wrote (dwell profile), advances one control interval (or, for the dwell
  profile, every interval until the episode ends) with :func:`abb_gym.physics.batch.advance`
  - the production RK4 over :func:`abb_gym.physics.model.state_derivative` - and computes the
  reward terms, the termination flags and the observation.

The Python side (:class:`EnvSetup`) resolves the preset, builds the spaces and the constants
array ``cfg``, draws each episode from the environment's ``np_random`` and writes its row.
The reward and observation definitions are documented in :mod:`abb_gym.envs.base`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
from gymnasium import spaces
from numba import njit, prange

from ..physics import batch
from ..physics import integrators as integ
from ..physics import drive_law as dl
from ..physics import model as mdl
from ..physics.drives import SpeedProfile
from ..physics.scene import Scene, load_scene
from ..physics.simulate import default_step, state_names
from .config import EnvConfig, PresetError, load_preset

KIND_TORQUE = 0
KIND_SPEED = 1
KIND_DWELL = 2
KINDS = {"torque": KIND_TORQUE, "speed": KIND_SPEED, "dwell": KIND_DWELL}

# ---------------------------------------------------------------- cfg: environment constants
(C_KIND, C_DT, C_WOP, C_TOL, C_OVERSPEED, C_TLIM, C_AMAX, C_CLEAR, C_VSCALE, C_FILT,
 C_NSETTLE, C_NMAX, C_BACKSTOP, C_TREF, C_WV, C_WT, C_WE, C_WR, C_WF, C_NACT, C_OBS_BALLS,
 C_SPEED_LO, C_SPEED_HI, C_VIB_HI, C_BAL_TOL, C_TEP, C_METHOD) = range(27)
N_CFG = 27
# ---------------------------------------------------------------- st: per-environment state
(S_K, S_FILT, S_NSETTLE, S_REACHED, S_T_REACH, S_RES_SUM, S_PEAK, S_DONE, S_TERM, S_TRUNC,
 S_AREF, S_AOP, S_USCALE, S_UBEST, S_DTMAX, S_NSEG, S_J, S_PEN_RATE, S_PEN_TERM, S_XS, S_YS,
 S_ACT) = range(22)
N_ST = S_ACT + 3  # up to three action entries
# ---------------------------------------------------------------- out: per-step outputs
(O_REWARD, O_VIB, O_TIME, O_EFFORT, O_RESID, O_FAIL, O_TERM, O_TRUNC, O_FCODE, O_FTIME,
 O_FINDEX, O_R, O_RDYN, O_IMB, O_BAL, O_ACTFLAG, O_STEPS, O_WINT, O_WMAX, O_WXS,
 O_WYS) = range(21)
N_OUT = 21
TERM_NAMES = ("vibration", "time", "effort", "residual", "failure")

FAIL_NONE = 0
FAIL_NUMERICAL = 1
FAIL_CLEARANCE = 2
FAIL_OVERSPEED = 3

ACT_OK = 0
ACT_CLIPPED = 1
ACT_NONFINITE = 2


# =============================================================================== kernels
@njit(cache=True)
def _balance(i, s, p, b, st, cfg, out):
    """Residual imbalance |U0 + sum m_i (E e^{i gam} + R e^{i ph_i})| / U and the balanced flag."""
    nb = b.shape[1]
    big_r = p[i, mdl.P_R]
    e = p[i, mdl.P_E]
    gam = p[i, mdl.P_GAM]
    ux = p[i, mdl.P_U0]
    uy = 0.0
    for k in range(nb):
        m = b[i, k, mdl.B_MASS]
        ph = s[i, 3 + k]
        ux += m * (e * math.cos(gam) + big_r * math.cos(ph))
        uy += m * (e * math.sin(gam) + big_r * math.sin(ph))
    res = math.sqrt(ux * ux + uy * uy)
    out[i, O_IMB] = res / st[i, S_USCALE]
    out[i, O_BAL] = 1.0 if res <= st[i, S_UBEST] + cfg[C_BAL_TOL] * st[i, S_USCALE] else 0.0


@njit(cache=True)
def _clip(v, lo, hi):
    if v < lo:
        return lo
    if v > hi:
        return hi
    return v


@njit(cache=True)
def _observe(i, s, p, b, st, cfg, obs, out, trace):
    """Write the observation row ``obs[i]``, the whirl radius and balance outputs, the trace."""
    nq = s.shape[1] // 2
    nb = nq - 3
    x = s[i, 0]
    y = s[i, 1]
    dx = x - st[i, S_XS]
    dy = y - st[i, S_YS]
    w = s[i, nq + 2]
    vs = cfg[C_VSCALE]
    vh = cfg[C_VIB_HI]
    obs[i, 0] = _clip(w / cfg[C_WOP], cfg[C_SPEED_LO], cfg[C_SPEED_HI])
    obs[i, 1] = _clip(dx / vs, -vh, vh)
    obs[i, 2] = _clip(dy / vs, -vh, vh)
    obs[i, 3] = _clip(st[i, S_FILT] / vs, 0.0, vh)
    obs[i, 4] = _clip(st[i, S_K] / cfg[C_NMAX], 0.0, 1.0)
    na = int(cfg[C_NACT])
    for a in range(na):
        obs[i, 5 + a] = st[i, S_ACT + a]
    if cfg[C_OBS_BALLS] != 0.0:
        for k in range(nb):
            ph = s[i, 3 + k]
            obs[i, 5 + na + 2 * k] = math.cos(ph)
            obs[i, 6 + na + 2 * k] = math.sin(ph)
    out[i, O_R] = math.sqrt(x * x + y * y)
    out[i, O_RDYN] = math.sqrt(dx * dx + dy * dy)
    _balance(i, s, p, b, st, cfg, out)
    if i < trace.shape[0]:
        k = int(st[i, S_K])
        if k < trace.shape[1]:
            trace[i, k, 0] = k * cfg[C_DT]
            trace[i, k, 1] = x
            trace[i, k, 2] = y
            trace[i, k, 3] = w


@njit(cache=True)
def _interval(i, s, p, b, d, st, cfg, out, ws, work):
    """Advance environment ``i`` by one control interval and add its reward terms to ``out``.

    Returns True when the episode ended (terminated or truncated) in this interval.
    """
    nq = s.shape[1] // 2
    dt = cfg[C_DT]
    kk = st[i, S_K]
    t0 = kk * dt
    t1 = (kk + 1.0) * dt
    si = s[i]
    wsi = ws[i]
    backup = wsi[batch.WS_BACKUP]
    for c in range(si.shape[0]):
        backup[c] = si[c]
    whirl = out[i, O_WINT:O_WYS + 1]
    whirl[0] = 0.0
    whirl[1] = 0.0
    whirl[2] = st[i, S_XS]
    whirl[3] = st[i, S_YS]
    nseg = int(st[i, S_NSEG])
    status, j, t_fail, bad, steps = batch.advance(si, t0, t1, d[i], nseg, int(st[i, S_J]),
                                                  p[i], b[i], st[i, S_DTMAX], wsi, work[i],
                                                  whirl, int(cfg[C_METHOD]))
    st[i, S_J] = j
    out[i, O_STEPS] += steps
    st[i, S_K] = kk + 1.0
    fail = FAIL_NONE
    if status != 0:
        for c in range(si.shape[0]):
            si[c] = backup[c]
        fail = FAIL_NUMERICAL
        out[i, O_FTIME] = t_fail
        out[i, O_FINDEX] = bad
        dx = si[0] - st[i, S_XS]
        dy = si[1] - st[i, S_YS]
        r_mean = math.sqrt(dx * dx + dy * dy)
        r_max = math.sqrt(si[0] * si[0] + si[1] * si[1])
    else:
        r_mean = whirl[0] / dt
        r_max = whirl[1]
    w = si[nq + 2]
    # control effort: time integral of (drive command / its limit)^2 over the interval
    effort = 0.0
    for r in range(nseg):
        ts = d[i, r, dl.D_T0]
        te = d[i, r + 1, dl.D_T0] if r + 1 < nseg else math.inf
        ov = min(t1, te) - max(t0, ts)
        if ov > 0.0:
            if d[i, r, dl.D_MODE] == dl.MODE_PRESCRIBED:
                u = d[i, r, dl.D_ALPHA] / cfg[C_AMAX]
            else:
                u = d[i, r, dl.D_TORQUE] / cfg[C_TLIM]
            effort += u * u * ov
    tref = cfg[C_TREF]
    vib = -cfg[C_WV] * (r_mean / st[i, S_AREF]) * dt / tref
    wop = cfg[C_WOP]
    at_speed = abs(w - wop) <= cfg[C_TOL] * wop
    tim = 0.0 if at_speed else -cfg[C_WT] * dt / tref
    eff = -cfg[C_WE] * effort / tref
    st[i, S_FILT] += cfg[C_FILT] * (r_mean - st[i, S_FILT])
    if r_max > st[i, S_PEAK]:
        st[i, S_PEAK] = r_max
    if at_speed and fail == FAIL_NONE:
        if st[i, S_REACHED] == 0.0:
            st[i, S_REACHED] = 1.0
            st[i, S_T_REACH] = t1
        st[i, S_NSETTLE] += 1.0
        st[i, S_RES_SUM] += r_mean / st[i, S_AOP]
    if fail == FAIL_NONE:
        if r_max > cfg[C_CLEAR]:
            fail = FAIL_CLEARANCE
        elif abs(w) > cfg[C_OVERSPEED] * wop:
            fail = FAIL_OVERSPEED
    resid = 0.0
    pen = 0.0
    term = False
    if fail != FAIL_NONE:
        term = True
        remaining = cfg[C_TEP] - t1
        if remaining < 0.0:
            remaining = 0.0
        pen = -(cfg[C_WF] + st[i, S_PEN_RATE] * remaining / tref + st[i, S_PEN_TERM])
        out[i, O_FCODE] = fail
        if fail != FAIL_NUMERICAL:
            out[i, O_FTIME] = t1
    elif st[i, S_REACHED] != 0.0 and st[i, S_NSETTLE] >= cfg[C_NSETTLE]:
        term = True
        if st[i, S_NSETTLE] > 0.0:
            resid = -cfg[C_WR] * st[i, S_RES_SUM] / st[i, S_NSETTLE]
    trunc = (not term) and st[i, S_K] >= cfg[C_NMAX]
    if trunc:
        # the time limit does not excuse the residual term: it is paid over the settling
        # window so far, or at its bound (the whirl at the clearance) if the rotor never
        # reached operating speed, so that a run-up too slow to finish never pays
        if st[i, S_NSETTLE] > 0.0:
            resid = -cfg[C_WR] * st[i, S_RES_SUM] / st[i, S_NSETTLE]
        else:
            resid = -st[i, S_PEN_TERM]
    out[i, O_VIB] += vib
    out[i, O_TIME] += tim
    out[i, O_EFFORT] += eff
    out[i, O_RESID] += resid
    out[i, O_FAIL] += pen
    if term:
        out[i, O_TERM] = 1.0
    if trunc:
        out[i, O_TRUNC] = 1.0
    return term or trunc


@njit(cache=True)
def _env_step(i, act, s, p, b, d, st, cfg, obs, out, trace, ws, work, active):
    for c in range(out.shape[1]):
        out[i, c] = 0.0
    if active[i] == 0:
        return
    if st[i, S_DONE] != 0.0:
        # stepping a finished episode: nothing moves, no reward (the caller warns)
        out[i, O_TERM] = st[i, S_TERM]
        out[i, O_TRUNC] = st[i, S_TRUNC]
        _observe(i, s, p, b, st, cfg, obs, out, trace)
        return
    na = int(cfg[C_NACT])
    for a in range(na):
        if not math.isfinite(act[i, a]):
            out[i, O_ACTFLAG] = ACT_NONFINITE
            out[i, O_FINDEX] = a
            return
    flag = ACT_OK
    for a in range(na):
        v = act[i, a]
        if v > 1.0:
            v = 1.0
            flag = ACT_CLIPPED
        elif v < -1.0:
            v = -1.0
            flag = ACT_CLIPPED
        st[i, S_ACT + a] = v
    out[i, O_ACTFLAG] = flag
    kind = int(cfg[C_KIND])
    nq = s.shape[1] // 2
    t0 = st[i, S_K] * cfg[C_DT]
    if kind == KIND_TORQUE:
        row = d[i, 0]
        row[dl.D_T0] = t0
        row[dl.D_MODE] = dl.MODE_MOTOR
        row[dl.D_TORQUE] = st[i, S_ACT] * cfg[C_TLIM]
        row[dl.D_GAIN] = 0.0
        row[dl.D_TW0] = 0.0
        row[dl.D_TALPHA] = 0.0
        row[dl.D_TLIM] = cfg[C_TLIM]
        st[i, S_NSEG] = 1.0
        st[i, S_J] = 0.0
        done = _interval(i, s, p, b, d, st, cfg, out, ws, work)
    elif kind == KIND_SPEED:
        w = s[i, nq + 2]
        dt = cfg[C_DT]
        alpha = st[i, S_ACT] * cfg[C_AMAX]
        hi = (cfg[C_WOP] - w) / dt
        lo = -w / dt
        if alpha > hi:
            alpha = hi
        if alpha < lo:
            alpha = lo
        row = d[i, 0]
        row[dl.D_T0] = t0
        row[dl.D_TH0] = s[i, 2]
        row[dl.D_W0] = w
        row[dl.D_ALPHA] = alpha
        row[dl.D_MODE] = dl.MODE_PRESCRIBED
        st[i, S_NSEG] = 1.0
        st[i, S_J] = 0.0
        done = _interval(i, s, p, b, d, st, cfg, out, ws, work)
    else:
        # dwell profile: the rows were written from the action; run the whole episode
        done = False
        while not done:
            done = _interval(i, s, p, b, d, st, cfg, out, ws, work)
            if not done:
                _observe(i, s, p, b, st, cfg, obs, out, trace)  # fills the render trace
    if cfg[C_BACKSTOP] > 0.0:
        # the rule of gymnasium's TimeLimit: truncated once elapsed steps >= the limit
        elapsed = 1.0 if kind == KIND_DWELL else st[i, S_K]
        if elapsed >= cfg[C_BACKSTOP]:
            out[i, O_TRUNC] = 1.0
            done = True
    out[i, O_REWARD] = (out[i, O_VIB] + out[i, O_TIME] + out[i, O_EFFORT] + out[i, O_RESID]
                        + out[i, O_FAIL])
    if done:
        st[i, S_DONE] = 1.0
        st[i, S_TERM] = out[i, O_TERM]
        st[i, S_TRUNC] = out[i, O_TRUNC]
    _observe(i, s, p, b, st, cfg, obs, out, trace)


@njit(cache=True)
def step_serial(act, s, p, b, d, st, cfg, obs, out, trace, ws, work, active):
    """One environment step for every row (serial; single environments)."""
    for i in range(s.shape[0]):
        _env_step(i, act, s, p, b, d, st, cfg, obs, out, trace, ws, work, active)


@njit(cache=True, parallel=True)
def step_parallel(act, s, p, b, d, st, cfg, obs, out, trace, ws, work, active):
    """One environment step for every row, in parallel over rows (vector environment)."""
    for i in prange(s.shape[0]):
        _env_step(i, act, s, p, b, d, st, cfg, obs, out, trace, ws, work, active)


@njit(cache=True)
def observe_rows(rows, s, p, b, st, cfg, obs, out, trace):
    """Observation (and whirl/balance outputs) of the given rows, e.g. after a reset."""
    for r in range(rows.shape[0]):
        i = rows[r]
        for c in range(out.shape[1]):
            out[i, c] = 0.0
        _observe(i, s, p, b, st, cfg, obs, out, trace)


# =============================================================================== Python side
def jeffcott_amplitude(imbalance: float, mass: float, stiffness: float, damping: float,
                       speed: float) -> float:
    """Steady whirl amplitude U w^2 / sqrt((k - m w^2)^2 + (c w)^2) of a Jeffcott rotor [m]."""
    w2 = speed * speed
    den = math.hypot(stiffness - mass * w2, damping * speed)
    return imbalance * w2 / den if den > 0 else math.inf


def reference_amplitudes(scene: Scene, operating_speed: float, imbalance: float
                         ) -> tuple[float, float]:
    """(peak over [0, w_op], value at w_op) of the ball-less rotor's steady whirl amplitude [m].

    The rotor without balls: mass ``rotor_mass``, the scene's support, imbalance ``imbalance``.
    With an orthotropic support each axis is a Jeffcott oscillator of its own; the orbit's
    major semi-axis is the larger of the two amplitudes.  The peak of U w^2/|...| lies at
    w*^2 = k / (m - c^2 / (2 k)) (if that is positive and w* <= w_op), else at w_op.
    """
    m = scene.rotor_mass
    peak = 0.0
    at_op = 0.0
    for k, c in ((scene.support_stiffness_x, scene.support_damping_x),
                 (scene.support_stiffness_y, scene.support_damping_y)):
        a_op = jeffcott_amplitude(imbalance, m, k, c, operating_speed)
        at_op = max(at_op, a_op)
        peak = max(peak, a_op)
        den = m - c * c / (2.0 * k)
        if den > 0:
            w_star = math.sqrt(k / den)
            if w_star <= operating_speed:
                peak = max(peak, jeffcott_amplitude(imbalance, m, k, c, w_star))
    return peak, at_op


def static_deflection(scene: Scene) -> tuple[float, float]:
    """Rest position (x, y) [m] of the rotor centre: the sag M g / k under gravity, else 0.

    Gravity acts in the balancing plane only for a horizontal-axis rotor (scenes with
    ``gravity_acceleration > 0``); then the supported mass M hangs at M g_x / k_x, M g_y / k_y.
    """
    g = float(getattr(scene, "gravity_acceleration", 0.0) or 0.0)
    if g <= 0.0:
        return 0.0, 0.0
    a = float(getattr(scene, "gravity_angle", -0.5 * math.pi))
    m = scene.total_mass
    return (m * g * math.cos(a) / scene.support_stiffness_x,
            m * g * math.sin(a) / scene.support_stiffness_y)


def imbalance_scale(scene: Scene) -> float:
    """Imbalance that normalises the residual imbalance [kg m].

    U0 if positive, else the race-eccentricity imbalance sum m_i E, else the capacity."""
    if scene.imbalance > 0:
        return scene.imbalance
    ecc = float(sum(scene.ball_mass)) * scene.race_eccentricity
    return ecc if ecc > 0 else scene.balancing_capacity


def best_residual(scene: Scene) -> float:
    """Smallest residual imbalance the balls can reach [kg m] (race eccentricity included).

    The balls' own imbalance sum m_i R e^{i ph_i} can take any magnitude in
    [max(0, 2 max m_i R - sum m_i R), sum m_i R]; the fixed part is U0 + sum m_i E e^{i gam}.
    """
    mr = np.asarray(scene.ball_mass) * scene.race_radius
    cap = float(mr.sum())
    lo = max(0.0, 2.0 * float(mr.max()) - cap)
    me = float(sum(scene.ball_mass)) * scene.race_eccentricity
    fixed = math.hypot(scene.imbalance + me * math.cos(scene.race_eccentricity_angle),
                       me * math.sin(scene.race_eccentricity_angle))
    if fixed < lo:
        return lo - fixed
    if fixed > cap:
        return fixed - cap
    return 0.0


@dataclass
class Episode:
    """Parameters of one episode (drawn by :meth:`EnvSetup.draw_episode`)."""

    scene: Scene
    imbalance: float
    imbalance_phase: float
    ball_angles: np.ndarray
    ball_drag_scale: float
    rolling_resistance_scale: float
    integration_step: float
    static_deflection: tuple[float, float] = (0.0, 0.0)

    def as_info(self) -> dict[str, Any]:
        return {"imbalance": self.imbalance, "imbalance_phase": self.imbalance_phase,
                "initial_ball_angles": self.ball_angles.copy(),
                "ball_drag_scale": self.ball_drag_scale,
                "rolling_resistance_scale": self.rolling_resistance_scale,
                "integration_step": self.integration_step,
                "static_deflection": np.array(self.static_deflection)}


RESET_OPTIONS = ("imbalance", "imbalance_ratio", "imbalance_phase", "ball_angles",
                 "ball_drag_scale", "rolling_resistance_scale")


class Buffers:
    """The preallocated arrays of ``n`` environments (rows)."""

    def __init__(self, setup: "EnvSetup", n: int, n_trace: int = 0):
        nb = setup.scene.ball_count
        ns = 2 * (3 + nb)
        self.act = np.zeros((n, setup.n_actions))
        self.s = np.zeros((n, ns))
        self.p = np.zeros((n, mdl.N_PARAMS))
        self.b = np.zeros((n, nb, mdl.N_BALL_PARAMS))
        self.d = np.zeros((n, setup.n_rows, dl.N_DRIVE))
        self.st = np.zeros((n, N_ST))
        self.st[:, S_DONE] = 1.0
        self.st[:, S_USCALE] = 1.0
        self.obs = np.zeros((n, setup.obs_dim), dtype=np.float32)
        self.out = np.zeros((n, N_OUT))
        k = setup.max_steps + 1 if n_trace > 0 else 0
        self.trace = np.zeros((min(n_trace, n), k, 4))
        self.ws, self.work = batch.make_workspace(n, nb)
        self.active = np.ones(n, dtype=np.uint8)
        self.cfg = setup.cfg

    def kernel_args(self) -> tuple:
        """Arguments of :func:`step_serial` / :func:`step_parallel`, in order."""
        return (self.act, self.s, self.p, self.b, self.d, self.st, self.cfg, self.obs, self.out,
                self.trace, self.ws, self.work, self.active)

    def observe(self, rows: np.ndarray) -> None:
        observe_rows(np.asarray(rows, dtype=np.int64), self.s, self.p, self.b, self.st,
                     self.cfg, self.obs, self.out, self.trace)


def _as_int_steps(seconds: float, dt: float) -> int:
    return max(1, int(math.ceil(seconds / dt - 1e-9)))


class EnvSetup:
    """Everything an environment of one kind, scene and preset shares between episodes."""

    def __init__(self, kind: str, scene: Any = "yoshida_odd", preset: Any = "train",
                 observe_balls: bool = False, max_episode_steps: int | None = None,
                 overrides: Mapping[str, Any] | None = None):
        if kind not in KINDS:
            raise ValueError(f"kind must be one of {list(KINDS)} (got {kind!r})")
        self.kind = kind
        if not isinstance(scene, (str, Scene)) and not hasattr(scene, "__fspath__"):
            raise ValueError(f"scene must be a scene name, a path or a Scene (got {scene!r})")
        self.scene = load_scene(scene)
        self.config: EnvConfig = load_preset(preset, **dict(overrides or {}))
        if not isinstance(observe_balls, (bool, np.bool_)):
            raise ValueError(f"observe_balls must be True or False (got {observe_balls!r})")
        self.observe_balls = bool(observe_balls)
        if max_episode_steps is not None:
            if isinstance(max_episode_steps, bool) or not isinstance(
                    max_episode_steps, (int, np.integer)) or max_episode_steps < 1:
                raise ValueError(f"max_episode_steps must be an integer >= 1 or None "
                                 f"(got {max_episode_steps!r})")
        self.backstop = int(max_episode_steps or 0)
        cfg = self.config
        sc = self.scene
        self.operating_speed = float(cfg.operating_speed or sc.drive_operating_speed)
        self.control_interval = float(cfg.control_interval)
        self.max_acceleration = float(sc.drive_max_acceleration)
        self.torque_limit = float(sc.drive_torque_limit)
        # reference time: the fastest run-up the drive allows
        self.reference_time = self.operating_speed / self.max_acceleration
        dw = cfg.dwell
        self.dwell_acceleration = dw.runup_acceleration * self.max_acceleration
        self.nominal_runup_time = self.operating_speed / self.dwell_acceleration
        if cfg.episode_length is not None:
            length = float(cfg.episode_length)
        elif kind == "dwell":
            # the slowest profile: the longest dwell at the lowest dwell acceleration
            slowest_dwell = dw.time_range[1] * self.nominal_runup_time
            length = (self.nominal_runup_time + slowest_dwell * max(0.0, 1.0 - dw.accel_range[0])
                      + cfg.settle_time + 2.0 * self.control_interval)
        else:
            length = 2.5 * self.reference_time + cfg.settle_time
        self.max_steps = _as_int_steps(length, self.control_interval)
        self.episode_length = self.max_steps * self.control_interval
        self.settle_steps = int(round(cfg.settle_time / self.control_interval))
        if cfg.settle_time > 0 and self.settle_steps == 0:
            self.settle_steps = 1
        if self.settle_steps >= self.max_steps:
            raise PresetError(f"environment preset {cfg.name!r}: settle_time = "
                              f"{cfg.settle_time:g} s must be shorter than the episode "
                              f"length {self.episode_length:g} s")
        if kind == "dwell" and dw.speed_range[0] * sc.critical_speed > self.operating_speed:
            raise PresetError(f"environment preset {cfg.name!r}: field 'dwell.speed_range' "
                              f"starts above the operating speed ({dw.speed_range[0]:g} x "
                              f"{sc.critical_speed:.4g} rad/s > {self.operating_speed:.4g} rad/s)")
        self.max_speed = self.operating_speed * (cfg.overspeed if kind == "torque" else 1.0)
        # observation scale: the ball-less rotor's resonance amplitude with the scene's imbalance
        self.vibration_scale = reference_amplitudes(sc, self.operating_speed,
                                                    imbalance_scale(sc))[0]
        self.vibration_bound = sc.housing_clearance / self.vibration_scale
        # largest (command / limit)^2 the effort term can see
        self.effort_bound = 1.0 if kind != "dwell" else max(
            1.0, (dw.runup_acceleration * max(abs(dw.accel_range[0]), abs(dw.accel_range[1])))
            ** 2)
        self.n_actions = 3 if kind == "dwell" else 1
        self.n_rows = 4 if kind == "dwell" else 1
        nb = sc.ball_count
        self.obs_dim = 5 + self.n_actions + (2 * nb if self.observe_balls else 0)
        speed_lo, speed_hi = ((-cfg.overspeed, cfg.overspeed) if kind == "torque"
                              else (0.0, 1.0))
        lo = [speed_lo, -self.vibration_bound, -self.vibration_bound, 0.0, 0.0]
        hi = [speed_hi, self.vibration_bound, self.vibration_bound, self.vibration_bound, 1.0]
        lo += [-1.0] * self.n_actions + [-1.0] * (self.obs_dim - 5 - self.n_actions)
        hi += [1.0] * self.n_actions + [1.0] * (self.obs_dim - 5 - self.n_actions)
        self.observation_space = spaces.Box(np.array(lo, np.float32), np.array(hi, np.float32),
                                            dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(self.n_actions,), dtype=np.float32)
        self.obs_names = (["rotor_speed", "vibration_x", "vibration_y", "vibration_amplitude",
                           "time_fraction"]
                          + ([f"last_action[{a}]" for a in range(self.n_actions)])
                          + [f"{fn}(ball_angle[{k}])" for k in range(nb) for fn in ("cos", "sin")
                             if self.observe_balls])
        w = cfg.reward
        c = np.zeros(N_CFG)
        c[C_KIND] = KINDS[kind]
        c[C_DT] = self.control_interval
        c[C_WOP] = self.operating_speed
        c[C_TOL] = cfg.at_speed_tolerance
        c[C_OVERSPEED] = cfg.overspeed if kind == "torque" else math.inf
        c[C_TLIM] = self.torque_limit
        c[C_AMAX] = self.max_acceleration
        c[C_CLEAR] = sc.housing_clearance
        c[C_VSCALE] = self.vibration_scale
        c[C_FILT] = 1.0 - math.exp(-self.control_interval / cfg.vibration_filter_time)
        c[C_NSETTLE] = self.settle_steps
        c[C_NMAX] = self.max_steps
        c[C_BACKSTOP] = self.backstop
        c[C_TREF] = self.reference_time
        c[C_WV], c[C_WT], c[C_WE], c[C_WR], c[C_WF] = (w.vibration, w.time, w.effort,
                                                       w.residual, w.failure)
        c[C_NACT] = self.n_actions
        c[C_OBS_BALLS] = 1.0 if self.observe_balls else 0.0
        c[C_SPEED_LO], c[C_SPEED_HI] = speed_lo, speed_hi
        c[C_VIB_HI] = self.vibration_bound
        c[C_BAL_TOL] = cfg.balance_tolerance
        c[C_TEP] = self.episode_length
        c[C_METHOD] = integ.METHOD_IDS[cfg.integrator]
        self.cfg = c
        self._state_names = state_names(nb)

    # ------------------------------------------------------------------ episodes
    def draw_episode(self, rng: np.random.Generator, options: Mapping[str, Any] | None
                     ) -> Episode:
        """Draw one episode's parameters from ``rng`` (fixed order), then apply ``options``."""
        sc = self.scene
        rz = self.config.randomize
        nb = sc.ball_count
        cap = sc.balancing_capacity
        imbalance = sc.imbalance
        phase = 0.0
        angles = np.asarray(sc.ball_angles0, dtype=float).copy()
        drag = 1.0
        roll = 1.0
        if rz.imbalance_ratio is not None:
            imbalance = float(rng.uniform(*rz.imbalance_ratio)) * cap
        if rz.imbalance_phase is not None:
            phase = float(rng.uniform(*rz.imbalance_phase))
        if rz.ball_angles is not None:
            angles = rng.uniform(rz.ball_angles[0], rz.ball_angles[1], size=nb)
        if rz.ball_drag_scale is not None:
            drag = float(rng.uniform(*rz.ball_drag_scale))
        if rz.rolling_resistance_scale is not None:
            roll = float(rng.uniform(*rz.rolling_resistance_scale))
        if options:
            if not isinstance(options, Mapping):
                raise ValueError(f"options must be a dict with keys from {list(RESET_OPTIONS)}"
                                 f" (got {options!r})")
            unknown = sorted(set(options) - set(RESET_OPTIONS))
            if unknown:
                raise ValueError(f"unknown reset option(s) {unknown}; allowed: "
                                 f"{list(RESET_OPTIONS)}")
            if "imbalance" in options and "imbalance_ratio" in options:
                raise ValueError("reset options 'imbalance' and 'imbalance_ratio' exclude "
                                 "each other")
            if "imbalance" in options:
                imbalance = _opt_number("imbalance", options["imbalance"], 0.0, "kg m")
            if "imbalance_ratio" in options:
                imbalance = _opt_number("imbalance_ratio", options["imbalance_ratio"], 0.0,
                                        "-") * cap
            if "imbalance_phase" in options:
                phase = _opt_number("imbalance_phase", options["imbalance_phase"], None, "rad")
            if "ball_angles" in options:
                a = np.asarray(options["ball_angles"], dtype=float)
                if a.ndim == 0:
                    a = np.full(nb, float(a))
                if a.shape != (nb,) or not np.all(np.isfinite(a)):
                    raise ValueError(f"reset option 'ball_angles' must be {nb} finite angles "
                                     f"[rad] (got {options['ball_angles']!r})")
                angles = a.copy()
            if "ball_drag_scale" in options:
                drag = _opt_number("ball_drag_scale", options["ball_drag_scale"], 0.0, "-",
                                   inclusive=False)
            if "rolling_resistance_scale" in options:
                roll = _opt_number("rolling_resistance_scale",
                                   options["rolling_resistance_scale"], 0.0, "-")
        changes: dict[str, Any] = {}
        if imbalance != sc.imbalance:
            changes["rotor_eccentricity"] = imbalance / sc.rotor_mass
        if drag != 1.0:
            changes["ball_drag"] = [v * drag for v in sc.ball_drag]
        if roll != 1.0:
            changes["ball_rolling_resistance"] = [v * roll for v in sc.ball_rolling_resistance]
        ep_scene = sc.replace(**changes) if changes else sc
        h = self.config.integration_step
        if h is None:
            h = default_step(ep_scene, self.max_speed, self.config.integrator)
        return Episode(ep_scene, float(imbalance), float(phase), angles, float(drag),
                       float(roll), float(h), static_deflection(ep_scene))

    def write_episode(self, bufs: Buffers, i: int, ep: Episode) -> None:
        """Reset row ``i`` of ``bufs`` to the start of episode ``ep`` (rotor at rest)."""
        sc = ep.scene
        nb = sc.ball_count
        nq = 3 + nb
        p, b = mdl.pack_parameters(sc)
        bufs.p[i] = p
        bufs.b[i] = b
        xs, ys = ep.static_deflection
        s = bufs.s[i]
        s[:] = 0.0
        s[0] = xs
        s[1] = ys
        s[2] = ep.imbalance_phase
        s[3:nq] = ep.ball_angles
        st = bufs.st[i]
        st[:] = 0.0
        st[S_XS] = xs
        st[S_YS] = ys
        u_ref = imbalance_scale(sc)
        a_peak, a_op = reference_amplitudes(sc, self.operating_speed, u_ref)
        st[S_AREF] = a_peak
        st[S_AOP] = a_op
        st[S_USCALE] = u_ref
        st[S_UBEST] = best_residual(sc)
        st[S_DTMAX] = ep.integration_step
        st[S_NSEG] = 1.0
        w = self.config.reward
        clear = sc.housing_clearance
        st[S_PEN_RATE] = w.vibration * clear / a_peak + w.time + w.effort * self.effort_bound
        st[S_PEN_TERM] = w.residual * clear / a_op
        d = bufs.d[i]
        d[:] = 0.0
        if self.kind == "speed":
            d[0, dl.D_TH0] = ep.imbalance_phase
            d[0, dl.D_MODE] = dl.MODE_PRESCRIBED
        elif self.kind == "torque":
            d[0, dl.D_MODE] = dl.MODE_MOTOR
            d[0, dl.D_TLIM] = self.torque_limit
        else:
            d[:, dl.D_TH0] = ep.imbalance_phase
            d[:, dl.D_MODE] = dl.MODE_PRESCRIBED
        bufs.act[i] = 0.0

    # ------------------------------------------------------------------ dwell actions
    def dwell_profile(self, action: np.ndarray, phase: float = 0.0) -> tuple[SpeedProfile, dict]:
        """Map a clipped DwellProfile action to its speed profile and physical parameters.

        Dwell start speed, duration and acceleration are mapped linearly from [-1, 1] to their
        ranges; the dwell is then shortened so that the speed stays in [0, w_op].
        """
        dw = self.config.dwell
        a = [float(v) for v in action]

        def lerp(rng, u):
            return rng[0] + 0.5 * (u + 1.0) * (rng[1] - rng[0])

        alpha = self.dwell_acceleration
        wop = self.operating_speed
        w_s = min(lerp(dw.speed_range, a[0]) * self.scene.critical_speed, wop)
        t_c = lerp(dw.time_range, a[1]) * self.nominal_runup_time
        a_c = lerp(dw.accel_range, a[2]) * alpha
        if a_c < 0:
            t_c = min(t_c, w_s / -a_c)
        elif a_c > 0:
            t_c = min(t_c, (wop - w_s) / a_c)
        after = min(max(w_s + a_c * t_c, 0.0), wop)
        segs = ((w_s / alpha, alpha), (t_c, a_c), ((wop - after) / alpha, alpha))
        profile = SpeedProfile(segments=segs, initial_angle=phase)
        params = {"dwell_speed": w_s, "dwell_time": t_c, "dwell_acceleration": a_c,
                  "runup_acceleration": alpha, "dwell_start_time": w_s / alpha}
        return profile, params

    def write_dwell_rows(self, bufs: Buffers, i: int, profile: SpeedProfile) -> None:
        _, rows = profile.segment_table(self.episode_length + self.control_interval)
        d = bufs.d[i]
        d[:] = 0.0
        d[:len(rows)] = rows
        bufs.st[i, S_NSEG] = len(rows)
        bufs.st[i, S_J] = 0.0

    # ------------------------------------------------------------------ info
    def failure_message(self, code: int, out_row: np.ndarray, st_row: np.ndarray,
                        s_row: np.ndarray) -> str:
        t = out_row[O_FTIME]
        if code == FAIL_NUMERICAL:
            name = self._state_names[int(out_row[O_FINDEX])]
            return (f"numerical: the state became non-finite at t = {t:.6g} s in {name!r} "
                    f"(RK4 step {st_row[S_DTMAX]:.3g} s); the episode ended at the last "
                    f"finite state; reduce integration_step")
        if code == FAIL_CLEARANCE:
            return (f"clearance: the whirl radius exceeded the housing clearance "
                    f"{self.scene.housing_clearance:g} m at t = {t:.6g} s")
        if code == FAIL_OVERSPEED:
            nq = s_row.shape[0] // 2
            return (f"overspeed: rotor speed {s_row[nq + 2]:.6g} rad/s beyond "
                    f"{self.config.overspeed:g} x the operating speed {self.operating_speed:g}"
                    f" rad/s at t = {t:.6g} s")
        return ""


def _opt_number(name: str, value: Any, lo: float | None, unit: str, inclusive: bool = True
                ) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"reset option {name!r} must be a number [{unit}] (got {value!r})"
                         ) from None
    if not math.isfinite(v) or (lo is not None and (v < lo or (v == lo and not inclusive))):
        rng = "finite" if lo is None else f"{'>=' if inclusive else '>'} {lo:g}"
        raise ValueError(f"reset option {name!r} must be {rng} [{unit}] (got {value!r})")
    return v
