# Needed only when building against the ROS 2 Jazzy wheels from PyPI (the `.venv` of
# scripts/bootstrap.sh): their exported *__rosidl_generator_py targets carry an include
# directory of the wheel build host (/opt/python/cp311-cp311/include/python3.11), and cmake
# refuses to generate when an imported target names a directory that does not exist.
# At the end of configuring, this drops such entries: only those that match ^/opt/python/
# AND do not exist on this machine. On a real ROS install (/opt/ros/jazzy) no imported
# target has such an entry, so nothing changes. CMakeLists.txt includes it; bootstrap.sh
# also passes it as CMAKE_PROJECT_INCLUDE (the include guard makes that harmless).
include_guard(GLOBAL)
function(clothfold_drop_wheel_host_includes)
  get_directory_property(_targets DIRECTORY ${CMAKE_SOURCE_DIR} IMPORTED_TARGETS)
  foreach(_t IN LISTS _targets)
    get_target_property(_inc ${_t} INTERFACE_INCLUDE_DIRECTORIES)
    if(_inc)
      set(_kept "")
      set(_dropped FALSE)
      foreach(_dir IN LISTS _inc)
        if(_dir MATCHES "^/opt/python/" AND NOT EXISTS "${_dir}")
          set(_dropped TRUE)
        else()
          list(APPEND _kept "${_dir}")
        endif()
      endforeach()
      if(_dropped)
        set_target_properties(${_t} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_kept}")
      endif()
    endif()
  endforeach()
endfunction()
cmake_language(DEFER DIRECTORY ${CMAKE_SOURCE_DIR} CALL clothfold_drop_wheel_host_includes)
