// libFuzzer target: capture.json as the upload service receives it (server/capture_upload.cc) and a
// capture folder holds it: json::ParseUntrustedJson with capture::kCaptureJsonLimits, then
// capture::CaptureFromJson. A rejected text must come back as InvalidArgument; an accepted capture
// must survive capture::ToJson unchanged, because capture stations write the format that ToJson
// defines and the reader must accept whatever it wrote.
#include <cstddef>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string_view>

#include "core/capture/capture.h"
#include "core/common/status.h"
#include "core/common/untrusted_json.h"
#include "tests/fuzz/fuzz_checks.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace softid;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  const Result<nlohmann::json> parsed =
      json::ParseUntrustedJson(text, capture::kCaptureFileName, capture::kCaptureJsonLimits);
  if (!parsed.ok()) {
    fuzz::RequireRejection(parsed.status());
    return 0;
  }
  const Result<capture::Capture> capture = capture::CaptureFromJson(*parsed);
  if (!capture.ok()) {
    fuzz::RequireRejection(capture.status());
    return 0;
  }
  const nlohmann::json written = capture::ToJson(*capture);
  const Result<capture::Capture> reread = capture::CaptureFromJson(written);
  fuzz::Require(reread.ok(), "CaptureFromJson rejects what ToJson wrote of an accepted capture",
                reread.status().ToString());
  fuzz::Require(capture::ToJson(*reread) == written, "a capture changed in a ToJson round trip",
                written.dump());
  return 0;
}
