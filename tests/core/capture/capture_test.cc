#include "core/capture/capture.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <fstream>
#include <initializer_list>
#include <iterator>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "core/capture/capture_writer.h"
#include "core/capture/depth_renderer.h"
#include "core/geometry/primitives.h"
#include "tests/core/capture/test_temp_dir.h"

namespace softid::capture {
namespace {

using nlohmann::json;
using testing::TempDir;
namespace fs = std::filesystem;

constexpr int kNumFrames = 3;

PinholeCamera MakeCamera(const std::string& name, const Eigen::Vector3d& eye_W) {
  PinholeCamera camera;
  camera.name = name;
  camera.width = 32;
  camera.height = 24;
  camera.fx = 30.0;
  camera.fy = 31.0;
  camera.cx = 15.5;
  camera.cy = 11.5;
  camera.X_WC = LookAt(eye_W, Eigen::Vector3d(0, 0, 0.05));
  return camera;
}

// A small valid capture: a falling sphere seen by two cameras for three frames.
struct TestCapture {
  Capture capture;
  geometry::TriangleMesh mesh;
  std::vector<std::vector<DepthImage>> frames;  // [camera][frame]
};

TestCapture MakeTestCapture() {
  TestCapture test;
  test.mesh = geometry::MakeSphere(0.1, 2);
  test.capture.fps = 60.0;
  test.capture.mass_kg = 0.25;
  test.capture.fixed_region =
      Eigen::AlignedBox3d(Eigen::Vector3d(-1, -1, -0.5), Eigen::Vector3d(1, 1, -0.4));
  CameraRecording cam0{MakeCamera("cam0", Eigen::Vector3d(0.6, 0.05, 0.15)), 0.0005, {}};
  CameraRecording cam1{MakeCamera("cam1", Eigen::Vector3d(-0.1, -0.7, 0.3)), 0.001, {}};
  test.capture.cameras = {cam0, cam1};
  const DepthRenderer renderer;
  for (const CameraRecording& recording : test.capture.cameras) {
    std::vector<DepthImage> images;
    for (int k = 0; k < kNumFrames; ++k) {
      geometry::TriangleMesh moved = test.mesh;
      const double t = k / test.capture.fps;
      for (Eigen::Vector3d& v : moved.vertices) v.z() -= 0.5 * 9.81 * t * t;
      images.push_back(renderer.Render(moved, recording.camera));
    }
    test.frames.push_back(std::move(images));
  }
  return test;
}

// A temporary folder holding a freshly written valid capture.
class CaptureDir {
 public:
  CaptureDir() : test_(MakeTestCapture()) {
    const Status status = WriteCapture(dir_.path(), test_.capture, test_.mesh, test_.frames);
    EXPECT_TRUE(status.ok()) << status.ToString();
    original_json_ = LoadJson();
  }
  const fs::path& path() const { return dir_.path(); }
  const TestCapture& test() const { return test_; }

  json LoadJson() const {
    std::ifstream file(path() / "capture.json");
    return json::parse(file);
  }
  void SaveJson(const json& j) const { WriteText("capture.json", j.dump(2)); }
  void WriteText(const std::string& file, const std::string& text) const {
    std::ofstream(path() / file, std::ios::binary | std::ios::trunc) << text;
  }
  // Applies `edit` to the originally written capture.json and reads the capture back.
  template <typename Edit>
  Result<Capture> ReadEdited(Edit edit) const {
    json j = original_json_;
    edit(j);
    SaveJson(j);
    return ReadCapture(path());
  }

