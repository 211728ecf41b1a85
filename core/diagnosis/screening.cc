#include "core/diagnosis/screening.h"

#include <spdlog/spdlog.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <optional>
#include <utility>

#include "core/common/check.h"
#include "core/common/json_fields.h"
#include "core/diagnosis/likelihood_ratio.h"
#include "core/inverse/objective_pool.h"

namespace softid::diagnosis {
namespace {

bool Contains(const std::vector<std::string>& names, const std::string& name) {
  return std::find(names.begin(), names.end(), name) != names.end();
}

// One way of leaving the null: parameters at theta (base variables at x), and dC/dtheta from the
// adjoint's gradient at those parameters.
struct Variant {
  Extension extension;
  int axis = -1;
  bool boundary = false;   // theta >= 0
  bool central = false;    // curvature from theta = +-delta (else from 0 and delta)
  double step = 0.0;       // delta
  double max_start = 0.0;  // |theta| bound of the refit start
  std::function<fem::PhysicalParameters(const fem::PhysicalParameters&, double)> make;
  // The base variables' share of a ladder start at theta (identity when absent): what the
  // extension changes that the base model already fitted, put back.
  std::function<fem::PhysicalParameters(fem::PhysicalParameters, double)> rebalance;
  // Further ways to put the base share back, laddered over the larger starts too (see below).
  std::vector<std::function<fem::PhysicalParameters(fem::PhysicalParameters, double)>>
      alternative_rebalances;
  std::function<double(const fem::ParameterGradient&, const fem::PhysicalParameters&)> dtheta;
};

// A refit start to try: its theta (the side of the null it lies on) and parameters.
using Try = std::pair<double, fem::PhysicalParameters>;

// A variant screened up to its refit tries, which run for all variants at once.
struct PreparedVariant {
  ScreenedCandidate screened;
  std::vector<fem::PhysicalParameters> slope_points;  // empty: the variant does not apply
  double predicted_drop = 0.0;                        // by the profiled quadratic model [m^2]
  std::vector<Try> tries;                             // empty: `screened` is final
};

struct Point {
  double dtheta = 0.0;
  Eigen::VectorXd gx;  // dC/dx_b
  double cost = 0.0;
};

}  // namespace

std::array<Eigen::Vector3d, 3> PrincipalAxes(const fem::HexMesh& mesh) {
  // Second moment of the volume about the centroid, from the (cut-)cell volumes.
  double volume = 0.0;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (int e = 0; e < mesh.NumElements(); ++e) {
    const double w = mesh.element_weights[e].volume;
    volume += w;
    centroid += w * mesh.ElementCentre(e);
  }
  std::array<Eigen::Vector3d, 3> world = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(),
                                          Eigen::Vector3d::UnitZ()};
  if (!(volume > 0.0)) return world;
  centroid /= volume;
  Eigen::Matrix3d moment = Eigen::Matrix3d::Zero();
  for (int e = 0; e < mesh.NumElements(); ++e) {
    const Eigen::Vector3d d = mesh.ElementCentre(e) - centroid;
    moment += mesh.element_weights[e].volume * d * d.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(moment);
  const Eigen::Vector3d lambda = eigen.eigenvalues();  // ascending
  // Moments within 5 % of each other leave the axes in their plane undefined by the shape (a
  // cube, the square section of a bar): there the world axes projected into that plane are used,
  // so that the choice is reproducible and, for a body set square to the capture frame, exact.
  constexpr double kSame = 0.05;
  std::array<Eigen::Vector3d, 3> out;
  int i = 0;
  while (i < 3) {
    int j = i + 1;
    while (j < 3 && lambda[j] - lambda[i] <= kSame * lambda[2]) ++j;
    const Eigen::MatrixXd basis = eigen.eigenvectors().middleCols(i, j - i);
    if (j - i == 1) {
      out[i] = basis.col(0);
    } else {
      // The world axes with the largest projections into the plane, orthonormalised.
      std::array<int, 3> order = {0, 1, 2};
      std::array<double, 3> projected;
      for (int a = 0; a < 3; ++a) projected[a] = (basis.transpose() * world[a]).norm();
      std::sort(order.begin(), order.end(),
                [&](int a, int b) { return projected[a] > projected[b]; });
      for (int k = i; k < j; ++k) {
        Eigen::Vector3d v = basis * (basis.transpose() * world[order[k - i]]);
        for (int m = i; m < k; ++m) v -= v.dot(out[m]) * out[m];
        out[k] = v.norm() > 1e-9 ? v.normalized() : basis.col(k - i);
      }
    }
    i = j;
  }
  return out;
}

Status ScreeningOptions::Validate() const {
  if (!(signature_weight >= 0.0 && signature_weight <= 1.0))
    return json::Invalid("screening.signature_weight", signature_weight, "must lie in [0, 1]");
  const std::pair<double, const char*> positive[] = {
      {friction_step, "screening.friction_step"},
      {drag_step, "screening.drag_step"},
      {log_ratio_step, "screening.log_ratio_step"},
      {log_contact_step, "screening.log_contact_step"},
      {spin_step, "screening.spin_step"},
      {max_friction_start, "screening.max_friction_start"},
      {max_drag_start, "screening.max_drag_start"},
      {max_log_ratio_start, "screening.max_log_ratio_start"},
      {max_log_contact_start, "screening.max_log_contact_start"},
      {max_spin_start, "screening.max_spin_start"}};
  for (const auto& [value, field] : positive) {
    if (!(value > 0.0) || !std::isfinite(value))
      return json::Invalid(field, value, "must be positive");
  }
  if (!(two_sided_start_factor > 1.0) || !std::isfinite(two_sided_start_factor))
    return json::Invalid("screening.two_sided_start_factor", two_sided_start_factor, "must be > 1");
  return Status::Ok();
}

std::vector<bool> SignatureFrames(const Candidate& candidate,
                                  const std::vector<FrameMotion>& motion) {
  std::vector<bool> out(motion.size(), false);
  bool contact_seen = false;
  for (size_t k = 0; k < motion.size(); ++k) {
    contact_seen |= motion[k].phase != Phase::kFlight;
    out[k] = candidate.all_frames || (candidate.after_contact && contact_seen) ||
             std::find(candidate.phases.begin(), candidate.phases.end(), motion[k].phase) !=
                 candidate.phases.end();
  }
  return out;
}

namespace {

// The screening of one base fit: what every variant shares (the base point, its gradient in the
// base variables, the profiled inverse Hessian) and the steps each variant goes through.
struct Screening {
  inverse::TrajectoryObjective& objective;
  const ScreeningBase& base;
  const ScreeningOptions& options;
  const inverse::ParameterSpace& space;
  const fem::PhysicalParameters& p0;
  std::vector<double> x0;
  int nb = 0;
  double k0 = 0.0;              // the contact stiffness the contact variant scales [Pa/m]
  Eigen::MatrixXd hbb_inverse;  // H_bb^+ over the base variables
  fem::ParameterGradient g0;    // at the null
  Point null_point;
  Eigen::Vector3d spin_direction = Eigen::Vector3d::Zero();

