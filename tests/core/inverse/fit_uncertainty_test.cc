// Every result's uncertainty: propagated to each fitted parameter in its public form, consistent
// with the analysis in the optimiser's variables, and written into result.json beside the value.
#include "core/inverse/fit_uncertainty.h"

#include <gtest/gtest.h>

#include <cmath>

#include "tests/core/inverse/inverse_test_util.h"

namespace softid::inverse {
namespace {

using testing::MakeSmallCapture;
using testing::SmallCapture;

// A fit "ended" at the truth of a short free fall of the torus, for the analysis to look at.
FitResult FitAtTruth(const SmallCapture& capture, const std::vector<std::string>& fitted) {
  FitResult fit;
  fit.fitted = fitted;
  fit.base = capture.truth;
  fit.starts.resize(1);
  fit.starts[0].initial = capture.truth;
  fit.starts[0].final = capture.truth;
  fit.best = 0;
  fit.substeps = 2;
  return fit;
}

JobConfig SmallConfig(const std::vector<std::string>& fitted) {
  JobConfig config;
  config.solver.cells = 8;
  config.solver.substeps = 2;
  config.solver.threads = 2;
  config.fit = fitted;
  return config;
}

// The first 0.1 s of torus-drop (free fall), analysed at the truth.
class FitUncertaintyTest : public ::testing::Test {
 protected:
  void SetUp() override { ASSERT_TRUE(capture.ok) << capture.error; }
  Result<FitUncertainty> Analyse(const std::vector<std::string>& fitted, FitResult* fit) {
    *fit = FitAtTruth(capture, fitted);
    return EstimateFitUncertainty(capture.capture, SmallConfig(fitted), *fit);
  }
  const SmallCapture capture = MakeSmallCapture("torus-drop", /*duration=*/0.1);
};

// Gravity (identity transform) keeps the analysis' own sigma; the log-transformed density's sigma
// is its value times the variable's; result.json carries both in the value's shape.
TEST_F(FitUncertaintyTest, PropagatesTheAnalysisToEachPublicValue) {
  FitResult fit;
  Result<FitUncertainty> uncertainty = Analyse({"gravity", "density"}, &fit);
  ASSERT_TRUE(uncertainty.ok()) << uncertainty.status().ToString();
  ASSERT_EQ(uncertainty->parameters.size(), 2u);
  EXPECT_GE(uncertainty->report.residual_sigma, DepthQuantisationSigma(capture.capture));
  EXPECT_GT(DepthQuantisationSigma(capture.capture), 0.0);

  const ParameterUncertainty& gravity = uncertainty->parameters[0];
  ASSERT_EQ(gravity.standard_uncertainty.size(), 3u);
  const VariableIdentifiability* gz = uncertainty->report.Find("gravity[2]");
  ASSERT_NE(gz, nullptr);
  EXPECT_NEAR(gravity.standard_uncertainty[2], gz->standard_uncertainty,
              1e-6 * gz->standard_uncertainty);
  EXPECT_GT(gravity.standard_uncertainty[2], 0.0);
  EXPECT_LT(gravity.standard_uncertainty[2], 0.05 * 9.81);

  const ParameterUncertainty& density = uncertainty->parameters[1];
  ASSERT_EQ(density.standard_uncertainty.size(), 1u);
  const VariableIdentifiability* rho = uncertainty->report.Find("density");
  ASSERT_NE(rho, nullptr);
  if (std::isfinite(rho->variable_uncertainty)) {
    EXPECT_NEAR(density.standard_uncertainty[0], capture.truth.density * rho->variable_uncertainty,
                1e-4 * density.standard_uncertainty[0]);
  }

  const nlohmann::json json = ToJson(fit, &*uncertainty);
  const nlohmann::json& g = json["parameters"]["gravity"];
  ASSERT_TRUE(g["standard_uncertainty"].is_array());
  EXPECT_EQ(g["standard_uncertainty"].size(), g["value"].size());
  EXPECT_DOUBLE_EQ(g["standard_uncertainty"][2].get<double>(), gravity.standard_uncertainty[2]);
  EXPECT_TRUE(json["parameters"]["density"].contains("relative_uncertainty"));
  EXPECT_TRUE(json["uncertainty"].contains("variables"));
  EXPECT_TRUE(json["uncertainty"].contains("degenerate_combinations"));
}

// A value the data do not determine (stiffness in free fall: no deformation) is reported as
// undetermined (null), never as a small number.
TEST_F(FitUncertaintyTest, UndeterminedValuesAreNull) {
  FitResult fit;
  Result<FitUncertainty> uncertainty = Analyse({"youngs_modulus", "gravity"}, &fit);
  ASSERT_TRUE(uncertainty.ok()) << uncertainty.status().ToString();
  const nlohmann::json json = ToJson(fit, &*uncertainty);
  const nlohmann::json& youngs = json["parameters"]["youngs_modulus"];
  const bool undetermined = youngs["standard_uncertainty"].is_null() ||
                            youngs["relative_uncertainty"].get<double>() > 0.1;
  EXPECT_TRUE(undetermined) << youngs.dump();
}

// Without an analysis the result still says why (and has no uncertainty fields).
TEST(FitUncertainty, AFailedAnalysisIsReportedNotFatal) {
  FitResult fit;
  fit.fitted = {"youngs_modulus"};
  fit.starts.resize(1);
  fit.best = 0;
  const nlohmann::json json = ToJson(fit, nullptr, "the simulation diverged");
  EXPECT_EQ(json["uncertainty"]["error"], "the simulation diverged");
  EXPECT_FALSE(json["parameters"]["youngs_modulus"].contains("standard_uncertainty"));
}

}  // namespace
}  // namespace softid::inverse
