#include "core/recording/recording.h"

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <initializer_list>
#include <iterator>
#include <limits>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "core/capture/capture.h"
#include "core/capture/depth_renderer.h"
#include "core/geometry/primitives.h"
#include "tests/core/capture/test_temp_dir.h"

namespace softid::recording {
namespace {

using capture::DepthImage;
using capture::PinholeCamera;
using capture::testing::TempDir;
using nlohmann::json;
namespace fs = std::filesystem;

PinholeCamera MakeCamera(const std::string& name, const Eigen::Vector3d& eye_W) {
  PinholeCamera camera;
  camera.name = name;
  camera.width = 32;
  camera.height = 24;
  camera.fx = 30.0;
  camera.fy = 31.0;
  camera.cx = 15.5;
  camera.cy = 11.5;
  camera.X_WC = capture::LookAt(eye_W, Eigen::Vector3d(0, 0, 0.05));
  return camera;
}

// A small valid recording: a sphere of radius 0.1 m (scanned in millimetres) seen by two cameras
// with different frame counts and clocks; cam0 also saw the empty scene twice.
struct TestRecording {
  Recording recording;
  geometry::TriangleMesh mesh;                  // [m]
  std::vector<std::vector<DepthImage>> frames;  // [camera][frame]
  std::vector<std::vector<DepthImage>> background;
};

TestRecording MakeTestRecording() {
  TestRecording test;
  test.mesh = geometry::MakeSphere(0.1, 2);
  Recording& recording = test.recording;
  recording.mesh_file = "scan.ply";
  recording.mesh_unit = MeshUnit::kMillimetre;
  recording.mass_kg = 0.38;
  RecordingCamera cam0;
  cam0.camera = MakeCamera("cam0", Eigen::Vector3d(0.6, 0.05, 0.15));
  cam0.has_world_from_camera = true;
  cam0.distortion = {0.1, -0.25, 0.001, -0.002, 0.05};
  cam0.depth_scale = 0.0005;
  cam0.frames = {{"", 12.3451}, {"", 12.3785}, {"", 12.4118}};
  RecordingCamera cam1;
  cam1.camera = MakeCamera("cam1", Eigen::Vector3d(-0.1, -0.7, 0.3));
  cam1.has_world_from_camera = true;
  cam1.depth_scale = 0.001;
  cam1.frames = {{"", -0.5}, {"", 1.7e9}};
  recording.cameras = {cam0, cam1};
  const capture::DepthRenderer renderer;
  for (const RecordingCamera& camera : recording.cameras) {
    std::vector<DepthImage> images;
    for (size_t k = 0; k < camera.frames.size(); ++k) {
      geometry::TriangleMesh moved = test.mesh;
      for (Eigen::Vector3d& v : moved.vertices) v.z() -= 0.01 * k;
      images.push_back(renderer.Render(moved, camera.camera));
    }
    test.frames.push_back(std::move(images));
  }
  DepthImage wall = DepthImage::Zeros(32, 24);
  for (float& d : wall.depth) d = 1.5f;
  test.background = {{wall, DepthImage::Zeros(32, 24)}, {}};
  return test;
}

// recording.json of MakeTestRecording() with file names, as WriteRecording writes it.
json ValidJson() {
  Recording recording = MakeTestRecording().recording;
  for (RecordingCamera& camera : recording.cameras) {
    for (size_t k = 0; k < camera.frames.size(); ++k) {
      camera.frames[k].file = camera.camera.name + "/" + std::to_string(k) + ".png";
    }
  }
  return ToJson(recording);
}

// A temporary folder holding a freshly written valid recording.
class RecordingDir {
 public:
  RecordingDir() : test_(MakeTestRecording()) {
    const Status status =
        WriteRecording(dir_.path(), test_.recording, test_.mesh, test_.frames, test_.background);
    EXPECT_TRUE(status.ok()) << status.ToString();
    original_json_ = LoadJson();
  }
  const fs::path& path() const { return dir_.path(); }
  const TestRecording& test() const { return test_; }
  const json& original_json() const { return original_json_; }

  json LoadJson() const {
    std::ifstream file(path() / "recording.json");
    return json::parse(file);
  }
  void SaveJson(const json& j) const { WriteText("recording.json", j.dump(2)); }
  void WriteText(const std::string& file, const std::string& text) const {
    std::ofstream(path() / file, std::ios::binary | std::ios::trunc) << text;
  }
  // Applies `edit` to the originally written recording.json and reads the recording back.
  template <typename Edit>
  Result<Recording> ReadEdited(Edit edit) const {
    json j = original_json_;
    edit(j);
    SaveJson(j);
    return ReadRecording(path());
  }

