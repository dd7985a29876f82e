#!/usr/bin/env python3
"""Every test of the Catch binary runs with the environment the suite assumes (one OpenMP thread,
threads that sleep at a barrier, PoCL's cache in the build folder), as ctest will run it, and the
OpenCL backend's tests carry the label opencl.

Two test processes share the two cores of `make test`; without OMP_NUM_THREADS=1 and
OMP_WAIT_POLICY=passive each spins its own threads through the other's time slices, and a suite
of minutes takes hours. The environment is set after discovery (cmake/test_environment.cmake.in);
this checks what ctest actually holds.

Usage: check_test_environment.py CTEST BUILD_DIR
"""
import json
import subprocess
import sys

WANT = {"OMP_NUM_THREADS=1", "OMP_WAIT_POLICY=passive"}
OWN = {"graph_schema", "vtk_client", "opencl_kernels_compile", "opencl_kernels_compile_without_fp64",
       "test_environment"}

ctest, build = sys.argv[1], sys.argv[2]
listing = json.loads(subprocess.run([ctest, "--show-only=json-v1"], cwd=build, check=True,
                                    capture_output=True, text=True).stdout)
missing = []
count = 0
for test in listing["tests"]:
    if test["name"] in OWN:
        continue
    count += 1
    env = set()
    for prop in test.get("properties", []):
        if prop["name"] == "ENVIRONMENT":
            env.update(prop["value"])
    if not WANT <= env or not any(v.startswith("POCL_CACHE_DIR=") for v in env):
        missing.append(f"{test['name']}: {sorted(env)}")
if count == 0:
    sys.exit("no Catch tests listed: was grains_tests built and discovered?")
opencl = [t["name"] for t in listing["tests"]
          if any(p["name"] == "LABELS" and "opencl" in p["value"] for p in t.get("properties", []))]
if len(opencl) < 8:
    missing.append(f"label opencl on {len(opencl)} tests, fewer than the backend's 8: {opencl}")
if missing:
    print(f"{len(missing)} of {count} tests lack the suite's environment:", file=sys.stderr)
    print("\n".join(missing[:10]), file=sys.stderr)
    sys.exit(1)
print(f"{count} tests, each with {sorted(WANT)} and POCL_CACHE_DIR; {len(opencl)} labelled opencl")
