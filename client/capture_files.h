// The files of a local capture folder as the upload sends them: capture.json's contents plus
// every file it references (mesh, frame PNGs), each with its size and sha256; or the same for a
// raw recording folder (recording.json: mesh, frames, background frames). The client does not
// validate either (the server does, with the core's readers); it only needs the file list.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "softid/v1/softid.pb.h"

namespace softid::client {

struct CaptureFiles {
  std::filesystem::path directory;
  std::string capture_json;            // capture.json's contents for a capture folder, or
  std::string recording_json;          // recording.json's contents for a recording folder
  std::vector<v1::CaptureFile> files;  // paths relative to `directory`
};

// Reads <directory>/capture.json and hashes the mesh and every frame it names. Returns false and
// sets `error` (naming the file) when a file is missing or capture.json is not the expected JSON.
bool ReadCaptureFiles(const std::filesystem::path& directory, CaptureFiles* out,
                      std::string* error);

// Reads <directory>/recording.json and hashes the mesh, every frame and every background frame it
// names; errors as ReadCaptureFiles.
bool ReadRecordingFiles(const std::filesystem::path& directory, CaptureFiles* out,
                        std::string* error);

// ReadCaptureFiles or ReadRecordingFiles after the file the folder holds; an error when it
// holds both capture.json and recording.json (ambiguous) or neither.
bool ReadFolderFiles(const std::filesystem::path& directory, CaptureFiles* out, std::string* error);

// Lowercase hex SHA-256 of a file; false on a read error.
bool Sha256OfFile(const std::filesystem::path& file, std::string* hex, int64_t* size_bytes);

}  // namespace softid::client
