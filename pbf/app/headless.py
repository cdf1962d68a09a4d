"""The headless viewer: numbered PNG frames, an optional video (or the video alone) and per-frame
particle and surface mesh files, with a progress bar. Each frame is drawn on the device and copied to
the host once; its PNG and video encoding run in worker threads (``pbf.app.writer``) while the next
frames are simulated and drawn."""

from __future__ import annotations

import os
import shutil
from functools import partial
from pathlib import Path

import imageio.v2 as imageio
import numpy as np
from tqdm import tqdm

from pbf.app.export import RUN_INFO, run_info, write_particles, write_run_info
from pbf.app.mesh import SurfaceError, body_mesh, reconstruct, write_mesh
from pbf.app.outputs import bodies_name, diffuse_name, frame_name, particles_name, surface_name
from pbf.app.render import SceneRenderer, View
from pbf.app.writer import FrameFiles, WriteFailed


class ExportError(RuntimeError):
    """A frame's files could not be made (the surface mesh); the message names the frame and what the
    folder holds. The frames before it are complete: a frame's files are written only once all exist."""


FULL_BELOW_BYTES = 16 << 20
"""Free space below which a failed video's message says that the disk is full (ffmpeg's own error
is only a broken pipe to us)."""


def disk_note(folder: Path) -> str:
    """ ", the disk holding ``folder`` is full" when it nearly is, else ""."""
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return ""
    return f", the disk holding {folder} is full ({free:,} bytes free)" if free < FULL_BELOW_BYTES else ""


