#include "server/self_signed_certificate.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <openssl/bio.h>
#include <openssl/bn.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/x509.h>
#include <openssl/x509v3.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <memory>
#include <sstream>
#include <utility>

namespace softid::server {
namespace {

namespace fs = std::filesystem;

template <typename T, void (*Free)(T*)>
struct Deleter {
  void operator()(T* p) const { Free(p); }
};
using KeyPtr = std::unique_ptr<EVP_PKEY, Deleter<EVP_PKEY, EVP_PKEY_free>>;
using CertPtr = std::unique_ptr<X509, Deleter<X509, X509_free>>;
using BioPtr = std::unique_ptr<BIO, Deleter<BIO, BIO_free_all>>;
using BigNumPtr = std::unique_ptr<BIGNUM, Deleter<BIGNUM, BN_free>>;

constexpr int kRenewBeforeDays = 30;

bool IsIpLiteral(const std::string& name) {
  unsigned char buffer[16];
  return inet_pton(AF_INET, name.c_str(), buffer) == 1 ||
         inet_pton(AF_INET6, name.c_str(), buffer) == 1;
}

std::vector<std::string> AllHostNames(const SelfSignedCertificateOptions& options) {
  std::vector<std::string> names = {"localhost", "127.0.0.1", "::1"};
  for (const std::string& name : options.host_names) {
    if (std::find(names.begin(), names.end(), name) == names.end()) names.push_back(name);
  }
  return names;
}

std::string ReadText(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

KeyPtr ParseKey(const std::string& pem) {
  BioPtr bio(BIO_new_mem_buf(pem.data(), static_cast<int>(pem.size())));
  return KeyPtr(PEM_read_bio_PrivateKey(bio.get(), nullptr, nullptr, nullptr));
}

CertPtr ParseCert(const std::string& pem) {
  BioPtr bio(BIO_new_mem_buf(pem.data(), static_cast<int>(pem.size())));
  return CertPtr(PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr));
}

// Empty when the existing pair can be reused, else why not (for the log).
std::string WhyNotReusable(X509* cert, EVP_PKEY* key, const std::vector<std::string>& names) {
  if (cert == nullptr || key == nullptr) return "no readable key and certificate";
  if (X509_check_private_key(cert, key) != 1) return "the key does not match the certificate";
  if (X509_cmp_time(X509_get0_notBefore(cert), nullptr) > 0) return "not valid yet";
  const time_t renew_after = time(nullptr) + static_cast<time_t>(kRenewBeforeDays) * 86400;
  time_t horizon = renew_after;
  if (X509_cmp_time(X509_get0_notAfter(cert), &horizon) < 0) return "it expires within 30 days";
  for (const std::string& name : names) {
    const bool named = IsIpLiteral(name)
                           ? X509_check_ip_asc(cert, name.c_str(), 0) == 1
                           : X509_check_host(cert, name.c_str(), name.size(), 0, nullptr) == 1;
    if (!named) return "it does not name " + name;
  }
  return "";
}

Status AddExtension(X509* cert, int nid, const std::string& value) {
  X509V3_CTX context;
  X509V3_set_ctx_nodb(&context);
  X509V3_set_ctx(&context, cert, cert, nullptr, nullptr, 0);
  X509_EXTENSION* extension = X509V3_EXT_conf_nid(nullptr, &context, nid, value.c_str());
  if (extension == nullptr) {
    return Status::Internal("cannot make certificate extension " + value);
  }
  const int added = X509_add_ext(cert, extension, -1);
  X509_EXTENSION_free(extension);
  return added == 1 ? Status::Ok() : Status::Internal("cannot add certificate extension " + value);
}

std::string SubjectAltNames(const std::vector<std::string>& names) {
  std::string text;
  for (const std::string& name : names) {
    if (!text.empty()) text += ",";
    text += (IsIpLiteral(name) ? "IP:" : "DNS:") + name;
  }
  return text;
}

Result<CertPtr> MakeCertificate(EVP_PKEY* key, const std::vector<std::string>& names,
                                int valid_days) {
  CertPtr cert(X509_new());
  BigNumPtr serial(BN_new());
  if (!cert || !serial || X509_set_version(cert.get(), 2) != 1 ||
      BN_rand(serial.get(), 127, BN_RAND_TOP_ANY, BN_RAND_BOTTOM_ANY) != 1 ||
      BN_to_ASN1_INTEGER(serial.get(), X509_get_serialNumber(cert.get())) == nullptr) {
    return Status::Internal("cannot start a certificate");
  }
  // An hour's margin for clients whose clocks run behind.
  X509_gmtime_adj(X509_getm_notBefore(cert.get()), -3600);
  X509_gmtime_adj(X509_getm_notAfter(cert.get()), static_cast<long>(valid_days) * 86400);
  X509_set_pubkey(cert.get(), key);
  X509_NAME* subject = X509_get_subject_name(cert.get());
  X509_NAME_add_entry_by_txt(subject, "O", MBSTRING_ASC,
                             reinterpret_cast<const unsigned char*>("softid"), -1, -1, 0);
  X509_NAME_add_entry_by_txt(subject, "CN", MBSTRING_ASC,
                             reinterpret_cast<const unsigned char*>("softid-server"), -1, -1, 0);
  X509_set_issuer_name(cert.get(), subject);
  // Clients use the certificate itself as their trust anchor, so it is its own CA (pathlen 0:
  // it signs nothing else).
  SOFTID_RETURN_IF_ERROR(
      AddExtension(cert.get(), NID_basic_constraints, "critical,CA:TRUE,pathlen:0"));
  SOFTID_RETURN_IF_ERROR(
      AddExtension(cert.get(), NID_key_usage, "critical,digitalSignature,keyCertSign"));
  SOFTID_RETURN_IF_ERROR(AddExtension(cert.get(), NID_ext_key_usage, "serverAuth"));
  SOFTID_RETURN_IF_ERROR(AddExtension(cert.get(), NID_subject_key_identifier, "hash"));
  SOFTID_RETURN_IF_ERROR(AddExtension(cert.get(), NID_subject_alt_name, SubjectAltNames(names)));
  if (X509_sign(cert.get(), key, EVP_sha256()) == 0) {
    return Status::Internal("cannot sign the certificate");
  }
  return cert;
}

std::string Fingerprint(X509* cert) {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  X509_digest(cert, EVP_sha256(), digest, &length);
  std::string text;
  char byte[4];
  for (unsigned int i = 0; i < length; ++i) {
    std::snprintf(byte, sizeof(byte), i == 0 ? "%02X" : ":%02X", digest[i]);
    text += byte;
  }
  return text;
}

template <typename Write>
Result<std::string> ToPem(Write write) {
  BioPtr bio(BIO_new(BIO_s_mem()));
  if (!bio || write(bio.get()) != 1) return Status::Internal("cannot write PEM");
  char* data = nullptr;
  const long size = BIO_get_mem_data(bio.get(), &data);
  return std::string(data, static_cast<size_t>(size));
}

// An exclusive lock on DIR/.lock while held: processes sharing the folder (pods starting
// together on one volume) decide and write one at a time, so the later ones reuse the pair the
// first made instead of each replacing the others'.
class FolderLock {
 public:
  static Result<FolderLock> Take(const fs::path& dir) {
    const fs::path path = dir / ".lock";
    const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600);
    if (fd < 0)
      return Status::IoError("cannot open " + path.string() + ": " + std::strerror(errno));
    while (::flock(fd, LOCK_EX) != 0) {
      if (errno == EINTR) continue;
      const std::string why = std::strerror(errno);
      ::close(fd);
      return Status::IoError("cannot lock " + path.string() + ": " + why);
    }
    return FolderLock(fd);
  }
  FolderLock(FolderLock&& other) noexcept : fd_(std::exchange(other.fd_, -1)) {}
  FolderLock& operator=(FolderLock&&) = delete;
  ~FolderLock() {
    if (fd_ >= 0) ::close(fd_);  // releases the lock
  }

