# The two commands of the README. Both set up the machine if needed (scripts/setup.sh installs
# missing Debian packages, configures and builds), then run.
#   make demo   the main job: the SECURE pipeline on the default domain, printing its table,
#               then its HTML report (secure report; the run directory is $(BUILD)/demo-run,
#               made anew by each `make demo`: a run directory's finished seeds are otherwise reused)
#   make test   every unit test (ctest)
BUILD ?= build
JOBS  ?= $(shell nproc)

.PHONY: demo test build bench check clean

build:
	SECURE_BUILD_DIR=$(BUILD) scripts/setup.sh

demo: build
	rm -rf $(BUILD)/demo-run
	$(BUILD)/apps/secure/secure demo --out $(BUILD)/demo-run
	$(BUILD)/apps/secure/secure report $(BUILD)/demo-run

# Every test but the `long` label (ctest -L long: the shield's properties at 10^6 cases).
test: build
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS) -LE long

bench: build
	cmake --build $(BUILD) --target bench
	@echo "benchmarks are in $(BUILD)/bench/ (bench/README.md says what each measures)"

# The checking build: ASan + UBSan unit tests and the fuzzers (scripts/check.sh; run by CI).
check:
	scripts/check.sh

clean:
	rm -rf $(BUILD) build-check
