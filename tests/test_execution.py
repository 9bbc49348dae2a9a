"""Executor layer, local modes: identical results serially and on processes, per-task seeds,
stable ids, retries after a killed worker or an exception, resume after an interruption
without recomputing finished tasks, the CLI options, and the local mode of run_trials.
(The Ray modes are in test_execution_ray.py.)"""
import argparse
import multiprocessing
import os
import pickle
import signal
import socket
import subprocess
import sys
import time
import warnings
from dataclasses import dataclass

import numpy as np
import pytest

from abb_gym._threads import available_cpus
from abb_gym.analysis import Groups, stability_map
from abb_gym.execution import (Executor, MissingExtraError, ResultStore, TaskFailed, run_tasks,
                               seed_int, task_id, task_seed)
from abb_gym.execution.cli import add_executor_arguments, executor_from_args
from abb_gym.execution.errors import (RayConnectionError, RemoteTraceback, SweepInterrupted,
                                      portable_error)
from abb_gym.execution.store import STALE_TMP_AGE
from abb_gym.execution.testing import (ToyTask, count_computed, count_started,
                                       ctrl_c_after_saves, parallel_threads, running_keys,
                                       toy_task, toy_trainable)
from abb_gym.execution.tune import (choice, expand_space, grid, loguniform, randint,
                                    run_trials, uniform)

N = 24


def _expected(n=N, seed=7):
    return run_tasks(toy_task, [ToyTask(key=i, x=float(i)) for i in range(n)], workers=1,
                     seed=seed, progress=False)


def test_serial_and_processes_give_identical_results():
    """Seeds come from (root, task index), so neither the worker count nor the chunking
    changes any result; results come back in task order."""
    tasks = [ToyTask(key=i, x=float(i)) for i in range(N)]
    serial = run_tasks(toy_task, tasks, workers=1, seed=7, progress=False)
    assert len(set(serial)) == N
    for kw in (dict(workers=2), dict(workers=2, chunksize=1), dict(workers=2, chunksize=5)):
        assert run_tasks(toy_task, tasks, seed=7, progress=False, **kw) == serial
    assert run_tasks(toy_task, tasks, workers=1, seed=8, progress=False) != serial
    # unseeded: toy_task falls back to its key, again independent of the executor
    assert run_tasks(toy_task, tasks, workers=2, progress=False) == \
        run_tasks(toy_task, tasks, workers=1, progress=False)
    assert run_tasks(toy_task, [], workers=2, progress=False) == []


