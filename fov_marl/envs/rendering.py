"""Headless rendering with Pillow; a window (matplotlib) only in ``"human"`` mode.

A frame shows the arena, the density φ as a heat map, sensing disks, FoV sectors,
robots with their heading and ID, and crossing targets. Policies draw their own
layers (particles, ellipses, Voronoi cells) through :class:`Canvas`, in world
coordinates: register a callable with ``env.add_render_layer(fn)``; it is called
as ``fn(canvas)`` on every frame after the built-in layers.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from PIL import Image, ImageDraw

__all__ = ["Canvas", "RenderLayer", "robot_color", "render_frame", "draw_beliefs"]

RenderLayer = Callable[["Canvas"], None]

_PALETTE = [
    (31, 119, 180),
    (214, 39, 40),
    (44, 160, 44),
    (148, 103, 189),
    (255, 127, 14),
    (23, 190, 207),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
]


def robot_color(i: int) -> tuple[int, int, int]:
    """Stable RGB colour of robot ``i``."""
    return _PALETTE[i % len(_PALETTE)]


class Canvas:
    """A Pillow image with world-coordinate drawing helpers (y axis up).

    Attributes:
        image: the RGB ``PIL.Image``.
        draw: its ``ImageDraw`` (RGBA blending enabled).
        scale: pixels per metre.
    """

    def __init__(self, size_px: int, arena_size_m: float, margin_px: int = 10) -> None:
        self.size_px = size_px
        self.margin = margin_px
        self.arena_size_m = arena_size_m
        self.scale = (size_px - 2 * margin_px) / arena_size_m
        self.image = Image.new("RGB", (size_px, size_px), (255, 255, 255))
        self.draw = ImageDraw.Draw(self.image, "RGBA")

    def to_px(self, p_world: np.ndarray) -> np.ndarray:
        """``(..., 2)`` world metres -> pixel coordinates (float)."""
        p = np.asarray(p_world, dtype=np.float64)
        x = self.margin + p[..., 0] * self.scale
        y = self.size_px - self.margin - p[..., 1] * self.scale
        return np.stack([x, y], -1)

    def circle(self, c_world, r_m: float, outline=None, fill=None, width: int = 1) -> None:
        x, y = self.to_px(c_world)
        r = r_m * self.scale
        self.draw.ellipse([x - r, y - r, x + r, y + r], outline=outline, fill=fill, width=width)

    def points(self, p_world: np.ndarray, color, radius_px: float = 1.0) -> None:
        """Many small dots (e.g. particles), ``(K, 2)`` world points."""
        for x, y in self.to_px(np.asarray(p_world).reshape(-1, 2)):
            self.draw.ellipse(
                [x - radius_px, y - radius_px, x + radius_px, y + radius_px], fill=color
            )

    def line(self, a_world, b_world, color, width: int = 1) -> None:
        self.draw.line(
            [tuple(self.to_px(a_world)), tuple(self.to_px(b_world))], fill=color, width=width
        )

    def polygon(self, p_world: np.ndarray, outline=None, fill=None, width: int = 1) -> None:
        pts = [tuple(p) for p in self.to_px(np.asarray(p_world).reshape(-1, 2))]
        if len(pts) >= 3:
            self.draw.polygon(pts, outline=outline, fill=fill, width=width)

    def ellipse(
        self, c_world, a_m: float, b_m: float, psi_rad: float, outline, width: int = 1, n: int = 48
    ) -> None:
        """Rotated ellipse with semi-axes ``a_m``, ``b_m`` and inclination ``psi_rad``."""
        t = np.linspace(0.0, 2.0 * np.pi, n)
        c, s = math.cos(psi_rad), math.sin(psi_rad)
        ex, ey = a_m * np.cos(t), b_m * np.sin(t)
        pts = np.column_stack([c * ex - s * ey, s * ex + c * ey]) + np.asarray(c_world)
        self.draw.line([tuple(p) for p in self.to_px(pts)], fill=outline, width=width)

    def sector(self, pose_world, fov_rad: float, range_m: float, fill, outline=None) -> None:
        """The FoV sector of a robot at ``pose_world`` ``[x, y, yaw]``."""
        x, y, yaw = (float(v) for v in pose_world)
        if fov_rad >= 2 * math.pi:
            self.circle((x, y), range_m, outline=outline, fill=fill)
            return
        t = np.linspace(yaw - fov_rad / 2, yaw + fov_rad / 2, 33)
        pts = np.vstack(
            [[x, y], np.column_stack([x + range_m * np.cos(t), y + range_m * np.sin(t)])]
        )
        self.polygon(pts, outline=outline, fill=fill)

    def text(self, p_world, s: str, color=(0, 0, 0)) -> None:
        x, y = self.to_px(p_world)
        self.draw.text((x + 4, y - 12), s, fill=color)


_HEAT_CACHE: dict[tuple, np.ndarray] = {}


def _heat_map(size_px: int, margin: int, L: float, q_m, sigma: float) -> np.ndarray:
    key = (size_px, margin, L, tuple(q_m), sigma)
    if key not in _HEAT_CACHE:
        scale = (size_px - 2 * margin) / L
        px = (np.arange(size_px) + 0.5 - margin) / scale
        x = px[None, :]
        y = ((size_px - margin) - (np.arange(size_px) + 0.5))[:, None] / scale
        phi = np.exp(-((x - q_m[0]) ** 2 + (y - q_m[1]) ** 2) / (2 * sigma**2))
        inside = (x >= 0) & (x <= L) & (y >= 0) & (y <= L)
        phi = np.where(inside, phi, 0.0)
        white = np.array([255.0, 255.0, 255.0])
        warm = np.array([250.0, 170.0, 60.0])
        img = white + phi[..., None] * (warm - white)
        img[~inside] = (235, 235, 235)
        _HEAT_CACHE[key] = img.astype(np.uint8)
    return _HEAT_CACHE[key]


def render_frame(
    config,
    poses_world: np.ndarray,
    targets_world: np.ndarray | None = None,
    layers: Sequence[RenderLayer] = (),
    size_px: int = 640,
    caption: str = "",
) -> np.ndarray:
    """Draw one frame.

    Args:
        config: the env's :class:`~fov_marl.config.ScenarioConfig`.
        poses_world: ``(N, 3)`` ground-truth poses.
        targets_world: ``(N, 2)`` crossing targets or ``None``.
        layers: extra callables ``fn(canvas)`` drawn last.

    Returns:
        ``(size_px, size_px, 3)`` uint8 RGB frame.
    """
    canvas = Canvas(size_px, config.arena_size_m)
    heat = _heat_map(
        size_px, canvas.margin, config.arena_size_m, config.density_mean_m, config.density_sigma_m
    )
    canvas.image.paste(Image.fromarray(heat))
    L = config.arena_size_m
    canvas.polygon(np.array([[0, 0], [L, 0], [L, L], [0, L]]), outline=(60, 60, 60), width=2)
    for i, pose in enumerate(poses_world):
        col = robot_color(i)
        canvas.sector(pose, config.fov_rad, config.detection_range_m, fill=col + (28,))
        if config.scenario == "coverage":
            canvas.circle(pose[:2], config.sensing_radius_m, outline=col + (150,))
    if targets_world is not None:
        for i, t in enumerate(targets_world):
            col = robot_color(i)
            canvas.line(t - [0.6, 0.6], t + [0.6, 0.6], col, width=3)
            canvas.line(t + [-0.6, 0.6], t + [0.6, -0.6], col, width=3)
    for layer in layers:
        layer(canvas)
    for i, pose in enumerate(poses_world):
        col = robot_color(i)
        canvas.circle(pose[:2], config.robot_radius_m, outline=(0, 0, 0), fill=col, width=1)
        head = pose[:2] + 1.5 * np.array([math.cos(pose[2]), math.sin(pose[2])])
        canvas.line(pose[:2], head, (0, 0, 0), width=2)
        canvas.text(pose[:2], str(i))
    if caption:
        canvas.draw.text((canvas.margin + 4, canvas.margin + 2), caption, fill=(0, 0, 0))
    return np.asarray(canvas.image, dtype=np.uint8).copy()


class HumanWindow:
    """A matplotlib window showing frames; created only in ``render_mode="human"``."""

    def __init__(self, title: str) -> None:
        import matplotlib.pyplot as plt

        self._plt = plt
        self.fig, self.ax = plt.subplots(num=title)
        self.ax.set_axis_off()
        self.im = None
        self.interactive = plt.get_backend().lower() not in ("agg", "pdf", "svg", "ps", "cairo")

    def show(self, frame: np.ndarray, fps: float) -> None:
        if self.im is None:
            self.im = self.ax.imshow(frame)
        else:
            self.im.set_data(frame)
        if self.interactive:
            self._plt.pause(1.0 / fps)
        else:
            self.fig.canvas.draw()

    def close(self) -> None:
        self._plt.close(self.fig)


def draw_beliefs(
    canvas: Canvas, pipeline, robots: Sequence[int] = (0,), particles: bool = True
) -> None:
    """Draw robots' beliefs from a :class:`fov_marl.pipeline.PfCbfPipeline`: particles and
    95% ellipses, coloured by neighbour, placed with each robot's own pose estimate.

    Duck-typed on the pipeline (``bank``, ``own_pose``, ``estimates_view``) so the env
    layer does not import the controller layer.
    """
    from fov_marl.geometry import body_to_world

    est = pipeline.estimates_view()
    if est is None:
        return
    for i in robots:
        pose = pipeline.own_pose[i]
        bank = pipeline.bank
        if particles and bank is not None:
            p_body, owner = bank.particles_body(i)
            pw = body_to_world(p_body, pose)
            step = max(1, len(pw) // 1500)
            pw, owner = pw[::step], owner[::step]
            for j in np.unique(owner):
                canvas.points(pw[owner == j], robot_color(int(j)) + (110,), radius_px=0.8)
        if "ellipse_a" in est:
            for k, j in enumerate(est["ids"][i]):
                c = body_to_world(est["mean_body"][i, k], pose)
                canvas.ellipse(
                    c,
                    float(est["ellipse_a"][i, k]),
                    float(est["ellipse_b"][i, k]),
                    float(est["ellipse_psi"][i, k] + pose[2]),
                    outline=robot_color(int(j)) + (220,),
                    width=2,
                )
