// Ray-cast depth images of triangle meshes (Embree), as an ideal depth camera would see them.
#pragma once

#include <memory>
#include <vector>

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

  // As above, only through the pixels listed (row-major indices, each in the image): the depth
  // seen through each, 0 where its ray misses. A few pixels of a large image cost their number,
  // not the image's size. Throws as Render, and std::invalid_argument for a pixel off the image.
  std::vector<float> RenderPixels(const geometry::TriangleMesh& mesh_W, const PinholeCamera& camera,
                                  const PixelRays& rays, const std::vector<int>& pixels) const;

 private:
  // Render's implementation: pinhole rays when `lens_rays` is null.
  DepthImage RenderRays(const geometry::TriangleMesh& mesh_W, const PinholeCamera& camera,
                        const PixelRays* lens_rays) const;

  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Depths of one rigid mesh seen from changing poses, through listed pixels: its scene is built
// once, in the mesh's own frame, and each call casts the pixels' rays moved into that frame (a
// rigid move keeps the depth along a ray). Following a body from frame to frame, a scene rebuilt
// for every pose cost more than its rays. Move-only; one per thread.
class RigidMeshRenderer {
 public:
  // mesh_S in its own frame [m]. Throws std::invalid_argument for a triangle index out of range
  // or a vertex that is not finite, std::runtime_error when Embree cannot create a device.
  explicit RigidMeshRenderer(const geometry::TriangleMesh& mesh_S);
  ~RigidMeshRenderer();
  RigidMeshRenderer(RigidMeshRenderer&&) noexcept;
  RigidMeshRenderer& operator=(RigidMeshRenderer&&) noexcept;
  RigidMeshRenderer(const RigidMeshRenderer&) = delete;
  RigidMeshRenderer& operator=(const RigidMeshRenderer&) = delete;

  // The depth along the camera's z axis seen through each listed pixel (row-major indices into
  // `rays`) with the mesh at pose X_CS in the camera's frame; 0 where the ray misses. Throws
  // std::invalid_argument for a pixel off the image.
  std::vector<float> RenderPixels(const Eigen::Isometry3d& X_CS, const PixelRays& rays,
                                  const std::vector<int>& pixels) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace softid::capture
