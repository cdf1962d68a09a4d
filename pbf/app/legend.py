"""The colour legend: what the particles' colours mean, as a bar with its range and unit.

Drawn onto headless frames when ``render.legend`` is set (Pillow draws the text: a font rasteriser
is not something to write by hand), and written as a line in the window's panel.
"""

import matplotlib
import numpy as np
from PIL import Image, ImageDraw, ImageFont

from pbf.scene import Render

BAR_PX = (16, 160)
"""Width and height of the colour bar, pixels (scaled down on small images)."""
MARGIN_PX = 12


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


def draw_legend(image: np.ndarray, render: Render) -> np.ndarray:
    """``image`` ((H, W, 3) uint8) with the colour bar, its range and unit at the right edge."""
    height, width = image.shape[:2]
    scale = min(1.0, height / 360)
    bar_w, bar_h = max(4, round(BAR_PX[0] * scale)), max(16, round(BAR_PX[1] * scale))
    margin = max(4, round(MARGIN_PX * scale))
    font = ImageFont.load_default()
    quantity, low, high = legend_range(render)
    picture = Image.fromarray(image)
    draw = ImageDraw.Draw(picture)
    label_w = max(draw.textlength(text, font=font) for text in (low, high, quantity))
    left = int(width - margin - bar_w - 4 - label_w)
    top = margin + 14
    ramp = matplotlib.colormaps[render.colour_map](np.linspace(1.0, 0.0, bar_h))[:, :3]  # top = high
    bar = (np.repeat(ramp[:, None, :], bar_w, axis=1) * 255 + 0.5).astype(np.uint8)
    picture.paste(Image.fromarray(bar), (left, top))
    ink = (20, 20, 20) if np.mean(render.background_rgb) > 0.5 else (235, 235, 235)
    draw.text((left, margin), quantity, fill=ink, font=font)
    draw.text((left + bar_w + 4, top), high, fill=ink, font=font)
    draw.text((left + bar_w + 4, top + bar_h - 10), low, fill=ink, font=font)
    return np.asarray(picture)
