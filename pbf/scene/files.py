"""Scene files and ``--set`` overrides: finding a preset, reading TOML safely, applying overrides,
and saying of an error whether the file or the command line set its key."""

from __future__ import annotations

import copy
import dataclasses
import os
import re
import sys
import typing
from importlib import resources
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # tomllib is tomli, taken into the standard library in 3.11
    import tomli as tomllib

from pbf.scene.root import Scene
from pbf.scene.schema import SceneError, _clip, _closest, _show, _table_values, echo


def _presets_folder() -> Path:
    """Where the presets are: inside the installed package (``pbf/scenes/``, where a wheel puts them),
    else the checkout's top-level ``scenes/`` beside ``pbf/`` (an editable install, or the source tree
    on the path). ``importlib.resources`` names the package's own folder; the package is always
    installed as files (never zipped), so that folder is a real path for ``glob``."""
    shipped = Path(str(resources.files("pbf"))) / "scenes"
    return shipped if shipped.is_dir() else Path(__file__).resolve().parent.parent.parent / "scenes"


SCENES_DIR = _presets_folder()
"""The presets' folder: ``scenes/`` in a checkout, ``pbf/scenes/`` in an installed wheel."""

MAX_SCENE_BYTES = 1 << 20
"""The largest scene file read (1 MiB; the presets are 1-2 kB): a bigger one is refused unread."""


def from_dict(table: dict, source: str = "<dict>") -> Scene:
    """Validate a scene given as a dict shaped like the TOML file."""
    scene = Scene(source=source, **_table_values(Scene, table, source, ""))
    render = table.get("render")
    # The key's default follows the style (no legend on the surface); one asked for is refused there.
    if isinstance(render, dict) and render.get("legend") is True and scene.render.style == "surface":
        raise SceneError(
            f"{source}: key 'render.legend' = true asks for a legend that render.style = \"surface\" does not "
            f'draw (its colours are the water\'s own); allowed: render.legend = false, or render.style = "particles"'
        )
    return scene


def _presets() -> list[str]:
    return sorted(p.stem for p in SCENES_DIR.glob("*.toml"))


def resolve_path(name_or_path: str | os.PathLike) -> Path:
    """A preset name (``dam_break``) or a path to a TOML file; a clear error if neither exists."""
    text = os.fspath(name_or_path)
    if not isinstance(text, str) or not text or not text.isprintable():
        raise SceneError(f"{_show(text)}: expected a preset name or the path of a TOML file")
    shown = _clip(text, 200)
    path = Path(text)
    try:
        if path.suffix != ".toml" and not path.exists() and re.fullmatch(r"[\w-]+", text):
            path = SCENES_DIR / f"{text}.toml"
        if path.is_dir():
            raise SceneError(f"{shown}: is a folder; expected a TOML scene file or a preset name")
        if not path.exists():
            closest = _closest(path.stem, _presets())
            hint = f"did you mean {closest}? " if closest else ""
            raise SceneError(f"{shown}: no such scene file; {hint}presets: {', '.join(_presets())}")
        if not path.is_file():
            raise SceneError(f"{shown}: not a regular file; expected a TOML scene file")
    except OSError as error:
        raise SceneError(f"{shown}: cannot be read ({error.strerror or error})") from None
    return path


