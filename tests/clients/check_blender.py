"""A run imported by the Blender add-on (tools/blender/grains_import.py), in Blender itself.

Run by `make test-clients`:
  blender -b --factory-startup --python-exit-code 1 --python tests/clients/check_blender.py -- \
      GRAINS_BINARY SOURCE_DIR WORK_DIR
Runs graphs/rope.json's first frames, imports the folder with the add-on and checks, at several
frames, against each frame's PLY: the scene's frame range and fps; the object's point count,
positions turned Z-up, edges (the constraints); every PLY column as an attribute of the right
kind (v, velocity and requested vectors Z-up; restlength and strain on the edges); the spheres'
modifier. Then renders a still with Cycles and checks that it is not blank.
"""
import os
import sys

import bpy
import numpy as np

# Blender adds no script's folder to sys.path; rope_run.py lies beside this file
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import rope_run  # noqa: E402

FRAMES = 6


def main():
    grains, src, work = rope_run.arguments()
    graph, out = rope_run.run_rope(grains, src, work, FRAMES,
                                   {"attributes": ["mass", "force", "ispbd"]}, ["--overwrite"])

    sys.path.insert(0, os.path.join(src, "tools", "blender"))
    import grains_import
    bpy.ops.wm.read_factory_settings(use_empty=True)
    grains_import.register()
    failures = []
    scene = bpy.context.scene
    objs = grains_import.import_run(out)
    if len(objs) != 1:
        failures.append(f"{len(objs)} objects for one solver")
    obj = objs[0]
    if (scene.frame_start, scene.frame_end) != (1, FRAMES):
        failures.append(f"frame range {scene.frame_start}-{scene.frame_end}, want 1-{FRAMES}")
    if abs(scene.render.fps / scene.render.fps_base - graph["fps"]) > 1e-6:
        failures.append(f"fps {scene.render.fps / scene.render.fps_base}, want {graph['fps']}")
    if not any(m.type == "NODES" and m.node_group for m in obj.modifiers):
        failures.append("no spheres modifier")

    for frame in (1, 4, FRAMES):
        scene.frame_set(frame)
        ply = grains_import.read_ply(os.path.join(out, f"frame_{frame:04d}.ply"))
        v, e = ply["vertex"], ply["edge"]
        mesh = obj.data
        where = f"frame {frame}"
        n = len(v["x"])
        if len(mesh.vertices) != n:
            failures.append(f"{where}: {len(mesh.vertices)} points, the PLY has {n}")
            continue
        co = np.empty(3 * n, np.float32)
        mesh.vertices.foreach_get("co", co)
        want = np.stack([v["x"], -v["z"], v["y"]], axis=1).ravel()
        if not np.array_equal(co, want):
            failures.append(f"{where}: positions are not the PLY's turned Z-up (x, -z, y)")
        if len(mesh.edges) != len(e["vertex1"]):
            failures.append(f"{where}: {len(mesh.edges)} edges, the PLY has {len(e['vertex1'])}")
        want_attrs = {"v": "FLOAT_VECTOR", "velocity": "FLOAT_VECTOR", "pscale": "FLOAT",
                      "id": "INT", "mass": "FLOAT", "force": "FLOAT_VECTOR", "ispbd": "INT"}
        for name, kind in want_attrs.items():
            a = mesh.attributes.get(name)
            if a is None or a.data_type != kind or a.domain != "POINT":
                failures.append(f"{where}: attribute {name} missing or not a {kind} point "
                                f"attribute ({None if a is None else (a.data_type, a.domain)})")
        got = np.empty(3 * n, np.float32)
        mesh.attributes["v"].data.foreach_get("vector", got)
        if not np.array_equal(got, np.stack([v["vx"], -v["vz"], v["vy"]], axis=1).ravel()):
            failures.append(f"{where}: v is not the PLY's vx vy vz turned Z-up")
        ids = np.empty(n, np.int32)
        mesh.attributes["id"].data.foreach_get("value", ids)
        if not np.array_equal(ids, v["id"]):
            failures.append(f"{where}: id differs from the PLY's")
        for name in ("restlength", "strain"):
            a = mesh.attributes.get(name)
            if a is None or a.domain != "EDGE":
                failures.append(f"{where}: {name} is not an edge attribute")
                continue
            vals = np.empty(len(mesh.edges), np.float32)
            a.data.foreach_get("value", vals)
            if not np.array_equal(vals, e[name]):
                failures.append(f"{where}: {name} differs from the PLY's edges")

    # a still, rendered headless with Cycles: the rope's spheres on a dark background
    scene.frame_set(FRAMES)
    co = np.empty(3 * len(obj.data.vertices), np.float32)
    obj.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    lo, hi = co.min(axis=0), co.max(axis=0)
    centre = (lo + hi) / 2
    cam_data = bpy.data.cameras.new("cam")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = float(max(hi[0] - lo[0], hi[2] - lo[2])) * 1.3 + 0.1
    cam = bpy.data.objects.new("cam", cam_data)
    cam.location = (float(centre[0]), float(lo[1]) - 5, float(centre[2]))
    cam.rotation_euler = (np.pi / 2, 0, 0)  # looking along +y
    scene.collection.objects.link(cam)
    scene.camera = cam
    sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    sun.rotation_euler = (0.8, 0.2, 0.3)
    scene.collection.objects.link(sun)
    scene.world = bpy.data.worlds.new("world")
    scene.world.color = (0.02, 0.02, 0.05)
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 8
    scene.cycles.use_denoising = False  # Debian's Blender has no OpenImageDenoise
    scene.render.resolution_x, scene.render.resolution_y = 320, 240
    scene.render.resolution_percentage = 100
    still = os.path.join(work, "still.png")
    scene.render.filepath = still
    scene.render.image_settings.file_format = "PNG"
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(still)
    w, h = image.size
    px = np.array(image.pixels[:], dtype=np.float32).reshape(h, w, -1)[..., :3]
    background = np.median(px.reshape(-1, 3), axis=0)  # most of the frame is the world
    lit = (np.abs(px - background).max(axis=2) > 0.15).mean()
    if (w, h) != (320, 240):
        failures.append(f"still: {w}x{h}, want 320x240")
    if not 0.005 < lit < 0.5:  # the rope's 41 spheres cover about 2% of the frame
        failures.append(f"still: {lit:.4f} of its pixels show grains (blank, or all covered)")

    print(f"Blender {bpy.app.version_string}: imported {out}, {len(obj.data.vertices)} points, "
          f"still {still} with grains on {lit:.2%} of its pixels")
    for f in failures:
        print("FAIL:", f)
    return 1 if failures else 0


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    # blender -b --python keeps running after the script: leave with the script's verdict
    os._exit(code)
