"""Bad arguments to every ``abb-gym`` subcommand: exit 0 for valid input, and for bad input exit 2
with ONE line on stderr that names the argument (no traceback, no usage block); never another
exception, a hang, an empty path silently read as "no output" or as the current folder, or a
value silently changed (``--set n_balls=2.5`` truncated to 2).

First one regression test per class of bad input found by fuzzing, then a property-based test
(hypothesis) over the arguments of every subcommand.  The expensive work of each command
(the map, the study, the evaluation, the tuning, the training, the benchmarks, the kernel
build, the demo's runs) is replaced by a stub that records that the checks passed, so only
the argument checks run; ``simulate`` runs for real with t_end <= 0.05 s.  Everything runs
in a temporary folder (default output paths included).  ``ABB_GYM_FUZZ_SCALE=20`` runs 20
times the examples with a fresh seed.
"""
from __future__ import annotations

import contextlib
import importlib
import io
import json
import os
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from abb_gym.analysis import Groups
from abb_gym.analysis import rotating_frame as rf
from abb_gym.cli import main

try:
    import stable_baselines3  # noqa: F401
    HAVE_TRAIN = True
except ImportError:  # the training extra is not installed
    HAVE_TRAIN = False


class Reached(Exception):
    """Raised by the stubs: every argument check passed and the work would start now."""


def _reached(*args, **kwargs):
    raise Reached


STUBS = ["abb_gym.cli.demo.demonstrate", "abb_gym.benchmarks.speed.iter_speed",
         "abb_gym.benchmarks.accuracy.run_accuracy", "abb_gym.analysis.stability_map",
         "abb_gym.evaluation.studies.settling_study",
         "abb_gym.evaluation.studies.ball_position_study",
         "abb_gym.evaluation.evaluate.evaluate", "abb_gym.baselines.tuner.tune",
         "abb_gym.kernels.build"] + (["abb_gym.rl.train.train"] if HAVE_TRAIN else [])


@pytest.fixture(scope="module", autouse=True)
def stubbed(tmp_path_factory):
    """The stubs, and a temporary working folder (default outputs land there)."""
    work = tmp_path_factory.mktemp("cli_work")
    mp = pytest.MonkeyPatch()
    for target in STUBS:
        module, name = target.rsplit(".", 1)
        mp.setattr(importlib.import_module(module), name, _reached)
    mp.chdir(work)
    from abb_gym import resources
    mp.setattr(resources, "_EXTRA_USER_FOLDERS", [])  # --configs DIR: for this module only
    (work / "a_dir").mkdir()
    (work / "a_file").write_text("not a folder")
    (work / "binary").write_bytes(bytes(range(256)))
    yield work
    mp.undo()


