"""Render one episode to an animated GIF, an MP4 or a PNG of the last frame."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["render_episode", "save_frames"]


def save_frames(frames: list[np.ndarray], out: Path, fps: int = 10) -> Path:
    """Write ``frames`` (uint8 (H, W, 3)) to ``out`` by its suffix: .gif, .mp4 or .png.

    Raises:
        ValueError: unsupported suffix or no frames.
    """
    out = Path(out)
    if not frames:
        raise ValueError("no frames to save")
    suffix = out.suffix.lower()
    out.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".png":
        from PIL import Image

        Image.fromarray(frames[-1]).save(out)
    elif suffix == ".gif":
        from PIL import Image

        imgs = [Image.fromarray(f) for f in frames]
        imgs[0].save(out, save_all=True, append_images=imgs[1:], duration=int(1000 / fps), loop=0)
    elif suffix == ".mp4":
        import imageio.v2 as imageio

        try:
            imageio.mimwrite(out, frames, fps=fps)
        except Exception as exc:  # imageio-ffmpeg is optional
            raise ValueError(
                f"--out {out}: writing .mp4 needs imageio-ffmpeg (pip install imageio-ffmpeg); "
                f"use .gif instead ({exc})"
            ) from None
    else:
        raise ValueError(f"--out must end in .gif, .mp4 or .png, got {out.name!r}")
    return out


def render_episode(
    scenario: str,
    policy: str,
    seed: int,
    out: Path,
    safety_filter: bool = False,
    every: int = 5,
    fps: int = 10,
    **env_kwargs: Any,
) -> Path:
    """Run one episode with ``render_mode="rgb_array"`` and save every ``every``-th frame.

    Policies (and the safety filter) that define ``draw(canvas)`` get it registered
    as a render layer, so particles, ellipses and FoV sectors appear in the video.
    """
    from fov_marl.evaluation import run_episode

    suffix = Path(out).suffix.lower()
    if suffix not in (".gif", ".mp4", ".png"):
        raise ValueError(f"--out must end in .gif, .mp4 or .png, got {Path(out).name!r}")
    frames: list[np.ndarray] = []
    state = {"k": 0, "registered": False}

    def on_step(env: Any, infos: dict) -> None:
        if state["k"] % every == 0:
            frames.append(env.render())
        state["k"] += 1

    def factory(env: Any):
        from fov_marl.baselines import make_policy

        pol = make_policy(policy, env)
        base = env.unwrapped
        for layer_owner in (pol, env):
            draw = getattr(layer_owner, "draw", None)
            if callable(draw):
                base.add_render_layer(draw)
        return pol

    factory.__name__ = policy
    run_episode(
        scenario,
        factory,
        seed,
        safety_filter=safety_filter,
        on_step=on_step,
        render_mode="rgb_array",
        **env_kwargs,
    )
    return save_frames(frames, Path(out), fps=fps)
