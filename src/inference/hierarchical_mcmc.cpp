#include "inference/hierarchical_mcmc.hpp"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>

#include "core/error.hpp"
#include "inference/population.hpp"
#include "inference/priors.hpp"

namespace trbc {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
const double kHalfLog2Pi = 0.5 * std::log(2.0 * std::numbers::pi);
const double kInvSqrt2Pi = 1.0 / std::sqrt(2.0 * std::numbers::pi);

enum StreamPurpose : std::uint64_t { kStart = 11, kSweep = 12 };

/// Mean and variance of the standard normal restricted to [alpha, beta], alpha >= 0 (upper tail),
/// with Q(x) = e^{-x^2/2} R(x) (R = scaledNormalTail) so that e^{-alpha^2/2} cancels.
void upperTailMoments(double alpha, double beta, double& mean, double& variance) {
    const double e = std::isinf(beta) ? 0.0 : std::exp(-0.5 * (beta - alpha) * (beta + alpha));
    const double D = scaledNormalTail(alpha) - (std::isinf(beta) ? 0.0 : scaledNormalTail(beta) * e);
    const double phiDiff = kInvSqrt2Pi * (1.0 - e);
    const double xphiDiff = kInvSqrt2Pi * (alpha - (std::isinf(beta) ? 0.0 : beta * e));
    mean = phiDiff / D;
    variance = 1.0 + xphiDiff / D - mean * mean;
}

}  // namespace

double truncatedNormalLogDensity(double x, double m, double s, double lo, double hi) {
    if (!(x >= lo && x <= hi)) return -kInf;
    const double z = (x - m) / s;
    double logZ = 0.0;
    if (std::isfinite(lo) || std::isfinite(hi)) logZ = logNormalMass((lo - m) / s, (hi - m) / s);
    return -0.5 * z * z - std::log(s) - kHalfLog2Pi - logZ;
}

TruncatedMoments truncatedNormalMoments(double m, double s, double a, double b) {
    TruncatedMoments t;
    double alpha = (a - m) / s, beta = (b - m) / s;
    t.logMass = logNormalMass(alpha, beta);
    double mean = 0.0, var = 1.0;
    if (beta - alpha < 1e-6) {  // so narrow that the density is flat across it
        mean = 0.5 * (alpha + beta);
        var = (beta - alpha) * (beta - alpha) / 12.0;
    } else if (alpha >= 0.0) {
        upperTailMoments(alpha, beta, mean, var);
    } else if (beta <= 0.0) {
        upperTailMoments(-beta, -alpha, mean, var);
        mean = -mean;
    } else {
        const double Z = std::exp(t.logMass);
        const double pa = std::isinf(alpha) ? 0.0 : normalPdf(alpha), pb = std::isinf(beta) ? 0.0 : normalPdf(beta);
        const double xa = std::isinf(alpha) ? 0.0 : alpha * pa, xb = std::isinf(beta) ? 0.0 : beta * pb;
        mean = (pa - pb) / Z;
        var = 1.0 + (xa - xb) / Z - mean * mean;
    }
    t.mean = m + s * mean;
    t.variance = s * s * std::max(var, 0.0);
    return t;
}

double truncatedNormalCdf(double x, double m, double s, double a, double b) {
    if (x <= a) return 0.0;
    if (x >= b) return 1.0;
    const double alpha = (a - m) / s, beta = (b - m) / s, z = (x - m) / s;
    return std::clamp(std::exp(logNormalMass(alpha, z) - logNormalMass(alpha, beta)), 0.0, 1.0);
}

namespace {

using Clock = std::chrono::steady_clock;

/// A random-walk block: proposal = exp(logScale) * L xi, L the Cholesky factor of the current
/// covariance estimate; Robbins-Monro on logScale during warm-up.
struct Block {
    Eigen::MatrixXd L;
    double logScale = 0.0;
    double target = 0.25;
    long long proposed = 0, accepted = 0;  // after warm-up

