#include "solvers/gmres.hpp"

#include <algorithm>
#include <cmath>

namespace trbc {

using Eigen::Index;
using Eigen::VectorXd;

GmresResult gmres(const LinearMap& A, const LinearMap& preconditioner, const VectorXd& b, VectorXd& x,
                  const GmresSettings& settings, const VectorXd* initialGuess) {
    GmresResult st;
    const Index n = b.size();
    const double bn = b.norm();
    const double tol = settings.tolerance;
    if (bn == 0.0) {
        x = VectorXd::Zero(n);
        st.converged = true;
        return st;
    }
    VectorXd r, w(n), z(n);
    if (initialGuess) {
        x = *initialGuess;
        A(x, r);
        r = b - r;
    } else {
        x = VectorXd::Zero(n);
        r = b;
    }
    // z = M^-1 v (identity without a preconditioner).
    const auto applyM = [&](const auto& v, VectorXd& out) {
        if (preconditioner)
            preconditioner(v, out);
        else
            out = v;
    };
    double beta = r.norm();
    st.residual = beta / bn;
    Eigen::MatrixXd V, H;
    VectorXd cs, sn, g;
    while (st.residual > tol && st.iterations < settings.maxIterations) {
        const int m = std::min(settings.restart, settings.maxIterations - st.iterations);
        V.resize(n, m + 1);
        H = Eigen::MatrixXd::Zero(m + 1, m);
        cs.resize(m);
        sn.resize(m);
        g = VectorXd::Zero(m + 1);
        V.col(0) = r / beta;
        g[0] = beta;
        int j = 0;
        while (j < m) {
            applyM(V.col(j), z);
            A(z, w);
            for (int pass = 0; pass < 2; ++pass)
                for (int i = 0; i <= j; ++i) {
                    const double h = w.dot(V.col(i));
                    H(i, j) += h;
                    w -= h * V.col(i);
                }
            const double hn = w.norm();
            H(j + 1, j) = hn;
            if (hn > 0.0) V.col(j + 1) = w / hn;
            for (int i = 0; i < j; ++i) {
                const double t = cs[i] * H(i, j) + sn[i] * H(i + 1, j);
                H(i + 1, j) = -sn[i] * H(i, j) + cs[i] * H(i + 1, j);
                H(i, j) = t;
            }
            const double den = std::hypot(H(j, j), H(j + 1, j));
            if (den == 0.0) break;
            cs[j] = H(j, j) / den;
            sn[j] = H(j + 1, j) / den;
            H(j, j) = den;
            H(j + 1, j) = 0.0;
            g[j + 1] = -sn[j] * g[j];
            g[j] = cs[j] * g[j];
            ++j;
            ++st.iterations;
            if (std::abs(g[j]) <= 0.5 * tol * bn || hn <= 1e-14 * den) break;
        }
        if (j == 0) break;
        const VectorXd y = H.topLeftCorner(j, j).triangularView<Eigen::Upper>().solve(g.head(j));
        applyM(V.leftCols(j) * y, z);
        x += z;
        A(x, r);
        r = b - r;
        beta = r.norm();
        const double previous = st.residual;
        st.residual = beta / bn;
        if (!std::isfinite(st.residual) || st.residual >= previous) break;
    }
    st.converged = st.residual <= tol;
    return st;
}

}  // namespace trbc
