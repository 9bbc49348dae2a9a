"""Smoke test of the work-precision benchmark (the real run is ``abb-gym bench accuracy``)."""
import numpy as np

from abb_gym import SpeedProfile
from abb_gym.benchmarks.accuracy import Case, plot_work_precision, run_accuracy


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
    png = plot_work_precision(rows, tmp_path / "wp.png")
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_speed_benchmark_parts_measure_what_they_name():
    from abb_gym.benchmarks import env_speed
    vec = env_speed.vector_rate(64, 3, kernel="generic")
    assert vec["kernel"] == "generic" and vec["rate"] > 0 and vec["reset_us"] > 0
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
