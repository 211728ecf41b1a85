#include "core/cost/surface_fitted_sdf.h"

#include <fmt/format.h>

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <algorithm>
#include <cmath>
#include <vector>

#include "core/common/check.h"
#include "core/common/json_fields.h"
#include "core/geometry/regular_grid.h"

namespace softid::cost {
namespace {

struct Sample {
  int cell = -1;
  std::array<double, 8> weights;  // trilinear weights of the sample in its cell
  double area_weight = 0.0;       // area / h^2
};

// Centroids of the n^2 similar sub-triangles of (a, b, c), each with a 1 / n^2 share of the area.
template <typename Visit>
void SubTriangleCentroids(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                          const Eigen::Vector3d& c, int n, Visit visit) {
  const Eigen::Vector3d e1 = (b - a) / n, e2 = (c - a) / n;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; i + j < n; ++j) {
      // Upright sub-triangle (i, j), (i+1, j), (i, j+1): centroid at (i + 1/3, j + 1/3).
      visit(a + (i + 1.0 / 3.0) * e1 + (j + 1.0 / 3.0) * e2);
      // Inverted one (i+1, j), (i, j+1), (i+1, j+1), where it exists.
      if (i + j + 2 <= n) visit(a + (i + 2.0 / 3.0) * e1 + (j + 2.0 / 3.0) * e2);
    }
  }
}

// @throws std::invalid_argument for an SDF whose phi does not match its grid, an empty surface or
// a surface vertex outside the grid.
void CheckSurfaceInGrid(const geometry::SignedDistanceField& sdf,
                        const geometry::TriangleMesh& surface) {
  const geometry::RegularGrid& grid = sdf.grid;
  SOFTID_THROW_UNLESS(
      grid.NumCells() > 0 && static_cast<int>(sdf.phi.size()) == grid.NumNodes(),
      fmt::format("sdf: {} values for {} grid nodes", sdf.phi.size(), grid.NumNodes()));
  SOFTID_THROW_UNLESS(!surface.triangles.empty(), "surface: has no triangles");
  const double h = grid.cell_size;
  const Eigen::Vector3d grid_max = grid.origin + h * grid.num_cells.cast<double>();
  for (size_t v = 0; v < surface.vertices.size(); ++v) {
    const Eigen::Vector3d& p = surface.vertices[v];
    SOFTID_THROW_UNLESS(p.allFinite() && (p.array() >= grid.origin.array()).all() &&
                            (p.array() <= grid_max.array()).all(),
                        fmt::format("surface: vertex {} at ({:.6g}, {:.6g}, {:.6g}) m lies outside "
                                    "the SDF grid",
                                    v, p.x(), p.y(), p.z()));
  }
}

// Samples of the surface, grouped by cell through a sort.
std::vector<Sample> SampleSurface(const geometry::RegularGrid& grid,
                                  const geometry::TriangleMesh& surface, int samples_per_cell) {
  const double h = grid.cell_size;
  std::vector<Sample> samples;
  for (const Eigen::Vector3i& t : surface.triangles) {
    const Eigen::Vector3d &a = surface.vertices[t[0]], &b = surface.vertices[t[1]],
                          &c = surface.vertices[t[2]];
    const double longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const int n = std::max(1, static_cast<int>(std::ceil(longest * samples_per_cell / h)));
    const double area = 0.5 * (b - a).cross(c - a).norm();
    if (!(area > 0.0)) continue;
    const double share = area / (static_cast<double>(n) * n * h * h);
    SubTriangleCentroids(a, b, c, n, [&](const Eigen::Vector3d& x) {
      Sample s;
      Eigen::Vector3d xi;
      s.cell = grid.LocateCell(x, &xi);
      s.weights = geometry::TrilinearWeights(xi.cwiseMax(0.0).cwiseMin(1.0));
      s.area_weight = share;
      samples.push_back(s);
    });
  }
  std::sort(samples.begin(), samples.end(),
            [](const Sample& x, const Sample& y) { return x.cell < y.cell; });
  return samples;
}

