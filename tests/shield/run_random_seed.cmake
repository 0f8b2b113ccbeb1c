# Runs a RapidCheck program with a fresh seed and prints the seed first, so that a red run can be
# replayed: RC_PARAMS="seed=<seed>" <program> --gtest_filter=<filter>.
#   cmake -DPROGRAM=... -DFILTER=... -DCASES=... -P run_random_seed.cmake
string(RANDOM LENGTH 9 ALPHABET 0123456789 seed)
string(REGEX REPLACE "^0+" "" seed "1${seed}")
message(STATUS "rapidcheck seed: ${seed} (replay: RC_PARAMS=\"seed=${seed}\" ${PROGRAM} --gtest_filter=${FILTER})")
set(ENV{RC_PARAMS} "max_success=${CASES} seed=${seed}")
execute_process(COMMAND ${PROGRAM} --gtest_filter=${FILTER} RESULT_VARIABLE status)
if(NOT status EQUAL 0)
  message(FATAL_ERROR "rapidcheck seed ${seed} failed (exit ${status}); keep it in "
                      "tests/shield/rapidcheck_regression_seeds.txt once fixed")
endif()
