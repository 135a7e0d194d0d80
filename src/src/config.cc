#include "hermes/core/config_file.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <fstream>
#include <sstream>

namespace hermes {

struct Config::Impl {
  YAML::Node root = YAML::Node(YAML::NodeType::Map);
  std::string origin = "<defaults>";
  mutable std::set<std::string> used;
};

Config::Config() : impl_(std::make_unique<Impl>()) {}
Config::~Config() = default;
Config::Config(const Config& o) : impl_(std::make_unique<Impl>()) {
  impl_->root = YAML::Clone(o.impl_->root);
  impl_->origin = o.impl_->origin;
  impl_->used = o.impl_->used;
}
Config& Config::operator=(const Config& o) {
  if (this != &o) {
    impl_->root = YAML::Clone(o.impl_->root);
    impl_->origin = o.impl_->origin;
    impl_->used = o.impl_->used;
  }
  return *this;
}

namespace {

std::vector<std::string> splitKey(const std::string& key) {
  std::vector<std::string> parts;
  std::stringstream ss(key);
  std::string p;
  while (std::getline(ss, p, '.')) parts.push_back(p);
  return parts;
}

YAML::Node lookup(const YAML::Node& root, const std::string& key) {
  // Note: YAML::Node::operator= assigns content; reset() rebinds the handle.
  YAML::Node n;
  n.reset(root);
  for (const auto& part : splitKey(key)) {
    if (!n.IsMap()) return YAML::Node(YAML::NodeType::Undefined);
    const YAML::Node& cn = n;
    YAML::Node child = cn[part];
    if (!child.IsDefined()) return YAML::Node(YAML::NodeType::Undefined);
    n.reset(child);
  }
  return n;
}

void collectLeaves(const YAML::Node& n, const std::string& prefix, std::vector<std::string>* out) {
  if (n.IsMap()) {
    for (const auto& kv : n) {
      const std::string k = kv.first.as<std::string>();
      collectLeaves(kv.second, prefix.empty() ? k : prefix + "." + k, out);
    }
  } else if (!prefix.empty()) {
    out->push_back(prefix);
  }
}

Error typeError(const std::string& origin, const std::string& key, const std::string& want,
                const YAML::Node& n) {
  std::string got = n.IsScalar() ? "'" + n.Scalar() + "'" : "a non-scalar value";
  return Error{"config " + origin + ": key '" + key + "' must be " + want + ", got " + got};
}

}  // namespace

Expected<Config> Config::fromString(const std::string& yaml, const std::string& origin) {
  Config c;
  c.impl_->origin = origin;
  try {
    YAML::Node n = YAML::Load(yaml);
    if (n.IsNull()) n = YAML::Node(YAML::NodeType::Map);
    if (!n.IsMap()) return Error{"config " + origin + ": top level must be a mapping"};
    c.impl_->root = n;
  } catch (const YAML::Exception& e) {
    return Error{"config " + origin + ": " + e.what()};
  }
  return c;
}

Expected<Config> Config::fromFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Error{"config file '" + path + "' cannot be opened"};
  std::stringstream ss;
  ss << in.rdbuf();
  return fromString(ss.str(), path);
}

Status Config::applyOverride(const std::string& assignment) {
  const auto eq = assignment.find('=');
  if (eq == std::string::npos || eq == 0)
    return Error{"override '" + assignment + "' must look like key=value"};
  const std::string key = assignment.substr(0, eq);
  const std::string value = assignment.substr(eq + 1);
  auto parts = splitKey(key);
  for (const auto& p : parts)
    if (p.empty()) return Error{"override '" + assignment + "' has an empty key part"};
  YAML::Node n;
  n.reset(impl_->root);
  for (std::size_t i = 0; i + 1 < parts.size(); ++i) {
    if (!n[parts[i]].IsMap()) n[parts[i]] = YAML::Node(YAML::NodeType::Map);
    YAML::Node child = n[parts[i]];
    n.reset(child);
  }
  try {
    n[parts.back()] = YAML::Load(value);
  } catch (const YAML::Exception&) {
    n[parts.back()] = value;
  }
  return Status::Ok();
}

bool Config::has(const std::string& key) const { return lookup(impl_->root, key).IsDefined(); }

