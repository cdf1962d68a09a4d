"""Taichi's internals in one module (``tests/test_private_taichi.py``), used only on the Taichi
``WRITTEN_FOR`` unless ``PBF_PUBLIC_LAUNCH`` is set: :class:`Launcher` (the same launch without Taichi's
per-call Python) and :func:`watching` (launches, element accesses and compiles, for the studies).
"""

from __future__ import annotations

import contextlib
import inspect
import io
import os
import sys
import time

import numpy as np
import taichi as ti

try:  # the internals this module reads, in the Taichi it was written for
    from taichi._lib.core.taichi_python import is_signed
    from taichi.lang import impl
    from taichi.lang.exception import handle_exception_from_cpp
    from taichi.lang.kernel_impl import Kernel
    from taichi.lang.util import cook_dtype
    from taichi.profiler.kernel_profiler import get_default_kernel_profiler
    from taichi.types import primitive_types
    from taichi.types.annotations import template as template_type
    from taichi.types.ndarray_type import NdarrayType
except ImportError:  # pragma: no cover - another Taichi: its public call only
    impl = None

WRITTEN_FOR = (1, 7, 4)  # the Taichi version whose internals this module reads (``ti.__version__``)
PUBLIC_LAUNCH_VAR = "PBF_PUBLIC_LAUNCH"
"""Set to anything but "" or "0": every Launcher made afterwards takes Taichi's public call."""


def knows_taichi() -> bool:
    """Whether the running Taichi is the one this module was written for, its internals imported."""
    return impl is not None and tuple(ti.__version__) == WRITTEN_FOR


def fast_launch() -> bool:
    """Whether a Launcher made now launches past Taichi's call."""
    return knows_taichi() and os.environ.get(PUBLIC_LAUNCH_VAR, "") in ("", "0")


def compile_config():
    """Taichi's public ``ti.cfg`` (arch, offline cache, compiler switches; settable), None before Taichi starts."""
    return ti.cfg


def current_arch():
    """The running backend's arch (``ti.x64``, ``ti.cuda`` …), None before Taichi starts."""
    config = ti.cfg
    return None if config is None else config.arch


TAICHI_START_LINE = "[Taichi] Starting on arch="  # printed by every ti.init; no option silences it


def start_taichi(**options) -> None:
    """``ti.init(**options)`` without Taichi's "Starting on" line; anything else it prints passes."""
    printed = io.StringIO()
    try:
        with contextlib.redirect_stdout(printed):
            ti.init(**options)
    finally:
        rest = [line for line in printed.getvalue().splitlines(keepends=True) if not line.startswith(TAICHI_START_LINE)]
        sys.stdout.write("".join(rest))


class Observer:
    """What a study is told while it watches; only the methods a subclass overrides are watched for."""

    def launched(self, kernel: str, waits: bool) -> None:
        """A kernel launch (Taichi's own included); ``waits``: the host waits for a result."""

    def accessed(self, read: bool) -> None:
        """An element of a field or ndarray read (``read``) or written from Python (``field[None]``)."""

    def compiled(self, kernel: str, seconds: float) -> None:
        """A kernel call that compiled a new variant: its wall time (front end, compile, one synchronised run)."""


_observers: list[Observer] = []
_wrapped: list[tuple[type, str, object]] = []  # (class, attribute, Taichi's own) of each wrapper in place
_depth = 0  # element accesses under way (what one launches inside is part of it)


def _overrides(observer: Observer, name: str) -> bool:
    return getattr(type(observer), name) is not getattr(Observer, name)


def _tell(name: str, *args) -> None:
    for observer in list(_observers):
        getattr(observer, name)(*args)


def _wrap_launch(original):
    def launch_kernel(kernel, compiled, *args):
        waits = _depth == 0 and (kernel.return_type is not None or any(isinstance(a, np.ndarray) for a in args))
        _tell("launched", kernel.func.__qualname__, waits)
        return original(kernel, compiled, *args)

    return launch_kernel


def _wrap_access(original, read: bool):
    def access(obj, *args):
        global _depth
        if _depth == 0:
            _tell("accessed", read)
        _depth += 1
        try:
            return original(obj, *args)
        finally:
            _depth -= 1

    return access


def _wrap_call(original):
    def call(kernel, *args, **kwargs):
        variants = len(kernel.compiled_kernels)
        began = time.perf_counter()
        result = original(kernel, *args, **kwargs)
        if len(kernel.compiled_kernels) > variants:
            ti.sync()
            _tell("compiled", kernel.func.__qualname__, time.perf_counter() - began)
        return result

    return call


def _rewrap() -> None:
    """Taichi's classes wrapped for what the observers now watching want, and only for that."""
    for cls, name, original in reversed(_wrapped):
        setattr(cls, name, original)
    _wrapped.clear()
    targets = []
    if any(_overrides(o, "launched") for o in _observers):
        targets.append((Kernel, "launch_kernel", _wrap_launch))
    if any(_overrides(o, "accessed") for o in _observers):
        for cls in (ti.ScalarField, ti.MatrixField, ti.ScalarNdarray, ti.VectorNdarray, ti.MatrixNdarray):
            targets.append((cls, "__getitem__", lambda f: _wrap_access(f, True)))
            targets.append((cls, "__setitem__", lambda f: _wrap_access(f, False)))
    if any(_overrides(o, "compiled") for o in _observers):
        targets.append((Kernel, "__call__", _wrap_call))
    for cls, name, wrap in targets:
        original = cls.__dict__[name]
        _wrapped.append((cls, name, original))
        setattr(cls, name, wrap(original))


