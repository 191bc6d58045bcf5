# swarf: top-level entry points. `make demo` and `make test` work on a fresh
# Debian bookworm machine: both install what is missing first.
BUILD ?= build
JOBS ?= $(shell nproc)
# The clang-14 libFuzzer build (scripts/fuzz) and the ASan+UBSan build.
FUZZ_BUILD ?= build-fuzz
ASAN_BUILD ?= build-asan
FUZZ_SECONDS ?= 30

.PHONY: all build deps demo test bench clean lint-deploy fuzz fuzz-build \
	test-sanitize test-fresh

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

# Also a short run of each fuzzer (20 s, the ctest label "fuzz" of the
# clang build), the four at once whatever JOBS is (each runs for a fixed
# time); the corpus replays are part of the main ctest.
test: deps build fuzz-build
	cd $(BUILD) && ctest --output-on-failure --timeout 900 -j $(JOBS)
	cd $(FUZZ_BUILD) && ctest --output-on-failure -j 4 -L '^fuzz$$'

# What a new user gets: `make test` in a fresh clone of the committed HEAD in
# an empty temporary folder, nothing beside it (scripts/test-fresh). Long (a
# full build); not part of CI.
test-fresh:
	JOBS=$(JOBS) scripts/test-fresh

bench: deps build
	$(BUILD)/bin/swarf_bench
	scripts/bench-plate $(BUILD) 100

clean:
	rm -rf $(BUILD)

# Deployment files without an engine or a cluster: nginx -t on the rendered
# balancer config, compose and Kubernetes YAML, the Dockerfile's shape (also
# run by `make test`, as the ctest deploy_lint).
lint-deploy: deps
	deploy/lint

# Fuzzing (tests/fuzz): each libFuzzer target for FUZZ_SECONDS, all at once;
# a long run: make fuzz FUZZ_SECONDS=3600 (or scripts/fuzz 3600).
fuzz-build: deps
	FUZZ_BUILD=$(FUZZ_BUILD) JOBS=$(JOBS) scripts/fuzz --build-only

fuzz: deps
	FUZZ_BUILD=$(FUZZ_BUILD) JOBS=$(JOBS) scripts/fuzz $(FUZZ_SECONDS)

# The whole test suite built with ASan + UBSan (-O1, no recovery: any report
# fails its test), but the headless-Chromium viewer tests: Chromium is not our
# code and is slow under load; viewer_api_test covers the relay. Nor the
# FreeCAD add-on's (Python in FreeCAD; `make test` runs them), nor the
# precision sweeps (14 jobs, 150 s under ASan: the valuation of whole jobs,
# which RunE2eTest's jobs run there too), nor the Python client's tests
# (23 s: Python, against a server the C++ API tests drive). Together they
# took CI past its 20 minutes. Run by .ci/run after `make test`.
$(ASAN_BUILD)/build.ninja:
	cmake -S . -B $(ASAN_BUILD) -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1" -DSWARF_SANITIZE=ON \
	  -DSWARF_BENCH=OFF

test-sanitize: deps $(ASAN_BUILD)/build.ninja
	cmake --build $(ASAN_BUILD) -j $(JOBS)
	cd $(ASAN_BUILD) && UBSAN_OPTIONS=print_stacktrace=1 \
	  LSAN_OPTIONS=suppressions=$(CURDIR)/tests/lsan.supp \
	  ctest --output-on-failure --timeout 900 -j $(JOBS) \
	  -E '^ViewerBrowserTest|^freecad_|^python_client$$|PrecisionTest\.DefaultSchemeNeverWorseThanTheZmap/'

# The differential test against LinuxCNC's own interpreter (issue 27):
# rs274 (Debian's linuxcnc-uspace, installed here when missing: it is large,
# so not in scripts/install-deps) and `swarf moves` on LinuxCNC's example
# programs and on tests/linuxcnc/*.ngc; verdicts in tests/linuxcnc/expected.txt.
.PHONY: test-linuxcnc
test-linuxcnc: $(BUILD)/build.ninja
	@command -v rs274 >/dev/null || { \
	  SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
	  $$SUDO apt-get update && \
	  DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y \
	    --no-install-recommends linuxcnc-uspace; }
	cmake --build $(BUILD) -j $(JOBS) --target swarf
	scripts/linuxcnc-diff --swarf $(BUILD)/bin/swarf \
	  --expect tests/linuxcnc/expected.txt \
	  /usr/share/linuxcnc/ncfiles/*.ngc tests/linuxcnc/*.ngc

# The FreeCAD add-on (client/freecad) headless: FreeCAD builds a Job, the
# add-on simulates it, checked against `swarf run` bit for bit
# (tests/freecad; the ctest label "freecad", also run by `make test` where
# freecadcmd is installed; the GUI test under Xvfb). Installs Debian's
# freecad and xvfb when missing (large: not in scripts/install-deps).
.PHONY: test-freecad
test-freecad: $(BUILD)/build.ninja
	@command -v freecadcmd >/dev/null && command -v xvfb-run >/dev/null || { \
	  SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
	  $$SUDO apt-get update && \
	  DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y \
	    --no-install-recommends freecad xvfb xauth; }
	cmake --build $(BUILD) -j $(JOBS) --target swarf swarfd
	cd $(BUILD) && ctest --output-on-failure -L '^freecad$$'
