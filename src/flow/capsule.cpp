#include "flow/capsule.hpp"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <numbers>

#include "core/error.hpp"
#include "experiments/parameters.hpp"
#include "flow/shear_observables.hpp"
#include "mesh/geometry.hpp"
#include "mesh/icosphere.hpp"

namespace trbc {
namespace {

constexpr double kPi = std::numbers::pi;

void requireInRange(const char* option, double v, double lo, double hi, const char* range) {
    if (!(v >= lo && v <= hi) || !std::isfinite(v))
        throw InputError(fmt::format("{} = {}: must be in {}", option, v, range));
}

}  // namespace

void validateCapsuleCase(const CapsuleCase& c) {
    requireInRange("--ca", c.capillary, 1e-6, 100.0, "[1e-6, 100]");
    if (!(c.capillary > 0.0)) throw InputError("--ca must be > 0");
    requireInRange("--viscosity-ratio", c.viscosityRatio, 1e-3, 1e3, "[1e-3, 1e3]");
    requireInRange("--skalak-c", c.skalakC, -0.5, 1e4, "(-0.5, 1e4]");
    if (!(c.skalakC > -0.5)) throw InputError(fmt::format("--skalak-c = {}: must be in (-0.5, 1e4]", c.skalakC));
    requireInRange("--bending", c.bending, 0.0, 1e3, "[0, 1e3]");
    requireInRange("--membrane-viscosity", c.membraneViscosity, 0.0, 1e3, "[0, 1e3]");
    if (c.level < 1 || c.level > 5) throw InputError(fmt::format("--level = {}: must be in [1, 5]", c.level));
    requireInRange("--strain", c.strain, 0.5, 1e4, "[0.5, 1e4]");
    requireInRange("--step-tol", c.stepTolerance, 1e-8, 0.1, "[1e-8, 0.1]");
    requireInRange("--frame-interval", c.frameInterval, 1e-3, 1.0, "[1e-3, 1]");
    if (c.strain / c.frameInterval > 1e5)
        throw InputError(fmt::format("--strain / --frame-interval = {:.3g} frames: at most 1e5", c.strain / c.frameInterval));
    requireInRange("steady window", c.steadyWindow, c.frameInterval, c.strain, "[frame interval, strain]");
}

MembraneFlowSpec capsuleFlowSpec(const CapsuleCase& c) {
    validateCapsuleCase(c);
    MembraneFlowSpec s;
    const double Gs = 1.0 / c.capillary;
    s.membrane.law = c.law;
    if (c.law == InPlaneLaw::Lim)
        s.membrane.lim = {Gs, cell::a3, cell::a4, Gs, cell::b1, 0.0};
    else
        s.membrane.capsule = {Gs, c.law == InPlaneLaw::Skalak ? c.skalakC : 0.0};
    s.membrane.bending.kb = c.bending * Gs;
    s.edgeFriction = 4.0 * c.membraneViscosity / std::sqrt(3.0);
    s.viscosityRatio = c.viscosityRatio;
    s.areaConstraint = false;
    return s;
}

EquivalentEllipsoid equivalentEllipsoid(const Vertices& X, const Faces& F) {
    // Tetrahedra (c, x_i, x_j, x_k) about a point c inside: V_t = (x_i - c) . ((x_j - c) x (x_k - c)) / 6,
    // first moment V_t (sum of the four corners) / 4, second moments
    // int y y^T dV = V_t / 20 (sum_k y_k y_k^T + s s^T), s the sum of the four corners (c at 0).
    const Eigen::Vector3d c = X.rowwise().mean();
    double V = 0.0;
    Eigen::Vector3d first = Eigen::Vector3d::Zero();
    Eigen::Matrix3d second = Eigen::Matrix3d::Zero();
    for (Eigen::Index f = 0; f < F.cols(); ++f) {
        const Eigen::Vector3d a = X.col(F(0, f)) - c, b = X.col(F(1, f)) - c, d = X.col(F(2, f)) - c;
        const double Vt = a.dot(b.cross(d)) / 6.0;
        const Eigen::Vector3d s = a + b + d;
        V += Vt;
        first += Vt * s / 4.0;
        second += Vt / 20.0 * (a * a.transpose() + b * b.transpose() + d * d.transpose() + s * s.transpose());
    }
    if (!(V > 0.0)) throw NumericalError(fmt::format("equivalent ellipsoid: enclosed volume {} is not positive", V));
    const Eigen::Vector3d centroid = first / V;  // relative to c
    const Eigen::Matrix3d M = second - V * centroid * centroid.transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(M);
    // The principal axis closest to z is the vorticity axis; the other two lie in the shear plane.
    int kz = 0;
    for (int k = 1; k < 3; ++k)
        if (std::abs(eig.eigenvectors()(2, k)) > std::abs(eig.eigenvectors()(2, kz))) kz = k;
    int kl = -1, kb = -1;
    for (int k = 0; k < 3; ++k) {
        if (k == kz) continue;
        if (kl < 0 || eig.eigenvalues()[k] > eig.eigenvalues()[kl]) {
            kb = kl;
            kl = k;
        } else {
            kb = k;
        }
    }
    const auto semiAxis = [&](int k) { return std::sqrt(5.0 * std::max(eig.eigenvalues()[k], 0.0) / V); };
    EquivalentEllipsoid e;
    e.L = semiAxis(kl);
    e.B = semiAxis(kb);
    e.W = semiAxis(kz);
    Eigen::Vector3d dir = eig.eigenvectors().col(kl);
    if (dir.x() < 0.0) dir = -dir;
    e.inclination = std::atan2(dir.y(), dir.x());
    e.volume = V;
    return e;
}

double taylorDeformation(const EquivalentEllipsoid& e) { return (e.L - e.B) / (e.L + e.B); }

CapsuleResult runCapsule(const CapsuleCase& c) {
    const MembraneFlowSpec spec = capsuleFlowSpec(c);
    const Mesh sphere = icosphere(c.level);
    const CellFlowModel model(spec, sphere.F, sphere.X);
    CellFlowOptions opt;
    opt.tEnd = c.strain;
    opt.frameInterval = c.frameInterval;
    opt.errorTolerance = c.stepTolerance;
    CapsuleResult out;
    out.vertices = static_cast<int>(sphere.X.cols());
    const CellFlowResult r = integrateCellFlow(model, sphere.X, opt, [&](double t, const Vertices& X) {
        const EquivalentEllipsoid e = equivalentEllipsoid(X, sphere.F);
        out.times.push_back(t);
        out.d12.push_back(taylorDeformation(e));
        out.inclination.push_back(e.inclination * 180.0 / kPi);
    });
    out.completed = r.completed;
    out.message = r.message;
    out.steps = r.steps;
    out.rejectedSteps = r.rejectedSteps;
    out.gmresIterations = r.gmresIterations;
    out.wallSeconds = r.wallSeconds;
    if (!r.completed || out.times.size() < 8) return out;
    out.areaChange = totalArea(r.final, sphere.F) / model.targetArea() - 1.0;
    // The steady window: the last steadyWindow strain units.
    const double t1 = out.times.back(), t0 = t1 - c.steadyWindow;
    double dMin = INFINITY, dMax = -INFINITY, dSum = 0.0, aSum = 0.0;
    int n = 0;
    for (std::size_t k = 0; k < out.times.size(); ++k) {
        if (out.times[k] < t0 - 1e-9) continue;
        dMin = std::min(dMin, out.d12[k]);
        dMax = std::max(dMax, out.d12[k]);
        dSum += out.d12[k];
        aSum += out.inclination[k];
        ++n;
    }
    out.taylorD12 = dSum / n;
    out.inclinationDeg = aSum / n;
    out.d12Variation = (dMax - dMin) / std::max(std::abs(out.d12.back()), 1e-12);
    out.steady = out.d12Variation <= c.steadyTolerance;
    // The membrane's rotation over the second half (ShearObservables::membraneAdvance: radians,
    // negative in the shear's sense).
    const ShearObservables obs = analyzeShearFrames(r.times, r.frames, 1.0, 0.5);
    const double window = r.times.back() - r.times[obs.firstFrame];
    out.membraneFrequencyOverRate = std::abs(obs.membraneAdvance) / window;
    return out;
}

}  // namespace trbc
