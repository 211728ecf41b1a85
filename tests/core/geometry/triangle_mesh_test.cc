#include "core/geometry/triangle_mesh.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <numbers>
#include <stdexcept>
#include <string>

#include "core/geometry/primitives.h"
#include "tests/core/geometry/mesh_test_util.h"

namespace softid::geometry {
namespace {

using testing::IsWatertight;
using testing::MaxEdgeLength;
using testing::TempPath;

// A regular tetrahedron-like corner tet: volume 1/6 * a^3 with a = 0.1 m.
TriangleMesh CornerTet() {
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {0.1, 0, 0}, {0, 0.1, 0}, {0, 0, 0.1}};
  mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return mesh;
}

// Expects `read` to have the same triangles (in order) at the same positions as `expected`.
void ExpectSameGeometry(const TriangleMesh& expected, const TriangleMesh& read, double tol) {
  ASSERT_EQ(read.vertices.size(), expected.vertices.size());
  ASSERT_EQ(read.triangles.size(), expected.triangles.size());
  for (size_t t = 0; t < expected.triangles.size(); ++t) {
    for (int c = 0; c < 3; ++c) {
      const Eigen::Vector3d& a = expected.vertices[expected.triangles[t][c]];
      const Eigen::Vector3d& b = read.vertices[read.triangles[t][c]];
      ASSERT_LE((a - b).norm(), tol) << "triangle " << t << " corner " << c;
    }
  }
}

void WriteText(const std::filesystem::path& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

// OBJ written with %.9g reads back with the same triangles and float-precision positions.
TEST(TriangleMesh, ObjRoundTrip) {
  TriangleMesh mesh = MakeSphere(0.1, 2);
  for (Eigen::Vector3d& v : mesh.vertices) v += Eigen::Vector3d(1.25, -0.5, 3.0);
  const auto path = TempPath("mesh.obj");
  ASSERT_TRUE(WriteTriangleMeshObj(path, mesh).ok());
  const Result<TriangleMesh> read = ReadTriangleMesh(path);
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  ExpectSameGeometry(mesh, *read, 1e-6);
}

// Binary PLY reads back with the same triangles and float-precision positions.
TEST(TriangleMesh, PlyRoundTrip) {
  TriangleMesh mesh = MakeTorus(0.2, 0.05, 24, 12);
  for (Eigen::Vector3d& v : mesh.vertices) v += Eigen::Vector3d(-2.0, 0.75, 0.125);
  const auto path = TempPath("mesh.ply");
  ASSERT_TRUE(WriteTriangleMeshPly(path, mesh).ok());
  const Result<TriangleMesh> read = ReadTriangleMesh(path);
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  ExpectSameGeometry(mesh, *read, 1e-6);
}

// A hand-written binary STL (no index, 12 corners) is merged back to 4 vertices.
TEST(TriangleMesh, ReadsBinaryStlAndMergesVertices) {
  const TriangleMesh tet = CornerTet();
  std::string bytes(80, ' ');
  const std::uint32_t count = 4;
  bytes.append(reinterpret_cast<const char*>(&count), 4);
  for (const Eigen::Vector3i& t : tet.triangles) {
    float record[12] = {0};
    for (int c = 0; c < 3; ++c) {
      for (int a = 0; a < 3; ++a) record[3 + 3 * c + a] = static_cast<float>(tet.vertices[t[c]][a]);
    }
    bytes.append(reinterpret_cast<const char*>(record), sizeof(record));
    bytes.append(2, '\0');  // attribute byte count
  }
  const auto path = TempPath("tet.stl");
  WriteText(path, bytes);
  const Result<TriangleMesh> read = ReadTriangleMesh(path);
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(read->vertices.size(), 4u);
  EXPECT_EQ(read->triangles.size(), 4u);
  EXPECT_TRUE(IsWatertight(*read));
  EXPECT_NEAR(SignedVolume(*read), 0.1 * 0.1 * 0.1 / 6.0, 1e-9);
}

// A hand-written ascii STL is merged back to 4 vertices with the right orientation.
TEST(TriangleMesh, ReadsAsciiStlAndMergesVertices) {
  const TriangleMesh tet = CornerTet();
  std::string text = "solid tet\n";
  for (const Eigen::Vector3i& t : tet.triangles) {
    text += " facet normal 0 0 0\n  outer loop\n";
    for (int c = 0; c < 3; ++c) {
      const Eigen::Vector3d& v = tet.vertices[t[c]];
      text += "   vertex " + std::to_string(v.x()) + " " + std::to_string(v.y()) + " " +
              std::to_string(v.z()) + "\n";
    }
    text += "  endloop\n endfacet\n";
  }
  text += "endsolid tet\n";
  const auto path = TempPath("tet_ascii.stl");
  WriteText(path, text);
  const Result<TriangleMesh> read = ReadTriangleMesh(path);
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_EQ(read->vertices.size(), 4u);
  EXPECT_EQ(read->triangles.size(), 4u);
  EXPECT_TRUE(IsWatertight(*read));
  EXPECT_NEAR(SignedVolume(*read), 0.1 * 0.1 * 0.1 / 6.0, 1e-9);
}

// Reading `path` fails with `code` and the message names the path.
void ExpectRejectedNamingPath(const std::filesystem::path& path, StatusCode code) {
  const Result<TriangleMesh> read = ReadTriangleMesh(path);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), code);
  EXPECT_NE(read.status().message().find(path.string()), std::string::npos)
      << read.status().message();
}

