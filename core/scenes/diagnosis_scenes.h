// Concealed-effect scenes for proving the diagnosis of left-out physics: each scene
// carries one piece of physics the base model lacks (friction on a ramp, two halves of different
// stiffness, air drag on a light throw) or a nuisance (an initial spin), at a strength the caller
// chooses; strength 0 is the control. The scenes are small on purpose (a fit runs ~10 cells along
// the longest side), but nothing in them is tuned to the diagnosis: the physics is textbook and
// the values are those of real foam objects.
//
// How the proof uses them (core/lab/prove_diagnosis_command.cc): synthesise with a finer grid and
// a smaller time step than the fit, with realistic depth noise, then diagnose with the effect off.
#pragma once

#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/scenes/camera_rig.h"
#include "core/scenes/scene.h"

namespace softid::scenes {

// What a concealed-effect scene hides from the base model.
enum class ConcealedEffect {
  kNone,                    // control: the base model is the truth
  kFriction,                // Coulomb friction coefficient mu [-]
  kHeterogeneousStiffness,  // E ratio between the two halves along the longest axis [-]
  kAirDrag,                 // quadratic air drag rho_air C_d / 2 [kg/m^3]
  kInitialSpin,             // initial angular velocity about the centre of mass [rad/s] (nuisance)
};
// "none" | "friction" | "heterogeneous_stiffness" | "air_drag" | "initial_spin".
const char* ToString(ConcealedEffect effect);
// InvalidArgument naming `field` and the value for an unknown name.
Result<ConcealedEffect> ParseConcealedEffect(const std::string& name, const std::string& field);

// A scene plus the cameras that see its whole motion.
struct ConcealedScene {
  Scene scene;
  ConcealedEffect effect = ConcealedEffect::kNone;
  double strength = 0.0;  // the hidden value, in the unit of `effect` (0 for a control)
  CameraRigOptions cameras;
};

// Names of the concealed-effect scenes: ramp-block, halves-drop, light-throw.
std::vector<std::string> DiagnosisSceneNames();

// The effect each scene can carry: ramp-block -> friction, halves-drop -> heterogeneous stiffness,
// light-throw (a foam cube) -> air drag or initial spin.
//
// @param name one of DiagnosisSceneNames().
// @param effect kNone for the control, or an effect the scene carries.
// @param strength the effect's value: mu in [0, 2], a stiffness ratio in (0, 100] (the half at
//   lower coordinates along the longest axis is that much stiffer), a drag in [0, 10] kg/m^3, a
//   spin rate in [0, 50] rad/s (about the scene's horizontal axis across the throw).
// @param variation in (-0.5, 0.5): a relative change of Young's modulus (E x (1 + variation))
//   so that controls over many seeds are not one motion with different noise.
// InvalidArgument naming the field and value for an unknown scene, an effect the scene does not
// carry or a strength out of range.
Result<ConcealedScene> MakeDiagnosisScene(const std::string& name, ConcealedEffect effect,
                                          double strength, double variation = 0.0);

}  // namespace softid::scenes
