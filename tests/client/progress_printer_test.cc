// The watch line: one line for the job whatever the number of starts, showing the start with the
// lowest cost with its values in their units, the iterations of all starts in its bar, and the
// stage without the start prefix.
#include "client/progress_printer.h"

#include <gtest/gtest.h>

#include <string>

namespace softid::client {
namespace {

v1::JobEvent Iteration(int start, int num_starts, int iteration, double cost, double e,
                       const std::string& message) {
  v1::JobEvent event;
  event.set_kind(v1::JobEvent::ITERATION);
  event.set_start(start);
  event.set_num_starts(num_starts);
  event.set_iteration(iteration);
  event.set_max_iterations(10);
  event.set_cost(cost);
  event.set_parameters_json("{\"youngs_modulus\": " + std::to_string(e) + "}");
  event.set_message(message);
  event.set_remaining_seconds(12.4);
  (*event.mutable_parameter_units())["youngs_modulus"] = "Pa";
  return event;
}

TEST(ProgressPrinter, OneLineShowsTheBestStartAndEveryStartsIterations) {
  ProgressPrinter printer(/*json=*/false);
  EXPECT_EQ(printer.Line(), "");
  testing::internal::CaptureStdout();
  printer(Iteration(0, 2, 5, 3e-5, 52000, "start 1/2, frames 0-30 (stage 2/5)"));
  printer(Iteration(1, 2, 5, 1e-5, 39500, "start 2/2, frames 0-30 (stage 3/5)"));
  printer(Iteration(0, 2, 6, 2e-5, 45000, "start 1/2, frames 0-30 (stage 3/5)"));
  testing::internal::GetCapturedStdout();
  // 11 of 20 iterations: 11 of the bar's 20 marks.
  EXPECT_EQ(printer.Line(),
            "[###########         ] 2 starts, best: start 2 it 5/10 cost 1.0000e-05  "
            "youngs_modulus=39500 Pa  [frames 0-30 (stage 3/5)]  ~12 s left");
}

TEST(ProgressPrinter, OneStartAndANewAttemptStartOver) {
  ProgressPrinter printer(/*json=*/false);
  testing::internal::CaptureStdout();
  printer(Iteration(0, 1, 10, 4e-6, 40000, ""));
  v1::JobEvent running;
  running.set_kind(v1::JobEvent::STATE_CHANGE);
  running.set_state(v1::RUNNING);
  running.set_message("started (attempt 2)");
  printer(running);
  printer(Iteration(0, 1, 2, 8e-6, 41000, ""));
  const std::string printed = testing::internal::GetCapturedStdout();
  EXPECT_NE(printed.find("\nRUNNING: started (attempt 2)\n"), std::string::npos) << printed;
  EXPECT_EQ(printer.Line(),
            "[####                ] it 2/10 cost 8.0000e-06  youngs_modulus=41000 Pa  ~12 s left");
}

}  // namespace
}  // namespace softid::client
