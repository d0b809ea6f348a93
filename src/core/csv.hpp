#pragma once
// Numeric CSV tables with a header line (experimental data, surrogate inputs). Strict: every
// problem is an InputError naming the file, the line and the column.
#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <initializer_list>
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
/// empty) must be numbers; the others are ignored (NaN). A blank field of a column in
/// `blankColumns` reads as NaN (a missing measurement); elsewhere it is an error. Empty lines are
/// skipped; '#' starts a comment line; fields may be quoted as csvField writes them.
NumericTable readNumericTable(const std::filesystem::path& path, const std::vector<std::string>& numericColumns = {},
                              const std::vector<std::string>& blankColumns = {});

/// One CSV field as RFC 4180 writes it: as is, or in double quotes with '"' doubled when it holds a
/// comma, a quote, a line break, leading/trailing space or a leading '#', so that no text can add a
/// column or a row, or turn a row into a comment line.
std::string csvField(std::string_view text);

/// The fields of a line joined by commas, each through csvField, and a line break.
std::string csvRow(std::initializer_list<std::string_view> fields);
std::string csvRow(const std::vector<std::string>& fields);

/// The records of a CSV file (RFC 4180: quoted fields may hold commas, quotes and line breaks), header
/// first. Lines that start with '#' (the provenance line) and empty lines are skipped. Empty when the
/// file cannot be read.
std::vector<std::vector<std::string>> readCsvRecords(const std::filesystem::path& path);
/// The records of CSV text, as readCsvRecords.
std::vector<std::vector<std::string>> parseCsvRecords(std::string_view text);
/// The index of the column `name` in a header record of readCsvRecords; -1 when absent.
int columnOf(const std::vector<std::string>& header, const std::string& name);

/// The items of a list separated by `separator` (no quoting), each with its blanks (space, tab,
/// CR) trimmed: "a, b,,c," gives {"a", "b", "", "c", ""} and "" gives {""}, so that an empty item
/// reaches the caller's check instead of vanishing.
std::vector<std::string> splitList(std::string_view text, char separator = ',');

/// The provenance line that opens every CSV table trbc writes, for example
/// "# trbc 1.4.0 (v1.4.0-12-gabc1234) | command: trbc infer --seed 3 | seed: 3 | build: GCC 12.2.0,
/// x86-64 (SSE2 baseline; dispatched kernels: avx2)\n": the version, the revision of the source it was
/// built from (`git describe --always --dirty`, "unknown" outside a git checkout), the command line,
/// the run seed ("n/a" for a command without one) and the compiler and instruction set
/// (simd::buildTarget). Every CSV reader of trbc skips lines that start with '#'.
std::string csvProvenance();
/// Records the command line that csvProvenance names (the CLI's main does, once).
void setProvenanceCommand(std::string commandLine);
/// Records the run seed that csvProvenance names (each command with a seed does).
void setProvenanceSeed(std::uint64_t seed);

/// One Markdown table cell: '|' escaped and line breaks as spaces, so that no text can add a cell or a row.
std::string markdownCell(std::string_view text);

}  // namespace trbc
