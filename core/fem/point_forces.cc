#include "core/fem/point_forces.h"

#include <cmath>

namespace softid::fem {

namespace {
// softplus(s) = log(1 + e^s), computed stably.
double Softplus(double s) {
  return s > 0.0 ? s + std::log1p(std::exp(-s)) : std::log1p(std::exp(s));
}
}  // namespace

double ContactNormalForce(const ContactLaw& law, double area, const Eigen::Vector3d& x) {
  const double a = 1.0 / law.smoothing;
  const double s = -a * law.plane.SignedDistance(x);
  if (s < -40.0) return 0.0;
  return law.stiffness * area * Softplus(s) / a;
}

Eigen::Vector3d FrictionForce(const ContactLaw& law, const Eigen::Vector3d& v,
                              double lagged_normal_force) {
  if (!(law.friction_coefficient > 0.0 && lagged_normal_force > 0.0))
    return Eigen::Vector3d::Zero();
  const Eigen::Vector3d& n = law.plane.normal;
  const Eigen::Vector3d vt = v - n.dot(v) * n;
  const double eps = law.friction_velocity_scale;
  const double speed = std::sqrt(vt.squaredNorm() + eps * eps);
  return (-law.friction_coefficient * lagged_normal_force / speed) * vt;
}

bool GroundContactVanishes(const ContactLaw& law, const Eigen::Vector3d& x,
                           double lagged_normal_force) {
  const bool friction = law.friction_coefficient > 0.0 && lagged_normal_force > 0.0;
  // s = -d / smoothing < -40: exp(-40), no normal force to double precision.
  return !friction && law.plane.SignedDistance(x) > 40.0 * law.smoothing;
}

PointForce GroundContactForce(const ContactLaw& law, double area, const Eigen::Vector3d& x,
                              const Eigen::Vector3d& v, double lagged_normal_force,
                              const Eigen::Vector3d* friction_iterate) {
  PointForce out;
  if (GroundContactVanishes(law, x, lagged_normal_force)) return out;
  const double a = 1.0 / law.smoothing;
  const double d = law.plane.SignedDistance(x);
  const double s = -a * d;  // > 0 when penetrating
  const bool friction = law.friction_coefficient > 0.0 && lagged_normal_force > 0.0;
  // sigma = logistic(s) is the derivative of softplus.
  const double softplus = Softplus(s);
  const double sigma = 1.0 / (1.0 + std::exp(-s));
  const Eigen::Vector3d& n = law.plane.normal;
  const double k_area = law.stiffness * area;
  const double normal_force = k_area * softplus / a;  // >= 0 [N]
  const double normal_stiffness = k_area * sigma;     // -d f_n / d d [N/m]
  const Eigen::Matrix3d nnt = n * n.transpose();
  out.force = normal_force * n;
  out.stiffness = normal_stiffness * nnt;
  if (law.damping > 0.0) {
    out.force -= law.damping * normal_stiffness * n.dot(v) * n;
    out.damping += law.damping * normal_stiffness * nnt;
    // d sigma / d d = -a sigma (1 - sigma).
    out.stiffness_indefinite = (-law.damping * k_area * a * sigma * (1.0 - sigma) * n.dot(v)) * nnt;
  }
  if (friction) {
    const Eigen::Matrix3d tangential = Eigen::Matrix3d::Identity() - nnt;
    const Eigen::Vector3d vt = tangential * v;
    const double eps = law.friction_velocity_scale;
    const double speed = std::sqrt(vt.squaredNorm() + eps * eps);
    const double c = law.friction_coefficient * lagged_normal_force / speed;
    out.force -= c * vt;
    if (friction_iterate != nullptr) {
      const Eigen::Vector3d lambda = tangential * *friction_iterate;
      out.damping += c * tangential + lambda * vt.transpose() / (speed * speed);
    } else {
      out.damping += c * (tangential - vt * vt.transpose() / (speed * speed));
    }
  }
  return out;
}

PointForce AirDragForce(double drag_linear, double drag_quadratic, double area,
                        const Eigen::Vector3d& v) {
  PointForce out;
  const double projected = 0.25 * area;
  const double speed = v.norm();
  out.force = -projected * (drag_linear + drag_quadratic * speed) * v;
  out.damping = projected * (drag_linear + drag_quadratic * speed) * Eigen::Matrix3d::Identity();
  if (speed > 0.0) out.damping += projected * drag_quadratic * v * v.transpose() / speed;
  return out;
}

}  // namespace softid::fem
