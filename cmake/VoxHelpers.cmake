# vox_library(NAME SOURCES ... DEPS ...): library target vox_NAME, alias vox::NAME.
function(vox_library name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(vox_${name} STATIC ${ARG_SOURCES})
  # Position-independent: the libraries also link into the Python module
  # (tools/python), a shared object.
  set_target_properties(vox_${name} PROPERTIES POSITION_INDEPENDENT_CODE ON)
  add_library(vox::${name} ALIAS vox_${name})
  target_include_directories(vox_${name} PUBLIC ${PROJECT_SOURCE_DIR})
  target_compile_options(vox_${name} PRIVATE -Wall -Wextra)
  target_link_libraries(vox_${name} PUBLIC ${ARG_DEPS} PRIVATE ${ARG_PRIVATE_DEPS})
endfunction()

# vox_tool(NAME SOURCES ... DEPS ...): a command-line program.
function(vox_tool name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_compile_options(${name} PRIVATE -Wall -Wextra)
  target_link_libraries(${name} PRIVATE ${ARG_DEPS})
endfunction()

# vox_test(NAME SOURCES ... DEPS ... [LABELS ...] [TIMEOUT s]): a GoogleTest program run by CTest.
# Its main (tests/common/gtest_main.cpp) exits 77 when a test skipped and
# none failed: ctest then reports it as skipped, not passed.
function(vox_test name)
  cmake_parse_arguments(ARG "" "TIMEOUT" "SOURCES;DEPS;LABELS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_compile_options(${name} PRIVATE -Wall -Wextra)
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} GTest::gtest vox_gtest_main)
  add_test(NAME ${name} COMMAND ${name})
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 600)
  endif()
  set_tests_properties(${name} PROPERTIES TIMEOUT ${ARG_TIMEOUT} SKIP_RETURN_CODE 77)
  if(ARG_LABELS)
    set_tests_properties(${name} PROPERTIES LABELS "${ARG_LABELS}")
  endif()
endfunction()

# vox_find_openvdb_module(): puts the directory of OpenVDB's FindOpenVDB.cmake
# on CMAKE_MODULE_PATH (OpenVDB installs that module and its FindTBB,
# FindBlosc ... rather than a config file). Looked for in OpenVDB_DIR or
# VOX_OPENVDB_MODULE_DIR when given, then under OpenVDB_ROOT, CMAKE_PREFIX_PATH
# and the system prefixes in lib/<multiarch>/cmake/OpenVDB, lib64/..., lib/...
# (Debian's libopenvdb-dev: /usr/lib/x86_64-linux-gnu/cmake/OpenVDB).
function(vox_find_openvdb_module)
  set(prefixes ${OpenVDB_ROOT} $ENV{OpenVDB_ROOT} ${CMAKE_PREFIX_PATH} $ENV{CMAKE_PREFIX_PATH}
               ${CMAKE_INSTALL_PREFIX} ${CMAKE_SYSTEM_PREFIX_PATH})
  string(REPLACE ":" ";" prefixes "${prefixes}")
  set(candidates "")
  foreach(prefix IN LISTS prefixes)
    foreach(libdir lib/${CMAKE_LIBRARY_ARCHITECTURE} lib64 lib)
      list(APPEND candidates "${prefix}/${libdir}/cmake/OpenVDB")
    endforeach()
  endforeach()
  find_path(VOX_OPENVDB_MODULE_DIR FindOpenVDB.cmake
            HINTS ${OpenVDB_DIR} $ENV{OpenVDB_DIR}
            PATHS ${candidates}
            NO_DEFAULT_PATH
            DOC "the directory of OpenVDB's FindOpenVDB.cmake")
  if(NOT VOX_OPENVDB_MODULE_DIR)
    list(REMOVE_DUPLICATES candidates)
    list(JOIN candidates "\n  " looked)
    message(FATAL_ERROR "OpenVDB's FindOpenVDB.cmake not found (Debian: libopenvdb-dev). Give its "
            "directory with -DOpenVDB_DIR=... (or the OpenVDB install prefix with "
            "-DCMAKE_PREFIX_PATH=...). Looked in:\n  ${looked}")
  endif()
  list(APPEND CMAKE_MODULE_PATH "${VOX_OPENVDB_MODULE_DIR}")
  set(CMAKE_MODULE_PATH "${CMAKE_MODULE_PATH}" PARENT_SCOPE)
  message(STATUS "OpenVDB's CMake modules: ${VOX_OPENVDB_MODULE_DIR}")
endfunction()
