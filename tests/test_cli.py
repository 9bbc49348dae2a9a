"""The command line: simulate writes a table, JSON and a PNG; bad input exits 2 with one line,
a failed simulation exits 1 with one line, output paths are checked before computing, and a
closed stdout ends the command quietly."""
import io
import json
import subprocess
import sys

import numpy as np
import pytest

from abb_gym.cli import main


def test_simulate_json_plot_and_overrides(tmp_path, capsys):
    png, js = tmp_path / "run.png", tmp_path / "run.json"
    rc = main(["simulate", "--scene", "yoshida_odd", "--profile", "dwell", "--dwell-time", "0.4",
               "--set", "ball_mass=2e-3", "--t-end", "3.5", "--ball-angles-deg", "45", "-45",
               "--plot", str(png), "--json", str(js)])
    assert rc == 0
    assert png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG"
    data = json.loads(js.read_text())
    assert data["scene"]["ball_mass"] == [2e-3, 2e-3]
    assert abs(np.degrees(data["ball_angles"][0][0]) - 45.0) < 1e-9
    assert len(data["t"]) == len(data["whirl_radius"]) == 3501
    assert "peak_whirl_ratio" in capsys.readouterr().out


def test_simulate_motor_and_stdout_json(capsys):
    rc = main(["simulate", "--limited-power", "2e-4", "--speed", "150", "--t-end", "0.5",
               "--output-dt", "0.01", "--json"])
    assert rc == 0
    data = json.loads(capsys.readouterr().out)
    assert len(data["motor_torque"]) == 51 and data["rotor_speed"][-1] > 0


def test_bad_input_is_one_line_and_exit_2(capsys):
    assert main(["simulate", "--set", "ball_mass=-1"]) == 2
    err = capsys.readouterr().err
    assert "ball_mass" in err and "[1e-07, 1000] [kg]" in err and "Traceback" not in err
    assert main(["simulate", "--scene", "nope"]) == 2
    assert main(["simulate", "--set", "oops"]) == 2


def test_demo_writes_figures(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path)]) == 0
    assert len(list(tmp_path.glob("*.png"))) == 2
    out = capsys.readouterr().out
    assert "dwell 2.5-3.0 s" in out and "peak W_r/e" in out


# ---------------------------------------------------------------- failures are one line
def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_simulation_error_is_one_line_and_exit_1(capsys, monkeypatch):
    from abb_gym import SimulationError

    def diverge(*args, **kwargs):
        raise SimulationError("the state became non-finite in 'x' at t = 0.004 s", 0.004, "x")

    monkeypatch.setattr("abb_gym.physics.simulate", diverge)
    assert main(["simulate", "--t-end", "0.2"]) == 1
    assert "non-finite in 'x'" in _one_line(capsys.readouterr().err)


@pytest.mark.parametrize("argv, code", [
    (["--set", "ball_drag=1e30", "--t-end", "0.2"], 2),  # beyond the field's bound
    (["--set", "support_stiffness_x=1e30", "--t-end", "0.2"], 2),
    (["--set", "support_stiffness_x=1e12", "--t-end", "0.2"], 1),  # valid, but diverges
    (["--t-end", "1e30"], 2),  # more work than the bound allows
])
def test_diverging_or_out_of_range_runs_are_one_line(argv, code, capsys):
    # out-of-range fields are bad input (2); a run the integrator cannot follow fails (1)
    assert main(["simulate", *argv]) == code
    assert _one_line(capsys.readouterr().err).startswith("abb-gym simulate: error: ")


def test_json_into_a_missing_folder_creates_it(tmp_path):
    path = tmp_path / "new" / "deeper" / "run.json"
    assert main(["simulate", "--t-end", "0.05", "--json", str(path)]) == 0
    assert json.loads(path.read_text())["t"][-1] == pytest.approx(0.05)


def _refuse(*args, **kwargs):
    raise AssertionError("computed before the output path was checked")


