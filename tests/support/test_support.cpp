#include "test_support.hpp"

#include <Eigen/Geometry>
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <iterator>

#include "core/error.hpp"
#include "mesh/icosphere.hpp"
#include "mesh/topology.hpp"

namespace trbc::test {

double meanEdgeLength(const Mesh& m) {
    const Topology t = buildTopology(m.F, m.numVertices());
    double s = 0.0;
    for (Eigen::Index e = 0; e < t.numEdges(); ++e) s += (m.X.col(t.edges(1, e)) - m.X.col(t.edges(0, e))).norm();
    return s / static_cast<double>(t.numEdges());
}

Mesh perturbedIcosphere(int level, double amplitude, unsigned seed) {
    Mesh m = icosphere(level);
    const double h = meanEdgeLength(m);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (Eigen::Index i = 0; i < m.numVertices(); ++i)
        for (int k = 0; k < 3; ++k) m.X(k, i) += amplitude * h * u(rng);
    return m;
}

Vertices finiteDifferenceGradient(const MembraneModel& model, const Vertices& X, double h) {
    Vertices g(3, X.cols());
    Vertices Y = X;
    for (Eigen::Index i = 0; i < X.cols(); ++i)
        for (int k = 0; k < 3; ++k) {
            const double x0 = Y(k, i);
            Y(k, i) = x0 + h;
            const double ep = model.evaluate(Y);
            Y(k, i) = x0 - h;
            const double em = model.evaluate(Y);
            Y(k, i) = x0;
            g(k, i) = (ep - em) / (2.0 * h);
        }
    return g;
}

double relativeMaxError(const Vertices& a, const Vertices& b) {
    return (a - b).cwiseAbs().maxCoeff() / b.cwiseAbs().maxCoeff();
}

Eigen::Matrix3d randomRotation(unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> n;
    Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
    return q.normalized().toRotationMatrix();
}

namespace fs = std::filesystem;

TempDir::TempDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name = info ? std::string(info->test_suite_name()) + "_" + info->name() : "trbc";
    for (char& c : name)
        if (c == '/') c = '_';
    path_ = fs::temp_directory_path() / ("trbc_" + std::to_string(::getpid()) + "_" + name);
    fs::remove_all(path_);
    fs::create_directories(path_);
}

TempDir::~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
}

fs::path writeText(const fs::path& p, const std::string& text) {
    if (p.has_parent_path()) fs::create_directories(p.parent_path());
    std::ofstream(p) << text;
    return p;
}

std::string inputError(const std::function<void()>& f) {
    try {
        f();
    } catch (const InputError& e) {
        return e.what();
    }
    return {};
}

std::string slurp(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

std::string tableBody(const fs::path& csv) {
    const std::string text = slurp(csv);
    return text.starts_with('#') ? text.substr(text.find('\n') + 1) : text;
}

std::string shellQuote(const std::string& s) {
    std::string q = "'";
    for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return q + "'";
}

CliRun runTrbc(const std::string& args, const fs::path& scratch) {
    return runShell(shellQuote(TRBC_CLI) + " " + args, scratch);
}

CliRun runShell(const std::string& commandLine, const fs::path& scratch) {
    const fs::path out = scratch / "stdout.txt", err = scratch / "stderr.txt";
    const std::string cmd = commandLine + " </dev/null >" + shellQuote(out.string()) + " 2>" + shellQuote(err.string());
    const int raw = std::system(cmd.c_str());
    CliRun r;
    r.status = raw != -1 && WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
    r.out = slurp(out);
    r.err = slurp(err);
    return r;
}

int processesMentioning(const std::string& needle) {
    int n = 0;
    for (const auto& e : std::filesystem::directory_iterator("/proc")) {
        const std::string name = e.path().filename().string();
        if (name.find_first_not_of("0123456789") != std::string::npos || std::stoi(name) == ::getpid()) continue;
        std::string cmd = slurp(e.path() / "cmdline");
        std::replace(cmd.begin(), cmd.end(), '\0', ' ');
        if (cmd.find(needle) != std::string::npos) ++n;
    }
    return n;
}

}  // namespace trbc::test
