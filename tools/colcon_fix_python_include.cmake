# Passed to CMake with -DCMAKE_PROJECT_INCLUDE=<this file> by `make ros` (see
# ../shared/notes/ros2-from-pip.md, trap 2).
#
# The ros-jazzy-* wheels on the package index were built with the manylinux Python at
# /opt/python/cpXY-cpXY/, and that path is a literal in the INTERFACE_INCLUDE_DIRECTORIES of
# every imported `<pkg>::<pkg>__rosidl_generator_py` target (Python and numpy include dirs).
# CMake refuses imported targets with non-existent include dirs, so building a message
# package against those wheels fails at generate time.
#
# This file defers a fix-up to the end of the configure step: it walks every directory's
# imported targets and replaces /opt/python/... include entries with the include dirs of the
# Python that is building (the venv's). On a normal ROS install no target carries such a path
# and this is a no-op. Needs CMake >= 3.21 (IMPORTED_TARGETS directory property, DEFER).

cmake_minimum_required(VERSION 3.21)

if(NOT COMMAND _pose_lifter_fix_python_includes)
  function(_pose_lifter_collect_dirs dir out_var)
    set(dirs "${dir}")
    get_property(subdirs DIRECTORY "${dir}" PROPERTY SUBDIRECTORIES)
    foreach(sub IN LISTS subdirs)
      _pose_lifter_collect_dirs("${sub}" sub_dirs)
      list(APPEND dirs ${sub_dirs})
    endforeach()
    set(${out_var} "${dirs}" PARENT_SCOPE)
  endfunction()

  function(_pose_lifter_fix_python_includes)
    set(python_include "")
    set(numpy_include "")
    _pose_lifter_collect_dirs("${CMAKE_SOURCE_DIR}" all_dirs)
    set(n_fixed 0)
    foreach(dir IN LISTS all_dirs)
      get_property(targets DIRECTORY "${dir}" PROPERTY IMPORTED_TARGETS)
      foreach(target IN LISTS targets)
        get_target_property(includes ${target} INTERFACE_INCLUDE_DIRECTORIES)
        if(NOT includes OR NOT includes MATCHES "^/opt/python/|;/opt/python/")
          continue()
        endif()
        if(python_include STREQUAL "")
          # Resolved lazily: only builds that hit the problem look for Python and numpy.
          find_package(Python3 REQUIRED COMPONENTS Interpreter Development NumPy)
          set(python_include "${Python3_INCLUDE_DIRS}")
          set(numpy_include "${Python3_NumPy_INCLUDE_DIRS}")
        endif()
        set(fixed "")
        foreach(inc IN LISTS includes)
          if(inc MATCHES "^/opt/python/.*/numpy/")
            list(APPEND fixed ${numpy_include})
          elseif(inc MATCHES "^/opt/python/")
            list(APPEND fixed ${python_include})
          else()
            list(APPEND fixed "${inc}")
          endif()
        endforeach()
        list(REMOVE_DUPLICATES fixed)
        set_target_properties(${target} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${fixed}")
        math(EXPR n_fixed "${n_fixed} + 1")
      endforeach()
    endforeach()
    if(n_fixed GREATER 0)
      message(STATUS "pose_lifter: replaced /opt/python include dirs of ${n_fixed} imported "
                     "targets with ${python_include};${numpy_include}")
    endif()
  endfunction()
endif()

# CMAKE_PROJECT_INCLUDE runs after every project() call; defer once, in the top directory.
if(CMAKE_CURRENT_SOURCE_DIR STREQUAL CMAKE_SOURCE_DIR)
  get_property(_pose_lifter_deferred GLOBAL PROPERTY _POSE_LIFTER_FIX_DEFERRED)
  if(NOT _pose_lifter_deferred)
    set_property(GLOBAL PROPERTY _POSE_LIFTER_FIX_DEFERRED TRUE)
    cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}" CALL _pose_lifter_fix_python_includes)
  endif()
endif()
