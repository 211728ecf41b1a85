// The client's side of transport security: TLS when the station is given the server's CA (or
// asks for TLS with the system's roots), with its own certificate and key for mutual TLS;
// plain text otherwise.
#pragma once

#include <grpcpp/security/credentials.h>

#include <memory>
#include <string>

namespace softid::client {

struct TlsClientOptions {
  bool enabled = false;   // TLS with the system's root certificates unless ca_file is set
  std::string ca_file;    // PEM bundle the server's certificate must chain to; implies TLS
  std::string cert_file;  // client certificate (PEM), for servers that require one
  std::string key_file;   // its private key (PEM)
};

// Credentials for `options`, or null with `error` naming the flag and file that could not be
// read.
std::shared_ptr<grpc::ChannelCredentials> MakeChannelCredentials(const TlsClientOptions& options,
                                                                 std::string* error);

}  // namespace softid::client
