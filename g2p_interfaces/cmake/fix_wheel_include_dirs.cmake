# The ROS 2 wheels on PyPI export CMake targets (<pkg>::<pkg>__rosidl_generator_py, ...) whose
# INTERFACE_INCLUDE_DIRECTORIES name the Python and NumPy include directories of the container the
# wheels were built in (/opt/python/cp311-cp311/...). CMake refuses targets with missing include
# directories, so replace each missing one by this machine's Python or NumPy include directory.
# On an apt ROS install every directory exists and nothing changes.
find_package(Python3 REQUIRED COMPONENTS Interpreter Development NumPy)

function(g2p_fix_include_dirs target)
  get_target_property(_dirs ${target} INTERFACE_INCLUDE_DIRECTORIES)
  if(NOT _dirs)
    return()
  endif()
  set(_fixed "")
  set(_changed FALSE)
  foreach(_dir IN LISTS _dirs)
    if(_dir MATCHES "^\\$<" OR EXISTS "${_dir}")
      list(APPEND _fixed "${_dir}")
    elseif(_dir MATCHES "numpy")
      list(APPEND _fixed ${Python3_NumPy_INCLUDE_DIRS})
      set(_changed TRUE)
    else()
      list(APPEND _fixed ${Python3_INCLUDE_DIRS})
      set(_changed TRUE)
    endif()
  endforeach()
  if(_changed)
    list(REMOVE_DUPLICATES _fixed)
    set_target_properties(${target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_fixed}")
  endif()
endfunction()

# Imported targets are only visible in the directory that found them: fix them now, after the
# find_package calls above, and again for targets rosidl finds later via a deferred call.
function(g2p_fix_all_imported_targets)
  get_directory_property(_targets IMPORTED_TARGETS)
  foreach(_target IN LISTS _targets)
    g2p_fix_include_dirs(${_target})
  endforeach()
endfunction()

g2p_fix_all_imported_targets()
cmake_language(DEFER CALL g2p_fix_all_imported_targets)
