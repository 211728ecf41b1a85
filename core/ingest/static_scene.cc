#include "core/ingest/static_scene.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <map>

#include "core/common/for_each_index.h"

namespace softid::ingest {

double MedianSigma(const StaticScene& scene) {
  std::vector<float> sigmas = scene.sigma_m;
  std::erase(sigmas, 0.0f);
  if (sigmas.empty()) return 1e-4;
  std::nth_element(sigmas.begin(), sigmas.begin() + sigmas.size() / 2, sigmas.end());
  return std::max<double>(sigmas[sigmas.size() / 2], 1e-4);
}
namespace {

float Median(std::vector<float>& values) {
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  return values[mid];
}

constexpr double kDepthBinRatio = 1.03;  // depth bins 3 % wide
constexpr size_t kMinPixelsPerBin = 20;

int DepthBin(float z) {
  return static_cast<int>(std::floor(std::log(z) / std::log(kDepthBinRatio)));
}

// A pixel seen behind the object in few frames has a sigma from few readings, often far too
// small. The sensor's noise depends on depth: each pixel's sigma is raised to the median sigma of
// the pixels at its depth (bins 3 % wide, at least 20 pixels each).
void FloorSigmaByDepth(StaticScene* scene) {
  std::map<int, std::vector<float>> bins;
  for (size_t p = 0; p < scene->depth_m.size(); ++p) {
    if (scene->depth_m[p] > 0.0f) bins[DepthBin(scene->depth_m[p])].push_back(scene->sigma_m[p]);
  }
  std::map<int, float> floor;
  for (auto& [bin, sigmas] : bins) {
    if (sigmas.size() >= kMinPixelsPerBin) floor[bin] = Median(sigmas);
  }
  for (size_t p = 0; p < scene->depth_m.size(); ++p) {
    if (scene->depth_m[p] <= 0.0f) continue;
    const auto it = floor.find(DepthBin(scene->depth_m[p]));
    if (it != floor.end()) scene->sigma_m[p] = std::max(scene->sigma_m[p], it->second);
  }
}

// Per pixel p in [begin, end): the farthest window of cluster_width_m holding min_readings
// readings (a lone reading far behind, a flying pixel, is skipped rather than taken for the
// scene); its median is the depth and 1.4826 times its median absolute deviation the sigma.
// The median of readings[first, last) (sorted, descending) and the median of their absolute
// deviations from it, each the element Median() would take (index count / 2 in ascending order),
// without copying or partitioning: the deviations grow outward from the median on both sides, so
// the two sides merge in order.
void SortedMedianAndDeviation(const std::vector<float>& readings, size_t first, size_t last,
                              float* median, float* deviation) {
  const size_t rank = (last - first) / 2;
  const size_t at = last - 1 - rank;  // ascending index `rank` of a descending run
  *median = readings[at];
  *deviation = 0.0f;                 // the median's own
  size_t farther = at, nearer = at;  // the sides' last merged readings
  constexpr float kNone = std::numeric_limits<float>::infinity();
  for (size_t k = 0; k < rank; ++k) {
    const float up = farther > first ? readings[farther - 1] - *median : kNone;
    const float down = nearer + 1 < last ? *median - readings[nearer + 1] : kNone;
    if (up <= down) {
      *deviation = up;
      --farther;
    } else {
      *deviation = down;
      ++nearer;
    }
  }
}

// Per pixel p in [begin, end): the farthest window of cluster_width_m holding min_readings
// readings (a lone reading far behind, a flying pixel, is skipped rather than taken for the
// scene); its median is the depth and 1.4826 times its median absolute deviation the sigma.
void FarthestClusters(const std::vector<capture::DepthImage>& images,
                      const StaticSceneOptions& options, size_t begin, size_t end,
                      StaticScene* scene) {
  const size_t min_count = static_cast<size_t>(options.min_readings);
  std::vector<float> readings;
  readings.reserve(images.size());
  for (size_t p = begin; p < end; ++p) {
    readings.clear();
    for (const capture::DepthImage& image : images) {
      if (image.depth[p] > 0.0f) readings.push_back(image.depth[p]);
    }
    std::sort(readings.begin(), readings.end(), std::greater<float>());
    size_t last = 0;
    for (size_t first = 0; first < readings.size(); ++first) {
      last = std::max(last, first);
      while (last < readings.size() && readings[first] - readings[last] <= options.cluster_width_m)
        ++last;
      if (last - first < min_count) continue;
      float deviation = 0.0f;
      SortedMedianAndDeviation(readings, first, last, &scene->depth_m[p], &deviation);
      scene->sigma_m[p] = 1.4826f * deviation;
      break;
    }
  }
}

}  // namespace

Status StaticSceneOptions::Validate() const {
  if (!(cluster_width_m > 0.0) || !std::isfinite(cluster_width_m)) {
    return Status::InvalidArgument(
        fmt::format("cluster_width_m = {}: must be positive", cluster_width_m));
  }
  if (min_readings < 1) {
    return Status::InvalidArgument(fmt::format("min_readings = {}: must be >= 1", min_readings));
  }
  if (!(min_height_above_floor_m >= 0.0) || !std::isfinite(min_height_above_floor_m)) {
    return Status::InvalidArgument(
        fmt::format("min_height_above_floor_m = {}: must be >= 0", min_height_above_floor_m));
  }
  if (threads < 0)
    return Status::InvalidArgument(fmt::format("threads = {}: must be >= 0", threads));
  return Status::Ok();
}

Result<StaticScene> EstimateStaticScene(const std::vector<capture::DepthImage>& images,
                                        const StaticSceneOptions& options) {
  SOFTID_RETURN_IF_ERROR(options.Validate());
  if (images.empty()) return Status::InvalidArgument("static scene: no images");
  StaticScene scene;
  scene.width = images.front().width;
  scene.height = images.front().height;
  const size_t pixels = static_cast<size_t>(scene.width) * scene.height;
  for (size_t i = 0; i < images.size(); ++i) {
    if (images[i].width != scene.width || images[i].height != scene.height ||
        images[i].depth.size() != pixels) {
      return Status::InvalidArgument(
          fmt::format("static scene: image {} is {}x{}, image 0 is {}x{}", i, images[i].width,
                      images[i].height, scene.width, scene.height));
    }
  }
  scene.depth_m.assign(pixels, 0.0f);
  scene.sigma_m.assign(pixels, 0.0f);
  // Rows in bands, a band per task: each pixel's readings are sorted on their own (the dearest
  // part of an ingest's static scene: 64 frames of 640 x 480), so bands run side by side.
  constexpr int kRowsPerBand = 16;
  const int bands = (scene.height + kRowsPerBand - 1) / kRowsPerBand;
  ForEachIndex(bands, options.threads > 0 ? options.threads : CoreCount(), [&](size_t band) {
    const int first_row = static_cast<int>(band) * kRowsPerBand;
    const size_t begin = static_cast<size_t>(first_row) * scene.width;
    const size_t end =
        static_cast<size_t>(std::min(scene.height, first_row + kRowsPerBand)) * scene.width;
    FarthestClusters(images, options, begin, end, &scene);
  });
  FloorSigmaByDepth(&scene);
  return scene;
}

namespace {

// Per 3 % depth bin (at least 20 pixels): the median over the bin's pixels of the sample variance
// of all their readings, divided by the median of chi-square / dof for the pixel's count
// (Wilson-Hilferty), so that it estimates the variance itself.
std::map<int, float> NoiseByDepth(const std::vector<capture::DepthImage>& images,
                                  const StaticScene& scene) {
  std::map<int, std::vector<float>> variances;
  for (size_t p = 0; p < scene.depth_m.size(); ++p) {
    if (scene.depth_m[p] <= 0.0f) continue;
    double sum = 0.0, squares = 0.0;
    int count = 0;
    for (const capture::DepthImage& image : images) {
      const double z = image.depth[p];
      if (z <= 0.0) continue;
      sum += z;
      squares += z * z;
      ++count;
    }
    if (count < 2) continue;
    const int dof = count - 1;
    const double variance = std::max(0.0, (squares - sum * sum / count) / dof);
    const double median_ratio = std::pow(1.0 - 2.0 / (9.0 * dof), 3);
    variances[DepthBin(scene.depth_m[p])].push_back(static_cast<float>(variance / median_ratio));
  }
  std::map<int, float> sigma;
  for (auto& [bin, values] : variances) {
    if (values.size() >= kMinPixelsPerBin) sigma[bin] = std::sqrt(Median(values));
  }
  return sigma;
}

}  // namespace

Result<StaticScene> EstimateEmptyScene(const std::vector<capture::DepthImage>& images,
                                       const StaticSceneOptions& options) {
  SOFTID_ASSIGN_OR_RETURN(StaticScene scene, EstimateStaticScene(images, options));
  const std::map<int, float> noise = NoiseByDepth(images, scene);
  std::vector<float> readings, cluster;
  for (size_t p = 0; p < scene.depth_m.size(); ++p) {
    if (scene.depth_m[p] <= 0.0f) continue;
    const auto it = noise.find(DepthBin(scene.depth_m[p]));
    if (it == noise.end()) continue;
    const double window_m = 4.0 * it->second;
    if (window_m > options.cluster_width_m) {
      readings.clear();
      for (const capture::DepthImage& image : images) {
        if (image.depth[p] > 0.0f) readings.push_back(image.depth[p]);
      }
      // All readings are the scene: their median, and the readings within 2 sigma of it.
      const float centre = Median(readings);
      cluster.clear();
      for (const float z : readings) {
        if (std::abs(z - centre) <= 0.5 * window_m) cluster.push_back(z);
      }
      scene.depth_m[p] = Median(cluster);
    }
    scene.sigma_m[p] = std::max(scene.sigma_m[p], it->second);
  }
  return scene;
}

void MarkHiddenByTheObject(const std::vector<int>& first_object_pixels,
                           const Eigen::Vector3d& floor_normal_C, double floor_offset_m,
                           const capture::PixelRays& rays, const StaticSceneOptions& options,
                           StaticScene* scene) {
  scene->maybe_object.assign(scene->depth_m.size(), 0);
  for (const int p : first_object_pixels) {
    const float z = scene->depth_m[p];
    if (z <= 0.0f) continue;
    const Eigen::Vector3d point = z * Eigen::Vector3d(rays.xy[p].x(), rays.xy[p].y(), 1.0);
    if (floor_normal_C.dot(point) - floor_offset_m > options.min_height_above_floor_m)
      scene->maybe_object[p] = 1;
  }
}

void StaticScenePoints(const StaticScene& scene, const capture::PixelRays& rays,
                       std::vector<Eigen::Vector3d>* points_C, std::vector<float>* sigmas_m) {
  points_C->clear();
  sigmas_m->clear();
  for (int row = 0; row < scene.height; ++row) {
    for (int col = 0; col < scene.width; ++col) {
      const float z = scene.depth(col, row);
      if (z <= 0.0f) continue;
      const Eigen::Vector2d& xy = rays.at(col, row);
      points_C->push_back(z * Eigen::Vector3d(xy.x(), xy.y(), 1.0));
      sigmas_m->push_back(scene.sigma(col, row));
    }
  }
}

}  // namespace softid::ingest
