// The seed sweep behind the Monte-Carlo tolerances of tests/inference/test_tmcmc.cpp: TMCMC and
// BASIS on the verification problems with known answers (tests/inference/tmcmc_verification.hpp),
// 16 seeds each, one line per problem and settings with the mean +- SD over the seeds of
//   logZ err           log Z-hat - log Z
//   max mean err/sd    max_i |mean_i - exact_i| / exact sd_i
//   max cov err        max_ij |cov_ij - exact_ij| / sqrt(exact_ii exact_jj)
// and the mean time of a run; T3 (bimodal) gives the fraction of samples in the theta_0 < 0 mode
// (exact 0.3) and T5 (unknown noise) the error of E[s] instead. Minutes on 2 cores (T3 the most).
//   build/bench_tmcmc_seed_sweep [GROUP...]   GROUP: T1 T2 T3 T4 T5 half variants (default: all)
// A group runs when an argument contains its name ("T1,T4" selects two); without arguments the
// environment variable SWEEP selects the same way.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "tmcmc_verification.hpp"

using namespace trbc;
using namespace trbc::tmcmc_verification;

namespace {

constexpr int kSeeds = 16;
const std::vector<std::string> kGroups{"T1", "T2", "T3", "T4", "T5", "half", "variants"};

/// Mean and sample SD (divisor n - 1) of `x`.
struct MeanSd {
    double mean = 0, sd = 0;
};
MeanSd meanSd(const std::vector<double>& x) {
    MeanSd r;
    for (double v : x) r.mean += v;
    r.mean /= static_cast<double>(x.size());
    for (double v : x) r.sd += (v - r.mean) * (v - r.mean);
    r.sd = std::sqrt(r.sd / static_cast<double>(x.size() - 1));
    return r;
}

/// One line: the errors of `v` over seeds 1000, 1001, ... with the options `options(seed)`.
void sweep(const std::string& label, const Verification& v, const std::function<TmcmcOptions(std::uint64_t)>& options) {
    std::vector<double> z, m, c, t;
    for (int s = 0; s < kSeeds; ++s) {
        const std::uint64_t seed = 1000 + static_cast<std::uint64_t>(s);
        TmcmcResult r;
        const Errors e = runAndCompare(v, options(seed), &r);
        if (!r.completed || r.exponent != 1.0)
            throw std::runtime_error(fmt::format("{} {} seed {}: the run ended at exponent {} before 1", v.name, label, seed, r.exponent));
        z.push_back(e.logZ), m.push_back(e.mean), c.push_back(e.cov), t.push_back(e.seconds);
    }
    const MeanSd Z = meanSd(z), M = meanSd(m), C = meanSd(c), T = meanSd(t);
    std::printf("%s %s: logZ err %+.4f +- %.4f | max mean err/sd %.4f +- %.4f | max cov err %.4f +- %.4f | %.3f s\n",
                v.name.c_str(), label.c_str(), Z.mean, Z.sd, M.mean, M.sd, C.mean, C.sd, T.mean);
    std::fflush(stdout);
}

void sweep(const Verification& v, Variant var, int N, int burnIn) {
    sweep(fmt::format("{} N={} B={}", variantName(var), N, burnIn), v,
          [&](std::uint64_t seed) { return settings(var, N, seed, burnIn); });
}

/// T3 over seeds 2000, 2001, ...: the weight of the theta_0 < 0 mode and the log-evidence error.
void sweepBimodal(Variant var, int N, int burnIn) {
    std::vector<double> f, z;
    const Verification v = bimodal();
    for (int s = 0; s < kSeeds; ++s) {
        const TmcmcResult r = runTmcmc(v.problem, settings(var, N, 2000 + static_cast<std::uint64_t>(s), burnIn));
        f.push_back(fractionNegative(r));
        z.push_back(r.logEvidence - v.logZ);
    }
    const MeanSd F = meanSd(f), Z = meanSd(z);
    std::printf("T3 %s N=%d B=%d: fraction %.4f +- %.4f | logZ err %+.4f +- %.4f\n", variantName(var), N, burnIn, F.mean, F.sd,
                Z.mean, Z.sd);
    std::fflush(stdout);
}

/// T5 (BASIS, N = 4000, 2 burn-in steps) over seeds 3000, 3001, ...: the errors of log Z and E[s].
void sweepUnknownNoise() {
    const Verification v = unknownNoise();
    std::vector<double> z, m;
    for (int s = 0; s < kSeeds; ++s) {
        const TmcmcResult r = runTmcmc(v.problem, settings(Variant::Basis, 4000, 3000 + static_cast<std::uint64_t>(s), 2));
        z.push_back(r.logEvidence - v.logZ);
        m.push_back(r.samples.row(2).mean() - v.mean[2]);
    }
    const MeanSd Z = meanSd(z), M = meanSd(m);
    std::printf("T5 BASIS N=4000 B=2: logZ err %+.4f +- %.4f | E[s] err %+.5f +- %.5f\n", Z.mean, Z.sd, M.mean, M.sd);
    std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
    // The filter: the arguments joined, else SWEEP, else every group.
    std::string filter;
    bool all = true;
    if (argc > 1) {
        all = false;
        for (int i = 1; i < argc; ++i) {
            const std::string a = argv[i];
            bool known = false;
            for (const auto& g : kGroups) known = known || a.find(g) != std::string::npos;
            if (!known) {
                std::fprintf(stderr, "bench_tmcmc_seed_sweep: '%s' names no group (valid: T1 T2 T3 T4 T5 half variants)\n", a.c_str());
                return 2;
            }
            filter += a + " ";
        }
    } else if (const char* e = std::getenv("SWEEP")) {
        all = false;
        filter = e;
    }
    auto selected = [&](const char* group) { return all || filter.find(group) != std::string::npos; };

    try {
        for (Variant var : {Variant::Basis, Variant::Tmcmc}) {
            if (selected("T1")) sweep(gaussian1D(), var, 2000, 0);
            if (selected("T2")) sweep(gaussian5D(), var, 4000, 0);
            if (selected("T2")) sweep(gaussian5D(), var, 4000, 2);
            if (selected("T4")) sweep(regression(), var, 3000, 0);
            if (selected("half")) sweep(halfNormal(), var, 2000, 0);
            if (selected("T3")) sweepBimodal(var, 5000, 2);
            if (selected("T3")) sweepBimodal(var, 20000, 2);
        }
        if (selected("variants")) {
            sweep("L=5", regression(), [](std::uint64_t s) {
                auto o = settings(Variant::Basis, 3000, s);
                o.maxChainLength = 5;
                return o;
            });
            sweep("BASIS 6.3 covariance", regression(), [](std::uint64_t s) {
                auto o = settings(Variant::Basis, 3000, s);
                o.proposalCovariance = ProposalCovariance::SelectionCounts;
                return o;
            });
            sweep("library defaults, burn-in {0,3,1}", gaussian1D(), [](std::uint64_t s) {
                TmcmcOptions o;
                o.populationSize = 2000;
                o.seed = s;
                o.burnIn = {0, 3, 1};
                return o;
            });
        }
        if (selected("T5")) sweepUnknownNoise();
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench_tmcmc_seed_sweep: %s\n", e.what());
        return 1;
    }
    return 0;
}
