"""Balancer fluids and the race drag they exert: presets, temperature dependence, c_d(Re) laws.

The fluid in the annulus is assumed to co-rotate rigidly with the rotor, so the flow seen by
ball i has the relative speed ``u = R ph_i'`` (Spannan eq. 5.24); the lag of the core flow
during fast run-ups (Spannan ch. 3, eq. 5.18) is not modelled.  With that speed:

* **Drag force** (eq. 5.17) ``F = 1/2 rho A c_d(Re) u |u|`` with ``A = pi r^2`` and the particle
  Reynolds number ``Re = |u| d / nu`` (eq. 5.20), acting against u at the ball centre; its
  generalised force on ph_i is ``-F R``.
* **Stokes regime** ``c_d = C / Re`` (``C = c_d Re``, a constant of the annulus geometry) makes
  the force linear, ``F = C (pi/4) rho nu r u``, which is eq. (5.26) divided by R^2: the
  ``ball_drag`` of a scene is that coefficient [N s/m].  Every law below is exactly this linear
  law for Re <= 10, so a nonlinear law reduces to the linear one at low Re.
* **Laws** (``fluid_drag_law`` of a scene):

  ======================  =======================================================================
  ``linear``              no fluid drag from this module; the scene's ``ball_drag`` only (default)
  ``stokes``              c_d = C/Re at every Re (the linear law computed from rho, nu, r); C
                          = ``fluid_stokes_drag``, default 322 (Jan & Chen, Spannan's first guess)
  ``jan_chen_1997``       Spannan eq. 5.21 as printed: sphere rolling on a plane [JC97]; C = 322,
                          10^Y for 10 < Re <= 2e4 with Y = 3.02 - 1.89 L + 0.411 L^2 - 0.033 L^3
                          (L = log10 Re), 0.74 above.  Continuous at both ends (32.2, 0.739).
  ``spannan_2021``        Spannan eq. 6.9, the discoidal-rig fit: C = 387 for Re <= 10, plateau
                          0.6 above Re = 2e4, and between them a cubic Y(L) reconstructed from
                          those anchors (see below).  C and the plateau can be changed
                          (``fluid_stokes_drag``, e.g. 327 from eq. 5.22 for the CFRP annulus;
                          ``fluid_drag_plateau``); the cubic follows them.
  ======================  =======================================================================

  **Decision on eq. 6.9.**  The thesis defines the fit by c_d(10) = 38.7 (c_d Re = 387) and a
  plateau 0.6 for Re > 2e4, but its printed coefficients (2.72, -1.25, 0.121, 0.038) give
  c_d(10) = 42.6 and c_d(2e4) = 403 (:data:`SPANNAN_6_9_PRINTED`; a jump of three orders of
  magnitude at Re = 2e4), so they cannot be what was simulated.  Here the cubic is the Hermite
  interpolant that meets the stated anchors with matching slopes: Y(1) = log10(C/10) with
  dY/dL = -1 (continuous c_d Re) and Y(log10 2e4) = log10(plateau) with dY/dL = 0.  For C = 387,
  plateau 0.6 this is the physics note's reconstruction Y = 2.6865 - 1.1888 L + 0.08115 L^2 +
  0.008843 L^3 (c_d(100) = 5.06, c_d(1000) = 1.23, c_d(1e4) = 0.625).  It is a reconstruction,
  not the author's numbers; it does match his statement that c_d is "almost constant at 0.6"
  at Re = 2.4e4 (L1790).

* **Virtual mass** (eq. 5.23) ``F_vm = c_vm rho V u'`` with the ball volume V and
  ``u' = R ph_i''`` (the relative acceleration along the track in the co-rotating fluid): a
  kinetic energy ``1/2 c_vm rho V R^2 ph_i'^2`` that adds ``c_vm rho V R^2`` to the ball's
  relative inertia, i.e. only to the ph_i diagonal of the mass matrix (symmetric, energy
  consistent).  c_vm = 2 for a sphere at a wall [JC97]; its weight against the ball's own
  inertia 1.4 m is c_vm rho_fl / (1.4 rho_b): 17 % for steel in silicone oil, so it matters for
  light balls in dense fluids and for fast ball accelerations, and is negligible in air.

**When the fluid model matters.**  The linear law is exact in the Stokes regime: at steady
operation, during slow positioning and in every stability analysis (balls near rest relative to
the rotor, Re < 10).  The nonlinear law matters when the balls move fast relative to the rotor:
the non-synchronous whirl (Sommerfeld region, Re up to ~2.4e4 in the discoidal rig, where the
drag is ~37x the linear value in S0.65 oil) and the lag of the balls while the rotor
accelerates through the critical speed.  In low-viscosity fluids this is what decides whether
the balls lock on at all.

**Fluid presets** (:data:`FLUIDS`): Table 6.1 silicone oils [Mar99] (``S1`` .. ``S100``) with
the temperature law (6.1) and thermal expansion; Table 6.3 drag-rig fluids (``S0.65``,
``S2_mix``, ``S5_mix``, ``S10_mix`` - silicone blends by eq. 6.7, so lighter than Table 6.1's
oils of the same viscosity -, ``S23``, ``S50_rig``, ``S200_rig``, ``S400_rig`` - measured
values of nominal 200 and 400 cSt oils -, ``ravenol_80w``, ``addinol_sd_5w``), which the
thesis gives at room temperature only; and ``air`` (20 C, 101.325 kPa; not from the thesis,
which ran its discoidal rig with air too, L1754).

**Temperature.**  For the Table 6.1 oils, eq. (6.1)
``log10(log10(nu/(mm^2/s) + 0.8)) = P1 + P2 log10(T/K)`` is scaled by its own value at 25 C so
that it returns the tabulated nominal viscosity there exactly (the printed 4-digit P1, P2 alone
give it to within 0.3 %).  Density follows the volumetric expansion coefficient,
``rho(T) = rho_25 / (1 + alpha (T - 298.15 K))``, where the table gives one (S10 and above);
S1-S5 keep their 25 C density (the table has no coefficient; silicone oils expand by about
1e-3 /K, so this under-states the change by ~1 % per 10 K).  Fluids without a temperature law
accept only T = 298.15 K.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from .._numba import njit
from . import elementary as el

__all__ = ["Fluid", "FLUIDS", "DRAG_LAWS", "fluid_properties", "drag_coefficient",
           "law_coefficients", "stokes_drag_coefficient", "SPANNAN_6_9_PRINTED", "RE_STOKES",
           "RE_PLATEAU", "T_NOMINAL", "T_RANGE"]

T_NOMINAL = 298.15  # K, 25 C: the reference temperature of the tables
T_RANGE = (250.0, 400.0)  # K, where eq. 6.1 is used (its VTC anchors are 311 K and 372 K)
RE_STOKES = 10.0  # upper end of the Stokes regime (eqs. 5.21, 6.9)
RE_PLATEAU = 2.0e4  # start of the constant-c_d plateau (eqs. 5.21, 6.9)
LN10 = math.log(10.0)
INV_LN10 = 1.0 / LN10

# drag-law identifiers used by the kernel
LAW_NONE = 0  # ball_drag only
LAW_STOKES = 1  # linear from the fluid
LAW_CUBIC = 2  # Stokes | 10^cubic | plateau
DRAG_LAWS = ("linear", "stokes", "jan_chen_1997", "spannan_2021")

JAN_CHEN = (3.02, -1.89, 0.411, -0.033)  # eq. 5.21, Y(L) coefficients as printed
JAN_CHEN_STOKES = 322.0
JAN_CHEN_PLATEAU = 0.74
SPANNAN_STOKES = 387.0
SPANNAN_PLATEAU = 0.6
SPANNAN_6_9_PRINTED = (2.72, -1.25, 0.121, 0.038)  # inconsistent with its anchors (docstring)


@dataclass(frozen=True)
class Fluid:
    """A balancer fluid at 25 C: density [kg/m^3], kinematic viscosity [m^2/s], and, where the
    source gives them, the volumetric expansion coefficient [1/K] and eq. (6.1)'s P1, P2."""

    density: float
    viscosity: float
    source: str
    expansion: float | None = None
    p1: float | None = None
    p2: float | None = None
    vtc: float | None = None

    def at(self, temperature: float) -> tuple[float, float]:
        """(density [kg/m^3], kinematic viscosity [m^2/s]) at ``temperature`` [K]."""
        if self.p1 is None:
            if abs(temperature - T_NOMINAL) > 1e-9:
                raise ValueError(f"this fluid has no temperature law ({self.source}); allowed "
                                 f"temperature: {T_NOMINAL} K")
            return self.density, self.viscosity
        nu = self.viscosity * _eq_6_1(self.p1, self.p2, temperature) \
            / _eq_6_1(self.p1, self.p2, T_NOMINAL)
        rho = self.density
        if self.expansion is not None:
            rho = rho / (1.0 + self.expansion * (temperature - T_NOMINAL))
        return rho, nu


