# Workaround for the ROS 2 PyPI wheels (docs/install.md, "The ROS 2 wheels from PyPI"): their
# exported cmake targets list include directories of the machine that built them (for example
# /opt/python/cp311-cp311/include/python3.11), which makes cmake's generate step fail. Drop every
# INTERFACE_INCLUDE_DIRECTORIES entry of an imported target that does not exist here; generator
# expressions are kept untouched. On a stock ROS install every entry exists, so this is a no-op.
function(tsk_drop_missing_include_dirs)
  get_directory_property(_imported_targets IMPORTED_TARGETS)
  foreach(_target IN LISTS _imported_targets)
    get_target_property(_dirs ${_target} INTERFACE_INCLUDE_DIRECTORIES)
    if(NOT _dirs)
      continue()
    endif()
    set(_kept "")
    set(_changed FALSE)
    foreach(_dir IN LISTS _dirs)
      # Keep generator expressions (also the pieces of one split at a ';') and existing paths.
      if(_dir MATCHES "\\$<" OR _dir MATCHES ">$" OR EXISTS "${_dir}")
        list(APPEND _kept "${_dir}")
      else()
        set(_changed TRUE)
        message(STATUS "Dropping missing include directory '${_dir}' of ${_target}")
      endif()
    endforeach()
    if(_changed)
      set_target_properties(${_target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_kept}")
    endif()
  endforeach()
endfunction()

# The development setup keeps its Python venv inside the repository (.venv), so the numpy include
# directory that rosidl_generator_py puts on its target lies inside the source tree, which cmake
# refuses in an exported target's interface. Such entries are only needed to build here: keep them
# for the build interface alone. No-op when no entry is inside the source tree (a workspace).
function(tsk_source_tree_includes_build_only target)
  get_target_property(_dirs ${target} INTERFACE_INCLUDE_DIRECTORIES)
  if(NOT _dirs)
    return()
  endif()
  set(_kept "")
  foreach(_dir IN LISTS _dirs)
    if(NOT _dir MATCHES "\\$<" AND _dir MATCHES "^${CMAKE_CURRENT_SOURCE_DIR}/")
      list(APPEND _kept "$<BUILD_INTERFACE:${_dir}>")
    else()
      list(APPEND _kept "${_dir}")
    endif()
  endforeach()
  set_target_properties(${target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_kept}")
endfunction()
