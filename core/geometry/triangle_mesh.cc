#include "core/geometry/triangle_mesh.h"

#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <algorithm>
#include <array>
#include <assimp/Importer.hpp>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <system_error>
#include <unordered_map>
#include <utility>

#include "core/common/check.h"
#include "core/geometry/confined_io_system.h"

namespace softid::geometry {
namespace {

// Exact-position key for merging duplicate vertices (-0 and +0 compare equal).
struct PositionKey {
  std::array<std::uint32_t, 3> bits;
  bool operator==(const PositionKey&) const = default;
};

PositionKey MakeKey(const aiVector3D& v) {
  PositionKey key;
  const float c[3] = {v.x + 0.0f, v.y + 0.0f, v.z + 0.0f};
  for (int a = 0; a < 3; ++a) key.bits[a] = std::bit_cast<std::uint32_t>(c[a]);
  return key;
}

struct PositionKeyHash {
  std::size_t operator()(const PositionKey& k) const {
    std::uint64_t h = 1469598103934665603ull;
    for (std::uint32_t b : k.bits) h = (h ^ b) * 1099511628211ull;
    return static_cast<std::size_t>(h ^ (h >> 29));
  }
};

std::string Quoted(const std::filesystem::path& path) {
  return path.string();
}

struct FileCloser {
  void operator()(std::FILE* f) const {
    if (f != nullptr) std::fclose(f);
  }
};
using FilePtr = std::unique_ptr<std::FILE, FileCloser>;

Result<FilePtr> OpenForWriting(const std::filesystem::path& path) {
  FilePtr file(std::fopen(path.string().c_str(), "wb"));
  if (file == nullptr) {
    return Status::IoError(Quoted(path) + ": cannot open for writing: " + std::strerror(errno));
  }
  return file;
}

Status CloseChecked(FilePtr file, const std::filesystem::path& path) {
  const bool write_error = std::ferror(file.get()) != 0;
  const bool close_error = std::fclose(file.release()) != 0;
  if (write_error || close_error) return Status::IoError(Quoted(path) + ": write failed");
  return Status::Ok();
}

double TriangleArea(const TriangleMesh& mesh, const Eigen::Vector3i& t) {
  const Eigen::Vector3d& a = mesh.vertices[t[0]];
  return 0.5 * (mesh.vertices[t[1]] - a).cross(mesh.vertices[t[2]] - a).norm();
}

// The file checks that give a clearer message than the importer's.
Status CheckMeshFile(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    return Status::NotFound(Quoted(path) + ": mesh file does not exist");
  }
  if (!std::filesystem::is_regular_file(path, ec)) {
    return Status::InvalidArgument(Quoted(path) + ": not a regular file");
  }
  if (std::filesystem::file_size(path, ec) == 0) {
    return Status::InvalidArgument(Quoted(path) + ": file is empty");
  }
  return Status::Ok();
}

// Reads `path` with `importer`, which owns the returned scene; files the mesh refers to are read
// only from confine_to (default: the mesh's folder).
Result<const aiScene*> ImportScene(const std::filesystem::path& path,
                                   const std::filesystem::path& confine_to,
                                   Assimp::Importer* importer) {
  // The importer owns and deletes its IO handler.
  auto* files = new ConfinedIOSystem(confine_to.empty() ? path.parent_path() : confine_to);
  importer->SetIOHandler(files);
  const aiScene* scene =
      importer->ReadFile(path.string(), aiProcess_Triangulate | aiProcess_PreTransformVertices);
  if (files->refused_any()) {
    // One message whatever the file was and whether it exists: no oracle for paths elsewhere.
    return Status::InvalidArgument(
        Quoted(path) +
        ": refers to a file outside its folder (only self-contained meshes, or "
        "files beside the mesh, are read)");
  }
  if (scene == nullptr) {
    return Status::InvalidArgument(Quoted(path) +
                                   ": cannot read mesh: " + importer->GetErrorString());
  }
  return scene;
}

// Vertices already in the merged mesh, by exact position.
using MergedIndex = std::unordered_map<PositionKey, int, PositionKeyHash>;

// Appends the triangles of `in` to `mesh`, merging vertices through `index_of`; skips points,
// lines and collapsed triangles. `remap` is scratch (input vertex -> merged vertex).
Status AppendMeshTriangles(const aiMesh& in, const std::filesystem::path& path,
                           MergedIndex* index_of, std::vector<int>* remap, TriangleMesh* mesh) {
  remap->assign(in.mNumVertices, -1);
  for (unsigned f = 0; f < in.mNumFaces; ++f) {
    const aiFace& face = in.mFaces[f];
    if (face.mNumIndices != 3) continue;  // points and lines
    Eigen::Vector3i tri;
    for (int c = 0; c < 3; ++c) {
      const unsigned vi = face.mIndices[c];
      if (vi >= in.mNumVertices) {
        return Status::InvalidArgument(Quoted(path) + ": face " + std::to_string(f) +
                                       " references vertex " + std::to_string(vi) + " of " +
                                       std::to_string(in.mNumVertices));
      }
      if ((*remap)[vi] < 0) {
        const aiVector3D& v = in.mVertices[vi];
        if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z)) {
          return Status::InvalidArgument(Quoted(path) + ": vertex " + std::to_string(vi) +
                                         " has non-finite coordinates");
        }
        const auto [it, inserted] =
            index_of->try_emplace(MakeKey(v), static_cast<int>(mesh->vertices.size()));
        if (inserted) mesh->vertices.emplace_back(v.x, v.y, v.z);
        (*remap)[vi] = it->second;
      }
      tri[c] = (*remap)[vi];
    }
    if (tri[0] == tri[1] || tri[1] == tri[2] || tri[2] == tri[0]) continue;  // collapsed
    mesh->triangles.push_back(tri);
  }
  return Status::Ok();
}

