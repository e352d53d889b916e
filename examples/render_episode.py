"""Render a crossing episode to a GIF with every robot's beliefs drawn.

python examples/render_episode.py            # writes crossing.gif in the current folder
"""

from __future__ import annotations

from pathlib import Path

from _common import steps

from fov_marl.video import render_episode


def main() -> None:
    out = render_episode(
        "crossing",
        "pfcbf",
        seed=0,
        out=Path("crossing.gif"),
        every=5,
        beliefs_of="all",
        max_cycles=steps(250),
    )
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
