// Numerical settings of the forward simulation (not physics: those are PhysicalParameters).
#pragma once

#include <limits>

#include "core/common/status.h"
#include "core/fem/hex_element.h"

namespace softid::fem {

// How the grid's axes lie: along the world's (the rest mesh's own coordinates), or turned with the
// body to its flat faces (geometry::AlignGridToSurface).
enum class GridOrientation { kWorld, kBody };
// "world" | "body" (the names in job configs).
const char* ToString(GridOrientation orientation);

struct SimulationOptions {
  // Grid resolution: cells along the longest side of the rest mesh's bounds, unless cell_size > 0.
  int cells_along_longest_side = 20;  // [-], >= 2
  double cell_size = 0.0;             // h [m]; > 0 overrides cells_along_longest_side
  // Empty cells around the object's bounds; the cost's narrow band lives there.
  int padding_cells = 3;  // [-], >= 1
  // kBody: the grid is laid along the rest mesh's flat faces (geometry::AlignGridToSurface) when
  // the body has them (kMinAlignedScore) and the turn aligns clearly more of its surface than the
  // mesh's own axes (kMinAlignmentGain), and is turned back into the world with the initial pose
  // (RestFrame). A box resting at an angle to the world's axes is then cut into whole cells, which
  // converge under refinement; on a world-aligned grid its faces are staircases that change with
  // every resolution. A clamped body keeps the world's axes (its clamp is a world box, whose face
  // the grid must follow).
  GridOrientation grid_orientation = GridOrientation::kWorld;
  // geometry::AxisAlignmentScore the turned grid must reach: a body of mostly flat faces (a box
  // scores 1; half its area on flat faces and half curved, about 0.8). A curved body is cut into
  // cut cells in every orientation: a torus scores 0.66 at best, the scanned bunny and dragon
  // 0.66 and 0.65.
  static constexpr double kMinAlignedScore = 0.8;
  // ... and gain over the mesh's own axes: below it the orientations are alike to the grid, and
  // the mesh's axes keep every result made on them. A box turned by 5 degrees gains about 0.01,
  // by 25 degrees 0.2.
  static constexpr double kMinAlignmentGain = 0.005;
  // Cut cells with less inside volume than this fraction of h^3 are dropped (their surface points
  // then act on the neighbouring element): their nodes would be nearly massless, and a contact
  // force on them throws them centimetres per Newton iteration. Loses ~0.1 % of the volume.
  double min_cell_volume_fraction = 0.05;  // [-], in [0, 0.5)
  // Distance samples per cell edge that shape a cut cell's inside (integration weights, mass)
  // [-]: 1, 2, 4 or 8. With 1 the inside is where the trilinear interpolant of the node values is
  // negative (the paper's cut cells), which rounds a sharp feature at the scale of a cell: a box's
  // corner filling 0.55 of a cell counts 0.2, its edges lose a fifth of their cells; with n the
  // mesh's distance is also sampled every h / n inside cut cells and the rounding shrinks to h / n.
  // 4: a box's lowest mode within 0.7 % of a converged reference from 8 cells on (1: +10 % at 8,
  // +4 % at 16), for 117 more distance queries per cut cell, once per simulator.
  int cut_cell_samples = 4;  // [-], in {1, 2, 4, 8}
  // Ghost stiffness: every Gauss point of an element integrates at least this fraction of a full
  // octant, so slivers of material do not leave nodes nearly free (mass is not affected). Small
  // enough to change the stiffness of a well-resolved body by well under a percent.
  double ghost_stiffness_fraction = 0.02;  // [-], in [0, 1]
  // Contact and drag act only through elements at least this full; surface points in thinner ones
  // push on the nearest such element, clamped into it (slivers cannot carry contact: the floor
  // would crush them and stall Newton; on torus-drop at 8 cells they make the motion rattle)...
  double min_force_volume_fraction = 0.25;  // [-], in [0, 1]
  // ... unless the clamp would move a point by more than this many cells: its own element then
  // carries it, so the surface that is seen is the surface the floor stops. A box's corner cells
  // can be under a quarter full by their trilinear distance though the box fills most of them:
  // the thrown block (0.1 x 0.06 x 0.04 m, 16 cells) had its corners' contact points clamped 0.7
  // cells inwards, and at a landing the rendered corner, moving with its own element, sank 9 mm
  // into the floor (CalculiX with the same contact: 0.3 mm; at 0.5 cells softid: 0.3 mm). Not
  // yet the default: at 0.5 a thin corner element carrying contact and friction makes a landing
  // sensitive to round-off (a box thrown on a turned grid departs 0.1 mm from its unturned twin,
  // against 1e-6 m always clamped).
  double max_force_clamp_cells = std::numeric_limits<double>::infinity();  // [-], >= 0

