"""The block-size benchmark (benchmarks.block_size): each environment gets the block size it
asked for, the global is restored, and bad input is refused by name."""
import pytest

from abb_gym.benchmarks import block_size as bs
from abb_gym.physics import batch


def test_each_environment_gets_its_block_size_and_the_default_comes_back():
    before = batch.MAX_LANES
    rows = bs.block_size_rates(num_envs=32, lanes=(4, 8), rounds=2)
    assert batch.MAX_LANES == before
    assert [r["lanes"] for r in rows] == [4, 8]
    assert all(r["best"] >= r["median"] > 0 for r in rows)
    assert "ratio" not in rows[0]
    median, low, high = rows[1]["ratio"]
    assert 0 < low <= median <= high


def test_a_size_the_environment_cannot_fill_is_reported_as_what_it_got():
    # 32 sub-environments: at most 32 lanes per block (one block), whatever is allowed
    rows = bs.block_size_rates(num_envs=32, lanes=(8, 64), rounds=2)
    assert [(r["requested"], r["lanes"]) for r in rows] == [(8, 8), (64, 32)]


def test_the_global_comes_back_after_a_failure(monkeypatch):
    before = batch.MAX_LANES

    def broken(*args, **kwargs):
        assert batch.MAX_LANES == 4
        raise RuntimeError("make_vector failed")

    monkeypatch.setattr(bs, "make_vector", broken)
    with pytest.raises(RuntimeError, match="make_vector failed"):
        bs.block_size_rates(num_envs=32, lanes=(4, 8), rounds=2)
    assert batch.MAX_LANES == before


@pytest.mark.parametrize("kwargs, field", [
    ({"num_envs": 1}, "num_envs"), ({"num_envs": True}, "num_envs"),
    ({"lanes": (64,)}, "lanes"), ({"lanes": (64, 96)}, "lanes"), ({"lanes": (0, 8)}, "lanes"),
    ({"precision": "float16"}, "precision"), ({"rounds": 1}, "rounds")])
def test_bad_input_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        bs.block_size_rates(**kwargs)


def test_cli_prints_the_table(capsys):
    assert bs.main(["--envs", "32", "--lanes", "4", "8", "--rounds", "2"]) == 0
    out = capsys.readouterr().out
    assert "burst-time ratio to 4 lanes" in out
    assert out.splitlines()[-1].split()[0] == "8"
