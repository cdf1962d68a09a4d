"""A stage's scene constants as data, one () struct field: a Python number would be baked into the kernels,
and every scene of another spacing would compile again. Read them into locals once a particle. And
fields filled from NumPy arrays in one launch (:func:`array_loader`)."""

import numbers

import numpy as np
import taichi as ti


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
    """A () struct field holding ``values`` (name → number, bool or 2-4 vector; int32 or float32), written in
    one launch. Read a member in a kernel as ``self.constants[None].name``."""
    types = {name: _member_type(name, value) for name, value in values.items()}
    struct = ti.types.struct(**types)
    field = struct.field(shape=())
    _write(field, struct, values)
    return field


def _write(field, struct, values: dict) -> None:
    @ti.kernel
    def write(value: struct):
        field[None] = value

    write(struct(**{name: int(v) if isinstance(v, bool) else v for name, v in values.items()}))


def array_loader(fields):
    """A function that fills ``fields`` (float32 or int32, scalar or vector, any shape) from NumPy arrays
    of their shapes in one launch: a ``from_numpy`` compiles a kernel of its own for every field, each
    with the whole of a compile's fixed cost. Make it once and call it as often as needed."""
    fields = tuple(fields)
    widths = tuple(getattr(field, "n", 1) for field in fields)
    integer = tuple(field.dtype == ti.i32 for field in fields)
    sizes = [int(np.prod(field.shape)) * width for field, width in zip(fields, widths)]
    offsets, taken = [], {False: 0, True: 0}  # each field's start in the flat array of its type
    for size, is_integer in zip(sizes, integer):
        offsets.append(taken[is_integer])
        taken[is_integer] += size
    offsets = tuple(offsets)

    @ti.kernel
    def load(reals: ti.types.ndarray(dtype=ti.f32, ndim=1), integers: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        for k in ti.static(range(len(fields))):
            for index in ti.grouped(fields[k]):
                flat = 0  # the row-major index NumPy's ravel gives
                for d in ti.static(range(len(fields[k].shape))):
                    flat = flat * fields[k].shape[d] + index[d]
                at = offsets[k] + flat * widths[k]
                if ti.static(widths[k] == 1):
                    if ti.static(integer[k]):
                        fields[k][index] = integers[at]
                    else:
                        fields[k][index] = reals[at]
                else:
                    for c in ti.static(range(widths[k])):
                        if ti.static(integer[k]):
                            fields[k][index][c] = integers[at + c]
                        else:
                            fields[k][index][c] = reals[at + c]

    def loader(arrays) -> None:
        flat = {False: [np.zeros(1, np.float32)], True: [np.zeros(1, np.int32)]}  # never empty
        for field, width, is_integer, values in zip(fields, widths, integer, arrays):
            expected = tuple(field.shape) + ((width,) if width > 1 else ())
            values = np.asarray(values)
            if values.shape != expected:
                raise ValueError(f"expected an array of shape {expected}, got {values.shape}")
            flat[is_integer].insert(-1, values.astype(np.int32 if is_integer else np.float32).ravel())
        load(np.concatenate(flat[False]), np.concatenate(flat[True]))

    return loader
