// The likelihood-ratio test of a nested model extension on depth residuals.
//
// The depth cost is a mean of (robust) squared residuals, so under a Gaussian residual model with
// unknown variance the profile log-likelihood is -(n / 2) log C. Adding q parameters lowers C0 to
// C1 and the statistic is
//   LR = n_eff log(C0 / C1),
// with n_eff = n / tau the effective number of independent residuals: depth residuals of
// neighbouring pixels and neighbouring frames are correlated (a smooth misfit, the discretisation
// error), and counting them as independent would make every extension "significant".
// tau = tau_pixels tau_frames, each an integrated autocorrelation time (Sokal's windowed
// estimator) of the signed residuals in acquisition order (pixels of a frame) and of the per-frame
// mean residual (frames).
//
// Under the null (Wilks) LR ~ chi2_q. When m of the q parameters sit on the boundary of their
// range at the null (mu = 0, a drag of 0), the null distribution is the chi-bar-square mixture
//   sum_j C(m, j) 2^-m chi2_{q - m + j}    (chi2_0 = a point mass at 0)
// (Self & Liang 1987); for q = m = 1 it is the 50:50 mixture of chi2_0 and chi2_1 with critical
// values 2.71 at 5 % and 5.41 at 1 %.
#pragma once

#include <span>
#include <vector>

namespace softid::diagnosis {

// P(chi2_k > x) for k >= 0 degrees of freedom (k = 0: the point mass at 0, so 0 for x >= 0).
double ChiSquareSurvival(int k, double x);

// P(T > x) under the chi-bar-square mixture of `num_parameters` added parameters of which
// `num_boundary` lie on a boundary at the null (0 <= num_boundary <= num_parameters).
double ChiBarSquareSurvival(int num_parameters, int num_boundary, double x);

// The critical value c with ChiBarSquareSurvival(q, m, c) = alpha, alpha in (0, 1).
// @throws std::invalid_argument for q < 1, m outside [0, q] or alpha outside (0, 1).
double ChiBarSquareCriticalValue(int num_parameters, int num_boundary, double alpha);

// Integrated autocorrelation time tau = 1 + 2 sum_{k=1}^{W} rho_k of a series, with Sokal's
// automatic window (the smallest W >= 5 tau(W)); >= 1. Series shorter than 4 give 1.
double IntegratedAutocorrelationTime(std::span<const double> series);

// The effective sample size n / (tau_pixels tau_frames) of residuals given per frame in
// acquisition order; tau_pixels is averaged over frames (weighted by their size).
struct EffectiveSampleSize {
  double n = 0.0;           // residuals
  double tau_pixels = 1.0;  // >= 1
  double tau_frames = 1.0;  // >= 1
  double n_eff = 0.0;       // n / (tau_pixels tau_frames)
};
EffectiveSampleSize ComputeEffectiveSampleSize(const std::vector<std::vector<double>>& residuals);

// LR = n_eff log(cost_before / cost_after), 0 when cost_after >= cost_before.
// @pre costs > 0.
double LikelihoodRatioStatistic(double cost_before, double cost_after, double n_eff);

}  // namespace softid::diagnosis
