// trbc._core: the Python extension module over the trbc library (pybind11). A thin layer: it
// converts numpy arrays and keyword arguments, calls the same library functions as the CLI and
// returns numpy arrays and dicts. The Python package trbc (src/python/trbc) adds the pieces that
// are pure bookkeeping (default data paths, named posteriors).
//
// Arrays: trbc stores one sample (vertex, network input) per column of a column-major matrix; its
// memory is that of a C-contiguous numpy array with one sample per row, so (n, k) float64 arrays
// map onto k x n Eigen matrices without a copy, and results are handed to numpy without a copy.
// Long calls release the GIL and poll Ctrl-C (PyErr_CheckSignals) from the library's
// per-iteration, per-frame or per-stage hooks.
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <omp.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "analysis/calibrated_cell.hpp"
#include "analysis/prediction.hpp"
#include "analysis/validation_data.hpp"
#include "core/csv.hpp"
#include "core/error.hpp"
#include "core/simd.hpp"
#include "core/version.hpp"
#include "experiments/experiments.hpp"
#include "experiments/hochmuth.hpp"
#include "experiments/parameters.hpp"
#include "experiments/sfs.hpp"
#include "experiments/simulation_report.hpp"
#include "flow/flow_record.hpp"
#include "flow/shear_case.hpp"
#include "flow/tube_case.hpp"
#include "inference/hierarchical.hpp"
#include "inference/population.hpp"
#include "inference/rbc_pipeline.hpp"
#include "inference/rbc_problem.hpp"
#include "membrane/model.hpp"
#include "mesh/geometry.hpp"
#include "mesh/icosphere.hpp"
#include "mesh/io.hpp"
#include "mesh/validate.hpp"
#include "surrogate/flow_surrogate.hpp"
#include "surrogate/surrogate.hpp"

namespace py = pybind11;
using namespace pybind11::literals;

