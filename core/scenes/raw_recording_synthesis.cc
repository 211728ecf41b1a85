#include "core/scenes/raw_recording_synthesis.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <fstream>
#include <map>
#include <numeric>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>

#include "core/capture/capture.h"
#include "core/capture/depth_renderer.h"
#include "core/common/json_fields.h"
#include "core/geometry/hole_caps.h"
#include "core/geometry/primitives.h"
#include "core/recording/recording.h"
#include "core/scenes/synthesize.h"

namespace softid::scenes {
namespace {

// Row-major 16 numbers of a rigid transform.
nlohmann::json MatrixJson(const Eigen::Isometry3d& X) {
  nlohmann::json out = nlohmann::json::array();
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) out.push_back(X.matrix()(r, c));
  }
  return out;
}

nlohmann::json VectorJson(const Eigen::Vector3d& v) {
  return {v.x(), v.y(), v.z()};
}

// A right-handed frame on the floor plane: origin on the plane, e1 along the first camera's
// horizontal view direction, e2 = n x e1, n the floor's normal (pointing into the room).
struct FloorFrame {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  Eigen::Vector3d e1 = Eigen::Vector3d::UnitX();
  Eigen::Vector3d e2 = Eigen::Vector3d::UnitY();
  Eigen::Vector3d n = Eigen::Vector3d::UnitZ();

  Eigen::Vector3d ToFloor(const Eigen::Vector3d& p_W) const {
    const Eigen::Vector3d d = p_W - origin;
    return {e1.dot(d), e2.dot(d), n.dot(d)};
  }
  Eigen::Vector3d ToWorld(const Eigen::Vector3d& p_F) const {
    return origin + p_F.x() * e1 + p_F.y() * e2 + p_F.z() * n;
  }
  Eigen::Isometry3d WorldFromFloor() const {
    Eigen::Isometry3d X = Eigen::Isometry3d::Identity();
    X.linear().col(0) = e1;
    X.linear().col(1) = e2;
    X.linear().col(2) = n;
    X.translation() = origin;
    return X;
  }
};

// A box given in floor coordinates: centre and edge lengths along (e1, e2, n).
struct FloorBox {
  Eigen::Vector3d center_F = Eigen::Vector3d::Zero();
  Eigen::Vector3d size = Eigen::Vector3d::Ones();
};

geometry::TriangleMesh BoxMesh(const FloorFrame& frame, const FloorBox& box) {
  geometry::TriangleMesh mesh = geometry::MakeBox(box.size, 2.0 * box.size.maxCoeff());
  const Eigen::Isometry3d X = frame.WorldFromFloor();
  for (auto& v : mesh.vertices) v = X * (v + box.center_F);
  return mesh;
}

void Append(const geometry::TriangleMesh& part, geometry::TriangleMesh* mesh) {
  const int offset = static_cast<int>(mesh->vertices.size());
  mesh->vertices.insert(mesh->vertices.end(), part.vertices.begin(), part.vertices.end());
  for (const auto& t : part.triangles) {
    mesh->triangles.push_back(t + Eigen::Vector3i::Constant(offset));
  }
}

nlohmann::json BoxJson(const FloorFrame& frame, const FloorBox& box) {
  return {
      {"center", VectorJson(frame.ToWorld(box.center_F))},
      {"size", VectorJson(box.size)},
      {"world_from_box", MatrixJson(frame.WorldFromFloor() * Eigen::Translation3d(box.center_F))}};
}

// Whether every corner of the box projects into the camera's image (1 px margin) in front of it.
bool BoxInView(const FloorFrame& frame, const FloorBox& box, const capture::PinholeCamera& camera,
               const capture::DistortionCoefficients& distortion) {
  for (int i = 0; i < 8; ++i) {
    const Eigen::Vector3d corner_F =
        box.center_F + 0.5 * Eigen::Vector3d((i & 1) ? box.size.x() : -box.size.x(),
                                             (i & 2) ? box.size.y() : -box.size.y(),
                                             (i & 4) ? box.size.z() : -box.size.z());
    const Eigen::Vector3d p_C = camera.X_WC.inverse() * frame.ToWorld(corner_F);
    if (p_C.z() <= 0.05) return false;
    // Far outside the image the distortion polynomial folds back; check the pinhole first.
    const double x = p_C.x() / p_C.z(), y = p_C.y() / p_C.z();
    if (std::abs(x * camera.fx) > 2.0 * camera.width ||
        std::abs(y * camera.fy) > 2.0 * camera.height)
      return false;
    const Eigen::Vector2d uv = capture::ProjectDistorted(camera, distortion, p_C);
    if (!(uv.x() >= 1.0 && uv.x() <= camera.width - 2.0 && uv.y() >= 1.0 &&
          uv.y() <= camera.height - 2.0)) {
      return false;
    }
  }
  return true;
}