    void setCovariance(const Eigen::MatrixXd& C) {
        const Eigen::Index d = C.rows();
        Eigen::MatrixXd S = 0.5 * (C + C.transpose());
        double scale = S.diagonal().mean();
        if (!(scale > 0.0) || !std::isfinite(scale)) scale = 1.0;
        for (double eps = 0.0; eps <= 1.0; eps = eps == 0.0 ? 1e-10 : eps * 10.0) {
            Eigen::LLT<Eigen::MatrixXd> llt(S + eps * scale * Eigen::MatrixXd::Identity(d, d));
            if (llt.info() == Eigen::Success) {
                L = llt.matrixL();
                return;
            }
        }
        L = std::sqrt(scale) * Eigen::MatrixXd::Identity(d, d);
    }
    Eigen::VectorXd propose(Rng& rng) const {
        Eigen::VectorXd xi(L.rows());
        for (Eigen::Index i = 0; i < xi.size(); ++i) xi[i] = rng.normal();
        Eigen::VectorXd step = L.triangularView<Eigen::Lower>() * xi;
        return std::exp(logScale) * step;
    }
    /// Robbins-Monro step after a sweep with acceptance rate `rate` over the chains.
    void adapt(double rate, int sweep) { logScale += std::pow(sweep + 10.0, -0.6) * (rate - target); }
};

/// Covariance of the columns of x (divisor K - 1); identity-scaled fallback for too few columns.
Eigen::MatrixXd sampleCovariance(const Eigen::MatrixXd& x) {
    const Eigen::Index d = x.rows(), K = x.cols();
    if (K < 2) return Eigen::MatrixXd::Identity(d, d);
    const Eigen::VectorXd mean = x.rowwise().mean();
    const Eigen::MatrixXd c = x.colwise() - mean;
    return c * c.transpose() / static_cast<double>(K - 1);
}

/// z = log y for the group's log variables, y otherwise.
Eigen::VectorXd toWalk(const HierarchicalGroup& g, Eigen::VectorXd y) {
    for (int i : g.logVariables) y[i] = std::log(y[i]);
    return y;
}
Eigen::VectorXd fromWalk(const HierarchicalGroup& g, Eigen::VectorXd z) {
    for (int i : g.logVariables) z[i] = std::exp(z[i]);
    return z;
}

struct ChainState {
    Eigen::VectorXd psi;
    std::vector<Eigen::VectorXd> y;
    std::vector<double> ll, support;
};

class Sampler {
public:
    Sampler(const HierarchicalModel& model, const HierarchicalMcmcOptions& opt) : m_(model), o_(opt) {
        P_ = static_cast<int>(m_.population.size());
        G_ = static_cast<int>(m_.groups.size());
        seenBy_.assign(static_cast<std::size_t>(P_), 0);
        for (const HierarchicalGroup& g : m_.groups)
            for (int j : g.pooled) ++seenBy_[static_cast<std::size_t>(j)];
    }

