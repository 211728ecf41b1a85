#include "core/diagnosis/time_step_error.h"

#include <Eigen/QR>
#include <algorithm>
#include <cmath>

namespace softid::diagnosis {
namespace {

// A point's place in the stacked vectors: frame k, index i.
struct PointRef {
  int frame = 0, index = 0;
};

// The points matched in every map.
std::vector<PointRef> CommonPoints(const ResidualMap& compared, const ResidualMap& finer,
                                   const std::vector<const ResidualMap*>& sensitivities) {
  std::vector<PointRef> out;
  auto matched = [](const ResidualMap& map, size_t k, size_t i) {
    return k < map.frames.size() && i < map.frames[k].matched.size() && map.frames[k].matched[i];
  };
  for (size_t k = 0; k < compared.frames.size(); ++k) {
    for (size_t i = 0; i < compared.frames[k].phi.size(); ++i) {
      bool all = matched(compared, k, i) && matched(finer, k, i);
      for (const ResidualMap* s : sensitivities) all = all && matched(*s, k, i);
      if (all) out.push_back({static_cast<int>(k), static_cast<int>(i)});
    }
  }
  return out;
}

double Phi(const ResidualMap& map, const PointRef& p) {
  return map.frames[p.frame].phi[p.index];
}

}  // namespace

TimeStepError EstimateTimeStepError(const ResidualMap& compared, const ResidualMap& finer,
                                    const Sensitivities* sensitivities, int substeps,
                                    int finer_substeps) {
  TimeStepError out;
  out.substeps = substeps;
  out.finer_substeps = finer_substeps;
  const double ratio = static_cast<double>(finer_substeps) / substeps;
  const double richardson = ratio / (ratio - 1.0);  // first order
  std::vector<const ResidualMap*> maps;
  if (sensitivities != nullptr && !sensitivities->moved.empty()) {
    maps.push_back(&sensitivities->at);
    for (const ResidualMap& m : sensitivities->moved) maps.push_back(&m);
  }
  const std::vector<PointRef> points = CommonPoints(compared, finer, maps);
  const Eigen::Index n = static_cast<Eigen::Index>(points.size());
  const Eigen::Index variables = maps.empty() ? 0 : static_cast<Eigen::Index>(maps.size()) - 1;
  Eigen::VectorXd change(n);
  Eigen::MatrixXd jacobian(n, variables);
  for (Eigen::Index j = 0; j < n; ++j) {
    change[j] = Phi(finer, points[j]) - Phi(compared, points[j]);
    for (Eigen::Index v = 0; v < variables; ++v) {
      jacobian(j, v) =
          (Phi(*maps[v + 1], points[j]) - Phi(*maps[0], points[j])) / sensitivities->step;
    }
  }
  Eigen::VectorXd left = change;
  if (n > jacobian.cols() && jacobian.cols() > 0)
    left -= jacobian * jacobian.colPivHouseholderQr().solve(change);
  if (n > 0) {
    out.change_m = std::sqrt(change.squaredNorm() / n);
    out.unabsorbed_m = std::sqrt(left.squaredNorm() / n);
  }
  out.point_m.resize(compared.frames.size());
  for (size_t k = 0; k < compared.frames.size(); ++k)
    out.point_m[k].assign(compared.frames[k].phi.size(), 0.0f);
  const int patches = compared.patches.size();
  std::vector<double> frame_sum(compared.frames.size(), 0.0), patch_sum(patches, 0.0);
  std::vector<long long> frame_n(compared.frames.size(), 0), patch_n(patches, 0);
  for (Eigen::Index j = 0; j < n; ++j) {
    const double e = richardson * left[j];
    out.point_m[points[j].frame][points[j].index] = static_cast<float>(e);
    const double e2 = e * e;
    frame_sum[points[j].frame] += e2;
    ++frame_n[points[j].frame];
    const int patch = compared.frames[points[j].frame].patch[points[j].index];
    if (patch >= 0 && patch < patches) {
      patch_sum[patch] += e2;
      ++patch_n[patch];
    }
  }
  for (size_t k = 0; k < frame_sum.size(); ++k)
    out.frame_m.push_back(frame_n[k] > 0 ? std::sqrt(frame_sum[k] / frame_n[k]) : 0.0);
  for (int p = 0; p < patches; ++p)
    out.patch_m.push_back(patch_n[p] > 0 ? std::sqrt(patch_sum[p] / patch_n[p]) : 0.0);
  return out;
}

ResidualMap WithoutTimeStepComponent(const ResidualMap& map, const TimeStepError& error,
                                     std::vector<double>* share) {
  ResidualMap out = map;
  if (share != nullptr) share->assign(map.frames.size(), 0.0);
  for (size_t k = 0; k < out.frames.size() && k < error.point_m.size(); ++k) {
    FrameResiduals& f = out.frames[k];
    const std::vector<float>& e = error.point_m[k];
    double re = 0.0, ee = 0.0, rr = 0.0;
    for (size_t i = 0; i < f.phi.size() && i < e.size(); ++i) {
      if (!f.matched[i]) continue;
      re += static_cast<double>(f.phi[i]) * e[i];
      ee += static_cast<double>(e[i]) * e[i];
      rr += static_cast<double>(f.phi[i]) * f.phi[i];
    }
    if (!(ee > 0.0) || !(rr > 0.0)) continue;
    // The amplitude is bounded: where the estimated error is tiny (round-off on a frame the finer
    // step barely changes), a free amplitude scales it up to absorb a real misfit along it.
    const double amplitude = std::clamp(re / ee, -kMaxStepErrorAmplitude, kMaxStepErrorAmplitude);
    for (size_t i = 0; i < f.phi.size() && i < e.size(); ++i)
      if (f.matched[i]) f.phi[i] -= static_cast<float>(amplitude * e[i]);
    const double removed =
        std::clamp((2.0 * amplitude * re - amplitude * amplitude * ee) / rr, 0.0, 1.0);
    f.cost *= 1.0 - removed;
    f.misfit = std::sqrt(2.0 * f.cost);
    if (share != nullptr) (*share)[k] = removed;
  }
  return out;
}

nlohmann::json ToJson(const TimeStepError& error) {
  return {{"substeps", error.substeps},
          {"finer_substeps", error.finer_substeps},
          {"method",
           "residual change at half the step, less what the base parameters absorb (least "
           "squares on their finite-difference sensitivities), x r / (r - 1) (Richardson, first "
           "order); its least-squares component (amplitude at most 2) removed from each frame's "
           "residuals"},
          {"change_m", error.change_m},
          {"unabsorbed_m", error.unabsorbed_m},
          {"frame_m", error.frame_m},
          {"patch_m", error.patch_m},
          {"frame_share_removed", error.frame_share}};
}

}  // namespace softid::diagnosis
