"""The substep's kernel calls with less of Taichi's Python in them: on a GPU, small scenes wait on it.

A call of a Taichi kernel first works out, in Python, which compiled variant its arguments select
(``Kernel.ensure_compiled``: every argument's features, the template arguments by value or by
identity, each through a chain of type tests), then sets the arguments and launches. In Taichi 1.7.4
the first part costs about 8 µs a call and 0.6 µs an argument on this 2-core VM, as much as the
second (a kernel of 14 arguments: 35 µs a call, 19.5 µs launched directly; Vulkan). At 8,000
particles a GPU substep took as much host time to issue as the device took to run it
(docs/BENCHMARKS.md, "On a GPU"), and a substep's three calls on the device path carry 40 arguments.

:class:`Launcher` calls a bound kernel the ordinary way the first time a variant is asked for (so
the compile, Taichi's offline cache and whatever wraps ``Kernel.__call__`` see it), keeps the
compiled kernel under the variant's template arguments (plain values by value, fields and objects by
identity, kept alive so that no other object takes their identity), and from then on launches it
directly. A kernel that returns nothing and takes only scalars and ndarrays besides its templates
(the device path's three) is launched from a launch context whose arguments the Launcher sets itself,
as ``Kernel.launch_kernel`` sets them but without the closures and the type dispatch that function
builds a call, and with Taichi's lookup of the compiled code done once; any other goes through
``Kernel.launch_kernel``. A call with an argument Taichi would refuse, or with another count of
arguments, is an ordinary call, so that Taichi refuses it in its own words. The same kernel, the
same arguments: the same launch, bit for bit (``tests/test_launch.py``).
The host's CPU time per substep on the device path (Vulkan, 125 particles): 24% less through
``launch_kernel`` than through Taichi's call, and 29% less again from the context (docs/BENCHMARKS.md,
"Host time per substep").

This reads Taichi's own classes (``_BoundedDifferentiableMethod``, ``Kernel.ensure_compiled``,
``compiled_kernels``, ``launch_kernel``, ``template_slot_locations``, and for the context the C++
kernel's ``make_launch_context``, its ``set_arg_*`` and the program's ``compile_kernel`` and
``launch_kernel``), which the pinned Taichi 1.7.4 has; where one is missing a Launcher calls its
kernel the ordinary way.
"""

from __future__ import annotations

import numpy as np
from taichi.lang import impl
from taichi.lang._ndarray import Ndarray
from taichi.lang.exception import handle_exception_from_cpp
from taichi.lang.util import cook_dtype
from taichi.types import primitive_types
from taichi.types.annotations import template as template_type
from taichi.types.ndarray_type import NdarrayType

try:  # Taichi's own test of a signed integer type, as its argument setting uses it
    from taichi._lib.core.taichi_python import is_signed
except ImportError:  # pragma: no cover - another Taichi: every variant launches through launch_kernel
    is_signed = None

MOST_VARIANTS = 64
"""Variants a Launcher keeps; past them it calls the ordinary way (a template argument that never
compares equal to itself, a NaN, would otherwise add one a call)."""
PLAIN = (bool, int, float, str, type(None))
"""Template arguments told apart by value (by type too: Taichi compiles True and 1 alike, but a
variant should not be found by either for the other)."""


def _variant(value):
    """A template argument's part of a variant's key."""
    if type(value) in PLAIN:
        return (type(value), value)
    if type(value) is tuple:
        return tuple(_variant(item) for item in value)
    return id(value)  # fields and objects: the Launcher keeps them alive while it holds the key


REALS = (float, int, np.floating, np.integer)
"""What Taichi takes for a float argument (anything else goes to its own launch, which refuses it)."""
INTEGERS = (int, np.integer)
"""What Taichi takes for an integer argument."""


def _argument_setters(primal) -> tuple | None:
    """How each argument the call site passes is set, in Taichi 1.7.4's own way (``Kernel.launch_kernel``:
    a template argument not at all, the others at their place among the non-template ones): None for a
    template, else (kind, index). None for the whole kernel when an argument is of a kind this does not
    set (a matrix, a struct, a texture...), or when the kernel returns values or prints (Taichi waits
    for the device after those): such a kernel launches through ``launch_kernel``."""
    if is_signed is None or primal.return_type is not None or getattr(primal, "has_print", True):
        return None
    setters, place = [], 0
    for argument in primal.arguments[1:]:  # the owner, a template, is not passed at the call site
        annotation = argument.annotation
        if isinstance(annotation, template_type):
            setters.append(None)
            continue
        if id(annotation) in primitive_types.real_type_ids:
            kind = "real"
        elif id(annotation) in primitive_types.integer_type_ids:
            kind = "signed" if is_signed(cook_dtype(annotation)) else "unsigned"
        elif isinstance(annotation, NdarrayType):
            kind = "ndarray"
        else:
            return None
        setters.append((kind, (place,)))
        place += 1
    return tuple(setters)


