// The header lookup of the CSV records (core/csv.hpp) that the report and the calibrated cell read
// posterior_stats.csv with.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "core/csv.hpp"
#include "core/error.hpp"
#include "test_support.hpp"

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

// A blank field is a missing measurement (NaN) only in the columns that allow it; elsewhere the error
// names the file, the line and the column.
TEST(NumericTable, BlankFieldsOnlyWhereAllowed) {
    test::TempDir dir;
    const auto file = test::writeText(dir.path() / "donors.csv", "# provenance\nrate,a1,a2,note\n1.5,,12.0,x\n\n2.5,11.0,,y\n");
    const NumericTable t = readNumericTable(file, {"rate", "a1", "a2"}, {"a1", "a2"});
    ASSERT_EQ(t.values.rows(), 2);
    EXPECT_EQ(t.lines, (std::vector<long>{3, 5}));
    EXPECT_TRUE(std::isnan(t.values(0, 1)));
    EXPECT_EQ(t.values(0, 2), 12.0);
    EXPECT_EQ(t.values(1, 1), 11.0);
    EXPECT_TRUE(std::isnan(t.values(1, 3)));  // not a numeric column: ignored
    try {
        readNumericTable(file, {"rate", "a1", "a2"}, {"a1"});
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("donors.csv:5: column 'a2': '' is not a finite number"), std::string::npos) << e.what();
    }
}

// The list splitter of the CLI options, data-set lists and header lines.
TEST(SplitList, ItemsTrimmedAndEmptyItemsKept) {
    EXPECT_EQ(splitList("a, b,,c,"), (std::vector<std::string>{"a", "b", "", "c", ""}));
    EXPECT_EQ(splitList(""), (std::vector<std::string>{""}));
    EXPECT_EQ(splitList(" \t "), (std::vector<std::string>{""}));
    EXPECT_EQ(splitList("x\r"), (std::vector<std::string>{"x"}));
    EXPECT_EQ(splitList(" one item "), (std::vector<std::string>{"one item"}));
    EXPECT_EQ(splitList("1;2", ';'), (std::vector<std::string>{"1", "2"}));
    EXPECT_EQ(splitList("1;2"), (std::vector<std::string>{"1;2"}));
}

}  // namespace
}  // namespace trbc
