// Synthetic depth-sensor noise: depth-dependent Gaussian noise and pixel dropout.
#pragma once

#include <cstdint>

#include "core/capture/depth_image.h"
#include "core/common/status.h"

namespace softid::capture {

struct DepthNoiseOptions {
  // a [m]: depth-independent part of the noise standard deviation sigma = a + b z^2. Default 0.
  double sigma_constant = 0.0;
  // b [1/m]: quadratic part of sigma = a + b z^2 (structured-light and ToF sensors grow roughly
  // with z^2). Default 0.
  double sigma_quadratic = 0.0;
  // Probability in [0, 1) that each valid pixel independently loses its data (becomes 0).
  // Default 0.
  double dropout_probability = 0.0;
  // Seed of the noise; with the frame and camera index it fully determines the noise. Default 0.
  uint64_t seed = 0;

  // InvalidArgument naming the field and value unless sigma_constant and sigma_quadratic are
  // finite and >= 0 and dropout_probability is in [0, 1).
  Status Validate() const;
};

// A structured-light depth sensor, the "realistic noise" of softid's benchmarks and proofs:
// sigma = 1.5 mm + 2.5 mm (z / 1 m)^2, 1 % dropout; captured with kStructuredLightDepthScale
// (1 mm quantisation).
DepthNoiseOptions StructuredLightNoise(uint64_t seed = 0);
inline constexpr double kStructuredLightDepthScale = 1e-3;  // [m per PNG unit]

// Adds noise to every valid pixel (depth z > 0) of `image` in place: with probability
// dropout_probability the pixel becomes 0 (no data), otherwise z becomes z + sigma(z) n with
// n ~ N(0, 1) and sigma(z) = a + b z^2 evaluated at the noise-free z; a result <= 0 becomes 0.
// Pixels without data stay 0. The noise is a deterministic function of (options.seed,
// frame_index, camera_index) and the image (std::mt19937_64 seeded from a hash of the three;
// identical across runs of the same build, not guaranteed across standard libraries).
// Quantisation to the PNG's depth_scale happens in WriteDepthPng. Throws std::invalid_argument
// when the options are invalid or image is null.
void ApplyDepthNoise(const DepthNoiseOptions& options, int frame_index, int camera_index,
                     DepthImage* image);

}  // namespace softid::capture
