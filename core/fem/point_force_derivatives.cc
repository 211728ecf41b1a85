#include "core/fem/point_force_derivatives.h"

#include <ceres/jet.h>

#include <cmath>

namespace softid::fem {
namespace {

// Forward-mode derivatives over the inputs below; the force law is short, so dual numbers are
// cheaper to trust than a hand expansion of every product rule, and only points near the ground
// pay for them.
enum Input { kNormal = 0, kOffset = 3, kStiffness, kDamping, kFriction, kVelocity, kPrevious = 10 };
constexpr int kNumInputs = 13;
using Jet = ceres::Jet<double, kNumInputs>;
using Vector3J = Eigen::Matrix<Jet, 3, 1>;

Jet Softplus(const Jet& s) {
  using std::exp;
  using std::log1p;
  return s.a > 0.0 ? s + log1p(exp(-s)) : log1p(exp(s));
}

// Written so that exp never overflows (inf derivatives would turn into NaN).
Jet Logistic(const Jet& s) {
  using std::exp;
  if (s.a >= 0.0) return 1.0 / (1.0 + exp(-s));
  const Jet e = exp(s);
  return e / (1.0 + e);
}

}  // namespace

bool GroundContactDerivativesVanish(const ContactLaw& law, const Eigen::Vector3d& x,
                                    const Eigen::Vector3d& x_previous) {
  // exp(-40): no force, and no lagged normal force for friction, to double precision.
  const double limit = 40.0 * law.smoothing;
  return law.plane.SignedDistance(x) > limit && law.plane.SignedDistance(x_previous) > limit;
}

GroundForceDerivatives GroundContactForceDerivatives(const ContactLaw& law, double area,
                                                     const Eigen::Vector3d& x,
                                                     const Eigen::Vector3d& v,
                                                     const Eigen::Vector3d& x_previous) {
  GroundForceDerivatives out;
  if (GroundContactDerivativesVanish(law, x, x_previous)) return out;
  const double a = 1.0 / law.smoothing;

  Vector3J n, vel, xp;
  for (int i = 0; i < 3; ++i) {
    n[i] = Jet(law.plane.normal[i], kNormal + i);
    vel[i] = Jet(v[i], kVelocity + i);
    xp[i] = Jet(x_previous[i], kPrevious + i);
  }
  const Jet offset(law.plane.offset, kOffset);
  const Jet k(law.stiffness, kStiffness);
  const Jet c(law.damping, kDamping);
  const Jet mu(law.friction_coefficient, kFriction);
  const Vector3J xj = x.cast<Jet>();

  const Jet s = -a * (n.dot(xj) - offset);
  const Jet k_area = k * area;
  Vector3J force = (k_area * Softplus(s) / a) * n;
  // Normal damping: -c (k A sigma) (n . v) n.
  force -= (c * k_area * Logistic(s) * n.dot(vel)) * n;
  // Friction with the lagged normal force.
  const Jet s_lag = -a * (n.dot(xp) - offset);
  if (s_lag.a >= -40.0) {
    const Jet normal_force_lag = k_area * Softplus(s_lag) / a;
    const Vector3J vt = vel - n.dot(vel) * n;
    const Jet eps(law.friction_velocity_scale);
    using std::sqrt;
    const Jet speed = sqrt(vt.squaredNorm() + eps * eps);
    force -= (mu * normal_force_lag / speed) * vt;
  }
  for (int i = 0; i < 3; ++i) {
    out.force[i] = force[i].a;
    const auto& d = force[i].v;
    out.d_normal.row(i) = d.segment<3>(kNormal).transpose();
    out.d_offset[i] = d[kOffset];
    out.d_stiffness[i] = d[kStiffness];
    out.d_damping[i] = d[kDamping];
    out.d_friction[i] = d[kFriction];
    out.d_velocity.row(i) = d.segment<3>(kVelocity).transpose();
    out.d_previous_position.row(i) = d.segment<3>(kPrevious).transpose();
  }
  return out;
}

}  // namespace softid::fem
