"""What the application shows: the camera, the rendering of frames and the reconstructed surface.
The solver reads none of these."""

from __future__ import annotations

from dataclasses import dataclass

from pbf.scene.schema import (
    SceneError,
    Vec3,
    _between,
    _colour_map,
    _even_pixels,
    _length,
    _num,
    _one_of,
    _vec,
    _vec_between,
    key,
)

CAMERA_REACH_DIAGONALS = 1000
"""How far the camera may stand from the container's centre, in container diagonals: from farther,
the whole box is narrower than a pixel at any allowed field of view and image size."""


@dataclass(frozen=True)
class Camera:
    """Where the window opens and what headless frames show; omitted points are derived from the box."""

    position_m: Vec3 | None = key(None, doc="eye position, m (default: in front of the box, above it)")
    look_at_m: Vec3 | None = key(None, doc="point at the image centre, m (default: the box centre)")
    fov_deg: float = key(45.0, _between(5.0, 150.0), "vertical field of view, degrees")


@dataclass(frozen=True)
class Render:
    colour_by: str = key("speed", _one_of("speed", "density"), "particle colour: speed or density")
    colour_map: str = key("coolwarm", _colour_map, "Matplotlib colour map")
    speed_max_m_s: float = key(3.0, _between(1e-6, 1e6), "speed at the top of the colour map, m/s")
    density_error_max: float = key(
        0.05,
        _between(1e-6, 1.0),
        "colour map spans ρ/ρ0 from 1 − this to 1 + this (ρ/ρ0 ≥ 0, and float32 resolves 1e-6)",
    )
    background_rgb: Vec3 = key((0.96, 0.96, 0.94), _vec_between(0.0, 1.0), "background colour (red, green, blue)")
    container_rgb: Vec3 = key((0.25, 0.25, 0.3), _vec_between(0.0, 1.0), "colour of the container's edges")
    width_px: int = key(1280, _even_pixels, "image width, pixels")
    height_px: int = key(720, _even_pixels, "image height, pixels")
    legend: bool = key(
        True,
        doc="draw the colour legend (bar, range and unit) on headless frames of particles (the surface style's "
        "colours are the water's own: no legend); the window's panel always shows it",
    )
    style: str = key(
        "particles",
        _one_of("particles", "surface"),
        "frames and the window (at first; key v "
        "switches) show particles (spheres in the colour map) or the water's surface (see [surface])",
    )


@dataclass(frozen=True)
class Surface:
    """The free surface reconstructed from the particles (``--export mesh``, ``--style surface``).

    Lengths are in particle spacings, so one table serves every resolution. The mesh is the iso
    surface of splashsurf's colour field Σ_j (m_j/ρ_j) W(x − x_j) (about 1 inside, 0 outside),
    smoothed by the weighted Laplacian of Löschner et al. 2023. The defaults keep a splash's mesh
    within 5% of its water's volume (a wider kernel wraps spray and thin sheets in fat blobs).
    """

    smoothing_length_spacings: float = key(
        0.8,
        _between(0.5, 4.0),
        "SPH smoothing length of the colour field (kernel support twice this; wider wraps a splash's spray "
        "and sheets in fat blobs), spacings",
    )
    cube_size_spacings: float = key(0.5, _between(0.1, 2.0), "marching-cubes cell edge, spacings")
    iso_level: float = key(
        0.5,
        _between(0.05, 0.95),
        "colour-field value of the surface (1 in the bulk, 0.5 where a flat body of the particles' volume ends)",
    )
    smoothing_iterations: int = key(
        10,
        _between(0, 1000),
        "Laplacian smoothing passes over the mesh (they round off marching cubes' steps; resting water keeps "
        "its volume)",
    )
    mesh_format: str = key("ply", _one_of("ply", "obj"), "file format of --export mesh: binary PLY or text OBJ")
    deterministic: bool = key(
        True,
        doc="one thread, no subdomains: the same mesh for the same particles on every run "
        "(splashsurf's parallel subdomains vary from run to run); false is faster",
    )
    absorption_per_m: Vec3 = key(
        (5.0, 1.8, 1.0),
        _vec_between(0.0, 1e6),
        "Beer–Lambert absorption of red, green and blue light in render.style = surface, 1/m",
    )
    water_rgb: Vec3 = key(
        (0.03, 0.25, 0.4), _vec_between(0.0, 1.0), "colour of deep water (the light it absorbs is replaced by this)"
    )
    shutter_frames: float = key(
        0.5,
        _between(0.0, 2.0),
        "motion blur: how long a frame's exposure lasts, in frame times (0.5: a film camera's 180° shutter; 0: "
        "none); drops and white water are drawn stretched along their velocity over it",
    )