    HierarchicalMcmcResult run() {
        const auto t0 = Clock::now();
        const int C = o_.chains;
        initialise();
        HierarchicalMcmcResult r;
        r.hyper.assign(static_cast<std::size_t>(C), Eigen::MatrixXd(2 * P_, o_.draws));
        r.group.assign(static_cast<std::size_t>(G_), {});
        r.logLikelihood.assign(static_cast<std::size_t>(G_), {});
        for (int g = 0; g < G_; ++g) {
            r.group[static_cast<std::size_t>(g)].assign(static_cast<std::size_t>(C), Eigen::MatrixXd(dim(g), o_.draws));
            r.logLikelihood[static_cast<std::size_t>(g)].assign(static_cast<std::size_t>(C), Eigen::VectorXd(o_.draws));
        }
        const int total = o_.warmup + o_.draws * o_.thin;
        // Covariance re-estimates from the second half of each warm-up window.
        std::vector<int> milestones;
        for (double f : {0.2, 0.4, 0.7}) milestones.push_back(static_cast<int>(f * o_.warmup));
        std::vector<std::vector<Eigen::VectorXd>> windowY(static_cast<std::size_t>(G_));
        std::vector<std::vector<Eigen::Vector2d>> windowHyper(static_cast<std::size_t>(P_));
        int windowStart = 0;
        for (int sweep = 0; sweep < total; ++sweep) {
            const bool warm = sweep < o_.warmup;
            for (int g = 0; g < G_; ++g)
                for (int k = 0; k < o_.groupSteps * m_.groups[static_cast<std::size_t>(g)].stepsPerSweep; ++k) groupMove(g, sweep, warm);
            for (int j = 0; j < P_; ++j) {
                for (int k = 0; k < o_.hyperSteps; ++k) hyperMove(j, sweep, warm);
                if (o_.locationScaleMoves && seenBy_[static_cast<std::size_t>(j)] > 0) {
                    componentMove(j, true, sweep, warm);
                    componentMove(j, false, sweep, warm);
                }
            }
            if (warm) {
                if (!milestones.empty() && sweep >= (windowStart + milestones.front()) / 2) {  // the window's second half
                    for (int g = 0; g < G_; ++g)
                        for (const ChainState& s : state_)
                            windowY[static_cast<std::size_t>(g)].push_back(toWalk(m_.groups[static_cast<std::size_t>(g)], s.y[static_cast<std::size_t>(g)]));
                    for (const ChainState& s : state_)
                        for (int j = 0; j < P_; ++j) windowHyper[static_cast<std::size_t>(j)].push_back({s.psi[2 * j], s.psi[2 * j + 1]});
                }
                if (!milestones.empty() && sweep + 1 == milestones.front()) {
                    updateCovariances(windowY, windowHyper);
                    windowStart = milestones.front();
                    milestones.erase(milestones.begin());
                }
            } else if ((sweep - o_.warmup + 1) % o_.thin == 0) {
                const int d = (sweep - o_.warmup) / o_.thin;
                for (int c = 0; c < C; ++c) {
                    const ChainState& s = state_[static_cast<std::size_t>(c)];
                    r.hyper[static_cast<std::size_t>(c)].col(d) = s.psi;
                    for (int g = 0; g < G_; ++g) {
                        r.group[static_cast<std::size_t>(g)][static_cast<std::size_t>(c)].col(d) = s.y[static_cast<std::size_t>(g)];
                        r.logLikelihood[static_cast<std::size_t>(g)][static_cast<std::size_t>(c)][d] = s.ll[static_cast<std::size_t>(g)];
                    }
                }
            }
            if (o_.progress && (sweep + 1) % std::max(1, total / 10) == 0)
                o_.progress(fmt::format("hierarchical MCMC: sweep {} of {} ({} warm-up), {:.1f} s", sweep + 1, total, o_.warmup,
                                        std::chrono::duration<double>(Clock::now() - t0).count()));
        }
        auto rate = [](const Block& b) { return b.proposed ? static_cast<double>(b.accepted) / static_cast<double>(b.proposed) : 0.0; };
        for (const Block& b : groupBlocks_) r.groupAcceptance.push_back(rate(b));
        for (const Block& b : hyperBlocks_) r.hyperAcceptance.push_back(rate(b));
        auto pooledRate = [&](const std::vector<Block>& v) {
            long long a = 0, p = 0;
            for (const Block& b : v) a += b.accepted, p += b.proposed;
            return p ? static_cast<double>(a) / static_cast<double>(p) : 0.0;
        };
        r.shiftAcceptance = pooledRate(shift_);
        r.scaleAcceptance = pooledRate(scale_);
        r.likelihoodEvaluations = evaluations_;
        r.wallSeconds = std::chrono::duration<double>(Clock::now() - t0).count();
        return r;
    }

private:
    const HierarchicalModel& m_;
    HierarchicalMcmcOptions o_;
    int P_ = 0, G_ = 0;
    std::vector<int> seenBy_;
    std::vector<ChainState> state_;
    std::vector<Rng> rng_;
    std::vector<Block> groupBlocks_, hyperBlocks_;
    std::vector<Block> shift_, scale_;  // per component
    long long evaluations_ = 0;

    Eigen::Index dim(int g) const { return static_cast<Eigen::Index>(m_.groups[static_cast<std::size_t>(g)].names.size()); }

    static Eigen::MatrixXd toMatrix(const std::vector<Eigen::VectorXd>& v) {
        Eigen::MatrixXd x(v.empty() ? 0 : v[0].size(), static_cast<Eigen::Index>(v.size()));
        for (std::size_t k = 0; k < v.size(); ++k) x.col(static_cast<Eigen::Index>(k)) = v[k];
        return x;
    }