// Zeroes depths a PNG of this scale cannot hold (beyond the sensor's range, or below half a unit).
void ClampToRange(double depth_scale, capture::DepthImage* image) {
  const double max_depth = (capture::kMaxDepthPngValue - 0.5) * depth_scale;
  for (float& z : image->depth) {
    if (z > max_depth || z < 0.5 * depth_scale) z = 0.0f;
  }
}

Status WriteMask(const std::filesystem::path& path, const std::vector<uint8_t>& mask, int width,
                 int height) {
  std::error_code ec;
  std::filesystem::create_directories(path.parent_path(), ec);
  if (ec) return Status::IoError(path.parent_path().string() + ": " + ec.message());
  const cv::Mat image(height, width, CV_8UC1, const_cast<uint8_t*>(mask.data()));
  bool ok = false;
  try {
    ok = cv::imwrite(path.string(), image);
  } catch (const cv::Exception& e) {
    return Status::IoError("cannot write " + path.string() + ": " + e.what());
  }
  if (!ok) return Status::IoError("cannot write " + path.string());
  return Status::Ok();
}

// The static room of a recording: a box of clutter beside the motion where the first camera sees
// it, a back wall and a side wall beyond the motion and every camera, and the floor slab.
struct Room {
  FloorBox clutter, back_wall, side_wall, floor_slab;
  geometry::TriangleMesh mesh;
};

// The clutter box beside the motion (lo, hi in floor coordinates [m]): the first of the candidate
// places the camera sees whole, else the last. *side: the clutter's side along e2 (+1 / -1).
FloorBox PlaceClutter(const FloorFrame& floor, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi,
                      double gap, double clutter_side, const capture::PinholeCamera& camera,
                      const capture::DistortionCoefficients& distortion, int* side) {
  const Eigen::Vector3d mid = 0.5 * (lo + hi);
  FloorBox clutter;
  clutter.size = Eigen::Vector3d(clutter_side, clutter_side, 1.4 * clutter_side);
  const double half = 0.5 * clutter_side, z = 0.7 * clutter_side;
  const std::vector<Eigen::Vector3d> candidates = {
      {mid.x(), hi.y() + gap + half, z},
      {mid.x(), lo.y() - gap - half, z},
      {hi.x() + gap + half, mid.y(), z},
  };
  clutter.center_F = candidates[2];
  for (size_t i = 0; i < candidates.size(); ++i) {
    FloorBox trial = clutter;
    trial.center_F = candidates[i];
    if (BoxInView(floor, trial, camera, distortion)) {
      clutter = trial;
      *side = i == 1 ? -1 : 1;
      break;
    }
  }
  return clutter;
}

// lo, hi: the motion's extent, cam_lo, cam_hi: the cameras', in floor coordinates [m].
Room BuildRoom(const FloorFrame& floor, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi,
               const Eigen::Vector3d& cam_lo, const Eigen::Vector3d& cam_hi,
               const std::vector<capture::PinholeCamera>& cameras,
               const capture::DistortionCoefficients& distortion, double view_radius) {
  const double size = view_radius;
  const double gap = 0.03 + 0.1 * size;
  const double clutter_side = std::clamp(0.35 * size, 0.03, 0.25);
  const double half = 0.5 * clutter_side;
  int side = 1;  // side of the clutter along e2 (+1 / -1); the side wall goes to the other
  FloorBox clutter = PlaceClutter(floor, lo, hi, gap, clutter_side, cameras[0], distortion, &side);
  const double wall_thickness = 0.05;
  const double wall_height = std::max(1.5, 2.0 * cam_hi.z());
  const double back = std::max({hi.x() + gap + 0.1 + 0.3 * size, clutter.center_F.x() + half + gap,
                                cameras.size() > 1 ? cam_hi.x() + 0.15 : -1e300}) +
                      0.5 * wall_thickness;
  FloorBox back_wall;
  // Side wall on the far side from the clutter, beyond the motion and (with several cameras)
  // beyond every camera, so that it never stands between a camera and the object.
  const double lateral_motion = side > 0 ? lo.y() - gap : -(hi.y() + gap);
  const double lateral_cameras =
      cameras.size() > 1 ? (side > 0 ? cam_lo.y() : -cam_hi.y()) - 0.15 : -0.15;
  const double wall_lateral =
      side * (std::min(lateral_motion, lateral_cameras) - 0.5 * wall_thickness);
  const double side_start = cameras.size() > 1 ? std::min(cam_lo.x(), lo.x()) - 0.2 : lo.x() - gap;
  FloorBox side_wall;
  side_wall.size = Eigen::Vector3d(back - side_start, wall_thickness, wall_height);
  side_wall.center_F = Eigen::Vector3d(0.5 * (back + side_start), wall_lateral, 0.5 * wall_height);
  const double far_lateral = side > 0 ? std::max({hi.y(), cam_hi.y(), clutter.center_F.y()}) + 1.0
                                      : std::min({lo.y(), cam_lo.y(), clutter.center_F.y()}) - 1.0;
  const double lat_min = std::min(wall_lateral, far_lateral);
  const double lat_max = std::max(wall_lateral, far_lateral);
  back_wall.size = Eigen::Vector3d(wall_thickness, lat_max - lat_min + wall_thickness, wall_height);
  back_wall.center_F = Eigen::Vector3d(back, 0.5 * (lat_min + lat_max), 0.5 * wall_height);
  FloorBox floor_slab;
  const double front = std::min(cam_lo.x(), lo.x()) - 1.0;
  floor_slab.size = Eigen::Vector3d(back - front, lat_max - lat_min + 2.0, 0.05);
  floor_slab.center_F =
      Eigen::Vector3d(0.5 * (back + front), 0.5 * (lat_min + lat_max), -0.5 * floor_slab.size.z());

  Room room{clutter, back_wall, side_wall, floor_slab, {}};
  for (const FloorBox* box : {&floor_slab, &back_wall, &side_wall, &clutter}) {
    Append(BoxMesh(floor, *box), &room.mesh);
  }
  return room;
}

