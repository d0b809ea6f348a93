// The experimental sets of the flow validations: the catalogue, its unit conversions and the reader.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <string>

#include "analysis/validation_data.hpp"
#include "core/error.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;
using test::TempDir;
using test::writeText;

const fs::path kValidationData = test::experimentsDir() / "validation";

TEST(ValidationData, ShippedFilesReadWithBlanksAndBadCellsAreNamed) {
    const fs::path angles = kValidationData / "shear_flow" / "inclination_angle" / "Fisher2015_eta_23.9_mPa_s.csv";
    const std::vector<std::string> donors = {"angle1", "angle2", "angle3", "angle4", "angle5", "angle6", "angle7"};
    const ExperimentalPoints a = readExperimentalPoints(angles, "shear_rate", donors);
    ASSERT_GT(a.x.size(), 10u);
    EXPECT_NEAR(a.x[0], 2.5942, 1e-12);
    EXPECT_EQ(a.y[0].size(), 1u);  // one donor at the lowest rate, blanks skipped
    const ExperimentalPoints kept = readExperimentalPoints(angles, "shear_rate", donors, true);
    ASSERT_EQ(kept.y[0].size(), 7u);  // "2.5942,,,12.053,,,,": the third donor, the others NaN
    EXPECT_NEAR(kept.y[0][2], 12.053, 1e-12);
    EXPECT_TRUE(std::isnan(kept.y[0][0]) && std::isnan(kept.y[0][6]));
    const ExperimentalPoints dropped = withoutBlanks(kept);
    EXPECT_EQ(dropped.x, a.x);
    EXPECT_EQ(dropped.y, a.y);
    TempDir dir;
    const fs::path bad = writeText(dir.path() / "bad.csv", "pg,v\n1,0.1\n2,fast\n");
    try {
        readExperimentalPoints(bad, "pg", {"v"});
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("bad.csv:3: column 'v': 'fast' is not a finite number"), std::string::npos) << e.what();
    }
    EXPECT_THROW(readExperimentalPoints(bad, "pressure", {"v"}), InputError);
}

/// The one set of `observable` (from `source`, when given) of the list.
const ValidationDataSet& setOf(const std::vector<ValidationDataSet>& sets, const std::string& observable, const std::string& source = "") {
    for (const ValidationDataSet& s : sets)
        if (s.observable == observable && (source.empty() || s.source == source)) return s;
    throw std::runtime_error("no set of " + observable);
}

// Every shipped set is listed once, the angle sets in increasing viscosity, with trbc's units.
TEST(ValidationData, TheListHasTheShippedSetsInTrbcsUnits) {
    const std::vector<ValidationDataSet> sets = validationDataSets(kValidationData);
    std::vector<double> angleViscosities;
    int critical = 0, judged = 0;
    for (const ValidationDataSet& s : sets) {
        if (s.observable == "inclination_deg") angleViscosities.push_back(s.etaOutMPaS);
        critical += s.observable == "critical_stress_Pa";
        judged += s.judged;
    }
    EXPECT_EQ(angleViscosities, (std::vector<double>{10.7, 23.9, 55.9, 104.0}));
    EXPECT_EQ(critical, 2);
    EXPECT_EQ(sets.size(), 4u + 6u);
    EXPECT_EQ(judged, int(sets.size()) - 1);  // the 6.7 µm tube is drawn, not judged
    EXPECT_EQ(setOf(sets, "inclination_deg").file.filename(), "Fisher2015_eta_10.7_mPa_s.csv");

    // The donors' TTF is f / rate; trbc's is 4 pi f / rate (first row 8.068529, 0.062906).
    const ValidationDataSet& ttf = setOf(sets, "ttf_4pi_f_over_rate");
    EXPECT_EQ(ttf.etaOutMPaS, 28.9);
    const ExperimentalPoints t = readValidationData(ttf);
    EXPECT_NEAR(t.x[0], 8.068529, 1e-12);
    EXPECT_NEAR(t.y[0][0], 4.0 * M_PI * 0.062906, 1e-12);
    // Hochmuth's velocities are in mm/s (first row 0.035111 mm/s), trbc's in cm/s.
    const ValidationDataSet& h = setOf(sets, "length_um", "Hochmuth et al. 1970 (6.7 µm tube)");
    EXPECT_FALSE(h.judged);
    EXPECT_NEAR(readValidationData(h).x[0], 0.0035111, 1e-15);
    EXPECT_EQ(setOf(sets, "length_um").yColumns, (std::vector<std::string>{"l", "l_high", "l_low"}));

    // The record of validate: blanks are null, units as above.
    const nlohmann::json j = validationDataJson(readValidationDataSets(kValidationData));
    ASSERT_EQ(j.size(), sets.size());
    EXPECT_EQ(j[1].at("eta_out_mPa_s"), 23.9);
    EXPECT_TRUE(j[1].at("y")[0][0].is_null());
    EXPECT_NEAR(j[1].at("y")[0][2].get<double>(), 12.053, 1e-12);
    EXPECT_TRUE(j[5].at("eta_out_mPa_s").is_null());  // the first critical-stress set spans viscosities
    EXPECT_EQ(j[5].at("observable"), "critical_stress_Pa");

    // A folder that is not validation data is named; a listed file that is absent fails when read.
    TempDir empty;
    try {
        validationDataSets(empty.path());
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("is not a validation data folder: it has neither shear_flow/ nor microtube/"),
                  std::string::npos) << e.what();
    }
    fs::create_directories(empty.path() / "microtube");
    const std::vector<ValidationDataSet> bare = validationDataSets(empty.path());
    EXPECT_EQ(bare.size(), 6u);  // no angle sets found, the fixed ones listed
    try {
        readValidationDataSets(empty.path());
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("cannot open " + (empty.path() / "shear_flow" / "ttf" / "data_donors12.csv").string()),
                  std::string::npos) << e.what();
    }
}

}  // namespace
}  // namespace trbc
