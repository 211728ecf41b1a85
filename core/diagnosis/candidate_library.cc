#include "core/diagnosis/candidate_library.h"

#include <cmath>

#include "core/common/check.h"
#include "core/common/json_fields.h"
#include "core/fem/parameter_registry.h"

namespace softid::diagnosis {

const char* ToString(Extension extension) {
  switch (extension) {
    case Extension::kFriction: return "friction";
    case Extension::kHeterogeneousStiffness: return "heterogeneous_stiffness";
    case Extension::kAirDrag: return "air_drag";
    case Extension::kContact: return "contact";
    case Extension::kInitialSpin: return "initial_spin";
  }
  return "?";
}

Result<Extension> ParseExtension(const std::string& name, const std::string& field) {
  for (const Candidate& c : CandidateLibrary())
    if (name == ToString(c.extension)) return c.extension;
  return json::Invalid(field, name,
                       "unknown extension (known: friction, heterogeneous_stiffness, air_drag, "
                       "contact, initial_spin)");
}

const std::vector<Candidate>& CandidateLibrary() {
  static const std::vector<Candidate> kLibrary = [] {
    std::vector<Candidate> c(5);
    c[0].extension = Extension::kFriction;
    c[0].parameters = {"friction_coefficient"};
    c[0].num_boundary = 1;
    c[0].needs_ground = true;
    c[0].phases = {Phase::kImpact, Phase::kSliding, Phase::kRest};
    c[0].description = "Coulomb friction: the simulation slides too far and too fast";
    c[1].extension = Extension::kHeterogeneousStiffness;
    c[1].parameters = {"stiffness_field"};
    c[1].num_variants = 3;
    c[1].after_contact = true;
    c[1].description = "two halves of different Young's modulus: asymmetric compression and tilt";
    c[2].extension = Extension::kAirDrag;
    c[2].parameters = {"drag_quadratic"};
    c[2].num_boundary = 1;
    c[2].phases = {Phase::kFlight, Phase::kRebound};
    c[2].description = "quadratic air drag: a lag against the velocity growing in flight";
    c[3].extension = Extension::kContact;
    c[3].parameters = {"contact_stiffness", "contact_damping"};
    c[3].num_added = 2;
    c[3].num_boundary = 1;
    c[3].needs_ground = true;
    c[3].phases = {Phase::kImpact, Phase::kRest};
    // A nuisance: the floor's compliance and restitution belong to the rig (a mat, a table, the
    // penalty of another code), not to the object, and a real floor is never softid's default.
    c[3].nuisance = true;
    // On a coarse step a penalty's stiffness follows the step's error at the impact (the CalculiX
    // block dropped on a corner, at 4 substeps per frame: 20 x softer than the default, with E
    // 70 % too high; refitted at the job's step, E doubled).
    c[3].absorbs_step_error = true;
    c[3].description =
        "contact compliance and restitution (a nuisance of the floor, not the object's physics): "
        "wrong rebound, hovering or sinking";
    c[4].extension = Extension::kInitialSpin;
    c[4].nuisance = true;
    c[4].parameters = {"initial_angular_velocity"};
    c[4].num_added = 3;
    c[4].all_frames = true;
    c[4].description = "initial spin (a nuisance of the release, not physics)";
    return c;
  }();
  return kLibrary;
}

const Candidate& GetCandidate(Extension extension) {
  for (const Candidate& c : CandidateLibrary())
    if (c.extension == extension) return c;
  return CandidateLibrary().front();
}

fem::StiffnessField HalvesField(const Eigen::AlignedBox3d& rest_bounds, int axis, double ratio) {
  fem::StiffnessField field;
  field.kind = fem::StiffnessField::Kind::kRegions;
  // The box reaches well past the body on every other side.
  Eigen::Vector3d lo = rest_bounds.min() - Eigen::Vector3d::Ones();
  Eigen::Vector3d hi = rest_bounds.max() + Eigen::Vector3d::Ones();
  hi[axis] = rest_bounds.center()[axis];
  field.regions = {{Eigen::AlignedBox3d(lo, hi), ratio}};
  return field;
}

fem::PhysicalParameters CopyExtension(Extension extension, const fem::PhysicalParameters& from,
                                      fem::PhysicalParameters to) {
  for (const std::string& name : GetCandidate(extension).parameters) {
    const fem::ParameterInfo* parameter = fem::FindParameter(name);
    SOFTID_DEMAND(parameter != nullptr);  // the library names registry parameters only
    fem::CopyParameter(*parameter, from, &to);
  }
  return to;
}

fem::PhysicalParameters NullModelStart(Extension extension, const fem::PhysicalParameters& null,
                                       const fem::PhysicalParameters& refit,
                                       const Eigen::AlignedBox3d& rest_bounds) {
  fem::PhysicalParameters out = CopyExtension(extension, null, refit);
  if (extension != Extension::kHeterogeneousStiffness || rest_bounds.isEmpty()) return out;
  const double volume = rest_bounds.volume();
  if (!(volume > 0.0)) return out;
  if (refit.stiffness_field.kind != fem::StiffnessField::Kind::kRegions) return out;
  double log_mean = 0.0;
  for (const fem::StiffnessField::Region& region : refit.stiffness_field.regions) {
    const Eigen::AlignedBox3d inside = region.box.intersection(rest_bounds);
    if (inside.isEmpty() || !(region.scale > 0.0)) continue;
    log_mean += inside.volume() / volume * std::log(region.scale);
  }
  out.youngs_modulus = refit.youngs_modulus * std::exp(log_mean);
  return out;
}

namespace {

double HalvesRatio(const fem::PhysicalParameters& p) {
  if (p.stiffness_field.kind != fem::StiffnessField::Kind::kRegions ||
      p.stiffness_field.regions.size() != 1)
    return 1.0;
  return p.stiffness_field.regions[0].scale;
}

int HalvesAxis(const fem::PhysicalParameters& p) {
  if (p.stiffness_field.regions.size() != 1) return 0;
  const Eigen::AlignedBox3d& box = p.stiffness_field.regions[0].box;
  // The split axis is the one whose upper face lies inside the body (not 1 m beyond it).
  int axis = 0;
  double smallest = std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    const double extent = box.max()[a] - box.min()[a];
    if (extent < smallest) {
      smallest = extent;
      axis = a;
    }
  }
  return axis;
}

}  // namespace

