"""``abb-gym render`` (one episode of a policy as a GIF or MP4) and the legend of the rendered
frame (abb_gym.envs.rendering)."""
from __future__ import annotations

import sys

import numpy as np
import pytest

from abb_gym.cli import main
from abb_gym.envs.rendering import Renderer
from abb_gym.evaluation.video import MAX_GIF_FRAMES, frame_count

iio = pytest.importorskip("imageio.v3", reason="the video extra: pip install 'abb-gym[video]'")


# ------------------------------------------------------------------------------ the frame
def _overlap(a, b) -> bool:
    """True if two display boxes share any area."""
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def test_legend_names_what_is_drawn_and_covers_no_panel():
    from abb_gym.physics import load_scene
    scene = load_scene("yoshida_odd")
    r = Renderer(scene, 300.0, 8.0, "rgb_array")
    nq = 3 + scene.ball_count
    state = np.zeros(2 * nq)
    state[0], state[1], state[2], state[3:nq] = 1e-3, -2e-3, 0.7, [0.3, 2.5]
    state[nq + 2] = 150.0
    trace = np.array([[0.0, 0.0, 0.0, 0.0], [0.5, 1e-3, -2e-3, 150.0]])
    frame = r.draw(state, trace)
    assert frame.shape == (360, 720, 3)
    labels = {t.get_text() for leg in (r.legend_orbit, r.legend_speed) for t in leg.get_texts()}
    assert {"balls (2)", "angle of the imbalance", "rotor centre", "race (not to scale)",
            "orbit of the rotor centre", "housing clearance", "rotor speed", "operating speed",
            "whirl radius (right axis)"} <= labels
    fig = r.fig
    renderer = fig.canvas.get_renderer()
    panels = [ax.get_window_extent(renderer) for ax in (r.ax_orbit, r.ax_speed, r.ax_whirl)]
    # the whole figure, in display pixels
    whole = fig.bbox
    for item in (r.legend_orbit, r.legend_speed, r.text):
        box = item.get_window_extent(renderer)
        assert not any(_overlap(box, p) for p in panels), item
        assert whole.x0 <= box.x0 and box.x1 <= whole.x1 and whole.y0 <= box.y0 \
            and box.y1 <= whole.y1, item
    assert "t = 0.50 s" in r.text.get_text()
    r.close()


def test_frame_count():
    assert frame_count(12, 5) == 4  # after the reset and steps 5, 10, 12
    assert frame_count(10, 5) == 3
    assert frame_count(1, 4) == 2   # DwellProfile: before and after its one step


# ------------------------------------------------------------------------------ the command
def _run(capsys, *args):
    code = main(["render", *args])
    out, err = capsys.readouterr()
    return code, out, err


def test_render_gif_of_a_short_baseline_episode(tmp_path, capsys):
    out = tmp_path / "sub" / "ramp.gif"
    code, text, _ = _run(capsys, "--policy", "baseline:ramp", "--steps", "12", "--every", "5",
                         "--fps", "10", "--out", str(out))
    assert code == 0, text
    frames = iio.imread(out, index=None)
    assert frames.shape == (frame_count(12, 5), 360, 720, 3)  # steps 0, 5, 10, 12
    for a, b in zip(frames[:-1], frames[1:]):
        assert not np.array_equal(a, b)
    assert iio.immeta(out, index=0)["duration"] == 100  # ms at 10 fps
    assert f"wrote {out}: 4 frames of 720 x 360 at 10 fps" in text
    assert "12 steps" in text
    assert [p.name for p in out.parent.iterdir()] == ["ramp.gif"]  # no partial file left


def test_render_mp4(tmp_path, capsys):
    pytest.importorskip("imageio_ffmpeg")
    import imageio.v2 as iio2
    out = tmp_path / "knots.mp4"
    code, text, _ = _run(capsys, "--policy", "baseline:knots", "--steps", "6", "--every", "3",
                         "--out", str(out))
    assert code == 0, text
    reader = iio2.get_reader(out)
    assert reader.count_frames() == frame_count(6, 3)
    assert reader.get_meta_data()["size"] == (720, 360)
    reader.close()


