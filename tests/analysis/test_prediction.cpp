// Forward propagation of posteriors (src/analysis/prediction.hpp, docs/BAYESIAN_INFERENCE.md, prediction).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "analysis/prediction.hpp"
#include "core/error.hpp"

namespace {

using namespace trbc;
namespace fs = std::filesystem;

fs::path scratch(const std::string& name) {
    const fs::path d = fs::temp_directory_path() / ("trbc_test_prediction_" + name);
    fs::remove_all(d);
    fs::create_directories(d);
    return d;
}

void writeFile(const fs::path& p, const std::string& text) {
    fs::create_directories(p.parent_path());
    std::ofstream(p) << text;
}

/// Models with known outputs: equilibrium (7.8, 0.8, 2.6); stretching D0 = 7 - 0.01 F, D1 = 8 + 0.02 F.
RbcModel constantModel() {
    RbcModel m;
    m.equilibrium = [](const Eigen::MatrixXd& x) {
        Eigen::MatrixXd f(3, x.cols());
        for (Eigen::Index k = 0; k < x.cols(); ++k) f.col(k) << 7.8, 0.8, 2.6;
        return f;
    };
    m.stretching = [](const Eigen::MatrixXd& x) {
        Eigen::MatrixXd f(2, x.cols());
        for (Eigen::Index k = 0; k < x.cols(); ++k) f.col(k) << 7.0 - 0.01 * x(4, k), 8.0 + 0.02 * x(4, k);
        return f;
    };
    m.relaxationTime = [](const Eigen::MatrixXd& x) { return Eigen::VectorXd(x.row(4).transpose() / 4.0); };
    return m;
}

PosteriorSamples stretchingPosterior(double sigma0, double sigma1) {
    PosteriorSamples p;
    p.name = p.label = "mills_2004";
    p.experiment = RbcExperiment::Stretching;
    p.columns = phase1OutputNames(RbcExperiment::Stretching);
    p.values.resize(6, 1);
    p.values.col(0) << 0.9, 5.0, 2e-19, 1.5, sigma0, sigma1;
    return p;
}

constexpr double kZ95 = 1.6448536269514715, kZ995 = 2.5758293035489;

TEST(PredictionMixture, TwoGaussianQuantilesMatchIndependentValues) {
    // 0.3 N(0, 1) + 0.7 N(3, 0.5^2) as 10 equally weighted components; reference quantiles by a
    // 200-step bisection with Python's statistics.NormalDist.
    Eigen::VectorXd m(10), s(10);
    for (int k = 0; k < 10; ++k) m[k] = k < 3 ? 0.0 : 3.0, s[k] = k < 3 ? 1.0 : 0.5;
    const double q[5] = {0.05, 0.25, 0.5, 0.75, 0.95};
    const double ref[5] = {-0.9674215661017109, 0.9671978854290906, 2.719086654752049, 3.183471152395424, 3.7327657287793703};
    for (int i = 0; i < 5; ++i) {
        EXPECT_NEAR(normalMixtureQuantile(m, s, q[i]), ref[i], 1e-7) << "q = " << q[i];
        EXPECT_NEAR(normalMixtureCdf(m, s, ref[i]), q[i], 1e-12);
    }
    // Symmetric mixture: median 0, q and 1 - q mirror each other.
    Eigen::VectorXd ms(2), ss(2);
    ms << -2.0, 2.0;
    ss << 1.0, 1.0;
    EXPECT_NEAR(normalMixtureQuantile(ms, ss, 0.5), 0.0, 1e-8);
    EXPECT_NEAR(normalMixtureQuantile(ms, ss, 0.1), -normalMixtureQuantile(ms, ss, 0.9), 1e-8);
    // Point masses (sd 0) and bad levels.
    Eigen::VectorXd mp(4), sp = Eigen::VectorXd::Zero(4);
    mp << 1.0, 2.0, 3.0, 4.0;
    EXPECT_NEAR(normalMixtureQuantile(mp, sp, 0.6), 3.0, 1e-8);
    EXPECT_THROW(normalMixtureQuantile(m, s, 1.0), InputError);
    EXPECT_THROW(normalMixtureQuantile(Eigen::VectorXd(), Eigen::VectorXd(), 0.5), InputError);
}

TEST(PredictionMixture, LevelsAndSuffixes) {
    std::vector<std::string> names;
    for (double q : predictiveLevels()) names.push_back(levelSuffix(q));
    EXPECT_EQ(names, (std::vector<std::string>{"q005", "q05", "q125", "q25", "q50", "q75", "q875", "q95", "q995"}));
}

TEST(PredictionBand, SingleSampleGivesNormalQuantiles) {
    const RbcModel model = constantModel();
    // Stretching: one sample, sigma0 = 0.3, sigma1 = 0.5.
    const PosteriorPrediction st = predictPosterior(stretchingPosterior(0.3, 0.5), model, nullptr);
    ASSERT_EQ(st.bands.size(), 2u);
    ASSERT_EQ(st.bands[0].x.size(), 100u);
    EXPECT_DOUBLE_EQ(st.bands[0].x.back(), 200.0);
    for (std::size_t i = 0; i < st.bands[0].x.size(); i += 33) {
        const double F = st.bands[0].x[i];
        const PredictiveSummary& d0 = st.bands[0].summary[i];
        const PredictiveSummary& d1 = st.bands[1].summary[i];
        EXPECT_NEAR(d0.q05(), 7.0 - 0.01 * F - kZ95 * 0.3, 1e-7);
        EXPECT_NEAR(d0.q95(), 7.0 - 0.01 * F + kZ95 * 0.3, 1e-7);
        EXPECT_NEAR(d0.quantiles[4], 7.0 - 0.01 * F, 1e-7);
        EXPECT_NEAR(d0.quantiles[0], 7.0 - 0.01 * F - kZ995 * 0.3, 1e-7);
        EXPECT_NEAR(d1.q95(), 8.0 + 0.02 * F + kZ95 * 0.5, 1e-7);
        EXPECT_NEAR(d1.mean, 8.0 + 0.02 * F, 1e-12);
    }
    // Equilibrium: relative error, sd = sigma f.
    PosteriorSamples eq;
    eq.name = eq.label = "evans_fung_1972";
    eq.experiment = RbcExperiment::Equilibrium;
    eq.columns = phase1OutputNames(RbcExperiment::Equilibrium);
    eq.values.resize(3, 1);
    eq.values.col(0) << 0.9, 200.0, 0.1;
    const PosteriorPrediction pe = predictPosterior(eq, model, nullptr);
    ASSERT_EQ(pe.bands.size(), 3u);
    EXPECT_NEAR(pe.bands[0].summary[0].q95(), 7.8 * (1 + 0.1 * kZ95), 1e-7);
    EXPECT_NEAR(pe.bands[2].summary[0].q05(), 2.6 * (1 - 0.1 * kZ95), 1e-7);
    ASSERT_EQ(pe.density[0].size(), 200u);
    EXPECT_NEAR(pe.density[0][100] * 0.78 * std::sqrt(2 * M_PI), 1.0, 1e-3);  // near the mode
    // Relaxation: Hochmuth's law of the sample with sigma_z.
    PosteriorSamples re;
    re.name = re.label = "cell";
    re.experiment = RbcExperiment::Relaxation;
    re.columns = phase1OutputNames(RbcExperiment::Relaxation);
    re.values.resize(6, 1);
    re.values.col(0) << 0.1, 0.01, 0.12, 2.0, 1.1, 0.05;
    const PosteriorPrediction pr = predictPosterior(re, model, nullptr);
    ASSERT_EQ(pr.bands.size(), 1u);
    for (std::size_t i = 0; i < pr.bands[0].x.size(); i += 17) {
        const double z = hochmuthAspect(pr.bands[0].x[i], 0.12, 2.0, 1.1);
        EXPECT_NEAR(pr.bands[0].summary[i].q05(), z - kZ95 * 0.05, 1e-7);
        EXPECT_NEAR(pr.bands[0].summary[i].q95(), z + kZ95 * 0.05, 1e-7);
    }
    ASSERT_EQ(pr.tcSim.size(), 1);
    EXPECT_NEAR(pr.tcSim[0], 0.1, 1e-12);  // etam = 4 r, model tc = etam / 4
}

TEST(PredictionCoverage, MarksPointOutsideTheBand) {
    RbcDataSet data;
    data.name = "mills_2004";
    data.experiment = RbcExperiment::Stretching;
    data.force.resize(3);
    data.d0.resize(3);
    data.d1.resize(3);
    data.force << 0.0, 50.0, 100.0;
    data.d0 << 7.0, 6.5 + 0.1, 6.0;  // inside (0.1 < 1.645 * 0.3)
    data.d1 << 8.0, 9.0, 10.0 + 2.0; // the last is 4 sigma1 above: outside
    const PosteriorPrediction p = predictPosterior(stretchingPosterior(0.3, 0.5), constantModel(), &data);
    ASSERT_EQ(p.coverage.size(), 6u);
    int outside = 0;
    for (const CoveragePoint& c : p.coverage) {
        const bool expectInside = !(c.observable == "D1_um" && c.x == 100.0);
        EXPECT_EQ(c.inside(), expectInside) << c.observable << " at " << c.x;
        outside += c.inside() ? 0 : 1;
    }
    EXPECT_EQ(outside, 1);
    const std::string md = coverageMarkdown({p});
    EXPECT_NE(md.find("| mills_2004 | stretching | 1 | 6 | 5 | D1_um at Fext_pN = 100: 12 > q95"), std::string::npos) << md;
    EXPECT_NE(md.find("5 of 6 data points"), std::string::npos) << md;

    const fs::path dir = scratch("coverage");
    writeCoverageCsv(dir / "coverage.csv", {p});
    const auto files = writePredictionCsv(dir, p);
    ASSERT_EQ(files.size(), 1u);
    EXPECT_EQ(files[0].filename(), "predict_mills_2004_stretching.csv");
    std::ifstream in(files[0]);
    std::string header;
    std::getline(in, header);
    EXPECT_TRUE(header.starts_with("# trbc ")) << header;  // the provenance line
    std::getline(in, header);
    EXPECT_EQ(header.rfind("Fext_pN,D0_um_q005,D0_um_q05,", 0), 0u) << header;
    EXPECT_NE(header.find("D1_um_q95,D1_um_q995,D1_um_mean"), std::string::npos) << header;
    fs::remove_all(dir);
}

TEST(PredictionInput, ReadsSamplesAndRejectsBadInput) {
    const fs::path root = scratch("input");
    // A well-formed phase-3b stretching posterior.
    writeFile(root / "phase3" / "mills_2004" / "samples.csv",
              "v,mu_uN_per_m,kb_J,b2,sigma0_um,sigma1_um,log_likelihood,log_prior\n"
              "0.9,5,2e-19,1.5,0.3,0.5,-10,-inf\n0.8,6,3e-19,1.0,0.2,0.4,-11,-2\n");
    const PosteriorSamples s = readPosteriorSamples(root / "phase3" / "mills_2004");
    EXPECT_EQ(s.experiment, RbcExperiment::Stretching);
    EXPECT_EQ(s.label, "hierarchical_mills_2004");
    EXPECT_EQ(s.name, "mills_2004");
    ASSERT_EQ(s.values.cols(), 2);
    EXPECT_DOUBLE_EQ(s.values(2, 1), 3e-19);
    const auto idx = subsampleIndices(100, 10, 7);
    EXPECT_EQ(idx.size(), 10u);
    EXPECT_EQ(idx, subsampleIndices(100, 10, 7));
    EXPECT_EQ(subsampleIndices(5, 0, 1).size(), 5u);

    // Missing samples.csv: the message names the file.
    const fs::path missing = root / "phase1" / "suresh_2005";
    fs::create_directories(missing);
    try {
        readPosteriorSamples(missing);
        ADD_FAILURE() << "no InputError";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find((missing / "samples.csv").string()), std::string::npos) << e.what();
    }
    // Missing column: names the file and the column.
    const fs::path bad = root / "phase1" / "hochmuth_1979_cell1" / "samples.csv";
    writeFile(bad, "etam_over_mu_s,sigma_tc_rel,tc_s,z0,zinf,log_likelihood,log_prior\n0.1,0.01,0.1,2,1.1,-1,-1\n");
    try {
        readPosteriorSamples(bad.parent_path());
        ADD_FAILURE() << "no InputError";
    } catch (const InputError& e) {
        const std::string w = e.what();
        EXPECT_NE(w.find(bad.string()), std::string::npos) << w;
        EXPECT_NE(w.find("sigma_z"), std::string::npos) << w;
    }
    // Not a posterior at all.
    const fs::path other = root / "x" / "samples.csv";
    writeFile(other, "a,b\n1,2\n");
    try {
        readPosteriorSamples(other);
        ADD_FAILURE() << "no InputError";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find(other.string()), std::string::npos) << e.what();
    }
    // A non-numeric value in a used column.
    const fs::path junk = root / "phase1" / "evans_fung_1972" / "samples.csv";
    writeFile(junk, "v,FvK,sigma_rel,log_likelihood,log_prior\n0.9,abc,0.1,-1,-1\n");
    EXPECT_THROW(readPosteriorSamples(junk.parent_path()), InputError);
    fs::remove_all(root);
}

