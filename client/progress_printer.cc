#include "client/progress_printer.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>

#include "client/text_format.h"

namespace softid::client {

void ProgressPrinter::operator()(const v1::JobEvent& event) {
  if (json_) {
    PrintJson(event);
    return;
  }
  if (event.kind() == v1::JobEvent::STATE_CHANGE) {
    if (on_line_) std::cout << "\n";
    on_line_ = false;
    starts_.clear();  // a new attempt starts its starts again
    std::cout << StateName(event.state());
    if (!event.message().empty()) std::cout << ": " << event.message();
    std::cout << std::endl;
    return;
  }
  Remember(event);
  std::printf("\r\033[K%s", Line().c_str());
  std::fflush(stdout);
  on_line_ = true;
}

void ProgressPrinter::PrintJson(const v1::JobEvent& event) const {
  nlohmann::json line = {{"seq", event.seq()},
                         {"kind", v1::JobEvent::Kind_Name(event.kind())},
                         {"iteration", event.iteration()},
                         {"state", StateName(event.state())},
                         {"elapsed_seconds", event.elapsed_seconds()},
                         {"message", event.message()}};
  if (event.kind() == v1::JobEvent::ITERATION) {
    line["start"] = event.start();
    line["num_starts"] = event.num_starts();
    if (std::isfinite(event.remaining_seconds())) {
      line["remaining_seconds"] = event.remaining_seconds();
    }
  }
  if (std::isfinite(event.cost())) line["cost"] = event.cost();
  if (!event.parameters_json().empty()) {
    line["parameters"] = nlohmann::json::parse(event.parameters_json(), nullptr, false);
  }
  std::cout << line.dump() << std::endl;
}

void ProgressPrinter::Remember(const v1::JobEvent& event) {
  StartProgress& start = starts_[event.start()];
  start.iteration = event.iteration();
  start.max_iterations = std::max(1, event.max_iterations());
  start.cost = event.cost();
  start.values.clear();
  const nlohmann::json parameters = nlohmann::json::parse(event.parameters_json(), nullptr, false);
  if (parameters.is_object()) {
    for (const auto& [name, value] : parameters.items()) {
      start.values += "  " + name + "=" + Compact(value);
      const auto unit = event.parameter_units().find(name);
      if (unit != event.parameter_units().end() && unit->second != "1") {
        start.values += " " + unit->second;
      }
    }
  }
  // With several starts the message begins "start k/N": the rest says the stage.
  start.stage = event.message();
  if (start.stage.rfind("start ", 0) == 0) {
    const size_t comma = start.stage.find(", ");
    start.stage = comma == std::string::npos ? "" : start.stage.substr(comma + 2);
  }
  num_starts_ = std::max(1, event.num_starts());
  remaining_s_ = event.remaining_seconds();
}

std::string ProgressPrinter::Line() const {
  if (starts_.empty()) return "";
  int done = 0, max = 1, best_index = 0;
  const StartProgress* best = nullptr;
  for (const auto& [index, start] : starts_) {
    done += start.iteration;
    max = std::max(max, start.max_iterations);
    if (best == nullptr || start.cost < best->cost) {
      best = &start;
      best_index = index;
    }
  }
  constexpr int kWidth = 20;
  const int filled = std::min(kWidth, kWidth * done / (max * num_starts_));
  char numbers[96];
  if (num_starts_ > 1) {
    std::snprintf(numbers, sizeof(numbers), "%d starts, best: start %d it %d/%d cost %.4e",
                  num_starts_, best_index + 1, best->iteration, max, best->cost);
  } else {
    std::snprintf(numbers, sizeof(numbers), "it %d/%d cost %.4e", best->iteration, max, best->cost);
  }
  std::string line = "[" + std::string(filled, '#') + std::string(kWidth - filled, ' ') + "] ";
  line += numbers + best->values;
  if (!best->stage.empty()) line += "  [" + best->stage + "]";
  if (std::isfinite(remaining_s_)) {
    line += "  ~" + std::to_string(static_cast<long>(std::lround(remaining_s_))) + " s left";
  }
  return line;
}

}  // namespace softid::client
