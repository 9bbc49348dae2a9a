"""Tune and sweep the baseline families on an environment's scenario distribution.

Every candidate parameter set of a family becomes a :class:`SpeedProfile`; candidates x
episodes run as the sub-environments of native vector environments (RunUpSpeed, each
sub-environment with its own profile and seeded episode), chunked into executor tasks.

* :func:`tune` - the tuner: per family, a seeded space-filling sample of the parameter box
  (:data:`SPACES`, in units of the scene's critical speed, Yoshida's dwell time and the default
  run-up acceleration), then a second sample in a box a quarter the size around the best;
  the objective is the mean return on the **training** preset (what the agents optimise).
  The result goes where ``out`` says (:func:`write_tuned`); a ``baselines/<scene>.yaml`` on
  the search path of :mod:`abb_gym.resources` is what ``baseline:NAME`` policies then use.
* :func:`sweep` - the same families over the same boxes on the **test** preset, as points
  (mean run-up time, mean residual vibration) for the speed-versus-accuracy chart.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from tqdm import tqdm

from .baseline_policy import BaselinePolicy
from ..evaluation.evaluate import Chunk, run_chunk
from . import profiles

ENV_ID = "abb_gym/RunUpSpeed-v0"

# parameter -> (low, high, unit): "wc" x critical speed, "td" x default dwell time,
# "acc" x default run-up acceleration
SPACES: dict[str, dict[str, tuple[float, float, str]]] = {
    "ramp": {"accel": (0.5, 2.0, "acc")},
    "speed_dwell": {"dwell_speed": (0.8, 1.4, "wc"), "dwell_time": (0.2, 2.5, "td")},
    "accel_dwell": {"dwell_speed": (0.8, 1.4, "wc"), "dwell_time": (0.2, 2.5, "td"),
                    "dwell_accel": (0.1, 0.9, "acc")},
    "decel_dwell": {"dwell_speed": (0.9, 1.6, "wc"), "dwell_time": (0.1, 1.5, "td"),
                    "dwell_accel": (-0.9, -0.1, "acc")},
    "speed_reduction": {"plateau_speed": (1.05, 2.0, "wc"), "plateau_time": (0.2, 4.0, "td")},
}


def _scales(scene) -> dict[str, float]:
    return {"wc": scene.critical_speed, "td": profiles.default_dwell_time(scene),
            "acc": profiles.default_accel(scene)}


def sample(family: str, scene, n: int, rng: np.random.Generator,
           box: dict[str, tuple[float, float]] | None = None) -> list[dict[str, float]]:
    """``n`` parameter sets of ``family`` (Latin hypercube in the box, physical units)."""
    space = SPACES[family]
    sc = _scales(scene)
    box = box or {k: (lo * sc[u], hi * sc[u]) for k, (lo, hi, u) in space.items()}
    out = []
    cols = {k: (rng.permutation(n) + rng.random(n)) / n for k in box}
    for i in range(n):
        params = {k: float(lo + cols[k][i] * (hi - lo)) for k, (lo, hi) in box.items()}
        if "plateau_speed" in params:
            params["plateau_speed"] = min(params["plateau_speed"], scene.drive_operating_speed)
        if "dwell_speed" in params:
            params["dwell_speed"] = min(params["dwell_speed"], scene.drive_operating_speed)
        out.append(params)
    return out


@dataclass(frozen=True)
class CandidateTask:
    """Candidates x episodes of one family as one vector environment."""
    scene: str
    preset: str
    family: str
    candidates: tuple[tuple[tuple[str, float], ...], ...]
    episodes: tuple[int, ...]
    seed: int


def _run_candidates(task: CandidateTask) -> list[dict]:
    pairs = [(c, k) for c in range(len(task.candidates)) for k in task.episodes]
    chunk = Chunk(ENV_ID, task.scene, task.preset, f"sweep:{task.family}", task.seed,
                  tuple(k for _, k in pairs))

    def factory(env):
        setup = env.unwrapped.setup
        sc = setup.scene.replace(drive_operating_speed=setup.operating_speed)
        profs = [profiles.build(task.family, sc, **dict(task.candidates[c])) for c, _ in pairs]
        return BaselinePolicy(f"baseline:{task.family}", profs)

    episodes, _ = run_chunk(chunk, factory)
    for (c, _), row in zip(pairs, episodes):
        row["candidate"] = c
    return episodes


def evaluate_candidates(scene_name: str, family: str, candidates: list[dict], episodes: int,
                        seed: int, preset: str, executor=None, per_task: int = 256) -> list[dict]:
    """Mean metrics of each candidate over ``episodes`` seeded episodes."""
    from ..physics.scene import load_scene
    load_scene(scene_name)  # validate early, with the scene's own error message
    per = max(1, per_task // episodes)
    cand = [tuple(sorted(c.items())) for c in candidates]
    tasks = [CandidateTask(scene_name, preset, family, tuple(cand[a:a + per]),
                           tuple(range(episodes)), seed)
             for a in range(0, len(cand), per)]
    if executor is None:  # this process; the vector environment already uses every core
        parts = [_run_candidates(t) for t in tqdm(tasks, desc=f"{family} candidates",
                                                  disable=len(tasks) < 2)]
    else:
        parts = executor.map(_run_candidates, tasks, desc=f"{family} candidates")
    rows = []
    for a, part in zip(range(0, len(cand), per), parts):
        for c in range(len(tasks[a // per].candidates)):
            eps = [e for e in part if e["candidate"] == c]
            mean = {k: float(np.nanmean([float(e[k]) for e in eps])) if any(
                np.isfinite(float(e[k])) for e in eps) else math.nan
                for k in ("return", "time_to_speed", "residual_vibration", "peak_whirl",
                          "balanced")}
            rows.append({"family": family, "params": dict(cand[a + c]), **mean})
    return rows


def tune(scene_name: str, families=tuple(SPACES), n_first: int = 24, n_second: int = 16,
         episodes: int = 24, seed: int = 20_000, preset: str = "train", executor=None,
         out: str | Path | None = None, force: bool = False) -> dict[str, Any]:
    """Tune each family (see the module docstring); returns the result and, with ``out``,
    writes it there (:func:`write_tuned`)."""
    from ..physics.scene import load_scene
    scene = load_scene(scene_name)
    rng = np.random.default_rng(seed)
    result: dict[str, Any] = {
        "scene": scene_name, "env": ENV_ID, "preset": preset, "episodes": episodes,
        "seed": seed, "objective": "mean return on the preset (the environment's reward)",
        "families": {}}
    for fam in families:
        first = sample(fam, scene, n_first, rng)
        default = {}
        rows = evaluate_candidates(scene_name, fam, [default] + first, episodes, seed, preset,
                                   executor)
        best = max(rows[1:], key=lambda r: r["return"])
        sc = _scales(scene)
        box = {}
        for k, (lo, hi, u) in SPACES[fam].items():
            width = 0.25 * (hi - lo) * sc[u]
            centre = best["params"][k]
            box[k] = (max(lo * sc[u], centre - width / 2), min(hi * sc[u], centre + width / 2))
        second = evaluate_candidates(scene_name, fam, sample(fam, scene, n_second, rng, box),
                                     episodes, seed, preset, executor)
        best = max([best] + second, key=lambda r: r["return"])
        result["families"][fam] = {
            "params": {k: round(v, 6) for k, v in best["params"].items()},
            "mean_return": round(best["return"], 5),
            "default_mean_return": round(rows[0]["return"], 5),
            "mean_time_to_speed": round(best["time_to_speed"], 4),
            "mean_residual_vibration": round(best["residual_vibration"], 5),
            "candidates": 1 + n_first + n_second,
        }
    if out is not None:
        result["path"] = str(write_tuned(result, out, force=force))
    return result


def write_tuned(result: dict[str, Any], path: str | Path, force: bool = False) -> Path:
    """Write a tuning result to ``path`` (a ``.yaml`` file, or a folder that gets
    ``<scene>.yaml``).  An existing file
    is replaced only with ``force``; the installed package's shipped files never are."""
    from .. import resources
    path = Path(path)
    if path.suffix not in (".yaml", ".yml"):  # a folder
        path = path / f"{result['scene']}.yaml"
    if resources.is_shipped(path) and "site-packages" in path.resolve().parts:
        raise ValueError(f"{str(path)!r} belongs to the installed abb-gym package; write the "
                         f"tuned parameters to your own folder and add it with --configs or "
                         f"${resources.ENV_VAR}")
    if path.exists() and not force:
        raise ValueError(f"{str(path)!r} exists; pass --force to replace it")
    if path.parent.exists() and not path.parent.is_dir():
        raise ValueError(f"cannot write {str(path)!r}: {str(path.parent)!r} is a file")
    path.parent.mkdir(parents=True, exist_ok=True)
    header = ("# Tuned baseline parameters (abb-gym tune-baselines); SI units, rad/s, s,\n"
              "# rad/s^2.  Tuned on the training preset; evaluate on the test preset.\n")
    path.write_text(header + yaml.safe_dump(result, sort_keys=False))
    return path


def sweep(scene_name: str, families=tuple(SPACES), n: int = 12, episodes: int = 12,
          seed: int = 0, preset: str = "test", executor=None) -> list[dict]:
    """Each family over its box on the test preset: rows with mean time and residual."""
    from ..physics.scene import load_scene
    scene = load_scene(scene_name)
    rng = np.random.default_rng(seed + 7)
    rows = []
    for fam in families:
        rows += evaluate_candidates(scene_name, fam, sample(fam, scene, n, rng), episodes, seed,
                                    preset, executor)
    return rows
