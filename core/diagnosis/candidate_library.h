// The candidate extensions of the base model, taken from the physics the simulator has (and the
// base fit left at its null value), plus the nuisances that can mimic physics and must never be
// reported as such.
//
//   extension                parameters freed                        added q  on boundary m
//   friction                 friction_coefficient (mu >= 0, null 0)        1        1
//   heterogeneous_stiffness  stiffness_field: E ratio of two halves        1        0
//                            along the axis the screening picks (null 1)
//   air_drag                 drag_quadratic (>= 0, null 0)                 1        1
//   contact (nuisance)       contact_stiffness (null 100 E / L),           2        1
//                            contact_damping (>= 0, null 0)
//   initial_spin (nuisance)  initial_angular_velocity (null 0)             3        0
//
// The contact law is the floor's, not the object's: fitted as a nuisance, it is measured where
// the residual concentrates in contact, and never named as the physics the object left out.
// Camera pose and time offset are nuisances the fit cannot model; noise_floor.h flags their
// signature (a frame 0 worse than the moving frames).
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/diagnosis/motion_phases.h"
#include "core/fem/physical_parameters.h"

namespace softid::diagnosis {

enum class Extension { kFriction, kHeterogeneousStiffness, kAirDrag, kContact, kInitialSpin };
// "friction" | "heterogeneous_stiffness" | "air_drag" | "contact" | "initial_spin".
const char* ToString(Extension extension);
Result<Extension> ParseExtension(const std::string& name, const std::string& field);

struct Candidate {
  Extension extension = Extension::kFriction;
  bool nuisance = false;                // never reported as physics
  std::vector<std::string> parameters;  // fittable names freed on top of the base fit
  int num_added = 1;                    // q, degrees of freedom of the likelihood-ratio test
  int num_boundary = 0;                 // m of them on the boundary of their range at the null
  // Number of variants the screening chooses among (the stiffness split axis: 3); the test's
  // level is divided by it (Bonferroni), because the choice is made on the same data.
  int num_variants = 1;
  bool needs_ground = false;  // only where there is contact
  // Where its residual shows (signature table of the diagnosis notes); `after_contact` widens it
  // to every frame from the first contact on (a stiffness contrast shows in and after the bounce).
  std::vector<Phase> phases;
  bool after_contact = false;
  bool all_frames = false;  // grows from frame 0 (spin)
  // Its values take up the compared time step's error where the motion is stiffest (a contact
  // law at an impact), so they describe that step only: alone, it joins the final model only when
  // the models were compared at the job's own discretisation.
  bool absorbs_step_error = false;
  std::string description;
};

// Every candidate, physics first.
const std::vector<Candidate>& CandidateLibrary();
const Candidate& GetCandidate(Extension extension);

// The two halves of a body along one axis for the heterogeneous_stiffness candidate: the region
// at lower coordinates (world frame, rest pose) gets the ratio r = E_lower / E_upper; E becomes
// the upper half's modulus.
fem::StiffnessField HalvesField(const Eigen::AlignedBox3d& rest_bounds, int axis, double ratio);

// `to` with the extension's parameters taken from `from` (friction_coefficient, drag_quadratic,
// stiffness_field, contact_stiffness and contact_damping, or initial_angular_velocity): a joint
// refit of a physics candidate with a nuisance starts from one refit with the other's values.
fem::PhysicalParameters CopyExtension(Extension extension, const fem::PhysicalParameters& from,
                                      fem::PhysicalParameters to);

// `to` (a model without the extension) with the extension present at its null, in the form
// `refit` gives it: a stiffness split becomes ratio 1 along the refit's axis, so that a fit can
// free it from there; any other extension's null is a value `to` already has.
fem::PhysicalParameters WithExtensionAtNull(Extension extension,
                                            const fem::PhysicalParameters& refit,
                                            fem::PhysicalParameters to,
                                            const Eigen::AlignedBox3d& rest_bounds);

// The start of the null model refitted from an extension's refit: `refit` with the extension
// back at its null (taken from `null`). A stiffness split keeps its stiffness: E becomes the
// volume-weighted geometric mean E_upper r^f (f = the share of `rest_bounds` inside the scaled
// region), since E_upper alone is the stiffness of one half only.
fem::PhysicalParameters NullModelStart(Extension extension, const fem::PhysicalParameters& null,
                                       const fem::PhysicalParameters& refit,
                                       const Eigen::AlignedBox3d& rest_bounds);

// Whether the fitted value of the extension is physically plausible; `why` says which bound.
//   friction: mu in [0.01, 1.5]; air_drag: [0.01, 5] kg/m^3 (rho_air C_d / 2 of bluff bodies is
//   ~0.6); heterogeneous_stiffness: ratio outside [0.8, 1.25] and inside [1/50, 50];
//   contact: stiffness within [0.01, 100] x the default 100 E / L, damping <= 0.1 s;
//   initial_spin: |omega| <= 50 rad/s.
bool IsPlausible(Extension extension, const fem::PhysicalParameters& fitted,
                 double default_contact_stiffness, std::string* why);

// The extension's fitted values in report form, e.g. {"friction_coefficient": 0.31} or
// {"stiffness_ratio": 2.1, "axis": "x", "youngs_modulus_lower": .., "youngs_modulus_upper": ..}.
nlohmann::json ExtensionValues(Extension extension, const fem::PhysicalParameters& fitted,
                               double default_contact_stiffness);

}  // namespace softid::diagnosis
