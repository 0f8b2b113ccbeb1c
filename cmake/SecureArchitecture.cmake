# The module layering of docs/ARCHITECTURE.md ("Modules and targets"), enforced by the build.
#
# Every project target registered here (secure_add_library / secure_add_domain register theirs;
# secure_check_includes(<target>) registers any other, e.g. the CLI) gets a check that runs
# before its sources compile and fails the build on an include that breaks one of these rules,
# all derived from the CMake link graph, so they follow the targets as they change:
#
#   layering  A file may include a header of this repository only if the header belongs to its
#             own target or to a target it links (transitively, through PUBLIC/INTERFACE links;
#             its own PRIVATE links count for its own sources). A header belongs to the target
#             that compiles its .cc (secure/cbf/barrier_trainer.h -> secure_cbf_train), otherwise
#             to the targets of the nearest folder holding a target (secure/nn/torch_threads.h ->
#             secure_nn, secure_nn_torch). A header in no target's folder (tests/, bench/) may not
#             be included at all. A header is checked both as a file of its own target and as a
#             file compiled into each target that reaches it (a public header must not include
#             its target's PRIVATE dependencies).
#   internal  A header under <module>/internal/ may be included only from files under <module>/.
#   torch     <torch/...>, <ATen/...> and <c10/...> only from files of targets that link Torch
#             (any item of TORCH_LIBRARIES, transitively).
#   plugin    A file under a host folder (SECURE_ARCH_HOST_FOLDERS: apps/, the CLI) includes no
#             header under domains/ (a plug-in, or the Franka arm the plug-ins share) nor under
#             the folder of a plug-in outside it (secure_add_domain: examples/toy_domain/), although
#             it links them all through secure::plugins: a host meets a domain only through the
#             registry and the capabilities a domain offers (secure/experiments/domain.h).
#
# The check (cmake/check_includes.cmake, run with `cmake -P`: no new dependency) follows the
# includes from the target's sources through every header of the repository they reach. It
# writes a stamp and a depfile listing every file it read, so it re-runs only when one of those
# files, the link graph or the checker changes. A violation fails the build with
#   <file>:<line>: error: #include "<header>": <rule>: <why> [<target>]
# `cmake --build build --target check_includes` runs every check; ctest -L architecture proves
# they catch planted wrong-way includes (tests/architecture/).
#
# An include the rules reject but the design needs is allowed explicitly, with the reason:
#   secure_allow_include(<target> <header> REASON "<why>")
# (header as included, e.g. secure/cbf/internal/x.h). Keep such exceptions few; each is listed in
# the configure log.

set_property(GLOBAL PROPERTY SECURE_ARCH_TARGETS "")
# The host folders of the plugin rule: their files may include no domains/<name>/ header.
set(SECURE_ARCH_HOST_FOLDERS apps CACHE INTERNAL
    "folders whose files may not include a domain plug-in's header (cmake/SecureArchitecture.cmake)")
set(SECURE_ARCH_CHECKER "${CMAKE_CURRENT_LIST_DIR}/check_includes.cmake" CACHE INTERNAL "")

# secure_check_includes(<target>): check <target>'s includes (library targets made by
# secure_add_library and secure_add_domain are registered already).
function(secure_check_includes target)
  get_target_property(_aliased ${target} ALIASED_TARGET)
  if(_aliased)
    set(target ${_aliased})
  endif()
  set_property(GLOBAL APPEND PROPERTY SECURE_ARCH_TARGETS ${target})
endfunction()

# secure_allow_include(<target> <header> REASON <why>)
function(secure_allow_include target header)
  cmake_parse_arguments(ARG "" "REASON" "" ${ARGN})
  if(NOT ARG_REASON)
    message(FATAL_ERROR "secure_allow_include(${target} ${header}): give the REASON")
  endif()
  get_target_property(_aliased ${target} ALIASED_TARGET)
  if(_aliased)
    set(target ${_aliased})
  endif()
  set_property(TARGET ${target} APPEND PROPERTY SECURE_ALLOWED_INCLUDES ${header})
  message(STATUS "architecture: ${target} may include ${header}: ${ARG_REASON}")
