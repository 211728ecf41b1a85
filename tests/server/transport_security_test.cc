// TLS on the server's port, in process over loopback: certificates made with the openssl tool
// into a temporary folder, a server with and without client-certificate checks, clients with
// the right CA, a wrong CA, no TLS and (for mutual TLS) with and without a certificate.
#include "server/transport_security.h"

#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include <cstdlib>
#include <fstream>
#include <iterator>
#include <memory>
#include <sstream>
#include <string>

#include "client/channel_credentials.h"
#include "client/reconstruction_client.h"
#include "server/server.h"
#include "tests/server/temp_dir.h"

namespace softid::server {
namespace {

namespace fs = std::filesystem;
using store::testing::TempDir;

TEST(TransportSecurity, LoopbackAddressesAreRecognised) {
  for (const char* address : {"localhost:50051", "127.0.0.1:0", "127.1.2.3:9", "[::1]:50051", "::1",
                              "unix:/tmp/softid.sock", "localhost"}) {
    EXPECT_TRUE(IsLoopbackAddress(address)) << address;
  }
  for (const char* address :
       {"0.0.0.0:50051", "[::]:50051", "10.0.0.7:50051", "softid.example.org:443", "128.0.0.1:1"}) {
    EXPECT_FALSE(IsLoopbackAddress(address)) << address;
  }
}

// Plain text on a network address needs the operator's explicit word; TLS flags are checked.
TEST(TransportSecurity, ServerOptionsRefuseAccidentalPlainText) {
  TempDir data;
  ServerOptions options;
  options.data_dir = data.path();
  options.listen_address = "0.0.0.0:0";
  const Status refused = options.Validate();
  EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(refused.message().find("listen = 0.0.0.0:0: not a loopback address"), std::string::npos)
      << refused.message();
  options.allow_insecure = true;
  EXPECT_TRUE(options.Validate().ok());

  options.tls.cert_file = data.path() / "missing.pem";
  EXPECT_NE(options.Validate().message().find("--tls-cert is given without --tls-key"),
            std::string::npos);
  options.tls.key_file = data.path() / "missing.key";
  EXPECT_NE(options.Validate().message().find("--tls-cert = "), std::string::npos)
      << options.Validate().message();
  std::ofstream(data.path() / "not.pem") << "hello";
  options.tls.cert_file = data.path() / "not.pem";
  EXPECT_NE(options.Validate().message().find("not a PEM file with a CERTIFICATE"),
            std::string::npos)
      << options.Validate().message();
}

// Client TLS settings: trust `ca`, and present `cert` (with its key) when given.
client::TlsClientOptions Trusting(const fs::path& dir, const std::string& ca,
                                  const std::string& cert = "") {
  client::TlsClientOptions tls;
  tls.ca_file = (dir / (ca + ".pem")).string();
  if (!cert.empty()) {
    tls.cert_file = (dir / (cert + ".pem")).string();
    tls.key_file = (dir / (cert + ".key")).string();
  }
  return tls;
}

class TlsServerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { spdlog::set_level(spdlog::level::warn); }

  void SetUp() override {
    const fs::path d = certs_.path();
    // Two CAs (one the server's, one a stranger), a server certificate for localhost and a
    // client certificate, all signed by the first CA; P-256 keys are quick to make.
    const std::string key = "-newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes";
    const std::string script =
        "cd '" + d.string() + "' && " + "openssl req -x509 " + key +
        " -keyout ca.key -out ca.pem -days 2 -subj /CN=ca && " + "openssl req -x509 " + key +
        " -keyout other.key -out other.pem -days 2 -subj /CN=other && " + "openssl req " + key +
        " -keyout server.key -out server.csr -subj /CN=localhost && " +
        "printf 'subjectAltName=DNS:localhost,IP:127.0.0.1\\n' > server.ext && " +
        "openssl x509 -req -in server.csr -CA ca.pem -CAkey ca.key -CAcreateserial " +
        "-out server.pem -days 2 -extfile server.ext && " + "openssl req " + key +
        " -keyout client.key -out client.csr -subj /CN=station-1 && " +
        "openssl x509 -req -in client.csr -CA ca.pem -CAkey ca.key -CAcreateserial " +
        "-out client.pem -days 2 > /dev/null 2>&1";
    ASSERT_EQ(std::system((script + " > /dev/null 2>&1").c_str()), 0) << "openssl failed";
  }

  void StartServer(bool require_client_certificate, bool self_signed = false,
                   bool own_certificate = true) {
    ServerOptions options;
    options.listen_address = "localhost:0";
    options.data_dir = data_.path();
    options.num_workers = 0;
    options.shutdown_grace = std::chrono::milliseconds(200);
    options.tls.self_signed = self_signed;
    if (own_certificate) {
      options.tls.cert_file = certs_.path() / "server.pem";
      options.tls.key_file = certs_.path() / "server.key";
    }
    if (require_client_certificate) options.tls.client_ca_file = certs_.path() / "ca.pem";
    Result<std::unique_ptr<Server>> server = Server::Start(options);
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(*server);
  }

