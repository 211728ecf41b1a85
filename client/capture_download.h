// Writes files the server sends (a capture by DownloadCapture, a job's report by
// DownloadArtifact) into a local folder. The folder must not
// exist or be empty, so nothing of the user's is overwritten; every path the server names must
// stay inside it (relative, no "." or ".." segments), so a faulty or hostile server cannot write
// elsewhere; each file's bytes must arrive in order and match the size and sha256 listed.
// Not thread-safe.
#pragma once

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "softid/v1/softid.pb.h"

namespace softid::client {

// True when `path` is relative, '/'-separated, without empty, "." or ".." segments, backslashes
// or control characters: joined to a folder it names a file inside that folder.
bool IsSafeRelativePath(std::string_view path);

// True when `directory` does not exist or is an empty folder; otherwise false with `error`.
bool IsEmptyTarget(const std::filesystem::path& directory, std::string* error);

// A file a download expects: its path inside the folder, size and (when known) sha256.
struct ExpectedFile {
  std::string path;
  int64_t size_bytes = 0;
  std::string sha256;  // lowercase hex; empty: not checked
};

class CaptureDownload {
 public:
  explicit CaptureDownload(std::filesystem::path directory) : directory_(std::move(directory)) {}
  ~CaptureDownload() = default;
  CaptureDownload(const CaptureDownload&) = delete;
  CaptureDownload& operator=(const CaptureDownload&) = delete;

  // Checks the target (IsEmptyTarget) and every listed path, then creates the folder. False with
  // `error` naming the path otherwise; nothing is written then.
  bool Begin(const v1::Capture& capture, std::string* error);
  bool Begin(const std::vector<ExpectedFile>& files, std::string* error);
  // Appends a chunk of a listed file at the offset its bytes so far end at.
  bool AddChunk(const v1::FileChunk& chunk, std::string* error);
  // Every listed file arrived complete with its listed sha256.
  bool Finish(std::string* error);
  // Removes everything written (the folder too, when Begin created it); nothing before Begin
  // succeeded.
  void Discard();

 private:
  struct File {
    int64_t size_bytes = 0;
    std::string sha256;
    int64_t received = 0;
    std::ofstream out;
  };
  std::filesystem::path directory_;
  bool begun_ = false;    // Begin succeeded: what is in the folder was written here
  bool created_ = false;  // Begin created the folder
  std::map<std::string, File> files_;
};

}  // namespace softid::client
