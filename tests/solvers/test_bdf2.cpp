// The BDF2 stepper of solvers/bdf2.hpp on linear ODEs X' = A X with known solutions (a decay and
// an oscillator): second order in the step and in the tolerance^(1/3), Milne's error estimate,
// the dense output, and the step controller's rules.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <iostream>
#include <vector>

#include "solvers/bdf2.hpp"

namespace trbc {
namespace {

using Exact = std::function<Vertices(double)>;

// X' = A X column by column; X(0) = X0.
struct LinearOde {
    Eigen::Matrix3d A;
    Vertices X0;
    Exact exact;
};

// Decay at the rates 1, 3 and 0.5 per component: X(t) = exp(-k t) X0.
LinearOde decay() {
    LinearOde o;
    const Eigen::Vector3d k(1.0, 3.0, 0.5);
    o.A = -k.asDiagonal().toDenseMatrix();
    o.X0 = Vertices(3, 2);
    o.X0 << 1.0, -0.5, 2.0, 0.3, -1.0, 1.5;
    o.exact = [k, X0 = o.X0](double t) { return Vertices((-k * t).array().exp().matrix().asDiagonal() * X0); };
    return o;
}

// Oscillator x' = v, v' = -w^2 x in the first two components (the third at rest).
LinearOde oscillator() {
    LinearOde o;
    const double w = 2.0;
    o.A << 0.0, 1.0, 0.0, -w * w, 0.0, 0.0, 0.0, 0.0, 0.0;
    o.X0 = Vertices(3, 2);
    o.X0 << 1.0, 0.0, 0.0, -1.0, 0.2, 0.4;
    o.exact = [w, X0 = o.X0](double t) {
        Eigen::Matrix3d R;
        R << std::cos(w * t), std::sin(w * t) / w, 0.0, -w * std::sin(w * t), std::cos(w * t), 0.0, 0.0, 0.0, 1.0;
        return Vertices(R * X0);
    };
    return o;
}

// The implicit solve of one step: c0 (X - Y) / h = A X.
Vertices solveStep(const Eigen::Matrix3d& A, const Vertices& Y, double c0, double h) {
    const double k = c0 / h;
    return (k * Eigen::Matrix3d::Identity() - A).partialPivLu().solve(k * Y);
}

struct StepperRun {
    double finalError = 0.0;   ///< max-norm error at tEnd
    double stateError = 0.0;   ///< largest max-norm error of the accepted states
    double sampleError = 0.0;  ///< largest max-norm error of the dense output at the samples
    int steps = 0, rejected = 0;
    bool failed = false;
};

// The loop of the integrators (solvers/viscous_dynamics.cpp, flow/cell_flow.cpp) with the
// exact linear solve.
StepperRun integrate(const LinearOde& ode, const bdf2::StepControl& control, double tEnd,
              const std::vector<double>& samples = {}) {
    bdf2::History history(ode.X0);
    double t = 0.0, dt = std::min(control.dtInitial, control.dtMax);
    std::size_t next = 0;
    StepperRun run;
    while (!bdf2::reaches(t, tEnd)) {
        const bdf2::Step step = control.propose(dt, history, t, tEnd);
        const bdf2::Coefficients coef = bdf2::coefficients(history, step.h);
        const Vertices Xpred = bdf2::predictor(history, step.h);
        Vertices Xnew = solveStep(ode.A, coef.historyTerm(history.X, history.Xprev), coef.c0, step.h);
        const double err = history.accepted >= 2 ? bdf2::localError(Xnew, Xpred) : 0.0;
        const bdf2::Verdict v = control.judge(step, err, history);
        if (v.outcome == bdf2::Outcome::Fail) {
            run.failed = true;
            return run;
        }
        dt = v.dt;
        if (v.outcome == bdf2::Outcome::Retry) {
            ++run.rejected;
            continue;
        }
        const double tStart = t;
        history.accept(Xnew, step.h);
        t = step.end;
        ++run.steps;
        run.stateError = std::max(run.stateError, bdf2::maxNorm(history.X - ode.exact(t)));
        for (; next < samples.size() && bdf2::covers(t, samples[next]); ++next) {
            const Vertices dense = bdf2::interpolate(history, tStart, t, samples[next]);
            run.sampleError = std::max(run.sampleError, bdf2::maxNorm(dense - ode.exact(samples[next])));
        }
    }
    EXPECT_EQ(t, tEnd);
    EXPECT_EQ(next, samples.size());
    run.finalError = bdf2::maxNorm(history.X - ode.exact(tEnd));
    return run;
}

bdf2::StepControl fixedSteps(double dt) {
    bdf2::StepControl c;
    c.adaptive = false;
    c.dtInitial = dt;
    c.dtMax = 1e3;
    return c;
}

// The first step (implicit Euler, no estimate) scaled like the others, h ~ tol^(1/3).
bdf2::StepControl adaptiveSteps(double tolerance) {
    bdf2::StepControl c;
    c.tolerance = tolerance;
    c.dtInitial = 0.1 * std::cbrt(tolerance);
    c.dtMin = 1e-12;
    c.dtMax = 1e3;
    return c;
}

// Sample times off the step grid, after the start steps (the first is implicit Euler, its
// interpolant linear: second order globally, but with a constant that depends on where a sample
// falls in the step).
std::vector<double> sampleTimes(double tEnd) {
    std::vector<double> s;
    for (double t = 0.1037; t < tEnd; t += 0.0731) s.push_back(t);
    return s;
}

// Least-squares slope of log y against log x.
double logSlope(const std::vector<double>& x, const std::vector<double>& y) {
    const auto n = static_cast<double>(x.size());
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    for (std::size_t i = 0; i < x.size(); ++i) {
        const double lx = std::log(x[i]), ly = std::log(y[i]);
        sx += lx;
        sy += ly;
        sxx += lx * lx;
        sxy += lx * ly;
    }
    return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

TEST(Bdf2Stepper, FixedStepsAndDenseOutputAreSecondOrder) {
    for (const auto& [name, ode] : {std::pair{"decay", decay()}, std::pair{"oscillator", oscillator()}}) {
        const double tEnd = 2.0;
        std::vector<StepperRun> runs;
        for (int n : {50, 100, 200, 400}) runs.push_back(integrate(ode, fixedSteps(tEnd / n), tEnd, sampleTimes(tEnd)));
        for (std::size_t i = 1; i < runs.size(); ++i) {
            const double step = runs[i - 1].finalError / runs[i].finalError;
            const double dense = runs[i - 1].sampleError / runs[i].sampleError;
            std::cout << name << ": halving the step divides the error by " << step << ", the dense output's by " << dense
                      << "\n";
            EXPECT_GT(step, 3.5) << name;  // 4 for second order, 2 for first
            EXPECT_LT(step, 4.6) << name;
            EXPECT_GT(dense, 3.5) << name;
            EXPECT_LT(dense, 4.6) << name;
            // Between the states the interpolant is about as accurate as the states themselves.
            EXPECT_LT(runs[i].sampleError, 1.5 * runs[i].stateError) << name;
        }
    }
}

// Local error tol per step of size h ~ tol^(1/3): the global error falls as tol^(2/3) and the
// step count grows as tol^(-1/3).
TEST(Bdf2Stepper, AdaptiveStepsConvergeAsTheToleranceToTheTwoThirds) {
    for (const auto& [name, ode] : {std::pair{"decay", decay()}, std::pair{"oscillator", oscillator()}}) {
        const double tEnd = 3.0;
        std::vector<double> tols, errors, denseErrors, steps;
        for (double tol = 1e-4; tol > 1e-8; tol /= 10) {
            const StepperRun r = integrate(ode, adaptiveSteps(tol), tEnd, sampleTimes(tEnd));
            ASSERT_FALSE(r.failed) << name;
            std::cout << name << ": tol " << tol << ", " << r.steps << " steps (" << r.rejected << " rejected), error "
                      << r.finalError << ", dense output " << r.sampleError << "\n";
            tols.push_back(tol);
            errors.push_back(r.finalError);
            denseErrors.push_back(r.sampleError);
            steps.push_back(r.steps);
        }
        EXPECT_NEAR(logSlope(tols, errors), 2.0 / 3.0, 0.12) << name;
        EXPECT_NEAR(logSlope(tols, denseErrors), 2.0 / 3.0, 0.12) << name;
        EXPECT_NEAR(logSlope(tols, steps), -1.0 / 3.0, 0.06) << name;
    }
}

// With constant steps from exact states, the estimate 2/11 |X - X*| approaches the true local error.
TEST(Bdf2Stepper, MilneEstimateMatchesTheLocalError) {
    for (const auto& [name, ode] : {std::pair{"decay", decay()}, std::pair{"oscillator", oscillator()}}) {
        for (double h : {0.02, 0.005}) {
            const double t = 0.7;
            bdf2::History history(ode.exact(t - 2 * h));
            Vertices X1 = ode.exact(t - h), X2 = ode.exact(t);
            history.accept(X1, h);
            history.accept(X2, h);
            const bdf2::Coefficients coef = bdf2::coefficients(history, h);
            EXPECT_DOUBLE_EQ(coef.c0, 1.5);
            const Vertices X = solveStep(ode.A, coef.historyTerm(history.X, history.Xprev), coef.c0, h);
            const double estimate = bdf2::localError(X, bdf2::predictor(history, h));
            const double truth = bdf2::maxNorm(X - ode.exact(t + h));
            std::cout << name << ", h = " << h << ": estimate / local error = " << estimate / truth << "\n";
            EXPECT_NEAR(estimate / truth, 1.0, h < 0.01 ? 0.03 : 0.1) << name;
        }
    }
}

// The predictor and the dense output are the quadratic through the last three states, whatever
// the steps: exact on a quadratic trajectory.
TEST(Bdf2Stepper, PredictorAndDenseOutputAreExactForQuadratics) {
    Vertices a(3, 2), b(3, 2), c(3, 2);
    a << 1, 2, 3, 4, 5, 6;
    b << -1, 0.5, 2, 0, 1, -3;
    c << 0.3, -2, 1, 1, -0.7, 2;
    const auto X = [&](double t) { return Vertices(a + t * b + t * t * c); };
    const double t0 = 0.4, h2 = 0.3, h1 = 0.7;  // states at t0, t0 + h2, t0 + h2 + h1
    bdf2::History history(X(t0));
    Vertices X1 = X(t0 + h2), X2 = X(t0 + h2 + h1);
    history.accept(X1, h2);
    history.accept(X2, h1);
    const double t = t0 + h2 + h1;
    for (double h : {0.1, 1.5})
        EXPECT_LT(bdf2::maxNorm(bdf2::predictor(history, h) - X(t + h)), 1e-12) << "h = " << h;
    for (double ts : {t0 + h2 + 0.01, t0 + h2 + 0.35, t})
        EXPECT_LT(bdf2::maxNorm(bdf2::interpolate(history, t0 + h2, t, ts) - X(ts)), 1e-12) << "ts = " << ts;
    // A sample time past the step within round-off is taken at the step's end.
    EXPECT_TRUE(bdf2::covers(t, t * (1 + 1e-14)));
    EXPECT_EQ(bdf2::interpolate(history, t0 + h2, t, t * (1 + 1e-14)), bdf2::interpolate(history, t0 + h2, t, t));
}

TEST(Bdf2Stepper, StepControllerRules) {
    bdf2::StepControl c;
    c.tolerance = 1e-3;
    c.dtMin = 1e-6;
    c.dtMax = 5.0;
    bdf2::History s(Vertices::Zero(3, 1));
    // First step: dtMax caps it; none before, so no ratio cap.
    EXPECT_EQ(c.propose(10.0, s, 0.0, 100.0).h, 5.0);
    Vertices X = Vertices::Zero(3, 1);
    s.accept(X, 1.0);
    // The ratio to the previous step is capped at 2.4 (zero-stability).
    bdf2::Step step = c.propose(4.0, s, 0.0, 100.0);
    EXPECT_EQ(step.h, 2.4);
    EXPECT_FALSE(step.landed);
    EXPECT_EQ(step.end, 2.4);
    // A step reaching the target, or falling short of it by round-off, lands on it exactly.
    for (double dt : {0.3, 0.2 - 1e-13}) {
        step = c.propose(dt, s, 9.8, 10.0);
        EXPECT_TRUE(step.landed) << dt;
        EXPECT_EQ(step.end, 10.0) << dt;
        EXPECT_EQ(step.h, 10.0 - 9.8) << dt;
    }
    EXPECT_FALSE(c.propose(0.1, s, 9.8, 10.0).landed);

    // Without an estimate: growth by firstStepGrowth after the first step, by 2 after the second.
    bdf2::History fresh(Vertices::Zero(3, 1));
    const bdf2::Step unit{1.0, 1.0, false, 1.0};
    c.firstStepGrowth = 1.0;
    EXPECT_EQ(c.judge(unit, 0.0, fresh).dt, 1.0);
    c.firstStepGrowth = 2.0;
    EXPECT_EQ(c.judge(unit, 0.0, fresh).dt, 2.0);
    EXPECT_EQ(c.judge(unit, 0.0, s).dt, 2.0);

    s.accept(X, 1.0);  // two steps: the estimate decides
    bdf2::Verdict v = c.judge(unit, 1e-3 / 8, s);  // err = tol / 8: 0.9 * 2
    EXPECT_EQ(v.outcome, bdf2::Outcome::Accept);
    EXPECT_DOUBLE_EQ(v.dt, 1.8);
    EXPECT_DOUBLE_EQ(c.judge(unit, 0.0, s).dt, 2.0);            // growth at most 2
    EXPECT_DOUBLE_EQ(c.judge({4.0, 4.0, false, 4.0}, 0.0, s).dt, 5.0);  // and dtMax
    v = c.judge(unit, 8e-3, s);  // err = 8 tol: retried with 0.9 / 2
    EXPECT_EQ(v.outcome, bdf2::Outcome::Retry);
    EXPECT_DOUBLE_EQ(v.dt, 0.45);
    EXPECT_DOUBLE_EQ(c.judge(unit, 1.0, s).dt, 0.2);  // shrink at most 5x
    EXPECT_EQ(c.judge(unit, std::nan(""), s).outcome, bdf2::Outcome::Retry);
    // A step shortened to land on a sample: the factor applies to the step asked for.
    EXPECT_DOUBLE_EQ(c.judge({0.1, 1.0, true, 1.0}, 1e-3 / 8, s).dt, 1.8);
    // Failures: a failed solve retries with h / 4; a retry below dtMin ends the run.
    v = c.afterFailedSolve(unit);
    EXPECT_EQ(v.outcome, bdf2::Outcome::Retry);
    EXPECT_EQ(v.dt, 0.25);
    EXPECT_EQ(c.afterFailedSolve({3e-6, 3e-6, false, 1.0}).outcome, bdf2::Outcome::Fail);
    EXPECT_EQ(c.judge({3e-6, 3e-6, false, 1.0}, 1.0, s).outcome, bdf2::Outcome::Fail);
    // Fixed steps: always dtInitial, the error only reported.
    c.adaptive = false;
    c.dtInitial = 0.3;
    EXPECT_EQ(c.judge(unit, 1.0, s).outcome, bdf2::Outcome::Accept);
    EXPECT_EQ(c.judge(unit, 1.0, s).dt, 0.3);
}

}  // namespace
}  // namespace trbc
