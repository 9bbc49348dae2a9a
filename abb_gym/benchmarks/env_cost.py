"""CPU time per env-step, side by side in one process: ball counts, the washer, batch sizes
with the default threads and with one, and the CartPole ratio per core (``abb-gym bench
speed``; ``python -m abb_gym.benchmarks.env_cost [ballcount|washer|batch|cartpole|ops]``).

Wall rates on a shared machine vary 2-10x from minute to minute, so every table here steps
its cases in alternating bursts (:data:`BURST_S` each) within one process, reads both the
wall clock and this process's CPU time (:func:`time.process_time`, every thread) around each
burst, and reports medians over the rounds.  The ratios are those of the CPU time per
env-step; where the thread counts differ, the CPU time counts every thread's work (a thread
that waits at a barrier counts what it spins).  Each table says the machine's load (the
one-minute load average) when it ran.

The cost tables (ball count, washer, CartPole) step every case on **one thread**, so that the
CPU time is the work of the step alone.  With the default threads it also counts the OpenMP
worker's wait after each parallel step (up to :data:`abb_gym._threads.SHORT_SPIN` spins, about
0.17 ms here), a share that depends on the step's length and on what else the machine runs.

Tables:

* :func:`ball_count_table` - the vector environment at 256 sub-environments of the
  ``yoshida_odd`` machine with 2 .. 12 balls (spread evenly; contact off and on), against 2
  balls, beside the ratio of the right-hand side's operation counts (:func:`operation_count`);
* :func:`washer_row` - the washer against ``yoshida_odd`` at 256 sub-environments;
* :func:`batch_table` - 1 .. 4096 sub-environments, default threads against one thread, on
  its own and beside another process that keeps one CPU busy (:func:`busy_neighbour`);
* :func:`cartpole_row` - ``yoshida_odd`` at 1024 on one thread against Gymnasium's
  ``CartPoleVectorEnv`` (one thread: numpy), per core.
"""
from __future__ import annotations

import contextlib
import importlib
import math
import os
import re
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable, Iterable, Iterator

import numpy as np

__all__ = ["interleaved", "ball_count_table", "washer_row", "batch_table", "cartpole_row",
           "operation_count", "load_note", "speed_rows", "performance_page", "LAST_TABLES"]

BURST_S = 0.25  # [s] of stepping per case and round
ENV_ID = "abb_gym/RunUpSpeed-v0"
EPISODE_STEPS = 100


def load_note() -> str:
    """The machine's load when a table ran: ``load 1.9 on 2 CPUs`` (one-minute average)."""
    try:
        load = os.getloadavg()[0]
    except OSError:
        return "load unknown"
    return f"load {load:.1f} on {os.cpu_count()} CPUs"


def _env(scene, num_envs: int, preset: str = "train", **kw):
    import gymnasium as gym
    import abb_gym  # noqa: F401  (registers the ids)
    return gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        scene=scene, preset=preset, control_interval=0.01,
                        max_episode_steps=EPISODE_STEPS, **kw)