TEST(PosteriorSamples, AFlowDataSetsPosteriorIsNamedAndLeftOutOfAnInferenceDirectory) {
    // trbc infer --datasets all writes flow posteriors beside the single-cell ones; predict takes the
    // single-cell ones and names a flow posterior given to it.
    const fs::path root = scratch("flow");
    writeFile(root / "phase3" / "mills_2004" / "samples.csv",
              "# trbc\nv,mu_uN_per_m,kb_J,b2,sigma0_um,sigma1_um,log_likelihood,log_prior\n0.9,4,2e-19,2,0.2,0.2,-1,-1\n");
    writeFile(root / "phase3" / "fischer_2015_donor1" / "samples.csv",
              "# trbc\nv,mu_uN_per_m,kb_J,b2,etam_over_mu_s,sigma_deg,etam_Pa_s_um,log_likelihood,log_prior\n0.9,1.2,9e-19,3.6,0.17,1.3,0.2,-1,-1\n");
    writeFile(root / "phase3" / "fischer_ttf_donors12" / "samples.csv",
              "# trbc\nv,mu_uN_per_m,kb_J,b2,etam_over_mu_s,sigma_rel,etam_Pa_s_um,log_likelihood,log_prior\n0.9,2.6,9e-19,3.0,0.16,0.16,0.4,-1,-1\n");
    const std::vector<fs::path> dirs = inferencePosteriorDirectories(root, false);
    ASSERT_EQ(dirs.size(), 1u);
    EXPECT_EQ(dirs[0], root / "phase3" / "mills_2004");
    for (const char* set : {"fischer_2015_donor1", "fischer_ttf_donors12"}) {
        try {
            readPosteriorSamples(root / "phase3" / set);
            ADD_FAILURE() << "no InputError for " << set;
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find("a flow data set's posterior"), std::string::npos) << e.what();
        }
    }
    fs::remove_all(root);
}