  double time_step = 1.0 / 240.0;  // dt [s], > 0 (a capture's dt is 1 / (fps * substeps))
  // Newmark parameters. The defaults (gamma = 0.6, beta = (gamma + 1/2)^2 / 4) add a little
  // numerical dissipation of the highest frequencies, which keeps penalty contact calm; beta = 1/4,
  // gamma = 1/2 is the energy-conserving average-acceleration rule.
  double newmark_beta = 0.3025;  // [-], in (0, 0.5]
  double newmark_gamma = 0.6;    // [-], in [0.5, 1]
  // Generalized-alpha weights (Chung & Hulbert 1993): the step equations hold at
  // u_f = (1 - alpha_f) u_{n+1} + alpha_f u_n (v likewise) with the inertia of
  // a_m = (1 - alpha_m) a_{n+1} + alpha_m a_n; u, v and a advance by Newmark. 0 and 0 is plain
  // Newmark. UseGeneralizedAlpha sets these and the Newmark parameters together.
  double generalized_alpha_m = 0.0;  // [-], in (-1, generalized_alpha_f]
  double generalized_alpha_f = 0.0;  // [-], in [0, 0.5]

  // The generalized-alpha scheme with high-frequency spectral radius rho_infinity in [0, 1]:
  // second-order accurate for every rho_infinity, which sets how strongly the highest
  // frequencies (penalty contact, the grid's own modes) are damped: 1 none, 0 annihilated in one
  // step. (Newmark with gamma > 1/2 damps them too, but is only first-order accurate.)
  // Measured on torus-drop (16 cells, 1 s at 60 fps; capture made with rho 0.8 at 32 substeps,
  // 0.07 mm from 16): Young's modulus fitted with the default Newmark was 2.5 % off at 4
  // substeps and 2.7 % at 8; with rho 0.8, 4.2 % at 4 and 0.3 % at 8. Step doubling then takes
  // 8 for rho 0.8 (4 vs 8 differ by 1.71 mm) but 4 for Newmark (0.31 mm; its differences do not
  // shrink: 0.40 mm at 8 vs 16, 0.25 mm at 16 vs 32). Not yet the default: switching it changes
  // every synthetic capture and needs the accuracy and diagnosis benchmarks re-run.
  void UseGeneralizedAlpha(double rho_infinity);

  // Newton iterations on the nonlinear (corotated, contact) step equations; converged when the
  // largest displacement update is below newton_tolerance * h. In contact Newton contracts ~10x
  // per iteration, so the error left after the last update is ~newton_tolerance * h / 10 (0.7 um
  // at h = 7 mm, a thousandth of a depth camera's noise). 1e-5 took one more iteration per
  // contact step for nothing a capture can show: 1e-4 ran torus-drop, pillow-ramp and ball-bounce
  // over 1 s at 26 cells 30 %, 16 % and 23 % faster, the centre of mass within 1e-6 m; 3e-4
  // began to break the torus's symmetry (1.5e-5 m).
  int max_newton_iterations = 12;  // [-], >= 1
  double newton_tolerance = 1e-4;  // [-], > 0
  // A step that leaves the body's extent (the diagonal of its FE nodes' bounding box) above this
  // multiple of the rest extent has diverged: no soft solid stretches that far (a rigid rotation
  // changes the diagonal by at most sqrt(3)). Such runs stay finite for many steps (pillow-ramp
  // with its ground plane through the body at t = 0: every Newton step unconverged, extent 7.5x
  // after 2 steps, 16x after 4, 1e18 m later), and their cost must not count.
  double max_extent_ratio = 10.0;  // [-], > 1
  // After a step that converged with one Newton update (free flight, gentle contact), the next
  // step first takes the preconditioner's estimate from its residual, P^-1 (-r), and ends there
  // when that is below Newton's tolerance, without assembling the tangent or running GMRES
  // (torus-drop at 3,100 cells: free-flight steps 5.6 -> 2.5 ms); otherwise the estimate is
  // GMRES's initial guess. The state meets the same tolerance either way.
  bool newton_estimate_first = true;
  // Newton's dynamic step matrix is applied element by element in GMRES (StepTangentOperator)
  // instead of being assembled: its tangent then costs nothing beyond the residual, and a product
  // reads the rotations and a shared element matrix instead of ~10 MB of matrix at 3,100 cells.
  // A matrix is assembled only when the preconditioner is refactorised. The states agree with the
  // assembled matrix's to round-off in the products (within Newton's tolerance).
  bool matrix_free_newton = true;
  // GMRES right-preconditioned by a sparse Cholesky factor (CHOLMOD) of the symmetric part of a
  // reference step matrix, rotated with the body; the factor is renewed when the extra iterations
  // it causes have cost more than a factorisation (see LinearSolver::RefactorPays).
  // Inexact Newton (forcing term): each solve only needs to shrink the residual by this factor for
  // Newton to converge to its own tolerance; tighter solves cost iterations and buy nothing
  // (torus-drop at 3k cells: 1e-6 -> 1e-3 is 1.5x faster, same state to 6 digits). In contact
  // Newton contracts only ~10x per iteration (its tangent leaves out the geometric term of
  // compressed elements), so 1e-3 still over-solved there: 1e-2 keeps the Newton counts (+0-6 %);
  // over 1 s it ran torus-drop, pillow-ramp and bar-hanging at 20 cells 9-15 % and ball-bounce at
  // 26 cells 17 % faster, torus-drop at 26 cells 9 % slower (the refactorisation rule then renewed
  // the factor 4 times instead of 10, and GMRES paid for it); after 1 s the centre of mass is
  // within 2e-7 m of a 1e-8 solve's (1e-3: 1e-7 m), about newton_tolerance * h. 3e-2 was faster in
  // every case (16-33 % at 26 cells) but raised the Newton counts 3-10 %, and 1e-1 by 10-25 %.
  double linear_tolerance = 1e-2;   // relative residual [-], > 0
  int max_linear_iterations = 500;  // [-], >= 1
  // Relative residual of the adjoint's transposed solves [-], > 0. Unlike the forward solves, an
  // inexact adjoint solve is an error in the gradient itself. 1e-5 made the adjoint ~19 % faster
  // (torus-drop, 3,100 cells) and left Table 1 c1-50, bar-hanging and the diagnosis proof
  // unchanged, but L-BFGS in pillow-ramp's curved 9-variable valleys then took other paths: of its
  // first 4 starts 1 instead of 2 reached the minimum (2026-11-25; a small sample, but the gradient
  // is what those valleys are walked by). Gradient tests tighten it to 1e-12.
  double adjoint_linear_tolerance = 1e-6;
  // The adjoint pass preconditions each step with the factor the forward pass solved it with,
  // kept from the forward pass (up to 128 MB per simulation), instead of its own stale one and
  // refactorisations: torus-drop's impact (3,100 cells) and pillow-ramp's slide ran their adjoint
  // 8-12 % faster, torus-drop over 1 s the same. false: the adjoint renews its own factor only.
  bool adjoint_reuses_forward_factors = true;

