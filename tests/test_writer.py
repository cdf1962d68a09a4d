"""The threaded frame writer (``pbf.app.writer``): frames encoded in worker threads are renamed into
place in frame order, complete, and an interrupted or failing run leaves only complete frames
0 … k behind, with no temporary files."""

import errno
import os
import threading
import time

import imageio.v3 as iio
import numpy as np
import pytest

from pbf.app import loop, writer
from pbf.app.headless import ExportError, FrameWriter
from pbf.app.writer import FrameFiles
from scenes import small_dam_break

FRAMES = 8


def images(count=FRAMES):
    """Distinct small images: frame k is filled with k."""
    return [np.full((12, 16, 3), k, np.uint8) for k in range(count)]


def slow_early_frames(monkeypatch, fail_at=None, error=OSError):
    """Frame k's encoding waits (FRAMES − k) × 10 ms, so that later frames finish first; ``fail_at``
    raises ``error`` in that frame's worker. Returns the list the renames are recorded in."""
    encode = writer.write_png

    def write_png(path, image, level):
        number = int(image[0, 0, 0])
        time.sleep(0.01 * (FRAMES - number))
        if number == fail_at:
            raise error("no space left on device")
        encode(path, image, level)

    renamed = []
    replace = writer.os.replace

    def record(source, target):
        renamed.append(target.name)
        replace(source, target)

    monkeypatch.setattr(writer, "write_png", write_png)
    monkeypatch.setattr(writer.os, "replace", record)
    return renamed


def test_frames_finished_out_of_order_are_written_in_order(tmp_path, monkeypatch):
    renamed = slow_early_frames(monkeypatch)
    files = FrameFiles(workers=4, depth=FRAMES)
    for k, image in enumerate(images()):
        files.submit(tmp_path / f"frame_{k:05d}.png", image)
    files.close()
    assert renamed == [f"frame_{k:05d}.png" for k in range(FRAMES)]
    assert sorted(p.name for p in tmp_path.iterdir()) == renamed  # no temporary file left
    for k in range(FRAMES):
        assert (iio.imread(tmp_path / f"frame_{k:05d}.png") == k).all()


def test_the_queue_is_bounded(tmp_path, monkeypatch):
    # With every encoder blocked, submit returns only while at most ``depth`` frames are in flight.
    release = threading.Event()
    encode = writer.write_png

    def blocked(path, image, level):
        release.wait(5.0)
        encode(path, image, level)

    monkeypatch.setattr(writer, "write_png", blocked)
    files = FrameFiles(workers=1, depth=2)
    submitted = []

    def produce():
        for k, image in enumerate(images(4)):
            files.submit(tmp_path / f"frame_{k:05d}.png", image)
            submitted.append(k)

    producer = threading.Thread(target=produce)
    producer.start()
    time.sleep(0.3)
    assert submitted == [0, 1]  # the third waits for the first to be written
    release.set()
    producer.join(5.0)
    files.close()
    assert submitted == [0, 1, 2, 3] and len(list(tmp_path.glob("frame_*.png"))) == 4


@pytest.mark.parametrize("error, raised", [(OSError, writer.WriteFailed), (KeyboardInterrupt, KeyboardInterrupt)])
def test_a_failing_frame_stops_the_writer_leaving_complete_frames_before_it(tmp_path, monkeypatch, error, raised):
    renamed = slow_early_frames(monkeypatch, fail_at=3, error=error)
    files = FrameFiles(workers=3, depth=FRAMES)
    for k, image in enumerate(images()):
        files.submit(tmp_path / f"frame_{k:05d}.png", image)
    with pytest.raises(raised):
        files.close()
    assert renamed == ["frame_00000.png", "frame_00001.png", "frame_00002.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == renamed  # the later frames' temporary files removed


def test_an_interrupted_run_writes_every_frame_drawn(tmp_path):
    # Ctrl-C while the simulation steps: the loop closes the viewer, which writes the frames already drawn.
    from pbf import Simulation

    sim = Simulation(small_dam_break(), overrides=["render.width_px=64", "render.height_px=36"], quiet=True)
    step = sim.step
    steps = []

    def interrupted(frames=1):
        if len(steps) == 3:
            raise KeyboardInterrupt
        steps.append(frames)
        step(frames)

    sim.step = interrupted
    viewer = FrameWriter(sim, 10, tmp_path, progress=False)
    with pytest.raises(KeyboardInterrupt):
        loop.run(sim, viewer, 10)
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"frame_{k:05d}.png" for k in range(4)]
    assert len({iio.imread(p).tobytes() for p in tmp_path.iterdir()}) == 4  # four different, readable frames


def test_png_files_decode_to_the_image():
    # The Sub filter subtracts modulo 256: noise (every difference, wrapping both ways) and a smooth
    # ramp, odd sizes, decoded by Pillow (through imageio) to the same bytes.
    rng = np.random.default_rng(7)
    noise = rng.integers(0, 256, (37, 53, 3), dtype=np.uint8)
    ramp = np.broadcast_to(np.arange(53, dtype=np.uint8)[None, :, None] * 5, (37, 53, 3)).copy()
    for image in (noise, ramp):
        for level in (0, 1, 9):
            assert np.array_equal(iio.imread(writer.png_bytes(image, level), extension=".png"), image)


@pytest.fixture(scope="module")
def small_sim():
    from pbf import Simulation

    return Simulation(small_dam_break(), overrides=["render.width_px=64", "render.height_px=36"], quiet=True)


def full_disk_at(monkeypatch, frame):
    """PNG frame ``frame`` fails as on a full disk (ENOSPC), in its worker."""
    encode = writer.write_png

    def write_png(path, image, level):
        if path.name == f".frame_{frame:05d}.png.partial":
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
        encode(path, image, level)

    monkeypatch.setattr(writer, "write_png", write_png)


def test_a_full_disk_is_one_line_naming_the_frame_and_what_was_kept(small_sim, tmp_path, monkeypatch):
    # The frames before the failure are whole; the video closed whole is kept under a name saying so.
    small_sim.reset()
    full_disk_at(monkeypatch, 3)
    video = tmp_path / "v.mp4"
    viewer = FrameWriter(small_sim, 8, tmp_path / "run", video=video, progress=False)
    with pytest.raises(ExportError) as failed:
        loop.run(small_sim, viewer, 8)
    message = str(failed.value)
    assert message.startswith(f"frame 3: could not write {tmp_path / 'run' / 'frame_00003.png'}: "), message
    assert "No space left on device (errno 28); frames 0-2 are complete in" in message and "\n" not in message
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == [f"frame_{k:05d}.png" for k in range(3)]
    assert not video.exists() and (tmp_path / "v.incomplete.mp4").exists(), message
    assert f"kept as {tmp_path / 'v.incomplete.mp4'}" in message


def test_a_video_writer_dying_mid_run_removes_the_unfinished_video(small_sim, tmp_path):
    small_sim.reset()
    video = tmp_path / "v.mp4"
    viewer = FrameWriter(small_sim, 8, None, video=video, progress=False, png=False)
    append = viewer.writer.append_data
    taken = []

    def dies(image):
        if len(taken) == 2:
            raise BrokenPipeError(errno.EPIPE, "Broken pipe")
        taken.append(image)
        append(image)

    viewer.writer.append_data = dies
    with pytest.raises(ExportError) as failed:
        loop.run(small_sim, viewer, 8)
    message = str(failed.value)
    assert f"could not write {video}: the video encoder (ffmpeg) stopped" in message, message
    assert f"the unfinished video {video} was removed" in message and "\n" not in message
    assert not video.exists() and list(tmp_path.iterdir()) == []
