# Cutting-mark tests (issue 3), included from tests/CMakeLists.txt.
add_executable(cutting_marks_test cutting_marks_test.cc)
target_link_libraries(cutting_marks_test swarf_core GTest::gtest_main)
gtest_discover_tests(cutting_marks_test)
