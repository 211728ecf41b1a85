#include "core/geometry/grid_alignment.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

namespace softid::geometry {
namespace {

// The area-weighted fourth moments of the unit normals, sum_t A_t n^(x)4 / sum_t A_t, as the 15
// distinct entries of the symmetric tensor: q(v) = T(v, v, v, v) is then a quartic with 15 terms
// and a score costs three of them whatever the mesh's size.
class NormalMoments {
 public:
  explicit NormalMoments(const TriangleMesh& mesh) {
    int index = 0;
    for (int i = 4; i >= 0; --i) {
      for (int j = 4 - i; j >= 0; --j) {
        powers_[index] = {i, j, 4 - i - j};
        ++index;
      }
    }
    double total_area = 0.0;
    for (const Eigen::Vector3i& t : mesh.triangles) {
      const Eigen::Vector3d doubled = (mesh.vertices[t[1]] - mesh.vertices[t[0]])
                                          .cross(mesh.vertices[t[2]] - mesh.vertices[t[0]]);
      const double norm = doubled.norm();
      if (!(norm > 0.0)) continue;
      const Eigen::Vector3d n = doubled / norm;
      const Powers p(n);
      for (int k = 0; k < kTerms; ++k) weights_[k] += norm * p.Monomial(powers_[k]);
      total_area += norm;
    }
    if (!(total_area > 0.0)) return;
    for (int k = 0; k < kTerms; ++k) weights_[k] *= Multinomial(k) / total_area;
  }

  double Quartic(const Eigen::Vector3d& v) const {
    const Powers p(v);
    double sum = 0.0;
    for (int k = 0; k < kTerms; ++k) sum += weights_[k] * p.Monomial(powers_[k]);
    return sum;
  }
  double Score(const Eigen::Matrix3d& axes) const {
    return Quartic(axes.col(0)) + Quartic(axes.col(1)) + Quartic(axes.col(2));
  }

