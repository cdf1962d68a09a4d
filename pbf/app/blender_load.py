"""A run's exports in Blender: ``blender -b -P pbf/app/blender_load.py -- OUTPUT_FOLDER [options]``.

Run inside Blender (3.4 or later; it needs nothing but Blender's own Python, not even NumPy). It reads
``run.json`` and the ``surface_NNNNN.ply``, ``particles_NNNNN.ply`` and ``diffuse_NNNNN.ply`` (white
water, in the surface style) files that ``run.py --headless --export mesh --export ply`` wrote, and builds
a scene: the water's surface as ONE object, the particles as another and white water as small white
spheres, each replaced a frame at a time by a frame-change handler (one frame in
memory, however long the run), with the vertex attributes ``velocity`` (m/s, a vector) and ``speed``
(m/s); a glass-like water material absorbing light as the scene's ``surface.absorption_per_m`` says; a
floor just under the container; a sun and a sky; the run's camera, frame range and frame rate. Then it
renders the frames asked for with Cycles, saves a .blend, or prints a report of what it loaded.

Outside Blender, ``python -m pbf.app.blender_load`` prints this file's path, for ``-P``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from array import array
from pathlib import Path

USAGE = "blender -b -P blender_load.py -- OUTPUT_FOLDER [--frame N ...] [--animation] [--samples N] [--scale %]"


class LoadError(Exception):
    """Bad input (the folder, its run.json or a file): one line naming it and what is allowed."""


def read_ply(path: Path) -> dict:
    """A binary little-endian PLY of float32 vertex properties and triangles (what pbf writes):
    {"properties": names, "vertex": array('f') interleaved, "faces": array('i') of 3 per triangle}."""
    data = path.read_bytes()
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        raise LoadError(f"{path}: not a PLY file")
    header = data[:end].decode("ascii", "replace").splitlines()
    if "format binary_little_endian 1.0" not in header:
        raise LoadError(f"{path}: expected a binary little-endian PLY (as pbf writes), got {header[1]!r}")
    elements, current = [], None
    for line in header:
        words = line.split()
        if words[:1] == ["element"]:
            current = {"name": words[1], "count": int(words[2]), "properties": []}
            elements.append(current)
        elif words[:1] == ["property"] and current is not None:
            current["properties"].append(words[1:])
    offset = end + len(b"end_header\n")
    result = {"properties": [], "vertex": array("f"), "faces": array("i")}
    for element in elements:
        if element["name"] == "vertex":
            if any(p[0] != "float" for p in element["properties"]):
                raise LoadError(f"{path}: expected float32 vertex properties")
            size = 4 * len(element["properties"]) * element["count"]
            result["properties"] = [p[1] for p in element["properties"]]
            result["vertex"] = array("f", data[offset : offset + size])
            offset += size
        elif element["name"] == "face":
            kind = element["properties"][0]
            if kind[:4] != ["list", "uchar", "int", "vertex_indices"]:
                raise LoadError(f"{path}: expected faces as 'list uchar int vertex_indices'")
            count = element["count"]
            chunk = data[offset : offset + 13 * count]
            if any(chunk[k] != 3 for k in range(0, len(chunk), 13)):
                raise LoadError(f"{path}: expected triangles only")
            result["faces"] = array("i", b"".join(chunk[k + 1 : k + 13] for k in range(0, len(chunk), 13)))
            offset += 13 * count
    return result


def columns(ply: dict, names) -> array:
    """The vertex properties ``names`` interleaved (x, y, z → a flat array of 3 per vertex)."""
    stride = len(ply["properties"])
    count = len(ply["vertex"]) // max(stride, 1)
    out = array("f", bytes(4 * count * len(names)))
    for k, name in enumerate(names):
        out[k :: len(names)] = ply["vertex"][ply["properties"].index(name) :: stride]
    return out


class Run:
    """An output folder: its run.json and the frames' files."""

    def __init__(self, folder: Path):
        self.folder = folder
        if not folder.is_dir():
            raise LoadError(f"{folder}: no such folder; give the --out folder of a run with --export mesh or ply")
        info_path = folder / "run.json"
        if not info_path.is_file():
            raise LoadError(
                f"{info_path}: missing; the folder must hold a run made with --headless --export mesh "
                "(and/or --export ply), which writes it"
            )
        try:
            self.info = json.loads(info_path.read_text())
        except ValueError as error:
            raise LoadError(f"{info_path}: not JSON ({error})") from None
        keys = self.info if isinstance(self.info, dict) else {}
        missing = [key for key in ("frames", "frame_rate_hz", "camera", "container") if key not in keys]
        if missing:
            raise LoadError(f"{info_path}: lacks {', '.join(missing)}; write it again with the run")
        try:
            planned = int(self.info["frames"])
        except (TypeError, ValueError):
            raise LoadError(f"{info_path}: 'frames' is not a frame count; write it again with the run") from None
        self.surface = self.info.get("surface") == "ply" and (folder / "surface_00000.ply").is_file()
        self.particles = self.info.get("particles") == "ply" and (folder / "particles_00000.ply").is_file()
        self.diffuse = self.info.get("diffuse") == "ply" and (folder / "diffuse_00000.ply").is_file()
        if not (self.surface or self.particles):
            raise LoadError(
                f"{folder}: no surface_00000.ply or particles_00000.ply; export PLY files "
                "(--export mesh with surface.mesh_format = ply, or --export ply)"
            )
        # The frames whose files are all there (a run cut short wrote fewer than run.json plans).
        kinds = [
            kind
            for kind, present in (("surface", self.surface), ("particles", self.particles), ("diffuse", self.diffuse))
            if present
        ]
        self.frames = 0
        while self.frames < planned and all((folder / f"{k}_{self.frames:05d}.ply").is_file() for k in kinds):
            self.frames += 1

    def path(self, kind: str, frame: int) -> Path:
        return self.folder / f"{kind}_{min(max(frame, 0), self.frames - 1):05d}.ply"


