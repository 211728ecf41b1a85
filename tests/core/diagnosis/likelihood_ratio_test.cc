#include "core/diagnosis/likelihood_ratio.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <stdexcept>

namespace softid::diagnosis {
namespace {

// Textbook chi-square quantiles: 3.841 (1 dof, 5 %), 6.635 (1 dof, 1 %), 5.991 (2 dof, 5 %).
TEST(ChiBarSquare, PlainChiSquareCriticalValues) {
  EXPECT_NEAR(ChiBarSquareCriticalValue(/*num_parameters=*/1, /*num_boundary=*/0, 0.05), 3.841,
              1e-3);
  EXPECT_NEAR(ChiBarSquareCriticalValue(1, 0, 0.01), 6.635, 1e-3);
  EXPECT_NEAR(ChiBarSquareCriticalValue(2, 0, 0.05), 5.991, 1e-3);
  EXPECT_NEAR(ChiSquareSurvival(3, 7.815), 0.05, 1e-4);
  EXPECT_NEAR(ChiSquareSurvival(30, 43.773), 0.05, 1e-4);  // continued-fraction branch
}

// A boundary parameter (mu = 0): the 50:50 mixture of chi2_0 and chi2_1 has critical values 2.71
// at 5 % and 5.41 at 1 % (diagnosis notes).
TEST(ChiBarSquare, BoundaryMixtureCriticalValues) {
  EXPECT_NEAR(ChiBarSquareCriticalValue(1, 1, 0.05), 2.706, 1e-3);
  EXPECT_NEAR(ChiBarSquareCriticalValue(1, 1, 0.01), 5.412, 1e-3);
  // chi2_0 is a point mass at 0: half the probability sits there.
  EXPECT_NEAR(ChiBarSquareSurvival(1, 1, 1e-12), 0.5, 1e-6);
  // One of two on the boundary: 0.5 chi2_1 + 0.5 chi2_2.
  const double c = ChiBarSquareCriticalValue(2, 1, 0.05);
  EXPECT_NEAR(0.5 * ChiSquareSurvival(1, c) + 0.5 * ChiSquareSurvival(2, c), 0.05, 1e-9);
}

TEST(ChiBarSquare, RejectsBadArguments) {
  try {
    ChiBarSquareCriticalValue(1, 2, 0.05);
    FAIL() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("num_boundary = 2"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ChiBarSquareCriticalValue(0, 0, 0.05), std::invalid_argument);
  EXPECT_THROW(ChiBarSquareCriticalValue(1, 0, 1.0), std::invalid_argument);
}

// White noise has tau ~ 1; an AR(1) series x_t = a x_{t-1} + e_t has tau = (1 + a) / (1 - a).
TEST(EffectiveSampleSize, AutocorrelationTimeOfKnownProcesses) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> normal;
  std::vector<double> white(20000), ar(20000);
  double x = 0.0;
  for (size_t i = 0; i < white.size(); ++i) {
    white[i] = normal(rng);
    x = 0.8 * x + normal(rng);
    ar[i] = x;
  }
  EXPECT_NEAR(IntegratedAutocorrelationTime(white), 1.0, 0.1);
  EXPECT_NEAR(IntegratedAutocorrelationTime(ar), 9.0, 1.5);
  // Frames of correlated pixels: n_eff is n / tau_pixels (frames independent here).
  std::vector<std::vector<double>> frames(20, std::vector<double>(1000));
  for (auto& frame : frames) {
    for (double& v : frame) {
      x = 0.8 * x + normal(rng);
      v = x;
    }
  }
  const EffectiveSampleSize ess = ComputeEffectiveSampleSize(frames);
  EXPECT_EQ(ess.n, 20000.0);
  EXPECT_NEAR(ess.tau_pixels, 9.0, 2.0);
  EXPECT_NEAR(ess.n_eff, ess.n / (ess.tau_pixels * ess.tau_frames), 1e-9);
  EXPECT_LT(ess.n_eff, 3000.0);
}

// LR = n_eff log(C0 / C1); a cost that did not fall gives 0.
TEST(LikelihoodRatio, StatisticFromCosts) {
  EXPECT_NEAR(LikelihoodRatioStatistic(2.0, 1.0, 100.0), 100.0 * std::log(2.0), 1e-12);
  EXPECT_EQ(LikelihoodRatioStatistic(1.0, 1.5, 100.0), 0.0);
}

}  // namespace
}  // namespace softid::diagnosis
