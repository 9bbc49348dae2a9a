"""Smoke test of the work-precision benchmark (the real run is ``abb-gym bench accuracy``)."""
import os
from pathlib import Path

import numpy as np
import pytest

from abb_gym import SpeedProfile
from abb_gym.benchmarks.accuracy import (BATCH_RUNS, Case, plot_work_precision,
                                         precision_table, run_accuracy)

ERRORS = ("peak_whirl_rel", "final_angle_deg", "trajectory_rel")


def test_work_precision_rows_and_chart(tmp_path):
    case = Case("yoshida_odd", SpeedProfile.dwell(40.0, 100.0, 0.5), 3.0, "short")
    rows = run_accuracy([case], repeats=1, progress=False)
    methods = {r["method"] for r in rows}
    assert {"rk4", "etdrk4", "ros2", "dopri5", "DOP853", "Radau", "RK45"} <= methods
    stable = [r for r in rows if r["stable"]]
    assert all(np.isfinite(r["trajectory_rel"]) and r["wall_ms_per_sim_s"] > 0 for r in stable)
    # refining the step of each fixed-step method lowers its error
    for method in ("rk4", "etdrk4", "ros2"):
        errs = [r["trajectory_rel"] for r in stable if r["method"] == method]
        assert errs[-1] < errs[0] / 100
    # the batched RK4 in float64 is rk4's arithmetic: the same errors at every step; in
    # float32 its peak whirl stays within 1e-4 of them (measured: 1e-6)
    single = [r for r in stable if r["method"] == "rk4"]
    batch64 = [r for r in stable if r["method"] == f"rk4 x{BATCH_RUNS} float64"]
    batch32 = [r for r in stable if r["method"] == f"rk4 x{BATCH_RUNS} float32"]
    # (the coarsest step, 4x the default, diverges in all three)
    assert len(single) == len(batch64) == len(batch32) == 5
    for a, b64, b32 in zip(single, batch64, batch32):
        assert a["setting"] == b64["setting"] == b32["setting"]
        assert [a[k] for k in ERRORS] == [b64[k] for k in ERRORS]
        assert abs(b32["peak_whirl_rel"] - a["peak_whirl_rel"]) < 1e-4
    png = plot_work_precision(rows, tmp_path / "wp.png")
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_precision_table_compares_float32_with_float64_and_two_float64_controls():
    rows = precision_table(["yoshida_odd"], kernel="specialised", progress=False)
    (row,) = rows
    # measured: 1.7e-7 and 2.3e-4 deg; the controls 6e-6 deg (a 1e-7 rad nudge) and 1e-3 deg
    # (one step more per 10 ms)
    assert row["peak_whirl_rel"] < 1e-5 and row["ball_angle_deg"] < 0.01 and row["within"]
    assert 0 < row["nudged_float64_ball_angle_deg"] < 1e-3
    assert 0 < row["finer_step_float64_ball_angle_deg"] < 0.1


def test_speed_benchmark_parts_measure_what_they_name():
    from abb_gym.benchmarks import env_speed
    vec = env_speed.vector_rate(64, 3, kernel="generic")
    assert vec["kernel"] == "generic" and vec["rate"] > 0 and vec["reset_us"] > 0
    assert env_speed.batch_rate(16, 2) > 0
    cp_vec, cp_single = env_speed.cartpole_rates(16, 3)
    assert cp_vec > 0 and cp_single > 0
    cold = env_speed.cold_start(with_empty_cache=False)
    assert set(cold) == {"python", "import", "help", "first_step_cached"}
    assert cold["import"] >= cold["python"] > 0


def test_energy_drift_runs_every_integrator():
    from abb_gym.benchmarks.accuracy import energy_drift
    rows = energy_drift(t_end=1.0, progress=False)
    assert {r["method"] for r in rows} >= {"rk4", "etdrk4", "ros2", "dopri5", "DOP853", "Radau"}
    assert all(np.isfinite(r["energy_drift_rel"]) and "max_steps" not in r["setting"]
               for r in rows)


