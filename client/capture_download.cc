#include "client/capture_download.h"

#include <algorithm>
#include <system_error>

#include "client/capture_files.h"
#include "proto/capture_file_path.h"

namespace softid::client {

namespace fs = std::filesystem;

bool IsSafeRelativePath(std::string_view path) {
  for (const char c : path) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) return false;
  }
  return api::IsSafeRelativePath(path);
}

bool IsEmptyTarget(const fs::path& directory, std::string* error) {
  std::error_code code;
  if (!fs::exists(fs::symlink_status(directory, code))) return true;
  if (!fs::is_directory(fs::symlink_status(directory, code))) {
    *error = directory.string() + ": exists and is not a folder";
    return false;
  }
  if (!fs::is_empty(directory, code) || code) {
    *error = directory.string() + ": is not empty; download into a new or empty folder";
    return false;
  }
  return true;
}

bool CaptureDownload::Begin(const v1::Capture& capture, std::string* error) {
  std::vector<ExpectedFile> files;
  for (const v1::CaptureFile& file : capture.files()) {
    files.push_back({file.path(), file.size_bytes(), file.sha256()});
  }
  return Begin(files, error);
}

bool CaptureDownload::Begin(const std::vector<ExpectedFile>& files, std::string* error) {
  if (!IsEmptyTarget(directory_, error)) return false;
  for (const ExpectedFile& file : files) {
    if (!IsSafeRelativePath(file.path)) {
      *error = "files: \"" + file.path + "\": not a relative path inside the folder; refused";
      return false;
    }
    if (file.size_bytes < 0 || !files_.emplace(file.path, File{}).second) {
      *error = "files: \"" + file.path + "\": listed twice or with a negative size";
      return false;
    }
    File& entry = files_[file.path];
    entry.size_bytes = file.size_bytes;
    entry.sha256 = file.sha256;
  }
  std::error_code code;
  created_ = !fs::exists(directory_, code);
  fs::create_directories(directory_, code);
  if (code) {
    *error = directory_.string() + ": cannot create: " + code.message();
    return false;
  }
  begun_ = true;
  return true;
}

bool CaptureDownload::AddChunk(const v1::FileChunk& chunk, std::string* error) {
  auto it = files_.find(chunk.path());
  if (it == files_.end()) {
    *error = "chunk.path: \"" + chunk.path() + "\" is not a file listed for the download";
    return false;
  }
  File& file = it->second;
  const int64_t size = static_cast<int64_t>(chunk.data().size());
  if (chunk.offset_bytes() != file.received || file.received + size > file.size_bytes) {
    *error = "chunk of \"" + chunk.path() + "\" at byte " + std::to_string(chunk.offset_bytes()) +
             ": out of order or past its size of " + std::to_string(file.size_bytes) + " bytes";
    return false;
  }
  if (!file.out.is_open()) {
    const fs::path target = directory_ / chunk.path();
    std::error_code code;
    fs::create_directories(target.parent_path(), code);
    file.out.open(target, std::ios::binary | std::ios::trunc);
    if (code || !file.out) {
      *error = target.string() + ": cannot write";
      return false;
    }
  }
  file.out.write(chunk.data().data(), size);
  file.received += size;
  if (!file.out) {
    *error = (directory_ / chunk.path()).string() + ": cannot write";
    return false;
  }
  return true;
}

bool CaptureDownload::Finish(std::string* error) {
  for (auto& [path, file] : files_) {
    if (!file.out.is_open() && file.size_bytes == 0) {
      file.out.open(directory_ / path, std::ios::binary | std::ios::trunc);  // may come unsent
    }
    if (file.out.is_open()) file.out.close();
    if (file.received != file.size_bytes || file.out.fail()) {
      *error = "\"" + path + "\": " + std::to_string(file.received) + " of " +
               std::to_string(file.size_bytes) + " bytes arrived";
      return false;
    }
    if (file.sha256.empty()) continue;  // a report's file: its size is all that is listed
    std::string hex;
    int64_t size = 0;
    if (!Sha256OfFile(directory_ / path, &hex, &size) || hex != file.sha256) {
      *error = "\"" + path + "\": its bytes hash to " + hex + ", not the listed " + file.sha256;
      return false;
    }
  }
  return true;
}

void CaptureDownload::Discard() {
  if (!begun_) return;  // the folder is not ours to clean
  for (auto& [path, file] : files_) file.out.close();
  std::error_code ignored;
  if (created_) {
    fs::remove_all(directory_, ignored);
    return;
  }
  // The folder was empty before: everything in it is ours.
  for (const fs::directory_entry& entry : fs::directory_iterator(directory_, ignored)) {
    fs::remove_all(entry.path(), ignored);
  }
}

}  // namespace softid::client
