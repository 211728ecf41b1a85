#include "server/store/progress_event.h"

namespace softid::server::store {

const char* ToString(ProgressKind kind) {
  switch (kind) {
    case ProgressKind::kIteration: return "iteration";
    case ProgressKind::kState: return "state";
  }
  return "unknown";
}

Result<ProgressKind> ProgressKindFromString(std::string_view text) {
  if (text == "iteration") return ProgressKind::kIteration;
  if (text == "state") return ProgressKind::kState;
  return Status::InvalidArgument("progress event = '" + std::string(text.substr(0, 40)) +
                                 "': must be 'iteration' or 'state'");
}

}  // namespace softid::server::store
