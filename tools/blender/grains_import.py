# A Blender add-on (Blender 3.4 and later): File > Import > Grains run imports the folder
# `grains run` wrote as one animated point cloud per solver, with every attribute of its PLY
# frames (vectors and positions turned from Grains' Y-up to Blender's Z-up; restlength and
# strain on the edges), drawn as spheres of radius pscale (a geometry-nodes modifier), with the
# velocity also as `velocity` (m/s), the attribute Cycles reads for motion blur of geometry
# whose points change from frame to frame. The scene's frame range and fps follow the run.
# Install: Edit > Preferences > Add-ons > Install..., pick this file, tick "Import-Export:
# Grains run". Headless: with this folder on sys.path, `import grains_import;
# grains_import.register(); grains_import.import_run("out/first")` (tests/clients/
# check_blender.py, run by make test-clients).
#
# How the animation works: each imported object keeps its folder in the custom property
# `grains_dir`; a frame-change handler loads that folder's frame_NNNN.ply for the scene's frame
# (the nearest written frame at or before it) into the object's mesh: points, edges (the
# explicit constraints) and point attributes. Point counts may change from frame to frame
# (sources emitting, kills), which a shape-key or cache animation could not follow.
import os
import re

import bpy
import numpy as np
from bpy.props import BoolProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

bl_info = {
    "name": "Grains run",
    "author": "Grains",
    "version": (1, 0, 0),
    "blender": (3, 4, 0),
    "location": "File > Import > Grains run",
    "description": "Import a Grains run (frame_NNNN.ply and stats.csv) as an animated point "
                   "cloud with every attribute, Z-up, spheres at pscale",
    "category": "Import-Export",
}

FRAME = re.compile(r"frame_(\d+)\.ply$")
PLY_TYPES = {"float": "<f4", "float32": "<f4", "double": "<f8", "int": "<i4", "int32": "<i4",
             "uint": "<u4", "uchar": "u1", "uint8": "u1", "char": "i1", "int8": "i1",
             "short": "<i2", "ushort": "<u2"}


# ---- reading ---------------------------------------------------------------------------------

def read_ply(path):
    """A binary little-endian PLY of Grains (no list properties): {element: {property: array}}."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    elements, current = [], None
    for line in data[:end].decode("ascii").splitlines():
        words = line.split()
        if not words:
            continue
        if words[0] == "format" and words[1] != "binary_little_endian":
            raise ValueError(f"{path}: {words[1]} PLY; Grains writes binary_little_endian")
        if words[0] == "element":
            current = (words[1], int(words[2]), [])
            elements.append(current)
        elif words[0] == "property":
            if words[1] == "list":
                raise ValueError(f"{path}: list properties are not a Grains frame's")
            current[2].append((words[2], PLY_TYPES[words[1]]))
    out, at = {}, end
    for name, count, props in elements:
        rows = np.frombuffer(data, dtype=np.dtype(props), count=count, offset=at)
        at += rows.nbytes
        out[name] = {p: np.ascontiguousarray(rows[p]) for p, _ in props}
    return out


def frames_in(folder):
    """{frame number: path} of the PLY frames in a folder."""
    out = {}
    for name in os.listdir(folder):
        m = FRAME.match(name)
        if m:
            out[int(m.group(1))] = os.path.join(folder, name)
    return out


def run_objects(folder):
    """[(name, folder)]: the run's one folder, or one sub-folder per solver."""
    if frames_in(folder):
        return [(os.path.basename(os.path.normpath(folder)) or "grains", folder)]
    subs = sorted(d for d in os.listdir(folder) if os.path.isdir(os.path.join(folder, d)))
    return [(d, os.path.join(folder, d)) for d in subs if frames_in(os.path.join(folder, d))]


def run_fps(folder):
    """Frames per second from stats.csv (frame / time of its first row), else 24."""
    path = os.path.join(folder, "stats.csv")
    try:
        with open(path, encoding="ascii") as f:
            header = f.readline().strip().split(",")
            row = f.readline().strip().split(",")
        frame, time = float(row[header.index("frame")]), float(row[header.index("time")])
        fps = frame / time if time > 0 else 24.0
        # time has 6 digits: 1 / 24 s reads back as 23.99998 frames a second
        return float(round(fps)) if abs(fps - round(fps)) < 1e-3 * fps else fps
    except (OSError, ValueError, IndexError):
        return 24.0


