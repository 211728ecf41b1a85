// A raw depth recording in memory for the ingest's tests: a ball arcing past a floor, a wall and a
// static box, seen through a distorted lens with depth noise, with the true masks of the ball.
#pragma once

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "core/capture/depth_renderer.h"
#include "core/capture/pixel_rays.h"
#include "core/geometry/primitives.h"

namespace softid::ingest::testing {

using capture::DepthImage;

inline geometry::TriangleMesh Moved(geometry::TriangleMesh mesh, const Eigen::Vector3d& offset) {
  for (Eigen::Vector3d& v : mesh.vertices) v += offset;
  return mesh;
}

inline geometry::TriangleMesh Merged(const std::vector<geometry::TriangleMesh>& parts) {
  geometry::TriangleMesh out;
  for (const geometry::TriangleMesh& part : parts) {
    const int base = static_cast<int>(out.vertices.size());
    out.vertices.insert(out.vertices.end(), part.vertices.begin(), part.vertices.end());
    for (const Eigen::Vector3i& t : part.triangles)
      out.triangles.push_back(t + Eigen::Vector3i::Constant(base));
  }
  return out;
}

struct RawScene {
  capture::PinholeCamera camera;
  capture::PixelRays rays;
  std::vector<DepthImage> frames, background;
  std::vector<std::vector<uint8_t>> true_masks;
};

// 40 frames of a 6 cm ball arcing over the floor in front of a wall, beside a static 10 cm box;
// depth noise 1.5 mm + 0.2 % of depth, stored in 1 mm units (a 16-bit PNG's quantum).
inline RawScene MakeRawScene() {
  RawScene s;
  s.camera.name = "cam0";
  s.camera.width = 160;
  s.camera.height = 120;
  s.camera.fx = s.camera.fy = 140.0;
  s.camera.cx = 79.5;
  s.camera.cy = 59.5;
  s.camera.X_WC = capture::LookAt(Eigen::Vector3d(0.0, -1.2, 0.7), Eigen::Vector3d(0.0, 0.0, 0.15));
  s.rays = *capture::ComputePixelRays(s.camera, {-0.12, 0.03, 0.0005, -0.0003, 0.0});
  const geometry::TriangleMesh floor =
      Moved(geometry::MakeBox(Eigen::Vector3d(3.0, 3.0, 0.1), 0.5), Eigen::Vector3d(0, 0, -0.05));
  const geometry::TriangleMesh wall =
      Moved(geometry::MakeBox(Eigen::Vector3d(3.0, 0.1, 2.0), 0.5), Eigen::Vector3d(0, 0.8, 1.0));
  const geometry::TriangleMesh box = Moved(geometry::MakeBox(Eigen::Vector3d(0.1, 0.1, 0.1), 0.05),
                                           Eigen::Vector3d(0.3, 0.1, 0.05));
  const geometry::TriangleMesh statics = Merged({floor, wall, box});
  const geometry::TriangleMesh ball = geometry::MakeSphere(0.06, 3);
  const capture::DepthRenderer renderer;
  std::mt19937 rng(5);
  std::normal_distribution<float> unit(0.0f, 1.0f);
  auto noisy = [&](DepthImage image) {
    for (float& z : image.depth) {
      if (z > 0.0f) z = std::round((z + (0.0015f + 0.002f * z) * unit(rng)) * 1000.0f) / 1000.0f;
    }
    return image;
  };
  for (int k = 0; k < 40; ++k) {
    const double t = k / 30.0;
    const Eigen::Vector3d centre(-0.5 + 0.7 * t, -0.1, 0.5 + 1.0 * t - 4.9 * t * t);
    const geometry::TriangleMesh ball_k =
        Moved(ball, Eigen::Vector3d(centre.x(), centre.y(), std::max(0.06, centre.z())));
    const DepthImage only_ball = renderer.Render(ball_k, s.camera, s.rays);
    const DepthImage only_scene = renderer.Render(statics, s.camera, s.rays);
    std::vector<uint8_t> mask(only_ball.depth.size(), 0);
    for (size_t p = 0; p < mask.size(); ++p) {
      const float b = only_ball.depth[p], z = only_scene.depth[p];
      mask[p] = b > 0.0f && (z == 0.0f || b < z);
    }
    s.true_masks.push_back(std::move(mask));
    s.frames.push_back(noisy(renderer.Render(Merged({statics, ball_k}), s.camera, s.rays)));
    if (k < 8) s.background.push_back(noisy(only_scene));
  }
  return s;
}

}  // namespace softid::ingest::testing
