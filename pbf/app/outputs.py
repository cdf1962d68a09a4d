"""Where a run writes, checked before it starts: the frame folder, the video and the files in them.

A run writes ``frame_NNNNN.png`` and, when asked, ``particles_NNNNN.ply`` or ``.npz`` and
``surface_NNNNN.ply`` or ``.obj`` (and ``bodies_NNNNN`` beside it, the rigid bodies' meshes; ``diffuse_NNNNN``,
white water's particles, in the surface style) into one folder, and a
video where ``--video`` says. Every path is
checked before the simulation starts, so a bad one fails with one message and leaves nothing half
written: an empty path, the filesystem root, a file where a folder is needed (or a folder where a
file is), a parent that is a file, a place that cannot be written (tried by creating and removing
a probe file there: permissions alone do not tell, /proc and read-only mounts refuse anyway).

Nothing of the user's is deleted unasked: a folder the user named holding files under these names (an
earlier run's) and an existing video are refused, unless ``overwrite`` is given (the command line's
``--overwrite``); then only files under these names are removed, so that old and new frames never
mix, and nothing else in the folder is touched. A run into the default folder instead takes the next
free name (``out/dam_break-2`` …, ``free_default_folder``), so that the README's examples run one after
another. Pure standard library: the command line checks its outputs without starting Taichi.
"""

from __future__ import annotations

import errno
import os
import re
import tempfile
from pathlib import Path

MAX_FRAMES = 99_999
"""Frame numbers have five digits (frame_00000.png …), so that the files sort in order."""
VIDEO_SUFFIXES = (".mp4", ".mkv", ".mov", ".avi")
OWN_FILE = re.compile(r"(frame_\d{5}\.png|(particles|diffuse)_\d{5}\.(ply|npz)|(surface|bodies)_\d{5}\.(ply|obj))")
"""The names a run writes into its folder (``pbf.app.headless.FrameWriter``), and the only files an
earlier run's clean-up removes."""


class OutputError(ValueError):
    """An output path that cannot be written; the message names the option, the path and why."""


def frame_name(number: int) -> str:
    return f"frame_{number:05d}.png"


def particles_name(number: int, suffix: str) -> str:
    return f"particles_{number:05d}.{suffix}"


def diffuse_name(number: int, suffix: str) -> str:
    """White water's diffuse particles of a frame (the surface style with white water on)."""
    return f"diffuse_{number:05d}.{suffix}"


def surface_name(number: int, suffix: str) -> str:
    return f"surface_{number:05d}.{suffix}"


def bodies_name(number: int, suffix: str) -> str:
    """The rigid bodies' meshes of a frame, beside the water's surface (scenes with [[bodies]])."""
    return f"bodies_{number:05d}.{suffix}"


def default_folder(scene_path: str) -> Path:
    """``out/`` + the scene file's name (``out/dam_break`` for ``scenes/dam_break.toml``), made of
    letters, digits, ``_``, ``-`` and ``.`` only, so no name can lead outside ``out/``."""
    stem = re.sub(r"[^\w.-]", "_", Path(scene_path).stem).lstrip(".")
    return Path("out") / (stem or "scene")


MAX_DEFAULT_FOLDERS = 999
"""How many numbered default folders (``out/dam_break-2`` … ``-999``) a run tries before it asks for --out."""


def free_default_folder(base: Path) -> Path:
    """``base`` (``out/dam_break``) if it holds no earlier run's files, else the first of ``base-2``,
    ``base-3`` … that holds none (or does not exist yet): a run into the default folder never mixes
    with, nor deletes, an earlier one's frames. OutputError when all of them are taken."""
    for number in range(1, MAX_DEFAULT_FOLDERS + 1):
        candidate = base if number == 1 else base.with_name(f"{base.name}-{number}")
        try:
            if not earlier_files(candidate):
                return candidate
        except OSError:
            return candidate  # not a readable folder: check_folder says why, naming it
    raise OutputError(
        f"the default output folder (--out) {_shown(str(base))}: it and {base.name}-2 … "
        f"{base.name}-{MAX_DEFAULT_FOLDERS} all hold earlier runs' files; give --out, or --overwrite "
        f"to replace {base}'s"
    )


def _shown(text: str) -> str:
    return repr(text if len(text) <= 80 else text[:79] + "…")


KERNEL_FILESYSTEMS = {"proc", "sysfs", "cgroup", "cgroup2", "debugfs", "tracefs", "securityfs", "configfs", "bpf"}
"""Filesystems through which the kernel shows its own state (Linux): no user file can be made in them."""


def _filesystem(folder: Path) -> str | None:
    """The type of the filesystem ``folder`` is on, from the kernel's mount table (Linux), or None."""
    try:
        mounts = Path("/proc/self/mounts").read_text().splitlines()
    except OSError:
        return None
    point = folder.resolve()
    while not os.path.ismount(point) and point != point.parent:
        point = point.parent
    # The table escapes a space in a mount point as \040 (octal); the last mount on a point is the one in use.
    types = [
        fields[2]
        for fields in map(str.split, mounts)
        if len(fields) > 2 and re.sub(r"\\([0-7]{3})", lambda m: chr(int(m[1], 8)), fields[1]) == str(point)
    ]
    return types[-1] if types else None


