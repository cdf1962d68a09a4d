"""The window's keys, mouse and help lines, apart from the window so that ``--help`` can list them
without starting Taichi. Key names are GGUI's (``ti.ui.SPACE`` is " ", ``ti.ui.ESCAPE`` "Escape")."""

import string

SPACE, ESCAPE = " ", "Escape"
KEYS = {
    SPACE: "pause / resume",
    "n": "one frame while paused",
    "r": "reset",
    "f": "emitters on / off (scenes with [[emitters]])",
    "m": "wave maker on / off (scenes with [wave_maker])",
    "v": "particles / surface",
    "h": "help: these lines",
    "Tab": "hide / show the panel",
    ESCAPE: "quit",
}
"""The window's keys and what they do (W A S D / Q E, held, move the camera)."""
GGUI_KEYS = set(string.ascii_lowercase) | {
    SPACE,
    ESCAPE,
    "Tab",
    "Return",
    "BackSpace",
    "Shift",
    "Left",
    "Right",
    "Up",
    "Down",
}
"""Key names GGUI reports. Measured under Xvfb with xdotool: letters and these named keys arrive;
'.', ',', '/', '-', '=', digits and F1 never do, so no key of ours may be one of them."""
MOUSE = ("mouse: left drag pushes water, right drag orbits,", "shift + right (or middle) drag zooms")
HELP = (
    *MOUSE,
    "keys: WASD/QE move the camera",
    *(f"  {'space' if key == SPACE else 'esc' if key == ESCAPE else key}: {what}" for key, what in KEYS.items()),
)
"""The help lines, in the window's panel (key h) and at the end of ``--help``."""
