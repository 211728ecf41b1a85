// Who makes a call: the station an API token belongs to, or the operator when the server runs
// without authentication. The job service checks every capture and job against it: a station
// sees, watches, cancels and deletes only what it created; an admin token and the operator see
// everything. Another station's resources answer NOT_FOUND, exactly like missing ones.
#pragma once

#include <string>

namespace softid::server {

struct Caller {
  std::string station;  // owner recorded on what this caller creates; empty for the operator
  bool admin = false;   // sees every station's captures and jobs

  // The caller of a server without authentication: owns "" and sees everything.
  static Caller Operator() { return Caller{"", true}; }
  // Whether the caller may see a resource owned by `owner`.
  bool Sees(const std::string& owner) const { return admin || owner == station; }
};

}  // namespace softid::server
