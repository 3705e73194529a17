"""Evaluation videos: frames rendered headless (EGL) and written as MP4.

imageio with its ffmpeg plugin (``imageio-ffmpeg`` ships an ffmpeg binary), so
no system ffmpeg and no torchvision are needed.
"""

from __future__ import annotations

from pathlib import Path

import gymnasium
import numpy as np


def frames_per_second(env: gymnasium.Env, action_repeat: int) -> int:
    """Real time for a video with one frame per agent step (every ``action_repeat`` env steps)."""
    dt = getattr(env.unwrapped, "control_timestep", None) or getattr(env.unwrapped, "dt", None)
    if not dt:
        return 30
    return max(1, round(1.0 / (dt * action_repeat)))


def write_video(path: Path, frames: list[np.ndarray], fps: int) -> Path:
    """Write RGB frames [H, W, 3] (uint8) to an H.264 MP4 that common players open."""
    import imageio.v2 as imageio

    if not frames:
        raise ValueError("no frames to write")
    path.parent.mkdir(parents=True, exist_ok=True)
    # yuv420p needs even sizes: macro_block_size=2 pads odd ones by a pixel at most.
    with imageio.get_writer(path, fps=fps, codec="libx264", pixelformat="yuv420p",
                            macro_block_size=2, output_params=["-loglevel", "error"]) as writer:
        for frame in frames:
            writer.append_data(np.asarray(frame, dtype=np.uint8))
    return path
