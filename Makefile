# The commands of the README. Each sets up the machine if needed (scripts/setup.sh installs
# missing Debian packages, configures and builds), then run.
#   make demo   the main job: the SECURE pipeline on the default domain, printing its table,
#               then its HTML report (secure report; the run directory is $(BUILD)/demo-run,
#               made anew by each `make demo`: a run directory's finished seeds are otherwise reused)
#   make reproduce  every experiment of the paper on every domain declaring it (secure reproduce,
#               into $(BUILD)/reproduce: rerun to resume), then one HTML page of every table
#               ($(BUILD)/reproduce/report.html). REPRODUCE_FLAGS='--profile quick' for the small
#               sizes, '--shard k/N' for one shard (apps/secure/README.md, docs/CLUSTER.md)
#   make test   every fast unit test of every module, the Python and report tests included
#               (ctest without the labels slow, long, dispatch, property-random and install;
#               tests/README.md)
BUILD ?= build
JOBS  ?= $(shell nproc)

.PHONY: demo reproduce test test-slow test-ci test-install build bench check clean

build:
	SECURE_BUILD_DIR=$(BUILD) scripts/setup.sh

demo: build
	rm -rf $(BUILD)/demo-run
	$(BUILD)/apps/secure/secure demo --out $(BUILD)/demo-run
	$(BUILD)/apps/secure/secure report $(BUILD)/demo-run

REPRODUCE_DIR ?= $(BUILD)/reproduce
REPRODUCE_FLAGS ?=
reproduce: build
	$(BUILD)/apps/secure/secure reproduce --out $(REPRODUCE_DIR) $(REPRODUCE_FLAGS)
	$(BUILD)/apps/secure/secure report $(REPRODUCE_DIR)

# The labels `make test` leaves out (tests/README.md): slow (tests that train whole quick
# experiments), dispatch (the inference and shield tests again on each forced kernel path),
# property-random (the shield's properties with a fresh RapidCheck seed) and long (10^6 cases).
test: build
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS) -LE 'slow|long|dispatch|property-random|install'

# Only the slow tests.
test-slow: build
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS) -L slow

# `pip install .` into a scratch venv, with --user, and `pip wheel .` (python_pip_install; about
# 11 minutes the first time: it builds the module in its own CMake directory). Not run by CI.
test-install: build
	cd $(BUILD) && ctest --output-on-failure -L install

# What CI runs after `make test` (.ci/run): the slow, dispatch and fresh-seed tests.
test-ci: build
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS) -L 'slow|dispatch|property-random'

bench: build
	cmake --build $(BUILD) --target bench
	@echo "benchmarks are in $(BUILD)/bench/ (bench/README.md says what each measures)"

# The checking build: ASan + UBSan unit tests and the fuzzers (scripts/check.sh; run by CI).
check:
	scripts/check.sh

clean:
	rm -rf $(BUILD) build-check