namespace trbc::python {
namespace {

// ---- Ctrl-C ------------------------------------------------------------------------------------

/// Thrown from a library hook after PyErr_CheckSignals() has set a Python exception
/// (KeyboardInterrupt); turned back into that exception once the GIL is held again.
struct Interrupted {};

/// A library hook that polls Python's signal handlers at most every 50 ms, from the thread that
/// called into the module only (the main thread; OpenMP workers never run Python code).
class InterruptPoller {
public:
    void operator()() {
        if (std::this_thread::get_id() != thread_) return;
        const auto now = std::chrono::steady_clock::now();
        if (now - last_ < std::chrono::milliseconds(50)) return;
        last_ = now;
        py::gil_scoped_acquire gil;
        if (PyErr_CheckSignals() != 0) throw Interrupted{};
    }

private:
    std::thread::id thread_ = std::this_thread::get_id();
    std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
};

std::function<void()> interruptHook() {
    auto poller = std::make_shared<InterruptPoller>();
    return [poller]() { (*poller)(); };
}

/// Runs f without the GIL; a Ctrl-C seen by the hooks becomes the pending KeyboardInterrupt.
template <class F>
auto withoutGil(F&& f) -> decltype(f()) {
    try {
        py::gil_scoped_release release;
        return f();
    } catch (const Interrupted&) {
        throw py::error_already_set();
    }
}

/// Sets the OpenMP thread count of the calling thread for one call (0 or less: unchanged).
class ThreadScope {
public:
    explicit ThreadScope(int threads) : saved_(omp_get_max_threads()) {
        if (threads > 0) omp_set_num_threads(threads);
    }
    ~ThreadScope() { omp_set_num_threads(saved_); }
    ThreadScope(const ThreadScope&) = delete;
    ThreadScope& operator=(const ThreadScope&) = delete;

private:
    int saved_;
};

// ---- arrays ------------------------------------------------------------------------------------

using RowArray = py::array_t<double, py::array::c_style | py::array::forcecast>;
using IntArray = py::array_t<int, py::array::c_style | py::array::forcecast>;

/// A k x n column-major matrix handed to numpy as an (n, k) array (k = 1: shape (n,)), no copy.
template <class M>
py::array ownedRows(M&& m, bool vector = false) {
    using Plain = std::decay_t<M>;
    using Scalar = typename Plain::Scalar;
    auto* heap = new Plain(std::forward<M>(m));
    py::capsule owner(heap, [](void* p) { delete static_cast<Plain*>(p); });
    const py::ssize_t k = heap->rows(), n = heap->cols();
    if (vector) return py::array_t<Scalar>({n}, {py::ssize_t(sizeof(Scalar)) * k}, heap->data(), owner);
    return py::array_t<Scalar>({n, k}, {py::ssize_t(sizeof(Scalar)) * k, py::ssize_t(sizeof(Scalar))}, heap->data(), owner);
}

py::array ownedVector(Eigen::VectorXd v) {
    auto* heap = new Eigen::VectorXd(std::move(v));
    py::capsule owner(heap, [](void* p) { delete static_cast<Eigen::VectorXd*>(p); });
    return py::array_t<double>({heap->size()}, {py::ssize_t(sizeof(double))}, heap->data(), owner);
}

py::array vectorArray(const std::vector<double>& v) { return ownedVector(Eigen::Map<const Eigen::VectorXd>(v.data(), Eigen::Index(v.size()))); }

/// An (n, k) float64 array as a k x n matrix view (the array must stay alive while it is used).
Eigen::Map<const Eigen::MatrixXd> columnsOf(const RowArray& a, Eigen::Index k, const char* name) {
    if (a.ndim() != 2 || a.shape(1) != k)
        throw InputError(fmt::format("{}: expected an array of shape (n, {}), got {} dimension(s) of sizes {}", name, k, a.ndim(),
                                     fmt::join(std::vector<py::ssize_t>(a.shape(), a.shape() + a.ndim()), " x ")));
    return {a.data(), k, Eigen::Index(a.shape(0))};
}

py::object jsonToPython(const nlohmann::json& j) { return py::module_::import("json").attr("loads")(j.dump()); }

// ---- meshes ------------------------------------------------------------------------------------

Mesh meshFromArrays(const RowArray& vertices, const IntArray& faces) {
    if (vertices.ndim() != 2 || vertices.shape(1) != 3) throw InputError("vertices: expected an array of shape (n, 3)");
    if (faces.ndim() != 2 || faces.shape(1) != 3) throw InputError("faces: expected an integer array of shape (m, 3)");
    Mesh m;
    m.X = Eigen::Map<const Vertices>(vertices.data(), 3, Eigen::Index(vertices.shape(0)));
    m.F = Eigen::Map<const Faces>(faces.data(), 3, Eigen::Index(faces.shape(0)));
    if (!m.X.allFinite()) throw InputError("vertices: every coordinate must be finite");
    if (m.F.size() > 0 && (m.F.minCoeff() < 0 || m.F.maxCoeff() >= m.X.cols()))
        throw InputError(fmt::format("faces: vertex indices must lie in [0, {}]", m.X.cols() - 1));
    return m;
}

/// View of a mesh's vertices as (n, 3) (writable, kept alive by the mesh object).
py::array verticesView(py::object self) {
    Mesh& m = self.cast<Mesh&>();
    return py::array_t<double>({m.X.cols(), Eigen::Index(3)}, {py::ssize_t(3 * sizeof(double)), py::ssize_t(sizeof(double))},
                               m.X.data(), self);
}

py::array facesView(py::object self) {
    Mesh& m = self.cast<Mesh&>();
    return py::array_t<int>({m.F.cols(), Eigen::Index(3)}, {py::ssize_t(3 * sizeof(int)), py::ssize_t(sizeof(int))}, m.F.data(),
                            self);
}

std::vector<VertexField> vertexFields(const Mesh& m, const py::dict& fields) {
    std::vector<VertexField> out;
    for (auto item : fields) {
        const std::string name = py::str(item.first);
        RowArray a = RowArray::ensure(item.second);
        if (!a) throw InputError(fmt::format("fields['{}']: not a numeric array", name));
        const bool scalar = a.ndim() == 1 && a.shape(0) == m.X.cols();
        const bool vector = a.ndim() == 2 && a.shape(0) == m.X.cols() && a.shape(1) == 3;
        if (!scalar && !vector) throw InputError(fmt::format("fields['{}']: expected shape ({},) or ({}, 3)", name, m.X.cols(), m.X.cols()));
        VertexField f;
        f.name = name;
        f.values = Eigen::Map<const Eigen::MatrixXd>(a.data(), scalar ? 1 : 3, m.X.cols());
        out.push_back(std::move(f));
    }
    return out;
}

// ---- membrane energy ---------------------------------------------------------------------------

py::dict membraneEnergy(const Mesh& mesh, const Mesh* reference, double kb, double C0, double kad, double DA0, double ka, double a3,
                        double a4, double mu, double b1, double b2, double kA, std::optional<double> A0, double kV,
                        std::optional<double> V0) {
    MembraneParameters raw;
    raw.bending = {kb, C0, kad, DA0};
    raw.lim = {ka, a3, a4, mu, b1, b2};
    raw.penalty.kA = kA;
    raw.penalty.kV = kV;
    const MembraneParameters p = checkedMembraneParameters(raw, A0.has_value(), A0.value_or(0.0), V0.has_value(), V0.value_or(0.0));
    validateClosedManifold(mesh);
    if (reference)
        validateSameConnectivity(mesh, *reference, "reference");
    else if (p.hasLim())
        throw InputError("the Lim term (ka or mu > 0) needs the stress-free mesh reference");
    const MembraneModel model(mesh.F, mesh.numVertices(), p, reference ? &reference->X : nullptr);
    Vertices grad;
    EnergyTerms terms;
    const double energy = model.evaluate(mesh.X, &grad, &terms);
    if (!std::isfinite(energy) || !grad.allFinite()) throw NumericalError("energy or forces are not finite on this mesh");
    py::dict t;
    if (p.hasBending()) t["bending"] = terms.bending;
    if (p.hasAde()) t["ade"] = terms.ade;
    if (p.hasLim()) t["lim"] = terms.lim;
    if (p.hasArea()) t["area"] = terms.area;
    if (p.hasVolume()) t["volume"] = terms.volume;
    return py::dict("energy"_a = energy, "terms"_a = t, "forces"_a = ownedRows(Vertices(-grad)));
}

// ---- forward model -----------------------------------------------------------------------------

CellParameters cellFromArguments(double v, double mu, std::optional<double> FvK, std::optional<double> kbJ, double b2, double etam,
                                 double defaultKbJ, double defaultFvK) {
    if (FvK && kbJ) throw InputError("give FvK or kb_J, not both");
    CellParameters p;
    p.v = v;
    p.mu = mu;
    p.b2 = b2;
    p.etam = etam;
    if (FvK) {
        p.FvK = *FvK;
    } else {
        const double kb = kbJ ? *kbJ : defaultKbJ;
        if (kbJ || defaultFvK <= 0.0) {
            if (!(kb > 0.0) || !std::isfinite(kb))
                throw InputError(fmt::format("parameter kb_J = {} must be positive (prior [1.074e-19, 1.074e-18] J)", kb));
            p.FvK = CellParameters::fvkFromKb(p.mu, kb);
        } else {
            p.FvK = defaultFvK;
        }
    }
    return p;
}

std::filesystem::path cachePath(bool cache, const std::optional<std::string>& cacheDir) {
    if (!cache) return {};
    return cacheDir ? std::filesystem::path(*cacheDir) : defaultCacheDirectory();
}

Mesh meshOf(const Vertices& X, const Faces& F) { return Mesh{X, F}; }

py::dict simulate(double v, double mu, std::optional<double> FvK, std::optional<double> kbJ, double b2, double etam, double fext,
                  int level, const std::vector<std::string>& experiments, const std::vector<double>& forceCurve,
                  bool allowOutside, int threads, bool cache, const std::optional<std::string>& cacheDir, bool overdamped,
                  const std::string& inPlaneAxis, const std::string& equilibriumSymmetry,
                  std::optional<std::uint64_t> equilibriumSeed, std::optional<int> equilibriumKicks) {
    const CellParameters p = cellFromArguments(v, mu, FvK, kbJ, b2, etam, 0.0, 250.0);
    if (level < 2 || level > 6) throw InputError(fmt::format("level = {} is out of range [2, 6]", level));
    validateCellParameters(p, allowOutside);
    validateForce(fext, allowOutside);
    const ExperimentSet which = parseExperimentSet(experiments, "experiments");
    for (double f : forceCurve) validateForce(f, allowOutside);
    ExperimentOptions eo;
    eo.level = level;
    eo.cacheDir = cachePath(cache, cacheDir);
    eo.overdamped = overdamped;
    if (inPlaneAxis == inPlaneAxisName(InPlaneAxis::LargestVariance))
        eo.inPlaneAxis = InPlaneAxis::LargestVariance;
    else if (inPlaneAxis != inPlaneAxisName(InPlaneAxis::FarthestVertex))
        throw InputError(fmt::format("in_plane_axis = '{}' is not one of farthest-vertex, largest-variance", inPlaneAxis));
    eo.equilibriumSymmetry = equilibriumSymmetryFromName(equilibriumSymmetry, "equilibrium_symmetry");
    if (equilibriumSeed) eo.kicks.seed = *equilibriumSeed;
    if (equilibriumKicks) {
        if (*equilibriumKicks < 1 || *equilibriumKicks > 100)
            throw InputError(fmt::format("equilibrium_kicks = {} is out of range [1, 100]", *equilibriumKicks));
        eo.kicks.perRound = *equilibriumKicks;
    }
    eo.interruptCheck = interruptHook();
    eo.sfs.interruptCheck = eo.interruptCheck;
    if (threads < 1) throw InputError(fmt::format("threads = {} is out of range [1, 1024]", threads));

    SampleResult s;
    double wall = 0.0;
    withoutGil([&] {
        const ThreadScope ts(threads);
        const auto t0 = std::chrono::steady_clock::now();
        s = runSample(p, fext, which, eo, forceCurve, true);
        wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        return 0;
    });
    nlohmann::json j = simulationJson(p, fext, level, which, s, wall);
    j["provenance"] = withBuild({{"forward_model_revision", kForwardModelRevision}, {"level", level},
                                 {"vertices", 10 * (1 << (2 * level)) + 2}, {"sfs_model_version", kSfsModelVersion}, {"threads", threads},
                                 {"in_plane_axis", inPlaneAxisName(eo.inPlaneAxis)}, {"preconditioner", "multigrid"},
                                 {"equilibrium_symmetry", equilibriumSymmetryName(eo.equilibriumSymmetry)},
                                 {"equilibrium_seed", eo.kicks.seed}, {"equilibrium_kicks", eo.kicks.perRound}});
    py::dict out = jsonToPython(j).cast<py::dict>();
    // Shapes and curves (what `trbc simulate --save-shapes` writes), um and s.
    const Faces& F = s.sfs.mesh.F;
    py::dict shapes;
    shapes["sfs"] = meshOf(cellMeshes(s.sfs).reference, F);
    shapes["equilibrium"] = meshOf(s.equilibrium.shape, F);
    const ThicknessProfile& pr = s.equilibrium.profile;
    std::vector<double> h(pr.r.size());
    for (std::size_t i = 0; i < h.size(); ++i) h[i] = pr.zHigh[i] - pr.zLow[i];
    out["equilibrium_profile"] = py::dict("r_um"_a = vectorArray(pr.r), "zlow_um"_a = vectorArray(pr.zLow),
                                          "zhigh_um"_a = vectorArray(pr.zHigh), "h_um"_a = vectorArray(h));
    if (which.stretching) {
        py::list stretched;
        std::vector<double> f, d0, d1;
        for (std::size_t k = 0; k < s.stretching.size(); ++k) {
            stretched.append(py::make_tuple(s.stretching[k].fext, meshOf(s.stretchShapes[k], F)));
            if (k == 0 && s.stretching.size() > 1) continue;  // the requested force; the curve follows
            f.push_back(s.stretching[k].fext);
            d0.push_back(s.stretching[k].observables.D0);
            d1.push_back(s.stretching[k].observables.D1);
        }
        shapes["stretched"] = stretched;
        out["stretching_curve_arrays"] = py::dict("Fext_pN"_a = vectorArray(f), "D0_um"_a = vectorArray(d0), "D1_um"_a = vectorArray(d1));
    }
    if (which.relaxation) {
        const RelaxationResult& r = s.relaxation;
        shapes["relaxation_release"] = meshOf(r.released, F);
        shapes["relaxation_end"] = meshOf(r.final, F);
        out["relaxation"] = py::dict("t_s"_a = vectorArray(r.t), "L_um"_a = vectorArray(r.L), "W_um"_a = vectorArray(r.W),
                                     "z"_a = vectorArray(r.z));
    }
    out["shapes"] = shapes;
    return out;
}

py::dict stressFree(double v, int level, double tol, const std::string& preconditioner, bool cache,
                    const std::optional<std::string>& cacheDir) {
    if (level < 1 || level > 6) throw InputError(fmt::format("level = {} is out of range [1, 6]", level));
    if (!(tol > 0.0)) throw InputError(fmt::format("tol = {} must be > 0", tol));
    if (preconditioner != "multigrid" && preconditioner != "none")
        throw InputError(fmt::format("preconditioner = '{}' is not one of multigrid, none", preconditioner));
    SfsOptions so;
    so.gradientTolerance = tol;
    so.multigrid = preconditioner == "multigrid";
    so.interruptCheck = interruptHook();
    const std::filesystem::path dir = cachePath(cache, cacheDir);
    const StressFreeState s = withoutGil([&] { return stressFreeState(v, level, dir, so); });
    Mesh out = s.mesh;
    out.X = scaleToArea(out.X, out.F, cell::area);
    return py::dict("mesh"_a = out, "diagnostics"_a = jsonToPython(sfsJson(s)));
}

// ---- reference shape and relaxation law --------------------------------------------------------

/// A 1-D float64 array as a vector (ValueError naming the argument otherwise).
std::vector<double> vectorOf(const RowArray& a, const char* name) {
    if (a.ndim() != 1) throw InputError(fmt::format("{}: expected a 1-D array, got {} dimension(s)", name, a.ndim()));
    return {a.data(), a.data() + a.shape(0)};
}

/// h(r) of the Evans-Fung shape at every element of r (any shape; the result has the same shape).
py::array evansFungThicknessArray(const RowArray& r) {
    py::array_t<double> h(std::vector<py::ssize_t>(r.shape(), r.shape() + r.ndim()));
    const double* in = r.data();
    double* out = h.mutable_data();
    for (py::ssize_t i = 0; i < r.size(); ++i) out[i] = evansFungThickness(in[i]);
    return h;
}

/// fitHochmuth on two 1-D arrays. A start not given is fitHochmuth's default argument; its defaults are
/// positional (tc, then zInf), so zInf alone cannot be given without restating the tc default here.
py::dict fitHochmuthArrays(const RowArray& t, const RowArray& z, std::optional<double> tcGuess, std::optional<double> zInfGuess) {
    const std::vector<double> tv = vectorOf(t, "t_s"), zv = vectorOf(z, "z");
    HochmuthFit f;
    if (tcGuess && zInfGuess)
        f = fitHochmuth(tv, zv, *tcGuess, *zInfGuess);
    else if (tcGuess)
        f = fitHochmuth(tv, zv, *tcGuess);
    else if (zInfGuess)
        throw InputError("zinf_guess needs tc_guess_s as well");
    else
        f = fitHochmuth(tv, zv);
    return py::dict("tc_s"_a = f.tc, "zinf"_a = f.zInf, "z0"_a = f.z0, "t0_s"_a = f.t0, "rms"_a = f.rms,
                    "converged"_a = f.converged, "iterations"_a = f.iterations, "message"_a = f.message);
}

// ---- surrogates --------------------------------------------------------------------------------

py::array surrogateEvaluate(const Surrogate& s, const RowArray& x, int threads) {
    const auto X = columnsOf(x, 6, "x");
    Eigen::MatrixXd y = withoutGil([&] {
        const ThreadScope ts(threads);
        return s.evaluate(X);
    });
    return ownedRows(std::move(y));
}

/// The cytosol viscosity of each of n inputs.
Eigen::Map<const Eigen::VectorXd> cytosolOf(const RowArray& etaIn, Eigen::Index n) {
    if (etaIn.ndim() != 1 || etaIn.shape(0) != n)
        throw InputError(fmt::format("eta_in_mPa_s: {} values for {} inputs", etaIn.ndim() == 1 ? etaIn.shape(0) : -1, n));
    return {etaIn.data(), etaIn.shape(0)};
}

/// (n, 7) inputs and (n,) cytosol viscosities -> (n, 5): p_tank_treading, inclination_deg, swing_deg,
/// ttf_4pi_f_over_rate, outside_box (0 or 1).

py::array flowSurrogatePredict(const FlowSurrogate& s, const RowArray& x, const RowArray& etaIn, int threads) {
    const auto X = columnsOf(x, 7, "x");
    const auto eta = cytosolOf(etaIn, X.cols());
    Eigen::MatrixXd y = withoutGil([&] {
        const ThreadScope ts(threads);
        const FlowPrediction p = s.predict(X, eta);
        Eigen::MatrixXd out(5, X.cols());
        out.row(0) = p.pTankTreading.transpose();
        out.row(1) = p.inclinationDeg.transpose();
        out.row(2) = p.swingDeg.transpose();
        out.row(3) = p.ttf.transpose();
        for (Eigen::Index j = 0; j < X.cols(); ++j) out(4, j) = p.outsideBox[std::size_t(j)] ? 1.0 : 0.0;
        return out;
    });
    return ownedRows(std::move(y));
}

py::array surrogateGradient(const Surrogate& s, const RowArray& x, std::optional<RowArray> weights, int threads) {
    const auto X = columnsOf(x, 6, "x");
    if (weights) {
        const auto W = columnsOf(*weights, 6, "weights");
        if (W.cols() != X.cols()) throw InputError(fmt::format("weights: {} rows, x has {}", W.cols(), X.cols()));
        Eigen::MatrixXd g = withoutGil([&] {
            const ThreadScope ts(threads);
            return s.inputGradient(X, W);
        });
        return ownedRows(std::move(g));
    }
    auto* J = new Eigen::MatrixXd(withoutGil([&] {
        const ThreadScope ts(threads);
        return s.inputJacobian(X);
    }));
    py::capsule owner(J, [](void* p) { delete static_cast<Eigen::MatrixXd*>(p); });
    const py::ssize_t d = sizeof(double);
    return py::array_t<double>({py::ssize_t(J->cols()), py::ssize_t(6), py::ssize_t(6)}, {36 * d, 6 * d, d}, J->data(), owner);
}

py::array outsideBox(const RowArray& x) {
    const auto X = columnsOf(x, 6, "x");
    const std::vector<bool> o = outsideTrainingBox(X);
    py::array_t<bool> out(py::ssize_t(o.size()));
    auto r = out.mutable_unchecked<1>();
    for (std::size_t i = 0; i < o.size(); ++i) r(py::ssize_t(i)) = o[i];
    return out;
}

// ---- inference ---------------------------------------------------------------------------------

/// Phase-1 log-posterior of one data set, log pi_i(theta) + log L_i(theta), in the physical units of
/// the samples files (kb in J; the density is that of the inference variables, kb in 1e-18 J, so
/// log-densities differ from a density in J by a constant).
class Phase1Posterior {
public:
    Phase1Posterior(std::shared_ptr<Surrogate> surrogate, RbcDataSet data)
        : model_(surrogateRbcModel(std::move(surrogate))), data_(std::move(data)), prior_(phase1Prior(data_)),
          scale_(phase1OutputScale(data_.experiment)) {}