def y_up_to_z_up(x, y, z):
    """Grains is Y-up (Houdini's convention), Blender Z-up: (x, y, z) -> (x, -z, y)."""
    return np.stack([x, -z, y], axis=1).astype(np.float32)


def point_attributes(vertex):
    """The PLY's vertex columns as Blender attributes: (name, 'FLOAT' | 'INT' | 'FLOAT_VECTOR',
    values). x y z are the positions (not listed); vx vy vz become `v`, NAME_x NAME_y NAME_z the
    vector NAME, both Z-up; `velocity` repeats `v` for motion blur."""
    out, vectors = [], {}
    for prop, values in vertex.items():
        if prop in ("x", "y", "z"):
            continue
        if prop in ("vx", "vy", "vz"):
            vectors.setdefault("v", {})[prop[1]] = values
        elif prop[-2:] in ("_x", "_y", "_z"):
            vectors.setdefault(prop[:-2], {})[prop[-1]] = values
        else:
            kind = "INT" if values.dtype.kind in "iu" else "FLOAT"
            out.append((prop, kind, values.astype(np.int32 if kind == "INT" else np.float32)))
    for name, c in vectors.items():
        if set(c) == {"x", "y", "z"}:
            out.append((name, "FLOAT_VECTOR", y_up_to_z_up(c["x"], c["y"], c["z"])))
        else:  # an incomplete vector: its components as floats
            out += [(f"{name}_{k}", "FLOAT", v.astype(np.float32)) for k, v in c.items()]
    if "v" in vectors and len(vectors["v"]) == 3:
        out.append(("velocity", "FLOAT_VECTOR", next(a for n, _, a in out if n == "v")))
    return out


# ---- the mesh of a frame ---------------------------------------------------------------------

_cache = {}  # path -> parsed frame (the last few)


def load_frame(path):
    if path not in _cache:
        if len(_cache) > 8:
            _cache.pop(next(iter(_cache)))
        _cache[path] = read_ply(path)
    return _cache[path]


def fill_mesh(mesh, frame):
    """Replaces the mesh's geometry and attributes with one parsed frame."""
    v = frame["vertex"]
    e = frame.get("edge", {})
    n = len(v["x"])
    positions = y_up_to_z_up(v["x"], v["y"], v["z"])
    mesh.clear_geometry()
    mesh.vertices.add(n)
    mesh.vertices.foreach_set("co", positions.ravel())
    if "vertex1" in e and len(e["vertex1"]):
        pairs = np.stack([e["vertex1"], e["vertex2"]], axis=1).astype(np.int32)
        mesh.edges.add(len(pairs))
        mesh.edges.foreach_set("vertices", pairs.ravel())
    for name, kind, values in point_attributes(v):
        if name in mesh.attributes:
            mesh.attributes.remove(mesh.attributes[name])
        attr = mesh.attributes.new(name, kind, "POINT")
        attr.data.foreach_set("vector" if kind == "FLOAT_VECTOR" else "value", values.ravel())
    # edge attributes (restlength, strain)
    for name, values in e.items():
        if name in ("vertex1", "vertex2") or values.dtype.kind != "f":
            continue
        if name in mesh.attributes:
            mesh.attributes.remove(mesh.attributes[name])
        mesh.attributes.new(name, "FLOAT", "EDGE").data.foreach_set("value", values.astype(np.float32))
    mesh.update()


def frame_path(folder, scene_frame):
    """The written frame shown at scene_frame: the latest at or before it, else the first."""
    frames = frames_in(folder)
    if not frames:
        return None
    at = [f for f in frames if f <= scene_frame]
    return frames[max(at) if at else min(frames)]


def update_object(obj, scene_frame):
    path = frame_path(bpy.path.abspath(obj["grains_dir"]), scene_frame)
    if path and obj.get("grains_frame_file") != path:
        fill_mesh(obj.data, load_frame(path))
        obj["grains_frame_file"] = path


# ---- spheres at pscale -----------------------------------------------------------------------

