// The stop-rule study (flow/steady_rule_study.hpp) on hand-made turn records with known answers:
// where each rule stops, what that costs, and how the observables at the stop differ from the
// full run's; the records' file round trip and its errors; the study's title.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "core/error.hpp"
#include "flow/steady_rule_study.hpp"
#include "test_support.hpp"

namespace trbc {
namespace {

namespace fs = std::filesystem;

TurnRecord turn(int k, ShearRegime regime, double angle, double swing, double ttf) {
    TurnRecord r;
    r.turn = k;
    r.steps = 10L * k;
    r.gmresIterations = 100L * k;
    r.rule.regime = regime;
    r.rule.inclinationDeg = angle;
    r.rule.swingAmplitudeDeg = swing;
    r.rule.ttf.defined = std::isfinite(ttf);
    r.rule.ttf4piFOverRate = ttf;
    r.stop = r.rule;
    r.stop.inclinationDeg += 0.001;  // the stopped run sees a frame more than the rule
    return r;
}

/// Case 0 tank-treads and settles: from turn k - 1 to k the angle changes by 2, 1, 0.5, 0.25, 0.12, 0.06,
/// 0.03, 0.015 deg (k = 3..10; 20 deg at turn 2, 16.07 at 8, 16.025 at 10; swing and TTF fixed);
/// case 1 tumbles from turn 2; case 2 never settles (intermittent). Turns 2-10 are recorded.
std::vector<FullLengthCase> cases() {
    constexpr auto TT = ShearRegime::TankTreading;
    FullLengthCase settling{0, {}}, tumbling{1, {}}, never{2, {}};
    double angle = 20.0;
    const double steps[] = {0.0, 0.0, 2.0, 1.0, 0.5, 0.25, 0.12, 0.06, 0.03, 0.015};  // [k - 1]
    for (int k = 2; k <= 10; ++k) {
        angle -= steps[k - 1];
        settling.turns.push_back(turn(k, TT, angle, 5.0, 0.4));
        tumbling.turns.push_back(turn(k, ShearRegime::Tumbling, 0.0, 0.0, NAN));
        never.turns.push_back(turn(k, ShearRegime::Intermittent, 0.0, 0.0, NAN));
    }
    return {settling, tumbling, never};
}

TEST(SteadyRuleStudy, EachRuleStopsWhereItsTolerancesAreFirstMet) {
    const std::vector<FullLengthCase> c = cases();
    // The default rule (from turn 4, 0.1 deg, 0.5 %): case 0 at turn 8, case 1 at 4, case 2 runs to 10.
    const SteadyRuleEffect d = steadyRuleEffect(c, {});
    EXPECT_EQ(d.cases, 3);
    EXPECT_EQ(d.stopped, 2);
    EXPECT_DOUBLE_EQ(d.meanTurns, (8.0 + 4.0 + 10.0) / 3.0);
    EXPECT_DOUBLE_EQ(d.costFraction, (8.0 + 4.0 + 10.0) / 30.0);  // iterations proportional to the turn
    EXPECT_EQ(d.regimeChanged, 0);
    EXPECT_EQ(d.tankTreading, 1);
    EXPECT_NEAR(d.angleRmsDeg, 0.045, 1e-12);  // 16.071 against 16.026: what the runs report
    EXPECT_NEAR(d.angleMaxDeg, 0.045, 1e-12);
    EXPECT_EQ(d.swingMaxDeg, 0.0);
    EXPECT_EQ(d.ttfRelMax, 0.0);
    // A looser rule from turn 3 (0.6 deg): case 0 at 5 (16.5 deg), case 1 at 3.
    const SteadyRuleEffect loose = steadyRuleEffect(c, {3.0, 0.6, 0.01});
    EXPECT_DOUBLE_EQ(loose.meanTurns, (5.0 + 3.0 + 10.0) / 3.0);
    EXPECT_NEAR(loose.angleMaxDeg, 0.475, 1e-12);
    // A TTF that moves by 1 % per turn holds case 0 under the default rule to the end.
    std::vector<FullLengthCase> drifting = c;
    for (TurnRecord& t : drifting[0].turns) t.rule.ttf4piFOverRate = 0.4 * std::pow(1.01, t.turn);
    EXPECT_EQ(steadyRuleEffect(drifting, {}).stopped, 1);
    EXPECT_NEAR(steadyRuleEffect(drifting, {}).ttfRelMax, 0.0, 1e-15);
    // A rule that starts after the last turn of every case stops none and counts none.
    EXPECT_EQ(steadyRuleEffect(c, {11.0, 0.1, 0.005}).cases, 0);
    // A regime that changes after the stop is counted.
    std::vector<FullLengthCase> flips = c;
    flips[1].turns.back().stop.regime = ShearRegime::Intermittent;
    EXPECT_EQ(steadyRuleEffect(flips, {}).regimeChanged, 1);
    // Only successive turns are compared: without turn 8, case 0 has no pair within 0.1 deg before its
    // last record and runs to turn 10.
    std::vector<FullLengthCase> gap = c;
    gap[0].turns.erase(gap[0].turns.begin() + 6);  // turns 2..10: index 6 is turn 8
    const SteadyRuleEffect g = steadyRuleEffect(gap, {});
    EXPECT_EQ(g.stopped, 1);
    EXPECT_DOUBLE_EQ(g.meanTurns, (10.0 + 4.0 + 10.0) / 3.0);
    // Agreement only between the last two records is the full run, not a stop.
    std::vector<FullLengthCase> late = c;
    for (std::size_t k = 1; k + 1 < late[0].turns.size(); ++k) late[0].turns[k].rule.inclinationDeg = 20.0 + double(k);
    late[0].turns[8].rule.inclinationDeg = late[0].turns[7].rule.inclinationDeg;  // turn 10 equals turn 9
    EXPECT_EQ(steadyRuleEffect(late, {}).stopped, 1);
    SteadyRuleEffect none = steadyRuleEffect(c, {11.0, 0.1, 0.005});
    EXPECT_NE(steadyRuleTable({none}).find("| 11, 0.1, 0.5 % | 0 | 0 | – | – | 0 | 0 | – | – | – |"), std::string::npos)
        << steadyRuleTable({none});
    EXPECT_NE(test::inputError([] { validateSteadyRule({1.0, 0.1, 0.005}, 10, "--rule"); })
                  .find("--rule 1,0.1,0.005: the first turn must be in [2, 10]"),
              std::string::npos);
    EXPECT_NE(test::inputError([] { validateSteadyRule({4.0, -1.0, 0.005}, 10, "--rule"); }).find("angle tolerance in (0, 10] deg"),
              std::string::npos);
    const std::string table = steadyRuleTable({d, loose});
    EXPECT_NE(table.find("| 4, 0.1, 0.5 % | 3 | 2 | 7.33 | 73 % | 0 | 1 | 0.045 / 0.045 |"), std::string::npos) << table;
}

TEST(SteadyRuleStudy, RecordsRoundTripAndBadFilesAreNamed) {
    test::TempDir dir;
    const std::vector<FullLengthCase> c = cases();
    for (const FullLengthCase& k : c)
        test::writeText(dir.path() / "by_turn" / ("case" + std::to_string(k.caseId) + ".json"), turnRecordsJson(k.caseId, k.turns).dump());
    const std::vector<FullLengthCase> back = readFullLengthCases(dir.path());
    ASSERT_EQ(back.size(), 3u);
    EXPECT_EQ(back[1].caseId, 1);
    EXPECT_FALSE(back[1].turns[0].rule.ttf.defined);  // null TTF
    EXPECT_EQ(back[0].turns[3].stop.inclinationDeg, c[0].turns[3].stop.inclinationDeg);
    const SteadyRuleEffect a = steadyRuleEffect(c, {}), b = steadyRuleEffect(back, {});
    EXPECT_EQ(a.meanTurns, b.meanTurns);
    EXPECT_EQ(a.angleMaxDeg, b.angleMaxDeg);

    // A NaN (a failed fit) is written as null and read back as NaN.
    std::vector<TurnRecord> nan = c[0].turns;
    nan[2].stop.inclinationDeg = NAN;
    test::writeText(dir.path() / "by_turn" / "case0.json", turnRecordsJson(0, nan).dump());
    EXPECT_TRUE(std::isnan(readFullLengthCases(dir.path())[0].turns[2].stop.inclinationDeg));

    const fs::path bad = dir.path() / "by_turn" / "case7.json";
    test::writeText(bad, R"({"case": 7, "turns": [{"turn": 1}]})");
    EXPECT_NE(test::inputError([&] { readFullLengthCases(dir.path()); }).find("case7.json: not a by-turn record"), std::string::npos);
    test::writeText(bad, turnRecordsJson(8, c[0].turns).dump());
    EXPECT_NE(test::inputError([&] { readFullLengthCases(dir.path()); }).find("case7.json: holds case 8"), std::string::npos);
    test::writeText(bad, turnRecordsJson(7, {}).dump());
    EXPECT_NE(test::inputError([&] { readFullLengthCases(dir.path()); }).find("case7.json: no turns"), std::string::npos);
    std::vector<TurnRecord> backwards = c[0].turns;
    std::swap(backwards[1], backwards[2]);
    test::writeText(bad, turnRecordsJson(7, backwards).dump());
    EXPECT_NE(test::inputError([&] { readFullLengthCases(dir.path()); }).find("turns must increase"), std::string::npos);
    test::TempDir empty;
    EXPECT_NE(test::inputError([&] { readFullLengthCases(empty.path()); }).find("--full-length"), std::string::npos);
}

TEST(SteadyRuleStudy, TitleNamesTheCampaignsSettingsNotItsPath) {
    test::TempDir dir;
    const fs::path campaign = dir.path() / "full_length";
    fs::create_directories(campaign);
    EXPECT_EQ(steadyRuleStudyTitle(campaign / "", 3), "3 full-length cases of full_length");
    test::writeText(campaign / "campaign.json",
                    R"({"settings": {"level": 3, "design": "sobol", "seed": 20261129, "max_rotations": 10.0}})");
    EXPECT_EQ(steadyRuleStudyTitle(campaign, 72), "72 full-length cases (level 3, design sobol, seed 20261129, 10 turns)");
    test::writeText(campaign / "campaign.json", R"({"settings": {"level": "three"}})");
    EXPECT_EQ(steadyRuleStudyTitle(campaign, 72), "72 full-length cases of full_length");
}

}  // namespace
}  // namespace trbc