 private:
  static constexpr int kTerms = 15;
  // v's coordinates to the powers 0..4, so that a monomial is two products (the search scores
  // ~100,000 frames).
  struct Powers {
    explicit Powers(const Eigen::Vector3d& v) {
      for (int a = 0; a < 3; ++a) {
        of[a][0] = 1.0;
        for (int e = 1; e <= 4; ++e) of[a][e] = of[a][e - 1] * v[a];
      }
    }
    double Monomial(const std::array<int, 3>& exponents) const {
      return of[0][exponents[0]] * of[1][exponents[1]] * of[2][exponents[2]];
    }
    std::array<std::array<double, 5>, 3> of;
  };
  double Multinomial(int k) const {
    constexpr std::array<double, 5> kFactorial = {1, 1, 2, 6, 24};
    const auto& p = powers_[k];
    return kFactorial[4] / (kFactorial[p[0]] * kFactorial[p[1]] * kFactorial[p[2]]);
  }
  std::array<std::array<int, 3>, kTerms> powers_{};
  std::array<double, kTerms> weights_{};
};

// A frame whose first axis is `first` (unit), turned by `angle` about it.
Eigen::Matrix3d FrameAbout(const Eigen::Vector3d& first, double angle) {
  const Eigen::Vector3d helper =
      std::abs(first.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d u = first.cross(helper).normalized();
  const Eigen::Vector3d w = first.cross(u);
  Eigen::Matrix3d axes;
  axes.col(0) = first;
  axes.col(1) = std::cos(angle) * u + std::sin(angle) * w;
  axes.col(2) = first.cross(axes.col(1));
  return axes;
}

struct Candidate {
  Eigen::Matrix3d axes;
  double score;
};

// Directions on a Fibonacci lattice over the upper half sphere (q(-v) = q(v)), ~4 degrees
// apart, each with turns about it every 3 degrees over a quarter turn (the grid's symmetry).
std::vector<Candidate> GlobalSearch(const NormalMoments& moments, int keep) {
  constexpr int kDirections = 1000;
  constexpr int kTurns = 30;
  const double golden_angle = M_PI * (3.0 - std::sqrt(5.0));
  std::vector<Candidate> found;
  found.reserve(kDirections * kTurns);
  for (int i = 0; i < kDirections; ++i) {
    const double z = 1.0 - (i + 0.5) / kDirections;
    const double r = std::sqrt(1.0 - z * z);
    const Eigen::Vector3d d(r * std::cos(golden_angle * i), r * std::sin(golden_angle * i), z);
    for (int k = 0; k < kTurns; ++k) {
      const Eigen::Matrix3d axes = FrameAbout(d, 0.5 * M_PI * k / kTurns);
      found.push_back({axes, moments.Score(axes)});
    }
  }
  const int kept = std::min<int>(keep, static_cast<int>(found.size()));
  std::partial_sort(found.begin(), found.begin() + kept, found.end(),
                    [](const Candidate& a, const Candidate& b) { return a.score > b.score; });
  found.resize(kept);
  return found;
}

// Pattern search over small turns about the frame's own axes, halving the step from 2 degrees to
// 1e-6 rad.
Candidate Refine(const NormalMoments& moments, Candidate c) {
  for (double step = 2.0 * M_PI / 180.0; step > 1e-6; step *= 0.5) {
    bool improved = true;
    while (improved) {
      improved = false;
      for (int a = 0; a < 3; ++a) {
        for (double sign : {1.0, -1.0}) {
          const Eigen::Matrix3d turned =
              c.axes * Eigen::AngleAxisd(sign * step, Eigen::Vector3d::Unit(a)).toRotationMatrix();
          const double score = moments.Score(turned);
          if (score > c.score) {
            c = {turned, score};
            improved = true;
          }
        }
      }
    }
  }
  return c;
}

// The grid's axes permuted and flipped (det +1) to lie closest to the mesh's own: a body already
// nearly aligned keeps its axes' names and directions.
Eigen::Matrix3d ClosestToIdentity(const Eigen::Matrix3d& axes) {
  Eigen::Matrix3d best = axes;
  double best_trace = -4.0;
  std::array<int, 3> order = {0, 1, 2};
  do {
    for (int signs = 0; signs < 8; ++signs) {
      Eigen::Matrix3d p = Eigen::Matrix3d::Zero();
      for (int a = 0; a < 3; ++a) p(order[a], a) = (signs >> a) & 1 ? -1.0 : 1.0;
      if (p.determinant() < 0.0) continue;
      const Eigen::Matrix3d candidate = axes * p;
      if (candidate.trace() > best_trace) {
        best_trace = candidate.trace();
        best = candidate;
      }
    }
  } while (std::next_permutation(order.begin(), order.end()));
  return best;
}

}  // namespace

double AxisAlignmentScore(const TriangleMesh& mesh, const Eigen::Matrix3d& mesh_from_grid) {
  return NormalMoments(mesh).Score(mesh_from_grid);
}

GridAlignment AlignGridToSurface(const TriangleMesh& mesh) {
  const NormalMoments moments(mesh);
  GridAlignment out;
  out.identity_score = moments.Score(Eigen::Matrix3d::Identity());
  Candidate best{Eigen::Matrix3d::Identity(), out.identity_score};
  std::vector<Candidate> starts = GlobalSearch(moments, 4);
  starts.push_back(best);
  for (const Candidate& start : starts) {
    const Candidate refined = Refine(moments, start);
    if (refined.score > best.score) best = refined;
  }
  // Re-orthonormalise the product of many small turns.
  const Eigen::Quaterniond q(best.axes);
  out.mesh_from_grid = ClosestToIdentity(q.normalized().toRotationMatrix());
  out.score = moments.Score(out.mesh_from_grid);
  return out;
}

Eigen::AlignedBox3d BoundsInGrid(const TriangleMesh& mesh, const Eigen::Matrix3d& mesh_from_grid) {
  Eigen::AlignedBox3d box;
  for (const Eigen::Vector3d& x : mesh.vertices) box.extend(mesh_from_grid.transpose() * x);
  return box;
}

}  // namespace softid::geometry
