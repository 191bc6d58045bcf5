# swarf: top-level entry points. `make demo` and `make test` work on a fresh
# Debian bookworm machine: both install what is missing first.
BUILD ?= build
JOBS ?= $(shell nproc)

.PHONY: all build deps demo test bench clean

all: build

deps:
	scripts/install-deps

$(BUILD)/build.ninja:
	cmake -S . -B $(BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Release

build: $(BUILD)/build.ninja
	cmake --build $(BUILD) -j $(JOBS)

demo: deps build
	@mkdir -p out
	$(BUILD)/bin/swarf table | tee out/table.txt
	@echo "demo: the table above is also in out/table.txt"

test: deps build
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS)

bench: deps build
	$(BUILD)/bin/swarf_bench

clean:
	rm -rf $(BUILD)