// The frames a device delivers of num_ideal: round(drop_fraction * (num_ideal - 1)) of them
// dropped at random, never frame 0.
std::vector<int> KeptFrames(int num_ideal, double drop_fraction, std::mt19937_64& rng) {
  std::vector<int> candidates(std::max(0, num_ideal - 1));
  std::iota(candidates.begin(), candidates.end(), 1);
  std::shuffle(candidates.begin(), candidates.end(), rng);
  const int num_drop = static_cast<int>(std::lround(drop_fraction * (num_ideal - 1)));
  std::vector<bool> dropped(num_ideal, false);
  for (int i = 0; i < num_drop; ++i) dropped[candidates[i]] = true;
  std::vector<int> kept;
  for (int k = 0; k < num_ideal; ++k) {
    if (!dropped[k]) kept.push_back(k);
  }
  return kept;
}

// The random draws of a recording, all from one generator (seeded by options.seed), in this order:
// the clock's offset, jitter and dropped frames (DrawFrameClock), then the scanner's pose.
struct RandomDraws {
  std::mt19937_64& rng;
  std::normal_distribution<double>& gaussian;
  std::uniform_real_distribution<double>& uniform;
};

// The device's clock: the ideal frames k / fps, their jittered true times, the frames it keeps.
struct FrameClock {
  int num_ideal = 0;               // frames of the ideal clock
  RunOptions fine;                 // Synthesize's time step: one RunScene frame per step
  int num_steps = 0;               // simulation states, step 0 at rest
  double h = 0.0;                  // time step [s]
  double time_offset = 0.0;        // device-clock time of t = 0 [s]
  std::vector<double> true_times;  // per ideal frame [s]
  std::vector<int> kept;           // the ideal frames the recording holds
};

FrameClock DrawFrameClock(const Scene& scene, const RawSynthesisOptions& options,
                          const RandomDraws& draws) {
  FrameClock clock;
  clock.num_ideal = options.run.NumFrames(scene);
  clock.fine = options.run;
  clock.fine.fps = options.run.fps * options.run.substeps_per_frame;
  clock.fine.substeps_per_frame = 1;
  clock.num_steps = clock.fine.NumFrames(scene);
  clock.h = 1.0 / clock.fine.fps;
  const double t_end = (clock.num_steps - 1) * clock.h;
  clock.time_offset = 1000.0 + 100.0 * draws.uniform(draws.rng);
  clock.true_times.resize(clock.num_ideal);
  for (int k = 0; k < clock.num_ideal; ++k) {
    const double jitter = std::clamp(draws.gaussian(draws.rng), -2.0, 2.0) * options.time_jitter_s;
    clock.true_times[k] = std::clamp(k / options.run.fps + jitter, 0.0, t_end);
  }
  clock.kept = KeptFrames(clock.num_ideal, options.drop_fraction, draws.rng);
  return clock;
}

// A recorded frame's surface: step's, moved by `weight` towards step + 1's.
struct FrameSample {
  int step = 0;
  double weight = 0.0;  // of step + 1
};