def frame_mesh(bpy, name: str, ply: dict, material):
    """A new mesh of ``ply``'s vertices (and triangles), with ``velocity`` and ``speed`` attributes."""
    mesh = bpy.data.meshes.new(name)
    co = columns(ply, ("x", "y", "z"))
    faces = ply["faces"]
    mesh.vertices.add(len(co) // 3)
    mesh.vertices.foreach_set("co", co)
    triangles = len(faces) // 3
    if triangles:
        mesh.loops.add(3 * triangles)
        mesh.polygons.add(triangles)
        mesh.loops.foreach_set("vertex_index", faces)
        mesh.polygons.foreach_set("loop_start", array("i", range(0, 3 * triangles, 3)))
        try:
            mesh.polygons.foreach_set("loop_total", array("i", [3]) * triangles)
        except (AttributeError, TypeError, RuntimeError):
            pass  # read-only from Blender 4: the loop starts say it
        mesh.polygons.foreach_set("use_smooth", array("b", [1]) * triangles)
    if "vx" in ply["properties"]:
        mesh.attributes.new("velocity", "FLOAT_VECTOR", "POINT").data.foreach_set(
            "vector", columns(ply, ("vx", "vy", "vz"))
        )
    if "speed" in ply["properties"]:
        mesh.attributes.new("speed", "FLOAT", "POINT").data.foreach_set("value", columns(ply, ("speed",)))
    mesh.update()
    if material is not None:
        mesh.materials.append(material)
    return mesh


def water_material(bpy, info: dict):
    """Glass of water's index (1.33) with Beer–Lambert absorption: Cycles' volume absorption takes
    density × (1 − colour) per metre, so density = the largest of the scene's coefficients."""
    material = bpy.data.materials.new("pbf water")
    material.use_nodes = True
    nodes, links = material.node_tree.nodes, material.node_tree.links
    bsdf = nodes["Principled BSDF"]
    for names, value in (
        (("Base Color",), (1.0, 1.0, 1.0, 1.0)),
        (("Transmission", "Transmission Weight"), 1.0),
        (("IOR",), 1.33),
        (("Roughness",), 0.02),
    ):
        for socket in names:
            if socket in bsdf.inputs:
                bsdf.inputs[socket].default_value = value
                break
    absorption = info.get("absorption_per_m", [5.0, 1.8, 1.0])
    density = max(max(absorption), 1e-6)
    volume = nodes.new("ShaderNodeVolumeAbsorption")
    volume.inputs["Color"].default_value = (*[1.0 - a / density for a in absorption], 1.0)
    volume.inputs["Density"].default_value = density
    links.new(volume.outputs["Volume"], nodes["Material Output"].inputs["Volume"])
    return material


def diffuse_material(bpy, name: str, rgb):
    material = bpy.data.materials.new(name)
    material.use_nodes = True
    bsdf = material.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*rgb, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.8
    return material


WHITE_WATER_RADIUS_SPACINGS = 0.15
"""The radius of white water's points in the render, in the run's particle spacings."""


def as_points(bpy, obj, radius_m: float, material) -> None:
    """Render ``obj``'s vertices as spheres of ``radius_m`` (a geometry-nodes Mesh to Points modifier: Cycles
    draws points, not bare vertices)."""
    group = bpy.data.node_groups.new("pbf points", "GeometryNodeTree")
    if hasattr(group, "interface"):  # Blender 4
        group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
        group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    else:
        group.inputs.new("NodeSocketGeometry", "Geometry")
        group.outputs.new("NodeSocketGeometry", "Geometry")
    nodes, links = group.nodes, group.links
    given, result = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    points = nodes.new("GeometryNodeMeshToPoints")
    points.inputs["Radius"].default_value = radius_m
    shade = nodes.new("GeometryNodeSetMaterial")
    shade.inputs["Material"].default_value = material
    links.new(given.outputs[0], points.inputs["Mesh"])
    links.new(points.outputs["Points"], shade.inputs["Geometry"])
    links.new(shade.outputs["Geometry"], result.inputs[0])
    obj.modifiers.new("pbf points", "NODES").node_group = group


def white_water_material(bpy):
    material = bpy.data.materials.new("pbf white water")
    material.use_nodes = True
    bsdf = material.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.95, 0.97, 1.0, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.6
    return material


def build(bpy, run: Run):
    """The scene: objects, handler, materials, floor, light, camera, frames and rate."""
    from mathutils import Euler, Vector

    scene = bpy.context.scene
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj, do_unlink=True)
    info = run.info
    y_up = info.get("up_axis") == "y"
    # y-up files stand up in Blender by a quarter turn about x (pbf.app.export.Z_UP's rotation).
    rotation = Euler((math.pi / 2, 0.0, 0.0)) if y_up else Euler((0.0, 0.0, 0.0))

    loaded = {}
    for kind, wanted, material in (
        ("surface", run.surface, water_material(bpy, info)),
        ("particles", run.particles, diffuse_material(bpy, "pbf particles", (0.1, 0.35, 0.8))),
    ):
        if not wanted:
            continue
        obj = bpy.data.objects.new(f"pbf {kind}", frame_mesh(bpy, f"pbf {kind}", read_ply(run.path(kind, 0)), material))
        obj.rotation_euler = rotation
        scene.collection.objects.link(obj)
        loaded[kind] = (obj, material)
    if "surface" in loaded and "particles" in loaded:
        loaded["particles"][0].hide_render = True  # bare vertices do not render; the surface does
    if run.diffuse:  # white water: spray, foam and bubbles, drawn as small white spheres
        material = white_water_material(bpy)
        obj = bpy.data.objects.new(
            "pbf white water", frame_mesh(bpy, "pbf diffuse", read_ply(run.path("diffuse", 0)), None)
        )
        obj.rotation_euler = rotation
        scene.collection.objects.link(obj)
        as_points(bpy, obj, WHITE_WATER_RADIUS_SPACINGS * float(info.get("spacing_m", 0.025)), material)
        loaded["diffuse"] = (obj, None)

    def load_frame(scene_now, *args):
        for kind, (obj, material) in loaded.items():
            path = run.path(kind, scene_now.frame_current)
            try:
                ply = read_ply(path)
            except (LoadError, OSError) as error:  # the previous frame stays; one line, no traceback
                print(f"error: frame {scene_now.frame_current}: {error}", file=sys.stderr)
                continue
            old = obj.data
            obj.data = frame_mesh(bpy, f"pbf {kind}", ply, material)
            bpy.data.meshes.remove(old)

    load_frame.pbf = True
    bpy.app.handlers.frame_change_pre[:] = [h for h in bpy.app.handlers.frame_change_pre if not hasattr(h, "pbf")]
    bpy.app.handlers.frame_change_pre.append(load_frame)

    lower = [info["container"]["min_m"][k] for k in range(3)]
    upper = [info["container"]["max_m"][k] for k in range(3)]
    if y_up:  # the container's corners as Blender shows them after the quarter turn
        lower, upper = [lower[0], -upper[2], lower[1]], [upper[0], -lower[2], upper[1]]
    centre = [(a + b) / 2 for a, b in zip(lower, upper)]
    size = max(b - a for a, b in zip(lower, upper))
    # The floor 1 mm under the water's lowest faces: coincident faces would flicker between the two.
    bpy.ops.mesh.primitive_plane_add(size=20 * size, location=(centre[0], centre[1], lower[2] - 1e-3))
    floor = bpy.context.active_object
    floor.name = "floor"
    floor.data.materials.append(diffuse_material(bpy, "floor", (0.55, 0.55, 0.5)))

    sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    sun.data.energy = 3.0
    sun.data.angle = math.radians(5.0)
    sun.rotation_euler = Euler((math.radians(35.0), 0.0, math.radians(30.0)))
    scene.collection.objects.link(sun)
    world = scene.world or bpy.data.worlds.new("pbf sky")
    scene.world = world
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.8, 0.85, 0.9, 1.0)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.6

    camera_info = info["camera"]
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    eye, target = Vector(camera_info["position_m"]), Vector(camera_info["look_at_m"])
    if y_up:
        eye, target = Vector((eye.x, -eye.z, eye.y)), Vector((target.x, -target.z, target.y))
    camera.location = eye
    camera.rotation_euler = (target - eye).to_track_quat("-Z", "Y").to_euler()
    camera.data.sensor_fit = "VERTICAL"
    camera.data.angle_y = math.radians(camera_info["fov_deg"])
    camera.data.clip_start = 0.01
    scene.collection.objects.link(camera)
    scene.camera = camera

    scene.render.resolution_x = camera_info.get("width_px", 1280)
    scene.render.resolution_y = camera_info.get("height_px", 720)
    scene.frame_start, scene.frame_end = 0, run.frames - 1
    rate = float(info["frame_rate_hz"])
    scene.render.fps = max(1, round(rate))
    scene.render.fps_base = scene.render.fps / rate
    scene.render.use_lock_interface = True  # the handler swaps meshes while a render reads the scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.use_denoising = False
    scene.render.image_settings.file_format = "PNG"
    scene.frame_set(0)
    return loaded