// All triangles of the scene's meshes in one mesh.
Result<TriangleMesh> MergeSceneMeshes(const aiScene& scene, const std::filesystem::path& path) {
  TriangleMesh mesh;
  MergedIndex index_of;
  std::vector<int> remap;
  for (unsigned m = 0; m < scene.mNumMeshes; ++m) {
    SOFTID_RETURN_IF_ERROR(AppendMeshTriangles(*scene.mMeshes[m], path, &index_of, &remap, &mesh));
  }
  if (mesh.triangles.empty()) {
    return Status::InvalidArgument(Quoted(path) + ": mesh has no triangles");
  }
  return mesh;
}

// Order-independent key of the edge (a, b).
std::uint64_t EdgeKey(int a, int b) {
  return (static_cast<std::uint64_t>(std::min(a, b)) << 32) |
         static_cast<std::uint32_t>(std::max(a, b));
}

// Appends the pieces of triangle t to next, given the midpoints m of its edges (t0, t1), (t1, t2),
// (t2, t0) (-1 where the edge is not split); midpoints must already be in next->vertices.
void AppendSplitTriangle(const Eigen::Vector3i& t, const std::array<int, 3>& m,
                         TriangleMesh* next) {
  const int marked = (m[0] >= 0) + (m[1] >= 0) + (m[2] >= 0);
  if (marked == 0) {
    next->triangles.push_back(t);
  } else if (marked == 3) {
    next->triangles.emplace_back(t[0], m[0], m[2]);
    next->triangles.emplace_back(m[0], t[1], m[1]);
    next->triangles.emplace_back(m[2], m[1], t[2]);
    next->triangles.emplace_back(m[0], m[1], m[2]);
  } else if (marked == 1) {
    // Rotate so the split edge is (v0, v1); keep the orientation.
    const int r = m[0] >= 0 ? 0 : (m[1] >= 0 ? 1 : 2);
    const int v0 = t[r], v1 = t[(r + 1) % 3], v2 = t[(r + 2) % 3], mid = m[r];
    next->triangles.emplace_back(v0, mid, v2);
    next->triangles.emplace_back(mid, v1, v2);
  } else {
    // Rotate so the unsplit edge is (v0, v1): corner triangle at v2, quad split by the shorter
    // diagonal.
    const int r = m[0] < 0 ? 0 : (m[1] < 0 ? 1 : 2);
    const int v0 = t[r], v1 = t[(r + 1) % 3], v2 = t[(r + 2) % 3];
    const int m12 = m[(r + 1) % 3], m20 = m[(r + 2) % 3];
    next->triangles.emplace_back(m12, v2, m20);
    const auto& x = next->vertices;
    if ((x[v0] - x[m12]).squaredNorm() <= (x[v1] - x[m20]).squaredNorm()) {
      next->triangles.emplace_back(v0, v1, m12);
      next->triangles.emplace_back(v0, m12, m20);
    } else {
      next->triangles.emplace_back(v0, v1, m20);
      next->triangles.emplace_back(v1, m12, m20);
    }
  }
}

// One refinement pass into the empty mesh *next: every edge longer than sqrt(max_sq) [m] is split
// at its midpoint. Returns false, with *next incomplete, when no edge was long.
bool SplitLongEdges(const TriangleMesh& current, double max_sq, TriangleMesh* next) {
  next->vertices = current.vertices;
  std::unordered_map<std::uint64_t, int> midpoint_of;
  auto split = [&](int a, int b) -> int {  // midpoint index, or -1 when the edge is short
    if ((current.vertices[a] - current.vertices[b]).squaredNorm() <= max_sq) return -1;
    const auto [it, inserted] =
        midpoint_of.try_emplace(EdgeKey(a, b), static_cast<int>(next->vertices.size()));
    if (inserted) next->vertices.push_back(0.5 * (current.vertices[a] + current.vertices[b]));
    return it->second;
  };
  next->triangles.reserve(current.triangles.size() * 2);
  for (const Eigen::Vector3i& t : current.triangles) {
    const std::array<int, 3> m = {split(t[0], t[1]), split(t[1], t[2]), split(t[2], t[0])};
    AppendSplitTriangle(t, m, next);
  }
  return !midpoint_of.empty();
}

}  // namespace