  Screening(inverse::TrajectoryObjective& objective, const ScreeningBase& base,
            const ScreeningOptions& options)
      : objective(objective),
        base(base),
        options(options),
        space(*base.space),
        p0(base.parameters),
        x0(space.ToVariables(p0)),
        nb(space.NumVariables()) {
    k0 = p0.contact_stiffness > 0.0
             ? p0.contact_stiffness
             : fem::DefaultContactStiffness(p0.youngs_modulus, base.rest_bounds.sizes().maxCoeff());
    hbb_inverse = ProfiledInverse();
  }

  // H_bb^+ (pseudo-inverse over its positive eigenvalues): base directions the data do not fix
  // cannot absorb anything to second order.
  Eigen::MatrixXd ProfiledInverse() const {
    Eigen::MatrixXd out = Eigen::MatrixXd::Zero(nb, nb);
    if (base.hessian.rows() != nb || base.hessian.cols() != nb || nb == 0) return out;
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(0.5 *
                                                         (base.hessian + base.hessian.transpose()));
    const double top = eigen.eigenvalues().cwiseAbs().maxCoeff();
    for (int i = 0; i < nb; ++i) {
      const double lambda = eigen.eigenvalues()[i];
      if (lambda > 1e-8 * top) {
        out += eigen.eigenvectors().col(i) * eigen.eigenvectors().col(i).transpose() / lambda;
      }
    }
    return out;
  }

