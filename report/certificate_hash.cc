// The certificate's content hash (report/certificate.h): SHA-256 over the file's bytes with the
// hash's own digits replaced by zeros, and its verification. Bytes only: no parsing of the HTML
// and no normalisation, so that what is checked is exactly the file -- and so that the check can
// be repeated without turncal:
//   h=$(grep -o 'turncal-certificate-sha256" content="[0-9a-f]*' F.html | cut -d'"' -f3)
//   sed "s/$h/$(printf '0%.0s' $(seq 64))/g" F.html | sha256sum

#include <openssl/evp.h>

#include <cstdlib>
#include <memory>
#include <optional>

#include "report/certificate.h"

namespace turncal::report {

const char* const kCertificateHashPlaceholder =
    "0000000000000000000000000000000000000000000000000000000000000000";

namespace {

constexpr const char* kCertMetaBefore = "<meta name=\"turncal-certificate-sha256\" content=\"";
constexpr const char* kCertVisibleBefore = "id=\"content-hash\">";

bool CertIsHash(const std::string& s) {
  if (s.size() != 64) return false;
  for (char ch : s) {
    if (!((ch >= '0' && ch <= '9') || (ch >= 'a' && ch <= 'f'))) return false;
  }
  return true;
}

// The text after `before` up to `end` (exclusive), or nullopt when `before` is not there.
std::optional<std::string> CertFieldAfter(const std::string& html, const std::string& before,
                                          char end) {
  const std::size_t at = html.find(before);
  if (at == std::string::npos) return std::nullopt;
  const std::size_t from = at + before.size();
  const std::size_t to = html.find(end, from);
  return html.substr(from, to == std::string::npos ? std::string::npos : to - from);
}

}  // namespace

std::string Sha256Hex(const std::string& bytes) {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  std::unique_ptr<EVP_MD_CTX, decltype(&EVP_MD_CTX_free)> ctx(EVP_MD_CTX_new(), EVP_MD_CTX_free);
  // Failing here means OpenSSL cannot allocate or has no SHA-256: nothing input can cause.
  const bool ok = ctx && EVP_DigestInit_ex(ctx.get(), EVP_sha256(), nullptr) == 1 &&
                  EVP_DigestUpdate(ctx.get(), bytes.data(), bytes.size()) == 1 &&
                  EVP_DigestFinal_ex(ctx.get(), digest, &length) == 1;
  if (!ok) std::abort();
  static const char* const kHex = "0123456789abcdef";
  std::string hex;
  for (unsigned int i = 0; i < length; ++i) {
    hex += kHex[digest[i] >> 4];
    hex += kHex[digest[i] & 0xF];
  }
  return hex;
}

CertificateCheck VerifyCertificateHtml(const std::string& html) {
  CertificateCheck check;
  const auto claimed = CertFieldAfter(html, kCertMetaBefore, '"');
  if (!claimed) {
    check.not_a_certificate = true;
    check.reason = "no <meta name=\"turncal-certificate-sha256\">: not a turncal certificate";
    return check;
  }
  check.hash_claimed = *claimed;
  if (!CertIsHash(*claimed)) {
    check.reason = "the hash in the <meta> is not 64 hexadecimal digits";
    return check;
  }
  std::string zeroed = html;
  const std::string placeholder = kCertificateHashPlaceholder;
  for (std::size_t at = zeroed.find(*claimed); at != std::string::npos;
       at = zeroed.find(*claimed, at + placeholder.size())) {
    zeroed.replace(at, claimed->size(), placeholder);
  }
  check.hash_computed = Sha256Hex(zeroed);
  const auto visible = CertFieldAfter(html, kCertVisibleBefore, '<');
  if (!visible) {
    check.reason = "the visible content hash is missing";
  } else if (*visible != *claimed) {
    check.reason = "the visible content hash (" + *visible + ") differs from the <meta>'s";
  } else if (check.hash_computed != *claimed) {
    check.reason = "the content hash does not match: the file was changed after turncal wrote it";
  } else {
    check.ok = true;
  }
  return check;
}

}  // namespace turncal::report
