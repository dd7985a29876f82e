#!/usr/bin/env python3
"""A run's VTK frames read by VTK itself (python3-vtk9), as ParaView reads them.

Runs an example graph with constraints (graphs/rope.json, its first frames) with
"formats": ["ply", "vtp"] and a float, an int and a vector attribute requested, then checks with
vtkXMLPolyDataReader, frame by frame, against the run's own PLY frame:
- the points: count and positions;
- a vertex cell per point and a line cell per constraint, each line on the PLY edge's two points;
- every PLY vertex column as a point array of the same name (x y z the points, vx vy vz `v`,
  NAME_x NAME_y NAME_z a 3-component NAME), with its values and its type (float or int);
- restlength and strain as cell data, NaN on the vertex cells and the PLY's values on the lines;
- the frame's time in its TimeValue field.
And frames.pvd, parsed as XML: one DataSet per written frame, in order, each naming a file that
exists, with timestep frame / fps in seconds.
Usage: check_vtk.py GRAINS_BINARY SOURCE_DIR WORK_DIR
"""
import os
import shutil
import sys
import xml.etree.ElementTree as ET

import rope_run

try:
    import numpy as np
    import vtk
    from vtk.util.numpy_support import vtk_to_numpy
except ImportError as e:  # never a silent skip: make test installs them (scripts/install-deps.sh)
    sys.exit(f"check_vtk.py: {e}: install python3-vtk9 and python3-numpy "
             "(scripts/install-deps.sh, which make test runs)")

FRAMES = 6
EVERY = 2
ATTRIBUTES = ["mass", "force", "ispbd", "id"]


