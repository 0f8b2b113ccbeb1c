# secure_add_library(<module> SOURCES ... DEPS ...)
# Creates target secure_<module> with alias secure::<module>. Includes are rooted at the repo
# ("secure/<module>/x.h"), and DEPS are linked PUBLIC so the module order is visible in CMake:
# a module that includes a header of a module it does not depend on fails to build.
function(secure_add_library module)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(secure_${module} STATIC ${ARG_SOURCES})
  add_library(secure::${module} ALIAS secure_${module})
  target_include_directories(secure_${module} PUBLIC ${PROJECT_SOURCE_DIR})
  target_compile_options(secure_${module} PRIVATE ${SECURE_WARNINGS} PUBLIC ${SECURE_ARCH_FLAGS})
  target_link_libraries(secure_${module} PUBLIC ${ARG_DEPS} PRIVATE ${ARG_PRIVATE_DEPS})
endfunction()

# secure_add_test(<name> <module-label> SOURCES ... DEPS ...)
# One GoogleTest executable per unit, registered with CTest and labelled by module
# (ctest -L cbf runs the cbf tests).
function(secure_add_test name label)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_include_directories(${name} PRIVATE ${PROJECT_SOURCE_DIR})  # "tests/test_util.h"
  target_compile_options(${name} PRIVATE ${SECURE_WARNINGS})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} GTest::gtest GTest::gtest_main)
  target_compile_definitions(${name} PRIVATE
    SECURE_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
    SECURE_SHARED_DIR="${PROJECT_SOURCE_DIR}/../shared")
  gtest_discover_tests(${name} PROPERTIES LABELS ${label} DISCOVERY_TIMEOUT 60)
endfunction()

# secure_add_domain(<name> SOURCES ... DEPS ... [PRIVATE_DEPS ...])
# A domain plug-in (domains/<name>/): target secure_domain_<name>, alias secure::domain_<name>.
# Its dependencies stay its own (a MuJoCo domain links MuJoCo PRIVATE), so nothing else pulls them.
function(secure_add_domain name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS;PRIVATE_DEPS" ${ARGN})
  secure_add_library(domain_${name} SOURCES ${ARG_SOURCES} DEPS ${ARG_DEPS}
                     PRIVATE_DEPS ${ARG_PRIVATE_DEPS})
endfunction()
