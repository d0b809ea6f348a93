#include "core/csv.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <iterator>

#include "core/error.hpp"
#include "core/simd.hpp"
#include "core/version.hpp"

namespace trbc {

namespace {

/// One record from `pos` (RFC 4180): fields split at commas outside quotes; a quoted field keeps its
/// commas and line breaks and "" stands for '"'. Unquoted fields are trimmed of blanks. `pos` moves past
/// the record's line break.
std::vector<std::string> nextCsvRecord(std::string_view text, std::size_t& pos) {
    std::vector<std::string> out;
    std::string field;
    bool quoted = false, wasQuoted = false;
    const auto finish = [&] {
        if (!wasQuoted) {
            const auto b = field.find_first_not_of(" \t\r"), e = field.find_last_not_of(" \t\r");
            field = b == std::string::npos ? std::string() : field.substr(b, e - b + 1);
        }
        out.push_back(std::move(field));
        field.clear();
        wasQuoted = false;
    };
    for (; pos < text.size(); ++pos) {
        const char ch = text[pos];
        if (quoted) {
            if (ch != '"')
                field += ch;
            else if (pos + 1 < text.size() && text[pos + 1] == '"')
                field += '"', ++pos;
            else
                quoted = false;
        } else if (ch == '"' && field.find_first_not_of(" \t") == std::string::npos) {
            field.clear();
            quoted = wasQuoted = true;
        } else if (ch == ',') {
            finish();
        } else if (ch == '\n') {
            ++pos;
            break;
        } else if (!(wasQuoted && (ch == '\r' || ch == ' ' || ch == '\t'))) {
            field += ch;
        }
    }
    finish();
    return out;
}

/// True for a line to skip: empty, blank or a '#' comment.
bool skippedLine(std::string_view text, std::size_t pos) {
    const std::size_t end = std::min(text.find('\n', pos), text.size());
    const std::size_t first = text.find_first_not_of(" \t\r", pos);
    return first == std::string_view::npos || first >= end || text[first] == '#';
}

std::string& provenanceCommand() {
    static std::string command = "trbc";
    return command;
}
std::string& provenanceSeed() {
    static std::string seed = "n/a";
    return seed;
}

}  // namespace

int NumericTable::find(const std::string& name) const {
    const auto it = std::find(columns.begin(), columns.end(), name);
    return it == columns.end() ? -1 : int(it - columns.begin());
}

Eigen::VectorXd NumericTable::column(const std::string& name, const std::string& meaning) const {
    const int c = find(name);
    if (c < 0)
        throw InputError(fmt::format("{}: missing column '{}'{} (columns found: {})", path.string(), name,
                                     meaning.empty() ? "" : " (" + meaning + ")", fmt::join(columns, ", ")));
    return values.col(c);
}

NumericTable readNumericTable(const std::filesystem::path& path, const std::vector<std::string>& numericColumns,
                              const std::vector<std::string>& blankColumns) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(fmt::format("cannot open {}", path.string()));
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    NumericTable t;
    t.path = path;
    long lineNo = 1;
    std::vector<int> wanted;
    std::vector<std::vector<double>> rows;
    for (std::size_t pos = 0; pos < text.size();) {
        const long recordLine = lineNo;
        const std::size_t start = pos;
        if (skippedLine(text, pos)) {
            pos = std::min(text.find('\n', pos), text.size()) + 1;
            ++lineNo;
            continue;
        }
        const auto fields = nextCsvRecord(text, pos);
        lineNo += long(std::count(text.begin() + long(start), text.begin() + long(std::min(pos, text.size())), '\n'));
        if (t.columns.empty()) {
            t.columns = fields;
            for (std::size_t c = 0; c < fields.size(); ++c) {
                if (fields[c].empty()) throw InputError(fmt::format("{}:{}: empty column name in the header", path.string(), recordLine));
                if (std::count(fields.begin(), fields.end(), fields[c]) > 1)
                    throw InputError(fmt::format("{}:{}: column '{}' appears twice", path.string(), recordLine, fields[c]));
            }
            for (std::size_t c = 0; c < fields.size(); ++c)
                if (numericColumns.empty() || std::count(numericColumns.begin(), numericColumns.end(), fields[c])) wanted.push_back(int(c));
            continue;
        }
        if (fields.size() != t.columns.size())
            throw InputError(fmt::format("{}:{}: {} fields, the header has {}", path.string(), recordLine, fields.size(), t.columns.size()));
        std::vector<double> row(t.columns.size(), NAN);
        for (int c : wanted) {
            const std::string& s = fields[c];
            if (s.empty() && std::count(blankColumns.begin(), blankColumns.end(), t.columns[c])) continue;
            double x = 0.0;
            const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), x);
            if (s.empty() || ec != std::errc() || ptr != s.data() + s.size() || !std::isfinite(x))
                throw InputError(fmt::format("{}:{}: column '{}': '{}' is not a finite number", path.string(), recordLine, t.columns[c], s));
            row[c] = x;
        }
        rows.push_back(std::move(row));
        t.lines.push_back(recordLine);
    }
    if (t.columns.empty()) throw InputError(fmt::format("{}: empty file (expected a header line)", path.string()));
    t.values.resize(Eigen::Index(rows.size()), Eigen::Index(t.columns.size()));
    for (std::size_t r = 0; r < rows.size(); ++r)
        for (std::size_t c = 0; c < t.columns.size(); ++c) t.values(Eigen::Index(r), Eigen::Index(c)) = rows[r][c];
    return t;
}

