// Sparse surface constraint (SSC) cost of one frame (Weiss et al. CVPR 2020, Sec. 4, Eq. 4;
// method-notes Sec. 4): observed surface points x (depth pixels in world space, no
// correspondences) should lie on the deformed surface, i.e. at zero rest-pose signed distance
// phi_0(X) of the material point X that the displacement carries to x (x = X + u(X)).
//
// u is known on FE nodes only; it is extended harmonically into a narrow band of grid nodes
// (DisplacementExtension), and every grid cell whose 8 corners carry a displacement is a candidate.
// Per point, the candidate cells whose deformed bounding box contains x are found through a uniform
// spatial binning rebuilt every call (never a scan over all cells per point: method-notes Sec. 7,
// item 4); for each, the trilinear map of the deformed cell is inverted by Newton
// (InvertTrilinearMap), and phi = sum_c N_c(xi) phi_0,c interpolates the rest SDF. The cost is
//   C = (1 / N) sum_p rho(phi_p),   rho = Tukey biweight truncated at phi_max (tukey_loss.h),
// over all N observed points; a point that no candidate cell contains gets rho = phi_max^2 / 6.
//
// Gradient: with x = sum_c N_c(xi) x_c held fixed (x is data), the implicit function theorem gives
// d xi / d x_c = -N_c J^-1 (J = dx/dxi), so d phi / d x_c = -N_c(xi) J^-T grad_xi(phi); chained
// with rho'(phi) and then through the extension's adjoint onto the FE displacements. Only the
// chosen cell of each point contributes (the reference code leaked rejected candidates into the
// gradient and dropped the truncation's derivative: method-notes Sec. 7, item 4).
//
// Rest SDF values: sampled exact distances make the trilinear interpolant vanish off the rest
// surface (a cost floor that biases fits), so by default the values next to the surface are
// refitted so that the interpolant's zero set matches the rest surface (surface_fitted_sdf.h);
// the interpolation itself, with the weights of the inverted deformation map, is unchanged.
//
// Thread-compatibility: Evaluate reuses member scratch storage (no allocation in steady state), so
// an instance is not thread-safe; use one instance per thread.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <memory>
#include <span>
#include <vector>

#include "core/common/status.h"
#include "core/cost/displacement_extension.h"
#include "core/cost/surface_fitted_sdf.h"
#include "core/fem/hex_mesh.h"
#include "core/geometry/mesh_distance.h"
#include "core/geometry/signed_distance_field.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::cost {

// How the cost evaluates the rest signed distance phi_0 at a matched material point X.
enum class RestSdf {
  kSampled,        // trilinear interpolation of the exact distances at the nodes (the paper's)
  kSurfaceFitted,  // trilinear interpolation of values refitted so it vanishes on the surface
  // The exact signed distance to the rest surface at X (Embree closest point; the sign from the
  // closest triangle's side, or from the interpolant where that is far from zero). Cells are still
  // found and ranked with the surface-fitted interpolant. No discretisation floor at all, at the
  // price of one closest-point query per matched point.
  kExact,
};
// "sampled" | "surface_fitted" | "exact".
const char* ToString(RestSdf mode);

struct SurfaceCostOptions {
  // Width of the extension band around the FE nodes [cells], >= 1. Points that map outside the band
  // cannot be matched and get the constant truncated cost, so the band should reach where that
  // constant is already attained: band_cells >= truncation_cells + 1 (FE nodes reach up to one
  // cell beyond the surface). Where the grid boundary cuts the band off, the rest signed distance
  // there must be >= phi_max, else the constructor throws: use a grid padding of at least
  // truncation_cells + 1 cells (the Simulator's default 3 suffices for the defaults here).
  int band_cells = 3;
  // phi_max = truncation_cells * h [-], > 0: residuals beyond this many cells are outliers (two
  // cells: noisy depth is within a cell of the surface, a misplaced limb is not).
  double truncation_cells = 2.0;
  // How u is carried into the band (displacement_extension.h). kHarmonic is the paper's; it
  // distorts the band of a rotated body (on a torus turned by 90 degrees, 18 % of the points
  // 0.5 h outside match nothing), which kAffinePlusHarmonic (the default) avoids by reproducing
  // every affine (rigid included) motion exactly, at no measurable extra cost.
  ExtensionMode extension_mode = ExtensionMode::kAffinePlusHarmonic;
  // Rest SDF evaluation; needs the rest surface, so it applies to the constructor given one.
  // kSurfaceFitted (default) lowers the rms residual at the true state 3x (torus at 16 cells:
  // from 0.040 h to 0.014 h), and with it the bias that floor puts on fitted parameters.
  RestSdf rest_sdf = RestSdf::kSurfaceFitted;
  SurfaceFitOptions surface_fit;  // used with kSurfaceFitted and kExact

