"""Render one episode to an animated GIF, an MP4 or a PNG of the last frame.

GIF and PNG need only Pillow. MP4 needs the ffmpeg writer of imageio, which the
``[video]`` extra installs (``pip install 'fov_marl[video]'``, i.e. imageio-ffmpeg);
:func:`check_writer` says so before any episode is simulated.

Frames carry a title (policy, scenario, N, β, simulated time) and a legend
(:func:`fov_marl.envs.rendering.render_frame`); ``beliefs_of`` picks whose particle
filters are drawn: ``"robot_k"``, ``"all"`` or ``"none"``.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["render_episode", "save_frames", "check_writer", "parse_beliefs_of", "VIDEO_SUFFIXES"]

VIDEO_SUFFIXES = (".gif", ".mp4", ".png")
VIDEO_EXTRA_HINT = "pip install 'fov_marl[video]'"


def check_writer(out: str | Path) -> None:
    """Check that a writer for ``out``'s suffix is available, before any simulation.

    Raises:
        ValueError: an unsupported suffix, or ``.mp4`` without imageio-ffmpeg (the
            message names the ``[video]`` extra).
    """
    suffix = Path(out).suffix.lower()
    if suffix not in VIDEO_SUFFIXES:
        raise ValueError(f"--out must end in .gif, .mp4 or .png, got {Path(out).name!r}")
    if suffix == ".mp4":
        try:
            import imageio_ffmpeg

            imageio_ffmpeg.get_ffmpeg_exe()
        except (ImportError, RuntimeError, OSError) as exc:
            reason = " ".join(str(exc).split()) or type(exc).__name__
            raise ValueError(
                f"--out {out}: writing .mp4 needs imageio-ffmpeg, which the [video] extra "
                f"installs ({VIDEO_EXTRA_HINT}), or write a .gif ({reason})"
            ) from None


def parse_beliefs_of(value: str, n_agents: int) -> list[int] | str:
    """``"robot_k"`` -> ``[k]``, ``"all"`` -> ``"all"``, ``"none"`` -> ``[]``.

    Raises:
        ValueError: another value, or k outside ``[0, n_agents - 1]`` (naming the flag).
    """
    text = str(value).strip()
    if text in ("all", "none"):
        return "all" if text == "all" else []
    m = re.fullmatch(r"robot_(\d+)", text)
    if m is None or int(m.group(1)) >= n_agents:
        raise ValueError(
            f"--beliefs-of must be robot_k with k in [0, {n_agents - 1}], 'all' or 'none', "
            f"got {value!r}"
        )
    return [int(m.group(1))]


def save_frames(frames: list[np.ndarray], out: Path, fps: int = 10) -> Path:
    """Write ``frames`` (uint8 (H, W, 3)) to ``out`` by its suffix: .gif, .mp4 or .png.

    Raises:
        ValueError: unsupported suffix, no frames, or .mp4 without imageio-ffmpeg.
    """
    out = Path(out)
    if not frames:
        raise ValueError("no frames to save")
    check_writer(out)
    suffix = out.suffix.lower()
    out.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".png":
        from PIL import Image

        Image.fromarray(frames[-1]).save(out)
    elif suffix == ".gif":
        from PIL import Image

        imgs = [Image.fromarray(f) for f in frames]
        imgs[0].save(out, save_all=True, append_images=imgs[1:], duration=int(1000 / fps), loop=0)
    else:  # .mp4, writer checked above
        import imageio.v2 as imageio

        imageio.mimwrite(out, frames, fps=fps)
    return out


def render_episode(
    scenario: str,
    policy: str,
    seed: int,
    out: Path,
    safety_filter: bool = False,
    every: int = 5,
    fps: int = 10,
    *,
    beliefs_of: str | list[int] = "robot_0",
    legend: bool = True,
    safety_filter_kwargs: dict[str, Any] | None = None,
    **env_kwargs: Any,
) -> Path:
    """Run one episode and save every ``every``-th frame to ``out`` (.gif/.mp4/.png).

    Args:
        scenario: ``"coverage"`` or ``"crossing"``.
        policy: a registered policy name or the path of a trained ``model.zip`` (its
            config.json gives the config fields not in ``env_kwargs``, and its safety
            filter); ``"learned"`` and an exported folder trained behind the filter run
            behind it (:func:`fov_marl.evaluation.learned_filter`; the shipped
            filter's options unless ``safety_filter_kwargs`` gives others).
        seed: the episode's seed.
        out: output file; its writer is checked before the episode runs.
        safety_filter: run behind :class:`~fov_marl.wrappers.SafetyFilterWrapper`.
        every: keep every k-th step's frame.
        fps: frames per second of the GIF/MP4.
        beliefs_of: whose particle filters to draw (``"robot_k"``, ``"all"``, ``"none"``
            or a list of indices): the safety filter's trackers when the env is
            filtered, else the policy's (PF+CBF policies); policies without a
            pipeline that define ``draw(canvas)`` draw their own layer.
        legend: draw the legend.
        safety_filter_kwargs: keywords of the filter
            (:func:`fov_marl.evaluation.make_env`); None: its defaults, or a trained
            model's own filter options.
        **env_kwargs: config fields.
    """
    from fov_marl.envs.rendering import draw_beliefs, frame_title, render_frame
    from fov_marl.evaluation import is_model_path, run_episode

    check_writer(out)
    factory_base: Any
    if is_model_path(policy):
        from fov_marl.training import load_policy  # torch only for learned policies

        loaded = load_policy(policy)
        env_kwargs = {**loaded.env_kwargs, **env_kwargs}
        if loaded.safety_filter and not safety_filter_kwargs:
            safety_filter_kwargs = loaded.safety_filter_kwargs or None  # as trained
        safety_filter = bool(safety_filter or loaded.safety_filter)
        factory_base = loaded.factory
        label = Path(policy).parent.name if Path(policy).suffix == ".zip" else Path(policy).name
        label = f"{loaded.name} ({label})"
    else:
        from fov_marl.baselines import make_policy
        from fov_marl.evaluation import is_exported_policy, learned_filter

        kw = {"path": policy} if is_exported_policy(policy) else {}
        safety_filter = safety_filter or learned_filter(policy)  # trained behind it

        def factory_base(env: Any) -> Any:
            return make_policy("learned" if kw else policy, env, **kw)

        label = policy
    frames: list[np.ndarray] = []
    state: dict[str, Any] = {"k": 0, "layers": [], "beliefs": False, "chosen": None}

    def factory(env: Any) -> Any:
        pol = factory_base(env)
        n = len(env.possible_agents)
        chosen = parse_beliefs_of(beliefs_of, n) if isinstance(beliefs_of, str) else beliefs_of
        state["chosen"] = chosen
        owners = [o for o in (env, pol) if getattr(o, "pipeline", None) is not None]
        if owners and chosen:
            pipeline = owners[0].pipeline

            def beliefs_layer(canvas: Any) -> None:
                if pipeline.estimates_view() is not None:
                    draw_beliefs(canvas, pipeline, robots=chosen)

            state["layers"].append(beliefs_layer)
            state["beliefs"] = True
        elif not owners:
            draw = getattr(pol, "draw", None)
            if callable(draw):
                state["layers"].append(draw)
        return pol

    def on_step(env: Any, infos: dict) -> None:
        if state["k"] % every == 0:
            base = env.unwrapped
            t_s = base.num_steps * base.config.dt_s
            frames.append(
                render_frame(
                    base.config,
                    base.poses,
                    base.targets,
                    state["layers"],
                    title=frame_title(base.config, t_s, label),
                    legend=legend,
                    beliefs=state["beliefs"],
                )
            )
        state["k"] += 1

    factory.__name__ = label
    run_episode(
        scenario,
        factory,
        seed,
        safety_filter=safety_filter,
        on_step=on_step,
        safety_filter_kwargs=safety_filter_kwargs,
        **env_kwargs,
    )
    return save_frames(frames, Path(out), fps=fps)
