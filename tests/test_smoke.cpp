#include <gtest/gtest.h>
#include "mesh/icosphere.hpp"
TEST(Smoke, Icosphere) { EXPECT_EQ(trbc::icosphere(2).numVertices(), 162); }
