// A scene: an object's rest mesh in the world frame, its true physical parameters, what is clamped,
// how long it runs, and where cameras should look. Built-in scenes reproduce the paper's
// experiments; any mesh can be dropped with the same machinery.
#pragma once

#include <Eigen/Geometry>
#include <optional>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/fem/physical_parameters.h"
#include "core/geometry/triangle_mesh.h"

namespace softid::scenes {

struct Scene {
  std::string name;
  geometry::TriangleMesh mesh;  // rest pose at t = 0, world frame [m]
  fem::PhysicalParameters parameters;
  std::optional<Eigen::AlignedBox3d> fixed_region;  // clamped nodes, world frame [m]
  double duration = 1.0;                            // [s]
  // Region the cameras must see (the object's whole motion) [m].
  Eigen::Vector3d view_target = Eigen::Vector3d::Zero();
  double view_radius = 0.5;
};

// Names of the built-in scenes: torus-drop, ball-bounce, bar-hanging, pillow-ramp.
std::vector<std::string> BuiltinSceneNames();

// @returns InvalidArgument naming the scene when it is unknown.
Result<Scene> MakeBuiltinScene(const std::string& name);

// A scene for any mesh file (OBJ/PLY/STL, metres): the mesh falls from its own pose onto a
// horizontal floor half its height below its lowest point. Errors name the path.
Result<Scene> MakeMeshScene(const std::string& mesh_path);

}  // namespace softid::scenes