def test_each_worker_runs_its_share_of_the_cores():
    """Worker processes split the CPUs between them (abb_gym._threads.share_cores): on a
    2-core machine two workers run numba's parallel loops on one thread each, not two (each
    worker's idle thread would spin against the other worker)."""
    import numba
    share = max(1, min(available_cpus() // 2, numba.config.NUMBA_NUM_THREADS))
    assert set(run_tasks(parallel_threads, list(range(4)), workers=2, progress=False)) == {share}
    if available_cpus() >= 2 and numba.config.NUMBA_NUM_THREADS >= 2:
        assert share < numba.config.NUMBA_NUM_THREADS  # the test can tell the share apart
    assert run_tasks(parallel_threads, [0], workers=1, progress=False) == \
        [numba.get_num_threads()]  # in this process: unchanged


def test_stability_map_identical_on_executor_and_workers():
    g = Groups(eta=0.4, delta=10)
    kw = dict(n_balls=(3, 2), n_members=5, progress=False)
    axes = (("zeta", [0.05, 0.2]), ("Omega", [1.2, 1.8, 2.1]))
    a = stability_map(g, *axes, workers=1, **kw)
    b = stability_map(g, *axes, executor=Executor(workers=2, chunksize=2), **kw)
    for n in (3, 2):
        for f in ("exists", "union_stable", "all_stable", "fraction_stable", "best", "worst"):
            assert np.array_equal(a.field(n, f), b.field(n, f), equal_nan=True)
    with pytest.raises(ValueError, match="through the executor"):
        stability_map(g, *axes, workers=2, executor=Executor(), **kw)


def test_seeds_are_per_task_and_match_spawn():
    children = np.random.SeedSequence(5).spawn(4)
    for i, c in enumerate(children):
        assert np.array_equal(task_seed(5, i).generate_state(4), c.generate_state(4))
    assert seed_int(task_seed(5, 1)) == seed_int(task_seed(5, 1)) != seed_int(task_seed(5, 2))
    with pytest.raises(ValueError, match="seed must be an integer >= 0"):
        task_seed(-1, 0)
    with pytest.raises(ValueError, match="index"):
        task_seed(1, -2)


@dataclass(frozen=True)
class _Spec:
    a: float
    b: tuple


def test_task_ids_are_stable_and_faithful():
    t = {"scene": Groups(eta=0.4), "omega": 1.5, "arr": np.arange(3.0), "tag": "x"}
    same = {"tag": "x", "arr": np.arange(3.0), "omega": np.float64(1.5),
            "scene": Groups(eta=0.4)}
    assert task_id(toy_task, t) == task_id(toy_task, same)        # key order, numpy scalars
    assert len(task_id(toy_task, t)) == 32
    different = [dict(t, omega=1.5000000000000002), dict(t, arr=np.arange(3)),
                 dict(t, scene=Groups(eta=0.41)), dict(t, tag="y")]
    ids = {task_id(toy_task, d) for d in different} | {task_id(toy_task, t)}
    assert len(ids) == 5
    assert task_id(toy_task, 1) != task_id(toy_task, 1.0) != task_id(toy_task, True)
    assert task_id(toy_task, _Spec(1.0, (2,))) != task_id(toy_trainable, _Spec(1.0, (2,)))
    assert task_id(toy_task, t, task_seed(1, 0)) != task_id(toy_task, t, task_seed(1, 1))
    # the id does not depend on the process (hash randomisation): compute it in a child
    code = ("from abb_gym.execution import task_id; from abb_gym.execution.testing import "
            "toy_task, ToyTask; print(task_id(toy_task, {'s': {'b', 'a'}, 't': ToyTask(3)}))")
    env = dict(os.environ, PYTHONHASHSEED="123")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, check=True).stdout.strip()
    assert out == task_id(toy_task, {"s": {"a", "b"}, "t": ToyTask(3)})


def test_store_is_atomic_and_ignores_unreadable_files(tmp_path):
    st = ResultStore(tmp_path / "s")
    tid = "0123456789abcdef0123456789abcdef"
    assert st.load(tid) == (False, None) and len(st) == 0
    st.save(tid, {"v": 1})
    assert st.load(tid) == (True, {"v": 1}) and list(st.ids()) == [tid]
    assert not list((tmp_path / "s").glob(".*.tmp"))              # no temporary file left
    (tmp_path / "s" / f"{tid}.npz").write_bytes(b"PK\x03\x04truncated")
    with pytest.warns(RuntimeWarning, match=f"unreadable result file .*{tid}.npz"):
        assert st.load(tid) == (False, None)                      # recomputed, not an error
    with pytest.raises(ValueError, match="task id"):
        st.save("../evil", 1)
    st.clear()
    assert len(st) == 0


class _Payload:
    """Unpickling this creates the file ``path``: what planted code would do first."""

    def __init__(self, path):
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


def test_a_planted_result_file_runs_no_code(tmp_path):
    """Task ids are predictable (a hash of the task function and spec), so anyone who can
    write the resume folder can plant a file under the id of the next task: as a pickle in
    the name an older abb-gym read (``<id>.pkl``), or inside the archive this one reads (an
    object array, which NumPy would unpickle).  Neither runs, and every task is computed."""
    tasks = [ToyTask(key=i, x=float(i), marker_dir=str(tmp_path / "m")) for i in range(4)]
    (tmp_path / "m").mkdir()
    ids, store, marker = _ids(tasks), tmp_path / "store", tmp_path / "created_by_the_payload"
    store.mkdir()
    (store / f"{ids[0]}.pkl").write_bytes(pickle.dumps(
        {"format": 1, "task_id": ids[0], "result": _Payload(marker)}))
    payload = np.empty(1, dtype=object)
    payload[0] = _Payload(marker)
    with open(store / f"{ids[1]}.npz", "wb") as fh:
        np.savez(fh, record=np.frombuffer(b'{"format": 2}', dtype=np.uint8), a0=payload)
    with warnings.catch_warnings(record=True) as warned:
        warnings.simplefilter("always")
        out = run_tasks(toy_task, tasks, workers=1, seed=7, store=store, progress=False)
    assert not marker.exists(), "a planted result file ran its code"
    assert out == _expected(4) and count_computed(tmp_path / "m") == {i: 1 for i in range(4)}
    text = " ".join(str(w.message) for w in warned)
    assert "older abb-gym" in text and f"{ids[1]}.npz" in text


def _ids(tasks, seed=7):
    return [task_id(toy_task, t, task_seed(seed, i)) for i, t in enumerate(tasks)]


def test_damaged_store_is_named_or_healed(tmp_path):
    """A tampered result file is recomputed with a warning naming it (and rewritten); a
    directory in place of a result file is a ValueError naming it, before anything runs; a
    temporary file a killed run left behind is never read and, once stale, deleted."""
    tasks = [ToyTask(key=i, x=float(i), marker_dir=str(tmp_path)) for i in range(6)]
    ids, store = _ids(tasks), tmp_path / "store"
    run_tasks(toy_task, tasks, workers=1, seed=7, store=store, progress=False)
    tampered = store / f"{ids[2]}.npz"
    tampered.write_text("Every result in this store is wrong\n")
    with pytest.warns(RuntimeWarning, match=f"unreadable result file .*{tampered.name}"):
        out = run_tasks(toy_task, tasks, workers=1, seed=7, store=store, progress=False)
    assert out == _expected(6) and count_computed(tmp_path)[2] == 2
    assert ResultStore(store).load(ids[2]) == (True, out[2])     # healed

    (store / f"{ids[4]}.npz").unlink()
    (store / f"{ids[4]}.npz").mkdir()
    with pytest.raises(ValueError, match=f"{ids[4]}.npz' is a directory"):
        run_tasks(toy_task, tasks, workers=2, seed=7, store=store, progress=False)
    assert count_started(tmp_path)[4] == 1                       # failed before running
    assert ids[4] not in set(ResultStore(store).ids())
    (store / f"{ids[4]}.npz").rmdir()

    # leftovers of a run killed mid-write: full records, but not results
    (store / f"{ids[4]}.npz").unlink(missing_ok=True)
    ResultStore(tmp_path / "other").save(ids[4], -1.0, "abb_gym.execution.testing:toy_task")
    record = (tmp_path / "other" / f"{ids[4]}.npz").read_bytes()
    stale, fresh = store / f".{ids[4]}.old.tmp", store / f".{ids[4]}.new.tmp"
    stale.write_bytes(record)
    fresh.write_bytes(record)
    old = time.time() - STALE_TMP_AGE - 60
    os.utime(stale, (old, old))
    assert ids[4] not in set(ResultStore(store).ids())
    assert run_tasks(toy_task, tasks, workers=1, seed=7, store=store, progress=False) == \
        _expected(6)
    assert not stale.exists() and fresh.exists()        # a fresh one may be another run's


def test_input_errors_are_not_retried_and_reach_the_caller(tmp_path):
    """ValueError and TypeError (bad input, e.g. an unknown scene name) stop the sweep at their
    first occurrence and reach the caller unchanged; nothing runs on after the call."""
    cases = [(ValueError, -1, "negative dimensions are not allowed"),
             (TypeError, "x", "cannot be interpreted as an integer")]
    for k, (kind, n, message) in enumerate(cases):
        for kw in (dict(workers=1), dict(workers=2, chunksize=1), dict(workers=2, chunksize=4)):
            d = tmp_path / f"{k}-{kw['workers']}-{kw.get('chunksize')}"
            d.mkdir()
            tasks = [ToyTask(key=i, x=float(i), marker_dir=str(d), sleep=0.02,
                             n=n if i == 9 else 16) for i in range(N)]
            with pytest.raises(kind, match=message) as err:
                run_tasks(toy_task, tasks, seed=7, store=d / "store", progress=False, **kw)
            assert type(err.value) is kind
            assert count_started(d)[9] == 1                   # no retry (retries=2)
            assert running_keys(d) == set() and multiprocessing.active_children() == []
            assert any("task 9" in note for note in err.value.__notes__)
            if kw["workers"] > 1:
                assert isinstance(err.value.__cause__, RemoteTraceback)
                assert message in str(err.value.__cause__)
            stored = set(ResultStore(d / "store").ids())
            assert stored <= {t for i, t in enumerate(_ids(tasks)) if count_computed(d).get(i)}


class _PickyError(ValueError):
    def __init__(self, field, value):
        super().__init__(f"{field} must be positive (got {value})")


def test_an_input_error_that_does_not_unpickle_still_arrives():
    back = pickle.loads(pickle.dumps(portable_error(_PickyError("mass", -1))))
    assert type(back) is ValueError and str(back) == "_PickyError: mass must be positive (got -1)"
    keeps = pickle.loads(pickle.dumps(portable_error(ValueError("x"))))
    assert type(keeps) is ValueError and str(keeps) == "x"


def test_ctrl_c_stops_the_sweep_says_how_to_resume_and_resumes(tmp_path):
    for kw in (dict(workers=1), dict(workers=2, chunksize=1), dict(workers=2, chunksize=3)):
        d = tmp_path / f"{kw['workers']}-{kw.get('chunksize')}"
        d.mkdir()
        tasks = [ToyTask(key=i, x=float(i), marker_dir=str(d), sleep=0.02) for i in range(N)]
        with ctrl_c_after_saves(5):
            with pytest.raises(KeyboardInterrupt) as err:
                run_tasks(toy_task, tasks, seed=7, store=d / "store", progress=False, **kw)
        assert isinstance(err.value, SweepInterrupted)
        assert (err.value.done, err.value.total, err.value.store) == (5, N, d / "store")
        assert str(err.value) == (f"interrupted; 5 of {N} tasks finished; rerun the same "
                                  f"command with --resume-dir {d / 'store'} to continue")
        assert running_keys(d) == set() and multiprocessing.active_children() == []
        finished = set(ResultStore(d / "store").ids())
        assert len(finished) == 5
        before = {p.name for p in d.glob("computed-*")}
        assert run_tasks(toy_task, tasks, seed=7, store=d / "store", progress=False,
                         **kw) == _expected()
        rerun = sorted(int(p.split("-")[1])
                       for p in {p.name for p in d.glob("computed-*")} - before)
        assert rerun == [i for i, t in enumerate(_ids(tasks)) if t not in finished]
    assert "nothing was kept" in str(SweepInterrupted(3, 8, None))


def test_killed_worker_and_exception_are_retried_nothing_lost_or_double(tmp_path):
    """Three tasks SIGKILL their worker once and one raises once: each is retried, the
    other tasks of the crashed chunks are not recomputed, every result arrives exactly once."""
    crash, boom = {3, 11, 17}, {5}
    tasks = [ToyTask(key=i, x=float(i), marker_dir=str(tmp_path), crash_once=i in crash,
                     raise_once=i in boom) for i in range(N)]
    store = tmp_path / "store"
    out = run_tasks(toy_task, tasks, workers=2, chunksize=3, seed=7, store=store,
                    progress=False)
    assert out == _expected()
    assert count_computed(tmp_path) == {i: 1 for i in range(N)}
    assert {int(p.name.split("-")[1]) for p in tmp_path.glob("crashed-*")} == crash
    assert (tmp_path / "raised-5").exists()
    assert len(ResultStore(store)) == N


def test_retries_exhausted_raise_task_failed_and_keep_finished_results(tmp_path):
    tasks = [ToyTask(key=i, x=float(i), marker_dir=str(tmp_path), crash_once=(i == 9))
             for i in range(N)]
    with pytest.raises(TaskFailed, match="killed by signal 9") as err:
        run_tasks(toy_task, tasks, workers=2, chunksize=1, seed=7, retries=0,
                  store=tmp_path / "store", progress=False)
    assert err.value.index == 9 and err.value.attempts == 1
    store = ResultStore(tmp_path / "store")
    finished = set(store.ids())
    assert len(finished) >= 1
    # the rerun resumes: finished tasks are loaded, the rest (task 9 now passes) computed
    before = {p.name for p in tmp_path.glob("computed-*")}
    out = run_tasks(toy_task, tasks, workers=2, chunksize=1, seed=7, retries=0,
                    store=store.directory, progress=False)
    assert out == _expected()
    rerun = sorted(int(p.split("-")[1])
                   for p in {p.name for p in tmp_path.glob("computed-*")} - before)
    ids = [task_id(toy_task, t, task_seed(7, i)) for i, t in enumerate(tasks)]
    assert rerun == [i for i in range(N) if ids[i] not in finished]
    with pytest.raises(TaskFailed, match="injected failure"):
        run_tasks(toy_task, [ToyTask(key=0, marker_dir=str(tmp_path), raise_once=True)],
                  workers=1, retries=0, progress=False)


_DRIVER = """
import sys
from abb_gym.execution import run_tasks
from abb_gym.execution.testing import ToyTask, toy_task
d = sys.argv[1]
tasks = [ToyTask(key=i, x=float(i), marker_dir=d, sleep=0.1) for i in range(%d)]
run_tasks(toy_task, tasks, workers=2, chunksize=1, seed=7, store=d + "/store", progress=False)
""" % N


def test_resume_after_killed_driver_does_not_recompute_finished_tasks(tmp_path):
    """The whole sweep (driver and workers) is SIGKILLed mid-way; the rerun computes exactly
    the tasks whose results were not on disk, and the final results are complete."""
    proc = subprocess.Popen([sys.executable, "-c", _DRIVER, str(tmp_path)],
                            start_new_session=True, stderr=subprocess.PIPE)
    store = ResultStore(tmp_path / "store")
    t0 = time.monotonic()
    while len(store) < 6 and time.monotonic() - t0 < 60 and proc.poll() is None:
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)          # driver and its workers, as a power cut
    proc.wait()
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read().decode()
    finished = set(store.ids())
    assert 6 <= len(finished) < N
    before = {p.name for p in tmp_path.glob("computed-*")}
    tasks = [ToyTask(key=i, x=float(i), marker_dir=str(tmp_path), sleep=0.1) for i in range(N)]
    out = run_tasks(toy_task, tasks, workers=2, chunksize=1, seed=7, store=store.directory,
                    progress=False)
    assert out == _expected()
    rerun = [int(p.split("-")[1]) for p in {p.name for p in tmp_path.glob("computed-*")} - before]
    ids = [task_id(toy_task, t, task_seed(7, i)) for i, t in enumerate(tasks)]
    assert sorted(rerun) == [i for i in range(N) if ids[i] not in finished]
    assert len(store) == N