def _parse_toml(text: str, source: str) -> dict:
    """TOML text as a dict; every way tomllib can fail becomes one SceneError naming ``source``."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise SceneError(f"{source}: not valid TOML: {error}") from None
    except RecursionError:
        raise SceneError(f"{source}: not valid TOML: arrays or tables nested deeper than Python can read") from None
    except ValueError:  # an integer longer than int() reads (sys.int_info.default_max_str_digits)
        raise SceneError(
            f"{source}: holds an integer of more than {sys.get_int_max_str_digits():,} digits; "
            f"every number in a scene has far fewer"
        ) from None


def read_table(path: Path) -> dict:
    """The TOML table of a scene file, or SceneError: unreadable, too large, not UTF-8 text or not TOML."""
    try:
        with path.open("rb") as file:
            data = file.read(MAX_SCENE_BYTES + 1)  # no more, whatever the file's size
    except OSError as error:
        raise SceneError(f"{path}: cannot be read ({error.strerror or error})") from None
    if len(data) > MAX_SCENE_BYTES:
        raise SceneError(
            f"{path}: more than {MAX_SCENE_BYTES:,} bytes; a scene file is at most {MAX_SCENE_BYTES:,} "
            f"bytes (the presets are 1-2 kB)"
        )
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise SceneError(
            f"{path}: not UTF-8 text (byte 0x{data[error.start]:02x} at offset {error.start}); a scene "
            f"is a TOML text file"
        ) from None
    return _parse_toml(text.removeprefix("\ufeff"), str(path))


MAX_EXTENDS = 8
"""How many presets a chain of ``extends`` may pass through."""


def _merged(base: dict, child: dict) -> dict:
    """``child`` over ``base``: tables merged key by key, anything else (numbers, lists of tables such
    as fluid.blocks) replaced whole."""
    merged = dict(base)
    for name, value in child.items():
        if isinstance(value, dict) and isinstance(merged.get(name), dict):
            merged[name] = _merged(merged[name], value)
        else:
            merged[name] = value
    return merged


def resolve_extends(table: dict, source: str, folder: Path | None = None, seen: tuple[str, ...] = ()) -> dict:
    """The table with its ``extends = "preset"`` resolved: the named preset (or TOML path, relative to
    ``folder``) is loaded, resolved the same way, and this table's keys laid over it. A preset that
    differs from another only in size says so in data, and follows the other's changes."""
    if "extends" not in table:
        return table
    name = table["extends"]
    where = f"{source}: key 'extends'"
    if not isinstance(name, str):
        raise SceneError(f"{where}: expected a preset name or the path of a TOML file, got {_show(name)}", "extends")
    if len(seen) >= MAX_EXTENDS:
        raise SceneError(f"{where}: more than {MAX_EXTENDS} scenes extend one another ({' → '.join(seen)})", "extends")
    candidate = Path(name)
    if folder is not None and candidate.suffix == ".toml" and not candidate.is_absolute():
        candidate = folder / candidate
    try:
        path = resolve_path(candidate if candidate.suffix == ".toml" else name)
    except SceneError as error:
        raise SceneError(f"{where}: {error}", "extends") from None
    if str(path.resolve()) in seen:
        raise SceneError(f"{where}: {name!r} extends this scene in turn; allowed: a chain without loops", "extends")
    base = resolve_extends(read_table(path), str(path), path.parent, seen + (str(path.resolve()),))
    return _merged(base, {k: v for k, v in table.items() if k != "extends"})


PYTHON_OVERRIDES = "overrides"
"""Where ``load_scene``'s overrides come from unless said: a Python caller's list (the command line says
``COMMAND_LINE``)."""
COMMAND_LINE = "command line --set"


def parse_override(assignment: str, given_by: str = PYTHON_OVERRIDES) -> tuple[list[str], object]:
    """Split ``solver.iterations=6`` into a key path and a TOML value (bare words are strings); an error
    names the override as ``given_by`` gave it."""
    label = f"{given_by} {echo(assignment) if isinstance(assignment, str) else _show(assignment)}"
    if not isinstance(assignment, str):
        raise SceneError(f"{label}: expected a 'KEY=VALUE' string")
    if not assignment.isprintable():
        raise SceneError(
            f"{label}: expected one line of printable text (a newline would start a second TOML statement)"
        )
    if "=" not in assignment:
        raise SceneError(f"{label}: expected KEY=VALUE, e.g. solver.iterations=6")
    dotted, text = assignment.split("=", 1)
    keys = dotted.strip().split(".")
    if not all(re.fullmatch(r"[A-Za-z0-9_-]+", k) for k in keys):
        raise SceneError(f"{label}: '{_clip(dotted.strip())}' is not a dotted key such as solver.iterations")
    try:
        document = tomllib.loads(f"v = {text}")
    except tomllib.TOMLDecodeError:
        return keys, text.strip()
    except (RecursionError, ValueError):
        document = _parse_toml(f"v = {text}", label)
    return keys, document["v"]