 private:
  TempDir dir_;
  TestCapture test_;
  json original_json_;
};

// Expects InvalidArgument whose message contains capture.json and every one of `parts`.
void ExpectInvalid(const Result<Capture>& result, std::initializer_list<std::string> parts) {
  ASSERT_FALSE(result.ok());
  const Status& status = result.status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << status.ToString();
  EXPECT_NE(status.message().find("capture.json"), std::string::npos) << status.message();
  for (const std::string& part : parts) {
    EXPECT_NE(status.message().find(part), std::string::npos)
        << "missing \"" << part << "\" in: " << status.message();
  }
}

void ExpectSameCapture(const Capture& a, const Capture& b) {
  EXPECT_EQ(a.mesh_file, b.mesh_file);
  EXPECT_EQ(a.fps, b.fps);
  EXPECT_EQ(a.mass_kg, b.mass_kg);
  ASSERT_EQ(a.fixed_region.has_value(), b.fixed_region.has_value());
  if (a.fixed_region) {
    EXPECT_EQ(a.fixed_region->min(), b.fixed_region->min());
    EXPECT_EQ(a.fixed_region->max(), b.fixed_region->max());
  }
  ASSERT_EQ(a.cameras.size(), b.cameras.size());
  for (size_t i = 0; i < a.cameras.size(); ++i) {
    const PinholeCamera& ca = a.cameras[i].camera;
    const PinholeCamera& cb = b.cameras[i].camera;
    EXPECT_EQ(ca.name, cb.name);
    EXPECT_EQ(ca.width, cb.width);
    EXPECT_EQ(ca.height, cb.height);
    EXPECT_EQ(ca.fx, cb.fx);
    EXPECT_EQ(ca.fy, cb.fy);
    EXPECT_EQ(ca.cx, cb.cx);
    EXPECT_EQ(ca.cy, cb.cy);
    EXPECT_EQ(ca.X_WC.matrix(), cb.X_WC.matrix());
    EXPECT_EQ(a.cameras[i].depth_scale, b.cameras[i].depth_scale);
    EXPECT_EQ(a.cameras[i].frames, b.cameras[i].frames);
  }
}

// A written capture reads back with every field identical and frames equal after quantisation.
TEST(Capture, WriteReadRoundTrip) {
  const CaptureDir dir;
  const TestCapture& test = dir.test();
  EXPECT_FALSE(fs::exists(dir.path() / "capture.json.tmp"));
  const Result<Capture> read = ReadCapture(dir.path());
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(read->directory, dir.path());
  EXPECT_EQ(read->mesh_file, "object.obj");
  EXPECT_EQ(read->NumFrames(), kNumFrames);
  EXPECT_EQ(read->NumCameras(), 2);
  EXPECT_EQ(read->cameras[1].frames[2], "cam1/000002.png");
  Capture expected = test.capture;
  for (CameraRecording& recording : expected.cameras) {
    for (int k = 0; k < kNumFrames; ++k) {
      recording.frames.push_back(recording.camera.name + "/00000" + std::to_string(k) + ".png");
    }
  }
  ExpectSameCapture(*read, expected);

  for (int i = 0; i < 2; ++i) {
    const double depth_scale = test.capture.cameras[i].depth_scale;
    for (int k = 0; k < kNumFrames; ++k) {
      const Result<DepthImage> frame = LoadFrame(*read, i, k);
      ASSERT_TRUE(frame.ok()) << frame.status().ToString();
      const DepthImage& original = test.frames[i][k];
      ASSERT_EQ(frame->depth.size(), original.depth.size());
      EXPECT_GT(original.NumValid(), 20);
      for (size_t p = 0; p < original.depth.size(); ++p) {
        EXPECT_EQ(frame->depth[p] == 0.0f, original.depth[p] == 0.0f);
        EXPECT_NEAR(frame->depth[p], original.depth[p], depth_scale / 2 + 1e-6);
      }
    }
  }
  const Result<geometry::TriangleMesh> mesh = LoadCaptureMesh(*read);
  ASSERT_TRUE(mesh.ok()) << mesh.status().ToString();
  ASSERT_EQ(mesh->vertices.size(), test.mesh.vertices.size());
  ASSERT_EQ(mesh->triangles.size(), test.mesh.triangles.size());
  // The reader may reorder vertices: map each read vertex to the original one at its position
  // (assimp reads single-precision coordinates) and compare the triangles with their winding.
  std::vector<int> original_index(mesh->vertices.size(), -1);
  for (size_t v = 0; v < mesh->vertices.size(); ++v) {
    for (size_t w = 0; w < test.mesh.vertices.size(); ++w) {
      if ((mesh->vertices[v] - test.mesh.vertices[w]).norm() < 1e-6) original_index[v] = w;
    }
    ASSERT_GE(original_index[v], 0) << "vertex " << v << " is not in the written mesh";
  }
  const auto canonical = [](Eigen::Vector3i t) {  // rotate the smallest index first
    while (t[0] != t.minCoeff()) t = Eigen::Vector3i(t[1], t[2], t[0]);
    return std::array<int, 3>{t[0], t[1], t[2]};
  };
  std::vector<std::array<int, 3>> written, read_back;
  for (const Eigen::Vector3i& t : test.mesh.triangles) written.push_back(canonical(t));
  for (const Eigen::Vector3i& t : mesh->triangles) {
    read_back.push_back(canonical(
        Eigen::Vector3i(original_index[t[0]], original_index[t[1]], original_index[t[2]])));
  }
  std::sort(written.begin(), written.end());
  std::sort(read_back.begin(), read_back.end());
  EXPECT_EQ(written, read_back);
}

// ToJson and CaptureFromJson are inverse; optional fields are omitted when unset.
TEST(Capture, JsonRoundTrip) {
  Capture capture = MakeTestCapture().capture;
  capture.cameras[0].frames = {"a/0.png", "a/1.png"};
  capture.cameras[1].frames = {"b/0.png", "b/1.png"};
  const json j = ToJson(capture);
  EXPECT_EQ(j["format"], "softid-capture/1");
  EXPECT_EQ(j["cameras"][0]["world_from_camera"].size(), 16u);
  EXPECT_EQ(j["cameras"][0]["world_from_camera"][3], capture.cameras[0].camera.X_WC(0, 3));
  const Result<Capture> parsed = CaptureFromJson(j);
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
  ExpectSameCapture(*parsed, capture);
  capture.mass_kg.reset();
  capture.fixed_region.reset();
  const json without = ToJson(capture);
  EXPECT_FALSE(without.contains("mass_kg"));
  EXPECT_FALSE(without.contains("fixed_region"));
  ASSERT_TRUE(CaptureFromJson(without).ok());
  EXPECT_FALSE(CaptureFromJson(without)->mass_kg.has_value());
}

// Unknown extra fields, at the top level and in cameras, are ignored.
TEST(Capture, IgnoresUnknownFields) {
  const CaptureDir dir;
  const Result<Capture> read = dir.ReadEdited([](json& j) {
    j["station"] = {{"operator", "x"}, {"temperature", 21}};
    j["cameras"][0]["serial"] = "ABC123";
  });
  EXPECT_TRUE(read.ok()) << read.status().ToString();
}

// A folder without capture.json (never or not completely written) is NotFound.
TEST(Capture, MissingCaptureJsonIsNotFound) {
  const CaptureDir dir;
  fs::remove(dir.path() / "capture.json");
  EXPECT_EQ(ReadCapture(dir.path()).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(ReadCapture(dir.path() / "nope").status().code(), StatusCode::kNotFound);
}

// Text that is not JSON is rejected naming the file.
TEST(CaptureRejects, InvalidJsonSyntax) {
  const CaptureDir dir;
  dir.WriteText("capture.json", "{\"format\": \"softid-capture/1\", ");
  ExpectInvalid(ReadCapture(dir.path()), {"invalid JSON"});
}

// A missing "format" is rejected.
TEST(CaptureRejects, MissingFormat) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j.erase("format"); }),
                {"format", "missing required field"});
}

