// The server's own TLS certificate: made once, reused while it fits, replaced when it does not,
// its key private; checked with the openssl tool where a second opinion is cheap.
#include "server/self_signed_certificate.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "tests/server/temp_dir.h"

namespace softid::server {
namespace {

namespace fs = std::filesystem;
using store::testing::TempDir;

// What `command` printed on stdout.
std::string CommandOutput(const std::string& command) {
  std::string out;
  FILE* pipe = ::popen(command.c_str(), "r");
  if (pipe == nullptr) return out;
  char buffer[4096];
  size_t n = 0;
  while ((n = std::fread(buffer, 1, sizeof(buffer), pipe)) > 0) out.append(buffer, n);
  ::pclose(pipe);
  return out;
}

unsigned Mode(const fs::path& path) {
  struct stat info {};
  ::stat(path.c_str(), &info);
  return info.st_mode & 0777;
}

TEST(SelfSignedCertificate, MadeOnceWithAPrivateKeyThenReused) {
  TempDir data;
  const fs::path dir = data.path() / "tls";
  SelfSignedCertificateOptions options;
  options.host_names = {"softid.lab.example", "10.1.2.3"};
  Result<SelfSignedCertificate> made = EnsureSelfSignedCertificate(dir, options);
  ASSERT_TRUE(made.ok()) << made.status().ToString();
  EXPECT_TRUE(made->created);
  EXPECT_TRUE(made->replaced_because.empty());
  EXPECT_EQ(Mode(made->key_file), 0600u);
  EXPECT_EQ(Mode(made->cert_file), 0644u);
  EXPECT_EQ(Mode(dir), 0700u);
  EXPECT_EQ(made->sha256_fingerprint.size(), 32u * 3 - 1) << made->sha256_fingerprint;

  // openssl agrees on the fingerprint and finds every name, and the key matches.
  std::string cert = "'";  // (appended, not "'" + ...: GCC 12 warns falsely on that)
  cert.append(made->cert_file.string()).append("'");
  EXPECT_NE(CommandOutput("openssl x509 -noout -fingerprint -sha256 -in " + cert)
                .find(made->sha256_fingerprint),
            std::string::npos);
  const std::string text = CommandOutput("openssl x509 -noout -text -in " + cert);
  for (const char* name : {"DNS:localhost", "IP Address:127.0.0.1", "DNS:softid.lab.example",
                           "IP Address:10.1.2.3", "CA:TRUE", "TLS Web Server Authentication"}) {
    EXPECT_NE(text.find(name), std::string::npos) << name << " missing in\n" << text;
  }
  EXPECT_EQ(CommandOutput("openssl verify -CAfile " + cert + " " + cert + " 2>&1"),
            made->cert_file.string() + ": OK\n");

  Result<SelfSignedCertificate> again = EnsureSelfSignedCertificate(dir, options);
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  EXPECT_FALSE(again->created);
  EXPECT_EQ(again->sha256_fingerprint, made->sha256_fingerprint);
  // Fewer names than it has: still fits.
  options.host_names = {"10.1.2.3"};
  EXPECT_FALSE(EnsureSelfSignedCertificate(dir, options)->created);
}

// Servers starting together on one empty volume (pods of a Deployment) take turns: one makes the
// pair, every other reuses it, and all serve the certificate that is in the folder.
TEST(SelfSignedCertificate, ServersStartingTogetherShareOnePair) {
  TempDir data;
  const fs::path dir = data.path() / "tls";
  constexpr int kServers = 8;
  std::vector<Result<SelfSignedCertificate>> results(kServers, Status::Internal("not run"));
  {
    std::vector<std::jthread> servers;
    for (int i = 0; i < kServers; ++i) {
      servers.emplace_back([&, i] { results[i] = EnsureSelfSignedCertificate(dir, {}); });
    }
  }
  int created = 0;
  for (const Result<SelfSignedCertificate>& result : results) {
    ASSERT_TRUE(result.ok()) << result.status().ToString();
    created += result->created ? 1 : 0;
    EXPECT_EQ(result->sha256_fingerprint, results[0]->sha256_fingerprint);
  }
  EXPECT_EQ(created, 1);
  Result<SelfSignedCertificate> after = EnsureSelfSignedCertificate(dir, {});
  ASSERT_TRUE(after.ok());
  EXPECT_FALSE(after->created);
  EXPECT_EQ(after->sha256_fingerprint, results[0]->sha256_fingerprint);
}

TEST(SelfSignedCertificate, ReplacedWhenItNoLongerFits) {
  TempDir data;
  const fs::path dir = data.path() / "tls";
  SelfSignedCertificateOptions options;
  const SelfSignedCertificate first = *EnsureSelfSignedCertificate(dir, options);

  options.host_names = {"new-name.example"};
  Result<SelfSignedCertificate> renamed = EnsureSelfSignedCertificate(dir, options);
  ASSERT_TRUE(renamed.ok());
  EXPECT_TRUE(renamed->created);
  EXPECT_NE(renamed->replaced_because.find("does not name new-name.example"), std::string::npos)
      << renamed->replaced_because;
  EXPECT_NE(renamed->sha256_fingerprint, first.sha256_fingerprint);

  // A key from another pair (as a crash between the two renames would leave).
  TempDir other;
  const SelfSignedCertificate stranger = *EnsureSelfSignedCertificate(other.path(), options);
  fs::copy_file(stranger.key_file, dir / "server.key", fs::copy_options::overwrite_existing);
  Result<SelfSignedCertificate> mismatched = EnsureSelfSignedCertificate(dir, options);
  ASSERT_TRUE(mismatched.ok());
  EXPECT_TRUE(mismatched->created);
  EXPECT_EQ(mismatched->replaced_because, "the key does not match the certificate");

  std::ofstream(dir / "server.crt") << "garbage";
  Result<SelfSignedCertificate> garbled = EnsureSelfSignedCertificate(dir, options);
  ASSERT_TRUE(garbled.ok());
  EXPECT_TRUE(garbled->created);
  EXPECT_FALSE(fs::exists(dir / "server.crt.tmp"));
  EXPECT_FALSE(fs::exists(dir / "server.key.tmp"));
}

TEST(SelfSignedCertificate, BadHostNamesAreRefusedByName) {
  TempDir data;
  SelfSignedCertificateOptions options;
  for (const char* bad : {"a,DNS:evil.example", "two words", "", "a..b", "-\n", ".example"}) {
    options.host_names = {bad};
    Result<SelfSignedCertificate> refused = EnsureSelfSignedCertificate(data.path(), options);
    ASSERT_FALSE(refused.ok()) << bad;
    EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(refused.status().message().find("--tls-hostnames = '" + std::string(bad) + "'"),
              std::string::npos)
        << refused.status().message();
  }
  EXPECT_FALSE(fs::exists(data.path() / "server.key"));
  for (const char* good : {"localhost", "*.lab.example", "::ffff:10.0.0.1", "host-7.example"}) {
    EXPECT_TRUE(IsValidCertificateHostName(good)) << good;
  }
}

}  // namespace
}  // namespace softid::server