  // Width of the smooth onset of contact force (softplus length) [m]; 0 selects 1e-3 L, L the
  // longest side of the rest mesh.
  double contact_smoothing = 0.0;
  // Regularised Coulomb friction: slip speeds well below this behave as stick [m/s], > 0.
  double friction_velocity_scale = 1e-3;
  // Newton's friction tangent follows a friction force estimate (primal-dual, see
  // GroundContactForce) instead of the exact one; false: exact tangent and a global step limit on
  // slip reversal, which stalls on blocks that stick under strong friction.
  bool primal_dual_friction = true;
  // GMRES's preconditioner is corrected on the nodes of the elements in contact by an exact solve
  // of the current step matrix's block on them (subdomain_correction.h), so that a factor taken
  // before a landing still preconditions it while stick, slip and contact change between Newton
  // iterations. Matrix-free Newton only; used for the rest of a step once one of its solves took
  // more than a few GMRES iterations on the plain factor (a body resting or sliding never needs
  // it). A friction landing on a 25-degree ramp (cube, 16 cells, 16 substeps, 0.3 s) ran 0.74x
  // the time without it; torus-drop, ball-bounce and pillow-ramp the same (docs/benchmarks.md).
  bool contact_correction = true;
  // The surface (contact, drag, rendering) is subdivided until its edges are at most this fraction
  // of h, so coarse input meshes still deform smoothly with the grid.
  double surface_edge_fraction = 0.5;  // [-], > 0

  // Threads of one simulation: the assembly's element loop, the preconditioner's triangular
  // solves and the products with the step matrix run on a team of this many (at most 4, and only
  // on meshes of several hundred elements); 0: one per core. 1 by default: softid runs optimiser
  // starts and jobs in parallel, and threads of their own then oversubscribe the cores (every
  // parallel region waits for its slowest thread); a fit gives each simulation the cores its
  // concurrent starts leave free. Results do not depend on thread timing, but the summation
  // order (the last bits) depends on the thread count.
  int threads = 1;  // [-], >= 0

  // The element (hex_element.h). Trilinear by default: the accuracy and diagnosis benchmarks were
  // run with it, and incompatible modes are not yet better on every capture measured
  // (docs/benchmarks.md, "Element").
  ElementFormulation element = ElementFormulation::kTrilinear;

  Status Validate() const;
};

}  // namespace softid::fem
