#include "core/geometry/cut_cell_weights.h"

#include <Eigen/Core>
#include <algorithm>
#include <bit>
#include <cmath>
#include <string>
#include <utility>

#include "core/common/check.h"

namespace softid::geometry {
namespace {

// Values of the trilinear interpolant of `phi` (corner order) on the 3x3x3 lattice of the
// children's corners, index i + 3j + 9k. Exact: trilinear restricted to a sub-box is trilinear.
void RefineCorners(const double phi[8], double g[27]) {
  for (int k = 0; k < 2; ++k) {
    for (int j = 0; j < 2; ++j) {
      const double a = phi[2 * j + 4 * k], b = phi[1 + 2 * j + 4 * k];
      const int base = 6 * j + 18 * k;
      g[base] = a;
      g[base + 1] = 0.5 * (a + b);
      g[base + 2] = b;
    }
  }
  for (int k = 0; k <= 2; k += 2) {
    for (int i = 0; i < 3; ++i) g[i + 3 + 9 * k] = 0.5 * (g[i + 9 * k] + g[i + 6 + 9 * k]);
  }
  for (int j = 0; j < 3; ++j) {
    for (int i = 0; i < 3; ++i) g[i + 3 * j + 9] = 0.5 * (g[i + 3 * j] + g[i + 3 * j + 18]);
  }
}

// Corner values of child (dx + 2dy + 4dz) from the refined lattice.
void ChildCorners(const double g[27], int child, double child_phi[8]) {
  const int dx = child & 1, dy = (child >> 1) & 1, dz = (child >> 2) & 1;
  for (int c = 0; c < 8; ++c) {
    child_phi[c] = g[(dx + (c & 1)) + 3 * (dy + ((c >> 1) & 1)) + 9 * (dz + ((c >> 2) & 1))];
  }
}

// Volume fraction of the unit cube {m . xi < alpha} for m >= 0 (Scardovelli & Zaleski 2000,
// "Analytical relations connecting linear interfaces and volume fractions", as in Basilisk's
// plane_volume): piecewise cubic in alpha, using the symmetry V(alpha) = 1 - V(sum m - alpha).
double UnitCubeFractionBelowPlane(double m1, double m2, double m3, double alpha) {
  const double total = m1 + m2 + m3;
  if (alpha <= 0.0) return 0.0;
  if (alpha >= total) return 1.0;
  // Normalise to m1 + m2 + m3 = 1 and sort m1 <= m2 <= m3; negligible components are dropped
  // (the formula divides by them where they are not exactly zero).
  m1 /= total;
  m2 /= total;
  m3 /= total;
  alpha /= total;
  if (m1 > m2) std::swap(m1, m2);
  if (m2 > m3) std::swap(m2, m3);
  if (m1 > m2) std::swap(m1, m2);
  constexpr double kTiny = 1e-9;
  if (m1 < kTiny) m1 = 0.0;
  if (m2 < kTiny) m2 = 0.0;
  const double a = std::min(alpha, 1.0 - alpha);
  const double m12 = m1 + m2;
  const double pr = 6.0 * m1 * m2 * m3;
  double v;
  if (a < m1) {
    v = a * a * a / pr;
  } else if (a < m2) {
    // m1 = 0 (a plane parallel to an axis) makes pr vanish; the corner term then vanishes too.
    v = 0.5 * a * (a - m1) / (m2 * m3) + (m1 > 0.0 ? m1 * m1 * m1 / pr : 0.0);
  } else if (a < std::min(m12, m3)) {
    v = (a * a * (3.0 * m12 - a) + m1 * m1 * (m1 - 3.0 * a) + m2 * m2 * (m2 - 3.0 * a)) / pr;
  } else if (m12 < m3) {
    v = (a - 0.5 * m12) / m3;
  } else {
    v = (a * a * (3.0 - 2.0 * a) + m1 * m1 * (m1 - 3.0 * a) + m2 * m2 * (m2 - 3.0 * a) +
         m3 * m3 * (m3 - 3.0 * a)) /
        pr;
  }
  v = std::clamp(v, 0.0, 1.0);
  return alpha <= 0.5 ? v : 1.0 - v;
}

// Adds the box volume v with N_c evaluated at `point` (unit cell coordinates). Exact for a full
// box with point = box centre: the integral of N_c over a box is its volume times N_c at the box
// centre (N_c is a product of per-axis linear factors).
void AddInsideVolume(double v, const Eigen::Vector3d& point, double* volume,
                     std::array<double, 8>* node) {
  *volume += v;
  const double wx[2] = {1.0 - point.x(), point.x()}, wy[2] = {1.0 - point.y(), point.y()},
               wz[2] = {1.0 - point.z(), point.z()};
  for (int c = 0; c < 8; ++c) (*node)[c] += v * wx[c & 1] * wy[(c >> 1) & 1] * wz[(c >> 2) & 1];
}

// Moments mu[p] = integral of prod_{i in p} xi_i over {m . xi < beta} within the unit cube, for the
// 8 axis subsets p (bit i = axis i), m >= 0. Inclusion-exclusion over the corners v of the cube:
// the orthant {xi >= v} below the plane is the simplex v + {eta >= 0, m . eta < beta - m . v} with
// legs L_i = (beta - m . v) / m_i, whose monomial integrals are
// integral eta^q = prod_i L_i^(1 + q_i) / (d + |q|)!  (q_i in {0,1}, d = dimension).
// Axes with m_i below 1e-6 of the largest are treated as parallel to the plane (a prism along
// them), which keeps the terms well conditioned.
void MomentsBelowPlane(const Eigen::Vector3d& m, double beta, double mu[8]) {
  static constexpr double kInverseFactorial[7] = {1.0,      1.0,       1.0 / 2,  1.0 / 6,
                                                  1.0 / 24, 1.0 / 120, 1.0 / 720};
  const double tol = 1e-6 * m.maxCoeff();
  int active[3], d = 0;
  for (int i = 0; i < 3; ++i) {
    if (m[i] > tol) active[d++] = i;
  }
  for (int p = 0; p < 8; ++p) mu[p] = 0.0;
  for (int corner = 0; corner < (1 << d); ++corner) {
    double a = beta;
    int v = 0;  // corner as an axis mask
    for (int k = 0; k < d; ++k) {
      if (corner & (1 << k)) {
        a -= m[active[k]];
        v |= 1 << active[k];
      }
    }
    if (a <= 0.0) continue;
    const double sign = std::popcount(static_cast<unsigned>(v)) % 2 == 0 ? 1.0 : -1.0;
    double legs[3] = {0.0, 0.0, 0.0};
    double leg_product = 1.0;
    for (int k = 0; k < d; ++k) {
      legs[active[k]] = a / m[active[k]];
      leg_product *= legs[active[k]];
    }
    for (int p = 0; p < 8; ++p) {
      // Inactive axes in p contribute integral_0^1 xi = 1/2.
      double inactive_factor = 1.0;
      int p_active = 0;
      for (int i = 0; i < 3; ++i) {
        if (!(p & (1 << i))) continue;
        if (legs[i] > 0.0) {
          p_active |= 1 << i;
        } else {
          inactive_factor *= 0.5;
        }
      }
      // prod_{i in p_active} (v_i + eta_i) = sum over q subset of p_active with p_active \ q
      // inside v of eta^q.
      double sum = 0.0;
      for (int q = p_active;; q = (q - 1) & p_active) {
        if (((p_active & ~q) & ~v) == 0) {
          double term =
              leg_product * kInverseFactorial[d + std::popcount(static_cast<unsigned>(q))];
          for (int i = 0; i < 3; ++i) {
            if (q & (1 << i)) term *= legs[i];
          }
          sum += term;
        }
        if (q == 0) break;
      }
      mu[p] += sign * inactive_factor * sum;
    }
  }
}

// Adds the inside part of the leaf box [lo, lo + s]^3 (unit cell coordinates) where trilinear phi
// is replaced by its tangent plane phi_c + g . (xi - 1/2) at the leaf centre (xi leaf coordinates):
// volume (Scardovelli-Zaleski) and the exact integrals of N_c over that polytope (moments).
void AddPlanarLeaf(const double lo[3], double s, double centre, const Eigen::Vector3d& g,
                   double* volume, std::array<double, 8>* node) {
  // Reflect axes with g_i < 0 (xi_i -> 1 - xi_i) so that the inside reads m . xi' < alpha.
  const Eigen::Vector3d m = g.cwiseAbs();
  const double alpha = 0.5 * m.sum() - centre;
  const double fraction = UnitCubeFractionBelowPlane(m.x(), m.y(), m.z(), alpha);
  if (fraction <= 0.0) return;
  const Eigen::Vector3d box_centre =
      Eigen::Vector3d(lo[0], lo[1], lo[2]) + Eigen::Vector3d::Constant(0.5 * s);
  if (fraction >= 1.0) {
    AddInsideVolume(s * s * s, box_centre, volume, node);
    return;
  }
  // Integrate over the smaller of the inside and its complement {m . xi'' < sum m - alpha},
  // xi'' = 1 - xi' (all axes reflected once more).
  const bool complement = fraction > 0.5;
  double mu[8];
  MomentsBelowPlane(m, complement ? m.sum() - alpha : alpha, mu);
  const double part = complement ? 1.0 - fraction : fraction;
  if (!(mu[0] > 0.0)) {
    AddInsideVolume(fraction * s * s * s, box_centre, volume, node);
    return;
  }
  const double scale = part / mu[0];  // make the moments consistent with the robust volume
  // Per axis: cell coordinate x_i = A_i + B_i * xi_i in the integration frame.
  double A[3], B[3];
  for (int i = 0; i < 3; ++i) {
    const bool reflected = (g[i] < 0.0) != complement;
    A[i] = reflected ? lo[i] + s : lo[i];
    B[i] = reflected ? -s : s;
  }
  const double leaf_volume = s * s * s;
  *volume += fraction * leaf_volume;
  for (int c = 0; c < 8; ++c) {
    // N_c = prod_i (d_i ? x_i : 1 - x_i) = prod_i (a_i + b_i xi_i), expanded over axis subsets p.
    double a[3], b[3];
    for (int i = 0; i < 3; ++i) {
      const bool upper = (c >> i) & 1;
      a[i] = upper ? A[i] : 1.0 - A[i];
      b[i] = upper ? B[i] : -B[i];
    }
    double integral = 0.0;
    for (int p = 0; p < 8; ++p) {
      integral += (p & 1 ? b[0] : a[0]) * (p & 2 ? b[1] : a[1]) * (p & 4 ? b[2] : a[2]) * mu[p];
    }
    integral *= scale;
    if (complement) {
      const double full = (c & 1 ? box_centre.x() : 1.0 - box_centre.x()) *
                          (c & 2 ? box_centre.y() : 1.0 - box_centre.y()) *
                          (c & 4 ? box_centre.z() : 1.0 - box_centre.z());
      integral = full - integral;
    }
    (*node)[c] += integral * leaf_volume;
  }
}

// Integrates the inside of the sub-cube [lo, lo + s]^3 (edge s = 2^-depth) with corner values phi.
void Integrate(const double phi[8], const double lo[3], double s, int depth, double* volume,
               std::array<double, 8>* node) {
  int negative = 0;
  for (int c = 0; c < 8; ++c) negative += phi[c] < 0.0;
  if (negative == 0) return;  // a trilinear function takes its extremes at the box corners
  if (negative == 8) {
    AddInsideVolume(s * s * s,
                    Eigen::Vector3d(lo[0], lo[1], lo[2]) + Eigen::Vector3d::Constant(0.5 * s),
                    volume, node);
    return;
  }
  if (depth >= kCutCellMaxDepth) {
    // Leaf: replace the trilinear phi by its tangent plane at the leaf centre (second order).
    const double centre =
        0.125 * (phi[0] + phi[1] + phi[2] + phi[3] + phi[4] + phi[5] + phi[6] + phi[7]);
    const Eigen::Vector3d g(
        0.25 * (phi[1] - phi[0] + phi[3] - phi[2] + phi[5] - phi[4] + phi[7] - phi[6]),
        0.25 * (phi[2] - phi[0] + phi[3] - phi[1] + phi[6] - phi[4] + phi[7] - phi[5]),
        0.25 * (phi[4] - phi[0] + phi[5] - phi[1] + phi[6] - phi[2] + phi[7] - phi[3]));
    AddPlanarLeaf(lo, s, centre, g, volume, node);
    return;
  }
  double g[27];
  RefineCorners(phi, g);
  const double half = 0.5 * s;
  for (int child = 0; child < 8; ++child) {
    double child_phi[8];
    ChildCorners(g, child, child_phi);
    const double child_lo[3] = {lo[0] + (child & 1) * half, lo[1] + ((child >> 1) & 1) * half,
                                lo[2] + ((child >> 2) & 1) * half};
    Integrate(child_phi, child_lo, half, depth + 1, volume, node);
  }
}

}  // namespace

CutCellWeights ComputeCutCellWeights(const std::array<double, 8>& corner_phi, double cell_size) {
  SOFTID_THROW_UNLESS(
      cell_size > 0.0 && std::isfinite(cell_size),
      "ComputeCutCellWeights: cell_size = " + std::to_string(cell_size) + ": must be positive");
  CutCellWeights w;
  int negative = 0;
  for (double p : corner_phi) negative += p < 0.0;
  if (negative == 0) return w;
  const double h3 = cell_size * cell_size * cell_size;
  if (negative == 8) {
    w.node_volume.fill(h3 / 8.0);
    w.octant_volume.fill(h3 / 8.0);
    w.volume = h3;
    return w;
  }
  // Split the root here so that each octant's volume lands in its own accumulator.
  double g[27];
  RefineCorners(corner_phi.data(), g);
  std::array<double, 8> unit_node{};
  double unit_volume = 0.0;
  for (int octant = 0; octant < 8; ++octant) {
    double octant_phi[8];
    ChildCorners(g, octant, octant_phi);
    const double lo[3] = {0.5 * (octant & 1), 0.5 * ((octant >> 1) & 1), 0.5 * ((octant >> 2) & 1)};
    double octant_volume = 0.0;
    Integrate(octant_phi, lo, 0.5, 1, &octant_volume, &unit_node);
    w.octant_volume[octant] = octant_volume * h3;
    unit_volume += octant_volume;
  }
  for (int c = 0; c < 8; ++c) w.node_volume[c] = unit_node[c] * h3;
  w.volume = unit_volume * h3;
  return w;
}

CutCellWeights ComputeCutCellWeights(std::span<const double> lattice_phi, int samples_per_side,
                                     double cell_size) {
  const int n = samples_per_side;
  SOFTID_THROW_UNLESS(IsCutCellSampling(n), "ComputeCutCellWeights: samples_per_side = " +
                                                std::to_string(n) + ": must be 1, 2, 4 or 8");
  const int side = n + 1;
  SOFTID_THROW_UNLESS(static_cast<int>(lattice_phi.size()) == side * side * side,
                      "ComputeCutCellWeights: lattice of " + std::to_string(lattice_phi.size()) +
                          " values: must hold (samples_per_side + 1)^3");
  auto at = [&](int i, int j, int k) { return lattice_phi[i + side * (j + side * k)]; };
  if (n == 1) {
    std::array<double, 8> corners;
    for (int c = 0; c < 8; ++c) corners[c] = at(c & 1, (c >> 1) & 1, (c >> 2) & 1);
    return ComputeCutCellWeights(corners, cell_size);
  }
  SOFTID_THROW_UNLESS(
      cell_size > 0.0 && std::isfinite(cell_size),
      "ComputeCutCellWeights: cell_size = " + std::to_string(cell_size) + ": must be positive");
  const int depth = std::countr_zero(static_cast<unsigned>(n));
  const double s = 1.0 / n;
  std::array<double, 8> unit_node{};
  std::array<double, 8> unit_octant{};
  for (int k = 0; k < n; ++k) {
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        double phi[8];
        for (int c = 0; c < 8; ++c)
          phi[c] = at(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1));
        const double lo[3] = {i * s, j * s, k * s};
        const int octant = (2 * i >= n) + 2 * (2 * j >= n) + 4 * (2 * k >= n);
        Integrate(phi, lo, s, depth, &unit_octant[octant], &unit_node);
      }
    }
  }
  const double h3 = cell_size * cell_size * cell_size;
  CutCellWeights w;
  for (int c = 0; c < 8; ++c) {
    w.node_volume[c] = unit_node[c] * h3;
    w.octant_volume[c] = unit_octant[c] * h3;
    w.volume += unit_octant[c] * h3;
  }
  return w;
}

}  // namespace softid::geometry
