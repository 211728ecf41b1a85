#include "core/cost/sparse_surface_cost.h"

#include <fmt/format.h>

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "core/common/check.h"
#include "core/common/json_fields.h"
#include "core/cost/trilinear_inversion.h"
#include "core/cost/tukey_loss.h"
#include "core/geometry/regular_grid.h"

namespace softid::cost {
namespace {

// Bounding boxes are inflated by this fraction of h so that points on a cell face, which Newton
// accepts up to kLocalTolerance, are never lost to round-off in the box test.
constexpr double kBoxMargin = 1e-6;
// Local coordinates may leave [0,1] by this much and still count as inside (shared faces).
constexpr double kLocalTolerance = 1e-9;
// A candidate overlapping more bins than this (a wildly stretched cell) is checked for every point
// instead, so one exploded cell cannot blow up the bin lists.
constexpr int kMaxBinsPerCandidate = 64;

const SurfaceCostOptions& ValidOrThrow(const SurfaceCostOptions& options) {
  const Status status = options.Validate();
  SOFTID_THROW_UNLESS(status.ok(), status.message());
  return options;
}

bool SameGrid(const geometry::RegularGrid& a, const geometry::RegularGrid& b) {
  return a.origin == b.origin && a.cell_size == b.cell_size && a.num_cells == b.num_cells;
}

}  // namespace

Status SurfaceCostOptions::Validate() const {
  if (band_cells < 1)
    return json::Invalid("SurfaceCostOptions.band_cells", band_cells, "must be >= 1");
  if (!(truncation_cells > 0.0) || !std::isfinite(truncation_cells)) {
    return json::Invalid("SurfaceCostOptions.truncation_cells", truncation_cells,
                         "must be positive and finite");
  }
  return surface_fit.Validate();
}

const char* ToString(RestSdf mode) {
  switch (mode) {
    case RestSdf::kSampled: return "sampled";
    case RestSdf::kSurfaceFitted: return "surface_fitted";
    case RestSdf::kExact: return "exact";
  }
  return "?";
}

SparseSurfaceCost::SparseSurfaceCost(const fem::HexMesh& mesh,
                                     const geometry::SignedDistanceField& sdf,
                                     const SurfaceCostOptions& options)
    : options_(ValidOrThrow(options)),
      grid_(mesh.grid),
      phi_max_(options.truncation_cells * mesh.grid.cell_size),
      extension_(mesh, options.band_cells, options.extension_mode),
      rest_sdf_(sdf) {
  SOFTID_THROW_UNLESS(
      SameGrid(mesh.grid, sdf.grid) && static_cast<int>(sdf.phi.size()) == sdf.grid.NumNodes(),
      "sdf: its grid differs from mesh.grid");
  BuildCandidates();
}

SparseSurfaceCost::SparseSurfaceCost(const fem::HexMesh& mesh,
                                     const geometry::SignedDistanceField& sdf,
                                     const geometry::TriangleMesh& rest_surface,
                                     const SurfaceCostOptions& options)
    : options_(ValidOrThrow(options)),
      grid_(mesh.grid),
      phi_max_(options.truncation_cells * mesh.grid.cell_size),
      extension_(mesh, options.band_cells, options.extension_mode) {
  SOFTID_THROW_UNLESS(
      SameGrid(mesh.grid, sdf.grid) && static_cast<int>(sdf.phi.size()) == sdf.grid.NumNodes(),
      "sdf: its grid differs from mesh.grid");
  rest_sdf_ = options_.rest_sdf == RestSdf::kSampled
                  ? sdf
                  : FitSdfToSurface(sdf, rest_surface, options_.surface_fit, &surface_fit_summary_);
  if (options_.rest_sdf == RestSdf::kExact) {
    Result<geometry::MeshDistance> distance = geometry::MeshDistance::Create(rest_surface);
    SOFTID_THROW_UNLESS(distance.ok(), "rest_surface: " + distance.status().message());
    exact_distance_ = std::make_shared<const geometry::MeshDistance>(std::move(*distance));
    face_normals_.reserve(rest_surface.triangles.size());
    for (const Eigen::Vector3i& t : rest_surface.triangles) {
      const Eigen::Vector3d n =
          (rest_surface.vertices[t[1]] - rest_surface.vertices[t[0]])
              .cross(rest_surface.vertices[t[2]] - rest_surface.vertices[t[0]]);
      face_normals_.push_back(n.norm() > 0.0 ? Eigen::Vector3d(n.normalized())
                                             : Eigen::Vector3d::Zero());
    }
  }
  BuildCandidates();
}

void SparseSurfaceCost::BuildCandidates() {
  const geometry::SignedDistanceField& sdf = rest_sdf_;
  const int num_domain = extension_.num_domain_nodes();

  std::vector<int> cell_to_candidate(grid_.NumCells(), -1);
  for (int cell = 0; cell < grid_.NumCells(); ++cell) {
    const std::array<int, 8> nodes = grid_.CellNodes(cell);
    Candidate candidate;
    candidate.cell = cell;
    bool inside = true;
    for (int c = 0; c < 8 && inside; ++c) {
      candidate.nodes[c] = extension_.domain_node(nodes[c]);
      candidate.phi[c] = sdf.phi[nodes[c]];
      inside = candidate.nodes[c] >= 0;
    }
    if (!inside) continue;
    cell_to_candidate[cell] = static_cast<int>(candidates_.size());
    candidates_.push_back(candidate);
  }

  // The candidate set's outer faces: where points leave the band. Along the grid boundary (a band
  // clipped by the grid), the cost must already be truncated there, or it would jump.
  band_edge_distance_ = std::numeric_limits<double>::infinity();
  double clipped_edge_distance = std::numeric_limits<double>::infinity();
  for (const Candidate& candidate : candidates_) {
    const Eigen::Vector3i coords = grid_.CellCoords(candidate.cell);
    for (int axis = 0; axis < 3; ++axis) {
      for (int side = 0; side < 2; ++side) {
        Eigen::Vector3i next = coords;
        next[axis] += side == 0 ? -1 : 1;
        const bool off_grid = next[axis] < 0 || next[axis] >= grid_.num_cells[axis];
        if (!off_grid && cell_to_candidate[grid_.CellIndex(next.x(), next.y(), next.z())] >= 0) {
          continue;
        }
        for (int c = 0; c < 8; ++c) {
          if (((c >> axis) & 1) != side) continue;
          const double distance = std::abs(candidate.phi[c]);
          band_edge_distance_ = std::min(band_edge_distance_, distance);
          if (off_grid) clipped_edge_distance = std::min(clipped_edge_distance, distance);
        }
      }
    }
  }
  // Relative slack: an SDF node exactly phi_max away must not fail by round-off.
  SOFTID_THROW_UNLESS(
      clipped_edge_distance >= phi_max_ * (1.0 - 1e-9),
      fmt::format("SurfaceCostOptions.band_cells = {}: the band is cut off by the grid boundary "
                  "where the rest signed distance is only {:.3g} h, below truncation_cells = {:g} "
                  "(the cost would jump there); add grid padding or lower truncation_cells",
                  options_.band_cells, clipped_edge_distance / grid_.cell_size,
                  options_.truncation_cells));

  positions_.resize(num_domain);
  boxes_.resize(candidates_.size());
  bin_ranges_.resize(candidates_.size());
  grad_domain_.resize(3 * num_domain);
}

void SparseSurfaceCost::BuildBins() {
  const double margin = kBoxMargin * grid_.cell_size;
  LayOutBins(margin);
  CountCandidatesPerBin(margin);
  FillBins();
}

void SparseSurfaceCost::LayOutBins(double margin) {
  const double h = grid_.cell_size;
  Eigen::AlignedBox3d bounds;
  for (const Eigen::Vector3d& x : positions_) bounds.extend(x);
  bin_origin_ = bounds.min() - Eigen::Vector3d::Constant(margin);
  const Eigen::Vector3d extent = bounds.sizes() + Eigen::Vector3d::Constant(2 * margin);
  // Bins of one cell keep ~1-3 candidates per point; a body torn far apart by a bad u would need
  // very many, so the bin size grows to cap their number at a few per candidate.
  const double max_bins = 4.0 * static_cast<double>(candidates_.size()) + 64.0;
  bin_size_ = h;
  for (;;) {
    const Eigen::Vector3d dims = (extent / bin_size_).array().floor() + 1.0;
    if (dims.prod() <= max_bins) {
      bin_dims_ = dims.cast<int>();
      break;
    }
    bin_size_ *= std::max(1.1, std::cbrt(dims.prod() / max_bins));
  }
}

void SparseSurfaceCost::CountCandidatesPerBin(double margin) {
  const int num_bins = bin_dims_.prod();
  bin_offsets_.assign(num_bins + 1, 0);
  overflow_.clear();
  const auto bin_coord = [&](double value, int axis) {
    const int b = static_cast<int>(std::floor((value - bin_origin_[axis]) / bin_size_));
    return std::clamp(b, 0, bin_dims_[axis] - 1);
  };
  for (size_t i = 0; i < candidates_.size(); ++i) {
    Eigen::AlignedBox3d& box = boxes_[i];
    box.setEmpty();
    for (int c = 0; c < 8; ++c) box.extend(positions_[candidates_[i].nodes[c]]);
    box.min().array() -= margin;
    box.max().array() += margin;
    std::array<int, 6>& range = bin_ranges_[i];
    int count = 1;
    for (int a = 0; a < 3; ++a) {
      range[a] = bin_coord(box.min()[a], a);
      range[3 + a] = bin_coord(box.max()[a], a);
      count *= range[3 + a] - range[a] + 1;
    }
    if (count > kMaxBinsPerCandidate) {
      range[0] = -1;
      overflow_.push_back(static_cast<int>(i));
      continue;
    }
    for (int z = range[2]; z <= range[5]; ++z) {
      for (int y = range[1]; y <= range[4]; ++y) {
        for (int x = range[0]; x <= range[3]; ++x) {
          ++bin_offsets_[x + bin_dims_.x() * (y + bin_dims_.y() * z)];
        }
      }
    }
  }
}

void SparseSurfaceCost::FillBins() {
  const int num_bins = bin_dims_.prod();
  // Counts become end offsets (the last entry stays at the total) ...
  for (int b = 1; b <= num_bins; ++b) bin_offsets_[b] += bin_offsets_[b - 1];
  bin_items_.resize(bin_offsets_[num_bins]);
  // ... and filling from the back, candidates in descending order, leaves each bin ascending and
  // bin_offsets_[b] at the bin's start.
  for (int i = static_cast<int>(candidates_.size()) - 1; i >= 0; --i) {
    const std::array<int, 6>& range = bin_ranges_[i];
    if (range[0] < 0) continue;
    for (int z = range[2]; z <= range[5]; ++z) {
      for (int y = range[1]; y <= range[4]; ++y) {
        for (int x = range[0]; x <= range[3]; ++x) {
          bin_items_[--bin_offsets_[x + bin_dims_.x() * (y + bin_dims_.y() * z)]] = i;
        }
      }
    }
  }
}

double SparseSurfaceCost::ExactDistance(const Eigen::Vector3d& rest, double interpolated,
                                        Eigen::Vector3d* gradient) const {
  const geometry::ClosestPoint closest = exact_distance_->Closest(rest);
  const Eigen::Vector3d& face = face_normals_[closest.triangle];
  const Eigen::Vector3d offset = rest - closest.point;
  // The side of the closest triangle decides the sign near the surface; that test can fail only
  // next to a crease or a vertex (where several triangles are closest), so away from the surface
  // (beyond the interpolant's error, a few % of h) the interpolant's sign is used instead.
  const double side = offset.dot(face);
  const bool outside =
      std::abs(interpolated) > 0.25 * grid_.cell_size ? interpolated > 0.0 : side >= 0.0;
  const double sign = outside ? 1.0 : -1.0;
  // grad phi = sign * (X - closest) / |X - closest|: the unit vector to X; on the surface itself
  // (distance ~ 0) that is the face normal.
  if (closest.distance > 1e-9 * grid_.cell_size)
    *gradient = sign * offset / closest.distance;
  else
    *gradient = face;
  return sign * closest.distance;
}

void SparseSurfaceCost::TryCandidate(int i, const Eigen::Vector3d& x, Match* best) const {
  if (!boxes_[i].contains(x)) return;
  const Candidate& candidate = candidates_[i];
  std::array<Eigen::Vector3d, 8> corners;
  for (int c = 0; c < 8; ++c) corners[c] = positions_[candidate.nodes[c]];
  const TrilinearInversion inversion = InvertTrilinearMap(corners, x);
  if (!inversion.converged) return;
  if ((inversion.xi.array() < -kLocalTolerance).any() ||
      (inversion.xi.array() > 1.0 + kLocalTolerance).any()) {
    return;
  }
  const std::array<double, 8> weights = geometry::TrilinearWeights(inversion.xi);
  double phi = 0.0;
  for (int c = 0; c < 8; ++c) phi += weights[c] * candidate.phi[c];
  // The deformed object is the union of its cells' images, so its signed distance at x is the
  // smallest (most inside) rest signed distance among x's preimages. Taking the smallest |phi|
  // instead rewarded folds: a crumpled surface offers every noisy point a sheet close by.
  if (best->candidate >= 0 &&
      (phi > best->phi ||
       (phi == best->phi && candidate.cell > candidates_[best->candidate].cell))) {
    return;
  }
  best->candidate = i;
  best->rho = TukeyLoss(phi, phi_max_);
  best->phi = phi;
  best->xi = inversion.xi;
  best->jacobian = inversion.jacobian;
}

void SparseSurfaceCost::DeformDomain(const Eigen::VectorXd& u) {
  extension_.Extend(u, &u_domain_);
  for (size_t d = 0; d < positions_.size(); ++d) {
    positions_[d] = extension_.rest_position(static_cast<int>(d)) + u_domain_.segment<3>(3 * d);
  }
  BuildBins();
}

void SparseSurfaceCost::FindMatch(const Eigen::Vector3d& x, Match* best) const {
  if (x.allFinite()) {
    const Eigen::Vector3d t = (x - bin_origin_) / bin_size_;
    if ((t.array() >= 0.0).all() && (t.array() < bin_dims_.cast<double>().array()).all()) {
      const int bin =
          static_cast<int>(t.x()) +
          bin_dims_.x() * (static_cast<int>(t.y()) + bin_dims_.y() * static_cast<int>(t.z()));
      for (int k = bin_offsets_[bin]; k < bin_offsets_[bin + 1]; ++k) {
        TryCandidate(bin_items_[k], x, best);
      }
    }
    for (int i : overflow_) TryCandidate(i, x, best);
  }
}

Eigen::Vector3d SparseSurfaceCost::MatchPhiGradient(const Candidate& candidate, Match* best) const {
  // kExact: the chosen match's phi is the exact distance at its material point X = corner 0 +
  // h xi (the rest cell is an axis-aligned cube), d phi / d xi = h grad_X phi.
  Eigen::Vector3d grad_xi = Eigen::Vector3d::Zero();
  if (exact_distance_ != nullptr) {
    const Eigen::Vector3d rest =
        extension_.rest_position(candidate.nodes[0]) + grid_.cell_size * best->xi;
    Eigen::Vector3d grad_rest;
    best->phi = ExactDistance(rest, best->phi, &grad_rest);
    best->rho = TukeyLoss(best->phi, phi_max_);
    grad_xi = grid_.cell_size * grad_rest;
  } else {
    const std::array<Eigen::Vector3d, 8> shape_gradients = geometry::TrilinearGradients(best->xi);
    for (int c = 0; c < 8; ++c) grad_xi += candidate.phi[c] * shape_gradients[c];
  }
  return grad_xi;
}

void SparseSurfaceCost::RecordMatch(const Candidate& candidate, const Match& best,
                                    PointMatch* match) const {
  match->matched = true;
  match->phi = best.phi;
  match->cost = best.rho;
  match->cell = candidate.cell;
  const std::array<double, 8> weights = geometry::TrilinearWeights(best.xi);
  match->rest_position.setZero();
  for (int c = 0; c < 8; ++c) {
    match->rest_position += weights[c] * extension_.rest_position(candidate.nodes[c]);
  }
}

void SparseSurfaceCost::AccumulateGradient(const Candidate& candidate, const Match& best,
                                           const Eigen::Vector3d& grad_xi, double inverse_count) {
  const double drho = TukeyLossDerivative(best.phi, phi_max_) * inverse_count;
  if (drho == 0.0) return;
  // d phi / d x_c = -N_c(xi) J^-T grad_xi(phi): x = sum_c N_c(xi) x_c is data, so moving a
  // corner moves xi by -J^-1 N_c dx_c.
  const std::array<double, 8> weights = geometry::TrilinearWeights(best.xi);
  const Eigen::Vector3d grad_x = best.jacobian.transpose().inverse() * grad_xi;
  for (int c = 0; c < 8; ++c) {
    grad_domain_.segment<3>(3 * candidate.nodes[c]) -= (drho * weights[c]) * grad_x;
  }
}

double SparseSurfaceCost::Evaluate(const Eigen::VectorXd& u,
                                   std::span<const Eigen::Vector3d> points,
                                   Eigen::VectorXd* gradient, std::vector<PointMatch>* matches) {
  SOFTID_THROW_UNLESS(u.size() == 3 * static_cast<Eigen::Index>(extension_.num_fe_nodes()),
                      "u: size " + std::to_string(u.size()) + ", expected 3 * " +
                          std::to_string(extension_.num_fe_nodes()) + " FE nodes");
  SOFTID_THROW_UNLESS(u.allFinite(), "u: has non-finite entries");
  const size_t num_points = points.size();
  if (matches != nullptr) matches->assign(num_points, PointMatch{});
  if (gradient != nullptr) gradient->setZero(u.size());
  if (num_points == 0) return 0.0;

  DeformDomain(u);
  if (gradient != nullptr) grad_domain_.setZero();

  const double inverse_count = 1.0 / static_cast<double>(num_points);
  const double truncated = TukeyLoss(phi_max_, phi_max_);
  double sum = 0.0;
  for (size_t p = 0; p < num_points; ++p) {
    Match best;
    FindMatch(points[p], &best);
    if (best.candidate < 0) {
      sum += truncated;
      if (matches != nullptr) (*matches)[p].cost = truncated;
      continue;
    }
    const Candidate& candidate = candidates_[best.candidate];
    const Eigen::Vector3d grad_xi = MatchPhiGradient(candidate, &best);
    sum += best.rho;
    if (matches != nullptr) RecordMatch(candidate, best, &(*matches)[p]);
    if (gradient != nullptr) AccumulateGradient(candidate, best, grad_xi, inverse_count);
  }
  if (gradient != nullptr) extension_.AccumulateAdjoint(grad_domain_, gradient);
  return sum * inverse_count;
}

}  // namespace softid::cost