def _table_of(scene: Scene) -> dict:
    """A Scene as the dict of its TOML file (omitted camera points left out)."""

    def plain(value):
        if dataclasses.is_dataclass(value):
            return {
                f.name: plain(getattr(value, f.name))
                for f in dataclasses.fields(value)
                if not f.metadata.get("internal") and getattr(value, f.name) is not None
            }
        if isinstance(value, tuple):
            return [plain(v) for v in value]
        return value

    return plain(scene)


def _set(table: dict, keys: list[str], value, label: str) -> None:
    """table[k0][k1]…[kn] = value, making the tables on the way."""
    target = table
    for depth, part in enumerate(keys[:-1]):
        target = target.setdefault(part, {})
        if isinstance(target, list):
            raise SceneError(
                f"{label}: '{'.'.join(keys[: depth + 1])}' is a list of tables; set it whole, e.g. "
                f"--set '{'.'.join(keys[: depth + 1])}=[{{min_m = [0, 0, 0], max_m = [0.5, 0.5, 0.5]}}]'"
            )
        if not isinstance(target, dict):
            raise SceneError(f"{label}: '{'.'.join(keys[: depth + 1])}' is not a table")
    target[keys[-1]] = value


def load_scene(
    source: str | os.PathLike | dict | Scene, overrides: typing.Sequence[str] = (), given_by: str = PYTHON_OVERRIDES
) -> Scene:
    """Load and validate a preset name, a TOML path, a dict or a Scene, applying ``KEY=VALUE``
    overrides first. An error in a key an override set names the override, not the file, and where it
    came from: ``given_by`` (the command line passes ``COMMAND_LINE``)."""
    if isinstance(overrides, (str, bytes)) or not isinstance(overrides, typing.Iterable):
        raise SceneError(f"overrides: expected a list of 'KEY=VALUE' strings, got {_show(overrides)}")
    if isinstance(source, Scene) and not overrides:
        return source  # checked when it was made
    if isinstance(source, Scene):
        table, origin = _table_of(source), source.source
    elif isinstance(source, dict):
        table, origin = copy.deepcopy(source), "<dict>"  # the overrides must not change the caller's dict
        table = resolve_extends(table, origin)
    elif isinstance(source, (str, os.PathLike)):
        path = resolve_path(source)
        origin = str(path)
        table = resolve_extends(read_table(path), origin, path.parent, (str(path.resolve()),))
    else:
        raise SceneError(f"{_show(source)}: expected a preset name, a TOML path, a dict or a pbf.Scene")
    overridden = {}
    for assignment in overrides:
        keys, value = parse_override(assignment, given_by)
        label = f"{given_by} {echo(assignment)}"
        _set(table, keys, value, label)
        overridden[".".join(keys)] = label
    try:
        return from_dict(table, origin)
    except SceneError as error:
        raise attribute(error, overridden) from None


def attribute(error: SceneError, labels: dict[str, str]) -> SceneError:
    """``error`` said of the command line when its key (or a table holding it) is one ``labels``
    maps to a label (``{"solver.iterations": "command line --set solver.iterations=0"}``): the
    user typed that value, not the file. Otherwise ``error`` itself."""
    key = error.key
    # The key itself or a table inside it came from the command line, or the command line made the
    # table by setting a key in it (--set obstacles.min_m=… makes 'obstacles' a table, not a list).
    label = next(
        (
            label
            for dotted, label in labels.items()
            if key is not None and (re.match(re.escape(dotted) + r"($|[.\[])", key) or dotted.startswith(key + "."))
        ),
        None,
    )
    if label is None:
        # A check of what two keys must agree on names one of them; when the other came from the
        # command line (--set obstacles=… against the file's time.max_cfl), say so, and keep the file's.
        message = str(error)
        mentioned = next(
            (
                label
                for dotted, label in labels.items()
                if re.search(r"(?<![\w.])" + re.escape(dotted) + r"(?![\w])", message)
            ),
            None,
        )
        if mentioned is None or message.startswith(mentioned):
            return error
        return SceneError(f"{mentioned}: does not agree with {message}", key)
    message = str(error)
    start = message.find(f"key '{_clip(key)}'")
    start -= len("unknown ") if message[:start].endswith("unknown ") else 0
    return SceneError(f"{label}: {message[max(start, 0) :]}", key)
