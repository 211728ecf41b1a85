#include "client/capture_files.h"

#include <openssl/evp.h>

#include <fstream>
#include <initializer_list>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <vector>

namespace softid::client {

bool Sha256OfFile(const std::filesystem::path& file, std::string* hex, int64_t* size_bytes) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return false;
  std::unique_ptr<EVP_MD_CTX, decltype(&EVP_MD_CTX_free)> ctx(EVP_MD_CTX_new(), EVP_MD_CTX_free);
  if (!ctx || EVP_DigestInit_ex(ctx.get(), EVP_sha256(), nullptr) != 1) return false;
  std::vector<char> buffer(1 << 20);
  int64_t size = 0;
  while (in) {
    in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    const std::streamsize got = in.gcount();
    if (got > 0) {
      EVP_DigestUpdate(ctx.get(), buffer.data(), static_cast<size_t>(got));
      size += got;
    }
  }
  if (in.bad()) return false;
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  EVP_DigestFinal_ex(ctx.get(), digest, &length);
  static const char* kHex = "0123456789abcdef";
  hex->clear();
  for (unsigned int i = 0; i < length; ++i) {
    hex->push_back(kHex[digest[i] >> 4]);
    hex->push_back(kHex[digest[i] & 15]);
  }
  *size_bytes = size;
  return true;
}

namespace {

// Reads <directory>/<name> into `text` and parses it into `json` (an object).
bool ReadDescription(const std::filesystem::path& directory, const std::string& name,
                     const std::string& kind, std::string* text, nlohmann::json* json,
                     std::string* error) {
  const std::filesystem::path json_path = directory / name;
  std::ifstream in(json_path, std::ios::binary);
  if (!in) {
    *error = json_path.string() + ": not found (is " + directory.string() + " a " + kind + "?)";
    return false;
  }
  std::stringstream contents;
  contents << in.rdbuf();
  *text = contents.str();
  *json = nlohmann::json::parse(*text, nullptr, false);
  if (json->is_discarded() || !json->is_object()) {
    *error = json_path.string() + ": not a JSON object";
    return false;
  }
  return true;
}

// Hashes each of `paths` (duplicates once) into out->files.
bool HashFiles(const std::filesystem::path& directory, const std::vector<std::string>& paths,
               const std::string& named_in, CaptureFiles* out, std::string* error) {
  std::set<std::string> seen;
  for (const std::string& path : paths) {
    if (!seen.insert(path).second) continue;
    v1::CaptureFile file;
    file.set_path(path);
    std::string hex;
    int64_t size = 0;
    if (!Sha256OfFile(directory / path, &hex, &size)) {
      *error = (directory / path).string() + ": cannot read (named in " + named_in + ")";
      return false;
    }
    file.set_sha256(hex);
    file.set_size_bytes(size);
    out->files.push_back(std::move(file));
  }
  return true;
}

}  // namespace

namespace {

// The file names a description holds (only the names: their meaning is checked by the server): its
// "mesh" and, for each camera, every entry of the arrays `lists` names, a string or an object's
// "file".
std::vector<std::string> NamedFiles(const nlohmann::json& json,
                                    std::initializer_list<const char*> lists) {
  std::vector<std::string> paths;
  if (auto mesh = json.find("mesh"); mesh != json.end() && mesh->is_string()) {
    paths.push_back(mesh->get<std::string>());
  }
  auto cameras = json.find("cameras");
  if (cameras == json.end() || !cameras->is_array()) return paths;
  for (const nlohmann::json& camera : *cameras) {
    if (!camera.is_object()) continue;
    for (const char* list : lists) {
      auto entries = camera.find(list);
      if (entries == camera.end() || !entries->is_array()) continue;
      for (const nlohmann::json& entry : *entries) {
        if (entry.is_string()) paths.push_back(entry.get<std::string>());
        if (!entry.is_object()) continue;
        if (auto file = entry.find("file"); file != entry.end() && file->is_string()) {
          paths.push_back(file->get<std::string>());
        }
      }
    }
  }
  return paths;
}

// Reads <directory>/<name> into `text` and hashes the files it names.
bool ReadDescribedFolder(const std::filesystem::path& directory, const std::string& name,
                         const std::string& kind, std::initializer_list<const char*> lists,
                         std::string* text, CaptureFiles* out, std::string* error) {
  nlohmann::json json;
  out->directory = directory;
  if (!ReadDescription(directory, name, kind, text, &json, error)) return false;
  return HashFiles(directory, NamedFiles(json, lists), name, out, error);
}

}  // namespace

bool ReadCaptureFiles(const std::filesystem::path& directory, CaptureFiles* out,
                      std::string* error) {
  return ReadDescribedFolder(directory, "capture.json", "capture folder", {"frames"},
                             &out->capture_json, out, error);
}

bool ReadRecordingFiles(const std::filesystem::path& directory, CaptureFiles* out,
                        std::string* error) {
  return ReadDescribedFolder(directory, "recording.json", "recording folder",
                             {"frames", "background"}, &out->recording_json, out, error);
}

bool ReadFolderFiles(const std::filesystem::path& directory, CaptureFiles* out,
                     std::string* error) {
  std::error_code ignored;
  const bool capture = std::filesystem::exists(directory / "capture.json", ignored);
  const bool recording = std::filesystem::exists(directory / "recording.json", ignored);
  if (capture && recording) {
    *error = directory.string() +
             ": holds both capture.json and recording.json; a folder is one or the other";
    return false;
  }
  if (recording) return ReadRecordingFiles(directory, out, error);
  if (capture) return ReadCaptureFiles(directory, out, error);
  *error = directory.string() +
           ": holds neither capture.json nor recording.json (is it a capture or recording "
           "folder?)";
  return false;
}

}  // namespace softid::client