    bool hyperInPrior(const Eigen::VectorXd& psi) const {
        for (int j = 0; j < P_; ++j) {
            const PopulationComponent& p = m_.population[static_cast<std::size_t>(j)];
            if (!(psi[2 * j] >= p.meanLo && psi[2 * j] <= p.meanHi && psi[2 * j + 1] >= p.sdLo && psi[2 * j + 1] <= p.sdHi)) return false;
        }
        return true;
    }

    /// sum over the group's pooled variables of log TN(x; m_j, s_j).
    double populationTerm(int g, const Eigen::VectorXd& psi, const Eigen::VectorXd& y) const {
        const HierarchicalGroup& G = m_.groups[static_cast<std::size_t>(g)];
        double s = 0.0;
        for (std::size_t k = 0; k < G.pooled.size(); ++k) {
            const int j = G.pooled[k];
            const PopulationComponent& p = m_.population[static_cast<std::size_t>(j)];
            s += truncatedNormalLogDensity(y[static_cast<Eigen::Index>(k)], psi[2 * j], psi[2 * j + 1], p.lo, p.hi);
        }
        return s;
    }

    /// l_g of the columns of `batch` (one call), checked for NaN.
    Eigen::VectorXd likelihood(int g, const Eigen::MatrixXd& batch) {
        if (batch.cols() == 0) return Eigen::VectorXd();
        const HierarchicalGroup& G = m_.groups[static_cast<std::size_t>(g)];
        Eigen::VectorXd l = G.batchLogLikelihood(batch);
        if (l.size() != batch.cols())
            throw InputError(fmt::format("hierarchical MCMC: group {} returned {} log-likelihoods for {} candidates", G.name, l.size(), batch.cols()));
        for (Eigen::Index i = 0; i < l.size(); ++i)
            if (std::isnan(l[i]) || l[i] == kInf)
                throw NumericalError(fmt::format("hierarchical MCMC: the log-likelihood of group {} is {} at a candidate", G.name, l[i]));
        evaluations_ += batch.cols();
        return l;
    }

