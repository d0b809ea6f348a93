// The calibrated cell of a theta_new posterior: the inference's Rao-Blackwellised means where an
// infer output holds them, the sample means of a samples file alone, and clear errors.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "analysis/calibrated_cell.hpp"
#include "core/error.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;
using test::TempDir;
using test::writeText;

// Two samples: means v 0.9, mu 5, kb 2e-19, b2 2, etam 0.6.
const char* kSamples =
    "v,mu_uN_per_m,kb_J,b2,etam_Pa_s_um,log_likelihood\n"
    "0.8,4,1e-19,1,0.5,-1\n"
    "1.0,6,3e-19,3,0.7,-2\n";

std::string stats(double mu) {
    return fmt::format("posterior,parameter,mean,median,sd\n"
                       "theta_new,v,0.93,0.95,0.06\n"
                       "theta_new,mu_uN_per_m,{},4.3,2.1\n", mu) +
           "theta_new,kb_J,2.25e-19,1.7e-19,1.5e-19\n"
           "theta_new,b2,1.99,1.5,1.6\n"
           "theta_new,etam_Pa_s_um,0.699,0.61,0.46\n"
           "mills_2004,mu_uN_per_m,9.0,9.0,1.0\n";
}

TEST(CalibratedCell, AnInferOutputGivesTheRaoBlackwellisedMeansOfItsStatistics) {
    TempDir tmp;
    const fs::path post = tmp.path() / "infer" / "phase3" / "theta_new";
    writeText(post / "samples.csv", kSamples);
    writeText(tmp.path() / "infer" / "posterior_stats.csv", stats(4.667));
    for (const fs::path& p : {post, post / "samples.csv", fs::path(post.string() + "/"), post / "."}) {
        const CalibratedCell c = calibratedCell(p);
        EXPECT_DOUBLE_EQ(c.cell.v, 0.93);
        EXPECT_DOUBLE_EQ(c.cell.mu, 4.667);  // theta_new's row, not mills_2004's
        EXPECT_DOUBLE_EQ(c.kbJ, 2.25e-19);
        EXPECT_NEAR(c.cell.kbJoule(), 2.25e-19, 1e-30);
        EXPECT_DOUBLE_EQ(c.cell.b2, 1.99);
        EXPECT_DOUBLE_EQ(c.cell.etam, 0.699);
        EXPECT_EQ(c.source, fs::absolute(tmp.path() / "infer" / "posterior_stats.csv").lexically_normal());
        EXPECT_NE(c.estimator.find("Rao-Blackwellised"), std::string::npos);
    }
}

TEST(CalibratedCell, ASamplesFileAloneGivesItsSampleMeans) {
    TempDir tmp;
    for (const fs::path& p : {tmp.path() / "draws", tmp.path() / "infer" / "phase3" / "theta_new"}) {
        writeText(p / "samples.csv", kSamples);
        const CalibratedCell c = calibratedCell(p);  // the second: an infer output without posterior_stats.csv
        EXPECT_DOUBLE_EQ(c.cell.v, 0.9);
        EXPECT_DOUBLE_EQ(c.cell.mu, 5.0);
        EXPECT_DOUBLE_EQ(c.kbJ, 2e-19);
        EXPECT_DOUBLE_EQ(c.cell.b2, 2.0);
        EXPECT_DOUBLE_EQ(c.cell.etam, 0.6);
        EXPECT_EQ(c.estimator, "sample means");
    }
}

TEST(CalibratedCell, StatisticsWithoutEveryThetaNewRowFallBackToTheSamples) {
    TempDir tmp;
    const fs::path post = tmp.path() / "phase3" / "theta_new";
    writeText(post / "samples.csv", kSamples);
    writeText(tmp.path() / "posterior_stats.csv", "posterior,parameter,mean\ntheta_new,v,0.93\n");
    EXPECT_DOUBLE_EQ(calibratedCell(post).cell.mu, 5.0);
}

TEST(CalibratedCell, BadInputNamesTheFileAndTheOption) {
    TempDir tmp;
    try {
        calibratedCell(tmp.path() / "missing", "cell.posterior");
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("cell.posterior"), std::string::npos) << e.what();
    }
    const fs::path post = tmp.path() / "phase3" / "theta_new";
    writeText(post / "samples.csv", kSamples);
    writeText(tmp.path() / "posterior_stats.csv", stats(4.667) + "theta_new,v,abc,0.9,0.1\n");
    try {
        calibratedCell(post);
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("posterior_stats.csv"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("abc"), std::string::npos) << e.what();
    }
}

}  // namespace
}  // namespace trbc
