"""``abb-gym study``: Yoshida-style parameter studies as charts and tables.

    abb-gym study settling --out out/study        # Fig. 4.23: settling period vs dwell length
    abb-gym study ball-position --out out/study   # Figs. 5.5/5.11: ball position vs mass, drag
"""
from __future__ import annotations

from ..execution.cli import add_executor_arguments
from ..tables import markdown_table
from .evaluate import _executor


def register(sub) -> None:
    p = sub.add_parser("study", help="Yoshida-style parameter studies (charts + tables)",
                       description=__doc__)
    p.add_argument("which", choices=["settling", "ball-position"])
    p.add_argument("--scene", default="yoshida_odd", help="scene name or YAML path")
    p.add_argument("--out", default="out/study", help="output folder (created)")
    add_executor_arguments(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..evaluation import studies
    from ..physics.scene import load_scene
    from .outputs import output_folder
    # the inputs first: a bad scene is one line before any folder or task exists (the study
    # functions check their points again before they dispatch)
    load_scene(args.scene)
    ex = _executor(args)
    out = output_folder(args.out, "--out")
    if args.which == "settling":
        rows = studies.settling_study(args.scene, executor=ex)
        png = studies.plot_settling_study(rows, out / "settling_period.png")
    else:
        rows = studies.ball_position_study(args.scene, executor=ex)
        png = studies.plot_ball_position_study(rows, out / "ball_position.png")
    text = markdown_table(rows)
    from .._files import write_text
    write_text(out / f"{args.which}.md", text + "\n")
    print(text)
    print(f"wrote {png} and {png.with_suffix('.csv')}")
    return 0