    const RbcDataSet& data() const { return data_; }
    std::vector<std::string> names() const { return phase1OutputNames(data_); }
    int dimension() const { return int(scale_.size()); }
    py::array lower() const { return ownedVector(prior_->lowerBounds().cwiseProduct(scale_)); }
    py::array upper() const { return ownedVector(prior_->upperBounds().cwiseProduct(scale_)); }

    /// (d,) -> float, (n, d) -> (n,) array.
    py::object logPrior(const py::array& theta) const { return apply(theta, false, true); }
    py::object logLikelihood(const py::array& theta) const { return apply(theta, true, false); }
    py::object logPosterior(const py::array& theta) const { return apply(theta, true, true); }

    py::array samplePrior(long n, std::uint64_t seed) const {
        if (n < 1) throw InputError(fmt::format("n = {} must be >= 1", n));
        Eigen::MatrixXd out(scale_.size(), n);
        for (long k = 0; k < n; ++k) {
            Rng rng(seed, 0x50524952ULL, std::uint64_t(k));
            out.col(k) = prior_->sample(rng).cwiseProduct(scale_);
        }
        return ownedRows(std::move(out));
    }

private:
    py::object apply(const py::array& theta, bool likelihood, bool prior) const {
        RowArray a = RowArray::ensure(theta);
        if (!a) throw InputError("theta: not a numeric array");
        const Eigen::Index d = scale_.size();
        const bool single = a.ndim() == 1;
        if (!(single && a.shape(0) == d) && !(a.ndim() == 2 && a.shape(1) == d))
            throw InputError(fmt::format("theta: expected shape ({},) or (n, {}) with the parameters {}", d, d, fmt::join(names(), ", ")));
        const Eigen::Index n = single ? 1 : Eigen::Index(a.shape(0));
        Eigen::MatrixXd t = Eigen::Map<const Eigen::MatrixXd>(a.data(), d, n);
        t.array().colwise() /= scale_.array();
        Eigen::VectorXd out = withoutGil([&] {
            Eigen::VectorXd lp(n);
            for (Eigen::Index k = 0; k < n; ++k) lp(k) = prior_->logDensity(t.col(k));
            Eigen::VectorXd r = prior ? lp : Eigen::VectorXd::Zero(n);
            if (likelihood) {
                const Eigen::VectorXd ll = rbcLogLikelihood(model_, data_, t);
                for (Eigen::Index k = 0; k < n; ++k) r(k) = (prior && std::isinf(lp(k)) && lp(k) < 0) ? lp(k) : r(k) + ll(k);
            }
            return r;
        });
        if (single) return py::float_(out(0));
        return ownedVector(std::move(out));
    }

