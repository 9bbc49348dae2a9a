"""Progress bars that count what they say and stop at their total: the baseline sweep of
``abb-gym evaluate --sweep``, the tuner (candidates, within the budget) and training.  (The
streamed rows of ``abb-gym bench speed``: tests/test_bench.py.)"""
from __future__ import annotations

import pytest
from tqdm import tqdm

from abb_gym.baselines import tuner

SCENE = "yoshida_odd"
SHORT = {"max_episode_steps": 4}  # episodes of a few control steps: the bars, not the physics


def recording_tqdm():
    """A tqdm class that keeps, per bar, its description, unit, total, every update and the
    largest count it showed."""
    class Recording(tqdm):
        bars: list[dict] = []

        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            # a disabled bar has no description (tqdm returns early)
            self.record = {"desc": getattr(self, "desc", ""), "unit": getattr(self, "unit", ""),
                           "updates": [], "most": 0}
            Recording.bars.append(self.record)

        def update(self, n=1):
            out = super().update(n)
            self.record["updates"].append(n)
            self.record["most"] = max(self.record["most"], self.n)
            return out

        def close(self):
            if not self.disable:
                self.record.update(total=self.total, n=self.n)
            super().close()

    return Recording


def test_candidates_bar_counts_candidates_not_tasks(monkeypatch):
    bar = recording_tqdm()
    monkeypatch.setattr(tuner, "ProgressBar", bar)
    rows = tuner.evaluate_candidates(SCENE, "ramp", [{}, {}, {}], episodes=1, seed=0,
                                     preset="train", per_task=2, progress=True,
                                     env_kwargs=SHORT)
    assert len(rows) == 3
    [rec] = bar.bars
    # two tasks (2 + 1 candidates); the bar counts the candidates as each task finishes
    assert rec["unit"] == "candidate" and rec["total"] == 3 and rec["n"] == 3
    assert rec["updates"] == [2, 1]


def test_tuner_stays_within_its_budget_and_its_bar_ends_at_its_total(monkeypatch):
    """budget 4 with populations of 2: the default, one generation, and one candidate of the
    next (before: the whole next generation, 5 candidates, a bar at 5/4)."""
    bar = recording_tqdm()
    monkeypatch.setattr(tuner, "ProgressBar", bar)
    result = tuner.tune(SCENE, families=("speed_dwell", "ramp"), budget=4, popsize=2,
                        episodes=1, seed=0, env_kwargs=SHORT)
    assert result["families"]["speed_dwell"]["candidates"] == 4
    assert result["families"]["ramp"]["candidates"] <= 4
    [rec] = [b for b in bar.bars if b["desc"].startswith("tune")]
    assert rec["unit"] == "candidate"
    assert rec["most"] <= rec["total"] and rec["n"] == rec["total"]
    assert rec["n"] == sum(f["candidates"] for f in result["families"].values())


def test_sweep_has_a_candidate_bar(monkeypatch):
    bar = recording_tqdm()
    monkeypatch.setattr(tuner, "ProgressBar", bar)
    rows = tuner.sweep(SCENE, families=("ramp", "speed_dwell"), n=2, episodes=1)
    assert len(rows) == 4
    [rec] = [b for b in bar.bars if b["desc"] == f"sweep {SCENE}"]
    assert rec["unit"] == "candidate" and rec["total"] == 4 and rec["n"] == 4
    assert rec["updates"] == [2, 2]


def test_sweep_without_progress_shows_no_bar(monkeypatch, capsys):
    rows = tuner.sweep(SCENE, families=("ramp",), n=2, episodes=1, progress=False)
    assert len(rows) == 2
    assert capsys.readouterr().err == ""


def tiny_training(n_timesteps: int, n_steps: int):
    """A training config of two environments and rollouts of ``n_steps`` each."""
    from abb_gym.rl.config import TrainConfig
    return TrainConfig.from_mapping("abb_gym/RunUpSpeed-v0", {
        "n_envs": 2, "n_timesteps": n_timesteps, "policy": "BoundedMlpPolicy",
        "n_steps": n_steps, "batch_size": n_steps, "n_epochs": 1,
        "policy_kwargs": {"net_arch": [8]},
        "env_kwargs": {"scene": SCENE, "preset": "train", "control_interval": 0.05},
        "eval_freq": 0, "eval_episodes": 1, "checkpoint_freq": 0})


def test_training_bar_stops_at_its_total(tmp_path, monkeypatch):
    """20 steps asked, rollouts of 2 x 8 = 16 steps: training runs 32 steps, the bar shows
    20/20 (SB3's own bar ends at 32/20)."""
    pytest.importorskip("stable_baselines3")
    import importlib

    from abb_gym.rl.train import train
    bar = recording_tqdm()
    # the module (abb_gym.rl.train is also the name of the function)
    monkeypatch.setattr(importlib.import_module("abb_gym.rl.train"), "ProgressBar", bar)
    res = train(tiny_training(20, 8), seed=0, run_dir=tmp_path / "run", progress=True,
                final_eval=False)
    assert res.env_steps == 32
    [rec] = bar.bars
    assert rec["total"] == 20 and rec["n"] == 20 and rec["most"] == 20


