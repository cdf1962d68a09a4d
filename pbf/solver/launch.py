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
directly (``Kernel.launch_kernel``, which sets the arguments as an ordinary call does). The same
kernel, the same arguments: the same launch, bit for bit (``tests/test_launch.py``).

This reads Taichi's own classes (``_BoundedDifferentiableMethod``, ``Kernel.ensure_compiled``,
``compiled_kernels``, ``launch_kernel``, ``template_slot_locations``), which the pinned Taichi 1.7.4
has; where one is missing a Launcher calls its kernel the ordinary way.
"""

from __future__ import annotations

from taichi.types.ndarray_type import NdarrayType

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
        self._variants: dict = {}
        """key → (the compiled kernel, the template arguments it was compiled for, kept alive)."""

    def __call__(self, *args):
        if self._primal is None:
            return self._bound(*args)
        key = tuple(_variant(args[i]) for i in self._templates)
        if self._arrays:
            key += tuple((getattr(args[i], "dtype", None), len(getattr(args[i], "shape", ()))) for i in self._arrays)
        entry = self._variants.get(key)
        if entry is None:  # the first call of this variant: Taichi's own path compiles it and launches
            result = self._bound(*args)
            if len(self._variants) < MOST_VARIANTS:
                compiled = self._primal.compiled_kernels[self._primal.ensure_compiled(self._owner, *args)]
                self._variants[key] = (compiled, tuple(args[i] for i in self._templates))
            return result
        self._primal.runtime.materialize()  # fields allocated since the last kernel call, as a call does
        return self._primal.launch_kernel(entry[0], self._owner, *args)
