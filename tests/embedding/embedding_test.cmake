# The embedding test (ctest -L embedding): SECURE installed into a fresh prefix, a consumer built
# against it, and the realtime_loop example run for a few seconds (docs/EMBEDDING.md).
#   cmake -DSOURCE_DIR=<repo> -DBUILD_DIR=<secure build> -DWORK_DIR=<scratch> -DSECURE_CLI=<secure>
#         [-DCXX_COMPILER=...] [-DCOMPILER_LAUNCHER=ccache] [-DDURATION=2] -P embedding_test.cmake
# Steps: (1) cmake --install into WORK_DIR/prefix; (2) the installed package names neither Torch
# nor MuJoCo; (3) every installed header compiles in a consumer (headers_check/); (4) the example
# configures and builds against the prefix, and its link line has no Torch/MuJoCo/OSMesa;
# (5) `secure cbf train` writes a small double-integrator barrier; (6) the example runs for
# DURATION seconds and prints its latency report, then 1 s with a quick BC policy model, and a
# missing model file is a one-line error with exit 1.
foreach(_v SOURCE_DIR BUILD_DIR WORK_DIR SECURE_CLI)
  if(NOT DEFINED ${_v})
    message(FATAL_ERROR "embedding_test.cmake: -D${_v}=... is required")
  endif()
endforeach()
if(NOT DEFINED DURATION)
  set(DURATION 2)
endif()
set(_forbidden "torch|c10|caffe2|mujoco|osmesa")

# Runs a command; fails the test with its output unless it exits 0. Not with the flags of a make
# that runs ctest (`make test`): -k, -n or a jobserver would leak into the consumer builds.
function(run)
  execute_process(COMMAND "${CMAKE_COMMAND}" -E env --unset=MAKEFLAGS --unset=MFLAGS
                          --unset=MAKELEVEL ${ARGN}
                  RESULT_VARIABLE _rc OUTPUT_VARIABLE _out ERROR_VARIABLE _out)
  if(NOT _rc EQUAL 0)
    string(REPLACE ";" " " _cmd "${ARGN}")
    message(FATAL_ERROR "failed (${_rc}): ${_cmd}\n${_out}")
  endif()
  set(run_output "${_out}" PARENT_SCOPE)
endfunction()

set(_prefix "${WORK_DIR}/prefix")
file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")

# (1) Install.
run("${CMAKE_COMMAND}" --install "${BUILD_DIR}" --prefix "${_prefix}")
if(NOT EXISTS "${_prefix}/include/secure/shield/shield.h")
  message(FATAL_ERROR "the install has no include/secure/shield/shield.h")
endif()

# (2) Nothing of the training or simulation stack is installed or referenced.
file(GLOB_RECURSE _installed RELATIVE "${_prefix}" "${_prefix}/*")
foreach(_f IN LISTS _installed)
  string(TOLOWER "${_f}" _lower)
  if(_lower MATCHES "${_forbidden}|_train|experiments|plugins|domain_")
    message(FATAL_ERROR "installed a file of a private part: ${_prefix}/${_f}")
  endif()
  if(_f MATCHES "\\.cmake$")
    file(STRINGS "${_prefix}/${_f}" _text REGEX "^[ \t]*[^# \t]")  # code, not comments
    string(TOLOWER "${_text}" _text)
    if(_text MATCHES "${_forbidden}")
      message(FATAL_ERROR "${_prefix}/${_f} mentions '${CMAKE_MATCH_0}'")
    endif()
  endif()
endforeach()

# Makefiles whatever the project's generator: step (4) reads the link line from link.txt.
set(_configure_args -G "Unix Makefiles" -DCMAKE_BUILD_TYPE=Release "-DCMAKE_PREFIX_PATH=${_prefix}")
if(CXX_COMPILER)
  list(APPEND _configure_args "-DCMAKE_CXX_COMPILER=${CXX_COMPILER}")
endif()
if(COMPILER_LAUNCHER)
  list(APPEND _configure_args "-DCMAKE_CXX_COMPILER_LAUNCHER=${COMPILER_LAUNCHER}")
endif()

# (3) Every installed header compiles against the installed package alone.
run("${CMAKE_COMMAND}" -S "${SOURCE_DIR}/tests/embedding/headers_check" -B "${WORK_DIR}/headers"
    ${_configure_args})
run("${CMAKE_COMMAND}" --build "${WORK_DIR}/headers")

# (4) The example, in its own build directory.
run("${CMAKE_COMMAND}" -S "${SOURCE_DIR}/examples/cpp/realtime_loop" -B "${WORK_DIR}/example"
    ${_configure_args})
run("${CMAKE_COMMAND}" --build "${WORK_DIR}/example")
file(READ "${WORK_DIR}/example/CMakeFiles/realtime_loop.dir/link.txt" _link)
string(TOLOWER "${_link}" _link_lower)
if(_link_lower MATCHES "${_forbidden}")
  message(FATAL_ERROR "the example links '${CMAKE_MATCH_0}': ${_link}")
endif()
if(NOT _link MATCHES "libsecure_shield\\.a")
  message(FATAL_ERROR "the example does not link the installed secure::shield: ${_link}")
endif()

# (5) A small barrier (about a second of training).
run("${SECURE_CLI}" cbf train --domain double-integrator --epochs 50 --seed 1
    --out "${WORK_DIR}/di.model")

# (6) The loop: exit 0 (misses are reported, not errors) and the report.
run("${WORK_DIR}/example/realtime_loop" --barrier "${WORK_DIR}/di.model" --duration "${DURATION}")
message(STATUS "realtime_loop:\n${run_output}")
foreach(_line "deadline misses [0-9]+" "decision latency \\(us\\): p50 [0-9.]+  p90 [0-9.]+  p99 [0-9.]+  max [0-9.]+"
              "decisions: safe [0-9]+")
  if(NOT run_output MATCHES "${_line}")
    message(FATAL_ERROR "the realtime_loop report has no line matching '${_line}'")
  endif()
endforeach()
# With a Gaussian policy model (secure::policy from the install): a quick BC policy.
run("${SECURE_CLI}" demos generate --domain double-integrator --episodes 20
    --out "${WORK_DIR}/demos")
run("${SECURE_CLI}" policy train --algo bc --demos "${WORK_DIR}/demos/demos.csv" --epochs 2
    --out "${WORK_DIR}/bc.model")
run("${WORK_DIR}/example/realtime_loop" --barrier "${WORK_DIR}/di.model"
    --policy "${WORK_DIR}/bc.model" --duration 1)
if(NOT run_output MATCHES "policy: [^\n]*bc\\.model" OR NOT run_output MATCHES "p99 [0-9.]+")
  message(FATAL_ERROR "realtime_loop with --policy printed no report:\n${run_output}")
endif()
# An error is one line and exit 1.
execute_process(COMMAND "${WORK_DIR}/example/realtime_loop" --barrier "${WORK_DIR}/missing.model"
                RESULT_VARIABLE _rc OUTPUT_VARIABLE _out ERROR_VARIABLE _err)
if(NOT _rc EQUAL 1 OR NOT _err MATCHES "^realtime_loop: error: [^\n]*missing\\.model[^\n]*\n$")
  message(FATAL_ERROR "a missing barrier file gave exit ${_rc} and '${_err}'")
endif()