def _require(what: str) -> None:
    if not knows_taichi():
        raise RuntimeError(
            f"{what} reads Taichi {'.'.join(map(str, WRITTEN_FOR))}'s internals; "
            f"this is Taichi {'.'.join(map(str, ti.__version__))}"
        )


@contextlib.contextmanager
def watching(observer: Observer):
    """``observer`` told of what Taichi does while inside; observers nest. RuntimeError on another Taichi."""
    _require("watching Taichi's launches")
    _observers.append(observer)
    _rewrap()
    try:
        yield observer
    finally:
        _observers.remove(observer)
        _rewrap()


def profiled_tasks() -> list[tuple[str, float]]:
    """(task, milliseconds) of every task the kernel profiler recorded since last cleared, in order."""
    _require("reading the kernel profiler's records")
    profiler = get_default_kernel_profiler()
    profiler._update_records()
    return [(record.name, record.kernel_time) for record in profiler._traced_records]


MOST_VARIANTS = 64  # variants a Launcher keeps; past them the ordinary call (a NaN template adds one a call)
PLAIN = (bool, int, float, str, type(None))  # template arguments told apart by value and type


def _variant(value):
    if type(value) in PLAIN:
        return (type(value), value)
    if type(value) is tuple:
        return tuple(_variant(item) for item in value)
    return id(value)  # fields and objects: the Launcher keeps them alive while it holds the key


REALS = (float, int, np.floating, np.integer)  # a float argument (anything else: Taichi's launch refuses it)
INTEGERS = (int, np.integer)


def _argument_setters(primal) -> tuple | None:
    """How each argument is set, as ``Kernel.launch_kernel`` does: None for a template, else (kind, index).
    None for a kernel with another kind of argument, or that returns values or prints."""
    if primal.return_type is not None or getattr(primal, "has_print", True):
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


class Launcher:
    """``bound`` (``obj.kernel`` of a ``ti.data_oriented`` object) called with arguments by position or name,
    each variant the ordinary way once (so the compile and the cache see it), then directly."""

    def __init__(self, bound):
        self._bound = bound
        primal = getattr(bound, "_primal", None) if fast_launch() else None
        owner = getattr(bound, "_kernel_owner", None)
        direct = (
            primal is not None
            and owner is not None
            and not getattr(bound, "_is_staticmethod", True)
            and isinstance(primal, Kernel)
        )
        self._primal = primal if direct else None  # Taichi's kernel; None: every call is the public one
        self._owner = owner
        self._name = primal.func.__qualname__ if direct else ""
        # The call site's parameters and its template arguments' places (the owner, ``self``, not counted).
        self._names = tuple(inspect.signature(primal.func).parameters)[1:] if direct else ()
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
        self._count = len(primal.arguments) - 1 if direct else 0  # the call site's arguments (not the owner)
        self._variants: dict = {}  # key → (compiled kernel, its template arguments kept alive, launch data)

    def _in_order(self, args: tuple, kwargs: dict) -> tuple | None:
        """The arguments by position; None where they do not fill the parameters once each."""
        rest = self._names[len(args) :]
        if len(args) > len(self._names) or set(kwargs) != set(rest):
            return None
        return args + tuple(kwargs[name] for name in rest)

    def __call__(self, *args, **kwargs):
        if self._primal is None:
            return self._bound(*args, **kwargs)
        if kwargs:
            in_order = self._in_order(args, kwargs)
            if in_order is None:
                return self._bound(*args, **kwargs)
            args = in_order
        if len(args) != self._count:  # another count: Taichi's call says so
            return self._bound(*args)
        key = tuple(_variant(args[i]) for i in self._templates)
        if self._arrays:
            key += tuple((getattr(args[i], "dtype", None), len(getattr(args[i], "shape", ()))) for i in self._arrays)
        entry = self._variants.get(key)
        if entry is None:  # the variant's first call: Taichi's own path compiles it and launches
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
            if context is None:  # an argument Taichi refuses (its call says how)
                return self._bound(*args)
            if _observers:  # Taichi's launch_kernel, which observers see, is not on this path
                _tell("launched", self._name, False)
            try:
                impl.get_runtime().prog.launch_kernel(entry[2], context)
            except Exception as error:  # Taichi's exceptions for its C++ ones, as its launch raises them
                raise handle_exception_from_cpp(error) from None
            return None
        return self._primal.launch_kernel(entry[0], self._owner, *args)

    def _context(self, compiled, args):
        """The launch context with every argument set; None for one Taichi refuses or an ndarray with a gradient."""
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
                if not isinstance(value, ti.Ndarray) or value.grad is not None:
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
