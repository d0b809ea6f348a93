"""trbc from Python: the red-blood-cell membrane model, its surrogates, the hierarchical Bayesian
inference and the Stokes flows of the trbc C++ library, with numpy arrays in and out.

Units follow the project's canonical names: v (reduced volume), mu_uN_per_m (uN/m), FvK
(mu R_A^2 / kb), kb_J (J), b2, etam_Pa_s_um (Pa s um), Fext_pN (pN) in; D_um, hmin_um, hmax_um,
D0_um, D1_um (um) and tc_s (s) out. Bad input raises ValueError with the library's message
(naming the parameter); a solver that does not converge raises trbc.NumericalError. Long calls
release the GIL and stop on Ctrl-C (KeyboardInterrupt).

See docs/PYTHON.md for the whole API.
"""
from __future__ import annotations

import csv
import json
import os
import pkgutil
import tempfile
from pathlib import Path
from typing import Iterable, Mapping, Optional, Sequence, Union

import numpy as np

# The extension module is built into <build>/python/trbc/ and the Python sources stay in
# src/python/trbc/: extending the package path to every trbc/ folder on sys.path lets
# PYTHONPATH=src/python:build/python import the package from a build tree, without installing it.
__path__ = pkgutil.extend_path(__path__, __name__)

from . import _core  # noqa: E402
from ._core import Mesh, NumericalError, DataSet  # noqa: E402
# The reference shape and the relaxation law the forward model is compared with; their docstrings
# (units included) are those of the bindings.
from ._core import evans_fung_thickness, evans_fung_radius_um, fit_hochmuth  # noqa: E402

__version__ = _core.__version__
__revision__ = _core.__revision__

__all__ = [
    "Mesh", "NumericalError", "DataSet", "Surrogate", "FlowSurrogate", "Posterior", "membrane_energy", "simulate", "sfs",
    "data_dir", "load_data_sets", "phase1_log_posterior", "hierarchical_log_posterior", "infer",
    "load_inference", "load_validation", "validation_data", "predict", "calibrated_cell", "flow_shear", "flow_tube", "INPUT_NAMES",
    "OUTPUT_NAMES",
    "evans_fung_thickness", "evans_fung_radius_um", "fit_hochmuth",
]

INPUT_NAMES = tuple(_core.surrogate_input_names)    #: v, mu_uN_per_m, FvK, b2, etam_Pa_s_um, Fext_pN
OUTPUT_NAMES = tuple(_core.surrogate_output_names)  #: D_um, hmin_um, hmax_um, D0_um, D1_um, tc_s

_PathLike = Union[str, os.PathLike]


def data_dir(*parts: str) -> Path:
    """The data shipped with the package (surrogates, experiments, examples): $TRBC_DATA_DIR if
    set, else the copy installed inside the package."""
    base = Path(os.environ.get("TRBC_DATA_DIR", Path(__file__).resolve().parent / "data"))
    return base.joinpath(*parts)


# ---- meshes and the membrane energy --------------------------------------------------------------

def membrane_energy(mesh: Mesh, reference: Optional[Mesh] = None, **moduli) -> dict:
    """Energy, energy terms and per-vertex forces of a mesh (the numbers of `trbc forces`).

    Lengths and moduli are in the mesh's own units; every modulus defaults to 0 (term off):
    kb, C0 (Juelicher bending 2 kb sum A_i (H_i - C0/2)^2), kad, DA0 (area difference),
    ka, a3, a4, mu, b1, b2 (Lim in-plane elasticity against `reference`, the stress-free mesh),
    kA with A0 and kV with V0 (penalties kA/2 (A-A0)^2/A0, kV/2 (V-V0)^2/V0).

    Returns {"energy": float, "terms": {"bending": .., "lim": .., ...} (terms that are on),
    "forces": (n, 3) array, -dU/dx}.
    """
    return _core.membrane_energy(mesh, reference, **moduli)


# ---- the forward model ---------------------------------------------------------------------------

