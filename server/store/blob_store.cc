#include "server/store/blob_store.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <system_error>
#include <utility>
#include <vector>

namespace softid::server::store {
namespace {

namespace fs = std::filesystem;

Status ErrnoStatus(const std::string& what, const fs::path& path, int error) {
  return Status::IoError(path.string() + ": " + what + ": " + std::strerror(error));
}

fs::path TempDir(const fs::path& blobs_dir) {
  return blobs_dir / "tmp";
}

// Makes a directory entry (a new name or a removed one) durable.
Status FsyncDirectory(const fs::path& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return ErrnoStatus("open directory", dir, errno);
  const int rc = ::fsync(fd);
  const int error = errno;
  ::close(fd);
  if (rc != 0) return ErrnoStatus("fsync directory", dir, error);
  return Status::Ok();
}

Status CheckHash(std::string_view sha256) {
  if (!Sha256::IsValidHex(sha256)) {
    return Status::InvalidArgument("sha256 = '" + std::string(sha256.substr(0, 80)) +
                                   "': must be 64 lowercase hex digits");
  }
  return Status::Ok();
}

fs::path ShardDir(const fs::path& blobs_dir, std::string_view sha256) {
  return blobs_dir / std::string(sha256.substr(0, 2));
}

fs::path FinalPath(const fs::path& blobs_dir, std::string_view sha256) {
  return ShardDir(blobs_dir, sha256) / std::string(sha256);
}

// Creates blobs/ab/ on first use; the new entry in blobs/ must itself be made durable, or the
// renamed file could vanish with its directory after a power loss.
Status EnsureShardDir(const fs::path& blobs_dir, const fs::path& shard) {
  if (::mkdir(shard.c_str(), 0755) == 0) return FsyncDirectory(blobs_dir);
  if (errno == EEXIST) return Status::Ok();
  return ErrnoStatus("create directory", shard, errno);
}

}  // namespace

// --- BlobWriter ----------------------------------------------------------------------------------

BlobWriter::BlobWriter(fs::path blobs_dir, fs::path temp_path, int fd, PutOptions options)
    : blobs_dir_(std::move(blobs_dir)),
      temp_path_(std::move(temp_path)),
      fd_(fd),
      options_(std::move(options)) {}

BlobWriter::BlobWriter(BlobWriter&& other) noexcept
    : blobs_dir_(std::move(other.blobs_dir_)),
      temp_path_(std::move(other.temp_path_)),
      fd_(std::exchange(other.fd_, -1)),
      options_(std::move(other.options_)),
      hasher_(std::move(other.hasher_)),
      size_bytes_(other.size_bytes_),
      finished_(std::exchange(other.finished_, true)) {}

BlobWriter& BlobWriter::operator=(BlobWriter&& other) noexcept {
  if (this != &other) {
    Abort();
    blobs_dir_ = std::move(other.blobs_dir_);
    temp_path_ = std::move(other.temp_path_);
    fd_ = std::exchange(other.fd_, -1);
    options_ = std::move(other.options_);
    hasher_ = std::move(other.hasher_);
    size_bytes_ = other.size_bytes_;
    finished_ = std::exchange(other.finished_, true);
  }
  return *this;
}

BlobWriter::~BlobWriter() {
  Abort();
}

void BlobWriter::Abort() {
  if (fd_ >= 0) ::close(std::exchange(fd_, -1));
  if (!finished_) {
    // Best effort: a leftover is removed by the next BlobStore::Open.
    ::unlink(temp_path_.c_str());
    finished_ = true;
  }
}

Status BlobWriter::Append(std::string_view bytes) {
  if (finished_ || fd_ < 0) {
    return Status::FailedPrecondition(options_.source_name + ": append after commit or abort");
  }
  hasher_.Update(bytes);
  const char* data = bytes.data();
  size_t remaining = bytes.size();
  while (remaining > 0) {
    const ssize_t written = ::write(fd_, data, remaining);
    if (written < 0) {
      if (errno == EINTR) continue;
      const Status status = ErrnoStatus("write " + options_.source_name, temp_path_, errno);
      Abort();
      return status;
    }
    data += written;
    remaining -= static_cast<size_t>(written);
  }
  size_bytes_ += static_cast<int64_t>(bytes.size());
  return Status::Ok();
}

Result<std::string> BlobWriter::Commit() {
  if (finished_ || fd_ < 0) {
    return Status::FailedPrecondition(options_.source_name + ": commit after commit or abort");
  }
  std::string sha256 = hasher_.FinishHex();
  if (!options_.expected_sha256.empty() && options_.expected_sha256 != sha256) {
    Abort();
    return Status::InvalidArgument(options_.source_name + ": sha256 mismatch: expected " +
                                   options_.expected_sha256 + ", got " + sha256 + " (" +
                                   std::to_string(size_bytes_) + " bytes)");
  }
  // Blobs are immutable: read-only permissions catch an accidental in-place edit.
  if (::fchmod(fd_, 0444) != 0 || ::fsync(fd_) != 0) {
    const Status status = ErrnoStatus("fsync " + options_.source_name, temp_path_, errno);
    Abort();
    return status;
  }
  // close() can report a deferred write error (e.g. on NFS), so its result matters.
  const int close_rc = ::close(std::exchange(fd_, -1));
  if (close_rc != 0) {
    const Status status = ErrnoStatus("close " + options_.source_name, temp_path_, errno);
    Abort();
    return status;
  }

  const fs::path shard = ShardDir(blobs_dir_, sha256);
  const fs::path final_path = FinalPath(blobs_dir_, sha256);
  if (Status made = EnsureShardDir(blobs_dir_, shard); !made.ok()) {
    Abort();
    return made;
  }
  // The same bytes stored before: keep the existing file, which readers may hold open.
  struct stat existing {};
  if (::stat(final_path.c_str(), &existing) == 0) {
    Abort();
    return sha256;
  }
  if (::rename(temp_path_.c_str(), final_path.c_str()) != 0) {
    const Status status = ErrnoStatus("rename to " + final_path.string(), temp_path_, errno);
    Abort();
    return status;
  }
  finished_ = true;
  SOFTID_RETURN_IF_ERROR(FsyncDirectory(shard));
  return sha256;
}

// --- BlobStore -----------------------------------------------------------------------------------

Result<BlobStore> BlobStore::Open(const fs::path& root, const BlobStoreOptions& options) {
  const fs::path blobs_dir = root / "blobs";
  const fs::path temp_dir = TempDir(blobs_dir);
  std::error_code error;
  fs::create_directories(temp_dir, error);
  if (error) return Status::IoError(temp_dir.string() + ": cannot create: " + error.message());

  const auto now = fs::file_time_type::clock::now();
  std::vector<fs::path> stale;
  for (fs::directory_iterator it(temp_dir, error), end; !error && it != end; it.increment(error)) {
    std::error_code stat_error;
    const auto written = it->last_write_time(stat_error);
    if (stat_error) continue;  // removed meanwhile by its writer
    if (now - written >= options.remove_temp_files_older_than) stale.push_back(it->path());
  }
  if (error) return Status::IoError(temp_dir.string() + ": cannot list: " + error.message());
  for (const fs::path& path : stale) {
    fs::remove(path, error);
    if (error) return Status::IoError(path.string() + ": cannot remove: " + error.message());
  }
  return BlobStore(root, blobs_dir);
}

Result<BlobWriter> BlobStore::NewWriter(PutOptions options) const {
  if (!options.expected_sha256.empty()) {
    SOFTID_RETURN_IF_ERROR(
        CheckHash(options.expected_sha256).WithContext(options.source_name + ": expected"));
  }
  std::string pattern = (TempDir(blobs_dir_) / "put-XXXXXX").string();
  // mkstemp: a unique name created with O_EXCL, so concurrent writers never share a file.
  const int fd = ::mkostemp(pattern.data(), O_CLOEXEC);
  if (fd < 0) return ErrnoStatus("create temporary file", pattern, errno);
  return BlobWriter(blobs_dir_, pattern, fd, std::move(options));
}

Result<std::string> BlobStore::Put(std::string_view bytes, const PutOptions& options) const {
  SOFTID_ASSIGN_OR_RETURN(BlobWriter writer, NewWriter(options));
  SOFTID_RETURN_IF_ERROR(writer.Append(bytes));
  return writer.Commit();
}

Result<std::string> BlobStore::Put(std::istream& in, const PutOptions& options) const {
  SOFTID_ASSIGN_OR_RETURN(BlobWriter writer, NewWriter(options));
  std::vector<char> buffer(1 << 20);
  while (in) {
    in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    const std::streamsize count = in.gcount();
    if (count > 0) {
      SOFTID_RETURN_IF_ERROR(writer.Append(std::string_view(buffer.data(), count)));
    }
  }
  if (in.bad()) return Status::IoError(options.source_name + ": read failed");
  return writer.Commit();
}

bool BlobStore::Has(std::string_view sha256) const {
  if (!Sha256::IsValidHex(sha256)) return false;
  struct stat info {};
  return ::stat(FinalPath(blobs_dir_, sha256).c_str(), &info) == 0 && S_ISREG(info.st_mode);
}

Result<fs::path> BlobStore::PathOf(std::string_view sha256) const {
  SOFTID_RETURN_IF_ERROR(CheckHash(sha256));
  if (!Has(sha256)) {
    return Status::NotFound("blob " + std::string(sha256) + " not found under " +
                            blobs_dir_.string());
  }
  return FinalPath(blobs_dir_, sha256);
}

Result<std::ifstream> BlobStore::OpenBlob(std::string_view sha256) const {
  SOFTID_ASSIGN_OR_RETURN(const fs::path path, PathOf(sha256));
  std::ifstream in(path, std::ios::binary);
  if (!in) return ErrnoStatus("open", path, errno);
  return in;
}

Result<std::string> BlobStore::Get(std::string_view sha256) const {
  SOFTID_ASSIGN_OR_RETURN(std::ifstream in, OpenBlob(sha256));
  std::string bytes;
  std::vector<char> buffer(1 << 20);
  while (in) {
    in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    bytes.append(buffer.data(), static_cast<size_t>(in.gcount()));
  }
  if (in.bad()) return Status::IoError(FinalPath(blobs_dir_, sha256).string() + ": read failed");
  return bytes;
}

Status BlobStore::Remove(std::string_view sha256) const {
  SOFTID_RETURN_IF_ERROR(CheckHash(sha256));
  const fs::path path = FinalPath(blobs_dir_, sha256);
  std::error_code error;
  fs::remove(path, error);
  if (error) return Status::IoError(path.string() + ": cannot remove: " + error.message());
  return Status::Ok();
}

Result<std::vector<std::string>> BlobStore::List() const {
  std::vector<std::string> hashes;
  std::error_code error;
  for (const fs::directory_entry& shard : fs::directory_iterator(blobs_dir_, error)) {
    const std::string prefix = shard.path().filename().string();
    if (prefix.size() != 2 || !shard.is_directory(error)) continue;  // tmp/ and strays
    for (const fs::directory_entry& blob : fs::directory_iterator(shard.path(), error)) {
      const std::string name = blob.path().filename().string();
      if (Sha256::IsValidHex(name) && name.compare(0, 2, prefix) == 0) hashes.push_back(name);
    }
    if (error) break;
  }
  if (error) return Status::IoError("blobs: cannot list: " + error.message());
  return hashes;
}

Status BlobStore::Verify(std::string_view sha256) const {
  SOFTID_ASSIGN_OR_RETURN(std::ifstream in, OpenBlob(sha256));
  Sha256 hasher;
  std::vector<char> buffer(1 << 20);
  while (in) {
    in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    hasher.Update(std::string_view(buffer.data(), static_cast<size_t>(in.gcount())));
  }
  const fs::path path = FinalPath(blobs_dir_, sha256);
  if (in.bad()) return Status::IoError(path.string() + ": read failed");
  const std::string actual = hasher.FinishHex();
  if (actual != sha256) {
    return Status::IoError(path.string() + ": corrupt blob: named " + std::string(sha256) +
                           " but its content hashes to " + actual);
  }
  return Status::Ok();
}

}  // namespace softid::server::store
