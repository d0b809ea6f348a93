#include "analysis/toml_reader.hpp"

#include <optional>

namespace trbc {
namespace fs = std::filesystem;

namespace {

/// Moves every key of `over` into `base`: a table into the table of the same name, key by key;
/// any other value (arrays such as [[data]] included) replaces the base's.
void mergeInto(toml::table& base, toml::table&& over) {
    for (auto&& [key, node] : over) {
        toml::node* b = base.get(key.str());
        if (node.is_table() && b && b->is_table())
            mergeInto(*b->as_table(), std::move(*node.as_table()));
        else
            base.insert_or_assign(key, std::move(node));
    }
}

}  // namespace

toml::table parseWithBases(const fs::path& file, std::vector<fs::path>& chain, std::vector<fs::path>& bases) {
    toml::table t = parseTomlFile(file);
    const toml::node* key = t.get("base");
    if (!key) return t;
    const std::optional<std::string> name = key->value_exact<std::string>();
    if (!name || name->empty())
        TableReader::failAt(*key, file, "'base' must be the path of the configuration that this one overrides, e.g. base = \"paper.toml\"");
    const fs::path base = resolveConfigPath(*name, file.parent_path(), {});
    if (!fs::is_regular_file(base))
        TableReader::failAt(*key, file, fmt::format("base = \"{}\": the configuration {} does not exist", *name, base.string()));
    chain.push_back(file);
    for (const fs::path& f : chain)
        if (std::error_code ec; fs::equivalent(f, base, ec)) {
            std::string cycle;
            for (const fs::path& g : chain) cycle += g.string() + " -> ";
            TableReader::failAt(*key, file, fmt::format("base = \"{}\" makes a cycle: {}{}", *name, cycle, base.string()));
        }
    bases.push_back(fs::absolute(base).lexically_normal());
    toml::table merged = parseWithBases(base, chain, bases);
    chain.pop_back();
    t.erase("base");
    mergeInto(merged, std::move(t));
    return merged;
}

}  // namespace trbc
