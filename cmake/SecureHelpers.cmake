# The layering check (cmake/SecureArchitecture.cmake): every target made here is checked.
include(${CMAKE_CURRENT_LIST_DIR}/SecureArchitecture.cmake)

# secure_add_library(<module> SOURCES ... DEPS ...)
# Creates target secure_<module> with alias secure::<module>. Includes are rooted at the repo
# ("secure/<module>/x.h"), and DEPS are linked PUBLIC so the module order is visible in CMake.
# The repository root is an include directory of every target, so the compiler alone would
# accept any include: the build checks each target's includes against its links instead
# (SecureArchitecture.cmake), and a module that includes a header of a target it does not link
# fails to build, naming the file, the include and the rule.
function(secure_add_library module)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(secure_${module} STATIC ${ARG_SOURCES})
  add_library(secure::${module} ALIAS secure_${module})
  # The source tree in the build; <prefix>/include once installed (cmake/SecureInstall.cmake).
  target_include_directories(secure_${module} PUBLIC $<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}>
                                                     $<INSTALL_INTERFACE:include>)
  target_compile_options(secure_${module} PRIVATE ${SECURE_WARNINGS} PUBLIC ${SECURE_ARCH_FLAGS})
  target_link_libraries(secure_${module} PUBLIC ${ARG_DEPS} PRIVATE ${ARG_PRIVATE_DEPS})
  secure_check_includes(secure_${module})
endfunction()

# secure_embed_text(<file> <namespace> <symbol> <out-var>)
# Makes the text of <file> (in the calling folder, e.g. a MuJoCo model) a string in the library:
# writes <build>/generated/<file's stem>_<file's extension>.cc defining
# `const char <namespace>::<symbol>[]` and sets <out-var> to its path (add it to the SOURCES).
# There is no path to find at run time; editing <file> re-runs CMake.
function(secure_embed_text file namespace symbol out_var)
  file(READ ${CMAKE_CURRENT_SOURCE_DIR}/${file} _text)
  set_property(DIRECTORY APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS ${file})
  string(REPLACE "." "_" _stem "${file}")
  file(RELATIVE_PATH _rel ${PROJECT_SOURCE_DIR} ${CMAKE_CURRENT_SOURCE_DIR}/${file})
  set(_out ${CMAKE_BINARY_DIR}/generated/${_stem}.cc)
  file(CONFIGURE OUTPUT ${_out} CONTENT
"// Generated from ${_rel} by its CMakeLists.txt: do not edit.
namespace ${namespace} {
extern const char ${symbol}[];
const char ${symbol}[] = R\"mjcf(@_text@)mjcf\";
}  // namespace ${namespace}
" @ONLY)
  set(${out_var} ${_out} PARENT_SCOPE)
endfunction()

# secure_add_test(<name> <module-label> [CLI] SOURCES ... DEPS ...)
# One GoogleTest executable per unit, registered with CTest and labelled by module
# (ctest -L cbf runs the cbf tests). CLI: the test runs the `secure` executable, whose path is
# SECURE_CLI there (and which is built first).
function(secure_add_test name label)
  cmake_parse_arguments(ARG "CLI" "" "SOURCES;DEPS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_include_directories(${name} PRIVATE ${PROJECT_SOURCE_DIR})  # "tests/test_util.h"
  target_compile_options(${name} PRIVATE ${SECURE_WARNINGS} ${SECURE_TEST_OPTIMIZATION})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} GTest::gtest GTest::gtest_main)
  target_compile_definitions(${name} PRIVATE
    SECURE_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
    SECURE_SHARED_DIR="${PROJECT_SOURCE_DIR}/../shared")
  # A fixed RapidCheck seed for every test (SECURE_RAPIDCHECK_SEED): a red run is the same red run
  # again. `ctest -L property-random` runs the properties with fresh seeds (tests/CMakeLists.txt).
  gtest_discover_tests(${name} PROPERTIES LABELS ${label} DISCOVERY_TIMEOUT 60
    ENVIRONMENT "RC_PARAMS=seed=${SECURE_RAPIDCHECK_SEED}")
  if(ARG_CLI)
    target_compile_definitions(${name} PRIVATE SECURE_CLI="$<TARGET_FILE:secure>")
    add_dependencies(${name} secure)
  endif()
endfunction()

