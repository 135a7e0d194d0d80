// HMAC-SHA256 frame tags with OpenSSL 3's EVP_MAC interface, and key files.
#include "hermes/core/frame_auth.h"

#include <openssl/core_names.h>
#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/params.h>
#include <sys/stat.h>

#include <fstream>
#include <memory>
#include <sstream>

#include "hermes/core/wire_format.h"
#include "wire_internal.h"

namespace hermes {
namespace {

using Tag = std::array<std::uint8_t, kWireTagBytes>;

struct MacDeleter {
  void operator()(EVP_MAC* m) const { EVP_MAC_free(m); }
};
struct MacCtxDeleter {
  void operator()(EVP_MAC_CTX* c) const { EVP_MAC_CTX_free(c); }
};

/// HMAC-SHA256 over bytes [0,16) and [20, covered) of a frame: every header
/// field but the CRC, and the body.
Expected<Tag> frameTag(const std::uint8_t* frame, std::size_t covered, const FrameKey& key) {
  static thread_local std::unique_ptr<EVP_MAC, MacDeleter> mac(EVP_MAC_fetch(nullptr, "HMAC", nullptr));
  if (!mac) return Error{"auth: OpenSSL has no HMAC implementation"};
  std::unique_ptr<EVP_MAC_CTX, MacCtxDeleter> ctx(EVP_MAC_CTX_new(mac.get()));
  if (!ctx) return Error{"auth: cannot create an HMAC context"};
  char digest[] = "SHA256";
  const OSSL_PARAM params[] = {OSSL_PARAM_construct_utf8_string(OSSL_MAC_PARAM_DIGEST, digest, 0),
                               OSSL_PARAM_construct_end()};
  Tag tag{};
  std::size_t n = 0;
  if (EVP_MAC_init(ctx.get(), key.bytes.data(), key.bytes.size(), params) != 1 ||
      EVP_MAC_update(ctx.get(), frame, kWireCrcOffset) != 1 ||
      EVP_MAC_update(ctx.get(), frame + kWireCrcOffset + 4, covered - kWireCrcOffset - 4) != 1 ||
      EVP_MAC_final(ctx.get(), tag.data(), &n, tag.size()) != 1 || n != tag.size())
    return Error{"auth: HMAC-SHA256 computation failed"};
  return tag;
}

int hexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

}  // namespace

Expected<FrameKey> parseKeyHex(const std::string& text, const std::string& where) {
  std::string hex = text;
  while (!hex.empty() && (hex.back() == '\n' || hex.back() == '\r' || hex.back() == ' '))
    hex.pop_back();
  if (hex.size() != 2 * kFrameKeyBytes)
    return Error{"auth: key in " + where + " has " + std::to_string(hex.size()) +
                 " characters; a key is " + std::to_string(2 * kFrameKeyBytes) +
                 " hexadecimal digits (create one with ./hermes keys add ROBOT)"};
  FrameKey key;
  for (std::size_t i = 0; i < kFrameKeyBytes; ++i) {
    const int hi = hexValue(hex[2 * i]), lo = hexValue(hex[2 * i + 1]);
    if (hi < 0 || lo < 0)
      return Error{"auth: key in " + where + " has a non-hexadecimal character at position " +
                   std::to_string(2 * i + (hi < 0 ? 0 : 1))};
    key.bytes[i] = static_cast<std::uint8_t>(hi * 16 + lo);
  }
  return key;
}

Expected<FrameKey> readKeyFile(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return Error{"auth: key file " + path + " does not exist"};
  if (!S_ISREG(st.st_mode)) return Error{"auth: key file " + path + " is not a regular file"};
  if (st.st_mode & (S_IRWXG | S_IRWXO))
    return Error{"auth: key file " + path +
                 " is accessible by group or others; make it private with: chmod 600 " + path};
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error{"auth: cannot read key file " + path};
  std::ostringstream text;
  text << in.rdbuf();
  return parseKeyHex(text.str(), path);
}

Expected<std::vector<std::uint8_t>> signFrame(const std::uint8_t* data, std::size_t size,
                                              const FrameKey& key) {
  auto header = peekFrame(data, size);
  if (!header) return Error{"auth: cannot sign: " + header.error()};
  const std::size_t covered = kWireFixedBytes + header->body_bytes;
  std::vector<std::uint8_t> out(data, data + covered);
  wire::putLE(out.data() + 6, header->flags | kWireFlagTag, 2);
  auto tag = frameTag(out.data(), covered, key);
  if (!tag) return Error{tag.error()};
  out.insert(out.end(), tag->begin(), tag->end());
  wire::putLE(out.data() + kWireCrcOffset, wire::frameCrc(out.data(), out.size()), 4);
  return out;
}

const char* toString(TagCheck check) {
  switch (check) {
    case TagCheck::kValid: return "valid";
    case TagCheck::kMissing: return "missing";
    case TagCheck::kMismatch: return "mismatch";
    case TagCheck::kMalformed: return "malformed";
  }
  return "?";
}

TagCheck verifyFrameTag(const std::uint8_t* data, std::size_t size, const FrameKey& key) {
  auto header = peekFrame(data, size);
  if (!header) return TagCheck::kMalformed;
  if (!header->tagged()) return TagCheck::kMissing;
  const std::size_t covered = kWireFixedBytes + header->body_bytes;
  auto tag = frameTag(data, covered, key);
  if (!tag) return TagCheck::kMismatch;  // no tag can be computed: nothing is trusted
  return CRYPTO_memcmp(tag->data(), data + covered, kWireTagBytes) == 0 ? TagCheck::kValid
                                                                        : TagCheck::kMismatch;
}

}  // namespace hermes