 private:
  TempDir dir_;
  TestRecording test_;
  json original_json_;
};

// Expects InvalidArgument whose message contains recording.json and every one of `parts`.
void ExpectInvalid(const Result<Recording>& result, std::initializer_list<std::string> parts) {
  ASSERT_FALSE(result.ok());
  const Status& status = result.status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument) << status.ToString();
  EXPECT_NE(status.message().find("recording.json"), std::string::npos) << status.message();
  for (const std::string& part : parts) {
    EXPECT_NE(status.message().find(part), std::string::npos)
        << "missing \"" << part << "\" in: " << status.message();
  }
}

void ExpectMessageHas(const Status& status, std::initializer_list<std::string> parts) {
  EXPECT_FALSE(status.ok());
  for (const std::string& part : parts) {
    EXPECT_NE(status.message().find(part), std::string::npos)
        << "missing \"" << part << "\" in: " << status.message();
  }
}

void ExpectSameRecording(const Recording& a, const Recording& b) {
  EXPECT_EQ(a.mesh_file, b.mesh_file);
  EXPECT_EQ(a.mesh_unit, b.mesh_unit);
  EXPECT_EQ(a.mass_kg, b.mass_kg);
  ASSERT_EQ(a.cameras.size(), b.cameras.size());
  for (size_t i = 0; i < a.cameras.size(); ++i) {
    const RecordingCamera& ca = a.cameras[i];
    const RecordingCamera& cb = b.cameras[i];
    EXPECT_EQ(ca.camera.name, cb.camera.name);
    EXPECT_EQ(ca.camera.width, cb.camera.width);
    EXPECT_EQ(ca.camera.height, cb.camera.height);
    EXPECT_EQ(ca.camera.fx, cb.camera.fx);
    EXPECT_EQ(ca.camera.fy, cb.camera.fy);
    EXPECT_EQ(ca.camera.cx, cb.camera.cx);
    EXPECT_EQ(ca.camera.cy, cb.camera.cy);
    EXPECT_EQ(ca.has_world_from_camera, cb.has_world_from_camera);
    EXPECT_EQ(ca.camera.X_WC.matrix(), cb.camera.X_WC.matrix());
    EXPECT_EQ(ca.distortion, cb.distortion);
    EXPECT_EQ(ca.depth_scale, cb.depth_scale);
    ASSERT_EQ(ca.frames.size(), cb.frames.size());
    for (size_t k = 0; k < ca.frames.size(); ++k) {
      EXPECT_EQ(ca.frames[k].file, cb.frames[k].file);
      EXPECT_EQ(ca.frames[k].time_s, cb.frames[k].time_s);
    }
    EXPECT_EQ(ca.background, cb.background);
  }
}

// Expects `read` to equal `original` after 16-bit quantisation at `depth_scale`.
void ExpectSameDepth(const DepthImage& read, const DepthImage& original, double depth_scale) {
  ASSERT_EQ(read.depth.size(), original.depth.size());
  for (size_t p = 0; p < original.depth.size(); ++p) {
    EXPECT_EQ(read.depth[p] == 0.0f, original.depth[p] == 0.0f);
    EXPECT_NEAR(read.depth[p], original.depth[p], depth_scale / 2 + 1e-6);
  }
}

// A written recording reads back with every field, time stamp and background frame; the mesh
// scanned in millimetres loads in metres.
TEST(Recording, WriteReadRoundTrip) {
  const RecordingDir dir;
  const TestRecording& test = dir.test();
  EXPECT_FALSE(fs::exists(dir.path() / "recording.json.tmp"));
  const Result<Recording> read = ReadRecording(dir.path());
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(read->directory, dir.path());
  EXPECT_EQ(read->NumCameras(), 2);
  Recording expected = test.recording;
  for (RecordingCamera& camera : expected.cameras) {
    for (size_t k = 0; k < camera.frames.size(); ++k) {
      camera.frames[k].file = camera.camera.name + "/00000" + std::to_string(k) + ".png";
    }
  }
  expected.cameras[0].background = {"cam0/bg_000.png", "cam0/bg_001.png"};
  ExpectSameRecording(*read, expected);
  EXPECT_EQ(read->cameras[1].frames[1].time_s, 1.7e9);

  for (int i = 0; i < 2; ++i) {
    const double depth_scale = test.recording.cameras[i].depth_scale;
    for (size_t k = 0; k < test.frames[i].size(); ++k) {
      const Result<DepthImage> frame = LoadRecordingFrame(*read, i, static_cast<int>(k));
      ASSERT_TRUE(frame.ok()) << frame.status().ToString();
      EXPECT_GT(test.frames[i][k].NumValid(), 20);
      ExpectSameDepth(*frame, test.frames[i][k], depth_scale);
    }
  }
  const Result<DepthImage> wall = LoadBackgroundFrame(*read, 0, 0);
  ASSERT_TRUE(wall.ok()) << wall.status().ToString();
  ExpectSameDepth(*wall, test.background[0][0], 0.0005);
  EXPECT_EQ(LoadBackgroundFrame(*read, 0, 1)->NumValid(), 0);

  // The file holds millimetres; LoadRecordingMesh gives metres.
  const Result<geometry::TriangleMesh> raw = geometry::ReadTriangleMesh(dir.path() / "scan.ply");
  ASSERT_TRUE(raw.ok()) << raw.status().ToString();
  EXPECT_NEAR(raw->Bounds().sizes().maxCoeff(), 200.0, 1e-3);
  const Result<geometry::TriangleMesh> mesh = LoadRecordingMesh(*read);
  ASSERT_TRUE(mesh.ok()) << mesh.status().ToString();
  EXPECT_EQ(mesh->vertices.size(), test.mesh.vertices.size());
  EXPECT_EQ(mesh->triangles.size(), test.mesh.triangles.size());
  EXPECT_NEAR(mesh->Bounds().sizes().maxCoeff(), 0.2, 1e-6);
  EXPECT_NEAR(std::abs(geometry::SignedVolume(*mesh)), geometry::SignedVolume(test.mesh), 1e-9);
}

// A mesh named .obj is written as OBJ; metres are the default unit.
TEST(Recording, WritesObjInMetres) {
  TestRecording test = MakeTestRecording();
  test.recording.mesh_file = "mesh/object.OBJ";
  test.recording.mesh_unit = MeshUnit::kMetre;
  const TempDir dir;
  ASSERT_TRUE(WriteRecording(dir.path(), test.recording, test.mesh, test.frames).ok());
  const Result<Recording> read = ReadRecording(dir.path());
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_TRUE(read->cameras[0].background.empty());
  std::ifstream obj(dir.path() / "mesh" / "object.OBJ");
  const std::string text((std::istreambuf_iterator<char>(obj)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("\nv "), std::string::npos);
  const Result<geometry::TriangleMesh> raw =
      geometry::ReadTriangleMesh(dir.path() / "mesh" / "object.OBJ");
  ASSERT_TRUE(raw.ok()) << raw.status().ToString();
  EXPECT_NEAR(raw->Bounds().sizes().maxCoeff(), 0.2, 1e-6);
  const Result<geometry::TriangleMesh> mesh = LoadRecordingMesh(*read);
  ASSERT_TRUE(mesh.ok()) << mesh.status().ToString();
  EXPECT_NEAR(mesh->Bounds().sizes().maxCoeff(), 0.2, 1e-6);
}

// ToJson and RecordingFromJson are inverse; optional fields are omitted when unset and take
// their defaults when absent.
TEST(Recording, JsonRoundTrip) {
  Recording recording = MakeTestRecording().recording;
  recording.cameras[0].frames = {{"a/0.png", -3.25}, {"a/1.png", 1e-9}};
  recording.cameras[0].background = {"a/bg.png"};
  recording.cameras[1].frames = {{"b/0.png", 1712345678.123456}};
  const json j = ToJson(recording);
  EXPECT_EQ(j["format"], "softid-recording/1");
  EXPECT_EQ(j["mesh_unit"], "mm");
  EXPECT_EQ(j["cameras"][0]["distortion"].size(), 5u);
  EXPECT_EQ(j["cameras"][0]["frames"][0]["t"], -3.25);
  const Result<Recording> parsed = RecordingFromJson(j);
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
  ExpectSameRecording(*parsed, recording);
  EXPECT_EQ(ToJson(*parsed), j);
  EXPECT_EQ(RecordingFromJson(json::parse(j.dump()))->cameras[1].frames[0].time_s,
            1712345678.123456);

  // One camera: no pose needed (identity), no distortion, background, mass or unit.
  recording.cameras.pop_back();
  recording.cameras[0].has_world_from_camera = false;
  recording.cameras[0].camera.X_WC = Eigen::Isometry3d::Identity();
  recording.cameras[0].distortion.clear();
  recording.cameras[0].background.clear();
  recording.mass_kg.reset();
  json without = ToJson(recording);
  for (const char* key : {"world_from_camera", "distortion", "background"}) {
    EXPECT_FALSE(without["cameras"][0].contains(key)) << key;
  }
  EXPECT_FALSE(without.contains("mass_kg"));
  without.erase("mesh_unit");
  const Result<Recording> minimal = RecordingFromJson(without);
  ASSERT_TRUE(minimal.ok()) << minimal.status().ToString();
  EXPECT_EQ(minimal->mesh_unit, MeshUnit::kMetre);
  EXPECT_FALSE(minimal->cameras[0].has_world_from_camera);
  EXPECT_TRUE(minimal->cameras[0].camera.X_WC.matrix().isIdentity(0.0));
  EXPECT_EQ(MetresPerUnit(MeshUnit::kMillimetre), 1e-3);
  EXPECT_EQ(MetresPerUnit(MeshUnit::kMetre), 1.0);
}

// Unknown extra fields, at every level, are ignored.
TEST(Recording, IgnoresUnknownFields) {
  const RecordingDir dir;
  const Result<Recording> read = dir.ReadEdited([](json& j) {
    j["station"] = {{"operator", "x"}};
    j["cameras"][0]["serial"] = "ABC123";
    j["cameras"][0]["frames"][1]["exposure_us"] = 250;
  });
  EXPECT_TRUE(read.ok()) << read.status().ToString();
}

// A folder without recording.json (never or not completely written) is NotFound.
TEST(Recording, MissingRecordingJsonIsNotFound) {
  const RecordingDir dir;
  fs::remove(dir.path() / "recording.json");
  EXPECT_EQ(ReadRecording(dir.path()).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(ReadRecording(dir.path() / "nope").status().code(), StatusCode::kNotFound);
}

// Index errors of the loaders name the index.
TEST(Recording, LoadersRejectBadIndices) {
  const RecordingDir dir;
  const Result<Recording> read = ReadRecording(dir.path());
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  ExpectMessageHas(LoadRecordingFrame(*read, 2, 0).status(), {"camera = 2", "[0, 2)"});
  ExpectMessageHas(LoadRecordingFrame(*read, 1, 2).status(), {"frame = 2", "[0, 2)"});
  ExpectMessageHas(LoadRecordingFrame(*read, 0, -1).status(), {"frame = -1"});
  ExpectMessageHas(LoadBackgroundFrame(*read, 1, 0).status(), {"background = 0", "[0, 0)"});
  ExpectMessageHas(LoadBackgroundFrame(*read, -1, 0).status(), {"camera = -1"});
}

// Another kind of file, another version, or no string is rejected with the value.
TEST(RecordingRejects, WrongFormat) {
  const RecordingDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["format"] = "softid-capture/1"; }),
                {"recording.json: format = \"softid-capture/1\": not a softid recording "
                 "(expected \"softid-recording/1\")"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["format"] = "softid-recording/2"; }),
                {"format = \"softid-recording/2\"", "unsupported version"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["format"] = 1; }),
                {"format = 1", "must be a string"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j = json::array(); }), {"(root) = []", "object"});
  dir.WriteText("recording.json", "{\"format\": \"softid-recording/1\", ");
  ExpectInvalid(ReadRecording(dir.path()), {"invalid JSON"});
}