# secure_add_domain(<name> SOURCES ... DEPS ... [PRIVATE_DEPS ...] [TESTS ...] [TEST_DEPS ...])
# A domain plug-in (its own folder, usually domains/<name>/): target secure_domain_<name>, alias
# secure::domain_<name>. Its dependencies stay its own (a MuJoCo domain links MuJoCo PRIVATE), so
# nothing else pulls them. The plug-in defines
# `void secure::plugins::Register_<name>(experiments::DomainRegistry&)` (it adds its
# experiments::Domain); secure_generate_domain_registry() calls every one of them from
# secure::plugins::RegisterBuiltinDomains().
# TESTS: the plug-in's own GoogleTest files (conventionally <folder>/tests/*.cc), built by
# secure_add_domain_tests() (tests/CMakeLists.txt) into one executable <name>_test, label
# `domains`, linking the plug-in, its DEPS and TEST_DEPS (not PRIVATE_DEPS: an imported target such
# as mujoco::mujoco exists only in the plug-in's folder; the static plug-in links it anyway);
# SECURE_CLI is the path of the `secure` executable there (for tests that run the CLI on it).
# Its includes are checked like a module's: it may include the generic modules it links (DEPS),
# and generic code may include it only by linking it.
function(secure_add_domain name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS;PRIVATE_DEPS;TESTS;TEST_DEPS" ${ARGN})
  secure_add_library(domain_${name} SOURCES ${ARG_SOURCES} DEPS ${ARG_DEPS}
                     PRIVATE_DEPS ${ARG_PRIVATE_DEPS})
  set_property(GLOBAL APPEND PROPERTY SECURE_DOMAIN_PLUGINS ${name})
  list(TRANSFORM ARG_TESTS PREPEND "${CMAKE_CURRENT_SOURCE_DIR}/")
  set_property(GLOBAL PROPERTY SECURE_DOMAIN_TESTS_${name} ${ARG_TESTS})
  set_property(GLOBAL PROPERTY SECURE_DOMAIN_TEST_DEPS_${name} ${ARG_DEPS} ${ARG_TEST_DEPS})
endfunction()

# secure_add_domain_tests(): one test executable per plug-in that declared TESTS (called once,
# from tests/CMakeLists.txt, where GoogleTest is found): <name>_test, label `domains`.
function(secure_add_domain_tests)
  get_property(_domains GLOBAL PROPERTY SECURE_DOMAIN_PLUGINS)
  foreach(_d IN LISTS _domains)
    get_property(_tests GLOBAL PROPERTY SECURE_DOMAIN_TESTS_${_d})
    if(NOT _tests)
      continue()
    endif()
    get_property(_deps GLOBAL PROPERTY SECURE_DOMAIN_TEST_DEPS_${_d})
    secure_add_test(${_d}_test domains CLI SOURCES ${_tests} DEPS secure::domain_${_d} ${_deps})
  endforeach()
endfunction()

# secure_generate_domain_registry(): after every secure_add_domain (the top-level CMakeLists.txt
# calls it once, after domains/ and the plug-in folders outside it, e.g. examples/toy_domain/),
# writes <build>/generated/secure_registered_domains.cc (RegisterBuiltinDomains calling each
# plug-in's Register_<name>) and the target secure::plugins, which links every domain plug-in.
function(secure_generate_domain_registry)
  get_property(_domains GLOBAL PROPERTY SECURE_DOMAIN_PLUGINS)
  set(_declarations "")
  set(_calls "")
  foreach(_d IN LISTS _domains)
    string(APPEND _declarations "void Register_${_d}(experiments::DomainRegistry& registry);\n")
    string(APPEND _calls "  Register_${_d}(registry);\n")
  endforeach()
  set(_file "${CMAKE_BINARY_DIR}/generated/secure_registered_domains.cc")
  file(CONFIGURE OUTPUT "${_file}" CONTENT
"// Generated by secure_generate_domain_registry() (cmake/SecureHelpers.cmake): do not edit.
#include \"secure/experiments/domain.h\"

#include <algorithm>
#include <mutex>
#include <vector>

namespace secure::plugins {
${_declarations}
void RegisterBuiltinDomains(experiments::DomainRegistry& registry) {
  // Each registry once (the CLI and the tests call this at start-up).
  static std::mutex mutex;
  static std::vector<const experiments::DomainRegistry*> done;
  const std::lock_guard<std::mutex> lock(mutex);
  if (std::find(done.begin(), done.end(), &registry) != done.end()) return;
${_calls}  done.push_back(&registry);
}
}  // namespace secure::plugins
")
  add_library(secure_plugins STATIC "${_file}")
  add_library(secure::plugins ALIAS secure_plugins)
  target_include_directories(secure_plugins PUBLIC ${PROJECT_SOURCE_DIR})
  list(TRANSFORM _domains PREPEND "secure::domain_" OUTPUT_VARIABLE _targets)
  target_link_libraries(secure_plugins PUBLIC secure::experiments ${_targets})
endfunction()
