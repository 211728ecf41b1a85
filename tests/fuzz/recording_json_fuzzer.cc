// libFuzzer target: recording.json as a recording folder holds it (recording::ReadRecording):
// json::ParseUntrustedJson with capture::kCaptureJsonLimits, then recording::RecordingFromJson. A
// rejected text must come back as InvalidArgument; an accepted recording must survive
// recording::ToJson unchanged, because capture stations write the format that ToJson defines and
// the reader must accept whatever it wrote.
#include <cstddef>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string_view>

#include "core/capture/capture.h"
#include "core/common/status.h"
#include "core/common/untrusted_json.h"
#include "core/recording/recording.h"
#include "tests/fuzz/fuzz_checks.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace softid;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  const Result<nlohmann::json> parsed =
      json::ParseUntrustedJson(text, recording::kRecordingFileName, capture::kCaptureJsonLimits);
  if (!parsed.ok()) {
    fuzz::RequireRejection(parsed.status());
    return 0;
  }
  const Result<recording::Recording> read = recording::RecordingFromJson(*parsed);
  if (!read.ok()) {
    fuzz::RequireRejection(read.status());
    return 0;
  }
  const nlohmann::json written = recording::ToJson(*read);
  const Result<recording::Recording> reread = recording::RecordingFromJson(written);
  fuzz::Require(reread.ok(), "RecordingFromJson rejects what ToJson wrote of an accepted recording",
                reread.status().ToString());
  fuzz::Require(recording::ToJson(*reread) == written, "a recording changed in a ToJson round trip",
                written.dump());
  return 0;
}
