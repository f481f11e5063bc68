#include "server/page_token.h"

#include <openssl/evp.h>
#include <openssl/rand.h>

#include <algorithm>

#include "absl/strings/ascii.h"
#include "absl/strings/escaping.h"
#include "absl/strings/str_cat.h"
#include "proto/api/sha256.h"

namespace radiosity::service {
namespace {

constexpr int kDefaultPageSize = 50;
constexpr int kMaxPageSize = 1000;

// A tenant's tag in its page tokens: the first 8 bytes of SHA-256(tenant).
uint64_t TenantTag(const std::string& tenant) {
  const std::string bytes = absl::HexStringToBytes(Sha256Hex(tenant).substr(0, 16));
  uint64_t tag = 0;
  for (unsigned char c : bytes) tag = tag << 8 | c;
  return tag;
}

// One AES-128 block (a pseudo-random permutation of 16 bytes) with the store's page key.
bool AesBlock(const std::string& key, bool encrypt, const unsigned char in[16],
              unsigned char out[16]) {
  EVP_CIPHER_CTX* ctx = EVP_CIPHER_CTX_new();
  if (ctx == nullptr) return false;
  int n = 0, m = 0;
  const auto* k = reinterpret_cast<const unsigned char*>(key.data());
  const bool ok =
      EVP_CipherInit_ex(ctx, EVP_aes_128_ecb(), nullptr, k, nullptr, encrypt ? 1 : 0) == 1 &&
      EVP_CIPHER_CTX_set_padding(ctx, 0) == 1 && EVP_CipherUpdate(ctx, out, &n, in, 16) == 1 &&
      EVP_CipherFinal_ex(ctx, out + n, &m) == 1 && n + m == 16;
  EVP_CIPHER_CTX_free(ctx);
  return ok;
}

}  // namespace

int PageSize(int requested) {
  if (requested <= 0) return kDefaultPageSize;
  return requested > kMaxPageSize ? kMaxPageSize : requested;
}

absl::StatusOr<std::string> PageTokens::NewKey() {
  std::string key(16, '\0');
  if (RAND_bytes(reinterpret_cast<unsigned char*>(key.data()), 16) != 1) {
    return absl::InternalError("cannot make a page-token key: no randomness");
  }
  return key;
}

std::string PageTokens::Make(const std::string& tenant, int64_t seq) const {
  unsigned char in[16], out[16];
  const uint64_t tag = TenantTag(tenant);
  for (int i = 0; i < 8; ++i) {
    in[i] = static_cast<unsigned char>(static_cast<uint64_t>(seq) >> (8 * i));
    in[8 + i] = static_cast<unsigned char>(tag >> (8 * i));
  }
  if (!valid() || !AesBlock(key_, true, in, out)) return absl::StrCat(seq);  // Not reached.
  return absl::BytesToHexString(absl::string_view(reinterpret_cast<const char*>(out), sizeof(out)));
}

absl::StatusOr<int64_t> PageTokens::Parse(const std::string& tenant,
                                          const std::string& token) const {
  if (token.empty()) return INT64_MAX;
  const auto invalid = [&] {
    return absl::InvalidArgumentError(
        absl::StrCat("page_token '", token.substr(0, 64), token.size() > 64 ? "...' " : "' ",
                     "is not valid: pass the next_page_token of a previous list call, unchanged"));
  };
  if (token.size() != 32 || !std::all_of(token.begin(), token.end(), [](char c) {
        return absl::ascii_isdigit(c) || (c >= 'a' && c <= 'f');
      })) {
    return invalid();
  }
  const std::string bytes = absl::HexStringToBytes(token);
  unsigned char out[16];
  if (!valid() ||
      !AesBlock(key_, false, reinterpret_cast<const unsigned char*>(bytes.data()), out)) {
    return invalid();
  }
  uint64_t seq = 0, tag = 0;
  for (int i = 7; i >= 0; --i) {
    seq = seq << 8 | out[i];
    tag = tag << 8 | out[8 + i];
  }
  if (tag != TenantTag(tenant) || seq == 0 || seq > static_cast<uint64_t>(INT64_MAX)) {
    return invalid();
  }
  return static_cast<int64_t>(seq);
}

}  // namespace radiosity::service