MAX_WHITE_WATER = 2**24
"""Most diffuse particles a budget may ask for (about 80 bytes each on the device)."""


@dataclass(frozen=True)
class WhiteWater:
    """Spray, foam and air bubbles (Ihmsen et al. 2012): diffuse particles emitted where the water traps air,
    at wave crests and where it moves fast, drawn in ``render.style = "surface"`` and written by ``--export``.
    A post-process of the fluid's particles: the simulation never sees them. Its thresholds are in units of
    the scene's kernel radius h and gravity, so every scene gets white water without tuning."""

    enabled: bool = key(
        True, doc="emit and draw white water in the surface style (and write it with --export in that style)"
    )
    budget: int = key(
        0,
        _between(0, MAX_WHITE_WATER),
        "most diffuse particles at once, allocated at the start (0: twice the fluid's particle capacity); "
        "when it is full, emission waits",
    )
    lifetime_s: float = key(2.0, _between(0.01, 600.0), "mean life of foam on the surface, s")
    amount: float = key(
        1.0, _between(0.0, 100.0), "emission rate, relative to the default (0: only what is alive stays)"
    )


def default_look_at_m(scene) -> Vec3:
    """Where the camera looks when camera.look_at_m is omitted: a little below the box centre (the
    renderer's ``View.of_scene``; seen from above, the box's near bottom corner reaches lowest)."""
    lo, hi = scene.container.min_m, scene.container.max_m
    centre = [0.5 * (a + b) for a, b in zip(lo, hi)]
    return (centre[0], centre[1] - 0.08 * (hi[1] - lo[1]), centre[2])


def _check_camera(scene, source: str) -> None:
    lo, hi = scene.container.min_m, scene.container.max_m
    centre = [0.5 * (a + b) for a, b in zip(lo, hi)]
    diagonal = _length([b - a for a, b in zip(lo, hi)])
    farthest = CAMERA_REACH_DIAGONALS * diagonal
    for name in ("position_m", "look_at_m"):
        point = getattr(scene.camera, name)
        distance = None if point is None else _length([a - b for a, b in zip(point, centre)])
        if distance is not None and not distance <= farthest:
            raise SceneError(
                f"{source}: key 'camera.{name}': {_vec(point)} m is {_num(distance)} m "
                f"from the container's centre; allowed: within {CAMERA_REACH_DIAGONALS} container "
                f"diagonals ({_num(farthest)} m), beyond which the box is smaller than a pixel"
            )
    eye = scene.camera.position_m
    target = scene.camera.look_at_m if scene.camera.look_at_m is not None else default_look_at_m(scene)
    if eye is not None and not _length([a - b for a, b in zip(eye, target)]) > 1e-6 * diagonal:
        given = "camera.look_at_m" if scene.camera.look_at_m is not None else "the default look-at point"
        raise SceneError(
            f"{source}: key 'camera.position_m': the eye {_vec(eye)} m is at {given} {_vec(target)} m, "
            f"so it looks nowhere; move camera.position_m or set camera.look_at_m elsewhere"
        )
