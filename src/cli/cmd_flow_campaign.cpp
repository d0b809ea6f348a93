// trbc flow campaign: the shear-flow campaign (flow/shear_campaign.hpp, docs/FLOW_CAMPAIGN.md).
// Parses, then runs the library's three phases on the ranks of cli/campaign_ranks.hpp.
#include <fmt/format.h>

#include <algorithm>
#include <iostream>
#include <memory>
#include <sstream>

#include "cli/campaign_ranks.hpp"
#include "cli/common.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "flow/shear_campaign.hpp"
#include "flow/steady_rule_study.hpp"

namespace trbc::cli {
namespace {

struct FlowCampaignCli {
    ShearCampaignOptions c;
    std::string design = "sobol", start = "random", out, inject, steadyRule;
    CacheOptions cache;
};

/// "FIRST_TURN,ANGLE_DEG,TTF" (for example 4,0.1,0.005) as a SteadyStopRule; validateSteadyRule checks
/// the ranges (a NaN or an infinity among them too).
SteadyStopRule parseSteadyRule(const std::string& text, const std::string& option) {
    const std::vector<double> v = parseNumberList(text, option, "FIRST_TURN,ANGLE_DEG,TTF, for example 4,0.1,0.005");
    if (v.size() != 3)
        throw InputError(fmt::format("{}: '{}' has {} numbers, 3 expected: FIRST_TURN,ANGLE_DEG,TTF (for example 4,0.1,0.005)", option, text,
                                     v.size()));
    return {v[0], v[1], v[2]};
}

void runFlowCampaign(FlowCampaignCli& o) {
    ShearCampaignOptions c = o.c;
    c.design = parseDesignKind(o.design);
    if (o.start != "random" && o.start != "in-plane")
        throw InputError(fmt::format("--start: '{}' is not a start (valid: random, in-plane)", o.start));
    c.randomStart = o.start == "random";
    if (!o.steadyRule.empty()) {
        if (c.fullLength) throw InputError("--steady-rule: a --full-length campaign stops no case; give one or the other");
        c.steadyRule = parseSteadyRule(o.steadyRule, "--steady-rule");
    }
    c.outDir = o.out;
    c.command = commandLine();
    c.cacheDir = cacheDirectory(o.cache);
    setProvenanceSeed(c.seed);
    if (!o.inject.empty()) for (long id : parseIntegerList(o.inject, "--inject-failures", "a case id", 0)) c.injectFailures.insert(id);
    runCampaignCommand(c, {"flow campaign", "cases", "cases", "cases.csv"}, c.cases, prepareShearCampaign, runShearCampaignShare,
                       finalizeShearCampaign);
}

}  // namespace

void registerFlowCampaign(CLI::App* flow) {
    auto o = std::make_shared<FlowCampaignCli>();
    CLI::App* cmd = flow->add_subcommand(
        "campaign",
        "Shear-flow campaign (docs/FLOW_CAMPAIGN.md): a design over the cell (v, mu, FvK, b2, eta_m) and the flow (eta_out, "
        "shear stress), one shear case per point at --level, started by --start and stopped at the steady state; one CSV row "
        "per case (regime, inclination_deg, swing_deg, ttf_4pi_f_over_rate with their uncertainties, turns, status, reason, "
        "wall_s) in OUT/cases.csv, provenance in OUT/campaign.json. Checkpoints every case; --resume continues a killed run "
        "or grows a sobol/uniform design to more --cases. Under MPI (mpirun -n P trbc flow campaign ...) the cases are shared "
        "between ranks");
    addNumber(cmd, "--cases", o->c.cases, "number of cases", NumberRange::closed(1, 1e7))->capture_default_str();
    cmd->add_option("--design", o->design,
                    "sobol (shifted Sobol' sequence: space-filling, and any prefix is a smaller design), uniform (i.i.d.) or lhs")
        ->capture_default_str();
    addNumber(cmd, "--seed", o->c.seed, "seed of the design, the shift and the random starts", NumberRange::nonNegative())
        ->capture_default_str();
    addNumber(cmd, "--level", o->c.level, "icosphere level of the cell mesh", NumberRange::closed(1, 5))->capture_default_str();
    addNumber(cmd, "--rotations", o->c.maxRotations,
              "longest run, rigid-sphere turns 4 pi / rate; a case stops earlier once steady (--steady-rule), except with --full-length",
              NumberRange::closed(5, 1000))
        ->capture_default_str();
    cmd->add_option("--start", o->start,
                    "random: the ensemble protocol's start (random orientation and thermal l = 2, 3 undulations at 293.15 K, "
                    "seeded per case); in-plane: the disc in the shear plane")
        ->capture_default_str();
    cmd->add_option("--steady-rule", o->steadyRule,
                    fmt::format("FIRST_TURN,ANGLE_DEG,TTF: a case is steady at the first whole turn >= FIRST_TURN whose observables agree "
                                "with those one turn earlier, angle and swing within ANGLE_DEG and the TTF within the fraction TTF "
                                "(default {:g},{:g},{:g}; docs/FLOW_CAMPAIGN.md, stop rule)",
                                SteadyStopRule{}.minRotations, SteadyStopRule{}.angleToleranceDeg, SteadyStopRule{}.ttfTolerance));
    cmd->add_flag("--full-length", o->c.fullLength,
                  "run every case all --rotations (whole turns) and record, per turn, what a run stopped there would "
                  "report, in OUT/by_turn/ (for `trbc flow steady-rules`)");
    addNumber(cmd, "--eta-in", o->c.etaIn, "cytosol viscosity", NumberRange::leftOpen(0, 1e6, "mPa s"))->capture_default_str();
    addThreadsOption(cmd, o->c.threads, "cases run concurrently (one thread each)");
    addOutOption(cmd, o->out);
    cmd->add_flag("--resume", o->c.resume, "continue the campaign in --out (same settings; a larger --cases grows a sobol or uniform design)");
    cmd->add_option("--inject-failures", o->inject, "comma-separated case ids that fail on purpose (to test failure records)");
    addCacheOptions(cmd, o->cache);
    cmd->callback([o]() { runFlowCampaign(*o); });

    auto rules = std::make_shared<std::pair<std::string, std::vector<std::string>>>();
    CLI::App* study = flow->add_subcommand(
        "steady-rules",
        "What steady-state stop rules cost and change (docs/FLOW_CAMPAIGN.md, stop rule): each --rule applied to the turn-by-turn "
        "observables of a `trbc flow campaign --full-length` run; prints per rule the turns run, the share of the full runs' cost, "
        "the regimes changed and the angle, swing and TTF at the stop against the full runs (Markdown)");
    study->add_option("--campaign", rules->first, "a `trbc flow campaign --full-length` directory")->required();
    study->add_option("--rule", rules->second, "FIRST_TURN,ANGLE_DEG,TTF (repeatable; default: the campaign's default rule)");
    study->callback([rules]() {
        std::vector<SteadyStopRule> list;
        const std::vector<FullLengthCase> cases = readFullLengthCases(rules->first);
        int lastTurn = 0;
        for (const FullLengthCase& c : cases) lastTurn = std::max(lastTurn, c.turns.back().turn);
        for (const std::string& r : rules->second) list.push_back(parseSteadyRule(r, "--rule"));
        if (list.empty()) list.push_back(SteadyStopRule{});
        for (const SteadyStopRule& r : list) validateSteadyRule(r, lastTurn, "--rule");
        std::vector<SteadyRuleEffect> effects;
        for (const SteadyStopRule& r : list) effects.push_back(steadyRuleEffect(cases, r));
        std::cout << steadyRuleStudyTitle(rules->first, cases.size()) << "\n\n" << steadyRuleTable(effects);
    });
}

}  // namespace trbc::cli