// Steps whose surfaces are needed: the two around each kept frame's true time (the keys of
// *surfaces, their meshes still empty).
void PlanFrameSamples(const FrameClock& clock, std::vector<FrameSample>* samples,
                      std::map<int, geometry::TriangleMesh>* surfaces) {
  for (int k : clock.kept) {
    FrameSample s;
    if (clock.num_steps >= 2) {
      s.step = std::clamp(static_cast<int>(std::floor(clock.true_times[k] / clock.h)), 0,
                          clock.num_steps - 2);
      s.weight = std::clamp(clock.true_times[k] / clock.h - s.step, 0.0, 1.0);
      (*surfaces)[s.step + 1];
    }
    (*surfaces)[s.step];
    samples->push_back(s);
  }
}

// The floor frame, aimed along the first camera's horizontal view direction.
FloorFrame AimFloorFrame(const Scene& scene, const CameraRigOptions& camera_options) {
  const fem::PhysicalParameters& p = scene.parameters;
  FloorFrame floor;
  const Eigen::Vector3d up = p.ground                 ? p.ground->normal.normalized()
                             : p.gravity.norm() > 0.0 ? Eigen::Vector3d(-p.gravity.normalized())
                                                      : Eigen::Vector3d::UnitZ();
  floor.n = up;
  floor.origin = scene.view_target;
  if (p.ground) {
    floor.origin -= (up.dot(scene.view_target) - p.ground->offset) * up;
  }
  const std::vector<capture::PinholeCamera> probe =
      MakeCameraRing(camera_options, scene.view_target, scene.view_radius);
  Eigen::Vector3d forward = probe[0].X_WC.linear().col(2);
  forward -= forward.dot(up) * up;
  if (forward.norm() < 1e-6) forward = up.unitOrthogonal();
  floor.e1 = forward.normalized();
  floor.e2 = up.cross(floor.e1);
  return floor;
}

// Where the object went: lo, hi in floor coordinates [m]; reach: the largest distance of a
// surface vertex from the view target, at least the view radius [m].
struct MotionExtent {
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = Eigen::Vector3d::Constant(-1e300);
  double reach = 0.0;
};

// Simulates at the fine step (Synthesize's time step), keeping the surfaces needed (the keys of
// *surfaces) and the object's extent in the floor frame and around the view target.
Status SimulateMotion(const Scene& scene, const FrameClock& clock, const FloorFrame& floor,
                      const std::function<void(int, int)>& progress,
                      std::map<int, geometry::TriangleMesh>* surfaces, MotionExtent* extent,
                      RawSynthesisSummary* summary) {
  Eigen::Vector3d& lo = extent->lo;
  Eigen::Vector3d& hi = extent->hi;
  double& reach = extent->reach;
  reach = scene.view_radius;
  const int num_steps = clock.num_steps;
  // The real object is closed where its scan has holes: the cameras see the caps, not through.
  geometry::HoleLoops holes;  // found on the first state's surface
  const auto record_step = [&](int step, const fem::Simulator& sim) {
    if (step == 0) {
      summary->num_elements = sim.hex_mesh().NumElements();
      summary->num_nodes = sim.hex_mesh().NumNodes();
      summary->mass = sim.total_mass();
      holes = geometry::FindHoleLoops(sim.DeformedSurface());
    }
    geometry::TriangleMesh surface = geometry::WithHolesCapped(sim.DeformedSurface(), holes);
    for (const auto& v : surface.vertices) {
      const Eigen::Vector3d f = floor.ToFloor(v);
      lo = lo.cwiseMin(f);
      hi = hi.cwiseMax(f);
      reach = std::max(reach, (v - scene.view_target).norm());
    }
    auto it = surfaces->find(step);
    if (it != surfaces->end()) it->second = std::move(surface);
    if (progress) progress(step, num_steps);
  };
  SOFTID_ASSIGN_OR_RETURN(summary->run, RunSceneToEnd(scene, clock.fine, record_step, "steps"));
  return Status::Ok();
}

// Without a ground plane (free flight, clamped objects) the floor lies below the motion: moves the
// floor (and the extent, in floor coordinates) there. Returns the floor's offset d (n . x = d).
double SettleFloor(const Scene& scene, FloorFrame* floor, MotionExtent* extent) {
  const fem::PhysicalParameters& p = scene.parameters;
  if (p.ground) return p.ground->offset;
  const double shift = extent->lo.z() - 0.1 * scene.view_radius - 0.02;
  floor->origin += shift * floor->n;
  extent->lo.z() -= shift;
  extent->hi.z() -= shift;
  return floor->n.dot(floor->origin);
}

// The cameras' extent in floor coordinates [m].
void CameraExtent(const std::vector<capture::PinholeCamera>& cameras, const FloorFrame& floor,
                  Eigen::Vector3d* cam_lo, Eigen::Vector3d* cam_hi) {
  *cam_lo = Eigen::Vector3d::Constant(1e300);
  *cam_hi = Eigen::Vector3d::Constant(-1e300);
  for (const auto& camera : cameras) {
    const Eigen::Vector3d f = floor.ToFloor(camera.X_WC.translation());
    *cam_lo = cam_lo->cwiseMin(f);
    *cam_hi = cam_hi->cwiseMax(f);
  }
}