    RbcModel model_;
    RbcDataSet data_;
    std::shared_ptr<const ProductPrior> prior_;
    Eigen::VectorXd scale_;
};

/// Phase-2 (hierarchical) log-posterior of the hyper-parameters psi given the phase-1 samples of
/// every data set (docs/BAYESIAN_INFERENCE.md): log p(psi) + sum_i log b_i(psi); psi in the physical units of
/// the samples files (hyperOutputNames), the density that of the inference variables.
class HierarchicalPosterior {
public:
    HierarchicalPosterior(const std::vector<RbcDataSet>& data, const std::vector<RowArray>& phase1Samples) {
        if (data.size() != phase1Samples.size() || data.empty())
            throw InputError(fmt::format("phase1_samples: one array per data set is needed ({} data sets, {} arrays)", data.size(),
                                         phase1Samples.size()));
        std::vector<ReweightingSamples> sets;
        for (std::size_t i = 0; i < data.size(); ++i) {
            const Eigen::VectorXd scale = phase1OutputScale(data[i].experiment);
            const std::string what = "phase1_samples[" + data[i].name + "]";
            Eigen::MatrixXd x = columnsOf(phase1Samples[i], scale.size(), what.c_str());
            x.array().colwise() /= scale.array();
            sets.push_back(reweightingSamples(data[i], x));
        }
        problem_ = phase2Problem(std::move(sets));
    }
    std::vector<std::string> names() const { return hyperOutputNames(); }
    py::object logPosterior(const py::array& psi) const { return apply(psi, true); }
    py::object logLikelihood(const py::array& psi) const { return apply(psi, false); }

private:
    py::object apply(const py::array& psi, bool withPrior) const {
        RowArray a = RowArray::ensure(psi);
        if (!a) throw InputError("psi: not a numeric array");
        const bool single = a.ndim() == 1;
        if (!(single && a.shape(0) == kHyperDimension) && !(a.ndim() == 2 && a.shape(1) == kHyperDimension))
            throw InputError(fmt::format("psi: expected shape ({},) or (n, {})", kHyperDimension, kHyperDimension));
        const Eigen::Index n = single ? 1 : Eigen::Index(a.shape(0));
        Eigen::MatrixXd p = Eigen::Map<const Eigen::MatrixXd>(a.data(), kHyperDimension, n);
        p.array().colwise() /= hyperOutputScale().array();  // physical units (kb in J) -> inference units
        Eigen::VectorXd out = withoutGil([&] {
            Eigen::VectorXd lp(n);
            for (Eigen::Index k = 0; k < n; ++k) lp(k) = problem_.prior->logDensity(p.col(k));
            const Eigen::VectorXd ll = problem_.batchLogLikelihood(p);
            if (!withPrior) return ll;
            for (Eigen::Index k = 0; k < n; ++k) lp(k) = std::isinf(lp(k)) && lp(k) < 0 ? lp(k) : lp(k) + ll(k);
            return lp;
        });
        if (single) return py::float_(out(0));
        return ownedVector(std::move(out));
    }

