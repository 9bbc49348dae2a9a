"""Workflows of engineers and RL users (issue 48, "A user guide, not a lab notebook"): one
name per scene field everywhere, a scene template, stability-map axes with units, the
drive limits of ``simulate``, ``abb-gym list`` and ``python -m abb_gym``."""
from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from abb_gym import SceneError, load_scene
from abb_gym.cli import main
from abb_gym.configuration import bounds_text
from abb_gym.physics.scene import _SPECS, FIELD_NAMES, resolve_field

REPO = Path(__file__).resolve().parents[1]


def _run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


# ------------------------------------------------------------- python -m abb_gym
def test_python_dash_m_abb_gym_is_the_command_line():
    out = subprocess.run([sys.executable, "-m", "abb_gym", "--version"], capture_output=True,
                         text=True, timeout=300, cwd=REPO)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.startswith("abb-gym ")


# ------------------------------------------------------------- one name per field
def test_every_scene_field_is_named_by_its_yaml_path_and_its_flat_name():
    for field, spec in _SPECS.items():
        assert resolve_field(field) == (field,)
        if spec.yaml:
            assert resolve_field(spec.yaml) == (field,)
    assert resolve_field("support.stiffness") == resolve_field("support_stiffness") \
        == ("support_stiffness_x", "support_stiffness_y")


@pytest.mark.parametrize("path, flat, value", [
    ("balls.drag", "ball_drag", 2.0), ("rotor.mass", "rotor_mass", 0.2),
    ("support.damping", "support_damping", 0.5), ("balls.count", "ball_count", 3),
    ("fluid.drag_law", "fluid_drag_law", "linear"), ("drive.operating_speed",
                                                     "drive_operating_speed", 150.0)])
def test_load_scene_and_replace_take_either_name(path, flat, value):
    by_path = load_scene("yoshida_odd", **{path: value})
    assert by_path == load_scene("yoshida_odd", **{flat: value})
    assert by_path == load_scene("yoshida_odd").replace(**{path: value})


def test_a_field_given_by_both_names_or_by_an_unknown_name_is_one_clear_error():
    with pytest.raises(SceneError, match="'ball_drag' is given twice"):
        load_scene("yoshida_odd", ball_drag=1.0, **{"balls.drag": 2.0})
    with pytest.raises(SceneError, match=r"unknown field.*'ball\.drag'.*did you mean "
                                         r"'balls\.drag'"):
        load_scene("yoshida_odd", **{"ball.drag": 2.0})


def test_a_scene_file_may_name_a_field_flat_at_its_top_level(tmp_path):
    path = tmp_path / "flat.yaml"
    text = (REPO / "configs/scenes/yoshida_odd.yaml").read_text()
    path.write_text(text + "ball_drag: 3.0\nsupport_damping: 0.4\n")
    scene = load_scene(path)
    assert scene.ball_drag == (3.0, 3.0) and scene.support_damping_y == 0.4


def test_the_scene_docs_list_both_names_of_every_field():
    import abb_gym.physics.scene as scene_module
    doc = scene_module.__doc__
    for field, spec in _SPECS.items():
        if field == "name":
            continue
        row = next(line for line in doc.splitlines() if line.startswith(f"{spec.yaml or field} "))
        assert f" {field} " in row


def test_simulate_set_takes_the_yaml_path(capsys):
    import json

    def run(*extra):
        code, out, err = _run(capsys, "simulate", "--t-end", "0.05", "--json", "-", *extra)
        assert code == 0, err
        data = json.loads(out)
        return data["scene"], data["ball_angles"]

    by_path, flat = run("--set", "balls.drag=2.5"), run("--set", "ball_drag=2.5")
    assert by_path == flat and by_path[0]["ball_drag"] == [2.5, 2.5]
    assert run()[1] != flat[1]


