#include "core/capture/depth_renderer.h"

#include <embree3/rtcore.h>
#include <fmt/format.h>

#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/common/check.h"

namespace softid::capture {

struct DepthRenderer::Impl {
  RTCDevice device = nullptr;
  // Whether this Embree build culls back faces; then every triangle is added with both windings.
  bool backface_culling = false;
  ~Impl() {
    if (device != nullptr) rtcReleaseDevice(device);
  }
};

namespace {

// Releases an Embree scene on scope exit.
struct SceneHandle {
  RTCScene scene = nullptr;
  ~SceneHandle() {
    if (scene != nullptr) rtcReleaseScene(scene);
  }
};

void ThrowOnDeviceError(RTCDevice device, const char* what) {
  const RTCError error = rtcGetDeviceError(device);
  if (error != RTC_ERROR_NONE) {
    throw std::runtime_error(
        fmt::format("DepthRenderer: Embree error {} in {}", static_cast<int>(error), what));
  }
}

void CheckTriangleIndices(const geometry::TriangleMesh& mesh_W) {
  const int num_vertices = static_cast<int>(mesh_W.vertices.size());
  for (const Eigen::Vector3i& t : mesh_W.triangles) {
    SOFTID_THROW_UNLESS(t.minCoeff() >= 0 && t.maxCoeff() < num_vertices,
                        "DepthRenderer::Render: triangle vertex index out of range");
  }
}

// Attaches mesh_W to `scene` as one triangle geometry in the camera frame (vertices transformed in
// double precision); with back-face culling every triangle is added with both windings.
void AttachMeshInCameraFrame(RTCDevice device, bool backface_culling,
                             const geometry::TriangleMesh& mesh_W, const PinholeCamera& camera,
                             RTCScene scene) {
  const int num_vertices = static_cast<int>(mesh_W.vertices.size());
  RTCGeometry geometry = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vertices_C = static_cast<float*>(rtcSetNewGeometryBuffer(
      geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), num_vertices));
  const size_t num_triangles = mesh_W.triangles.size() * (backface_culling ? 2 : 1);
  auto* indices = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
      geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), num_triangles));
  if (vertices_C == nullptr || indices == nullptr) {
    rtcReleaseGeometry(geometry);
    ThrowOnDeviceError(device, "rtcSetNewGeometryBuffer");
    throw std::runtime_error("DepthRenderer: cannot allocate Embree buffers");
  }
  const Eigen::Isometry3d X_CW = camera.X_WC.inverse();
  for (int i = 0; i < num_vertices; ++i) {
    const Eigen::Vector3d p_C = X_CW * mesh_W.vertices[i];
    if (!p_C.allFinite()) {
      rtcReleaseGeometry(geometry);
      SOFTID_THROW_UNLESS(false, "DepthRenderer::Render: vertex is not finite");
    }
    for (int k = 0; k < 3; ++k) vertices_C[3 * i + k] = static_cast<float>(p_C[k]);
  }
  size_t j = 0;
  for (const Eigen::Vector3i& t : mesh_W.triangles) {
    for (int k = 0; k < 3; ++k) indices[j++] = static_cast<unsigned>(t[k]);
    if (backface_culling) {  // the reversed winding faces the other way
      indices[j++] = static_cast<unsigned>(t[0]);
      indices[j++] = static_cast<unsigned>(t[2]);
      indices[j++] = static_cast<unsigned>(t[1]);
    }
  }
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(scene, geometry);
  rtcReleaseGeometry(geometry);
}

// Ray from the camera centre with direction (x, y, 1) in C: the hit distance t (in units of the
// direction) is then the depth along the camera z axis.
void SetRay(const Eigen::Vector3d& dir_C, unsigned id, RTCRayHit* ray_hit) {
  ray_hit->ray.org_x = ray_hit->ray.org_y = ray_hit->ray.org_z = 0.0f;
  ray_hit->ray.dir_x = static_cast<float>(dir_C.x());
  ray_hit->ray.dir_y = static_cast<float>(dir_C.y());
  ray_hit->ray.dir_z = 1.0f;
  ray_hit->ray.tnear = 0.0f;
  ray_hit->ray.tfar = std::numeric_limits<float>::infinity();
  ray_hit->ray.time = 0.0f;
  ray_hit->ray.mask = std::numeric_limits<unsigned>::max();
  ray_hit->ray.id = id;
  ray_hit->ray.flags = 0;
  ray_hit->hit.geomID = RTC_INVALID_GEOMETRY_ID;
  ray_hit->hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
}

// mesh_W added to `scene` in the camera's frame, committed.
void BuildScene(RTCDevice device, bool backface_culling, const geometry::TriangleMesh& mesh_W,
                const PinholeCamera& camera, RTCScene scene) {
  CheckTriangleIndices(mesh_W);
  rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_LOW);  // one build per frame
  AttachMeshInCameraFrame(device, backface_culling, mesh_W, camera, scene);
  rtcCommitScene(scene);
  ThrowOnDeviceError(device, "rtcCommitScene");
}