  // The null, shared by the variants whose null is the base model itself.
  Status EvaluateNull() {
    SOFTID_ASSIGN_OR_RETURN(inverse::ObjectiveEvaluation null_eval, objective.Evaluate(p0, true));
    if (null_eval.diverged)
      return Status::FailedPrecondition("the base fit's simulation diverges: cannot screen");
    g0 = null_eval.gradient;
    null_point.cost = null_eval.cost;
    null_point.gx.resize(nb);
    if (nb > 0) space.ChainGradient(g0, x0.data(), null_point.gx.data());
    if (g0.initial_angular_velocity.norm() > 0.0)
      spin_direction = -g0.initial_angular_velocity.normalized();
    return Status::Ok();
  }

  // The point of a slope run at p (empty: invalid parameters or a diverged simulation).
  bool ToPoint(const std::optional<inverse::ObjectiveEvaluation>& e,
               const fem::PhysicalParameters& p, const Variant& v, Point* out) const {
    if (!e) return false;
    out->cost = e->cost;
    out->dtheta = v.dtheta(e->gradient, p);
    out->gx.resize(nb);
    if (nb > 0) space.ChainGradient(e->gradient, x0.data(), out->gx.data());
    return true;
  }

  // Where the slope and curvature of v are measured: theta = +-delta (central), else delta.
  std::vector<fem::PhysicalParameters> SlopePoints(const Variant& v) const {
    if (v.central) return {v.make(p0, -v.step), v.make(p0, v.step)};
    return {v.make(p0, v.step)};
  }

  // Every way of leaving the null: friction, drag, the stiffness halves along each axis, contact
  // stiffness, spin.
  std::vector<Variant> Variants() const {
    std::vector<Variant> variants;
    {
      Variant v;
      v.extension = Extension::kFriction;
      v.boundary = true;
      v.step = options.friction_step;
      v.max_start = options.max_friction_start;
      v.make = [](fem::PhysicalParameters p, double t) {
        p.friction_coefficient = t;
        return p;
      };
      v.dtheta = [](const fem::ParameterGradient& g, const fem::PhysicalParameters&) {
        return g.friction_coefficient;
      };
      variants.push_back(v);
      v.extension = Extension::kAirDrag;
      v.step = options.drag_step;
      v.max_start = options.max_drag_start;
      v.make = [](fem::PhysicalParameters p, double t) {
        p.drag_quadratic = t;
        return p;
      };
      v.dtheta = [](const fem::ParameterGradient& g, const fem::PhysicalParameters&) {
        return g.drag_quadratic;
      };
      variants.push_back(v);
    }
    for (int axis = 0; axis < 3; ++axis) variants.push_back(HalvesVariant(axis));
    {
      Variant v;
      v.extension = Extension::kContact;
      v.central = true;
      v.step = options.log_contact_step;
      v.max_start = options.max_log_contact_start;
      v.make = [k0 = k0](fem::PhysicalParameters p, double t) {
        p.contact_stiffness = k0 * std::exp(t);
        return p;
      };
      v.dtheta = [](const fem::ParameterGradient& g, const fem::PhysicalParameters& p) {
        return g.contact_stiffness * p.contact_stiffness;
      };
      variants.push_back(v);
    }
    {
      Variant v;
      v.extension = Extension::kInitialSpin;
      v.boundary = true;  // a rate along the descent direction
      v.step = options.spin_step;
      v.max_start = options.max_spin_start;
      v.make = [spin_direction = spin_direction](fem::PhysicalParameters p, double t) {
        p.initial_angular_velocity = t * spin_direction;
        return p;
      };
      v.dtheta = [spin_direction = spin_direction](const fem::ParameterGradient& g,
                                                   const fem::PhysicalParameters&) {
        return g.initial_angular_velocity.dot(spin_direction);
      };
      variants.push_back(v);
    }
    return variants;
  }