class _Case:
    """One vector environment stepped in bursts of whole episodes, with the same random
    actions in every episode (resets included), on ``threads`` numba threads (None: the
    default).

    Whole episodes, because an env-step's cost follows the episode: the step rule shortens
    the integrator's step as the rotor speeds up (the rolling resistance's slope grows with
    the speed squared), and the sub-environments of a benchmark start their episodes
    together, so a burst that cut episodes anywhere would do a different share of cheap and
    dear steps than the next."""

    def __init__(self, env, threads: int | None = None, seed: int = 0):
        self.env = env
        self.threads = threads
        self.n = env.num_envs
        env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        shape = (EPISODE_STEPS, self.n) + env.single_action_space.shape
        self.actions = rng.uniform(-1.0, 1.0, shape).astype(env.single_action_space.dtype)
        self.k = 0
        self.steps_per_burst = EPISODE_STEPS

    def step(self, count: int) -> None:
        for _ in range(count):
            self.env.step(self.actions[self.k % len(self.actions)])
            self.k += 1

    def burst(self) -> tuple[float, float, int]:
        """(wall [s], CPU [s], env-steps) of one burst."""
        # (by name: an import statement would put this module into the kernel-cache
        # fingerprint of abb_gym._jit_cache, and each edit here would flush the kernels)
        numba = importlib.import_module("numba")
        before = numba.get_num_threads()
        if self.threads is not None:
            numba.set_num_threads(self.threads)
        try:
            w0, c0 = time.perf_counter(), time.process_time()
            self.step(self.steps_per_burst)
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        finally:
            numba.set_num_threads(before)
        steps = self.n * self.steps_per_burst
        # aim each burst at BURST_S of wall time, in whole episodes
        episodes = int(self.steps_per_burst * min(4.0, BURST_S / max(wall, 1e-6))
                       // EPISODE_STEPS)
        self.steps_per_burst = EPISODE_STEPS * max(1, episodes)
        return wall, cpu, steps

    def close(self) -> None:
        self.env.close()


def interleaved(cases: dict[str, _Case], rounds: int) -> dict[str, dict]:
    """Median CPU us per env-step and wall env-steps per second of each case, over ``rounds``
    rounds in which every case runs one burst (after two warm-up rounds), and the best wall
    rate (``best_rate``: the round least disturbed by the rest of the machine)."""
    samples: dict[str, list] = {k: [] for k in cases}
    for r in range(rounds + 2):
        # every other round in reverse order: a case that always ran first (after the
        # interpreter's own work between rounds) measured up to 1.3x slower than the same
        # code run second
        for name, case in (list(cases.items()) if r % 2 == 0 else list(cases.items())[::-1]):
            wall, cpu, steps = case.burst()
            if r >= 2:
                samples[name].append((cpu / steps * 1e6, steps / wall))
    out = {}
    for name, rows in samples.items():
        arr = np.array(rows)
        out[name] = {"cpu_us": float(np.median(arr[:, 0])),
                     "rate": float(np.median(arr[:, 1])), "best_rate": float(arr[:, 1].max()),
                     "rounds": len(rows)}
    return out


def _ring_scene(n_balls: int, contact: bool):
    """``yoshida_odd`` with ``n_balls`` balls spread evenly (contact 1000 N/m if asked)."""
    from ..physics import load_scene
    base = load_scene("yoshida_odd")
    angles = list(np.linspace(-np.pi, np.pi, n_balls, endpoint=False) + np.pi / n_balls)
    sc = base.replace(ball_count=n_balls, ball_angles0=angles)
    return sc.replace(contact_stiffness=1000.0) if contact else sc


_OPS = re.compile(r"= (fadd|fsub|fmul|fdiv|fneg|fcmp)\b|@llvm\.(sqrt|floor|fabs|fma|minnum|"
                  r"maxnum)\.f(32|64)|= select [^,]*(double|float)")
_DEFINE = re.compile(r'^define [^@]*@"?([^"(]+)', re.M)

# (numba imported within a line: a line that starts with "from numba" would put this module
# into the kernel-cache fingerprint of abb_gym._jit_cache, even inside this string, and each
# edit here would flush every compiled kernel)
_OPS_SCRIPT = """
import re, sys, json, numpy as np; from numba import types, typeof
from abb_gym.benchmarks import env_cost as ec
from abb_gym.physics import model as mdl
from abb_gym.benchmarks.rhs_cost import _inputs, _drive_row
res = {}
for n in json.loads(sys.argv[1]):
    for contact in (False, True):
        sc = ec._ring_scene(n, contact)
        spec = mdl.spec_of(mdl.pack_parameters(sc)[0], _drive_row(sc)) | mdl.SPEC_ONE_LANE
        args = _inputs(sc, 1, spec)
        sig = tuple(typeof(a) if i < 7 else types.literal(int(a)) for i, a in enumerate(args))
        mdl.accelerations_block.compile(sig)
        res[f"{n},{int(contact)}"] = ec.count_ir(mdl.accelerations_block.inspect_llvm(sig))
print("OPS", json.dumps(res))
"""


def count_ir(ir: str) -> int:
    """Floating-point operations one call of the one-lane right-hand side executes, read
    from its optimised LLVM IR (where every loop is unrolled): arithmetic, comparisons,
    selects and the sqrt/floor/fabs/fma intrinsics of the function, plus those of each
    function it calls times its call sites.  The all-pairs contact loop
    (``ball_contacts_lane``), which runs only where the neighbour list does not apply, is
    left out."""
    bodies = {}
    found = [(m.start(), m.group(1)) for m in _DEFINE.finditer(ir)]
    for k, (pos, name) in enumerate(found):
        end = found[k + 1][0] if k + 1 < len(found) else len(ir)
        bodies[name] = ir[pos:end]
    main = next(n for n in bodies if "accelerations_block" in n
                and not n.startswith(("cpython", "cfunc")))
    total = len(_OPS.findall(bodies[main]))
    for name, body in bodies.items():
        if name == main or name.startswith(("cpython", "cfunc", "NRT")) \
                or "ball_contacts_lane" in name:
            continue
        calls = len(re.findall(re.escape(name) + r'"?\(', bodies[main]))
        total += calls * len(_OPS.findall(body))
    return total


#: ball counts whose one-lane right-hand side LLVM unrolls whole, so that its IR holds every
#: operation a call executes (from 10 balls on it keeps a loop)
COUNTED = (2, 3, 4, 5)


def operation_count(ball_counts: Iterable[int]) -> dict[tuple[int, bool], int]:
    """:func:`count_ir` of the right-hand side for each ball count, contact off and on
    (``_ring_scene``): ``{(n, contact): operations}``.

    Counted in a fresh process with an empty cache (a kernel loaded from the cache has no IR
    to read) for :data:`COUNTED`; each further ball adds what the fifth added (the count is
    linear in n from 4 balls on, with contact too: the neighbour list has one pair per ball;
    counted up to 9 balls: 104 + 159 n without contact, 1451 + 267 (n - 5) with it)."""
    import json
    import tempfile
    with tempfile.TemporaryDirectory() as cache:
        res = subprocess.run([sys.executable, "-c", _OPS_SCRIPT, json.dumps(list(COUNTED))],
                             capture_output=True, text=True, timeout=3600,
                             env={**os.environ, "NUMBA_CACHE_DIR": cache, "ABB_GYM_QUIET": "1"})
    if res.returncode != 0:
        raise RuntimeError(f"operation count failed:\n{res.stderr[-2000:]}")
    line = next(ln for ln in res.stdout.splitlines() if ln.startswith("OPS "))
    counted = {(int(k.split(",")[0]), k.endswith("1")): v
               for k, v in json.loads(line[4:]).items()}
    out = {}
    for n in ball_counts:
        for contact in (False, True):
            if (n, contact) in counted:
                out[(n, contact)] = counted[(n, contact)]
            else:
                last, before = counted[(5, contact)], counted[(4, contact)]
                out[(n, contact)] = last + (n - 5) * (last - before)
    return out



def _measure_and_close(cases: dict, rounds: int) -> tuple[dict, dict]:
    """Interleaved CPU times of ``cases`` and their integrator steps; the cases closed."""
    try:
        return interleaved(cases, rounds), {k: _substeps(c) for k, c in cases.items()}
    finally:
        for c in cases.values():
            c.close()

def ball_count_table(ball_counts=(2, 3, 5, 8, 12), num_envs: int = 256, rounds: int = 7,
                     ops: dict | None = None) -> list[dict]:
    """The vector environment per ball count, contact off and on, against 2 balls without
    contact, on one thread: CPU us per env-step, its ratio, the same per integrator substep
    (contact shortens the step), the operation-count ratio (``ops``, default
    :func:`operation_count`) and the quotient of the last two (the target: within 1.3)."""
    ops = operation_count(ball_counts) if ops is None else ops
    rows = []
    for contact in (False, True):
        # (the nominal preset: the balls start where the scene spreads them; the train preset
        # would draw them into each other, and contact then takes every pair)
        cases = {n: _Case(_env(_ring_scene(n, contact), num_envs, preset="nominal"), threads=1)
                 for n in ball_counts}
        base = (_Case(_env(_ring_scene(2, False), num_envs, preset="nominal"), threads=1)
                if contact else None)
        if base is not None:
            cases["base"] = base
        res, steps = _measure_and_close(cases, rounds)
        ref = "base" if contact else 2
        for n in ball_counts:
            ratio = res[n]["cpu_us"] / res[ref]["cpu_us"]
            # per substep: contact shortens the step (its frequency bounds it)
            per_step = ratio * steps[ref] / steps[n]
            op_ratio = ops[(n, contact)] / ops[(2, False)]
            rows.append({"balls": n, "contact": "on" if contact else "off",
                         "cpu_us_per_env_step": round(res[n]["cpu_us"], 3),
                         "env_steps_per_s": round(res[n]["rate"]),
                         "substeps": steps[n], "ratio_to_2": round(ratio, 2),
                         "ratio_per_substep": round(per_step, 2),
                         "operations": ops[(n, contact)],
                         "operation_ratio": round(op_ratio, 2),
                         "ratio_over_operations": round(per_step / op_ratio, 2)})
    return rows


def washer_row(num_envs: int = 256, rounds: int = 7, integrator: str | None = None) -> dict:
    """The washer against ``yoshida_odd`` at ``num_envs`` sub-environments, CPU time per
    env-step on one thread (the target: <= 10x).  The washer runs the ``nominal`` preset (its
    balls start where the scene puts them): the ``train`` preset draws each ball's angle over
    the whole circle, which puts balls with contact into each other (every lane then takes
    the all-pairs contact: :func:`abb_gym.physics.model._contacts`)."""
    kw = {} if integrator is None else {"integrator": integrator}
    cases = {"washer": _Case(_env("washer", num_envs, preset="nominal", **kw), threads=1),
             "yoshida_odd": _Case(_env("yoshida_odd", num_envs), threads=1)}
    res, steps = _measure_and_close(cases, rounds)
    return {"num_envs": num_envs, "integrator": integrator or "default",
            "washer_cpu_us": round(res["washer"]["cpu_us"], 2),
            "yoshida_cpu_us": round(res["yoshida_odd"]["cpu_us"], 3),
            "ratio": round(res["washer"]["cpu_us"] / res["yoshida_odd"]["cpu_us"], 1),
            "washer_substeps": steps["washer"], "yoshida_substeps": steps["yoshida_odd"]}


def _substeps(case: _Case) -> float:
    """Median integrator steps per env-step of a case's last step."""
    from ..envs.layout import O_STEPS
    return float(np.median(case.env.unwrapped._bufs.out[:, O_STEPS]))


BATCH_SIZES = (1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048, 4096)


@contextlib.contextmanager
def busy_neighbour():
    """Another process keeping one CPU busy (a Python loop) while the block runs: a second
    training run, a seed sweep or any background job, as the threads' target names it."""
    proc = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        time.sleep(1.0)  # (the free-CPU estimate of abb_gym._threads sees it by then)
        yield proc
    finally:
        proc.kill()
        proc.wait()


def batch_table(sizes=BATCH_SIZES, rounds: int = 15, busy: bool = False) -> list[dict]:
    """Per batch size, the vector environment (``yoshida_odd``) with the default threads and
    with one thread, stepped alternately: wall rate and CPU time per env-step of each, and
    the wall-rate ratio default / one thread (the target: >= 0.9), of the median rounds and of
    the best ones; ``busy``: all of it beside :func:`busy_neighbour`.

    Both cases step one environment (its arrays at the same addresses): two environments of
    the same seed and actions ran the same serial code at 64 sub-environments 1.33x apart.
    Up to 128 sub-environments (one block) both cases run the same serial kernel, so a ratio
    there away from 1 is the method's noise, which 15 rounds narrow."""
    if busy:
        with busy_neighbour():
            return batch_table(sizes, rounds)
    rows = []
    for n in sizes:
        env = _env("yoshida_odd", n)
        cases = {"default": _Case(env), "one": _Case(env, threads=1)}
        try:
            res = interleaved(cases, rounds)
        finally:
            env.close()
        rows.append({"num_envs": n, "blocks": env.unwrapped._bufs.blocks.s.shape[0],
                     "lanes": env.unwrapped._bufs.blocks.lanes,
                     "default_rate": round(res["default"]["rate"]),
                     "one_thread_rate": round(res["one"]["rate"]),
                     "default_over_one": round(res["default"]["rate"] / res["one"]["rate"], 2),
                     "best_default_over_one": round(res["default"]["best_rate"]
                                                    / res["one"]["best_rate"], 2),
                     "default_cpu_us": round(res["default"]["cpu_us"], 3),
                     "one_thread_cpu_us": round(res["one"]["cpu_us"], 3)})
    return rows


class _CartPole:
    def __init__(self, num_envs: int):
        import gymnasium as gym
        self.env = gym.make_vec("CartPole-v1", num_envs=num_envs,
                                vectorization_mode="vector_entry_point")
        self.env.reset(seed=0)
        self.n = num_envs
        self.actions = np.random.default_rng(0).integers(0, 2, size=(64, num_envs))
        self.k = 0
        self.steps_per_burst = EPISODE_STEPS
        self.threads = None

    step = _Case.step
    burst = _Case.burst

    def close(self):
        self.env.close()


def cartpole_row(num_envs: int = 1024, rounds: int = 7) -> dict:
    """``yoshida_odd`` at ``num_envs`` on one thread against ``CartPoleVectorEnv`` per
    env-step, CPU time (the target: <= 8x)."""
    cp = _CartPole(num_envs)
    cases = {"abb": _Case(_env("yoshida_odd", num_envs), threads=1), "cartpole": cp}
    try:
        res = interleaved(cases, rounds)
    finally:
        for c in cases.values():
            c.close()
    return {"num_envs": num_envs, "abb_cpu_us": round(res["abb"]["cpu_us"], 3),
            "cartpole_cpu_us": round(res["cartpole"]["cpu_us"], 3),
            "ratio_per_core": round(res["abb"]["cpu_us"] / res["cartpole"]["cpu_us"], 1),
            "abb_one_thread_rate": round(res["abb"]["rate"]),
            "cartpole_rate": round(res["cartpole"]["rate"])}


def _print(rows) -> None:
    rows = rows if isinstance(rows, list) else [rows]
    from ..tables import markdown_table
    print(markdown_table(rows))


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    what = argv[0] if argv else "all"
    print(load_note())
    tables: dict[str, Callable] = {"ballcount": ball_count_table, "washer": washer_row,
                                   "batch": batch_table, "cartpole": cartpole_row,
                                   "batch_busy": lambda: batch_table(busy=True)}
    if what == "ops":
        counts = operation_count(range(2, 13))
        _print([{"balls": n, "contact": c, "operations": v,
                 "ratio_to_2": round(v / counts[(2, False)], 2)}
                 for (n, c), v in sorted(counts.items())])
        return 0
    for name, fn in tables.items():
        if what in (name, "all"):
            _print(fn())
            print(load_note())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


#: the tables of the last :func:`speed_rows` run, for the docs page (:func:`performance_page`)
LAST_TABLES: dict[str, list[dict]] = {}


def speed_rows(quick: bool = False) -> Iterator[dict]:
    """The rows of ``abb-gym bench speed`` from these tables (measurement, value, target,
    note), each as soon as it is measured; the whole tables go to :data:`LAST_TABLES`."""
    rounds = 2 if quick else 7
    counts = (2, 5) if quick else (2, 3, 5, 8, 12)
    sizes = (8, 256) if quick else BATCH_SIZES
    LAST_TABLES.clear()
    cp = cartpole_row(256 if quick else 1024, rounds)
    LAST_TABLES["cartpole"] = [dict(cp, load=load_note())]
    yield {"measurement": f"CPU time per env-step, yoshida_odd vector env at {cp['num_envs']} "
                          f"on one thread against CartPoleVectorEnv",
           "value": f"{cp['abb_cpu_us']:.3f} us vs {cp['cartpole_cpu_us']:.3f} us: "
                    f"{cp['ratio_per_core']:.1f}x per core",
           "target": "<= 8x", "note": f"wall {cp['abb_one_thread_rate']:,} vs "
                                      f"{cp['cartpole_rate']:,} env-steps/s; {load_note()}"}
    ball = ball_count_table(counts, 64 if quick else 256, rounds)
    LAST_TABLES["ball_count"] = ball
    five = next(r for r in ball if r["balls"] == 5 and r["contact"] == "off")
    worst = max(ball, key=lambda r: abs(math.log(r["ratio_over_operations"])))
    yield {"measurement": "5 balls against 2 balls per env-step (contact off, 256 "
                          "sub-environments)",
           "value": f"{five['ratio_to_2']:.2f}x (operations {five['operation_ratio']:.2f}x)",
           "target": "<= 2.7x", "note": f"furthest from the operation ratio: "
                                        f"{worst['balls']} balls, contact {worst['contact']}: "
                                        f"{worst['ratio_over_operations']:.2f}x (target within "
                                        f"1.3x); {load_note()}"}
    for integrator in (None, "etdrk4"):
        w = washer_row(64 if quick else 256, rounds, integrator)
        LAST_TABLES.setdefault("washer", []).append(dict(w, load=load_note()))
        yield {"measurement": f"washer against yoshida_odd per env-step ({w['num_envs']} "
                              f"sub-environments, washer integrator {w['integrator']})",
               "value": f"{w['ratio']:.1f}x", "target": "<= 10x",
               "note": f"{w['washer_cpu_us']:.2f} vs {w['yoshida_cpu_us']:.3f} us CPU; "
                       f"substeps per env-step {w['washer_substeps']:.0f} vs "
                       f"{w['yoshida_substeps']:.0f}; {load_note()}"}
    for key, busy in (("batch", False), ("batch_busy", True)):
        table = batch_table(sizes, 2 if quick else 15, busy=busy)
        LAST_TABLES[key] = table
        low = min(table, key=lambda r: r["default_over_one"])
        best = min(table, key=lambda r: r["best_default_over_one"])
        yield {"measurement": f"default threads against one thread, {sizes[0]}-{sizes[-1]} "
                              f"sub-environments (wall rate)"
                              + (", beside one busy process" if busy else ""),
               "value": f"lowest {low['default_over_one']:.2f}x (at {low['num_envs']}); of the "
                        f"best rounds {best['best_default_over_one']:.2f}x (at "
                        f"{best['num_envs']})",
               "target": ">= 0.9x", "note": f"{load_note()}; table: performance page"}


#: the lines around the generated section of the docs' performance page, which
#: ``abb-gym bench speed --docs PAGE`` replaces (the rest of the page is written by hand)
COST_MARKERS = ("<!-- bench-costs:begin: generated by `abb-gym bench speed --docs`; do not edit "
                "by hand -->", "<!-- bench-costs:end -->")


def performance_page(speed_rows_: list[dict], columns, level: int = 2) -> str:
    """The page of ``abb-gym bench speed`` (``out/bench/performance.md``): its rows, then the
    tables of :data:`LAST_TABLES` (the current figures only; their history is in
    CHANGELOG.md), its sections at heading ``level`` under the page's title; ``level`` 3:
    no title, for the docs page between :data:`COST_MARKERS` (:func:`write_docs_section`)."""
    from ..tables import markdown_table
    h = "#" * level
    parts = (["# Performance", ""] if level == 2 else []) + [
             "Generated by `abb-gym bench speed --docs docs/performance.md` on the machine that "
             "ran it; ratios are of CPU time per env-step measured side by side in one process "
             "(`abb_gym.benchmarks.env_cost`), with the load stated.  The history of these "
             "figures is in CHANGELOG.md.", "", f"{h} Summary", "",
             markdown_table(speed_rows_, columns)]
    titles = {"cartpole": "CartPole per core", "ball_count":
              "Ball count (vector env, CPU time per env-step; operations of the right-hand "
              "side from its LLVM IR)", "washer": "Washer against yoshida_odd",
              "batch": "Batch size: default threads against one thread",
              "batch_busy": "Batch size beside one busy process (another process keeps one "
                            "CPU busy)"}
    for key, title in titles.items():
        if LAST_TABLES.get(key):
            parts += ["", f"{h} {title}", "", markdown_table(LAST_TABLES[key])]
    return "\n".join(parts) + "\n"


def write_docs_section(path, speed_rows_: list[dict], columns) -> None:
    """Replace the section between :data:`COST_MARKERS` of the docs page ``path`` by this
    run's figures (:func:`performance_page` at heading level 3); the rest of the page stays
    as written.  A ValueError naming the page if it lacks the markers."""
    from ..evaluation.results_pages import replace_between_markers
    replace_between_markers(Path(path), performance_page(speed_rows_, columns, level=3).strip(),
                            COST_MARKERS)