    TmcmcProblem problem_;
};

py::dict runInference(const std::string& out, int firstPhase, int lastPhase, int samples, std::uint64_t seed,
                      std::shared_ptr<Surrogate> surrogate, const std::vector<RbcDataSet>& data, bool resume, int threads,
                      py::object progress, const std::string& method, int chains, int warmup, int draws, int thin) {
    if (samples < 2) throw InputError(fmt::format("samples = {} is out of range [2, 100000000]", samples));
    if (firstPhase < 1 || lastPhase > 3 || firstPhase > lastPhase)
        throw InputError(fmt::format("phase: {}..{} is not a range of the phases 1, 2, 3", firstPhase, lastPhase));
    RbcInferenceOptions opt;
    opt.outputDirectory = out;
    opt.firstPhase = firstPhase;
    opt.lastPhase = lastPhase;
    opt.populationSize = samples;
    opt.seed = seed;
    opt.resume = resume;
    if (method != "joint" && method != "reweighting")
        throw InputError(fmt::format("method = '{}' is invalid: joint or reweighting", method));
    opt.method = method == "joint" ? HierarchicalMethod::Joint : HierarchicalMethod::Reweighting;
    opt.chains = chains, opt.warmup = warmup, opt.draws = draws, opt.thin = thin;  // checked by the sampler, naming each
    opt.provenance = {{"command", "trbc.infer (Python)"}, {"model", {{"precision", surrogate->precision == Precision::Single ? "single" : "double"}}}};
    auto poll = interruptHook();
    opt.progress = [poll, progress](const std::string& line) {
        poll();
        if (!progress.is_none()) {
            py::gil_scoped_acquire gil;
            try {
                progress(line);
            } catch (py::error_already_set& e) {
                e.restore();  // the callback's exception, raised once the GIL is held again
                throw Interrupted{};
            }
        }
    };
    const RbcInferenceResult r = withoutGil([&] {
        const ThreadScope ts(threads);
        return runRbcInference(surrogateRbcModel(surrogate), data, opt);
    });
    py::dict timing;
    for (int ph = 0; ph < 3; ++ph)
        if (r.timing[ph].ran)
            timing[py::str("phase" + std::to_string(ph + 1))] =
                py::dict("wall_s"_a = r.timing[ph].wallSeconds, "surrogate_s"_a = r.timing[ph].surrogateSeconds,
                         "population_s"_a = r.timing[ph].populationSeconds);
    py::dict evidence;
    for (std::size_t i = 0; i < r.phase1.size() && i < data.size(); ++i) evidence[py::str(data[i].name)] = r.phase1[i].logEvidence;
    return py::dict("wall_s"_a = r.wallSeconds, "timing"_a = timing, "phase1_log_evidence"_a = evidence);
}

/// Columns and values (n, k) of a samples.csv written by `trbc infer`.
py::tuple readSamples(const std::string& file) {
    const NumericTable t = readNumericTable(file, {});
    Eigen::MatrixXd v = t.values.transpose();  // k x n column-major = (n, k) row-major
    return py::make_tuple(t.columns, ownedRows(std::move(v)));
}

py::dict bandDict(const ObservableBand& b) {
    const std::vector<double>& levels = predictiveLevels();
    py::dict d;
    d["x"] = vectorArray(b.x);
    std::vector<double> mean;
    for (const PredictiveSummary& s : b.summary) mean.push_back(s.mean);
    d["mean"] = vectorArray(mean);
    for (std::size_t q = 0; q < levels.size(); ++q) {
        std::vector<double> col;
        for (const PredictiveSummary& s : b.summary) col.push_back(s.quantiles(Eigen::Index(q)));
        d[py::str(levelSuffix(levels[q]))] = vectorArray(col);
    }
    return d;
}

py::dict predict(const std::string& posterior, std::shared_ptr<Surrogate> surrogate, const std::optional<RbcDataSet>& data,
                 int grid, long maxSamples, std::uint64_t seed) {
    if (grid < 2) throw InputError(fmt::format("grid = {} is out of range [2, 100000]", grid));
    PosteriorSamples full = readPosteriorSamples(posterior);
    const PosteriorSamples s = maxSamples > 0 ? selectSamples(full, subsampleIndices(full.values.cols(), maxSamples, seed)) : full;
    PredictionOptions popt;
    popt.gridPoints = grid;
    const RbcDataSet* ds = data ? &*data : nullptr;
    const PosteriorPrediction p = withoutGil([&] { return predictPosterior(s, surrogateRbcModel(surrogate), ds, popt); });
    py::dict bands;
    for (const ObservableBand& b : p.bands) bands[py::str(b.observable)] = bandDict(b);
    py::list coverage;
    for (const CoveragePoint& c : p.coverage)
        coverage.append(py::dict("observable"_a = c.observable, "x"_a = c.x, "y"_a = c.y, "q05"_a = c.q05, "q50"_a = c.q50,
                                 "q95"_a = c.q95, "inside"_a = c.inside()));
    return py::dict("label"_a = p.label, "experiment"_a = experimentName(p.experiment), "samples_used"_a = p.samplesUsed,
                    "x_name"_a = p.xName, "bands"_a = bands, "coverage"_a = coverage);
}

// ---- flows -------------------------------------------------------------------------------------

/// The library's stepping options of a Python call (times in the case's unit); Ctrl-C is polled
/// at every frame.
FlowCaseStepping pythonStepping(FlowCaseStepping s, double frameInterval, std::optional<double> stepTol,
                                std::optional<double> dt, int maxSteps) {
    s.frameInterval = frameInterval;
    if (stepTol) s.stepTolerance = *stepTol;
    s.dt = dt.value_or(0.0);
    s.maxSteps = maxSteps;
    s.progress = [poll = interruptHook()](const FlowCaseProgress&) { poll(); };
    return s;
}

/// Where a flow call's cell came from, for its record.
constexpr const char* kPythonCellSource = "keyword arguments (those not given: the paper's Table 1 means)";

/// The provenance of a flow call's record.
nlohmann::json flowProvenance(int level, int threads) {
    return withBuild({{"command", "trbc Python package"},
                      {"level", level},
                      {"vertices", 10 * (1 << (2 * level)) + 2},
                      {"threads", threads > 0 ? threads : omp_get_max_threads()},
                      {"sfs_model_version", kSfsModelVersion}});
}

py::dict flowShear(double etaOut, double rate, double etaIn, double v, double mu, std::optional<double> FvK, std::optional<double> kbJ,
                   double b2, double etam, bool allowOutside, int level, double rotations, double tiltDeg,
                   const std::string& start, double kickTemperatureK, double temperatureK, double thermalStep,
                   std::uint64_t seed, bool stopWhenSteady, double stepTol, double frameInterval, std::optional<double> dt,
                   int maxSteps, int threads, bool cache, const std::optional<std::string>& cacheDir) {
    ShearCaseOptions o;
    o.stopWhenSteady = stopWhenSteady;
    if (start != "in-plane" && start != "random")
        throw InputError(fmt::format("flow_shear: start = '{}': must be 'in-plane' or 'random'", start));
    o.randomStart = start == "random";
    o.kickTemperatureK = kickTemperatureK;
    o.temperatureK = temperatureK;
    o.thermalStep = thermalStep;
    o.seed = seed;
    o.etaOut = etaOut;
    o.shearRate = rate;
    o.etaIn = etaIn;
    o.cell = cellFromArguments(v, mu, FvK, kbJ, b2, etam, table1::kbJ, 0.0);
    o.allowOutsidePrior = allowOutside;
    o.level = level;
    o.rotations = rotations;
    o.tiltDeg = tiltDeg;
    o.cacheDir = cachePath(cache, cacheDir);
    o.step = pythonStepping(o.step, frameInterval, stepTol, dt, maxSteps);
    const ShearCaseResult r = withoutGil([&] {
        const ThreadScope ts(threads);
        return runShearCase(o);
    });
    if (!r.completed) throw NumericalError("flow shear: " + r.message);
    const ShearFrameSeries& s = r.series;
    py::dict out = jsonToPython(shearRecord(r, o, kPythonCellSource, flowProvenance(level, threads))).cast<py::dict>();
    out["time_series"] = py::dict("t_s"_a = vectorArray(s.time), "shear_strain"_a = vectorArray(s.shearStrain),
                                  "inclination_deg"_a = vectorArray(s.inclinationDeg),
                                  "orientation_unwrapped_deg"_a = vectorArray(s.orientationDeg),
                                  "area_drift"_a = vectorArray(s.areaDrift), "volume_drift"_a = vectorArray(s.volumeDrift),
                                  "centroid_um"_a = ownedRows(Eigen::Matrix3Xd(s.centroidUm)));
    out["final_shape"] = meshOf(r.flow.final * r.scales.length, r.prepared.faces);
    return out;
}

py::dict tubeSeriesDict(const TubeFrameSeries& s) {
    return py::dict("t_s"_a = vectorArray(s.time), "t_R_over_V"_a = vectorArray(s.timeROverV),
                    "centroid_um"_a = ownedRows(Eigen::Matrix3Xd(s.centroidUm)), "length_um"_a = vectorArray(s.lengthUm),
                    "width_y_um"_a = vectorArray(s.widthYUm), "width_z_um"_a = vectorArray(s.widthZUm),
                    "clearance_um"_a = vectorArray(s.clearanceUm), "area_drift"_a = vectorArray(s.areaDrift),
                    "volume_drift"_a = vectorArray(s.volumeDrift));
}

/// The settling stage: its diagnostics as flow.json has them and its time series; None when it did not run.
py::object tubeSettlingDict(const TubeCaseResult& r, const nlohmann::json& record) {
    if (!r.settling.ran) return py::none();
    py::dict d = jsonToPython(record.at("diagnostics").at("settling")).cast<py::dict>();
    d["time_series"] = tubeSeriesDict(r.settling.series);
    return d;
}

py::dict flowTube(double radius, double pg, double etaOut, double lambda, double v, double mu, std::optional<double> FvK,
                  std::optional<double> kbJ, double b2, double etam, bool allowOutside, int level, double duration, double settle,
                  std::optional<double> settleRelax, std::optional<double> settleEtam, double settleTol, int wallPoints,
                  double tubeLength, double repulsionRange, double repulsionPressure, double frameInterval,
                  std::optional<double> stepTol, std::optional<double> dt, int maxSteps, int threads, bool cache,
                  const std::optional<std::string>& cacheDir) {
    if (settleRelax && settleEtam) throw InputError("give settle_relax_R_over_V or settle_etam_Pa_s_um, not both");
    TubeCaseOptions o;
    o.radius = radius, o.pressureGradient = pg, o.etaOut = etaOut, o.viscosityRatio = lambda;
    o.cell = cellFromArguments(v, mu, FvK, kbJ, b2, etam, table1::kbJ, 0.0);
    o.allowOutsidePrior = allowOutside;
    o.level = level, o.duration = duration, o.settle = settle;
    if (settleRelax) o.settleRelax = *settleRelax;
    o.settleEtam = settleEtam;
    o.settleTolerance = settleTol, o.wallPoints = wallPoints, o.tubeLength = tubeLength;
    o.repulsionRange = repulsionRange, o.repulsionPressure = repulsionPressure;
    o.cacheDir = cachePath(cache, cacheDir);
    o.step = pythonStepping(o.step, frameInterval, stepTol, dt, maxSteps);
    const TubeCaseResult r = withoutGil([&] {
        const ThreadScope ts(threads);
        return runTubeCase(o);
    });
    if (!r.completed) throw NumericalError((r.stage == TubeCaseStage::Fit ? "flow tube: " : "flow tube, ") + r.message);
    const nlohmann::json record = tubeRecord(r, o, kPythonCellSource, flowProvenance(level, threads));
    py::dict out = jsonToPython(record).cast<py::dict>();
    out["time_series"] = tubeSeriesDict(r.main.series);
    out["settling"] = tubeSettlingDict(r, record);
    out["final_shape"] = meshOf(r.main.flow.final * r.scales.length, r.prepared.faces);
    return out;
}

// ---- module ------------------------------------------------------------------------------------

/// The library's errors as Python exceptions: InputError -> ValueError, NumericalError ->
/// trbc._core.NumericalError (a RuntimeError), IoError -> OSError.
void registerExceptions(py::module_& m) {
    static py::exception<NumericalError> numericalError(m, "NumericalError", PyExc_RuntimeError);
    py::register_exception_translator([](std::exception_ptr p) {
        try {
            if (p) std::rethrow_exception(p);
        } catch (const InputError& e) {
            PyErr_SetString(PyExc_ValueError, e.what());
        } catch (const NumericalError& e) {
            numericalError(e.what());
        } catch (const IoError& e) {
            PyErr_SetString(PyExc_OSError, e.what());
        }
    });
}

/// trbc.Mesh; vertices and faces are views of the mesh's own storage, kept alive by the Python object.
void registerMesh(py::module_& m) {
    py::class_<Mesh>(m, "Mesh", "A closed triangle mesh: vertices (n, 3) float64 and faces (m, 3) int32, counter-clockwise seen "
                                "from outside. Lengths in the mesh's own units (trbc's cell shapes: um).")
        .def(py::init(&meshFromArrays), "vertices"_a, "faces"_a, "Copies the arrays: vertices (n, 3), faces (m, 3) 0-based indices.")
        .def_property("vertices", &verticesView,
                      [](Mesh& self, const RowArray& a) {
                          if (a.ndim() != 2 || a.shape(1) != 3 || a.shape(0) != self.X.cols())
                              throw InputError(fmt::format("vertices: expected an array of shape ({}, 3)", self.X.cols()));
                          self.X = Eigen::Map<const Vertices>(a.data(), 3, self.X.cols());
                      },
                      "(n, 3) float64 view of the vertex positions (writable; no copy)")
        .def_property_readonly("faces", &facesView, "(m, 3) int32 view of the faces (no copy)")
        .def_property_readonly("n_vertices", &Mesh::numVertices)
        .def_property_readonly("n_faces", &Mesh::numFaces)
        .def_property_readonly("area", [](const Mesh& s) { return totalArea(s.X, s.F); }, "total area A = sum of face areas (length^2)")
        .def_property_readonly("volume", [](const Mesh& s) { return enclosedVolume(s.X, s.F); }, "enclosed volume V (length^3)")
        .def_property_readonly("reduced_volume", [](const Mesh& s) { return reducedVolume(s.X, s.F); },
                               "v = 6 sqrt(pi) V / A^(3/2) (dimensionless, 1 for a sphere)")
        .def("vertex_areas", [](const Mesh& s) { return ownedVector(vertexAreas(s.X, s.F)); }, "A_i = 1/3 of the adjacent face areas, (n,)")
        .def("validate", [](const Mesh& s) { validateClosedManifold(s); }, "ValueError unless the mesh is a closed, oriented 2-manifold")
        .def_static("read", [](const std::string& path) { return readMesh(path); }, "path"_a,
                    "Reads an ASCII .off, .ply or .vtk file (validated as a closed manifold)")
        .def("write", [](const Mesh& s, const std::string& path, std::optional<py::dict> fields) {
                 writeMesh(path, s, fields ? vertexFields(s, *fields) : std::vector<VertexField>{});
             }, "path"_a, "fields"_a = py::none(),
             "Writes .off, .ply or .vtk by extension; fields: {name: (n,) or (n, 3) array} per vertex (PLY, VTK)")
        .def_static("icosphere", [](int level) {
                        if (level < 0 || level > 7) throw InputError(fmt::format("level = {} is out of range [0, 7]", level));
                        return icosphere(level);
                    }, "level"_a, "Unit icosphere after `level` subdivisions: 10 4^level + 2 vertices")
        .def("copy", [](const Mesh& s) { return s; })
        .def("__copy__", [](const Mesh& s) { return s; })
        .def("__deepcopy__", [](const Mesh& s, py::dict) { return s; })
        .def("__repr__", [](const Mesh& s) { return fmt::format("trbc.Mesh({} vertices, {} faces)", s.X.cols(), s.F.cols()); });
}

/// The forward model: membrane energy of a mesh, the cell simulation of the experiments, the stress-free shape;
/// the Evans-Fung resting shape and the Hochmuth fit that its outputs are compared with.
void registerForwardModel(py::module_& m) {
    m.def("membrane_energy", &membraneEnergy, "mesh"_a, "reference"_a = nullptr, py::kw_only(), "kb"_a = 0.0, "C0"_a = 0.0, "kad"_a = 0.0,
          "DA0"_a = 0.0, "ka"_a = 0.0, "a3"_a = 0.0, "a4"_a = 0.0, "mu"_a = 0.0, "b1"_a = 0.0, "b2"_a = 0.0, "kA"_a = 0.0,
          "A0"_a = py::none(), "kV"_a = 0.0, "V0"_a = py::none());
    m.def("simulate", &simulate, py::kw_only(), "v"_a, "mu_uN_per_m"_a, "FvK"_a, "kb_J"_a, "b2"_a, "etam_Pa_s_um"_a, "Fext_pN"_a,
          "level"_a, "experiments"_a, "force_curve"_a, "allow_outside_prior"_a, "threads"_a, "cache"_a, "cache_dir"_a, "overdamped"_a,
          "in_plane_axis"_a, "equilibrium_symmetry"_a, "equilibrium_seed"_a, "equilibrium_kicks"_a);
    m.def("sfs", &stressFree, py::kw_only(), "v"_a, "level"_a, "tol"_a, "preconditioner"_a, "cache"_a, "cache_dir"_a);
    m.def("evans_fung_thickness", &evansFungThicknessArray, "r_um"_a,
          "Thickness h (um) of the Evans & Fung (1972) biconcave resting shape at distance r_um (um) from its symmetry "
          "axis: h = R0 sqrt(1 - rho^2) (c0 + c1 rho^2 + c2 rho^4), rho = r/R0, R0 = evans_fung_radius_um(); 0 for "
          "|r| >= R0. Array (or scalar) in, float64 array of the same shape out.");
    m.def("evans_fung_radius_um", [] { return EvansFung{}.R0; },
          "Radius R0 (um) of the Evans & Fung (1972) shape: the thickness vanishes at r = R0 (diameter 2 R0).");
    m.def("fit_hochmuth", &fitHochmuthArrays, "t_s"_a, "z"_a, py::kw_only(), "tc_guess_s"_a = py::none(), "zinf_guess"_a = py::none(),
          "Least-squares fit of the Hochmuth et al. (1979) recovery law z(t) = zinf (Lam + e)/(Lam - e), "
          "e = exp(-(t - t0)/tc), Lam = (z0 + zinf)/(z0 - zinf), to a deformation index z = L/W sampled at times t_s "
          "(s, strictly increasing); z0 = z[0] and t0 = t_s[0] are fixed, tc and zinf are fitted (Levenberg-Marquardt "
          "in log tc, as for the relaxation_fit of `trbc simulate`). tc_guess_s (s), zinf_guess: the start (None: the "
          "library's; zinf_guess only together with tc_guess_s). Returns {tc_s (s), zinf, z0, t0_s (s), rms "
          "(root-mean-square residual of z), converged, iterations, message}; a fit that does not converge returns "
          "converged = False with the reason in message. ValueError on bad data (lengths differ, fewer than 3 "
          "samples, non-finite values, t_s not strictly increasing).");
}

/// The network surrogates of the experiments and of the flow cases, with their input and output names.
void registerSurrogates(py::module_& m) {
    py::class_<Surrogate, std::shared_ptr<Surrogate>>(m, "Surrogate")
        .def(py::init([](const std::string& dir, const std::string& precision) {
                 if (precision != "double" && precision != "single")
                     throw InputError(fmt::format("precision = '{}' is not one of double, single", precision));
                 auto s = std::make_shared<Surrogate>(Surrogate::load(dir));
                 s->precision = precision == "single" ? Precision::Single : Precision::Double;
                 return s;
             }), "model_dir"_a, "precision"_a = "double")
        .def_property_readonly("precision", [](const Surrogate& s) { return s.precision == Precision::Single ? "single" : "double"; })
        .def("_evaluate", &surrogateEvaluate, "x"_a, "threads"_a = 0)
        .def("_gradient", &surrogateGradient, "x"_a, "weights"_a = py::none(), "threads"_a = 0);
    m.def("outside_training_box", &outsideBox, "x"_a);
    py::class_<FlowSurrogate, std::shared_ptr<FlowSurrogate>>(m, "FlowSurrogate")
        .def(py::init([](const std::string& dir) { return std::make_shared<FlowSurrogate>(FlowSurrogate::load(dir)); }), "model_dir"_a)
        .def_readonly("eta_in_mPa_s", &FlowSurrogate::etaIn)
        .def_readonly("start", &FlowSurrogate::start, "the regime network's campaign start ('random': the ensemble protocol)")
        .def_readonly("tank_treading_start", &FlowSurrogate::tankTreadingStart, "the campaign start of the angle, swing and TTF")
        .def("_predict", &flowSurrogatePredict, "x"_a, "eta_in"_a, "threads"_a = 0)
        .def("_critical_stress", [](const FlowSurrogate& s, const RowArray& x, const RowArray& etaIn) {
            const auto X = columnsOf(x, 7, "x");
            const auto eta = cytosolOf(etaIn, X.cols());
            return ownedVector(withoutGil([&] { return Eigen::VectorXd(s.criticalStressPa(X, eta)); }));
        }, "x"_a, "eta_in"_a);
    m.attr("flow_surrogate_input_names") = py::cast(flowSurrogateInputNames());
    m.attr("surrogate_input_names") = py::cast(surrogateInputNames());
    m.attr("surrogate_output_names") = py::cast(surrogateOutputNames());
}

/// Data sets, posteriors, the inference run, its samples and posterior predictions.
void registerInference(py::module_& m) {
    py::class_<RbcDataSet>(m, "DataSet", "One experimental data set (docs/BAYESIAN_INFERENCE.md, data)")
        .def_readonly("name", &RbcDataSet::name)
        .def_property_readonly("experiment", [](const RbcDataSet& d) { return experimentName(d.experiment); })
        .def_property_readonly("file", [](const RbcDataSet& d) { return d.file.string(); })
        .def_property_readonly("shape", [](const RbcDataSet& d) { return ownedVector(d.shape); }, "equilibrium: mean D, hmin, hmax (um)")
        .def_property_readonly("shape_sd_um", [](const RbcDataSet& d) { return ownedVector(d.shapeSd); },
                               "equilibrium: population SD of D, hmin, hmax (um); NaN where the file gives none")
        .def_property_readonly("force_pN", [](const RbcDataSet& d) { return ownedVector(d.force); })
        .def_property_readonly("D0_um", [](const RbcDataSet& d) { return ownedVector(d.d0); })
        .def_property_readonly("D1_um", [](const RbcDataSet& d) { return ownedVector(d.d1); })
        .def_property_readonly("t_s", [](const RbcDataSet& d) { return ownedVector(d.time); })
        .def_property_readonly("aspect", [](const RbcDataSet& d) { return ownedVector(d.aspect); }, "relaxation: L/W")
        .def("__repr__", [](const RbcDataSet& d) { return fmt::format("trbc.DataSet('{}', {})", d.name, experimentName(d.experiment)); });
    m.def("load_data_sets", [](const std::string& dir) { return loadRbcDataSets(dir); }, "data_dir"_a);

    py::class_<Phase1Posterior>(m, "Phase1Posterior")
        .def(py::init<std::shared_ptr<Surrogate>, RbcDataSet>(), "surrogate"_a, "data_set"_a)
        .def_property_readonly("names", &Phase1Posterior::names)
        .def_property_readonly("dimension", &Phase1Posterior::dimension)
        .def_property_readonly("data_set", &Phase1Posterior::data)
        .def_property_readonly("lower", &Phase1Posterior::lower)
        .def_property_readonly("upper", &Phase1Posterior::upper)
        .def("log_prior", &Phase1Posterior::logPrior, "theta"_a)
        .def("log_likelihood", &Phase1Posterior::logLikelihood, "theta"_a)
        .def("__call__", &Phase1Posterior::logPosterior, "theta"_a)
        .def("sample_prior", &Phase1Posterior::samplePrior, "n"_a, "seed"_a = 1);
    py::class_<HierarchicalPosterior>(m, "HierarchicalPosterior")
        .def(py::init<const std::vector<RbcDataSet>&, const std::vector<RowArray>&>(), "data_sets"_a, "phase1_samples"_a)
        .def_property_readonly("names", &HierarchicalPosterior::names)
        .def("log_likelihood", &HierarchicalPosterior::logLikelihood, "psi"_a)
        .def("__call__", &HierarchicalPosterior::logPosterior, "psi"_a);
    m.def("run_inference", &runInference, "out"_a, "first_phase"_a, "last_phase"_a, "samples"_a, "seed"_a, "surrogate"_a, "data_sets"_a,
          "resume"_a, "threads"_a, "progress"_a, "method"_a = "joint", "chains"_a = 16, "warmup"_a = 1000, "draws"_a = 2500,
          "thin"_a = 4);
    m.def("read_samples", &readSamples, "file"_a);
    m.def(
        "calibrated_cell",
        [](const std::string& posterior) {
            const CalibratedCell c = calibratedCell(posterior, "posterior");
            py::dict d;
            d["v"] = c.cell.v;
            d["mu_uN_per_m"] = c.cell.mu;
            d["kb_J"] = c.kbJ;
            d["FvK"] = c.cell.FvK;
            d["b2"] = c.cell.b2;
            d["etam_Pa_s_um"] = c.cell.etam;
            d["estimator"] = c.estimator;
            d["source"] = c.source.string();
            return d;
        },
        "posterior"_a, "The calibrated cell of a theta_new posterior (analysis/calibrated_cell.hpp)");
    m.def("predict", &predict, "posterior"_a, "surrogate"_a, "data_set"_a, "grid"_a, "max_samples"_a, "seed"_a);
}

/// The flow cases: a cell in shear flow and in a tube.
void registerFlow(py::module_& m) {
    m.def("validation_data", [](const std::string& dir) { return jsonToPython(validationDataJson(readValidationDataSets(dir))); }, "data_dir"_a,
          "The experimental sets of the flow validations with their points, as validationDataJson gives them (JSON types)");
    m.def("flow_shear", &flowShear, py::kw_only(), "eta_out_mPa_s"_a, "shear_rate_per_s"_a, "eta_in_mPa_s"_a, "v"_a, "mu_uN_per_m"_a,
          "FvK"_a, "kb_J"_a, "b2"_a, "etam_Pa_s_um"_a, "allow_outside_prior"_a, "level"_a, "rotations"_a, "tilt_deg"_a,
          "start"_a, "kick_temperature_K"_a, "temperature_K"_a, "thermal_step"_a, "seed"_a, "stop_when_steady"_a,
          "step_tol"_a, "frame_interval"_a, "dt"_a, "max_steps"_a, "threads"_a, "cache"_a, "cache_dir"_a);
    m.def("flow_tube", &flowTube, py::kw_only(), "radius_um"_a, "pressure_gradient_mmHg_per_mm"_a, "eta_out_mPa_s"_a,
          "viscosity_ratio"_a, "v"_a, "mu_uN_per_m"_a, "FvK"_a, "kb_J"_a, "b2"_a, "etam_Pa_s_um"_a, "allow_outside_prior"_a, "level"_a,
          "duration_R_over_V"_a, "settle_R_over_V"_a, "settle_relax_R_over_V"_a, "settle_etam_Pa_s_um"_a, "settle_tol"_a,
          "wall_points"_a, "tube_length_um"_a, "repulsion_range_um"_a, "repulsion_pressure"_a, "frame_interval"_a, "step_tol"_a,
          "dt"_a, "max_steps"_a, "threads"_a, "cache"_a, "cache_dir"_a);
}

}  // namespace
}  // namespace trbc::python

// Registration order matters: a signature names a bound type (trbc._core.Mesh) only when that type
// is registered before the function that takes it.
PYBIND11_MODULE(_core, m) {
    using namespace trbc;
    using namespace trbc::python;
    m.doc() = "trbc C++ core (pybind11); use the trbc package, which wraps it";
    (void)simd::active();  // a bad TRBC_SIMD fails the import, not a call inside a parallel region
    m.attr("__version__") = kVersion;
    m.attr("__revision__") = gitDescribe();  // git describe of the build, "-dirty" for uncommitted changes
    registerExceptions(m);
    registerMesh(m);
    registerForwardModel(m);
    registerSurrogates(m);
    registerInference(m);
    registerFlow(m);
    // The stress-free shape cache that simulate, sfs and both flow cases share.
    m.def("default_cache_dir", [] { return defaultCacheDirectory().string(); });
}