  // The health answer through a client with `tls`, or its gRPC error code.
  grpc::StatusCode Health(const client::TlsClientOptions& tls) {
    std::string error;
    std::shared_ptr<grpc::ChannelCredentials> credentials =
        client::MakeChannelCredentials(tls, &error);
    EXPECT_TRUE(credentials) << error;
    client::ClientOptions options;
    options.retry_budget = std::chrono::milliseconds(0);
    options.call_timeout = std::chrono::milliseconds(3000);
    client::ReconstructionClient client(
        grpc::CreateChannel("localhost:" + std::to_string(server_->port()), credentials), options);
    client::ServingStatus serving = client::ServingStatus::kUnknown;
    const grpc::Status status = client.Health("", &serving);
    if (status.ok()) {
      EXPECT_EQ(serving, client::ServingStatus::kServing);
    }
    return status.error_code();
  }

  void TearDown() override {
    if (server_) {
      ASSERT_TRUE(server_->Shutdown().ok());
    }
  }

  TempDir certs_, data_;
  std::unique_ptr<Server> server_;
};

TEST_F(TlsServerTest, OnlyClientsTrustingTheServersCaConnect) {
  StartServer(/*require_client_certificate=*/false);
  EXPECT_EQ(Health(Trusting(certs_.path(), "ca")), grpc::StatusCode::OK);
  EXPECT_NE(Health(Trusting(certs_.path(), "other")), grpc::StatusCode::OK);
  EXPECT_NE(Health({}), grpc::StatusCode::OK);  // plain text to a TLS port
}

TEST_F(TlsServerTest, MutualTlsRequiresAClientCertificateFromTheCa) {
  StartServer(/*require_client_certificate=*/true);
  EXPECT_NE(Health(Trusting(certs_.path(), "ca")), grpc::StatusCode::OK);
  EXPECT_EQ(Health(Trusting(certs_.path(), "ca", "client")), grpc::StatusCode::OK);
  // A certificate signed by another CA is refused.
  EXPECT_NE(Health(Trusting(certs_.path(), "ca", "other")), grpc::StatusCode::OK);
}

// With --tls-self-signed the first start makes DATA/tls/server.crt; clients that trust that file
// connect, others do not, and a restart keeps the same certificate.
TEST_F(TlsServerTest, SelfSignedCertificateIsMadeOnceAndTrustedByItsFile) {
  StartServer(/*require_client_certificate=*/false, /*self_signed=*/true,
              /*own_certificate=*/false);
  const fs::path cert = data_.path() / "tls" / "server.crt";
  ASSERT_TRUE(fs::exists(cert));
  client::TlsClientOptions trusting;
  trusting.ca_file = cert.string();
  EXPECT_EQ(Health(trusting), grpc::StatusCode::OK);
  EXPECT_NE(Health(Trusting(certs_.path(), "ca")), grpc::StatusCode::OK);
  EXPECT_NE(Health({}), grpc::StatusCode::OK);

  std::ifstream first_in(cert);
  const std::string first((std::istreambuf_iterator<char>(first_in)), {});
  ASSERT_TRUE(server_->Shutdown().ok());
  StartServer(/*require_client_certificate=*/false, /*self_signed=*/true,
              /*own_certificate=*/false);
  std::ifstream second_in(cert);
  EXPECT_EQ(std::string((std::istreambuf_iterator<char>(second_in)), {}), first);
  EXPECT_EQ(Health(trusting), grpc::StatusCode::OK);

  // The operator's own certificate takes precedence over the self-signed default.
  ASSERT_TRUE(server_->Shutdown().ok());
  StartServer(/*require_client_certificate=*/false, /*self_signed=*/true,
              /*own_certificate=*/true);
  EXPECT_EQ(Health(Trusting(certs_.path(), "ca")), grpc::StatusCode::OK);
  EXPECT_NE(Health(trusting), grpc::StatusCode::OK);
}

TEST(TransportSecurity, SelfSignedHostNamesAreChecked) {
  TempDir data;
  ServerOptions options;
  options.data_dir = data.path();
  options.listen_address = "0.0.0.0:0";
  options.tls.self_signed = true;
  EXPECT_TRUE(options.Validate().ok()) << options.Validate().message();
  options.tls.host_names = {"bad name"};
  EXPECT_NE(options.Validate().message().find("--tls-hostnames = 'bad name'"), std::string::npos)
      << options.Validate().message();
  options.tls.self_signed = false;
  options.tls.host_names = {"softid.example"};
  EXPECT_NE(options.Validate().message().find("--tls-hostnames is given without"),
            std::string::npos)
      << options.Validate().message();
}

}  // namespace
}  // namespace softid::server
