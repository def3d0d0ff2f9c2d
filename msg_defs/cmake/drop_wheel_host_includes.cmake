# The PyPI ROS 2 wheels export *__rosidl_generator_py targets whose include path points
# at the wheel build host (/opt/python/...). cmake refuses to generate with a missing
# include directory, so after configuring we drop those entries from imported targets.
function(clothfold_drop_wheel_host_includes)
  get_directory_property(_targets DIRECTORY ${CMAKE_SOURCE_DIR} IMPORTED_TARGETS)
  foreach(_t IN LISTS _targets)
    get_target_property(_inc ${_t} INTERFACE_INCLUDE_DIRECTORIES)
    if(_inc)
      list(FILTER _inc EXCLUDE REGEX "^/opt/python/")
      set_target_properties(${_t} PROPERTIES INTERFACE_INCLUDE_DIRECTORIES "${_inc}")
    endif()
  endforeach()
endfunction()
cmake_language(DEFER DIRECTORY ${CMAKE_SOURCE_DIR} CALL clothfold_drop_wheel_host_includes)
