#include "core/diagnosis/motion_phases.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/common/json_fields.h"

namespace softid::diagnosis {

const char* ToString(Phase phase) {
  switch (phase) {
    case Phase::kFlight: return "flight";
    case Phase::kImpact: return "impact";
    case Phase::kSliding: return "sliding";
    case Phase::kRest: return "rest";
    case Phase::kRebound: return "rebound";
  }
  return "?";
}

Status MotionPhaseOptions::Validate() const {
  if (!(contact_cells > 0.0) || !std::isfinite(contact_cells))
    return json::Invalid("phases.contact_cells", contact_cells, "must be positive");
  if (!(rest_speed_fraction > 0.0) || !std::isfinite(rest_speed_fraction))
    return json::Invalid("phases.rest_speed_fraction", rest_speed_fraction, "must be positive");
  return Status::Ok();
}

Result<std::vector<FrameMotion>> SplitMotionPhases(fem::Simulator& sim,
                                                   const fem::PhysicalParameters& parameters,
                                                   const std::vector<FrameAt>& frames,
                                                   const MotionPhaseOptions& options,
                                                   const FrameVisitor& visit) {
  SOFTID_RETURN_IF_ERROR(options.Validate());
  try {
    sim.SetParameters(parameters);
  } catch (const std::invalid_argument& e) {
    return Status::InvalidArgument(e.what());
  }
  const double h = sim.hex_mesh().CellSize();
  const double still = options.rest_speed_fraction *
                       std::sqrt(parameters.gravity.norm() * sim.characteristic_length());
  std::vector<FrameMotion> out;
  int64_t step = 0;
  bool was_in_contact = false;
  bool contact_seen = false;
  const double time_step = sim.options().time_step;
  for (const FrameAt& frame : frames) {
    const int64_t frame_step = std::llround(frame.time_s / time_step);
    for (; step < frame_step; ++step) {
      if (sim.Step().diverged || !sim.state().u.allFinite()) {
        return Status::FailedPrecondition("the simulation diverged at step " +
                                          std::to_string(step + 1) + ": no motion phases");
      }
    }
    if (visit) visit(out.size(), sim);
    FrameMotion m;
    m.frame = frame.frame;
    m.time = frame.time_s;
    const Eigen::Vector3d v = sim.CentreOfMassVelocity();
    m.speed = v.norm();
    m.ground_distance = std::numeric_limits<double>::infinity();
    if (parameters.ground) {
      const Eigen::Vector3d& n = parameters.ground->normal;
      for (const Eigen::Vector3d& p : sim.SurfacePositions())
        m.ground_distance = std::min(m.ground_distance, parameters.ground->SignedDistance(p));
      m.normal_speed = v.dot(n);
      m.tangential_speed = (v - v.dot(n) * n).norm();
    } else {
      m.tangential_speed = m.speed;
    }
    const bool contact = m.ground_distance < options.contact_cells * h;
    if (!contact) {
      m.phase = contact_seen ? Phase::kRebound : Phase::kFlight;
    } else if (!was_in_contact || std::abs(m.normal_speed) > still) {
      m.phase = Phase::kImpact;
    } else if (m.tangential_speed > still) {
      m.phase = Phase::kSliding;
    } else {
      m.phase = Phase::kRest;
    }
    was_in_contact = contact;
    contact_seen |= contact;
    out.push_back(m);
  }
  return out;
}

}  // namespace softid::diagnosis
