// How the server's port is protected: TLS with a certificate and key (PEM files), optionally
// requiring client certificates signed by a CA (mutual TLS). Without TLS the server serves in
// plain text only on a loopback address, unless the operator says otherwise (allow_insecure):
// tokens and captures must not cross a network unencrypted by accident.
#pragma once

#include <grpcpp/security/server_credentials.h>

#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/status.h"

namespace softid::server {

struct TlsOptions {
  std::filesystem::path cert_file;  // server certificate chain, PEM; empty: no TLS
  std::filesystem::path key_file;   // its private key, PEM; required with cert_file
  // CA bundle (PEM) that client certificates must chain to; empty: no client certificates asked.
  std::filesystem::path client_ca_file;
  // When cert_file is empty: serve TLS with a certificate the server makes and keeps in
  // DATA/tls/ (self_signed_certificate.h), naming these hosts besides localhost; Server::Start
  // fills cert_file and key_file with its files. A given cert_file takes precedence, so an image
  // can default to self-signed and an operator can still mount a certificate of their own.
  bool self_signed = false;
  std::vector<std::string> host_names;

  bool enabled() const { return !cert_file.empty() || self_signed; }
  // InvalidArgument naming the flag (--tls-cert, --tls-key, --tls-client-ca) when a file is
  // missing, unreadable or not PEM, or only one of cert and key is given; a bad host name.
  Status Validate() const;
};

// Whether "host:port" names a loopback host (localhost, 127.0.0.0/8, ::1).
bool IsLoopbackAddress(std::string_view listen_address);

// TLS credentials from `tls` (validated), or plain-text ones when TLS is off.
Result<std::shared_ptr<grpc::ServerCredentials>> MakeServerCredentials(const TlsOptions& tls);

}  // namespace softid::server