endfunction()

# The link items of <item> (a target) whose include directories a consumer sees, as resolved
# target names or plain items. $<LINK_ONLY:...> (a static library's PRIVATE links) is skipped.
function(_secure_arch_links item property out)
  set(_result "")
  if(TARGET "${item}")
    get_target_property(_links "${item}" ${property})
    if(_links)
      foreach(_link IN LISTS _links)
        if(_link MATCHES "^\\$<LINK_ONLY:")
          continue()
        elseif(_link MATCHES "^\\$<BUILD_INTERFACE:(.*)>$")
          set(_link "${CMAKE_MATCH_1}")
        elseif(_link MATCHES "^\\$<")
          continue()  # other generator expressions: not resolvable here
        endif()
        if(TARGET "${_link}")
          get_target_property(_aliased "${_link}" ALIASED_TARGET)
          if(_aliased)
            set(_link "${_aliased}")
          endif()
        endif()
        list(APPEND _result "${_link}")
      endforeach()
    endif()
  endif()
  set(${out} "${_result}" PARENT_SCOPE)
endfunction()

# Writes <binary dir>/architecture/graph.cmake and adds the check targets. Runs once, deferred to
# the end of the top-level CMakeLists.txt, when every target and link is known.
function(_secure_arch_generate)
  get_property(_targets GLOBAL PROPERTY SECURE_ARCH_TARGETS)
  list(REMOVE_DUPLICATES _targets)
  set(_root "${PROJECT_SOURCE_DIR}")
  set(_dir "${PROJECT_BINARY_DIR}/architecture")
  set(_torch_items ${TORCH_LIBRARIES})
  list(TRANSFORM _torch_items REPLACE "^\\$<.*>$" "")
  list(REMOVE_ITEM _torch_items "")

  set(_graph "# Generated by cmake/SecureArchitecture.cmake: the project's targets and links.\n")
  string(APPEND _graph "set(ARCH_ROOT \"${_root}\")\nset(ARCH_BINARY_DIR \"${PROJECT_BINARY_DIR}\")\n")
  string(APPEND _graph "set(ARCH_TARGETS \"${_targets}\")\n")
  string(APPEND _graph "set(ARCH_HOST_FOLDERS \"${SECURE_ARCH_HOST_FOLDERS}\")\n")
  set(_folders "")
  foreach(_t IN LISTS _targets)
    # Folder: where the target is defined, relative to the repository.
    get_target_property(_src_dir ${_t} SOURCE_DIR)
    file(RELATIVE_PATH _folder "${_root}" "${_src_dir}")
    list(APPEND _folders "${_folder}")
    list(APPEND _folder_targets_${_folder} ${_t})

    # Sources in the repository (generated ones under the build tree are skipped).
    get_target_property(_sources ${_t} SOURCES)
    set(_rel_sources "")
    set(_abs_sources "")
    foreach(_s IN LISTS _sources)
      if(_s MATCHES "^\\$<")
        continue()
      endif()
      get_filename_component(_abs "${_s}" ABSOLUTE BASE_DIR "${_src_dir}")
      file(RELATIVE_PATH _rel "${_root}" "${_abs}")
      string(FIND "${_abs}/" "${PROJECT_BINARY_DIR}/" _in_build)
      if(_rel MATCHES "^\\.\\./" OR _in_build EQUAL 0)
        continue()
      endif()
      list(APPEND _rel_sources "${_rel}")
      list(APPEND _abs_sources "${_abs}")
      string(APPEND _graph "list(APPEND ARCH_SRC_${_rel} ${_t})\n")
    endforeach()
    set(_abs_sources_${_t} "${_abs_sources}")

    # Include-visible links, transitively: the target's own links (PUBLIC and PRIVATE), then
    # each linked target's INTERFACE links.
    _secure_arch_links(${_t} LINK_LIBRARIES _queue)
    set(_seen "")
    while(_queue)
      list(POP_FRONT _queue _item)
      if(_item IN_LIST _seen)
        continue()
      endif()
      list(APPEND _seen "${_item}")
      _secure_arch_links("${_item}" INTERFACE_LINK_LIBRARIES _more)
      list(APPEND _queue ${_more})
    endwhile()
    set(_allowed ${_t})
    set(_torch 0)
    foreach(_item IN LISTS _seen)
      if(_item IN_LIST _targets)
        list(APPEND _allowed ${_item})
      endif()
      if(_item IN_LIST _torch_items)
        set(_torch 1)
      endif()
    endforeach()
    get_target_property(_exceptions ${_t} SECURE_ALLOWED_INCLUDES)
    if(NOT _exceptions)
      set(_exceptions "")
    endif()
    string(APPEND _graph "set(ARCH_FOLDER_OF_${_t} \"${_folder}\")\n"
                         "set(ARCH_SOURCES_${_t} \"${_rel_sources}\")\n"
                         "set(ARCH_ALLOWED_${_t} \"${_allowed}\")\n"
                         "set(ARCH_TORCH_${_t} ${_torch})\n"
                         "set(ARCH_EXCEPTIONS_${_t} \"${_exceptions}\")\n")
  endforeach()
  list(REMOVE_DUPLICATES _folders)
  # The plugin rule's folders: domains/ and every plug-in's own (secure_domain_<name>).
  set(_plugin_folders domains)
  foreach(_t IN LISTS _targets)
    if(_t MATCHES "^secure_domain_")
      get_target_property(_src_dir ${_t} SOURCE_DIR)
      file(RELATIVE_PATH _folder "${_root}" "${_src_dir}")
      list(APPEND _plugin_folders "${_folder}")
    endif()
  endforeach()
  list(REMOVE_DUPLICATES _plugin_folders)
  string(APPEND _graph "set(ARCH_PLUGIN_FOLDERS \"${_plugin_folders}\")\n")
  foreach(_folder IN LISTS _folders)
    string(APPEND _graph "set(ARCH_FOLDER_${_folder} \"${_folder_targets_${_folder}}\")\n")
  endforeach()
  # Rewritten only when the graph changes, so the checks do not re-run after every configure.
  file(CONFIGURE OUTPUT "${_dir}/graph.cmake" CONTENT "${_graph}" @ONLY)

  if(NOT TARGET check_includes)
    add_custom_target(check_includes)
  endif()
  foreach(_t IN LISTS _targets)
    set(_stamp "${_dir}/${_t}.stamp")
    add_custom_command(
      OUTPUT "${_stamp}"
      COMMAND "${CMAKE_COMMAND}" "-DGRAPH=${_dir}/graph.cmake" "-DCHECK_TARGETS=${_t}"
              "-DSTAMP=${_stamp}" "-DDEPFILE=${_dir}/${_t}.d" -P "${SECURE_ARCH_CHECKER}"
      DEPENDS "${SECURE_ARCH_CHECKER}" "${_dir}/graph.cmake" ${_abs_sources_${_t}}
      DEPFILE "${_dir}/${_t}.d"
      COMMENT "Checking includes of ${_t} (docs/ARCHITECTURE.md)"
      VERBATIM)
    add_custom_target(${_t}_includes DEPENDS "${_stamp}")
    add_dependencies(${_t} ${_t}_includes)
    add_dependencies(check_includes ${_t}_includes)
  endforeach()
endfunction()

# Once per configure, at the end of the top-level directory (after every add_subdirectory).
get_property(_secure_arch_deferred GLOBAL PROPERTY SECURE_ARCH_DEFERRED)
if(NOT _secure_arch_deferred)
  set_property(GLOBAL PROPERTY SECURE_ARCH_DEFERRED 1)
  cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}" CALL _secure_arch_generate)
endif()
