#include "server/store/blob_store.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <fstream>
#include <sstream>

#include "tests/server/temp_dir.h"

namespace softid::server::store {
namespace {

namespace fs = std::filesystem;
using testing::TempDir;

std::vector<fs::path> FilesUnder(const fs::path& dir) {
  std::vector<fs::path> files;
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (entry.is_regular_file()) files.push_back(entry.path());
  }
  return files;
}

// Put stores the bytes under blobs/<ab>/<hash>, read-only; Get/OpenBlob/Has find them again.
TEST(BlobStore, PutGetRoundTrip) {
  TempDir dir;
  Result<BlobStore> store = BlobStore::Open(dir.path());
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  const std::string bytes("depth\0frame", 11);
  const Result<std::string> hash = store->Put(bytes);
  ASSERT_TRUE(hash.ok()) << hash.status().ToString();
  EXPECT_EQ(*hash, Sha256::Hex(bytes));
  EXPECT_TRUE(store->Has(*hash));
  EXPECT_EQ(*store->Get(*hash), bytes);

  const fs::path expected = dir.path() / "blobs" / hash->substr(0, 2) / *hash;
  EXPECT_EQ(*store->PathOf(*hash), expected);
  struct stat info {};
  ASSERT_EQ(::stat(expected.c_str(), &info), 0);
  EXPECT_EQ(info.st_mode & 0777, 0444u);
  Result<std::ifstream> in = store->OpenBlob(*hash);
  ASSERT_TRUE(in.ok());
  std::stringstream read;
  read << in->rdbuf();
  EXPECT_EQ(read.str(), bytes);
  EXPECT_TRUE(store->Verify(*hash).ok());

  // Storing the same bytes again is a no-op with the same name.
  EXPECT_EQ(*store->Put(bytes), *hash);
  EXPECT_EQ(FilesUnder(dir.path()).size(), 1u);
}

// A streamed put (in chunks, or from an istream) gives the same name as a one-shot put.
TEST(BlobStore, StreamedPuts) {
  TempDir dir;
  Result<BlobStore> store = BlobStore::Open(dir.path());
  ASSERT_TRUE(store.ok());
  std::string bytes(3 * (1 << 20) + 17, '\0');
  for (size_t i = 0; i < bytes.size(); ++i) bytes[i] = static_cast<char>(i * 7 + (i >> 9));
  Result<BlobWriter> writer = store->NewWriter({.expected_sha256 = Sha256::Hex(bytes)});
  ASSERT_TRUE(writer.ok());
  for (size_t start = 0; start < bytes.size(); start += 1 << 20) {
    ASSERT_TRUE(writer->Append(std::string_view(bytes).substr(start, 1 << 20)).ok());
  }
  EXPECT_EQ(writer->size_bytes(), static_cast<int64_t>(bytes.size()));
  const Result<std::string> hash = writer->Commit();
  ASSERT_TRUE(hash.ok()) << hash.status().ToString();
  EXPECT_EQ(*hash, Sha256::Hex(bytes));
  EXPECT_EQ(writer->Append("x").code(), StatusCode::kFailedPrecondition);

  std::istringstream in("from a stream");
  EXPECT_EQ(*store->Put(in), Sha256::Hex("from a stream"));
  EXPECT_EQ(*store->Get(Sha256::Hex("from a stream")), "from a stream");
}

// A wrong expected hash rejects the put naming the source and both hashes, and leaves no file
// under either name.
TEST(BlobStore, HashMismatchStoresNothing) {
  TempDir dir;
  Result<BlobStore> store = BlobStore::Open(dir.path());
  ASSERT_TRUE(store.ok());
  const std::string claimed = Sha256::Hex("what the client said");
  const std::string actual = Sha256::Hex("what arrived");
  const Result<std::string> put =
      store->Put("what arrived", {.expected_sha256 = claimed, .source_name = "frames/cam0.png"});
  ASSERT_FALSE(put.ok());
  EXPECT_EQ(put.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(put.status().message(), "frames/cam0.png: sha256 mismatch: expected " + claimed +
                                        ", got " + actual + " (12 bytes)");
  EXPECT_FALSE(store->Has(actual));
  EXPECT_FALSE(store->Has(claimed));
  EXPECT_TRUE(FilesUnder(dir.path()).empty());

  // A malformed expected hash is refused before anything is written.
  const Result<BlobWriter> malformed = store->NewWriter({.expected_sha256 = "abc"});
  ASSERT_FALSE(malformed.ok());
  EXPECT_EQ(malformed.status().message(),
            "blob: expected: sha256 = 'abc': must be 64 lowercase hex digits");
}

// An abandoned writer deletes its temporary file; a stray one from a crash goes on Open.
TEST(BlobStore, NoLeftoversFromAbandonedPuts) {
  TempDir dir;
  Result<BlobStore> store = BlobStore::Open(dir.path());
  ASSERT_TRUE(store.ok());
  {
    Result<BlobWriter> writer = store->NewWriter();
    ASSERT_TRUE(writer.ok());
    ASSERT_TRUE(writer->Append("half an upload").ok());
    EXPECT_EQ(FilesUnder(dir.path()).size(), 1u);  // the temporary file
  }
  EXPECT_TRUE(FilesUnder(dir.path()).empty());

  { std::ofstream(dir.path() / "blobs" / "tmp" / "put-crashed") << "partial"; }
  ASSERT_EQ(FilesUnder(dir.path()).size(), 1u);
  // With a grace period the fresh file stays (another process may own it) ...
  EXPECT_TRUE(
      BlobStore::Open(dir.path(), {.remove_temp_files_older_than = std::chrono::hours(1)}).ok());
  EXPECT_EQ(FilesUnder(dir.path()).size(), 1u);
  // ... and by default it is removed.
  EXPECT_TRUE(BlobStore::Open(dir.path()).ok());
  EXPECT_TRUE(FilesUnder(dir.path()).empty());
}

// Lookups distinguish a malformed hash (InvalidArgument) from an absent blob (NotFound).
TEST(BlobStore, LookupErrors) {
  TempDir dir;
  Result<BlobStore> store = BlobStore::Open(dir.path());
  ASSERT_TRUE(store.ok());
  EXPECT_FALSE(store->Has("../../etc/passwd"));
  EXPECT_EQ(store->Get("../../etc/passwd").status().code(), StatusCode::kInvalidArgument);
  const std::string absent = Sha256::Hex("never stored");
  const Result<std::string> missing = store->Get(absent);
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  EXPECT_NE(missing.status().message().find("blob " + absent + " not found"), std::string::npos);
}

// Verify notices a file whose content no longer matches its name.
TEST(BlobStore, VerifyDetectsCorruption) {
  TempDir dir;
  Result<BlobStore> store = BlobStore::Open(dir.path());
  ASSERT_TRUE(store.ok());
  const std::string hash = *store->Put("original");
  const fs::path path = *store->PathOf(hash);
  fs::permissions(path, fs::perms::owner_write, fs::perm_options::add);
  { std::ofstream(path, std::ios::trunc) << "tampered"; }
  const Status verified = store->Verify(hash);
  EXPECT_EQ(verified.code(), StatusCode::kIoError);
  EXPECT_NE(verified.message().find("corrupt blob: named " + hash + " but its content hashes to " +
                                    Sha256::Hex("tampered")),
            std::string::npos)
      << verified.message();
}

}  // namespace
}  // namespace softid::server::store
