// Triangle surface meshes: storage, file I/O (assimp) and integral measures.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <filesystem>
#include <vector>

#include "core/common/status.h"

namespace softid::geometry {

// Triangle surface mesh [m]. Closed meshes are oriented outward (counter-clockwise seen from
// outside); scanned meshes may have holes.
struct TriangleMesh {
  std::vector<Eigen::Vector3d> vertices;   // positions [m]
  std::vector<Eigen::Vector3i> triangles;  // vertex indices, counter-clockwise seen from outside
  // Axis-aligned bounds of the vertices [m]; empty box when there are no vertices.
  Eigen::AlignedBox3d Bounds() const;
};

// Reads OBJ, PLY (ascii/binary) or STL (ascii/binary) via assimp; merges duplicate vertices (STL
// has no index) and drops unreferenced vertices and triangles with a repeated vertex index. Errors
// (Status InvalidArgument/NotFound) name the path and what is wrong: missing file, unreadable, no
// triangles, non-finite coordinates. The importer opens only files inside `confine_to` (default:
// the mesh's own folder): a format that refers to other files (glTF buffers, OBJ material
// libraries) outside it is refused with one message, whether or not that file exists.
Result<TriangleMesh> ReadTriangleMesh(const std::filesystem::path& path,
                                      const std::filesystem::path& confine_to = {});
// Writes a Wavefront OBJ ("v x y z" with %.9g, "f a b c" 1-based). IoError names the path.
Status WriteTriangleMeshObj(const std::filesystem::path& path, const TriangleMesh& mesh);
// Writes a binary little-endian PLY with double vertex coordinates. IoError names the path.
Status WriteTriangleMeshPly(const std::filesystem::path& path, const TriangleMesh& mesh);

// Enclosed volume as the sum of signed tetrahedra taken about the vertex centroid [m^3]: positive
// for a closed outward mesh; for a mesh with small holes a close estimate.
double SignedVolume(const TriangleMesh& mesh);
// Total triangle area [m^2].
double SurfaceArea(const TriangleMesh& mesh);
// One third of the adjacent triangles' areas per vertex [m^2]; sums to SurfaceArea.
std::vector<double> VertexAreas(const TriangleMesh& mesh);
// Splits every triangle 1->4 at edge midpoints (shared midpoints, stays watertight) until no edge
// is longer than max_edge_length [m] (> 0, else std::invalid_argument). Returns a copy when no edge
// is too long. Midpoints are not projected onto any smooth surface.
TriangleMesh SubdivideToEdgeLength(const TriangleMesh& mesh, double max_edge_length);

}  // namespace softid::geometry