 private:
  explicit FolderLock(int fd) : fd_(fd) {}
  int fd_;
};

// Writes `text` to `path` with `perms`, through a temporary file in the same folder.
Status WriteFileAtomically(const fs::path& path, const std::string& text, fs::perms perms) {
  const fs::path temporary = path.string() + ".tmp";
  {
    std::ofstream out(temporary, std::ios::binary | std::ios::trunc);
    out << text;
    if (!out.flush()) return Status::IoError("cannot write " + temporary.string());
  }
  std::error_code error;
  fs::permissions(temporary, perms, fs::perm_options::replace, error);
  if (!error) fs::rename(temporary, path, error);
  if (error) return Status::IoError("cannot write " + path.string() + ": " + error.message());
  return Status::Ok();
}

std::string LocalHostName() {
  char name[256] = {};
  if (::gethostname(name, sizeof(name) - 1) != 0) return "";
  return IsValidCertificateHostName(name) ? name : "";
}

}  // namespace

bool IsValidCertificateHostName(const std::string& name) {
  if (name.empty() || name.size() > 253) return false;
  if (IsIpLiteral(name)) return true;
  const std::string labels = name.rfind("*.", 0) == 0 ? name.substr(2) : name;
  if (labels.empty() || labels.front() == '.' || labels.back() == '.' ||
      labels.find("..") != std::string::npos) {
    return false;
  }
  return std::all_of(labels.begin(), labels.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '-' ||
           c == '.';
  });
}

