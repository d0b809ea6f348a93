// The header lookup of the CSV records (core/csv.hpp) that the report and the calibrated cell read
// posterior_stats.csv with.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "core/csv.hpp"

namespace trbc {
namespace {

TEST(CsvRecords, ColumnOfAHeader) {
    const std::vector<std::vector<std::string>> rows = parseCsvRecords("# provenance\nposterior,parameter,\"mean\"\ntheta_new,v,0.94\n");
    ASSERT_EQ(rows.size(), 2u);
    EXPECT_EQ(columnOf(rows[0], "posterior"), 0);
    EXPECT_EQ(columnOf(rows[0], "mean"), 2);
    EXPECT_EQ(columnOf(rows[0], "sd"), -1);
    EXPECT_EQ(columnOf({}, "mean"), -1);
    EXPECT_EQ(columnOf({"a", "b", "a"}, "a"), 0);  // the first of repeated names
}

}  // namespace
}  // namespace trbc