bool IsPlausible(Extension extension, const fem::PhysicalParameters& p,
                 double default_contact_stiffness, std::string* why) {
  auto fail = [&](const std::string& reason) {
    if (why != nullptr) *why = reason;
    return false;
  };
  switch (extension) {
    case Extension::kFriction:
      if (p.friction_coefficient < 0.01) return fail("mu < 0.01: no friction to speak of");
      if (p.friction_coefficient > 1.5) return fail("mu > 1.5: no soft material is that sticky");
      return true;
    case Extension::kAirDrag:
      if (p.drag_quadratic < 0.01) return fail("drag < 0.01 kg/m^3: negligible");
      if (p.drag_quadratic > 5.0) return fail("drag > 5 kg/m^3: far above air (~0.6)");
      return true;
    case Extension::kHeterogeneousStiffness: {
      const double r = HalvesRatio(p);
      if (r > 0.8 && r < 1.25) return fail("stiffness ratio within [0.8, 1.25]: uniform");
      if (r < 1.0 / 50 || r > 50) return fail("stiffness ratio beyond 50: implausible");
      return true;
    }
    case Extension::kContact: {
      const double k = p.contact_stiffness > 0 ? p.contact_stiffness : default_contact_stiffness;
      const double f = k / default_contact_stiffness;
      if (f < 0.01 || f > 100) return fail("contact stiffness beyond 100x its default");
      if (p.contact_damping > 0.1) return fail("contact damping > 0.1 s");
      return true;
    }
    case Extension::kInitialSpin:
      if (p.initial_angular_velocity.norm() > 50.0) return fail("spin > 50 rad/s");
      return true;
  }
  return fail("unknown extension");
}

nlohmann::json ExtensionValues(Extension extension, const fem::PhysicalParameters& p,
                               double default_contact_stiffness) {
  switch (extension) {
    case Extension::kFriction: return {{"friction_coefficient", p.friction_coefficient}};
    case Extension::kAirDrag: return {{"drag_quadratic", p.drag_quadratic}};
    case Extension::kHeterogeneousStiffness: {
      const double r = HalvesRatio(p);
      const int axis = HalvesAxis(p);
      return {{"stiffness_ratio", r},
              {"axis", std::string(1, "xyz"[axis])},
              {"youngs_modulus_lower", p.youngs_modulus * r},
              {"youngs_modulus_upper", p.youngs_modulus}};
    }
    case Extension::kContact:
      return {{"contact_stiffness",
               p.contact_stiffness > 0 ? p.contact_stiffness : default_contact_stiffness},
              {"contact_damping", p.contact_damping}};
    case Extension::kInitialSpin:
      return {{"initial_angular_velocity", json::FromVector3(p.initial_angular_velocity)}};
  }
  return nlohmann::json::object();
}

fem::PhysicalParameters WithExtensionAtNull(Extension extension,
                                            const fem::PhysicalParameters& refit,
                                            fem::PhysicalParameters to,
                                            const Eigen::AlignedBox3d& rest_bounds) {
  if (extension == Extension::kHeterogeneousStiffness)
    to.stiffness_field = HalvesField(rest_bounds, HalvesAxis(refit), 1.0);
  return to;
}

}  // namespace softid::diagnosis