Eigen::Vector3d RayDirection_C(const PinholeCamera& camera, const PixelRays* lens_rays, int col,
                               int row) {
  return lens_rays == nullptr
             ? camera.RayDirection_C(col, row)
             : Eigen::Vector3d(lens_rays->at(col, row).x(), lens_rays->at(col, row).y(), 1.0);
}

// Casts one ray per listed pixel through `scene`, in streams of 256 (Embree's stream API traces
// them as packets); set_ray(i, &hit) sets the i-th listed pixel's ray, its direction's z in the
// camera's frame 1. The depth seen through each (the hit distance), 0 where the ray misses.
template <typename SetRayOfPixel>
std::vector<float> TraceListedPixels(RTCScene scene, size_t count, const SetRayOfPixel& set_ray) {
  std::vector<float> depth(count, 0.0f);
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  constexpr size_t kStream = 256;
  std::vector<RTCRayHit> hits(std::min(kStream, count));
  for (size_t first = 0; first < count; first += kStream) {
    const size_t n = std::min(kStream, count - first);
    for (size_t i = 0; i < n; ++i) {
      set_ray(first + i, &hits[i]);
      hits[i].ray.id = static_cast<unsigned>(i);
    }
    rtcIntersect1M(scene, &context, hits.data(), static_cast<unsigned>(n), sizeof(RTCRayHit));
    for (size_t i = 0; i < n; ++i) {
      if (hits[i].hit.geomID != RTC_INVALID_GEOMETRY_ID) depth[first + i] = hits[i].ray.tfar;
    }
  }
  return depth;
}

// Throws std::invalid_argument naming `who` when a listed pixel lies off a width x height image.
void CheckPixelsInImage(const std::vector<int>& pixels, int width, int height, const char* who) {
  const int count = width * height;
  for (const int p : pixels) {
    SOFTID_THROW_UNLESS(p >= 0 && p < count, fmt::format("{}: pixel off the image", who));
  }
}

}  // namespace

DepthRenderer::DepthRenderer() : impl_(std::make_unique<Impl>()) {
  impl_->device = rtcNewDevice("verbose=0");
  if (impl_->device == nullptr) {
    throw std::runtime_error(fmt::format("DepthRenderer: cannot create an Embree device (error {})",
                                         static_cast<int>(rtcGetDeviceError(nullptr))));
  }
  impl_->backface_culling =
      rtcGetDeviceProperty(impl_->device, RTC_DEVICE_PROPERTY_BACKFACE_CULLING_ENABLED) != 0;
}

DepthRenderer::~DepthRenderer() = default;
DepthRenderer::DepthRenderer(DepthRenderer&&) noexcept = default;
DepthRenderer& DepthRenderer::operator=(DepthRenderer&&) noexcept = default;

DepthImage DepthRenderer::Render(const geometry::TriangleMesh& mesh_W,
                                 const PinholeCamera& camera) const {
  return RenderRays(mesh_W, camera, nullptr);
}

DepthImage DepthRenderer::Render(const geometry::TriangleMesh& mesh_W, const PinholeCamera& camera,
                                 const PixelRays& rays) const {
  SOFTID_THROW_UNLESS(rays.width == camera.width && rays.height == camera.height &&
                          rays.xy.size() == static_cast<size_t>(camera.width) * camera.height,
                      "DepthRenderer::Render: the pixel rays must have the camera's size");
  return RenderRays(mesh_W, camera, &rays);
}

DepthImage DepthRenderer::RenderRays(const geometry::TriangleMesh& mesh_W,
                                     const PinholeCamera& camera,
                                     const PixelRays* lens_rays) const {
  SOFTID_THROW_UNLESS(impl_ != nullptr, "DepthRenderer::Render on a moved-from renderer");
  const Status camera_valid = camera.Validate();
  SOFTID_THROW_UNLESS(camera_valid.ok(), camera_valid.message());
  DepthImage image = DepthImage::Zeros(camera.width, camera.height);
  if (mesh_W.vertices.empty() || mesh_W.triangles.empty()) return image;
  SceneHandle scene{rtcNewScene(impl_->device)};
  BuildScene(impl_->device, impl_->backface_culling, mesh_W, camera, scene.scene);

  // One coherent stream of rays per image row (Embree's stream API traces them as packets).
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  std::vector<RTCRayHit> rays(static_cast<size_t>(camera.width));
  for (int row = 0; row < camera.height; ++row) {
    for (int col = 0; col < camera.width; ++col) {
      SetRay(RayDirection_C(camera, lens_rays, col, row), static_cast<unsigned>(col), &rays[col]);
    }
    rtcIntersect1M(scene.scene, &context, rays.data(), static_cast<unsigned>(rays.size()),
                   sizeof(RTCRayHit));
    for (int col = 0; col < camera.width; ++col) {
      if (rays[col].hit.geomID != RTC_INVALID_GEOMETRY_ID) image.at(col, row) = rays[col].ray.tfar;
    }
  }
  return image;
}