// A missing file is NotFound and the message names the path.
TEST(TriangleMesh, MissingFileNamesPath) {
  const auto path = TempPath("does_not_exist.obj");
  ExpectRejectedNamingPath(path, StatusCode::kNotFound);
}

// A garbage file is InvalidArgument and the message names the path.
TEST(TriangleMesh, GarbageFileNamesPath) {
  const auto path = TempPath("garbage.ply");
  WriteText(path, "ply\nformat nonsense 7\n\x01\x02\x03 not a mesh at all\n");
  ExpectRejectedNamingPath(path, StatusCode::kInvalidArgument);
}

// An empty file is InvalidArgument and the message names the path.
TEST(TriangleMesh, EmptyFileNamesPath) {
  const auto path = TempPath("empty.stl");
  WriteText(path, "");
  ExpectRejectedNamingPath(path, StatusCode::kInvalidArgument);
}

// A point cloud OBJ (vertices only) is rejected for having no triangles.
TEST(TriangleMesh, NoTrianglesIsAnError) {
  const auto path = TempPath("points.obj");
  WriteText(path, "v 0 0 0\nv 1 0 0\nv 0 1 0\n");
  ExpectRejectedNamingPath(path, StatusCode::kInvalidArgument);
}

// Non-finite coordinates are rejected naming the path.
TEST(TriangleMesh, NonFiniteCoordinatesAreAnError) {
  const auto path = TempPath("nan.obj");
  WriteText(path, "v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n");
  ExpectRejectedNamingPath(path, StatusCode::kInvalidArgument);
  const Result<TriangleMesh> read = ReadTriangleMesh(path);
  EXPECT_NE(read.status().message().find("non-finite"), std::string::npos)
      << read.status().message();
}

// Writing into a missing directory is an IoError naming the path.
TEST(TriangleMesh, WriteFailureNamesPath) {
  const auto path = TempPath("no_such_dir") / "mesh.ply";
  const Status status = WriteTriangleMeshPly(path, CornerTet());
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.code(), StatusCode::kIoError);
  EXPECT_NE(status.message().find(path.string()), std::string::npos);
}

