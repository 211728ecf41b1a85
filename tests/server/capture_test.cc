#include "server/store/capture.h"

#include <gtest/gtest.h>

#include "server/store/sha256.h"

namespace softid::server::store {
namespace {

std::vector<ManifestEntry> TwoFiles() {
  return {{"capture.json", Sha256::Hex("a"), 1},
          {"frames/cam0_0000.png", Sha256::Hex("b"), 614400}};
}

// The JSON form is [{path, sha256, size}] and parses back to the same manifest.
TEST(Manifest, JsonRoundTrip) {
  const nlohmann::json json = ManifestToJson(TwoFiles());
  EXPECT_EQ(json[1]["path"], "frames/cam0_0000.png");
  EXPECT_EQ(json[1]["size"], 614400);
  const Result<std::vector<ManifestEntry>> parsed = ManifestFromJson(json);
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
  EXPECT_EQ(*parsed, TwoFiles());
}

// Each rule names the entry, the field and the value it rejects.
TEST(Manifest, ValidationNamesTheEntry) {
  auto message_for = [](std::vector<ManifestEntry> manifest) {
    const Status status = ValidateManifest(manifest);
    EXPECT_EQ(status.code(), StatusCode::kInvalidArgument);
    return status.message();
  };
  EXPECT_EQ(message_for({}), "manifest = []: must list at least one file");
  auto manifest = TwoFiles();
  manifest[1].path = "frames/../../etc/passwd";
  EXPECT_EQ(message_for(manifest),
            "manifest[1].path = \"frames/../../etc/passwd\": must be a relative '/'-separated "
            "path without '.' or '..' segments");
  manifest = TwoFiles();
  manifest[0].path = "/abs";
  EXPECT_NE(message_for(manifest).find("manifest[0].path"), std::string::npos);
  manifest = TwoFiles();
  manifest[1].path = manifest[0].path;
  EXPECT_EQ(message_for(manifest),
            "manifest[1].path = \"capture.json\": appears twice in the manifest");
  manifest = TwoFiles();
  manifest[0].sha256 = "ABC";
  EXPECT_EQ(message_for(manifest), "manifest[0].sha256 = \"ABC\": must be 64 lowercase hex digits");
  manifest = TwoFiles();
  manifest[1].size_bytes = -1;
  EXPECT_EQ(message_for(manifest), "manifest[1].size = -1: must be non-negative");
}

// Missing or mistyped JSON fields are rejected with their path.
TEST(Manifest, FromJsonRejectsMalformedEntries) {
  const Result<std::vector<ManifestEntry>> missing =
      ManifestFromJson(nlohmann::json::parse(R"([{"path": "a", "sha256": "x"}])"));
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().message(), "manifest[0].size = null: is required");
  const Result<std::vector<ManifestEntry>> not_array = ManifestFromJson({{"path", "a"}});
  ASSERT_FALSE(not_array.ok());
  EXPECT_NE(not_array.status().message().find("must be an array"), std::string::npos);
  const Result<std::vector<ManifestEntry>> fractional = ManifestFromJson(nlohmann::json::parse(
      R"([{"path": "a", "sha256": ")" + Sha256::Hex("a") + R"(", "size": 1.5}])"));
  ASSERT_FALSE(fractional.ok());
  EXPECT_EQ(fractional.status().message(),
            "manifest[0].size = 1.5: must be an integer number of bytes");
}

}  // namespace
}  // namespace softid::server::store