class FrameWriter:
    """Writes ``out_dir/frame_00000.png`` (the state it is shown first) and one PNG per later frame
    (unless ``png`` is false: a video alone), and, when asked, appends each to a video and writes the
    particles (``particles_00000.ply`` or ``.npz``) and the surface mesh (``surface_00000.ply`` or
    ``.obj``, and the bodies' ``bodies_00000``) beside it. The paths are checked before the run
    (``pbf.app.outputs``); this only creates the folders. ``out_dir`` may be None when nothing goes
    there (no PNG, no exports)."""

    def __init__(
        self,
        sim,
        frames: int,
        out_dir: Path | None,
        video: Path | None = None,
        export=(),
        progress: bool = True,
        png: bool = True,
    ):
        self.sim = sim
        self.out_dir = out_dir
        self.exports = tuple(dict.fromkeys(export or ()))
        """Names from ``pbf.app.export.EXPORTS``, each once."""
        self.png = png
        if png or self.exports:
            out_dir.mkdir(parents=True, exist_ok=True)
        self.renderer = SceneRenderer(sim)
        self.writer = None
        if video is not None:
            video.parent.mkdir(parents=True, exist_ok=True)
            fps = 1.0 / sim.scene.time.frame_dt_s
            # ffmpeg quiet: a failure is said in one line of ours (_failure), not its log.
            self.writer = imageio.get_writer(
                video, fps=fps, codec="libx264", quality=8, macro_block_size=2, ffmpeg_log_level="quiet"
            )
        self.video = video
        self.files = FrameFiles(video=self.writer, video_path=video)
        self.failed = False
        """A write failed: the files were cleaned up and the failure reported (:meth:`_failure`)."""
        """The PNG and video encoders, in worker threads."""
        self.paths: list[Path] = []
        """The PNG frames written."""
        self.shown = 0
        """Frames shown (drawn and handed to the encoders), with or without a PNG."""
        self.total = frames + 1
        """The start and ``frames`` steps."""
        self.show_progress = progress
        self.progress = None
        """The progress bar, from the second frame on: the command line says when the first is written."""

    def running(self) -> bool:
        return True

    def advance(self) -> bool:
        return True

    def show(self) -> None:
        number = self.shown
        # The surface first: when splashsurf fails, nothing of this frame is written and the folder
        # holds whole frames only (each with its PNG, particles and meshes).
        meshes = {}
        if "mesh" in self.exports:
            fmt = self.sim.scene.surface.mesh_format
            try:
                meshes[surface_name(number, fmt)] = reconstruct(
                    self.sim.positions(), self.sim.scene, self.sim.velocities()
                )
            except SurfaceError as error:
                kept = (
                    f"frames 0-{number - 1} are complete in {self.out_dir}/"
                    if number > 1
                    else f"frame 0 is complete in {self.out_dir}/"
                    if number
                    else "no frame was written"
                )
                raise ExportError(
                    f"frame {number} (t = {self.sim.time_s:.3f} s): the surface mesh could not be made ({error}); "
                    f"{kept}; --set surface.deterministic=false may mesh it another way"
                ) from None
            bodies = self.sim.scene.bodies
            if bodies:
                meshes[bodies_name(number, fmt)] = body_mesh(
                    [b.shape for b in bodies], [b.half_extents() for b in bodies], self.sim.body_states()
                )
        image = self.renderer.frame()  # a fresh host array, handed over to the encoders
        path = self.out_dir / frame_name(number) if self.png else None
        try:
            self.files.submit(path, image)
            if path is not None:
                self.paths.append(path)
            self.shown += 1
            for file_path, write in self._exported(number, meshes):
                try:
                    write(file_path)
                except OSError as error:
                    raise WriteFailed(file_path, number, error) from error
        except WriteFailed as error:
            raise self._failure(error) from None
        if number == 1:
            self.progress = tqdm(
                total=self.total,
                initial=1,
                desc=f"{self.sim.scene.name}: frames",
                unit="frame",
                disable=not self.show_progress,
            )
        if self.progress is not None:
            self.progress.update()

    def _exported(self, number: int, meshes: dict):
        """(path, write) of every file this frame exports: run.json with the first, the meshes, the
        particles, white water's particles."""
        sim, up_axis = self.sim, self.sim.scene.export.up_axis
        files = []
        if number == 0 and self.exports:
            view = View.of_scene(sim.scene)
            info = run_info(
                sim.scene,
                view.eye,
                view.target,
                view.fov_deg,
                self.total - 1,
                self.exports,
                sim.scene.surface.mesh_format,
                self._diffuse_format() if self.renderer.white_water is not None else None,
            )
            files.append((self.out_dir / RUN_INFO, lambda path: write_run_info(path.parent, info)))
        for name in self.exports:
            if name == "mesh":
                for file_name, mesh in meshes.items():
                    files.append(
                        (self.out_dir / file_name, partial(write_mesh, mesh=mesh, time_s=sim.time_s, up_axis=up_axis))
                    )
            else:
                files.append(
                    (
                        self.out_dir / particles_name(number, name),
                        lambda path: write_particles(path, sim.positions(), sim.velocities(), sim.time_s, up_axis),
                    )
                )
        white_water = self.renderer.white_water
        if self.exports and white_water is not None:  # drawn with this frame: written beside it
            diffuse = white_water.arrays()
            extra = {"kind": diffuse["kind"].astype(np.float32), "age_s": diffuse["age"]}
            files.append(
                (
                    self.out_dir / diffuse_name(number, self._diffuse_format()),
                    lambda path: write_particles(
                        path, diffuse["positions"], diffuse["velocities"], sim.time_s, up_axis, extra
                    ),
                )
            )
        return files

    def _diffuse_format(self) -> str:
        """White water's file format: the particles' (``--export ply|npz``), PLY beside meshes alone."""
        return next((name for name in self.exports if name != "mesh"), "ply")

    def close(self) -> None:
        """Write the frames still queued (also when the run was interrupted or failed: they are drawn),
        then close the video. A write that fails here too is one ExportError (:meth:`_failure`)."""
        try:
            if not self.failed:
                self.files.close()
        except WriteFailed as error:
            raise self._failure(error) from None
        finally:
            if self.progress is not None:
                self.progress.close()
        if self.writer is not None:
            writer, self.writer = self.writer, None
            try:
                writer.close()
            except Exception as error:
                raise self._failure(WriteFailed(self.video, self.files.video_frames, error)) from None

    def _failure(self, failed: WriteFailed) -> ExportError:
        """What to raise when a file could not be written (a full disk, a folder that lost its permissions,
        the video encoder that died): the frames queued dropped with their temporary files, a video that
        could not be finished removed, or kept as ``NAME.incomplete.mp4`` when it closes whole but the
        run stopped early; one line saying what failed, where, and what was kept."""
        self.failed = True
        why = failed.reason
        if failed.path == self.video and self.video is not None:  # the disk as it was when the encoder stopped
            why = f"the video encoder (ffmpeg) stopped ({why}){disk_note(self.video.parent)}"
        self.files.abort()
        if self.progress is not None:
            self.progress.close()
        video = ""
        if self.writer is not None or (failed.path == self.video and self.video is not None):
            video = self._video_after_failure(video_failed=failed.path == self.video)
        written = self.files.written
        kept = (
            f"frames 0-{written - 1} are complete in {self.out_dir}/"
            if written > 1
            else f"frame 0 is complete in {self.out_dir}/"
            if written
            else "no PNG frame was written"
        )
        if not self.png:
            kept = "no PNG frames were asked for"
        frame = "" if failed.frame is None else f"frame {failed.frame}: "
        return ExportError(f"{frame}could not write {failed.path}: {why}; {kept}{video}")

    def _video_after_failure(self, video_failed: bool) -> str:
        writer, self.writer = self.writer, None
        closed = False
        if writer is not None:
            try:
                writer.close()
                closed = True
            except Exception:  # the encoder died with the disk: the file has no index, nothing plays it
                closed = False
        path = self.video
        if closed and not video_failed and path.exists():
            incomplete = path.with_name(f"{path.stem}.incomplete{path.suffix}")
            try:
                os.replace(path, incomplete)
                return f"; the video stopped early, kept as {incomplete}"
            except OSError:
                pass
        try:
            path.unlink(missing_ok=True)
        except OSError as error:
            return f"; the unfinished video {path} could not be removed ({error.strerror}): it will not play"
        return f"; the unfinished video {path} was removed"