  Variant HalvesVariant(int axis) const {
    Variant v;
    v.extension = Extension::kHeterogeneousStiffness;
    v.axis = axis;
    v.central = true;
    v.step = options.log_ratio_step;
    v.max_start = options.max_log_ratio_start;
    const Eigen::AlignedBox3d bounds = base.rest_bounds;
    v.make = [bounds, axis](fem::PhysicalParameters p, double t) {
      p.stiffness_field = HalvesField(bounds, axis, std::exp(t));
      return p;
    };
    v.dtheta = [](const fem::ParameterGradient& g, const fem::PhysicalParameters& p) {
      return g.stiffness_field.size() == 1
                 ? g.stiffness_field[0] * p.stiffness_field.regions[0].scale
                 : 0.0;
    };
    // E is the upper half's modulus and the lower one's is r E: E / sqrt(r) keeps their geometric
    // mean at the fitted E.
    if (Contains(base.fitted, "youngs_modulus")) {
      v.rebalance = [](fem::PhysicalParameters p, double t) {
        p.youngs_modulus *= std::exp(-0.5 * t);
        return p;
      };
      // A uniform fit of a two-stiffness body can also settle near one half's modulus (the
      // half that dominates the motion): the 4x halves' uniform fit found E = 7.0 kPa for
      // halves of 6 and 1.5 kPa, where no geometric-mean split comes near the truth. So the
      // ladder also keeps the fitted E on either half.
      v.alternative_rebalances = {[](fem::PhysicalParameters p, double) { return p; },
                                  [](fem::PhysicalParameters p, double t) {
                                    p.youngs_modulus *= std::exp(-t);
                                    return p;
                                  }};
    }
    return v;
  }

  // Whether the variant can be screened here; *s's note says why not.
  bool CheckApplicable(const Variant& v, const Candidate& candidate, ScreenedCandidate* s) const {
    const bool uniform_field = p0.stiffness_field.kind == fem::StiffnessField::Kind::kUniform;
    for (const std::string& name : candidate.parameters) {
      if (Contains(base.fitted, name)) {
        s->applicable = false;
        s->note = name + " is already fitted by the base model";
      }
    }
    if (candidate.needs_ground && !p0.ground) {
      s->applicable = false;
      s->note = "no ground plane: no contact";
    }
    // A value the job fixed away from the null is the job's claim; leave it alone.
    const bool off_null =
        (v.extension == Extension::kFriction && p0.friction_coefficient != 0.0) ||
        (v.extension == Extension::kAirDrag && p0.drag_quadratic != 0.0) ||
        (v.extension == Extension::kHeterogeneousStiffness && !uniform_field) ||
        (v.extension == Extension::kContact && p0.contact_damping != 0.0) ||
        (v.extension == Extension::kInitialSpin && p0.initial_angular_velocity.norm() != 0.0);
    if (s->applicable && off_null) {
      s->applicable = false;
      s->note = "fixed by the job away from its null value";
    }
    if (v.extension == Extension::kInitialSpin && spin_direction.norm() == 0.0) {
      s->applicable = false;
      s->note = "score: zero gradient";
    }
    return s->applicable;
  }

  // Score (slope at the null) and curvatures, raw and with the base variables profiled out, from
  // the runs at SlopePoints(v); *absorb is how the base variables move per unit of theta. False
  // when the simulation diverges next to the null.
  bool MeasureSlope(const Variant& v,
                    const std::vector<std::optional<inverse::ObjectiveEvaluation>>& runs,
                    ScreenedCandidate* s, Eigen::VectorXd* absorb) const {
    const std::vector<fem::PhysicalParameters> at = SlopePoints(v);
    Point a, b;
    double separation = v.step;
    if (v.central) {
      if (!ToPoint(runs[0], at[0], v, &a) || !ToPoint(runs[1], at[1], v, &b)) return false;
      separation = 2.0 * v.step;
      s->gradient = 0.5 * (a.dtheta + b.dtheta);
    } else {
      a = null_point;
      a.dtheta = v.dtheta(g0, p0);
      if (!ToPoint(runs[0], at[0], v, &b)) return false;
      s->gradient = a.dtheta;
    }
    s->curvature = (b.dtheta - a.dtheta) / separation;
    const Eigen::VectorXd h =
        nb > 0 ? Eigen::VectorXd((b.gx - a.gx) / separation) : Eigen::VectorXd();
    *absorb = nb > 0 ? Eigen::VectorXd(hbb_inverse * h) : Eigen::VectorXd();
    s->efficient_curvature = nb > 0 ? s->curvature - h.dot(*absorb) : s->curvature;
    return true;
  }

