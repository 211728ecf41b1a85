// A TLS certificate the server makes for itself, so that a server is encrypted from its first
// start without an operator having to run a certificate authority: a P-256 key and a self-signed
// certificate naming the hosts clients connect by. Clients trust it by its file (like an SSH host
// key, copied once): `softid --tls-ca DATA/tls/server.crt`.
//
// The pair is kept in a folder (the server uses DATA/tls/) and reused on later starts while it
// still matches: key and certificate belong together, the certificate is valid for at least
// another 30 days, and it names every requested host. Otherwise a new pair replaces it (clients
// must then copy the new certificate); the files are written to temporary names and renamed, so a
// crash leaves either the old pair or the new one. Processes sharing the folder take turns (a
// lock file in it), so servers starting together on one volume all serve the pair the first made.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "core/common/status.h"

namespace softid::server {

struct SelfSignedCertificateOptions {
  // Names and addresses clients use to reach the server (DNS names or IPv4/IPv6 literals), put in
  // the certificate's subjectAltName. localhost, 127.0.0.1 and ::1 are always added; the
  // machine's host name is added when the pair is made.
  std::vector<std::string> host_names;
  int valid_days = 825;  // >= 31
  // Where the flag came from, for error messages.
  std::string flag_name = "--tls-hostnames";
};

struct SelfSignedCertificate {
  std::filesystem::path cert_file;  // DIR/server.crt, PEM, mode 0644 (public)
  std::filesystem::path key_file;   // DIR/server.key, PEM, mode 0600
  std::string sha256_fingerprint;   // "AB:CD:..." as `openssl x509 -fingerprint -sha256` prints
  bool created = false;             // made now rather than reused
  // Why an existing pair was replaced (for the log); empty when none existed or it was reused.
  std::string replaced_because;
};

// Whether `name` may go into a subjectAltName: an IP literal, or a DNS name of letters, digits,
// '-' and '.' (a leading "*." allowed), at most 253 characters.
bool IsValidCertificateHostName(const std::string& name);

// The pair in `dir` (created with mode 0700 if missing), reused or made as described above.
// InvalidArgument naming options.flag_name for a bad host name; IoError when files cannot be
// written.
Result<SelfSignedCertificate> EnsureSelfSignedCertificate(
    const std::filesystem::path& dir, const SelfSignedCertificateOptions& options);

}  // namespace softid::server