// Every required field, when missing, is named in the error.
TEST(RecordingRejects, MissingRequiredFields) {
  const RecordingDir dir;
  for (const std::string top : {"format", "mesh", "cameras"}) {
    ExpectInvalid(dir.ReadEdited([&](json& j) { j.erase(top); }),
                  {"recording.json: " + top + ": missing required field"});
  }
  for (const std::string field :
       {"name", "width", "height", "fx", "fy", "cx", "cy", "depth_scale", "frames"}) {
    ExpectInvalid(dir.ReadEdited([&](json& j) { j["cameras"][1].erase(field); }),
                  {"cameras[1]." + field + ": missing required field"});
  }
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["frames"][2].erase("t"); }),
                {"cameras[0].frames[2].t: missing required field"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["frames"][0].erase("file"); }),
                {"cameras[0].frames[0].file: missing required field"});
}

// mesh_unit is "m" or "mm".
TEST(RecordingRejects, BadMeshUnit) {
  const RecordingDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mesh_unit"] = "cm"; }),
                {"mesh_unit = \"cm\": must be \"m\" or \"mm\""});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mesh_unit"] = 0.001; }),
                {"mesh_unit = 0.001", "must be a string"});
}

// A mesh in millimetres declared as metres is 200 m long: the error suggests "mesh_unit": "mm".
// The reverse suggests "m"; the extent is checked after the unit.
TEST(RecordingRejects, MeshUnitMismatch) {
  const RecordingDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mesh_unit"] = "m"; }),
                {"mesh = \"scan.ply\"", "longest side 200 m", "must lie in [0.001, 100] m",
                 "set \"mesh_unit\": \"mm\""});
  ExpectInvalid(dir.ReadEdited([](json& j) { j.erase("mesh_unit"); }),
                {"mesh = \"scan.ply\"", "\"mesh_unit\": \"mm\""});
  ASSERT_TRUE(geometry::WriteTriangleMeshObj(dir.path() / "metres.obj", dir.test().mesh).ok());
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mesh"] = "metres.obj"; }),
                {"mesh = \"metres.obj\"", "longest side 0.0002 m", "set \"mesh_unit\": \"m\""});
  EXPECT_TRUE(dir.ReadEdited([](json& j) {
                   j["mesh"] = "metres.obj";
                   j["mesh_unit"] = "m";
                 })
                  .ok());
  dir.WriteText("flat.obj", "v 0 0 0\nv 100 0 0\nv 0 100 0\nv 100 100 0\nf 1 2 3\nf 2 4 3\n");
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mesh"] = "flat.obj"; }),
                {"mesh = \"flat.obj\"", "encloses no volume"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mesh"] = "missing.ply"; }),
                {"mesh = \"missing.ply\"", "cannot load mesh"});
}