  // Refit starts to try, each with its theta (the side of the null it lies on): the best of the
  // joint Newton step (base variables re-adjusted), the extension alone, and half the joint step,
  // then ladders over the start range.
  std::vector<Try> RefitTries(const Variant& v, const ScreenedCandidate& s, double theta,
                              const Eigen::VectorXd& absorb) const {
    std::vector<Try> tries;
    Eigen::VectorXd dx = nb > 0 ? Eigen::VectorXd(-absorb * theta) : Eigen::VectorXd();
    for (int i = 0; i < nb; ++i) dx[i] = std::clamp(dx[i], -1.0, 1.0);
    auto with_base = [&](double t, double fraction) {
      std::vector<double> x = x0;
      for (int i = 0; i < nb; ++i) x[i] += fraction * dx[i];
      return v.make(space.ToParameters(x.data(), p0), t);
    };
    tries.emplace_back(theta, with_base(theta, 1.0));
    tries.emplace_back(theta, with_base(theta, 0.0));
    tries.emplace_back(0.5 * theta, with_base(0.5 * theta, 0.5));
    auto ladder_start = [&](double t) {
      fem::PhysicalParameters p = with_base(t, 0.0);
      return v.rebalance ? v.rebalance(p, t) : p;
    };
    // And a ladder of the extension alone over its start range: the cost is far from quadratic
    // for large effects (stick-slip, a spinning cube that looks the same every quarter turn), and
    // a start in the wrong basin stalls the refit.
    const double downhill = v.boundary ? 1.0 : (s.gradient > 0.0 ? -1.0 : 1.0);
    constexpr double kLadder[] = {1.0 / 16, 1.0 / 8, 3.0 / 16, 1.0 / 4, 3.0 / 8, 1.0 / 2, 3.0 / 4};
    for (double f : kLadder) {
      const double t = downhill * f * v.max_start;
      tries.emplace_back(t, ladder_start(t));
    }
    // A two-sided variable is laddered uphill of the score too: the score is the slope at the
    // null, and a large effect's minimum can lie the other way (seen with a 2x stiffness contrast
    // between the halves of a bouncing bar: the slope at ratio 1 pointed to ratios below 1, the
    // minimum is at 2). The cost decides between the two sides, not the slope.
    if (!v.boundary) {
      for (double f : kLadder) {
        const double t = -downhill * f * v.max_start;
        tries.emplace_back(t, ladder_start(t));
      }
    }
    for (const auto& rebalance : v.alternative_rebalances) {
      for (double f : {1.0 / 4, 3.0 / 8, 1.0 / 2, 3.0 / 4}) {
        for (double side : {1.0, -1.0}) {
          const double t = side * f * v.max_start;
          tries.emplace_back(t, rebalance(with_base(t, 0.0), t));
        }
      }
    }
    // A spin also along each principal axis of the body, both ways. The score is the linear
    // response at rest; a spin of a few rad/s turns the body by tens of degrees, and a symmetric
    // body looks alike after a quarter turn, so the score's direction mixes in other axes and
    // even its sign along the true axis can be wrong (a cube turned by 80 degrees looks like one
    // turned back by 10). A ladder along the score alone then starts the refit in a wrong basin.
    // A body released with a spin turns about a principal axis of inertia in the common case
    // (the only steady free rotations), so these six directions are where a start is worth
    // trying; the refit frees all three components anyway.
    if (v.extension == Extension::kInitialSpin) {
      // The hex mesh lies in the grid's frame; the spin is a world vector.
      const Eigen::Matrix3d world_from_grid =
          objective.simulator().rest_frame().world_from_rest().linear();
      for (const Eigen::Vector3d& grid_axis : PrincipalAxes(objective.simulator().hex_mesh())) {
        const Eigen::Vector3d axis = world_from_grid * grid_axis;
        for (const Eigen::Vector3d& turn : {Eigen::Vector3d(axis), Eigen::Vector3d(-axis)}) {
          if (turn.dot(spin_direction) > 0.99) continue;  // the score's ladder already covers it
          for (double f : kLadder) {
            fem::PhysicalParameters p = with_base(0.0, 0.0);
            p.initial_angular_velocity = f * v.max_start * turn;
            tries.emplace_back(f * v.max_start, p);
          }
        }
      }
    }
    return tries;
  }