std::vector<std::vector<std::string>> parseCsvRecords(std::string_view text) {
    std::vector<std::vector<std::string>> rows;
    for (std::size_t pos = 0; pos < text.size();) {
        if (skippedLine(text, pos)) {
            pos = std::min(text.find('\n', pos), text.size()) + 1;
            continue;
        }
        rows.push_back(nextCsvRecord(text, pos));
    }
    return rows;
}

std::vector<std::vector<std::string>> readCsvRecords(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) return {};
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    return parseCsvRecords(text);
}

int columnOf(const std::vector<std::string>& header, const std::string& name) {
    const auto it = std::find(header.begin(), header.end(), name);
    return it == header.end() ? -1 : static_cast<int>(it - header.begin());
}

std::vector<std::string> splitList(std::string_view text, char separator) {
    std::vector<std::string> items;
    for (std::size_t start = 0;;) {
        const std::size_t end = std::min(text.find(separator, start), text.size());
        std::string_view item = text.substr(start, end - start);
        const std::size_t first = item.find_first_not_of(" \t\r");
        item = first == std::string_view::npos ? std::string_view{} : item.substr(first, item.find_last_not_of(" \t\r") - first + 1);
        items.emplace_back(item);
        if (end == text.size()) return items;
        start = end + 1;
    }
}

std::string csvRow(std::initializer_list<std::string_view> fields) {
    std::string out;
    bool first = true;
    for (std::string_view f : fields) {
        if (!first) out += ',';
        out += csvField(f);
        first = false;
    }
    return out + '\n';
}

std::string csvRow(const std::vector<std::string>& fields) {
    std::string out;
    for (std::size_t k = 0; k < fields.size(); ++k) {
        if (k) out += ',';
        out += csvField(fields[k]);
    }
    return out + '\n';
}

void setProvenanceCommand(std::string commandLine) {
    // One line: a line break in an argument would end the comment line.
    for (char& ch : commandLine)
        if (ch == '\n' || ch == '\r') ch = ' ';
    provenanceCommand() = std::move(commandLine);
}

void setProvenanceSeed(std::uint64_t seed) { provenanceSeed() = std::to_string(seed); }

std::string csvProvenance() {
    return fmt::format("# trbc {} ({}) | command: {} | seed: {} | build: {}\n", kVersion, gitDescribe(), provenanceCommand(),
                       provenanceSeed(), simd::buildTarget());
}

std::string csvField(std::string_view text) {
    // A leading '#' is quoted too: a row that starts with it would read as a comment line.
    const bool quote = text.find_first_of(",\"\r\n") != std::string_view::npos ||
                       (!text.empty() && (text.front() == ' ' || text.back() == ' ' || text.front() == '#'));
    if (!quote) return std::string(text);
    std::string out = "\"";
    for (char ch : text) {
        if (ch == '"') out += '"';
        out += ch;
    }
    return out + '"';
}

std::string markdownCell(std::string_view text) {
    std::string out;
    for (char ch : text) {
        if (ch == '|')
            out += "\\|";
        else if (ch == '\n' || ch == '\r')
            out += ' ';
        else
            out += ch;
    }
    return out;
}

}  // namespace trbc