// Time stamps increase strictly within a camera.
TEST(RecordingRejects, NonIncreasingTimeStamps) {
  const RecordingDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) {
    j["cameras"][0]["frames"][0]["t"] = 1.0;
    j["cameras"][0]["frames"][1]["t"] = 1.3;
    j["cameras"][0]["frames"][2]["t"] = 1.2;
  }),
                {"recording.json: cameras[0].frames[2].t = 1.2: must be greater than "
                 "cameras[0].frames[1].t = 1.3 (time stamps strictly increasing)"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][1]["frames"][1]["t"] = -0.5; }),
                {"cameras[1].frames[1].t = -0.5", "cameras[1].frames[0].t = -0.5"});
}

// Time stamps are finite numbers (negative and large ones are fine).
TEST(RecordingRejects, NonFiniteTimeStamps) {
  const json original = ValidJson();
  for (const double bad :
       {std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity(),
        std::numeric_limits<double>::quiet_NaN()}) {
    json j = original;
    j["cameras"][0]["frames"][1]["t"] = bad;
    ExpectInvalid(RecordingFromJson(j), {"cameras[0].frames[1].t = ", "must be finite"});
  }
  json j = original;
  j["cameras"][0]["frames"][1]["t"] = nullptr;
  ExpectInvalid(RecordingFromJson(j), {"cameras[0].frames[1].t = null", "must be a number"});
  j["cameras"][0]["frames"][1]["t"] = "12.3785";
  ExpectInvalid(RecordingFromJson(j), {"cameras[0].frames[1].t = \"12.3785\"", "must be a number"});
  // JSON text cannot hold infinity: a number too large for a double is refused by the parser.
  const RecordingDir dir;
  json text = dir.original_json();
  text["cameras"][0]["frames"][1]["t"] = 7.0;
  std::string dumped = text.dump();
  dumped.replace(dumped.find("7.0"), 3, "1e999");
  dir.WriteText("recording.json", dumped);
  ExpectInvalid(ReadRecording(dir.path()), {"invalid JSON", "cameras[0].frames[1].t", "1e999"});
}

