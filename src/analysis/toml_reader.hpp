#pragma once
// Checked reading of TOML tables (toml++) for the configuration files of `trbc calibrate` and
// `trbc validate`: every key type- and range-checked, unknown keys rejected, every error an
// InputError "file:line: 'section.key' ..." with the valid range.
#include <fmt/format.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <initializer_list>
#include <limits>
#include <string>
#include <toml++/toml.h>
#include <vector>

#include "core/error.hpp"

namespace trbc {

/// Reads the keys of one table, each checked for type and range, and rejects unknown keys.
class TableReader {
public:
    TableReader(const std::filesystem::path& file, const toml::table& table, std::string context)
        : file_(file), table_(table), context_(std::move(context)) {}

    /// InputError for every key not in `allowed` (typos must not be ignored silently).
    void allowOnly(std::initializer_list<const char*> allowed) const {
        for (const auto& [key, node] : table_) {
            const std::string k(key.str());
            if (std::none_of(allowed.begin(), allowed.end(), [&](const char* a) { return k == a; })) {
                std::string list;
                for (const char* a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
                fail(node, fmt::format("unknown key '{}' (valid keys: {})", qualified(k), list));
            }
        }
    }

    template <class Int>
    void integer(const char* key, Int& out, long long lo, long long hi) const {
        const toml::node* n = table_.get(key);
        if (!n) return;
        const auto v = n->value_exact<std::int64_t>();
        if (!v) fail(*n, fmt::format("'{}' must be an integer in [{}, {}]", qualified(key), lo, hi));
        if (*v < lo || *v > hi) fail(*n, fmt::format("'{}' = {} is out of range: valid range [{}, {}]", qualified(key), *v, lo, hi));
        out = static_cast<Int>(*v);
    }

    void unsignedInteger(const char* key, std::uint64_t& out) const {
        long long v = static_cast<long long>(out & 0x7fffffffffffffffULL);
        integer(key, v, 0, std::numeric_limits<long long>::max());
        out = static_cast<std::uint64_t>(v);
    }

    void real(const char* key, double& out, double lo, double hi, bool openLo = false, bool openHi = false) const {
        const toml::node* n = table_.get(key);
        if (!n) return;
        const auto v = n->value<double>();  // integers convert
        const std::string range = fmt::format("{}{}, {}{}", openLo ? "(" : "[", lo, hi, openHi ? ")" : "]");
        if (!v) fail(*n, fmt::format("'{}' must be a number in {}", qualified(key), range));
        const bool bad = !(openLo ? *v > lo : *v >= lo) || !(openHi ? *v < hi : *v <= hi);
        if (bad) fail(*n, fmt::format("'{}' = {} is out of range: valid range {}", qualified(key), *v, range));
        out = *v;
    }

    void boolean(const char* key, bool& out) const {
        const toml::node* n = table_.get(key);
        if (!n) return;
        const auto v = n->value_exact<bool>();
        if (!v) fail(*n, fmt::format("'{}' must be true or false", qualified(key)));
        out = *v;
    }

    void string(const char* key, std::string& out, std::initializer_list<const char*> choices = {}) const {
        const toml::node* n = table_.get(key);
        if (!n) return;
        const auto v = n->value_exact<std::string>();
        if (!v) fail(*n, fmt::format("'{}' must be a string", qualified(key)));
        if (choices.size() && std::none_of(choices.begin(), choices.end(), [&](const char* c) { return *v == c; })) {
            std::string list;
            for (const char* c : choices) list += (list.empty() ? "" : ", ") + std::string(c);
            fail(*n, fmt::format("'{}' = \"{}\" is not one of: {}", qualified(key), *v, list));
        }
        out = *v;
    }

    [[noreturn]] void fail(const toml::node& n, const std::string& what) const { failAt(n, file_, what); }

    /// InputError "file:line: what" for a node read from `file` (or from the file it was merged from).
    [[noreturn]] static void failAt(const toml::node& n, const std::filesystem::path& file, const std::string& what) {
        throw InputError(fmt::format("{}:{}: {}", sourceFile(n, file).string(), n.source().begin.line, what));
    }

    /// The file a node was parsed from: `file`, unless a configuration merged over its base holds it.
    static std::filesystem::path sourceFile(const toml::node& n, const std::filesystem::path& file) {
        return n.source().path ? std::filesystem::path(*n.source().path) : file;
    }

private:
    std::string qualified(const std::string& key) const { return context_.empty() ? key : context_ + "." + key; }

    const std::filesystem::path& file_;
    const toml::table& table_;
    std::string context_;
};

/// The largest configuration file read, and the deepest nesting (dotted key parts, table header
/// parts, inline arrays and tables): the TOML parser recurses per level, so a crafted file could
/// otherwise exhaust the stack or the memory before any key is checked.
inline constexpr std::uintmax_t kMaxConfigBytes = 4u << 20;
inline constexpr int kMaxConfigDepth = 32;

/// Throws InputError "file:line: ..." when `text` nests deeper than kMaxConfigDepth. Counts the
/// dots of keys and headers and the open [ and { of values, outside strings and comments.
inline void checkTomlDepth(const std::string& text, const std::filesystem::path& file) {
    int dots = 0, line = 1;
    std::string open;  // the [ and { not closed yet
    bool inKey = true;  // before the line's '=' (or in a header): dots separate key parts
    for (std::size_t i = 0; i < text.size(); ++i) {
        const char c = text[i];
        if (c == '"' || c == '\'') {  // a string: skipped, multi-line ones included
            const bool triple = text.compare(i, 3, std::string(3, c)) == 0;
            const std::string end = triple ? std::string(3, c) : std::string(1, c);
            std::size_t j = i + end.size();
            while (j < text.size() && text.compare(j, end.size(), end) != 0) {
                if (text[j] == '\n') ++line;
                j += (c == '"' && text[j] == '\\') ? 2 : 1;
            }
            i = j + end.size() - 1;
            continue;
        }
        if (c == '#') {
            while (i + 1 < text.size() && text[i + 1] != '\n') ++i;
            continue;
        }
        if (c == '\n') {
            ++line;
            if (open.empty()) inKey = true, dots = 0;
            continue;
        }
        if (c == '=') {
            inKey = false, dots = 0;
        } else if (c == '.' && inKey) {
            ++dots;
        } else if (c == '[' || c == '{') {
            inKey = c == '{' || (open.empty() && inKey);  // an inline table's keys, or a header's parts
            open += c;
        } else if ((c == ']' || c == '}') && !open.empty()) {
            open.pop_back();
        } else if (c == ',' && !open.empty()) {
            inKey = open.back() == '{', dots = 0;
        }
        if (static_cast<int>(open.size()) + dots > kMaxConfigDepth)
            throw InputError(fmt::format("{}:{}: nested deeper than {} levels (dotted key parts, tables and arrays); not read",
                                         file.string(), line, kMaxConfigDepth));
    }
}

/// Parses a TOML file; a missing file or a syntax error is an InputError "file:line:column: ...".
/// Files over kMaxConfigBytes or nested deeper than kMaxConfigDepth are refused before parsing.
inline toml::table parseTomlFile(const std::filesystem::path& file) {
    if (!std::filesystem::is_regular_file(file))
        throw InputError(fmt::format("configuration file {} does not exist", file.string()));
    const std::uintmax_t bytes = std::filesystem::file_size(file);
    if (bytes > kMaxConfigBytes)
        throw InputError(fmt::format("configuration file {}: {} bytes, more than the limit of {} MiB; not read", file.string(), bytes,
                                     kMaxConfigBytes >> 20));
    std::string text;
    {
        std::ifstream in(file, std::ios::binary);
        text.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    }
    checkTomlDepth(text, file);
    try {
        return toml::parse(text, file.string());
    } catch (const toml::parse_error& e) {
        throw InputError(fmt::format("{}:{}:{}: TOML syntax error: {}", file.string(), e.source().begin.line, e.source().begin.column,
                                     e.description()));
    }
}

/// A path of a configuration file: "@experiments/X" is X in the experimental data directory,
/// a relative path is relative to the configuration's directory.
inline std::filesystem::path resolveConfigPath(const std::string& s, const std::filesystem::path& configDir,
                                               const std::filesystem::path& experiments) {
    static const std::string alias = "@experiments/";
    if (s.rfind(alias, 0) == 0) return (experiments / s.substr(alias.size())).lexically_normal();
    const std::filesystem::path p(s);
    return (p.is_absolute() ? p : configDir / p).lexically_normal();
}

/// The configuration in `file` over the one its `base` key names, recursively: a table of the
/// file is merged key by key into the base's table of the same name, any other value (arrays such
/// as [[data]] included) replaces the base's. `chain` holds the files read so far (the including
/// ones); the bases are appended to `bases`, nearest first. A missing base, a base that is not a
/// string or a cycle is an InputError naming the `base` line.
toml::table parseWithBases(const std::filesystem::path& file, std::vector<std::filesystem::path>& chain,
                           std::vector<std::filesystem::path>& bases);

}  // namespace trbc
