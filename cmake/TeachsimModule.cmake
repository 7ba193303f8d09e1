# Shared build settings and the one function that declares a module.

add_library(teachsim_options INTERFACE)
target_compile_options(teachsim_options INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor -Wno-missing-field-initializers
  $<$<BOOL:${TEACHSIM_WERROR}>:-Werror>
  # GCC 12's -Wrestrict fires on std::string concatenation at -O3 (GCC bug 105329, a false positive).
  $<$<CXX_COMPILER_ID:GNU>:-Wno-restrict>)
if(TEACHSIM_SANITIZE)
  target_compile_options(teachsim_options INTERFACE
    -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=all)
  target_link_options(teachsim_options INTERFACE -fsanitize=address,undefined)
endif()

# teachsim_module(NAME [DEPS public-deps...] [PRIVATE_DEPS private-deps...])
#
# Builds src/NAME/*.cc into teachsim::NAME, with src/NAME/include as its public include folder,
# src/NAME/tests/*_test.cc into the test executable NAME_tests (registered with ctest), and
# src/NAME/bench/*.cc into NAME_bench.
function(teachsim_module name)
  cmake_parse_arguments(M "" "" "DEPS;PRIVATE_DEPS;TEST_DEPS;BENCH_DEPS" ${ARGN})
  set(target teachsim_${name})
  file(GLOB srcs CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/*.cc)
  if(srcs)
    add_library(${target} STATIC ${srcs})
    target_include_directories(${target} PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/include)
    target_link_libraries(${target} PUBLIC ${M_DEPS} teachsim_options PRIVATE ${M_PRIVATE_DEPS})
  else()
    add_library(${target} INTERFACE)
    target_include_directories(${target} INTERFACE ${CMAKE_CURRENT_SOURCE_DIR}/include)
    target_link_libraries(${target} INTERFACE ${M_DEPS} teachsim_options)
  endif()
  add_library(teachsim::${name} ALIAS ${target})

  file(GLOB tests CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/tests/*_test.cc)
  if(TEACHSIM_BUILD_TESTS AND tests)
    add_executable(${name}_tests ${tests})
    target_include_directories(${name}_tests PRIVATE ${CMAKE_CURRENT_SOURCE_DIR})
    target_link_libraries(${name}_tests PRIVATE ${target} ${M_TEST_DEPS} GTest::gtest GTest::gmock
                          GTest::gtest_main)
    target_compile_definitions(${name}_tests PRIVATE
      TEACHSIM_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
      TEACHSIM_SHARED_DIR="${PROJECT_SOURCE_DIR}/../shared")
    gtest_discover_tests(${name}_tests DISCOVERY_MODE PRE_TEST DISCOVERY_TIMEOUT 60
                         PROPERTIES LABELS ${name})
  endif()

  file(GLOB benches CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/bench/*.cc)
  if(TEACHSIM_BUILD_BENCHMARKS AND benches)
    add_library(${name}_bench OBJECT ${benches})
    target_link_libraries(${name}_bench PUBLIC ${target} ${M_BENCH_DEPS} benchmark::benchmark)
    target_include_directories(${name}_bench PRIVATE ${CMAKE_CURRENT_SOURCE_DIR})
    target_compile_definitions(${name}_bench PRIVATE TEACHSIM_BENCH_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
    set_property(GLOBAL APPEND PROPERTY TEACHSIM_BENCH_TARGETS ${name}_bench)
  endif()
endfunction()
