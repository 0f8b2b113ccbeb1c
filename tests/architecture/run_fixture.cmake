# Proves the layering check (cmake/SecureArchitecture.cmake) fails the build on a wrong-way
# include. Copies tests/architecture/fixture (a miniature of the repository made with the real
# cmake/SecureHelpers.cmake), builds it (it must pass, and a second build must not re-run the
# checks), then plants one wrong-way include at a time into a file of the copy: the build must
# fail naming the file, the include, the rule and the target. Restored, the fixture builds again.
#
#   cmake -DSECURE_SOURCE_DIR=<repo> -DWORK=<dir> [-DGENERATOR=<g> -DMAKE_PROGRAM=<p>
#         -DCXX=<compiler>] -P tests/architecture/run_fixture.cmake
cmake_minimum_required(VERSION 3.25)

set(_src "${WORK}/src")
set(_build "${WORK}/build")
file(REMOVE_RECURSE "${WORK}")
file(COPY "${SECURE_SOURCE_DIR}/tests/architecture/fixture/" DESTINATION "${_src}")

set(_configure "${CMAKE_COMMAND}" -S "${_src}" -B "${_build}"
               "-DSECURE_CMAKE_DIR=${SECURE_SOURCE_DIR}/cmake")
if(GENERATOR)
  list(APPEND _configure -G "${GENERATOR}")
endif()
if(MAKE_PROGRAM)
  list(APPEND _configure "-DCMAKE_MAKE_PROGRAM=${MAKE_PROGRAM}")
endif()
if(CXX)
  list(APPEND _configure "-DCMAKE_CXX_COMPILER=${CXX}")
endif()
execute_process(COMMAND ${_configure} RESULT_VARIABLE _rc OUTPUT_VARIABLE _out ERROR_VARIABLE _out)
if(NOT _rc EQUAL 0)
  message(FATAL_ERROR "configuring the fixture failed:\n${_out}")
endif()

function(build out_rc out_text)
  # Not the flags of a make that runs ctest (`make test`): -k, -n or a jobserver would leak in.
  execute_process(COMMAND "${CMAKE_COMMAND}" -E env --unset=MAKEFLAGS --unset=MFLAGS
                          --unset=MAKELEVEL "${CMAKE_COMMAND}" --build "${_build}"
                  RESULT_VARIABLE _rc OUTPUT_VARIABLE _out ERROR_VARIABLE _out)
  set(${out_rc} ${_rc} PARENT_SCOPE)
  set(${out_text} "${_out}" PARENT_SCOPE)
endfunction()

set(_failures "")

# The fixture as written follows the rules (including a domain plug-in on top of the generic
# modules and one secure_allow_include exception).
build(_rc _out)
if(NOT _rc EQUAL 0)
  message(FATAL_ERROR "the clean fixture must build:\n${_out}")
endif()
if(NOT _out MATCHES "Checking includes of secure_cbf")
  message(FATAL_ERROR "the build did not run the include checks:\n${_out}")
endif()
# Cheap: nothing changed, so no check runs again.
build(_rc _out)
if(NOT _rc EQUAL 0 OR _out MATCHES "Checking includes")
  message(FATAL_ERROR "an up-to-date build re-ran the include checks (rc ${_rc}):\n${_out}")
endif()
message(STATUS "clean fixture: builds, and an up-to-date build re-runs no check")

# plant(<name> <file> <include line> <expected output regex>)
function(plant name file line expected)
  set(_problem "")
  set(_path "${_src}/${file}")
  file(READ "${_path}" _original)
  file(APPEND "${_path}" "${line}\n")
  build(_rc _out)
  file(WRITE "${_path}" "${_original}")
  if(_rc EQUAL 0)
    set(_problem "the build passed")
  elseif(NOT _out MATCHES "${expected}")
    set(_problem "the build failed, but its output does not match\n  ${expected}")
  endif()
  if(_problem)
    message(NOTICE "FAIL ${name}: ${file} with ${line}: ${_problem}\n--- build output:\n${_out}---")
    set(_failures "${_failures} ${name}" PARENT_SCOPE)
    return()
  endif()
  string(REGEX MATCH "${expected}[^\n]*" _line "${_out}")
  message(STATUS "${name}: ${_line}")
endfunction()

# Generic code including a domain plug-in.
plant(cbf_includes_domain secure/cbf/barrier.cc "#include \"domains/derby/derby.h\""
  "secure/cbf/barrier\\.cc:[0-9]+: error: #include \"domains/derby/derby\\.h\": layering: domains/derby/derby\\.h belongs to secure_domain_derby, which secure_cbf \\(owning secure/cbf/barrier\\.cc\\) does not link \\[secure_cbf\\]")