def simulate(v: float = 0.95, mu_uN_per_m: float = 4.0, FvK: Optional[float] = None, b2: float = 1.5,
             etam_Pa_s_um: float = 0.7, Fext_pN: float = 100.0, level: int = 4,
             experiments: Sequence[str] = ("eq", "stretch", "relax"), *, kb_J: Optional[float] = None,
             force_curve: Optional[Sequence[float]] = None, allow_outside_prior: bool = False, threads: int = 1,
             cache: bool = True, cache_dir: Optional[_PathLike] = None, overdamped: bool = False,
             in_plane_axis: str = "farthest-vertex", equilibrium_symmetry: str = "lowest",
             equilibrium_seed: Optional[int] = None, equilibrium_kicks: Optional[int] = None) -> dict:
    """One forward-model sample, as `trbc simulate`: stress-free state, equilibrium shape,
    two-bead stretching at Fext_pN and relaxation (docs/FORWARD_MODEL.md).

    Parameters: v (reduced volume of the SFS, prior [0.65, 1]), mu_uN_per_m (uN/m, [1, 10]),
    FvK (mu R_A^2 / kb, [10, 1000]; default 250) or kb_J (J, replaces FvK), b2 ([0, 4]),
    etam_Pa_s_um (Pa s um, [0.1, 1]), Fext_pN (pN per bead, [0, 200]); level: icosphere level of
    the meshes (2..6, Nv = 10 4^level + 2); experiments: subset of "eq", "stretch", "relax";
    force_curve: extra forces (pN) for a whole stretching curve. The SFS is cached on disk like the
    CLI's ($TRBC_CACHE_DIR or ~/.cache/trbc; cache=False: none). equilibrium_symmetry, equilibrium_seed,
    equilibrium_kicks: as --equilibrium-symmetry (lowest, inversion, none), --equilibrium-seed and
    --equilibrium-kicks of `trbc simulate` (None: the CLI's default).

    Returns the CLI's JSON object as a dict ("parameters", "observables" with D_um, hmin_um,
    hmax_um, D0_um, D1_um, tc_s (None for an experiment not run), "diagnostics",
    "stretching_curve", "relaxation_fit", "status", "provenance") plus numpy arrays and meshes:
    "equilibrium_profile" (r_um, zlow_um, zhigh_um, h_um), "stretching_curve_arrays" (Fext_pN,
    D0_um, D1_um), "relaxation" (t_s, L_um, W_um, z) and "shapes" (Mesh objects in um: sfs,
    equilibrium, stretched = [(Fext_pN, Mesh), ...], relaxation_release, relaxation_end).
    Raises trbc.NumericalError when a stage does not converge.
    """
    if isinstance(experiments, str):
        experiments = experiments.split(",")
    return _core.simulate(v=float(v), mu_uN_per_m=float(mu_uN_per_m), FvK=None if FvK is None else float(FvK),
                          kb_J=None if kb_J is None else float(kb_J), b2=float(b2), etam_Pa_s_um=float(etam_Pa_s_um),
                          Fext_pN=float(Fext_pN), level=int(level), experiments=list(experiments),
                          force_curve=[float(f) for f in (force_curve or [])], allow_outside_prior=bool(allow_outside_prior),
                          threads=int(threads), cache=bool(cache), cache_dir=None if cache_dir is None else str(cache_dir),
                          overdamped=bool(overdamped), in_plane_axis=in_plane_axis,
                          equilibrium_symmetry=equilibrium_symmetry,
                          equilibrium_seed=None if equilibrium_seed is None else int(equilibrium_seed),
                          equilibrium_kicks=None if equilibrium_kicks is None else int(equilibrium_kicks))


def sfs(v: float, level: int = 4, *, tol: float = 1e-5, preconditioner: str = "multigrid", cache: bool = True,
        cache_dir: Optional[_PathLike] = None) -> dict:
    """The stress-free state of the cytoskeleton for reduced volume v (docs/FORWARD_MODEL.md, stress-free state), as `trbc sfs`.

    Returns {"mesh": Mesh in um at the cell area 135 um^2, "diagnostics": dict (dimensionless
    units of docs/FORWARD_MODEL.md, stress-free state: energy_kappa, iterations, converged, ...)}. tol: largest tangential force
    at convergence, kappa / R'_A.
    """
    return _core.sfs(v=float(v), level=int(level), tol=float(tol), preconditioner=preconditioner, cache=bool(cache),
                     cache_dir=None if cache_dir is None else str(cache_dir))


# ---- surrogates ----------------------------------------------------------------------------------

_RA2_UM2 = 10.742958658  # R_A^2 = A0 / (4 pi) of the reference cell (um^2)


def _fvk_from_kb(mu_uN_per_m, kb_J):
    """FvK = mu R_A^2 / kb (mu in uN/m, kb in J; kb * 1e18 is in pN um)."""
    return np.asarray(mu_uN_per_m, dtype=float) * _RA2_UM2 / (np.asarray(kb_J, dtype=float) * 1e18)