  // The refit's start(s) from the tries by their forward cost (infinite: invalid or diverged),
  // and the fallbacks.
  void ChooseStarts(const Variant& v, const std::vector<Try>& tries,
                    const std::vector<double>& try_costs, ScreenedCandidate* s_ptr) const {
    ScreenedCandidate& s = *s_ptr;
    s.start_cost = std::numeric_limits<double>::infinity();
    double start_theta = 0.0;
    for (size_t i = 0; i < tries.size(); ++i) {
      if (try_costs[i] < s.start_cost) {
        s.start_cost = try_costs[i];
        s.start = tries[i].second;
        start_theta = tries[i].first;
      }
    }
    // Two-sided variables: the best start on each side, far enough from the null; the side
    // with the lower forward cost first.
    s.refit_starts = {s.start};
    s.refit_thetas = {start_theta};
    if (!v.boundary) {
      const double min_theta = std::log(options.two_sided_start_factor);
      std::array<int, 2> best_of_side = {-1, -1};
      for (size_t i = 0; i < tries.size(); ++i) {
        if (!std::isfinite(try_costs[i]) || std::abs(tries[i].first) < min_theta) continue;
        int& best = best_of_side[tries[i].first > 0.0 ? 0 : 1];
        if (best < 0 || try_costs[i] < try_costs[best]) best = static_cast<int>(i);
      }
      if (best_of_side[0] >= 0 && best_of_side[1] >= 0 &&
          try_costs[best_of_side[1]] < try_costs[best_of_side[0]])
        std::swap(best_of_side[0], best_of_side[1]);
      s.refit_starts.clear();
      s.refit_thetas.clear();
      for (int i : best_of_side) {
        if (i < 0) continue;
        s.refit_starts.push_back(tries[i].second);
        s.refit_thetas.push_back(tries[i].first);
      }
      if (s.refit_starts.empty()) {
        s.refit_starts = {s.start};
        s.refit_thetas = {start_theta};
      }
    }
    {
      // Fallbacks: the other finite tries on the same side as the first refit start (the
      // screening found the effect that way), in order of cost.
      std::vector<size_t> order;
      const double side = s.refit_thetas.empty() ? start_theta : s.refit_thetas.front();
      for (size_t i = 0; i < tries.size(); ++i) {
        if (!std::isfinite(try_costs[i]) || tries[i].first * side <= 0.0) continue;
        if (std::abs(tries[i].first - side) < 1e-12) continue;
        order.push_back(i);
      }
      std::sort(order.begin(), order.end(),
                [&](size_t a, size_t b) { return try_costs[a] < try_costs[b]; });
      for (size_t i : order) {
        if (static_cast<int>(s.fallback_starts.size()) >= ScreenedCandidate::kMaxFallbackStarts)
          break;
        s.fallback_starts.push_back(tries[i].second);
      }
    }
  }

  // A variant's screening begins: applicability, and where its slope is measured (none when it
  // does not apply).
  PreparedVariant Begin(const Variant& v) const {
    PreparedVariant prepared;
    ScreenedCandidate& s = prepared.screened;
    s.extension = v.extension;
    s.axis = v.axis;
    s.start = p0;
    s.start_cost = base.cost;
    if (v.extension == Extension::kInitialSpin) s.direction = spin_direction;
    if (CheckApplicable(v, GetCandidate(v.extension), &s)) prepared.slope_points = SlopePoints(v);
    return prepared;
  }

