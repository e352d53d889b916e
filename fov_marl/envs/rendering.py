"""Headless rendering with Pillow; a window (matplotlib) only in ``"human"`` mode.

A frame shows the arena, FoV sectors, robots with their heading and ID, a title
(policy, N, β, simulated time) and a legend. Coverage frames add the density φ as a
heat map and the sensing disks; crossing frames show no density but each robot's
target (a cross inside the arrival tolerance circle, and a faint line from the
robot to it). Policies draw their own layers (particles, ellipses, Voronoi cells)
through :class:`Canvas`, in world coordinates: register a callable with
``env.add_render_layer(fn)``; it is called as ``fn(canvas)`` on every frame after the
built-in layers. :func:`draw_beliefs` draws the particle filters of chosen robots
(``fov-marl render --beliefs-of robot_k|all|none``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from PIL import Image, ImageDraw, ImageFont

__all__ = [
    "Canvas",
    "RenderLayer",
    "robot_color",
    "render_frame",
    "draw_beliefs",
    "frame_title",
    "LegendEntry",
    "CROSSING_BACKGROUND",
]

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


#: RGB of the arena floor in crossing frames (no density there)
CROSSING_BACKGROUND = (250, 250, 250)
#: one legend row: (symbol, RGB colour, label); symbols: "robot", "sector", "disk",
#: "cross", "dots", "ellipse"
LegendEntry = tuple[str, tuple[int, int, int], str]

_FONTS: dict[int, object] = {}


def _font(size: int):
    """Pillow's bundled FreeType font at ``size`` px (the bitmap font without FreeType)."""
    if size not in _FONTS:
        try:
            _FONTS[size] = ImageFont.load_default(size=size)
        except (TypeError, ImportError, OSError):  # Pillow < 10.1 or no FreeType
            _FONTS[size] = ImageFont.load_default()
    return _FONTS[size]


def frame_title(config, t_s: float | None = None, policy: str | None = None) -> str:
    """``"pfcbf | N = 6 | beta = 120° | t = 12.4 s"`` (parts that are None left out;
    "beta" spelled out: the bundled font has no Greek letters)."""
    parts = [policy] if policy else []
    parts += [f"{config.scenario}", f"N = {config.n_agents}", f"beta = {config.fov_deg:g}°"]
    if t_s is not None:
        parts.append(f"t = {t_s:.1f} s")
    return " | ".join(parts)


def _default_legend(config, n_robots: int, beliefs: bool) -> list[LegendEntry]:
    grey = (90, 90, 90)
    entries: list[LegendEntry] = []
    shown = min(n_robots, 6)
    for i in range(shown):
        entries.append(("robot", robot_color(i), f"robot {i}"))
    if n_robots > shown:
        entries.append(("robot", grey, f"... {n_robots - shown} more"))
    entries.append(("sector", grey, f"FoV {config.fov_deg:g}°, R_d {config.detection_range_m:g} m"))
    if config.scenario == "coverage":
        entries.append(("disk", grey, f"sensing R_s {config.sensing_radius_m:g} m"))
        entries.append(("heat", (250, 170, 60), "density phi"))
    else:
        entries.append(("cross", grey, "target (colour of its robot)"))
    if beliefs:
        entries.append(("dots", grey, "particles (colour of the neighbour)"))
        entries.append(("ellipse", grey, "95% ellipse"))
    return entries


