#include "core/geometry/mesh_distance.h"

#include <embree3/rtcore.h>

#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include "core/common/check.h"
#include "core/geometry/closest_point.h"

namespace softid::geometry {
namespace {

// Per-query state handed to the Embree callback.
struct QueryState {
  const TriangleMesh* mesh;
  Eigen::Vector3d p;
  ClosestPoint best;
  double best_distance_sq;
  float slack;  // absolute radius margin for the float rounding of the query point and bounds [m]
};

bool ClosestPointCallback(RTCPointQueryFunctionArguments* args) {
  QueryState& state = *static_cast<QueryState*>(args->userPtr);
  const Eigen::Vector3i& t = state.mesh->triangles[args->primID];
  const Eigen::Vector3d q = ClosestPointOnTriangle(
      state.p, state.mesh->vertices[t[0]], state.mesh->vertices[t[1]], state.mesh->vertices[t[2]]);
  const double distance_sq = (q - state.p).squaredNorm();
  if (distance_sq >= state.best_distance_sq) return false;
  state.best_distance_sq = distance_sq;
  state.best.point = q;
  state.best.triangle = static_cast<int>(args->primID);
  // Shrink the search sphere, rounded up so float bounds never cull an equally close triangle.
  args->query->radius = static_cast<float>(std::sqrt(distance_sq)) * (1.0f + 1e-6f) + state.slack;
  return true;
}

std::string EmbreeErrorText(RTCError error) {
  switch (error) {
    case RTC_ERROR_NONE: return "none";
    case RTC_ERROR_INVALID_ARGUMENT: return "invalid argument";
    case RTC_ERROR_INVALID_OPERATION: return "invalid operation";
    case RTC_ERROR_OUT_OF_MEMORY: return "out of memory";
    case RTC_ERROR_UNSUPPORTED_CPU: return "unsupported CPU";
    case RTC_ERROR_CANCELLED: return "cancelled";
    default: return "unknown error";
  }
}

}  // namespace

struct MeshDistance::Impl {
  TriangleMesh mesh;
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  ~Impl() {
    if (scene != nullptr) rtcReleaseScene(scene);
    if (device != nullptr) rtcReleaseDevice(device);
  }
};

Status ValidateTriangleMesh(const TriangleMesh& mesh) {
  if (mesh.triangles.empty()) return Status::InvalidArgument("mesh: has no triangles");
  const int n = static_cast<int>(mesh.vertices.size());
  for (size_t v = 0; v < mesh.vertices.size(); ++v) {
    if (!mesh.vertices[v].allFinite()) {
      return Status::InvalidArgument("mesh: vertex " + std::to_string(v) +
                                     " has non-finite coordinates");
    }
  }
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Eigen::Vector3i& tri = mesh.triangles[t];
    if ((tri.array() < 0).any() || (tri.array() >= n).any()) {
      return Status::InvalidArgument("mesh: triangle " + std::to_string(t) + " = (" +
                                     std::to_string(tri[0]) + ", " + std::to_string(tri[1]) + ", " +
                                     std::to_string(tri[2]) + "): index out of range [0, " +
                                     std::to_string(n) + ")");
    }
  }
  return Status::Ok();
}

Result<MeshDistance> MeshDistance::Create(const TriangleMesh& mesh) {
  SOFTID_RETURN_IF_ERROR(ValidateTriangleMesh(mesh));
  auto impl = std::make_unique<Impl>();
  impl->mesh = mesh;
  impl->device = rtcNewDevice(nullptr);
  if (impl->device == nullptr) {
    return Status::Internal("Embree: cannot create device: " +
                            EmbreeErrorText(rtcGetDeviceError(nullptr)));
  }
  impl->scene = rtcNewScene(impl->device);
  rtcSetSceneBuildQuality(impl->scene, RTC_BUILD_QUALITY_HIGH);
  RTCGeometry geometry = rtcNewGeometry(impl->device, RTC_GEOMETRY_TYPE_TRIANGLE);
  const size_t num_vertices = mesh.vertices.size(), num_triangles = mesh.triangles.size();
  auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(
      geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), num_vertices));
  auto* indices = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
      geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), num_triangles));
  if (vertices == nullptr || indices == nullptr) {
    rtcReleaseGeometry(geometry);
    return Status::Internal("Embree: cannot allocate buffers: " +
                            EmbreeErrorText(rtcGetDeviceError(impl->device)));
  }
  for (size_t v = 0; v < num_vertices; ++v) {
    for (int a = 0; a < 3; ++a) vertices[3 * v + a] = static_cast<float>(mesh.vertices[v][a]);
  }
  for (size_t t = 0; t < num_triangles; ++t) {
    for (int a = 0; a < 3; ++a) indices[3 * t + a] = static_cast<unsigned>(mesh.triangles[t][a]);
  }
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(impl->scene, geometry);
  rtcReleaseGeometry(geometry);
  rtcCommitScene(impl->scene);
  const RTCError error = rtcGetDeviceError(impl->device);
  if (error != RTC_ERROR_NONE) {
    return Status::Internal("Embree: scene build failed: " + EmbreeErrorText(error));
  }
  return MeshDistance(std::move(impl));
}

MeshDistance::MeshDistance(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
MeshDistance::MeshDistance(MeshDistance&&) noexcept = default;
MeshDistance& MeshDistance::operator=(MeshDistance&&) noexcept = default;
MeshDistance::~MeshDistance() = default;

ClosestPoint MeshDistance::Closest(const Eigen::Vector3d& p) const {
  const float slack = static_cast<float>(1e-6 * p.cwiseAbs().maxCoeff()) + 1e-12f;
  QueryState state{&impl_->mesh, p, ClosestPoint{}, std::numeric_limits<double>::infinity(), slack};
  RTCPointQuery query;
  query.x = static_cast<float>(p.x());
  query.y = static_cast<float>(p.y());
  query.z = static_cast<float>(p.z());
  query.time = 0.0f;
  query.radius = std::numeric_limits<float>::infinity();
  RTCPointQueryContext context;
  rtcInitPointQueryContext(&context);
  rtcPointQuery(impl_->scene, &query, &context, ClosestPointCallback, &state);
  if (state.best.triangle < 0) {
    // Embree culled every primitive (e.g. only degenerate triangles): brute force.
    const TriangleMesh& mesh = impl_->mesh;
    for (size_t t = 0; t < mesh.triangles.size(); ++t) {
      const Eigen::Vector3i& tri = mesh.triangles[t];
      const Eigen::Vector3d q = ClosestPointOnTriangle(
          p, mesh.vertices[tri[0]], mesh.vertices[tri[1]], mesh.vertices[tri[2]]);
      const double distance_sq = (q - p).squaredNorm();
      if (distance_sq < state.best_distance_sq) {
        state.best_distance_sq = distance_sq;
        state.best.point = q;
        state.best.triangle = static_cast<int>(t);
      }
    }
  }
  state.best.distance = std::sqrt(state.best_distance_sq);
  return state.best;
}

}  // namespace softid::geometry
