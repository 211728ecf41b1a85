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

  CheckTriangleIndices(mesh_W);
  RTCDevice device = impl_->device;
  SceneHandle scene{rtcNewScene(device)};
  rtcSetSceneFlags(scene.scene, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(scene.scene, RTC_BUILD_QUALITY_LOW);  // one build per frame
  AttachMeshInCameraFrame(device, impl_->backface_culling, mesh_W, camera, scene.scene);
  rtcCommitScene(scene.scene);
  ThrowOnDeviceError(device, "rtcCommitScene");

  // One coherent stream of rays per image row (Embree's stream API traces them as packets).
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  std::vector<RTCRayHit> rays(static_cast<size_t>(camera.width));
  for (int row = 0; row < camera.height; ++row) {
    for (int col = 0; col < camera.width; ++col) {
      // Ray from the camera centre with direction (x, y, 1) in C: the hit distance t (in units of
      // the direction) is then the depth along the camera z axis.
      const Eigen::Vector3d dir_C =
          lens_rays == nullptr
              ? camera.RayDirection_C(col, row)
              : Eigen::Vector3d(lens_rays->at(col, row).x(), lens_rays->at(col, row).y(), 1.0);
      RTCRayHit& ray_hit = rays[col];
      ray_hit.ray.org_x = ray_hit.ray.org_y = ray_hit.ray.org_z = 0.0f;
      ray_hit.ray.dir_x = static_cast<float>(dir_C.x());
      ray_hit.ray.dir_y = static_cast<float>(dir_C.y());
      ray_hit.ray.dir_z = 1.0f;
      ray_hit.ray.tnear = 0.0f;
      ray_hit.ray.tfar = std::numeric_limits<float>::infinity();
      ray_hit.ray.time = 0.0f;
      ray_hit.ray.mask = std::numeric_limits<unsigned>::max();
      ray_hit.ray.id = static_cast<unsigned>(col);
      ray_hit.ray.flags = 0;
      ray_hit.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      ray_hit.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    }
    rtcIntersect1M(scene.scene, &context, rays.data(), static_cast<unsigned>(rays.size()),
                   sizeof(RTCRayHit));
    for (int col = 0; col < camera.width; ++col) {
      if (rays[col].hit.geomID != RTC_INVALID_GEOMETRY_ID) image.at(col, row) = rays[col].ray.tfar;
    }
  }
  return image;
}

}  // namespace softid::capture