def test_stability_map_resumes_from_store(tmp_path, monkeypatch):
    g = Groups(eta=0.4, delta=10)
    axes = (("zeta", [0.05, 0.2]), ("Omega", [1.2, 2.1]))
    ex = Executor(workers=1, store=tmp_path, progress=False)
    a = stability_map(g, *axes, n_balls=(3,), n_members=5, executor=ex)
    assert len(ResultStore(tmp_path)) == 4

    def no_compute(*args, **kw):
        raise AssertionError("a stored point was recomputed")
    monkeypatch.setattr("abb_gym.analysis.maps.family_stability", no_compute)
    b = stability_map(g, *axes, n_balls=(3,), n_members=5, executor=ex)
    assert np.array_equal(a.field(3, "best"), b.field(3, "best"))


def test_duplicate_tasks_run_once(tmp_path):
    t = ToyTask(key=1, x=1.0, marker_dir=str(tmp_path))
    out = run_tasks(toy_task, [t, t, t], workers=2, progress=False)
    assert out[0] == out[1] == out[2] and count_computed(tmp_path) == {1: 1}


def test_executor_validation_and_description():
    for bad in (dict(workers=0), dict(workers=1.5), dict(retries=-1), dict(chunksize=0),
                dict(ray_address=""), dict(ray_options=[1]), dict(start_method="teleport")):
        with pytest.raises(ValueError, match=next(iter(bad))):
            Executor(**bad)
    assert Executor(workers=1).mode == "serial"
    assert Executor(workers=3).mode == "processes"
    ex = Executor(ray_address="auto", store="out/x")
    assert ex.ray and ex.mode == "ray"
    assert ex.describe() == "Ray cluster at auto, results in out/x"
    with pytest.raises(ValueError, match="task_ids"):
        run_tasks(toy_task, [ToyTask(1)], task_ids=["a", "b"], workers=1, progress=False)
    with pytest.raises(ValueError, match="stable name"):
        run_tasks(lambda t: t, [1], store="unused", workers=1, progress=False)


