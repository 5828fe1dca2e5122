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
