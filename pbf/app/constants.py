"""The renderers' scene constants as data and their arrays sized by buckets, as the solver's are.

Taichi's offline cache names a compiled kernel by a hash of its code, in which every Python number a
kernel reads is a constant, and of the shapes of the fields it touches. The renderers read the scene's
numbers (colours, radii, counts of segments and bodies) from a () struct field and size their arrays by
powers of two, so that a scene of another spacing, size or colours finds their kernels compiled.

The same rules as the solver's ``pbf.solver.constants`` and ``pbf.solver.model.allocation``, which lie
behind its public face (``pbf.solver``), where the application does not reach.
"""

import numbers

import numpy as np
import taichi as ti


def bucket(count: int, floor: int) -> int:
    """Entries to allocate for ``count``: the next power of two, at least ``floor``."""
    return max(int(floor), 1 << max(int(count) - 1, 0).bit_length())


def padded(values: np.ndarray, length: int) -> np.ndarray:
    """``values`` followed by rows of zeros up to ``length`` rows: the contents of a field of a bucket's size."""
    out = np.zeros((length,) + values.shape[1:], values.dtype)
    out[: len(values)] = values
    return out


def colour(rgb) -> tuple[float, float, float]:
    """An RGB triple as floats, whatever the scene wrote: ``(0, 0, 0)`` would make an int32 member, another
    struct and so another compile."""
    return tuple(float(c) for c in rgb)


def _member_type(name: str, value):
    if isinstance(value, bool) or isinstance(value, numbers.Integral):
        return ti.i32
    if isinstance(value, numbers.Real):
        return ti.f32
    components = tuple(value)
    if len(components) in (2, 3, 4):
        if all(isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in components):
            return ti.types.vector(len(components), ti.i32)
        return ti.types.vector(len(components), ti.f32)
    raise TypeError(f"scene constant {name!r}: expected a number or 2-4 numbers, got {value!r}")


def scene_constants(**values):
    """A () struct field holding ``values`` (name → number, bool or a 2-4 vector): ints and bools as
    int32, reals as float32. Read a member in a kernel as ``self.constants[None].name``.

    Written in one launch: a write per member from Python would compile a kernel per member."""
    struct = ti.types.struct(**{name: _member_type(name, value) for name, value in values.items()})
    field = struct.field(shape=())

    @ti.kernel
    def write(value: struct):
        field[None] = value

    write(struct(**{name: int(v) if isinstance(v, bool) else v for name, v in values.items()}))
    return field
