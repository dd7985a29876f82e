# The README's two commands. Each installs missing Debian packages, configures and builds first.
BUILD ?= build
JOBS ?= $(shell nproc)
GRAINS := $(BUILD)/grains
GRAINS_LAB := $(BUILD)/grains-lab

.PHONY: deps configure build demo test docs bench bench-features clean format \
        fuzz-build fuzz-short fuzz test-sanitize test-clients

deps:
	bash scripts/install-deps.sh

configure: deps
	cmake -S . -B $(BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Release

build: configure
	cmake --build $(BUILD) -j $(JOBS)

demo: build
	$(GRAINS) run graphs/default.json --out out/demo --overwrite
	$(GRAINS) render out/demo --graph graphs/default.json
	$(GRAINS) heap out/demo/frame_0096.ply
	@echo "demo: frames and stats.csv are in out/demo; pictures in out/demo/render, contact sheet out/demo/render/contact_sheet.png"

test: build
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS)
	$(MAKE) fuzz-short

# The tools people open runs with, reading a real example run with their own code: VTK's reader
# (the CTest vtk_client, also part of test) and Blender headless with the add-on in tools/blender
# (installs Blender first: about 300 MB of Debian packages; the add-on's import checked against
# the PLY frames, and a still rendered with Cycles that must not be blank).
test-clients: build
	bash scripts/install-deps.sh --clients
	cd $(BUILD) && ctest --output-on-failure -R vtk_client
	blender -b --factory-startup --python-exit-code 1 --python tests/clients/check_blender.py -- \
	  $(abspath $(GRAINS)) $(CURDIR) $(abspath $(BUILD))/blender_client

# The node reference and the graph schema, generated from the node types' parameter tables
# (a test fails when the committed copies are stale).
docs: build
	$(GRAINS) nodes --markdown > docs/nodes.md
	$(GRAINS) schema > docs/graph.schema.json

# libFuzzer targets (fuzz/, docs/fuzzing.md), built with clang in their own folder.
# fuzz-short (part of test): each target FUZZ_SHORT_SECONDS from its corpus; fails on a finding.
# fuzz: the longer run, FUZZ_SECONDS per target (default 10 minutes each); FUZZ_TARGETS narrows it.
FUZZ_BUILD ?= build-fuzz
FUZZ_CXX ?= clang++-14
FUZZ_SHORT_SECONDS ?= 25
FUZZ_SECONDS ?= 600
FUZZ_TARGETS ?= graph expression ply obj

fuzz-build: deps
	cmake -S . -B $(FUZZ_BUILD) -G Ninja -DCMAKE_CXX_COMPILER=$(FUZZ_CXX) -DCMAKE_BUILD_TYPE=Fuzz -DGRAINS_FUZZ=ON
	cmake --build $(FUZZ_BUILD) -j $(JOBS) --target fuzzers

fuzz-short: fuzz-build
	bash fuzz/run.sh $(FUZZ_SHORT_SECONDS) $(FUZZ_BUILD) $(FUZZ_TARGETS)

fuzz: fuzz-build
	bash fuzz/run.sh $(FUZZ_SECONDS) $(FUZZ_BUILD) $(FUZZ_TARGETS)

# The whole test suite under address and undefined-behaviour sanitizers (g++, -O1) in build-asan.
# Not part of test: it takes far longer than CI's budget (about 2 hours on two cores).
# Any sanitizer report fails the test that printed it.
ASAN_BUILD ?= build-asan
test-sanitize: deps
	cmake -S . -B $(ASAN_BUILD) -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1" -DGRAINS_SANITIZE=ON "-DGRAINS_TEST_GLOB=tests/*.cpp"
	cmake --build $(ASAN_BUILD) -j $(JOBS)
	cd $(ASAN_BUILD) && ASAN_OPTIONS=halt_on_error=1:detect_leaks=1:abort_on_error=1 \
	  LSAN_OPTIONS=suppressions=$(CURDIR)/tests/lsan.supp \
	  UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1 ctest --output-on-failure -j $(JOBS)

bench: build
	$(GRAINS_LAB) bench --out out/bench

bench-features: build
	$(GRAINS_LAB) features --out out/bench

clean:
	rm -rf $(BUILD) $(FUZZ_BUILD) $(ASAN_BUILD) out

format:
	find engine nodes cli app lab tests bench viewer-offline -name '*.cpp' -o -name '*.h' | xargs clang-format -i
