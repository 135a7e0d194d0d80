#include "dataset_text.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace hermes {
namespace dataset_text {

std::string trim(const std::string& s) {
  const char* ws = " \t\r\n";
  const auto b = s.find_first_not_of(ws);
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(ws);
  return s.substr(b, e - b + 1);
}

Status forEachDataLine(const std::string& path, const std::string& what,
                       const std::function<Status(const std::string& text, const std::string& where)>& row) {
  std::ifstream in(path);
  if (!in) return Error{what + " '" + path + "' cannot be opened"};
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    const std::string t = trim(line);
    if (t.empty() || t[0] == '#') continue;
    if (Status s = row(t, path + ":" + std::to_string(lineno)); !s) return s;
  }
  return Status::Ok();
}

std::vector<std::string> splitFields(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::string::size_type start = 0;
  while (true) {
    const auto pos = s.find(sep, start);
    out.push_back(trim(s.substr(start, pos == std::string::npos ? std::string::npos : pos - start)));
    if (pos == std::string::npos) break;
    start = pos + 1;
  }
  return out;
}

bool parseInt64(const std::string& s, std::int64_t* out) {
  if (s.empty()) return false;
  errno = 0;
  char* end = nullptr;
  const long long v = std::strtoll(s.c_str(), &end, 10);
  if (errno != 0 || end != s.c_str() + s.size()) return false;
  *out = static_cast<std::int64_t>(v);
  return true;
}

bool parseDouble(const std::string& s, double* out) {
  if (s.empty()) return false;
  errno = 0;
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (errno == ERANGE || end != s.c_str() + s.size() || !std::isfinite(v)) return false;
  *out = v;
  return true;
}

Expected<std::string> readTextFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error{"file '" + path + "' cannot be opened"};
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) return Error{"error while reading '" + path + "'"};
  return ss.str();
}

Status writeTextFile(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) return Error{"cannot write '" + path + "'"};
  out << text;
  out.flush();
  if (!out) return Error{"error while writing '" + path + "'"};
  return Status::Ok();
}

}  // namespace dataset_text
}  // namespace hermes
