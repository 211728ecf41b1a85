#include "core/capture/camera.h"

#include <fmt/format.h>

#include <cmath>

#include "core/common/check.h"

namespace softid::capture {

Eigen::Vector3d PinholeCamera::RayDirection_C(double u, double v) const {
  return Eigen::Vector3d((u - cx) / fx, (v - cy) / fy, 1.0);
}

std::optional<Eigen::Vector2d> PinholeCamera::Project(const Eigen::Vector3d& p_W) const {
  const Eigen::Vector3d p_C = X_WC.inverse() * p_W;
  if (!(p_C.z() > 0.0)) return std::nullopt;
  return Eigen::Vector2d(fx * p_C.x() / p_C.z() + cx, fy * p_C.y() / p_C.z() + cy);
}

double PinholeCamera::Depth(const Eigen::Vector3d& p_W) const {
  return (X_WC.inverse() * p_W).z();
}

Eigen::Vector3d PinholeCamera::Unproject(double u, double v, double depth_z) const {
  return X_WC * (depth_z * RayDirection_C(u, v));
}

namespace {

Status CheckPositiveInt(std::string_view prefix, const char* field, int value) {
  if (value > 0) return Status::Ok();
  return Status::InvalidArgument(
      fmt::format("{}{} = {}: must be a positive integer", prefix, field, value));
}

Status CheckPositiveFinite(std::string_view prefix, const char* field, double value) {
  if (std::isfinite(value) && value > 0.0) return Status::Ok();
  return Status::InvalidArgument(
      fmt::format("{}{} = {}: must be positive and finite", prefix, field, value));
}

// Principal point coordinate `value` must lie inside [-0.5, size - 0.5].
Status CheckInsideImage(std::string_view prefix, const char* field, double value, int size,
                        const char* size_field) {
  if (std::isfinite(value) && value >= -0.5 && value <= size - 0.5) return Status::Ok();
  return Status::InvalidArgument(
      fmt::format("{}{} = {}: outside the image (must be in [-0.5, {} - 0.5] for {} = {})", prefix,
                  field, value, size_field, size_field, size));
}

}  // namespace

Status ValidateRigidTransform(const Eigen::Matrix4d& X, std::string_view field) {
  if (!X.allFinite()) {
    return Status::InvalidArgument(fmt::format("{}: entries must be finite", field));
  }
  const Eigen::RowVector4d last_row = X.row(3);
  if ((last_row - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > kRigidTolerance) {
    return Status::InvalidArgument(
        fmt::format("{}: last row = [{}, {}, {}, {}]: must be [0, 0, 0, 1]", field, last_row(0),
                    last_row(1), last_row(2), last_row(3)));
  }
  const Eigen::Matrix3d R = X.topLeftCorner<3, 3>();
  const double orthonormality_error =
      (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (orthonormality_error > kRigidTolerance) {
    return Status::InvalidArgument(fmt::format(
        "{}: rotation part is not orthonormal (max |R^T R - I| = {:.3g} > {:g}): must be a rigid "
        "transform",
        field, orthonormality_error, kRigidTolerance));
  }
  const double det = R.determinant();
  if (std::abs(det - 1.0) > kRigidTolerance) {
    return Status::InvalidArgument(fmt::format(
        "{}: rotation part has determinant {:.6g}: must be +1 (a reflection is not a rigid "
        "transform)",
        field, det));
  }
  return Status::Ok();
}

Status PinholeCamera::Validate(std::string_view field_prefix) const {
  SOFTID_RETURN_IF_ERROR(CheckPositiveInt(field_prefix, "width", width));
  SOFTID_RETURN_IF_ERROR(CheckPositiveInt(field_prefix, "height", height));
  SOFTID_RETURN_IF_ERROR(CheckPositiveFinite(field_prefix, "fx", fx));
  SOFTID_RETURN_IF_ERROR(CheckPositiveFinite(field_prefix, "fy", fy));
  SOFTID_RETURN_IF_ERROR(CheckInsideImage(field_prefix, "cx", cx, width, "width"));
  SOFTID_RETURN_IF_ERROR(CheckInsideImage(field_prefix, "cy", cy, height, "height"));
  return ValidateRigidTransform(X_WC.matrix(), fmt::format("{}X_WC", field_prefix));
}

Eigen::Isometry3d LookAt(const Eigen::Vector3d& eye_W, const Eigen::Vector3d& target_W,
                         const Eigen::Vector3d& up_W) {
  const Eigen::Vector3d forward = target_W - eye_W;
  SOFTID_THROW_UNLESS(forward.norm() > 0.0, "LookAt: eye_W and target_W coincide");
  const Eigen::Vector3d z_C = forward.normalized();
  const Eigen::Vector3d right = z_C.cross(up_W);
  SOFTID_THROW_UNLESS(right.norm() > 1e-9 * up_W.norm() && up_W.norm() > 0.0,
                      "LookAt: view direction is parallel to up_W");
  const Eigen::Vector3d x_C = right.normalized();
  const Eigen::Vector3d y_C = z_C.cross(x_C);  // image down, i.e. roughly -up_W
  Eigen::Isometry3d X_WC = Eigen::Isometry3d::Identity();
  X_WC.linear().col(0) = x_C;
  X_WC.linear().col(1) = y_C;
  X_WC.linear().col(2) = z_C;
  X_WC.translation() = eye_W;
  return X_WC;
}

}  // namespace softid::capture
