#include "core/geometry/closest_point.h"

#include <algorithm>

namespace softid::geometry {

Eigen::Vector3d ClosestPointOnSegment(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                      const Eigen::Vector3d& b) {
  const Eigen::Vector3d ab = b - a;
  const double length_sq = ab.squaredNorm();
  if (length_sq <= 0.0) return a;
  const double t = std::clamp((p - a).dot(ab) / length_sq, 0.0, 1.0);
  return a + t * ab;
}

Eigen::Vector3d ClosestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                       const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;  // vertex region a

  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return b;  // vertex region b

  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return a + (d1 / (d1 - d3)) * ab;  // edge ab

  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return c;  // vertex region c

  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return a + (d2 / (d2 - d6)) * ac;  // edge ac

  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {  // edge bc
    return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);
  }

  const double sum = va + vb + vc;  // = |ab x ac|^2
  if (!(sum > 0.0)) {
    // Degenerate triangle: closest of the three edges.
    const Eigen::Vector3d candidates[3] = {ClosestPointOnSegment(p, a, b),
                                           ClosestPointOnSegment(p, b, c),
                                           ClosestPointOnSegment(p, c, a)};
    int best = 0;
    for (int i = 1; i < 3; ++i) {
      if ((candidates[i] - p).squaredNorm() < (candidates[best] - p).squaredNorm()) best = i;
    }
    return candidates[best];
  }
  const double v = vb / sum, w = vc / sum;  // face region
  return a + v * ab + w * ac;
}

}  // namespace softid::geometry
