#include "core/diagnosis/plots.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/diagnosis/plot_style.h"

namespace softid::diagnosis {
namespace {

using plot::kBlack;
using plot::kColours;
using plot::kGrey;
using plot::kWhite;
using plot::Save;
using plot::Short;
using plot::Text;

// A plot frame mapping data (x, y) to pixels; y optionally logarithmic.
struct Axes {
  cv::Rect area;
  double x0, x1, y0, y1;
  bool log_y = false;
  cv::Point Map(double x, double y) const {
    if (log_y) y = std::log10(std::max(y, 1e-300));
    const double u = (x - x0) / std::max(x1 - x0, 1e-300);
    const double v = (y - y0) / std::max(y1 - y0, 1e-300);
    return {area.x + static_cast<int>(u * area.width),
            area.y + area.height - static_cast<int>(v * area.height)};
  }
  void Draw(cv::Mat& image, const std::string& x_label, const std::string& y_label) const {
    cv::rectangle(image, area, kBlack, 1);
    auto y_text = [&](double y) { return log_y ? "1e" + Short(y) : Short(y); };
    Text(image, Short(x0), {area.x - 5, area.y + area.height + 18});
    Text(image, Short(x1), {area.x + area.width - 20, area.y + area.height + 18});
    Text(image, y_text(y0), {5, area.y + area.height});
    Text(image, y_text(y1), {5, area.y + 12});
    Text(image, x_label, {area.x + area.width / 2 - 30, area.y + area.height + 36});
    Text(image, y_label, {5, area.y - 10});
  }
};

void DrawLine(cv::Mat& image, const Axes& axes, const std::vector<double>& x,
              const std::vector<double>& y, cv::Scalar colour) {
  for (size_t i = 1; i < x.size() && i < y.size(); ++i) {
    if (!std::isfinite(y[i - 1]) || !std::isfinite(y[i])) continue;
    cv::line(image, axes.Map(x[i - 1], y[i - 1]), axes.Map(x[i], y[i]), colour, 2, cv::LINE_AA);
  }
}

}  // namespace

Status WriteFrameMisfitPlot(const std::filesystem::path& path, const std::vector<int>& frames,
                            const std::vector<double>& before, const std::vector<double>& after,
                            const std::vector<FrameMotion>& motion, double threshold,
                            const std::string& before_label,
                            const std::vector<double>& as_compared) {
  cv::Mat image(440, 760, CV_8UC3, kWhite);
  if (frames.empty()) return Save(path, image);
  double top = threshold * 1.2;
  for (double v : as_compared) top = std::max(top, v);
  for (double v : before) top = std::max(top, v);
  for (double v : after) top = std::max(top, v);
  Axes axes{cv::Rect(70, 40, 660, 320), double(frames.front()),
            double(std::max(frames.back(), frames.front() + 1)), 0.0, top * 1.05};
  // Phase bands.
  const cv::Scalar phase_tint[] = {cv::Scalar(250, 245, 235), cv::Scalar(215, 215, 255),
                                   cv::Scalar(215, 245, 215), cv::Scalar(235, 235, 235),
                                   cv::Scalar(245, 230, 250)};
  for (size_t k = 0; k < frames.size() && k < motion.size(); ++k) {
    const double half = 0.5;
    cv::Point a = axes.Map(frames[k] - half, axes.y1), b = axes.Map(frames[k] + half, 0.0);
    a.x = std::max(a.x, axes.area.x);
    b.x = std::min(b.x, axes.area.x + axes.area.width);
    cv::rectangle(image, cv::Rect(a, b), phase_tint[static_cast<int>(motion[k].phase)], cv::FILLED);
  }
  for (int ph = 0; ph < kNumPhases; ++ph) {
    cv::rectangle(image, cv::Rect(350 + 80 * ph, 8, 14, 14), phase_tint[ph], cv::FILLED);
    cv::rectangle(image, cv::Rect(350 + 80 * ph, 8, 14, 14), kGrey, 1);
    Text(image, ToString(static_cast<Phase>(ph)), {368 + 80 * ph, 20}, 0.4);
  }
  // Threshold, dashed.
  for (double x = axes.x0; x < axes.x1; x += (axes.x1 - axes.x0) / 60.0) {
    cv::line(image, axes.Map(x, threshold), axes.Map(x + (axes.x1 - axes.x0) / 120.0, threshold),
             kGrey, 1);
  }
  std::vector<double> x(frames.begin(), frames.end());
  if (!as_compared.empty()) {
    DrawLine(image, axes, x, as_compared, kGrey);
    Text(image, "with the compared time step's error", {250, 428}, 0.45, kGrey);
  }
  DrawLine(image, axes, x, before, kColours[0]);
  Text(image, before_label, {80, 428}, 0.45, kColours[0]);
  if (!after.empty()) {
    DrawLine(image, axes, x, after, kColours[2]);
    Text(image, "after", {160, 428}, 0.45, kColours[2]);
  }
  axes.Draw(image, "frame", "misfit / noise floor");
  return Save(path, image);
}

Status WriteCostHistoryPlot(const std::filesystem::path& path, const std::vector<Series>& series) {
  cv::Mat image(440, 760, CV_8UC3, kWhite);
  double x1 = 1.0, lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (const Series& s : series) {
    for (size_t i = 0; i < s.y.size(); ++i) {
      if (!(s.y[i] > 0.0)) continue;
      x1 = std::max(x1, s.x[i]);
      lo = std::min(lo, std::log10(s.y[i]));
      hi = std::max(hi, std::log10(s.y[i]));
    }
  }
  if (!std::isfinite(lo)) lo = -6, hi = -5;
  if (hi - lo < 0.1) hi += 0.05, lo -= 0.05;
  Axes axes{cv::Rect(70, 40, 660, 320), 0.0, x1, lo, hi, true};
  for (size_t i = 0; i < series.size(); ++i) {
    const cv::Scalar colour = kColours[i % 4];
    DrawLine(image, axes, series[i].x, series[i].y, colour);
    Text(image, series[i].label, {80 + 170 * static_cast<int>(i % 4), 428}, 0.45, colour);
  }
  axes.Draw(image, "iteration", "cost [m^2]");
  return Save(path, image);
}

Status WriteResidualPainting(const std::filesystem::path& path, const capture::Capture& capture,
                             const Observations& observations, int k,
                             const std::vector<std::pair<std::string, const ResidualMap*>>& rows,
                             double sigma) {
  const int cameras = capture.NumCameras();
  if (cameras == 0 || rows.empty() || k < 0 || k >= static_cast<int>(observations.frames.size()))
    return Status::InvalidArgument("residual painting: nothing to paint");
  int cell_w = 0, cell_h = 0;
  for (const auto& rec : capture.cameras) {
    cell_w = std::max(cell_w, rec.camera.width);
    cell_h = std::max(cell_h, rec.camera.height);
  }
  // Upscale small depth images to ~240 px so that the pixels can be seen.
  const int zoom = std::max(1, 240 / std::max(cell_w, cell_h));
  const int pad = 24;
  const int legend = 30;
  cv::Mat image(static_cast<int>(rows.size()) * (cell_h * zoom + pad) + pad + legend,
                cameras * (cell_w * zoom + pad) + 90, CV_8UC3, kWhite);
  const inverse::ObservedFrame& frame = observations.frames[k];
  const std::vector<int>& offsets = observations.camera_offsets[k];
  for (size_t r = 0; r < rows.size(); ++r) {
    const FrameResiduals& residuals = rows[r].second->frames[k];
    const int y0 = pad + static_cast<int>(r) * (cell_h * zoom + pad);
    Text(image, rows[r].first, {5, y0 + cell_h * zoom / 2}, 0.5);
    for (int c = 0; c < cameras; ++c) {
      const capture::PinholeCamera& camera = capture.cameras[c].camera;
      const int x0 = 90 + c * (cell_w * zoom + pad);
      cv::rectangle(image, cv::Rect(x0, y0, camera.width * zoom, camera.height * zoom),
                    cv::Scalar(235, 235, 235), cv::FILLED);
      if (r == 0) Text(image, camera.name, {x0, y0 - 6}, 0.45);
      for (int i = offsets[c]; i < offsets[c + 1]; ++i) {
        const std::optional<Eigen::Vector2d> uv = camera.Project(frame.points[i]);
        if (!uv) continue;
        const int col = static_cast<int>(std::lround((*uv)[0]));
        const int row = static_cast<int>(std::lround((*uv)[1]));
        if (col < 0 || row < 0 || col >= camera.width || row >= camera.height) continue;
        const cv::Scalar colour = residuals.matched[i]
                                      ? plot::ResidualColour(std::abs(residuals.phi[i]) / sigma)
                                      : plot::kUnmatched;
        cv::rectangle(image, cv::Rect(x0 + col * zoom, y0 + row * zoom, zoom, zoom), colour,
                      cv::FILLED);
      }
    }
  }
  plot::DrawResidualLegend(image, 90, image.rows - legend + 8);
  Text(image, "frame " + std::to_string(frame.frame), {5, 16}, 0.5);
  return Save(path, image);
}

}  // namespace softid::diagnosis