def read_ply(path):
    """The binary little-endian PLY frames Grains writes: {element: {property: array}}."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    elements, current = [], None
    for line in data[:end].decode().splitlines():
        words = line.split()
        if words[0] == "format":
            assert words[1] == "binary_little_endian", line
        elif words[0] == "element":
            current = (words[1], int(words[2]), [])
            elements.append(current)
        elif words[0] == "property":
            current[2].append((words[2], {"float": "<f4", "int": "<i4"}[words[1]]))
    out, at = {}, end
    for name, count, props in elements:
        rows = np.frombuffer(data, dtype=np.dtype(props), count=count, offset=at)
        at += rows.nbytes
        out[name] = {p: rows[p] for p, _ in props}
    assert at == len(data), f"{path}: {len(data) - at} bytes after the elements"
    return out


def check_frame(vtp, ply, time, failures):
    where = os.path.basename(vtp)
    reader = vtk.vtkXMLPolyDataReader()
    reader.SetFileName(vtp)
    reader.Update()
    if reader.GetErrorCode() != 0:
        failures.append(f"{where}: VTK could not read it (error {reader.GetErrorCode()})")
        return
    poly = reader.GetOutput()
    v, e = ply["vertex"], ply.get("edge", {"vertex1": np.zeros(0, "<i4")})
    n, m = len(v["x"]), len(e["vertex1"])

    def fail(what):
        failures.append(f"{where}: {what}")

    if poly.GetNumberOfPoints() != n:
        fail(f"{poly.GetNumberOfPoints()} points, the PLY has {n}")
        return
    if n == 0 or m == 0:
        fail(f"the check needs points and constraints ({n} points, {m} constraints)")
        return
    points = vtk_to_numpy(poly.GetPoints().GetData())
    if not np.array_equal(points, np.stack([v["x"], v["y"], v["z"]], axis=1)):
        fail("the points are not the PLY's x y z")
    if poly.GetNumberOfVerts() != n:
        fail(f"{poly.GetNumberOfVerts()} vertex cells for {n} points")
    if poly.GetNumberOfLines() != m:
        fail(f"{poly.GetNumberOfLines()} line cells, the PLY has {m} edges")
    if poly.GetNumberOfPolys() != 0 or poly.GetNumberOfStrips() != 0:
        fail("polygons or strips")
    # the cells, in VTK's order: verts then lines
    ids = vtk.vtkIdList()
    for k in range(n):
        poly.GetCellPoints(k, ids)
        if ids.GetNumberOfIds() != 1 or ids.GetId(0) != k:
            fail(f"vertex cell {k} is not point {k}")
            break
    for k in range(m):
        poly.GetCellPoints(n + k, ids)
        got = [ids.GetId(j) for j in range(ids.GetNumberOfIds())]
        if got != [e["vertex1"][k], e["vertex2"][k]]:
            fail(f"line {k} joins {got}, the PLY's edge {e['vertex1'][k]} {e['vertex2'][k]}")
            break

    # every PLY vertex column as a point array
    pd = poly.GetPointData()
    expected = {}
    for prop, values in v.items():
        if prop in ("x", "y", "z"):
            continue
        if prop in ("vx", "vy", "vz"):
            expected.setdefault("v", [None] * 3)["xyz".index(prop[1])] = values
        elif prop[-2:] in ("_x", "_y", "_z"):
            expected.setdefault(prop[:-2], [None] * 3)["xyz".index(prop[-1])] = values
        else:
            expected[prop] = [values]
    names = {pd.GetArrayName(k) for k in range(pd.GetNumberOfArrays())}
    if names != set(expected):
        fail(f"point arrays {sorted(names)}, the PLY's columns give {sorted(expected)}")
    for name, columns in expected.items():
        array = pd.GetArray(name)
        if array is None:
            continue
        if array.GetNumberOfComponents() != len(columns) or array.GetNumberOfTuples() != n:
            fail(f"{name}: {array.GetNumberOfComponents()} components x "
                 f"{array.GetNumberOfTuples()}, want {len(columns)} x {n}")
            continue
        got = vtk_to_numpy(array).reshape(n, len(columns))
        want = np.stack(columns, axis=1)
        if got.dtype.kind != want.dtype.kind or not np.array_equal(got, want):
            fail(f"{name}: values or type ({got.dtype}) differ from the PLY's ({want.dtype})")
    if pd.GetScalars() is None or pd.GetScalars().GetName() != "pscale":
        fail("pscale is not the active scalars")
    if pd.GetVectors() is None or pd.GetVectors().GetName() != "v":
        fail("v is not the active vectors")

    # the edges' columns as cell data: NaN on the vertex cells, the PLY's values on the lines
    cd = poly.GetCellData()
    edge_columns = [p for p in e if p not in ("vertex1", "vertex2")]
    cell_names = {cd.GetArrayName(k) for k in range(cd.GetNumberOfArrays())}
    if cell_names != set(edge_columns):
        fail(f"cell arrays {sorted(cell_names)}, the PLY's edges give {sorted(edge_columns)}")
    for name in edge_columns:
        array = cd.GetArray(name)
        if array is None:
            continue
        got = vtk_to_numpy(array)
        if array.GetNumberOfComponents() != 1 or len(got) != n + m:
            fail(f"cell array {name}: {len(got)} values for {n + m} cells")
            continue
        if not np.all(np.isnan(got[:n])):
            fail(f"cell array {name}: a vertex cell holds a number")
        if not np.array_equal(got[n:], e[name]):
            fail(f"cell array {name}: the line cells differ from the PLY's edges")

    tv = poly.GetFieldData().GetArray("TimeValue")
    if tv is None or abs(tv.GetValue(0) - time) > 1e-12:
        fail(f"TimeValue {None if tv is None else tv.GetValue(0)}, want {time}")


def main():
    grains, src, work = rope_run.arguments()
    shutil.rmtree(work, ignore_errors=True)
    graph, out = rope_run.run_rope(grains, src, work, FRAMES,
                                   {"every": EVERY, "attributes": ATTRIBUTES,
                                    "formats": ["ply", "vtp"]})

    failures = []
    fps = graph["fps"]
    written = list(range(EVERY, FRAMES + 1, EVERY))
    pvd = os.path.join(out, "frames.pvd")
    root = ET.parse(pvd).getroot()
    if root.tag != "VTKFile" or root.get("type") != "Collection":
        failures.append("frames.pvd: not a VTK collection")
    sets = root.findall("./Collection/DataSet")
    if [d.get("file") for d in sets] != [f"frame_{f:04d}.vtp" for f in written]:
        failures.append(f"frames.pvd lists {[d.get('file') for d in sets]}, the run wrote "
                        f"frames {written}")
    for d, frame in zip(sets, written):
        time = float(d.get("timestep"))
        if abs(time - frame / fps) > 1e-12:
            failures.append(f"frames.pvd: {d.get('file')} at {time} s, want {frame / fps}")
        vtp = os.path.join(out, d.get("file"))
        if not os.path.isfile(vtp):
            failures.append(f"frames.pvd names {d.get('file')}, which is not there")
            continue
        check_frame(vtp, read_ply(os.path.join(out, f"frame_{frame:04d}.ply")), frame / fps,
                    failures)
    leftovers = [f for f in os.listdir(out) if f.endswith(".tmp")]
    if leftovers:
        failures.append(f"temporary files left: {leftovers}")

    print(f"VTK {vtk.vtkVersion.GetVTKVersion()} read {len(sets)} frames of {out}")
    for f in failures:
        print("FAIL:", f)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
