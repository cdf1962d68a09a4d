"""A stage's scene constants as data, one () struct field: a Python number would be baked into the kernels,
and every scene of another spacing would compile again. Read them into locals once a particle."""

import numbers

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
