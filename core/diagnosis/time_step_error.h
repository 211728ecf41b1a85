// How much of a misfit the comparison's own time step makes: the diagnosis compares its models on
// a coarse step (DiagnoseOptions::comparison_substeps), and an impact resolved by 4 substeps per
// frame moves the simulated surface by millimetres, many times the depth noise. That misfit is no
// evidence of missing physics: no candidate removes it, and calling it "unexplained" blames the
// recording for the comparison's step.
//
// Per observed point, the change of its residual when the same model runs at half the step,
// d = phi_half - phi, less the part the base model's own parameters absorb (the least-squares
// fit of d by their sensitivities J, finite differences at the compared step: a coarse step's
// numerical damping looks like a stiffer damping, which a refit takes up), times r / (r - 1) with
// r = 2 (Richardson, first order: the integrator is first order in time, inverse/
// discretisation_error.h): e = (d - J delta) r / (r - 1).
//
// WithoutTimeStepComponent removes from each frame's residuals their component along e (one
// amplitude per frame, least squares, bounded by kMaxStepErrorAmplitude): what is left is the
// misfit no step error explains, which localization.h then flags. The bound matters where e is
// round-off (a frame the finer step barely changes, e ~ 1e-11 m): a free amplitude of 1e6 would
// scale that noise up until it took a real effect's misfit with it (air drag's slow lag was
// half removed so). The extrapolation is first order, so a true amplitude far from 1 means e is
// not the step's error. A projection only lowers a misfit, so it cannot invent one where
// the extrapolation is poor, and a missing effect whose pattern differs from the step's error
// (a stiffness contrast tilting the body, friction holding it back) keeps its misfit.
#pragma once

#include <nlohmann/json.hpp>
#include <vector>

#include "core/diagnosis/residual_map.h"

namespace softid::diagnosis {

// The largest factor by which WithoutTimeStepComponent scales the estimated error e [-].
inline constexpr double kMaxStepErrorAmplitude = 2.0;

struct TimeStepError {
  int substeps = 0;        // the compared time step [substeps per frame]
  int finer_substeps = 0;  // the run it was compared with
  // RMS of d over every point, and of what the base parameters leave of it [m].
  double change_m = 0.0, unabsorbed_m = 0.0;
  std::vector<double> frame_m;  // per observed frame: RMS of e [m]
  std::vector<double> patch_m;  // per patch, over every frame [m]
  // e per frame and point, aligned with the map (0 where a run did not match the point) [m].
  std::vector<std::vector<float>> point_m;
  // Per observed frame: the share of the base fit's misfit^2 (matched points) along e [-], in
  // [0, 1]; the diagnosis fills it from WithoutTimeStepComponent's `share`.
  std::vector<double> frame_share;
};

// The base parameters' sensitivities at the compared step: the map at the base variables x0, and
// per variable the map with it moved to x0 + step (optimiser units).
struct Sensitivities {
  ResidualMap at;
  std::vector<ResidualMap> moved;
  double step = 1.0;  // > 0
};

// @param sensitivities null or without `moved`: nothing is absorbed.
// @pre every map holds the same frames and points in the same order (runs of one objective's
//   observations), finer_substeps > substeps > 0.
TimeStepError EstimateTimeStepError(const ResidualMap& compared, const ResidualMap& finer,
                                    const Sensitivities* sensitivities, int substeps,
                                    int finer_substeps);

// `map` with each frame's residuals less their least-squares component along error.point_m, the
// frame's cost scaled by the share left (of its matched points' squared residuals). `share`, when
// given, receives per frame the share removed.
ResidualMap WithoutTimeStepComponent(const ResidualMap& map, const TimeStepError& error,
                                     std::vector<double>* share = nullptr);

nlohmann::json ToJson(const TimeStepError& error);

}  // namespace softid::diagnosis
