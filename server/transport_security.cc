#include "server/transport_security.h"

#include <grpcpp/security/server_credentials.h>

#include <fstream>
#include <sstream>

#include "server/self_signed_certificate.h"

namespace softid::server {
namespace {

// The file's text, or InvalidArgument "<flag> = <path>: <why>".
Result<std::string> ReadPem(const std::filesystem::path& path, std::string_view flag,
                            std::string_view expected_block) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return Status::InvalidArgument(std::string(flag) + " = " + path.string() + ": cannot be read");
  }
  std::ostringstream text;
  text << in.rdbuf();
  const std::string pem = text.str();
  if (pem.find("-----BEGIN ") == std::string::npos ||
      pem.find(std::string(expected_block)) == std::string::npos) {
    return Status::InvalidArgument(std::string(flag) + " = " + path.string() +
                                   ": not a PEM file with a " + std::string(expected_block));
  }
  return pem;
}

}  // namespace

Status TlsOptions::Validate() const {
  if (cert_file.empty() != key_file.empty()) {
    return Status::InvalidArgument(cert_file.empty() ? "--tls-key is given without --tls-cert"
                                                     : "--tls-cert is given without --tls-key");
  }
  if (!client_ca_file.empty() && !enabled()) {
    return Status::InvalidArgument(
        "--tls-client-ca needs --tls-cert and --tls-key (or --tls-self-signed)");
  }
  if (!host_names.empty() && !self_signed) {
    return Status::InvalidArgument("--tls-hostnames is given without --tls-self-signed");
  }
  for (const std::string& name : host_names) {
    if (!IsValidCertificateHostName(name)) {
      return Status::InvalidArgument("--tls-hostnames = '" + name +
                                     "': not a host name (letters, digits, '-', '.') or an IP "
                                     "address");
    }
  }
  if (cert_file.empty()) return Status::Ok();
  SOFTID_RETURN_IF_ERROR(ReadPem(cert_file, "--tls-cert", "CERTIFICATE").status());
  SOFTID_RETURN_IF_ERROR(ReadPem(key_file, "--tls-key", "PRIVATE KEY").status());
  if (!client_ca_file.empty()) {
    SOFTID_RETURN_IF_ERROR(ReadPem(client_ca_file, "--tls-client-ca", "CERTIFICATE").status());
  }
  return Status::Ok();
}

bool IsLoopbackAddress(std::string_view listen_address) {
  if (listen_address.rfind("unix:", 0) == 0) return true;  // a local socket file
  std::string_view host = listen_address;
  if (!host.empty() && host.front() == '[') {  // "[v6]:port"
    host =
        host.substr(1, host.find(']') == std::string_view::npos ? host.npos : host.find(']') - 1);
  } else if (host.find(':') == host.rfind(':') && host.find(':') != std::string_view::npos) {
    host = host.substr(0, host.find(':'));  // "host:port"
  }
  return host == "localhost" || host == "ip6-localhost" || host == "::1" ||
         host.rfind("127.", 0) == 0;
}

Result<std::shared_ptr<grpc::ServerCredentials>> MakeServerCredentials(const TlsOptions& tls) {
  SOFTID_RETURN_IF_ERROR(tls.Validate());
  if (!tls.enabled()) return grpc::InsecureServerCredentials();
  if (tls.cert_file.empty()) {
    return Status::Internal("the self-signed certificate was not made before listening");
  }
  grpc::SslServerCredentialsOptions options(
      tls.client_ca_file.empty() ? GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE
                                 : GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY);
  SOFTID_ASSIGN_OR_RETURN(const std::string cert,
                          ReadPem(tls.cert_file, "--tls-cert", "CERTIFICATE"));
  SOFTID_ASSIGN_OR_RETURN(const std::string key, ReadPem(tls.key_file, "--tls-key", "PRIVATE KEY"));
  options.pem_key_cert_pairs.push_back({key, cert});
  if (!tls.client_ca_file.empty()) {
    SOFTID_ASSIGN_OR_RETURN(options.pem_root_certs,
                            ReadPem(tls.client_ca_file, "--tls-client-ca", "CERTIFICATE"));
  }
  return grpc::SslServerCredentials(options);
}

}  // namespace softid::server