// What the cameras recorded, per camera and recorded frame (masks only with write_true_masks).
struct RenderedImages {
  std::vector<std::vector<capture::DepthImage>> frames;
  std::vector<std::vector<std::vector<uint8_t>>> masks;
  std::vector<std::vector<capture::DepthImage>> backgrounds;  // per camera, background_frames
  long long valid_pixels = 0, object_pixels = 0;
};

// The static room once per camera, with each camera's lens rays for the frames.
Status RenderRoom(const capture::DepthRenderer& renderer, const geometry::TriangleMesh& room,
                  const std::vector<capture::PinholeCamera>& cameras,
                  const capture::DistortionCoefficients& distortion,
                  std::vector<capture::PixelRays>* rays,
                  std::vector<capture::DepthImage>* room_depth) {
  for (const auto& camera : cameras) {
    SOFTID_ASSIGN_OR_RETURN(capture::PixelRays r, capture::ComputePixelRays(camera, distortion));
    room_depth->push_back(renderer.Render(room, camera, r));
    rays->push_back(std::move(r));
  }
  return Status::Ok();
}

// The object's surface at a recorded frame, interpolated between the steps around it.
geometry::TriangleMesh SampledSurface(const std::map<int, geometry::TriangleMesh>& surfaces,
                                      const FrameSample& s) {
  geometry::TriangleMesh surface = surfaces.at(s.step);
  if (s.weight > 0.0) {
    const geometry::TriangleMesh& next = surfaces.at(s.step + 1);
    for (size_t v = 0; v < surface.vertices.size(); ++v) {
      surface.vertices[v] += s.weight * (next.vertices[v] - surface.vertices[v]);
    }
  }
  return surface;
}

// One camera's image of ideal frame `frame_index`: the object over the room (the nearer surface
// wins), then the sensor's noise and range; appended to out's frames (and masks).
void RecordImage(const capture::DepthImage& object, const capture::DepthImage& room_depth,
                 int frame_index, int c, const RawSynthesisOptions& options, RenderedImages* out) {
  capture::DepthImage image = room_depth;
  std::vector<uint8_t> mask(image.depth.size(), 0);
  for (size_t px = 0; px < image.depth.size(); ++px) {
    const float zo = object.depth[px];
    if (zo > 0.0f && (image.depth[px] <= 0.0f || zo <= image.depth[px])) {
      image.depth[px] = zo;
      mask[px] = 255;
      ++out->object_pixels;
    }
  }
  capture::ApplyDepthNoise(options.noise, frame_index, c, &image);
  ClampToRange(options.depth_scale, &image);
  // A pixel the sensor dropped shows nothing, the object neither.
  for (size_t px = 0; px < mask.size(); ++px) {
    if (image.depth[px] <= 0.0f) mask[px] = 0;
  }
  out->valid_pixels += image.NumValid();
  out->frames[c].push_back(std::move(image));
  if (options.write_true_masks) out->masks[c].push_back(std::move(mask));
}

// Frames of the empty room per camera, with noise of their own.
std::vector<std::vector<capture::DepthImage>> RenderBackgrounds(
    const std::vector<capture::DepthImage>& room_depth, const RawSynthesisOptions& options) {
  std::vector<std::vector<capture::DepthImage>> backgrounds;
  if (options.background_frames > 0) {
    const int num_cameras = static_cast<int>(room_depth.size());
    backgrounds.resize(num_cameras);
    for (int c = 0; c < num_cameras; ++c) {
      for (int b = 0; b < options.background_frames; ++b) {
        capture::DepthImage image = room_depth[c];
        // Noise indices apart from the frames' (frame indices stay below 1e6).
        capture::ApplyDepthNoise(options.noise, 1000000 + b, c, &image);
        ClampToRange(options.depth_scale, &image);
        backgrounds[c].push_back(std::move(image));
      }
    }
  }
  return backgrounds;
}

