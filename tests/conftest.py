"""Shared test options: ``--runslow`` opts in to long runs marked ``@pytest.mark.slow``."""
import matplotlib
import pytest

matplotlib.use("Agg")


def pytest_addoption(parser):
    parser.addoption("--runslow", action="store_true", default=False,
                     help="run tests marked slow (training, sweeps)")
    parser.addoption("--runwheel", action="store_true", default=False,
                     help="run the wheel test (build, install in a fresh venv elsewhere)")


def pytest_collection_modifyitems(config, items):
    skip_slow = pytest.mark.skip(reason="slow: opt in with --runslow (make test-slow)")
    skip_wheel = pytest.mark.skip(reason="wheel: opt in with --runwheel (make test does)")
    for item in items:
        if "slow" in item.keywords and not config.getoption("--runslow"):
            item.add_marker(skip_slow)
        if "wheel" in item.keywords and not config.getoption("--runwheel"):
            item.add_marker(skip_wheel)


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