def report(bpy, loaded, frames) -> dict:
    """For each frame: each object's vertex and face counts, attribute names, bounding box (world
    axes) and the faces Blender's Recalculate Outside would flip."""
    import bmesh

    result = {}
    for frame in frames:
        bpy.context.scene.frame_set(frame)
        for kind, (obj, _) in loaded.items():
            mesh = obj.data
            world = [obj.matrix_world @ v.co for v in mesh.vertices]
            entry = {
                "vertices": len(mesh.vertices),
                "faces": len(mesh.polygons),
                "attributes": sorted(a.name for a in mesh.attributes if not a.name.startswith(".")),
                "min": [min(p[k] for p in world) for k in range(3)] if world else None,
                "max": [max(p[k] for p in world) for k in range(3)] if world else None,
                "objects": len(bpy.data.objects),
                "meshes": len(bpy.data.meshes),
            }
            if "speed" in entry["attributes"]:
                speeds = array("f", bytes(4 * len(mesh.vertices)))
                mesh.attributes["speed"].data.foreach_get("value", speeds)
                entry["speed_max"] = max(speeds) if speeds else 0.0
            if mesh.polygons:
                bm = bmesh.new()
                bm.from_mesh(mesh)
                before = [f.normal.copy() for f in bm.faces]
                bmesh.ops.recalc_face_normals(bm, faces=bm.faces)
                bm.normal_update()
                entry["recalculate_outside_flips"] = sum(1 for f, n in zip(bm.faces, before) if f.normal.dot(n) < 0)
                bm.free()
            result[f"{kind} {frame}"] = entry
    return result


