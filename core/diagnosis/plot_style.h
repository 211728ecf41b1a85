// What every PNG plot of the diagnosis and the fit report shares: colours, text, the residual
// colour scale and saving. Internal to core/diagnosis (OpenCV types; no public header uses it).
#pragma once

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "core/common/status.h"

namespace softid::diagnosis::plot {

inline const cv::Scalar kBlack(0, 0, 0), kGrey(160, 160, 160), kWhite(255, 255, 255);
inline const cv::Scalar kUnmatched(255, 0, 255);
inline const cv::Scalar kColours[] = {cv::Scalar(200, 80, 0), cv::Scalar(0, 120, 230),
                                      cv::Scalar(40, 160, 40), cv::Scalar(180, 0, 180)};

// A residual of `noise_multiples` times the noise floor: blue at 0 -> green -> red at 3 and more.
inline cv::Scalar ResidualColour(double noise_multiples) {
  const double t = std::clamp(noise_multiples / 3.0, 0.0, 1.0);
  return t < 0.5 ? cv::Scalar(255 * (1 - 2 * t), 255 * 2 * t, 0)
                 : cv::Scalar(0, 255 * (2 - 2 * t), 255 * (2 * t - 1));
}

// The colour scale of ResidualColour as a 200-pixel bar at (x, y) with its labels.
inline void DrawResidualLegend(cv::Mat& image, int x, int y) {
  for (int i = 0; i < 200; ++i) {
    cv::line(image, {x + i, y}, {x + i, y + 10}, ResidualColour(3.0 * i / 199.0));
  }
  cv::putText(image, "0", {x - 6, y + 24}, cv::FONT_HERSHEY_SIMPLEX, 0.4, kBlack, 1, cv::LINE_AA);
  cv::putText(image, "3+ x noise floor  (magenta: unmatched)", {x + 210, y + 10},
              cv::FONT_HERSHEY_SIMPLEX, 0.4, kBlack, 1, cv::LINE_AA);
}

inline std::string Short(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.3g", v);
  return buffer;
}

inline void Text(cv::Mat& image, const std::string& text, cv::Point at, double scale = 0.45,
                 cv::Scalar colour = kBlack) {
  cv::putText(image, text, at, cv::FONT_HERSHEY_SIMPLEX, scale, colour, 1, cv::LINE_AA);
}

// Writes `image` as a PNG, creating the folder; IoError naming the path on failure.
inline Status Save(const std::filesystem::path& path, const cv::Mat& image) {
  std::error_code ec;
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path(), ec);
  try {
    if (!cv::imwrite(path.string(), image)) return Status::IoError("cannot write " + path.string());
  } catch (const cv::Exception& e) {
    return Status::IoError("cannot write " + path.string() + ": " + e.what());
  }
  return Status::Ok();
}

}  // namespace softid::diagnosis::plot
