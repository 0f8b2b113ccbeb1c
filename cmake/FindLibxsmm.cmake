# FindLibxsmm: LIBXSMM (Debian libxsmm-dev: a static library, no CMake config), the JIT small-GEMM
# kernels behind nn::InferenceMlp. Defines the imported target Libxsmm::Libxsmm.
#
# libxsmm.a calls BLAS (sgemm_, dgemm_, ...) for shapes it does not generate code for; we never
# call those entry points, but the symbols must resolve, so the target links the system BLAS
# (OpenBLAS, as for LibTorch). Not libxsmmnoblas: its dummy sgemm_ would be exported from our
# executables and could shadow the real one for LibTorch.
find_path(LIBXSMM_INCLUDE_DIR NAMES libxsmm.h)
find_library(LIBXSMM_LIBRARY NAMES libxsmm.a xsmm)
find_package(BLAS QUIET)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(Libxsmm REQUIRED_VARS LIBXSMM_LIBRARY LIBXSMM_INCLUDE_DIR
                                  BLAS_FOUND)
if(Libxsmm_FOUND AND NOT TARGET Libxsmm::Libxsmm)
  add_library(Libxsmm::Libxsmm UNKNOWN IMPORTED)
  set_target_properties(Libxsmm::Libxsmm PROPERTIES
    IMPORTED_LOCATION "${LIBXSMM_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${LIBXSMM_INCLUDE_DIR}")
  target_link_libraries(Libxsmm::Libxsmm INTERFACE ${BLAS_LIBRARIES} Threads::Threads
                        ${CMAKE_DL_LIBS} rt m)
endif()
mark_as_advanced(LIBXSMM_INCLUDE_DIR LIBXSMM_LIBRARY)
