#include "server/store/api_token.h"

#include "core/common/json_fields.h"

namespace softid::server::store {

Status ValidateStationName(std::string_view station) {
  const char* requirement = "must be 1-64 characters of letters, digits, '.', '_' and '-'";
  if (station.empty() || station.size() > 64) {
    return json::Invalid("station", std::string(station), requirement);
  }
  for (const char c : station) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '.' || c == '_' || c == '-';
    if (!ok) return json::Invalid("station", std::string(station), requirement);
  }
  return Status::Ok();
}

}  // namespace softid::server::store
