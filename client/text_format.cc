#include "client/text_format.h"

#include <cstdio>

namespace softid::client {

std::string StateName(v1::JobState state) {
  return v1::JobState_Name(state);
}

std::string Compact(const nlohmann::json& value) {
  if (value.is_number()) {
    char text[32];
    std::snprintf(text, sizeof(text), "%.5g", value.get<double>());
    return text;
  }
  if (value.is_array()) {
    std::string out = "[";
    for (size_t i = 0; i < value.size(); ++i) out += (i ? ", " : "") + Compact(value[i]);
    return out + "]";
  }
  if (value.is_object() && value.contains("normal") && value.contains("offset")) {
    return "n=" + Compact(value["normal"]) + " d=" + Compact(value["offset"]);
  }
  return value.dump();
}

}  // namespace softid::client