def test_stability_map_axes_take_the_yaml_path_and_are_labelled_with_units():
    from abb_gym.analysis import stability_map
    from abb_gym.analysis.maps import axis_label
    scene = load_scene("lu_hung_odd3")
    kw = dict(workers=1, progress=False, n_members=5, n_balls=[3])
    by_path = stability_map(scene, ("balls.drag", [0.5, 2.0]), ("Omega", [1.0, 2.0]), **kw)
    flat = stability_map(scene, ("ball_drag", [0.5, 2.0]), ("Omega", [1.0, 2.0]), **kw)
    for f in ("union_stable", "best"):
        np.testing.assert_array_equal(by_path.field(3, f), flat.field(3, f))
    fig = by_path.figure()
    ax = fig.axes[0]
    assert ax.get_xlabel() == "balls.drag (ball_drag) [N s/m]"
    assert ax.get_ylabel() == "Omega = w / w_n [-]"
    assert "undamped natural frequency w_n = sqrt(K/M)" in fig._supxlabel.get_text()
    groups = stability_map(scene, ("zeta", [0.05, 0.1]), ("eta", [0.3, 0.5]), **kw)
    note = groups.figure()._supxlabel.get_text()
    # no axis changes K or M: w_n is the scene's
    assert "every point at Omega = 2" in note and f"w_n = {scene.critical_speed:.4g} rad/s" \
        in note
    assert axis_label("zeta") == "zeta = C / (2 M w_n) [-]"
    assert axis_label("race.eccentricity") == "race.eccentricity (race_eccentricity) [m]"


# ------------------------------------------------------------- the scene template
@pytest.mark.parametrize("base", ["yoshida_odd", "washer", "spannan_cfrp"])
def test_the_scene_template_loads_as_its_base_scene(base):
    from abb_gym.physics.scene_template import scene_template
    text = scene_template("mine", base)
    data = yaml.safe_load(text)
    assert data["name"] == "mine"
    import tempfile
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "mine.yaml"
        path.write_text(text)
        scene = load_scene(path)
    ref = load_scene(base)
    differ = [f.name for f in dataclasses.fields(scene) if getattr(scene, f.name)
              != getattr(ref, f.name)]
    assert differ == ["name", "description", "source"]


def test_the_scene_template_comments_every_field_with_its_unit_and_range():
    from abb_gym.physics.scene_template import scene_template
    text = scene_template("mine")
    lines = text.splitlines()
    for field, spec in _SPECS.items():
        if field in ("name", "description", "source"):
            continue
        section, _, key = spec.yaml.partition(".")
        line = next(line for line in lines if line.startswith(f"  {key}:")
                    and f"({field})" in line)
        comment = line.split("#", 1)[1]
        assert bounds_text(spec).replace(f" [{spec.unit}]", "") in comment
        if spec.unit not in ("", "-"):
            assert f"[{spec.unit}]" in comment


