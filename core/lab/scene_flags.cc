#include "core/lab/scene_flags.h"

#include <fstream>

#include "core/common/json_fields.h"

namespace softid::lab {

void SceneFlags::Register(CLI::App* app) {
  std::string names;
  for (const auto& n : scenes::BuiltinSceneNames()) names += (names.empty() ? "" : ", ") + n;
  app->add_option("--scene", scene, "built-in scene: " + names)->capture_default_str();
  app->add_option("--mesh", mesh, "drop any mesh (OBJ/PLY/STL, metres) instead of a scene");
  app->add_option("--parameters", parameters_file,
                  "JSON file of parameters (public names) applied over the scene's");
  app->add_option("--youngs-modulus", youngs_modulus, "Young's modulus E [Pa]");
  app->add_option("--poisson-ratio", poisson_ratio, "Poisson ratio nu in (0, 0.5)");
  app->add_option("--density", density, "density [kg/m^3]");
  app->add_option("--mass-damping", mass_damping, "Rayleigh mass damping alpha [1/s]");
  app->add_option("--stiffness-damping", stiffness_damping, "Rayleigh stiffness damping beta [s]");
  app->add_option("--gravity", gravity, "gravity vector [m/s^2]")->expected(3);
  app->add_option("--initial-velocity", initial_velocity, "initial velocity [m/s]")->expected(3);
  app->add_option("--initial-angular-velocity", initial_angular_velocity,
                  "initial angular velocity about the centre of mass [rad/s]")
      ->expected(3);
  app->add_option("--ground-normal", ground_normal, "ground plane normal n (n.x = offset)")
      ->expected(3);
  app->add_option("--ground-offset", ground_offset, "ground plane offset [m]");
  app->add_flag("--no-ground", no_ground, "remove the ground plane");
  app->add_option("--contact-stiffness", contact_stiffness, "penalty [Pa/m]; 0 = 100 E / L");
  app->add_option("--contact-damping", contact_damping, "contact damping [s]");
  app->add_option("--friction-coefficient,--friction", friction_coefficient,
                  "Coulomb mu (hidden physics)");
  app->add_option("--drag-linear", drag_linear, "linear air drag [kg/(m^2 s)] (hidden physics)");
  app->add_option("--drag-quadratic", drag_quadratic,
                  "quadratic air drag [kg/m^3] (hidden physics)");
  app->add_option("--stiffness-field", stiffness_field,
                  "JSON stiffness field, e.g. {\"kind\":\"linear\",\"origin\":[0,0,0],"
                  "\"log_gradient\":[3,0,0]} (hidden physics)");
  app->add_option("--stiffness-halves", stiffness_halves,
                  "E ratio between the two halves along the longest axis (hidden physics)");
  app->add_option("--cells", cells, "grid cells along the longest side")->capture_default_str();
  app->add_option("--cell-size", cell_size, "grid cell size [m] (overrides --cells)");
  app->add_option("--substeps", substeps, "time steps per frame")->capture_default_str();
  app->add_option("--rho-infinity", rho_infinity,
                  "generalized-alpha time stepping with this high-frequency spectral radius in "
                  "[0, 1] (default: Newmark, gamma 0.6)")
      ->check(CLI::Range(0.0, 1.0));
  app->add_option("--fps", fps, "frames per second")->capture_default_str();
  app->add_option("--duration", duration, "seconds to simulate (default: the scene's)");
}

namespace {
Result<Eigen::Vector3d> Vector(const std::vector<double>& v, const char* flag) {
  if (v.size() != 3) return json::Invalid(flag, v, "needs 3 numbers");
  return Eigen::Vector3d(v[0], v[1], v[2]);
}
}  // namespace

Result<scenes::Scene> SceneFlags::BuildScene() const {
  Result<scenes::Scene> made =
      mesh.empty() ? scenes::MakeBuiltinScene(scene) : scenes::MakeMeshScene(mesh);
  SOFTID_RETURN_IF_ERROR(made.status());
  scenes::Scene s = std::move(made).value();
  fem::PhysicalParameters& p = s.parameters;
  if (!parameters_file.empty()) {
    std::ifstream file(parameters_file);
    if (!file) return Status::NotFound("--parameters = " + parameters_file + ": cannot open");
    nlohmann::json j = nlohmann::json::parse(file, nullptr, /*allow_exceptions=*/false);
    if (j.is_discarded())
      return Status::InvalidArgument("--parameters = " + parameters_file + ": not valid JSON");
    SOFTID_ASSIGN_OR_RETURN(p, fem::PhysicalParametersFromJson(j, p));
  }
  if (youngs_modulus) p.youngs_modulus = *youngs_modulus;
  if (poisson_ratio) p.poisson_ratio = *poisson_ratio;
  if (density) p.density = *density;
  if (mass_damping) p.mass_damping = *mass_damping;
  if (stiffness_damping) p.stiffness_damping = *stiffness_damping;
  if (!gravity.empty()) {
    SOFTID_ASSIGN_OR_RETURN(p.gravity, Vector(gravity, "--gravity"));
  }
  if (!initial_velocity.empty()) {
    SOFTID_ASSIGN_OR_RETURN(p.initial_velocity, Vector(initial_velocity, "--initial-velocity"));
  }
  if (!initial_angular_velocity.empty()) {
    SOFTID_ASSIGN_OR_RETURN(p.initial_angular_velocity,
                            Vector(initial_angular_velocity, "--initial-angular-velocity"));
  }
  if (!ground_normal.empty() || ground_offset) {
    fem::GroundPlane plane = p.ground.value_or(fem::GroundPlane{});
    if (!ground_normal.empty()) {
      SOFTID_ASSIGN_OR_RETURN(Eigen::Vector3d n, Vector(ground_normal, "--ground-normal"));
      if (!(n.norm() > 0.0))
        return json::Invalid("--ground-normal", ground_normal, "must be non-zero");
      plane.normal = n.normalized();
    }
    if (ground_offset) plane.offset = *ground_offset;
    p.ground = plane;
  }
  if (no_ground) p.ground.reset();
  if (contact_stiffness) p.contact_stiffness = *contact_stiffness;
  if (contact_damping) p.contact_damping = *contact_damping;
  if (friction_coefficient) p.friction_coefficient = *friction_coefficient;
  if (drag_linear) p.drag_linear = *drag_linear;
  if (drag_quadratic) p.drag_quadratic = *drag_quadratic;
  if (!stiffness_field.empty()) {
    nlohmann::json j = nlohmann::json::parse(stiffness_field, nullptr, false);
    if (j.is_discarded())
      return Status::InvalidArgument("--stiffness-field = " + stiffness_field + ": not valid JSON");
    SOFTID_ASSIGN_OR_RETURN(p.stiffness_field, fem::StiffnessFieldFromJson(j, "--stiffness-field"));
  }
  if (stiffness_halves) {
    if (!(*stiffness_halves > 0.0))
      return json::Invalid("--stiffness-halves", *stiffness_halves, "must be positive");
    const Eigen::AlignedBox3d bounds = s.mesh.Bounds();
    int axis = 0;
    bounds.sizes().maxCoeff(&axis);
    // The lower half along the longest axis gets the ratio; the box reaches well past the body.
    Eigen::Vector3d lo = bounds.min() - Eigen::Vector3d::Ones();
    Eigen::Vector3d hi = bounds.max() + Eigen::Vector3d::Ones();
    hi[axis] = bounds.center()[axis];
    p.stiffness_field.kind = fem::StiffnessField::Kind::kRegions;
    p.stiffness_field.regions = {{Eigen::AlignedBox3d(lo, hi), *stiffness_halves}};
  }
  SOFTID_RETURN_IF_ERROR(p.Validate());
  return s;
}

scenes::RunOptions SceneFlags::BuildRunOptions() const {
  scenes::RunOptions run;
  run.simulation.cells_along_longest_side = cells;
  run.simulation.cell_size = cell_size;
  if (rho_infinity >= 0.0) run.simulation.UseGeneralizedAlpha(rho_infinity);
  run.fps = fps;
  run.substeps_per_frame = substeps;
  run.duration = duration;
  return run;
}

}  // namespace softid::lab