    void initialise() {
        const int C = o_.chains;
        state_.assign(static_cast<std::size_t>(C), ChainState{});
        rng_.clear();
        for (int c = 0; c < C; ++c) rng_.emplace_back(o_.seed, kSweep, static_cast<std::uint64_t>(c));
        groupBlocks_.assign(static_cast<std::size_t>(G_), Block{});
        for (int g = 0; g < G_; ++g) {
            const HierarchicalGroup& G = m_.groups[static_cast<std::size_t>(g)];
            const double d = static_cast<double>(dim(g));
            Eigen::MatrixXd z(G.start.rows(), G.start.cols());
            for (Eigen::Index k = 0; k < G.start.cols(); ++k) z.col(k) = toWalk(G, G.start.col(k));
            groupBlocks_[static_cast<std::size_t>(g)].setCovariance(2.38 * 2.38 / d * sampleCovariance(z));
        }
        hyperBlocks_.assign(static_cast<std::size_t>(P_), Block{});
        shift_.assign(static_cast<std::size_t>(P_), Block{});
        scale_.assign(static_cast<std::size_t>(P_), Block{});
        for (int j = 0; j < P_; ++j) {
            const PopulationComponent& p = m_.population[static_cast<std::size_t>(j)];
            Eigen::Matrix2d c = Eigen::Matrix2d::Zero();
            c(0, 0) = std::pow(0.05 * (p.meanHi - p.meanLo), 2);
            c(1, 1) = std::pow(0.05 * (p.sdHi - p.sdLo), 2);
            hyperBlocks_[static_cast<std::size_t>(j)].setCovariance(c);
            shift_[static_cast<std::size_t>(j)].setCovariance(Eigen::MatrixXd::Constant(1, 1, std::pow(0.02 * (p.meanHi - p.meanLo), 2)));
            scale_[static_cast<std::size_t>(j)].setCovariance(Eigen::MatrixXd::Constant(1, 1, 0.1 * 0.1));
            shift_[static_cast<std::size_t>(j)].target = scale_[static_cast<std::size_t>(j)].target = 0.44;  // one-dimensional
        }

        for (int c = 0; c < C; ++c) {
            ChainState& s = state_[static_cast<std::size_t>(c)];
            Rng rng(o_.seed, kStart, static_cast<std::uint64_t>(c));
            s.y.resize(static_cast<std::size_t>(G_));
            s.ll.assign(static_cast<std::size_t>(G_), -kInf);
            s.support.assign(static_cast<std::size_t>(G_), -kInf);
            for (int attempt = 0;; ++attempt) {
                if (attempt == 200)
                    throw NumericalError(fmt::format("hierarchical MCMC: no starting point with a finite density for chain {} in 200 tries", c));
                for (int g = 0; g < G_; ++g) {
                    const HierarchicalGroup& G = m_.groups[static_cast<std::size_t>(g)];
                    if (G.start.cols() == 0) throw InputError(fmt::format("hierarchical MCMC: group {} has no starting points", G.name));
                    const auto k = static_cast<Eigen::Index>(rng() % static_cast<std::uint64_t>(G.start.cols()));
                    s.y[static_cast<std::size_t>(g)] = G.start.col(k);
                }
                // psi: m_j near the groups' values, s_j spread over its hyper-prior range.
                s.psi.resize(2 * P_);
                for (int j = 0; j < P_; ++j) {
                    const PopulationComponent& p = m_.population[static_cast<std::size_t>(j)];
                    double sum = 0.0, n = 0.0;
                    for (int g = 0; g < G_; ++g) {
                        const HierarchicalGroup& G = m_.groups[static_cast<std::size_t>(g)];
                        for (std::size_t k = 0; k < G.pooled.size(); ++k)
                            if (G.pooled[k] == j) sum += s.y[static_cast<std::size_t>(g)][static_cast<Eigen::Index>(k)], n += 1.0;
                    }
                    const double centre = n > 0 ? sum / n : 0.5 * (p.meanLo + p.meanHi);
                    s.psi[2 * j] = std::clamp(centre + 0.05 * (p.meanHi - p.meanLo) * rng.normal(), p.meanLo, p.meanHi);
                    s.psi[2 * j + 1] = p.sdLo + (p.sdHi - p.sdLo) * std::pow(rng.uniform(), 2.0);
                }
                bool ok = true;
                for (int g = 0; g < G_ && ok; ++g) {
                    const HierarchicalGroup& G = m_.groups[static_cast<std::size_t>(g)];
                    s.support[static_cast<std::size_t>(g)] = G.logSupport(s.y[static_cast<std::size_t>(g)]);
                    ok = s.support[static_cast<std::size_t>(g)] > -kInf && populationTerm(g, s.psi, s.y[static_cast<std::size_t>(g)]) > -kInf;
                    for (int i : G.logVariables) ok = ok && s.y[static_cast<std::size_t>(g)][i] > 0.0;  // the walk runs on log y
                }
                if (!ok) continue;
                for (int g = 0; g < G_ && ok; ++g) {
                    s.ll[static_cast<std::size_t>(g)] = likelihood(g, s.y[static_cast<std::size_t>(g)])[0];
                    ok = s.ll[static_cast<std::size_t>(g)] > -kInf;
                }
                if (ok) break;
            }
        }
    }