def _as_inputs(x) -> np.ndarray:
    """(n, 6) float64 C-contiguous inputs from an array or a dict of arrays with the canonical names
    (kb_J instead of FvK is accepted: FvK = mu R_A^2 / kb)."""
    if isinstance(x, Mapping):
        missing = [k for k in INPUT_NAMES if k not in x and not (k == "FvK" and "kb_J" in x)]
        if missing:
            raise ValueError(f"x: missing input(s) {', '.join(missing)} (inputs: {', '.join(INPUT_NAMES)}; kb_J may replace FvK)")
        cols = []
        for k in INPUT_NAMES:
            if k == "FvK" and "FvK" not in x:
                cols.append(_fvk_from_kb(x["mu_uN_per_m"], x["kb_J"]))
            else:
                cols.append(np.asarray(x[k], dtype=float))
        cols = np.broadcast_arrays(*[np.atleast_1d(c) for c in cols])
        return np.ascontiguousarray(np.stack(cols, axis=1))
    a = np.asarray(x, dtype=np.float64)
    if a.ndim == 1 and a.shape[0] == 6:
        a = a[None, :]
    return np.ascontiguousarray(a)


class Surrogate(_core.Surrogate):
    """The three surrogate networks (docs/CAMPAIGN_AND_SURROGATE.md, surrogate training) as one model of the six outputs.

    Surrogate(model_dir=None, precision="double"): model_dir holds equilibrium.json,
    stretching.json and relaxation.json (default: the shipped networks). precision "single"
    evaluates in float (about 3x faster, ~1e-6 relative difference), as `--single-precision`.
    """

    input_names = INPUT_NAMES
    output_names = OUTPUT_NAMES

    def __init__(self, model_dir: Optional[_PathLike] = None, precision: str = "double"):
        super().__init__(str(model_dir if model_dir is not None else data_dir("surrogates")), precision)

    def evaluate_array(self, x, threads: int = 0) -> np.ndarray:
        """Outputs as one (n, 6) array (columns OUTPUT_NAMES) for inputs x (n, 6) (columns
        INPUT_NAMES) or a dict of arrays. A float64 C-contiguous array is read without a copy;
        threads > 0 sets the OpenMP threads of this call."""
        return self._evaluate(_as_inputs(x), threads)

    def evaluate(self, x, threads: int = 0) -> dict:
        """{name: (n,) array} of D_um, hmin_um, hmax_um, D0_um, D1_um (um) and tc_s (s) for inputs
        x: an (n, 6) array with columns v, mu_uN_per_m, FvK, b2, etam_Pa_s_um, Fext_pN, or a dict of
        arrays with those names (kb_J in J may replace FvK). The arrays are views of one result."""
        y = self.evaluate_array(x, threads)
        return {name: y[:, k] for k, name in enumerate(OUTPUT_NAMES)}

    def gradient(self, x, weights=None, threads: int = 0) -> np.ndarray:
        """Derivatives of the outputs with respect to the inputs (back-propagation through the
        networks, double precision). Without weights: the Jacobians, (n, 6, 6) with
        J[k, i, j] = d output_i / d input_j (units: output unit per input unit). With weights
        (n, 6): the vector-Jacobian products sum_i w_i d output_i / d input_j, (n, 6)."""
        w = None if weights is None else _as_inputs(weights)
        return self._gradient(_as_inputs(x), w, threads)

    @staticmethod
    def outside_training_box(x) -> np.ndarray:
        """(n,) bool: whether each input row lies outside the training box (an extrapolation)."""
        return _core.outside_training_box(_as_inputs(x))