// Bounds is the box of the vertices.
TEST(TriangleMesh, Bounds) {
  const Eigen::AlignedBox3d box = CornerTet().Bounds();
  EXPECT_TRUE(box.min().isApprox(Eigen::Vector3d::Zero()));
  EXPECT_TRUE(box.max().isApprox(Eigen::Vector3d::Constant(0.1)));
  EXPECT_TRUE(TriangleMesh().Bounds().isEmpty());
}

// SignedVolume is exact for a tet, flips with orientation and ignores translation.
TEST(TriangleMesh, SignedVolumeOfTet) {
  TriangleMesh tet = CornerTet();
  EXPECT_NEAR(SignedVolume(tet), 1e-3 / 6.0, 1e-15);
  for (Eigen::Vector3d& v : tet.vertices) v += Eigen::Vector3d(5, -3, 2);
  EXPECT_NEAR(SignedVolume(tet), 1e-3 / 6.0, 1e-14);
  for (Eigen::Vector3i& t : tet.triangles) std::swap(t[1], t[2]);
  EXPECT_NEAR(SignedVolume(tet), -1e-3 / 6.0, 1e-14);
}

// SurfaceArea of the corner tet: three right triangles plus an equilateral one.
TEST(TriangleMesh, SurfaceAreaOfTet) {
  const double a = 0.1;
  const double expected = 3 * 0.5 * a * a + std::sqrt(3.0) / 4.0 * 2.0 * a * a;
  EXPECT_NEAR(SurfaceArea(CornerTet()), expected, 1e-15);
}

// VertexAreas sums to the surface area and gives each corner a third of its triangles.
TEST(TriangleMesh, VertexAreasSumToSurfaceArea) {
  const TriangleMesh tet = CornerTet();
  const std::vector<double> areas = VertexAreas(tet);
  ASSERT_EQ(areas.size(), 4u);
  double sum = 0.0;
  for (double a : areas) sum += a;
  EXPECT_NEAR(sum, SurfaceArea(tet), 1e-15);
  EXPECT_NEAR(areas[0], 3 * 0.5 * 0.01 / 3.0, 1e-15);  // vertex 0 touches the three right triangles
}

// Subdivision bounds the edge length and keeps volume, area and watertightness.
TEST(TriangleMesh, SubdivideToEdgeLengthKeepsVolumeAndWatertightness) {
  const TriangleMesh sphere = MakeSphere(0.1, 1);
  ASSERT_TRUE(IsWatertight(sphere));
  const TriangleMesh fine = SubdivideToEdgeLength(sphere, 0.01);
  EXPECT_LE(MaxEdgeLength(fine), 0.01);
  EXPECT_GT(fine.triangles.size(), sphere.triangles.size() * 16);
  EXPECT_TRUE(IsWatertight(fine));
  EXPECT_NEAR(SignedVolume(fine), SignedVolume(sphere), 1e-12);
  EXPECT_NEAR(SurfaceArea(fine), SurfaceArea(sphere), 1e-12);
  // Already fine enough: unchanged.
  EXPECT_EQ(SubdivideToEdgeLength(sphere, 1.0).triangles.size(), sphere.triangles.size());
  EXPECT_THROW(SubdivideToEdgeLength(sphere, 0.0), std::invalid_argument);
}

// The Stanford bunny scan reads with a plausible size and orientation.
TEST(TriangleMesh, ReadsScannedBunny) {
  const auto path = testing::SharedMesh("stanford_bunny_res3.ply");
  if (!std::filesystem::exists(path)) GTEST_SKIP() << path << " not available";
  const Result<TriangleMesh> read = ReadTriangleMesh(path);
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  EXPECT_GT(read->triangles.size(), 3000u);
  const Eigen::Vector3d extent = read->Bounds().sizes();
  EXPECT_GT(extent.maxCoeff(), 0.1);  // about 15 cm
  EXPECT_LT(extent.maxCoeff(), 0.3);
  EXPECT_GT(std::abs(SignedVolume(*read)), 1e-4);
}

}  // namespace
}  // namespace softid::geometry

