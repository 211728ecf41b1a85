// "refine_grid": the decision from each fitted value's grid error against its statistical sigma
// and magnitude, and the refit on the finer grid against a fit made there from the start.
#include "core/inverse/grid_refinement.h"

#include <gtest/gtest.h>

#include <cmath>

#include "tests/core/inverse/inverse_test_util.h"

namespace softid::inverse {
namespace {

// A fit of Young's modulus at `modulus` on 16 cells whose analysis gives `sigma` and a grid
// error `grid_error` against 24 cells.
struct AnalysedFit {
  FitResult fit;
  FitUncertainty uncertainty;
};

AnalysedFit ModulusFit(double modulus, double sigma, double grid_error) {
  AnalysedFit out;
  out.fit.fitted = {"youngs_modulus"};
  out.fit.starts.resize(1);
  out.fit.starts[0].final.youngs_modulus = modulus;
  out.fit.best = 0;
  out.fit.cells = 16;
  out.fit.substeps = 8;
  out.uncertainty.parameters = {ParameterUncertainty{"youngs_modulus", {sigma}}};
  DiscretisationError errors;
  errors.grid.chosen = 16;
  errors.grid.compared = 24;
  errors.grid.ratio = 1.5;
  ParameterDiscretisationError e;
  e.name = "youngs_modulus";
  e.grid = {grid_error};
  errors.parameters = {e};
  out.uncertainty.discretisation = errors;
  return out;
}

TEST(GridRefinementDecision, RefinesWhenTheGridErrorExceedsTwoSigmaAndOnePercent) {
  // 10 kPa, sigma 100 Pa: the threshold is max(200, 100) = 200 Pa.
  AnalysedFit a = ModulusFit(1e4, 100.0, 250.0);
  GridRefinementDecision d = DecideGridRefinement(a.fit, a.uncertainty, 5000);
  EXPECT_TRUE(d.refine) << d.reason;
  EXPECT_EQ(d.parameter, "youngs_modulus");
  EXPECT_EQ(d.cells, 16);
  EXPECT_EQ(d.finer_cells, 24);
  EXPECT_DOUBLE_EQ(d.grid_error, 250.0);
  EXPECT_DOUBLE_EQ(d.threshold, 200.0);
  EXPECT_NE(d.reason.find("refit on 24 cells"), std::string::npos) << d.reason;

  // Within two sigmas: the data cannot tell the grids apart.
  AnalysedFit b = ModulusFit(1e4, 100.0, 150.0);
  d = DecideGridRefinement(b.fit, b.uncertainty, 5000);
  EXPECT_FALSE(d.refine) << d.reason;
  EXPECT_TRUE(d.parameter.empty());

  // A precise value: the 1 % floor decides (threshold 100 Pa).
  AnalysedFit c = ModulusFit(1e4, 1.0, 90.0);
  EXPECT_FALSE(DecideGridRefinement(c.fit, c.uncertainty, 5000).refine);
  AnalysedFit e = ModulusFit(1e4, 1.0, 110.0);
  EXPECT_TRUE(DecideGridRefinement(e.fit, e.uncertainty, 5000).refine);
}

TEST(GridRefinementDecision, KeepsTheGridWhenTheFinerOneIsUnaffordableOrUnjudged) {
  AnalysedFit a = ModulusFit(1e4, 100.0, 1000.0);
  GridRefinementOptions options;
  options.max_grid_nodes = 4000;
  GridRefinementDecision d = DecideGridRefinement(a.fit, a.uncertainty, 4001, options);
  EXPECT_FALSE(d.refine);
  EXPECT_EQ(d.parameter, "youngs_modulus");  // it asked, the budget said no
  EXPECT_NE(d.reason.find("above the budget of 4000"), std::string::npos) << d.reason;

  // An undetermined value (sigma +inf) or a missing estimate says nothing of the grid.
  AnalysedFit b = ModulusFit(1e4, std::numeric_limits<double>::infinity(), 1000.0);
  EXPECT_FALSE(DecideGridRefinement(b.fit, b.uncertainty, 5000).refine);
  AnalysedFit c = ModulusFit(1e4, 100.0, std::nan(""));
  EXPECT_FALSE(DecideGridRefinement(c.fit, c.uncertainty, 5000).refine);
  AnalysedFit e = ModulusFit(1e4, 100.0, 1000.0);
  e.uncertainty.discretisation.reset();
  d = DecideGridRefinement(e.fit, e.uncertainty, 5000);
  EXPECT_FALSE(d.refine);
  EXPECT_NE(d.reason.find("no discretisation estimate"), std::string::npos) << d.reason;
  e.uncertainty.discretisation = ModulusFit(1e4, 100.0, 1000.0).uncertainty.discretisation;
  e.uncertainty.discretisation->grid.error = "the finer run diverged";
  EXPECT_FALSE(DecideGridRefinement(e.fit, e.uncertainty, 5000).refine);
}

TEST(GridRefinementConfig, RefitsOneStartFromTheValuesAtTheFitsTimeStepAndFrames) {
  AnalysedFit a = ModulusFit(12345.0, 100.0, 1000.0);
  a.fit.predictable_last_frame = 17;
  JobConfig config;  // "auto" cells and substeps, 4 starts, every frame
  config.initial["youngs_modulus"] = InitialValue{.value = {}, .range = ScalarRange{1e3, 1e6}};
  const GridRefinementDecision d = DecideGridRefinement(a.fit, a.uncertainty, -1);
  ASSERT_TRUE(d.refine) << d.reason;
  const JobConfig refit = RefinementConfig(config, a.fit, d);
  EXPECT_EQ(refit.solver.cells, 24);
  EXPECT_EQ(refit.solver.substeps, 8);
  EXPECT_EQ(refit.frames.last, 17);
  EXPECT_EQ(refit.solver.starts, 1);
  ASSERT_TRUE(refit.initial.at("youngs_modulus").value.has_value());
  EXPECT_DOUBLE_EQ(refit.initial.at("youngs_modulus").value->get<double>(), 12345.0);
  EXPECT_TRUE(refit.Validate().ok()) << refit.Validate().ToString();

  // A cell size is divided by the ratio.
  config.solver.cell_size_m = 0.006;
  EXPECT_NEAR(RefinementConfig(config, a.fit, d).solver.cell_size_m, 0.004, 1e-15);
}

// Young's modulus of a ball bouncing once (captured on 14 cells), the rest of the truth fixed.
JobConfig BounceConfig(const fem::PhysicalParameters& truth, int cells) {
  JobConfig config = testing::ModulusAtDiscretisation(truth, cells, /*substeps=*/2);
  config.refine_grid = true;
  return config;
}

// On 6 cells the grid moves E by more than its sigma: the control refits on 9 cells, and lands
// where a fit on 9 cells from the start does; the first fit is kept beside it.
TEST(GridRefinement, RefitsOnTheFinerGridWhereTheGridMovesTheValue) {
  const testing::SmallCapture capture = testing::MakeSmallCapture("ball-bounce", 0.4, 2, 14);
  ASSERT_TRUE(capture.ok) << capture.error;
  const JobConfig config = BounceConfig(capture.truth, 6);
  Result<FitResult> fit = Fit(capture.capture, config);
  ASSERT_TRUE(fit.ok()) << fit.status().ToString();
  Result<FitUncertainty> analysis = EstimateFitUncertainty(capture.capture, config, *fit);
  ASSERT_TRUE(analysis.ok()) << analysis.status().ToString();
  const double coarse = fit->Best().final.youngs_modulus;

  // The floor off: the grid error of this noise-free capture against its sigma alone.
  GridRefinementOptions options;
  options.relative_floor = 0.0;
  const ControlledFit controlled =
      ControlGrid(capture.capture, config, *fit, *analysis, FitOptions{}, options);
  ASSERT_TRUE(controlled.refinement.refined) << controlled.refinement.decision.reason;
  EXPECT_EQ(controlled.fit.cells, 9);
  EXPECT_EQ(controlled.config.solver.cells, 9);
  EXPECT_GT(controlled.refinement.decision.finer_grid_nodes, 0);
  ASSERT_TRUE(controlled.uncertainty.has_value()) << controlled.uncertainty_error;
  ASSERT_TRUE(controlled.uncertainty->discretisation.has_value());
  EXPECT_EQ(controlled.uncertainty->discretisation->grid.chosen, 9);

  const Result<FitResult> direct = Fit(capture.capture, BounceConfig(capture.truth, 9));
  ASSERT_TRUE(direct.ok()) << direct.status().ToString();
  const double refined = controlled.fit.Best().final.youngs_modulus;
  const double fine = direct->Best().final.youngs_modulus;
  std::printf("E: 6 cells %.1f, refined on 9 %.1f, fitted on 9 %.1f, truth %.1f Pa\n", coarse,
              refined, fine, capture.truth.youngs_modulus);
  ASSERT_GT(std::abs(std::log(fine / coarse)), 2e-3);  // the grid does move the value
  EXPECT_LT(std::abs(std::log(refined / fine)), 0.1 * std::abs(std::log(fine / coarse)));

  const nlohmann::json json = ToJson(controlled.refinement);
  EXPECT_TRUE(json["refined"].get<bool>());
  EXPECT_EQ(json["cells"], 6);
  EXPECT_EQ(json["finer_cells"], 9);
  EXPECT_EQ(json["parameter"], "youngs_modulus");
  EXPECT_DOUBLE_EQ(json["first_fit"]["parameters"]["youngs_modulus"]["value"].get<double>(),
                   coarse);

  // Over a budget below the finer grid's nodes the first fit stands, unchanged.
  options.max_grid_nodes = controlled.refinement.decision.finer_grid_nodes - 1;
  const ControlledFit kept =
      ControlGrid(capture.capture, config, *fit, *analysis, FitOptions{}, options);
  EXPECT_FALSE(kept.refinement.refined);
  EXPECT_EQ(kept.fit.cells, 6);
  EXPECT_DOUBLE_EQ(kept.fit.Best().final.youngs_modulus, coarse);
  EXPECT_EQ(kept.config.solver.cells, 6);
}

}  // namespace
}  // namespace softid::inverse
