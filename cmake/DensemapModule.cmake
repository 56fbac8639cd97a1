# densemap_add_module(NAME SOURCES ... DEPS ... [PRIVATE_DEPS ...])
# One static library per core concept: public headers in include/densemap/<module>/, the rest
# in src/. Target name densemap_<NAME>, alias densemap::<NAME>.
function(densemap_add_module name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(densemap_${name} STATIC ${ARG_SOURCES})
  add_library(densemap::${name} ALIAS densemap_${name})
  target_include_directories(densemap_${name}
                             PUBLIC $<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include>
                             PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/src)
  target_link_libraries(densemap_${name} PUBLIC ${ARG_DEPS} densemap_options
                                         PRIVATE ${ARG_PRIVATE_DEPS})
endfunction()

# densemap_add_test(NAME SOURCES ... DEPS ... LABELS ...)
function(densemap_add_test name)
  cmake_parse_arguments(ARG "" "" "SOURCES;DEPS;LABELS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  target_link_libraries(${name} PRIVATE ${ARG_DEPS} densemap_test_support GTest::gtest_main)
  # Tests name only the option fields they set ({.resolution_m = 0.2, .threads = 2}): the rest
  # keep their defaults on purpose, so GCC's warning for each unnamed field is noise there.
  target_compile_options(${name} PRIVATE -Wno-missing-field-initializers)
  gtest_discover_tests(${name} PROPERTIES LABELS "${ARG_LABELS}"
                       ENVIRONMENT "DENSEMAP_DATA_DIR=${DENSEMAP_DATA_DIR}"
                       DISCOVERY_TIMEOUT 60)
endfunction()