def _eq_6_1(p1: float, p2: float, temperature: float) -> float:
    """Kinematic viscosity [m^2/s] from Spannan eq. (6.1) with coefficients P1, P2."""
    return (10.0 ** (10.0 ** (p1 + p2 * math.log10(temperature))) - 0.8) * 1e-6


_T61 = "Spannan 2021 Table 6.1 [Mar99]"
_T63 = "Spannan 2021 Table 6.3"
FLUIDS: dict[str, Fluid] = {
    # Table 6.1: silicone oils (PDMS), nu and rho at 25 C, expansion 1e-4/C, VTC, P1, P2
    "S1": Fluid(820.0, 1e-6, _T61, None, 6.839, -3.004, 0.370),
    "S2": Fluid(872.0, 2e-6, _T61, None, 7.547, -3.191, 0.480),
    "S3": Fluid(900.0, 3e-6, _T61, None, 7.106, -2.968, 0.510),
    "S5": Fluid(920.0, 5e-6, _T61, None, 6.758, -2.778, 0.550),
    "S10": Fluid(945.0, 10e-6, _T61, 10.0e-4, 5.514, -2.222, 0.560),
    "S20": Fluid(955.0, 20e-6, _T61, 9.7e-4, 4.709, -1.855, 0.575),
    "S50": Fluid(960.0, 50e-6, _T61, 9.5e-4, 3.920, -1.490, 0.590),
    "S100": Fluid(963.0, 100e-6, _T61, 9.4e-4, 3.497, -1.291, 0.600),
    # Table 6.3: fluids of the drag-coefficient rig (room temperature only)
    "S0.65": Fluid(760.0, 0.65e-6, _T63 + " (nominal)"),
    "S2_mix": Fluid(800.0, 2e-6, _T63 + " (blend, eq. 6.7)"),
    "S5_mix": Fluid(844.0, 5e-6, _T63 + " (blend, eq. 6.7)"),
    "S10_mix": Fluid(876.0, 10e-6, _T63 + " (blend, eq. 6.7)"),
    "S23": Fluid(939.0, 23e-6, _T63 + " (measured)"),
    "S50_rig": Fluid(950.0, 50e-6, _T63 + " (nominal)"),
    "S200_rig": Fluid(953.0, 298e-6, _T63 + " (nominal 200 cSt, measured)"),
    "S400_rig": Fluid(947.0, 715e-6, _T63 + " (nominal 400 cSt, measured)"),
    "ravenol_80w": Fluid(886.0, 214e-6, _T63 + " (nominal)"),
    "addinol_sd_5w": Fluid(836.0, 31e-6, _T63 + " (nominal)"),
    # not in the thesis: dry air at 20 C, 101.325 kPa (ISO 2533 values)
    "air": Fluid(1.204, 1.516e-5, "dry air, 20 C, 101.325 kPa"),
}
_FLUID_KEYS = {k.lower(): k for k in FLUIDS}