// A "format" of another kind of file is rejected with its value.
TEST(CaptureRejects, WrongFormat) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["format"] = "other-format/1"; }),
                {"format = \"other-format/1\"", "not a softid capture"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["format"] = 1; }),
                {"format = 1", "must be a string"});
}

// A later format version is rejected as unsupported.
TEST(CaptureRejects, UnsupportedVersion) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["format"] = "softid-capture/2"; }),
                {"format = \"softid-capture/2\"", "unsupported version"});
}

// A frame PNG that does not exist is rejected naming the field and the file.
TEST(CaptureRejects, MissingFramePng) {
  const CaptureDir dir;
  fs::remove(dir.path() / "cam0" / "000001.png");
  ExpectInvalid(ReadCapture(dir.path()),
                {"cameras[0].frames[1] = \"cam0/000001.png\"", "file not found"});
}

// A frame path that is not a readable file (here a folder) is rejected.
TEST(CaptureRejects, UnreadableFramePng) {
  const CaptureDir dir;
  fs::remove(dir.path() / "cam1" / "000000.png");
  fs::create_directory(dir.path() / "cam1" / "000000.png");
  ExpectInvalid(ReadCapture(dir.path()),
                {"cameras[1].frames[0] = \"cam1/000000.png\"", "not a regular file"});
}

// A frame that is not a PNG is rejected.
TEST(CaptureRejects, CorruptFramePng) {
  const CaptureDir dir;
  dir.WriteText("cam0/000002.png", "GIF89a garbage");
  ExpectInvalid(ReadCapture(dir.path()),
                {"cameras[0].frames[2] = \"cam0/000002.png\"", "not a PNG"});
}

// A truncated PNG is rejected when frames are decoded (the default); a header-only check passes.
TEST(CaptureRejects, TruncatedFramePng) {
  const CaptureDir dir;
  const fs::path frame = dir.path() / "cam1" / "000001.png";
  fs::resize_file(frame, fs::file_size(frame) / 2);
  ExpectInvalid(ReadCapture(dir.path()), {"cameras[1].frames[1]", "cannot decode"});
  ReadCaptureOptions header_only;
  header_only.decode_frames = false;
  EXPECT_TRUE(ReadCapture(dir.path(), header_only).ok());
}

