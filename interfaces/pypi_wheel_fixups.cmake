# Included into every interface package's project() by scripts/build_interfaces.sh (CMAKE_PROJECT_INCLUDE).
#
# The ROS 2 Jazzy wheels on PyPI were built in a manylinux container, and the CMake target exports of their
# Python message libraries (e.g. geometry_msgs::geometry_msgs__rosidl_generator_py) still name that container's
# include directories (/opt/python/cp311-cp311/include/python3.11 and its numpy include). CMake refuses to
# generate when an imported target names an include directory that does not exist. The libraries themselves are
# fine and the dependent targets add this interpreter's Python and NumPy include directories themselves, so at
# the end of configuration drop such non-existent absolute include directories from all imported targets.
cmake_minimum_required(VERSION 3.21)  # IMPORTED_TARGETS directory property

function(_lightfast_drop_missing_include_dirs)
  get_directory_property(_targets DIRECTORY "${CMAKE_SOURCE_DIR}" IMPORTED_TARGETS)
  foreach(_target IN LISTS _targets)
    get_target_property(_dirs ${_target} INTERFACE_INCLUDE_DIRECTORIES)
    if(NOT _dirs)
      continue()
    endif()
    set(_kept "")
    set(_dropped "")
    foreach(_dir IN LISTS _dirs)
      if(IS_ABSOLUTE "${_dir}" AND NOT _dir MATCHES "\\$<" AND NOT EXISTS "${_dir}")
        list(APPEND _dropped "${_dir}")
      else()
        list(APPEND _kept "${_dir}")
      endif()
    endforeach()
    if(_dropped)
      message(STATUS "lightfast: ${_target}: dropping missing include dirs ${_dropped}")
      set_target_properties(${_target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_kept}")
    endif()
  endforeach()
endfunction()

cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}" CALL _lightfast_drop_missing_include_dirs)
