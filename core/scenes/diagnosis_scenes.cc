#include "core/scenes/diagnosis_scenes.h"

#include <cmath>
#include <numbers>

#include "core/common/json_fields.h"
#include "core/geometry/primitives.h"

namespace softid::scenes {
namespace {

constexpr double kDegree = std::numbers::pi / 180.0;

void Transform(const Eigen::Isometry3d& pose, geometry::TriangleMesh* mesh) {
  for (auto& v : mesh->vertices) v = pose * v;
}

// A soft foam block dropped 1 cm onto a 30 degree ramp: it lands and slides, g (sin 30 deg -
// mu cos 30 deg) = 4.9 m/s^2 without friction, 0.66 m/s^2 at mu = 0.5 (it sticks from
// mu = tan 30 deg = 0.58 on, where only a lower bound of mu could be measured). The ramp
// n . x = 0 descends towards +x.
Scene RampBlock() {
  Scene s;
  s.name = "ramp-block";
  const double angle = 30.0 * kDegree;
  const Eigen::Vector3d normal(std::sin(angle), 0.0, std::cos(angle));
  const Eigen::Vector3d downhill(std::cos(angle), 0.0, -std::sin(angle));
  s.mesh = geometry::MakeBox(Eigen::Vector3d(0.16, 0.12, 0.08), 0.02);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translate(-0.2 * downhill + 0.05 * normal);  // half thickness 4 cm + 1 cm gap
  pose.rotate(Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitY()));
  Transform(pose, &s.mesh);
  s.parameters.youngs_modulus = 2.0e4;
  s.parameters.poisson_ratio = 0.3;
  s.parameters.density = 150.0;
  s.parameters.mass_damping = 0.0;
  s.parameters.stiffness_damping = 0.02;
  s.parameters.ground = fem::GroundPlane{normal, 0.0};
  s.duration = 0.5;  // frictionless: ~0.6 m down the ramp
  s.view_target = 0.1 * downhill + 0.04 * normal;
  s.view_radius = 0.45;
  return s;
}

// A soft foam bar (16 x 8 x 8 cm, 3 kPa, 100 kg/m^3) dropped flat from 15 cm: the impact
// compresses it by ~30 %. Halves of different stiffness push back unequally, so the bar leaves the
// ground turning and its ends part by ~ (turn rate) x (rebound flight time) x length: the contrast
// shows in proportion to the time in the air after the bounce (2 e v / g, e the restitution). A
// lively foam (stiffness damping 2.5 ms: damping ratio ~0.1 at the bar's bounce frequency) bounces
// about twice as long as a dull one (5 ms). (Dropped tilted by 10 degrees it rocks on its landing
// end and shows the contrast less. The static sag, rho g H^2 / 2E ~ 1 mm, is below the depth
// noise: the contrast shows only in the bounce.)
Scene HalvesDrop() {
  Scene s;
  s.name = "halves-drop";
  s.mesh = geometry::MakeBox(Eigen::Vector3d(0.16, 0.08, 0.08), 0.02);
  Transform(Eigen::Isometry3d(Eigen::Translation3d(0.0, 0.0, 0.19)), &s.mesh);
  s.parameters.youngs_modulus = 3.0e3;
  s.parameters.poisson_ratio = 0.3;
  s.parameters.density = 100.0;
  s.parameters.mass_damping = 0.0;
  s.parameters.stiffness_damping = 0.0025;
  s.parameters.ground = fem::GroundPlane{Eigen::Vector3d::UnitZ(), 0.0};
  s.duration = 0.6;
  s.view_target = Eigen::Vector3d(0.0, 0.0, 0.11);
  s.view_radius = 0.2;
  return s;
}

// A light foam cube (20 cm, 10 kg/m^3, 80 g: expanded polystyrene) thrown 2 m/s forward and 3 m/s
// up: at 3-4 m/s air drag (rho_air C_d / 2 ~ 0.6 kg/m^3 on a quarter of its surface) decelerates it
// by several m/s^2. It is caught before it lands (free flight throughout).
Scene LightThrow() {
  Scene s;
  s.name = "light-throw";
  s.mesh = geometry::MakeBox(Eigen::Vector3d(0.2, 0.2, 0.2), 0.04);
  Transform(Eigen::Isometry3d(Eigen::Translation3d(-0.5, 0.0, 0.3)), &s.mesh);
  s.parameters.youngs_modulus = 3.0e4;
  s.parameters.poisson_ratio = 0.3;
  s.parameters.density = 10.0;
  s.parameters.mass_damping = 0.0;
  s.parameters.stiffness_damping = 0.01;
  s.parameters.initial_velocity = Eigen::Vector3d(2.0, 0.0, 3.0);
  s.parameters.ground = fem::GroundPlane{Eigen::Vector3d::UnitZ(), -0.5};
  s.duration = 0.6;
  s.view_target = Eigen::Vector3d(0.1, 0.0, 0.55);
  s.view_radius = 0.75;
  return s;
}

// Sets *scene to the scene called `name` and returns the effect it carries (for light-throw, the
// one `effect` asks for); InvalidArgument for an unknown name.
Result<ConcealedEffect> BaseScene(const std::string& name, ConcealedEffect effect, Scene* scene) {
  ConcealedEffect carried;
  if (name == "ramp-block") {
    *scene = RampBlock();
    carried = ConcealedEffect::kFriction;
  } else if (name == "halves-drop") {
    *scene = HalvesDrop();
    carried = ConcealedEffect::kHeterogeneousStiffness;
  } else if (name == "light-throw") {
    *scene = LightThrow();
    carried = effect == ConcealedEffect::kInitialSpin ? ConcealedEffect::kInitialSpin
                                                      : ConcealedEffect::kAirDrag;
  } else {
    return json::Invalid("scene", name, "unknown (known: ramp-block, halves-drop, light-throw)");
  }
  return carried;
}

// Puts `effect` at strength s into p; InvalidArgument naming "strength" when s is out of the
// effect's range. `mesh` is where the halves of kHeterogeneousStiffness are split.
Status ApplyConcealedEffect(ConcealedEffect effect, double s, const geometry::TriangleMesh& mesh,
                            fem::PhysicalParameters* p) {
  auto in_range = [&](double lo, double hi) -> Status {
    if (!(s >= lo && s <= hi)) {
      return json::Invalid("strength", s,
                           "must lie in [" + std::to_string(lo) + ", " + std::to_string(hi) +
                               "] for " + ToString(effect));
    }
    return Status::Ok();
  };
  switch (effect) {
    case ConcealedEffect::kNone: break;
    case ConcealedEffect::kFriction:
      SOFTID_RETURN_IF_ERROR(in_range(0.0, 2.0));
      p->friction_coefficient = s;
      break;
    case ConcealedEffect::kHeterogeneousStiffness: {
      if (!(s > 0.0 && s <= 100.0)) return json::Invalid("strength", s, "must lie in (0, 100]");
      const Eigen::AlignedBox3d bounds = mesh.Bounds();
      int axis = 0;
      bounds.sizes().maxCoeff(&axis);
      Eigen::Vector3d lo = bounds.min() - Eigen::Vector3d::Ones();
      Eigen::Vector3d hi = bounds.max() + Eigen::Vector3d::Ones();
      hi[axis] = bounds.center()[axis];
      // E stays the mean modulus in log terms, so the ratio is the only change.
      p->youngs_modulus /= std::sqrt(s);
      p->stiffness_field.kind = fem::StiffnessField::Kind::kRegions;
      p->stiffness_field.regions = {{Eigen::AlignedBox3d(lo, hi), s}};
      break;
    }
    case ConcealedEffect::kAirDrag:
      SOFTID_RETURN_IF_ERROR(in_range(0.0, 10.0));
      p->drag_quadratic = s;
      break;
    case ConcealedEffect::kInitialSpin:
      SOFTID_RETURN_IF_ERROR(in_range(0.0, 50.0));
      // About the horizontal axis across the throw (a tumbling board).
      p->initial_angular_velocity = Eigen::Vector3d(0.0, s, 0.0);
      break;
  }
  return Status::Ok();
}

void SetDiagnosisCameras(const std::string& name, CameraRigOptions* cameras) {
  cameras->count = 2;
  // The throw spans ~1.5 m: more pixels keep ~100 points per camera on the cube.
  cameras->width = name == "light-throw" ? 128 : 80;
  cameras->height = name == "light-throw" ? 96 : 64;
  cameras->elevation = 25.0;
  cameras->azimuth = -90.0;
}

}  // namespace