// An 8-bit PNG frame is rejected naming its bit depth.
TEST(CaptureRejects, EightBitFramePng) {
  const CaptureDir dir;
  ASSERT_TRUE(cv::imwrite((dir.path() / "cam0" / "000000.png").string(),
                          cv::Mat(24, 32, CV_8UC1, cv::Scalar(100))));
  ExpectInvalid(ReadCapture(dir.path()), {"cameras[0].frames[0]", "8-bit"});
}

// A 16-bit PNG with three channels is rejected.
TEST(CaptureRejects, MultiChannelFramePng) {
  const CaptureDir dir;
  ASSERT_TRUE(cv::imwrite((dir.path() / "cam0" / "000000.png").string(),
                          cv::Mat(24, 32, CV_16UC3, cv::Scalar(1000, 1000, 1000))));
  ExpectInvalid(ReadCapture(dir.path()), {"cameras[0].frames[0]", "RGB", "single-channel"});
}

// A frame whose size differs from the camera's width and height is rejected.
TEST(CaptureRejects, FrameSizeMismatch) {
  const CaptureDir dir;
  ASSERT_TRUE(cv::imwrite((dir.path() / "cam1" / "000002.png").string(),
                          cv::Mat(24, 33, CV_16UC1, cv::Scalar(1000))));
  ExpectInvalid(ReadCapture(dir.path()), {"cameras[1].frames[2]", "33x24", "expected 32x24"});
}

// A string in a number field is rejected with the value.
TEST(CaptureRejects, StringInNumberField) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["fx"] = "525"; }),
                {"cameras[0].fx = \"525\"", "must be a number"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["fps"] = "60"; }),
                {"fps = \"60\"", "must be a number"});
}

// null in a number field is rejected (JSON cannot hold NaN; null is its usual stand-in).
TEST(CaptureRejects, NullInNumberField) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][1]["fy"] = nullptr; }),
                {"cameras[1].fy = null", "must be a number"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mass_kg"] = nullptr; }), {"mass_kg = null"});
}

// A negative focal length is rejected with the documented message.
TEST(CaptureRejects, NegativeFocalLength) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["fx"] = -1; }),
                {"capture.json: cameras[0].fx = -1: must be positive and finite"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["fy"] = 0.0; }),
                {"cameras[0].fy = 0", "must be positive"});
}

// Non-positive or non-integer image sizes are rejected.
TEST(CaptureRejects, BadImageSize) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["width"] = 0; }),
                {"cameras[0].width = 0", "must be a positive integer"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["height"] = -24; }),
                {"cameras[0].height = -24"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["width"] = 32.5; }),
                {"cameras[0].width = 32.5", "must be an integer"});
}

// Non-positive fps is rejected.
TEST(CaptureRejects, NonPositiveFps) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["fps"] = 0; }),
                {"fps = 0", "must be positive and finite"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["fps"] = -30.0; }), {"fps = -30"});
}

// A principal point outside the image is rejected.
TEST(CaptureRejects, PrincipalPointOutsideImage) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["cx"] = 500; }),
                {"cameras[0].cx = 500", "outside the image"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][1]["cy"] = -3.25; }),
                {"cameras[1].cy = -3.25", "outside the image"});
}

// A negative or zero depth_scale is rejected.
TEST(CaptureRejects, NonPositiveDepthScale) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["depth_scale"] = -0.001; }),
                {"cameras[0].depth_scale = -0.001", "must be positive"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][1]["depth_scale"] = 0; }),
                {"cameras[1].depth_scale = 0", "must be positive"});
}

// world_from_camera must hold 16 numbers.
TEST(CaptureRejects, PoseNotSixteenNumbers) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["world_from_camera"].erase(15); }),
                {"cameras[0].world_from_camera = [", "16 numbers"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["world_from_camera"][5] = "x"; }),
                {"cameras[0].world_from_camera[5] = \"x\"", "must be a number"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["world_from_camera"] = 1; }),
                {"cameras[0].world_from_camera = 1"});
}

// A scaled, reflected or projective world_from_camera is not rigid and is rejected.
TEST(CaptureRejects, PoseNotRigid) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) {
    json& pose = j["cameras"][0]["world_from_camera"];
    for (int i : {0, 1, 2, 4, 5, 6, 8, 9, 10}) pose[i] = pose[i].get<double>() * 1.01;
  }),
                {"cameras[0].world_from_camera", "not orthonormal"});
  ExpectInvalid(dir.ReadEdited([](json& j) {
    json& pose = j["cameras"][1]["world_from_camera"];
    for (int i : {0, 4, 8}) pose[i] = -pose[i].get<double>();  // mirror x
  }),
                {"cameras[1].world_from_camera", "determinant -1"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["world_from_camera"][12] = 0.5; }),
                {"cameras[0].world_from_camera", "last row = [0.5, 0, 0, 1]"});
}

