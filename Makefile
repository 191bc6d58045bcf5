# swarf: top-level entry points. `make demo` and `make test` work on a fresh
# Debian bookworm machine: both install what is missing first.
BUILD ?= build
JOBS ?= $(shell nproc)

.PHONY: all build deps demo test bench clean lint-deploy

all: build

deps:
	scripts/install-deps

$(BUILD)/build.ninja:
	cmake -S . -B $(BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Release

build: $(BUILD)/build.ninja
	cmake --build $(BUILD) -j $(JOBS)

# The main job: a sample finishing program (examples/relief.nc, written by
# scripts/make-example) simulated on the embedded server.
demo: deps build
	$(BUILD)/bin/swarf run examples/relief.nc --tool ball:d=2 \
	  --stock 0,0,60,60,0 --spacing 0.05 --out out/demo
	@echo
	@echo "demo: pictures, meshes and stats are in out/demo/:"
	@echo "  relief.png (the machined surface), error.png (where the scheme's"
	@echo "  error is), marks.png/.svg/.json (cutting marks), surface.stl and"
	@echo "  surface.wrl (meshes), stats.json. The paper's tables: build/bin/swarf table"

test: deps build
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS)

bench: deps build
	$(BUILD)/bin/swarf_bench

clean:
	rm -rf $(BUILD)

# Deployment files without an engine or a cluster: nginx -t on the rendered
# balancer config, compose and Kubernetes YAML, the Dockerfile's shape (also
# run by `make test`, as the ctest deploy_lint).
lint-deploy: deps
	deploy/lint
