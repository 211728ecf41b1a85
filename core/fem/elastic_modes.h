// The lowest elastic eigenfrequencies of a Simulator's discrete body at rest: K x = w^2 M x with
// the elements' stiffness K (Simulator::RestStiffnessMatrix) and the lumped mass M.
//
// Why: a check of the model's stiffness that involves no contact, no time step and no fit. With
// the Poisson ratio fixed, every eigenfrequency of a linear elastic body scales as sqrt(E), so a
// model that vibrates at f_model where the body it should match vibrates at f_true will fit
// E_true (f_true / f_model)^2 to that body's motion (ExpectedFittedModulus). Comparing f_model
// with another code's converged frequency, or an analytic one, bounds the element formulation's
// and the cut cells' share of a fitted E's error.
#pragma once

#include <vector>

#include "core/common/status.h"
#include "core/fem/simulator.h"

namespace softid::fem {

struct ElasticModesOptions {
  int count = 6;  // elastic modes wanted, rigid-body modes not counted; >= 1
};

struct ElasticModes {
  std::vector<double> frequencies_hz;  // the lowest `count` elastic modes, ascending [Hz]
  // Rigid-body modes set aside: 6 for a free body, 0 for a clamped one.
  int rigid_modes = 0;
  // The largest of the rigid modes' computed frequencies [Hz]: round-off, far below the first
  // elastic one (a check that they are rigid).
  double rigid_frequency_hz = 0.0;
  int degrees_of_freedom = 0;  // of the free nodes
};

// @returns InvalidArgument naming the field when options.count is out of range, Internal when the
//   eigensolver does not converge. Leaves the simulator's assembly storage overwritten (see
//   Simulator::RestStiffnessMatrix).
Result<ElasticModes> ComputeElasticModes(Simulator& simulator,
                                         const ElasticModesOptions& options = {});

// The Young's modulus [Pa] a model with modulus `model_modulus_pa` and lowest frequency
// `model_frequency_hz` fits to a body whose lowest frequency is `true_frequency_hz` (same shape,
// density and Poisson ratio): E (f_true / f_model)^2.
inline double ExpectedFittedModulus(double model_modulus_pa, double model_frequency_hz,
                                    double true_frequency_hz) {
  const double ratio = true_frequency_hz / model_frequency_hz;
  return model_modulus_pa * ratio * ratio;
}

}  // namespace softid::fem
