"""The command line: simulate writes a table, JSON and a PNG; bad input exits 2 with one line."""
import json

import numpy as np

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
