// The holes of a scanned surface and the caps that close them. A scan misses patches (the base of
// the Stanford bunny, a few concave spots); the real object is closed, so a camera looking at it
// never sees through those patches. The synthetic captures render the surface with its caps.
#pragma once

#include <vector>

#include "core/geometry/triangle_mesh.h"

namespace softid::geometry {

// Each hole is a closed loop of boundary edges (edges used by exactly one triangle), in the order
// and direction the triangles beside it run them.
struct HoleLoops {
  std::vector<std::vector<int>> loops;  // vertex indices; each loop has >= 3 vertices

  bool empty() const { return loops.empty(); }
};

// The holes of `mesh` (none for a closed mesh). A vertex where several holes meet is visited by
// each of them.
HoleLoops FindHoleLoops(const TriangleMesh& mesh);

// `mesh` with each hole closed by a fan of triangles around a new vertex at the centroid of the
// loop's vertices, oriented like the triangles beside the hole. `holes` must come from a mesh of
// the same topology (FindHoleLoops at rest; a deformed copy reuses it).
TriangleMesh WithHolesCapped(const TriangleMesh& mesh, const HoleLoops& holes);

}  // namespace softid::geometry