def test_bench_speed_prints_each_row_as_soon_as_it_is_measured(tmp_path, capsys, monkeypatch):
    """Every measurement is replaced by an instant stand-in that notes how many table rows
    stdout already shows when it starts: each must see the rows of all earlier ones."""
    from abb_gym.benchmarks import effects, env_cost, env_speed, speed
    from abb_gym.cli import main
    stdout: list[str] = []
    seen: list[tuple[str, int]] = []

    def rows_printed() -> int:
        stdout.append(capsys.readouterr().out)
        lines = "".join(stdout).splitlines()
        return sum(line.startswith("| ") for line in lines) - 1  # less the header

    vector_calls: list[dict] = []

    def stand_in(name, value):
        def f(*args, **kwargs):
            if name == "vector":
                vector_calls.append(kwargs)
            seen.append((name, rows_printed()))
            return value
        return f

    def runup(repeats):
        for kernel in ("generic", "specialised"):
            seen.append((f"run-up {kernel}", rows_printed()))
            yield {"measurement": f"run-up {kernel}", "value": "1 ms", "target": "-",
                   "note": "-"}

    def effect_rows(methods=("rk4",), repeats=1):
        seen.append(("effects", rows_printed()))
        yield {"case": "effects off", "method": "rk4", "ms_per_simulated_s": 1.0,
               "us_per_step": 1.0, "dt_s": 1e-4}

    monkeypatch.setattr(speed, "runup_wall_time", runup)
    monkeypatch.setattr(speed, "stepping_rates", stand_in("stepping", (
        [{"measurement": "kernel", "value": "1", "target": "-", "note": "-"},
         {"measurement": "scipy", "value": "1", "target": "-", "note": "-"}], 100.0)))
    rate = {"rate": 1e6, "reset_us": 1.0, "kernel": "generic"}
    monkeypatch.setattr(env_speed, "vector_rate", stand_in("vector", rate))
    monkeypatch.setattr(env_speed, "batch_rate", stand_in("batch", 1e6))
    monkeypatch.setattr(env_speed, "single_rate", stand_in("single", 1e5))
    monkeypatch.setattr(env_speed, "cartpole_rates", stand_in("cartpole", (1e6, 1e4)))
    monkeypatch.setattr(env_speed, "cold_start", stand_in("cold", {
        "python": 0.01, "import": 0.1, "help": 0.1, "first_step_cached": 1.0}))
    monkeypatch.setattr(env_speed, "_vector_memory", stand_in("memory", 10.0))
    def cost_rows(quick=False):
        seen.append(("cost", rows_printed()))
        env_cost.LAST_TABLES["batch"] = [{"num_envs": 8, "default_over_one": 1.0}]
        yield {"measurement": "per core", "value": "1x", "target": "-", "note": "-"}

    monkeypatch.setattr(effects, "iter_speed_rows", effect_rows)
    monkeypatch.setattr(env_cost, "speed_rows", cost_rows)
    docs = tmp_path / "docs" / "performance.md"
    docs.parent.mkdir()
    begin, end = env_cost.COST_MARKERS
    docs.write_text(f"# Performance\n\nWritten by hand.\n\n{begin}\nold figures\n{end}\n\n"
                    f"## What sets the speed\n")
    assert main(["bench", "speed", "--quick", "--out", str(tmp_path), "--docs", str(docs)]) == 0
    total = rows_printed()
    # rows before each measurement: 2 run-up rows, 2 stepping rows, one per vector size, the
    # general kernel, ETDRK4, float32, the batch simulation and its float32 row, then
    # CartPole/single/speed-up once both are measured, 2 cold-start rows, the memory
    assert seen == [("run-up generic", 0), ("run-up specialised", 1), ("stepping", 2),
                    ("vector", 4), ("vector", 5), ("vector", 6), ("vector", 7),
                    ("vector", 8), ("vector", 9), ("batch", 10), ("batch", 11),
                    ("single", 12), ("cartpole", 12), ("cold", 15), ("memory", 17),
                    ("effects", 18), ("cost", 19)]
    assert total == 20
    assert [kw.get("integrator", "rk4") for kw in vector_calls].count("etdrk4") == 1
    table = (tmp_path / "speed.md").read_text().splitlines()
    assert len(table) == 2 + total and table[2].startswith("| run-up generic ")
    # the docs page: its generated section replaced (headings one level down), the rest kept
    page = docs.read_text()
    assert page.startswith("# Performance\n\nWritten by hand.\n\n" + begin)
    assert page.endswith(end + "\n\n## What sets the speed\n") and "old figures" not in page
    assert "| per core " in page and "\n### Batch size" in page and "| 8 " in page
    own = (tmp_path / "performance.md").read_text()
    assert own.startswith("# Performance") and "\n## Batch size" in own and "| per core " in own
    docs.write_text("# Performance\n\nno markers\n")
    assert main(["bench", "speed", "--quick", "--out", str(tmp_path), "--docs", str(docs)]) != 0
    assert "performance.md has no <!-- bench-costs:begin" in capsys.readouterr().err


