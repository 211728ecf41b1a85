// What `softid watch` prints for a job's events: a state line per state change, and one live line
// for the fit (a bar over every start's iterations, then the start with the lowest cost so far:
// its iteration, cost, values, stage, and the time left by the fit's own estimate). With --json,
// one JSON object per event instead.
#pragma once

#include <limits>
#include <map>
#include <string>

#include "softid/v1/softid.pb.h"

namespace softid::client {

class ProgressPrinter {
 public:
  explicit ProgressPrinter(bool json) : json_(json) {}
  void operator()(const v1::JobEvent& event);

  // The live line after the events so far (empty before the first iteration).
  std::string Line() const;

 private:
  // The latest iteration of one start.
  struct StartProgress {
    int iteration = 0;
    int max_iterations = 1;
    double cost = 0.0;
    std::string values;  // "  name=value" per fitted parameter
    std::string stage;   // "frames 0-30 (stage 2/5)", ... from the event's message
  };

  void PrintJson(const v1::JobEvent& event) const;
  void Remember(const v1::JobEvent& event);

  bool json_;
  bool on_line_ = false;
  std::map<int, StartProgress> starts_;  // of the current attempt
  int num_starts_ = 1;
  double remaining_s_ = std::numeric_limits<double>::quiet_NaN();
};

}  // namespace softid::client