// Render: the static room once per camera, the object per frame; the nearer surface wins.
Result<RenderedImages> RenderImages(const geometry::TriangleMesh& room,
                                    const std::vector<capture::PinholeCamera>& cameras,
                                    const std::vector<FrameSample>& samples,
                                    const std::map<int, geometry::TriangleMesh>& surfaces,
                                    const std::vector<int>& kept,
                                    const RawSynthesisOptions& options) {
  capture::DepthRenderer renderer;
  const int num_cameras = static_cast<int>(cameras.size());
  const int num_frames = static_cast<int>(kept.size());
  std::vector<capture::PixelRays> rays;
  std::vector<capture::DepthImage> room_depth;
  SOFTID_RETURN_IF_ERROR(
      RenderRoom(renderer, room, cameras, options.distortion, &rays, &room_depth));
  RenderedImages out;
  out.frames.resize(num_cameras);
  out.masks.resize(num_cameras);
  for (int i = 0; i < num_frames; ++i) {
    const geometry::TriangleMesh surface = SampledSurface(surfaces, samples[i]);
    for (int c = 0; c < num_cameras; ++c) {
      const capture::DepthImage object = renderer.Render(surface, cameras[c], rays[c]);
      RecordImage(object, room_depth[c], kept[i], c, options, &out);
    }
  }
  out.backgrounds = RenderBackgrounds(room_depth, options);
  return out;
}

