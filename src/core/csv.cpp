#include "core/csv.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>

#include "core/error.hpp"

namespace trbc {

namespace {

std::vector<std::string> splitCsvLine(const std::string& line) {
    std::vector<std::string> out;
    std::size_t start = 0;
    for (;;) {
        const std::size_t comma = line.find(',', start);
        std::string f = line.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
        const auto b = f.find_first_not_of(" \t\r"), e = f.find_last_not_of(" \t\r");
        out.push_back(b == std::string::npos ? std::string() : f.substr(b, e - b + 1));
        if (comma == std::string::npos) return out;
        start = comma + 1;
    }
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

NumericTable readNumericTable(const std::filesystem::path& path, const std::vector<std::string>& numericColumns) {
    std::ifstream in(path);
    if (!in) throw InputError(fmt::format("cannot open {}", path.string()));
    NumericTable t;
    t.path = path;
    std::string line;
    long lineNo = 0;
    std::vector<int> wanted;
    std::vector<std::vector<double>> rows;
    while (std::getline(in, line)) {
        ++lineNo;
        if (line.find_first_not_of(" \t\r") == std::string::npos || line[line.find_first_not_of(" \t")] == '#') continue;
        const auto fields = splitCsvLine(line);
        if (t.columns.empty()) {
            t.columns = fields;
            for (std::size_t c = 0; c < fields.size(); ++c) {
                if (fields[c].empty()) throw InputError(fmt::format("{}:{}: empty column name in the header", path.string(), lineNo));
                if (std::count(fields.begin(), fields.end(), fields[c]) > 1)
                    throw InputError(fmt::format("{}:{}: column '{}' appears twice", path.string(), lineNo, fields[c]));
            }
            for (std::size_t c = 0; c < fields.size(); ++c)
                if (numericColumns.empty() || std::count(numericColumns.begin(), numericColumns.end(), fields[c])) wanted.push_back(int(c));
            continue;
        }
        if (fields.size() != t.columns.size())
            throw InputError(fmt::format("{}:{}: {} fields, the header has {}", path.string(), lineNo, fields.size(), t.columns.size()));
        std::vector<double> row(t.columns.size(), NAN);
        for (int c : wanted) {
            const std::string& s = fields[c];
            double x = 0.0;
            const auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), x);
            if (s.empty() || ec != std::errc() || ptr != s.data() + s.size() || !std::isfinite(x))
                throw InputError(fmt::format("{}:{}: column '{}': '{}' is not a finite number", path.string(), lineNo, t.columns[c], s));
            row[c] = x;
        }
        rows.push_back(std::move(row));
        t.lines.push_back(lineNo);
    }
    if (t.columns.empty()) throw InputError(fmt::format("{}: empty file (expected a header line)", path.string()));
    t.values.resize(Eigen::Index(rows.size()), Eigen::Index(t.columns.size()));
    for (std::size_t r = 0; r < rows.size(); ++r)
        for (std::size_t c = 0; c < t.columns.size(); ++c) t.values(Eigen::Index(r), Eigen::Index(c)) = rows[r][c];
    return t;
}

std::string csvField(std::string_view text) {
    const bool quote = text.find_first_of(",\"\r\n") != std::string_view::npos ||
                       (!text.empty() && (text.front() == ' ' || text.back() == ' '));
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