Eigen::AlignedBox3d TriangleMesh::Bounds() const {
  Eigen::AlignedBox3d box;  // empty
  for (const Eigen::Vector3d& v : vertices) box.extend(v);
  return box;
}

Result<TriangleMesh> ReadTriangleMesh(const std::filesystem::path& path,
                                      const std::filesystem::path& confine_to) {
  SOFTID_RETURN_IF_ERROR(CheckMeshFile(path));
  Assimp::Importer importer;  // owns the scene
  SOFTID_ASSIGN_OR_RETURN(const aiScene* scene, ImportScene(path, confine_to, &importer));
  return MergeSceneMeshes(*scene, path);
}

Status WriteTriangleMeshObj(const std::filesystem::path& path, const TriangleMesh& mesh) {
  SOFTID_ASSIGN_OR_RETURN(FilePtr file, OpenForWriting(path));
  std::fprintf(file.get(), "# softid triangle mesh [m]\n");
  for (const Eigen::Vector3d& v : mesh.vertices) {
    std::fprintf(file.get(), "v %.9g %.9g %.9g\n", v.x(), v.y(), v.z());
  }
  for (const Eigen::Vector3i& t : mesh.triangles) {
    std::fprintf(file.get(), "f %d %d %d\n", t[0] + 1, t[1] + 1, t[2] + 1);
  }
  return CloseChecked(std::move(file), path);
}

Status WriteTriangleMeshPly(const std::filesystem::path& path, const TriangleMesh& mesh) {
  static_assert(std::endian::native == std::endian::little, "PLY writer assumes little endian");
  SOFTID_ASSIGN_OR_RETURN(FilePtr file, OpenForWriting(path));
  std::fprintf(file.get(),
               "ply\nformat binary_little_endian 1.0\ncomment softid triangle mesh [m]\n"
               "element vertex %zu\nproperty double x\nproperty double y\nproperty double z\n"
               "element face %zu\nproperty list uchar int vertex_indices\nend_header\n",
               mesh.vertices.size(), mesh.triangles.size());
  for (const Eigen::Vector3d& v : mesh.vertices) {
    const double xyz[3] = {v.x(), v.y(), v.z()};
    std::fwrite(xyz, sizeof(double), 3, file.get());
  }
  for (const Eigen::Vector3i& t : mesh.triangles) {
    unsigned char record[1 + 3 * sizeof(std::int32_t)];
    record[0] = 3;
    const std::int32_t idx[3] = {t[0], t[1], t[2]};
    std::memcpy(record + 1, idx, sizeof(idx));
    std::fwrite(record, sizeof(record), 1, file.get());
  }
  return CloseChecked(std::move(file), path);
}

double SignedVolume(const TriangleMesh& mesh) {
  if (mesh.vertices.empty()) return 0.0;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& v : mesh.vertices) centroid += v;
  centroid /= static_cast<double>(mesh.vertices.size());
  double six_volume = 0.0;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.vertices[t[0]] - centroid;
    const Eigen::Vector3d b = mesh.vertices[t[1]] - centroid;
    const Eigen::Vector3d c = mesh.vertices[t[2]] - centroid;
    six_volume += a.dot(b.cross(c));
  }
  return six_volume / 6.0;
}

double SurfaceArea(const TriangleMesh& mesh) {
  double area = 0.0;
  for (const Eigen::Vector3i& t : mesh.triangles) area += TriangleArea(mesh, t);
  return area;
}

std::vector<double> VertexAreas(const TriangleMesh& mesh) {
  std::vector<double> areas(mesh.vertices.size(), 0.0);
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const double third = TriangleArea(mesh, t) / 3.0;
    for (int c = 0; c < 3; ++c) areas[t[c]] += third;
  }
  return areas;
}

TriangleMesh SubdivideToEdgeLength(const TriangleMesh& mesh, double max_edge_length) {
  SOFTID_THROW_UNLESS(max_edge_length > 0.0 && std::isfinite(max_edge_length),
                      "SubdivideToEdgeLength: max_edge_length = " +
                          std::to_string(max_edge_length) + ": must be positive and finite");
  // Only edges longer than the limit are split, so a scan with a few long slivers is not refined
  // everywhere. A triangle's split depends only on which of its edges are split, and both sides
  // of a shared edge agree, so the result stays watertight.
  const double max_sq = max_edge_length * max_edge_length;
  TriangleMesh current = mesh;
  while (true) {
    TriangleMesh next;
    if (!SplitLongEdges(current, max_sq, &next)) return current;
    current = std::move(next);
  }
}

}  // namespace softid::geometry
