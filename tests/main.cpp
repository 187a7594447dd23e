// Test main: Debug builds trap floating-point exceptions (invalid, divide-by-zero,
// overflow) so that a NaN is caught where it is born (STYLE 9, libigl tests/main.cpp).
#include <gtest/gtest.h>

#ifndef NDEBUG
#include <cfenv>
#endif

int main(int argc, char** argv) {
#if !defined(NDEBUG) && defined(__GLIBC__)
  feenableexcept(FE_INVALID | FE_DIVBYZERO | FE_OVERFLOW);
#endif
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
