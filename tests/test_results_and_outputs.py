"""Results that are never silently wrong, outputs that never lose data, and input that is one
clear error.

* the tuner names its file after the scene's ``name`` (a ``--scene`` path ``dir/my.yaml``
  wrote ``my.yaml.yaml``, and ``evaluate --configs`` then used the default parameters);
* ``evaluate`` scores an agent with the reward weights recorded with it, takes
  ``--env-kwargs``, states the weights, and scores every policy of one run with the same;
* a report folder has one writer at a time, and a report is replaced whole or not at all;
* a YAML key given twice is refused naming the key and the lines; nesting beyond a sane
  depth is one line, not a RecursionError;
* Ctrl-C prints ``interrupted: N of M tasks stored; rerun the same command to resume`` with
  the N of the whole command and exits 130, without a traceback.
"""
from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml

from abb_gym import SceneError, load_scene
from abb_gym.cli import main
from abb_gym.execution import ResultStore
from abb_gym.execution.testing import ctrl_c_after_saves

REPO = Path(__file__).resolve().parents[1]
SCENE = REPO / "configs" / "scenes" / "yoshida_odd.yaml"

try:
    import stable_baselines3  # noqa: F401
    HAVE_TRAIN = True
except ImportError:  # the training extra is not installed
    HAVE_TRAIN = False
needs_train = pytest.mark.skipif(not HAVE_TRAIN, reason="needs the training extra")


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err[-2000:]
    return lines[0]


# --------------------------------------------------------------------------- finding 4
def test_the_tuner_names_its_file_after_the_scene_and_evaluate_finds_it(tmp_path, capsys):
    scene = tmp_path / "dir" / "my.yaml"
    scene.parent.mkdir()
    scene.write_text(SCENE.read_text().replace("name: yoshida_odd", "name: my_machine"))
    conf = tmp_path / "conf"
    assert main(["tune-baselines", "--scene", str(scene), "--family", "ramp", "--budget", "4",
                 "--episodes", "1", "--workers", "1", "--out", str(conf / "baselines")]) == 0
    assert sorted(p.name for p in (conf / "baselines").iterdir()) == ["my_machine.yaml"]
    tuned = yaml.safe_load((conf / "baselines" / "my_machine.yaml").read_text())
    assert tuned["scene"] == "my_machine"
    capsys.readouterr()
    assert main(["--configs", str(conf), "evaluate", "--scene", str(scene), "--policy",
                 "baseline:ramp", "--episodes", "1", "--out", str(tmp_path / "eval")]) == 0
    report = json.loads((tmp_path / "eval" / "evaluation.json").read_text())
    assert report["policies"][0]["policy"] == "baseline:ramp (tuned)"
    assert report["policies"][0]["params"] == tuned["families"]["ramp"]["params"]


# --------------------------------------------------------------------------- finding 5
def _report(folder: Path) -> dict:
    return json.loads((folder / "evaluation.json").read_text())


@needs_train
def test_evaluate_scores_an_agent_with_its_own_reward_weights(tmp_path, capsys):
    """runup_speed_yoshida_odd was trained and evaluated with residual weight 6; the test
    preset has 2.  The same machines give the agent's own return by default, the summary
    says which weights, and a baseline of the same run is scored with the same."""
    agent = "runup_speed_yoshida_odd"
    args = ["--episodes", "2", "--seed", "5"]
    assert main(["evaluate", "--policy", f"ppo:{agent}", "--policy", "baseline:ramp", *args,
                 "--out", str(tmp_path / "own")]) == 0
    printed = capsys.readouterr().out
    own = _report(tmp_path / "own")
    assert own["reward_weights"]["residual"] == 6.0
    assert own["reward_source"] == f"recorded with ppo:{agent}"
    summary = (tmp_path / "own" / "summary.md").read_text()
    for text in (summary, printed):
        assert (f"Reward weights (recorded with ppo:{agent}): vibration 1, time 1, effort 0.1, "
                f"residual 6, failure 10.") in text
    for weight in ("6", "2"):
        assert main(["evaluate", "--policy", f"ppo:{agent}", "--policy", "baseline:ramp", *args,
                     "--env-kwargs", f"reward={{residual: {weight}}}",
                     "--out", str(tmp_path / weight)]) == 0
    returns = {name: [p["summary"]["return"]["mean"] for p in _report(tmp_path / name)[
        "policies"]] for name in ("own", "6", "2")}
    assert returns["own"] == returns["6"] != returns["2"]
    assert _report(tmp_path / "2")["reward_source"] == "--env-kwargs"


