#include "flow/shear_observables.hpp"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>
#include <numeric>

#include "core/error.hpp"

namespace trbc {
namespace {

constexpr double kPi = std::numbers::pi;

/// Periodogram peak frequency of y(t) (mean removed), frequencies k / (t_end - t_0 + dt),
/// k = 1..N/2, with parabolic interpolation of the peak; columns of Y are independent series.
Eigen::VectorXd periodogramPeaks(const std::vector<double>& t, const Eigen::MatrixXd& Y) {
    const Eigen::Index n = Y.rows(), m = Y.cols();
    Eigen::VectorXd out = Eigen::VectorXd::Zero(m);
    if (n < 4) return out;
    const double span = (t.back() - t.front()) * static_cast<double>(n) / static_cast<double>(n - 1);
    const Eigen::Index kmax = n / 2;
    Eigen::MatrixXcd E(kmax, n);
    for (Eigen::Index k = 1; k <= kmax; ++k) {
        const double f = static_cast<double>(k) / span;
        for (Eigen::Index j = 0; j < n; ++j) E(k - 1, j) = std::polar(1.0, -2.0 * kPi * f * (t[j] - t.front()));
    }
    Eigen::MatrixXd centred = Y.rowwise() - Y.colwise().mean();
    const Eigen::MatrixXd P = (E * centred.cast<std::complex<double>>()).cwiseAbs2();
    for (Eigen::Index c = 0; c < m; ++c) {
        Eigen::Index k = 0;
        P.col(c).maxCoeff(&k);
        double shift = 0.0;
        if (k > 0 && k + 1 < kmax) {
            const double a = P(k - 1, c), b = P(k, c), d = P(k + 1, c);
            const double den = a - 2.0 * b + d;
            if (den < 0.0) shift = std::clamp(0.5 * (a - d) / den, -0.5, 0.5);
        }
        out[c] = (static_cast<double>(k + 1) + shift) / span;
    }
    return out;
}

}  // namespace

double inclinationAngle(const Vertices& X) {
    const Eigen::Vector2d c = X.topRows<2>().rowwise().mean();
    // Second moments summed in vertex order (what Eigen's reductions over these strided rows do;
    // written out because GCC 12 warns falsely inside them on a baseline x86-64 build).
    double sxx = 0.0, syy = 0.0, sxy = 0.0;
    for (Eigen::Index j = 0; j < X.cols(); ++j) {
        const double x = X(0, j) - c.x(), y = X(1, j) - c.y();
        sxx += x * x;
        syy += y * y;
        sxy += x * y;
    }
    // Leading eigenvector of [[sxx, sxy], [sxy, syy]] (= leading right-singular vector of Y^T).
    double theta = 0.5 * std::atan2(2.0 * sxy, sxx - syy);  // (-pi/2, pi/2]
    if (theta <= -0.5 * kPi) theta += kPi;
    return theta;
}

SinusoidFit fitSinusoid(const std::vector<double>& t, const std::vector<double>& y, double frequency0) {
    if (t.size() != y.size() || t.size() < 4)
        throw InputError(fmt::format("sinusoid fit: {} times and {} values (need equal sizes >= 4)", t.size(), y.size()));
    const std::size_t n = t.size();
    const double mean = std::accumulate(y.begin(), y.end(), 0.0) / static_cast<double>(n);
    const auto [lo, hi] = std::minmax_element(y.begin(), y.end());
    Eigen::Vector4d p(mean, 0.5 * (*hi - *lo), frequency0, 0.0);
    auto residual = [&](const Eigen::Vector4d& q, Eigen::VectorXd& r, Eigen::MatrixXd* J) {
        r.resize(static_cast<Eigen::Index>(n));
        if (J) J->resize(static_cast<Eigen::Index>(n), 4);
        for (std::size_t k = 0; k < n; ++k) {
            const double psi = 2.0 * kPi * q[2] * t[k] + q[3];
            const double c = std::cos(psi), s = std::sin(psi);
            r[k] = q[0] + q[1] * c - y[k];
            if (J) (*J).row(k) << 1.0, c, -q[1] * s * 2.0 * kPi * t[k], -q[1] * s;
        }
        return 0.5 * r.squaredNorm();
    };
    Eigen::VectorXd r, rTrial;
    Eigen::MatrixXd J;
    double cost = residual(p, r, &J);
    double damping = 1e-3;
    SinusoidFit fit;
    const double scale = std::max(1e-300, 0.5 * y.size() * (std::pow(*hi - *lo, 2) + mean * mean));
    for (int it = 0; it < 500; ++it) {
        fit.iterations = it + 1;
        const Eigen::Matrix4d JtJ = J.transpose() * J;
        const Eigen::Vector4d g = J.transpose() * r;
        bool improved = false;
        for (int tries = 0; tries < 30 && !improved; ++tries) {
            Eigen::Matrix4d A = JtJ;
            A.diagonal() += damping * (JtJ.diagonal().array() + 1e-12 * JtJ.diagonal().maxCoeff()).matrix();
            const Eigen::Vector4d dp = A.ldlt().solve(-g);
            if (!dp.allFinite()) {
                damping *= 10.0;
                continue;
            }
            const Eigen::Vector4d q = p + dp;
            const double c2 = residual(q, rTrial, nullptr);
            if (c2 < cost) {
                const double drop = cost - c2;
                p = q;
                cost = residual(p, r, &J);
                damping = std::max(1e-12, damping / 3.0);
                improved = true;
                if (drop <= 1e-14 * scale || dp.cwiseAbs().maxCoeff() <= 1e-12 * (1.0 + p.cwiseAbs().maxCoeff())) {
                    fit.converged = true;
                }
            } else {
                damping *= 4.0;
            }
        }
        if (!improved) {  // no descent possible: at a minimum to round-off
            fit.converged = true;
            break;
        }
        if (fit.converged) break;
    }
    fit.mean = p[0];
    fit.amplitude = p[1];
    fit.frequency = p[2];
    fit.phase = p[3];
    if (fit.amplitude < 0.0) {
        fit.amplitude = -fit.amplitude;
        fit.phase += kPi;
    }
    if (fit.frequency < 0.0) {  // cos is even: (nu, phi) and (-nu, -phi) are the same curve
        fit.frequency = -fit.frequency;
        fit.phase = -fit.phase;
    }
    fit.phase = std::remainder(fit.phase, 2.0 * kPi);
    fit.rms = std::sqrt(2.0 * cost / static_cast<double>(n));
    return fit;
}

TankTreadingFrequency tankTreadingFrequency(const std::vector<double>& t, const std::vector<Vertices>& frames) {
    if (t.size() != frames.size() || frames.size() < 4)
        throw InputError(fmt::format("tank-treading frequency: {} times and {} frames (need equal sizes >= 4)",
                                     t.size(), frames.size()));
    const Eigen::Index nf = static_cast<Eigen::Index>(frames.size()), nv = frames.front().cols();
    Eigen::MatrixXd x(nf, nv);  // x of every vertex relative to the mean, per frame
    for (Eigen::Index k = 0; k < nf; ++k) {
        if (frames[k].cols() != nv) throw InputError("tank-treading frequency: frames differ in vertex count");
        x.row(k) = frames[k].row(0).array() - frames[k].row(0).mean();
    }
    const Eigen::VectorXd sd = ((x.rowwise() - x.colwise().mean()).colwise().squaredNorm() / nf).cwiseSqrt();
    std::vector<Eigen::Index> order(nv);
    std::iota(order.begin(), order.end(), 0);
    const Eigen::Index keep = std::max<Eigen::Index>(1, static_cast<Eigen::Index>(std::ceil(0.1 * nv)));
    std::partial_sort(order.begin(), order.begin() + keep, order.end(),
                      [&](Eigen::Index a, Eigen::Index b) { return sd[a] > sd[b]; });
    order.resize(keep);

    TankTreadingFrequency res;
    double periodSum = 0.0;
    for (const Eigen::Index i : order) {
        std::vector<double> crossings;
        for (Eigen::Index k = 0; k + 1 < nf; ++k) {
            const double a = x(k, i), b = x(k + 1, i);
            if ((a < 0.0 && b >= 0.0) || (a >= 0.0 && b < 0.0))
                crossings.push_back(t[k] + (t[k + 1] - t[k]) * a / (a - b));
        }
        if (crossings.size() < 2) continue;
        // Whole periods where possible: the two half periods of a vertex on a flattened cell
        // differ, so an odd number of intervals biases the mean.
        if (crossings.size() >= 4 && crossings.size() % 2 == 0) crossings.pop_back();
        const double meanInterval = (crossings.back() - crossings.front()) / static_cast<double>(crossings.size() - 1);
        periodSum += 2.0 * meanInterval;
        ++res.vertices;
    }
    if (res.vertices > 0) {
        res.defined = true;
        res.frequency = 1.0 / (periodSum / res.vertices);
    }
    Eigen::MatrixXd sel(nf, keep);
    for (Eigen::Index c = 0; c < keep; ++c) sel.col(c) = x.col(order[c]);
    res.fftFrequency = periodogramPeaks(t, sel).mean();
    return res;
}

std::vector<double> unwrappedOrientation(const std::vector<Vertices>& frames) {
    std::vector<double> out;
    out.reserve(frames.size());
    for (const Vertices& X : frames) {
        double a = inclinationAngle(X);
        if (!out.empty()) a = out.back() + std::remainder(a - out.back(), kPi);
        out.push_back(a);
    }
    return out;
}

std::string regimeName(ShearRegime r) {
    switch (r) {
        case ShearRegime::TankTreading: return "tank-treading";
        case ShearRegime::Tumbling: return "tumbling";
        default: return "intermittent";
    }
}

ShearObservables analyzeShearFrames(const std::vector<double>& t, const std::vector<Vertices>& frames,
                                    double shearRate, double discardFraction) {
    if (t.size() != frames.size())
        throw InputError(fmt::format("shear analysis: {} times but {} frames", t.size(), frames.size()));
    if (!(shearRate > 0.0) || !std::isfinite(shearRate))
        throw InputError(fmt::format("shear analysis: shear rate = {} must be finite and > 0", shearRate));
    if (!(discardFraction >= 0.0 && discardFraction < 1.0))
        throw InputError(fmt::format("shear analysis: discard fraction = {} must be in [0, 1)", discardFraction));
    ShearObservables o;
    o.firstFrame = static_cast<std::size_t>(std::floor(discardFraction * static_cast<double>(frames.size())));
    o.framesUsed = frames.size() - o.firstFrame;
    if (o.framesUsed < 8)
        throw InputError(fmt::format("shear analysis: {} frames after discarding the first {:.0f} % (need >= 8)",
                                     o.framesUsed, 100.0 * discardFraction));
    const std::vector<double> tw(t.begin() + static_cast<std::ptrdiff_t>(o.firstFrame), t.end());
    const std::vector<Vertices> fw(frames.begin() + static_cast<std::ptrdiff_t>(o.firstFrame), frames.end());

    // Inclination angle and its fit.
    std::vector<double> theta(fw.size());
    for (std::size_t k = 0; k < fw.size(); ++k) theta[k] = inclinationAngle(fw[k]);
    const std::vector<double> tRel = [&] {
        std::vector<double> r(tw.size());
        for (std::size_t k = 0; k < tw.size(); ++k) r[k] = tw[k] - tw.front();
        return r;
    }();
    // Tank-treading frequency.
    o.ttf = tankTreadingFrequency(tw, fw);

    // The fit from the rigid-sphere start (frequency rate / 4 pi) and, because the least-squares
    // problem has local minima in the frequency, also from the periodogram peak of theta and from
    // twice the tank-treading frequency (the shape swings twice per membrane turn); the sane fit
    // (amplitude within the range of theta, at least half a period in the window) with the
    // smallest residual wins. If none is sane: mean of theta and half its range.
    const auto [thLo, thHi] = std::minmax_element(theta.begin(), theta.end());
    const double thRange = *thHi - *thLo, window = tRel.back();
    std::vector<double> starts{shearRate / (4.0 * kPi)};
    {
        Eigen::MatrixXd th(static_cast<Eigen::Index>(theta.size()), 1);
        for (std::size_t k = 0; k < theta.size(); ++k) th(static_cast<Eigen::Index>(k), 0) = theta[k];
        starts.push_back(periodogramPeaks(tRel, th)[0]);
    }
    if (o.ttf.defined) starts.push_back(2.0 * o.ttf.frequency);
    bool found = false;
    for (const double f0 : starts) {
        const SinusoidFit fit = fitSinusoid(tRel, theta, f0);
        const bool sane = std::isfinite(fit.rms) && fit.amplitude <= thRange && fit.frequency * window >= 0.5 &&
                          fit.mean >= *thLo && fit.mean <= *thHi;
        if (sane && (!found || fit.rms < o.angleFit.rms)) {
            o.angleFit = fit;
            found = true;
        }
    }
    if (!found) {
        o.angleFit = SinusoidFit{};
        o.angleFit.mean = std::accumulate(theta.begin(), theta.end(), 0.0) / static_cast<double>(theta.size());
        o.angleFit.amplitude = 0.5 * thRange;
        double ss = 0.0;
        for (double v : theta) ss += (v - o.angleFit.mean) * (v - o.angleFit.mean);
        o.angleFit.rms = std::sqrt(ss / static_cast<double>(theta.size()));
    }
    o.inclinationDeg = o.angleFit.mean * 180.0 / kPi;
    o.swingAmplitudeDeg = o.angleFit.amplitude * 180.0 / kPi;
    o.swingFrequency = o.angleFit.frequency;
    o.ttf4piFOverRate = 4.0 * kPi * o.ttf.frequency / shearRate;
    o.ttfFft4piFOverRate = 4.0 * kPi * o.ttf.fftFrequency / shearRate;

    // Membrane motion relative to the shape: the polar angle of every vertex in the x-y plane of
    // the frame turned with the long axis (unwrapped orientation, so that a tumbling cell's frame
    // turns continuously), unwrapped over time; mean advance over the vertices at least half the
    // largest in-plane distance from the centre.
    const std::vector<double> phi = unwrappedOrientation(fw);
    {
        const Eigen::Index nv = fw.front().cols();
        Eigen::VectorXd prev(nv), advance = Eigen::VectorXd::Zero(nv), radius = Eigen::VectorXd::Zero(nv);
        for (std::size_t k = 0; k < fw.size(); ++k) {
            const Eigen::Vector2d c = fw[k].topRows<2>().rowwise().mean();
            const double ct = std::cos(phi[k]), st = std::sin(phi[k]);
            for (Eigen::Index i = 0; i < nv; ++i) {
                const double x = fw[k](0, i) - c.x(), y = fw[k](1, i) - c.y();
                const double xb = ct * x + st * y, yb = -st * x + ct * y;
                const double psi = std::atan2(yb, xb);
                if (k > 0) advance[i] += std::remainder(psi - prev[i], 2.0 * kPi);
                prev[i] = psi;
                radius[i] += std::hypot(x, y) / static_cast<double>(fw.size());
            }
        }
        const double rmax = radius.maxCoeff();
        double sum = 0.0;
        int count = 0;
        for (Eigen::Index i = 0; i < nv; ++i)
            if (radius[i] >= 0.5 * rmax) {
                sum += advance[i];
                ++count;
            }
        o.membraneAdvance = count > 0 ? sum / count : 0.0;
        const double span = tw.back() - tw.front();
        o.membraneAdvance4piFOverRate = span > 0.0 ? 2.0 * std::abs(o.membraneAdvance) / (span * shearRate) : 0.0;
    }

    // Regime.
    const auto [lo, hi] = std::minmax_element(phi.begin(), phi.end());
    o.orientationAdvance = phi.back() - phi.front();
    o.orientationRange = *hi - *lo;
    const std::size_t mid = phi.size() / 2;
    const double firstHalf = std::abs(phi[mid] - phi.front()), secondHalf = std::abs(phi.back() - phi[mid]);
    if (std::abs(o.orientationAdvance) > kPi && firstHalf > 0.5 * kPi && secondHalf > 0.5 * kPi)
        o.regime = ShearRegime::Tumbling;
    else if (o.orientationRange < 0.5 * kPi && o.ttf.defined && std::abs(o.membraneAdvance) >= kPi)
        o.regime = ShearRegime::TankTreading;
    else
        o.regime = ShearRegime::Intermittent;
    return o;
}

namespace {

/// Frames up to the first one at or after time `end` (1/rate).
std::size_t framesUpTo(const std::vector<double>& t, double end) {
    std::size_t m = 0;
    while (m < t.size() && t[m] < end * (1.0 - 1e-12)) ++m;
    return std::min(t.size(), m + 1);
}

}  // namespace

ShearObservables analyzeFirstShearFrames(const std::vector<double>& t, const std::vector<Vertices>& frames, std::size_t m) {
    m = std::min({m, t.size(), frames.size()});
    return analyzeShearFrames(std::vector<double>(t.begin(), t.begin() + static_cast<std::ptrdiff_t>(m)),
                              std::vector<Vertices>(frames.begin(), frames.begin() + static_cast<std::ptrdiff_t>(m)), 1.0);
}

bool steadyBetween(const ShearObservables& now, const ShearObservables& before, const SteadyStopRule& rule) {
    if (now.regime == ShearRegime::Tumbling && before.regime == ShearRegime::Tumbling) return true;
    if (now.regime != ShearRegime::TankTreading || before.regime != ShearRegime::TankTreading) return false;
    if (!now.ttf.defined || !before.ttf.defined) return false;
    return std::abs(now.inclinationDeg - before.inclinationDeg) <= rule.angleToleranceDeg &&
           std::abs(now.swingAmplitudeDeg - before.swingAmplitudeDeg) <= rule.angleToleranceDeg &&
           std::abs(now.ttf4piFOverRate - before.ttf4piFOverRate) <= rule.ttfTolerance * std::abs(now.ttf4piFOverRate);
}

std::vector<TurnObservables> observablesByTurn(const std::vector<double>& t, const std::vector<Vertices>& frames, double tEnd) {
    if (frames.size() != t.size()) throw InputError(fmt::format("{} frames but {} times", frames.size(), t.size()));
    std::vector<TurnObservables> out;
    const double turn = 4.0 * kPi;
    if (std::isnan(tEnd)) tEnd = t.empty() ? 0.0 : t.back();
    const int last = int(std::floor(tEnd / turn * (1.0 + 1e-12)));
    for (int k = 1; k <= last; ++k) {
        const std::size_t m = framesUpTo(t, k * turn);
        try {
            out.push_back({k, m, analyzeFirstShearFrames(t, frames, m)});
        } catch (const InputError&) {  // too few frames up to turn k
        }
    }
    return out;
}

bool shearSteadyStateReached(const std::vector<double>& t, const std::vector<Vertices>& frames, const SteadyStopRule& rule,
                             double since) {
    const std::size_t n = t.size();
    if (n < 2 || frames.size() != n) return false;
    const double turn = 4.0 * kPi;
    const double k = std::floor(t[n - 1] / turn * (1.0 + 1e-12));
    if (k < rule.minRotations) return false;
    const std::size_t atTurn = framesUpTo(t, k * turn);
    if (!(t[atTurn - 1] > since)) return false;  // turn k was looked at after an earlier step
    try {
        return steadyBetween(analyzeFirstShearFrames(t, frames, atTurn), analyzeFirstShearFrames(t, frames, framesUpTo(t, (k - 1.0) * turn)), rule);
    } catch (const InputError&) {  // too few frames so far
        return false;
    }
}

}  // namespace trbc