// The scanner's frame: a random rigid pose of the rest mesh.
Eigen::Isometry3d DrawScannerPose(const RandomDraws& draws) {
  std::mt19937_64& rng = draws.rng;
  std::normal_distribution<double>& gaussian = draws.gaussian;
  std::uniform_real_distribution<double>& uniform = draws.uniform;
  Eigen::Isometry3d world_from_scanner = Eigen::Isometry3d::Identity();
  // Drawn one by one, last component first: C++ leaves the order in which a call's arguments are
  // evaluated unspecified, and drawing inside the argument list made the pose depend on the
  // compiler. Last first is the order GCC took, so the seeds keep their recordings.
  const auto draw_reversed = [&](auto* values, int count) {
    for (int i = count - 1; i >= 0; --i) values[i] = gaussian(rng);
  };
  std::array<double, 4> wxyz;
  draw_reversed(wxyz.data(), 4);
  Eigen::Quaterniond q(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
  q.normalize();
  Eigen::Vector3d direction;
  draw_reversed(direction.data(), 3);
  direction.normalize();
  world_from_scanner.linear() = q.toRotationMatrix();
  world_from_scanner.translation() = (0.1 + 0.9 * uniform(rng)) * direction;
  return world_from_scanner;
}

// recording.json's contents: the scan, the cameras (their poses only with several), the frames
// with their device-clock times and the background frames.
recording::Recording MakeRecording(const Scene& scene, const RawSynthesisOptions& options,
                                   const std::vector<capture::PinholeCamera>& cameras,
                                   const FrameClock& clock) {
  const int num_cameras = static_cast<int>(cameras.size());
  const int num_frames = static_cast<int>(clock.kept.size());
  recording::Recording rec;
  rec.mesh_file = "scan.ply";
  rec.mesh_unit =
      options.mesh_in_mm ? recording::MeshUnit::kMillimetre : recording::MeshUnit::kMetre;
  if (options.write_mass) {
    rec.mass_kg = scene.parameters.density * std::abs(geometry::SignedVolume(scene.mesh));
  }
  for (int c = 0; c < num_cameras; ++c) {
    recording::RecordingCamera cam;
    cam.camera = cameras[c];
    cam.has_world_from_camera = num_cameras > 1;
    if (!cam.has_world_from_camera) cam.camera.X_WC = Eigen::Isometry3d::Identity();
    cam.distortion = options.distortion;
    cam.depth_scale = options.depth_scale;
    for (int i = 0; i < num_frames; ++i) {
      cam.frames.push_back({fmt::format("{}/{:06d}.png", cameras[c].name, i),
                            clock.time_offset + clock.true_times[clock.kept[i]]});
    }
    for (int b = 0; b < options.background_frames; ++b) {
      cam.background.push_back(fmt::format("{}/bg_{:03d}.png", cameras[c].name, b));
    }
    rec.cameras.push_back(std::move(cam));
  }
  return rec;
}

// The room and cameras a recording was made in, in the floor frame (floor_offset: d of n . x = d).
struct RecordingSetup {
  FloorFrame floor;
  double floor_offset = 0.0;
  std::vector<capture::PinholeCamera> cameras;
  Room room;
};

// truth.json: Synthesize's truth plus "raw", what ingest has to recover.
nlohmann::json RawTruthJson(const Scene& scene, const RawSynthesisOptions& options,
                            const RawSynthesisSummary& summary, const FrameClock& clock,
                            const RecordingSetup& setup,
                            const Eigen::Isometry3d& world_from_scanner,
                            recording::MeshUnit mesh_unit) {
  const FloorFrame& floor = setup.floor;
  nlohmann::json truth = SynthesisTruthJson(scene, options.run, options.noise, options.depth_scale,
                                            summary.num_elements, summary.mass);
  nlohmann::json truth_cameras = nlohmann::json::array();
  for (const auto& camera : setup.cameras) {
    truth_cameras.push_back(
        {{"name", camera.name}, {"world_from_camera", MatrixJson(camera.X_WC)}});
  }
  nlohmann::json frame_times = nlohmann::json::array(), frame_indices = nlohmann::json::array();
  for (int k : clock.kept) {
    frame_times.push_back(clock.true_times[k]);
    frame_indices.push_back(k);
  }
  truth["raw"] = {
      {"world_from_scanner", MatrixJson(world_from_scanner)},
      {"floor", {{"normal", VectorJson(floor.n)}, {"offset", setup.floor_offset}}},
      {"time_offset_s", clock.time_offset},
      {"time_jitter_s", options.time_jitter_s},
      {"frame_times_s", frame_times},
      {"frame_indices", frame_indices},
      {"fps", options.run.fps},
      {"cameras", truth_cameras},
      {"distortion", options.distortion},
      {"mesh_unit", std::string(recording::ToString(mesh_unit))},
      {"clutter", BoxJson(floor, setup.room.clutter)},
      {"walls", {BoxJson(floor, setup.room.back_wall), BoxJson(floor, setup.room.side_wall)}},
      {"floor_slab", BoxJson(floor, setup.room.floor_slab)},
      {"seed", options.seed},
  };
  return truth;
}

// truth_masks/<camera>/%06d.png per recorded frame.
Status WriteTrueMasks(const std::filesystem::path& directory,
                      const std::vector<capture::PinholeCamera>& cameras,
                      const std::vector<std::vector<std::vector<uint8_t>>>& masks, int num_frames) {
  for (size_t c = 0; c < cameras.size(); ++c) {
    for (int i = 0; i < num_frames; ++i) {
      SOFTID_RETURN_IF_ERROR(
          WriteMask(directory / kTrueMasksFolder / cameras[c].name / fmt::format("{:06d}.png", i),
                    masks[c][i], cameras[c].width, cameras[c].height));
    }
  }
  return Status::Ok();
}

// The ring of cameras around the view target, far enough to keep the whole motion in view, and
// the room around the motion and the cameras.
void PlaceCamerasAndRoom(const Scene& scene, const RawSynthesisOptions& options,
                         const MotionExtent& motion, RecordingSetup* setup) {
  // Cameras: the ring around the view target, far enough to keep the whole motion in view.
  setup->cameras = MakeCameraRing(options.cameras, scene.view_target, motion.reach);
  Eigen::Vector3d cam_lo, cam_hi;
  CameraExtent(setup->cameras, setup->floor, &cam_lo, &cam_hi);
  // The room: clutter beside the motion where the first camera sees it, walls behind.
  setup->room = BuildRoom(setup->floor, motion.lo, motion.hi, cam_lo, cam_hi, setup->cameras,
                          options.distortion, scene.view_radius);
}

// The rest mesh as the scanner delivered it: in the scanner's frame.
geometry::TriangleMesh ScanInScannerFrame(const geometry::TriangleMesh& mesh,
                                          const Eigen::Isometry3d& world_from_scanner) {
  geometry::TriangleMesh scan = mesh;
  const Eigen::Isometry3d scanner_from_world = world_from_scanner.inverse();
  for (auto& v : scan.vertices) v = scanner_from_world * v;
  return scan;
}

Status WriteTruthFile(const std::filesystem::path& directory, const nlohmann::json& truth) {
  std::ofstream file(directory / kTruthFileName);
  file << truth.dump(2) << "\n";
  if (!file) return Status::IoError("cannot write " + (directory / kTruthFileName).string());
  return Status::Ok();
}

// The summary's counts of what was recorded (the simulation's part is filled in by SimulateMotion).
void CompleteSummary(const FrameClock& clock, const RenderedImages& images, int num_cameras,
                     const Eigen::Isometry3d& world_from_scanner, RawSynthesisSummary* summary) {
  const int num_frames = static_cast<int>(clock.kept.size());
  summary->num_cameras = num_cameras;
  summary->num_frames = num_frames;
  summary->num_dropped = clock.num_ideal - num_frames;
  summary->time_offset_s = clock.time_offset;
  summary->world_from_scanner = world_from_scanner;
  const double image_count = static_cast<double>(num_frames) * num_cameras;
  summary->mean_valid_pixels = images.valid_pixels / image_count;
  summary->mean_object_pixels = images.object_pixels / image_count;
}

// FailedPrecondition if `directory` already holds a recording or a capture.
Status CheckNoRecordingIn(const std::filesystem::path& directory) {
  for (const std::string& name :
       {std::string(recording::kRecordingFileName), std::string(capture::kCaptureFileName)}) {
    if (std::filesystem::exists(directory / name)) {
      return Status::FailedPrecondition("out = " + directory.string() + ": already holds " + name +
                                        "; choose an empty folder");
    }
  }
  return Status::Ok();
}

}  // namespace