class FlowSurrogate(_core.FlowSurrogate):
    """The flow networks (docs/FLOW_NETWORKS.md): the probability that a cell in simple shear
    tank-treads (over random starts) and its inclination angle, swing amplitude and tank-treading
    frequency. FlowSurrogate(model_dir=None): a `trbc flow train` directory (default: the shipped
    networks, data/surrogates/flow)."""

    input_names = tuple(_core.flow_surrogate_input_names)
    output_names = ("p_tank_treading", "inclination_deg", "swing_deg", "ttf_4pi_f_over_rate")

    def __init__(self, model_dir: Optional[_PathLike] = None):
        super().__init__(str(model_dir if model_dir is not None else data_dir("surrogates", "flow")))

    @staticmethod
    def _columns(v, mu_uN_per_m, kb_J, FvK, b2, etam_Pa_s_um, eta_out_mPa_s, shear_rate_per_s, eta_in_mPa_s):
        """The broadcast shape, the (n, 7) inputs in flow_surrogate_input_names order and the (n,)
        cytosol viscosities."""
        if (kb_J is None) == (FvK is None):
            raise ValueError("give exactly one of kb_J and FvK")
        args = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in
                                     (v, mu_uN_per_m, kb_J if FvK is None else FvK, b2, etam_Pa_s_um, eta_out_mPa_s,
                                      shear_rate_per_s, eta_in_mPa_s)))
        cols = [a.ravel() for a in args]
        if FvK is None:
            cols[2] = _fvk_from_kb(cols[1], cols[2])
        return args[0].shape, np.ascontiguousarray(np.stack(cols[:7], axis=1)), np.ascontiguousarray(cols[7])

    def predict(self, *, eta_out_mPa_s, shear_rate_per_s, v, mu_uN_per_m, b2, etam_Pa_s_um, kb_J=None, FvK=None,
                eta_in_mPa_s=10.0, threads: int = 0) -> dict:
        """{name: array} of p_tank_treading, inclination_deg, swing_deg, ttf_4pi_f_over_rate (4 pi f /
        rate) and outside_box (bool: an input outside the campaign's box, an extrapolation). The
        arguments broadcast against each other like numpy arrays; give the bending modulus as kb_J
        (J) or FvK. The angle, swing and TTF are those of the tank-treading state (extrapolated where
        p_tank_treading is small)."""
        shape, x, eta_in = self._columns(v, mu_uN_per_m, kb_J, FvK, b2, etam_Pa_s_um, eta_out_mPa_s, shear_rate_per_s,
                                         eta_in_mPa_s)
        y = self._predict(x, eta_in, threads)
        out = {name: y[:, k].reshape(shape) for k, name in enumerate(self.output_names)}
        out["outside_box"] = (y[:, 4] > 0.5).reshape(shape)
        return out

    def critical_stress_Pa(self, *, eta_out_mPa_s, v, mu_uN_per_m, b2, etam_Pa_s_um, kb_J=None, FvK=None,
                           eta_in_mPa_s=10.0) -> np.ndarray:
        """The shear stress (Pa) at which p_tank_treading crosses 1/2, NaN where it does not cross
        inside the campaign's stress range; broadcasts like predict."""
        shape, x, eta_in = self._columns(v, mu_uN_per_m, kb_J, FvK, b2, etam_Pa_s_um, eta_out_mPa_s, 1.0, eta_in_mPa_s)
        return self._critical_stress(x, eta_in).reshape(shape)


# ---- inference -----------------------------------------------------------------------------------

def load_data_sets(data: Optional[_PathLike] = None) -> list:
    """The experimental data sets (docs/BAYESIAN_INFERENCE.md, data) of a directory (default: the shipped seven,
    evans_fung_1972, mills_2004, suresh_2005, hochmuth_1979_cell1..4), as trbc.DataSet objects."""
    return _core.load_data_sets(str(data if data is not None else data_dir("experiments")))


def _data_set(data_set, data: Optional[_PathLike] = None) -> DataSet:
    if isinstance(data_set, DataSet):
        return data_set
    sets = load_data_sets(data)
    for d in sets:
        if d.name == data_set:
            return d
    raise ValueError(f"data_set: no data set named '{data_set}' (valid: {', '.join(d.name for d in sets)})")


def phase1_log_posterior(data_set, surrogate: Optional[Surrogate] = None, data: Optional[_PathLike] = None):
    """The phase-1 log-posterior log pi_i(theta) + log L_i(theta) of one data set (docs/BAYESIAN_INFERENCE.md),
    on the surrogate, as a callable: f(theta) with theta (d,) -> float or (n, d) -> (n,) array,
    -inf outside the prior's support.

    theta is in the physical units of the samples files, columns f.names: equilibrium (v, FvK,
    sigma_rel), stretching (v, mu_uN_per_m, kb_J, b2, sigma0_um, sigma1_um), relaxation
    (etam_over_mu_s, sigma_tc_rel, tc_s, z0, zinf, sigma_z). The density is that of trbc's own
    sampler, whose variable is kb in 1e-18 J (a constant offset against a density in J). Also
    f.log_prior, f.log_likelihood, f.lower, f.upper (prior support) and f.sample_prior(n, seed).
    No gradient: the likelihoods have none in the library (Surrogate.gradient gives the networks').
    """
    return _core.Phase1Posterior(surrogate if surrogate is not None else Surrogate(), _data_set(data_set, data))


