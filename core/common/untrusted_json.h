// Parsing JSON that arrives from outside (RPC fields, uploaded files, config files) with bounds on
// its size and nesting depth. nlohmann::json parses iteratively, but copying, printing and
// comparing a value recurse once per nesting level: 100,000 nested arrays in a 200 KB request
// overflow a thread's stack. Every untrusted JSON text goes through ParseUntrustedJson, which
// measures the depth with a SAX pass before it builds anything.
#pragma once

#include <cstddef>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include "core/common/status.h"

namespace softid::json {

struct UntrustedJsonLimits {
  // Longest accepted text [bytes].
  std::size_t max_bytes = 4u << 20;
  // Deepest accepted nesting of arrays and objects (a scalar or an empty array has depth 0, [1]
  // and {"a": 1} depth 1). softid's own formats need at most 5.
  int max_depth = 32;

  // InvalidArgument naming the field when a limit is not positive.
  Status Validate() const;
};

// Parses `text` as one JSON value. InvalidArgument "<field>: ..." when the text is longer than
// limits.max_bytes, nests deeper than limits.max_depth, or is not valid JSON (with the byte
// position of the error). Never throws, never recurses deeper than limits.max_depth.
Result<nlohmann::json> ParseUntrustedJson(std::string_view text, std::string_view field,
                                          const UntrustedJsonLimits& limits = {});

}  // namespace softid::json
