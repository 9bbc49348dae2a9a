"""Executor layer on a local Ray instance started by this module with 2 CPUs: the same sweep
gives identical results locally and on Ray, a killed Ray worker is retried with nothing lost or
counted twice, a sweep stopped by a failed task, an input error or Ctrl-C leaves nothing running
and resumes at once, in the same session, without recomputing finished tasks, run_trials gives
the same trials on Ray Tune as locally, and ``abb-gym stability-map --ray`` matches
``--workers 1``.  Skipped only when Ray is not installed (``pip install 'abb-gym[cluster]'``).

No assertion depends on timing: the order in which Ray runs tasks, and how far a sweep got when
it stopped, may vary; the assertions hold for every order."""
import numpy as np
import pytest

ray = pytest.importorskip(
    "ray", reason="Ray is not installed: pip install 'abb-gym[cluster]' to run the Ray tests")

from abb_gym.analysis import Groups, stability_map  # noqa: E402
from abb_gym.execution import (Executor, ResultStore, TaskFailed, run_tasks,  # noqa: E402
                               task_id, task_seed)
from abb_gym.execution import ray_backend  # noqa: E402
from abb_gym.execution.errors import RemoteTraceback, SweepInterrupted  # noqa: E402
from abb_gym.execution.testing import (ToyTask, count_computed, count_started,  # noqa: E402
                                       ctrl_c_after_saves, parallel_threads, running_keys,
                                       toy_task, toy_trainable)
from abb_gym.execution.tune import grid, loguniform, run_trials  # noqa: E402

N = 24


@pytest.fixture(scope="module", autouse=True)
def ray_instance():
    if ray.is_initialized():
        ray.shutdown()
    # a small object store: these tests move kilobytes, and the machine is shared
    # address="local": a new instance even if RAY_ADDRESS or a `ray start` cluster exists
    ray.init(address="local", num_cpus=2, include_dashboard=False,
             object_store_memory=100 * 2**20)
    yield
    ray.shutdown()


def _tasks(tmp_path=None, **flags):
    return [ToyTask(key=i, x=float(i), marker_dir=None if tmp_path is None else str(tmp_path),
                    **{k: i in v for k, v in flags.items()}) for i in range(N)]


def test_same_sweep_identical_locally_and_on_ray():
    tasks = _tasks()
    local = run_tasks(toy_task, tasks, workers=2, seed=7, progress=False)
    assert run_tasks(toy_task, tasks, workers=1, seed=7, progress=False) == local
    assert run_tasks(toy_task, tasks, ray=True, seed=7, progress=False) == local
    assert run_tasks(toy_task, tasks, ray=True, seed=7, chunksize=5, workers=1,
                     progress=False) == local


def test_ray_tasks_run_on_their_cpus():
    """A Ray task's parallel loops use the task's CPUs (one by default, two when asked),
    not every core of the node (abb_gym._threads.share_cores)."""
    assert set(run_tasks(parallel_threads, list(range(4)), ray=True, progress=False)) == {1}
    import numba
    if numba.config.NUMBA_NUM_THREADS >= 2:
        assert set(run_tasks(parallel_threads, [0, 1], ray=True, ray_options={"num_cpus": 2},
                             progress=False)) == {2}


def test_stability_map_identical_locally_and_on_ray():
    g = Groups(eta=0.4, delta=10)
    kw = dict(n_balls=(3, 2), n_members=5, progress=False)
    axes = (("zeta", [0.05, 0.1, 0.2]), ("Omega", [1.2, 1.5, 1.8, 2.1]))
    a = stability_map(g, *axes, workers=2, **kw)
    b = stability_map(g, *axes, executor=Executor(ray=True), **kw)
    for n in (3, 2):
        for f in ("exists", "union_stable", "all_stable", "fraction_stable", "best", "worst"):
            assert np.array_equal(a.field(n, f), b.field(n, f), equal_nan=True)


