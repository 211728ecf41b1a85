#include "core/diagnosis/surface_overlay.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>

#include "core/diagnosis/plot_style.h"

namespace softid::diagnosis {
namespace {

constexpr int kPanel = 320;  // pixels per panel side
constexpr int kPad = 28;
constexpr int kLabel = 70;  // left column with the row names
constexpr int kLegend = 36;

// An orthographic view: world point -> (right, up, towards the viewer).
struct Projection {
  Eigen::Vector3d right, up, towards;
  Eigen::Vector3d Apply(const Eigen::Vector3d& p) const {
    return {right.dot(p), up.dot(p), towards.dot(p)};
  }
};

// The square region of the (right, up) plane every snapshot occupies in both views, shared so
// that the panels compare at one scale.
struct Window {
  double centre_x = 0.0, centre_y = 0.0, half = 1.0;  // [m]
  cv::Point Map(const Eigen::Vector3d& q, cv::Point origin) const {
    const double s = 0.5 * kPanel / half;
    return {origin.x + static_cast<int>(std::lround(0.5 * kPanel + s * (q.x() - centre_x))),
            origin.y + static_cast<int>(std::lround(0.5 * kPanel - s * (q.y() - centre_y)))};
  }
};

Window FitWindow(const std::vector<SurfaceSnapshot>& snapshots,
                 const std::vector<Projection>& views) {
  Eigen::Vector2d lo = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector2d hi = -lo;
  for (const Projection& view : views) {
    for (const SurfaceSnapshot& s : snapshots) {
      for (const auto* list : {&s.surface.vertices, &s.points}) {
        for (const Eigen::Vector3d& p : *list) {
          const Eigen::Vector3d q = view.Apply(p);
          lo = lo.cwiseMin(q.head<2>());
          hi = hi.cwiseMax(q.head<2>());
        }
      }
    }
  }
  Window window;
  if (!lo.allFinite() || !hi.allFinite()) return window;
  window.centre_x = 0.5 * (lo.x() + hi.x());
  window.centre_y = 0.5 * (lo.y() + hi.y());
  window.half = 0.55 * std::max({hi.x() - lo.x(), hi.y() - lo.y(), 1e-3});
  return window;
}

// The surface shaded by the light from the viewer, far triangles first (painter's algorithm).
void DrawSurface(cv::Mat& image, const geometry::TriangleMesh& surface, const Projection& view,
                 const Window& window, cv::Point origin) {
  std::vector<Eigen::Vector3d> q(surface.vertices.size());
  for (size_t i = 0; i < q.size(); ++i) q[i] = view.Apply(surface.vertices[i]);
  std::vector<int> order(surface.triangles.size());
  std::iota(order.begin(), order.end(), 0);
  const auto depth = [&](int t) {
    const Eigen::Vector3i& tri = surface.triangles[t];
    return q[tri[0]].z() + q[tri[1]].z() + q[tri[2]].z();
  };
  std::sort(order.begin(), order.end(), [&](int a, int b) { return depth(a) < depth(b); });
  for (int t : order) {
    const Eigen::Vector3i& tri = surface.triangles[t];
    const Eigen::Vector3d n = (q[tri[1]] - q[tri[0]]).cross(q[tri[2]] - q[tri[0]]);
    if (!(n.norm() > 0.0)) continue;
    const double shade = 150 + 90 * std::abs(n.z()) / n.norm();
    const cv::Point corners[3] = {window.Map(q[tri[0]], origin), window.Map(q[tri[1]], origin),
                                  window.Map(q[tri[2]], origin)};
    cv::fillConvexPoly(image, corners, 3, cv::Scalar(shade, shade, shade), cv::LINE_AA);
  }
}

// Where the ground plane n . p = offset cuts the view plane through the window's centre.
void DrawGround(cv::Mat& image, const fem::GroundPlane& ground, const Projection& view,
                const Window& window, cv::Point origin) {
  const double n_up = ground.normal.dot(view.up);
  if (std::abs(n_up) < 1e-6) return;
  const Eigen::Vector3d centre = window.centre_x * view.right + window.centre_y * view.up;
  std::vector<cv::Point> ends;
  for (double s : {-2.0 * window.half, 2.0 * window.half}) {
    const Eigen::Vector3d along = centre + s * view.right;
    const double t = (ground.offset - ground.normal.dot(along)) / n_up;
    ends.push_back(window.Map(view.Apply(along + t * view.up), origin));
  }
  if (cv::clipLine(cv::Rect(origin.x, origin.y, kPanel, kPanel), ends[0], ends[1]))
    cv::line(image, ends[0], ends[1], cv::Scalar(60, 120, 60), 2, cv::LINE_AA);
}

void DrawPoints(cv::Mat& image, const SurfaceSnapshot& s, const Projection& view,
                const Window& window, cv::Point origin, double noise_floor_m) {
  for (size_t i = 0; i < s.points.size(); ++i) {
    const cv::Scalar colour =
        s.matched[i] ? plot::ResidualColour(std::abs(s.phi[i]) / noise_floor_m) : plot::kUnmatched;
    cv::circle(image, window.Map(view.Apply(s.points[i]), origin), 1, colour, cv::FILLED);
  }
}

}  // namespace

Status WriteSurfaceOverlay(const std::filesystem::path& path,
                           const std::vector<SurfaceSnapshot>& snapshots,
                           const SurfaceOverlayView& view) {
  if (snapshots.empty()) return Status::InvalidArgument("surface overlay: no snapshot");
  if (!(view.noise_floor_m > 0.0)) {
    return Status::InvalidArgument(
        "surface overlay: noise_floor_m = " + std::to_string(view.noise_floor_m) + ": must be > 0");
  }
  for (const SurfaceSnapshot& s : snapshots) {
    if (s.phi.size() != s.points.size() || s.matched.size() != s.points.size()) {
      return Status::InvalidArgument("surface overlay: frame " + std::to_string(s.frame) +
                                     " has residuals for other points than it has");
    }
  }
  const Eigen::Vector3d up = view.up_W.normalized();
  const Eigen::Vector3d front = (view.front_W - view.front_W.dot(up) * up).normalized();
  // Front: looking along `front`, so the viewer is at -front; side: turned 90 degrees about up.
  const Projection front_view{up.cross(-front), up, -front};
  const Eigen::Vector3d side_sight = up.cross(front);
  const Projection side_view{up.cross(-side_sight), up, -side_sight};
  const std::vector<Projection> views = {front_view, side_view};
  const Window window = FitWindow(snapshots, views);
  const int columns = static_cast<int>(snapshots.size());
  cv::Mat image(kPad + 2 * (kPanel + kPad) + kLegend, kLabel + columns * (kPanel + kPad), CV_8UC3,
                plot::kWhite);
  const char* row_names[] = {"front", "side"};
  for (int r = 0; r < 2; ++r) {
    const int y0 = kPad + r * (kPanel + kPad);
    plot::Text(image, row_names[r], {8, y0 + kPanel / 2}, 0.55);
    for (int c = 0; c < columns; ++c) {
      const SurfaceSnapshot& s = snapshots[c];
      const cv::Point origin(kLabel + c * (kPanel + kPad), y0);
      cv::rectangle(image, cv::Rect(origin.x, origin.y, kPanel, kPanel), cv::Scalar(248, 248, 248),
                    cv::FILLED);
      if (view.ground) DrawGround(image, *view.ground, views[r], window, origin);
      DrawSurface(image, s.surface, views[r], window, origin);
      DrawPoints(image, s, views[r], window, origin, view.noise_floor_m);
      cv::rectangle(image, cv::Rect(origin.x, origin.y, kPanel, kPanel), plot::kGrey, 1);
      if (r == 0) {
        plot::Text(image,
                   "frame " + std::to_string(s.frame) + "  t = " + plot::Short(s.time_s) + " s",
                   {origin.x, origin.y - 8}, 0.5);
      }
    }
  }
  const double scale_m = 2.0 * window.half;
  plot::Text(image, "panel width " + plot::Short(100.0 * scale_m) + " cm; grey: simulated surface",
             {kLabel, image.rows - kLegend - 2}, 0.4);
  plot::DrawResidualLegend(image, kLabel, image.rows - kLegend + 8);
  return plot::Save(path, image);
}

}  // namespace softid::diagnosis
