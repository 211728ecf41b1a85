#include "core/geometry/hole_caps.h"

#include <map>
#include <unordered_map>
#include <utility>

namespace softid::geometry {

HoleLoops FindHoleLoops(const TriangleMesh& mesh) {
  // Directed edges as the triangles run them; a boundary edge has no twin running the other way.
  std::map<std::pair<int, int>, int> uses;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) ++uses[{t[k], t[(k + 1) % 3]}];
  }
  // The loop around a hole runs each boundary edge backwards (the hole lies on its other side);
  // following them backwards keeps the loop oriented like the neighbouring triangles.
  std::unordered_multimap<int, int> next;  // loop edge a -> b
  for (const auto& [edge, count] : uses) {
    if (count == 1 && uses.find({edge.second, edge.first}) == uses.end()) {
      next.emplace(edge.second, edge.first);
    }
  }
  HoleLoops out;
  while (!next.empty()) {
    auto it = next.begin();
    const int start = it->first;
    std::vector<int> loop;
    int at = start;
    while (it != next.end()) {
      loop.push_back(at);
      at = it->second;
      next.erase(it);
      if (at == start) break;
      it = next.find(at);
    }
    if (at == start && loop.size() >= 3) out.loops.push_back(std::move(loop));
  }
  return out;
}

TriangleMesh WithHolesCapped(const TriangleMesh& mesh, const HoleLoops& holes) {
  TriangleMesh out = mesh;
  for (const std::vector<int>& loop : holes.loops) {
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (const int v : loop) centroid += mesh.vertices.at(v);
    const int c = static_cast<int>(out.vertices.size());
    out.vertices.push_back(centroid / static_cast<double>(loop.size()));
    for (size_t i = 0; i < loop.size(); ++i) {
      out.triangles.emplace_back(loop[i], loop[(i + 1) % loop.size()], c);
    }
  }
  return out;
}

}  // namespace softid::geometry