  // InvalidArgument naming the field and value, e.g.
  // "SurfaceCostOptions.band_cells = 0: must be >= 1".
  Status Validate() const;
};

// Per observed point: how it was matched, for diagnosis and plots.
struct PointMatch {
  bool matched = false;
  double phi = 0.0;  // rest-pose signed distance at the matched material point [m] (0 if unmatched)
  double cost = 0.0;  // rho(phi) (the truncated value if unmatched) [m^2]
  Eigen::Vector3d rest_position = Eigen::Vector3d::Zero();  // matched material point X [m]
  int cell = -1;                                            // grid cell of the match
};

class SparseSurfaceCost {
 public:
  // Interpolates the nodal values of `sdf` as they are (options.rest_sdf needs the rest
  // surface: see the constructor below). `mesh` and `sdf` must share the grid (as
  // fem::Simulator's hex_mesh() and signed_distance()).
  // @throws std::invalid_argument naming the field for invalid options, a mesh and SDF on
  //   different grids, or a band cut off by the grid boundary where the rest signed distance is
  //   below phi_max (the cost would jump there).
  SparseSurfaceCost(const fem::HexMesh& mesh, const geometry::SignedDistanceField& sdf,
                    const SurfaceCostOptions& options = {});
  // As above, with the rest SDF evaluated as options.rest_sdf says; `rest_surface` is the
  // surface the observations show at rest (fem::Simulator::rest_surface()).
  // @throws std::invalid_argument also when the surface does not fit the SDF's grid or (kExact)
  //   cannot be queried (no triangles, non-finite vertices).
  SparseSurfaceCost(const fem::HexMesh& mesh, const geometry::SignedDistanceField& sdf,
                    const geometry::TriangleMesh& rest_surface,
                    const SurfaceCostOptions& options = {});

  // Frame cost C = (1/N) sum_p rho(phi_p) over the N = points.size() observed points [m^2], and,
  // if gradient != nullptr, dC/du (resized to u.size(), overwritten) [m]. An empty point set gives
  // C = 0 and a zero gradient. If matches != nullptr it gets one PointMatch per point.
  // If several cells contain a point (shared faces, folded cells), the match with the smallest
  // signed phi wins (the point is inside the deformed object if any preimage is: the signed
  // distance of a union), ties to the smallest cell index. Non-finite points match nothing.
  // @pre u.size() == 3 * mesh.NumNodes() (FE node i at u.segment<3>(3 i)), as
  //   fem::Simulator::state().u. @throws std::invalid_argument otherwise or if u is not finite
  //   (check the simulator's divergence flag first).
  double Evaluate(const Eigen::VectorXd& u, std::span<const Eigen::Vector3d> points,
                  Eigen::VectorXd* gradient, std::vector<PointMatch>* matches = nullptr);

  double truncation_distance() const { return phi_max_; }  // phi_max [m]
  const SurfaceCostOptions& options() const { return options_; }
  const DisplacementExtension& extension() const { return extension_; }
  // Grid cells whose 8 corners are in the extension's domain, ascending.
  int num_candidate_cells() const { return static_cast<int>(candidates_.size()); }
  int candidate_cell(int i) const { return candidates_[i].cell; }
  // Smallest |rest signed distance| over the nodes on the outer boundary of the candidate cells
  // [m]. When >= truncation_distance(), every point leaves the band with the truncated cost already
  // reached, so C is continuous in u; thin features missed by the grid can make it smaller.
  double band_edge_distance() const { return band_edge_distance_; }
  // The rest SDF whose nodal values the cost interpolates (the given one, or surface-fitted).
  const geometry::SignedDistanceField& rest_sdf() const { return rest_sdf_; }
  // What the surface fit did (all zero unless kSurfaceFitted with a rest surface).
  const SurfaceFitSummary& surface_fit_summary() const { return surface_fit_summary_; }