BAD = [
    (["--out", "{tmp}/x.avi"], "must end in .gif or .mp4"),
    (["--fps", "0"], "--fps must be a number > 0"),
    (["--fps", "nan"], "--fps must be a number > 0"),
    (["--fps", "60"], "too fast for a GIF"),
    (["--every", "0"], "--every must be an integer >= 1"),
    (["--steps", "0"], "--steps must be an integer >= 1"),
    (["--episode", "-1"], "--episode must be an integer >= 0"),
    (["--seed", "-2"], "--seed must be an integer >= 0"),
    (["--policy", "nonsense"], "KIND:ARG"),
    (["--policy", "baseline:nope"], "unknown baseline 'nope'"),
    (["--env", "abb_gym/Nope-v0"], "unknown environment"),
    (["--scene", "no_such_scene"], "no_such_scene"),
    (["--preset", "no_such_preset"], "no_such_preset"),
    (["--out", "{tmp}/folder.gif"], "is a folder"),
    (["--scene", "spannan_cfrp"], f"more than a GIF holds ({MAX_GIF_FRAMES})"),
]


@pytest.mark.parametrize("args, message", BAD, ids=[" ".join(a) for a, _ in BAD])
def test_bad_input_is_one_line(tmp_path, capsys, args, message):
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    (tmp_path / "folder.gif").mkdir()
    base = {"--policy": "baseline:ramp", "--out": str(tmp_path / "v.gif")}
    for key, value in zip(args[::2], args[1::2]):
        base[key] = value
    code, out, err = _run(capsys, *[x for kv in base.items() for x in kv])
    assert code == 2
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("abb-gym render: error: "), err
    assert message in lines[0], lines[0]
    assert not (tmp_path / "v.gif").exists()


@pytest.mark.parametrize("suffix, module", [(".gif", "imageio"), (".mp4", "imageio_ffmpeg")])
def test_missing_video_extra_names_the_pip_command(tmp_path, capsys, monkeypatch, suffix,
                                                   module):
    monkeypatch.setitem(sys.modules, module, None)  # import fails as if not installed
    out = tmp_path / f"v{suffix}"
    code, text, err = _run(capsys, "--policy", "baseline:ramp", "--out", str(out))
    assert code == 2 and text == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "pip install 'abb-gym[video]'" in lines[0], err
    assert not out.exists() and not tmp_path.joinpath("v").exists()


def test_the_render_bar_ends_at_the_steps_the_episode_ran(tmp_path, monkeypatch):
    """The bar's total is the longest episode (12 steps here); an episode that ends after 7
    ends the bar at 7/7 (before: 7/12, and the bar of a 700-step episode read 850)."""
    from abb_gym import progress
    from abb_gym.evaluation import evaluate, video

    class Env:
        def render(self):
            return [np.zeros((36, 72, 3), np.uint8)]

    def seven_steps(chunk, on_step=None):
        on_step(Env(), np.zeros(1, bool))
        for k in range(1, 8):
            on_step(Env(), np.array([k == 7]))
        return [{"return": 0.0}], {}

    bars = []

    class Bar(progress.ProgressBar):
        def close(self):
            if not self.disable:  # (tqdm closes again when the bar is collected)
                bars.append((self.n, self.total))
            super().close()

    monkeypatch.setattr(evaluate, "run_chunk", seven_steps)
    monkeypatch.setattr(progress, "ProgressBar", Bar)
    res = video.render_episode("abb_gym/RunUpSpeed-v0", "yoshida_odd", "baseline:ramp",
                               tmp_path / "x.gif", steps=12, every=5, fps=10)
    assert res["steps"] == 7
    assert bars == [(7, 7)]