def sphere_nodes(name):
    """A geometry-nodes group that instances an icosphere of radius pscale on every point."""
    group = bpy.data.node_groups.new(name, "GeometryNodeTree")
    if hasattr(group, "interface"):  # Blender 4
        group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
        group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    else:
        group.inputs.new("NodeSocketGeometry", "Geometry")
        group.outputs.new("NodeSocketGeometry", "Geometry")
    nodes, links = group.nodes, group.links
    gin = nodes.new("NodeGroupInput")
    gout = nodes.new("NodeGroupOutput")
    points = nodes.new("GeometryNodeMeshToPoints")
    ico = nodes.new("GeometryNodeMeshIcoSphere")
    ico.inputs["Radius"].default_value = 1.0
    ico.inputs["Subdivisions"].default_value = 2
    pscale = nodes.new("GeometryNodeInputNamedAttribute")
    pscale.data_type = "FLOAT"
    pscale.inputs["Name"].default_value = "pscale"
    inst = nodes.new("GeometryNodeInstanceOnPoints")
    shade = nodes.new("GeometryNodeSetShadeSmooth")
    # the named-attribute node has an output per data type, all called Attribute: the float one
    radius = next(o for o in pscale.outputs if o.name == "Attribute" and o.enabled)
    links.new(gin.outputs[0], points.inputs["Mesh"])
    links.new(radius, points.inputs["Radius"])
    links.new(points.outputs["Points"], inst.inputs["Points"])
    links.new(ico.outputs["Mesh"], inst.inputs["Instance"])
    links.new(radius, inst.inputs["Scale"])
    links.new(inst.outputs["Instances"], shade.inputs["Geometry"])
    links.new(shade.outputs["Geometry"], gout.inputs[0])
    return group


# ---- import ----------------------------------------------------------------------------------

def import_run(folder, context=None, spheres=True):
    """Imports the run in `folder`; returns the objects made (one per solver)."""
    context = context or bpy.context
    scene = context.scene
    folder = os.path.abspath(folder)
    objects = run_objects(folder)
    if not objects:
        raise ValueError(f"{folder}: no frame_NNNN.ply (nor sub-folders holding them)")
    made, first, last = [], None, None
    for name, path in objects:
        frames = frames_in(path)
        first = min(frames) if first is None else min(first, min(frames))
        last = max(frames) if last is None else max(last, max(frames))
        mesh = bpy.data.meshes.new(name)
        obj = bpy.data.objects.new(name, mesh)
        obj["grains_dir"] = path
        context.collection.objects.link(obj)
        if spheres:
            mod = obj.modifiers.new("grains spheres", "NODES")
            mod.node_group = sphere_nodes(f"{name} spheres")
        made.append(obj)
    fps = run_fps(objects[0][1])
    scene.render.fps = max(1, round(fps))
    scene.render.fps_base = scene.render.fps / fps
    scene.frame_start, scene.frame_end = first, last
    register_handler()
    for obj in made:
        update_object(obj, scene.frame_current)
    return made


@bpy.app.handlers.persistent
def on_frame_change(scene, *args):
    for obj in scene.objects:
        if "grains_dir" in obj and obj.type == "MESH":
            update_object(obj, scene.frame_current)


def register_handler():
    handlers = bpy.app.handlers.frame_change_pre
    if not any(getattr(h, "__name__", "") == "on_frame_change" for h in handlers):
        handlers.append(on_frame_change)


class IMPORT_OT_grains_run(bpy.types.Operator, ImportHelper):
    """Import a Grains run folder as an animated point cloud"""
    bl_idname = "import_scene.grains_run"
    bl_label = "Import Grains run"
    bl_options = {"REGISTER", "UNDO"}

    filename_ext = ".ply"
    filter_glob: StringProperty(default="*.ply;*.csv", options={"HIDDEN"})
    spheres: BoolProperty(name="Spheres at pscale", default=True,
                          description="Instance an icosphere of radius pscale on each grain")

    def execute(self, context):
        folder = self.filepath if os.path.isdir(self.filepath) else os.path.dirname(self.filepath)
        try:
            made = import_run(folder, context, self.spheres)
        except (OSError, ValueError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        self.report({"INFO"}, f"imported {len(made)} object(s) from {folder}")
        return {"FINISHED"}


def menu_import(self, context):
    self.layout.operator(IMPORT_OT_grains_run.bl_idname, text="Grains run (frame_NNNN.ply)")


def register():
    bpy.utils.register_class(IMPORT_OT_grains_run)
    bpy.types.TOPBAR_MT_file_import.append(menu_import)
    register_handler()


def unregister():
    bpy.types.TOPBAR_MT_file_import.remove(menu_import)
    bpy.utils.unregister_class(IMPORT_OT_grains_run)
    handlers = bpy.app.handlers.frame_change_pre
    for h in [h for h in handlers if getattr(h, "__name__", "") == "on_frame_change"]:
        handlers.remove(h)
