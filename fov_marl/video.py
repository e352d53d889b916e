"""Render one episode to an animated GIF, an MP4 or a PNG of the final state.

GIF and PNG need only Pillow. MP4 needs the ffmpeg writer of imageio, which the
``[video]`` extra installs (``pip install 'fov_marl[video]'``, i.e. imageio-ffmpeg);
:func:`check_writer` says so before any episode is simulated.

Frames: the initial state (t = 0), then the state after every ``every``-th step, and
always the episode's final state, once, as the last frame (:func:`frame_count`); a PNG
holds that last frame. Frames carry a title (policy, scenario, N, β, simulated time)
and a legend (:func:`fov_marl.envs.rendering.render_frame`); ``beliefs_of`` picks whose
particle filters are drawn: ``"robot_k"``, ``"all"`` or ``"none"``.

Every argument of :func:`render_episode` and :func:`save_frames` is checked before any
simulation: a bad one is a ``ValueError`` naming it and its allowed range (the ranges
of ``fov-marl render``).
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fov_marl.validation import (
    MAX_SEED,
    ConfigError,
    check_bool,
    check_choice,
    check_int,
    check_out_file,
    check_wrapper_kwargs,
    check_writable,
    describe,
)

__all__ = [
    "render_episode",
    "save_frames",
    "check_writer",
    "parse_beliefs_of",
    "frame_count",
    "VIDEO_SUFFIXES",
    "MAX_FPS",
    "MAX_RENDER_FRAMES",
]

VIDEO_SUFFIXES = (".gif", ".mp4", ".png")
VIDEO_EXTRA_HINT = "pip install 'fov_marl[video]'"
#: the largest frame rate (frames per second) of a GIF/MP4: a GIF stores each frame's
#: duration in 10 ms units, so 100 fps is its finest
MAX_FPS = 100
#: the most frames :func:`render_episode` keeps in memory for a GIF (640 x 640 RGB,
#: 1.2 MB each: about 1.2 GB at the cap), i.e. the default 1000-step episode at
#: ``every=1``; an MP4 is written frame by frame and a PNG keeps only its one frame, so
#: neither has a cap
MAX_RENDER_FRAMES = 1001


def frame_count(steps: int, every: int) -> int:
    """How many frames an episode of ``steps`` steps gives (and keeps in memory):
    ``1 + ceil(steps / every)``, i.e. the initial state (step 0), the state after steps
    ``every``, ``2 every``, ... and the final state (step ``steps``) once, last. An
    episode that terminates early (crossing: every robot arrived) gives fewer.

    >>> frame_count(10, 5), frame_count(12, 5), frame_count(1000, 1)
    (3, 4, 1001)
    """
    steps = check_int("steps", steps, 0)
    every = check_int("every", every, 1)
    return 1 + -(-steps // every)


def check_writer(out: str | os.PathLike, name: str = "--out") -> None:
    """Check that a writer for ``out``'s suffix is available, before any simulation.

    Args:
        out: the output file.
        name: how messages name it (the flag, or the Python argument).

    Raises:
        ValueError: an unsupported suffix, or ``.mp4`` without imageio-ffmpeg (the
            message names the ``[video]`` extra).
    """
    suffix = Path(out).suffix.lower()
    if suffix not in VIDEO_SUFFIXES:
        raise ValueError(f"{name} must end in .gif, .mp4 or .png, got {Path(out).name!r}")
    if suffix == ".mp4":
        try:
            import imageio_ffmpeg

            imageio_ffmpeg.get_ffmpeg_exe()
        except (ImportError, RuntimeError, OSError) as exc:
            reason = " ".join(str(exc).split()) or type(exc).__name__
            raise ValueError(
                f"{name} {out}: writing .mp4 needs imageio-ffmpeg, which the [video] extra "
                f"installs ({VIDEO_EXTRA_HINT}), or write a .gif ({reason})"
            ) from None


def parse_beliefs_of(value: str, n_agents: int, name: str = "--beliefs-of") -> list[int] | str:
    """An agent name ``"robot_k"`` -> ``[k]``, ``"all"`` -> ``"all"``, ``"none"`` -> ``[]``.

    Only the env's agent names exactly (``robot_0`` ... ``robot_{N-1}``, no leading
    zeros, no spaces), ``all`` and ``none`` are accepted.

    Args:
        value: the text.
        n_agents: N, the team size.
        name: how messages name the value (the flag, or the Python argument).

    Raises:
        ValueError: another value (naming ``name`` and listing the accepted forms).
    """
    if isinstance(value, str) and value in ("all", "none"):
        return "all" if value == "all" else []
    m = re.fullmatch(r"robot_(0|[1-9][0-9]*)", value) if isinstance(value, str) else None
    if m is None or int(m.group(1)) >= n_agents:
        names = "robot_0" if n_agents <= 1 else f"robot_0 ... robot_{n_agents - 1}"
        raise ValueError(f"{name} must be an agent name ({names}), 'all' or 'none', got {value!r}")
    return [int(m.group(1))]


def _check_beliefs_of(value: Any, n_agents: int) -> list[int] | str:
    """``beliefs_of`` of :func:`render_episode`: an agent name, ``"all"``, ``"none"`` or
    a list of robot indices in ``[0, N - 1]`` (no repeats)."""
    if isinstance(value, str):
        return parse_beliefs_of(value, n_agents, name="beliefs_of")
    names = "robot_0" if n_agents <= 1 else f"robot_0 ... robot_{n_agents - 1}"
    allowed = (
        f"an agent name ({names}), 'all', 'none' or a list of robot indices in [0, {n_agents - 1}]"
    )
    if not isinstance(value, list | tuple):
        raise ConfigError(f"beliefs_of must be {allowed}, got {describe(value)}")
    out = [check_int(f"beliefs_of[{k}]", i, 0, n_agents - 1) for k, i in enumerate(value)]
    if len(set(out)) != len(out):
        raise ConfigError(f"beliefs_of must not repeat a robot, got {describe(value)}")
    return out


def _check_frames(frames: Any) -> list[np.ndarray]:
    if not isinstance(frames, Sequence) or isinstance(frames, str | bytes) or not frames:
        raise ConfigError(
            f"frames must be a non-empty list of uint8 (H, W, 3) arrays, got {describe(frames)}"
        )
    shape = None
    for k, f in enumerate(frames):
        if not (isinstance(f, np.ndarray) and f.dtype == np.uint8 and f.ndim == 3):
            raise ConfigError(f"frames[{k}] must be a uint8 (H, W, 3) array, got {describe(f)}")
        if f.shape[2] != 3 or 0 in f.shape:
            raise ConfigError(f"frames[{k}] must be a uint8 (H, W, 3) array, got shape {f.shape}")
        if shape is None:
            shape = f.shape
        elif f.shape != shape:
            raise ConfigError(
                f"frames must all have the shape of frames[0], {shape}; frames[{k}] has {f.shape}"
            )
    return list(frames)


def save_frames(frames: Sequence[np.ndarray], out: str | os.PathLike, fps: int = 10) -> Path:
    """Write ``frames`` (uint8 (H, W, 3), all one shape) to ``out`` by its suffix: an
    animated .gif or .mp4 of every frame, or a .png of the last frame.

    Args:
        frames: the frames, first to last.
        out: the output file (.gif, .mp4 or .png); its folder is created.
        fps: frames per second of the GIF/MP4, an integer in [1, 100] (a GIF frame lasts
            ``1000 // fps`` ms).

    Raises:
        ValueError: no frames or not uint8 (H, W, 3) arrays of one shape, ``fps`` out
            of range, an unsupported suffix, an ``out`` that cannot be written, or .mp4
            without imageio-ffmpeg; each names the argument.
    """
    frames = _check_frames(frames)
    fps = check_int("fps", fps, 1, MAX_FPS)
    out = check_out_file("out", out, VIDEO_SUFFIXES)
    check_writer(out, "out")
    suffix = out.suffix.lower()
    out.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".png":
        from PIL import Image

        Image.fromarray(frames[-1]).save(out)
    elif suffix == ".gif":
        from PIL import Image

        imgs = [Image.fromarray(f) for f in frames]
        imgs[0].save(out, save_all=True, append_images=imgs[1:], duration=1000 // fps, loop=0)
    else:  # .mp4, writer checked above
        import imageio.v2 as imageio

        imageio.mimwrite(out, frames, fps=fps)
    return out


def _check_frame_budget(steps: int, every: int) -> None:
    """A GIF of ``steps`` steps at ``every`` keeps at most :data:`MAX_RENDER_FRAMES`."""
    n = frame_count(steps, every)
    if n > MAX_RENDER_FRAMES:
        raise ConfigError(
            f"every={every}: an episode of {steps} steps gives {n} frames, kept in memory "
            f"(640 x 640 RGB each: the start, every {every}-th step and the end); at most "
            f"{MAX_RENDER_FRAMES}: raise every to {-(-steps // (MAX_RENDER_FRAMES - 1))} or "
            "lower max_cycles, or write a .mp4 (streamed) or a .png (the final state only)"
        )


def _check_policy(policy: Any) -> str:
    """``policy``: a registered policy name, a trained model (``.zip`` or run folder) or
    an exported set-policy folder."""
    from fov_marl.baselines import available_policies
    from fov_marl.evaluation import is_exported_policy, is_model_path

    if isinstance(policy, os.PathLike):
        policy = os.fspath(policy)
    names = available_policies()
    if not isinstance(policy, str) or not (
        policy in names or is_model_path(policy) or is_exported_policy(policy)
    ):
        raise ConfigError(
            f"policy must be a registered policy {names}, the path of a trained model.zip "
            f"(or its run folder) or an exported set-policy folder, got {describe(policy)}"
        )
    return policy


def _check_filter_kwargs(value: Any, on: bool) -> dict[str, Any] | None:
    """``safety_filter_kwargs``: None or a dict of
    :class:`~fov_marl.wrappers.SafetyFilterWrapper` keywords (the message lists them),
    given only with the filter on (:func:`~fov_marl.validation.check_wrapper_kwargs`)."""
    from fov_marl.wrappers import SafetyFilterWrapper

    return check_wrapper_kwargs("safety_filter_kwargs", value, SafetyFilterWrapper, on=on) or None


class _DrawAfterReset:
    """The policy of the episode, drawing the initial state once it is reset (after the
    env: :func:`fov_marl.evaluation.run_episode` resets the env, then the policy)."""

    def __init__(self, policy: Any, draw: Any) -> None:
        self._policy = policy
        self._draw = draw

    def reset(self, *args: Any, **kwargs: Any) -> Any:
        out = self._policy.reset(*args, **kwargs)
        self._draw()
        return out

    def __getattr__(self, name: str) -> Any:
        return getattr(self._policy, name)


def render_episode(
    scenario: str,
    policy: str | os.PathLike,
    seed: int,
    out: str | os.PathLike,
    safety_filter: bool = False,
    every: int = 5,
    fps: int = 10,
    *,
    beliefs_of: str | list[int] = "robot_0",
    legend: bool = True,
    safety_filter_kwargs: dict[str, Any] | None = None,
    **env_kwargs: Any,
) -> Path:
    """Run one episode and save its frames to ``out`` (.gif/.mp4/.png).

    The frames are the initial state (t = 0 s), the state after every ``every``-th step
    and the final state, always, once, as the last frame (:func:`frame_count`). A .gif
    keeps them in memory until the episode ends, at most :data:`MAX_RENDER_FRAMES`; a
    .mp4 is written frame by frame (an episode that raises leaves no file); a .png
    draws and keeps only the final state. Every argument is checked (a ``ValueError``
    naming it and its range) before the episode runs.

    Args:
        scenario: ``"coverage"`` or ``"crossing"``.
        policy: a registered policy name or the path of a trained ``model.zip`` (its
            config.json gives the config fields not in ``env_kwargs``, and its safety
            filter); ``"learned"`` and an exported folder trained behind the filter run
            behind it (:func:`fov_marl.evaluation.learned_filter`; the shipped
            filter's options unless ``safety_filter_kwargs`` gives others).
        seed: the episode's seed, an integer in [0, 2**31 - 1].
        out: output file ending in .gif, .mp4 or .png; its writer is checked and a trial
            write made before the episode runs (its folder is created).
        safety_filter: run behind :class:`~fov_marl.wrappers.SafetyFilterWrapper`.
        every: draw the state every ``every`` steps, an integer >= 1 (1: every step);
            for a .gif, ``frame_count(max_cycles, every)`` must be at most
            :data:`MAX_RENDER_FRAMES`.
        fps: frames per second of the GIF/MP4, an integer in [1, 100].
        beliefs_of: whose particle filters to draw (``"robot_k"``, one of the env's
            agent names, ``"all"``, ``"none"``, or a list of robot indices in
            [0, N - 1]): the safety filter's trackers when the env is filtered, else the
            policy's (PF+CBF policies); policies without a pipeline that define
            ``draw(canvas)`` draw their own layer.
        legend: draw the legend (a bool).
        safety_filter_kwargs: keywords of the filter
            (:func:`fov_marl.evaluation.make_env`; unknown keys are an error listing
            the valid ones, and so are keys with the filter off); None: its defaults,
            or a trained model's own filter options.
        **env_kwargs: config fields.
    """
    from fov_marl.envs.base import scenario_config
    from fov_marl.envs.rendering import draw_beliefs, frame_title, render_frame
    from fov_marl.evaluation import is_model_path, run_episode

    # every check before the episode (and the model load); the trial write last
    scenario = check_choice("scenario", scenario, ("coverage", "crossing"))
    policy = _check_policy(policy)
    seed = check_int("seed", seed, 0, MAX_SEED)
    safety_filter = check_bool("safety_filter", safety_filter)
    every = check_int("every", every, 1)
    fps = check_int("fps", fps, 1, MAX_FPS)
    legend = check_bool("legend", legend)
    path = check_out_file("out", out, VIDEO_SUFFIXES)
    check_writer(path, "out")
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
    safety_filter_kwargs = _check_filter_kwargs(safety_filter_kwargs, safety_filter)
    cfg = scenario_config(scenario, "render_episode", env_kwargs)  # the env's own check
    chosen = _check_beliefs_of(beliefs_of, cfg.n_agents)
    suffix = path.suffix.lower()
    final_only = suffix == ".png"  # one frame kept
    streamed = suffix == ".mp4"  # each frame written as it is drawn
    if suffix == ".gif":  # Pillow writes a GIF from all its frames at once
        _check_frame_budget(cfg.max_cycles, every)
    # a trial write (a virtual or read-only file system, a folder in the way): the
    # episode never ends in a write error
    check_writable("out", [path])
    frames: list[np.ndarray] = []
    writer: Any = None  # the .mp4's, opened just before the episode
    state: dict[str, Any] = {"layers": [], "beliefs": False, "drawn": -1}

    def draw(env: Any) -> None:
        base = env.unwrapped
        state["drawn"] = base.num_steps
        if final_only:
            frames.clear()  # a .png keeps one frame, whatever the episode's length
        frame = render_frame(
            base.config,
            base.poses,
            base.targets,
            state["layers"],
            title=frame_title(base.config, base.num_steps * base.config.dt_s, label),
            legend=legend,
            beliefs=state["beliefs"],
        )
        if writer is not None:
            writer.append_data(frame)
        else:
            frames.append(frame)

    def factory(env: Any) -> Any:
        pol = factory_base(env)
        owners = [o for o in (env, pol) if getattr(o, "pipeline", None) is not None]
        if owners and chosen:
            pipeline = owners[0].pipeline

            def beliefs_layer(canvas: Any) -> None:
                if pipeline.estimates_view() is not None:
                    draw_beliefs(canvas, pipeline, robots=chosen)

            state["layers"].append(beliefs_layer)
            state["beliefs"] = True
        elif not owners:
            layer = getattr(pol, "draw", None)
            if callable(layer):
                state["layers"].append(layer)
        return _DrawAfterReset(pol, lambda: draw(env))

    def on_step(env: Any, infos: dict) -> None:
        k = env.unwrapped.num_steps
        # the last step (truncation or termination) is always drawn, once; a .png
        # draws only that one
        if (k % every == 0 and not final_only) or not env.agents:
            if state["drawn"] != k:
                draw(env)

    factory.__name__ = label
    if streamed:  # writer checked above; imageio's defaults, as save_frames
        import imageio.v2 as imageio

        writer = imageio.get_writer(path, fps=fps)
    try:
        run_episode(
            scenario,
            factory,
            seed,
            safety_filter=safety_filter,
            on_step=on_step,
            safety_filter_kwargs=safety_filter_kwargs,
            **env_kwargs,
        )
    except BaseException:
        if writer is not None:  # no partial video left behind
            writer.close()
            path.unlink(missing_ok=True)
        raise
    if writer is not None:
        writer.close()
        return path
    return save_frames(frames, path, fps=fps)