def test_script_functions_and_start_methods():
    """A lambda runs on processes (it travels as a cloudpickle), with every start method."""
    for method in (None, "fork", "spawn"):
        assert run_tasks(lambda x: x * x, range(5), workers=2, start_method=method,
                         progress=False) == [0, 1, 4, 9, 16]


def _parse(argv):
    p = argparse.ArgumentParser()
    add_executor_arguments(p)
    return p.parse_args(argv)


def test_cli_options(tmp_path, capsys):
    ex = executor_from_args(_parse(["--workers", "3", "--resume-dir", str(tmp_path),
                                    "--retries", "0"]), progress=False)
    assert ex == Executor(workers=3, store=str(tmp_path), retries=0, progress=False)
    assert executor_from_args(_parse([])) == Executor()
    for argv in (["--workers", "0"], ["--retries", "-1"], ["--workers", "x"]):
        with pytest.raises(SystemExit):
            _parse(argv)
    assert "must be an integer >= 1" in capsys.readouterr().err


def test_missing_ray_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)       # import ray -> ImportError
    with pytest.raises(MissingExtraError, match=r"abb-gym\[cluster\]"):
        executor_from_args(_parse(["--ray"]))
    with pytest.raises(ValueError, match=r"abb-gym\[cluster\]"):   # one line in the CLI
        run_tasks(toy_task, [ToyTask(1)], ray=True, progress=False)
    from abb_gym.cli import main
    assert main(["stability-map", "--nx", "1", "--ny", "1", "--ray", "--no-progress"]) == 2


