// libFuzzer target: the upload manifest as the store keeps it (JSON text in SQLite, see
// server/store/capture.h): json::ParseUntrustedJson, then store::ManifestFromJson, which runs
// store::ValidateManifest, the check every upload's file list passes before a worker writes its
// files to <dir>/<path>. A rejected text must come back as InvalidArgument; an accepted manifest
// must pass ValidateManifest on its own and round-trip through ManifestToJson.
#include <cstddef>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string_view>
#include <vector>

#include "core/common/status.h"
#include "core/common/untrusted_json.h"
#include "server/store/capture.h"
#include "tests/fuzz/fuzz_checks.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace softid;
  using server::store::ManifestEntry;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  const Result<nlohmann::json> parsed = json::ParseUntrustedJson(text, "manifest");
  if (!parsed.ok()) {
    fuzz::RequireRejection(parsed.status());
    return 0;
  }
  const Result<std::vector<ManifestEntry>> manifest = server::store::ManifestFromJson(*parsed);
  if (!manifest.ok()) {
    fuzz::RequireRejection(manifest.status());
    return 0;
  }
  const Status valid = server::store::ValidateManifest(*manifest);
  fuzz::Require(valid.ok(), "an accepted manifest fails ValidateManifest", valid.ToString());
  const Result<std::vector<ManifestEntry>> reread =
      server::store::ManifestFromJson(server::store::ManifestToJson(*manifest));
  fuzz::Require(reread.ok(), "ManifestFromJson rejects what ManifestToJson wrote",
                reread.status().ToString());
  fuzz::Require(*reread == *manifest, "a manifest changed in a ManifestToJson round trip");
  return 0;
}
