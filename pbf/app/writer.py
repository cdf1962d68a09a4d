"""Writing frames off the main thread: PNG encoding and the video's frames in worker threads, behind a
bounded queue, so that the simulation and the renderer run while earlier frames are compressed.

zlib, not the GPU, set the frame rate of headless runs: encoding a 1280×720 frame at PNG's default
level takes several times as long as simulating and drawing it. Here the main thread hands each frame
(a host array it no longer uses) to a pool of threads, which encode it (``png_bytes``: one filter for
every row and zlib at a fast level; docs/BENCHMARKS.md, "Headless frames", measures sizes and times)
into a hidden temporary file; the main thread renames the files into place strictly in frame order, so that the
folder only ever holds complete frames ``0 … k``. NumPy's filter, zlib and writing to ffmpeg's pipe
release the GIL, so threads run them in parallel with the main thread's Taichi launches.

The queue is bounded (``depth`` frames in flight): when the encoders fall behind, the main thread
waits for the oldest frame rather than piling up images. ``close`` drains it, which is also what
happens when the run is interrupted (Ctrl-C) or fails: the frames already drawn are written; an
interruption while draining cancels what has not started and removes the unfinished temporary files.
"""

from __future__ import annotations

import os
import struct
import zlib
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import numpy as np

PNG_LEVEL = 1
"""zlib's level for PNG frames: with the Sub filter, level 1 encodes the seed scene's frames in a
third to a sixth of the CPU time of Pillow's defaults (adaptive filters, level 6) for files 10-20%
larger (docs/BENCHMARKS.md, "Headless frames")."""
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def default_workers() -> int:
    """Encoding threads: half the cores (at least one, at most eight); the other half runs the
    simulation on a CPU backend, and on a GPU backend eight keep up with hundreds of frames a second."""
    return max(1, min(8, (os.cpu_count() or 2) // 2))


def temporary_path(path: Path) -> Path:
    """Where ``path`` is written before it is renamed into place: hidden, beside it (the same file
    system, so the rename is atomic)."""
    return path.with_name(f".{path.name}.partial")


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(data, zlib.crc32(kind)))


def png_bytes(image: np.ndarray, level: int = PNG_LEVEL) -> bytes:
    """``image`` ((H, W, 3) uint8) as an 8-bit RGB PNG file's bytes. Every row takes PNG's Sub filter
    (each byte less the same channel of the pixel on its left, modulo 256), which a rendered frame's
    flat and smoothly shaded areas turn into runs of zeros and small numbers; Pillow tries five filters
    per row and picks one, which costs more than zlib at level 1 itself and made files 0-10% smaller
    here. NumPy and zlib release the GIL, so encoder threads run in parallel."""
    height, width, _ = image.shape
    rows = image.reshape(height, width * 3)
    filtered = np.empty((height, width * 3 + 1), np.uint8)
    filtered[:, 0] = 1  # the Sub filter's number
    filtered[:, 1:4] = rows[:, :3]
    np.subtract(rows[:, 3:], rows[:, :-3], out=filtered[:, 4:])  # uint8: modulo 256, as PNG defines it
    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)  # 8 bits, RGB, deflate, no interlace
    return (
        PNG_SIGNATURE
        + _chunk(b"IHDR", header)
        + _chunk(b"IDAT", zlib.compress(filtered.tobytes(), level))
        + _chunk(b"IEND", b"")
    )


def write_png(path: Path, image: np.ndarray, level: int = PNG_LEVEL) -> None:
    """``image`` ((H, W, 3) uint8) as a PNG file at ``path``, compressed at zlib ``level``."""
    with open(path, "wb") as file:
        file.write(png_bytes(image, level))


class WriteFailed(Exception):
    """A frame could not be written: ``path`` (a PNG frame, or the video) and ``frame`` (its number, None
    when not known), with the reason as one line (``reason``)."""

    def __init__(self, path: Path | None, frame: int | None, cause: BaseException):
        self.path, self.frame, self.cause = path, frame, cause
        super().__init__(f"{path}: {reason(cause)}")

    @property
    def reason(self) -> str:
        return reason(self.cause)


