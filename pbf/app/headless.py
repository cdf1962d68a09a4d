"""The headless viewer: numbered PNG frames, an optional video (or the video alone) and per-frame
particle and surface mesh files, with a progress bar. Each frame is drawn on the device and copied to
the host once; its PNG and video encoding run in worker threads (``pbf.app.writer``) while the next
frames are simulated and drawn."""

from __future__ import annotations

from pathlib import Path

import imageio.v2 as imageio
import numpy as np
from tqdm import tqdm

from pbf.app.export import run_info, write_particles, write_run_info
from pbf.app.mesh import SurfaceError, body_mesh, reconstruct, write_mesh
from pbf.app.outputs import bodies_name, diffuse_name, frame_name, particles_name, surface_name
from pbf.app.render import SceneRenderer, View
from pbf.app.writer import FrameFiles


class ExportError(RuntimeError):
    """A frame's files could not be made (the surface mesh); the message names the frame and what the
    folder holds. The frames before it are complete: a frame's files are written only once all exist."""


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
            self.writer = imageio.get_writer(video, fps=fps, codec="libx264", quality=8, macro_block_size=2)
        self.files = FrameFiles(video=self.writer)
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
        self.files.submit(path, image)
        if path is not None:
            self.paths.append(path)
        self.shown += 1
        up_axis = self.sim.scene.export.up_axis
        if number == 0 and self.exports:
            view = View.of_scene(self.sim.scene)
            info = run_info(
                self.sim.scene,
                view.eye,
                view.target,
                view.fov_deg,
                self.total - 1,
                self.exports,
                self.sim.scene.surface.mesh_format,
                self._diffuse_format() if self.renderer.white_water is not None else None,
            )
            write_run_info(self.out_dir, info)
        for name in self.exports:
            if name == "mesh":
                for file_name, mesh in meshes.items():
                    write_mesh(self.out_dir / file_name, mesh, self.sim.time_s, up_axis)
            else:
                write_particles(
                    self.out_dir / particles_name(number, name),
                    self.sim.positions(),
                    self.sim.velocities(),
                    self.sim.time_s,
                    up_axis,
                )
        white_water = self.renderer.white_water
        if self.exports and white_water is not None:  # drawn with this frame: written beside it
            diffuse = white_water.arrays()
            write_particles(
                self.out_dir / diffuse_name(number, self._diffuse_format()),
                diffuse["positions"],
                diffuse["velocities"],
                self.sim.time_s,
                up_axis,
                {"kind": diffuse["kind"].astype(np.float32), "age_s": diffuse["age"]},
            )
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

    def _diffuse_format(self) -> str:
        """White water's file format: the particles' (``--export ply|npz``), PLY beside meshes alone."""
        return next((name for name in self.exports if name != "mesh"), "ply")

    def close(self) -> None:
        """Write the frames still queued (also when the run was interrupted or failed: they are drawn),
        then close the video."""
        try:
            self.files.close()
        finally:
            if self.progress is not None:
                self.progress.close()
            if self.writer is not None:
                self.writer.close()
