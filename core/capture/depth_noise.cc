#include "core/capture/depth_noise.h"

#include <fmt/format.h>

#include <cmath>
#include <random>

#include "core/common/check.h"

namespace softid::capture {

Status DepthNoiseOptions::Validate() const {
  if (!(std::isfinite(sigma_constant) && sigma_constant >= 0.0)) {
    return Status::InvalidArgument(fmt::format(
        "DepthNoiseOptions.sigma_constant = {}: must be finite and >= 0", sigma_constant));
  }
  if (!(std::isfinite(sigma_quadratic) && sigma_quadratic >= 0.0)) {
    return Status::InvalidArgument(fmt::format(
        "DepthNoiseOptions.sigma_quadratic = {}: must be finite and >= 0", sigma_quadratic));
  }
  if (!(dropout_probability >= 0.0 && dropout_probability < 1.0)) {
    return Status::InvalidArgument(fmt::format(
        "DepthNoiseOptions.dropout_probability = {}: must be in [0, 1)", dropout_probability));
  }
  return Status::Ok();
}

namespace {

// SplitMix64 finaliser: a bijective mixer with good avalanche.
uint64_t Mix64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

uint64_t NoiseSeed(uint64_t seed, int frame_index, int camera_index) {
  uint64_t h = Mix64(seed);
  h = Mix64(h ^ static_cast<uint64_t>(static_cast<uint32_t>(frame_index)));
  h = Mix64(h ^ (static_cast<uint64_t>(static_cast<uint32_t>(camera_index)) << 32));
  return h;
}

}  // namespace

void ApplyDepthNoise(const DepthNoiseOptions& options, int frame_index, int camera_index,
                     DepthImage* image) {
  SOFTID_THROW_UNLESS(image != nullptr, "ApplyDepthNoise: image is null");
  const Status valid = options.Validate();
  SOFTID_THROW_UNLESS(valid.ok(), valid.message());
  std::mt19937_64 rng(NoiseSeed(options.seed, frame_index, camera_index));
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  std::normal_distribution<double> normal(0.0, 1.0);
  const bool dropout = options.dropout_probability > 0.0;
  for (float& depth : image->depth) {
    if (!(depth > 0.0f)) continue;
    if (dropout && uniform(rng) < options.dropout_probability) {
      depth = 0.0f;
      continue;
    }
    const double z = depth;
    const double sigma = options.sigma_constant + options.sigma_quadratic * z * z;
    const double noisy = z + sigma * normal(rng);
    depth = noisy > 0.0 ? static_cast<float>(noisy) : 0.0f;
  }
}

DepthNoiseOptions StructuredLightNoise(uint64_t seed) {
  DepthNoiseOptions noise;
  noise.sigma_constant = 1.5e-3;
  noise.sigma_quadratic = 2.5e-3;
  noise.dropout_probability = 0.01;
  noise.seed = seed;
  return noise;
}

}  // namespace softid::capture
