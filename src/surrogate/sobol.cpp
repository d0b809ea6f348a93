#include "surrogate/sobol.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <random>
#include <string>

#include "core/error.hpp"
#include "sampling/sobol_sequence.hpp"

namespace trbc {

namespace {

using Eigen::Index;
using Eigen::MatrixXd;
using Eigen::VectorXd;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

void validateOptions(const SobolOptions& opt) {
    if (opt.nBase < 2)
        throw InputError("sobol: option nBase = " + std::to_string(opt.nBase) + " is out of range; valid: N >= 2");
    if (opt.resamples != 0 && opt.resamples < 2)
        throw InputError("sobol: option resamples = " + std::to_string(opt.resamples) +
                         " is out of range; valid: 0 (no intervals) or R >= 2");
    if (!(opt.z > 0) || !std::isfinite(opt.z))
        throw InputError("sobol: option z = " + std::to_string(opt.z) + " is out of range; valid: finite z > 0");
    if (opt.batchSize < 0)
        throw InputError("sobol: option batchSize = " + std::to_string(opt.batchSize) +
                         " is out of range; valid: 0 (one call) or >= 1");
    if (opt.sobolSkip < -1)
        throw InputError("sobol: option sobolSkip = " + std::to_string(opt.sobolSkip) +
                         " is out of range; valid: -1 (auto) or >= 0");
}

void validateBox(const VectorXd& lo, const VectorXd& hi) {
    if (lo.size() < 1 || lo.size() != hi.size())
        throw InputError("sobol: input box needs lo and hi of equal length >= 1 (got " + std::to_string(lo.size()) +
                         " and " + std::to_string(hi.size()) + ")");
    for (Index i = 0; i < lo.size(); ++i)
        if (!std::isfinite(lo[i]) || !std::isfinite(hi[i]) || !(lo[i] < hi[i]))
            throw InputError("sobol: input box of input " + std::to_string(i + 1) + " is [" + std::to_string(lo[i]) +
                             ", " + std::to_string(hi[i]) + "]; valid: finite lo < hi");
}

// SplitMix64 (Steele, Lea & Flood 2014) finaliser: decorrelates the per-replicate seeds.
std::uint64_t splitmix64(std::uint64_t x) {
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
}

// Uniform double in [0, 1) from the top 53 bits (portable, unlike uniform_real_distribution).
double uniform01(std::mt19937_64& gen) { return static_cast<double>(gen() >> 11) * 0x1p-53; }

// Uniform integer in [0, n) by rejection (no modulo bias; portable).
std::uint64_t uniformBelow(std::mt19937_64& gen, std::uint64_t n) {
    const std::uint64_t limit = std::numeric_limits<std::uint64_t>::max() - (std::numeric_limits<std::uint64_t>::max() % n + 1) % n;
    std::uint64_t x = gen();
    while (x > limit) x = gen();
    return x % n;
}

// Base sample u in [0,1)^(N x 2D).
MatrixXd baseSample(Index n, Index d, const SobolOptions& opt) {
    if (opt.base == SobolBase::Sobol) {
        if (2 * d > SobolSequence::kMaxDimensions)
            throw InputError("sobol: the Sobol' base sample needs 2D = " + std::to_string(2 * d) +
                             " dimensions; valid: D <= " + std::to_string(SobolSequence::kMaxDimensions / 2) +
                             " inputs (use the pseudo-random base for more)");
        const std::uint64_t skip = opt.sobolSkip >= 0 ? static_cast<std::uint64_t>(opt.sobolSkip)
                                                       : std::bit_ceil(static_cast<std::uint64_t>(n));
        SobolSequence seq(static_cast<int>(2 * d), skip);
        return seq.next(n);
    }
    std::mt19937_64 gen(opt.seed);
    MatrixXd U(n, 2 * d);
    for (Index k = 0; k < n; ++k)
        for (Index j = 0; j < 2 * d; ++j) U(k, j) = uniform01(gen);
    return U;
}

// Point estimates of one standardised output. F is N x blocks: column b holds block b of the
// design (at the base rows chosen by the caller). docs/CAMPAIGN_AND_SURROGATE.md, Sobol' indices:
//   V    = population variance of the 2N values {f_A, f_B}
//   S_i  = (1/N) sum_k f_B,k (f_AB,k^(i) - f_A,k) / V                         (Saltelli 2010)
//   ST_i = (1/2N) sum_k (f_A,k - f_AB,k^(i))^2 / V                             (Jansen 1999)
//   S_ij = (1/N) sum_k (f_BA,k^(i) f_AB,k^(j) - f_A,k f_B,k) / V - S_i - S_j   (Saltelli 2002)
struct Estimates {
    VectorXd S1, ST;
    MatrixXd S2;  // symmetric, diagonal 0; empty without second order
};

Estimates estimate(const Eigen::Ref<const MatrixXd>& F, const SaltelliDesign& dsg) {
    const Index n = F.rows(), d = dsg.d;
    const auto fA = F.col(0).array();
    const auto fB = F.col(dsg.blockB()).array();
    const double mean = (fA.sum() + fB.sum()) / static_cast<double>(2 * n);
    const double V = ((fA - mean).square().sum() + (fB - mean).square().sum()) / static_cast<double>(2 * n);

    Estimates e;
    e.S1.resize(d);
    e.ST.resize(d);
    for (Index i = 0; i < d; ++i) {
        const auto fAB = F.col(dsg.blockAB(i)).array();
        e.S1[i] = (fB * (fAB - fA)).mean() / V;
        e.ST[i] = 0.5 * (fA - fAB).square().mean() / V;
    }
    if (dsg.secondOrder) {
        e.S2 = MatrixXd::Zero(d, d);
        const double meanAB = (fA * fB).mean();
        for (Index i = 0; i < d; ++i)
            for (Index j = i + 1; j < d; ++j) {
                const double Vij = ((F.col(dsg.blockBA(i)).array() * F.col(dsg.blockAB(j)).array()).mean() - meanAB) / V;
                e.S2(i, j) = e.S2(j, i) = Vij - e.S1[i] - e.S1[j];
            }
    }
    return e;
}

// Each output standardised over all design rows: (y - mean) / SD (divisor = rows). A constant
// output becomes NaN (its indices are undefined).
MatrixXd standardise(const MatrixXd& Y) {
    MatrixXd Z(Y.rows(), Y.cols());
    for (Index o = 0; o < Y.cols(); ++o) {
        const double mean = Y.col(o).mean();
        const double sd = std::sqrt((Y.col(o).array() - mean).square().mean());
        if (sd > 0)
            Z.col(o) = (Y.col(o).array() - mean) / sd;
        else
            Z.col(o).setConstant(kNaN);
    }
    return Z;
}

void checkFinite(const SaltelliDesign& dsg, const MatrixXd& Y, const std::vector<std::string>& outputs) {
    for (Index o = 0; o < Y.cols(); ++o)
        for (Index r = 0; r < Y.rows(); ++r)
            if (!std::isfinite(Y(r, o)))
                throw NumericalError("sobol: model output '" + outputs[o] + "' is not finite (" + std::to_string(Y(r, o)) +
                                     ") at design row " + std::to_string(r) + " (block " + std::to_string(r / dsg.n) +
                                     ", base row " + std::to_string(r % dsg.n) + ")");
}

std::vector<std::string> defaultNames(std::vector<std::string> names, Index count, const char* prefix, const char* what) {
    if (names.empty()) {
        for (Index i = 0; i < count; ++i) names.push_back(prefix + std::to_string(i + 1));
        return names;
    }
    if (static_cast<Index>(names.size()) != count)
        throw InputError(std::string("sobol: ") + what + " names: got " + std::to_string(names.size()) + ", expected " +
                         std::to_string(count));
    return names;
}

// Half-widths z * SD (divisor R-1) of the replicates reps[r] (all of one shape), element-wise.
MatrixXd halfWidth(const std::vector<MatrixXd>& reps, double z) {
    const double R = static_cast<double>(reps.size());
    MatrixXd mean = MatrixXd::Zero(reps[0].rows(), reps[0].cols());
    for (const MatrixXd& m : reps) mean += m;
    mean /= R;
    MatrixXd ss = MatrixXd::Zero(mean.rows(), mean.cols());
    for (const MatrixXd& m : reps) ss.array() += (m - mean).array().square();
    return z * (ss / (R - 1)).cwiseSqrt();
}

}  // namespace

MatrixXd SaltelliDesign::points() const {
    MatrixXd X(rows(), d);
    X.middleRows(0, n) = A;
    for (Index i = 0; i < d; ++i) {
        auto AB = X.middleRows(blockAB(i) * n, n);
        AB = A;
        AB.col(i) = B.col(i);
        if (secondOrder) {
            auto BA = X.middleRows(blockBA(i) * n, n);
            BA = B;
            BA.col(i) = A.col(i);
        }
    }
    X.middleRows(blockB() * n, n) = B;
    return X;
}

SaltelliDesign saltelliDesign(const VectorXd& lo, const VectorXd& hi, const SobolOptions& opt) {
    validateOptions(opt);
    validateBox(lo, hi);
    SaltelliDesign dsg;
    dsg.n = opt.nBase;
    dsg.d = lo.size();
    dsg.secondOrder = opt.secondOrder;
    const MatrixXd U = baseSample(dsg.n, dsg.d, opt);
    // x = lo + u (hi - lo), per column.
    const Eigen::RowVectorXd l = lo.transpose(), w = (hi - lo).transpose();
    dsg.A = (U.leftCols(dsg.d).array().rowwise() * w.array()).rowwise() + l.array();
    dsg.B = (U.rightCols(dsg.d).array().rowwise() * w.array()).rowwise() + l.array();
    return dsg;
}

SobolResult sobolIndices(const SaltelliDesign& dsg, const MatrixXd& Y, const SobolOptions& opt,
                         std::vector<std::string> inputNames, std::vector<std::string> outputNames) {
    validateOptions(opt);
    if (Y.rows() != dsg.rows() || Y.cols() < 1)
        throw InputError("sobol: model values have " + std::to_string(Y.rows()) + " x " + std::to_string(Y.cols()) +
                         "; valid: design rows (" + std::to_string(dsg.rows()) + ") x outputs (>= 1)");
    const Index n = dsg.n, d = dsg.d, nOut = Y.cols(), blocks = dsg.blocks();

    SobolResult res;
    res.inputs = defaultNames(std::move(inputNames), d, "x", "input");
    res.outputs = defaultNames(std::move(outputNames), nOut, "y", "output");
    res.nBase = n;
    res.evaluations = dsg.rows();
    res.resamples = opt.resamples;
    checkFinite(dsg, Y, res.outputs);
    const MatrixXd Z = standardise(Y);

    res.S1.resize(nOut, d);
    res.ST.resize(nOut, d);
    for (Index o = 0; o < nOut; ++o) {
        // Column o of Z is the blocks stacked: as an N x blocks matrix it is F of estimate().
        const Eigen::Map<const MatrixXd> F(Z.col(o).data(), n, blocks);
        Estimates e = estimate(F, dsg);
        res.S1.row(o) = e.S1.transpose();
        res.ST.row(o) = e.ST.transpose();
        if (dsg.secondOrder) res.S2.push_back(std::move(e.S2));
    }

    res.S1_ci = MatrixXd::Zero(nOut, d);
    res.ST_ci = MatrixXd::Zero(nOut, d);
    if (dsg.secondOrder) res.S2_ci.assign(static_cast<std::size_t>(nOut), MatrixXd::Zero(d, d));
    if (opt.resamples == 0) return res;

    // Bootstrap: replicate r draws N base rows with replacement from its own stream, and
    // re-estimates every output with the same rows of all blocks.
    const int R = opt.resamples;
    std::vector<MatrixXd> s1Rep(R), stRep(R), s2Rep(R);  // nOut x d, nOut x d, nOut x d*d
#pragma omp parallel for schedule(dynamic)
    for (int r = 0; r < R; ++r) {
        std::mt19937_64 gen(splitmix64(opt.seed ^ splitmix64(static_cast<std::uint64_t>(r) + 1)));
        std::vector<Index> rows(static_cast<std::size_t>(n));
        for (Index& k : rows) k = static_cast<Index>(uniformBelow(gen, static_cast<std::uint64_t>(n)));
        s1Rep[r].resize(nOut, d);
        stRep[r].resize(nOut, d);
        if (dsg.secondOrder) s2Rep[r].resize(nOut, d * d);
        MatrixXd F(n, blocks);
        for (Index o = 0; o < nOut; ++o) {
            for (Index b = 0; b < blocks; ++b)
                for (Index k = 0; k < n; ++k) F(k, b) = Z(b * n + rows[k], o);
            const Estimates e = estimate(F, dsg);
            s1Rep[r].row(o) = e.S1.transpose();
            stRep[r].row(o) = e.ST.transpose();
            if (dsg.secondOrder) s2Rep[r].row(o) = e.S2.reshaped().transpose();
        }
    }
    res.S1_ci = halfWidth(s1Rep, opt.z);
    res.ST_ci = halfWidth(stRep, opt.z);
    if (dsg.secondOrder) {
        const MatrixXd s2ci = halfWidth(s2Rep, opt.z);
        for (Index o = 0; o < nOut; ++o) res.S2_ci[o] = s2ci.row(o).reshaped(d, d);
    }
    return res;
}

MatrixXd evaluateInBatches(const SobolModel& model, const MatrixXd& X, Index batchSize) {
    if (batchSize < 0)
        throw InputError("sobol: option batchSize = " + std::to_string(batchSize) +
                         " is out of range; valid: 0 (one call) or >= 1");
    const Index rows = X.rows();
    const Index batch = batchSize == 0 ? rows : batchSize;
    MatrixXd Y;
    for (Index start = 0; start < rows; start += batch) {
        const Index m = std::min(batch, rows - start);
        const MatrixXd Yb = model(X.middleRows(start, m));
        if (Yb.rows() != m || Yb.cols() < 1 || (start > 0 && Yb.cols() != Y.cols()))
            throw InputError("sobol: the model returned " + std::to_string(Yb.rows()) + " x " + std::to_string(Yb.cols()) +
                             " values for a batch of " + std::to_string(m) + " points; valid: " + std::to_string(m) +
                             " rows and the same number (>= 1) of outputs on every call");
        if (start == 0) Y.resize(rows, Yb.cols());
        Y.middleRows(start, m) = Yb;
    }
    return Y;
}

SobolResult sobolAnalysis(const SobolModel& model, const VectorXd& lo, const VectorXd& hi, const SobolOptions& opt,
                          std::vector<std::string> inputNames, std::vector<std::string> outputNames) {
    const SaltelliDesign dsg = saltelliDesign(lo, hi, opt);
    const MatrixXd Y = evaluateInBatches(model, dsg.points(), opt.batchSize);
    return sobolIndices(dsg, Y, opt, std::move(inputNames), std::move(outputNames));
}

}  // namespace trbc
