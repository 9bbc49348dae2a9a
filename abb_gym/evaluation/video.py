"""One episode of a policy as a video: the frames of the environment's ``rgb_array`` rendering
(:mod:`abb_gym.envs.rendering`) written to a GIF or an MP4 (``abb-gym render``).

Episode ``k`` with seed ``S`` is the machine of test episode ``k`` of ``abb-gym evaluate
--seed S`` (the environment reset with seed ``S + k``), run by the evaluation's own loop
(:func:`abb_gym.evaluation.evaluate.run_chunk`), so the video shows exactly the episode whose
metrics an evaluation reports.  A frame is drawn after the reset, after every ``every``-th
control step and after the last step; by default ``every`` makes the video play in real time
at ``fps``.

Writing needs the optional extra ``video`` (``pip install 'abb-gym[video]'``): imageio, with
pillow for GIF and imageio-ffmpeg (a bundled ffmpeg binary) for MP4.
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["FORMATS", "MAX_GIF_FRAMES", "MAX_GIF_FPS", "INSTALL_HINT", "check_video",
           "default_every", "frame_count", "render_episode"]

FORMATS = (".gif", ".mp4")
#: a GIF holds every frame in memory until it is written (about 0.26 MB each, paletted)
MAX_GIF_FRAMES = 1000
#: GIF delays are whole hundredths of a second, and browsers slow down delays below 20 ms
MAX_GIF_FPS = 50
INSTALL_HINT = "pip install 'abb-gym[video]'"


def _missing_extra(what: str) -> ValueError:
    return ValueError(f"writing {what} needs the optional extra 'video' (imageio"
                      f"{', imageio-ffmpeg' if what == 'an MP4' else ''}): {INSTALL_HINT}")


def check_video(path: str | os.PathLike, fps: Any) -> str:
    """The format (".gif" or ".mp4") of ``path``; raises ValueError for another suffix, an
    ``fps`` that the format cannot play, or a missing ``video`` extra."""
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise ValueError(f"--out {str(path)!r}: the file name must end in "
                         f"{' or '.join(FORMATS)} (got {suffix or 'no suffix'!r})")
    if isinstance(fps, bool) or not isinstance(fps, (int, float, np.integer, np.floating)) \
            or not math.isfinite(fps) or fps <= 0:
        raise ValueError(f"--fps must be a number > 0 (got {fps!r})")
    if suffix == ".gif" and fps > MAX_GIF_FPS:
        raise ValueError(f"--fps {fps:g} is too fast for a GIF (at most {MAX_GIF_FPS}: its "
                         f"delays are whole hundredths of a second); use an .mp4 for more")
    try:
        import imageio  # noqa: F401
    except ImportError:
        raise _missing_extra("a GIF" if suffix == ".gif" else "an MP4") from None
    if suffix == ".mp4":
        try:
            import imageio_ffmpeg  # noqa: F401
        except ImportError:
            raise _missing_extra("an MP4") from None
    return suffix


def default_every(fps: float, control_interval: float) -> int:
    """Control steps per frame for a video that plays in real time at ``fps`` (at least 1)."""
    return max(1, int(round(1.0 / (fps * control_interval))))


def frame_count(steps: int, every: int) -> int:
    """Frames of an episode of ``steps`` control steps: after the reset, after every
    ``every``-th step and after the last step."""
    return steps // every + 1 + (steps % every != 0)


class _Writer:
    """Appends RGB frames to a GIF (pillow, each frame paletted as it comes) or an MP4
    (ffmpeg, streamed)."""

    def __init__(self, path: Path, fps: float):
        self.path = path
        self.gif = path.suffix.lower() == ".gif"
        if self.gif:
            import imageio.v3 as iio
            self._w = iio.imopen(path, "w", plugin="pillow", extension=".gif")
            self._ms = 1000.0 / fps
        else:
            import imageio.v2 as iio2
            # 8-pixel blocks: ffmpeg keeps the frame size (720 x 360) instead of padding it
            self._w = iio2.get_writer(path, format="FFMPEG", mode="I", fps=fps,
                                      codec="libx264", macro_block_size=8,
                                      ffmpeg_log_level="error")

    def append(self, frame: np.ndarray) -> None:
        if self.gif:
            self._w.write(frame, duration=self._ms, loop=0, bits=8)
        else:
            self._w.append_data(frame)

    def close(self) -> None:
        self._w.close()


def render_episode(env_id: str, scene: str, policy: str, out: str | os.PathLike, *,
                   episode: int = 0, seed: int = 0, preset: str = "test", fps: float = 25,
                   every: int | None = None, steps: int | None = None, progress: bool = True,
                   ) -> dict[str, Any]:
    """Write episode ``episode`` of the test set with seed ``seed`` under ``policy`` to
    ``out`` (.gif or .mp4) and return what was written: ``path``, ``frames``, ``width``,
    ``height``, ``fps``, ``every``, ``steps`` (control steps run) and ``metrics`` (the
    episode's row of the evaluation).  ``steps`` cuts the episode after that many control
    steps (truncated, as ``max_episode_steps``).  Every input is checked before anything
    runs (ValueError naming it)."""
    from ..progress import ProgressBar

    from ..envs import episode_steps
    from ..envs.setup import EnvSetup
    from .evaluate import Chunk, check_inputs, run_chunk

    out = Path(out)
    check_video(out, fps)
    for name, value, least in (("episode", episode, 0), ("seed", seed, 0),
                               ("every", every, 1), ("steps", steps, 1)):
        if value is None and name in ("every", "steps"):
            continue
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) \
                or value < least:
            raise ValueError(f"--{name} must be an integer >= {least} (got {value!r})")
    env_kwargs = {"max_episode_steps": int(steps)} if steps is not None else {}
    check_inputs(env_id, scene, preset, seed, policy, **env_kwargs)
    n_steps = episode_steps(env_id, scene=scene, preset=preset, **env_kwargs)
    if every is None:
        interval = EnvSetup(env_id, scene, preset).control_interval
        every = default_every(fps, interval)
    every = int(every)
    expected = frame_count(n_steps, every)
    if out.suffix.lower() == ".gif" and expected > MAX_GIF_FRAMES:
        least = math.ceil(n_steps / (MAX_GIF_FRAMES - 2))
        raise ValueError(f"the episode has {n_steps} steps: {expected} frames at --every "
                         f"{every}, more than a GIF holds ({MAX_GIF_FRAMES}); use --every "
                         f"{least} or more, --steps, or an .mp4")

    # written next to the target and moved there at the end: a failed run leaves no half video
    part = out.with_name(f".{out.stem}.partial{out.suffix}")
    state = {"k": -1, "frames": 0, "shape": None}  # k: control steps run (-1 before the reset)
    writer = _Writer(part, fps)
    bar = ProgressBar(total=n_steps, desc=f"render {policy}", unit="step", disable=not progress)

    def on_step(env, done) -> None:
        last = bool(done[0])
        state["k"] += 1
        if state["k"]:  # the call after the reset is not a step
            bar.update(1)
        if last and state["k"] != bar.total:
            # the bar's total is the longest episode; this one ended at its own length
            bar.total = state["k"]
            bar.refresh()
        if state["k"] % every == 0 or last:
            frame = env.render()[0]
            state["shape"] = frame.shape
            writer.append(frame)
            state["frames"] += 1

    chunk = Chunk(env_id, scene, preset, policy, int(seed), (int(episode),),
                  env_kwargs=tuple(sorted({**env_kwargs, "render_mode": "rgb_array"}.items())))
    try:
        try:
            rows, _ = run_chunk(chunk, on_step=on_step)
        finally:
            bar.close()
            writer.close()
        os.replace(part, out)
    finally:
        if part.exists():
            part.unlink()
    height, width = state["shape"][:2]
    return {"path": out, "frames": state["frames"], "width": width, "height": height,
            "fps": fps, "every": every, "steps": state["k"], "metrics": rows[0]}