def test_new_scene_writes_the_template_and_refuses_to_overwrite(tmp_path, capsys,
                                                                 monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = _run(capsys, "new-scene", "my_drive")
    assert code == 0, err
    path = tmp_path / "scenes" / "my_drive.yaml"
    assert load_scene(path).name == "my_drive"
    assert "wrote scenes/my_drive.yaml" in out
    code, _, err = _run(capsys, "new-scene", "my_drive")
    assert code == 2 and "exists; use --force" in err
    code, _, err = _run(capsys, "--configs", str(tmp_path), "simulate", "--scene", "my_drive",
                        "--t-end", "0.01")
    assert code == 0, err
    code, _, err = _run(capsys, "new-scene", "../escape")
    assert code == 2 and "scene name must be" in err


# ------------------------------------------------------------- abb-gym list
def test_list_shows_scenes_presets_ids_baselines_and_agents(capsys):
    from abb_gym import resources
    from abb_gym.baselines.loader import BASELINE_NAMES
    from abb_gym.envs.tasks import TASKS
    code, out, err = _run(capsys, "list")
    assert code == 0, err
    for name in resources.names("scenes") + resources.names("envs"):
        assert f"  {name} " in out
    for env_id in TASKS:
        assert f"  {env_id} " in out
    for name in BASELINE_NAMES:
        assert f"  baseline:{name} " in out
    for name in resources.names("agents"):
        assert f"  ppo:{name} " in out
    code, only, _ = _run(capsys, "list", "scenes")
    assert only.startswith("scenes") and "baseline:" not in only


# ------------------------------------------------------------- the scene's drive limits
SLOW = {"drive.operating_speed": 150.0}  # a machine rated for 150 rad/s


def test_simulate_without_a_drive_runs_the_scenes_nominal_run_up():
    import warnings

    from abb_gym import SpeedProfile, simulate
    scene = load_scene("yoshida_odd", **SLOW)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # within the limits: no warning
        tr = simulate(scene)
    # a ramp at half of drive.max_acceleration (80 rad/s^2), held at 150 rad/s, for the
    # run-up (3.75 s) plus the 1 s settling window
    assert tr.t[-1] == pytest.approx(150.0 / 40.0 + 1.0)
    assert tr.rotor_speed.max() == pytest.approx(150.0)
    same = simulate(scene, SpeedProfile.ramp(40.0, 150.0), 4.75)
    np.testing.assert_array_equal(tr.states, same.states)


def test_the_api_warns_about_a_drive_beyond_the_limits_and_raises_or_ignores_when_asked():
    import warnings

    from abb_gym import MotorDrive, SpeedProfile, simulate
    from abb_gym.physics.drive_limits import DriveLimitWarning
    scene = load_scene("yoshida_odd", **SLOW)
    ramp = SpeedProfile.ramp(40.0)  # no hold: 320 rad/s at 8 s, what used to pass silently
    with pytest.warns(DriveLimitWarning, match=r"320 rad/s, beyond the scene's "
                                              r"drive\.operating_speed = 150 rad/s"):
        warned = simulate(scene, ramp, 8.0, output_dt=0.05)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ignored = simulate(scene, ramp, 8.0, output_dt=0.05, drive_limits="ignore")
    np.testing.assert_array_equal(warned.states, ignored.states)  # a warning, same run
    with pytest.raises(ValueError, match=r"acceleration 400 rad/s\^2 is beyond the scene's "
                                         r"drive\.max_acceleration = 80"):
        simulate(scene, SpeedProfile.ramp(400.0, 100.0), 1.0, drive_limits="raise")
    with pytest.warns(DriveLimitWarning, match=r"torque command 0\.01 N m is beyond"):
        simulate(scene, MotorDrive.constant_torque(0.01), 0.01)
    # a motor's speed is known after the run: 0.004 N m for 3 s passes 150 rad/s
    with pytest.raises(ValueError, match=r"rotor speed reached .* beyond the scene's "
                                         r"drive\.operating_speed = 150"):
        simulate(scene, MotorDrive.constant_torque(0.004), 3.0, drive_limits="raise")
    with pytest.raises(ValueError, match="drive_limits must be one of"):
        simulate(scene, drive_limits="off")


def test_the_simulate_command_defaults_to_the_drive_limits_and_refuses_beyond_them(capsys):
    import json
    set_slow = ["--set", "drive.operating_speed=150"]
    code, out, err = _run(capsys, "simulate", *set_slow, "--json", "-", "--output-dt", "0.05")
    assert code == 0, err
    data = json.loads(out)
    assert max(data["rotor_speed"]) == pytest.approx(150.0)  # before: 240 rad/s at 6 s
    for argv, limit in ((["--operating-speed", "320"], "drive.operating_speed = 150"),
                        (["--accel", "400", "--t-end", "0.1"], "drive.max_acceleration = 80"),
                        (["--motor-torque", "0.01", "--t-end", "0.1"], "torque command"),
                        (["--profile", "constant", "--speed", "200", "--t-end", "0.1"],
                         "drive.operating_speed = 150")):
        code, _, err = _run(capsys, "simulate", *set_slow, *argv)
        assert code == 2 and limit in err and "--allow-beyond-drive-limits" in err, err
        assert len(err.strip().splitlines()) == 1
    code, _, err = _run(capsys, "simulate", *set_slow, "--operating-speed", "320",
                        "--t-end", "0.5", "--allow-beyond-drive-limits")
    assert code == 0, err
    code, _, err = _run(capsys, "simulate", "--motor-torque", "0.004")
    assert code == 2 and "--t-end" in err


# ------------------------------------------------------------- the compile notice
def test_a_long_compilation_of_any_kernel_of_the_package_is_announced(monkeypatch, capsys):
    """numba's compilations at gym.make (the stiffness check) and reset (the observation)
    used to run silently, 40 s of the 111 s of a cold start; every compilation of a package
    function that runs past NOTICE_AFTER is announced, the first naming build-kernels."""
    import threading
    import time

    import numba
    from numba.core import event

    import abb_gym._numba  # noqa: F401  (installs the listener)
    from abb_gym import _compile_notice
    monkeypatch.setattr(_compile_notice, "NOTICE_AFTER", 0.05)
    monkeypatch.setattr(_compile_notice, "_hinted", threading.Event())
    monkeypatch.delenv("ABB_GYM_QUIET", raising=False)

    def probe(x):
        return x + 1

    def compiling(fn):
        return event.trigger_event("numba:compile", data={"dispatcher": numba.njit(fn),
                                                          "args": (), "return_type": None})

    probe.__module__ = "abb_gym.probe"
    with compiling(probe):
        time.sleep(0.5)
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("abb-gym: compiling abb_gym.probe.")
    assert "abb-gym build-kernels compiles every kernel ahead of time" in err[0]
    assert err[1].startswith("abb-gym: compiled abb_gym.probe.")
    with compiling(probe):  # the hint once per process
        time.sleep(0.5)
    assert "build-kernels" not in capsys.readouterr().err
    with compiling(probe):  # a quick one stays silent
        pass
    probe.__module__ = "someone_else"
    with compiling(probe):  # another package's functions are its own business
        time.sleep(0.5)
    monkeypatch.setenv("ABB_GYM_QUIET", "1")
    probe.__module__ = "abb_gym.probe"
    with compiling(probe):
        time.sleep(0.5)
    time.sleep(0.2)
    assert capsys.readouterr().err == ""


@pytest.mark.slow
def test_a_cold_make_and_reset_say_that_they_compile(tmp_path):
    """On an empty kernel cache, gym.make and reset each announce what they compile."""
    code = ("import gymnasium as gym, abb_gym, sys\n"
            "env = gym.make('abb_gym/RunUpSpeed-v0')\nprint('made', file=sys.stderr)\n"
            "env.reset(seed=0)\nprint('reset', file=sys.stderr)\n")
    import os
    env = {k: v for k, v in os.environ.items() if k != "ABB_GYM_QUIET"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=1800, cwd=REPO, env={**env, "NUMBA_CACHE_DIR": str(tmp_path)})
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stderr.splitlines()
    made, reset = lines.index("made"), lines.index("reset")
    assert any("compiling" in line and "build-kernels" in line for line in lines[:made])
    assert any("compiling" in line for line in lines[made:reset])


# ------------------------------------------------------------- the demo
def test_the_demo_states_its_conclusion_and_labels_every_line(tmp_path, capsys, monkeypatch):
    """The demo's table showed the dwell with the higher peak and nothing else, so a reader
    concluded "dwell is worse"; it now says what the dwell does (both balls opposite the
    imbalance soon after the critical speed, from both starts; without it one start never
    gets there), in one line, and its figures name every line and reference line."""
    from abb_gym import plots
    legends = []
    saved = plots.savefig

    def keep_legends(fig, path, **kw):
        legends.append([t.get_text() for ax in fig.axes if ax.get_legend()
                        for t in ax.get_legend().get_texts()])
        return saved(fig, path, **kw)

    monkeypatch.setattr(plots, "savefig", keep_legends)
    monkeypatch.setenv("ABB_GYM_PROGRESS", "lines")
    code, out, err = _run(capsys, "demo", "--out", str(tmp_path))
    assert code == 0, err
    assert "demo kernels: 100% 2/2" in err  # the kernels it needs, with a bar
    [line] = [line for line in out.splitlines() if line.startswith("conclusion:")]
    # from the runs: the dwell brings both balls over from both starts (Yoshida Figs. 4.7,
    # 4.9), the plain ramp leaves one ball of the 45/-45 start behind (Fig. 4.3)
    assert "with the dwell both balls are opposite the imbalance" in line
    with_dwell, without = line.split("without it from ")
    assert "never" not in with_dwell and "never (a ball ends at -58 deg)" in without
    assert "higher whirl peak" in line
    assert "balls opposite the imbalance from [s]" in out
    assert len(legends) == 2
    for texts in legends:
        assert {"rotor speed (left axis)", "whirl W_r / e (right axis)",
                "critical speed 100 rad/s reached", "-180 deg: opposite the imbalance",
                "balanced position (no residual imbalance): -241, -119 deg"} <= set(texts)
        assert {"no dwell: ball 1", "no dwell: ball 2", "dwell 2.5-3.0 s: ball 1"} <= set(texts)


# ------------------------------------------------------------- tuning to a specification
def test_a_specification_is_parsed_with_one_line_errors():
    from abb_gym.baselines.specification import Specification
    spec = Specification.parse("peak_whirl<=20, run_up <= 5")
    assert str(spec) == "peak_whirl<=20,run_up<=5,at_speed>=1"
    assert str(Specification.parse("at_speed>=0.9")) == "at_speed>=0.9"
    for text, message in (("peak<=3", "unknown metric 'peak'; allowed: peak_whirl"),
                          ("peak_whirl<3", "not METRIC<=BOUND"),
                          ("run_up<=soon", "must be a finite number [s]"),
                          ("run_up<=nan", "finite"), ("", "requirements like"),
                          ("run_up<=5,run_up<=4", "given twice")):
        with pytest.raises(ValueError, match=re_escape(message)):
            Specification.parse(text)


def re_escape(text):
    import re
    return re.escape(text)


def test_feasible_candidates_rank_before_infeasible_ones_whatever_their_residual():
    from abb_gym.baselines.specification import Specification
    spec = Specification.parse("peak_whirl<=20,run_up<=5")

    def row(peak, run_up, residual, at_speed=1.0):
        return {"peak_whirl": peak, "run_up_time": run_up, "residual_vibration": residual,
                "at_speed": at_speed, "balanced": 0.0}

    feasible_poor = row(19.0, 4.0, 2.0)
    feasible_good = row(20.0, 5.0, 1.0)  # on the bounds: met
    slightly_off = row(21.0, 4.0, 0.1)   # 5 % over one bound, a tiny residual
    far_off = row(40.0, 8.0, 0.05)
    not_at_speed = row(10.0, 4.0, 0.01, at_speed=0.5)
    rows = [far_off, feasible_poor, not_at_speed, slightly_off, feasible_good]
    assert sorted(rows, key=spec.key) == [feasible_good, feasible_poor, slightly_off,
                                          not_at_speed, far_off]
    assert spec.fitness(rows) == [4.0, 1.0, 3.0, 2.0, 0.0]
    assert spec.violation(slightly_off) == pytest.approx(0.05)


def test_tune_baselines_with_a_spec_minimises_the_residual_under_the_requirements(capsys):
    """On yoshida_odd's training machines a faster ramp lowers the peak and the run-up time
    and leaves more residual; the return prefers 40 rad/s^2 (peak 22.5 W_r/e).  Under
    peak_whirl<=20 and run_up<=5 the tuner finds a ramp that meets both with less residual
    than the fastest one (80 rad/s^2, which meets them too: residual 2.1 W_r/e)."""
    from abb_gym.baselines import tuner
    from abb_gym.baselines.specification import Specification
    spec = Specification.parse("peak_whirl<=20,run_up<=5")
    kw = dict(episodes=4, seed=20_000, preset="train")
    result = tuner.tune("yoshida_odd", families=("ramp",), budget=10, spec=spec,
                        progress=False, **kw)
    ramp = result["families"]["ramp"]
    assert ramp["feasible"] and all(r["met"] for r in ramp["requirements"].values())
    assert ramp["mean_peak_whirl"] <= 20.0 and ramp["mean_run_up_time"] <= 5.0
    [fastest, by_return] = tuner.evaluate_candidates("yoshida_odd", "ramp",
                                                     [{"accel": 80.0}, {"accel": 40.0}], **kw)
    assert spec.violation(fastest) == 0.0 and spec.violation(by_return) > 0.0
    assert ramp["mean_residual_vibration"] < fastest["residual_vibration"]
    assert "peak_whirl<=20,run_up<=5,at_speed>=1" in result["objective"]
    code, out, err = _run(capsys, "tune-baselines", "--family", "ramp", "--budget", "3",
                          "--episodes", "2", "--spec", "peak_whirl<=20,run_up<=5",
                          "--dry-run", "--workers", "1")
    assert code == 0, err
    assert "ramp: meets peak_whirl<=20,run_up<=5,at_speed>=1" in out \
        or "ramp: does NOT meet" in out
    code, _, err = _run(capsys, "tune-baselines", "--spec", "peak<=3", "--dry-run")
    assert code == 2 and "unknown metric 'peak'" in err


# ------------------------------------------------------------- RL users: how to start
def test_making_a_run_up_env_warns_once_how_a_policy_must_start_to_learn(monkeypatch):
    """Plain SB3 PPO at the registered defaults never reaches the operating speed (return
    -198 after 20k and 100k steps, at 0.01 and 0.05 s alike: abb_gym.envs.learning); a user
    who makes the environment is told once why and what the shipped configs do."""
    import warnings

    import gymnasium as gym

    from abb_gym.envs import learning
    from abb_gym.envs.learning import LearningDefaultsWarning
    monkeypatch.setattr(learning, "_advised", set())
    with pytest.warns(LearningDefaultsWarning) as caught:
        gym.make("abb_gym/RunUpSpeed-v0").close()
    [w] = caught
    assert w.filename == __file__  # points at the user's gym.make
    text = str(w.message)
    assert "abb_gym/RunUpSpeed-v0" in text and "BoundedMlpPolicy" in text \
        and "action_mean_init=0.5" in text and "control_interval=0.05" in text
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gym.make("abb_gym/RunUpSpeed-v0").close()  # once per process
        gym.make("abb_gym/DwellProfile-v0").close()  # decides a whole profile: no advice
        # abb-gym's own tools know: their environments are made silently
        from abb_gym.evaluation.evaluate import make_env
        make_env("abb_gym/RunUpTorque-v0", "yoshida_odd", "test", 2).close()
    with pytest.warns(LearningDefaultsWarning, match="action_mean_init=0.3"):
        gym.make_vec("abb_gym/RunUpTorque-v0", num_envs=2,
                     vectorization_mode="vector_entry_point").close()


def test_make_sb3_env_gives_the_advice_to_its_user(monkeypatch):
    pytest.importorskip("stable_baselines3")
    from abb_gym.envs import learning
    from abb_gym.envs.learning import LearningDefaultsWarning
    from abb_gym.rl import make_sb3_env
    monkeypatch.setattr(learning, "_advised", set())
    with pytest.warns(LearningDefaultsWarning) as caught:
        make_sb3_env("abb_gym/RunUpSpeed-v0", 2).close()
    assert caught[0].filename == __file__