def main(argv) -> int:
    import bpy

    parser = argparse.ArgumentParser(prog="blender -b -P blender_load.py --", description=__doc__.split("\n")[0])
    parser.add_argument("folder", help="a run's --out folder (run.json, surface_NNNNN.ply, particles_NNNNN.ply)")
    parser.add_argument("--frame", type=int, action="append", default=[], help="render this frame (repeatable)")
    parser.add_argument("--animation", action="store_true", help="render every frame")
    parser.add_argument("--samples", type=int, default=32, help="Cycles samples a pixel (default 32)")
    parser.add_argument("--scale", type=int, default=100, help="image size, percent of the run's (default 100)")
    parser.add_argument("--render-out", default=None, help="image path prefix (default FOLDER/blender_)")
    parser.add_argument("--save", default=None, help="save the scene as this .blend")
    parser.add_argument("--report", default=None, help="write counts, attributes and bounds of each frame (JSON)")
    args = parser.parse_args(argv)
    for name, value, lowest, highest in (("--samples", args.samples, 1, 65536), ("--scale", args.scale, 1, 1000)):
        if not lowest <= value <= highest:
            raise LoadError(f"{name} {value}: allowed: an integer in [{lowest}, {highest}]")
    run = Run(Path(args.folder))
    for frame in args.frame:
        if not 0 <= frame < run.frames:
            raise LoadError(f"--frame {frame}: {run.folder} holds frames 0-{run.frames - 1}")
    loaded = build(bpy, run)
    scene = bpy.context.scene
    scene.cycles.samples = args.samples
    scene.render.resolution_percentage = args.scale
    if args.report:
        Path(args.report).write_text(json.dumps(report(bpy, loaded, args.frame or [0]), indent=1) + "\n")
        return 0
    prefix = args.render_out or str(run.folder / "blender_")
    if args.animation:
        scene.render.filepath = prefix
        bpy.ops.render.render(animation=True)
    for frame in args.frame:
        scene.frame_set(frame)
        scene.render.filepath = f"{prefix}{frame:05d}.png"
        bpy.ops.render.render(write_still=True)
        print(f"[pbf] rendered {scene.render.filepath}")
    if args.save:
        bpy.ops.wm.save_as_mainfile(filepath=str(Path(args.save).resolve()))
    return 0


def arguments() -> list[str]:
    """What follows ``--`` on Blender's command line."""
    return sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else []


if __name__ == "__main__":
    try:
        import bpy  # noqa: F401
    except ImportError:
        print(Path(__file__).resolve())  # outside Blender: the path for -P
        sys.exit(0)
    try:
        code = main(arguments())
    except LoadError as error:
        print(f"error: {error}", file=sys.stderr)
        code = 2
    sys.stdout.flush()
    if "-b" in sys.argv or "--background" in sys.argv:
        sys.exit(code)
