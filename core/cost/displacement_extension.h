// Harmonic extension of the FE displacements into a narrow band of inactive grid nodes (Weiss et
// al. CVPR 2020, Sec. 4.1; method-notes Sec. 4). Observed points near but outside the rest surface
// can only be traced back to the rest pose where the grid carries a displacement, so the FE
// displacements u_F are extended to the band nodes B by the discrete Laplace equation
//   sum over the 6 grid neighbours j in F u B of (u_b - u_j) = 0   for every b in B,
// with u_F as Dirichlet data: L_BB u_B = A_BF u_F, where L_BB is the graph Laplacian of B (SPD,
// since every band node reaches an FE node through band nodes) and A_BF counts the FE neighbours.
//
// L_BB is factored once (sparse LDL^T) in the constructor; Extend and the adjoint both use that
// factor and solve directly, so the adjoint is exact to round-off (the reference code ran a capped
// warm-started CG forward and a cold-started one backward: method-notes Sec. 7, item 5).
//
// What the harmonic extension reproduces: constants exactly. Affine fields only where the
// discrete Laplacian of an affine field vanishes, i.e. at band nodes with all 6 neighbours in the
// domain; at the band's outer rim (truncated neighbourhoods act like a zero-flux boundary) they do
// not, and the rim's deviation spreads through the band. So a rotated body drags a distorted band
// along: on a torus turned rigidly by 30 degrees, points 1.5 h outside read phi wrong by up to
// 0.6 h; at 90 degrees band cells fold and 18 % of the points 0.5 h outside match nothing.
//
// ExtensionMode::kAffinePlusHarmonic removes that: it fits an affine field a(X) = u_bar +
// A (X - c) to u on the FE nodes next to the band (least squares, a linear map of u), extends only
// the remainder harmonically and adds a(X) back on the band:
//   u_B = a(X_B) + L_BB^-1 A_BF (u_F - a(X_F)).
// Every affine field (rigid motions included) is then reproduced exactly, and the map stays
// linear in u_F with an exact adjoint. kHarmonic is the paper's plain extension.
//
// Thread-compatibility: Extend and AccumulateAdjoint use member scratch storage; use one instance
// per thread.
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <vector>

#include "core/fem/hex_mesh.h"

namespace softid::cost {

enum class ExtensionMode {
  kHarmonic,            // L_BB u_B = A_BF u_F (Weiss et al. 2020)
  kAffinePlusHarmonic,  // affine fit + harmonic extension of the remainder
};

const char* ToString(ExtensionMode mode);

class DisplacementExtension {
 public:
  // Band = grid nodes that are not FE nodes and lie within `band_cells` (Chebyshev distance in
  // grid index space) of an FE node, clipped at the grid boundary.
  // @throws std::invalid_argument if band_cells < 1 or the mesh has no FE node.
  DisplacementExtension(const fem::HexMesh& mesh, int band_cells,
                        ExtensionMode mode = ExtensionMode::kHarmonic);

  // Domain = FE nodes followed by band nodes. Domain node d < num_fe_nodes() is FE node d.
  int num_fe_nodes() const { return num_fe_; }
  int num_band_nodes() const { return static_cast<int>(domain_grid_node_.size()) - num_fe_; }
  int num_domain_nodes() const { return static_cast<int>(domain_grid_node_.size()); }
  int band_cells() const { return band_cells_; }
  ExtensionMode mode() const { return mode_; }
  // Grid node of a domain node.
  int grid_node(int domain_node) const { return domain_grid_node_[domain_node]; }
  // Rest position of a domain node [m].
  const Eigen::Vector3d& rest_position(int domain_node) const { return rest_[domain_node]; }
  // Domain node of a grid node, or -1 outside the domain.
  int domain_node(int grid_node) const { return grid_to_domain_[grid_node]; }
  // True when the band was cut off by the grid boundary somewhere (some FE node lies closer than
  // band_cells to the boundary).
  bool clipped() const { return clipped_; }

  // u_domain (resized to 3 * num_domain_nodes(), node d at segment<3>(3 d)) = u_fe on FE nodes and
  // the extension (per mode()) on band nodes. @pre u_fe.size() == 3 * num_fe_nodes()
  void Extend(const Eigen::VectorXd& u_fe, Eigen::VectorXd* u_domain);

  // Adjoint of Extend: for a cost C(u_domain(u_fe)), grad_fe += dC/du_fe given grad_domain =
  // dC/du_domain. The band part goes through L_BB^-1 (same factor as Extend) and A_BF^T, and in
  // kAffinePlusHarmonic also back through the affine fit.
  // @pre grad_domain.size() == 3 * num_domain_nodes(), grad_fe->size() == 3 * num_fe_nodes()
  void AccumulateAdjoint(const Eigen::VectorXd& grad_domain, Eigen::VectorXd* grad_fe);

 private:
  // x <- L_BB^-1 x for 3 right-hand sides (the columns of x are band nodes).
  void SolveInPlace(Eigen::Matrix3Xd* x);
  // Least-squares affine fit over fit_nodes_: u_bar and A of a(X) = u_bar + A (X - c).
  void FitAffine(const Eigen::VectorXd& u_fe, Eigen::Vector3d* u_bar, Eigen::Matrix3d* a) const;

  int band_cells_ = 0;
  ExtensionMode mode_ = ExtensionMode::kHarmonic;
  int num_fe_ = 0;
  bool clipped_ = false;
  std::vector<int> domain_grid_node_;  // per domain node
  std::vector<int> grid_to_domain_;    // per grid node, -1 outside the domain
  std::vector<Eigen::Vector3d> rest_;  // per domain node [m]
  // Affine fit (kAffinePlusHarmonic): the FE nodes with a band neighbour, their centroid c and
  // the inverse of their second moment M = sum (X_i - c)(X_i - c)^T.
  std::vector<int> fit_nodes_;
  Eigen::Vector3d fit_centre_ = Eigen::Vector3d::Zero();
  Eigen::Matrix3d fit_inverse_moment_ = Eigen::Matrix3d::Zero();
  // A_BF in compressed rows: FE neighbours of band node b are fe_neighbours_[fe_offsets_[b] ..].
  std::vector<int> fe_offsets_;
  std::vector<int> fe_neighbours_;
  // L_BB = P^T L D L^T P (Eigen's SimplicialLDLT, AMD ordering): L strictly lower, column-major.
  Eigen::SparseMatrix<double, Eigen::ColMajor, int> factor_l_;
  Eigen::VectorXd inverse_d_;
  Eigen::VectorXi permutation_;  // row i of the system is row permutation_[i] of the factor
  Eigen::Matrix3Xd scratch_, permuted_;
};

}  // namespace softid::cost
