"""What the client checks (check_vtk.py, check_blender.py) start from: their three arguments, and
a copy of graphs/rope.json run by the grains binary for its first frames into WORK_DIR/out.
"""
import json
import os
import subprocess
import sys


def arguments():
    """GRAINS_BINARY SOURCE_DIR WORK_DIR: the script's arguments, or in Blender those after `--`."""
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    return argv[:3]


def run_rope(grains, src, work, frames, output, run_flags=()):
    """Runs graphs/rope.json's first `frames` frames with `output` (less its dir, which is
    WORK_DIR/out) as the graph's output block; returns the graph as run and its output folder."""
    os.makedirs(work, exist_ok=True)
    example = os.path.abspath(os.path.join(src, "graphs", "rope.json"))
    with open(example, encoding="utf-8") as f:
        graph = json.load(f)
    # the copy reads the example's files where they are
    for node in graph["nodes"]:
        if "file" in node.get("params", {}):
            node["params"]["file"] = os.path.join(os.path.dirname(example), node["params"]["file"])
    graph.pop("$schema", None)
    out = os.path.join(work, "out")
    graph["output"] = {"dir": out, **output}
    path = os.path.join(work, "rope.json")
    with open(path, "w", encoding="utf-8") as f:
        json.dump(graph, f)
    subprocess.run([grains, "run", path, "--frames", str(frames), "--quiet", *run_flags],
                   check=True)
    return graph, out
