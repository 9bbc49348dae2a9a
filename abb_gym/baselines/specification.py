"""An engineer's specification for the tuner: least residual vibration under requirements.

``abb-gym tune-baselines --spec "peak_whirl<=20,run_up<=5"`` tunes each family to the
smallest mean residual vibration [W_r/e] among the candidates that meet every requirement,
beside the default objective, the environment's return.  A requirement is ``METRIC<=BOUND``
or ``METRIC>=BOUND`` on a candidate's mean over the tuning episodes:

{table}

Every run-up must complete (``at_speed>=1``) unless the specification says otherwise: the
residual is measured over the runs that reach the operating speed, and a profile that reaches
it on half of the machines would otherwise win on those.

**Constraint handling: feasibility first** (Deb 2000, "An efficient constraint handling
method for genetic algorithms").  Candidates are ranked so that every feasible one comes
before every infeasible one; feasible ones by their residual, infeasible ones by their total
violation, each requirement's shortfall relative to its bound (``(value - bound) / |bound|``,
so that seconds and W_r/e add up).  Why not a penalty (residual + weight x violation): the
requirements have different units and scales, so any weight is a guess; too small a weight
lets an infeasible profile with a small residual win, too large a one flattens the
landscape.  Feasibility first needs no weight, never prefers an infeasible candidate, and
still leads an infeasible population toward the feasible region (less violation ranks
higher).  CMA-ES uses only the ranking of each generation, so it is given the candidates'
ranks (:meth:`Specification.fitness`): the ranking is the whole objective, nothing is lost
in a conversion to one number.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

__all__ = ["Requirement", "Specification", "METRICS"]

#: spec name -> (metric of the tuner's rows, unit, meaning)
METRICS = {
    "peak_whirl": ("peak_whirl", "W_r/e", "largest vibration before the settled entry"),
    "run_up": ("run_up_time", "s", "run-up time, to the start of the final stay in the band"),
    "residual": ("residual_vibration", "W_r/e", "mean vibration over the settling window"),
    "at_speed": ("at_speed", "share", "share of the runs that reach the operating speed"),
    "balanced": ("balanced", "share", "share of the runs whose balls end balanced"),
}
#: what is minimised
OBJECTIVE = "residual_vibration"
_PATTERN = re.compile(r"^\s*([A-Za-z_]+)\s*(<=|>=)\s*(\S+)\s*$")


def _table() -> str:
    rule = "  ".join("=" * w for w in (10, 18, 6, 56))
    rows = [f"{name:<10}  {metric:<18}  {unit:<6}  {meaning}"
            for name, (metric, unit, meaning) in METRICS.items()]
    return "\n".join([rule, f"{'name':<10}  {'metric':<18}  {'unit':<6}  meaning", rule, *rows,
                      rule])


__doc__ = __doc__.replace("{table}", _table())


@dataclass(frozen=True)
class Requirement:
    """``name`` (a key of :data:`METRICS`) ``op`` (``<=`` or ``>=``) ``bound``."""

    name: str
    op: str
    bound: float

    @property
    def metric(self) -> str:
        return METRICS[self.name][0]

    def violation(self, value: float) -> float:
        """How far ``value`` misses the bound, relative to it (0: met; inf: no value)."""
        if not math.isfinite(value):
            return math.inf
        miss = value - self.bound if self.op == "<=" else self.bound - value
        return max(0.0, miss) / max(abs(self.bound), 1e-12)

    def __str__(self) -> str:
        return f"{self.name}{self.op}{self.bound:g}"


@dataclass(frozen=True)
class Specification:
    """Requirements on the mean metrics of a candidate (module docstring)."""

    requirements: tuple[Requirement, ...]

    @classmethod
    def parse(cls, text: Any, option: str = "--spec") -> "Specification":
        """``"peak_whirl<=20,run_up<=5"`` -> a Specification (``at_speed>=1`` added unless
        given); a ValueError naming ``option`` and the allowed names otherwise."""
        if not isinstance(text, str) or not text.strip():
            raise ValueError(f"{option} must be requirements like 'peak_whirl<=20,run_up<=5' "
                             f"(got {text!r:.80})")
        reqs: list[Requirement] = []
        for part in text.split(","):
            m = _PATTERN.match(part)
            if not m:
                raise ValueError(f"{option}: {part.strip()!r} is not METRIC<=BOUND or "
                                 f"METRIC>=BOUND (metrics: {', '.join(METRICS)})")
            name, op, value = m.groups()
            if name not in METRICS:
                raise ValueError(f"{option}: unknown metric {name!r}; allowed: "
                                 f"{', '.join(METRICS)}")
            try:
                bound = float(value)
            except ValueError:
                bound = math.nan
            if not math.isfinite(bound):
                raise ValueError(f"{option}: the bound of {name!r} must be a finite number "
                                 f"[{METRICS[name][1]}] (got {value!r})")
            if any(r.name == name and r.op == op for r in reqs):
                raise ValueError(f"{option}: {name}{op} is given twice")
            reqs.append(Requirement(name, op, bound))
        if not any(r.name == "at_speed" for r in reqs):
            reqs.append(Requirement("at_speed", ">=", 1.0))
        return cls(tuple(reqs))

    def __str__(self) -> str:
        return ",".join(str(r) for r in self.requirements)

    def violation(self, row: Mapping[str, Any]) -> float:
        """The total relative violation of a candidate's mean metrics ``row`` (0: feasible)."""
        return sum(r.violation(float(row[r.metric])) for r in self.requirements)

    def key(self, row: Mapping[str, Any]) -> tuple:
        """The rank of a candidate, smaller is better: feasible ones first, by residual, then
        infeasible ones by violation (module docstring)."""
        violation = self.violation(row)
        if violation > 0.0:
            return (1, violation)
        residual = float(row[OBJECTIVE])
        return (0, residual if math.isfinite(residual) else math.inf)

    def fitness(self, rows: Sequence[Mapping[str, Any]]) -> list[float]:
        """The rank of each candidate of a generation (0: best; equal keys, equal ranks), for
        CMA-ES, which minimises."""
        keys = [self.key(r) for r in rows]
        order = sorted(set(keys))
        rank = {k: float(i) for i, k in enumerate(order)}
        return [rank[k] for k in keys]

    def report(self, row: Mapping[str, Any]) -> dict[str, Any]:
        """Each requirement with the candidate's value and whether it is met, for the result."""
        return {str(r): {"value": round(float(row[r.metric]), 5),
                         "met": r.violation(float(row[r.metric])) == 0.0}
                for r in self.requirements}