@pytest.fixture
def no_ray_cluster(monkeypatch) -> int:
    """A fresh process's view of Ray with ``RAY_ADDRESS`` naming a port nobody listens on
    (where ``auto`` then looks); the port."""
    ray = pytest.importorskip("ray")
    monkeypatch.setattr(ray, "is_initialized", lambda: False)   # as in a fresh process
    with socket.socket() as s:                                  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    monkeypatch.setenv("RAY_ADDRESS", f"127.0.0.1:{port}")      # where "auto" then looks
    return port


def test_ray_address_without_cluster_is_one_clear_line(no_ray_cluster, capsys):
    """No cluster at the address: a ValueError of one line saying how to start one, at once
    (Ray alone would retry for 30 s to minutes), and exit status 2 from ``abb-gym``."""
    port = no_ray_cluster
    for address in ("auto", f"127.0.0.1:{port}", f"ray://127.0.0.1:{port}"):
        with pytest.raises(RayConnectionError) as err:
            run_tasks(toy_task, [ToyTask(1)], ray_address=address, progress=False)
        text = str(err.value)
        assert isinstance(err.value, ValueError) and "\n" not in text
        assert text.startswith(f"no Ray cluster found at {address!r}")
        assert "ray start --head" in text and "--ray " in text and str(port) in text
    with pytest.raises(RayConnectionError, match=f"127.0.0.1:{port}"):     # --ray, RAY_ADDRESS
        run_tasks(toy_task, [ToyTask(1)], ray=True, progress=False)
    from abb_gym.cli import main
    argv = ["stability-map", "--nx", "1", "--ny", "1", "--ray-address", "auto", "--no-progress"]
    assert main(argv) == 2
    err_lines = capsys.readouterr().err.strip().splitlines()
    assert len(err_lines) == 1 and "no Ray cluster found at 'auto'" in err_lines[0]