// distortion holds 4, 5, 8, 12 or 14 finite numbers.
TEST(RecordingRejects, BadDistortion) {
  const json original = ValidJson();
  for (const int n : {4, 5, 8, 12, 14}) {
    json j = original;
    j["cameras"][1]["distortion"] = std::vector<double>(n, 0.01);
    EXPECT_TRUE(RecordingFromJson(j).ok()) << n;
  }
  for (const int n : {0, 3, 6, 13, 15}) {
    json j = original;
    j["cameras"][1]["distortion"] = std::vector<double>(n, 0.01);
    ExpectInvalid(RecordingFromJson(j),
                  {"cameras[1].distortion = [", "has " + std::to_string(n) + " coefficients",
                   "4, 5, 8, 12 or 14"});
  }
  json j = original;
  j["cameras"][0]["distortion"][1] = "x";
  ExpectInvalid(RecordingFromJson(j), {"cameras[0].distortion[1] = \"x\"", "must be a number"});
  j["cameras"][0]["distortion"][1] = std::numeric_limits<double>::infinity();
  ExpectInvalid(RecordingFromJson(j), {"cameras[0].distortion[1]", "must be finite"});
  j["cameras"][0]["distortion"] = 0.1;
  ExpectInvalid(RecordingFromJson(j), {"cameras[0].distortion = 0.1", "JSON array"});
}