 private:
  struct Candidate {
    int cell = -1;
    std::array<int, 8> nodes;   // domain nodes of the corners
    std::array<double, 8> phi;  // rest signed distance at the corners [m]
  };
  struct Match {
    int candidate = -1;
    double rho = 0.0, phi = 0.0;
    Eigen::Vector3d xi;
    Eigen::Matrix3d jacobian;
  };
  // Candidate cells, band edge checks and scratch sizes, from rest_sdf_.
  void BuildCandidates();
  // Bins of the deformed candidates (positions_): LayOutBins sizes them, CountCandidatesPerBin
  // fills boxes_, bin_ranges_, overflow_ and the per-bin counts, FillBins lists the candidates.
  void BuildBins();
  void LayOutBins(double margin);
  void CountCandidatesPerBin(double margin);
  void FillBins();
  // Deformed domain nodes (positions_) for FE displacements u, and their bins.
  void DeformDomain(const Eigen::VectorXd& u);
  // The best candidate containing point x (best->candidate stays -1 if none does).
  void FindMatch(const Eigen::Vector3d& x, Match* best) const;
  // d phi / d xi at the match; with kExact it first replaces best->phi and best->rho by the exact
  // distance.
  Eigen::Vector3d MatchPhiGradient(const Candidate& candidate, Match* best) const;
  void RecordMatch(const Candidate& candidate, const Match& best, PointMatch* match) const;
  // Adds the match's share of dC/d(domain positions) to grad_domain_.
  void AccumulateGradient(const Candidate& candidate, const Match& best,
                          const Eigen::Vector3d& grad_xi, double inverse_count);
  // kExact: the signed distance to the rest surface at X and its gradient d phi / d X;
  // `interpolated` is the interpolant's value there (its sign is trusted away from the surface).
  double ExactDistance(const Eigen::Vector3d& rest, double interpolated,
                       Eigen::Vector3d* gradient) const;
  // Tries candidate i for point x; updates `best` if it contains x with a better (phi, cell).
  void TryCandidate(int i, const Eigen::Vector3d& x, Match* best) const;

  SurfaceCostOptions options_;
  geometry::RegularGrid grid_;
  double phi_max_ = 0.0;
  double band_edge_distance_ = 0.0;
  DisplacementExtension extension_;
  geometry::SignedDistanceField rest_sdf_;
  SurfaceFitSummary surface_fit_summary_;
  // kExact: closest-point queries (thread-safe, shared by copies) and the surface's unit normals.
  std::shared_ptr<const geometry::MeshDistance> exact_distance_;
  std::vector<Eigen::Vector3d> face_normals_;
  std::vector<Candidate> candidates_;

  // Scratch of Evaluate, reused across calls.
  Eigen::VectorXd u_domain_, grad_domain_;
  std::vector<Eigen::Vector3d> positions_;  // deformed domain nodes [m]
  std::vector<Eigen::AlignedBox3d> boxes_;  // inflated deformed box per candidate [m]
  // Uniform bins over the deformed domain: bin b holds candidates bin_items_[bin_offsets_[b] ..
  // bin_offsets_[b + 1]) ascending; candidates spanning too many bins go to overflow_ instead.
  Eigen::Vector3d bin_origin_ = Eigen::Vector3d::Zero();
  double bin_size_ = 0.0;
  Eigen::Vector3i bin_dims_ = Eigen::Vector3i::Zero();
  std::vector<int> bin_offsets_, bin_items_, overflow_;
  std::vector<std::array<int, 6>> bin_ranges_;  // per candidate: lo/hi bin per axis, or -1
};

}  // namespace softid::cost