def test_no_progress_bar_before_the_ray_backend_is_up(no_ray_cluster, capsys, tmp_path):
    """``stability-map --ray-address auto`` without a cluster: its one error line, and no
    progress bar drawn before it (the bar starts once the backend is connected)."""
    from abb_gym.cli import main
    assert main(["stability-map", "--nx", "2", "--ny", "2", "--ray-address", "auto",
                 "--out", str(tmp_path / "map")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "stability map" not in err and "%" not in err, err
    assert err.startswith("abb-gym stability-map: error: no Ray cluster found at 'auto'")


def test_cli_stability_map_resume_dir(tmp_path):
    from abb_gym.cli import main
    argv = ["stability-map", "--x", "zeta", "--x-range", "0.05", "0.2", "--nx", "2",
            "--y", "Omega", "--y-range", "1.2", "2.0", "--ny", "2", "--members", "5",
            "--balls", "3", "--no-progress", "--workers", "2",
            "--resume-dir", str(tmp_path / "resume")]
    assert main(argv + ["--out", str(tmp_path / "a")]) == 0
    assert len(ResultStore(tmp_path / "resume")) == 4
    assert main(argv + ["--out", str(tmp_path / "b"), "--workers", "1"]) == 0
    assert (tmp_path / "a.csv").read_text() == (tmp_path / "b.csv").read_text()


def test_search_space_expansion():
    space = {"lr": loguniform(1e-4, 1e-2), "gamma": grid([0.9, 0.99]), "seed": grid([0, 1, 2]),
             "net": {"width": choice([32, 64]), "depth": randint(1, 4)}, "u": uniform(0, 1),
             "fixed": "x"}
    a = expand_space(space, num_samples=2, seed=3)
    assert len(a) == 12 and a == expand_space(space, num_samples=2, seed=3)
    assert [(c["gamma"], c["seed"]) for c in a[:6]] == [(0.9, 0), (0.9, 1), (0.9, 2),
                                                         (0.99, 0), (0.99, 1), (0.99, 2)]
    assert all(1e-4 <= c["lr"] < 1e-2 and c["net"]["width"] in (32, 64)
               and 1 <= c["net"]["depth"] < 4 and c["fixed"] == "x" for c in a)
    assert len({c["lr"] for c in a}) == 12                      # drawn anew per trial
    assert expand_space(space, 2, seed=4) != a
    for bad, match in ((lambda: loguniform(0, 1), "low > 0"), (lambda: grid([]), "at least"),
                       (lambda: expand_space(space, 0), "num_samples"),
                       (lambda: uniform(1, 1), "low < high")):
        with pytest.raises(ValueError, match=match):
            bad()


def test_run_trials_locally_with_resume(tmp_path):
    space = {"lr": loguniform(1e-5, 1e-1), "seed": grid([0, 1]), "marker_dir": str(tmp_path)}
    ex = Executor(workers=2, store=tmp_path / "store", progress=False)
    trials = run_trials(toy_trainable, space, num_samples=2, seed=4, executor=ex,
                        metric="score")
    assert [t.index for t in trials] == [0, 1, 2, 3]
    assert [t.config["seed"] for t in trials] == [0, 1, 0, 1]
    assert all(t.metrics["lr"] == t.config["lr"] for t in trials)
    best = trials.best()
    assert best.metrics["score"] == max(t.metrics["score"] for t in trials)
    assert trials.best(mode="min").metrics["score"] == min(t.metrics["score"] for t in trials)
    serial = run_trials(toy_trainable, space, num_samples=2, seed=4,
                        executor=Executor(workers=1, progress=False))
    assert [t.metrics for t in serial] == [t.metrics for t in trials]
    assert sum(count_computed(tmp_path).values()) == 8
    again = run_trials(toy_trainable, space, num_samples=2, seed=4, executor=ex)
    assert [t.metrics for t in again] == [t.metrics for t in trials]
    assert sum(count_computed(tmp_path).values()) == 8           # all four loaded, none rerun
