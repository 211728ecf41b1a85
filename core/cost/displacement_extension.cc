#include "core/cost/displacement_extension.h"

#include <Eigen/SparseCholesky>
#include <algorithm>
#include <string>

#include "core/common/check.h"

namespace softid::cost {
namespace {

// Chebyshev dilation of `mask` by `radius` nodes, clipped at the grid: a max filter of width
// 2 radius + 1 along each axis in turn (the Chebyshev ball is the product of 1-D intervals).
std::vector<char> DilateChebyshev(const std::vector<char>& mask, const Eigen::Vector3i& n,
                                  int radius) {
  std::vector<char> current = mask, next(mask.size());
  const int stride[3] = {1, n.x(), n.x() * n.y()};
  for (int axis = 0; axis < 3; ++axis) {
    const int len = n[axis];
    for (int node = 0; node < static_cast<int>(mask.size()); ++node) {
      const int coord = (node / stride[axis]) % len;
      const int lo = std::max(0, coord - radius), hi = std::min(len - 1, coord + radius);
      const int line_start = node - coord * stride[axis];
      char value = 0;
      for (int t = lo; t <= hi && !value; ++t) value = current[line_start + t * stride[axis]];
      next[node] = value;
    }
    current.swap(next);
  }
  return current;
}

// Per grid node: whether it is an FE node. *clipped: whether some FE node lies closer than
// band_cells to the grid boundary.
std::vector<char> MarkFeNodes(const fem::HexMesh& mesh, int band_cells, bool* clipped) {
  const geometry::RegularGrid& grid = mesh.grid;
  const Eigen::Vector3i n = grid.NumNodesPerAxis();
  const int num_fe = mesh.NumNodes();
  std::vector<char> is_fe(grid.NumNodes(), 0);
  for (int i = 0; i < num_fe; ++i) {
    is_fe[mesh.node_grid_index[i]] = 1;
    const Eigen::Vector3i c = grid.NodeCoords(mesh.node_grid_index[i]);
    for (int a = 0; a < 3; ++a) {
      *clipped |= c[a] < band_cells || c[a] > n[a] - 1 - band_cells;
    }
  }
  return is_fe;
}

// Domain numbering: FE nodes keep their index, band nodes follow in grid order.
void NumberDomain(const fem::HexMesh& mesh, const std::vector<char>& is_fe,
                  const std::vector<char>& in_domain, std::vector<int>* domain_grid_node,
                  std::vector<int>* grid_to_domain) {
  const int num_fe = mesh.NumNodes();
  const int num_grid_nodes = mesh.grid.NumNodes();
  *domain_grid_node = mesh.node_grid_index;
  grid_to_domain->assign(num_grid_nodes, -1);
  for (int i = 0; i < num_fe; ++i) (*grid_to_domain)[mesh.node_grid_index[i]] = i;
  for (int g = 0; g < num_grid_nodes; ++g) {
    if (in_domain[g] && !is_fe[g]) {
      (*grid_to_domain)[g] = static_cast<int>(domain_grid_node->size());
      domain_grid_node->push_back(g);
    }
  }
}

// L_BB's lower triangle (row > column, and the diagonal) as triplets, and A_BF in compressed rows:
// the FE neighbours of band node b are (*fe_neighbours)[(*fe_offsets)[b] ..].
std::vector<Eigen::Triplet<double, int>> AssembleBandLaplacian(
    const geometry::RegularGrid& grid, int num_fe, const std::vector<int>& domain_grid_node,
    const std::vector<int>& grid_to_domain, std::vector<int>* fe_offsets,
    std::vector<int>* fe_neighbours) {
  const Eigen::Vector3i n = grid.NumNodesPerAxis();
  const int num_band = static_cast<int>(domain_grid_node.size()) - num_fe;
  std::vector<Eigen::Triplet<double, int>> triplets;
  triplets.reserve(7 * static_cast<size_t>(num_band));
  fe_offsets->assign(1, 0);
  fe_offsets->reserve(num_band + 1);
  for (int b = 0; b < num_band; ++b) {
    const int g = domain_grid_node[num_fe + b];
    const Eigen::Vector3i c = grid.NodeCoords(g);
    int degree = 0;
    for (int a = 0; a < 3; ++a) {
      for (int step : {-1, 1}) {
        Eigen::Vector3i nc = c;
        nc[a] += step;
        if (nc[a] < 0 || nc[a] >= n[a]) continue;
        const int d = grid_to_domain[grid.NodeIndex(nc.x(), nc.y(), nc.z())];
        if (d < 0) continue;
        ++degree;
        if (d < num_fe) {
          fe_neighbours->push_back(d);
        } else if (d - num_fe > b) {  // lower triangle only, row > column
          triplets.emplace_back(d - num_fe, b, -1.0);
        }
      }
    }
    // Every band node has a domain neighbour: the path towards its nearest FE node stays in the
    // Chebyshev ball around that node.
    SOFTID_DEMAND(degree > 0);
    triplets.emplace_back(b, b, static_cast<double>(degree));
    fe_offsets->push_back(static_cast<int>(fe_neighbours->size()));
  }
  return triplets;
}

// The affine fit uses the FE nodes that feed the band (its Dirichlet data): those nodes, their
// centroid and the inverse of their second moment.
void PrepareAffineFit(const std::vector<int>& fe_neighbours,
                      const std::vector<Eigen::Vector3d>& rest, std::vector<int>* fit_nodes,
                      Eigen::Vector3d* fit_centre, Eigen::Matrix3d* fit_inverse_moment) {
  *fit_nodes = fe_neighbours;
  std::sort(fit_nodes->begin(), fit_nodes->end());
  fit_nodes->erase(std::unique(fit_nodes->begin(), fit_nodes->end()), fit_nodes->end());
  fit_centre->setZero();
  for (int i : *fit_nodes) *fit_centre += rest[i];
  *fit_centre /= static_cast<double>(fit_nodes->size());
  Eigen::Matrix3d moment = Eigen::Matrix3d::Zero();
  for (int i : *fit_nodes) moment += (rest[i] - *fit_centre) * (rest[i] - *fit_centre).transpose();
  // They are the nodes of whole grid cells, so never coplanar.
  SOFTID_DEMAND(moment.determinant() > 0.0);
  *fit_inverse_moment = moment.inverse();
}

// Factors L_BB = P^T L D L^T P (AMD ordering) from its lower triangle.
void FactorBandLaplacian(int num_band, const std::vector<Eigen::Triplet<double, int>>& triplets,
                         Eigen::SparseMatrix<double, Eigen::ColMajor, int>* factor_l,
                         Eigen::VectorXd* inverse_d, Eigen::VectorXi* permutation) {
  Eigen::SparseMatrix<double, Eigen::ColMajor, int> laplacian(num_band, num_band);
  laplacian.setFromTriplets(triplets.begin(), triplets.end());
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double, Eigen::ColMajor, int>, Eigen::Lower,
                        Eigen::AMDOrdering<int>>
      ldlt(laplacian);
  SOFTID_DEMAND(ldlt.info() == Eigen::Success);
  // Keep only the factor's arrays: our own solve handles the 3 right-hand sides in one sweep and
  // allocates nothing.
  *factor_l = ldlt.matrixL().nestedExpression();
  factor_l->prune([](int row, int col, double) { return row > col; });
  factor_l->makeCompressed();
  const Eigen::VectorXd d = ldlt.vectorD();
  SOFTID_DEMAND((d.array() > 0.0).all());
  *inverse_d = d.cwiseInverse();
  *permutation = ldlt.permutationP().indices();
}

}  // namespace

const char* ToString(ExtensionMode mode) {
  switch (mode) {
    case ExtensionMode::kHarmonic: return "harmonic";
    case ExtensionMode::kAffinePlusHarmonic: return "affine_plus_harmonic";
  }
  return "unknown";
}

DisplacementExtension::DisplacementExtension(const fem::HexMesh& mesh, int band_cells,
                                             ExtensionMode mode)
    : band_cells_(band_cells), mode_(mode), num_fe_(mesh.NumNodes()) {
  SOFTID_THROW_UNLESS(band_cells >= 1,
                      "band_cells = " + std::to_string(band_cells) + ": must be >= 1");
  SOFTID_THROW_UNLESS(num_fe_ > 0, "mesh: has no FE node");
  const geometry::RegularGrid& grid = mesh.grid;
  const int num_grid_nodes = grid.NumNodes();
  SOFTID_DEMAND(static_cast<int>(mesh.grid_node_to_node.size()) == num_grid_nodes);

  const std::vector<char> is_fe = MarkFeNodes(mesh, band_cells, &clipped_);
  const std::vector<char> in_domain = DilateChebyshev(is_fe, grid.NumNodesPerAxis(), band_cells);
  NumberDomain(mesh, is_fe, in_domain, &domain_grid_node_, &grid_to_domain_);

  rest_.resize(domain_grid_node_.size());
  for (size_t d = 0; d < rest_.size(); ++d) rest_[d] = grid.NodePosition(domain_grid_node_[d]);

  const int num_band = num_band_nodes();
  const std::vector<Eigen::Triplet<double, int>> triplets = AssembleBandLaplacian(
      grid, num_fe_, domain_grid_node_, grid_to_domain_, &fe_offsets_, &fe_neighbours_);
  if (num_band == 0) return;

  PrepareAffineFit(fe_neighbours_, rest_, &fit_nodes_, &fit_centre_, &fit_inverse_moment_);
  FactorBandLaplacian(num_band, triplets, &factor_l_, &inverse_d_, &permutation_);
  scratch_.resize(3, num_band);
  permuted_.resize(3, num_band);
}

void DisplacementExtension::SolveInPlace(Eigen::Matrix3Xd* x) {
  const int num_band = num_band_nodes();
  Eigen::Matrix3Xd& y = permuted_;
  for (int i = 0; i < num_band; ++i) y.col(permutation_[i]) = x->col(i);
  const int* outer = factor_l_.outerIndexPtr();
  const int* inner = factor_l_.innerIndexPtr();
  const double* value = factor_l_.valuePtr();
  for (int j = 0; j < num_band; ++j) {  // L z = y
    const Eigen::Vector3d yj = y.col(j);
    for (int p = outer[j]; p < outer[j + 1]; ++p) y.col(inner[p]) -= value[p] * yj;
  }
  for (int j = 0; j < num_band; ++j) y.col(j) *= inverse_d_[j];
  for (int j = num_band - 1; j >= 0; --j) {  // L^T w = z
    Eigen::Vector3d yj = y.col(j);
    for (int p = outer[j]; p < outer[j + 1]; ++p) yj -= value[p] * y.col(inner[p]);
    y.col(j) = yj;
  }
  for (int i = 0; i < num_band; ++i) x->col(i) = y.col(permutation_[i]);
}

void DisplacementExtension::FitAffine(const Eigen::VectorXd& u_fe, Eigen::Vector3d* u_bar,
                                      Eigen::Matrix3d* a) const {
  // min sum_i |u_bar + A (X_i - c) - u_i|^2: u_bar = mean u_i and A = S M^-1 with
  // S = sum u_i (X_i - c)^T (the u_bar term drops out since sum (X_i - c) = 0).
  u_bar->setZero();
  Eigen::Matrix3d s = Eigen::Matrix3d::Zero();
  for (int i : fit_nodes_) {
    const Eigen::Vector3d ui = u_fe.segment<3>(3 * i);
    *u_bar += ui;
    s += ui * (rest_[i] - fit_centre_).transpose();
  }
  *u_bar /= static_cast<double>(fit_nodes_.size());
  *a = s * fit_inverse_moment_;
}

void DisplacementExtension::Extend(const Eigen::VectorXd& u_fe, Eigen::VectorXd* u_domain) {
  SOFTID_DEMAND(u_fe.size() == 3 * num_fe_);
  u_domain->resize(3 * num_domain_nodes());
  u_domain->head(3 * num_fe_) = u_fe;
  const int num_band = num_band_nodes();
  if (num_band == 0) return;
  const Eigen::Map<const Eigen::Matrix3Xd> fe(u_fe.data(), 3, num_fe_);
  Eigen::Map<Eigen::Matrix3Xd> band(u_domain->data() + 3 * num_fe_, 3, num_band);
  if (mode_ == ExtensionMode::kHarmonic) {
    for (int b = 0; b < num_band; ++b) {
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      for (int p = fe_offsets_[b]; p < fe_offsets_[b + 1]; ++p) sum += fe.col(fe_neighbours_[p]);
      scratch_.col(b) = sum;
    }
    SolveInPlace(&scratch_);
    band = scratch_;
    return;
  }
  Eigen::Vector3d u_bar;
  Eigen::Matrix3d a;
  FitAffine(u_fe, &u_bar, &a);
  for (int b = 0; b < num_band; ++b) {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (int p = fe_offsets_[b]; p < fe_offsets_[b + 1]; ++p) {
      const int f = fe_neighbours_[p];
      sum += fe.col(f) - u_bar - a * (rest_[f] - fit_centre_);
    }
    scratch_.col(b) = sum;
  }
  SolveInPlace(&scratch_);
  for (int b = 0; b < num_band; ++b) {
    band.col(b) = scratch_.col(b) + u_bar + a * (rest_[num_fe_ + b] - fit_centre_);
  }
}

void DisplacementExtension::AccumulateAdjoint(const Eigen::VectorXd& grad_domain,
                                              Eigen::VectorXd* grad_fe) {
  SOFTID_DEMAND(grad_domain.size() == 3 * num_domain_nodes());
  SOFTID_DEMAND(grad_fe->size() == 3 * num_fe_);
  *grad_fe += grad_domain.head(3 * num_fe_);
  const int num_band = num_band_nodes();
  if (num_band == 0) return;
  // Harmonic part: u_B = L_BB^-1 A_BF w_F, so dC/dw_F = A_BF^T y with y = L_BB^-1 dC/du_B
  // (L_BB symmetric).
  const Eigen::Map<const Eigen::Matrix3Xd> grad_band(grad_domain.data() + 3 * num_fe_, 3, num_band);
  scratch_ = grad_band;
  SolveInPlace(&scratch_);
  Eigen::Map<Eigen::Matrix3Xd> fe(grad_fe->data(), 3, num_fe_);
  for (int b = 0; b < num_band; ++b) {
    for (int p = fe_offsets_[b]; p < fe_offsets_[b + 1]; ++p) {
      fe.col(fe_neighbours_[p]) += scratch_.col(b);
    }
  }
  if (mode_ == ExtensionMode::kHarmonic) return;
  // Affine part: u_bar and A enter through a(X_B) (added) and a(X_F) (subtracted from the
  // Dirichlet data), then go back through the linear fit.
  Eigen::Vector3d grad_u_bar = Eigen::Vector3d::Zero();
  Eigen::Matrix3d grad_a = Eigen::Matrix3d::Zero();
  for (int b = 0; b < num_band; ++b) {
    grad_u_bar += grad_band.col(b);
    grad_a += grad_band.col(b) * (rest_[num_fe_ + b] - fit_centre_).transpose();
    for (int p = fe_offsets_[b]; p < fe_offsets_[b + 1]; ++p) {
      grad_u_bar -= scratch_.col(b);
      grad_a -= scratch_.col(b) * (rest_[fe_neighbours_[p]] - fit_centre_).transpose();
    }
  }
  const Eigen::Vector3d per_node = grad_u_bar / static_cast<double>(fit_nodes_.size());
  const Eigen::Matrix3d grad_s = grad_a * fit_inverse_moment_;  // M symmetric
  for (int i : fit_nodes_) fe.col(i) += per_node + grad_s * (rest_[i] - fit_centre_);
}

}  // namespace softid::cost
