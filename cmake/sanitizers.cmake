# Sanitizer and fuzzing builds, off in the normal build:
#   SWARF_SANITIZE=ON  ASan + UBSan on everything (make test-sanitize)
#   SWARF_FUZZ=ON      clang only: the libFuzzer targets of tests/fuzz, with
#                      everything instrumented for coverage, ASan and UBSan
#                      (make fuzz, and the short fuzz runs of make test)
# The system libraries (gRPC, protobuf, absl) stay uninstrumented.
option(SWARF_SANITIZE "Build everything with ASan and UBSan" OFF)
option(SWARF_FUZZ "Build the libFuzzer targets (clang-14); implies ASan+UBSan"
       OFF)

set(swarf_sanitize ${SWARF_SANITIZE})
if(SWARF_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    message(FATAL_ERROR "SWARF_FUZZ needs clang with libFuzzer: configure "
                        "with -DCMAKE_CXX_COMPILER=clang++-14")
  endif()
  set(swarf_sanitize ON)
  # Coverage feedback from every target; -fsanitize=fuzzer (libFuzzer's
  # main) is linked into the fuzz targets only (tests/fuzz).
  add_compile_options(-fsanitize=fuzzer-no-link)
endif()

if(swarf_sanitize)
  # Any report fails the run (no recovery), with usable stack traces.
  add_compile_options(-fsanitize=address,undefined -fno-sanitize-recover=all
                      -fno-omit-frame-pointer)
  add_link_options(-fsanitize=address,undefined)
  if(CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
    # The omp simd loops are not vectorized under ASan: not an error here.
    add_compile_options(-Wno-pass-failed)
  else()
    # Not part of GCC's "undefined" (it is of clang's): a double converted
    # to an integer it does not fit, NaN included.
    add_compile_options(-fsanitize=float-cast-overflow)
    add_link_options(-fsanitize=float-cast-overflow)
    # The instrumentation makes GCC see uninitialized values that are not
    # (std::function in <regex>).
    add_compile_options(-Wno-maybe-uninitialized)
  endif()
endif()

# Clang 14 emits target_clones' ifunc under a suffixed name that callers in
# other files can't link against: clang builds keep the default clone only
# (core/cutter/ball_sweep.cc).
if(CMAKE_CXX_COMPILER_ID STREQUAL "Clang")
  add_compile_definitions(SWARF_NO_TARGET_CLONES)
endif()