// Unknowns: every node of a cell holding a sample, numbered in order of first appearance.
struct Unknowns {
  std::vector<int> of_node;  // per grid node: its unknown, or -1
  std::vector<int> nodes;    // per unknown: its grid node
  int size() const { return static_cast<int>(nodes.size()); }
};

Unknowns NumberUnknowns(const geometry::RegularGrid& grid, const std::vector<Sample>& samples) {
  Unknowns unknowns;
  std::vector<int>& unknown = unknowns.of_node;
  std::vector<int>& nodes_of_unknowns = unknowns.nodes;
  unknown.assign(grid.NumNodes(), -1);
  for (const Sample& s : samples) {
    for (int node : grid.CellNodes(s.cell)) {
      if (unknown[node] >= 0) continue;
      unknown[node] = static_cast<int>(nodes_of_unknowns.size());
      nodes_of_unknowns.push_back(node);
    }
  }
  return unknowns;
}

// Normal equations (S + lambda L + mu I) delta = -S d, S = sum_s w_s N_s N_s^T. S is summed per
// cell as a dense 8x8 block, so there are 64 triplets per cell rather than per sample.
// Adds S to *triplets and -S d to *rhs.
void AddSurfaceTerm(const geometry::SignedDistanceField& sdf, const std::vector<Sample>& samples,
                    const std::vector<int>& unknown, std::vector<Eigen::Triplet<double>>* triplets,
                    Eigen::VectorXd* rhs) {
  const geometry::RegularGrid& grid = sdf.grid;
  for (size_t begin = 0; begin < samples.size();) {
    const int cell = samples[begin].cell;
    size_t end = begin;
    Eigen::Matrix<double, 8, 8> block = Eigen::Matrix<double, 8, 8>::Zero();
    while (end < samples.size() && samples[end].cell == cell) {
      const Eigen::Map<const Eigen::Matrix<double, 8, 1>> n(samples[end].weights.data());
      block.noalias() += samples[end].area_weight * n * n.transpose();
      ++end;
    }
    const std::array<int, 8> nodes = grid.CellNodes(cell);
    Eigen::Matrix<double, 8, 1> d;
    for (int c = 0; c < 8; ++c) d[c] = sdf.phi[nodes[c]];
    const Eigen::Matrix<double, 8, 1> sd = block * d;
    for (int r = 0; r < 8; ++r) {
      (*rhs)[unknown[nodes[r]]] -= sd[r];
      for (int c = 0; c < 8; ++c)
        triplets->emplace_back(unknown[nodes[r]], unknown[nodes[c]], block(r, c));
    }
    begin = end;
  }
}

// Adds lambda L + mu I to *triplets (lambda: smoothness_weight, mu: value_weight).
void AddSmoothnessTerm(const geometry::RegularGrid& grid, const Unknowns& unknowns,
                       const SurfaceFitOptions& options,
                       std::vector<Eigen::Triplet<double>>* triplets) {
  const Eigen::Vector3i dims = grid.NumNodesPerAxis();
  const double lambda = options.smoothness_weight;
  for (int i = 0; i < unknowns.size(); ++i) {
    const Eigen::Vector3i coords = grid.NodeCoords(unknowns.nodes[i]);
    double diagonal = options.value_weight;
    for (int axis = 0; axis < 3; ++axis) {
      for (int side : {-1, 1}) {
        Eigen::Vector3i next = coords;
        next[axis] += side;
        if (next[axis] < 0 || next[axis] >= dims[axis]) continue;
        // Edge (i, j): lambda (delta_i - delta_j)^2, with delta_j = 0 at a fixed node. Each edge
        // between two unknowns is visited from both ends, each adding its own row.
        diagonal += lambda;
        const int j = unknowns.of_node[grid.NodeIndex(next.x(), next.y(), next.z())];
        if (j >= 0) triplets->emplace_back(i, j, -lambda);
      }
    }
    triplets->emplace_back(i, i, diagonal);
  }
}

