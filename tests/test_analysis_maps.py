"""Stability maps: determinism across workers, outputs, overlays, CLI."""
import argparse
import csv

import numpy as np
import pytest

from abb_gym import load_scene
from abb_gym.analysis import Groups, onset_speed, stability_map
from abb_gym.cli import stability as cli_stability


def test_map_is_identical_with_one_or_two_workers():
    """Deterministic ordering: ProcessPoolExecutor.map keeps submission order."""
    g = Groups(eta=0.4, delta=10)
    kw = dict(n_balls=(3, 2), n_members=5, progress=False)
    a = stability_map(g, ("zeta", [0.05, 0.1, 0.2]), ("Omega", [1.2, 1.5, 1.8, 2.1]),
                      workers=1, **kw)
    b = stability_map(g, ("zeta", [0.05, 0.1, 0.2]), ("Omega", [1.2, 1.5, 1.8, 2.1]),
                      workers=2, chunksize=1, **kw)
    for n in (3, 2):
        for f in ("exists", "union_stable", "all_stable", "best", "worst"):
            assert np.array_equal(a.field(n, f), b.field(n, f))
    assert a.field(3, "union_stable")[0].sum() == 0          # Omega 1.2: below onset
    assert a.field(3, "union_stable")[-1].all()               # Omega 2.1: stable


def test_three_balls_beat_two_at_eta_total_24():
    """P6 (paper L268/L277, Fig. 9, eta_total = 2.4): the three-ball stable region is larger.
    [derived] note A8 (mu 0.9, delta 10, zeta = zeta_b = 0.1, union, grid 0.01): onset 1.34
    (three balls) vs 1.56 (two balls); tolerance 0.02 (the note's grid plus bisection)."""
    g3 = Groups(eta=0.8, n_balls=3, mu=0.9, delta=10)
    g2 = g3.with_ball_count(2)
    assert g2.eta == pytest.approx(1.2)
    on3, on2 = onset_speed(g3, 1.0, 3.0), onset_speed(g2, 1.0, 3.0)
    assert on3 == pytest.approx(1.34, abs=0.02)
    assert on2 == pytest.approx(1.56, abs=0.02)
    m = stability_map(g3, ("zeta", [0.1, 0.2]), ("Omega", np.arange(1.3, 2.01, 0.1)),
                      n_balls=(3, 2), n_members=9, workers=1, progress=False)
    u3, u2 = m.field(3, "union_stable"), m.field(2, "union_stable")
    assert np.all(u3 >= u2) and u3.sum() > u2.sum()          # 3-ball region contains 2-ball


def test_outputs_and_scene_axes(tmp_path):
    """CSV has one row per (x, y, n) with the classification columns; PNG is written; a scene
    field (support_damping) works as an axis."""
    scene = load_scene("lu_hung_odd3")
    m = stability_map(scene, ("support_damping", [1.0, 2.0, 4.0]), ("Omega", [1.3, 1.8]),
                      n_members=5, workers=1, progress=False)
    assert m.n_balls == (3, 2)
    path = m.to_csv(tmp_path / "m.csv")
    rows = list(csv.DictReader(open(path)))
    assert len(rows) == 3 * 2 * 2
    assert set(rows[0]) == {"support_damping", "Omega", "n_balls", "exists", "union_stable",
                            "all_stable", "fraction_stable", "best", "worst"}
    png = m.plot(tmp_path / "m.png")
    assert png.stat().st_size > 5000
    with pytest.raises(ValueError, match="unknown map parameter"):
        stability_map(Groups(), ("bogus", [1.0]), ("Omega", [1.5]), workers=1, progress=False)
    with pytest.raises(ValueError, match="different"):
        stability_map(Groups(), ("zeta", [0.1]), ("zeta", [0.2]), workers=1, progress=False)


def test_cli_stability_map(tmp_path, capsys):
    """``abb-gym stability-map`` writes CSV + PNG (parser built from this module's register)."""
    parser = argparse.ArgumentParser()
    cli_stability.register(parser.add_subparsers(dest="command"))
    out = tmp_path / "cli"
    args = parser.parse_args(["stability-map", "--scene", "lu_hung_odd3", "--x", "zeta",
                              "--x-range", "0.05", "0.2", "--nx", "3", "--y", "Omega",
                              "--y-range", "1.2", "2.0", "--ny", "3", "--members", "5",
                              "--workers", "1", "--no-progress", "--out", str(out)])
    assert args.func(args) == 0
    assert (tmp_path / "cli.csv").exists() and (tmp_path / "cli.png").exists()
    assert "3 balls: union-stable" in capsys.readouterr().out
    args = parser.parse_args(["stability-map", "--set", "eta_total=2.4", "--set", "delta=10",
                              "--x", "zeta", "--nx", "2", "--ny", "2", "--workers", "1",
                              "--no-progress", "--out", str(out)])
    assert args.func(args) == 0
    args = parser.parse_args(["stability-map", "--set", "ball_drag=1", "--nx", "1", "--ny", "1",
                              "--no-progress", "--out", str(out)])
    with pytest.raises(ValueError, match="not a group"):
        args.func(args)
