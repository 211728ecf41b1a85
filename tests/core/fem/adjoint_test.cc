// The adjoint gradient of a trajectory loss with respect to every physical parameter agrees with
// central finite differences of the forward simulation (solver tolerances tight).
#include <gtest/gtest.h>

#include <functional>
#include <random>
#include <string>
#include <tuple>

#include "core/fem/simulator.h"
#include "core/geometry/primitives.h"

namespace softid::fem {
namespace {

// L = sum_k d_k . u_k + e . v_K over the steps k = 1..K of a run from Reset().
struct TrajectoryLoss {
  std::vector<Eigen::VectorXd> weights;  // d_k, k = 1..K (index k - 1)
  Eigen::VectorXd final_velocity_weight;

  double Evaluate(Simulator& sim, const PhysicalParameters& parameters) const {
    sim.SetParameters(parameters);
    double loss = 0.0;
    for (const Eigen::VectorXd& d : weights) {
      const StepSummary step = sim.Step();
      EXPECT_TRUE(step.converged) << "t = " << sim.state().time;
      loss += d.dot(sim.state().u);
    }
    return loss + final_velocity_weight.dot(sim.state().v);
  }

  ParameterGradient Gradient(Simulator& sim, const PhysicalParameters& parameters) const {
    sim.SetParameters(parameters);
    std::vector<SimulationState> states = {sim.state()};
    for (size_t k = 0; k < weights.size(); ++k) {
      sim.Step();
      states.push_back(sim.state());
    }
    const int size = static_cast<int>(states[0].u.size());
    StateAdjoint adjoint{Eigen::VectorXd::Zero(size), final_velocity_weight,
                         Eigen::VectorXd::Zero(size)};
    ParameterGradient gradient;
    for (size_t k = weights.size(); k >= 1; --k) {
      adjoint.u += weights[k - 1];
      const Status status = sim.BackpropagateStep(states[k - 1], states[k], &adjoint, &gradient);
      EXPECT_TRUE(status.ok()) << status.ToString();
    }
    sim.BackpropagateInitialState(states[0], adjoint, &gradient);
    return gradient;
  }
};

// The time integrator under test: plain Newmark (the default options) or generalized-alpha with
// this high-frequency spectral radius.
struct Integrator {
  const char* name;
  double rho_infinity;  // < 0: the default Newmark parameters
};

SimulationOptions TightOptions(const Integrator& integrator) {
  SimulationOptions options;
  if (integrator.rho_infinity >= 0.0) options.UseGeneralizedAlpha(integrator.rho_infinity);
  options.cells_along_longest_side = 4;
  options.time_step = 1.0 / 200.0;
  options.newton_tolerance = 1e-11;
  options.max_newton_iterations = 40;
  options.linear_tolerance = 1e-12;
  options.adjoint_linear_tolerance = 1e-12;
  return options;
}

TrajectoryLoss RandomLoss(int size, int steps, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, 1.0);
  TrajectoryLoss loss;
  for (int k = 0; k < steps; ++k) {
    Eigen::VectorXd d(size);
    for (int i = 0; i < size; ++i) d[i] = noise(rng);
    loss.weights.push_back(d);
  }
  loss.final_velocity_weight.resize(size);
  for (int i = 0; i < size; ++i) loss.final_velocity_weight[i] = 0.01 * noise(rng);
  return loss;
}

// Checks d L / d t along a one-parameter family of parameters p(t) against the adjoint's
// directional derivative.
void ExpectDirectionalDerivative(const std::string& name, Simulator& sim,
                                 const TrajectoryLoss& loss,
                                 const std::function<PhysicalParameters(double)>& family,
                                 double step, double adjoint_value) {
  const double plus = loss.Evaluate(sim, family(step));
  const double minus = loss.Evaluate(sim, family(-step));
  const double finite_difference = (plus - minus) / (2.0 * step);
  EXPECT_NEAR(adjoint_value, finite_difference, 1e-4 * std::abs(finite_difference) + 1e-12)
      << name << ": adjoint " << adjoint_value << " vs finite differences " << finite_difference;
}

// Relative change of one scalar parameter: d L / d log(p) = p dL/dp.
void ExpectRelativeDerivative(const char* name, Simulator& sim, const TrajectoryLoss& loss,
                              const PhysicalParameters& p, double PhysicalParameters::*field,
                              double adjoint_value) {
  const double base = p.*field;
  ExpectDirectionalDerivative(
      name, sim, loss,
      [&](double t) {
        PhysicalParameters q = p;
        q.*field = base * (1.0 + t);
        return q;
      },
      1e-4, adjoint_value * base);
}

// The linear stiffness field's log-gradient along one direction.
void ExpectStiffnessFieldDerivative(Simulator& sim, const TrajectoryLoss& loss,
                                    const PhysicalParameters& p, const ParameterGradient& g,
                                    const Eigen::Vector3d& direction) {
  ASSERT_EQ(g.stiffness_field.size(), 3u);
  ExpectDirectionalDerivative(
      "stiffness_field.log_gradient", sim, loss,
      [&](double t) {
        PhysicalParameters q = p;
        q.stiffness_field.log_gradient += t * direction;
        return q;
      },
      1e-4, Eigen::Vector3d::Map(g.stiffness_field.data()).dot(direction));
}

geometry::TriangleMesh SmallBox() {
  return geometry::MakeBox(Eigen::Vector3d(0.1, 0.07, 0.05), 0.025);
}

class Adjoint : public testing::TestWithParam<Integrator> {};

TEST_P(Adjoint, FreeFlightGradientMatchesFiniteDifferences) {
  PhysicalParameters p;
  p.youngs_modulus = 2e4;
  p.poisson_ratio = 0.32;
  p.density = 300.0;
  p.mass_damping = 0.4;
  p.stiffness_damping = 0.01;
  p.gravity = Eigen::Vector3d(0.3, -0.2, -9.7);
  p.initial_velocity = Eigen::Vector3d(0.4, -0.3, 1.0);
  p.initial_angular_velocity = Eigen::Vector3d(2.0, -4.0, 3.0);
  p.drag_linear = 0.5;
  p.drag_quadratic = 1.5;
  p.stiffness_field.kind = StiffnessField::Kind::kLinear;
  p.stiffness_field.log_gradient = Eigen::Vector3d(3.0, -2.0, 1.0);
  Simulator sim(SmallBox(), p, TightOptions(GetParam()));
  const TrajectoryLoss loss = RandomLoss(3 * sim.hex_mesh().NumNodes(), 12, 7);
  const ParameterGradient g = loss.Gradient(sim, p);

  auto scalar = [&](const char* name, double PhysicalParameters::*field, double adjoint_value) {
    ExpectRelativeDerivative(name, sim, loss, p, field, adjoint_value);
  };
  scalar("youngs_modulus", &PhysicalParameters::youngs_modulus, g.youngs_modulus);
  scalar("poisson_ratio", &PhysicalParameters::poisson_ratio, g.poisson_ratio);
  scalar("density", &PhysicalParameters::density, g.density);
  scalar("mass_damping", &PhysicalParameters::mass_damping, g.mass_damping);
  scalar("stiffness_damping", &PhysicalParameters::stiffness_damping, g.stiffness_damping);
  scalar("drag_linear", &PhysicalParameters::drag_linear, g.drag_linear);
  scalar("drag_quadratic", &PhysicalParameters::drag_quadratic, g.drag_quadratic);

  const Eigen::Vector3d direction(0.6, -0.3, 0.74);
  auto vector = [&](const char* name, Eigen::Vector3d PhysicalParameters::*field,
                    const Eigen::Vector3d& adjoint_value, double scale) {
    ExpectDirectionalDerivative(
        name, sim, loss,
        [&](double t) {
          PhysicalParameters q = p;
          q.*field += t * scale * direction;
          return q;
        },
        1e-4, scale * adjoint_value.dot(direction));
  };
  vector("gravity", &PhysicalParameters::gravity, g.gravity, 1.0);
  vector("initial_velocity", &PhysicalParameters::initial_velocity, g.initial_velocity, 0.1);
  vector("initial_angular_velocity", &PhysicalParameters::initial_angular_velocity,
         g.initial_angular_velocity, 1.0);
  ExpectStiffnessFieldDerivative(sim, loss, p, g, direction);
}

TEST_P(Adjoint, ContactAndFrictionGradientMatchesFiniteDifferences) {
  PhysicalParameters p;
  p.youngs_modulus = 3e4;
  p.poisson_ratio = 0.3;
  p.density = 400.0;
  p.stiffness_damping = 0.005;
  p.contact_damping = 0.002;
  p.friction_coefficient = 0.4;
  p.ground = GroundPlane{Eigen::Vector3d(0.2, 0.1, 1.0).normalized(), -0.04};
  p.initial_velocity = Eigen::Vector3d(0.6, 0.2, -0.3);
  p.stiffness_field.kind = StiffnessField::Kind::kRegions;
  p.stiffness_field.regions.push_back(
      {Eigen::AlignedBox3d(Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(0.0, 1, 1)), 2.0});
  // Smooth friction and contact knees, so that Newton converges to round-off at every step and the
  // finite differences see the same discrete solution as the adjoint.
  SimulationOptions options = TightOptions(GetParam());
  options.friction_velocity_scale = 0.05;
  options.contact_smoothing = 2e-3;
  Simulator sim(SmallBox(), p, options);
  const TrajectoryLoss loss = RandomLoss(3 * sim.hex_mesh().NumNodes(), 16, 11);
  const ParameterGradient g = loss.Gradient(sim, p);

  auto scalar = [&](const char* name, double PhysicalParameters::*field, double adjoint_value) {
    ExpectRelativeDerivative(name, sim, loss, p, field, adjoint_value);
  };
  // E also sets the default contact stiffness 100 E / L.
  scalar("youngs_modulus", &PhysicalParameters::youngs_modulus, g.youngs_modulus);
  scalar("friction_coefficient", &PhysicalParameters::friction_coefficient, g.friction_coefficient);
  scalar("contact_damping", &PhysicalParameters::contact_damping, g.contact_damping);
  scalar("density", &PhysicalParameters::density, g.density);
  scalar("poisson_ratio", &PhysicalParameters::poisson_ratio, g.poisson_ratio);
  scalar("stiffness_damping", &PhysicalParameters::stiffness_damping, g.stiffness_damping);
  const Eigen::Vector3d direction(-0.5, 0.4, 0.77);
  for (auto [name, field, adjoint_value] :
       {std::tuple{"gravity", &PhysicalParameters::gravity, g.gravity},
        std::tuple{"initial_velocity", &PhysicalParameters::initial_velocity, g.initial_velocity},
        std::tuple{"initial_angular_velocity", &PhysicalParameters::initial_angular_velocity,
                   g.initial_angular_velocity}}) {
    ExpectDirectionalDerivative(
        name, sim, loss,
        [&, field = field](double t) {
          PhysicalParameters q = p;
          q.*field += t * direction;
          return q;
        },
        1e-4, adjoint_value.dot(direction));
  }
  ExpectDirectionalDerivative(
      "ground.offset", sim, loss,
      [&](double t) {
        PhysicalParameters q = p;
        q.ground->offset += t;
        return q;
      },
      1e-6, g.ground_offset);
  const Eigen::Vector3d n = p.ground->normal;
  const Eigen::Vector3d tangent = n.cross(Eigen::Vector3d(0.3, 1.0, 0.2)).normalized();
  ExpectDirectionalDerivative(
      "ground.normal", sim, loss,
      [&](double t) {
        PhysicalParameters q = p;
        q.ground->normal = (n + t * tangent).normalized();
        return q;
      },
      1e-5, g.ground_normal.dot(tangent));
  ASSERT_EQ(g.stiffness_field.size(), 1u);
  ExpectDirectionalDerivative(
      "stiffness_field.regions[0].scale", sim, loss,
      [&](double t) {
        PhysicalParameters q = p;
        q.stiffness_field.regions[0].scale *= 1.0 + t;
        return q;
      },
      1e-4, g.stiffness_field[0] * 2.0);

  // An explicit contact stiffness, and friction screened at mu = 0.
  PhysicalParameters q = p;
  q.contact_stiffness = 100.0 * p.youngs_modulus / 0.1;
  q.friction_coefficient = 0.0;
  const ParameterGradient gq = loss.Gradient(sim, q);
  ExpectDirectionalDerivative(
      "contact_stiffness", sim, loss,
      [&](double t) {
        PhysicalParameters r = q;
        r.contact_stiffness *= 1.0 + t;
        return r;
      },
      1e-4, gq.contact_stiffness * q.contact_stiffness);
  // One-sided at the boundary mu = 0 (mu < 0 is not a valid parameter).
  const double step = 1e-6;
  PhysicalParameters with_friction = q;
  with_friction.friction_coefficient = step;
  const double forward_difference =
      (loss.Evaluate(sim, with_friction) - loss.Evaluate(sim, q)) / step;
  EXPECT_NEAR(gq.friction_coefficient, forward_difference, 1e-3 * std::abs(forward_difference))
      << "friction at mu = 0";
  EXPECT_GT(std::abs(gq.friction_coefficient), 0.0);
}

// The incompatible-modes element: its stiffness is not linear in the Lame parameters, so the
// Poisson ratio's derivative goes through d K / d mu at the current ratio. A simulator whose
// gradient was first taken at another Poisson ratio must give the same gradient as a fresh one
// (d K / d mu is rebuilt when the parameters change).
TEST(Adjoint, IncompatibleModesGradientMatchesFiniteDifferences) {
  PhysicalParameters p;
  p.youngs_modulus = 2e4;
  p.poisson_ratio = 0.42;
  p.density = 300.0;
  p.stiffness_damping = 0.01;
  p.gravity = Eigen::Vector3d(0.3, -0.2, -9.7);
  p.initial_angular_velocity = Eigen::Vector3d(2.0, -4.0, 3.0);
  p.stiffness_field.kind = StiffnessField::Kind::kLinear;
  p.stiffness_field.log_gradient = Eigen::Vector3d(3.0, -2.0, 1.0);
  SimulationOptions options = TightOptions(Integrator{"Newmark", -1.0});
  options.element = ElementFormulation::kIncompatibleModes;
  Simulator sim(SmallBox(), p, options);
  const TrajectoryLoss loss = RandomLoss(3 * sim.hex_mesh().NumNodes(), 12, 5);
  PhysicalParameters other = p;
  other.poisson_ratio = 0.2;
  loss.Gradient(sim, other);
  const ParameterGradient g = loss.Gradient(sim, p);
  Simulator fresh(SmallBox(), p, options);
  EXPECT_NEAR(loss.Gradient(fresh, p).poisson_ratio, g.poisson_ratio,
              1e-7 * std::abs(g.poisson_ratio));
  ExpectRelativeDerivative("youngs_modulus", sim, loss, p, &PhysicalParameters::youngs_modulus,
                           g.youngs_modulus);
  ExpectRelativeDerivative("poisson_ratio", sim, loss, p, &PhysicalParameters::poisson_ratio,
                           g.poisson_ratio);
  ExpectRelativeDerivative("stiffness_damping", sim, loss, p,
                           &PhysicalParameters::stiffness_damping, g.stiffness_damping);
  const Eigen::Vector3d direction(0.6, -0.3, 0.74);
  ExpectStiffnessFieldDerivative(sim, loss, p, g, direction);
}

INSTANTIATE_TEST_SUITE_P(Integrators, Adjoint,
                         testing::Values(Integrator{"Newmark", -1.0},
                                         Integrator{"GeneralizedAlpha", 0.8}),
                         [](const testing::TestParamInfo<Integrator>& info) {
                           return std::string(info.param.name);
                         });

}  // namespace
}  // namespace softid::fem
