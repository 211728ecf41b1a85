// Procedural closed, outward-oriented triangle meshes used by the built-in scenes.
#pragma once

#include <Eigen/Core>

#include "core/geometry/triangle_mesh.h"

namespace softid::geometry {

// Icosphere of the given radius [m] centred at the origin: an icosahedron whose triangles are split
// 1->4 `subdivisions` times (>= 0) with new vertices projected onto the sphere. 20*4^s triangles.
// Vertices lie on the sphere, so the enclosed volume is slightly below 4/3 pi r^3.
TriangleMesh MakeSphere(double radius, int subdivisions);

// Torus with axis z centred at the origin: tube centre circle of radius major_radius [m], tube
// radius minor_radius [m] (< major_radius), major_segments (>= 3) around z and minor_segments (>=
// 3) around the tube. Vertices lie on the exact torus.
TriangleMesh MakeTorus(double major_radius, double minor_radius, int major_segments,
                       int minor_segments);

// Axis-aligned box of edge lengths `size` [m] centred at the origin. Each face is a regular grid of
// rectangles (squares when the sizes are multiples of one spacing), 2 triangles each, with
// ceil(size_a * sqrt(2) / max_edge_length) divisions along axis a so that every triangle edge,
// diagonals included, is <= max_edge_length [m]. Watertight: faces share the vertices on box edges.
TriangleMesh MakeBox(const Eigen::Vector3d& size, double max_edge_length);

}  // namespace softid::geometry
