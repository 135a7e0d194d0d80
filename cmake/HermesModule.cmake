# hermes_module(NAME <lib> DIR <dir> [DEPS <targets...>] [TEST_LABEL unit|integration])
# Builds a shared library from <dir>/src/*.cc (public headers in <dir>/include),
# one executable per <dir>/tools/*.cc (named hermes_<stem>), and one GoogleTest
# executable per <dir>/test/test_*.cc (linked with <dir>/test/support/*.cc if any).
# Tests get HERMES_SOURCE_DIR; a test whose source mentions HERMES_BIN_DIR (the
# tools' folder) gets it and depends on the module's tools (the other tests
# compile alike in every build tree, so a compiler cache serves both). Tests are
# labelled TEST_LABEL: unit (default) or integration (whole-system runs).
# A tool's usage text is tools/help/hermes_<stem>.txt (HermesHelp.cmake).
# Sources are globbed, so adding a file needs no CMake edit (re-run cmake).
include(${CMAKE_CURRENT_LIST_DIR}/HermesHelp.cmake)

function(hermes_module)
  cmake_parse_arguments(M "" "NAME;DIR;TEST_LABEL" "DEPS" ${ARGN})
  if(NOT M_TEST_LABEL)
    set(M_TEST_LABEL unit)
  endif()
  file(GLOB_RECURSE srcs CONFIGURE_DEPENDS ${M_DIR}/src/*.cc)
  if(NOT srcs)  # a module that has no sources yet still yields a linkable library
    set(srcs ${CMAKE_CURRENT_BINARY_DIR}/${M_NAME}_empty.cc)
    file(WRITE ${srcs} "namespace hermes { void ${M_NAME}_empty() {} }\n")
  endif()
  add_library(${M_NAME} SHARED ${srcs})
  # Unity build (HERMES_UNITY_BUILD): the library's sources compiled in batches,
  # so the heavy headers (Eigen, OpenCV, Ceres) are parsed once a batch, not
  # once a file. Code generation is the same; a file's helpers must not clash
  # with another file's of the same library (put shared ones in a header).
  set_target_properties(${M_NAME} PROPERTIES
    UNITY_BUILD ${HERMES_UNITY_BUILD} UNITY_BUILD_BATCH_SIZE ${HERMES_UNITY_BATCH})
  target_include_directories(${M_NAME} PUBLIC
    $<BUILD_INTERFACE:${M_DIR}/include>)
  target_link_libraries(${M_NAME} PUBLIC ${M_DEPS})
  set_target_properties(${M_NAME} PROPERTIES
    LIBRARY_OUTPUT_DIRECTORY ${CMAKE_BINARY_DIR}/lib)

  file(GLOB tools CONFIGURE_DEPENDS ${M_DIR}/tools/*.cc)
  set(tool_targets "")
  foreach(tool ${tools})
    get_filename_component(stem ${tool} NAME_WE)
    add_executable(hermes_${stem} ${tool})
    list(APPEND tool_targets hermes_${stem})
    target_link_libraries(hermes_${stem} PRIVATE ${M_NAME})
    # Benchmarks find shipped files and the shared data beside the checkout.
    target_compile_definitions(hermes_${stem} PRIVATE
      HERMES_SOURCE_DIR="${CMAKE_SOURCE_DIR}"
      HERMES_DATA_DIR="${CMAKE_SOURCE_DIR}/data"
      HERMES_TRAJECTORY_DIR="${CMAKE_SOURCE_DIR}/config/trajectories")
    set_target_properties(hermes_${stem} PROPERTIES
      RUNTIME_OUTPUT_DIRECTORY ${CMAKE_BINARY_DIR}/bin)
    hermes_tool_help(hermes_${stem})
  endforeach()

  if(HERMES_BUILD_TESTS)
    file(GLOB support CONFIGURE_DEPENDS ${M_DIR}/test/support/*.cc)
    if(support)
      add_library(${M_NAME}_testsupport STATIC ${support})
      target_include_directories(${M_NAME}_testsupport PUBLIC ${M_DIR}/test/support)
      target_link_libraries(${M_NAME}_testsupport PUBLIC ${M_NAME} GTest::gtest)
      target_compile_definitions(${M_NAME}_testsupport PRIVATE
        HERMES_SOURCE_DIR="${CMAKE_SOURCE_DIR}"
        HERMES_DATA_DIR="${CMAKE_SOURCE_DIR}/data"
      HERMES_TRAJECTORY_DIR="${CMAKE_SOURCE_DIR}/config/trajectories")
    endif()
    file(GLOB tests CONFIGURE_DEPENDS ${M_DIR}/test/test_*.cc)
    foreach(t ${tests})
      get_filename_component(stem ${t} NAME_WE)
      set(exe ${M_NAME}_${stem})
      add_executable(${exe} ${t})
      target_link_libraries(${exe} PRIVATE ${M_NAME} GTest::gtest_main)
      if(support)
        target_link_libraries(${exe} PRIVATE ${M_NAME}_testsupport)
      endif()
      target_compile_definitions(${exe} PRIVATE
        HERMES_SOURCE_DIR="${CMAKE_SOURCE_DIR}"
        HERMES_DATA_DIR="${CMAKE_SOURCE_DIR}/data"
        HERMES_TRAJECTORY_DIR="${CMAKE_SOURCE_DIR}/config/trajectories")
      # A test that runs the module's tools (it names HERMES_BIN_DIR) needs them built.
      file(READ ${t} body)
      if(body MATCHES "HERMES_BIN_DIR")
        target_compile_definitions(${exe} PRIVATE HERMES_BIN_DIR="${CMAKE_BINARY_DIR}/bin")
        if(tool_targets)
          add_dependencies(${exe} ${tool_targets})
        endif()
      endif()
      set_target_properties(${exe} PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${CMAKE_BINARY_DIR}/test_bin)
      gtest_discover_tests(${exe} TEST_PREFIX "${M_NAME}." DISCOVERY_TIMEOUT 60
        PROPERTIES LABELS "${M_TEST_LABEL}")
    endforeach()
  endif()
endfunction()
