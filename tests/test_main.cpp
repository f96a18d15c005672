#include <gtest/gtest.h>

#include "libbtf/core/eigen_setup.h"

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  btf::FixEigenBlocking();
  return RUN_ALL_TESTS();
}
