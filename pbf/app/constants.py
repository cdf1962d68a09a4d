"""The renderers' scene constants as data and their arrays sized by buckets, as the solver's are.

Taichi's offline cache names a compiled kernel by a hash of its code, in which every Python number a
kernel reads is a constant, and of the shapes of the fields it touches. The renderers read the scene's
numbers (colours, radii, counts of segments and bodies) from a () struct field and size their arrays by
powers of two, so that a scene of another spacing, size or colours finds their kernels compiled.

The rules are the solver's (``pbf.solver.scene_constants``, ``pbf.solver.allocation``, its public face);
here are the two helpers the renderers add to them.
"""

import numpy as np


def padded(values: np.ndarray, length: int) -> np.ndarray:
    """``values`` followed by rows of zeros up to ``length`` rows: the contents of a field of a bucket's size."""
    out = np.zeros((length,) + values.shape[1:], values.dtype)
    out[: len(values)] = values
    return out


def colour(rgb) -> tuple[float, float, float]:
    """An RGB triple as floats, whatever the scene wrote: ``(0, 0, 0)`` would make an int32 member, another
    struct and so another compile."""
    return tuple(float(c) for c in rgb)
