"""Headless output: numbered PNG frames, an optional MP4 and per-frame particle files, with a progress bar."""
from pathlib import Path

import imageio.v2 as imageio
import imageio.v3 as iio
from tqdm import tqdm

from pbf.export import write_particles
from pbf.render import SceneRenderer


def render(sim, frames: int, out_dir: Path, video: Path | None = None, export: str | None = None,
           progress: bool = True) -> list[Path]:
    """Step ``sim`` ``frames`` times, writing ``out_dir/frame_00001.png``… (and the video and particle
    files when asked); frame 0 is the initial state. Returns the PNG paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    renderer = SceneRenderer(sim)
    writer = None
    if video is not None:
        video.parent.mkdir(parents=True, exist_ok=True)
        fps = 1.0 / sim.scene.time.frame_dt_s
        writer = imageio.get_writer(video, fps=fps, codec="libx264", quality=8, macro_block_size=2)
    paths = []
    try:
        for frame in tqdm(range(frames + 1), desc=f"{sim.scene.name}: frames", unit="frame", disable=not progress):
            if frame:
                sim.step()
            image = renderer.frame()
            path = out_dir / f"frame_{frame:05d}.png"
            iio.imwrite(path, image)
            paths.append(path)
            if writer is not None:
                writer.append_data(image)
            if export is not None:
                write_particles(out_dir / f"particles_{frame:05d}.{export}", sim.positions(), sim.velocities(),
                                sim.time_s)
    finally:
        if writer is not None:
            writer.close()
    return paths
