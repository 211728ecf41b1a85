#include "core/fem/step_tangent_operator.h"

#include <algorithm>

#include "core/common/check.h"
#include "core/fem/thread_team.h"

namespace softid::fem {

void StepTangentOperator::Bind(const Views& v) {
  SOFTID_THROW_UNLESS(v.element_nodes && v.stiffness_matrices && v.stiffness_index && v.rotations &&
                          v.mass && v.fixed && v.points && v.point_jacobians && v.point_active &&
                          v.element_chunks && v.shared_elements && v.point_chunks &&
                          v.shared_points,
                      "StepTangentOperator: a view is missing");
  const size_t elements = v.element_nodes->size();
  SOFTID_THROW_UNLESS(v.stiffness_index->size() == elements && v.rotations->size() == elements,
                      "StepTangentOperator: per-element views disagree in size");
  SOFTID_THROW_UNLESS(static_cast<Eigen::Index>(v.fixed->size()) == v.mass->size(),
                      "StepTangentOperator: fixed and mass disagree in size");
  const size_t points = v.points->element.size();
  SOFTID_THROW_UNLESS(v.point_jacobians->size() >= points && v.point_active->size() >= points,
                      "StepTangentOperator: per-point views are shorter than the points");
  const int members = v.team != nullptr ? v.team->size() : 1;
  SOFTID_THROW_UNLESS(static_cast<int>(v.element_chunks->size()) == members &&
                          static_cast<int>(v.point_chunks->size()) == members,
                      "StepTangentOperator: one element and point chunk per team member needed");
  views_ = v;
  has_fixed_ = std::any_of(v.fixed->begin(), v.fixed->end(), [](char f) { return f != 0; });
}

void StepTangentOperator::ApplyElements(const std::vector<int>& elements, const double* x,
                                        double* y) const {
  const auto& element_nodes = *views_.element_nodes;
  const auto& rotations = *views_.rotations;
  const auto& stiffness = *views_.stiffness_matrices;
  const auto& stiffness_index = *views_.stiffness_index;
  const double c = views_.stiffness_coefficient;
  for (int e : elements) {
    const auto& nodes = element_nodes[e];
    const Eigen::Matrix3d rt = rotations[e].transpose();
    Vector24d local;
    for (int k = 0; k < 8; ++k)
      local.segment<3>(3 * k).noalias() = rt * Eigen::Map<const Eigen::Vector3d>(x + 3 * nodes[k]);
    const Vector24d force = stiffness[stiffness_index[e]] * local;
    const Eigen::Matrix3d r = c * rotations[e];
    for (int k = 0; k < 8; ++k)
      Eigen::Map<Eigen::Vector3d>(y + 3 * nodes[k]).noalias() += r * force.segment<3>(3 * k);
  }
}

void StepTangentOperator::ApplyPoints(const std::vector<int>& points, const double* x,
                                      double* y) const {
  const auto& active = *views_.point_active;
  const auto& jacobians = *views_.point_jacobians;
  const SurfaceEmbedding& embedding = *views_.points;
  const auto& element_nodes = *views_.element_nodes;
  for (int p : points) {
    if (!active[p]) continue;
    const auto& nodes = element_nodes[embedding.element[p]];
    const auto& w = embedding.weights[p];
    Eigen::Vector3d xp = Eigen::Vector3d::Zero();
    for (int k = 0; k < 8; ++k) xp += w[k] * Eigen::Map<const Eigen::Vector3d>(x + 3 * nodes[k]);
    const Eigen::Vector3d force = jacobians[p] * xp;
    for (int k = 0; k < 8; ++k) Eigen::Map<Eigen::Vector3d>(y + 3 * nodes[k]) += w[k] * force;
  }
}

void StepTangentOperator::Apply(const Eigen::Ref<const Eigen::VectorXd>& x, Eigen::VectorXd* y) {
  const Eigen::Index n = size();
  SOFTID_DEMAND(n > 0 && x.size() == n);
  const std::vector<char>& fixed = *views_.fixed;
  const Eigen::VectorXd& mass = *views_.mass;
  const double* in = x.data();
  if (has_fixed_) {
    // Clamped nodes' columns are eliminated: their entries of x do not act on the others.
    masked_ = x;
    for (size_t i = 0; i < fixed.size(); ++i)
      if (fixed[i]) masked_.segment<3>(3 * i).setZero();
    in = masked_.data();
  }
  y->resize(n);
  for (Eigen::Index i = 0; i < mass.size(); ++i) {
    y->segment<3>(3 * i) =
        (views_.mass_coefficient * mass[i]) * Eigen::Map<const Eigen::Vector3d>(in + 3 * i);
  }
  double* out = y->data();
  const auto run = [&](int member) {
    ApplyElements((*views_.element_chunks)[member], in, out);
    ApplyPoints((*views_.point_chunks)[member], in, out);
  };
  if (views_.team != nullptr)
    views_.team->Run(run);
  else
    run(0);
  ApplyElements(*views_.shared_elements, in, out);
  ApplyPoints(*views_.shared_points, in, out);
  for (size_t i = 0; i < fixed.size(); ++i)
    if (fixed[i]) y->segment<3>(3 * i) = x.segment<3>(3 * i);
}

StepTangentOperator::RowMatrix StepTangentOperator::NodeRows(const std::vector<int>& nodes) {
  const std::vector<char>& fixed = *views_.fixed;
  const auto& element_nodes = *views_.element_nodes;
  local_index_.assign(fixed.size(), -1);
  for (size_t k = 0; k < nodes.size(); ++k)
    if (!fixed[nodes[k]]) local_index_[nodes[k]] = static_cast<int>(k);
  // The elements with a corner among the nodes, each with a 24x24 buffer for its points' blocks.
  element_slot_.assign(element_nodes.size(), -1);
  touched_elements_.clear();
  for (size_t e = 0; e < element_nodes.size(); ++e) {
    const auto& corners = element_nodes[e];
    if (std::any_of(corners.begin(), corners.end(), [&](int i) { return local_index_[i] >= 0; })) {
      element_slot_[e] = static_cast<int>(touched_elements_.size());
      touched_elements_.push_back(static_cast<int>(e));
    }
  }
  point_blocks_.resize(touched_elements_.size());
  for (Matrix24d& block : point_blocks_) block.setZero();
  const auto& active = *views_.point_active;
  const auto& jacobians = *views_.point_jacobians;
  const SurfaceEmbedding& embedding = *views_.points;
  for (size_t p = 0; p < embedding.element.size(); ++p) {
    const int slot = element_slot_[embedding.element[p]];
    if (!active[p] || slot < 0) continue;
    const auto& w = embedding.weights[p];
    for (int a = 0; a < 8; ++a)
      for (int b = 0; b < 8; ++b)
        point_blocks_[slot].block<3, 3>(3 * a, 3 * b) += (w[a] * w[b]) * jacobians[p];
  }
  // Each element's blocks from one of the nodes to any free corner: c R K_ab R^T plus its points'
  // blocks (a clamped corner's column is eliminated).
  const auto& rotations = *views_.rotations;
  const auto& stiffness = *views_.stiffness_matrices;
  const auto& stiffness_index = *views_.stiffness_index;
  entries_.clear();
  for (size_t slot = 0; slot < touched_elements_.size(); ++slot) {
    const int e = touched_elements_[slot];
    const auto& corners = element_nodes[e];
    const Eigen::Matrix3d r = rotations[e];
    const Eigen::Matrix3d cr = views_.stiffness_coefficient * r;
    const Matrix24d& k = stiffness[stiffness_index[e]];
    for (int a = 0; a < 8; ++a) {
      const int row = local_index_[corners[a]];
      if (row < 0) continue;
      for (int b = 0; b < 8; ++b) {
        const int column = corners[b];
        if (fixed[column]) continue;
        const Eigen::Matrix3d block = cr * k.block<3, 3>(3 * a, 3 * b) * r.transpose() +
                                      point_blocks_[slot].block<3, 3>(3 * a, 3 * b);
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j)
            entries_.emplace_back(3 * row + i, 3 * column + j, block(i, j));
      }
    }
  }
  const Eigen::VectorXd& mass = *views_.mass;
  for (size_t k = 0; k < nodes.size(); ++k) {
    const int node = nodes[k];
    const double diagonal = fixed[node] ? 1.0 : views_.mass_coefficient * mass[node];
    for (int i = 0; i < 3; ++i) entries_.emplace_back(3 * k + i, 3 * node + i, diagonal);
  }
  RowMatrix rows(3 * static_cast<Eigen::Index>(nodes.size()), size());
  rows.setFromTriplets(entries_.begin(), entries_.end());
  return rows;
}

}  // namespace softid::fem
