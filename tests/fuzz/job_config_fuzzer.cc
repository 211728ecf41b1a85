// libFuzzer target: a job config as the service receives it in CreateJob (server/job_service.cc):
// json::ParseUntrustedJson with the server's limits, then inverse::JobConfigFromJson. A rejected
// text must come back as InvalidArgument; an accepted config must be valid and round-trip through
// inverse::ToJson exactly, as job_config.h promises (the stored job keeps the config as JSON and
// the worker parses it again).
#include <cstddef>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string_view>

#include "core/common/status.h"
#include "core/common/untrusted_json.h"
#include "core/inverse/job_config.h"
#include "tests/fuzz/fuzz_checks.h"

namespace {

// The bounds server/job_service.cc applies to config_json (kept there in an unnamed namespace).
constexpr softid::json::UntrustedJsonLimits kConfigJsonLimits{.max_bytes = 1u << 20,
                                                              .max_depth = 16};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace softid;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  const Result<nlohmann::json> parsed =
      json::ParseUntrustedJson(text, "config_json", kConfigJsonLimits);
  if (!parsed.ok()) {
    fuzz::RequireRejection(parsed.status());
    return 0;
  }
  const Result<inverse::JobConfig> config = inverse::JobConfigFromJson(*parsed);
  if (!config.ok()) {
    fuzz::RequireRejection(config.status());
    return 0;
  }
  const Status valid = config->Validate();
  fuzz::Require(valid.ok(), "an accepted job config fails Validate", valid.ToString());
  const nlohmann::json written = inverse::ToJson(*config);
  const Result<inverse::JobConfig> reread = inverse::JobConfigFromJson(written);
  fuzz::Require(reread.ok(), "JobConfigFromJson rejects what ToJson wrote of an accepted config",
                reread.status().ToString());
  fuzz::Require(*reread == *config, "a job config changed in a ToJson round trip", written.dump());
  return 0;
}
