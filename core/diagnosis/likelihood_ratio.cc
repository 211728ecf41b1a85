#include "core/diagnosis/likelihood_ratio.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>

namespace softid::diagnosis {
namespace {

// Regularised upper incomplete gamma Q(a, x) = Gamma(a, x) / Gamma(a): a series for x < a + 1,
// Lentz's continued fraction otherwise (both converge fast there).
double UpperIncompleteGamma(double a, double x) {
  if (x <= 0.0) return 1.0;
  const double log_prefactor = -x + a * std::log(x) - std::lgamma(a);
  if (x < a + 1.0) {
    double term = 1.0 / a, sum = term;
    for (int n = 1; n < 1000; ++n) {
      term *= x / (a + n);
      sum += term;
      if (std::abs(term) < std::abs(sum) * 1e-16) break;
    }
    return std::max(0.0, 1.0 - sum * std::exp(log_prefactor));
  }
  constexpr double kTiny = 1e-300;
  double b = x + 1.0 - a, c = 1.0 / kTiny, d = 1.0 / b, h = d;
  for (int i = 1; i < 1000; ++i) {
    const double an = -i * (i - a);
    b += 2.0;
    d = an * d + b;
    if (std::abs(d) < kTiny) d = kTiny;
    c = b + an / c;
    if (std::abs(c) < kTiny) c = kTiny;
    d = 1.0 / d;
    const double delta = d * c;
    h *= delta;
    if (std::abs(delta - 1.0) < 1e-16) break;
  }
  return std::exp(log_prefactor) * h;
}

double Binomial(int n, int k) {
  return std::exp(std::lgamma(n + 1.0) - std::lgamma(k + 1.0) - std::lgamma(n - k + 1.0));
}

}  // namespace

double ChiSquareSurvival(int k, double x) {
  if (k <= 0) return x < 0.0 ? 1.0 : 0.0;
  if (x <= 0.0) return 1.0;
  return UpperIncompleteGamma(0.5 * k, 0.5 * x);
}

double ChiBarSquareSurvival(int num_parameters, int num_boundary, double x) {
  const int q = num_parameters, m = num_boundary;
  double p = 0.0;
  for (int j = 0; j <= m; ++j)
    p += Binomial(m, j) * std::ldexp(1.0, -m) * ChiSquareSurvival(q - m + j, x);
  return p;
}

double ChiBarSquareCriticalValue(int num_parameters, int num_boundary, double alpha) {
  if (num_parameters < 1) {
    throw std::invalid_argument("num_parameters = " + std::to_string(num_parameters) +
                                ": must be >= 1");
  }
  if (num_boundary < 0 || num_boundary > num_parameters) {
    throw std::invalid_argument("num_boundary = " + std::to_string(num_boundary) +
                                ": must lie in [0, num_parameters]");
  }
  if (!(alpha > 0.0 && alpha < 1.0)) {
    throw std::invalid_argument("alpha = " + std::to_string(alpha) + ": must lie in (0, 1)");
  }
  // The survival function falls monotonically from its value at 0+ (<= 1): bisection.
  double lo = 0.0, hi = 1.0;
  while (ChiBarSquareSurvival(num_parameters, num_boundary, hi) > alpha) hi *= 2.0;
  for (int i = 0; i < 200 && hi - lo > 1e-12 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    (ChiBarSquareSurvival(num_parameters, num_boundary, mid) > alpha ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

double IntegratedAutocorrelationTime(std::span<const double> series) {
  const size_t n = series.size();
  if (n < 4) return 1.0;
  const double mean = std::accumulate(series.begin(), series.end(), 0.0) / n;
  double c0 = 0.0;
  for (double v : series) c0 += (v - mean) * (v - mean);
  c0 /= n;
  if (!(c0 > 0.0)) return 1.0;
  double tau = 1.0;
  for (size_t lag = 1; lag < n / 2; ++lag) {
    double c = 0.0;
    for (size_t i = 0; i + lag < n; ++i) c += (series[i] - mean) * (series[i + lag] - mean);
    tau += 2.0 * (c / n) / c0;
    if (static_cast<double>(lag) >= 5.0 * tau) break;  // Sokal's window
  }
  return std::max(1.0, tau);
}

EffectiveSampleSize ComputeEffectiveSampleSize(const std::vector<std::vector<double>>& residuals) {
  EffectiveSampleSize out;
  double weighted_tau = 0.0;
  std::vector<double> frame_means;
  for (const std::vector<double>& frame : residuals) {
    if (frame.empty()) continue;
    out.n += frame.size();
    weighted_tau += IntegratedAutocorrelationTime(frame) * frame.size();
    frame_means.push_back(std::accumulate(frame.begin(), frame.end(), 0.0) / frame.size());
  }
  if (out.n == 0.0) return out;
  out.tau_pixels = weighted_tau / out.n;
  out.tau_frames = IntegratedAutocorrelationTime(frame_means);
  out.n_eff = out.n / (out.tau_pixels * out.tau_frames);
  return out;
}

double LikelihoodRatioStatistic(double cost_before, double cost_after, double n_eff) {
  if (!(cost_after < cost_before) || !(cost_after > 0.0)) return 0.0;
  return n_eff * std::log(cost_before / cost_after);
}

}  // namespace softid::diagnosis
