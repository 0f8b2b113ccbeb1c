# The two commands of the README. Both set up the machine if needed (scripts/setup.sh installs
# missing Debian packages, configures and builds), then run.
#   make demo   the main job: the SECURE pipeline on the default domain, printing its table
#   make test   every unit test (ctest)
BUILD ?= build
JOBS  ?= $(shell nproc)

.PHONY: demo test build bench clean

build:
	SECURE_BUILD_DIR=$(BUILD) scripts/setup.sh

demo: build
	$(BUILD)/apps/secure/secure demo

test: build
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS)

bench: build
	cmake --build $(BUILD) --target bench
	@echo "benchmarks are in $(BUILD)/bench/ (bench/README.md says what each measures)"

clean:
	rm -rf $(BUILD)