@needs_train
def test_agents_evaluated_with_other_weights_need_a_choice(tmp_path, capsys):
    rc = main(["evaluate", "--policy", "ppo:runup_speed_yoshida_odd", "--policy",
               "ppo:runup_speed_spannan_cfrp", "--scene", "yoshida_odd", "--episodes", "1",
               "--out", str(tmp_path / "e")])
    line = one_error_line(capsys)
    assert rc == 2 and "different reward weights" in line and "--env-kwargs" in line
    assert not (tmp_path / "e").exists()


# --------------------------------------------------------------------------- finding 8
def _hold_lock(folder: Path) -> subprocess.Popen:
    """Another process writing ``folder``: holds the lock until its stdin closes."""
    code = textwrap.dedent(f"""
        import sys
        from abb_gym.cli.outputs import lock_folder
        lock_folder({str(folder)!r}, "--out")
        print("locked", flush=True)
        sys.stdin.read()
    """)
    proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "locked"
    return proc


def test_a_second_writer_of_a_report_folder_is_refused_in_one_line(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    other = _hold_lock(out)
    try:
        rc = main(["evaluate", "--policy", "baseline:ramp", "--episodes", "1",
                   "--out", str(out)])
        line = one_error_line(capsys)
        assert rc == 2 and "--out" in line and "being written by another" in line, line
        assert not any(out.iterdir())
    finally:
        other.stdin.close()
        other.wait(30)
    # once the other command has ended, the folder is free; and a command's own lock ends
    # with it, so the next command (here, in the same process) may write there
    for _ in range(2):
        assert main(["evaluate", "--policy", "baseline:ramp", "--episodes", "1",
                     "--out", str(out)]) == 0


def test_a_report_that_fails_halfway_leaves_the_previous_one_whole(tmp_path, monkeypatch):
    from abb_gym.evaluation import report
    from abb_gym.evaluation.evaluate import evaluate
    results = [evaluate("abb_gym/RunUpSpeed-v0", "yoshida_odd", "baseline:ramp", 2, 0)]
    report.write_report(results, tmp_path)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}

    class DiskFull(OSError):
        pass

    def writerows(self, rows):  # half of the rows reach the file, then the disk is full
        rows = list(rows)
        for row in rows[: len(rows) // 2]:
            self.writerow(row)
        raise DiskFull("no space left on device")

    monkeypatch.setattr(csv.DictWriter, "writerows", writerows)
    results[0].episodes[0]["return"] = 123.0  # a new report would differ
    with pytest.raises(DiskFull):
        report.write_report(results, tmp_path)
    after = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert after == before  # no file replaced by half of a new one, no temporary file left


# --------------------------------------------------------------------------- findings 9, 10
def test_a_yaml_key_given_twice_is_refused_naming_the_key_and_lines(tmp_path, capsys):
    text = SCENE.read_text()
    nested = tmp_path / "nested.yaml"
    nested.write_text(text.replace("  drag: 1.0 ", "  drag: 1.0\n  drag: 9.0 "))
    line = text.splitlines().index(next(x for x in text.splitlines()
                                        if x.startswith("  drag: 1.0"))) + 1
    with pytest.raises(SceneError, match=rf"line {line + 1}: key 'drag' is given twice \(also "
                                         rf"on line {line}\)"):
        load_scene(nested)
    top = tmp_path / "top.yaml"
    top.write_text(text + "name: another_name\n")
    with pytest.raises(SceneError, match=r"key 'name' is given twice"):
        load_scene(top)
    assert main(["simulate", "--scene", str(nested), "--t-end", "0.01"]) == 2
    err = one_error_line(capsys)
    assert "nested.yaml" in err and "'drag' is given twice" in err
    # and in a KEY=VALUE option's YAML value
    assert main(["simulate", "--t-end", "0.01", "--set", "ball_drag={a: 1, a: 2}"]) == 2
    assert "'a' is given twice" in one_error_line(capsys)


def test_deeply_nested_yaml_is_one_line_not_a_recursion_error(tmp_path, capsys):
    deep = tmp_path / "deep.yaml"
    depth = 600_000  # 1.2 MB, under the 4 MB limit of a configuration file
    deep.write_text("name: deep\nrotor: " + "[" * depth + "]" * depth + "\n")
    assert 1_000_000 < deep.stat().st_size < 4 * 1024 * 1024
    with pytest.raises(SceneError, match=r"nesting deeper than 64 levels"):
        load_scene(deep)
    assert main(["simulate", "--scene", str(deep), "--t-end", "0.01"]) == 2
    line = one_error_line(capsys)
    assert "deep.yaml" in line and "line 2: nesting deeper than 64 levels" in line, line


# --------------------------------------------------------------------------- finding 11
def test_ctrl_c_says_how_many_tasks_of_the_command_are_stored(tmp_path, capsys, monkeypatch):
    """Two policies, one sweep each: Ctrl-C while the second one's result is saved.  The
    first sweep's result is stored, so "0 of 1 tasks finished" of the interrupted sweep was
    wrong; the line counts the command's tasks."""
    resume = tmp_path / "resume"
    argv = ["evaluate", "--policy", "baseline:ramp", "--policy", "baseline:knots",
            "--episodes", "2", "--workers", "1", "--resume-dir", str(resume),
            "--out", str(tmp_path / "out")]
    with ctrl_c_after_saves(1):
        try:
            rc = main(argv)
        except KeyboardInterrupt as exc:  # what happened: a traceback and a wrong count
            pytest.fail(f"Ctrl-C escaped the command: {exc}")
    err = capsys.readouterr().err
    assert rc == 130 and "Traceback" not in err, err
    assert len(ResultStore(resume)) == 1
    assert err.strip().splitlines()[-1] == ("abb-gym evaluate: interrupted: 1 of 2 tasks "
                                            "stored; rerun the same command to resume")
    assert main(argv) == 0  # the rerun resumes
    # without a store nothing is kept, and the line says so
    from abb_gym.execution import core

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(core.Executor, "map", interrupted)
    assert main(["evaluate", "--policy", "baseline:ramp", "--episodes", "2", "--workers", "1",
                 "--out", str(tmp_path / "out2")]) == 130
    assert "interrupted: nothing was stored" in capsys.readouterr().err


def test_ctrl_c_in_a_real_process_exits_130_without_a_traceback(tmp_path):
    """SIGINT to ``abb-gym`` while it computes: the interpreter's own handling, no stub."""
    import signal
    import time
    proc = subprocess.Popen([sys.executable, "-m", "abb_gym.cli", "evaluate", "--policy",
                             "baseline:ramp", "--episodes", "3000", "--workers", "1",
                             "--resume-dir", str(tmp_path / "r"), "--out", str(tmp_path / "o")],
                            stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"},
                            # as from a shell: a child inherits an ignored SIGINT, and Python
                            # then installs no KeyboardInterrupt handler (the test process may
                            # ignore SIGINT, depending on what ran before it in the worker)
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.time() + 300
    while time.time() < deadline and not [p for p in (tmp_path / "r").glob("*")
                                          if p.suffix in (".npz", ".pkl")]:
        time.sleep(0.2)  # until a result is stored (.pkl: an older abb-gym's store)
    proc.send_signal(signal.SIGINT)
    err = proc.communicate(timeout=120)[1]
    stored = len(ResultStore(tmp_path / "r"))
    assert proc.returncode == 130 and "Traceback" not in err, err[-3000:]
    assert stored >= 1
    assert err.strip().splitlines()[-1].endswith(
        f"interrupted: {stored} of 94 tasks stored; rerun the same command to resume"), err