# A lower module including a higher one.
plant(nn_includes_cbf secure/nn/mlp.cc "#include \"secure/cbf/barrier.h\""
  "secure/nn/mlp\\.cc:[0-9]+: error: #include \"secure/cbf/barrier\\.h\": layering: secure/cbf/barrier\\.h belongs to secure_cbf, which secure_nn .*does not link \\[secure_nn\\]")
# The same through a header (found through the depfile: the header is no source of any target).
plant(nn_header_includes_shield secure/nn/mlp.h "#include \"secure/shield/shield.h\""
  "secure/nn/mlp\\.h:[0-9]+: error: #include \"secure/shield/shield\\.h\": layering: secure/shield/shield\\.h belongs to secure_shield, which secure_nn \\(owning secure/nn/mlp\\.h\\) does not link")
plant(shield_header_includes_domain secure/shield/shield.h "#include \"domains/derby/derby.h\""
  "secure/shield/shield\\.h:[0-9]+: error: #include \"domains/derby/derby\\.h\": layering: domains/derby/derby\\.h belongs to secure_domain_derby, which secure_shield")
# A domain plug-in including a generic module it does not link.
plant(domain_includes_unlinked domains/derby/derby.cc "#include \"secure/cbf/barrier.h\""
  "domains/derby/derby\\.cc:[0-9]+: error: #include \"secure/cbf/barrier\\.h\": layering: secure/cbf/barrier\\.h belongs to secure_cbf, which secure_domain_derby")
# The inference target including its folder's training header (owned by cbf_train via its .cc).
plant(cbf_includes_trainer secure/cbf/barrier.cc "#include \"secure/cbf/trainer.h\""
  "secure/cbf/barrier\\.cc:[0-9]+: error: #include \"secure/cbf/trainer\\.h\": layering: secure/cbf/trainer\\.h belongs to secure_cbf_train, which secure_cbf")
# LibTorch outside the targets that link it, directly and in a header.
plant(torch_in_shield secure/shield/shield.cc "#include <torch/torch.h>"
  "secure/shield/shield\\.cc:[0-9]+: error: #include <torch/torch\\.h>: torch: LibTorch headers only in targets that link Torch, and secure_shield does not")
plant(torch_in_cbf_header secure/cbf/barrier.h "#include <ATen/ATen.h>"
  "secure/cbf/barrier\\.h:[0-9]+: error: #include <ATen/ATen\\.h>: torch: LibTorch headers only in targets that link Torch, and secure_cbf")
# Another module's internal header.
plant(internal_from_shield secure/shield/shield.cc "#include \"secure/cbf/internal/impl.h\""
  "secure/shield/shield\\.cc:[0-9]+: error: #include \"secure/cbf/internal/impl\\.h\": internal: secure/cbf/internal/impl\\.h is internal to secure/cbf/ and may be included only from files under it \\[secure_shield\\]")
# A host (apps/) including a plug-in it links: the plugin rule, from a source and from a header.
plant(app_includes_plugin apps/tool/main.cc "#include \"domains/derby/derby.h\""
  "apps/tool/main\\.cc:[0-9]+: error: #include \"domains/derby/derby\\.h\": plugin: domains/derby/derby\\.h is a domain's header, and apps/ is a host: it meets domains only through the registry and their capabilities \\(secure/experiments/domain\\.h\\) \\[tool\\]")
plant(app_header_includes_plugin apps/tool/tool.h "#include \"domains/derby/derby.h\""
  "apps/tool/tool\\.h:[0-9]+: error: #include \"domains/derby/derby\\.h\": plugin: domains/derby/derby\\.h is a domain's header, and apps/ is a host")
# A file of no target (tests/).
plant(library_includes_test_helper secure/common/common.cc "#include \"tests/helper.h\""
  "secure/common/common\\.cc:[0-9]+: error: #include \"tests/helper\\.h\": layering: tests/helper\\.h belongs to no target of the project")

# Restored, the fixture builds again (a failed check leaves no stamp, so each plant's build
# re-ran it).
build(_rc _out)
if(NOT _rc EQUAL 0)
  message(FATAL_ERROR "the restored fixture does not build:\n${_out}")
endif()

if(_failures)
  message(FATAL_ERROR "the layering check missed or misreported:${_failures}")
endif()
message(STATUS "every planted wrong-way include failed the build with its rule")
