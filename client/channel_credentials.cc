#include "client/channel_credentials.h"

#include <fstream>
#include <sstream>

namespace softid::client {
namespace {

bool ReadFile(const std::string& path, const char* flag, std::string* text, std::string* error) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    *error = std::string(flag) + " = " + path + ": cannot be read";
    return false;
  }
  std::ostringstream bytes;
  bytes << in.rdbuf();
  *text = bytes.str();
  return true;
}

}  // namespace

std::shared_ptr<grpc::ChannelCredentials> MakeChannelCredentials(const TlsClientOptions& options,
                                                                 std::string* error) {
  const bool tls = options.enabled || !options.ca_file.empty() || !options.cert_file.empty();
  if (!tls) return grpc::InsecureChannelCredentials();
  if (options.cert_file.empty() != options.key_file.empty()) {
    *error = "--tls-cert and --tls-key go together";
    return nullptr;
  }
  grpc::SslCredentialsOptions ssl;
  if (!options.ca_file.empty() &&
      !ReadFile(options.ca_file, "--tls-ca", &ssl.pem_root_certs, error)) {
    return nullptr;
  }
  if (!options.cert_file.empty() &&
      (!ReadFile(options.cert_file, "--tls-cert", &ssl.pem_cert_chain, error) ||
       !ReadFile(options.key_file, "--tls-key", &ssl.pem_private_key, error))) {
    return nullptr;
  }
  return grpc::SslCredentials(ssl);
}

}  // namespace softid::client