// With two or more cameras every camera needs world_from_camera; with one it is optional.
TEST(RecordingRejects, TwoCamerasWithoutPose) {
  const RecordingDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][1].erase("world_from_camera"); }),
                {"recording.json: cameras[1].world_from_camera: missing required field",
                 "2 cameras", "common world frame"});
  const Result<Recording> one = dir.ReadEdited([](json& j) {
    j["cameras"].erase(1);
    j["cameras"][0].erase("world_from_camera");
  });
  ASSERT_TRUE(one.ok()) << one.status().ToString();
  EXPECT_FALSE(one->cameras[0].has_world_from_camera);
  EXPECT_TRUE(one->cameras[0].camera.X_WC.matrix().isIdentity(0.0));
}

// A scaled, reflected, projective or short world_from_camera is rejected.
TEST(RecordingRejects, NonRigidPose) {
  const RecordingDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) {
    json& pose = j["cameras"][0]["world_from_camera"];
    for (int i : {0, 1, 2, 4, 5, 6, 8, 9, 10}) pose[i] = pose[i].get<double>() * 1.01;
  }),
                {"cameras[0].world_from_camera", "not orthonormal"});
  ExpectInvalid(dir.ReadEdited([](json& j) {
    json& pose = j["cameras"][1]["world_from_camera"];
    for (int i : {0, 4, 8}) pose[i] = -pose[i].get<double>();
  }),
                {"cameras[1].world_from_camera", "determinant -1"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["world_from_camera"][12] = 0.5; }),
                {"cameras[0].world_from_camera", "last row = [0.5, 0, 0, 1]"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["world_from_camera"].erase(15); }),
                {"cameras[0].world_from_camera = [", "16 numbers"});
}

// A frame or background PNG of another size than the camera's names the camera, the index, the
// file and both sizes.
TEST(RecordingRejects, FrameSizeMismatch) {
  const RecordingDir dir;
  ASSERT_TRUE(cv::imwrite((dir.path() / "cam1" / "000001.png").string(),
                          cv::Mat(24, 33, CV_16UC1, cv::Scalar(1000))));
  ExpectInvalid(ReadRecording(dir.path()), {"cameras[1].frames[1].file = \"cam1/000001.png\"",
                                            "camera \"cam1\"", "33x24", "expected 32x24"});
  ASSERT_TRUE(cv::imwrite((dir.path() / "cam1" / "000001.png").string(),
                          cv::Mat(24, 32, CV_16UC1, cv::Scalar(1000))));
  ASSERT_TRUE(cv::imwrite((dir.path() / "cam0" / "bg_001.png").string(),
                          cv::Mat(20, 32, CV_16UC1, cv::Scalar(1000))));
  ExpectInvalid(ReadRecording(dir.path()), {"cameras[0].background[1] = \"cam0/bg_001.png\"",
                                            "camera \"cam0\"", "32x20", "expected 32x24"});
  ASSERT_TRUE(cv::imwrite((dir.path() / "cam0" / "bg_001.png").string(),
                          cv::Mat(24, 32, CV_8UC1, cv::Scalar(10))));
  ExpectInvalid(ReadRecording(dir.path()), {"cameras[0].background[1]", "8-bit"});
}

// A frame or background file that does not exist is rejected naming the field and the file.
TEST(RecordingRejects, MissingFrameFile) {
  const RecordingDir dir;
  fs::remove(dir.path() / "cam0" / "000002.png");
  ExpectInvalid(ReadRecording(dir.path()),
                {"cameras[0].frames[2].file = \"cam0/000002.png\"", "file not found"});
  ExpectInvalid(dir.ReadEdited([](json& j) {
    j["cameras"][0]["frames"].erase(2);
    j["cameras"][1]["background"] = {"cam1/bg_000.png"};
  }),
                {"cameras[1].background[0] = \"cam1/bg_000.png\"", "file not found"});
}

