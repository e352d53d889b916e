"""``fov_marl.video``: every argument checked before the episode, the frames kept (t = 0,
every k-th step, the final state last), an output the OS cannot write refused up front
(red team 7: F3, F6, F7)."""

from __future__ import annotations

import os

import numpy as np
import pytest

import fov_marl.envs.rendering
import fov_marl.evaluation
from fov_marl.video import frame_count, parse_beliefs_of, render_episode, save_frames

TINY = {"n_agents": 2, "max_cycles": 10}


@pytest.fixture
def no_episode(monkeypatch):
    """Fail the test if an episode starts: the checks must come first."""

    def no_work(*args, **kwargs):
        raise AssertionError("the episode ran before the arguments were checked")

    monkeypatch.setattr(fov_marl.evaluation, "run_episode", no_work)


@pytest.mark.parametrize(
    ("kwargs", "says"),
    [
        ({"fps": 0}, "fps must be an integer in [1, 100], got 0"),
        ({"fps": -5}, "fps must be an integer in [1, 100], got -5"),
        ({"fps": 5000}, "fps must be an integer in [1, 100], got 5000"),
        ({"fps": None}, "fps must be an integer in [1, 100], got None"),
        ({"fps": 10.0}, "fps must be an integer in [1, 100], got 10.0"),
        ({"every": 0}, "every must be an integer in [1, inf), got 0"),
        ({"every": -1}, "every must be an integer in [1, inf), got -1"),
        ({"every": 1.5}, "every must be an integer in [1, inf), got 1.5"),
        ({"every": None}, "every must be an integer in [1, inf), got None"),
        ({"seed": -1}, "seed must be an integer in [0, 2147483647], got -1"),
        ({"scenario": "maze"}, "scenario must be one of ('coverage', 'crossing')"),
        ({"policy": None}, "policy must be a registered policy ["),
        ({"policy": "nope"}, "policy must be a registered policy ["),
        ({"legend": "no"}, "legend must be a bool (True or False), got 'no'"),
        ({"safety_filter": 1}, "safety_filter must be a bool"),
        ({"out": None}, "out must be a file path, got None"),
        ({"out": "episode.txt"}, "out must end in .gif, .mp4, .png"),
        ({"beliefs_of": 5}, "beliefs_of must be an agent name (robot_0 ... robot_1)"),
        ({"beliefs_of": "robot_2"}, "beliefs_of must be an agent name (robot_0 ... robot_1)"),
        ({"beliefs_of": [2]}, "beliefs_of[0] must be an integer in [0, 1], got 2"),
        ({"n_agents": 0}, "n_agents"),
        (
            {"safety_filter": True, "safety_filter_kwargs": {"foo": 1}},
            "unknown safety_filter_kwargs ['foo']; valid safety_filter_kwargs are [",
        ),
        ({"safety_filter": True, "safety_filter_kwargs": 3}, "safety_filter_kwargs must be a dict"),
        (
            {"safety_filter_kwargs": {"init": "known"}},
            "safety_filter_kwargs ['init'] need safety_filter=True",
        ),
    ],
)
def test_bad_arguments_are_value_errors_before_the_episode(kwargs, says, tmp_path, no_episode):
    """F6: ZeroDivisionError / OverflowError / TypeError after the episode, or silently
    accepted (every=-1 kept every frame, every=1.5 every third, fps=5000 wrote 0 ms
    frames), before the fix."""
    base = {"scenario": "coverage", "policy": "random", "seed": 0, "out": tmp_path / "e.gif"}
    with pytest.raises(ValueError) as exc:
        render_episode(**{**base, **TINY, **kwargs})
    assert says in str(exc.value)
    assert not (tmp_path / "e.gif").exists()


def test_unknown_filter_keys_list_the_valid_ones(tmp_path, no_episode):
    with pytest.raises(ValueError, match="unknown safety_filter_kwargs") as exc:
        render_episode(
            "coverage",
            "random",
            0,
            tmp_path / "e.gif",
            safety_filter=True,
            safety_filter_kwargs={"foo": 1},
            **TINY,
        )
    assert "controller_params" in str(exc.value) and "tracker_params" in str(exc.value)