  // ... continues from the slope runs: slope and curvature, and the refit tries to run (none when
  // the variant is settled already).
  void Prepare(const Variant& v,
               const std::vector<std::optional<inverse::ObjectiveEvaluation>>& runs,
               PreparedVariant* prepared_ptr) const {
    PreparedVariant& prepared = *prepared_ptr;
    ScreenedCandidate& s = prepared.screened;
    if (prepared.slope_points.empty()) return;
    Eigen::VectorXd absorb;
    if (!MeasureSlope(v, runs, &s, &absorb)) {
      s.applicable = false;
      s.note = "the simulation diverges next to the null";
      return;
    }
    if (v.boundary && !(s.gradient < 0.0)) {
      s.note = "score: the cost rises as the parameter leaves 0";
      return;
    }
    // Newton's step on the profiled quadratic model, or a few steps downhill without curvature.
    double curvature = s.efficient_curvature;
    if (!(curvature > 0.01 * std::abs(s.curvature))) {
      s.note = "the base parameters absorb most of it (profiled curvature ~0)";
      curvature = 0.01 * std::abs(s.curvature);
    }
    double theta =
        curvature > 0.0 ? -s.gradient / curvature : -4.0 * v.step * (s.gradient > 0 ? 1 : -1);
    theta = std::clamp(theta, v.boundary ? 0.5 * v.step : -v.max_start, v.max_start);
    prepared.predicted_drop =
        curvature > 0.0 ? 0.5 * s.gradient * s.gradient / curvature : std::abs(s.gradient * theta);
    prepared.tries = RefitTries(v, s, theta, absorb);
  }

