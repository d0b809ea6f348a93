#include "experiments/thermal_undulations.hpp"

#include <array>
#include <cmath>
#include <numbers>

#include "experiments/parameters.hpp"

namespace trbc {
namespace {

constexpr double kPi = std::numbers::pi;

// Orthonormal real spherical harmonics of degree 2 at the unit vector (x, y, z): m = 0, +-1, +-2.
std::array<double, 5> harmonicsL2(double x, double y, double z) {
    const double c0 = 0.25 * std::sqrt(5.0 / kPi), c1 = 0.5 * std::sqrt(15.0 / kPi), c2 = 0.25 * std::sqrt(15.0 / kPi);
    return {c0 * (3.0 * z * z - 1.0), c1 * x * z, c1 * y * z, c1 * x * y, c2 * (x * x - y * y)};
}

// Degree 3: m = 0, +-1, +-2, +-3.
std::array<double, 7> harmonicsL3(double x, double y, double z) {
    const double c0 = 0.25 * std::sqrt(7.0 / kPi), c1 = 0.125 * std::sqrt(42.0 / kPi), c2 = 0.25 * std::sqrt(105.0 / kPi),
                 c3 = 0.125 * std::sqrt(70.0 / kPi);
    const double w = 5.0 * z * z - 1.0;
    return {c0 * z * (5.0 * z * z - 3.0), c1 * x * w,  c1 * y * w, c2 * z * (x * x - y * y), 2.0 * c2 * x * y * z,
            c3 * x * (x * x - 3.0 * y * y), c3 * y * (3.0 * x * x - y * y)};
}

}  // namespace

double thermalEnergy(double temperatureK) { return kBoltzmannJPerK * temperatureK * cell::joule; }

double undulationVariance(int l, double kT, double kb) {
    const double ld = l;
    return kT / (kb * (ld - 1.0) * (ld + 2.0) * ld * (ld + 1.0));
}

double undulationRms(double radius, double kT, double kb) {
    double sum = 0.0;
    for (int l : {2, 3}) sum += (2.0 * l + 1.0) / (4.0 * kPi) * undulationVariance(l, kT, kb);
    return radius * std::sqrt(sum);
}

Vertices thermalUndulation(const Vertices& X, double radius, double kT, double kb, Rng& rng) {
    std::array<double, 5> u2{};
    std::array<double, 7> u3{};
    const double s2 = std::sqrt(undulationVariance(2, kT, kb)), s3 = std::sqrt(undulationVariance(3, kT, kb));
    for (double& u : u2) u = s2 * rng.normal();
    for (double& u : u3) u = s3 * rng.normal();
    const Eigen::Vector3d c = X.rowwise().mean();
    Vertices d(3, X.cols());
    for (Eigen::Index i = 0; i < X.cols(); ++i) {
        const Eigen::Vector3d n = (X.col(i) - c).normalized();
        const auto y2 = harmonicsL2(n.x(), n.y(), n.z());
        const auto y3 = harmonicsL3(n.x(), n.y(), n.z());
        double dr = 0.0;
        for (int m = 0; m < 5; ++m) dr += u2[m] * y2[m];
        for (int m = 0; m < 7; ++m) dr += u3[m] * y3[m];
        d.col(i) = radius * dr * n;
    }
    return d;
}

}  // namespace trbc