def _draw_legend(canvas: Canvas, entries: Sequence[LegendEntry]) -> None:
    """Rows of symbol + label in a translucent box at the top right of the frame."""
    if not entries:
        return
    font = _font(11)
    d = canvas.draw
    row_h, sym_w, pad = 14, 16, 4
    text_w = max(int(d.textlength(lab, font=font)) for _, _, lab in entries)
    w = pad * 3 + sym_w + text_w
    h = pad * 2 + row_h * len(entries)
    x0 = canvas.size_px - canvas.margin - w - 2
    y0 = canvas.margin + 2
    d.rectangle([x0, y0, x0 + w, y0 + h], fill=(255, 255, 255, 215), outline=(120, 120, 120))
    for k, (sym, col, label) in enumerate(entries):
        cy = y0 + pad + row_h * k + row_h / 2
        sx = x0 + pad
        if sym == "robot":
            d.ellipse([sx + 3, cy - 5, sx + 13, cy + 5], fill=col, outline=(0, 0, 0))
        elif sym == "sector":
            d.pieslice([sx - 4, cy - 10, sx + 20, cy + 14], 290, 350, fill=col + (130,))
        elif sym == "disk":
            d.ellipse([sx + 2, cy - 6, sx + 14, cy + 6], outline=col, width=1)
        elif sym == "heat":
            d.rectangle([sx + 2, cy - 5, sx + 14, cy + 5], fill=col)
        elif sym == "cross":
            d.line([sx + 3, cy - 5, sx + 13, cy + 5], fill=col, width=2)
            d.line([sx + 3, cy + 5, sx + 13, cy - 5], fill=col, width=2)
        elif sym == "dots":
            for dx, dy in ((4, -3), (9, 2), (12, -2), (6, 4)):
                d.ellipse([sx + dx - 1, cy + dy - 1, sx + dx + 1, cy + dy + 1], fill=col)
        elif sym == "ellipse":
            d.ellipse([sx + 1, cy - 4, sx + 15, cy + 4], outline=col, width=2)
        d.text((sx + sym_w + pad, cy - 6), label, fill=(20, 20, 20), font=font)


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
    *,
    title: str | None = None,
    legend: bool | Sequence[LegendEntry] = True,
    beliefs: bool = False,
) -> np.ndarray:
    """Draw one frame.

    Args:
        config: the env's :class:`~fov_marl.config.ScenarioConfig`.
        poses_world: ``(N, 3)`` ground-truth poses [x m, y m, yaw rad].
        targets_world: ``(N, 2)`` crossing targets (world, m) or ``None``.
        layers: extra callables ``fn(canvas)`` drawn after the built-in layers.
        size_px: side of the square frame in pixels.
        caption: appended to the default title (the env passes ``"t = ... s"``).
        title: the title line at the top left; ``None``: :func:`frame_title` (scenario,
            N, β) followed by ``caption``.
        legend: ``True`` for the default legend (robot colours, FoV sector, sensing
            disk and density or targets, beliefs when ``beliefs``), ``False`` for
            none, or the :data:`LegendEntry` rows to show.
        beliefs: the frame shows particle-filter beliefs (adds their legend rows).

    Returns:
        ``(size_px, size_px, 3)`` uint8 RGB frame.
    """
    canvas = Canvas(size_px, config.arena_size_m)
    L = config.arena_size_m
    if config.scenario == "coverage":
        heat = _heat_map(size_px, canvas.margin, L, config.density_mean_m, config.density_sigma_m)
        canvas.image.paste(Image.fromarray(heat))
    else:  # crossing: no density; the targets are what matters
        canvas.draw.rectangle([0, 0, size_px, size_px], fill=(235, 235, 235))
        lo, hi = canvas.to_px(np.array([0.0, L])), canvas.to_px(np.array([L, 0.0]))
        canvas.draw.rectangle([lo[0], lo[1], hi[0], hi[1]], fill=CROSSING_BACKGROUND)
    canvas.polygon(np.array([[0, 0], [L, 0], [L, L], [0, L]]), outline=(60, 60, 60), width=2)
    for i, pose in enumerate(poses_world):
        col = robot_color(i)
        canvas.sector(pose, config.fov_rad, config.detection_range_m, fill=col + (28,))
        if config.scenario == "coverage":
            canvas.circle(pose[:2], config.sensing_radius_m, outline=col + (150,))
    if targets_world is not None:
        tol = float(getattr(config, "target_tolerance_m", 0.5))
        for i, t in enumerate(np.asarray(targets_world, dtype=np.float64)):
            col = robot_color(i)
            if i < len(poses_world):
                canvas.line(poses_world[i][:2], t, col + (90,), width=1)
            canvas.circle(t, max(tol, 0.6), outline=col, fill=col + (40,), width=2)
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
    if title is None:
        title = frame_title(config) + (f" | {caption.strip()}" if caption.strip() else "")
    if title:
        font = _font(13)
        x, y = canvas.margin + 4, canvas.margin + 3
        w = canvas.draw.textlength(title, font=font)
        canvas.draw.rectangle([x - 2, y - 1, x + w + 3, y + 15], fill=(255, 255, 255, 200))
        canvas.draw.text((x, y), title, fill=(0, 0, 0), font=font)
    if legend is True:
        _draw_legend(canvas, _default_legend(config, len(poses_world), beliefs))
    elif legend:
        _draw_legend(canvas, legend)
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
    canvas: Canvas, pipeline, robots: Sequence[int] | str = (0,), particles: bool = True
) -> None:
    """Draw robots' beliefs from a :class:`fov_marl.pipeline.PfCbfPipeline`: particles and
    95% ellipses, coloured by neighbour, placed with each robot's own pose estimate.

    Args:
        canvas: the frame.
        pipeline: duck-typed (``bank``, ``own_pose``, ``estimates_view``) so the env
            layer does not import the controller layer.
        robots: indices of the robots whose beliefs are drawn, or ``"all"``.
        particles: draw the particles (at most ~1500 per robot), not only the ellipses.
    """
    from fov_marl.geometry import body_to_world

    est = pipeline.estimates_view()
    if est is None:
        return
    n = len(pipeline.own_pose)
    chosen = range(n) if isinstance(robots, str) and robots == "all" else robots
    for i in chosen:
        i = int(i)
        if not 0 <= i < n:
            raise ValueError(f"robots must be indices in [0, {n - 1}] or 'all', got {i}")
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