template <class T>
static Status getScalar(const YAML::Node& root, const std::string& origin,
                        std::set<std::string>& used, const std::string& key, T* out,
                        const char* want) {
  used.insert(key);
  YAML::Node n = lookup(root, key);
  if (!n.IsDefined() || n.IsNull()) return Status::Ok();
  if (!n.IsScalar()) return typeError(origin, key, want, n);
  try {
    *out = n.as<T>();
  } catch (const YAML::Exception&) {
    return typeError(origin, key, want, n);
  }
  return Status::Ok();
}

Status Config::get(const std::string& key, double* out) const {
  return getScalar(impl_->root, impl_->origin, impl_->used, key, out, "a number");
}
Status Config::get(const std::string& key, int* out) const {
  return getScalar(impl_->root, impl_->origin, impl_->used, key, out, "an integer");
}
Status Config::get(const std::string& key, bool* out) const {
  return getScalar(impl_->root, impl_->origin, impl_->used, key, out, "true or false");
}
Status Config::get(const std::string& key, std::string* out) const {
  return getScalar(impl_->root, impl_->origin, impl_->used, key, out, "a string");
}

Status Config::get(const std::string& key, std::vector<double>* out) const {
  impl_->used.insert(key);
  YAML::Node n = lookup(impl_->root, key);
  if (!n.IsDefined() || n.IsNull()) return Status::Ok();
  if (!n.IsSequence()) return typeError(impl_->origin, key, "a list of numbers", n);
  try {
    *out = n.as<std::vector<double>>();
  } catch (const YAML::Exception&) {
    return typeError(impl_->origin, key, "a list of numbers", n);
  }
  return Status::Ok();
}

Status Config::getChoice(const std::string& key, const std::vector<std::string>& choices,
                         std::string* out) const {
  std::string v = *out;
  Status s = get(key, &v);
  if (!s) return s;
  if (std::find(choices.begin(), choices.end(), v) == choices.end()) {
    std::string list;
    for (const auto& c : choices) list += (list.empty() ? "" : " | ") + c;
    return Error{"config " + impl_->origin + ": key '" + key + "' is '" + v + "', expected " +
                 list};
  }
  *out = v;
  return Status::Ok();
}

std::vector<std::string> Config::unusedKeys() const {
  std::vector<std::string> leaves, unused;
  collectLeaves(impl_->root, "", &leaves);
  for (const auto& k : leaves)
    if (!impl_->used.count(k)) unused.push_back(k);
  return unused;
}

const std::string& Config::origin() const { return impl_->origin; }

namespace {
std::string fmt(double v) {
  std::ostringstream ss;
  ss.precision(10);
  ss << v;
  return ss.str();
}
}  // namespace

void ConfigWriter::set(const std::string& key, double v) { values_[key] = fmt(v); }
void ConfigWriter::set(const std::string& key, int v) { values_[key] = std::to_string(v); }
void ConfigWriter::set(const std::string& key, bool v) { values_[key] = v ? "true" : "false"; }
void ConfigWriter::set(const std::string& key, const std::string& v) {
  YAML::Emitter e;
  e << YAML::DoubleQuoted << v;
  values_[key] = e.c_str();
}
void ConfigWriter::set(const std::string& key, const std::vector<double>& v) {
  std::string s = "[";
  for (std::size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + fmt(v[i]);
  values_[key] = s + "]";
}

std::string ConfigWriter::yaml() const {
  // values_ is sorted by dotted key, so sections come out grouped.
  std::ostringstream out;
  std::vector<std::string> open;
  for (const auto& [key, value] : values_) {
    auto parts = splitKey(key);
    std::size_t common = 0;
    while (common < open.size() && common + 1 < parts.size() && open[common] == parts[common])
      ++common;
    open.resize(common);
    for (std::size_t i = common; i + 1 < parts.size(); ++i) {
      out << std::string(2 * i, ' ') << parts[i] << ":\n";
      open.push_back(parts[i]);
    }
    out << std::string(2 * (parts.size() - 1), ' ') << parts.back() << ": " << value << "\n";
  }
  return out.str();
}

Expected<Config> loadConfig(const std::string& file, const std::vector<std::string>& sets) {
  Config config;
  if (!file.empty()) {
    auto loaded = Config::fromFile(file);
    if (!loaded.ok()) return Error{loaded.error()};
    config = std::move(*loaded);
  }
  for (const std::string& assignment : sets) {
    if (Status s = config.applyOverride(assignment); !s)
      return Error{"--set " + assignment + ": " + s.error()};
  }
  return config;
}

}  // namespace hermes
