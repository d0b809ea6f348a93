#pragma once
// Observables of one cell in simple shear flow u = (rate y, 0, 0) (flow x, gradient y, vorticity
// z), computed from the saved frames exactly as docs/FLOW.md, shear says:
//
// * inclination angle: per frame, the vertex positions minus their mean, (x, y) components; the
//   leading right-singular direction e of this Nv x 2 array, sign chosen with e_x > 0, gives
//   theta = atan2(e_y, e_x); the series is fitted with theta(t) = a + b cos(2 pi nu t + phi) by
//   non-linear least squares (Levenberg-Marquardt) from (mean, half range, rate / 4 pi, 0);
//   a = inclination, |b| = swinging amplitude. The frequency has local minima, so the fit is
//   repeated from the periodogram peak of theta and from twice the tank-treading frequency, and
//   the sane fit (|b| <= range of theta, >= half a period in the window) with the smallest
//   residual is kept (analyzeShearFrames);
// * tank-treading frequency: x of every vertex relative to the mean; the 10 % of vertices with
//   the largest temporal standard deviation; per vertex the sign changes of x(t) (times by linear
//   interpolation between frames), period = 2 x mean interval between successive crossings
//   (vertices with fewer than two crossings skipped; with four or more crossings the last is
//   dropped if needed so that the intervals make whole periods, because the two half periods of
//   a vertex on a flattened cell differ); f = 1 / mean period; reported as
//   4 pi f / rate (1 for a rigid sphere, which turns at rate / 2). Cross-check: the dominant
//   frequency of the periodogram of each mean-removed x(t) (parabolic peak interpolation), averaged;
// * regime (docs/FLOW.md specifies the rule, the reference has no script): the orientation
//   angle of the long axis in the x-y plane (the same singular direction, unwrapped modulo pi)
//   over the analysed window. Tumbling: it advances by more than pi, in both halves of the window
//   by more than pi / 2. Tank-treading: it stays bounded (range < pi / 2) and the membrane
//   rotates (TTF defined, and the vertices turn by at least half a revolution relative to the
//   long axis: the mean advance of their polar angle in the co-rotating frame, over the vertices
//   at least half the largest distance from the centre). Anything else (a flip in one half only,
//   a bounded angle without membrane rotation, ...) is "intermittent".
// The first quarter of the frames is discarded in all three analyses.
//
// Times and the shear rate may be in any consistent units (s and 1/s, or 1/rate and 1).
#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "mesh/mesh.hpp"

