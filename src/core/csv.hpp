#pragma once
// Numeric CSV tables with a header line (experimental data, surrogate inputs). Strict: every
// problem is an InputError naming the file, the line and the column.
#include <Eigen/Core>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace trbc {

struct NumericTable {
    std::filesystem::path path;
    std::vector<std::string> columns;  ///< header names, in file order
    Eigen::MatrixXd values;            ///< rows x columns
    std::vector<long> lines;           ///< file line of each row (1 = header)

    /// Index of a column; -1 when absent.
    int find(const std::string& name) const;
    /// The column, or InputError "<file>: missing column <name> (<what it is>)".
    Eigen::VectorXd column(const std::string& name, const std::string& meaning = "") const;
};

/// Reads a CSV whose header names the columns. Only the columns in `numericColumns` (all columns if
/// empty) must be numbers; the others are ignored. Empty lines are skipped; '#' starts a comment line.
NumericTable readNumericTable(const std::filesystem::path& path, const std::vector<std::string>& numericColumns = {});

/// One CSV field as RFC 4180 writes it: as is, or in double quotes with '"' doubled when it holds a
/// comma, a quote, a line break or leading/trailing space, so that no text can add a column or a row.
std::string csvField(std::string_view text);

/// One Markdown table cell: '|' escaped and line breaks as spaces, so that no text can add a cell or a row.
std::string markdownCell(std::string_view text);

}  // namespace trbc