def run(argv: list[str]) -> tuple[object, str, str]:
    """``main(argv)`` in this process: (exit code or "reached", stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse (usage errors, --help)
            code = exc.code
        except Reached:
            code = "reached"
    return code, out.getvalue(), err.getvalue()


def refused(argv: list[str], *names: str) -> str:
    """Assert that ``argv`` exits 2 with one line naming one of ``names``; the line."""
    code, _, err = run(argv)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, (argv, code, err)
    assert "Traceback" not in err and lines[0].startswith("abb-gym"), err
    assert any(n in lines[0] for n in names), (names, lines[0])
    return lines[0]


# ================================================================== regression, class by class
# ------------------------------------------ usage errors: one line, not the whole usage block
@pytest.mark.parametrize("argv, name", [
    (["simulate", "--accel", "x"], "--accel"),
    (["simulate", "--method", "x"], "--method"),
    (["simulate", "--ball-angles-deg"], "--ball-angles-deg"),
    (["bench"], "bench"),
    (["build-kernels", "--x"], "--x"),
    (["study", "x"], "which"),
    (["stability-map", "--workers", "0"], "--workers"),
    (["stability-map", "--nx", "1e3"], "--nx"),
    (["evaluate"], "--policy"),
    ([], "command"),
    (["--configs"], "--configs"),
])
def test_usage_errors_are_one_line(argv, name):
    line = refused(argv, name)
    assert "--help" in line  # where the usage is


def test_negative_numbers_in_any_notation_are_values_not_options():
    # argparse read "-1e-3" as an unknown option ("unrecognized arguments") before
    assert run(["simulate", "--t-end", "0.01", "--ball-angles-deg", "0", "-1e-3"])[0] == 0
    assert run(["simulate", "--t-end", "0.01", "--dwell-accel", "-4E1", "--profile",
                "dwell"])[0] == 0
    refused(["simulate", "--t-end", "0.01", "--profile", "dwell", "--dwell-accel", "-inf"],
            "--dwell-accel")


def test_the_training_script_has_one_line_usage_errors(capsys):
    from abb_gym.cli.train import main as train_main
    with pytest.raises(SystemExit) as exc:
        train_main(["--config", "x", "--seed", "one"])
    assert exc.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "--seed" in lines[0]


# ------------------ empty output paths: read as "no output" or as the current folder before
_EMPTY_PATH_CASES = [
    (["simulate", "--t-end", "0.01", "--json", ""], "--json"),
    (["simulate", "--t-end", "0.01", "--plot", " "], "--plot"),
    (["demo", "--out", ""], "--out"),
    (["bench", "accuracy", "--out", ""], "--out"),
    (["bench", "speed", "--out", ""], "--out"),
    (["bench", "time-to-target", "--target-return", "-4", "--run", "a=nowhere", "--out", ""],
     "--out"),
    (["bench", "time-to-target", "--target-return", "-4", "--run", "a=nowhere", "--out", " "],
     "--out"),
    (["stability-map", "--out", ""], "--out"),
    (["stability-map", "--out", "maps/"], "--out"),
    (["study", "settling", "--out", ""], "--out"),
    (["evaluate", "--policy", "baseline:ramp", "--out", ""], "--out"),
    (["tune-baselines", "--out", ""], "--out"),
    (["stability-map", "--resume-dir", ""], "--resume-dir"),
    (["--configs", "", "simulate", "--t-end", "0.01"], "--configs"),
    (["render", "--policy", "baseline:ramp", "--out", ""], "--out"),
    (["render", "--policy", "baseline:ramp", "--out", " "], "--out"),
    (["evaluate", "--policy", "baseline:ramp", "--resume-dir", ""], "--resume-dir"),
    (["tune-baselines", "--resume-dir", " "], "--resume-dir"),
    (["study", "settling", "--resume-dir", ""], "--resume-dir"),
    (["new-scene", "x", "--out", ""], "--out"),
    (["new-scene", "x", "--out", " "], "--out"),
] + ([(["train", "--config", "runup_speed_yoshida_odd", "--out", ""], "--out"),
      (["train", "--config", "runup_speed_yoshida_odd", "--tensorboard-log", ""],
       "--tensorboard-log"),
      (["convert-agent", "runs/x", "--out", ""], "--out"),
      (["convert-agent", ""], "source")] if HAVE_TRAIN else [])


@pytest.mark.parametrize("argv, option", _EMPTY_PATH_CASES)
def test_empty_paths_are_refused_not_read_as_no_output_or_here(argv, option, stubbed):
    before = sorted(p.name for p in stubbed.iterdir())
    refused(argv, option)
    assert sorted(p.name for p in stubbed.iterdir()) == before  # nothing written here


#: the options of every subcommand that name a file or folder to write
PATH_OPTIONS = ("--out", "--json", "--plot", "--resume-dir", "--tensorboard-log")


def test_every_output_path_option_of_every_command_refuses_an_empty_path():
    """No command takes an empty output path as the current folder or as its default: each
    output option of each (sub)command appears in the regression list above."""
    import argparse
    from abb_gym.cli import build_parser

    def commands(parser, prefix=()):
        sub = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not sub:
            yield prefix, parser
        for action in sub:
            for name, child in action.choices.items():
                yield from commands(child, prefix + (name,))

    covered = {(tuple(a for a in argv if not a.startswith("-") and a)[:len(argv)], option)
               for argv, option in _EMPTY_PATH_CASES}
    for names, parser in commands(build_parser()):
        for action in parser._actions:
            for option in set(action.option_strings) & set(PATH_OPTIONS):
                assert any(c[1] == option and c[0][:len(names)] == names for c in covered), \
                    (" ".join(names), option)


@pytest.mark.parametrize("path", ["a\x00b.json", "x" * 300 + ".json",
                                  "/".join(["d"] * 3000) + ".json"], ids=["nul", "long", "deep"])
def test_paths_the_system_refuses_name_the_option(path):
    refused(["simulate", "--t-end", "0.01", "--json", path], "--json")
    refused(["stability-map", "--resume-dir", path], "--resume-dir")


def test_a_figure_format_matplotlib_cannot_write_is_refused_before_the_run(monkeypatch):
    monkeypatch.setattr("abb_gym.physics.simulate", _reached)
    line = refused(["simulate", "--plot", "run.xyz"], "--plot")
    assert "png" in line
    assert run(["simulate", "--plot", "run.svg"])[0] == "reached"
    assert run(["simulate", "--plot", "run"])[0] == "reached"  # no suffix: PNG


def test_a_resume_folder_that_is_a_file_is_named(stubbed):
    refused(["stability-map", "--resume-dir", "a_file"], "--resume-dir")
    refused(["study", "settling", "--workers", "1", "--resume-dir", "a_file"], "--resume-dir")


# --------------------------------- drive and angle options are named as the user typed them
@pytest.mark.parametrize("argv, option", [
    (["--motor-torque", "nan"], "--motor-torque"),
    (["--limited-power", "1", "--speed", "-1"], "--speed"),
    (["--profile", "dwell", "--dwell-time", "-1"], "--dwell-time"),
    (["--accel", "inf"], "--accel"),
    (["--ball-angles-deg", "nan", "0"], "--ball-angles-deg"),
    (["--ball-angles-deg", "1"], "--ball-angles-deg"),
    (["--ball-angles-deg", "1e308", "0"], "--ball-angles-deg"),
])
def test_simulate_names_the_option_not_the_api_argument(argv, option):
    refused(["simulate", "--t-end", "0.01", *argv], option)


# --------------------------- drive options the chosen drive would ignore (silently before)
@pytest.mark.parametrize("argv, option", [
    (["--speed", "100"], "--speed"),  # a ramp has no speed
    (["--profile", "constant", "--accel", "10"], "--accel"),
    (["--profile", "ramp", "--dwell-time", "1"], "--dwell-time"),
    (["--motor-torque", "0.1", "--limited-power", "1e-3"], "--limited-power"),
    (["--motor-torque", "0.1", "--profile", "dwell"], "--profile"),
    (["--limited-power", "1e-3", "--operating-speed", "100"], "--operating-speed"),
    (["--profile", "dwell", "--speed", "nan"], "--speed"),
])
def test_drive_options_the_drive_would_ignore_are_refused(argv, option):
    line = refused(["simulate", "--t-end", "0.01", *argv], option)
    assert "does not apply" in line


def test_every_drive_takes_its_own_options():
    for argv in (["--accel", "20", "--operating-speed", "100"],
                 ["--profile", "dwell", "--dwell-speed", "50", "--dwell-time", "0.01",
                  "--dwell-accel", "1", "--accel", "40"],
                 ["--profile", "constant", "--speed", "50"],
                 ["--limited-power", "1e-3", "--speed", "50"],
                 # within the scene's drive.torque_limit, 5e-3 N m (tests/test_user_workflows)
                 ["--motor-torque", "0.004"]):
        code, out, err = run(["simulate", "--t-end", "0.01", *argv])
        assert code == 0, (argv, err)


# ---------------- ball counts: int() truncated 2.5, raised OverflowError and TypeError before
@pytest.mark.parametrize("setting", ["n_balls=2.5", "n_balls=1e400", "n_balls=[1]",
                                     "n_balls=nan", "n_balls=x", "n_balls=65"])
def test_ball_counts_are_checked_not_converted(setting):
    refused(["stability-map", "--set", setting], "n_balls")
    refused(["stability-map", "--scene", "yoshida_odd", "--set",
             setting.replace("n_balls", "ball_count")], "ball_count")


def test_a_ball_count_axis_that_rounds_to_zero_balls_is_named():
    # the default --x-range 0.02 0.3 as ball counts: 0 balls, a ZeroDivisionError before
    refused(["stability-map", "--x", "n_balls"], "n_balls")
    for n in (0, 2.5, "x", True):
        with pytest.raises(ValueError, match="n_balls"):
            Groups().replace(n_balls=n, eta_total=1.0)


def test_a_whole_ball_count_written_as_a_float_is_that_count(monkeypatch):
    seen = {}

    def capture(base, x, y, **kwargs):
        seen["n_balls"] = base.n_balls
        raise Reached

    monkeypatch.setattr("abb_gym.analysis.stability_map", capture)
    assert run(["stability-map", "--set", "n_balls=4.0", "--balls", "4"])[0] == "reached"
    assert seen["n_balls"] == 4


# ----------------------------- stability-map work that grows without bound (hangs before)
@pytest.mark.parametrize("argv, name", [
    (["--nx", "1000000000"], "--nx"),
    (["--members", "1000000000"], "--members"),
    (["--balls", "32", "--members", "2"], "--members"),  # 2^30 family candidates
    (["--balls", "100"], "--balls"),
    (["--x", "n_balls", "--x-range", "2", "40"], "--members"),  # 13^38 at a corner
    (["--omega", "1e308"], "--omega"),
    (["--y", "Omega", "--y-range", "0", "1"], "Omega"),
    (["--x", "zeta", "--x-range", "0", "1e308"], "zeta"),
    (["--x", "mu", "--x-range", "0", "1"], "mu"),
    (["--scene", "yoshida_odd", "--length-scale", "5e-324"], "length_scale"),
])
def test_stability_map_bounds_its_work_before_building_the_grid(argv, name):
    start = time.perf_counter()
    refused(["stability-map", *argv], name)
    assert time.perf_counter() - start < 5.0


def test_the_analysis_refuses_groups_and_speeds_its_linear_algebra_cannot_use():
    # LinAlgError, ZeroDivisionError or NaN before (mu = 5e-324, zeta = 1e308, Omega = 5e-324)
    for kwargs, name in (({"mu": 5e-324}, "mu"), ({"zeta": 1e308}, "zeta"),
                         ({"eta": 1e308}, "eta"), ({"delta": 5e-324}, "delta"),
                         ({"spin": 1e308}, "spin"), ({"n_balls": 65}, "n_balls"),
                         ({"n_balls": np.True_}, "n_balls"), ({"zeta": True}, "zeta")):
        with pytest.raises(ValueError, match=name):
            Groups().replace(**kwargs)
    for omega in (5e-324, 1e308, float("nan"), "2", None):
        with pytest.raises(ValueError, match="Omega"):
            rf.family_stability(Groups(), omega, 3)
    start = time.perf_counter()
    with pytest.raises(ValueError, match="n_members"):
        rf.balanced_family(Groups(n_balls=32), 2.0, 2)
    assert time.perf_counter() - start < 1.0
    # the corners of the ranges stay finite
    for kwargs in ({"mu": 1e-6}, {"mu": 1e6}, {"delta": 1e-6}, {"delta": 1e9}, {"zeta": 1e6},
                   {"eta": 1e6}, {"spin": 1e3}, {"race_eccentricity": 1e6}):
        for omega in rf.OMEGA_RANGE:
            fs = rf.family_stability(Groups().replace(**kwargs), omega, 3)
            assert not fs.exists or np.isfinite([fs.best, fs.worst]).all(), (kwargs, omega)


def test_stability_map_checks_ball_counts_and_the_map_size_up_front():
    from abb_gym.analysis.maps import MAX_MAP_TASKS, stability_map
    with pytest.raises(ValueError, match="n_balls"):
        stability_map(Groups(), ("zeta", [0.1]), ("Omega", [2.0]), n_balls=[100])
    with pytest.raises(ValueError, match="n_balls"):
        stability_map(Groups(), ("zeta", [0.1]), ("Omega", [2.0]), n_balls=[2.5])
    n = int(MAX_MAP_TASKS ** 0.5) + 1
    with pytest.raises(ValueError, match="map tasks"):
        stability_map(Groups(), ("zeta", np.linspace(0.0, 1.0, n)),
                      ("Omega", np.linspace(1.0, 2.0, n)), n_balls=[3])


# -------------------------------------------------- other checks that ran after the work
def test_bench_accuracy_needs_at_least_one_repeat():
    for repeats in ("0", "-1"):
        refused(["bench", "accuracy", "--repeats", repeats], "--repeats")


@pytest.mark.skipif(not HAVE_TRAIN, reason="needs the training extra")
def test_a_config_file_with_make_vec_keywords_is_refused(stubbed):
    path = stubbed / "nenv.yml"
    path.write_text("abb_gym/RunUpSpeed-v0:\n  n_timesteps: 100\n  env_kwargs:\n"
                    "    num_envs: 3\n")
    refused(["train", "--config", str(path)], "num_envs")


def test_tuning_work_that_cannot_fit_is_refused_before_the_search():
    # --episodes 1e12 built a list of 1e12 episodes for the first candidate; a population
    # beyond the budget is never evaluated
    line = refused(["tune-baselines", "--dry-run", "--episodes", "1000000000000"], "--episodes")
    assert "num_envs" in line
    refused(["tune-baselines", "--dry-run", "--budget", "10", "--popsize", "1000000000000"],
            "--popsize")
    assert run(["tune-baselines", "--dry-run", "--budget", "10", "--popsize", "10"])[0] == \
        "reached"
    refused(["tune-baselines", "--dry-run", "--restarts", "101"], "--restarts")


def test_tuning_from_the_tuned_parameters_needs_them(tmp_path):
    """``--from-tuned`` on a scene without tuned parameters names the option and the family;
    the tuned file is found by the scene's name, whether the scene is given by name or by
    path."""
    from abb_gym import resources
    shipped = resources.find("scenes", "yoshida_odd")
    scene = tmp_path / "copy.yaml"
    scene.write_text(shipped.read_text().replace("name: yoshida_odd", "name: untuned_machine"))
    line = refused(["tune-baselines", "--dry-run", "--scene", str(scene), "--family", "ramp",
                    "--from-tuned"], "--from-tuned")
    assert "ramp" in line and "untuned_machine" in line and "no baselines file" in line
    for given in ("yoshida_odd", str(shipped)):
        assert run(["tune-baselines", "--dry-run", "--scene", given, "--family", "ramp",
                    "--from-tuned"])[0] == "reached"


@pytest.mark.parametrize("key", ["num_envs", "vectorization_mode", "record_history", "scene",
                                 "preset", "wrappers"])
def test_environment_keywords_the_command_sets_itself_are_refused(key):
    # a TypeError ("got multiple values for keyword argument") deep in a task before
    refused(["tune-baselines", "--dry-run", "--env-kwargs", f"{key}=1"], key)
    if HAVE_TRAIN and key not in ("scene", "preset", "record_history"):
        refused(["train", "--config", "runup_speed_yoshida_odd", "--env-kwargs", f"{key}=1"],
                key)


def test_the_training_report_prints_no_nan(capsys):
    # "residual vibration nan [nan, nan]" when no test episode settled
    from types import SimpleNamespace

    from abb_gym.cli.train import _report
    metric = {"mean": 1.0, "ci_low": 0.5, "ci_high": 1.5}
    empty = {"mean": float("nan"), "ci_low": float("nan"), "ci_high": float("nan")}
    summary = {"episodes": 4, "return": metric, "at_speed": metric, "run_up_time": metric,
               "balanced": metric, "residual_vibration": empty}
    _report(SimpleNamespace(run_dir="r", wall_time_s=1.0, env_steps=10, env_steps_per_s=10.0,
                            evaluation=summary, training_steps_per_s=12.0))
    out = capsys.readouterr().out
    assert "nan" not in out and "residual vibration n/a (no episode settled)" in out


# ================================================================== property-based
SCALE = max(1, int(os.environ.get("ABB_GYM_FUZZ_SCALE", "1")))
PROPERTY = settings(deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                           HealthCheck.filter_too_much])

NUMBERS = ["nan", "inf", "-inf", "1e308", "-1e308", "-0.0", "0", "5e-324", "1e999", "x", "",
           " ", "0x10", "1_0", "-1", "2", "1e3", "True", "[1]"]
INTEGERS = ["0", "-1", "1", "2", "3", "1000000000000", "1e3", "1.5", "x", "", "99999999999999999999999"]
PATHS = ["", " ", "a_dir", "a_file", "a_file/x", "binary", "new/out", "a\x00b",
         "x" * 300, "/dev/null", "."]
NAMES = ["", " ", ".", "..", "a_dir", "binary", "a_file", "nope", "/dev/null", "\x00"]
ASSIGNMENTS = ["x", "=1", "a=", "a=[1,", "a=1e400", "a={b: 1}", "a=nan"]


def _chance(draw, p):
    return draw(st.sampled_from(range(100))) < 100 * p


def _value(draw, good, bad, p_bad=0.25):
    return draw(st.sampled_from(bad)) if _chance(draw, p_bad) else draw(good)


def _floats(lo, hi):
    return st.floats(lo, hi).map(lambda v: f"{v:.6g}")


def _ints(lo, hi):
    return st.integers(lo, hi).map(str)


def _assign(keys, values):
    return st.tuples(st.sampled_from(keys), st.sampled_from(values)).map(lambda kv: "=".join(kv))


SCENE_KEYS = ["ball_mass", "ball_count", "rotor_mass", "support_damping", "ball_drag",
              "race_radius", "bogus"]
GROUP_KEYS = ["eta", "mu", "delta", "zeta", "zeta_b", "spin", "n_balls", "eta_total",
              "race_eccentricity", "race_angle", "bogus"]
ENV_KEYS = ["control_interval", "settle_time", "episode_length", "observe_balls", "integrator",
            "reward", "operating_speed", "info_level", "bogus", "num_envs", "scene"]
SOME_VALUES = ["1", "2", "3.0", "2.5", "0", "-1", "1e-3", "1e400", "nan", "x", "true", "[1, 2]",
               "{time: 2}", "rk4", "lean", "null", "''"]

# option -> (strategy of good values, bad values, extra names an error may give); an option
# with a None strategy is a flag
SIMULATE = {
    "--scene": (st.sampled_from(["yoshida_odd", "lu_hung_odd3", "washer"]), NAMES, ("scene",)),
    "--set": (st.lists(_assign(SCENE_KEYS, SOME_VALUES), min_size=1, max_size=2),
              ASSIGNMENTS, ()),
    "--profile": (st.sampled_from(["ramp", "dwell", "constant"]), ["x", ""], ()),
    "--accel": (_floats(1.0, 400.0), NUMBERS, ()),
    "--dwell-speed": (_floats(0.0, 300.0), NUMBERS, ()),
    "--dwell-time": (_floats(0.0, 1.0), NUMBERS, ()),
    "--dwell-accel": (_floats(-40.0, 40.0), NUMBERS, ()),
    "--operating-speed": (_floats(10.0, 400.0), NUMBERS, ()),
    "--speed": (_floats(0.0, 300.0), NUMBERS, ()),
    "--motor-torque": (_floats(-1.0, 1.0), NUMBERS, ()),
    "--limited-power": (_floats(1e-5, 1e-2), NUMBERS, ()),
    "--ball-angles-deg": (st.lists(_floats(-180.0, 180.0), min_size=1, max_size=3), NUMBERS, ()),
    "--method": (st.sampled_from(["rk4", "RK45"]),
                 ["x", "", "RK4"], ()),
    "--dt": (_floats(1e-5, 1e-3), NUMBERS, ()),
    "--output-dt": (_floats(1e-3, 0.01), NUMBERS, ()),
    "--json": (st.sampled_from(["-", "out/run.json"]), PATHS, ()),
    "--plot": (st.sampled_from(["out/run.png"]), PATHS + ["run.xyz"], ()),
}
EXECUTION = {
    "--workers": (_ints(1, 2), INTEGERS, ()),
    "--retries": (_ints(0, 3), INTEGERS, ()),
    "--resume-dir": (st.sampled_from(["resume"]), PATHS, ()),
    "--ray-address": (st.sampled_from([""]), ["", " "], ()),
}
COMMANDS = {
    "simulate": ([], SIMULATE),
    "demo": ([], {"--out": (st.sampled_from(["out/demo"]), PATHS, ())}),
    "bench accuracy": ([], {"--out": (st.sampled_from(["out/bench"]), PATHS, ()),
                            "--repeats": (_ints(1, 3), INTEGERS, ())}),
    "bench speed": ([], {"--out": (st.sampled_from(["out/bench"]), PATHS, ()),
                         "--quick": (None, [], ())}),
    "build-kernels": ([], {"--quiet": (None, [], ())}),
    "stability-map": ([], {
        "--scene": (st.sampled_from(["lu_hung_odd3", "yoshida_odd"]), NAMES, ("scene",)),
        "--length-scale": (_floats(1e-5, 1e-2), NUMBERS, ()),
        "--set": (st.lists(_assign(GROUP_KEYS + SCENE_KEYS, SOME_VALUES), min_size=1,
                           max_size=2), ASSIGNMENTS, ()),
        "--x": (st.sampled_from(["zeta", "eta", "mu", "n_balls", "Omega", "ball_drag"]),
                ["", "x", "zeta "], ()),
        "--x-range": (st.tuples(_floats(0.0, 3.0), _floats(0.0, 3.0)).map(list), NUMBERS, ()),
        "--nx": (_ints(1, 5), INTEGERS, ()),
        "--y": (st.sampled_from(["Omega", "zeta_b", "delta"]), ["", "Omega2"], ()),
        "--y-range": (st.tuples(_floats(0.5, 3.0), _floats(0.5, 3.0)).map(list), NUMBERS, ()),
        "--ny": (_ints(1, 5), INTEGERS, ()),
        "--omega": (_floats(0.1, 5.0), NUMBERS, ()),
        "--balls": (st.lists(_ints(1, 5), min_size=1, max_size=3), INTEGERS, ()),
        "--members": (_ints(1, 20), INTEGERS, ()),
        "--out": (st.sampled_from(["out/map"]), PATHS, ()),
        "--no-progress": (None, [], ()),
        **EXECUTION}),
    "study": ([st.sampled_from(["settling", "ball-position"])], {
        "--scene": (st.sampled_from(["yoshida_odd"]), NAMES, ("scene",)),
        "--out": (st.sampled_from(["out/study"]), PATHS, ()),
        **EXECUTION}),
    "evaluate": ([], {
        "--env": (st.sampled_from(["abb_gym/RunUpSpeed-v0", "abb_gym/DwellProfile-v0"]),
                  NAMES + ["abb_gym/RunUpSpeed-v1"], ("env", "environment")),
        "--scene": (st.sampled_from(["yoshida_odd"]), NAMES, ("scene",)),
        "--policy": (st.sampled_from(["baseline:ramp", "baseline:retry"]),
                     ["", "x", "baseline:", "baseline:nope", "ppo:", "ppo:binary",
                      "ppo:a_dir", "replay:", "replay:x"], ("policy", "PPO agent", "baseline")),
        "--episodes": (_ints(1, 5), INTEGERS, ()),
        "--seed": (_ints(0, 10), INTEGERS, ()),
        "--preset": (st.sampled_from(["test", "train"]), NAMES, ("preset",)),
        "--sweep": (_ints(0, 3), INTEGERS, ()),
        "--sweep-episodes": (_ints(1, 3), INTEGERS, ()),
        "--out": (st.sampled_from(["out/eval"]), PATHS, ()),
        **EXECUTION}),
    "tune-baselines": ([], {
        "--scene": (st.sampled_from(["yoshida_odd"]), NAMES, ("scene",)),
        "--family": (st.sampled_from(["ramp", "retry"]), ["", "x"], ()),
        "--env": (st.sampled_from(["abb_gym/RunUpSpeed-v0"]), ["x"], ()),
        "--budget": (_ints(1, 10), INTEGERS, ()),
        "--popsize": (_ints(2, 6), INTEGERS, ()),
        "--restarts": (_ints(0, 2), INTEGERS, ()),
        "--from-tuned": (None, [], ()),
        "--episodes": (_ints(1, 4), INTEGERS, ()),
        "--seed": (_ints(0, 10), INTEGERS, ()),
        "--preset": (st.sampled_from(["train", "test"]), NAMES, ("preset",)),
        "--env-kwargs": (st.lists(_assign(ENV_KEYS, SOME_VALUES), min_size=1, max_size=2),
                         ASSIGNMENTS, ("preset",)),
        "--out": (st.sampled_from(["out/tuned", "out/tuned.yaml"]), PATHS, ()),
        "--dry-run": (None, [], ()),
        **EXECUTION}),
}
if HAVE_TRAIN:
    COMMANDS["train"] = ([], {
        "--config": (st.sampled_from(["runup_speed_yoshida_odd"]), NAMES, ("config",)),
        "--env": (st.sampled_from(["abb_gym/RunUpSpeed-v0"]), ["", "x"], ("entry",)),
        "--seed": (_ints(0, 10), INTEGERS, ()),
        "--seeds": (st.lists(_ints(0, 10), min_size=1, max_size=3), INTEGERS, ("seed",)),
        "--n-timesteps": (_floats(1.0, 1e6), NUMBERS, ()),
        "--n-envs": (_ints(1, 8), INTEGERS, ()),
        "--hyperparams": (st.lists(_assign(["learning_rate", "n_steps", "gamma", "bogus"],
                                           SOME_VALUES), min_size=1, max_size=2),
                          ASSIGNMENTS, ()),
        "--env-kwargs": (st.lists(_assign(ENV_KEYS, SOME_VALUES), min_size=1, max_size=2),
                         ASSIGNMENTS, ("preset",)),
        "--eval-freq": (_ints(0, 100), INTEGERS, ()),
        "--eval-episodes": (_ints(1, 5), INTEGERS, ()),
        "--checkpoint-freq": (_ints(0, 100), INTEGERS, ()),
        "--out": (st.sampled_from(["out/run"]), PATHS, ()),
        "--tensorboard-log": (st.sampled_from(["out/tb"]), PATHS, ()),
        "--verbose": (st.sampled_from(["0", "1"]), ["3", "x"], ()),
        "--no-progress": (None, [], ()),
        "--workers": (_ints(1, 2), INTEGERS, ()),
    })


@st.composite
def command_lines(draw):
    """(argv, names an error may give)."""
    name = draw(st.sampled_from(sorted(COMMANDS)))
    positional, options = COMMANDS[name]
    argv = name.split() + [draw(p) for p in positional]
    names = {name.split()[-1]}
    if name == "evaluate":  # a required option
        argv += ["--policy", "baseline:ramp"]
    if name == "train":
        argv += ["--config", "runup_speed_yoshida_odd"]
    if name == "simulate":  # kept cheap: t_end <= 0.05 s, or a value refused up front
        argv += ["--t-end", _value(draw, st.sampled_from(["0.01", "0.05"]),
                                   ["nan", "-1", "0", "5e-324", "1e308", "x"], 0.15)]
        names |= {"--t-end", "t_end"}
    for option in draw(st.lists(st.sampled_from(sorted(options)), max_size=4, unique=True)):
        good, bad, extra = options[option]
        names |= {option, option[2:].replace("-", "_"), *extra}
        if good is None:
            argv.append(option)
            continue
        value = _value(draw, good, bad)
        values = value if isinstance(value, list) else [value]
        for v in values:  # KEY=VALUE settings may name their key
            if isinstance(v, str) and "=" in v and v.split("=")[0].strip():
                names.add(v.split("=")[0].strip())
        if option in ("--x", "--y"):
            names.add(value)
        if option == "--set" or option in ("--env-kwargs", "--hyperparams"):
            argv.append(option)
            argv += values
        else:
            argv += [option, *values]
    if draw(st.booleans()):  # the global option before the command
        folder = _value(draw, st.sampled_from(["a_dir"]), PATHS, 0.5)
        argv = ["--configs", folder] + argv
        names |= {"--configs"}
    return argv, names


def _check_result(argv, out):
    """A run that exits 0 produced what it was asked for, with finite numbers."""
    if argv[0] != "simulate":
        return
    if "--json" in argv:
        target = argv[argv.index("--json") + 1]
        if target == "-" or os.path.isfile(target):  # not /dev/null
            text = out.splitlines()[0] if target == "-" else open(target).read()
            data = json.loads(text)
            assert np.all(np.isfinite(np.asarray(data["whirl_radius"], float)))
    if "--json" not in argv or argv[argv.index("--json") + 1] != "-":
        assert "peak_whirl_ratio" in out


@settings(PROPERTY, max_examples=600 * SCALE)
@given(line=command_lines())
def test_every_command_exits_0_or_2_with_one_line_naming_the_argument(line):
    argv, names = line
    code, out, err = run(argv)
    event(f"{next(a for a in argv if a in COMMANDS or a == 'bench')}: {code}")
    if code in (0, "reached"):
        if code == 0:
            _check_result(argv, out)
        return
    lines = err.strip().splitlines()
    assert "Traceback" not in err, (argv, err)
    assert code in (1, 2) and len(lines) == 1, (argv, code, err)  # 1: a failed simulation
    assert lines[0].startswith("abb-gym"), (argv, err)
    if code == 2:
        assert any(n in lines[0] for n in names), (argv, lines[0], sorted(names))


@pytest.mark.parametrize("option", ["--out", "--resume-dir"])
def test_evaluate_refuses_an_empty_path_before_it_builds_an_environment(option, monkeypatch,
                                                                        capsys):
    """Building the policies' environments may compile a kernel, whose notice would join the
    refusal on stderr (it did, on a clean clone's cold cache): the path comes first."""
    from abb_gym.cli import main
    from abb_gym.evaluation import evaluate as ev

    def built(*args, **kwargs):
        raise AssertionError("an environment was built before the path was checked")

    monkeypatch.setattr(ev, "check_inputs", built)
    assert main(["evaluate", "--policy", "baseline:ramp", option, ""]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and option in err[0]