@pytest.mark.parametrize("out", ["/proc/episode.gif", "/sys/episode.png"])
def test_an_output_the_os_cannot_write_is_refused_before_the_episode(out, no_episode):
    """F3: os.access says yes (always, for root) but /proc and /sys take no new file:
    the error came after the whole episode and did not name the argument."""
    if not os.path.isdir(os.path.dirname(out)):
        pytest.skip("needs Linux's /proc and /sys")
    with pytest.raises(ValueError) as exc:
        render_episode("coverage", "random", 0, out, **TINY)
    text = str(exc.value)
    assert text.startswith("out") and out in text, text


def test_save_frames_checks_its_arguments(tmp_path):
    frame = np.zeros((8, 8, 3), np.uint8)
    for fps in (0, -1, 101, 2.5, None):
        with pytest.raises(ValueError, match=r"fps must be an integer in \[1, 100\]"):
            save_frames([frame], tmp_path / "a.gif", fps=fps)
    with pytest.raises(ValueError, match="frames must be a non-empty list"):
        save_frames([], tmp_path / "a.gif")
    with pytest.raises(ValueError, match=r"frames\[1\] must be a uint8 \(H, W, 3\) array"):
        save_frames([frame, frame.astype(float)], tmp_path / "a.gif")
    with pytest.raises(ValueError, match="frames must all have the shape of frames"):
        save_frames([frame, np.zeros((4, 4, 3), np.uint8)], tmp_path / "a.gif")
    with pytest.raises(ValueError, match="out must end in"):
        save_frames([frame], tmp_path / "a.bmp")
    assert not list(tmp_path.iterdir())
    from PIL import Image

    with Image.open(save_frames([frame, frame + 1], tmp_path / "a.gif", fps=100)) as im:
        assert im.n_frames == 2 and im.info["duration"] == 10


@pytest.fixture
def titles(monkeypatch):
    """The titles (and frames) of every frame render_episode draws, in order."""
    seen: list[tuple[str, np.ndarray]] = []
    real = fov_marl.envs.rendering.render_frame

    def spy(*args, **kwargs):
        frame = real(*args, **kwargs)
        seen.append((kwargs["title"], frame))
        return frame

    monkeypatch.setattr(fov_marl.envs.rendering, "render_frame", spy)
    return seen


def _times(seen) -> list[str]:
    return [t.rsplit("|", 1)[-1].strip() for t, _ in seen]


@pytest.mark.parametrize(
    ("steps", "every", "times"),
    [
        (10, 5, ["t = 0.0 s", "t = 1.0 s", "t = 2.0 s"]),
        (12, 5, ["t = 0.0 s", "t = 1.0 s", "t = 2.0 s", "t = 2.4 s"]),
        (3, 1, ["t = 0.0 s", "t = 0.2 s", "t = 0.4 s", "t = 0.6 s"]),
        (4, 50, ["t = 0.0 s", "t = 0.8 s"]),
    ],
)
def test_frames_are_the_start_every_kth_step_and_the_final_state(
    steps, every, times, titles, tmp_path
):
    """F7: the first frame was t = 0.2 s and the final state was drawn only when
    (steps - 1) % every == 0 (a 10-step episode at every=5 ended its GIF at 1.8 s)."""
    from PIL import Image

    out = render_episode(
        "coverage", "random", 0, tmp_path / "e.gif", every=every, n_agents=2, max_cycles=steps
    )
    assert _times(titles) == times
    assert len(times) == frame_count(steps, every)
    with Image.open(out) as im:
        assert im.n_frames == len(times)


def test_the_png_is_the_final_state(titles, tmp_path):
    """F7: 'a PNG of the last frame' showed t = 1.2 s of a 2.0 s episode. A PNG draws
    only the start (at reset) and the final state: it keeps one frame."""
    from PIL import Image

    out = render_episode("crossing", "pfcbf", 0, tmp_path / "e.png", every=4, **TINY)
    assert _times(titles) == ["t = 0.0 s", "t = 2.0 s"]
    png = np.asarray(Image.open(out).convert("RGB"))
    np.testing.assert_array_equal(png, titles[-1][1])


def test_a_png_has_no_frame_cap(titles, tmp_path):
    """A PNG keeps one frame, so an episode longer than the GIF/MP4 frame cap renders at
    every=1 (the cap was the CLI's only, and counted a PNG's frames as a GIF's)."""
    from fov_marl.video import MAX_RENDER_FRAMES

    steps = MAX_RENDER_FRAMES + 4
    render_episode(
        "coverage", "random", 0, tmp_path / "e.png", every=1, n_agents=2, max_cycles=steps
    )
    assert _times(titles) == ["t = 0.0 s", f"t = {steps * 0.2:.1f} s"]