std::vector<float> DepthRenderer::RenderPixels(const geometry::TriangleMesh& mesh_W,
                                               const PinholeCamera& camera,
                                               const PixelRays& lens_rays,
                                               const std::vector<int>& pixels) const {
  SOFTID_THROW_UNLESS(impl_ != nullptr, "DepthRenderer::RenderPixels on a moved-from renderer");
  const Status camera_valid = camera.Validate();
  SOFTID_THROW_UNLESS(camera_valid.ok(), camera_valid.message());
  SOFTID_THROW_UNLESS(lens_rays.width == camera.width && lens_rays.height == camera.height &&
                          lens_rays.xy.size() == static_cast<size_t>(camera.width) * camera.height,
                      "DepthRenderer::RenderPixels: the pixel rays must have the camera's size");
  CheckPixelsInImage(pixels, camera.width, camera.height, "DepthRenderer::RenderPixels");
  if (mesh_W.vertices.empty() || mesh_W.triangles.empty() || pixels.empty())
    return std::vector<float>(pixels.size(), 0.0f);
  SceneHandle scene{rtcNewScene(impl_->device)};
  BuildScene(impl_->device, impl_->backface_culling, mesh_W, camera, scene.scene);
  return TraceListedPixels(scene.scene, pixels.size(), [&](size_t i, RTCRayHit* hit) {
    const int p = pixels[i];
    SetRay(RayDirection_C(camera, &lens_rays, p % camera.width, p / camera.width), 0, hit);
  });
}

struct RigidMeshRenderer::Impl {
  // Released in reverse order: the scene before its device.
  struct Device {
    RTCDevice device = nullptr;
    bool backface_culling = false;
    ~Device() {
      if (device != nullptr) rtcReleaseDevice(device);
    }
  } device;
  SceneHandle scene;
};

RigidMeshRenderer::RigidMeshRenderer(const geometry::TriangleMesh& mesh_S)
    : impl_(std::make_unique<Impl>()) {
  impl_->device.device = rtcNewDevice("verbose=0");
  if (impl_->device.device == nullptr) {
    throw std::runtime_error(
        fmt::format("RigidMeshRenderer: cannot create an Embree device (error {})",
                    static_cast<int>(rtcGetDeviceError(nullptr))));
  }
  impl_->device.backface_culling =
      rtcGetDeviceProperty(impl_->device.device, RTC_DEVICE_PROPERTY_BACKFACE_CULLING_ENABLED) != 0;
  impl_->scene.scene = rtcNewScene(impl_->device.device);
  if (mesh_S.vertices.empty() || mesh_S.triangles.empty()) {
    rtcCommitScene(impl_->scene.scene);
    return;
  }
  PinholeCamera identity;  // the mesh's own frame stands in for the camera's
  BuildScene(impl_->device.device, impl_->device.backface_culling, mesh_S, identity,
             impl_->scene.scene);
}

RigidMeshRenderer::~RigidMeshRenderer() = default;
RigidMeshRenderer::RigidMeshRenderer(RigidMeshRenderer&&) noexcept = default;
RigidMeshRenderer& RigidMeshRenderer::operator=(RigidMeshRenderer&&) noexcept = default;

std::vector<float> RigidMeshRenderer::RenderPixels(const Eigen::Isometry3d& X_CS,
                                                   const PixelRays& rays,
                                                   const std::vector<int>& pixels) const {
  SOFTID_THROW_UNLESS(impl_ != nullptr, "RigidMeshRenderer::RenderPixels on a moved-from renderer");
  CheckPixelsInImage(pixels, rays.width, rays.height, "RigidMeshRenderer::RenderPixels");
  // Rays from the camera's centre, in the mesh's frame: origin X_SC * 0, direction R_SC (x, y, 1);
  // t in units of the direction, whose z in the camera's frame is 1, is the depth.
  const Eigen::Isometry3d X_SC = X_CS.inverse();
  const Eigen::Vector3f origin_S = X_SC.translation().cast<float>();
  return TraceListedPixels(impl_->scene.scene, pixels.size(), [&](size_t i, RTCRayHit* hit) {
    const Eigen::Vector2d& xy = rays.xy[pixels[i]];
    const Eigen::Vector3d dir_S = X_SC.linear() * Eigen::Vector3d(xy.x(), xy.y(), 1.0);
    SetRay(dir_S, 0, hit);
    hit->ray.org_x = origin_S.x();
    hit->ray.org_y = origin_S.y();
    hit->ray.org_z = origin_S.z();
    hit->ray.dir_z = static_cast<float>(dir_S.z());
  });
}

}  // namespace softid::capture
