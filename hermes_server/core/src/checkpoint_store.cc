#include "hermes/server/checkpoint_store.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "hermes/core/crc32.h"
#include "hermes/server/byte_codec.h"

namespace hermes {
namespace server {
namespace fs = std::filesystem;
namespace {

constexpr char kCheckpointMagic[4] = {'H', 'C', 'K', 'P'};
constexpr char kJournalMagic[4] = {'H', 'J', 'N', 'L'};
constexpr char kCheckpointPrefix[] = "checkpoint-";
constexpr char kCheckpointSuffix[] = ".hck";
constexpr char kJournalSuffix[] = ".hjf";

std::string errnoText() { return std::strerror(errno); }

Status syncDirectory(const std::string& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return Error{"cannot open directory " + dir + ": " + errnoText()};
  const bool ok = ::fsync(fd) == 0;
  ::close(fd);
  if (!ok) return Error{"cannot fsync directory " + dir + ": " + errnoText()};
  return Status::Ok();
}

Expected<std::vector<std::uint8_t>> readAll(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return Error{"cannot open"};
  std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(f)),
                                  std::istreambuf_iterator<char>());
  if (f.bad()) return Error{"read error"};
  return bytes;
}

/// Magic, version, CRC of a "magic, u32 version, ..., u32 CRC" file; returns a
/// reader over what lies between version and CRC.
Expected<ByteReader> openSealed(const std::vector<std::uint8_t>& bytes, const char* magic,
                                std::uint32_t version, const char* kind) {
  if (bytes.size() < 12 || std::memcmp(bytes.data(), magic, 4) != 0)
    return Error{std::string("not a Hermes ") + kind + " file (bad magic or shorter than 12 bytes)"};
  std::uint32_t found = 0;
  std::memcpy(&found, bytes.data() + 4, 4);
  if (found != version)
    return Error{std::string(kind) + " format version " + std::to_string(found) +
                 ", this build reads version " + std::to_string(version)};
  std::uint32_t stored_crc = 0;
  std::memcpy(&stored_crc, bytes.data() + bytes.size() - 4, 4);
  if (crc32(bytes.data(), bytes.size() - 4) != stored_crc)
    return Error{"checksum mismatch (damaged or truncated)"};
  return ByteReader(bytes.data() + 8, bytes.size() - 12);
}

std::vector<std::uint8_t> sealed(const char* magic, std::uint32_t version, ByteWriter body) {
  ByteWriter w;
  w.out.assign(magic, magic + 4);
  w.pod(version);
  w.out.insert(w.out.end(), body.out.begin(), body.out.end());
  w.pod(crc32(w.out.data(), w.out.size()));
  return w.out;
}

/// n of "checkpoint-<n>.hck", 0 when the name is not a checkpoint's.
std::uint64_t checkpointNumber(const std::string& name) {
  const std::string prefix = kCheckpointPrefix, suffix = kCheckpointSuffix;
  if (name.size() <= prefix.size() + suffix.size() || name.compare(0, prefix.size(), prefix) != 0 ||
      name.compare(name.size() - suffix.size(), suffix.size(), suffix) != 0)
    return 0;
  const std::string digits = name.substr(prefix.size(), name.size() - prefix.size() - suffix.size());
  if (digits.empty() || digits.size() > 18 ||
      !std::all_of(digits.begin(), digits.end(), [](char c) { return c >= '0' && c <= '9'; }))
    return 0;
  return std::stoull(digits);
}

}  // namespace

Status CheckpointParams::read(const Config& c, const std::string& p) {
  for (Status s : {c.get(p + "checkpoint_dir", &dir), c.get(p + "checkpoint_period_s", &period_s),
                   c.get(p + "checkpoint_keep", &keep), c.get(p + "prior_map", &prior_map),
                   c.get(p + "prior_map_optional", &prior_map_optional)})
    if (!s) return s;
  return validate();
}

void CheckpointParams::write(ConfigWriter& w, const std::string& p) const {
  w.set(p + "checkpoint_dir", dir);
  w.set(p + "checkpoint_period_s", period_s);
  w.set(p + "checkpoint_keep", keep);
  w.set(p + "prior_map", prior_map);
  w.set(p + "prior_map_optional", prior_map_optional);
}

Status CheckpointParams::validate() const {
  if (!(period_s >= 0) || !std::isfinite(period_s))
    return Error{"server.checkpoint_period_s must be >= 0, got " + std::to_string(period_s)};
  if (keep < 2)
    return Error{"server.checkpoint_keep must be >= 2 (the previous good checkpoint is the "
                 "fallback), got " + std::to_string(keep)};
  auto same = [](const std::string& a, const std::string& b) {
    auto norm = [](const std::string& p) {
      std::error_code ec;
      std::string n = fs::weakly_canonical(fs::path(p), ec).lexically_normal().string();
      while (n.size() > 1 && n.back() == '/') n.pop_back();
      return n;
    };
    return norm(a) == norm(b);
  };
  if (!prior_map.empty() && !dir.empty() && same(prior_map, dir))
    return Error{"server.prior_map '" + prior_map + "' is the server's own checkpoint_dir: the prior "
                 "map would be overwritten; copy it elsewhere or checkpoint into another directory"};
  return Status::Ok();
}

