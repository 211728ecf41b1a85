#include "core/fem/rest_frame.h"

#include "core/fem/corotation.h"

namespace softid::fem {
namespace {

// d R / d theta_k of R = exp([theta]x) (Gallego and Yezzi, J. Math. Imaging Vis. 2015):
// (theta_k [theta]x + [theta x (I - R) e_k]x) R / |theta|^2, and [e_k]x at theta = 0.
std::array<Eigen::Matrix3d, 3> RotationDerivatives(const Eigen::Vector3d& theta,
                                                   const Eigen::Matrix3d& r) {
  std::array<Eigen::Matrix3d, 3> d;
  const double squared = theta.squaredNorm();
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d e = Eigen::Vector3d::Unit(k);
    // Below 1e-20 rad^2 the formula loses its digits; the generator is exact to first order.
    if (squared < 1e-20) {
      d[k] = Skew(e) * r;
      continue;
    }
    const Eigen::Vector3d column = theta.cross((Eigen::Matrix3d::Identity() - r) * e);
    d[k] = (theta[k] * Skew(theta) + Skew(column)) * r / squared;
  }
  return d;
}

// sum_k over a^T (dR_k)^T b: d (R^T b) . a / d theta.
Eigen::Vector3d TurnedBackGradient(const std::array<Eigen::Matrix3d, 3>& dR,
                                   const Eigen::Vector3d& b, const Eigen::Vector3d& a) {
  Eigen::Vector3d out;
  for (int k = 0; k < 3; ++k) out[k] = a.dot(dR[k].transpose() * b);
  return out;
}

}  // namespace

RestFrame::RestFrame(const InitialPose& pose, const Eigen::Vector3d& centre_m,
                     const Eigen::Matrix3d& mesh_from_grid)
    : identity_(pose.IsIdentity() && mesh_from_grid == Eigen::Matrix3d::Identity()),
      centre_(centre_m) {
  const Eigen::Isometry3d world_from_mesh = pose.WorldFromRest(centre_m);
  dR_ = RotationDerivatives(pose.rotation, world_from_mesh.linear());
  for (Eigen::Matrix3d& d : dR_) d = d * mesh_from_grid;
  X_WS_.linear() = world_from_mesh.linear() * mesh_from_grid;
  X_WS_.translation() = centre_m + pose.translation - X_WS_.linear() * centre_m;
}

PhysicalParameters RestFrame::ToRest(const PhysicalParameters& world) const {
  PhysicalParameters rest = world;
  rest.initial_pose = InitialPose{};
  if (identity_) return rest;
  const Eigen::Matrix3d rt = X_WS_.linear().transpose();
  rest.gravity = rt * world.gravity;
  rest.initial_velocity = rt * world.initial_velocity;
  rest.initial_angular_velocity = rt * world.initial_angular_velocity;
  if (world.ground) {
    // n_W . X_W = d_W  <=>  (R^T n_W) . X_S = d_W - n_W . (X_WS's translation).
    rest.ground->normal = rt * world.ground->normal;
    rest.ground->offset = world.ground->offset - world.ground->normal.dot(X_WS_.translation());
  }
  return rest;
}

void RestFrame::ChainToWorld(const PhysicalParameters& world, ParameterGradient* g) const {
  const Eigen::Matrix3d& r = X_WS_.linear();
  Eigen::Vector3d& rotation = g->initial_pose_rotation;
  rotation += TurnedBackGradient(dR_, world.gravity, g->gravity);
  rotation += TurnedBackGradient(dR_, world.initial_velocity, g->initial_velocity);
  rotation += TurnedBackGradient(dR_, world.initial_angular_velocity, g->initial_angular_velocity);
  g->gravity = r * g->gravity;
  g->initial_velocity = r * g->initial_velocity;
  g->initial_angular_velocity = r * g->initial_angular_velocity;
  if (!world.ground) return;
  // d_S = d_W - n_W . b with b = c + t - R c: d b / d theta_k = -dR_k c, d b / d t = I.
  const Eigen::Vector3d& n = world.ground->normal;
  const double offset_gradient = g->ground_offset;
  rotation += TurnedBackGradient(dR_, n, g->ground_normal);
  for (int k = 0; k < 3; ++k) rotation[k] += offset_gradient * n.dot(dR_[k] * centre_);
  g->initial_pose_translation -= offset_gradient * n;
  g->ground_normal = r * g->ground_normal - offset_gradient * X_WS_.translation();
}

void RestFrame::DisplacementToWorld(const std::vector<Eigen::Vector3d>& rest_positions,
                                    const Eigen::VectorXd& u_rest, Eigen::VectorXd* u_world) const {
  u_world->resize(u_rest.size());
  for (size_t i = 0; i < rest_positions.size(); ++i) {
    const Eigen::Vector3d& x = rest_positions[i];
    u_world->segment<3>(3 * i) = X_WS_ * (x + u_rest.segment<3>(3 * i)) - x;
  }
}

void RestFrame::DisplacementGradientToRest(const std::vector<Eigen::Vector3d>& rest_positions,
                                           const Eigen::VectorXd& u_rest,
                                           const Eigen::VectorXd& gradient_world,
                                           Eigen::VectorXd* gradient_rest,
                                           ParameterGradient* gradient) const {
  const Eigen::Matrix3d rt = X_WS_.linear().transpose();
  gradient_rest->resize(gradient_world.size());
  // d L / d theta_k = sum_i g_i . dR_k (x_i - c) = <dR_k, sum_i g_i (x_i - c)^T>.
  Eigen::Matrix3d moment = Eigen::Matrix3d::Zero();
  Eigen::Vector3d force = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < rest_positions.size(); ++i) {
    const Eigen::Vector3d g = gradient_world.segment<3>(3 * i);
    gradient_rest->segment<3>(3 * i) = rt * g;
    force += g;
    moment.noalias() += g * (rest_positions[i] + u_rest.segment<3>(3 * i) - centre_).transpose();
  }
  gradient->initial_pose_translation += force;
  for (int k = 0; k < 3; ++k)
    gradient->initial_pose_rotation[k] += dR_[k].cwiseProduct(moment).sum();
}

}  // namespace softid::fem