namespace trbc {

/// theta = atan2(e_y, e_x) in (-pi/2, pi/2] (radians) of the leading right-singular direction
/// of the centred (x, y) vertex coordinates, e_x >= 0.
double inclinationAngle(const Vertices& X);

/// theta(t) = mean + amplitude cos(2 pi frequency t + phase).
struct SinusoidFit {
    double mean = 0.0, amplitude = 0.0, frequency = 0.0, phase = 0.0;
    double rms = 0.0;  ///< root-mean-square residual
    int iterations = 0;
    bool converged = false;
};
/// Levenberg-Marquardt fit from the start (mean(y), (max - min) / 2, frequency0, 0). The
/// amplitude is returned non-negative (phase shifted by pi if needed).
SinusoidFit fitSinusoid(const std::vector<double>& t, const std::vector<double>& y, double frequency0);

struct TankTreadingFrequency {
    bool defined = false;       ///< at least one vertex with two crossings
    double frequency = 0.0;     ///< f = 1 / mean period (zero crossings), 1 / time unit
    double fftFrequency = 0.0;  ///< cross-check: mean periodogram peak
    int vertices = 0;           ///< vertices that entered the mean
};
/// Uses every frame given (discard beforehand). Frames: vertex positions, same connectivity.
TankTreadingFrequency tankTreadingFrequency(const std::vector<double>& t, const std::vector<Vertices>& frames);

/// Unwrapped orientation angle (radians) of the long axis in the x-y plane, frame by frame
/// (continuous modulo pi, starting in (-pi/2, pi/2]).
std::vector<double> unwrappedOrientation(const std::vector<Vertices>& frames);

enum class ShearRegime { TankTreading, Tumbling, Intermittent };
std::string regimeName(ShearRegime r);  ///< "tank-treading", "tumbling", "intermittent"

struct ShearObservables {
    ShearRegime regime = ShearRegime::Intermittent;
    /// Fit of the inclination angle (degrees); only meaningful when tank-treading (set for every
    /// regime, the caller decides what to report).
    SinusoidFit angleFit;
    double inclinationDeg = 0.0, swingAmplitudeDeg = 0.0;
    double swingFrequency = 0.0;        ///< nu of the fit, 1 / time unit
    TankTreadingFrequency ttf;
    double ttf4piFOverRate = 0.0;       ///< 4 pi f / rate (zero crossings)
    double ttfFft4piFOverRate = 0.0;    ///< 4 pi f / rate (periodogram cross-check)
    double orientationAdvance = 0.0;    ///< unwrapped orientation, last - first frame (radians)
    double orientationRange = 0.0;      ///< max - min over the window (radians)
    /// Mean advance (radians) of the vertices' polar angle in the frame turned with the long axis
    /// (membrane motion relative to the shape; negative = clockwise, the shear's sense)
    double membraneAdvance = 0.0;
    /// The same as a frequency, 4 pi f / rate with f = |advance| / (2 pi window): a third
    /// estimate of the TTF (whole window, no zero crossings)
    double membraneAdvance4piFOverRate = 0.0;
    std::size_t firstFrame = 0, framesUsed = 0;
};

/// All observables from the frames at times t (the first `discardFraction` of the frames is
/// dropped). Throws InputError when fewer than 8 frames remain or the sizes disagree.
ShearObservables analyzeShearFrames(const std::vector<double>& t, const std::vector<Vertices>& frames,
                                    double shearRate, double discardFraction = 0.25);
/// analyzeShearFrames of the first m frames, times in units of 1/rate.
ShearObservables analyzeFirstShearFrames(const std::vector<double>& t, const std::vector<Vertices>& frames, std::size_t m);

/// When a shear run may stop before its full duration (ShearCaseOptions::stopWhenSteady): at each
/// whole rigid-sphere turn k >= minRotations (t = 4 pi k / rate), the observables of the frames up
/// to turn k are compared with those up to turn k - 1 (each with the first quarter discarded, as
/// the final analysis does). Steady: both tumbling, or both tank-treading with the inclination and
/// the swing amplitude within angleToleranceDeg and the TTF within ttfTolerance (relative).
/// Intermittent cells run to the end.
struct SteadyStopRule {
    double minRotations = 4.0;
    double angleToleranceDeg = 0.1;
    double ttfTolerance = 0.005;
};

/// Whether the observables at turn k (`now`) and at turn k - 1 (`before`) agree by the rule: both
/// tumbling, or both tank-treading with a TTF and within the tolerances.
bool steadyBetween(const ShearObservables& now, const ShearObservables& before, const SteadyStopRule& rule);

/// The observables of the frames up to one whole rigid-sphere turn (observablesByTurn).
struct TurnObservables {
    int turn = 0;
    std::size_t frames = 0;  ///< frames up to that turn: through the first at or after it
    ShearObservables observables;
};
/// The observables of the frames up to each whole rigid-sphere turn k = 1, 2, ... that the run
/// reached (times in units of 1/rate from 0; tEnd the run's end, the last frame's time when NaN),
/// analysed as shearSteadyStateReached does; a turn with too few frames for the analysis is left
/// out. Frames fall on multiples of the frame interval, so the run's last whole turn may end after
/// its last frame: that turn's record then holds every frame. Each turn copies its frames: meant
/// for runs of tens of turns.
std::vector<TurnObservables> observablesByTurn(const std::vector<double>& t, const std::vector<Vertices>& frames, double tEnd = NAN);

/// Whether the frames (times in units of 1/rate from 0) are steady by the rule at the last whole turn
/// k they reach; evaluated only when the first frame at or after turn k is later than `since` (the
/// start of the step that recorded the newest frames), so that it can be asked after every step and
/// looks once per turn. Stateless: a resumed run stops where an uninterrupted one does.
bool shearSteadyStateReached(const std::vector<double>& t, const std::vector<Vertices>& frames, const SteadyStopRule& rule,
                             double since);

}  // namespace trbc
