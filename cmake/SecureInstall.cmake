# `cmake --install <build> --prefix <prefix>`: the torch-free inference part of SECURE, for a C++
# program that embeds the shield (docs/EMBEDDING.md, examples/cpp/realtime_loop/).
#
# Installed: the static libraries of the modules below, their headers under <prefix>/include
# (the same paths as in the repository: "secure/shield/shield.h"), and the CMake package
#   <prefix>/lib/cmake/secure/secureConfig.cmake, secureConfigVersion.cmake, secureTargets*.cmake
#   and FindLibxsmm.cmake (LIBXSMM has no CMake config on Debian)
# so that a consumer does
#   find_package(secure REQUIRED)
#   target_link_libraries(app PRIVATE secure::inference)   # or secure::shield, secure::policy, ...
#
# Not installed: everything that links LibTorch (nn_torch, cbf_train, dynamics_train, policy_train, experiments
# and the domain plug-ins, which register experiments::Domain objects), MuJoCo (panda_push), the
# evaluation harness and the CLI. The exported targets carry their usage requirements
# (-march=native when SECURE_NATIVE_ARCH, EIGEN_STACK_ALLOCATION_LIMIT, C++17) to the consumer,
# so every translation unit that includes our Eigen headers agrees with the libraries.
# install(EXPORT) fails the configure if an installed target links a target outside this list;
# tests/embedding/ checks the installed files name neither Torch nor MuJoCo.
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(SECURE_INSTALL_MODULES common nn data domains cbf dynamics shield policy)

# secure::inference: everything a shielded controller needs (barrier, shield, Gaussian policy,
# a learned dynamics ensemble as the shield model).
add_library(secure_inference INTERFACE)
add_library(secure::inference ALIAS secure_inference)
target_link_libraries(secure_inference INTERFACE secure::shield secure::policy secure::dynamics)
set_target_properties(secure_inference PROPERTIES EXPORT_NAME inference)

# C++17 for the consumer too (the project sets CMAKE_CXX_STANDARD, which does not propagate).
target_compile_features(secure_common INTERFACE cxx_std_17)

set(_secure_install_targets secure_inference)
foreach(_m IN LISTS SECURE_INSTALL_MODULES)
  set_target_properties(secure_${_m} PROPERTIES EXPORT_NAME ${_m})
  list(APPEND _secure_install_targets secure_${_m})
endforeach()

# Headers: those of each installed module's folder, except the headers of other targets in the
# same folder (a header belongs to the target that compiles its .cc: secure/nn/torch_mlp.h is
# secure_nn_torch's), headers that include LibTorch, <module>/internal/ (included only by the
# module's own sources, which are compiled already) and the ones listed here.
set(_secure_install_exclude secure/nn/torch_threads.h)  # defined in torch_mlp.cc (nn_torch)
get_property(_secure_arch_targets GLOBAL PROPERTY SECURE_ARCH_TARGETS)
set(_secure_other_sources "")
foreach(_t IN LISTS _secure_arch_targets)
  if(_t IN_LIST _secure_install_targets)
    continue()
  endif()
  get_target_property(_src_dir ${_t} SOURCE_DIR)
  get_target_property(_sources ${_t} SOURCES)
  foreach(_s IN LISTS _sources)
    if(NOT _s MATCHES "^\\$<")
      get_filename_component(_abs "${_s}" ABSOLUTE BASE_DIR "${_src_dir}")
      list(APPEND _secure_other_sources "${_abs}")
    endif()
  endforeach()
endforeach()
foreach(_m IN LISTS SECURE_INSTALL_MODULES)
  file(GLOB_RECURSE _headers RELATIVE "${PROJECT_SOURCE_DIR}" "${PROJECT_SOURCE_DIR}/secure/${_m}/*.h")
  foreach(_h IN LISTS _headers)
    string(REGEX REPLACE "\\.h$" ".cc" _cc "${PROJECT_SOURCE_DIR}/${_h}")
    file(STRINGS "${PROJECT_SOURCE_DIR}/${_h}" _torch REGEX "^#include <(torch|ATen|c10)/")
    if(_h IN_LIST _secure_install_exclude OR _cc IN_LIST _secure_other_sources OR _torch OR
       _h MATCHES "/internal/")
      continue()
    endif()
    get_filename_component(_dir "${_h}" DIRECTORY)
    install(FILES "${_h}" DESTINATION "${CMAKE_INSTALL_INCLUDEDIR}/${_dir}")
  endforeach()
endforeach()

set(_secure_cmake_dir "${CMAKE_INSTALL_LIBDIR}/cmake/secure")
install(TARGETS ${_secure_install_targets} EXPORT secureTargets
        ARCHIVE DESTINATION "${CMAKE_INSTALL_LIBDIR}"
        LIBRARY DESTINATION "${CMAKE_INSTALL_LIBDIR}")
install(EXPORT secureTargets NAMESPACE secure:: DESTINATION "${_secure_cmake_dir}"
        FILE secureTargets.cmake)
configure_package_config_file("${PROJECT_SOURCE_DIR}/cmake/secureConfig.cmake.in"
                              "${PROJECT_BINARY_DIR}/install/secureConfig.cmake"
                              INSTALL_DESTINATION "${_secure_cmake_dir}")
# 0.x: a minor version may change the API.
write_basic_package_version_file("${PROJECT_BINARY_DIR}/install/secureConfigVersion.cmake"
                                 VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
install(FILES "${PROJECT_BINARY_DIR}/install/secureConfig.cmake"
              "${PROJECT_BINARY_DIR}/install/secureConfigVersion.cmake"
              "${PROJECT_SOURCE_DIR}/cmake/FindLibxsmm.cmake"
        DESTINATION "${_secure_cmake_dir}")
