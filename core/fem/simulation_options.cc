#include "core/fem/simulation_options.h"

#include <cmath>
#include <string>

#include "core/common/check.h"
#include "core/common/json_fields.h"
#include "core/geometry/cut_cell_weights.h"

namespace softid::fem {

const char* ToString(GridOrientation orientation) {
  switch (orientation) {
    case GridOrientation::kWorld: return "world";
    case GridOrientation::kBody: return "body";
  }
  return "invalid";  // a value cast from an out-of-range integer
}

Status SimulationOptions::Validate() const {
  using json::Invalid;
  if (cell_size <= 0.0 && cells_along_longest_side < 2) {
    return Invalid("cells_along_longest_side", cells_along_longest_side, "must be at least 2");
  }
  if (!std::isfinite(cell_size) || cell_size < 0.0) {
    return Invalid("cell_size", cell_size, "must be non-negative and finite");
  }
  if (padding_cells < 1) return Invalid("padding_cells", padding_cells, "must be at least 1");
  if (!(min_cell_volume_fraction >= 0.0 && min_cell_volume_fraction < 0.5)) {
    return Invalid("min_cell_volume_fraction", min_cell_volume_fraction, "must lie in [0, 0.5)");
  }
  if (!(ghost_stiffness_fraction >= 0.0 && ghost_stiffness_fraction <= 1.0)) {
    return Invalid("ghost_stiffness_fraction", ghost_stiffness_fraction, "must lie in [0, 1]");
  }
  if (!(min_force_volume_fraction >= 0.0 && min_force_volume_fraction <= 1.0)) {
    return Invalid("min_force_volume_fraction", min_force_volume_fraction, "must lie in [0, 1]");
  }
  if (!geometry::IsCutCellSampling(cut_cell_samples)) {
    return Invalid("cut_cell_samples", cut_cell_samples, "must be 1, 2, 4 or 8");
  }
  if (!(max_force_clamp_cells >= 0.0)) {
    return Invalid("max_force_clamp_cells", max_force_clamp_cells, "must be non-negative");
  }
  if (!(time_step > 0.0) || !std::isfinite(time_step)) {
    return Invalid("time_step", time_step, "must be positive and finite");
  }
  if (!(newmark_gamma >= 0.5 && newmark_gamma <= 1.0)) {
    return Invalid("newmark_gamma", newmark_gamma, "must lie in [0.5, 1]");
  }
  if (!(newmark_beta > 0.0 && newmark_beta <= 0.5)) {
    return Invalid("newmark_beta", newmark_beta, "must lie in (0, 0.5]");
  }
  if (!(generalized_alpha_f >= 0.0 && generalized_alpha_f <= 0.5)) {
    return Invalid("generalized_alpha_f", generalized_alpha_f, "must lie in [0, 0.5]");
  }
  if (!(generalized_alpha_m > -1.0 && generalized_alpha_m <= generalized_alpha_f)) {
    return Invalid("generalized_alpha_m", generalized_alpha_m,
                   "must lie in (-1, generalized_alpha_f]");
  }
  if (max_newton_iterations < 1) {
    return Invalid("max_newton_iterations", max_newton_iterations, "must be at least 1");
  }
  if (!(newton_tolerance > 0.0))
    return Invalid("newton_tolerance", newton_tolerance, "must be positive");
  if (!(max_extent_ratio > 1.0) || !std::isfinite(max_extent_ratio)) {
    return Invalid("max_extent_ratio", max_extent_ratio, "must be greater than 1 and finite");
  }
  if (!(linear_tolerance > 0.0))
    return Invalid("linear_tolerance", linear_tolerance, "must be positive");
  if (max_linear_iterations < 1) {
    return Invalid("max_linear_iterations", max_linear_iterations, "must be at least 1");
  }
  if (!(adjoint_linear_tolerance > 0.0)) {
    return Invalid("adjoint_linear_tolerance", adjoint_linear_tolerance, "must be positive");
  }
  if (!(contact_smoothing >= 0.0) || !std::isfinite(contact_smoothing)) {
    return Invalid("contact_smoothing", contact_smoothing, "must be non-negative and finite");
  }
  if (!(friction_velocity_scale > 0.0)) {
    return Invalid("friction_velocity_scale", friction_velocity_scale, "must be positive");
  }
  if (!(surface_edge_fraction > 0.0)) {
    return Invalid("surface_edge_fraction", surface_edge_fraction, "must be positive");
  }
  if (threads < 0) return Invalid("threads", threads, "must be non-negative");
  return Status::Ok();
}

void SimulationOptions::UseGeneralizedAlpha(double rho_infinity) {
  SOFTID_THROW_UNLESS(rho_infinity >= 0.0 && rho_infinity <= 1.0,
                      "rho_infinity = " + std::to_string(rho_infinity) + " must lie in [0, 1]");
  generalized_alpha_m = (2.0 * rho_infinity - 1.0) / (rho_infinity + 1.0);
  generalized_alpha_f = rho_infinity / (rho_infinity + 1.0);
  newmark_gamma = 0.5 - generalized_alpha_m + generalized_alpha_f;
  const double sum = 1.0 - generalized_alpha_m + generalized_alpha_f;
  newmark_beta = 0.25 * sum * sum;
}

}  // namespace softid::fem