namespace softid::geometry {
namespace {

// A glTF 2.0 triangle whose vertex positions are in the external buffer `uri`.
std::string TriangleGltf(const std::string& uri) {
  return R"({"asset": {"version": "2.0"},
    "buffers": [{"uri": ")" +
         uri + R"(", "byteLength": 36}],
    "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}],
    "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                   "min": [0, 0, 0], "max": [1, 1, 0]}],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
    "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}], "scene": 0})";
}

void WriteTriangleBuffer(const std::filesystem::path& path) {
  const float xyz[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(xyz), sizeof(xyz));
}

// A mesh that arrived in an upload must not make the importer read anything outside the upload,
// nor tell an existing file elsewhere from a missing one.
TEST(TriangleMeshConfinement, ExternalFilesOutsideTheFolderAreNeverRead) {
  const std::filesystem::path root = TempPath("root");
  std::filesystem::remove_all(root);
  const std::filesystem::path upload = root / "upload";
  std::filesystem::create_directories(upload / "sub");
  WriteTriangleBuffer(root / "secret.bin");       // exists, outside
  WriteTriangleBuffer(upload / "sub" / "b.bin");  // inside

  WriteText(upload / "inside.gltf", TriangleGltf("sub/b.bin"));
  const Result<TriangleMesh> inside = ReadTriangleMesh(upload / "inside.gltf");
  ASSERT_TRUE(inside.ok()) << inside.status().ToString();
  EXPECT_EQ(inside->triangles.size(), 1u);

  WriteText(upload / "existing.gltf", TriangleGltf("../secret.bin"));
  WriteText(upload / "missing.gltf", TriangleGltf("../no-such-file.bin"));
  const Status existing = ReadTriangleMesh(upload / "existing.gltf").status();
  const Status missing = ReadTriangleMesh(upload / "missing.gltf").status();
  EXPECT_EQ(existing.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(missing.code(), StatusCode::kInvalidArgument);
  const auto reason = [](const Status& s) { return s.message().substr(s.message().find(": ")); };
  EXPECT_EQ(reason(existing), reason(missing));
  EXPECT_NE(existing.message().find("outside its folder"), std::string::npos) << existing.message();

  // An absolute uri is taken relative to the mesh's folder (assimp joins them): not read either.
  WriteText(upload / "absolute.gltf", TriangleGltf((root / "secret.bin").string()));
  EXPECT_FALSE(ReadTriangleMesh(upload / "absolute.gltf").ok());
  // A symlink out of the folder is refused like a relative path out of it.
  std::filesystem::create_symlink(root / "secret.bin", upload / "link.bin");
  WriteText(upload / "link.gltf", TriangleGltf("link.bin"));
  EXPECT_EQ(reason(ReadTriangleMesh(upload / "link.gltf").status()), reason(existing));

  // A wider confinement (the capture folder above the mesh's) allows files up to it.
  std::filesystem::create_directories(upload / "meshes");
  WriteText(upload / "meshes" / "up.gltf", TriangleGltf("../sub/b.bin"));
  EXPECT_FALSE(ReadTriangleMesh(upload / "meshes" / "up.gltf").ok());
  EXPECT_TRUE(ReadTriangleMesh(upload / "meshes" / "up.gltf", upload).ok());
}

// An OBJ's material library outside the folder is not opened either.
TEST(TriangleMeshConfinement, ObjMaterialLibraryOutsideIsRefused) {
  const std::filesystem::path root = TempPath("root");
  std::filesystem::remove_all(root);
  std::filesystem::create_directories(root / "upload");
  WriteText(root / "outside.mtl", "newmtl a\nKd 1 0 0\n");
  WriteText(root / "upload" / "mesh.obj",
            "mtllib ../outside.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  const Status status = ReadTriangleMesh(root / "upload" / "mesh.obj").status();
  EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(status.message().find("outside its folder"), std::string::npos) << status.message();
}

}  // namespace
}  // namespace softid::geometry
