#include "server/store/resource_id.h"

#include <cstdint>
#include <random>

#include "core/common/json_fields.h"

namespace softid::server::store {

std::string NewResourceId(std::string_view prefix) {
  // std::random_device reads getrandom(2) on Linux; a fresh device per call keeps this free of
  // shared state and locks, and ids are created far less often than the syscall costs matter.
  std::random_device device;
  const uint64_t bits = (static_cast<uint64_t>(device()) << 32) | device();
  static constexpr char kDigits[] = "0123456789abcdef";
  std::string id(prefix);
  for (int shift = 60; shift >= 0; shift -= 4) id += kDigits[(bits >> shift) & 0xf];
  return id;
}

Status CheckResourceId(std::string_view id, std::string_view prefix, std::string_view what) {
  bool ok = id.size() == prefix.size() + 16 && id.substr(0, prefix.size()) == prefix;
  for (size_t i = prefix.size(); ok && i < id.size(); ++i) {
    const char c = id[i];
    ok = (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f');
  }
  if (ok) return Status::Ok();
  return Status::InvalidArgument(std::string(what) + " = '" + std::string(id.substr(0, 80)) +
                                 "': must be '" + std::string(prefix) +
                                 "' and 16 lowercase hex digits");
}

Status CheckRequestId(std::string_view request_id) {
  if (request_id.size() > kMaxRequestIdLength) {
    return json::Invalid("request_id", std::string(request_id),
                         "must be at most " + std::to_string(kMaxRequestIdLength) + " characters");
  }
  for (const char c : request_id) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) {
      return json::Invalid("request_id", std::string(request_id),
                           "must not contain control characters");
    }
  }
  return Status::Ok();
}

}  // namespace softid::server::store