def _why_not(folder: Path, error: OSError) -> str:
    """Why nothing can be created in ``folder``, as a reader needs it: the kind of place first, then the
    system's own words (/proc answers a new file with "No such file or directory", which says nothing)."""
    words = error.strerror or str(error)
    kind = _filesystem(folder)
    if kind in KERNEL_FILESYSTEMS:
        return f"{folder} is the kernel's {kind} filesystem, which holds only the kernel's own files ({words})"
    if error.errno == errno.EROFS:
        return f"{folder} is on a read-only filesystem ({words})"
    if error.errno in (errno.EACCES, errno.EPERM):
        return f"no permission to write in {folder} ({words})"
    return f"{folder} refuses new files ({words})"


def _probe(folder: Path, label: str, what: str | None = None) -> None:
    """Create and remove a file in the existing ``folder``: the only test that a write will succeed
    (os.access says yes to root everywhere, and /proc or a read-only mount refuse anyway). ``what``:
    the folder or file the run would create in it, for the message; None when it writes in ``folder``."""
    try:
        handle, name = tempfile.mkstemp(prefix=".pbf-probe-", dir=folder)
    except OSError as error:
        if what is None:
            raise OutputError(f"{label}: cannot write in {folder}: {_why_not(folder, error)}") from None
        raise OutputError(f"{label}: the {what} cannot be created in {folder}: {_why_not(folder, error)}") from None
    os.close(handle)
    os.unlink(name)


def _writable_place(path: Path, label: str, what: str) -> None:
    """The nearest existing folder on the way to ``path`` must be a folder we may write in. ``what``:
    what ``path`` is (the "folder", the "video file"), for the message."""
    ancestor = path.absolute().parent
    while not ancestor.exists():
        ancestor = ancestor.parent
        what = "folder"  # the first thing the run would create is then a folder on the way
    if not ancestor.is_dir():
        raise OutputError(f"{label}: {ancestor} is a file, not a folder; choose another path")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise OutputError(f"{label}: cannot create it, no permission to write in {ancestor}")
    _probe(ancestor, label, what)


OVERWRITE_HINT = "add --overwrite to replace them (only the frame, particle and surface files of a run are removed)"


def check_folder(text: str, label: str, overwrite: bool = False) -> Path:
    """The folder ``text`` names, ready to hold a run's files, or OutputError; writes nothing that
    stays. A folder that holds an earlier run's files is refused unless ``overwrite``."""
    if not text or not text.isprintable():
        raise OutputError(f"{label} {_shown(text)}: expected the path of a folder for the frames")
    path = Path(text)
    try:
        if path.resolve() == Path(path.resolve().anchor):
            raise OutputError(f"{label} {_shown(text)}: is the filesystem root; choose a folder for the frames")
        if path.exists():
            if not path.is_dir():
                raise OutputError(f"{label} {_shown(text)}: is a file; expected a folder for the frames")
            if not os.access(path, os.W_OK | os.X_OK):
                raise OutputError(f"{label} {_shown(text)}: cannot write into it (no permission)")
            earlier = earlier_files(path)
            blocking = next((p for p in earlier if p.is_dir() and not p.is_symlink()), None)
            if blocking is not None:
                raise OutputError(
                    f"{label} {_shown(text)}: {blocking.name} is a folder where a frame file goes; "
                    f"move it or choose another folder"
                )
            if earlier and not overwrite:
                raise OutputError(
                    f"{label} {_shown(text)}: holds {len(earlier)} files of an earlier run "
                    f"({earlier[0].name} …); {OVERWRITE_HINT}, or choose another folder"
                )
            _probe(path, f"{label} {_shown(text)}")
        else:
            _writable_place(path, f"{label} {_shown(text)}", "folder")
    except OSError as error:
        raise OutputError(f"{label} {_shown(text)}: {error.strerror or error}") from None
    return path


def check_video(text: str, label: str, overwrite: bool = False) -> Path:
    """The video file ``text`` names, ready to be written, or OutputError; an existing one is refused
    unless ``overwrite`` (then it is replaced)."""
    if not text or not text.isprintable():
        raise OutputError(f"{label} {_shown(text)}: expected the path of a video file, e.g. out/scene.mp4")
    path = Path(text)
    if path.suffix.lower() not in VIDEO_SUFFIXES:
        raise OutputError(f"{label} {_shown(text)}: expected a file ending in {', '.join(VIDEO_SUFFIXES)}")
    try:
        if path.is_dir():
            raise OutputError(f"{label} {_shown(text)}: is a folder; expected a video file")
        if path.exists():
            if not path.is_file():
                raise OutputError(f"{label} {_shown(text)}: is not a regular file; expected a video file")
            if not overwrite:
                raise OutputError(
                    f"{label} {_shown(text)}: exists; add --overwrite to replace it, or choose another name"
                )
            if not os.access(path, os.W_OK):
                raise OutputError(f"{label} {_shown(text)}: cannot replace it (no permission)")
            _probe(path.parent, f"{label} {_shown(text)}")
        else:
            _writable_place(path, f"{label} {_shown(text)}", "video file")
    except OSError as error:
        raise OutputError(f"{label} {_shown(text)}: {error.strerror or error}") from None
    return path


def earlier_files(folder: Path) -> list[Path]:
    """The files in ``folder`` named as a run names its own (an earlier run's frames and particles)."""
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if OWN_FILE.fullmatch(p.name))


def clear_earlier(folder: Path) -> list[Path]:
    """Remove an earlier run's files from ``folder`` (links themselves, never what they point to),
    so that its frames cannot mix with the new ones; returns what was removed. Only for --overwrite
    (``check_folder`` refuses such a folder otherwise)."""
    removed = earlier_files(folder)
    for path in removed:
        path.unlink()
    return removed