def hierarchical_log_posterior(phase1_samples: Mapping[str, np.ndarray], data: Optional[_PathLike] = None):
    """The phase-2 log-posterior of the population hyper-parameters psi (docs/BAYESIAN_INFERENCE.md),
    log p(psi) + sum_i log b_i(psi), from the phase-1 samples of each data set
    ({data set name: (N, d) array in the units of phase1_log_posterior}, e.g. from trbc.infer).
    Callable on psi (10,) or (n, 10), columns f.names (mean_v, sd_v, ...)."""
    by_name = {d.name: d for d in load_data_sets(data)}
    sets, arrays = [], []
    for name, samples in phase1_samples.items():
        if name not in by_name:
            raise ValueError(f"phase1_samples: no data set named '{name}' (valid: {', '.join(by_name)})")
        s = samples.samples if isinstance(samples, Posterior) else samples
        sets.append(by_name[name])
        arrays.append(np.ascontiguousarray(s, dtype=np.float64))
    return _core.HierarchicalPosterior(sets, arrays)


class Posterior:
    """Samples of one posterior as written by `trbc infer` (DIR/<phase>/<name>/samples.csv):
    names (parameters, physical units), samples (N, d), log_likelihood and log_prior (N,).
    p["v"] gives one column; p.to_dict() all of them."""

    def __init__(self, file: _PathLike):
        self.file = Path(file)
        self.name = self.file.parent.name
        self.phase = self.file.parent.parent.name
        columns, values = _core.read_samples(str(self.file))
        extra = [c for c in ("log_likelihood", "log_prior") if c in columns]
        keep = [k for k, c in enumerate(columns) if c not in extra]
        self.names = [columns[k] for k in keep]
        self.samples = np.ascontiguousarray(values[:, keep])
        self.log_likelihood = values[:, columns.index("log_likelihood")] if "log_likelihood" in columns else None
        self.log_prior = values[:, columns.index("log_prior")] if "log_prior" in columns else None

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self.names:
            raise KeyError(f"{name} (parameters: {', '.join(self.names)})")
        return self.samples[:, self.names.index(name)]

    def __len__(self) -> int:
        return self.samples.shape[0]

    def to_dict(self) -> dict:
        return {n: self.samples[:, k] for k, n in enumerate(self.names)}

    def mean(self) -> dict:
        return {n: float(self.samples[:, k].mean()) for k, n in enumerate(self.names)}

    def __repr__(self) -> str:
        return f"trbc.Posterior({self.phase}/{self.name}: {len(self)} samples of {', '.join(self.names)})"


def calibrated_cell(posterior: _PathLike) -> dict:
    """The calibrated cell of a theta_new posterior (DIR/inference/phase3/theta_new of `trbc calibrate`,
    DIR/phase3/theta_new of `trbc infer`, or its samples.csv), the one every trbc command takes from
    `--posterior`: the Rao-Blackwellised means of the inference's posterior_stats.csv where it has
    them, else the sample means. {v, mu_uN_per_m, kb_J, FvK, b2, etam_Pa_s_um, estimator, source}."""
    return _core.calibrated_cell(str(posterior))


def load_inference(out: _PathLike) -> dict:
    """The posteriors of an inference output directory: {"phase1": {name: Posterior}, "phase2":
    {"hyper": Posterior}, "phase3": {"theta_new": Posterior, name: Posterior}} (phases present)."""
    out = Path(out)
    result = {}
    for phase in ("phase1", "phase2", "phase3"):
        d = out / phase
        if d.is_dir():
            posts = {p.parent.name: Posterior(p) for p in sorted(d.glob("*/samples.csv"))}
            if posts:
                result[phase] = posts
    return result


