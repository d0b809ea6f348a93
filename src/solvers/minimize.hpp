#pragma once
// Energy minimisation by L-BFGS (hand-written, see README "Why hand-written"): stops on the
// largest per-vertex gradient norm (a force, in the caller's units), is aware of energy round-off
// near tight tolerances, counts evaluations and never throws on a failed line search.
#include <Eigen/Core>
#include <functional>
#include <string>

#include "membrane/model.hpp"

namespace trbc {

struct MinimizeOptions {
    double gradientTolerance = 1e-6;  ///< stop when max_i |dU/dx_i| <= this (force units)
    int maxIterations = 100000;
    int memory = 12;                  ///< number of L-BFGS correction pairs
    double maxVertexStep = 0.0;       ///< cap on any vertex's displacement per iteration (0 = none)
};

struct MinimizeResult {
    bool converged = false;
    int iterations = 0;
    int evaluations = 0;
    double energy = 0.0;
    double gradientNorm = 0.0;        ///< max_i |dU/dx_i| at the returned point
    std::string message;
};

/// f(x, grad) returns the objective and writes its gradient; x holds 3 coordinates per vertex.
using Objective = std::function<double(const Eigen::VectorXd& x, Eigen::VectorXd& grad)>;

/// Minimises f starting from x (overwritten with the best point found).
MinimizeResult lbfgsMinimize(const Objective& f, Eigen::VectorXd& x, const MinimizeOptions& options);

/// U(X) - sum_i f_ext_i . x_i and its gradient (f_ext may be null): the potential that the
/// minimiser and the time integrator work on.
double loadedEnergy(const MembraneModel& model, const Vertices& X, const Vertices* externalForces, Vertices& grad);

/// Minimises U(X) - sum_i f_ext_i . x_i for a membrane model, X updated in place.
MinimizeResult minimizeEnergy(const MembraneModel& model, Vertices& X, const MinimizeOptions& options,
                              const Vertices* externalForces = nullptr);

/// max_i |g_i| over the 3-vectors of a flattened gradient.
double maxVertexNorm(const Eigen::VectorXd& g);

}  // namespace trbc