def launch_from_context(program, compiled, context) -> None:
    """The program's launch of ``compiled`` (its data for the launch) from a launch context: every direct
    launch of a :class:`Launcher` goes through here, where ``pbf.study.common.TransferCounter`` counts it."""
    program.launch_kernel(compiled, context)


class Launcher:
    """``bound`` (a kernel of a ``ti.data_oriented`` object, as ``obj.kernel`` gives it) called with
    positional arguments, its compiled variants launched directly after their first call (the module
    docstring). Keyword arguments are not taken: the call sites pass every argument in order."""

    def __init__(self, bound):
        self._bound = bound
        primal = getattr(bound, "_primal", None)
        owner = getattr(bound, "_kernel_owner", None)
        needed = ("ensure_compiled", "compiled_kernels", "launch_kernel", "template_slot_locations", "arguments")
        direct = (
            primal is not None
            and owner is not None
            and not getattr(bound, "_is_staticmethod", True)
            and all(hasattr(primal, name) for name in needed)
        )
        self._primal = primal if direct else None
        self._owner = owner
        # The template arguments' places among those the call site passes (Taichi's count the owner first).
        self._templates = tuple(i - 1 for i in primal.template_slot_locations if i > 0) if direct else ()
        # Ndarray arguments select a variant by element type and dimensions (Taichi's features of them).
        self._arrays = (
            tuple(
                i - 1
                for i, argument in enumerate(primal.arguments)
                if i > 0 and isinstance(argument.annotation, NdarrayType)
            )
            if direct
            else ()
        )
        self._setters = _argument_setters(primal) if direct else None
        self._count = len(primal.arguments) - 1 if direct else 0
        """The arguments the call site passes (the owner is not one)."""
        self._variants: dict = {}
        """key → (the compiled kernel, the template arguments it was compiled for, kept alive, and the
        compiled kernel's data for the program's launch, or None where ``launch_kernel`` launches it)."""

    def __call__(self, *args, **kwargs):
        if kwargs:  # by name: put in the kernel's order
            import inspect

            names = tuple(inspect.signature(self._bound._primal.func).parameters)[1:]
            args = args + tuple(kwargs[name] for name in names[len(args) :])
        if self._primal is None or len(args) != self._count:  # another count: Taichi's call says so
            return self._bound(*args)
        key = tuple(_variant(args[i]) for i in self._templates)
        if self._arrays:
            key += tuple((getattr(args[i], "dtype", None), len(getattr(args[i], "shape", ()))) for i in self._arrays)
        entry = self._variants.get(key)
        if entry is None:  # the first call of this variant: Taichi's own path compiles it and launches
            result = self._bound(*args)
            if len(self._variants) < MOST_VARIANTS:
                compiled = self._primal.compiled_kernels[self._primal.ensure_compiled(self._owner, *args)]
                data = None
                if self._setters is not None:  # Taichi's lookup of the compiled code, done once
                    program = impl.get_runtime().prog
                    data = program.compile_kernel(program.config(), program.get_device_caps(), compiled)
                self._variants[key] = (compiled, tuple(args[i] for i in self._templates), data)
            return result
        self._primal.runtime.materialize()  # fields allocated since the last kernel call, as a call does
        if entry[2] is not None:
            context = self._context(entry[0], args)
            if context is None:  # an argument Taichi refuses (its call says how) or one this does not set
                return self._bound(*args)
            try:
                launch_from_context(impl.get_runtime().prog, entry[2], context)
            except Exception as error:  # Taichi's own exceptions for its C++ ones, as its launch raises them
                raise handle_exception_from_cpp(error) from None
            return None
        return self._primal.launch_kernel(entry[0], self._owner, *args)

    def _context(self, compiled, args):
        """The launch context with every argument set as ``Kernel.launch_kernel`` sets it, without
        building its closures and type dispatch a call; None where an argument is not what Taichi takes
        for its type (Taichi's own call then refuses it, in its words) or an ndarray carries a gradient."""
        context = compiled.make_launch_context()
        for setter, value in zip(self._setters, args):
            if setter is None:
                continue
            kind, index = setter
            if kind == "real":
                if not isinstance(value, REALS):
                    return None
                context.set_arg_float(index, float(value))
            elif kind == "ndarray":
                if not isinstance(value, Ndarray) or value.grad is not None:
                    return None
                context.set_arg_ndarray(index, value.arr)
            else:
                if not isinstance(value, INTEGERS):
                    return None
                if kind == "signed":
                    context.set_arg_int(index, int(value))
                else:
                    context.set_arg_uint(index, int(value))
        return context
