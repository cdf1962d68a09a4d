"""Taichi's internals in one module (``tests/test_private_taichi.py``), used only on the Taichi
``WRITTEN_FOR`` unless ``PBF_PUBLIC_LAUNCH`` is set: :class:`Launcher` (the same launch without Taichi's
per-call Python) and :func:`short_positions` (its front end's source positions without the caret's
text until an error). It keeps no state of its own: the lab's instruments (``benchmarks/instruments.py``)
watch a direct launch at ``Launcher._launch``.
"""

from __future__ import annotations

import contextlib
import inspect
import io
import os
import sys

import numpy as np
import taichi as ti

try:  # the internals this module reads, in the Taichi it was written for
    from taichi._lib.core.taichi_python import is_signed
    from taichi.lang import impl
    from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext
    from taichi.lang.exception import handle_exception_from_cpp
    from taichi.lang.kernel_impl import Kernel
    from taichi.lang.util import cook_dtype
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
    """``ti.init(**options)`` without Taichi's "Starting on" line; anything else it prints passes. On the
    Taichi this module knows (unless ``PBF_PUBLIC_LAUNCH``), with :func:`short_positions`."""
    if fast_launch():
        short_positions()
    printed = io.StringIO()
    try:
        with contextlib.redirect_stdout(printed):
            ti.init(**options)
    finally:
        rest = [line for line in printed.getvalue().splitlines(keepends=True) if not line.startswith(TAICHI_START_LINE)]
        sys.stdout.write("".join(rest))


def short_positions() -> None:
    """Taichi's front end writes every AST node's source position as text, for messages that may never
    come: the line, a caret line under the node, both wrapped by ``textwrap``, for each inlined copy of a
    ``ti.func``, on every start (the offline cache is keyed by the front end's output). Here a node's text
    is its file, line, function and source line (Taichi's own form for Pythons before 3.8), so a compile
    error from Taichi's C++ still names the line; a Python-side error, raised once the transformer has
    marked its context, gets Taichi's whole text with the caret."""
    original = ASTTransformerContext.__dict__["get_pos_info"]
    if getattr(original, "short", False):
        return

    def get_pos_info(context, node):
        if context.raised:  # the message of an error being raised
            return original(context, node)
        line = node.lineno + context.lineno_offset
        return f'File "{context.file}", line {line}, in {context.func.func.__name__}:\n{context.src[node.lineno - 1]}\n'

    get_pos_info.short = True
    get_pos_info.original = original
    ASTTransformerContext.get_pos_info = get_pos_info


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
        self._variants: dict = {}  # key → (compiled kernel, its template arguments kept alive, launch data)
        if not direct:  # the rest is read only by a direct launch
            return
        self._name = primal.func.__qualname__
        # The call site's parameters and its template arguments' places (the owner, ``self``, not counted).
        self._names = tuple(inspect.signature(primal.func).parameters)[1:]
        self._templates = tuple(i - 1 for i in primal.template_slot_locations if i > 0)
        # Ndarray arguments select a variant by element type and dimensions (Taichi's features of them).
        arguments = enumerate(primal.arguments)
        self._arrays = tuple(i - 1 for i, a in arguments if i > 0 and isinstance(a.annotation, NdarrayType))
        self._setters = _argument_setters(primal)
        self._count = len(primal.arguments) - 1  # the call site's arguments (not the owner)

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
            self._launch(entry[2], context)
            return None
        return self._primal.launch_kernel(entry[0], self._owner, *args)

    def _launch(self, data, context) -> None:
        """The direct launch: past Taichi's ``launch_kernel`` (the one seam where a watcher sees it)."""
        try:
            impl.get_runtime().prog.launch_kernel(data, context)
        except Exception as error:  # Taichi's exceptions for its C++ ones, as its launch raises them
            raise handle_exception_from_cpp(error) from None

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
