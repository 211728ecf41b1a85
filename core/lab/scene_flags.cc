#include "core/lab/scene_flags.h"

#include <algorithm>
#include <fstream>

#include "core/common/json_fields.h"
#include "core/fem/parameter_registry.h"

namespace softid::lab {

namespace {

// "--initial-velocity" for "initial_velocity".
std::string FlagName(std::string_view parameter) {
  std::string flag = "--" + std::string(parameter);
  std::replace(flag.begin(), flag.end(), '_', '-');
  return flag;
}

bool HasFlag(const fem::ParameterInfo& p) {
  return p.shape == fem::ParameterShape::kScalar || p.shape == fem::ParameterShape::kVector3;
}

}  // namespace

// One flag per scalar or 3-vector parameter: "--youngs-modulus" takes Young's modulus in Pa.
void SceneFlags::RegisterParameterFlags(CLI::App* app) {
  for (const fem::ParameterInfo& p : fem::ParameterRegistry()) {
    if (!HasFlag(p)) continue;
    std::string names = FlagName(p.name);
    if (p.name == "friction_coefficient") names += ",--friction";  // the short spelling
    const bool scalar = p.shape == fem::ParameterShape::kScalar;
    app->add_option(names, parameter_values[std::string(p.name)],
                    std::string(p.description) + " [" + std::string(p.unit) + "]" +
                        (scalar ? "" : " (3 numbers)"))
        ->expected(scalar ? 1 : 3);
  }
}

void SceneFlags::Register(CLI::App* app) {
  std::string names;
  for (const auto& n : scenes::BuiltinSceneNames()) names += (names.empty() ? "" : ", ") + n;
  app->add_option("--scene", scene, "built-in scene: " + names)->capture_default_str();
  app->add_option("--mesh", mesh, "drop any mesh (OBJ/PLY/STL, metres) instead of a scene");
  app->add_option("--parameters", parameters_file,
                  "JSON file of parameters (public names) applied over the scene's");
  RegisterParameterFlags(app);
  app->add_option("--ground-normal", ground_normal, "ground plane normal n (n.x = offset)")
      ->expected(3);
  app->add_option("--ground-offset", ground_offset, "ground plane offset [m]");
  app->add_flag("--no-ground", no_ground, "remove the ground plane");
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
  app->add_option("--element", element,
                  "the grid's element: trilinear or incompatible_modes (docs/job-config.md)")
      ->check(CLI::IsMember({"trilinear", "incompatible_modes"}))
      ->capture_default_str();
  app->add_option("--cut-cell-samples", cut_cell_samples,
                  "distance samples per cell edge shaping cut cells: 1, 2, 4 or 8")
      ->check(CLI::IsMember({1, 2, 4, 8}))
      ->capture_default_str();
  app->add_option("--fps", fps, "frames per second")->capture_default_str();
  app->add_option("--duration", duration, "seconds to simulate (default: the scene's)");
}

Status SceneFlags::ApplyParameterFlags(fem::PhysicalParameters* p) const {
  for (const auto& [name, values] : parameter_values) {
    if (values.empty()) continue;
    const fem::ParameterInfo* parameter = fem::FindParameter(name);
    if (parameter == nullptr) return Status::Internal("no parameter " + name);
    const nlohmann::json value =
        values.size() == 1 ? nlohmann::json(values[0]) : nlohmann::json(values);
    SOFTID_RETURN_IF_ERROR(fem::ParameterFromJson(value, *parameter, FlagName(name), p));
  }
  return Status::Ok();
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
  SOFTID_RETURN_IF_ERROR(ApplyParameterFlags(&p));
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
  run.simulation.cut_cell_samples = cut_cell_samples;
  run.simulation.cell_size = cell_size;
  if (rho_infinity >= 0.0) run.simulation.UseGeneralizedAlpha(rho_infinity);
  run.simulation.element = element == fem::ToString(fem::ElementFormulation::kIncompatibleModes)
                               ? fem::ElementFormulation::kIncompatibleModes
                               : fem::ElementFormulation::kTrilinear;
  run.fps = fps;
  run.substeps_per_frame = substeps;
  run.duration = duration;
  return run;
}

}  // namespace softid::lab