// The corrections delta of the system given as triplets.
Eigen::VectorXd SolveCorrections(int num_unknowns,
                                 const std::vector<Eigen::Triplet<double>>& triplets,
                                 const Eigen::VectorXd& rhs) {
  Eigen::SparseMatrix<double> system(num_unknowns, num_unknowns);
  system.setFromTriplets(triplets.begin(), triplets.end());
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(system);
  SOFTID_DEMAND(solver.info() == Eigen::Success);  // SPD by construction (lambda > 0, anchored)
  const Eigen::VectorXd delta = solver.solve(rhs);
  SOFTID_DEMAND(solver.info() == Eigen::Success && delta.allFinite());
  return delta;
}

// The interpolated phi on the surface samples before and after the fit.
SurfaceFitSummary Summarize(const std::vector<Sample>& samples,
                            const geometry::SignedDistanceField& sdf,
                            const geometry::SignedDistanceField& fitted,
                            const Eigen::VectorXd& delta, int num_fitted_nodes) {
  SurfaceFitSummary summary;
  summary.num_samples = static_cast<int>(samples.size());
  summary.num_fitted_nodes = num_fitted_nodes;
  double area = 0.0, before = 0.0, after = 0.0;
  for (const Sample& s : samples) {
    const std::array<int, 8> nodes = sdf.grid.CellNodes(s.cell);
    double phi_before = 0.0, phi_after = 0.0;
    for (int c = 0; c < 8; ++c) {
      phi_before += s.weights[c] * sdf.phi[nodes[c]];
      phi_after += s.weights[c] * fitted.phi[nodes[c]];
    }
    area += s.area_weight;
    before += s.area_weight * phi_before * phi_before;
    after += s.area_weight * phi_after * phi_after;
    summary.max_before = std::max(summary.max_before, std::abs(phi_before));
    summary.max_after = std::max(summary.max_after, std::abs(phi_after));
  }
  summary.rms_before = area > 0.0 ? std::sqrt(before / area) : 0.0;
  summary.rms_after = area > 0.0 ? std::sqrt(after / area) : 0.0;
  summary.max_correction = delta.size() > 0 ? delta.cwiseAbs().maxCoeff() : 0.0;
  return summary;
}

}  // namespace

Status SurfaceFitOptions::Validate() const {
  if (samples_per_cell < 1)
    return json::Invalid("SurfaceFitOptions.samples_per_cell", samples_per_cell, "must be >= 1");
  if (!(smoothness_weight > 0.0) || !std::isfinite(smoothness_weight)) {
    return json::Invalid("SurfaceFitOptions.smoothness_weight", smoothness_weight,
                         "must be positive and finite");
  }
  if (!(value_weight >= 0.0) || !std::isfinite(value_weight)) {
    return json::Invalid("SurfaceFitOptions.value_weight", value_weight, "must be finite and >= 0");
  }
  return Status::Ok();
}

geometry::SignedDistanceField FitSdfToSurface(const geometry::SignedDistanceField& sdf,
                                              const geometry::TriangleMesh& surface,
                                              const SurfaceFitOptions& options,
                                              SurfaceFitSummary* summary) {
  const Status valid = options.Validate();
  SOFTID_THROW_UNLESS(valid.ok(), valid.message());
  CheckSurfaceInGrid(sdf, surface);
  const geometry::RegularGrid& grid = sdf.grid;
  const std::vector<Sample> samples = SampleSurface(grid, surface, options.samples_per_cell);
  const Unknowns unknowns = NumberUnknowns(grid, samples);
  const int num_unknowns = unknowns.size();

  std::vector<Eigen::Triplet<double>> triplets;
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(num_unknowns);
  AddSurfaceTerm(sdf, samples, unknowns.of_node, &triplets, &rhs);
  AddSmoothnessTerm(grid, unknowns, options, &triplets);
  const Eigen::VectorXd delta = SolveCorrections(num_unknowns, triplets, rhs);

  geometry::SignedDistanceField fitted = sdf;
  for (int i = 0; i < num_unknowns; ++i) fitted.phi[unknowns.nodes[i]] += delta[i];

  if (summary != nullptr) *summary = Summarize(samples, sdf, fitted, delta, num_unknowns);
  return fitted;
}

}  // namespace softid::cost