def _read_table(path: Path) -> dict:
    """A CSV as {column: array}: numbers as float arrays (empty and "n/a" cells NaN), other columns as lists."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader((ln for ln in f if not ln.startswith("#"))))
    table = {}
    for name in (rows[0].keys() if rows else []):
        cells = [r[name] for r in rows]
        try:
            table[name] = np.array([float(c) if c not in ("", "n/a") else np.nan for c in cells])
        except ValueError:
            table[name] = cells
    return table


def validation_data(data: Optional[_PathLike] = None) -> list:
    """The experimental sets the flow validations compare with (`trbc validate`'s verdicts read the
    same list), in trbc's units. `data`: the validation data directory (shear_flow/, microtube/);
    default data_dir("experiments", "validation").

    One dict per set: "observable" (inclination_deg, ttf_4pi_f_over_rate, critical_stress_Pa,
    velocity_cm_per_s, length_um), "x_name" (shear_rate_per_s, eta_out_mPa_s, pg_mmHg_per_mm,
    velocity_cm_per_s), "source", "file", "eta_out_mPa_s" (of a set measured at one viscosity, else
    None), "judged" (False: shown beside the verdicts only), "x" (n,), "y" (n, k) with NaN for a
    blank, and "y_columns" (the k columns: donors, or l, l_high, l_low). `trbc validate` records
    the same list in OUT/experimental_data.json. ValueError for a folder that is not validation data
    or a listed file that cannot be read."""
    sets = _core.validation_data(str(data if data is not None else data_dir("experiments", "validation")))
    for s in sets:
        s["x"] = np.asarray(s["x"], dtype=float)
        s["y"] = np.asarray(s["y"], dtype=float).reshape(len(s["x"]), len(s["y_columns"]))  # null -> NaN
    return sets


def load_validation(out: _PathLike) -> dict:
    """The tables of a `trbc validate` output directory: "summary" (validation.json: command,
    configuration, summary, draws) and, where present, "comparison", "shear", "threshold", "tube",
    "bands" (median, q05, q95, their MC errors median_mcse, q05_mcse, q95_mcse, band verdicts) and
    "draws" (one row per draw run), each as {column: numpy array or list of strings}."""
    out = Path(out)
    if not (out / "validation.json").is_file():
        raise ValueError(f"load_validation: {out} has no validation.json (not a `trbc validate` output directory)")
    result = {"summary": json.loads((out / "validation.json").read_text())}
    for name in ("comparison", "shear", "threshold", "tube", "bands", "draws"):
        if (out / f"{name}.csv").is_file():
            result[name] = _read_table(out / f"{name}.csv")
    return result


def infer(out: Optional[_PathLike] = None, phase: Union[int, str] = "all", *, samples: int = 50000, seed: int = 0xC0FFEE,
          data_sets: Optional[Iterable[str]] = None, data: Optional[_PathLike] = None, surrogate: Optional[Surrogate] = None,
          resume: bool = False, threads: int = 0, progress=None, method: str = "joint", chains: int = 16,
          warmup: int = 1000, draws: int = 2500, thin: int = 4) -> dict:
    """The hierarchical Bayesian inference of docs/BAYESIAN_INFERENCE.md on the surrogates, as
    `trbc infer --phase PHASE --samples N --seed S --method METHOD --out OUT` (same runs, seeds and files).

    samples: population of every phase-1 TMCMC/BASIS run. method: "joint" (phases 2-3 by one
    multi-chain MCMC of chains x draws, one draw every thin sweeps after warmup sweeps; theta_new
    Rao-Blackwellised, with MCSE, R-hat and ESS) or "reweighting" (the paper's route).

    phase: 1, 2, 3 or "all" (2 and 3 read the earlier phases from out). data_sets: names of a
    subset of the data sets (phase 1 only). out: output directory (default: a new temporary one).
    progress: callable receiving one line per stage. Returns load_inference(out) plus "out",
    "wall_s", "timing" and "phase1_log_evidence".
    """
    if out is None:
        out = tempfile.mkdtemp(prefix="trbc-infer-")
    first, last = (1, 3) if str(phase) == "all" else (int(phase), int(phase))
    sets = load_data_sets(data)
    if data_sets is not None:
        wanted = list(data_sets)
        if last > 1:
            raise ValueError("data_sets: a subset of the data sets can only be used with phase=1")
        sets = [_data_set(n, data) for n in wanted]
    Path(out).mkdir(parents=True, exist_ok=True)
    info = _core.run_inference(str(out), first, last, int(samples), int(seed), surrogate if surrogate is not None else Surrogate(),
                               sets, bool(resume), int(threads), progress, str(method), int(chains), int(warmup), int(draws),
                               int(thin))
    result = load_inference(out)
    result.update(info)
    result["out"] = Path(out)
    return result


def predict(posterior: Union[Posterior, _PathLike], data_set=None, *, surrogate: Optional[Surrogate] = None, grid: int = 100,
            max_samples: int = 0, seed: int = 1, data: Optional[_PathLike] = None) -> dict:
    """Posterior predictions (docs/BAYESIAN_INFERENCE.md, prediction), as `trbc predict`: every sample through the surrogate
    (or Hochmuth's law) with its error model. data_set: a name or DataSet for the coverage check
    (default: the data set named like the posterior, if any).

    Returns {"bands": {observable: {"x", "mean", "q005", "q05", ..., "q995"}}, "coverage": [...],
    "x_name" (Fext_pN, t_s or "" for the equilibrium), "experiment", "samples_used"}; x in pN or s,
    observables in um (D0_um, D1_um, D_um, hmin_um, hmax_um) or dimensionless (z = L/W).
    """
    path = posterior.file if isinstance(posterior, Posterior) else Path(posterior)
    if data_set is None:
        name = path.parent.name if path.name == "samples.csv" else path.name
        matches = [d for d in load_data_sets(data) if d.name == name]
        ds = matches[0] if matches else None
    else:
        ds = _data_set(data_set, data)
    return _core.predict(str(path), surrogate if surrogate is not None else Surrogate(), ds, int(grid), int(max_samples), int(seed))


# ---- flows ---------------------------------------------------------------------------------------

def flow_shear(eta_out_mPa_s: float, shear_rate_per_s: float, eta_in_mPa_s: float = 10.0, *, v: float = 0.94,
               mu_uN_per_m: float = 4.99, FvK: Optional[float] = None, kb_J: Optional[float] = None, b2: float = 1.84,
               etam_Pa_s_um: float = 0.69, allow_outside_prior: bool = False, level: int = 3, rotations: float = 10.0,
               tilt_deg: float = 0.0, start: str = "in-plane", kick_temperature_K: float = 293.15,
               temperature_K: float = 0.0, thermal_step: float = 0.2, seed: int = 1, stop_when_steady: bool = False,
               step_tol: float = 1e-3,
               frame_interval: float = 0.1, dt: Optional[float] = None, max_steps: int = 200000, threads: int = 0,
               cache: bool = True, cache_dir: Optional[_PathLike] = None) -> dict:
    """One cell in unbounded simple shear flow (docs/FLOW.md, shear), as `trbc flow shear`:
    boundary-integral Stokes flow, membrane forces with membrane viscosity, adaptive BDF2.

    eta_out_mPa_s, eta_in_mPa_s (mPa s), shear_rate_per_s (1/s); the cell (default: the paper's
    Table 1 means, kb_J = 2.10e-19 J); rotations: duration in rigid-sphere turns 4 pi / rate;
    tilt_deg: the start turned about the flow axis out of the shear plane, [0, 90] degrees;
    start: "in-plane" or "random" (random orientation with thermal l = 2, 3 undulations at
    kick_temperature_K, from seed: the ensemble start of docs/FLOW_THERMAL.md); temperature_K > 0:
    thermal fluctuations during the run, fixed steps thermal_step (1/rate; at most the membrane's
    viscous time eta_m / mu), noise from seed;
    stop_when_steady: stop at the first whole turn (from the 4th) with steady observables;
    frame_interval, dt in 1/rate; step_tol in R_A. Returns {"observables": regime, inclination_deg,
    swing_amplitude_deg, ttf_4pi_f_over_shear_rate (None unless tank-treading), "time_series":
    t_s, shear_strain, inclination_deg, orientation_unwrapped_deg, area_drift, volume_drift,
    centroid_um (k, 3), "parameters", "diagnostics", "final_shape": Mesh (um)}. A run that fails
    (step limit, solver divergence) raises trbc.NumericalError with the reason.
    """
    return _core.flow_shear(eta_out_mPa_s=float(eta_out_mPa_s), shear_rate_per_s=float(shear_rate_per_s),
                            eta_in_mPa_s=float(eta_in_mPa_s), v=float(v), mu_uN_per_m=float(mu_uN_per_m),
                            FvK=None if FvK is None else float(FvK), kb_J=None if kb_J is None else float(kb_J), b2=float(b2),
                            etam_Pa_s_um=float(etam_Pa_s_um), allow_outside_prior=bool(allow_outside_prior), level=int(level),
                            rotations=float(rotations), tilt_deg=float(tilt_deg), start=str(start),
                            kick_temperature_K=float(kick_temperature_K), temperature_K=float(temperature_K),
                            thermal_step=float(thermal_step), seed=int(seed), stop_when_steady=bool(stop_when_steady),
                            step_tol=float(step_tol),
                            frame_interval=float(frame_interval),
                            dt=None if dt is None else float(dt), max_steps=int(max_steps), threads=int(threads),
                            cache=bool(cache), cache_dir=None if cache_dir is None else str(cache_dir))


def flow_tube(radius_um: float, pressure_gradient_mmHg_per_mm: float, eta_out_mPa_s: float = 1.003, *,
              viscosity_ratio: float = 1.0, v: float = 0.94, mu_uN_per_m: float = 4.99, FvK: Optional[float] = None,
              kb_J: Optional[float] = None, b2: float = 1.84, etam_Pa_s_um: float = 0.69, allow_outside_prior: bool = False,
              level: int = 3, duration_R_over_V: float = 30.0, settle_R_over_V: float = 60.0,
              settle_relax_R_over_V: Optional[float] = None, settle_etam_Pa_s_um: Optional[float] = None,
              settle_tol: float = 2e-3, wall_points: int = 0, tube_length_um: float = 0.0, repulsion_range_um: float = 0.1,
              repulsion_pressure: float = 10.0, frame_interval: float = 1.0, step_tol: Optional[float] = None,
              dt: Optional[float] = None, max_steps: int = 200000, threads: int = 0, cache: bool = True,
              cache_dir: Optional[_PathLike] = None) -> dict:
    """One cell in a straight circular microtube driven by a pressure gradient (docs/FLOW_TUBE.md),
    as `trbc flow tube`: the cell fitted into the tube, a settling stage with a small membrane
    viscosity, then the main stage with the cell's own, which gives the observables.

    radius_um (um, at least the 1.4967 um that holds the cell's area and volume),
    pressure_gradient_mmHg_per_mm, eta_out_mPa_s; the cell as in flow_shear; times in R/V with
    V = (pressure gradient / 45) cm/s: duration_R_over_V (main stage), settle_R_over_V (longest
    settling stage; 0: none, else >= 10), settle_relax_R_over_V (eta_m / mu of the settling stage,
    default 1.5) or settle_etam_Pa_s_um, frame_interval, dt; step_tol in R_A (default 6.25e-5);
    wall_points per ring (0: from the cell's mesh), tube_length_um (0: from the fitted cell),
    repulsion_range_um, repulsion_pressure (eta_out V / R). Returns {"observables":
    velocity_cm_per_s, length_um, width_um, width_z_um, velocity_over_centre_line,
    velocity_over_mean_poiseuille (None for fewer than 16 frames), "time_series" of the main stage:
    t_s, t_R_over_V, centroid_um (k, 3), length_um, width_y_um, width_z_um, clearance_um,
    area_drift, volume_drift, "settling": None or {settled, t_reached_R_over_V, final_length_um,
    final_width_um, time_series, diagnostics}, "parameters", "diagnostics", "final_shape": Mesh
    (um)}. A cell that cannot be fitted or a failed stage raises trbc.NumericalError with the reason.
    """
    return _core.flow_tube(
        radius_um=float(radius_um), pressure_gradient_mmHg_per_mm=float(pressure_gradient_mmHg_per_mm),
        eta_out_mPa_s=float(eta_out_mPa_s), viscosity_ratio=float(viscosity_ratio), v=float(v), mu_uN_per_m=float(mu_uN_per_m),
        FvK=None if FvK is None else float(FvK), kb_J=None if kb_J is None else float(kb_J), b2=float(b2),
        etam_Pa_s_um=float(etam_Pa_s_um), allow_outside_prior=bool(allow_outside_prior), level=int(level),
        duration_R_over_V=float(duration_R_over_V), settle_R_over_V=float(settle_R_over_V),
        settle_relax_R_over_V=None if settle_relax_R_over_V is None else float(settle_relax_R_over_V),
        settle_etam_Pa_s_um=None if settle_etam_Pa_s_um is None else float(settle_etam_Pa_s_um), settle_tol=float(settle_tol),
        wall_points=int(wall_points), tube_length_um=float(tube_length_um), repulsion_range_um=float(repulsion_range_um),
        repulsion_pressure=float(repulsion_pressure), frame_interval=float(frame_interval),
        step_tol=None if step_tol is None else float(step_tol), dt=None if dt is None else float(dt), max_steps=int(max_steps),
        threads=int(threads), cache=bool(cache), cache_dir=None if cache_dir is None else str(cache_dir))
