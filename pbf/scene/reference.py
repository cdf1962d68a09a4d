"""The key reference, generated from the schema's own declarations: each key's dotted name, type,
default, allowed values and doc line, table by table. ``pbf --keys`` prints it and docs/KEYS.md is its
output (``tests/test_keys_reference.py`` fails when the file is stale)."""

from __future__ import annotations

import dataclasses
import typing

from pbf.scene.root import Scene
from pbf.scene.schema import MOVED, REMOVED, _num, _show, public_fields

HEADER = """# Scene keys

Every key a scene file may set, generated from the schema (`pbf --keys > docs/KEYS.md`; a test fails
when this file is stale). Units are in the names; each number's range is checked at load, and an
error names the file (or the command line's `--set`), the key and what is allowed. Tables of
`[[...]]` form are lists: each entry takes the keys listed under it.

A scene may start from another: `extends = "dam_break"` (a preset, or a TOML path relative to the
file) lays the file's keys over that scene's, tables merged key by key, lists such as
`[[fluid.blocks]]` replaced whole.
"""


def _type_name(annotation) -> str:
    if typing.get_origin(annotation) is not None and type(None) in typing.get_args(annotation):
        return _type_name(next(a for a in typing.get_args(annotation) if a is not type(None))) + " (optional)"
    return {float: "number", int: "integer", bool: "true/false", str: "string"}.get(annotation, "[x, y, z]")


def _allowed(check) -> str:
    if check is None:
        return ""
    bounds = getattr(check, "bounds", None)
    if bounds is not None:
        if all(isinstance(b, int) for b in bounds):
            return f"[{bounds[0]:,}, {bounds[1]:,}]"
        return f"[{_num(bounds[0])}, {_num(bounds[1])}]"
    choices = getattr(check, "choices", None)
    if choices is not None:
        return ", ".join(f'"{c}"' for c in choices)
    return (check.__doc__ or "").strip().split("\n")[0]


def _default(f) -> str:
    if f.default is dataclasses.MISSING:
        return "required"
    if dataclasses.is_dataclass(f.default):
        return ""
    return "`" + _show(f.default, 80).replace("'", '"') + "`"


def _rows(cls, prefix: str, tables: list) -> list[str]:
    rows = []
    for f, annotation in public_fields(cls):
        item = typing.get_args(annotation)[0] if typing.get_origin(annotation) is tuple else None
        if dataclasses.is_dataclass(annotation):
            tables.append((f"[{prefix}{f.name}]", annotation, f"{prefix}{f.name}."))
        elif item is not None and dataclasses.is_dataclass(item):
            tables.append((f"[[{prefix}{f.name}]]", item, f"{prefix}{f.name}[]."))
            rows.append(
                f"| `{prefix}{f.name}` | list of tables | `[]` | {_allowed(f.metadata['check'])} | "
                f"{f.metadata['doc']} |"
            )
        else:
            rows.append(
                f"| `{prefix}{f.name}` | {_type_name(annotation)} | {_default(f)} | "
                f"{_allowed(f.metadata['check'])} | {f.metadata['doc']} |"
            )
    return rows


def reference() -> str:
    """The whole reference as Markdown."""
    out = [HEADER]
    tables = [("top level", Scene, "")]
    while tables:
        title, cls, prefix = tables.pop(0)
        found = []
        rows = _rows(cls, prefix, found)
        tables[:0] = found  # a table's sub-tables follow it
        out.append(f"\n## {title}\n")
        doc = (cls.__doc__ or "").strip()
        if doc and not doc.startswith(cls.__name__ + "("):
            out.append(" ".join(doc.split("\n\n")[0].split()) + "\n")
        if rows:
            out.append("| key | type | default | allowed | meaning |\n|---|---|---|---|---|")
            out.extend(rows)
    out.append(
        "\n## Moved and removed keys\n\nKeys of earlier versions: a scene file, a `--set` or a dict that "
        "sets one is refused with\nwhere it went, or why it was removed.\n"
    )
    out.append("| key | now |\n|---|---|")
    out.extend(f"| `{old}` | moved to `{new}` |" for old, new in MOVED.items())
    out.extend(f"| `{old}` | removed: {why} |" for old, why in REMOVED.items())
    return "\n".join(out).rstrip() + "\n"
