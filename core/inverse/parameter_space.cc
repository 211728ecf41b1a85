#include "core/inverse/parameter_space.h"

#include <cmath>
#include <set>

#include "core/common/json_fields.h"

namespace softid::inverse {
namespace {

// Starting values for positive parameters that are 0 in the base parameters (log(0) is not a
// start): small next to any physically meaningful value, so the data decide.
double MinimumStart(const std::string& name) {
  if (name == "mass_damping") return 1e-3;       // [1/s]
  if (name == "stiffness_damping") return 1e-5;  // [s]
  if (name == "contact_damping") return 1e-5;    // [s]
  if (name == "drag_linear") return 1e-3;        // [kg/(m^2 s)]
  if (name == "drag_quadratic") return 1e-3;     // [kg/m^3]
  if (name == "friction_coefficient") return 1e-2;
  return 1e-12;
}

}  // namespace

bool IsLogParameter(std::string_view name) {
  static const std::set<std::string, std::less<>> kLog = {
      "youngs_modulus", "density",        "mass_damping",    "stiffness_damping",
      "drag_linear",    "drag_quadratic", "contact_damping", "contact_stiffness"};
  return kLog.find(name) != kLog.end();
}

double* ScalarParameter(fem::PhysicalParameters& p, std::string_view name) {
  if (name == "youngs_modulus") return &p.youngs_modulus;
  if (name == "poisson_ratio") return &p.poisson_ratio;
  if (name == "density") return &p.density;
  if (name == "mass_damping") return &p.mass_damping;
  if (name == "stiffness_damping") return &p.stiffness_damping;
  if (name == "drag_linear") return &p.drag_linear;
  if (name == "drag_quadratic") return &p.drag_quadratic;
  if (name == "contact_damping") return &p.contact_damping;
  if (name == "contact_stiffness") return &p.contact_stiffness;
  if (name == "friction_coefficient") return &p.friction_coefficient;
  return nullptr;
}

namespace {

double* ScalarField(fem::PhysicalParameters& p, const std::string& name) {
  return ScalarParameter(p, name);
}

double ScalarGradient(const fem::ParameterGradient& g, const std::string& name) {
  if (name == "youngs_modulus") return g.youngs_modulus;
  if (name == "poisson_ratio") return g.poisson_ratio;
  if (name == "density") return g.density;
  if (name == "mass_damping") return g.mass_damping;
  if (name == "stiffness_damping") return g.stiffness_damping;
  if (name == "drag_linear") return g.drag_linear;
  if (name == "drag_quadratic") return g.drag_quadratic;
  if (name == "contact_damping") return g.contact_damping;
  if (name == "contact_stiffness") return g.contact_stiffness;
  if (name == "friction_coefficient") return g.friction_coefficient;
  return 0.0;
}

Eigen::Vector3d* VectorField(fem::PhysicalParameters& p, const std::string& name) {
  if (name == "gravity") return &p.gravity;
  if (name == "initial_velocity") return &p.initial_velocity;
  if (name == "initial_angular_velocity") return &p.initial_angular_velocity;
  return nullptr;
}

Eigen::Vector3d VectorGradient(const fem::ParameterGradient& g, const std::string& name) {
  if (name == "gravity") return g.gravity;
  if (name == "initial_velocity") return g.initial_velocity;
  return g.initial_angular_velocity;
}

double Logistic(double x) {
  return 1.0 / (1.0 + std::exp(-x));
}
double Softplus(double x) {
  return x > 0.0 ? x + std::log1p(std::exp(-x)) : std::log1p(std::exp(x));
}
// Inverse of softplus: log(e^p - 1), stable for small and large p.
double InverseSoftplus(double p) {
  return p > 30.0 ? p : std::log(std::expm1(p));
}

}  // namespace

Result<ParameterSpace> ParameterSpace::Create(const std::vector<std::string>& names,
                                              const fem::PhysicalParameters& reference,
                                              double length_scale) {
  ParameterSpace space;
  space.names_ = names;
  space.length_scale_ = length_scale;
  std::set<std::string> seen;
  int offset = 0;
  for (size_t i = 0; i < names.size(); ++i) {
    const std::string& name = names[i];
    const std::string field = "fit[" + std::to_string(i) + "]";
    if (!seen.insert(name).second) return json::Invalid(field, name, "is listed twice");
    Entry entry{name, offset, 1};
    fem::PhysicalParameters probe = reference;
    if (ScalarField(probe, name) != nullptr) {
      space.variable_names_.push_back(name);
    } else if (VectorField(probe, name) != nullptr) {
      entry.size = 3;
      for (int k = 0; k < 3; ++k)
        space.variable_names_.push_back(name + "[" + std::to_string(k) + "]");
    } else if (name == "ground_plane") {
      if (!reference.ground) {
        return json::Invalid(field, name,
                             "needs a starting plane: give initial.ground_plane or "
                             "fixed.ground");
      }
      entry.size = 3;
      space.ground_normal_ = reference.ground->normal;
      const Eigen::Vector3d n = space.ground_normal_;
      const Eigen::Vector3d helper =
          std::abs(n.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
      space.ground_tangent_[0] = n.cross(helper).normalized();
      space.ground_tangent_[1] = n.cross(space.ground_tangent_[0]);
      space.variable_names_.insert(
          space.variable_names_.end(),
          {"ground_plane.tilt[0]", "ground_plane.tilt[1]", "ground_plane.offset"});
    } else if (name == "stiffness_field") {
      const fem::StiffnessField& f = reference.stiffness_field;
      if (f.kind == fem::StiffnessField::Kind::kUniform) {
        return json::Invalid(field, name,
                             "needs a field shape: give initial.stiffness_field or "
                             "fixed.stiffness_field as {\"kind\": \"regions\", ...} or "
                             "{\"kind\": \"linear\", ...}");
      }
      space.field_kind_ = f.kind;
      entry.size =
          f.kind == fem::StiffnessField::Kind::kRegions ? static_cast<int>(f.regions.size()) : 3;
      for (int k = 0; k < entry.size; ++k)
        space.variable_names_.push_back(name + "[" + std::to_string(k) + "]");
    } else {
      return json::Invalid(field, name, "is not a fittable parameter");
    }
    offset += entry.size;
    space.entries_.push_back(entry);
  }
  return space;
}

std::vector<double> ParameterSpace::ToVariables(const fem::PhysicalParameters& p_in) const {
  fem::PhysicalParameters p = p_in;
  std::vector<double> x(NumVariables(), 0.0);
  for (const Entry& e : entries_) {
    double* xe = x.data() + e.offset;
    if (double* value = ScalarField(p, e.name)) {
      double v = *value;
      if (e.name == "contact_stiffness" && v <= 0.0 && p.ground)
        v = 100.0 * p.youngs_modulus / length_scale_;  // the simulator's default
      if (e.name == "poisson_ratio") {
        xe[0] = std::log((2.0 * v) / (1.0 - 2.0 * v));
      } else if (e.name == "friction_coefficient") {
        xe[0] = InverseSoftplus(std::max(v, MinimumStart(e.name)));
      } else {
        xe[0] = std::log(std::max(v, MinimumStart(e.name)));
      }
    } else if (Eigen::Vector3d* vector = VectorField(p, e.name)) {
      for (int k = 0; k < 3; ++k) xe[k] = (*vector)[k];
    } else if (e.name == "ground_plane") {
      // Tilt relative to the reference normal: n / (n . n0) = n0 + x0 t1 + x1 t2.
      const Eigen::Vector3d n = p.ground->normal / p.ground->normal.dot(ground_normal_);
      xe[0] = n.dot(ground_tangent_[0]);
      xe[1] = n.dot(ground_tangent_[1]);
      xe[2] = p.ground->offset / (0.1 * length_scale_);
    } else if (e.name == "stiffness_field") {
      const fem::StiffnessField& f = p.stiffness_field;
      if (f.kind == fem::StiffnessField::Kind::kRegions) {
        for (int k = 0; k < e.size; ++k) xe[k] = std::log(f.regions[k].scale);
      } else {
        for (int k = 0; k < 3; ++k) xe[k] = f.log_gradient[k] * length_scale_;
      }
    }
  }
  return x;
}

fem::PhysicalParameters ParameterSpace::ToParameters(const double* x,
                                                     const fem::PhysicalParameters& base) const {
  fem::PhysicalParameters p = base;
  for (const Entry& e : entries_) {
    const double* xe = x + e.offset;
    if (double* value = ScalarField(p, e.name)) {
      if (e.name == "poisson_ratio")
        *value = 0.5 * Logistic(xe[0]);
      else if (e.name == "friction_coefficient")
        *value = Softplus(xe[0]);
      else
        *value = std::exp(xe[0]);
    } else if (Eigen::Vector3d* vector = VectorField(p, e.name)) {
      *vector = Eigen::Vector3d(xe[0], xe[1], xe[2]);
    } else if (e.name == "ground_plane") {
      const Eigen::Vector3d raw =
          ground_normal_ + xe[0] * ground_tangent_[0] + xe[1] * ground_tangent_[1];
      p.ground = fem::GroundPlane{raw.normalized(), xe[2] * 0.1 * length_scale_};
    } else if (e.name == "stiffness_field") {
      if (p.stiffness_field.kind == fem::StiffnessField::Kind::kRegions) {
        for (int k = 0; k < e.size; ++k) p.stiffness_field.regions[k].scale = std::exp(xe[k]);
      } else {
        for (int k = 0; k < 3; ++k) p.stiffness_field.log_gradient[k] = xe[k] / length_scale_;
      }
    }
  }
  return p;
}

void ParameterSpace::ChainGradient(const fem::ParameterGradient& g, const double* x,
                                   double* gx) const {
  for (const Entry& e : entries_) {
    const double* xe = x + e.offset;
    double* ge = gx + e.offset;
    fem::PhysicalParameters probe;
    if (ScalarField(probe, e.name) != nullptr) {
      const double dp = ScalarGradient(g, e.name);
      if (e.name == "poisson_ratio") {
        const double s = Logistic(xe[0]);
        ge[0] = dp * 0.5 * s * (1.0 - s);
      } else if (e.name == "friction_coefficient") {
        ge[0] = dp * Logistic(xe[0]);
      } else {
        ge[0] = dp * std::exp(xe[0]);
      }
    } else if (VectorField(probe, e.name) != nullptr) {
      const Eigen::Vector3d d = VectorGradient(g, e.name);
      for (int k = 0; k < 3; ++k) ge[k] = d[k];
    } else if (e.name == "ground_plane") {
      // n = m / |m|, m = n0 + x0 t1 + x1 t2: dn/dm = (I - n n^T) / |m|.
      const Eigen::Vector3d m =
          ground_normal_ + xe[0] * ground_tangent_[0] + xe[1] * ground_tangent_[1];
      const Eigen::Vector3d n = m.normalized();
      const Eigen::Vector3d dm = (g.ground_normal - n * n.dot(g.ground_normal)) / m.norm();
      ge[0] = dm.dot(ground_tangent_[0]);
      ge[1] = dm.dot(ground_tangent_[1]);
      ge[2] = g.ground_offset * 0.1 * length_scale_;
    } else if (e.name == "stiffness_field") {
      // Regions: x = log(scale), d/dx = scale d/dscale; linear: x = L g, d/dx = (d/dg) / L.
      for (int k = 0; k < e.size; ++k) {
        const double dk =
            k < static_cast<int>(g.stiffness_field.size()) ? g.stiffness_field[k] : 0.0;
        ge[k] = field_kind_ == fem::StiffnessField::Kind::kLinear ? dk / length_scale_
                                                                  : dk * std::exp(xe[k]);
      }
    }
  }
}

}  // namespace softid::inverse
