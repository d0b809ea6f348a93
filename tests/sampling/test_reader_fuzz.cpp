// The readers under corrupted files: the shipped OFF meshes (and the PLY and VTK that trbc writes),
// experimental CSV data, a campaign table, surrogate JSON and TOML configurations, each cut at a
// random length or with random bytes overwritten (seeded, so a failure replays). Every corrupted
// file must give InputError (a clean "file:line: problem"), or a result that passes the same checks
// as the intact file's. Any other exception, a crash or a sanitizer report is a failure; build with
// -fsanitize=address,undefined to run this under the sanitizers.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>

#include "analysis/calibrate_config.hpp"
#include "analysis/validation.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "inference/rbc_problem.hpp"
#include "mesh/geometry.hpp"
#include "mesh/icosphere.hpp"
#include "mesh/io.hpp"
#include "sampling/campaign.hpp"
#include "sampling/campaign_table.hpp"
#include "sampling/design.hpp"
#include "surrogate/surrogate.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;
using test::TempDir;

std::string readAll(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void writeAll(const fs::path& p, const std::string& s) {
    std::ofstream out(p, std::ios::binary | std::ios::trunc);
    out << s;
}

/// Truncation at a random length, or 1 to 8 bytes overwritten with random values (printable
/// digits, signs and separators half of the time, which reach deeper into the parsers).
std::string corrupt(const std::string& s, std::mt19937_64& rng) {
    std::string c = s;
    if (c.empty()) return c;
    std::uniform_int_distribution<std::size_t> pos(0, c.size() - 1);
    if (rng() % 3 == 0) {
        c.resize(pos(rng));
        return c;
    }
    static const std::string near = "0123456789.-+eE,\n #[]{}\":=naif";
    const int flips = 1 + static_cast<int>(rng() % 8);
    for (int k = 0; k < flips; ++k) {
        const std::size_t i = pos(rng);
        c[i] = rng() % 2 ? near[rng() % near.size()] : static_cast<char>(rng() % 256);
    }
    return c;
}

/// `trials` corruptions of `original` written to `target`; `read` must return normally (then
/// `check` validates the result) or throw InputError. Returns the counts of clean errors.
int fuzzReader(const fs::path& original, const fs::path& target, int trials, std::uint64_t seed,
               const std::function<void(const fs::path&)>& readAndCheck) {
    const std::string text = readAll(original);
    EXPECT_FALSE(text.empty()) << original;
    std::mt19937_64 rng(seed);
    int errors = 0;
    for (int t = 0; t < trials; ++t) {
        writeAll(target, corrupt(text, rng));
        try {
            readAndCheck(target);
        } catch (const InputError&) {
            ++errors;
        } catch (const std::exception& e) {
            ADD_FAILURE() << original << " corruption " << t << " (seed " << seed << "): not a clean InputError but "
                          << typeid(e).name() << ": " << e.what();
        }
    }
    // The intact file still reads.
    writeAll(target, text);
    EXPECT_NO_THROW(readAndCheck(target)) << original;
    return errors;
}

void checkMesh(const Mesh& m) {
    ASSERT_TRUE(m.X.allFinite());
    ASSERT_GE(m.numVertices(), 4);
    ASSERT_GE(m.F.minCoeff(), 0);
    ASSERT_LT(m.F.maxCoeff(), m.numVertices());
    EXPECT_TRUE(std::isfinite(totalArea(m.X, m.F)));
}

TEST(ReaderFuzz, Meshes) {
    TempDir tmp;
    const fs::path target = tmp.path() / "m.off";
    int errors = 0;
    for (const fs::path& f : {fs::path(test::meshPath("rbc_498.off")), fs::path(test::dataPath("bad_meshes/good_octahedron.off"))})
        errors += fuzzReader(f, target, 150, 11, [](const fs::path& p) { checkMesh(readOff(p.string())); });
    // PLY and VTK as trbc writes them, read back by readMesh.
    const Mesh m = readOff(test::meshPath("rbc_498.off"));
    for (const char* ext : {"ply", "vtk"}) {
        const fs::path written = tmp.path() / fmt::format("w.{}", ext);
        writeMesh(written.string(), m, {{"mean_curvature", Eigen::MatrixXd::Ones(1, m.numVertices())}});
        const Mesh back = readMesh(written.string());
        EXPECT_EQ(back.F, m.F);
        EXPECT_LT((back.X - m.X).cwiseAbs().maxCoeff(), 1e-12);
        errors += fuzzReader(written, tmp.path() / fmt::format("c.{}", ext), 100, 12,
                             [](const fs::path& p) { checkMesh(readMesh(p.string())); });
    }
    EXPECT_GT(errors, 100);  // most corruptions are detected, not just survived
}

TEST(ReaderFuzz, ExperimentalData) {
    TempDir tmp;
    const fs::path d = fs::path(TRBC_SOURCE_DIR) / "data" / "experiments";
    const fs::path target = tmp.path() / "d.csv";
    int errors = 0;
    errors += fuzzReader(d / "stretching" / "mills_2004" / "mills_2004.csv", target, 150, 21, [](const fs::path& p) {
        const RbcDataSet s = readStretchingData(p, "x");
        ASSERT_TRUE(s.force.allFinite() && s.d0.allFinite() && s.d1.allFinite());
        EXPECT_LE(s.force.maxCoeff(), kPriorFext.hi);
    });
    errors += fuzzReader(d / "relaxation" / "hochmuth_1979" / "1.csv", target, 150, 22, [](const fs::path& p) {
        const RbcDataSet s = readRelaxationData(p, "x");
        ASSERT_TRUE(s.time.allFinite() && s.aspect.allFinite());
        EXPECT_GT(s.aspect.minCoeff(), 0.0);
    });
    errors += fuzzReader(d / "equilibrium" / "evans_fung_1972.csv", target, 150, 23, [](const fs::path& p) {
        const RbcDataSet s = readEquilibriumData(p, "x");
        for (double v : s.shape) EXPECT_TRUE(std::isfinite(v) && v > 0);
    });
    errors += fuzzReader(fs::path(TRBC_SOURCE_DIR) / "data" / "examples" / "synthetic_stretching.csv", target, 100, 24,
                         [](const fs::path& p) {
                             const NumericTable t = readNumericTable(p);
                             EXPECT_EQ(t.values.rows(), static_cast<Eigen::Index>(t.lines.size()));
                         });
    EXPECT_GT(errors, 100);
}

TEST(ReaderFuzz, CampaignTable) {
    TempDir tmp;
    const fs::path table = tmp.path() / "samples.csv";
    {
        std::ofstream out(table);
        out << campaignCsvHeader() << '\n';
        for (const CampaignPoint& q : campaignDesign(DesignKind::Uniform, 24, 4, 5)) {
            CampaignRow r;
            r.point = q;
            r.seed = 5;
            r.D = 7.8, r.hmin = 0.9, r.hmax = 2.5, r.D0 = 7.0, r.D1 = 9.0, r.tc = 0.15;
            out << formatCampaignRow(r) << '\n';
        }
    }
    const int errors = fuzzReader(table, tmp.path() / "c.csv", 200, 31, [](const fs::path& p) {
        for (const CampaignRow& r : readCampaignCsv(p)) {
            EXPECT_TRUE(std::isfinite(r.point.p.v) && std::isfinite(r.point.fext)) << p;
            if (r.ok()) {
                EXPECT_TRUE(std::isfinite(r.D) && std::isfinite(r.tc));
            }
        }
    });
    EXPECT_GT(errors, 100);
}

TEST(ReaderFuzz, SurrogateJson) {
    TempDir tmp;
    const fs::path shipped = fs::path(TRBC_SOURCE_DIR) / "data" / "surrogates";
    const fs::path model = tmp.path() / "model";
    fs::create_directories(model);
    // The shipped model is branched: its classifier is read like the networks.
    const char* files[] = {"equilibrium.json", "stretching.json", "relaxation.json", "branch.json"};
    ASSERT_TRUE(fs::exists(shipped / "branch.json"));
    for (const char* f : files) fs::copy_file(shipped / f, model / f);
    Eigen::MatrixXd x(6, 2);
    x << 0.99, 0.7, 4.0, 9.0, 250.0, 20.0, 1.5, 0.1, 0.7, 0.2, 100.0, 10.0;
    int errors = 0;
    for (const char* f : files) {
        const fs::path keep = tmp.path() / "keep.json";
        fs::copy_file(model / f, keep, fs::copy_options::overwrite_existing);
        errors += fuzzReader(keep, model / f, 25, 41, [&](const fs::path&) {
            const Surrogate s = Surrogate::load(model);
            // A surviving corruption (a changed digit) may change the numbers, never make them non-finite.
            EXPECT_TRUE(s.evaluate(x).allFinite()) << f;
        });
    }
    EXPECT_GT(errors, 40);
}

TEST(ReaderFuzz, TomlConfigs) {
    TempDir tmp;
    const fs::path experiments = fs::path(TRBC_SOURCE_DIR) / "data" / "experiments";
    const fs::path target = tmp.path() / "c.toml";
    // paper.toml names validation.toml next to it.
    fs::copy_file(fs::path(TRBC_SOURCE_DIR) / "configs" / "validation.toml", tmp.path() / "validation.toml");
    int errors = 0;
    errors += fuzzReader(fs::path(TRBC_SOURCE_DIR) / "configs" / "paper.toml", target, 120, 51,
                         [&](const fs::path& p) { readCalibrateConfig(p, experiments); });
    errors += fuzzReader(fs::path(TRBC_SOURCE_DIR) / "configs" / "validation.toml", target, 120, 52,
                         [&](const fs::path& p) { readValidationConfig(p, experiments); });
    EXPECT_GT(errors, 100);
}

}  // namespace
}  // namespace trbc