def reason(error: BaseException) -> str:
    """An error as one line: an OSError's text and number (a full disk: "No space left on device (errno
    28)"), else its type and first line (the video encoder's StopIteration says nothing of itself)."""
    if isinstance(error, OSError) and error.strerror:
        return f"{error.strerror} (errno {error.errno})"
    text = (str(error).strip().splitlines() or [""])[0][:200]
    name = type(error).__name__
    if isinstance(error, StopIteration | BrokenPipeError | EOFError):
        return f"the video encoder (ffmpeg) stopped ({name}{': ' + text if text else ''})"
    return f"{name}: {text}" if text else name


class FrameFiles:
    """PNG frames (and optionally a video's frames) encoded in worker threads and written in order.

    ``submit(path, image)`` queues one frame (``path`` None: the video's frame alone, no PNG); the
    image must not change afterwards (the renderer hands over a fresh array each frame). Errors in a
    worker (a full disk) are raised by a later ``submit`` or by ``close``."""

    def __init__(
        self,
        video=None,
        workers: int | None = None,
        depth: int | None = None,
        level: int = PNG_LEVEL,
        video_path: Path | None = None,
    ):
        """``video``: an imageio writer whose ``append_data`` takes the frames in order, or None (its file
        ``video_path``, named when it fails). A failure is raised as :class:`WriteFailed`."""
        self.workers = workers or default_workers()
        self.depth = depth or 2 * self.workers + 1
        """Frames queued or being encoded at most, per kind of output."""
        self.level = level
        self.pool = ThreadPoolExecutor(self.workers, thread_name_prefix="pbf-png")
        self.video = video
        # One thread for the video: a single worker runs its tasks in the order they were queued.
        self.video_pool = ThreadPoolExecutor(1, thread_name_prefix="pbf-video") if video is not None else None
        self.pending: deque[tuple[Path, Future]] = deque()
        """PNG frames not yet renamed into place, in frame order."""
        self.video_path = video_path
        self.video_pending: deque[Future] = deque()
        self.video_frames = 0
        """Frames the video took."""
        self.submitted = 0
        self.written = 0
        """Frames renamed into place."""

    def submit(self, path: Path | None, image: np.ndarray) -> None:
        if path is not None:
            self.pending.append((path, self.pool.submit(write_png, temporary_path(path), image, self.level)))
        if self.video_pool is not None:
            self.video_pending.append(self.video_pool.submit(self.video.append_data, image))
        self.submitted += 1
        # Frames already encoded go into place now; beyond the bound, wait for the oldest.
        while self.pending and (self.pending[0][1].done() or len(self.pending) > self.depth):
            self._publish_oldest()
        while self.video_pending and (self.video_pending[0].done() or len(self.video_pending) > self.depth):
            self._video_oldest()

    def _publish_oldest(self) -> None:
        path, future = self.pending[0]
        try:
            future.result()  # the worker's error, if any, here
            os.replace(temporary_path(path), path)
        except Exception as error:
            raise WriteFailed(path, self.written, error) from error
        self.pending.popleft()
        self.written += 1

    def _video_oldest(self) -> None:
        try:
            self.video_pending[0].result()
        except Exception as error:
            raise WriteFailed(self.video_path, self.video_frames, error) from error
        self.video_pending.popleft()
        self.video_frames += 1

    def close(self) -> None:
        """Write every frame submitted, in order, and stop the threads. Interrupted (a second Ctrl-C)
        or failing, it stops cleanly instead: nothing more is started, what runs is waited for, and
        the temporary files of the frames not written are removed."""
        try:
            while self.pending:
                self._publish_oldest()
            while self.video_pending:
                self._video_oldest()
        except BaseException:
            self.abort()
            raise
        finally:
            self.pool.shutdown(wait=True)
            if self.video_pool is not None:
                self.video_pool.shutdown(wait=True)

    def abort(self) -> None:
        """Stop without writing the frames still queued: cancel what has not started, wait for what
        has, and remove their temporary files."""
        self.pool.shutdown(wait=True, cancel_futures=True)
        if self.video_pool is not None:
            self.video_pool.shutdown(wait=True, cancel_futures=True)
        for path, _ in self.pending:
            temporary_path(path).unlink(missing_ok=True)
        self.pending.clear()
        self.video_pending.clear()