// Absolute paths, ".." and '\\' are rejected for the mesh, the frames and the background.
TEST(RecordingRejects, PathsLeavingTheFolder) {
  const RecordingDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mesh"] = "../scan.ply"; }),
                {"mesh = \"../scan.ply\"", "must not leave the recording folder"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["frames"][1]["file"] = "/etc/x"; }),
                {"cameras[0].frames[1].file = \"/etc/x\"",
                 "must be relative to the recording folder, not absolute"});
  ExpectInvalid(
      dir.ReadEdited([](json& j) { j["cameras"][1]["frames"][0]["file"] = "cam1/../../a.png"; }),
      {"cameras[1].frames[0].file = \"cam1/../../a.png\"", "must not leave"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["background"][0] = "../bg.png"; }),
                {"cameras[0].background[0] = \"../bg.png\"", "must not leave"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mesh"] = "/tmp/scan.ply"; }),
                {"mesh = \"/tmp/scan.ply\"", "absolute"});
  ExpectInvalid(
      dir.ReadEdited([](json& j) { j["cameras"][0]["frames"][0]["file"] = "cam0\\000000.png"; }),
      {"cameras[0].frames[0].file", "'/'"});
}

// A symlink inside the folder that points outside it is rejected; one that stays inside is fine.
TEST(RecordingRejects, SymlinkEscapingTheFolder) {
  const RecordingDir dir;
  const TempDir outside;
  fs::copy_file(dir.path() / "cam0" / "000000.png", outside.path() / "frame.png");
  fs::copy_file(dir.path() / "scan.ply", outside.path() / "scan.ply");
  fs::create_symlink(outside.path() / "frame.png", dir.path() / "cam0" / "link.png");
  fs::create_symlink(outside.path() / "scan.ply", dir.path() / "link.ply");
  fs::create_directory_symlink(outside.path(), dir.path() / "elsewhere");
  ExpectInvalid(
      dir.ReadEdited([](json& j) { j["cameras"][0]["frames"][0]["file"] = "cam0/link.png"; }),
      {"cameras[0].frames[0].file = \"cam0/link.png\"", "resolves outside the recording folder"});
  ExpectInvalid(
      dir.ReadEdited([](json& j) { j["cameras"][0]["background"][1] = "elsewhere/frame.png"; }),
      {"cameras[0].background[1] = \"elsewhere/frame.png\"", "outside"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mesh"] = "link.ply"; }),
                {"mesh = \"link.ply\"", "resolves outside the recording folder"});
  fs::create_symlink("000001.png", dir.path() / "cam0" / "inside.png");
  EXPECT_TRUE(
      dir.ReadEdited([](json& j) { j["cameras"][0]["frames"][0]["file"] = "cam0/inside.png"; })
          .ok());
}

// Camera names are unique and usable as folder names.
TEST(RecordingRejects, BadCameraNames) {
  const RecordingDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][1]["name"] = "cam0"; }),
                {"cameras[1].name = \"cam0\"", "duplicate camera name"});
  for (const std::string name : {"a/b", "..", ".", "a\\b"}) {
    ExpectInvalid(dir.ReadEdited([&](json& j) { j["cameras"][0]["name"] = name; }),
                  {"cameras[0].name = ", "must be usable as a folder name"});
  }
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["name"] = ""; }),
                {"cameras[0].name = \"\"", "must not be empty"});
}

// Values and JSON types of the other fields are checked as in capture.json.
TEST(RecordingRejects, BadValuesAndTypes) {
  const RecordingDir dir;
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["fx"] = -1; }),
                {"recording.json: cameras[0].fx = -1: must be positive and finite"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][1]["depth_scale"] = 0; }),
                {"cameras[1].depth_scale = 0", "must be positive"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["mass_kg"] = -0.38; }),
                {"mass_kg = -0.38", "must be positive"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["width"] = 32.5; }),
                {"cameras[0].width = 32.5", "must be an integer"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"] = json::array(); }),
                {"cameras = []", "at least one camera"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["frames"] = json::array(); }),
                {"cameras[0].frames = []", "at least one frame"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["frames"][0] = "cam0/000000.png"; }),
                {"cameras[0].frames[0] = \"cam0/000000.png\"", "must be a JSON object"});
  ExpectInvalid(dir.ReadEdited([](json& j) { j["cameras"][0]["background"] = "cam0/bg.png"; }),
                {"cameras[0].background = \"cam0/bg.png\"", "JSON array"});
}

