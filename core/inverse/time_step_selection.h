// Choosing the simulation time step of a fit from the motion itself (step doubling).
//
// A fit on a capture made by another solver (or by nature) is biased by the time discretisation
// of our simulator: torus-drop at 60 fps, Young's modulus fitted at 2 substeps per frame to a
// capture made at 16 was 33-46 % off; at 4 substeps it was within 0.2 %. How many substeps a
// capture needs depends on what the motion excites (a stiff impact vs a slow swing), so the
// selection simulates the object at its starting parameters with s and 2 s substeps per frame
// and takes the smallest s whose surface trajectory agrees with the finer one to within a
// tolerance, the classic step-doubling error estimate.
#pragma once

#include <Eigen/Geometry>
#include <atomic>
#include <nlohmann/json.hpp>
#include <optional>
#include <vector>

#include "core/common/status.h"
#include "core/fem/physical_parameters.h"
#include "core/fem/simulation_options.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::inverse {

struct SubstepSelectionOptions {
  int min_substeps = 2;  // first candidate [-], >= 1
  // The candidates double up to this [-], >= min_substeps. A penalty contact's onset converges
  // at first order only, slowly: on CalculiX's block dropped onto a floor (fine reference, E
  // and the launch fitted over the landing and first rebound, frames 0-20, 16 cells) Young's
  // modulus came out -7.5 % at 16 substeps, +1.0 % at 32 and +0.2 % at 64, the fit's time
  // barely higher (64 s, 162 s, 77 s: Newton converges faster at the shorter step).
  int max_substeps = 64;
  // ... and while grid nodes x substeps stays within this [-], > 0: a fit keeps every step's
  // state for its adjoint, so this bounds its memory per frame (192,000 node-steps of 72 bytes:
  // 14 MB per frame). It is twice the 6,000-node grid limit at 16 substeps; the block above at 16
  // cells (1,620 nodes) may take 64 substeps, a 6,000-node grid 32.
  double max_node_steps_per_frame = 192000.0;
  // Accepted step-doubling difference: RMS over surface vertices of the distance between the
  // positions at s and 2 s substeps, maximised over the frames, as a fraction of the object's
  // longest side [-], > 0. Measured on torus-drop (28 cm, 60 fps, capture made at 16 substeps,
  // default Newmark gamma 0.6): 2 vs 4 substeps differ by 8.9 mm, 4 vs 8 by 0.62 mm, 8 vs 16 by
  // 0.38 mm; Young's modulus fitted at 4 substeps was 2.4-3.8 % off, at 2 substeps 33 %. 2e-3 L
  // (0.6 mm here, under a depth camera's noise) takes 8. (With gamma 1/2 the differences are 21,
  // 0.32 and 0.09 mm and 4 substeps give 0.2 %: see SimulationOptions::newmark_gamma.)
  double tolerance_fraction = 2e-3;
  // Wall time of the choice [s], >= 0; 0 = no limit. A halving of the step whose run would end
  // past it (twice the last run's time) is not simulated: the finest step run so far is taken,
  // and the selection says so.
  double max_seconds = 0.0;
  // Checked every simulation step; when set, selection stops with StatusCode::kCancelled.
  const std::atomic<bool>* cancel = nullptr;
};

struct SubstepTrial {
  int substeps = 0;           // s
  double difference_m = 0.0;  // max over frames of the RMS surface distance, s vs 2 s [m]
  int worst_frame = 0;        // where that maximum is
  // Leading frames whose difference is within the tolerance (every frame: the trial passed).
  int frames_within_tolerance = 0;
  // Leading frames in which this halving of the step shrank the difference of the previous one
  // to at most 3/4 or met the tolerance: where the motion converges with the step. Beyond them
  // no affordable step predicts it (contacts that converge too slowly, or later chaos). The
  // first trial: frames_within_tolerance.
  int frames_converging = 0;
  std::vector<double> per_frame_m;  // per frame 0..last: the RMS surface distance [m]
  bool diverged = false;            // either run failed
};

struct SubstepSelection {
  int substeps = 0;  // the choice
  // The largest candidate: max_substeps, or fewer on a large grid (max_node_steps_per_frame).
  int max_substeps = 0;
  double tolerance_m = 0.0;
  bool within_tolerance = false;  // false: max_substeps taken without meeting the tolerance
  // SubstepSelectionOptions::max_seconds ended the halving before max_substeps.
  bool stopped_at_time_limit = false;
  // False when the last halving of the step shrank the difference by less than a quarter, where
  // a step error halves at least (first order, in contact): an undamped block rocking on a floor
  // (7.4, 22 and 14 mm between 8/16, 16/32 and 32/64 substeps, docs/benchmarks.md) converges too
  // slowly for any affordable step, and turns chaotic later; no step makes its frames from
  // trials.back().frames_converging on predictable.
  bool converging = true;
  std::vector<SubstepTrial> trials;
  // A run's wall time per time step at the chosen step [s], measured (0: unknown, e.g. read back
  // from a checkpoint): a fit under a time limit scales its evaluations' cost from it.
  double seconds_per_step = 0.0;
};

// @param last_frame the last frame the fit compares (frames 0..last_frame are simulated).
// InvalidArgument for invalid options; parameters/simulation as for fem::Simulator.
Result<SubstepSelection> SelectSubsteps(const geometry::TriangleMesh& rest_mesh,
                                        const std::optional<Eigen::AlignedBox3d>& fixed_region,
                                        const fem::PhysicalParameters& parameters,
                                        const fem::SimulationOptions& simulation, double fps,
                                        int last_frame,
                                        const SubstepSelectionOptions& options = {});

// The last frame a fit should compare when `selection` found no affordable step that predicts the
// motion to the end: the last of the
// leading frames in which the last halving of the step still shrank the difference
// (trials.back().frames_converging), or -1 (every frame) when the last trial met the tolerance,
// the time limit ended the choice, fewer than two trials ran, every frame converges, or fewer than
// `min_converging_contact_frames` converge after those already within the tolerance (then not even
// the first impact converges, and the frames before it would not tell the fit anything).
int PredictableLastFrame(const SubstepSelection& selection, int last_frame,
                         int min_converging_contact_frames = 3);

// The largest candidate on a grid of `grid_nodes` nodes: the last of min_substeps x 2^k within
// options.max_substeps and within options.max_node_steps_per_frame / grid_nodes; never below
// min_substeps. Only doublings: each trial's difference estimates the coarser step's error,
// and its convergence frame by frame is judged against the previous halving's, so a last step
// short of double (32 vs 34 substeps: a difference 1/17 of the error) would pass frames as
// converging that are not.
int LargestSubstepCandidate(double grid_nodes, const SubstepSelectionOptions& options);

nlohmann::json ToJson(const SubstepSelection& selection);

}  // namespace softid::inverse