def canonical_fluid_name(name: str) -> str | None:
    """The preset key for ``name`` (case-insensitive) or None."""
    return _FLUID_KEYS.get(name.strip().lower())


def fluid_properties(name: str, temperature: float = T_NOMINAL) -> tuple[float, float]:
    """(density [kg/m^3], kinematic viscosity [m^2/s]) of preset ``name`` at ``temperature`` [K].

    Raises ValueError naming the allowed presets or temperatures."""
    key = canonical_fluid_name(name)
    if key is None:
        raise ValueError(f"unknown fluid {name!r}; allowed: {', '.join(FLUIDS)}")
    if not (T_RANGE[0] <= temperature <= T_RANGE[1]):
        raise ValueError(f"fluid temperature must be in [{T_RANGE[0]:g}, {T_RANGE[1]:g}] K "
                         f"(got {temperature:g} K)")
    return FLUIDS[key].at(temperature)


def stokes_drag_coefficient(cdre: float, density: float, viscosity: float,
                            ball_radius: float) -> float:
    """Linear race-drag coefficient [N s/m] of the Stokes regime: C (pi/4) rho nu r.

    Spannan eq. (5.26) is this times R^2 (the torque coefficient beta [N m s]); it is the
    ``ball_drag`` a scene needs for the same fluid with the linear law."""
    return cdre * 0.25 * math.pi * density * viscosity * ball_radius


