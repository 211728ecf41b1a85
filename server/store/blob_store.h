// Content-addressed, immutable files: a blob is named by the SHA-256 of its bytes and stored at
// ROOT/blobs/<first two hex digits>/<64 hex digits>. Depth frames (~600 KB each) live here rather
// than in SQLite because workers read them faster as plain files; the database keeps only their
// hashes (capture manifests).
//
// Durability protocol for a put: write ROOT/blobs/tmp/<random>, fsync it, rename it to its final
// name, fsync the directory. A crash at any point leaves either no file under the final name or
// the complete one, never a prefix; callers commit the database row that refers to a blob only
// after Put returned, so a committed row never points at a missing blob.
//
// The temporary file lives in blobs/tmp/ rather than next to its final name because a streamed
// upload's name is known only after its last byte; rename within one file system is atomic either
// way. Stray temporary files (a crash mid-upload) are removed when the store is opened.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <istream>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/status.h"
#include "server/store/sha256.h"

namespace softid::server::store {

struct BlobStoreOptions {
  // Open() removes files in blobs/tmp/ whose last write is at least this old. Zero removes every
  // one, which is right when a single process owns the directory (the single-node default). When
  // several processes share it (a shared volume), set this above the longest upload, or one
  // process's start-up would delete another's upload in progress.
  std::chrono::seconds remove_temp_files_older_than{0};
};

struct PutOptions {
  // When not empty, the put fails with InvalidArgument unless the bytes hash to this value
  // (64 lowercase hex digits), and nothing is stored.
  std::string expected_sha256 = "";
  // Names the source of the bytes in error messages, e.g. "frames/cam0_0001.png".
  std::string source_name = "blob";
};

// A put in progress: bytes are appended to a temporary file and hashed on the way; Commit() moves
// the file to its content address. Destroying an uncommitted writer deletes the temporary file.
// Movable, not copyable; not thread-safe.
class BlobWriter {
 public:
  BlobWriter(BlobWriter&& other) noexcept;
  BlobWriter& operator=(BlobWriter&& other) noexcept;
  BlobWriter(const BlobWriter&) = delete;
  BlobWriter& operator=(const BlobWriter&) = delete;
  ~BlobWriter();

  Status Append(std::string_view bytes);
  // Verifies the hash (if expected), makes the file durable and gives it its final name.
  // Returns the hash. On any failure the temporary file is removed.
  // @pre Neither Commit() nor Abort() ran before.
  Result<std::string> Commit();
  // Deletes the temporary file. Idempotent.
  void Abort();

  int64_t size_bytes() const { return size_bytes_; }

 private:
  friend class BlobStore;
  BlobWriter(std::filesystem::path blobs_dir, std::filesystem::path temp_path, int fd,
             PutOptions options);

  std::filesystem::path blobs_dir_;
  std::filesystem::path temp_path_;
  int fd_ = -1;  // -1 once closed
  PutOptions options_;
  Sha256 hasher_;
  int64_t size_bytes_ = 0;
  bool finished_ = false;
};

// Thread-safe: every operation works on its own files, and renames are atomic.
class BlobStore {
 public:
  // Creates ROOT/blobs/ if needed and removes stray temporary files (see BlobStoreOptions).
  static Result<BlobStore> Open(const std::filesystem::path& root,
                                const BlobStoreOptions& options = {});

  // Starts a streamed put (e.g. one upload arriving in 1 MiB chunks).
  Result<BlobWriter> NewWriter(PutOptions options = {}) const;
  // Stores `bytes` and returns their hash. Putting bytes that are already stored is a no-op.
  Result<std::string> Put(std::string_view bytes, const PutOptions& options = {}) const;
  // Stores everything `in` yields until end of stream.
  Result<std::string> Put(std::istream& in, const PutOptions& options = {}) const;

  // False for a malformed hash.
  bool Has(std::string_view sha256) const;
  // The whole blob. NotFound when absent, InvalidArgument for a malformed hash.
  Result<std::string> Get(std::string_view sha256) const;
  // The blob opened for binary reading.
  Result<std::ifstream> OpenBlob(std::string_view sha256) const;
  // The path of a stored blob, for readers that map or stream the file themselves.
  Result<std::filesystem::path> PathOf(std::string_view sha256) const;
  // Deletes a blob; absent is fine. The caller makes sure nothing refers to it any more
  // (JobStore::IsBlobReferenced) and that no put of the same bytes is under way.
  Status Remove(std::string_view sha256) const;
  // The hashes of every stored blob (temporary files excluded), in no particular order.
  Result<std::vector<std::string>> List() const;
  // Re-hashes a stored blob: IoError naming both hashes if the file no longer matches its name.
  Status Verify(std::string_view sha256) const;

  const std::filesystem::path& root() const { return root_; }

 private:
  BlobStore(std::filesystem::path root, std::filesystem::path blobs_dir)
      : root_(std::move(root)), blobs_dir_(std::move(blobs_dir)) {}

  std::filesystem::path root_;
  std::filesystem::path blobs_dir_;  // root_/blobs
};

}  // namespace softid::server::store