TEST(PosteriorSamples, InferenceDirectoriesArePhase3ThenPhase1SortedWithoutThetaNew) {
    const fs::path root = scratch("dirs");
    for (const char* d : {"phase3/suresh_2005", "phase3/mills_2004", "phase3/theta_new", "phase1/mills_2004"})
        writeFile(root / d / "samples.csv", "v\n");
    fs::create_directories(root / "phase3" / "empty");  // no samples: not a posterior
    std::vector<fs::path> dirs = inferencePosteriorDirectories(root, false);
    ASSERT_EQ(dirs.size(), 2u);
    EXPECT_EQ(dirs[0], root / "phase3" / "mills_2004");
    EXPECT_EQ(dirs[1], root / "phase3" / "suresh_2005");
    dirs = inferencePosteriorDirectories(root, true);
    ASSERT_EQ(dirs.size(), 3u);
    EXPECT_EQ(dirs[0], root / "phase1" / "mills_2004");
    try {
        inferencePosteriorDirectories(root / "phase2", false);
        FAIL() << "no error for a missing directory";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("--inference"), std::string::npos) << e.what();
    }
    fs::remove_all(root / "phase1");
    EXPECT_THROW(inferencePosteriorDirectories(root, true), InputError);  // no phase1 directory
    fs::remove_all(root);
}

}  // namespace