def test_a_gif_over_the_frame_cap_is_refused_before_the_episode(tmp_path, no_episode):
    """render_episode kept every frame of any episode (1.2 MB each): the cap was only the
    CLI's. 1000 steps at every=1 keep 1001 frames (the cap); 1001 steps keep 1002."""
    from fov_marl.video import MAX_RENDER_FRAMES

    assert MAX_RENDER_FRAMES == frame_count(1000, 1) == 1001
    with pytest.raises(
        ValueError,
        match=r"every=1: an episode of 1001 steps gives 1002 frames, .* raise every to 2 or "
        r"lower max_cycles, or write a \.mp4 \(streamed\) or a \.png",
    ):
        render_episode(
            "coverage", "random", 0, tmp_path / "e.gif", every=1, n_agents=2, max_cycles=1001
        )
    with pytest.raises(AssertionError, match="the episode ran"):  # at the cap: it starts
        render_episode(
            "coverage", "random", 0, tmp_path / "e.gif", every=1, n_agents=2, max_cycles=1000
        )


def test_an_mp4_is_streamed_past_the_frame_cap(titles, tmp_path, monkeypatch):
    """An .mp4 is written frame by frame: no cap, and every frame drawn is in the file
    (a cap of 3 frames here, an episode of 9 frames)."""
    pytest.importorskip("imageio_ffmpeg")
    import imageio.v2 as imageio

    import fov_marl.video

    monkeypatch.setattr(fov_marl.video, "MAX_RENDER_FRAMES", 3)
    with pytest.raises(ValueError, match="gives 9 frames"):  # the cap is the GIF's
        render_episode(
            "coverage", "random", 0, tmp_path / "e.gif", every=1, **{**TINY, "max_cycles": 8}
        )
    out = render_episode(
        "coverage", "random", 0, tmp_path / "e.mp4", every=1, **{**TINY, "max_cycles": 8}
    )
    assert len(titles) == 9
    with imageio.get_reader(out) as reader:
        assert reader.count_frames() == 9


def test_an_mp4_episode_that_fails_leaves_no_file(tmp_path, monkeypatch):
    pytest.importorskip("imageio_ffmpeg")
    real = fov_marl.envs.rendering.render_frame
    calls = []

    def fail_on_third(*args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            raise RuntimeError("boom")
        return real(*args, **kwargs)

    monkeypatch.setattr(fov_marl.envs.rendering, "render_frame", fail_on_third)
    out = tmp_path / "e.mp4"
    with pytest.raises(RuntimeError, match="boom"):
        render_episode("coverage", "random", 0, out, every=1, **TINY)
    assert not out.exists() and not list(tmp_path.iterdir())


def test_frames_behind_the_safety_filter(titles, tmp_path):
    render_episode(
        "coverage",
        "random",
        0,
        tmp_path / "e.gif",
        safety_filter=True,
        every=3,
        beliefs_of=[1],
        n_agents=2,
        max_cycles=7,
    )
    assert _times(titles) == ["t = 0.0 s", "t = 0.6 s", "t = 1.2 s", "t = 1.4 s"]


def test_frame_count():
    assert [frame_count(s, e) for s, e in [(0, 1), (1, 1), (10, 5), (12, 5), (1000, 1)]] == [
        1,
        2,
        3,
        4,
        1001,
    ]
    with pytest.raises(ValueError, match="every must be an integer"):
        frame_count(10, 0)


def test_beliefs_of_takes_only_the_env_agent_names():
    """Cosmetic: robot_01 was robot 1; only the env's names, exactly."""
    assert parse_beliefs_of("robot_0", 3) == [0] and parse_beliefs_of("robot_10", 11) == [10]
    for bad in ("robot_01", "robot_00", " robot_1", "robot_1 ", "robot_+1", "robot_١"):
        with pytest.raises(ValueError) as exc:
            parse_beliefs_of(bad, 3)
        assert str(exc.value) == (
            f"--beliefs-of must be an agent name (robot_0 ... robot_2), 'all' or 'none', "
            f"got {bad!r}"
        )
    with pytest.raises(ValueError, match=r"an agent name \(robot_0\), 'all' or 'none'"):
        parse_beliefs_of("robot_1", 1)