Status writeFileAtomically(const std::string& path, const std::vector<std::uint8_t>& bytes) {
  const std::string tmp = path + ".tmp";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return Error{"cannot create " + tmp + ": " + errnoText()};
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const std::string why = errnoText();
      ::close(fd);
      ::unlink(tmp.c_str());
      return Error{"cannot write " + tmp + ": " + why};
    }
    done += static_cast<std::size_t>(n);
  }
  if (::fsync(fd) != 0 || ::close(fd) != 0) {
    const std::string why = errnoText();
    ::unlink(tmp.c_str());
    return Error{"cannot flush " + tmp + ": " + why};
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string why = errnoText();
    ::unlink(tmp.c_str());
    return Error{"cannot rename " + tmp + " to " + path + ": " + why};
  }
  return syncDirectory(fs::path(path).parent_path().string());
}

Expected<CheckpointStore> CheckpointStore::open(const CheckpointParams& params) {
  if (Status s = params.validate(); !s) return Error{s.error()};
  if (!params.enabled()) return Error{"server checkpoint: no directory configured"};
  std::error_code ec;
  fs::create_directories(fs::path(params.dir) / "queue", ec);
  if (ec) return Error{"server checkpoint: cannot create " + params.dir + "/queue: " + ec.message()};
  CheckpointStore store(params);
  for (const fs::path& d : {fs::path(params.dir), fs::path(params.dir) / "queue"})
    for (const auto& e : fs::directory_iterator(d, ec))
      if (e.path().extension() == ".tmp") fs::remove(e.path(), ec);  // a crash mid-write
  for (const auto& e : fs::directory_iterator(params.dir, ec)) {
    const std::string name = e.path().filename().string();
    const std::string base = name.size() > 8 && name.compare(name.size() - 8, 8, ".refused") == 0
                                 ? name.substr(0, name.size() - 8)
                                 : name;
    store.next_ = std::max(store.next_, checkpointNumber(base) + 1);
  }
  return store;
}

std::vector<std::string> CheckpointStore::listCheckpoints(const std::string& dir) {
  std::vector<std::pair<std::uint64_t, std::string>> found;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (const std::uint64_t n = checkpointNumber(e.path().filename().string()); n > 0)
      found.emplace_back(n, e.path().string());
  std::sort(found.rbegin(), found.rend());
  std::vector<std::string> out;
  for (auto& f : found) out.push_back(std::move(f.second));
  return out;
}

Expected<std::string> CheckpointStore::write(const std::vector<std::uint8_t>& body) {
  char name[64];
  std::snprintf(name, sizeof(name), "%s%08llu%s", kCheckpointPrefix,
                static_cast<unsigned long long>(next_), kCheckpointSuffix);
  const std::string path = (fs::path(params_.dir) / name).string();
  ByteWriter w;
  w.blob(body);
  if (Status s = writeFileAtomically(path, sealed(kCheckpointMagic, kCheckpointVersion, std::move(w))); !s)
    return Error{"server checkpoint: " + s.error()};
  ++next_;
  const std::vector<std::string> all = checkpoints();
  std::error_code ec;
  for (std::size_t i = static_cast<std::size_t>(params_.keep); i < all.size(); ++i)
    fs::remove(all[i], ec);
  return path;
}

Expected<std::vector<std::uint8_t>> CheckpointStore::readCheckpoint(const std::string& path) {
  auto bytes = readAll(path);
  if (!bytes) return Error{bytes.error()};
  auto r = openSealed(*bytes, kCheckpointMagic, kCheckpointVersion, "server checkpoint");
  if (!r) return Error{r.error()};
  std::vector<std::uint8_t> body;
  if (!r->blob(&body) || !r->atEnd()) return Error{"body length does not match the file"};
  return body;
}

void CheckpointStore::refuse(const std::string& path) {
  std::error_code ec;
  fs::rename(path, path + ".refused", ec);
}

std::string CheckpointStore::journalPath(const SubmapHeader& routing) const {
  return (fs::path(params_.dir) / "queue" /
          (toString(routing.agent) + "-" + std::to_string(routing.session) + "-" +
           std::to_string(routing.seq) + kJournalSuffix))
      .string();
}

Status CheckpointStore::journalPut(const SubmapHeader& routing, double arrival,
                                   const std::uint8_t* frame, std::size_t size) {
  ByteWriter w;
  w.pod(arrival);
  w.blob(frame, size);
  if (Status s = writeFileAtomically(journalPath(routing), sealed(kJournalMagic, kJournalVersion, std::move(w))); !s)
    return Error{"server journal: " + s.error()};
  return Status::Ok();
}

void CheckpointStore::journalRemove(const SubmapHeader& routing) {
  std::error_code ec;
  fs::remove(journalPath(routing), ec);
}

std::vector<JournalEntry> CheckpointStore::journal(std::vector<std::string>* problems) const {
  std::vector<JournalEntry> out;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(fs::path(params_.dir) / "queue", ec)) {
    if (e.path().extension() != kJournalSuffix) continue;
    const std::string path = e.path().string();
    JournalEntry j;
    j.file = path;
    auto bytes = readAll(path);
    std::string why = bytes ? "" : bytes.error();
    if (bytes) {
      auto r = openSealed(*bytes, kJournalMagic, kJournalVersion, "server journal");
      if (!r)
        why = r.error();
      else if (!r->pod(&j.arrival) || !std::isfinite(j.arrival) || !r->blob(&j.frame) || !r->atEnd())
        why = "content does not match its length fields";
    }
    if (!why.empty()) {
      problems->push_back("server journal entry " + path + " refused: " + why);
      refuse(path);
      continue;
    }
    out.push_back(std::move(j));
  }
  std::sort(out.begin(), out.end(), [](const JournalEntry& a, const JournalEntry& b) {
    return a.arrival != b.arrival ? a.arrival < b.arrival : a.file < b.file;
  });
  return out;
}

}  // namespace server
}  // namespace hermes
