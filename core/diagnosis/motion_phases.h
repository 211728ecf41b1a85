// The phases of the motion, read off the simulated trajectory at the fitted parameters: flight (no
// contact, before the first contact), impact (contact while the body moves into or out of the
// ground), sliding (contact while it moves along the ground), rest (contact, almost still),
// rebound (no contact, after a contact: a bounce). Missing physics shows in particular phases
// (friction while sliding, drag in flight, a stiffness contrast in the bounce, ...), so residuals
// are summarised per phase.
//
// Why rebound is its own phase: before the first contact only the release state, gravity and
// drag act; after it the body carries what the impact gave it (rebound speed, a turn from halves
// that push back unequally). Lumped into one flight phase, a misfit confined to the bounce is
// averaged with the frames before the drop, which by construction cannot show it, and the
// per-phase test compares unlike regimes (a 2x stiffness contrast: 1.5x the floor in the bounce,
// 1.2x over all flight frames). The threshold and the other phases are unchanged.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/fem/physical_parameters.h"
#include "core/fem/simulator.h"

namespace softid::diagnosis {

enum class Phase { kFlight, kImpact, kSliding, kRest, kRebound };
inline constexpr int kNumPhases = 5;
// "flight" | "impact" | "sliding" | "rest" | "rebound".
const char* ToString(Phase phase);

struct MotionPhaseOptions {
  // In contact when the lowest surface point is within this many grid cells of the ground [-]:
  // penalty contact lets the surface sink a little, and the surface is resolved to about a cell.
  double contact_cells = 0.5;  // > 0
  // Speeds below rest_speed_fraction sqrt(|g| L) count as still [-] (L the body size; 5 % of the
  // speed of a fall from its own height).
  double rest_speed_fraction = 0.05;  // > 0
  Status Validate() const;
};

struct FrameMotion {
  int frame = 0;
  double time = 0.0;              // [s]
  double ground_distance = 0.0;   // lowest surface point above the ground [m] (inf: no ground)
  double normal_speed = 0.0;      // centre-of-mass velocity along the ground normal [m/s]
  double tangential_speed = 0.0;  // along the ground [m/s]
  double speed = 0.0;             // [m/s]
  Phase phase = Phase::kFlight;
};

// A capture frame and the time it shows [s].
struct FrameAt {
  int frame = 0;
  double time_s = 0.0;
};

// Called at each of the frames (its index into `frames`) with the simulator at that frame's step:
// lets a caller read other things off the same run (a report's surfaces) instead of simulating
// again.
using FrameVisitor = std::function<void(size_t index, const fem::Simulator& simulator)>;

// Simulates `parameters` on `simulator` (which it resets) up to the last of `frames` (ascending
// times; each classified at the simulation step nearest its time, with the simulator's own time
// step), and classifies each frame. FailedPrecondition when the simulation diverges.
Result<std::vector<FrameMotion>> SplitMotionPhases(fem::Simulator& simulator,
                                                   const fem::PhysicalParameters& parameters,
                                                   const std::vector<FrameAt>& frames,
                                                   const MotionPhaseOptions& options = {},
                                                   const FrameVisitor& visit = {});

}  // namespace softid::diagnosis
