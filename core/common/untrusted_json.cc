#include "core/common/untrusted_json.h"

#include <fmt/format.h>

#include <cctype>
#include <vector>

namespace softid::json {
namespace {

using nlohmann::json;

// Counts nesting and stops the parse at the first level past the limit; keeps nothing but the
// path to the value being read, so that a syntax error names the field it is in.
class DepthCheck : public nlohmann::json_sax<json> {
 public:
  explicit DepthCheck(int max_depth) : max_depth_(max_depth) {}

  bool null() override { return Value(); }
  bool boolean(bool) override { return Value(); }
  bool number_integer(number_integer_t) override { return Value(); }
  bool number_unsigned(number_unsigned_t) override { return Value(); }
  bool number_float(number_float_t, const string_t&) override { return Value(); }
  bool string(string_t&) override { return Value(); }
  bool binary(binary_t&) override { return Value(); }
  bool key(string_t& name) override {
    path_.back().key = name;
    return true;
  }
  bool start_object(std::size_t) override { return Enter(/*array=*/false); }
  bool end_object() override { return Leave(); }
  bool start_array(std::size_t) override { return Enter(/*array=*/true); }
  bool end_array() override { return Leave(); }
  bool parse_error(std::size_t position, const std::string& last_token,
                   const nlohmann::detail::exception& error) override {
    std::string reason = ShortReason(error.what());
    if (LooksLikeNanOrInfinity(last_token)) reason += " (NaN and Infinity are not JSON numbers)";
    syntax_error_ = fmt::format("invalid JSON at byte {}{}: {}", position, Location(), reason);
    return false;
  }

  bool too_deep() const { return too_deep_; }
  const std::string& syntax_error() const { return syntax_error_; }

 private:
  struct Level {
    bool array = false;
    std::size_t index = 0;  // arrays: elements read so far
    std::string key;        // objects: the last key read
  };

  bool Value() {
    if (!path_.empty() && path_.back().array) ++path_.back().index;
    return true;
  }
  bool Enter(bool array) {
    if (static_cast<int>(path_.size()) >= max_depth_) {
      too_deep_ = true;
      return false;
    }
    path_.push_back({array, 0, {}});
    return true;
  }
  bool Leave() {
    path_.pop_back();
    return Value();
  }
  // " (in cameras[0].fx)", or "" at the top level.
  std::string Location() const {
    std::string where;
    for (const Level& level : path_) {
      if (level.array) {
        where += fmt::format("[{}]", level.index);
      } else if (!level.key.empty()) {
        where += (where.empty() ? "" : ".") + level.key;
      }
    }
    return where.empty() ? "" : " (in " + where + ")";
  }
  // Whether the token that failed starts a NaN or an Infinity ("N", "Na", "-Inf", ...).
  static bool LooksLikeNanOrInfinity(const std::string& last_read) {
    size_t start = last_read.size();
    while (start > 0 && std::isalpha(static_cast<unsigned char>(last_read[start - 1]))) --start;
    const std::string word = last_read.substr(start);
    return !word.empty() &&
           (std::string("NaN").starts_with(word) || std::string("nan").starts_with(word) ||
            std::string("Infinity").starts_with(word) || std::string("inf").starts_with(word));
  }
  // nlohmann's messages start with "[json.exception.parse_error.101] parse error at line 1,
  // column 3: "; the part after that says what was wrong.
  static std::string ShortReason(const std::string& what) {
    const std::size_t colon = what.find(": ");
    return colon == std::string::npos ? what : what.substr(colon + 2);
  }

  int max_depth_;
  std::vector<Level> path_;
  bool too_deep_ = false;
  std::string syntax_error_;
};

}  // namespace

Status UntrustedJsonLimits::Validate() const {
  if (max_bytes == 0)
    return Status::InvalidArgument("UntrustedJsonLimits.max_bytes = 0: must be > 0");
  if (max_depth <= 0) {
    return Status::InvalidArgument(
        fmt::format("UntrustedJsonLimits.max_depth = {}: must be > 0", max_depth));
  }
  return Status::Ok();
}

Result<json> ParseUntrustedJson(std::string_view text, std::string_view field,
                                const UntrustedJsonLimits& limits) {
  SOFTID_RETURN_IF_ERROR(limits.Validate());
  if (text.size() > limits.max_bytes) {
    return Status::InvalidArgument(
        fmt::format("{}: {} bytes: at most {} are accepted", field, text.size(), limits.max_bytes));
  }
  DepthCheck check(limits.max_depth);
  if (!json::sax_parse(text, &check, nlohmann::detail::input_format_t::json, /*strict=*/true)) {
    if (check.too_deep()) {
      return Status::InvalidArgument(fmt::format(
          "{}: nested deeper than {} levels of arrays and objects", field, limits.max_depth));
    }
    return Status::InvalidArgument(fmt::format("{}: {}", field, check.syntax_error()));
  }
  // Valid and shallow: the DOM parse cannot fail now.
  json value = json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (value.is_discarded()) return Status::InvalidArgument(fmt::format("{}: invalid JSON", field));
  return value;
}

}  // namespace softid::json
