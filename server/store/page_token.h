// Opaque keyset-pagination tokens (AIP-158): a token records the sort key of the last item of the
// page, (created_at, id), so the next page starts strictly after it. Unlike OFFSET, a page stays
// correct when jobs are added or deleted in between, and costs an index seek however deep it is.
//
// The token also records the list's filter, and a token used with a different filter is rejected
// (AIP-158: the other request fields must match). The encoding (base64url of a small text record)
// is not a contract: clients must treat tokens as opaque. A checksum catches truncated or edited
// tokens.
#pragma once

#include <string>
#include <string_view>

#include "core/common/status.h"
#include "server/store/timestamp.h"

namespace softid::server::store {

struct PageCursor {
  Timestamp created_at{};
  std::string id;

  bool operator==(const PageCursor&) const = default;
};

// `filter` is a canonical rendering of the list request's filter, e.g. "state=QUEUED" or "".
std::string EncodePageToken(const PageCursor& cursor, std::string_view filter);
// InvalidArgument "page_token = '...': ..." for a token this code did not produce, or one made for
// another filter.
Result<PageCursor> DecodePageToken(std::string_view token, std::string_view filter);

}  // namespace softid::server::store
