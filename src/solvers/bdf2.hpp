#pragma once
// Variable-step BDF2 with error control: the one stepper of the membrane dynamics
// (solvers/viscous_dynamics.hpp) and of the cell in Stokes flow (flow/cell_flow.hpp). The
// integrators supply the implicit solve of each step; everything else is here (docs/FORWARD_MODEL.md,
// relaxation; docs/FLOW.md, time stepping).
//
// Formula. With the step h, the previous step hPrev and the ratio w = h / hPrev,
//   c0 (X^{n+1} - Y) / h = f(X^{n+1}),   c0 = (1 + 2w) / (1 + w),
//   Y = ((1 + w) X^n - w^2 / (1 + w) X^{n-1}) / c0;
// the first step is implicit Euler (c0 = 1, Y = X^n). Zero-stable for w < 1 + sqrt 2, so the ratio
// is capped at kMaxStepRatio.
//
// Predictor and error. X* = the quadratic through the last three states, extrapolated to t_n + h
// (linear after one step). With constant steps, the corrector's local error is -2/9 h^3 X''' and
// the predictor's h^3 X''', so Milne's device estimates the local error from their difference:
//   err = 2/9 / (1 + 2/9) max_i |X^{n+1}_i - X*_i| = 2/11 max_i |X^{n+1}_i - X*_i|
// (largest vertex displacement).
//
// Step control (StepControl). The local error scales as h^3; with q = 0.9 (tol/err)^(1/3):
// accepted steps are followed by h min(2, max(0.2, q)) (at most dtMax); a step with err > tol is
// retried with h max(0.2, q); a failed implicit solve is retried with h / 4; a retry step below
// dtMin ends the run. The first two steps have no estimate (it needs three states): after the
// first the step grows by firstStepGrowth, after the second by 2. A step shortened to land on a
// target time (a sample, the end) does not shrink the next: the factor applies to the step asked
// for.
//
// Dense output. Over the last step, the state at any time is the quadratic through the last three
// states (linear after one step): BDF2's own interpolant, second order like the steps.
#include <Eigen/Core>

#include "mesh/mesh.hpp"

namespace trbc::bdf2 {

inline constexpr double kMaxStepRatio = 2.4;   ///< h / hPrev below 1 + sqrt 2 (zero-stability)
inline constexpr double kSafety = 0.9;         ///< factor on the step that the error model predicts for err = tol
inline constexpr double kMaxGrowth = 2.0;      ///< largest growth of an accepted step
inline constexpr double kMinFactor = 0.2;      ///< smallest factor on a step after an error estimate
inline constexpr double kFailureFactor = 0.25; ///< factor on a step whose implicit solve failed

/// The last three accepted states and the steps between them: what the next step reads.
struct History {
    Vertices X, Xprev, Xprev2;         ///< states at t_n, t_n - hPrev, t_n - hPrev - hPrev2
    double hPrev = 0.0, hPrev2 = 0.0;
    int accepted = 0;                  ///< steps taken: BDF2 from the second, the quadratic predictor from the third

    History() = default;
    /// At the start: all three states X0, no steps.
    explicit History(const Vertices& X0) : X(X0), Xprev(X0), Xprev2(X0) {}
    /// Takes the step h to Xnew; Xnew receives the oldest state (its storage is reused).
    void accept(Vertices& Xnew, double h);
};

/// c0 and Y of the BDF2 formula for the step h (header comment).
struct Coefficients {
    double c0 = 1.0;
    double w = 0.0;  ///< step ratio h / hPrev; 0: implicit Euler

    /// Y for the states (X^n, X^{n-1}) of any quantity stepped with the same formula (positions,
    /// velocities).
    Vertices historyTerm(const Vertices& Xn, const Vertices& Xn1) const;
};
Coefficients coefficients(const History& s, double h);

/// Weights of the quadratic through (t0, t1, t2) at t (Lagrange basis).
Eigen::Vector3d lagrangeWeights(double t0, double t1, double t2, double t);

/// X* at t_n + h: X^n at the start, linear after one step, the quadratic through the last three
/// states after two.
Vertices predictor(const History& s, double h);

/// Largest vertex displacement max_i |D_i|.
double maxNorm(const Vertices& D);

/// Milne's estimate of the local error: 2/11 max_i |X^{n+1}_i - X*_i|.
double localError(const Vertices& corrector, const Vertices& predicted);

/// The state at ts in the step (tStart, tEnd] just accepted (s.X at tEnd, s.Xprev at tStart,
/// s.Xprev2 at tStart - s.hPrev2): the quadratic through the three, linear after one step. ts is
/// taken at most tEnd (a sample time covered within round-off).
Vertices interpolate(const History& s, double tStart, double tEnd, double ts);

/// Whether time t has reached `target` (within round-off): a step ending there lands on it.
bool reaches(double t, double target);

/// Whether the state at t covers the sample time ts (within round-off).
bool covers(double t, double ts);

/// A step as proposed by StepControl::propose.
struct Step {
    double h = 0.0;        ///< the step to take
    double wanted = 0.0;   ///< the step asked for, before the caps and the landing
    bool landed = false;   ///< shortened to end on the target
    double end = 0.0;      ///< time at the end of the step: the target when landed
};

enum class Outcome { Accept, Retry, Fail };

struct Verdict {
    Outcome outcome = Outcome::Accept;
    /// Accept: the next step to ask for; Retry: the step to retry with; Fail: the retry step,
    /// below dtMin.
    double dt = 0.0;
};

/// The step-size controller of the header comment.
struct StepControl {
    double tolerance = 1e-3;  ///< local error per step (largest vertex displacement)
    bool adaptive = true;     ///< false: fixed steps dtInitial (capped at dtMax), err only reported
    double dtInitial = 1e-2, dtMin = 1e-8, dtMax = 1.0;
    /// Growth after the first (implicit-Euler) step, which has no error estimate. The membrane
    /// dynamics takes 1: its relaxation starts in its fastest transient (a stretched cell released)
    /// with dtInitial set to that transient, and keeps it for the first BDF2 step. The cell flow
    /// takes 2 (kMaxGrowth): it starts from rest with dtInitial far below the steps that the flow's
    /// accuracy needs. Changing either changes its step sequence and so its outputs at the level of
    /// the tolerance.
    double firstStepGrowth = kMaxGrowth;

    /// The step to try from t: dt capped at dtMax and at kMaxStepRatio hPrev, shortened to end on
    /// `target` when it reaches it.
    Step propose(double dt, const History& s, double t, double target) const;
    /// After a solved step with local error err (s: the history before the step).
    Verdict judge(const Step& step, double err, const History& s) const;
    /// After a step whose implicit solve failed.
    Verdict afterFailedSolve(const Step& step) const;
};

}  // namespace trbc::bdf2
