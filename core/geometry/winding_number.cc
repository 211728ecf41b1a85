#include "core/geometry/winding_number.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <string>

#include "core/common/check.h"

namespace softid::geometry {
namespace {

// Area times unit normal of a triangle [m^2].
Eigen::Vector3d AreaNormal(const TriangleMesh& mesh, const Eigen::Vector3i& tri) {
  return 0.5 * (mesh.vertices[tri[1]] - mesh.vertices[tri[0]])
                   .cross(mesh.vertices[tri[2]] - mesh.vertices[tri[0]]);
}

constexpr int kLeafSize = 8;
constexpr int kMaxTreeDepth = 96;

// Signed solid angle of triangle (a, b, c) seen from p (Van Oosterom & Strackee 1983) [sr];
// positive when p is on the side opposite to the counter-clockwise normal.
double SolidAngle(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                  const Eigen::Vector3d& p) {
  const Eigen::Vector3d pa = a - p, pb = b - p, pc = c - p;
  const double la = pa.norm(), lb = pb.norm(), lc = pc.norm();
  const double numerator = pa.dot(pb.cross(pc));
  const double denominator = la * lb * lc + pa.dot(pb) * lc + pa.dot(pc) * lb + pb.dot(pc) * la;
  return 2.0 * std::atan2(numerator, denominator);
}

// Slot of the monomial r_j r_k r_l in Node::cubic, ordered xxx, xxy, xxz, xyy, xyz, xzz, yyy,
// yyz, yzz, zzz (the order the evaluation groups them in).
int CubicMonomial(int j, int k, int l) {
  int e[3] = {0, 0, 0};
  ++e[j];
  ++e[k];
  ++e[l];
  static constexpr int kSlot[4][4] = {
      // kSlot[ex][ey] with ez = 3 - ex - ey.
      {9, 8, 7, 6},    // ex = 0: zzz, yzz, yyz, yyy
      {5, 4, 3, -1},   // ex = 1: xzz, xyz, xyy
      {2, 1, -1, -1},  // ex = 2: xxz, xxy
      {0, -1, -1, -1}  // ex = 3: xxx
  };
  return kSlot[e[0]][e[1]];
}

// Zeroth and first moments of a cluster: where its expansion is centred, and its dipole term.
struct ClusterCenter {
  Eigen::Vector3d center;            // area-weighted centroid (plain mean if area is 0) [m]
  Eigen::Vector3d dipole;            // sum a_i n_i [m^2]
  Eigen::AlignedBox3d centroid_box;  // of the triangle centroids, for the split axis [m]
};

// Moments of the triangles order[begin, end).
ClusterCenter CenterCluster(const TriangleMesh& mesh, const std::vector<int>& order, int begin,
                            int end, const std::vector<Eigen::Vector3d>& centroids) {
  double area = 0.0;
  Eigen::Vector3d weighted = Eigen::Vector3d::Zero(), mean = Eigen::Vector3d::Zero();
  ClusterCenter cluster;
  cluster.dipole = Eigen::Vector3d::Zero();
  for (int i = begin; i < end; ++i) {
    const int t = order[i];
    const Eigen::Vector3i& tri = mesh.triangles[t];
    const Eigen::Vector3d area_normal = AreaNormal(mesh, tri);
    const double a = area_normal.norm();
    area += a;
    weighted += a * centroids[t];
    mean += centroids[t];
    cluster.dipole += area_normal;
    cluster.centroid_box.extend(centroids[t]);
  }
  cluster.center =
      area > 0.0 ? Eigen::Vector3d(weighted / area) : Eigen::Vector3d(mean / double(end - begin));
  return cluster;
}

// Higher moments of a cluster about its center (see WindingNumber::Node).
struct ClusterMoments {
  Eigen::Matrix3d second;                // M2 [m^3]
  std::array<Eigen::Matrix3d, 3> third;  // third[j](k, l) = T_jkl [m^4]
  double radius_sq = 0.0;                // (max |corner - center|)^2 [m^2]
};

ClusterMoments MomentsAboutCenter(const TriangleMesh& mesh, const std::vector<int>& order,
                                  int begin, int end, const std::vector<Eigen::Vector3d>& centroids,
                                  const Eigen::Vector3d& center) {
  ClusterMoments moments;
  Eigen::Matrix3d& second = moments.second;
  std::array<Eigen::Matrix3d, 3>& third = moments.third;
  second.setZero();
  for (Eigen::Matrix3d& m : third) m.setZero();
  double& radius_sq = moments.radius_sq;
  for (int i = begin; i < end; ++i) {
    const int t = order[i];
    const Eigen::Vector3i& tri = mesh.triangles[t];
    const Eigen::Vector3d area_normal = AreaNormal(mesh, tri);
    second += (centroids[t] - center) * area_normal.transpose();
    // Mean of (x - c)(x - c)^T over the triangle: (sum u_i u_i^T + s s^T) / 12, u_i = corner - c.
    const Eigen::Vector3d u0 = mesh.vertices[tri[0]] - center, u1 = mesh.vertices[tri[1]] - center,
                          u2 = mesh.vertices[tri[2]] - center;
    const Eigen::Vector3d sum = u0 + u1 + u2;
    const Eigen::Matrix3d moment =
        (u0 * u0.transpose() + u1 * u1.transpose() + u2 * u2.transpose() + sum * sum.transpose()) /
        12.0;
    for (int j = 0; j < 3; ++j) third[j] += area_normal[j] * moment;
    for (int c = 0; c < 3; ++c) {
      radius_sq = std::max(radius_sq, (mesh.vertices[tri[c]] - center).squaredNorm());
    }
  }
  return moments;
}

// Q2 coefficients of xx, yy, zz, xy, yz, zx.
std::array<double, 6> QuadraticCoefficients(const Eigen::Matrix3d& second) {
  return {second(0, 0),
          second(1, 1),
          second(2, 2),
          second(0, 1) + second(1, 0),
          second(1, 2) + second(2, 1),
          second(2, 0) + second(0, 2)};
}

// third_linear_l = 2 sum_j T_jjl + sum_k T_lkk.
Eigen::Vector3d ThirdLinearCoefficients(const std::array<Eigen::Matrix3d, 3>& third) {
  Eigen::Vector3d third_linear;
  for (int l = 0; l < 3; ++l) {
    third_linear[l] = 2.0 * (third[0](0, l) + third[1](1, l) + third[2](2, l)) + third[l].trace();
  }
  return third_linear;
}

// C3 coefficients: T_jkl summed into the slot of its monomial.
std::array<double, 10> CubicCoefficients(const std::array<Eigen::Matrix3d, 3>& third) {
  std::array<double, 10> cubic;
  cubic.fill(0.0);
  for (int j = 0; j < 3; ++j) {
    for (int k = 0; k < 3; ++k) {
      for (int l = 0; l < 3; ++l) cubic[CubicMonomial(j, k, l)] += third[j](k, l);
    }
  }
  return cubic;
}

}  // namespace

WindingNumber::WindingNumber(const TriangleMesh& mesh) {
  const int n = static_cast<int>(mesh.triangles.size());
  const int num_vertices = static_cast<int>(mesh.vertices.size());
  std::vector<Eigen::Vector3d> centroids(n);
  for (int t = 0; t < n; ++t) {
    const Eigen::Vector3i& tri = mesh.triangles[t];
    SOFTID_THROW_UNLESS(
        (tri.array() >= 0).all() && (tri.array() < num_vertices).all(),
        "WindingNumber: triangle " + std::to_string(t) + " has a vertex index out of range");
    centroids[t] = (mesh.vertices[tri[0]] + mesh.vertices[tri[1]] + mesh.vertices[tri[2]]) / 3.0;
  }
  if (n == 0) return;
  std::vector<int> order(n);
  for (int t = 0; t < n; ++t) order[t] = t;
  nodes_.reserve(2 * (n / kLeafSize + 1));
  Build(0, n, &order, centroids, mesh);
  corners_.reserve(3 * static_cast<size_t>(n));
  for (int t : order) {
    for (int c = 0; c < 3; ++c) corners_.push_back(mesh.vertices[mesh.triangles[t][c]]);
  }
}

int WindingNumber::Build(int begin, int end, std::vector<int>* order,
                         const std::vector<Eigen::Vector3d>& centroids, const TriangleMesh& mesh) {
  const int index = static_cast<int>(nodes_.size());
  nodes_.emplace_back();
  const ClusterCenter cluster = CenterCluster(mesh, *order, begin, end, centroids);
  const ClusterMoments moments =
      MomentsAboutCenter(mesh, *order, begin, end, centroids, cluster.center);
  Node& node = nodes_[index];
  node.center = cluster.center;
  node.radius_sq = moments.radius_sq;
  node.dipole = cluster.dipole;
  node.second_trace = moments.second.trace();
  node.quadratic = QuadraticCoefficients(moments.second);
  node.third_linear = ThirdLinearCoefficients(moments.third);
  node.cubic = CubicCoefficients(moments.third);
  node.begin = begin;
  node.end = end;
  if (end - begin <= kLeafSize) return index;
  int axis;
  cluster.centroid_box.sizes().maxCoeff(&axis);
  const int mid = begin + (end - begin) / 2;
  std::nth_element(order->begin() + begin, order->begin() + mid, order->begin() + end,
                   [&](int a, int b) { return centroids[a][axis] < centroids[b][axis]; });
  Build(begin, mid, order, centroids, mesh);  // left child = index + 1
  const int right = Build(mid, end, order, centroids, mesh);
  nodes_[index].right = right;
  return index;
}

double WindingNumber::LeafSolidAngle(const Node& node, const Eigen::Vector3d& p) const {
  double omega = 0.0;
  for (int t = node.begin; t < node.end; ++t) {
    omega += SolidAngle(corners_[3 * t], corners_[3 * t + 1], corners_[3 * t + 2], p);
  }
  return omega;
}

double WindingNumber::Evaluate(const Eigen::Vector3d& p, double far_factor) const {
  if (nodes_.empty()) return 0.0;
  const double far_sq = far_factor * far_factor;
  std::array<int, kMaxTreeDepth> stack;
  int size = 0;
  stack[size++] = 0;
  double omega = 0.0;
  while (size > 0) {
    const Node& node = nodes_[stack[--size]];
    const Eigen::Vector3d r = node.center - p;
    const double d_sq = r.squaredNorm();
    if (d_sq > far_sq * node.radius_sq) {
      const double inv_d_sq = 1.0 / d_sq;
      const double inv_d3 = inv_d_sq * std::sqrt(inv_d_sq);
      const double inv_d5 = inv_d3 * inv_d_sq;
      const double x = r.x(), y = r.y(), z = r.z();
      const double xx = x * x, yy = y * y, zz = z * z;
      const std::array<double, 6>& q = node.quadratic;
      const double quadratic =
          q[0] * xx + q[1] * yy + q[2] * zz + q[3] * x * y + q[4] * y * z + q[5] * z * x;
      const std::array<double, 10>& c = node.cubic;
      const double cubic =
          x * (c[0] * xx + c[1] * x * y + c[2] * x * z + c[3] * yy + c[4] * y * z + c[5] * zz) +
          y * (c[6] * yy + c[7] * y * z + c[8] * zz) + c[9] * zz * z;
      omega += inv_d3 * (r.dot(node.dipole) + node.second_trace) -
               inv_d5 * (3.0 * quadratic + 1.5 * node.third_linear.dot(r)) +
               7.5 * inv_d5 * inv_d_sq * cubic;
    } else if (node.right < 0) {
      omega += LeafSolidAngle(node, p);
    } else {
      SOFTID_DEMAND(size + 2 <= kMaxTreeDepth);
      stack[size++] = node.right;
      stack[size++] = static_cast<int>(&node - nodes_.data()) + 1;
    }
  }
  return omega / (4.0 * std::numbers::pi);
}

double WindingNumber::Exact(const Eigen::Vector3d& p) const {
  double omega = 0.0;
  const int n = static_cast<int>(corners_.size() / 3);
  for (int t = 0; t < n; ++t) {
    omega += SolidAngle(corners_[3 * t], corners_[3 * t + 1], corners_[3 * t + 2], p);
  }
  return omega / (4.0 * std::numbers::pi);
}

}  // namespace softid::geometry