  // The second half: the refit starts from the tries' forward costs, predicted LR and score.
  ScreenedCandidate Finish(const Variant& v, PreparedVariant prepared,
                           const std::vector<double>& try_costs,
                           const std::vector<FrameMotion>& motion,
                           const std::vector<double>& excess, double total_excess) const {
    ScreenedCandidate& s = prepared.screened;
    if (prepared.tries.empty()) return s;
    const Candidate& candidate = GetCandidate(v.extension);
    ChooseStarts(v, prepared.tries, try_costs, &s);
    if (!std::isfinite(s.start_cost)) {
      s.applicable = false;
      s.note = "the simulation diverges at every refit start";
      return s;
    }
    switch (v.extension) {
      case Extension::kFriction: s.theta = s.start.friction_coefficient; break;
      case Extension::kAirDrag: s.theta = s.start.drag_quadratic; break;
      case Extension::kInitialSpin:
        s.theta = s.start.initial_angular_velocity.norm();
        if (s.theta > 0.0) s.direction = s.start.initial_angular_velocity / s.theta;
        break;
      case Extension::kContact: s.theta = std::log(s.start.contact_stiffness / k0); break;
      case Extension::kHeterogeneousStiffness:
        s.theta = s.start.stiffness_field.regions.empty()
                      ? 0.0
                      : std::log(s.start.stiffness_field.regions[0].scale);
        break;
    }
    // The quadratic model's prediction where the profiled curvature is positive (a cost cannot
    // fall below the noise floor), otherwise only what the start actually achieved.
    const bool quadratic = s.efficient_curvature > 0.01 * std::abs(s.curvature);
    const double predicted_cost =
        quadratic
            ? std::min(std::max(base.cost - prepared.predicted_drop, base.floor_cost), s.start_cost)
            : s.start_cost;
    s.predicted_lr =
        LikelihoodRatioStatistic(base.cost, std::max(predicted_cost, 1e-30), base.n_eff);
    if (total_excess > 0.0) {
      const std::vector<bool> frames = SignatureFrames(candidate, motion);
      double inside = 0.0;
      for (size_t k = 0; k < frames.size() && k < excess.size(); ++k)
        if (frames[k]) inside += excess[k];
      s.signature_share = inside / total_excess;
    }
    s.score = s.predicted_lr *
              ((1.0 - options.signature_weight) + options.signature_weight * s.signature_share);
    return s;
  }
};

// Runs `tasks` tasks on base.make_objective's objectives over base.workers threads when
// given, else one after another on `objective`.
Status RunTasks(inverse::TrajectoryObjective& objective, const ScreeningBase& base, int tasks,
                const std::function<Status(inverse::TrajectoryObjective&, int)>& run) {
  if (base.make_objective)
    return inverse::RunOnObjectives(base.make_objective, tasks, base.workers, run);
  for (int i = 0; i < tasks; ++i) SOFTID_RETURN_IF_ERROR(run(objective, i));
  return Status::Ok();
}

// Forward and adjoint runs at the slope points (empty where the parameters are invalid or the
// simulation diverges); an error of the adjoint is passed on.
Result<std::vector<std::optional<inverse::ObjectiveEvaluation>>> SlopeRuns(
    inverse::TrajectoryObjective& objective, const ScreeningBase& base,
    const std::vector<fem::PhysicalParameters>& points) {
  std::vector<std::optional<inverse::ObjectiveEvaluation>> runs(points.size());
  const auto run = [&](inverse::TrajectoryObjective& on, int i) {
    if (!points[i].Validate().ok()) return Status::Ok();
    SOFTID_ASSIGN_OR_RETURN(inverse::ObjectiveEvaluation e, on.Evaluate(points[i], true));
    if (!e.diverged) runs[i] = std::move(e);
    return Status::Ok();
  };
  SOFTID_RETURN_IF_ERROR(RunTasks(objective, base, static_cast<int>(points.size()), run));
  return runs;
}

// The forward cost of each try (infinite where the parameters are invalid, the simulation
// diverges or fails).
Result<std::vector<double>> ForwardCosts(inverse::TrajectoryObjective& objective,
                                         const ScreeningBase& base, const std::vector<Try>& tries) {
  std::vector<double> costs(tries.size(), std::numeric_limits<double>::infinity());
  std::vector<int> steps(tries.size(), 0);
  const auto run = [&](inverse::TrajectoryObjective& on, int i) {
    if (!tries[i].second.Validate().ok()) return Status::Ok();
    Result<inverse::ObjectiveEvaluation> e = on.Evaluate(tries[i].second, false);
    if (!e.ok()) return Status::Ok();
    steps[i] = e->steps;
    if (!e->diverged) costs[i] = e->cost;
    return Status::Ok();
  };
  const int n = static_cast<int>(tries.size());
  SOFTID_RETURN_IF_ERROR(RunTasks(objective, base, n, run));
  long long total_steps = 0;
  for (int s : steps) total_steps += s;
  spdlog::debug("screening: {} refit tries, {} steps simulated on {} worker(s)", n, total_steps,
                base.make_objective ? base.workers : 1);
  return costs;
}

}  // namespace

Result<std::vector<ScreenedCandidate>> ScreenCandidates(inverse::TrajectoryObjective& objective,
                                                        const ScreeningBase& base,
                                                        const std::vector<FrameMotion>& motion,
                                                        const std::vector<double>& excess,
                                                        const ScreeningOptions& options) {
  SOFTID_RETURN_IF_ERROR(options.Validate());
  SOFTID_DEMAND(base.space != nullptr);
  Screening screening(objective, base, options);
  SOFTID_RETURN_IF_ERROR(screening.EvaluateNull());
  double total_excess = 0.0;
  for (double e : excess) total_excess += e;
  const std::vector<Variant> variants = screening.Variants();
  std::vector<PreparedVariant> prepared;
  std::vector<fem::PhysicalParameters> slope_points;  // every variant's, in order
  for (const Variant& v : variants) {
    prepared.push_back(screening.Begin(v));
    const auto& points = prepared.back().slope_points;
    slope_points.insert(slope_points.end(), points.begin(), points.end());
  }
  SOFTID_ASSIGN_OR_RETURN(const auto slope_runs, SlopeRuns(objective, base, slope_points));
  std::vector<Try> tries;  // every variant's, in order
  for (size_t i = 0, first = 0; i < variants.size(); ++i) {
    const size_t count = prepared[i].slope_points.size();
    screening.Prepare(variants[i], {slope_runs.begin() + first, slope_runs.begin() + first + count},
                      &prepared[i]);
    first += count;
    tries.insert(tries.end(), prepared[i].tries.begin(), prepared[i].tries.end());
  }
  SOFTID_ASSIGN_OR_RETURN(const std::vector<double> costs, ForwardCosts(objective, base, tries));
  std::vector<ScreenedCandidate> out;
  size_t first = 0;
  for (size_t i = 0; i < variants.size(); ++i) {
    const size_t count = prepared[i].tries.size();
    const std::vector<double> variant_costs(costs.begin() + first, costs.begin() + first + count);
    first += count;
    out.push_back(screening.Finish(variants[i], std::move(prepared[i]), variant_costs, motion,
                                   excess, total_excess));
  }
  std::stable_sort(
      out.begin(), out.end(),
      [](const ScreenedCandidate& a, const ScreenedCandidate& b) { return a.score > b.score; });
  return out;
}

}  // namespace softid::diagnosis
