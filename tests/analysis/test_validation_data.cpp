// The experimental sets of the flow validations: the catalogue, its unit conversions and the reader.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
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
    TempDir dir;
    const fs::path bad = writeText(dir.path() / "bad.csv", "pg,v\n1,0.1\n2,fast\n");
    try {
        readExperimentalPoints(bad, "pg", {"v"});
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("bad.csv:3: column 'v' = 'fast' is not a number"), std::string::npos) << e.what();
    }
    EXPECT_THROW(readExperimentalPoints(bad, "pressure", {"v"}), InputError);
}

// Every shipped set is listed once, the angle sets in increasing viscosity, with trbc's units.
TEST(ValidationData, TheCatalogueListsTheShippedSetsInTrbcsUnits) {
    const std::vector<ValidationDataSet> sets = validationDataSets(kValidationData);
    std::vector<double> angleViscosities;
    int critical = 0, judged = 0;
    for (const ValidationDataSet& s : sets) {
        EXPECT_TRUE(fs::exists(s.file)) << s.file;
        if (s.observable == "inclination_deg") angleViscosities.push_back(s.etaOutMPaS);
        critical += s.observable == "critical_stress_Pa";
        judged += s.judged;
    }
    EXPECT_EQ(angleViscosities, (std::vector<double>{10.7, 23.9, 55.9, 104.0}));
    EXPECT_EQ(critical, 2);
    EXPECT_EQ(sets.size(), 4u + 6u);
    EXPECT_EQ(judged, int(sets.size()) - 1);  // the 6.7 µm tube is drawn, not judged

    // The donors' TTF is f / rate; trbc's is 4 pi f / rate (first row 8.068529, 0.062906).
    const ValidationDataSet ttf = validationDataSet(kValidationData, "ttf_4pi_f_over_rate");
    EXPECT_EQ(ttf.etaOutMPaS, 28.9);
    const ExperimentalPoints t = readValidationData(ttf);
    EXPECT_NEAR(t.x[0], 8.068529, 1e-12);
    EXPECT_NEAR(t.y[0][0], 4.0 * M_PI * 0.062906, 1e-12);
    // Hochmuth's velocities are in mm/s (first row 0.035111 mm/s), trbc's in cm/s.
    const ValidationDataSet h = validationDataSet(kValidationData, "length_um", "Hochmuth et al. 1970 (6.7 µm tube)");
    EXPECT_FALSE(h.judged);
    EXPECT_NEAR(readValidationData(h).x[0], 0.0035111, 1e-15);
    EXPECT_EQ(validationDataSet(kValidationData, "length_um").yColumns, (std::vector<std::string>{"l", "l_high", "l_low"}));

    ASSERT_TRUE(inclinationDataSet(kValidationData, 55.9));
    EXPECT_EQ(inclinationDataSet(kValidationData, 55.9)->file.filename(), "Fisher2015_eta_55.9_mPa_s.csv");
    EXPECT_FALSE(inclinationDataSet(kValidationData, 30.0));

    // A directory without the data: no sets, and a named set is an error naming its file.
    TempDir empty;
    EXPECT_TRUE(validationDataSets(empty.path()).empty());
    try {
        validationDataSet(empty.path(), "velocity_cm_per_s");
        FAIL() << "no error";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("Tomaiuolo2009_pg_v_6.6um.csv"), std::string::npos) << e.what();
    }
    EXPECT_THROW(validationDataSet(kValidationData, "swing_deg"), InputError);
}

}  // namespace
}  // namespace trbc
