#include "surrogate/sobol_io.hpp"

#include <fstream>
#include <string>

#include "core/csv.hpp"
#include "core/error.hpp"

namespace trbc {

namespace {

std::string csvName(const std::string& name) {
    if (name.empty()) throw InputError("sobol csv: an output or input name is empty");
    return csvField(name);
}

std::ofstream openCsv(const std::filesystem::path& path) {
    std::ofstream out(path);
    if (!out) throw InputError("sobol csv: cannot open '" + path.string() + "' for writing");
    out.precision(17);
    return out;
}

void finish(std::ofstream& out, const std::filesystem::path& path) {
    out.flush();
    if (!out) throw InputError("sobol csv: writing '" + path.string() + "' failed");
}

}  // namespace

void writeSobolCsv(const std::filesystem::path& path, const SobolResult& r) {
    std::ofstream out = openCsv(path);
    out << csvProvenance() << "output,input,S1,S1_ci,ST,ST_ci\n";
    for (Eigen::Index o = 0; o < r.S1.rows(); ++o)
        for (Eigen::Index i = 0; i < r.S1.cols(); ++i)
            out << csvName(r.outputs[o]) << ',' << csvName(r.inputs[i]) << ',' << r.S1(o, i) << ',' << r.S1_ci(o, i)
                << ',' << r.ST(o, i) << ',' << r.ST_ci(o, i) << '\n';
    finish(out, path);
}

void writeSobolSecondOrderCsv(const std::filesystem::path& path, const SobolResult& r) {
    if (r.S2.size() != r.outputs.size())
        throw InputError("sobol csv: the result has no second-order indices (run with secondOrder = true)");
    std::ofstream out = openCsv(path);
    out << csvProvenance() << "output,input_i,input_j,S2,S2_ci\n";
    for (std::size_t o = 0; o < r.S2.size(); ++o)
        for (Eigen::Index i = 0; i < r.S2[o].rows(); ++i)
            for (Eigen::Index j = i + 1; j < r.S2[o].cols(); ++j)
                out << csvName(r.outputs[o]) << ',' << csvName(r.inputs[i]) << ',' << csvName(r.inputs[j]) << ','
                    << r.S2[o](i, j) << ',' << r.S2_ci[o](i, j) << '\n';
    finish(out, path);
}

}  // namespace trbc
