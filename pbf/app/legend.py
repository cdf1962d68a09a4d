"""The colour legend: what the particles' colours mean, as a bar with its range and unit.

Drawn onto headless frames when ``render.legend`` is set (the command line's ``--colour-by`` sets it),
and written as a line in the window's panel. Pillow draws the legend once per scene and frame size (a
font rasteriser is not something to write by hand) into a small picture with its own transparency;
each frame then only blends that picture into its corner.
"""

import functools
from pathlib import Path

import matplotlib
import numpy as np
from PIL import Image, ImageDraw, ImageFont

from pbf.scene import Render

BAR_PX = (16, 160)
"""Width and height of the colour bar, pixels (scaled down on small images)."""
MARGIN_PX = 12
FONT_PX = 12
"""The labels' font size, pixels (scaled down on small images, to no less than 8)."""
FONT_FILE = Path(matplotlib.get_data_path()) / "fonts" / "ttf" / "DejaVuSans.ttf"
"""Matplotlib's DejaVu Sans: it has the labels' ρ and minus sign, which Pillow's built-in bitmap font
draws as empty boxes."""


def legend_range(render: Render) -> tuple[str, str, str]:
    """What the colour shows and the labels of the bar's bottom and top."""
    if render.colour_by == "speed":
        return "speed", "0 m/s", f"{render.speed_max_m_s:g} m/s"
    span = render.density_error_max * 100
    return "density ρ/ρ0 − 1", f"−{span:g}%", f"+{span:g}%"


def legend_line(render: Render) -> str:
    """The legend as one line of text for the window's panel."""
    quantity, low, high = legend_range(render)
    return f"colour: {quantity}, {render.colour_map} from {low} to {high}"


def legend_font(height: int) -> ImageFont.FreeTypeFont:
    """The labels' font for frames ``height`` pixels high."""
    return ImageFont.truetype(str(FONT_FILE), max(8, round(FONT_PX * min(1.0, height / 360))))


@functools.lru_cache(maxsize=16)
def legend_picture(
    labels: tuple[str, str, str], colour_map: str, ink: tuple[int, int, int], height: int, width: int
) -> tuple[int, int, np.ndarray, np.ndarray]:
    """The legend of a frame ``height`` × ``width``: its top and left pixel, its colours (h, w, 3) and
    its opacity (h, w, 1), both float32 in [0, 255] and [0, 1]."""
    scale = min(1.0, height / 360)
    bar_w, bar_h = max(4, round(BAR_PX[0] * scale)), max(16, round(BAR_PX[1] * scale))
    margin = max(4, round(MARGIN_PX * scale))
    font = legend_font(height)
    quantity, low, high = labels
    _, text_top, _, text_bottom = font.getbbox("ρ0−%")
    text_h = text_bottom  # from the drawing origin to the lowest ink
    gap = max(2, round(4 * scale))
    label_w = max(font.getlength(text) for text in (low, high, quantity))
    box_w = int(bar_w + gap + label_w + 1)
    box_h = text_h + gap + bar_h
    picture = Image.new("RGBA", (box_w, box_h), (0, 0, 0, 0))
    draw = ImageDraw.Draw(picture)
    ramp = matplotlib.colormaps[colour_map](np.linspace(1.0, 0.0, bar_h))[:, :3]  # top = high
    bar = (np.repeat(ramp[:, None, :], bar_w, axis=1) * 255 + 0.5).astype(np.uint8)
    picture.paste(Image.fromarray(bar).convert("RGBA"), (0, text_h + gap))
    draw.text((0, 0), quantity, fill=(*ink, 255), font=font)
    draw.text((bar_w + gap, text_h + gap - text_top), high, fill=(*ink, 255), font=font)
    draw.text((bar_w + gap, box_h - text_h), low, fill=(*ink, 255), font=font)
    pixels = np.asarray(picture, np.float32)
    top, left = margin, max(0, width - margin - box_w)
    return top, left, pixels[..., :3], pixels[..., 3:] / 255.0


def draw_legend(image: np.ndarray, render: Render) -> np.ndarray:
    """``image`` ((H, W, 3) uint8, changed in place and returned) with the colour bar, its range and unit
    at the right edge."""
    height, width = image.shape[:2]
    ink = (20, 20, 20) if np.mean(render.background_rgb) > 0.5 else (235, 235, 235)
    top, left, colours, opacity = legend_picture(legend_range(render), render.colour_map, ink, height, width)
    h, w = min(opacity.shape[0], height - top), min(opacity.shape[1], width - left)
    region = image[top : top + h, left : left + w]
    alpha = opacity[:h, :w]
    region[...] = (region * (1.0 - alpha) + colours[:h, :w] * alpha + 0.5).astype(np.uint8)
    return image