def test_killed_ray_worker_is_retried_nothing_lost_or_double(tmp_path):
    crash, boom = {2, 13}, {6}
    tasks = _tasks(tmp_path, crash_once=crash, raise_once=boom)
    out = run_tasks(toy_task, tasks, ray=True, chunksize=1, seed=7, store=tmp_path / "s",
                    progress=False)
    assert out == run_tasks(toy_task, _tasks(), workers=1, seed=7, progress=False)
    assert count_computed(tmp_path) == {i: 1 for i in range(N)}
    assert {int(p.name.split("-")[1]) for p in tmp_path.glob("crashed-*")} == crash
    assert len(ResultStore(tmp_path / "s")) == N


def _resumes_exactly(tmp_path, tasks, store, **kw):
    """Rerun at once in the same Ray session, without retries (a worker killed by the stopped
    sweep would fail it): the rerun computes exactly the tasks that were not stored."""
    finished = set(store.ids())
    before = {p.name for p in tmp_path.glob("computed-*")}
    out = run_tasks(toy_task, tasks, ray=True, chunksize=1, seed=7, retries=0,
                    store=store.directory, progress=False, **kw)
    assert out == run_tasks(toy_task, _tasks(), workers=1, seed=7, progress=False)
    rerun = sorted(int(p.split("-")[1])
                   for p in {p.name for p in tmp_path.glob("computed-*")} - before)
    ids = [task_id(toy_task, t, task_seed(7, i)) for i, t in enumerate(tasks)]
    assert rerun == [i for i in range(N) if ids[i] not in finished]


def test_interrupted_ray_sweep_resumes_without_recomputing(tmp_path):
    """Task 15 fails with no retries left, which stops the sweep; the tasks in flight have
    ended by the time TaskFailed arrives; the rerun (task 15 now passes) computes exactly the
    tasks whose results were not stored."""
    tasks = _tasks(tmp_path, raise_once={15})
    store = ResultStore(tmp_path / "s")
    with pytest.raises(TaskFailed, match="injected failure"):
        run_tasks(toy_task, tasks, ray=True, workers=2, chunksize=1, seed=7, retries=0,
                  store=store.directory, progress=False)
    assert running_keys(tmp_path) == set()
    assert 0 < len(store) < N
    _resumes_exactly(tmp_path, tasks, store)


def test_ray_input_error_is_not_retried_and_reaches_the_caller(tmp_path):
    tasks = [ToyTask(key=i, x=float(i), marker_dir=str(tmp_path), n=-1 if i == 9 else 16)
             for i in range(N)]
    with pytest.raises(ValueError, match="negative dimensions are not allowed") as err:
        run_tasks(toy_task, tasks, ray=True, workers=2, chunksize=2, seed=7,
                  store=tmp_path / "s", progress=False)
    assert type(err.value) is ValueError and count_started(tmp_path)[9] == 1
    assert isinstance(err.value.__cause__, RemoteTraceback)
    assert running_keys(tmp_path) == set()


def test_ctrl_c_stops_a_ray_sweep_which_resumes_at_once(tmp_path):
    """The chunks in flight at Ctrl-C finish (their results are stored) or are cancelled
    before SweepInterrupted arrives; the rerun, at once, computes exactly the rest."""
    tasks = [ToyTask(key=i, x=float(i), marker_dir=str(tmp_path), sleep=0.05) for i in range(N)]
    store = ResultStore(tmp_path / "s")
    with ctrl_c_after_saves(5):
        with pytest.raises(SweepInterrupted) as err:
            run_tasks(toy_task, tasks, ray=True, chunksize=1, seed=7, store=store.directory,
                      progress=False)
    assert running_keys(tmp_path) == set()
    assert 5 <= err.value.done == len(store) < N and err.value.total == N
    _resumes_exactly(tmp_path, tasks, store)


def test_a_task_deaf_to_cancellation_is_killed_and_the_next_sweep_unharmed(tmp_path,
                                                                          monkeypatch):
    """Task 1 sleeps in one long call, where the KeyboardInterrupt of a cancellation cannot
    reach it, so its worker is killed after the grace period; the sweep started right after
    must not pay for that death (it runs without retries)."""
    monkeypatch.setattr(ray_backend, "CANCEL_GRACE", 0.3)
    monkeypatch.setattr(ray_backend, "_our_kills", [])
    tasks = [ToyTask(key=i, x=float(i), marker_dir=str(tmp_path), raise_once=i == 0,
                     sleep=2.0 if i == 1 else 0.0) for i in range(N)]
    store = ResultStore(tmp_path / "s")
    with pytest.raises(TaskFailed, match="injected failure"):
        run_tasks(toy_task, tasks, ray=True, workers=2, chunksize=1, seed=7, retries=0,
                  store=store.directory, progress=False)
    _resumes_exactly(tmp_path, tasks, store)


