"""The schema's machinery: key declarations and their checks, conversion of values to their types,
unknown and missing keys, and the one-line messages of :class:`SceneError`.

Nothing here knows a particular table, but for the keys the schema once had (:data:`MOVED`,
:data:`REMOVED`); each table's module declares its keys with :func:`key` and checks what its keys must
agree on.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import numbers
import re
import types
import typing
from dataclasses import field

import numpy as np

Vec3 = tuple[float, float, float]

FLOAT32_SAFE = 1e30
"""What the derived float32 quantities must stay below (float32 ends at 3.4e38; the margin leaves
room for the sums and products the kernels form from them)."""


class SceneError(ValueError):
    """A scene that cannot be run; the message names the source, the key and what is allowed.

    ``key`` is the dotted key the message names (``"solver.iterations"``), or None when the problem
    is the file itself, so that a caller can say where the key came from (``load_scene`` names the
    command line's ``--set`` for the keys it set).
    """

    def __init__(self, message: str, key: str | None = None):
        super().__init__(message)
        found = re.search(r"\bkey '([^']+)'", message)
        self.key = key if key is not None else (found.group(1) if found else None)


# ----------------------------------------------------------------------------- showing values


def _show(value, limit: int = 60, depth: int = 0) -> str:
    """A value as a message echoes it: TOML spelling, plain Python numbers (0.5, not
    np.float64(0.5)), at most ``limit`` characters, and no conversion that could fail (an integer
    of thousands of digits cannot be printed whole, an array nested a thousand deep not at all)."""
    if depth > 2:
        text = "…"
    elif value is None:
        text = "None"
    elif isinstance(value, (bool, np.bool_)):
        text = "true" if value else "false"
    elif isinstance(value, numbers.Integral):
        value = int(value)
        text = str(value) if abs(value) < 10**18 else f"{'-' if value < 0 else ''}~1e{int(math.log10(abs(value)))}"
    elif isinstance(value, numbers.Real):
        text = repr(float(value))
    elif isinstance(value, (list, tuple, np.ndarray)):
        items = list(value[:4])
        text = "[" + ", ".join(_show(v, limit, depth + 1) for v in items) + (", …" if len(value) > 4 else "") + "]"
        if len(value) > 4:
            text += f" ({len(value):,} items)"
    elif isinstance(value, dict):
        keys = ", ".join(_show(k, 20, depth + 1) for k in list(value)[:4])
        text = "a table {" + keys + (", …" if len(value) > 4 else "") + "}"
    elif isinstance(value, str):
        text = repr(str(_clip(value, limit)))  # str(): NumPy's str_ has a repr of its own
    else:
        text = type(value).__name__
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _clip(text: str, limit: int = 60) -> str:
    """Text a message quotes, cut to ``limit`` characters."""
    return text if len(text) <= limit else text[: limit - 1] + "…"


def echo(text: str) -> str:
    """Text the user typed (an option's value, a --set assignment) as a message echoes it: cut to 60
    characters, and in quotes with escapes where bare text would be unclear or span lines (empty,
    spaces, quotes, control characters)."""
    cut = _clip(text)
    return cut if cut and cut.isprintable() and not any(c in cut for c in " '\"") else repr(cut)


def _num(x: float) -> str:
    """A bound or a derived figure in a message: six significant digits."""
    return f"{float(x):g}"


def _vec(v) -> str:
    return "[" + ", ".join(_num(c) for c in v) + "]"


def _box(lo, hi) -> str:
    return f"{_vec(lo)}–{_vec(hi)} m"


def _closest(word: str, choices) -> str | None:
    found = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return found[0] if found else None


# ----------------------------------------------------------------------------- key checks


def _between(lowest, highest):
    """Allowed: lowest ≤ value ≤ highest (the check carries its ``bounds`` for tests/test_bounds.py)."""

    def check(value):
        return None if lowest <= value <= highest else f"a value in [{_num(lowest)}, {_num(highest)}]"

    check.bounds = (lowest, highest)
    return check


def _vec_between(lowest, highest):
    def check(value):
        inside = all(lowest <= c <= highest for c in value)
        return None if inside else f"three values in [{_num(lowest)}, {_num(highest)}]"

    check.bounds = (lowest, highest)
    return check


def _even_pixels(value):
    """an even number of pixels in [16, 8192]"""
    allowed = "an even number of pixels in [16, 8192] (video needs even sizes)"
    return None if 16 <= value <= 8192 and value % 2 == 0 else allowed


_even_pixels.bounds = (16, 8192)


def _one_of(*choices):
    """Allowed: one of ``choices``; a refusal also names the closest choice."""

    def check(value):
        return None if value in choices else ("one of " + ", ".join(map(repr, choices)), _closest(value, choices))

    check.choices = choices
    return check


def _colour_map(value):
    """a Matplotlib colour map name"""
    import matplotlib

    return (
        None
        if value in matplotlib.colormaps
        else ("a Matplotlib colour map name such as 'viridis' or 'Blues'", _closest(value, matplotlib.colormaps))
    )


def _line(longest):
    """A single line of printable text (it is echoed in titles, progress bars and --list)."""

    def check(value):
        return None if len(value) <= longest and value.isprintable() else allowed

    allowed = check.__doc__ = f"at most {longest} printable characters on one line"
    return check


def _at_most_tables(most):
    def check(value):
        return None if len(value) <= most else allowed

    allowed = check.__doc__ = f"at most {most} tables"
    return check


def key(default=dataclasses.MISSING, check=None, doc=""):
    """A scene key: its default (none means required), a check and a doc line. The check returns None
    for an allowed value, else what is allowed, or (what is allowed, the closest allowed value)."""
    return field(default=default, metadata={"check": check, "doc": doc})


# ----------------------------------------------------------------------------- the schema
#
# The bounds. Lengths: fluid.spacing_m in [1e-4, 100] m keeps the kernel's σ/h⁵ and h⁵ (float32,
# h ≤ 4 s) far inside float32; walls within POSITION_REACH_SPACINGS of the origin keep positions
# resolved. Time: frame_dt_s in [1e-4, 1] s and at most 1000 substeps give Δt ≥ 1e-7 s; the
# fastest a particle can move, across the whole box in one substep (2√3·2¹⁶ s / Δt ≤ 2.3e14 m/s),
# squared, stays below FLOAT32_SAFE, as does the pressure scale ρ0 h²/Δt² ≤ 1.6e24 Pa at
# ρ0 ≤ 1e5 kg/m³. Work: iterations ≤ 100 and substeps ≤ 1000 bound a frame's cost (a billion of
# either would hang). Initial speeds and gravity are bounded by what a frame's substeps can follow
# (see _check_time), and s_corr's float32 power by pbf.solver.model. tests/test_bounds.py checks
# these figures against the bounds.


# ----------------------------------------------------------------------------- values and types


def _type_name(annotation) -> str:
    return {float: "a number", int: "an integer", bool: "true or false", str: "a string"}.get(
        annotation, "three numbers [x, y, z]"
    )


def _is_number(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _finite_float(value) -> float | None:
    """float(value) if it is a finite float64, else None (an integer past 1e308 included)."""
    try:
        converted = float(value)
    except OverflowError:
        return None
    return converted if math.isfinite(converted) else None


def _convert(value, annotation, where):
    """Convert one value to the annotated type, or raise SceneError naming what was expected."""
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):  # X | None: None only from Python
        if value is None:
            return None
        annotation = next(a for a in typing.get_args(annotation) if a is not type(None))
    if annotation is bool:
        if isinstance(value, (bool, np.bool_)):
            return bool(value)
    elif annotation is int:
        if isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_)):
            return int(value)
    elif annotation is float:
        if _is_number(value):
            converted = _finite_float(value)
            if converted is None:
                raise SceneError(f"{where}: expected a finite number, got {_show(value)}")
            return converted
    elif annotation is str:
        if isinstance(value, str):
            return str(value)
    elif annotation == Vec3:
        if isinstance(value, (list, tuple, np.ndarray)) and len(value) == 3 and all(_is_number(c) for c in value):
            converted = [_finite_float(c) for c in value]
            if None in converted:
                raise SceneError(f"{where}: expected three finite numbers, got {_show(value)}")
            return tuple(converted)
    else:
        raise TypeError(annotation)
    raise SceneError(f"{where}: expected {_type_name(annotation)}, got {_show(value)}")


def public_fields(cls) -> list[tuple[dataclasses.Field, object]]:
    """The keys a scene file may set in the table of dataclass ``cls``: each field but the internal
    ones, with its annotation resolved (a nested table's dataclass, ``tuple[Item, ...]``, a type)."""
    hints = typing.get_type_hints(cls)
    return [(f, hints[f.name]) for f in dataclasses.fields(cls) if not f.metadata.get("internal")]


def _schema_keys(cls, prefix="") -> list[str]:
    """Every dotted key of the schema under ``cls`` (for "did you mean")."""
    found = []
    for f, annotation in public_fields(cls):
        found.append(prefix + f.name)
        if dataclasses.is_dataclass(annotation):
            found += _schema_keys(annotation, f"{prefix}{f.name}.")
    return found


# ----------------------------------------------------------------------------- keys that moved or went
#
# A scene written for an earlier version names keys the schema no longer has. Each is answered with
# where it went, or why it was removed, rather than with the nearest spelling of another key. A key
# that moves or goes gets its line here (and in CHANGELOG.md); docs/KEYS.md lists both tables.

MOVED = {
    "solver.acceleration": "solver.expert.acceleration",
    "solver.chebyshev_rho": "solver.expert.chebyshev_rho",
    "solver.step_back": "solver.expert.step_back",
    "solver.relaxation": "solver.expert.relaxation",
    "solver.wall_density": "solver.expert.wall_density",
}
"""Keys that moved: the old dotted name → the new one (the levers no preset needs went under
[solver.expert])."""

REMOVED = {
    "solver.warm_start": "the divergence pre-correction always starts from the whole of the last substep's pressure",
    "solver.clamp_pressure": "the clamp to compression, C = max(ρ/ρ0 − 1, 0), is always on",
    "solver.scorr_n": "s_corr keeps the exponent n = 8 (the paper's 4 kept water at rest jostling)",
    "solver.scorr_dq": "s_corr keeps the paper's reference distance Δq = 0.2 h",
}
"""Keys that were removed: the old dotted name → why, in a phrase."""


def _former_key(dotted: str, source: str) -> SceneError | None:
    """The error for a key the schema once had, or None. List entries are matched whatever their
    index (``bodies[2].x`` as ``bodies[].x``)."""
    generic = re.sub(r"\[\d+\]", "[]", dotted)
    if generic in MOVED:
        new = MOVED[generic]
        table = new.rsplit(".", 1)[0]
        return SceneError(
            f"{source}: key '{dotted}' moved to '{new}': set {new.rsplit('.', 1)[1]} in the [{table}] table "
            f"(--set {new}=…)",
            key=dotted,
        )
    if generic in REMOVED:
        return SceneError(f"{source}: key '{dotted}' was removed: {REMOVED[generic]}; delete it", key=dotted)
    return None


def _unknown_key(name: str, prefix: str, known, source: str, root) -> SceneError:
    """The error for an unknown key: where it went if the schema once had it, else the closest key of
    this table, else a key of the same name elsewhere (``iterations`` → ``solver.iterations``), and the
    keys allowed here."""
    dotted = f"{prefix}{name}"
    former = _former_key(dotted, source)
    if former is not None:
        return former
    closest = _closest(name, known)
    if closest is not None:
        hint = f"did you mean '{prefix}{closest}'? "
    else:
        leaves = {k: k.rsplit(".", 1)[-1] for k in _schema_keys(root)}
        leaf = _closest(name, set(leaves.values()))
        hint = next((f"did you mean '{k}'? " for k, l in leaves.items() if leaf is not None and l == leaf), "")
    return SceneError(
        f"{source}: unknown key '{_clip(dotted)}'; {hint}allowed keys here: {', '.join(sorted(known))}", key=dotted
    )


def _table_values(cls, table, source: str, prefix: str, root=None) -> dict:
    """The checked values of dataclass ``cls`` from a TOML table (a dict) or an instance of ``cls``:
    unknown and missing keys refused, each value converted to its type and checked, nested tables
    built the same way. ``root`` is the outermost table's class (for "did you mean" across tables)."""
    root = root or cls
    where_table = f"{source}: key '{prefix.rstrip('.')}'" if prefix else source
    fields = public_fields(cls)
    known, hints = {f.name: f for f, _ in fields}, {f.name: annotation for f, annotation in fields}
    if isinstance(table, cls):
        raw = {name: getattr(table, name) for name in known}
    elif isinstance(table, dict):
        strange = [k for k in table if not isinstance(k, str)]
        if strange:
            raise SceneError(
                f"{where_table}: key {_show(strange[0])} is not a string; keys are names such as {next(iter(known))!r}"
            )
        unknown = sorted(set(table) - set(known))
        if unknown:
            raise _unknown_key(unknown[0], prefix, known, source, root)
        raw = table
    else:
        raise SceneError(f"{where_table}: expected a table ([{prefix.rstrip('.') or 'scene'}]), got {_show(table)}")
    values = {}
    for name, f in known.items():
        where = f"{source}: key '{prefix}{name}'"
        if name not in raw:
            if f.default is dataclasses.MISSING:
                raise SceneError(f"{where} is required ({f.metadata['doc']})")
            continue
        annotation, value = hints[name], raw[name]
        if dataclasses.is_dataclass(annotation):
            value = annotation(**_table_values(annotation, value, source, f"{prefix}{name}.", root))
        elif typing.get_origin(annotation) is tuple and dataclasses.is_dataclass(typing.get_args(annotation)[0]):
            if not isinstance(value, (list, tuple)):
                raise SceneError(f"{where}: expected a list of tables ([[{prefix}{name}]]), got {_show(value)}")
            item = typing.get_args(annotation)[0]
            check = f.metadata["check"]
            allowed = None if check is None else check(value)
            if allowed is not None:
                raise SceneError(f"{where}: expected {allowed} ({f.metadata['doc']}), got {len(value):,}")
            value = tuple(
                item(**_table_values(item, t, source, f"{prefix}{name}[{i}].", root)) for i, t in enumerate(value)
            )
        else:
            value = _convert(value, annotation, where)
            check = f.metadata["check"]
            allowed = None if check is None or value is None else check(value)
            if allowed is not None:
                allowed, closest = allowed if isinstance(allowed, tuple) else (allowed, None)
                hint = f"; did you mean {closest!r}?" if closest else ""
                raise SceneError(f"{where}: expected {allowed} ({f.metadata['doc']}), got {_show(value)}{hint}")
        values[name] = value
    return values


def _length(v) -> float:
    """|v|, scaled by its largest component so that no square overflows (inf only past 1.8e308, and
    inf compares). Not math.hypot or math.dist: once Taichi has started, the process flushes
    subnormals to zero and they return NaN for large inputs, and every comparison with NaN is
    false, so a check would pass."""
    largest = max(abs(c) for c in v)
    return 0.0 if largest == 0.0 else largest * math.sqrt(sum((c / largest) ** 2 for c in v))
