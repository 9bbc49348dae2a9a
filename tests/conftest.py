"""Shared test options: ``--runslow`` opts in to long runs marked ``@pytest.mark.slow``.

Tests that call SB3's ``learn`` with its default logger (curricula, the everyday script) get
``SB3_LOGDIR`` pointed at the session's temporary folder, so the suite leaves no
``SB3-<time>`` folders in the system's temporary directory (it left 14 per run).

Property-based tests (hypothesis) are deterministic by default: the same examples on every
run, so the suite never flakes on an example no earlier run drew.  ``ABB_GYM_FUZZ_SCALE=N``
(N > 1) hunts instead: N times the examples, new random ones each run (``make fuzz``).
"""
import os

import matplotlib
import pytest

matplotlib.use("Agg")

FUZZ_SCALE = max(1, int(os.environ.get("ABB_GYM_FUZZ_SCALE", "1")))
try:
    from hypothesis import settings
except ImportError:  # the property-based tests skip themselves
    pass
else:
    settings.register_profile("abb_gym", derandomize=FUZZ_SCALE == 1, database=None)
    settings.load_profile("abb_gym")


def pytest_addoption(parser):
    parser.addoption("--runslow", action="store_true", default=False,
                     help="run tests marked slow (training, sweeps)")
    parser.addoption("--runwheel", action="store_true", default=False,
                     help="run the wheel test (build, install in a fresh venv elsewhere)")


def pytest_configure(config):
    # the tests make RunUp* environments from their own code, as a user would, and know how
    # a policy must start (tests/test_user_workflows.py checks the warning itself)
    config.addinivalue_line("filterwarnings",
                            "ignore::abb_gym.envs.learning.LearningDefaultsWarning")


def pytest_collection_modifyitems(config, items):
    skip_slow = pytest.mark.skip(reason="slow: opt in with --runslow (make test-slow)")
    skip_wheel = pytest.mark.skip(reason="wheel: opt in with --runwheel (make test does)")
    for item in items:
        if "slow" in item.keywords and not config.getoption("--runslow"):
            item.add_marker(skip_slow)
        if "wheel" in item.keywords and not config.getoption("--runwheel"):
            item.add_marker(skip_wheel)


@pytest.fixture(scope="session", autouse=True)
def sb3_log_folder(tmp_path_factory):
    """SB3's default logger folder, inside this session's temporary folder (module docstring;
    subprocesses inherit it)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("SB3_LOGDIR", str(tmp_path_factory.mktemp("sb3_logs")))
        yield


@pytest.fixture
def strict_check_env():
    """Gymnasium's ``check_env`` on ``env.unwrapped`` with every warning an error, except the
    one allowed by design: check_env renders each render mode, and "human" without a display
    warns so.  Closes the environment."""
    import warnings

    from gymnasium.utils.env_checker import check_env

    def check(env):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            warnings.filterwarnings("ignore", message=".*render_mode='human' has no display here")
            check_env(env.unwrapped)
        env.close()
    return check


def train_from_mapping(data: dict, root, seed: int = 0, name: str = "run") -> int:
    """Write the config ``data`` (a zoo-style mapping) to ``root/<name>.yml`` and train it
    through ``abb-gym train`` into ``root/<name>``; returns the command's exit code."""
    import yaml
    from abb_gym.cli import main as cli_main
    path = root / f"{name}.yml"
    path.write_text(yaml.safe_dump(data))
    return cli_main(["train", "--config", str(path), "--seed", str(seed),
                     "--out", str(root / name), "--no-progress"])


@pytest.fixture(scope="session")
def train_config():
    """:func:`train_from_mapping`, for tests (and module-scoped fixtures) that train."""
    return train_from_mapping