// A missing, unreadable or empty mesh is rejected naming the mesh field and file.
TEST(CaptureRejects, BadMesh) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mesh"] = "missing.obj"; }),
                {"mesh = \"missing.obj\"", "cannot load mesh"});
  dir.WriteText("garbage.stl", "\x01\x02 this is not a mesh");
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mesh"] = "garbage.stl"; }),
                {"mesh = \"garbage.stl\"", "cannot load mesh"});
  dir.WriteText("empty.obj", "# no vertices\n");
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mesh"] = "empty.obj"; }), {"mesh = \"empty.obj\""});
}

// A mesh softid cannot simulate is refused when the capture is read, not when a job fails later:
// flat (no volume), a thousand kilometres long (units), or smaller than a millimetre.
TEST(CaptureRejects, MeshOfNoVolumeOrImplausibleSize) {
  const CaptureDir dir;
  dir.WriteText("flat.obj", "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0.1 0.1 0\nf 1 2 3\nf 2 4 3\n");
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mesh"] = "flat.obj"; }),
                {"mesh = \"flat.obj\"", "encloses no volume"});
  geometry::TriangleMesh huge = dir.test().mesh;
  for (Eigen::Vector3d& v : huge.vertices) v *= 1e7;  // 0.2 m -> 2000 km
  ASSERT_TRUE(geometry::WriteTriangleMeshObj(dir.path() / "huge.obj", huge).ok());
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mesh"] = "huge.obj"; }),
                {"mesh = \"huge.obj\"", "longest side", "must lie in [0.001, 100] m"});
  geometry::TriangleMesh tiny = dir.test().mesh;
  for (Eigen::Vector3d& v : tiny.vertices) v *= 1e-3;  // 0.2 mm
  ASSERT_TRUE(geometry::WriteTriangleMeshObj(dir.path() / "tiny.obj", tiny).ok());
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mesh"] = "tiny.obj"; }), {"longest side"});
}

// Image sizes, frame and camera counts whose decoding would not fit in memory are refused from
// capture.json alone, before any frame is read.
TEST(CaptureRejects, ResourceBounds) {
  const CaptureDir dir;
  json j = dir.LoadJson();
  j["cameras"][0]["width"] = 16384;
  j["cameras"][0]["height"] = 16384;
  j["cameras"][0]["cx"] = 8000;
  j["cameras"][0]["cy"] = 8000;
  ExpectInvalid(CaptureFromJson(j),
                {"cameras[0].width = 16384", "16384 x 16384 pixels", "at most 16777216 pixels"});
  json frames = dir.LoadJson();
  frames["cameras"][0]["frames"] = json::array();
  for (int k = 0; k <= kMaxFramesPerCamera; ++k) frames["cameras"][0]["frames"].push_back("f.png");
  ExpectInvalid(CaptureFromJson(frames),
                {"cameras[0].frames", "20001 frames: at most 20000 frames per camera"});
  json cameras = dir.LoadJson();
  while (cameras["cameras"].size() <= static_cast<size_t>(kMaxCameras)) {
    json camera = cameras["cameras"][0];
    camera["name"] = "cam" + std::to_string(cameras["cameras"].size());
    cameras["cameras"].push_back(camera);
  }
  ExpectInvalid(CaptureFromJson(cameras), {"cameras: 17 cameras: at most 16 are accepted"});
}

// mass_kg must be positive.
TEST(CaptureRejects, NonPositiveMass) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mass_kg"] = 0; }),
                {"mass_kg = 0", "must be positive"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mass_kg"] = -0.25; }), {"mass_kg = -0.25"});
}

// A fixed_region with min > max, or malformed corners, is rejected.
TEST(CaptureRejects, FixedRegionMinAboveMax) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["fixed_region"]["min"][2] = -0.3; }),
                {"fixed_region.min[2] = -0.3", "fixed_region.max[2] = -0.4"});
  ExpectInvalid(dir.ReadEdited([](json& j) {
    j["fixed_region"]["max"] = {1, 2};
  }),
                {"fixed_region.max = [1,2]", "3 numbers"});
}

// Absolute paths and ".." components are rejected for the mesh and the frames.
TEST(CaptureRejects, PathsLeavingTheFolder) {
  const CaptureDir dir;
  const std::string absolute_mesh = (dir.path() / "object.obj").string();
  ExpectInvalid(dir.ReadEdited([&](json& j) { j["mesh"] = absolute_mesh; }),
                {"mesh = \"" + absolute_mesh + "\"", "absolute"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mesh"] = "../x/object.obj"; }),
                {"mesh = \"../x/object.obj\"", "must not leave the capture folder"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][1]["frames"][2] = "cam1/../../a.png"; }),
                {"cameras[1].frames[2] = \"cam1/../../a.png\"", "must not leave"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["frames"][0] = "/etc/passwd"; }),
                {"cameras[0].frames[0] = \"/etc/passwd\"", "absolute"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["frames"][0] = "cam0\\000000.png"; }),
                {"cameras[0].frames[0]", "'/'"});
}

