#include "core/diagnosis/residual_map.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/capture/depth_image.h"
#include "core/common/json_fields.h"

namespace softid::diagnosis {

Result<Observations> LoadObservations(const capture::Capture& capture, int first, int last,
                                      int heldout_every) {
  const int num_frames = capture.NumFrames();
  if (last < 0) last = num_frames - 1;
  if (first < 0 || first >= num_frames) {
    return json::Invalid("frames.first", first,
                         "must lie in [0, " + std::to_string(num_frames - 1) + "]");
  }
  if (last < first || last >= num_frames) {
    return json::Invalid("frames.last", last,
                         "must lie in [frames.first, " + std::to_string(num_frames - 1) + "]");
  }
  Observations out;
  for (int k = first; k <= last; ++k) {
    inverse::ObservedFrame frame;
    frame.frame = k;
    frame.time = capture.FrameTime(k);
    // Same rule as JobConfig::IsHeldOut.
    frame.heldout = heldout_every >= 2 && (k - first + 1) % heldout_every == 0;
    std::vector<int> offsets = {0};
    for (int c = 0; c < capture.NumCameras(); ++c) {
      SOFTID_ASSIGN_OR_RETURN(capture::DepthImage image, capture::LoadFrame(capture, c, k));
      const std::vector<Eigen::Vector3d> points =
          capture::DepthToWorldPoints(image, capture.cameras[c].camera);
      frame.points.insert(frame.points.end(), points.begin(), points.end());
      offsets.push_back(static_cast<int>(frame.points.size()));
    }
    out.frames.push_back(std::move(frame));
    out.camera_offsets.push_back(std::move(offsets));
  }
  return out;
}

int Patches::Assign(const Eigen::Vector3d& X) const {
  int best = -1;
  double best_d = std::numeric_limits<double>::infinity();
  for (size_t p = 0; p < centres.size(); ++p) {
    const double d = (centres[p] - X).squaredNorm();
    if (d < best_d) {
      best_d = d;
      best = static_cast<int>(p);
    }
  }
  return best;
}

Patches MakePatches(const geometry::TriangleMesh& rest_surface, int count,
                    const Eigen::Vector3d& up) {
  Patches out;
  const std::vector<Eigen::Vector3d>& v = rest_surface.vertices;
  if (v.empty() || count < 1) return out;
  count = std::min<int>(count, static_cast<int>(v.size()));
  // Farthest-point seeding from the vertex farthest from the centroid: deterministic and spread.
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& p : v) centroid += p;
  centroid /= static_cast<double>(v.size());
  std::vector<double> distance(v.size(), std::numeric_limits<double>::infinity());
  size_t seed = 0;
  for (size_t i = 0; i < v.size(); ++i)
    if ((v[i] - centroid).squaredNorm() > (v[seed] - centroid).squaredNorm()) seed = i;
  out.centres.push_back(v[seed]);
  while (static_cast<int>(out.centres.size()) < count) {
    size_t far = 0;
    for (size_t i = 0; i < v.size(); ++i) {
      distance[i] = std::min(distance[i], (v[i] - out.centres.back()).squaredNorm());
      if (distance[i] > distance[far]) far = i;
    }
    out.centres.push_back(v[far]);
  }
  // Lloyd iterations.
  std::vector<int> label(v.size(), 0);
  for (int iteration = 0; iteration < 20; ++iteration) {
    bool changed = false;
    for (size_t i = 0; i < v.size(); ++i) {
      const int p = out.Assign(v[i]);
      changed |= p != label[i];
      label[i] = p;
    }
    std::vector<Eigen::Vector3d> sum(out.centres.size(), Eigen::Vector3d::Zero());
    std::vector<int> n(out.centres.size(), 0);
    for (size_t i = 0; i < v.size(); ++i) {
      sum[label[i]] += v[i];
      ++n[label[i]];
    }
    for (size_t p = 0; p < out.centres.size(); ++p)
      if (n[p] > 0) out.centres[p] = sum[p] / n[p];
    if (!changed && iteration > 0) break;
  }
  // Labels: the side of the body centre each patch lies on, relative to the body's extent.
  const Eigen::AlignedBox3d bounds = rest_surface.Bounds();
  const Eigen::Vector3d half = 0.5 * bounds.sizes().cwiseMax(1e-12);
  const Eigen::Vector3d u = up.normalized();
  for (const Eigen::Vector3d& c : out.centres) {
    const Eigen::Vector3d d = (c - bounds.center()).cwiseQuotient(half);
    std::string label_text;
    const char* axes = "xyz";
    for (int a = 0; a < 3; ++a) {
      if (std::abs(u[a]) > 0.9) continue;  // the vertical is said as top/bottom
      if (std::abs(d[a]) > 0.35) label_text += std::string(d[a] > 0 ? "+" : "-") + axes[a] + " ";
    }
    const double vertical = (c - bounds.center()).dot(u) / half.dot(u.cwiseAbs());
    label_text += vertical > 0.35 ? "top" : vertical < -0.35 ? "bottom" : "side";
    out.labels.push_back(label_text);
  }
  return out;
}

ResidualMap BuildResidualMap(const Observations& observations,
                             const std::vector<std::vector<cost::PointMatch>>& matches,
                             const Patches& patches, double truncation) {
  ResidualMap map;
  map.patches = patches;
  map.truncation = truncation;
  for (size_t k = 0; k < observations.frames.size(); ++k) {
    const inverse::ObservedFrame& in = observations.frames[k];
    FrameResiduals f;
    f.frame = in.frame;
    f.time = in.time;
    f.heldout = in.heldout;
    const std::vector<cost::PointMatch>& m = matches.at(k);
    f.phi.resize(m.size());
    f.patch.resize(m.size());
    f.matched.resize(m.size());
    double sum = 0.0;
    for (size_t i = 0; i < m.size(); ++i) {
      f.matched[i] = m[i].matched;
      f.phi[i] = static_cast<float>(m[i].matched ? m[i].phi : truncation);
      f.patch[i] = m[i].matched ? patches.Assign(m[i].rest_position) : -1;
      sum += m[i].cost;
    }
    f.cost = m.empty() ? 0.0 : sum / m.size();
    f.misfit = std::sqrt(2.0 * f.cost);
    map.frames.push_back(std::move(f));
  }
  return map;
}

std::vector<std::vector<double>> FittedResiduals(const ResidualMap& map) {
  std::vector<std::vector<double>> out;
  for (const FrameResiduals& f : map.frames) {
    if (f.heldout) continue;
    std::vector<double> r;
    for (size_t i = 0; i < f.phi.size(); ++i)
      if (f.matched[i]) r.push_back(f.phi[i]);
    out.push_back(std::move(r));
  }
  return out;
}

}  // namespace softid::diagnosis