    void groupMove(int g, int sweep, bool warm) {
        const int C = o_.chains;
        const HierarchicalGroup& G = m_.groups[static_cast<std::size_t>(g)];
        Block& b = groupBlocks_[static_cast<std::size_t>(g)];
        std::vector<Eigen::VectorXd> prop(static_cast<std::size_t>(C));
        std::vector<double> sup(static_cast<std::size_t>(C)), logU(static_cast<std::size_t>(C)), logJacobian(static_cast<std::size_t>(C), 0.0);
        std::vector<int> live;
        for (int c = 0; c < C; ++c) {
            ChainState& s = state_[static_cast<std::size_t>(c)];
            Rng& rng = rng_[static_cast<std::size_t>(c)];
            const Eigen::VectorXd& y0 = s.y[static_cast<std::size_t>(g)];
            prop[static_cast<std::size_t>(c)] = fromWalk(G, toWalk(G, y0) + b.propose(rng));
            for (int i : G.logVariables) logJacobian[static_cast<std::size_t>(c)] += std::log(prop[static_cast<std::size_t>(c)][i] / y0[i]);
            logU[static_cast<std::size_t>(c)] = std::log(rng.uniformOpen());
            sup[static_cast<std::size_t>(c)] = G.logSupport(prop[static_cast<std::size_t>(c)]);
            if (sup[static_cast<std::size_t>(c)] > -kInf) live.push_back(c);
        }
        Eigen::MatrixXd batch(dim(g), static_cast<Eigen::Index>(live.size()));
        for (std::size_t i = 0; i < live.size(); ++i) batch.col(static_cast<Eigen::Index>(i)) = prop[static_cast<std::size_t>(live[i])];
        const Eigen::VectorXd l = likelihood(g, batch);
        int accepted = 0;
        for (std::size_t i = 0; i < live.size(); ++i) {
            const int c = live[i];
            ChainState& s = state_[static_cast<std::size_t>(c)];
            const Eigen::VectorXd& y1 = prop[static_cast<std::size_t>(c)];
            const double lNew = l[static_cast<Eigen::Index>(i)];
            if (!(lNew > -kInf)) continue;
            const double pNew = populationTerm(g, s.psi, y1);
            if (!(pNew > -kInf)) continue;
            const double pOld = populationTerm(g, s.psi, s.y[static_cast<std::size_t>(g)]);
            const double logRatio = logJacobian[static_cast<std::size_t>(c)] + (pNew + sup[static_cast<std::size_t>(c)] + lNew) -
                                    (pOld + s.support[static_cast<std::size_t>(g)] + s.ll[static_cast<std::size_t>(g)]);
            if (logU[static_cast<std::size_t>(c)] < logRatio) {
                s.y[static_cast<std::size_t>(g)] = y1;
                s.ll[static_cast<std::size_t>(g)] = lNew;
                s.support[static_cast<std::size_t>(g)] = sup[static_cast<std::size_t>(c)];
                ++accepted;
            }
        }
        tally(b, accepted, C, sweep, warm);
    }

    void tally(Block& b, int accepted, int proposed, int sweep, bool warm) {
        if (warm) {
            b.adapt(static_cast<double>(accepted) / proposed, sweep);
        } else {
            b.accepted += accepted;
            b.proposed += proposed;
        }
    }

    /// sum over every group's variables of component j of log TN(x; m, s).
    double componentTerm(const ChainState& st, int j, double m, double s) const {
        const PopulationComponent& p = m_.population[static_cast<std::size_t>(j)];
        double sum = 0.0;
        for (int g = 0; g < G_; ++g) {
            const HierarchicalGroup& G = m_.groups[static_cast<std::size_t>(g)];
            for (std::size_t k = 0; k < G.pooled.size(); ++k)
                if (G.pooled[k] == j) sum += truncatedNormalLogDensity(st.y[static_cast<std::size_t>(g)][static_cast<Eigen::Index>(k)], m, s, p.lo, p.hi);
        }
        return sum;
    }

    void hyperMove(int j, int sweep, bool warm) {
        const int C = o_.chains;
        Block& b = hyperBlocks_[static_cast<std::size_t>(j)];
        const PopulationComponent& p = m_.population[static_cast<std::size_t>(j)];
        int accepted = 0;
        for (int c = 0; c < C; ++c) {
            ChainState& s = state_[static_cast<std::size_t>(c)];
            Rng& rng = rng_[static_cast<std::size_t>(c)];
            const Eigen::VectorXd d = b.propose(rng);
            const double logU = std::log(rng.uniformOpen());
            const double m1 = s.psi[2 * j] + d[0], s1 = s.psi[2 * j + 1] + d[1];
            if (!(m1 >= p.meanLo && m1 <= p.meanHi && s1 >= p.sdLo && s1 <= p.sdHi)) continue;
            const double logRatio = componentTerm(s, j, m1, s1) - componentTerm(s, j, s.psi[2 * j], s.psi[2 * j + 1]);
            if (logU < logRatio) {
                s.psi[2 * j] = m1;
                s.psi[2 * j + 1] = s1;
                ++accepted;
            }
        }
        tally(b, accepted, C, sweep, warm);
    }