def hermite_cubic(stokes: float, plateau: float) -> tuple[float, float, float, float]:
    """Coefficients (a0..a3) of Y(L) = log10 c_d, L = log10 Re, on [1, log10 2e4] with
    Y(1) = log10(stokes/10), Y'(1) = -1, Y(L2) = log10(plateau), Y'(L2) = 0."""
    l1, l2 = math.log10(RE_STOKES), math.log10(RE_PLATEAU)
    y1, y2 = math.log10(stokes / RE_STOKES), math.log10(plateau)
    a = np.array([[1.0, l1, l1 ** 2, l1 ** 3], [0.0, 1.0, 2 * l1, 3 * l1 ** 2],
                  [1.0, l2, l2 ** 2, l2 ** 3], [0.0, 1.0, 2 * l2, 3 * l2 ** 2]])
    return tuple(float(v) for v in np.linalg.solve(a, [y1, -1.0, y2, 0.0]))


def law_coefficients(law: str, stokes: float = 0.0, plateau: float = 0.0
                     ) -> tuple[int, float, tuple[float, float, float, float], float]:
    """(kernel law id, c_d Re of the Stokes regime, cubic Y coefficients, plateau c_d).

    ``stokes``/``plateau`` of 0 take the law's own values."""
    if law == "linear":
        return LAW_NONE, 0.0, (0.0, 0.0, 0.0, 0.0), 0.0
    if law == "stokes":
        return LAW_STOKES, stokes or JAN_CHEN_STOKES, (0.0, 0.0, 0.0, 0.0), 0.0
    if law == "jan_chen_1997":
        if stokes or plateau:
            raise ValueError("fluid_stokes_drag and fluid_drag_plateau cannot be changed for "
                             "'jan_chen_1997' (its printed cubic fixes 322 and 0.74); use "
                             "'spannan_2021' for a law with other anchors")
        return LAW_CUBIC, JAN_CHEN_STOKES, JAN_CHEN, JAN_CHEN_PLATEAU
    if law == "spannan_2021":
        c = stokes or SPANNAN_STOKES
        pl = plateau or SPANNAN_PLATEAU
        return LAW_CUBIC, c, hermite_cubic(c, pl), pl
    raise ValueError(f"unknown drag law {law!r}; allowed: {', '.join(DRAG_LAWS)}")


def drag_coefficient(re, law: str = "spannan_2021", stokes: float = 0.0, plateau: float = 0.0):
    """c_d(Re) of ``law`` (numpy, for plots and tests; the kernel evaluates the same formula)."""
    lid, c, a, pl = law_coefficients(law, stokes, plateau)
    re = np.asarray(re, dtype=float)
    if lid == LAW_NONE:
        raise ValueError("the 'linear' law has no c_d(Re); it uses the scene's ball_drag")
    out = c / re
    if lid == LAW_CUBIC:
        mid = (re > RE_STOKES) & (re <= RE_PLATEAU)
        lg = np.log10(np.where(mid, re, RE_STOKES))
        out = np.where(mid, 10.0 ** (a[0] + lg * (a[1] + lg * (a[2] + lg * a[3]))), out)
        out = np.where(re > RE_PLATEAU, pl, out)
    return out


@njit(cache=True, inline="always")
def race_drag(u, law, klin, kquad, re_per_speed, a0, a1, a2, a3, plateau):
    """(drag force [N] along +u, d force / du [N s/m]) on one ball moving at ``u`` [m/s]
    relative to the fluid.  ``klin`` = C (pi/4) rho nu r, ``kquad`` = rho pi r^2 / 2,
    ``re_per_speed`` = 2 r / nu [s/m]; a0..a3 the cubic of log10 c_d over log10 Re."""
    if law == LAW_STOKES:
        return klin * u, klin
    re = abs(u) * re_per_speed
    if re <= RE_STOKES:
        return klin * u, klin
    if re > RE_PLATEAU:
        f = kquad * plateau * abs(u)
        return f * u, 2.0 * f
    # log10 and 10^Y by the branch-free log and exp of abb_gym.physics.elementary (the C
    # library's log10 and pow would keep every lane loop over the balls scalar), on Re held
    # inside the middle range so that lanes in the other regimes compute harmless numbers
    re_mid = min(max(float(re), RE_STOKES), RE_PLATEAU)
    lg = el.log_positive(re_mid) * INV_LN10
    cd = el.exp_bounded(LN10 * (a0 + lg * (a1 + lg * (a2 + lg * a3))))
    slope = a1 + lg * (2.0 * a2 + 3.0 * lg * a3)  # dY/dL: d(c_d u|u|)/du = c_d |u| (2 + Y')
    f = kquad * cd * abs(u)
    return f * u, f * (2.0 + slope)