// Camera, frame, background and image-size limits are refused from recording.json alone.
TEST(RecordingRejects, ResourceBounds) {
  const json original = ValidJson();
  json j = original;
  j["cameras"][0]["width"] = 16384;
  j["cameras"][0]["height"] = 16384;
  ExpectInvalid(RecordingFromJson(j), {"cameras[0].width = 16384", "at most 16777216 pixels"});
  j = original;
  json& frames = j["cameras"][1]["frames"] = json::array();
  for (int k = 0; k <= capture::kMaxFramesPerCamera; ++k) {
    frames.push_back({{"file", "f.png"}, {"t", k}});
  }
  ExpectInvalid(RecordingFromJson(j),
                {"cameras[1].frames", "20001 frames: at most 20000 frames per camera"});
  j = original;
  j["cameras"][0]["background"] = std::vector<std::string>(kMaxBackgroundFrames + 1, "bg.png");
  ExpectInvalid(RecordingFromJson(j), {"cameras[0].background", "1001 frames: at most 1000"});
  j = original;
  while (j["cameras"].size() <= static_cast<size_t>(capture::kMaxCameras)) {
    json camera = j["cameras"][0];
    camera["name"] = "cam" + std::to_string(j["cameras"].size());
    j["cameras"].push_back(camera);
  }
  ExpectInvalid(RecordingFromJson(j), {"cameras: 17 cameras: at most 16 are accepted"});
}

// WriteRecording validates before writing anything: bad input leaves no recording.json behind.
TEST(Recording, WriteRejectsInvalidInput) {
  const TestRecording test = MakeTestRecording();
  const TempDir dir;
  const auto write = [&](const TestRecording& t) {
    return WriteRecording(dir.path(), t.recording, t.mesh, t.frames, t.background);
  };
  TestRecording bad = test;
  bad.recording.cameras[0].camera.name = "a/b";
  ExpectMessageHas(write(bad), {"cameras[0].name = \"a/b\"", "folder name"});
  bad = test;
  bad.frames[1].pop_back();
  ExpectMessageHas(write(bad), {"cameras[1].frames has 2 time stamps", "holds 1 images"});
  bad = test;
  bad.background[0][1] = DepthImage::Zeros(10, 10);
  ExpectMessageHas(write(bad), {"background_per_camera[0][1] is 10x10", "\"cam0\" is 32x24"});
  bad = test;
  bad.recording.cameras[0].frames[2].time_s = 12.0;
  ExpectMessageHas(write(bad), {"cameras[0].frames[2].t = 12", "strictly increasing"});
  bad = test;
  bad.recording.mesh_file = "scan.stl";
  ExpectMessageHas(write(bad), {"mesh = \"scan.stl\"", "\".obj\" or \".ply\""});
  bad = test;
  for (Eigen::Vector3d& v : bad.mesh.vertices) v *= 1000.0;
  ExpectMessageHas(write(bad), {"longest side 200 m", "in metres"});
  bad = test;
  bad.recording.cameras[1].has_world_from_camera = false;
  ExpectMessageHas(write(bad), {"cameras[1].world_from_camera: missing required field"});
  EXPECT_FALSE(fs::exists(dir.path() / "recording.json"));
  EXPECT_FALSE(fs::exists(dir.path() / "scan.ply"));
  // A folder already holding a capture is not made ambiguous.
  std::ofstream(dir.path() / "capture.json") << "{}";
  ExpectMessageHas(write(test), {"capture.json", "either a capture or a recording"});
  EXPECT_FALSE(fs::exists(dir.path() / "recording.json"));
}

// capture.json means a capture, recording.json a recording; both are ambiguous, neither is
// NotFound naming both.
TEST(Recording, DetectFolderFormat) {
  const TempDir dir;
  Result<FolderFormat> format = DetectFolderFormat(dir.path());
  EXPECT_EQ(format.status().code(), StatusCode::kNotFound);
  ExpectMessageHas(format.status(), {"capture.json", "recording.json"});
  EXPECT_EQ(DetectFolderFormat(dir.path() / "nope").status().code(), StatusCode::kNotFound);

  std::ofstream(dir.path() / "recording.json") << "{}";
  format = DetectFolderFormat(dir.path());
  ASSERT_TRUE(format.ok()) << format.status().ToString();
  EXPECT_EQ(*format, FolderFormat::kRecording);

  std::ofstream(dir.path() / "capture.json") << "{}";
  format = DetectFolderFormat(dir.path());
  EXPECT_EQ(format.status().code(), StatusCode::kInvalidArgument);
  ExpectMessageHas(format.status(), {"capture.json", "recording.json", "ambiguous"});

  fs::remove(dir.path() / "recording.json");
  format = DetectFolderFormat(dir.path());
  ASSERT_TRUE(format.ok()) << format.status().ToString();
  EXPECT_EQ(*format, FolderFormat::kCapture);
}

}  // namespace
}  // namespace softid::recording
