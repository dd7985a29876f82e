# The README's two commands. Each installs missing Debian packages, configures and builds first.
BUILD ?= build
JOBS ?= $(shell nproc)
GRAINS := $(BUILD)/grains

.PHONY: deps configure build demo test bench bench-features clean format

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

bench: build
	$(GRAINS) bench --out out/bench

bench-features: build
	$(GRAINS) bench --features --out out/bench

clean:
	rm -rf $(BUILD) out

format:
	find engine nodes app tests bench viewer-offline -name '*.cpp' -o -name '*.h' | xargs clang-format -i