// A symlink inside the folder that points outside it is rejected.
TEST(CaptureRejects, SymlinkEscapingTheFolder) {
  const CaptureDir dir;
  const TempDir outside;
  fs::copy_file(dir.path() / "cam0" / "000000.png", outside.path() / "frame.png");
  fs::create_symlink(outside.path() / "frame.png", dir.path() / "cam0" / "link.png");
  fs::create_directory_symlink(outside.path(), dir.path() / "elsewhere");
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["frames"][0] = "cam0/link.png"; }),
                {"cameras[0].frames[0] = \"cam0/link.png\"", "outside the capture folder"});
  ExpectInvalid(
      dir.ReadEdited([](json& j) { j["cameras"][0]["frames"][0] = "elsewhere/frame.png"; }),
      {"cameras[0].frames[0] = \"elsewhere/frame.png\"", "outside"});
  // A symlink that stays inside is fine.
  fs::create_symlink("000001.png", dir.path() / "cam0" / "inside.png");
  EXPECT_TRUE(
      dir.ReadEdited([](json& j) { j["cameras"][0]["frames"][0] = "cam0/inside.png"; }).ok());
}

// Two cameras with the same name are rejected.
TEST(CaptureRejects, DuplicateCameraNames) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][1]["name"] = "cam0"; }),
                {"cameras[1].name = \"cam0\"", "duplicate camera name"});
}

// Every required field, when missing, is named in the error.
TEST(CaptureRejects, MissingRequiredFields) {
  const CaptureDir dir;
  const json original = dir.LoadJson();
  for (const std::string top : {"mesh", "fps", "cameras"}) {
    json j = original;
    j.erase(top);
    dir.SaveJson(j);
    ExpectInvalid(ReadCapture(dir.path()), {top + ": missing required field"});
  }
  for (const std::string field : {"name", "width", "height", "fx", "fy", "cx", "cy", "depth_scale",
                                  "world_from_camera", "frames"}) {
    json j = original;
    j["cameras"][1].erase(field);
    dir.SaveJson(j);
    ExpectInvalid(ReadCapture(dir.path()), {"cameras[1]." + field + ": missing required field"});
  }
  json j = original;
  j["fixed_region"].erase("min");
  dir.SaveJson(j);
  ExpectInvalid(ReadCapture(dir.path()), {"fixed_region.min: missing required field"});
}

// Values of the wrong JSON type are rejected naming the field.
TEST(CaptureRejects, WrongJsonTypes) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) {
    j = json::array({1, 2});
  }),
                {"(root) = [1,2]", "JSON object"});
  ExpectInvalid(dir.ReadEdited([](json& j) {
    j["cameras"] = {{"name", "cam0"}};
  }),
                {"cameras = {", "JSON array"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0] = "cam0"; }),
                {"cameras[0] = \"cam0\"", "JSON object"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["frames"] = "cam0/000000.png"; }),
                {"cameras[0].frames = \"cam0/000000.png\"", "JSON array"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["frames"][1] = 7; }),
                {"cameras[0].frames[1] = 7", "must be a string"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["name"] = 0; }),
                {"cameras[0].name = 0", "must be a string"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mesh"] = true; }), {"mesh = true"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["fixed_region"] = json::array(); }),
                {"fixed_region = []", "JSON object"});
}

// No cameras, a camera without frames, or cameras with different frame counts are rejected.
TEST(CaptureRejects, BadFrameCounts) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"] = json::array(); }),
                {"cameras = []", "at least one camera"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["frames"] = json::array(); }),
                {"cameras[0].frames = []", "at least one frame"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][1]["frames"].erase(2); }),
                {"cameras[1].frames", "2 frames", "cameras[0].frames has 3"});
}

