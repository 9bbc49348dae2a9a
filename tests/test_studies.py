"""Smoke test: the Yoshida parameter-study charts are produced."""
from abb_gym.evaluation import studies


def test_study_charts(tmp_path):
    rows = studies.settling_study(dwell_times=(0.4, 0.6), progress=False)
    assert studies.plot_settling_study(rows, tmp_path / "a.png").stat().st_size > 5000
    rows = studies.ball_position_study(masses=(1e-3, 2e-3), drags=(0.5, 2.0), progress=False)
    assert len(rows) == 8
    # heavier balls move further; more drag holds them back (Yoshida sec. 5)
    pos = {(r["profile"], r["ball_mass_g"], r["ball_drag_Ns_m"]): r["ball_angle_deg"] for r in rows}
    assert pos["no profile", 2.0, 2.0] < pos["no profile", 1.0, 2.0]
    assert pos["no profile", 1.0, 0.5] < pos["no profile", 1.0, 2.0]
    assert studies.plot_ball_position_study(rows, tmp_path / "b.png").stat().st_size > 5000


def test_study_cli_and_executor_give_the_same_rows(tmp_path, capsys):
    from abb_gym.cli import main
    from abb_gym.execution import Executor
    serial = studies.settling_study(dwell_times=(0.4, 0.5), progress=False)
    parallel = studies.settling_study(dwell_times=(0.4, 0.5), progress=False,
                                      executor=Executor(workers=2, progress=False))
    assert serial == parallel
    assert main(["study", "settling", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "settling_period.png").exists() and (tmp_path / "settling.md").exists()
