// Nodal rest-SDF values whose trilinear interpolation vanishes on the rest surface.
//
// The sparse surface cost interpolates the rest signed distance phi_0 trilinearly from grid nodes
// (with the weights that invert the deformation map). Sampled exact distances d_n do not make that
// interpolant vanish on the surface: the distance is convex outside a curved surface and concave
// inside, so the interpolant's zero set sits off the surface by O(kappa h^2) (~4 % of h rms on the
// torus-drop object at 16 cells). Observed points on the true deformed surface then never reach
// zero cost, and because the deformation decides which cells points fall in, a wrong Young's
// modulus can lower that floor: a bias of the fit (8 % in E on torus-drop at 16 cells).
//
// The fix keeps "interpolated with the same weights" and changes only the values: over the nodes
// of every cell the surface passes through (the unknowns, corrections delta_n = phi_n - d_n),
//   minimise  sum_s w_s (sum_c N_c(x_s) phi_c)^2                    (zero set on the surface)
//           + lambda sum_{grid edges (i,j)} (delta_i - delta_j)^2   (gradient of phi stays d's)
//           + mu sum_n delta_n^2                                      (uniqueness)
// over dense samples x_s of the rest surface (area weights w_s = area_s / h^2, so the first term
// approximates the surface integral of phi^2 in units of cells). Nodes that are not unknowns keep
// d_n and enter the edge term with delta = 0, so the correction fades out within the band. The
// edge term penalises what would break the cost away from the surface: a correction that rescales
// phi (shrinking all values also shrinks the zero-set residual) or flips signs changes
// differences between neighbours, while the smooth offset that moves the zero set does not.
// It is one sparse SPD solve (Eigen SimplicialLDLT), done once per grid.
#pragma once

#include "core/common/status.h"
#include "core/geometry/signed_distance_field.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::cost {

struct SurfaceFitOptions {
  // Surface samples per cell length along each triangle edge [-], >= 1: every triangle is cut
  // into n^2 similar sub-triangles, n = ceil(longest edge * samples_per_cell / h), sampled at
  // their centroids. 4 resolves the variation of the interpolant within a cell (it is trilinear:
  // quadratic along a straight line in a cell, so a few samples per cell pin it down); more only
  // costs setup time.
  int samples_per_cell = 4;
  // lambda [-], > 0: weight of the edge term relative to the surface term (one cell of surface
  // area weighs 1). Measured on spheres and tori at 6 to 30 cells per side (surface_fitted_sdf_
  // test.cc): 0.01 lowers the rms of phi on the surface 3-4x (torus, 16 cells: 0.040 h -> 0.014 h)
  // and halves phi's error 0.5 h off the surface; 0.1 fits the zero set only 2.5x better, 1e-3
  // bends phi off the surface (errors 0.5 h out grow past the sampled ones), 1e-4 by 0.1-0.2 h.
  // The rest (~0.01 h) is what a trilinear cell cannot follow: the facets' creases inside it.
  double smoothness_weight = 0.01;
  // mu [-], >= 0: weight of keeping each correction small. The edge term already anchors the
  // corrections at the surrounding fixed nodes; this only keeps the system definite if a region
  // of unknowns had no fixed neighbour.
  double value_weight = 1e-6;

  // InvalidArgument naming the field and value, e.g.
  // "SurfaceFitOptions.samples_per_cell = 0: must be >= 1".
  Status Validate() const;
};

// What the fit did, for logs and tests. Residuals are area-weighted over the surface samples.
struct SurfaceFitSummary {
  int num_samples = 0;
  int num_fitted_nodes = 0;
  double rms_before = 0.0, rms_after = 0.0;  // rms of the interpolated phi on the surface [m]
  double max_before = 0.0, max_after = 0.0;  // largest |interpolated phi| on the surface [m]
  double max_correction = 0.0;               // largest |phi_n - d_n| [m]
};

// `sdf` with the values of the nodes of every cell the surface passes through refitted (see the
// top of the file); other nodes keep their values.
// @pre `surface` lies inside sdf.grid (as the mesh sdf was computed from) and sdf.phi has one
//   value per grid node.
// @throws std::invalid_argument naming the field for invalid options, an empty surface, a surface
//   vertex outside the grid, or an SDF whose phi does not match its grid.
geometry::SignedDistanceField FitSdfToSurface(const geometry::SignedDistanceField& sdf,
                                              const geometry::TriangleMesh& surface,
                                              const SurfaceFitOptions& options = {},
                                              SurfaceFitSummary* summary = nullptr);

}  // namespace softid::cost
