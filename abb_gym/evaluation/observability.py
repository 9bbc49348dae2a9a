"""Can a drive tell where the balls started?  Observability of the balls' start from what a drive
measures.

The per-machine oracle (:mod:`abb_gym.baselines.oracle`) plans knowing where each machine's
balls start, and without that knowledge its residual gain over the best fixed profile is
gone.  A controller that only watches the drive can use it only if its measurements carry it.  This
module measures how much they do: machines of a preset run up under one open-loop policy (the
tuned ``knots`` by default, so that the measurements do not depend on a learner), and a
regressor learns, from the environment's observation over the first ``n`` decisions, three
quantities of the start on other machines:

* ``ball_vector``: the balls' mean direction ``z0 = mean_i exp(i phi_i(0))`` in the rotor
  frame, measured from the imbalance (what the oracle exploits; for two equal balls it fixes
  their angles up to a swap);
* ``total_imbalance``: ``|U0 + sum_i m_i R exp(i phi_i(0))|`` / balancing capacity, the
  imbalance a balancing machine would read at low speed;
* ``control``: a number drawn independently of the machine, which no measurement carries.  Its
  score shows what the regressor reports for nothing (about 0, or below).

The score is the coefficient of determination on held-out machines, ``R^2 = 1 - SSE / SST``
(for the vector, summed over both components), with a 95 % bootstrap interval over the
held-out machines.  The regressor is a small multilayer perceptron (two tanh layers of 128,
Adam, stopped early on a fifth of the training machines; ``torch``, from the ``train`` extra)
on the standardised observation history: a lower bound on what the measurements carry, since a
better estimator can only do better.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..envs import tasks

__all__ = ["ObservabilityRow", "ball_start_observability", "r2_score", "TARGETS"]

TARGETS = ("ball_vector", "total_imbalance", "control")


@dataclass(frozen=True)
class ObservabilityRow:
    """The scores after the first ``decisions`` decisions (``time`` s; the median rotor speed
    of the held-out machines then, rad/s): for each of :data:`TARGETS` a dict ``{"r2",
    "ci_low", "ci_high"}``."""
    decisions: int
    time: float
    rotor_speed: float
    scores: dict[str, dict[str, float]]


def r2_score(predicted: np.ndarray, actual: np.ndarray) -> float:
    """``1 - SSE / SST`` over all columns of (rows, columns) arrays; NaN if ``actual`` is
    constant."""
    predicted = np.asarray(predicted, float).reshape(len(predicted), -1)
    actual = np.asarray(actual, float).reshape(len(actual), -1)
    sst = float(((actual - actual.mean(0)) ** 2).sum())
    if sst == 0.0:
        return math.nan
    return 1.0 - float(((predicted - actual) ** 2).sum()) / sst


def _bootstrap(predicted, actual, rng, resamples: int = 1000) -> tuple[float, float]:
    n = len(actual)
    values = []
    for _ in range(resamples):
        i = rng.integers(0, n, n)
        values.append(r2_score(predicted[i], actual[i]))
    low, high = np.nanpercentile(values, [2.5, 97.5])
    return float(low), float(high)


def _collect(env_id, scene, preset, seeds, policy, steps, env_kwargs, control_seed):
    """Observations (machines, steps + 1, obs), rotor speeds (machines, steps) and targets."""
    from .evaluate import make_env, resolve
    n = len(seeds)
    env = make_env(env_id, scene, preset, n, **env_kwargs)
    pol = resolve(policy, env_id, scene)
    obs, info = env.reset(seed=[int(s) for s in seeds])
    pol.reset(env, np.ones(n, bool))
    sc = env.unwrapped.setup.scene
    phi0 = np.asarray(info["initial_ball_angles"], float)
    masses = np.asarray(sc.ball_mass, float)
    balls = (masses * sc.race_radius * np.exp(1j * phi0)).sum(1)
    z0 = np.exp(1j * phi0).mean(1)
    total = np.abs(np.asarray(info["imbalance"], float) + balls) / sc.balancing_capacity
    control = np.random.default_rng(control_seed).random(n)
    history, speeds = [np.array(obs, float)], []
    for _ in range(steps):
        obs, _, _, _, info = env.step(np.asarray(pol.act(obs, info), np.float32))
        history.append(np.array(obs, float))
        speeds.append(np.asarray(info["rotor_speed"], float))
    interval = float(env.unwrapped.setup.config.control_interval)
    env.close()
    targets = {"ball_vector": np.c_[z0.real, z0.imag], "total_imbalance": total[:, None],
               "control": control[:, None]}
    return np.stack(history, 1), np.stack(speeds, 1), targets, interval


def _fit_predict(x, y, x_test, seed: int, epochs: int):
    """Predictions for ``x_test`` of an MLP fitted to (``x``, ``y``); a fifth of the training
    machines is held back to stop the fit where it starts to learn noise (early stopping:
    without it, the control target scored R^2 of about -1.4 on 2,048 machines)."""
    import copy

    import torch
    torch.manual_seed(seed)
    n_val = max(2, len(x) // 5)
    mu, sd = x.mean(0), x.std(0) + 1e-8
    ym, ysd = y.mean(0), y.std(0) + 1e-12
    xs = torch.tensor((x - mu) / sd, dtype=torch.float32)
    ys = torch.tensor((y - ym) / ysd, dtype=torch.float32)
    xv, yv, xs, ys = xs[:n_val], ys[:n_val], xs[n_val:], ys[n_val:]
    xt = torch.tensor((x_test - mu) / sd, dtype=torch.float32)
    net = torch.nn.Sequential(torch.nn.Linear(xs.shape[1], 128), torch.nn.Tanh(),
                              torch.nn.Linear(128, 128), torch.nn.Tanh(),
                              torch.nn.Linear(128, ys.shape[1]))
    opt = torch.optim.Adam(net.parameters(), lr=1e-3, weight_decay=1e-4)
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        best, best_state = float(((net(xv) - yv) ** 2).mean()), copy.deepcopy(net.state_dict())
    for _ in range(epochs):
        order = torch.randperm(len(xs), generator=gen)
        for b in range(0, len(xs), 256):
            i = order[b:b + 256]
            loss = ((net(xs[i]) - ys[i]) ** 2).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
        with torch.no_grad():
            val = float(((net(xv) - yv) ** 2).mean())
        if val < best:
            best, best_state = val, copy.deepcopy(net.state_dict())
    net.load_state_dict(best_state)
    with torch.no_grad():
        return net(xt).numpy() * ysd + ym


def ball_start_observability(scene: str = "spannan_cfrp", train_preset: str = "varied",
                             test_preset: str = "varied_test",
                             env_id: str = tasks.DEFAULT_ENV_ID,
                             env_kwargs: dict[str, Any] | None = None,
                             policy: str = "baseline:knots", train_machines: int = 2048,
                             test_machines: int = 256, decisions: Sequence[int] = (4, 12, 24, 40),
                             seed: int = 0, epochs: int = 300, progress: bool = True
                             ) -> list[ObservabilityRow]:
    """Scores (module docstring) after each count of ``decisions``: the regressor learns on
    ``train_machines`` machines of ``train_preset`` (seeds 100000 + k) and is scored on the
    first ``test_machines`` held-out machines of ``test_preset`` (seeds ``seed`` + k, those
    :func:`abb_gym.evaluation.evaluate.evaluate` runs).  ``env_kwargs`` configure the
    environment (e.g. the agents' ``control_interval`` and the synchronous-vibration sensor);
    the observation is taken one decision at a time and stacked here."""
    from ..progress import ProgressBar
    for name, value, low in (("train_machines", train_machines, 8),
                             ("test_machines", test_machines, 8), ("epochs", epochs, 1)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise ValueError(f"{name} must be an integer >= {low} (got {value!r})")
    counts = sorted({int(n) for n in decisions})
    if not counts or counts[0] < 1:
        raise ValueError(f"decisions must be integers >= 1 (got {list(decisions)!r})")
    try:
        import torch  # noqa: F401
    except ImportError as exc:
        raise ImportError("ball_start_observability needs torch: pip install "
                          "'abb-gym[train]'") from exc
    env_kwargs = dict(env_kwargs or {})
    steps = counts[-1]
    x_tr, _, y_tr, _ = _collect(env_id, scene, train_preset,
                                range(100000, 100000 + train_machines), policy, steps,
                                env_kwargs, control_seed=(seed, 1))
    x_te, w_te, y_te, interval = _collect(env_id, scene, test_preset,
                                          range(seed, seed + test_machines), policy, steps,
                                          env_kwargs, control_seed=(seed, 2))
    rows = []
    rng = np.random.default_rng((seed, 3))
    with ProgressBar(total=len(counts) * len(TARGETS), desc="observability", unit="fit",
                     disable=not progress) as bar:
        for n in counts:
            x = x_tr[:, :n + 1].reshape(len(x_tr), -1)
            xt = x_te[:, :n + 1].reshape(len(x_te), -1)
            scores = {}
            for k, target in enumerate(TARGETS):
                predicted = _fit_predict(x, y_tr[target], xt, seed + k, epochs)
                low, high = _bootstrap(predicted, y_te[target], rng)
                scores[target] = {"r2": r2_score(predicted, y_te[target]), "ci_low": low,
                                  "ci_high": high}
                bar.update()
            rows.append(ObservabilityRow(n, n * interval, float(np.median(w_te[:, n - 1])),
                                         scores))
    return rows


def table(rows: Sequence[ObservabilityRow]) -> str:
    """The rows as a Markdown table, R^2 [95 % CI]."""
    head = ("| decisions | time [s] | rotor speed [rad/s] | "
            + " | ".join(f"R^2 {t}" for t in TARGETS) + " |")
    lines = [head, "|" + "---|" * (3 + len(TARGETS))]
    for r in rows:
        cells = [f"{r.scores[t]['r2']:.2f} [{r.scores[t]['ci_low']:.2f}, "
                 f"{r.scores[t]['ci_high']:.2f}]" for t in TARGETS]
        lines.append(f"| {r.decisions} | {r.time:.2f} | {r.rotor_speed:.1f} | "
                     + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    """``python -m abb_gym.evaluation.observability``: print the table."""
    import argparse
    import json
    import sys
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    p.add_argument("--scene", default="spannan_cfrp")
    p.add_argument("--train-preset", default="varied")
    p.add_argument("--test-preset", default="varied_test")
    p.add_argument("--env-kwargs", default="{}", help="JSON, e.g. "
                   "'{\"control_interval\": 0.25, \"reward\": {\"residual\": 10}}'")
    p.add_argument("--policy", default="baseline:knots")
    p.add_argument("--train-machines", type=int, default=2048)
    p.add_argument("--test-machines", type=int, default=256)
    p.add_argument("--decisions", type=int, nargs="+", default=[4, 12, 24, 40])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--epochs", type=int, default=300)
    args = p.parse_args(argv)
    try:
        rows = ball_start_observability(args.scene, args.train_preset, args.test_preset,
                                        env_kwargs=json.loads(args.env_kwargs),
                                        policy=args.policy,
                                        train_machines=args.train_machines,
                                        test_machines=args.test_machines,
                                        decisions=args.decisions, seed=args.seed,
                                        epochs=args.epochs)
    except (ValueError, ImportError) as exc:
        print(f"observability: error: {exc}", file=sys.stderr)
        return 2
    print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