@pytest.mark.parametrize("argv", [
    ["simulate", "--json", "{file}/run.json"],
    ["simulate", "--plot", "{file}/sub/run.png"],
    ["simulate", "--json", "{dir}"],
    ["evaluate", "--policy", "baseline:ramp", "--out", "{file}/eval"],
    ["evaluate", "--policy", "baseline:ramp", "--out", "{file}"],
    ["stability-map", "--out", "{file}/map"],
    ["study", "settling", "--out", "{file}/study"],
    ["tune-baselines", "--out", "{file}/tuned"],
    ["bench", "speed", "--out", "{file}/bench"],
    ["bench", "accuracy", "--out", "{file}/bench"],
    ["demo", "--out", "{file}/demo"],
])
def test_output_paths_are_checked_before_computing(argv, tmp_path, capsys, monkeypatch):
    for target in ("abb_gym.physics.simulate", "abb_gym.cli.demo.demonstrate",
                   "abb_gym.evaluation.evaluate.evaluate", "abb_gym.analysis.stability_map",
                   "abb_gym.evaluation.studies.settling_study", "abb_gym.baselines.tuner.tune",
                   "abb_gym.benchmarks.speed.iter_speed",
                   "abb_gym.benchmarks.accuracy.run_accuracy"):
        monkeypatch.setattr(target, _refuse)
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    argv = [a.format(file=blocker, dir=tmp_path) for a in argv]
    assert main(argv) == 2
    line = _one_line(capsys.readouterr().err)
    assert "is a file, not a folder" in line or "is a folder; give a file name" in line
    assert blocker.read_text() == "not a folder"


def test_train_output_below_a_file_is_refused_before_training(tmp_path, capsys):
    pytest.importorskip("stable_baselines3")
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    assert main(["train", "--config", "runup_speed_yoshida_odd", "--out",
                 str(blocker / "run")]) == 2
    assert "is a file, not a folder" in _one_line(capsys.readouterr().err)


def test_a_closed_stdout_ends_quietly_in_process(monkeypatch):
    class Closed(io.StringIO):
        def write(self, text):
            raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(sys, "stdout", Closed())
    assert main(["simulate", "--t-end", "0.05", "--json"]) == 141


def test_a_closed_stdout_ends_quietly(tmp_path):
    # `abb-gym simulate --json | head -c 10`: ~300 kB of JSON into a pipe closed after 10 bytes
    proc = subprocess.Popen([sys.executable, "-m", "abb_gym.cli", "simulate", "--json",
                             "--t-end", "2"], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    head = proc.stdout.read(10)
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=600) == 141, err
    assert head == b'{"scene": '
    assert "Traceback" not in err and "BrokenPipe" not in err and "Exception ignored" not in err


def test_help_shows_version_every_method_defaults_and_no_rest_markup(capsys):
    from abb_gym import __version__
    from abb_gym.cli import build_parser
    from abb_gym.physics.simulate import METHODS
    with pytest.raises(SystemExit):
        main(["--version"])
    assert capsys.readouterr().out.strip() == f"abb-gym {__version__}"
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name, p in sub.choices.items():
        text = p.format_help()
        assert "``" not in text and "::\n" not in text, name
        assert "(default: None)" not in text, name
    simulate_help = sub.choices["simulate"].format_help()
    assert all(m in simulate_help for m in METHODS)
    assert "(default: rk4)" in simulate_help
    # the examples of a description keep their lines
    assert "\n    abb-gym tune-baselines --scene yoshida_odd" in \
        sub.choices["tune-baselines"].format_help()


def test_evaluate_refuses_an_episode_count_beyond_its_bound(capsys):
    """`evaluate --episodes 1e12` passed every check and then built the chunk list for
    minutes; it is one line and exit 2 before any work."""
    from abb_gym.cli import main as cli_main
    assert cli_main(["evaluate", "--policy", "baseline:ramp", "--episodes",
                     str(10 ** 12)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--episodes must be in [1, 1000000]" in err[0]