// LoadFrame rejects indices out of range.
TEST(Capture, LoadFrameRejectsBadIndex) {
  const CaptureDir dir;
  const Result<Capture> capture = ReadCapture(dir.path());
  ASSERT_TRUE(capture.ok());
  EXPECT_EQ(LoadFrame(*capture, 2, 0).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(LoadFrame(*capture, 0, kNumFrames).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(LoadFrame(*capture, -1, 0).status().code(), StatusCode::kInvalidArgument);
}

// WriteCapture validates before writing anything: bad input leaves no capture.json behind.
TEST(Capture, WriteRejectsInvalidInput) {
  const TestCapture test = MakeTestCapture();
  const TempDir dir;
  TestCapture bad = test;
  bad.capture.cameras[0].camera.name = "a/b";
  Status status = WriteCapture(dir.path(), bad.capture, bad.mesh, bad.frames);
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("cameras[0].name = \"a/b\""), std::string::npos)
      << status.message();

  bad = test;
  bad.frames[1][2] = DepthImage::Zeros(10, 10);
  status = WriteCapture(dir.path(), bad.capture, bad.mesh, bad.frames);
  EXPECT_NE(status.message().find("frames_per_camera[1][2] is 10x10"), std::string::npos)
      << status.message();

  bad = test;
  bad.capture.cameras[1].camera.fx = -1;
  status = WriteCapture(dir.path(), bad.capture, bad.mesh, bad.frames);
  EXPECT_NE(status.message().find("cameras[1].fx = -1"), std::string::npos) << status.message();

  bad = test;
  bad.frames[0].pop_back();
  EXPECT_FALSE(WriteCapture(dir.path(), bad.capture, bad.mesh, bad.frames).ok());
  EXPECT_FALSE(fs::exists(dir.path() / "capture.json"));
  EXPECT_FALSE(fs::exists(dir.path() / "object.obj"));
}

// A rewrite that fails (a depth a 16-bit PNG cannot store) leaves the previous capture as it was:
// the new files are staged and moved into place only when all of them are written.
TEST(Capture, FailedRewriteKeepsThePreviousCapture) {
  const CaptureDir dir;
  TestCapture bad = dir.test();
  bad.frames[0][1].depth[0] = 1000.0f;  // too far for a 16-bit PNG at 0.5 mm
  const Status status = WriteCapture(dir.path(), bad.capture, bad.mesh, bad.frames);
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("000001.png"), std::string::npos) << status.message();
  const Result<Capture> read = ReadCapture(dir.path());
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  const Result<DepthImage> frame = LoadFrame(*read, 0, 1);
  ASSERT_TRUE(frame.ok()) << frame.status().ToString();
  EXPECT_NEAR(frame->depth[0], dir.test().frames[0][1].depth[0], 0.0005);
  EXPECT_FALSE(fs::exists(dir.path() / ".capture-writing"));
}

// Frames written one at a time, in any order, make the same files as WriteCapture.
TEST(CaptureWriter, WritesTheSameFilesAsWriteCapture) {
  const CaptureDir reference;
  const TestCapture& test = reference.test();
  const TempDir dir;
  {
    Result<CaptureWriter> writer = CaptureWriter::Create(dir.path(), test.capture, kNumFrames);
    ASSERT_TRUE(writer.ok()) << writer.status().ToString();
    for (int k = kNumFrames - 1; k >= 0; --k) {
      for (int c = 0; c < 2; ++c) ASSERT_TRUE(writer->WriteFrame(c, k, test.frames[c][k]).ok());
    }
    EXPECT_FALSE(fs::exists(dir.path() / "cam0" / "000000.png"));  // staged until Finish
    const Status finished = writer->Finish(test.capture, test.mesh);
    ASSERT_TRUE(finished.ok()) << finished.ToString();
  }
  for (const std::string file :
       {"capture.json", "object.obj", "cam0/000002.png", "cam1/000000.png"}) {
    std::ifstream a(reference.path() / file, std::ios::binary),
        b(dir.path() / file, std::ios::binary);
    const std::string bytes_a((std::istreambuf_iterator<char>(a)), {});
    const std::string bytes_b((std::istreambuf_iterator<char>(b)), {});
    EXPECT_FALSE(bytes_b.empty()) << file;
    if (file == "capture.json") continue;  // names its own folder
    EXPECT_EQ(bytes_a, bytes_b) << file;
  }
  EXPECT_FALSE(fs::exists(dir.path() / ".capture-writing"));
}

