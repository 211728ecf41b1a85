// Grid control by the fitted values themselves: "refine_grid" in a job config.
//
// "auto" cells (grid_selection.h) take the coarsest grid on which the simulated surface agrees
// with a finer grid's at the *starting* parameters. Whether that grid is fine enough for the
// *fitted* values is known only after the fit, from each value's discretisation error
// (discretisation_error.h): a surface difference below the depth noise can still move Young's
// modulus by several percent (the scanned bunny, clean capture, frames 0-20: -25 % at 16 cells,
// -7.4 % at 24). When a fitted value's grid error exceeds what the data resolve,
//   grid error > max(sigma_multiple x its statistical sigma, relative_floor x |value|),
// the fit runs again on the finer grid the estimate compared with (cells 1.5 x), from the fitted
// values with one start, at the first fit's time step and frames; that fit and its own analysis
// are the result, and the first one's values are kept beside them. One level at most: each level
// costs ~3.4 x the nodes, and a grid past max_grid_nodes is not tried (the result says why).
#pragma once

#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "core/capture/capture.h"
#include "core/common/status.h"
#include "core/inverse/fit.h"
#include "core/inverse/fit_uncertainty.h"
#include "core/inverse/job_config.h"

namespace softid::inverse {

struct GridRefinementOptions {
  // A value asks for the finer grid when its grid error exceeds this many statistical sigmas
  // [-], > 0: 2, the band a reader takes the sigma for.
  double sigma_multiple = 2.0;
  // ... and this fraction of its magnitude [-], >= 0: 1 %, well inside the 3 % a material value
  // is wanted to; a vector's magnitude is its length.
  double relative_floor = 0.01;
  // The finer grid's nodes (CountGridNodes: the cells the body cuts) at most [-], >= 1. 18000,
  // three times the "auto" budget (GridSelectionOptions::max_grid_nodes): one fit there costs
  // roughly what three at the chosen grid do.
  int max_grid_nodes = 18000;

  // InvalidArgument naming the field and value.
  Status Validate() const;
};

// Whether a fit's grid is refined, and why.
struct GridRefinementDecision {
  bool refine = false;
  int cells = 0;        // the fit's grid, cells along the longest side (0: config's cell_size)
  int finer_cells = 0;  // the grid compared with (0 with a cell_size)
  double ratio = 0.0;   // h / finer h [-]
  int finer_grid_nodes = -1;  // its node count; -1 when not counted
  std::string parameter;      // the fitted value whose grid error decides (empty: none)
  double grid_error = 0.0;    // that value's largest grid error [its unit]
  double threshold = 0.0;     // the error it was held against [its unit]
  std::string reason;         // one sentence, for logs and the result
};

// The decision from a fit and its analysis. `finer_grid_nodes` is the finer grid's node count
// (-1: not counted, then not limited). No refinement without a discretisation estimate.
GridRefinementDecision DecideGridRefinement(const FitResult& fit, const FitUncertainty& uncertainty,
                                            int finer_grid_nodes,
                                            const GridRefinementOptions& options = {});

// `config` on the decision's finer grid (cells, or the cell size divided by the ratio).
JobConfig WithFinerGrid(JobConfig config, const GridRefinementDecision& decision);

// The refit's config: the fit's time step and frames (WithFitDiscretisation) on the finer grid,
// one start from the best start's values.
JobConfig RefinementConfig(const JobConfig& config, const FitResult& fit,
                           const GridRefinementDecision& decision);

// What the refinement did: the decision, the first fit's result (ToJson with its uncertainty)
// when it refined, and its time [s].
struct GridRefinement {
  GridRefinementDecision decision;
  bool refined = false;      // the result is the refit's
  nlohmann::json first_fit;  // null unless refined
  double seconds = 0.0;
};

// A fit after grid control: the refit and its analysis when refined, else the inputs moved in.
struct ControlledFit {
  FitResult fit;
  // What `fit` was computed with: the caller's; when refined, with the refit's grid, time step
  // and frames (its starts and initial values stay the caller's).
  JobConfig config;
  std::optional<FitUncertainty> uncertainty;
  std::string uncertainty_error;
  GridRefinement refinement;
};

// Decides (counting the finer grid's nodes on the capture's mesh) and, when refining, fits again
// with `options` (progress, cancellation) and analyses the refit. Under the config's max_seconds
// the refit gets the time the first fit left, and none is made when nothing is left. A refit that
// fails or is cancelled leaves the first fit as the result, with the reason in
// refinement.decision.reason.
ControlledFit ControlGrid(const capture::Capture& capture, const JobConfig& config, FitResult fit,
                          FitUncertainty uncertainty, const FitOptions& options = {},
                          const GridRefinementOptions& refinement = {});

// result.json's "grid_refinement": {"refined", "cells", "finer_cells", "finer_grid_nodes",
// "parameter", "grid_error", "threshold", "reason", "seconds", "first_fit"?}.
nlohmann::json ToJson(const GridRefinement& refinement);

}  // namespace softid::inverse