# ------------------------------------------------------------------ bars in a log file
def _count_to(total: int, file, **kwargs) -> str:
    from abb_gym.progress import ProgressBar
    with ProgressBar(total=total, desc="work", file=file, mininterval=0, miniters=1,
                     **kwargs) as bar:
        for _ in range(total):
            bar.update(1)
    return file.getvalue()


def test_a_bar_writes_a_few_plain_lines_when_its_output_is_not_a_terminal(monkeypatch):
    """tqdm redraws a bar ~100 times with carriage returns, one long line in a log; in a file
    the bar writes each quarter and nothing twice."""
    import io
    monkeypatch.delenv("ABB_GYM_PROGRESS", raising=False)
    text = _count_to(200, io.StringIO())
    assert "\r" not in text
    lines = text.splitlines()
    assert [line.split()[2] for line in lines] == ["50/200", "100/200", "150/200", "200/200"]
    assert all(line.startswith("work:") for line in lines)


def test_a_bar_on_a_terminal_is_tqdms_bar(monkeypatch):
    import io

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    monkeypatch.delenv("ABB_GYM_PROGRESS", raising=False)
    text = _count_to(50, Terminal())
    assert text.count("\r") > 10  # redrawn in place


def test_the_environment_variable_forces_either_form(monkeypatch):
    import io
    monkeypatch.setenv("ABB_GYM_PROGRESS", "bar")
    assert "\r" in _count_to(20, io.StringIO())
    monkeypatch.setenv("ABB_GYM_PROGRESS", "lines")
    assert "\r" not in _count_to(20, io.StringIO())


def test_a_bar_without_a_total_writes_its_end_and_a_slow_one_says_it_runs(monkeypatch):
    import io
    from abb_gym.progress import ProgressBar
    monkeypatch.delenv("ABB_GYM_PROGRESS", raising=False)
    out = io.StringIO()
    for _ in ProgressBar(iter(range(30)), desc="open", file=out, mininterval=0):
        pass
    assert [line.split()[1] for line in out.getvalue().splitlines()] == ["30"]
    # a bar silent for FIRST_LINE_AFTER seconds writes a line, then waits twice as long
    from abb_gym import progress

    class Clock:
        now = 0.0

        def monotonic(self):
            return self.now

    clock = Clock()
    monkeypatch.setattr(progress, "time", clock)
    out = io.StringIO()
    bar = ProgressBar(total=1000, desc="slow", file=out, mininterval=0)
    for now in (31.0, 60.0, 92.0, 150.0):  # lines due at 30 s, then 60 s after the last
        clock.now = now
        bar.update(1)
    bar.close()
    assert [line.split()[2] for line in out.getvalue().splitlines()] == ["1/1000", "3/1000",
                                                                         "4/1000"]


def test_every_bar_of_the_package_is_the_one_progress_bar():
    """A tqdm bar made anywhere else would write its carriage returns into logs again."""
    import re
    from pathlib import Path
    import abb_gym
    package = Path(abb_gym.__file__).parent
    own = re.compile(r"^\s*(from tqdm|import tqdm)|\btqdm\(|progress_bar=True"
                     r"|ProgressBarCallback", re.MULTILINE)
    offenders = [str(p.relative_to(package)) for p in package.rglob("*.py")
                 if p.name != "progress.py" and own.search(p.read_text())]
    assert offenders == []


def test_training_throughput_leaves_out_the_first_step_and_the_evaluations(tmp_path,
                                                                          monkeypatch):
    """The first step of training compiles the kernel when it is not cached (here: a 3 s
    sleep in its place): the printed env-steps/s leaves it out (before: steps / wall time)."""
    pytest.importorskip("stable_baselines3")
    import time

    from abb_gym.rl import vec_env
    from abb_gym.rl.train import train
    original = vec_env.NativeVecEnv.step_wait
    calls = []

    def slow_first(self):
        calls.append(1)
        if len(calls) == 1:
            time.sleep(3.0)
        return original(self)

    monkeypatch.setattr(vec_env.NativeVecEnv, "step_wait", slow_first)
    res = train(tiny_training(64, 16), seed=0, run_dir=tmp_path / "run", progress=False,
                final_eval=False)
    assert res.env_steps == 64
    # the 62 steps after the first took at most the wall time less the 3 s
    assert res.training_steps_per_s >= (64 - 2) / (res.wall_time_s - 3.0)
    assert res.env_steps_per_s < res.training_steps_per_s