    /// Shift (m_j += d, x_gj += d) or scale (s_j *= e^c, x_gj = m_j + (x_gj - m_j) e^c, Jacobian
    /// e^{c (n_j + 1)}) of component j; the groups that see j are re-evaluated (one batch each).
    void componentMove(int j, bool shift, int sweep, bool warm) {
        const int C = o_.chains;
        Block& b = (shift ? shift_ : scale_)[static_cast<std::size_t>(j)];
        std::vector<int> affected;
        for (int g = 0; g < G_; ++g) {
            const auto& pooled = m_.groups[static_cast<std::size_t>(g)].pooled;
            if (std::find(pooled.begin(), pooled.end(), j) != pooled.end()) affected.push_back(g);
        }
        std::vector<ChainState> prop(static_cast<std::size_t>(C));
        std::vector<double> logU(static_cast<std::size_t>(C)), logJacobian(static_cast<std::size_t>(C), 0.0);
        std::vector<char> alive(static_cast<std::size_t>(C), 0);
        const PopulationComponent& p = m_.population[static_cast<std::size_t>(j)];
        for (int c = 0; c < C; ++c) {
            const ChainState& s = state_[static_cast<std::size_t>(c)];
            Rng& rng = rng_[static_cast<std::size_t>(c)];
            const double d = b.propose(rng)[0];
            logU[static_cast<std::size_t>(c)] = std::log(rng.uniformOpen());
            ChainState q = s;
            const double m = s.psi[2 * j];
            if (shift) q.psi[2 * j] += d;
            else q.psi[2 * j + 1] *= std::exp(d);
            logJacobian[static_cast<std::size_t>(c)] = shift ? 0.0 : d * (seenBy_[static_cast<std::size_t>(j)] + 1);
            bool ok = q.psi[2 * j] >= p.meanLo && q.psi[2 * j] <= p.meanHi && q.psi[2 * j + 1] >= p.sdLo && q.psi[2 * j + 1] <= p.sdHi;
            for (int g : affected) {
                if (!ok) break;
                const HierarchicalGroup& G = m_.groups[static_cast<std::size_t>(g)];
                Eigen::VectorXd& y = q.y[static_cast<std::size_t>(g)];
                for (std::size_t k = 0; k < G.pooled.size(); ++k)
                    if (G.pooled[k] == j) {
                        const auto i = static_cast<Eigen::Index>(k);
                        y[i] = shift ? y[i] + d : m + (y[i] - m) * std::exp(d);
                    }
                q.support[static_cast<std::size_t>(g)] = G.logSupport(y);
                ok = q.support[static_cast<std::size_t>(g)] > -kInf;
            }
            alive[static_cast<std::size_t>(c)] = ok;
            prop[static_cast<std::size_t>(c)] = std::move(q);
        }
        for (int g : affected) {
            std::vector<int> live;
            for (int c = 0; c < C; ++c)
                if (alive[static_cast<std::size_t>(c)]) live.push_back(c);
            Eigen::MatrixXd batch(dim(g), static_cast<Eigen::Index>(live.size()));
            for (std::size_t i = 0; i < live.size(); ++i) batch.col(static_cast<Eigen::Index>(i)) = prop[static_cast<std::size_t>(live[i])].y[static_cast<std::size_t>(g)];
            const Eigen::VectorXd l = likelihood(g, batch);
            for (std::size_t i = 0; i < live.size(); ++i) {
                const int c = live[i];
                prop[static_cast<std::size_t>(c)].ll[static_cast<std::size_t>(g)] = l[static_cast<Eigen::Index>(i)];
                if (!(l[static_cast<Eigen::Index>(i)] > -kInf)) alive[static_cast<std::size_t>(c)] = 0;
            }
        }
        int accepted = 0;
        for (int c = 0; c < C; ++c) {
            if (!alive[static_cast<std::size_t>(c)]) continue;
            ChainState& s = state_[static_cast<std::size_t>(c)];
            const ChainState& q = prop[static_cast<std::size_t>(c)];
            // Only component j's population terms and the affected groups change.
            double logRatio = logJacobian[static_cast<std::size_t>(c)] + componentTerm(q, j, q.psi[2 * j], q.psi[2 * j + 1]) -
                              componentTerm(s, j, s.psi[2 * j], s.psi[2 * j + 1]);
            for (int g : affected) {
                const auto gi = static_cast<std::size_t>(g);
                logRatio += q.support[gi] + q.ll[gi] - s.support[gi] - s.ll[gi];
            }
            if (logU[static_cast<std::size_t>(c)] < logRatio) {
                s = q;
                ++accepted;
            }
        }
        tally(b, accepted, C, sweep, warm);
    }