// A writer that does not finish leaves nothing: no capture.json, no frames, and not the folder it
// made; Finish refuses while a frame is missing, naming it; bad frames are refused by index and
// size.
TEST(CaptureWriter, UnfinishedWriteLeavesNothing) {
  const TestCapture test = MakeTestCapture();
  const TempDir dir;
  const fs::path folder = dir.path() / "capture";
  {
    Result<CaptureWriter> writer = CaptureWriter::Create(folder, test.capture, kNumFrames);
    ASSERT_TRUE(writer.ok()) << writer.status().ToString();
    for (int k = 0; k < kNumFrames; ++k)
      ASSERT_TRUE(writer->WriteFrame(0, k, test.frames[0][k]).ok());
    const Status missing = writer->Finish(test.capture, test.mesh);
    EXPECT_EQ(missing.code(), StatusCode::kFailedPrecondition);
    EXPECT_NE(missing.message().find("camera \"cam1\" frame 0 was not written"), std::string::npos)
        << missing.message();
    const Status out_of_range = writer->WriteFrame(1, kNumFrames, test.frames[1][0]);
    EXPECT_EQ(out_of_range.code(), StatusCode::kInvalidArgument);
    EXPECT_NE(out_of_range.message().find("camera 1 frame 3: out of range"), std::string::npos)
        << out_of_range.message();
    const Status wrong_size = writer->WriteFrame(1, 0, DepthImage::Zeros(8, 8));
    EXPECT_NE(wrong_size.message().find("is 8x8"), std::string::npos) << wrong_size.message();
    EXPECT_FALSE(fs::exists(folder / "capture.json"));
    EXPECT_FALSE(fs::exists(folder / "cam0"));
  }
  EXPECT_FALSE(fs::exists(folder));
  EXPECT_EQ(CaptureWriter::Create(folder, test.capture, 0).status().code(),
            StatusCode::kInvalidArgument);
}

// Frame times (jittered or dropped frames) round-trip and replace k / fps; without them frame k
// shows k / fps.
TEST(Capture, FrameTimesReplaceTheNominalRate) {
  const CaptureDir dir;
  const Result<Capture> plain = ReadCapture(dir.path());
  ASSERT_TRUE(plain.ok()) << plain.status().ToString();
  EXPECT_TRUE(plain->frame_times.empty());
  EXPECT_DOUBLE_EQ(plain->FrameTime(2), 2.0 / 60.0);
  const Result<Capture> timed = dir.ReadEdited([](json& j) {
    j["frame_times"] = {0.0, 0.0171, 0.0502};
  });
  ASSERT_TRUE(timed.ok()) << timed.status().ToString();
  EXPECT_EQ(timed->frame_times, (std::vector<double>{0.0, 0.0171, 0.0502}));
  EXPECT_EQ(timed->FrameTime(1), 0.0171);
  const Result<Capture> again = CaptureFromJson(ToJson(*timed));
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  EXPECT_EQ(again->frame_times, timed->frame_times);
  EXPECT_FALSE(ToJson(*plain).contains("frame_times"));
}

TEST(CaptureRejects, BadFrameTimes) {
  const CaptureDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) {
    j["frame_times"] = {0.0, 0.02};
  }),
                {"frame_times", "has 2 times but the cameras have 3 frames"});
  ExpectInvalid(dir.ReadEdited([](json& j) {
    j["frame_times"] = {0.0, 0.02, 0.02};
  }),
                {"frame_times[2] = 0.02", "strictly increasing"});
  ExpectInvalid(dir.ReadEdited([](json& j) {
    j["frame_times"] = {-0.01, 0.02, 0.03};
  }),
                {"frame_times[0] = -0.01", ">= 0"});
  ExpectInvalid(dir.ReadEdited([](json& j) {
    j["frame_times"] = {0.0, "0.02", 0.03};
  }),
                {"frame_times[1] = \"0.02\"", "must be a number"});
  ExpectInvalid(dir.ReadEdited([](json& j) {
    j["frame_times"] = {0.0, 0.02, 1e6};
  }),
                {"frame_times[2] = 1000000", "frame periods", "too long"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["frame_times"] = "0 0.02 0.03"; }),
                {"frame_times", "must be a JSON array"});
}

// The floor a station measured round-trips, normalised; malformed floors name the field.
TEST(Capture, FloorIsReadNormalisedAndRoundTrips) {
  const CaptureDir dir;
  const Result<Capture> with_floor = dir.ReadEdited([](json& j) {
    j["floor"] = {{"normal", {0.0, 0.0, 2.0}}, {"offset", -0.25}};
  });
  ASSERT_TRUE(with_floor.ok()) << with_floor.status().ToString();
  ASSERT_TRUE(with_floor->floor.has_value());
  EXPECT_EQ(with_floor->floor->normal, Eigen::Vector3d(0, 0, 1));
  EXPECT_EQ(with_floor->floor->offset_m, -0.25);
  const Result<Capture> again = CaptureFromJson(ToJson(*with_floor));
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->floor->offset_m, -0.25);
  Capture without = *with_floor;
  without.floor.reset();
  EXPECT_FALSE(ToJson(without).contains("floor"));
  ExpectInvalid(dir.ReadEdited([](json& j) {
    j["floor"] = {{"normal", {0, 0, 0}}, {"offset", 0}};
  }),
                {"floor.normal", "must not be zero"});
  ExpectInvalid(dir.ReadEdited([](json& j) {
    j["floor"] = {{"normal", {0, 0, 1}}};
  }),
                {"floor.offset", "missing"});
}

}  // namespace
}  // namespace softid::capture
