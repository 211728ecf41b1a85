#include "server/store/page_token.h"

#include <charconv>
#include <cstdint>
#include <optional>
#include <vector>

#include "server/store/sha256.h"

namespace softid::server::store {
namespace {

constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_";
constexpr std::string_view kVersion = "v1";
// A short checksum of the record turns a truncated or hand-edited token into a clear error instead
// of a silently different position. Not a security measure: a token only names a position.
constexpr size_t kChecksumChars = 8;

std::string Checksum(std::string_view record) {
  return Sha256::Hex(record).substr(0, kChecksumChars);
}

// RFC 4648 section 5 (URL- and filename-safe alphabet), without padding.
std::string Base64UrlEncode(std::string_view bytes) {
  std::string out;
  uint32_t buffer = 0;
  int bits = 0;
  for (const unsigned char c : bytes) {
    buffer = (buffer << 8) | c;
    bits += 8;
    while (bits >= 6) {
      bits -= 6;
      out += kAlphabet[(buffer >> bits) & 0x3f];
    }
  }
  if (bits > 0) out += kAlphabet[(buffer << (6 - bits)) & 0x3f];
  return out;
}

std::optional<std::string> Base64UrlDecode(std::string_view text) {
  std::string out;
  uint32_t buffer = 0;
  int bits = 0;
  for (const char c : text) {
    const char* found = std::char_traits<char>::find(kAlphabet, 64, c);
    if (found == nullptr) return std::nullopt;
    buffer = (buffer << 6) | static_cast<uint32_t>(found - kAlphabet);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out += static_cast<char>((buffer >> bits) & 0xff);
    }
  }
  return out;
}

std::vector<std::string_view> Split(std::string_view text, char separator) {
  std::vector<std::string_view> parts;
  size_t start = 0;
  while (true) {
    const size_t end = text.find(separator, start);
    parts.push_back(text.substr(start, end == std::string_view::npos ? end : end - start));
    if (end == std::string_view::npos) return parts;
    start = end + 1;
  }
}

Status Invalid(std::string_view token, const std::string& why) {
  return Status::InvalidArgument("page_token = '" + std::string(token.substr(0, 80)) + "': " + why);
}

}  // namespace

std::string EncodePageToken(const PageCursor& cursor, std::string_view filter) {
  std::string record(kVersion);
  record += '\n';
  record += filter;
  record += '\n';
  record += std::to_string(ToUnixMicros(cursor.created_at));
  record += '\n';
  record += cursor.id;
  record += '\n';
  record += Checksum(record);
  return Base64UrlEncode(record);
}

Result<PageCursor> DecodePageToken(std::string_view token, std::string_view filter) {
  const std::optional<std::string> record = Base64UrlDecode(token);
  if (!record.has_value()) return Invalid(token, "not a token returned by this server");
  const size_t checksum_start =
      record->size() < kChecksumChars ? 0 : record->size() - kChecksumChars;
  if (checksum_start == 0 || Checksum(std::string_view(*record).substr(0, checksum_start)) !=
                                 record->substr(checksum_start)) {
    return Invalid(token, "not a token returned by this server");
  }
  const std::vector<std::string_view> parts =
      Split(std::string_view(*record).substr(0, checksum_start), '\n');
  if (parts.size() != 5 || parts[0] != kVersion || !parts[4].empty()) {
    return Invalid(token, "not a token returned by this server");
  }
  if (parts[1] != filter) {
    return Invalid(token, "was issued for filter '" + std::string(parts[1]) + "', not '" +
                              std::string(filter) + "'");
  }
  int64_t micros = 0;
  const auto [end, error] =
      std::from_chars(parts[2].data(), parts[2].data() + parts[2].size(), micros);
  if (error != std::errc() || end != parts[2].data() + parts[2].size() || parts[3].empty()) {
    return Invalid(token, "not a token returned by this server");
  }
  return PageCursor{FromUnixMicros(micros), std::string(parts[3])};
}

}  // namespace softid::server::store
