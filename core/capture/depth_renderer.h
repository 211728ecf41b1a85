// Ray-cast depth images of triangle meshes (Embree), as an ideal depth camera would see them.
#pragma once

#include <memory>

#include "core/capture/camera.h"
#include "core/capture/depth_image.h"
#include "core/capture/pixel_rays.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::capture {

// Renders noise-free depth images by casting one ray per pixel centre. Owns an Embree device.
// Triangles are hit from both sides (no backface culling), so open meshes and meshes with holes
// render correctly. Use one renderer per thread; move-only.
class DepthRenderer {
 public:
  // Throws std::runtime_error when Embree cannot create a device.
  DepthRenderer();
  ~DepthRenderer();
  DepthRenderer(DepthRenderer&&) noexcept;
  DepthRenderer& operator=(DepthRenderer&&) noexcept;
  DepthRenderer(const DepthRenderer&) = delete;
  DepthRenderer& operator=(const DepthRenderer&) = delete;

  // Depth along the camera z axis [m] of the first surface of mesh_W (world frame, metres) hit by
  // the ray through each pixel centre (col, row); 0 where the ray misses. The image has the
  // camera's size. Vertices are transformed to the camera frame in double precision before
  // casting, so accuracy does not degrade far from the world origin. An empty mesh renders as all
  // zeros. Throws std::invalid_argument when the camera is invalid, a triangle index is out of
  // range or a vertex is not finite.
  DepthImage Render(const geometry::TriangleMesh& mesh_W, const PinholeCamera& camera) const;

  // As above through a real lens: the ray of pixel (col, row) has direction (x, y, 1) in the
  // camera frame for rays.at(col, row) = (x, y) (pixel_rays.h). Renders what a camera with lens
  // distortion records. Throws std::invalid_argument when `rays` is not of the camera's size.
  DepthImage Render(const geometry::TriangleMesh& mesh_W, const PinholeCamera& camera,
                    const PixelRays& rays) const;

 private:
  // Render's implementation: pinhole rays when `lens_rays` is null.
  DepthImage RenderRays(const geometry::TriangleMesh& mesh_W, const PinholeCamera& camera,
                        const PixelRays* lens_rays) const;

  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace softid::capture