def test_the_speed_table_warns_when_the_specialised_kernel_is_not_in_effect():
    from abb_gym.benchmarks.env_speed import SPECIALISATION_FLOOR, specialisation_note
    assert specialisation_note(845_000, 328_000) == "specialised/general = 2.58x"
    lost = specialisation_note(330_000, 328_000)
    assert lost.startswith("specialised/general = 1.01x - WARNING") and "may not be in effect" in lost
    assert "WARNING" in specialisation_note(SPECIALISATION_FLOOR * 0.99, 1.0)
    assert "WARNING" not in specialisation_note(SPECIALISATION_FLOOR, 1.0)


def test_bench_speed_costs_only_runs_the_side_by_side_tables_alone(tmp_path, monkeypatch):
    from abb_gym.benchmarks import env_cost, speed
    from abb_gym.cli import main

    def cost_rows(quick=False):
        env_cost.LAST_TABLES["washer"] = [{"num_envs": 4, "ratio": 3.0}]
        yield {"measurement": "washer", "value": "3x", "target": "<= 10x", "note": "-"}

    def refuse(*args, **kwargs):
        raise AssertionError("not a cost table")

    monkeypatch.setattr(env_cost, "speed_rows", cost_rows)
    monkeypatch.setattr(speed, "runup_wall_time", refuse)
    assert main(["bench", "speed", "--costs-only", "--out", str(tmp_path)]) == 0
    rows = (tmp_path / "speed.md").read_text().splitlines()
    assert len(rows) == 3 and rows[2].startswith("| washer ")
    assert "## Washer against yoshida_odd" in (tmp_path / "performance.md").read_text()


def test_the_busy_neighbour_runs_during_the_block_and_is_gone_after():
    """The batch table's busy case really has a second process on a CPU, and leaves none
    behind (also when the block raises)."""
    from abb_gym.benchmarks import env_cost
    with pytest.raises(RuntimeError):
        with env_cost.busy_neighbour() as proc:
            assert proc.poll() is None
            stat = Path(f"/proc/{proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
            user_s = int(stat[11]) / os.sysconf("SC_CLK_TCK")  # utime, field 14
            assert user_s > 0.05  # it spins (up to 1 s by now; less on a loaded machine)
            raise RuntimeError("the block fails")
    assert proc.poll() is not None


def test_a_cost_burst_counts_its_own_steps_in_whole_episodes(monkeypatch):
    """CPU time per env-step divides a burst's CPU time by that burst's env-steps (not the
    next burst's, whose size adapts to the wall time), and every burst is whole episodes: an
    env-step's cost follows the episode (the step shortens as the rotor speeds up)."""
    import gymnasium as gym

    from abb_gym.benchmarks import env_cost

    class Counting:
        num_envs = 3
        single_action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

        def __init__(self):
            self.steps = 0

        def reset(self, seed=None):
            return None

        def step(self, action):
            self.steps += 1

    env = Counting()
    case = env_cost._Case(env)
    monkeypatch.setattr(env_cost, "BURST_S", 1e9)  # every burst asks for 4x the last
    done = 0
    for _ in range(3):
        wall, cpu, steps = case.burst()
        assert steps == env.num_envs * (env.steps - done)
        assert (env.steps - done) % env_cost.EPISODE_STEPS == 0
        done = env.steps
    assert env.steps == env_cost.EPISODE_STEPS * (1 + 4 + 16)