Result<SelfSignedCertificate> EnsureSelfSignedCertificate(
    const fs::path& dir, const SelfSignedCertificateOptions& options) {
  for (const std::string& name : options.host_names) {
    if (!IsValidCertificateHostName(name)) {
      return Status::InvalidArgument(options.flag_name + " = '" + name +
                                     "': not a host name (letters, digits, '-', '.') or an IP "
                                     "address");
    }
  }
  if (options.valid_days <= kRenewBeforeDays) {
    return Status::InvalidArgument("valid_days = " + std::to_string(options.valid_days) +
                                   ": must exceed " + std::to_string(kRenewBeforeDays));
  }
  std::error_code error;
  fs::create_directories(dir, error);
  if (!error) fs::permissions(dir, fs::perms::owner_all, fs::perm_options::replace, error);
  if (error) return Status::IoError("cannot create " + dir.string() + ": " + error.message());

  SOFTID_ASSIGN_OR_RETURN(const FolderLock lock, FolderLock::Take(dir));
  SelfSignedCertificate result;
  result.cert_file = dir / "server.crt";
  result.key_file = dir / "server.key";
  const std::vector<std::string> names = AllHostNames(options);
  CertPtr cert = ParseCert(ReadText(result.cert_file));
  KeyPtr key = ParseKey(ReadText(result.key_file));
  const std::string why_not = WhyNotReusable(cert.get(), key.get(), names);
  if (why_not.empty()) {
    result.sha256_fingerprint = Fingerprint(cert.get());
    return result;
  }
  if (fs::exists(result.cert_file) || fs::exists(result.key_file)) {
    result.replaced_because = why_not;
  }

  std::vector<std::string> new_names = names;
  const std::string host = LocalHostName();
  if (!host.empty() && std::find(names.begin(), names.end(), host) == names.end()) {
    new_names.push_back(host);
  }
  key.reset(EVP_EC_gen("P-256"));
  if (!key) return Status::Internal("cannot make a P-256 key");
  SOFTID_ASSIGN_OR_RETURN(cert, MakeCertificate(key.get(), new_names, options.valid_days));
  SOFTID_ASSIGN_OR_RETURN(const std::string key_pem, ToPem([&](BIO* bio) {
                            return PEM_write_bio_PrivateKey(bio, key.get(), nullptr, nullptr, 0,
                                                            nullptr, nullptr);
                          }));
  SOFTID_ASSIGN_OR_RETURN(const std::string cert_pem,
                          ToPem([&](BIO* bio) { return PEM_write_bio_X509(bio, cert.get()); }));
  // Key first: a crash between the renames leaves a pair that does not match, which the next
  // start replaces.
  SOFTID_RETURN_IF_ERROR(WriteFileAtomically(result.key_file, key_pem,
                                             fs::perms::owner_read | fs::perms::owner_write));
  SOFTID_RETURN_IF_ERROR(WriteFileAtomically(result.cert_file, cert_pem,
                                             fs::perms::owner_read | fs::perms::owner_write |
                                                 fs::perms::group_read | fs::perms::others_read));
  result.sha256_fingerprint = Fingerprint(cert.get());
  result.created = true;
  return result;
}

}  // namespace softid::server
