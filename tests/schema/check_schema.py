#!/usr/bin/env python3
"""The graph schema and the node reference, checked against their one source: the node types'
parameter tables as the built program prints them.

1. docs/graph.schema.json is what `grains schema` prints, and docs/nodes.md what
   `grains nodes --markdown` prints (`make docs` writes both).
2. Every parameter of every node type in the schema appears in docs/nodes.md under its node and
   in `grains nodes`.
3. Every example graph names the schema in "$schema" and is valid against it, checked by an
   independent validator (python3-jsonschema).
4. The graphs of the catalogue of bad inputs (tests/catalogue): those the program accepts, the
   schema accepts; those it refuses for a structural error (a field, a type, a menu, a range, a
   vector's length), the schema refuses too.

Usage: check_schema.py GRAINS_BINARY SOURCE_DIR
"""
import glob
import json
import os
import re
import subprocess
import sys

import jsonschema

# what the loader says of a structural error: the schema states these
STRUCTURAL = [
    "unknown field", "unknown parameter", "unknown node type", "unknown keyframe field",
    "must be one of", "is a vector of 3", "is a string", "is an integer", "is a toggle",
    "is float, got", "is int, got", "is vector, got", "is toggle, got", "is an array",
    "is an object", "needs a 'nodes' array", "every node needs", "unsupported version",
    "missing", "must lie between", "keyframes need", "a key is", "interp is",
    "name is letters", "a collider takes no inputs", "the graph must be a JSON object",
    "expected a string", "an input is a node name", "seed is an integer",
    "unknown frame format", "is named twice",
] + [
    # a literal out of range (the same words for a value an expression gives: see literal)
    "must be at least", "must be at most", "must be greater than", "within the float range",
    "must be a finite number",
]
RANGE = STRUCTURAL[-5:]
# what needs the whole graph, the disk or a node's own check: beyond a schema
BEYOND = ["group name", "no solver node"]


def structural(graph, message):
    """Whether the loader's message names a structural error of the file itself: not a command
    line option, not a value an expression or keyframes gave at some frame, not what needs the
    whole graph."""
    if not message.startswith("{file}: ") or any(b in message for b in BEYOND):
        return False
    if not any(s in message for s in STRUCTURAL):
        return False
    m = re.match(r"\{file\}: (/[^:]*): (.*)", message)
    if not m:
        return True  # the file as a whole
    if re.match(r"frame \d+:", m.group(2)):
        return False
    if not any(r in message for r in RANGE):
        return True
    value = graph  # a range error: of a literal, or of an expression's value?
    for part in m.group(1).split("/")[1:]:
        part = part.replace("~1", "/").replace("~0", "~")
        if isinstance(value, list) and part.isdigit() and int(part) < len(value):
            value = value[int(part)]
        elif isinstance(value, dict) and part in value:
            value = value[part]
        else:
            return True

    def evaluated(v):
        return isinstance(v, (str, dict)) or (isinstance(v, list) and any(map(evaluated, v)))
    return not evaluated(value)


def run(cmd):
    return subprocess.run(cmd, check=True, capture_output=True, text=True).stdout


def main():
    grains, src = sys.argv[1], sys.argv[2]
    failures = []
    schema_text = run([grains, "schema"])
    schema = json.loads(schema_text)
    jsonschema.Draft7Validator.check_schema(schema)
    validator = jsonschema.Draft7Validator(schema)

    # 1. the committed copies are current
    for rel, text in (("docs/graph.schema.json", schema_text),
                      ("docs/nodes.md", run([grains, "nodes", "--markdown"]))):
        with open(os.path.join(src, rel), encoding="utf-8") as f:
            if f.read() != text:
                failures.append(f"{rel} is not what the program prints: run `make docs`")

    # 2. every declared parameter in the reference and in `grains nodes`
    with open(os.path.join(src, "docs/nodes.md"), encoding="utf-8") as f:
        sections = re.split(r"^## ", f.read(), flags=re.M)[1:]
    reference = {s.split("\n", 1)[0].strip(): s for s in sections}
    plain = run([grains, "nodes"])
    params = 0
    for key, definition in schema["definitions"].items():
        if not key.startswith("params_"):
            continue
        node = key[len("params_"):]
        listed = run([grains, "nodes", node])
        for name in definition["properties"]:
            params += 1
            if f"| `{name}` |" not in reference.get(node, ""):
                failures.append(f"docs/nodes.md: {node}.{name} missing")
            if not re.search(rf"^  {re.escape(name)} \(", listed, flags=re.M):
                failures.append(f"grains nodes {node}: {name} missing")
        if not plain.startswith(f"{node}:") and f"\n{node}:" not in plain:
            failures.append(f"grains nodes: node type {node} missing")
    if params < 50:
        failures.append(f"only {params} parameters in the schema")

    # 3. the example graphs
    examples = sorted(glob.glob(os.path.join(src, "graphs", "*.json")) +
                      glob.glob(os.path.join(src, "bench", "validation", "*.json")))
    schema_file = os.path.join(src, "docs", "graph.schema.json")
    for path in examples:
        with open(path, encoding="utf-8") as f:
            graph = json.load(f)
        named = graph.get("$schema")
        if not isinstance(named, str) or not os.path.samefile(
                os.path.join(os.path.dirname(path), named), schema_file):
            failures.append(f"{path}: \"$schema\" does not name docs/graph.schema.json")
        for e in validator.iter_errors(graph):
            failures.append(f"{path}: {e.json_path}: {e.message}")

    # 4. the catalogue's graphs
    with open(os.path.join(src, "tests/catalogue/cases.json"), encoding="utf-8") as f:
        cases = json.load(f)["cases"]
    accepted = refused = beyond = 0
    for case in cases:
        files = case.get("files", [])
        command = (case["args"].split() or [""])[0]
        if not files or not files[0].startswith("graph/") or not files[0].endswith(".json"):
            continue
        if command not in ("run", "validate") or "--set" in case["args"]:
            continue
        try:
            with open(os.path.join(src, "tests/catalogue/files", files[0]), encoding="utf-8") as f:
                graph = json.load(f)
        except (ValueError, UnicodeDecodeError):
            continue  # not JSON at all: no schema applies
        errors = list(validator.iter_errors(graph))
        message = case["message"]
        if case["exit"] == 0:
            accepted += 1
            for e in errors:
                failures.append(f"catalogue {case['name']} runs, but the schema refuses it: "
                                f"{e.json_path}: {e.message}")
        elif case["exit"] == 2 and structural(graph, message):
            refused += 1
            if not errors:
                failures.append(f"catalogue {case['name']}: the schema accepts what the loader "
                                f"refuses: {message}")
        else:
            beyond += 1
    if accepted < 20 or refused < 50:
        failures.append(f"too few catalogue graphs checked: {accepted} accepted, {refused} refused")

    print(f"{len(examples)} example graphs, {params} parameters, catalogue: {accepted} accepted, "
          f"{refused} structural refusals, {beyond} left to the loader")
    for f in failures:
        print("FAIL:", f)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