    void updateCovariances(std::vector<std::vector<Eigen::VectorXd>>& windowY, std::vector<std::vector<Eigen::Vector2d>>& windowHyper) {
        for (int g = 0; g < G_; ++g) {
            const Eigen::MatrixXd w = toMatrix(windowY[static_cast<std::size_t>(g)]);
            if (w.cols() > 2 * w.rows()) {
                Block& b = groupBlocks_[static_cast<std::size_t>(g)];
                b.setCovariance(2.38 * 2.38 / static_cast<double>(w.rows()) * sampleCovariance(w));
                b.logScale = 0.0;
            }
            windowY[static_cast<std::size_t>(g)].clear();
        }
        for (int j = 0; j < P_; ++j) {
            auto& w = windowHyper[static_cast<std::size_t>(j)];
            if (w.size() > 4) {
                Eigen::MatrixXd x(2, static_cast<Eigen::Index>(w.size()));
                for (std::size_t k = 0; k < w.size(); ++k) x.col(static_cast<Eigen::Index>(k)) = w[k];
                Block& b = hyperBlocks_[static_cast<std::size_t>(j)];
                b.setCovariance(2.38 * 2.38 / 2.0 * sampleCovariance(x));
                b.logScale = 0.0;
            }
            w.clear();
        }
    }
};

}  // namespace

void validateHierarchicalMcmcOptions(const HierarchicalMcmcOptions& o) {
    if (o.chains < 2) throw InputError(fmt::format("hierarchical MCMC: chains = {} is invalid: must be >= 2 (R-hat compares chains)", o.chains));
    if (o.warmup < 50) throw InputError(fmt::format("hierarchical MCMC: warmup = {} is invalid: must be >= 50 sweeps", o.warmup));
    if (o.draws < 8) throw InputError(fmt::format("hierarchical MCMC: draws = {} is invalid: must be >= 8 per chain", o.draws));
    if (o.groupSteps < 1) throw InputError(fmt::format("hierarchical MCMC: groupSteps = {} is invalid: must be >= 1", o.groupSteps));
    if (o.thin < 1) throw InputError(fmt::format("hierarchical MCMC: thin = {} is invalid: must be >= 1", o.thin));
    if (o.hyperSteps < 1) throw InputError(fmt::format("hierarchical MCMC: hyperSteps = {} is invalid: must be >= 1", o.hyperSteps));
}

namespace {

void validate(const HierarchicalModel& m, const HierarchicalMcmcOptions& o) {
    validateHierarchicalMcmcOptions(o);
    if (m.population.empty() || m.groups.empty()) throw InputError("hierarchical MCMC: the model has no population or no groups");
    for (const PopulationComponent& p : m.population)
        if (!(p.meanLo < p.meanHi && p.sdLo > 0.0 && p.sdLo < p.sdHi && p.lo < p.hi))
            throw InputError(fmt::format("hierarchical MCMC: component {} has invalid bounds", p.name));
    for (const HierarchicalGroup& g : m.groups) {
        if (g.pooled.size() > g.names.size() || !g.logSupport || !g.batchLogLikelihood)
            throw InputError(fmt::format("hierarchical MCMC: group {} is incomplete", g.name));
        for (int j : g.pooled)
            if (j < 0 || j >= static_cast<int>(m.population.size()))
                throw InputError(fmt::format("hierarchical MCMC: group {} sees component {}, which does not exist", g.name, j));
        if (g.start.rows() != static_cast<Eigen::Index>(g.names.size()))
            throw InputError(fmt::format("hierarchical MCMC: the starting points of group {} have {} rows, expected {}", g.name,
                                         g.start.rows(), g.names.size()));
    }
}

}  // namespace

HierarchicalMcmcResult runHierarchicalMcmc(const HierarchicalModel& model, const HierarchicalMcmcOptions& options) {
    validate(model, options);
    return Sampler(model, options).run();
}

}  // namespace trbc