RawSynthesisOptions::RawSynthesisOptions() {
  cameras.elevation = 30.0;
  cameras.width = 160;
  cameras.height = 120;
}

Status RawSynthesisOptions::Validate() const {
  using json::Invalid;
  SOFTID_RETURN_IF_ERROR(run.Validate());
  SOFTID_RETURN_IF_ERROR(cameras.Validate());
  SOFTID_RETURN_IF_ERROR(noise.Validate());
  SOFTID_RETURN_IF_ERROR(capture::ValidateDistortion(distortion, "distortion"));
  if (!(depth_scale > 0.0) || !std::isfinite(depth_scale)) {
    return Invalid("depth_scale", depth_scale, "must be positive and finite");
  }
  // Jitter is truncated at 2 sigma, so sigma <= 0.2 / fps keeps the true times increasing.
  if (!(time_jitter_s >= 0.0) || !(time_jitter_s <= 0.2 / run.fps)) {
    return Invalid("time_jitter_s", time_jitter_s,
                   fmt::format("must lie in [0, 0.2 / fps] = [0, {:.6g}] s", 0.2 / run.fps));
  }
  if (!(drop_fraction >= 0.0 && drop_fraction < 1.0)) {
    return Invalid("drop_fraction", drop_fraction, "must lie in [0, 1)");
  }
  if (background_frames < 0 || background_frames > recording::kMaxBackgroundFrames) {
    return Invalid("background_frames", background_frames,
                   fmt::format("must lie in [0, {}]", recording::kMaxBackgroundFrames));
  }
  return Status::Ok();
}
Result<RawSynthesisSummary> SynthesizeRawRecording(const Scene& scene,
                                                   const RawSynthesisOptions& options,
                                                   const std::filesystem::path& directory,
                                                   const std::function<void(int, int)>& progress) {
  SOFTID_RETURN_IF_ERROR(options.Validate());
  SOFTID_RETURN_IF_ERROR(CheckNoRecordingIn(directory));
  std::mt19937_64 rng(options.seed);
  std::normal_distribution<double> gaussian(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const RandomDraws draws{rng, gaussian, uniform};

  // The ideal clock k / fps, jittered true times, dropped frames.
  const FrameClock clock = DrawFrameClock(scene, options, draws);
  std::vector<FrameSample> samples;
  std::map<int, geometry::TriangleMesh> surfaces;
  PlanFrameSamples(clock, &samples, &surfaces);

  RecordingSetup setup;
  setup.floor = AimFloorFrame(scene, options.cameras);
  RawSynthesisSummary summary;
  MotionExtent motion;
  SOFTID_RETURN_IF_ERROR(
      SimulateMotion(scene, clock, setup.floor, progress, &surfaces, &motion, &summary));
  setup.floor_offset = SettleFloor(scene, &setup.floor, &motion);
  PlaceCamerasAndRoom(scene, options, motion, &setup);
  const std::vector<capture::PinholeCamera>& cameras = setup.cameras;
  SOFTID_ASSIGN_OR_RETURN(
      const RenderedImages images,
      RenderImages(setup.room.mesh, cameras, samples, surfaces, clock.kept, options));

  const Eigen::Isometry3d world_from_scanner = DrawScannerPose(draws);
  const geometry::TriangleMesh scan = ScanInScannerFrame(scene.mesh, world_from_scanner);
  const recording::Recording rec = MakeRecording(scene, options, cameras, clock);
  // Validate before writing anything (WriteRecording checks again).
  SOFTID_RETURN_IF_ERROR(recording::RecordingFromJson(recording::ToJson(rec)).status());

  std::error_code ec;
  std::filesystem::create_directories(directory, ec);
  if (ec) return Status::IoError("out = " + directory.string() + ": " + ec.message());

  // truth.json and the masks first: recording.json is written last.
  SOFTID_RETURN_IF_ERROR(WriteTruthFile(
      directory,
      RawTruthJson(scene, options, summary, clock, setup, world_from_scanner, rec.mesh_unit)));
  const int num_cameras = static_cast<int>(cameras.size());
  const int num_frames = static_cast<int>(clock.kept.size());
  if (options.write_true_masks) {
    SOFTID_RETURN_IF_ERROR(WriteTrueMasks(directory, cameras, images.masks, num_frames));
  }
  SOFTID_RETURN_IF_ERROR(
      recording::WriteRecording(directory, rec, scan, images.frames, images.backgrounds));

  CompleteSummary(clock, images, num_cameras, world_from_scanner, &summary);
  return summary;
}

}  // namespace softid::scenes
