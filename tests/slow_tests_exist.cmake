# The test `slow_tests_exist`: every entry of tests/slow_tests.cmake names a test of this build
# and carries the `slow` label (ctest -N -L slow lists exactly the entries).
#   cmake -DLIST=tests/slow_tests.cmake -DBUILD_DIR=<build> -DCTEST=<ctest> -P slow_tests_exist.cmake
set(SECURE_SLOW_TESTS_LIST_ONLY ON)
include(${LIST})
execute_process(COMMAND ${CTEST} -N -L slow WORKING_DIRECTORY ${BUILD_DIR}
                OUTPUT_VARIABLE listed RESULT_VARIABLE status)
if(NOT status EQUAL 0)
  message(FATAL_ERROR "ctest -N -L slow failed (exit ${status})")
endif()
list(LENGTH SECURE_SLOW_TESTS _n)
math(EXPR _last "${_n} - 1")
set(missing "")
foreach(_i RANGE 1 ${_last} 2)
  list(GET SECURE_SLOW_TESTS ${_i} _name)
  string(FIND "${listed}" ": ${_name}\n" _at)
  if(_at EQUAL -1)
    list(APPEND missing ${_name})
  endif()
endforeach()
if(missing)
  message(FATAL_ERROR "tests/slow_tests.cmake names tests that do not exist or lack the slow "
                      "label: ${missing}")
endif()
math(EXPR _count "${_n} / 2")
message(STATUS "${_count} slow tests, each defined and labelled")
