"""The pinhole camera both headless renderers share: the draw's view on the device (:func:`camera_field`,
:func:`aim`) and an eye-relative point's pixel (:func:`to_pixel`)."""

import numpy as np
import taichi as ti

vec3 = ti.types.vector(3, ti.f32)


def camera_field():
    """A () struct field for a draw's view: the eye, its unit axes (right, up, forward), the focal length in
    pixels of the image and of a coarse image of it, and the unit direction towards the light. Set once a
    draw (:func:`aim`) and read by the draw's kernels: a vector passed to each kernel instead cost the host
    more than the kernel's launch."""
    return ti.Struct.field(
        dict(eye=vec3, right=vec3, up=vec3, forward=vec3, focal=ti.f32, coarse_focal=ti.f32, light=vec3), shape=()
    )


@ti.kernel
def _set(
    camera: ti.template(), eye: vec3, right: vec3, up: vec3, forward: vec3, focal: ti.f32, coarse: ti.f32, light: vec3
):
    camera[None] = ti.Struct(
        eye=eye, right=right, up=up, forward=forward, focal=focal, coarse_focal=coarse, light=light
    )


def aim(camera, view, height: int, light, coarse_height: int | None = None) -> None:
    """``camera`` (a :func:`camera_field`) set to ``view`` (a ``pbf.app.render.View``) for an image ``height``
    pixels high (and a coarse one ``coarse_height`` high, else the same), lit from unit ``light``."""
    right, up, forward = (ti.Vector(v.astype(np.float32)) for v in view.basis())
    focal = view.focal_px(height)
    coarse = focal if coarse_height is None else view.focal_px(coarse_height)
    light = ti.Vector(np.asarray(light, np.float32))
    _set(camera, ti.Vector(view.eye.astype(np.float32)), right, up, forward, focal, coarse, light)


@ti.func
def to_pixel(p, right, up, forward, focal, width, height):
    """Row and column of eye-relative point ``p`` (row 0 at the top), its depth along ``forward``,
    and whether it lies in front of the eye and inside the image."""
    depth = p.dot(forward)
    row, col, inside = -1, -1, False
    if depth > 1e-6:
        col = ti.cast(0.5 * width + focal * p.dot(right) / depth, ti.i32)
        row = ti.cast(0.5 * height - focal * p.dot(up) / depth, ti.i32)
        inside = 0 <= row < height and 0 <= col < width
    return row, col, depth, inside
