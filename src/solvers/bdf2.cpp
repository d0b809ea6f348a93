#include "solvers/bdf2.hpp"

#include <algorithm>
#include <cmath>

namespace trbc::bdf2 {

void History::accept(Vertices& Xnew, double h) {
    Xprev2.swap(Xprev);
    Xprev.swap(X);
    X.swap(Xnew);
    hPrev2 = hPrev;
    hPrev = h;
    ++accepted;
}

Vertices Coefficients::historyTerm(const Vertices& Xn, const Vertices& Xn1) const {
    if (w == 0.0) return Xn;
    return ((1.0 + w) * Xn - (w * w / (1.0 + w)) * Xn1) / c0;
}

Coefficients coefficients(const History& s, double h) {
    if (s.accepted < 1) return {};
    const double w = h / s.hPrev;
    return {(1.0 + 2.0 * w) / (1.0 + w), w};
}

Eigen::Vector3d lagrangeWeights(double t0, double t1, double t2, double t) {
    return {(t - t1) * (t - t2) / ((t0 - t1) * (t0 - t2)), (t - t0) * (t - t2) / ((t1 - t0) * (t1 - t2)),
            (t - t0) * (t - t1) / ((t2 - t0) * (t2 - t1))};
}

Vertices predictor(const History& s, double h) {
    if (s.accepted < 1) return s.X;
    if (s.accepted < 2) return s.X + (h / s.hPrev) * (s.X - s.Xprev);
    // Times relative to t_n.
    const Eigen::Vector3d l = lagrangeWeights(-s.hPrev - s.hPrev2, -s.hPrev, 0.0, h);
    return l[0] * s.Xprev2 + l[1] * s.Xprev + l[2] * s.X;
}

double maxNorm(const Vertices& D) { return D.colwise().norm().maxCoeff(); }

double localError(const Vertices& corrector, const Vertices& predicted) {
    return (2.0 / 11.0) * maxNorm(corrector - predicted);
}

Vertices interpolate(const History& s, double tStart, double tEnd, double ts) {
    ts = std::min(ts, tEnd);
    if (s.accepted < 2) {
        const double a = (ts - tStart) / s.hPrev;
        return (1.0 - a) * s.Xprev + a * s.X;
    }
    const Eigen::Vector3d l = lagrangeWeights(tStart - s.hPrev2, tStart, tEnd, ts);
    return l[0] * s.Xprev2 + l[1] * s.Xprev + l[2] * s.X;
}

bool reaches(double t, double target) { return t >= target * (1.0 - 1e-12); }

bool covers(double t, double ts) { return ts <= t * (1.0 + 1e-12) + 1e-14; }

Step StepControl::propose(double dt, const History& s, double t, double target) const {
    Step step{std::min(dt, dtMax), dt, false, 0.0};
    if (s.accepted >= 1) step.h = std::min(step.h, kMaxStepRatio * s.hPrev);
    step.landed = reaches(t + step.h, target);
    if (step.landed) step.h = target - t;
    step.end = step.landed ? target : t + step.h;
    return step;
}

Verdict StepControl::judge(const Step& step, double err, const History& s) const {
    if (!adaptive) return {Outcome::Accept, dtInitial};
    // A step shortened to land on a target does not shrink the next.
    const double base = step.landed ? std::max(step.wanted, step.h) : step.h;
    if (s.accepted < 2) {
        const double growth = s.accepted == 0 ? firstStepGrowth : kMaxGrowth;
        return {Outcome::Accept, std::min(dtMax, base * growth)};
    }
    // Local error ~ h^3: the step that would give err = tol, with a safety factor (an error that
    // is not a number counts as too large).
    const double q = kSafety * std::cbrt(std::isnan(err) ? 0.0 : tolerance / std::max(err, 1e-300));
    if (!(err <= tolerance)) {
        const double retry = step.h * std::max(kMinFactor, q);  // q < 0.9 here
        return {retry < dtMin ? Outcome::Fail : Outcome::Retry, retry};
    }
    return {Outcome::Accept, std::min(dtMax, base * std::clamp(q, kMinFactor, kMaxGrowth))};
}

Verdict StepControl::afterFailedSolve(const Step& step) const {
    const double retry = kFailureFactor * step.h;
    return {retry < dtMin ? Outcome::Fail : Outcome::Retry, retry};
}

}  // namespace trbc::bdf2
