"""Rendering (issue 13): legend, title, beliefs of a chosen robot or all, crossing targets."""

from __future__ import annotations

import numpy as np
import pytest

from fov_marl.config import make_config
from fov_marl.envs.rendering import (
    CROSSING_BACKGROUND,
    frame_title,
    render_frame,
    robot_color,
)

POSES = np.array([[10.0, 10.0, 0.0], [30.0, 30.0, 1.0], [30.0, 10.0, 2.0]])


def _legend_box(frame: np.ndarray) -> np.ndarray:
    return frame[12:160, 420:628]


def test_legend_and_title_are_drawn():
    cfg = make_config(n_agents=3)
    bare = render_frame(cfg, POSES, legend=False, title="")
    full = render_frame(cfg, POSES, title=frame_title(cfg, 12.4, "pfcbf"))
    assert not np.array_equal(_legend_box(bare), _legend_box(full))
    # the legend shows each robot's colour
    box = _legend_box(full).reshape(-1, 3)
    for i in range(3):
        assert np.any(np.all(box == robot_color(i), axis=1)), i
    # the title sits at the top left: dark text pixels there only with a title
    assert (full[12:28, 12:300] < 60).all(axis=-1).sum() > 50
    assert (bare[12:28, 12:300] < 60).all(axis=-1).sum() < 5
    assert frame_title(cfg, 12.4, "pfcbf") == "pfcbf | coverage | N = 3 | beta = 120° | t = 12.4 s"


def test_crossing_frames_show_targets_not_the_density():
    cov = make_config(n_agents=3)
    cross = make_config(scenario="crossing", n_agents=3)
    targets = np.array([[20.0, 20.0], [5.0, 35.0], [35.0, 35.0]])
    f_cov = render_frame(cov, POSES, legend=False, title="")
    f_cross = render_frame(cross, POSES, targets, legend=False, title="")
    c = 320  # the arena centre (q_m) in pixels: warm in coverage, plain floor in crossing
    corner = f_cross[40, 200]
    assert f_cov[c + 30, c + 30, 2] < 200  # the density's warm colour (low blue)
    assert tuple(corner) == CROSSING_BACKGROUND
    # robot 0's target at the centre is drawn in its colour
    patch = f_cross[c - 12 : c + 12, c - 12 : c + 12].reshape(-1, 3)
    assert np.any(np.all(patch == robot_color(0), axis=1))


@pytest.mark.parametrize("beliefs", ["robot_1", "all", "none"])
def test_beliefs_of_a_chosen_robot_or_all(beliefs, tmp_path):
    from PIL import Image

    from fov_marl.video import render_episode

    out = tmp_path / f"{beliefs}.png"
    render_episode("coverage", "pfcbf", 0, out, every=5, beliefs_of=beliefs, n_agents=3,
                   max_cycles=10, fov_deg=360.0)  # fmt: skip
    frame = np.asarray(Image.open(out).convert("RGB"))
    _BELIEF_PIXELS[beliefs] = frame
    if len(_BELIEF_PIXELS) == 3:
        diff = {
            k: int((v != _BELIEF_PIXELS["none"]).any(-1).sum()) for k, v in _BELIEF_PIXELS.items()
        }
        assert diff["none"] == 0 < diff["robot_1"] < diff["all"]


_BELIEF_PIXELS: dict[str, np.ndarray] = {}


def test_beliefs_of_checks_the_robot():
    from fov_marl.video import parse_beliefs_of

    assert parse_beliefs_of("robot_2", 3) == [2]
    assert parse_beliefs_of("all", 3) == "all" and parse_beliefs_of("none", 3) == []
    for bad in ("robot_3", "robot", "2", "ALL", "", "robot_01", " robot_1", "robot_1\n"):
        with pytest.raises(ValueError, match="--beliefs-of"):
            parse_beliefs_of(bad, 3)