const char* ToString(ConcealedEffect effect) {
  switch (effect) {
    case ConcealedEffect::kNone: return "none";
    case ConcealedEffect::kFriction: return "friction";
    case ConcealedEffect::kHeterogeneousStiffness: return "heterogeneous_stiffness";
    case ConcealedEffect::kAirDrag: return "air_drag";
    case ConcealedEffect::kInitialSpin: return "initial_spin";
  }
  return "?";
}

Result<ConcealedEffect> ParseConcealedEffect(const std::string& name, const std::string& field) {
  for (ConcealedEffect e : {ConcealedEffect::kNone, ConcealedEffect::kFriction,
                            ConcealedEffect::kHeterogeneousStiffness, ConcealedEffect::kAirDrag,
                            ConcealedEffect::kInitialSpin}) {
    if (name == ToString(e)) return e;
  }
  return json::Invalid(field, name,
                       "unknown effect (known: none, friction, heterogeneous_stiffness, air_drag, "
                       "initial_spin)");
}

std::vector<std::string> DiagnosisSceneNames() {
  return {"ramp-block", "halves-drop", "light-throw"};
}

Result<ConcealedScene> MakeDiagnosisScene(const std::string& name, ConcealedEffect effect,
                                          double strength, double variation) {
  ConcealedScene out;
  SOFTID_ASSIGN_OR_RETURN(const ConcealedEffect carried, BaseScene(name, effect, &out.scene));
  if (effect != ConcealedEffect::kNone && effect != carried) {
    return json::Invalid(
        "effect", ToString(effect),
        "scene " + name + " carries " + std::string(ToString(carried)) + " (or none)");
  }
  if (!(variation > -0.5 && variation < 0.5)) {
    return json::Invalid("variation", variation, "must lie in (-0.5, 0.5)");
  }
  out.effect = effect;
  out.strength = effect == ConcealedEffect::kNone ? 0.0 : strength;
  fem::PhysicalParameters& p = out.scene.parameters;
  p.youngs_modulus *= 1.0 + variation;
  SOFTID_RETURN_IF_ERROR(ApplyConcealedEffect(effect, out.strength, out.scene.mesh, &p));
  SOFTID_RETURN_IF_ERROR(p.Validate());
  SetDiagnosisCameras(name, &out.cameras);
  return out;
}

}  // namespace softid::scenes
