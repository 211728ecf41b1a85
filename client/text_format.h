// Short text forms the client prints: job states and result.json / truth.json values.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "softid/v1/softid.pb.h"

namespace softid::client {

// "QUEUED", "SUCCEEDED", ...
std::string StateName(v1::JobState state);

// "2.1e+04", "[0, 0, -9.81]", "n=[0, 0, 1] d=0": short forms of result.json and truth.json values.
std::string Compact(const nlohmann::json& value);

}  // namespace softid::client