def test_run_trials_on_ray_tune_matches_local_and_resumes(tmp_path):
    space = {"lr": loguniform(1e-5, 1e-1), "seed": grid([0, 1]), "marker_dir": str(tmp_path)}
    local = run_trials(toy_trainable, space, seed=4, executor=Executor(workers=1,
                                                                       progress=False))
    ex = Executor(ray=True, store=tmp_path / "store", progress=False)
    tuned = run_trials(toy_trainable, space, seed=4, executor=ex, metric="score",
                       storage_path=tmp_path / "tune")
    assert [t.metrics for t in tuned] == [t.metrics for t in local]
    assert [t.config for t in tuned] == [t.config for t in local]
    assert sum(count_computed(tmp_path).values()) == 4
    again = run_trials(toy_trainable, space, seed=4, executor=ex, metric="score")
    assert [t.metrics for t in again] == [t.metrics for t in local]
    assert sum(count_computed(tmp_path).values()) == 4           # resumed: nothing rerun


def test_cli_stability_map_on_ray_matches_local(tmp_path):
    from abb_gym.cli import main
    argv = ["stability-map", "--x", "zeta", "--x-range", "0.05", "0.2", "--nx", "3",
            "--y", "Omega", "--y-range", "1.2", "2.0", "--ny", "2", "--members", "5",
            "--no-progress"]
    assert main(argv + ["--workers", "1", "--out", str(tmp_path / "local")]) == 0
    assert main(argv + ["--ray", "--out", str(tmp_path / "ray")]) == 0
    assert (tmp_path / "local.csv").read_text() == (tmp_path / "ray.csv").read_text()


@pytest.mark.slow
def test_ray_tune_retries_a_crashed_trial(tmp_path):
    """Each trial's first run kills its Ray actor; Tune's FailureConfig restarts it and the
    results still match the local run (slow: every restart costs a new actor)."""
    space = {"lr": loguniform(1e-5, 1e-1), "seed": grid([0, 1]), "marker_dir": str(tmp_path)}
    local = run_trials(toy_trainable, space, seed=4, executor=Executor(workers=1,
                                                                       progress=False))
    tuned = run_trials(toy_trainable, dict(space, crash_once=True), seed=4,
                       executor=Executor(ray=True, progress=False),
                       storage_path=tmp_path / "tune")
    assert [t.metrics for t in tuned] == [t.metrics for t in local]
    assert len(list(tmp_path.glob("crashed-*"))) == 2


def test_a_ray_instance_of_ray_true_listens_on_the_loopback_interface_only():
    """``--ray`` starts a throw-away instance: none of its processes (GCS, raylet, workers,
    agents, the driver's core worker) may accept connections from the network."""
    import json
    import subprocess
    import sys
    import textwrap
    code = textwrap.dedent("""
        import json, os
        from abb_gym.execution.ray_backend import ensure_ray
        ray = ensure_ray(None, 1)
        assert ray.get(ray.remote(lambda: 7).remote()) == 7  # the instance works
        import psutil  # Ray's own copy (ray/thirdparty_files), on the path once ray is imported
        ours = {p.pid for p in psutil.Process().children(recursive=True)} | {os.getpid()}
        listening = sorted({(c.laddr.ip, psutil.Process(c.pid).name())
                            for c in psutil.net_connections(kind="inet")
                            if c.status == psutil.CONN_LISTEN and c.pid in ours})
        ray.shutdown()
        print(json.dumps(listening))
    """)
    env = {k: v for k, v in __import__("os").environ.items() if k != "RAY_ADDRESS"}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    listening = json.loads(proc.stdout.strip().splitlines()[-1])
    assert listening, "no listening socket found: the check would pass on nothing"
    loopback = ("127.0.0.1", "::1", "::ffff:127.0.0.1")
    assert [s for s in listening if s[0] not in loopback] == [], listening
