// hermes_config_doc: writes docs/configuration.md from the code, and checks the
// shipped configuration files against it.
//
//   key, default   what SystemParams (every module's Params) writes with its defaults
//   valid range    what the modules' read() / validate() refuse, in their words: each
//                  key is read once with a value far below, once far above (numbers)
//                  or with a word that is no choice (strings)
//   meaning, unit  the key's comment in config/hermes.yaml (user settings) or in
//                  config/fault_injection.yaml (fault injection and testing hooks)
//
// Fails (exit 1, each problem on a line) when a file holds a key no module reads,
// a key a module reads is in neither file, in both, or has no comment, or a line
// of config/hermes.yaml is over 160 characters; with --check also when FILE is not
// what it would write.
#include <algorithm>
#include <cstdio>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "hermes/system/system_params.h"
#include "hermes_help/hermes_config_doc.h"  // tools/help/hermes_config_doc.txt

using namespace hermes;

namespace {

const char* const kUsage = hermes_help::kText;

/// A key as a commented YAML file shows it.
struct FileKey {
  std::string key, comment;
  int line = 0;
};

/// A line-based reading of a commented YAML file (block mappings, one key a line):
/// each key with the comment lines right above it and the comment on its line;
/// section keys (no value) too. The comment lines before the first key are the
/// file's header and belong to no key.
struct CommentedYaml {
  std::string path;
  std::vector<FileKey> keys;                    // leaves, in file order
  std::map<std::string, std::string> sections;  // section -> its comment
  std::vector<std::string> lines;
};

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t");
  if (b == std::string::npos) return "";
  return s.substr(b, s.find_last_not_of(" \t") - b + 1);
}

std::string joinText(const std::string& a, const std::string& b) {
  if (a.empty()) return b;
  if (b.empty()) return a;
  return a + "; " + b;
}

/// Splits "value  # comment" at the first '#' outside quotes that follows a blank.
void splitComment(const std::string& rest, std::string* value, std::string* comment) {
  char quote = 0;
  for (std::size_t i = 0; i < rest.size(); ++i) {
    const char c = rest[i];
    if (quote) {
      if (c == quote) quote = 0;
    } else if (c == '"' || c == '\'') {
      quote = c;
    } else if (c == '#' && (i == 0 || rest[i - 1] == ' ' || rest[i - 1] == '\t')) {
      *value = trim(rest.substr(0, i));
      *comment = trim(rest.substr(i + 1));
      return;
    }
  }
  *value = trim(rest);
  comment->clear();
}

Expected<CommentedYaml> readCommentedYaml(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Error{path + " cannot be opened"};
  CommentedYaml y;
  y.path = path;
  static const std::regex key_line(R"(^( *)([A-Za-z0-9_]+):(.*)$)");
  static const std::regex banner(R"(^-+ *(.*?) *-+$)");
  std::vector<std::pair<int, std::string>> open;  // indent, key
  std::string pending;
  bool pending_banner = false;  // the last comment line was a "---- title ----" banner
  bool header = true;
  for (std::string line; std::getline(in, line);) {
    y.lines.push_back(line);
    const int number = static_cast<int>(y.lines.size());
    const std::string t = trim(line);
    if (t.empty()) {
      pending.clear();
      pending_banner = false;
      continue;
    }
    if (t[0] == '#') {
      if (header) continue;
      std::string text = trim(t.substr(1));
      std::smatch m;
      const bool is_banner = std::regex_match(text, m, banner);
      if (is_banner) text = m[1];
      pending = pending.empty() ? text : pending + (is_banner || pending_banner ? "; " : " ") + text;
      pending_banner = is_banner;
      continue;
    }
    std::smatch m;
    if (!std::regex_match(line, m, key_line))
      return Error{path + ":" + std::to_string(number) + ": not 'key: value'"};
    header = false;
    const int indent = static_cast<int>(m[1].length());
    while (!open.empty() && open.back().first >= indent) open.pop_back();
    std::string key;
    for (const auto& o : open) key += o.second + ".";
    key += m[2].str();
    std::string value, comment;
    splitComment(m[3].str(), &value, &comment);
    comment = joinText(pending, comment);
    pending.clear();
    pending_banner = false;
    if (value.empty()) {
      y.sections[key] = comment;
      open.push_back({indent, m[2].str()});
    } else {
      y.keys.push_back({key, comment, number});
    }
  }
  return y;
}

/// Unit and meaning from a comment: the first [unit], or (unitless) (bool) (count) (fraction).
void splitUnit(std::string comment, std::string* unit, std::string* meaning) {
  static const std::regex bracket(R"(\[([^\[\]]+)\])");
  static const std::regex word(R"(\((unitless|bool|count|fraction)\))");
  std::smatch m;
  unit->clear();
  if (std::regex_search(comment, m, bracket) || std::regex_search(comment, m, word)) {
    *unit = m[1];
    comment = m.prefix().str() + m.suffix().str();
  }
  comment = std::regex_replace(comment, std::regex(R"(\s+)"), " ");
  comment = std::regex_replace(comment, std::regex(R"(\s+([;,:)]))"), "$1");
  comment = trim(comment);
  while (!comment.empty() && (comment.back() == ';' || comment.back() == ',' || comment.back() == ':'))
    comment = trim(comment.substr(0, comment.size() - 1));
  while (!comment.empty() && comment.front() == ';') comment = trim(comment.substr(1));
  *meaning = comment;
}

/// `message` without what only names `key` again: "config ...: " and "server: " style
/// prefixes, then the key itself (or its last components) or its section ("distill.").
std::string withoutKey(std::string message, const std::string& key) {
  std::vector<std::string> parts{key};  // key, then its shorter tails: a.b.c, b.c, c
  for (std::size_t at = key.find('.'); at != std::string::npos; at = key.find('.', at + 1))
    parts.push_back(key.substr(at + 1));
  auto starts = [&](const std::string& p) { return message.compare(0, p.size(), p) == 0; };
  static const std::regex section(R"(^([a-z_.]+?)\.?: )");
  for (std::smatch m;
       std::regex_search(message, m, section) && (key + ".").find(m[1].str() + ".") == 0;)
    message = m.suffix();
  const auto colon = message.find(": ");  // "rig matching: max_hamming must ..."
  const std::string after_colon = colon == std::string::npos ? "" : message.substr(colon + 2);
  for (const std::string& p : parts)
    for (const std::string verb : {" must ", " may ", " needs ", " need "}) {
      if (starts(p + verb)) return message.substr(p.size() + 1);
      if (after_colon.compare(0, p.size() + verb.size(), p + verb) == 0) return after_colon.substr(p.size() + 1);
    }
  for (std::size_t dot = key.rfind('.'); dot != std::string::npos && dot > 0; dot = key.rfind('.', dot - 1)) {
    const std::string prefix = key.substr(0, dot + 1);
    if (starts(prefix) && message.find(prefix, prefix.size()) == std::string::npos)
      return message.substr(prefix.size());
  }
  return message;
}

/// The error reading `key = value` gives (empty: accepted), in words about the key.
std::string probe(const std::string& key, const std::string& value) {
  auto config = Config::fromString("{}", "probe");
  if (!config.ok() || !config->applyOverride(key + "=" + value).ok()) return "";
  system::SystemParams params;
  Status s = params.read(*config);
  if (s) return "";
  std::string e = s.error();
  for (const std::string& noise : {std::string("config probe: "), std::string(" (in probe)")})
    for (std::size_t at; (at = e.find(noise)) != std::string::npos;) e.erase(at, noise.size());
  std::smatch m;
  if (std::regex_search(e, m, std::regex(R"(key '[^']*' is '[^']*', expected (.*)$)"))) return m[1];
  e = std::regex_replace(e, std::regex(R"(,? \(?got .*$)"), "");  // the probe value
  e = std::regex_replace(e, std::regex(R"([-+]?1(\.0+)?e\+?0?9|[-+]?1000000000(\.0+)?)"), "…");
  return trim(withoutKey(trim(e), key));
}

std::string validRange(const std::string& key, const std::string& value) {
  if (value == "true" || value == "false") return "true | false";
  std::vector<std::string> probes;
  if (value[0] == '"') {
    probes = {"\"?\""};
  } else if (value[0] == '[') {
    probes = {"[-1000000000]", "[1000000000]"};
  } else {
    probes = {"-1000000000", "1000000000"};
  }
  std::string out;
  for (const std::string& p : probes) {
    const std::string e = probe(key, p);
    if (!e.empty() && out.find(e) == std::string::npos) out = out.empty() ? e : out + "; " + e;
  }
  if (out.empty()) return value[0] == '"' ? "any text" : "not checked";
  return out;
}

/// Table cell text: '|' escaped, and '<' before a letter (it would open an HTML tag).
std::string cell(std::string s) {
  s = std::regex_replace(s, std::regex(R"(\|)"), "\\|");
  return std::regex_replace(s, std::regex(R"(<([A-Za-z]))"), "&lt;$1");
}

std::string shownDefault(const std::string& v) {
  const bool quoted = v.size() > 2 && v.front() == '"' && v.back() == '"';
  return quoted ? v.substr(1, v.size() - 2) : v;
}

struct Group {
  std::string name, comment;
  std::vector<std::string> rows;
};

/// The tables of one file's keys, grouped by the mapping that holds them (file order).
std::string tables(const CommentedYaml& y, const std::map<std::string, std::string>& defaults,
                   const std::string& top_heading) {
  std::vector<Group> groups;
  auto group = [&](const std::string& name) -> Group& {
    for (Group& g : groups)
      if (g.name == name) return g;
    auto it = y.sections.find(name);
    groups.push_back({name, it == y.sections.end() ? "" : it->second, {}});
    return groups.back();
  };
  auto parent = [](const std::string& key) {
    const auto dot = key.rfind('.');
    return dot == std::string::npos ? key : key.substr(0, dot);
  };
  auto top = [](const std::string& name) { return name.substr(0, name.find('.')); };
  std::vector<std::string> tops;  // top-level sections in file order
  for (const FileKey& k : y.keys)
    if (std::find(tops.begin(), tops.end(), top(k.key)) == tops.end()) tops.push_back(top(k.key));
  for (const std::string& t : tops) {  // each section's own keys first, then its subsections
    for (const FileKey& k : y.keys)
      if (parent(k.key) == t) group(t);
    for (const FileKey& k : y.keys)
      if (top(k.key) == t) group(parent(k.key));
  }
  for (const FileKey& k : y.keys) {
    Group& g = group(parent(k.key));
    std::string unit, meaning;
    splitUnit(k.comment, &unit, &meaning);
    const std::string& value = defaults.at(k.key);
    if (unit.empty()) unit = value == "true" || value == "false" ? "bool" : "–";
    g.rows.push_back("| `" + k.key + "` | `" + cell(shownDefault(value)) + "` | " + cell(unit) + " | " +
                     cell(meaning) + " | " + cell(validRange(k.key, value)) + " |\n");
  }
  std::ostringstream out;
  for (const Group& g : groups) {
    const bool top = g.name.find('.') == std::string::npos;
    out << "\n" << (top ? top_heading : top_heading + "#") << " " << g.name << "\n\n";
    if (!g.comment.empty()) out << g.comment << ".\n\n";
    out << "| key | default | unit | meaning | valid range |\n|---|---|---|---|---|\n";
    for (const std::string& r : g.rows) out << r;
  }
  return out.str();
}

std::string document(const CommentedYaml& user, const CommentedYaml& hooks,
                     const std::map<std::string, std::string>& defaults) {
  std::ostringstream out;
  out << "# Configuration reference\n\n"
         "<!-- Generated by hermes_config_doc (hermes_system/tools/config_doc.cc); do not edit. -->\n\n"
         "Every key the offline runner (`./hermes run`) and the ROS nodes read, by section. A file\n"
         "given with `--config FILE` is laid out like `config/hermes.yaml` (a missing key keeps its\n"
         "default, an unknown key is an error); `--set key=value` overrides one key, e.g. one robot\n"
         "tracking with the covisibility keyframe rule:\n\n"
         "```bash\n"
         "./hermes run --dataset data/euroc_V1_01_micro --out results/euroc_micro --no-server \\\n"
         "    --set keyframe.policy=covisibility\n"
         "```\n\n"
         "Each run writes the values it used to `OUT/config_used.yaml`. The columns:\n\n"
         "* **default**: the module's `Params` as constructed (what its `write()` gives);\n"
         "* **valid range**: what the module's `read()` / `validate()` refuse, in their words (each key\n"
         "  read with a value far below and one far above, …, or with a word that is no choice);\n"
         "  *not checked*: the code takes any number;\n"
         "* **meaning**, **unit**: the key's comment in `config/hermes.yaml` (user settings) or in\n"
         "  `config/fault_injection.yaml` (fault injection and testing hooks, the last section).\n\n"
         "This page is generated: after changing a `Params` or a comment, run `cmake --build build\n"
         "--target hermes_config_doc && build/bin/hermes_config_doc --out docs/configuration.md`. The\n"
         "unit test `configuration_doc_is_current` fails while the page is stale, and when a\n"
         "configuration file holds a key no module reads or a key is in neither file or has no comment.\n\n"
         "Sections:";
  std::vector<std::string> tops;
  for (const FileKey& k : user.keys) {
    const std::string t = k.key.substr(0, k.key.find('.'));
    if (std::find(tops.begin(), tops.end(), t) == tops.end()) tops.push_back(t);
  }
  for (const std::string& t : tops) out << " [" << t << "](#" << t << "),";
  out << " [fault injection and testing hooks](#fault-injection-and-testing-hooks).\n";
  out << tables(user, defaults, "##");
  out << "\n## Fault injection and testing hooks\n\n"
         "Not user settings: they are not in `config/hermes.yaml` and keep these defaults unless a\n"
         "test, a benchmark, a `./hermes run` option or `--set` sets them. `config/fault_injection.yaml`\n"
         "lists them with their defaults, a template for `--config`.\n";
  out << tables(hooks, defaults, "###");
  return out.str();
}

}  // namespace

int main(int argc, char** argv) {
  std::string root = HERMES_SOURCE_DIR, out_path, check_path;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--help" || a == "-h") {
      std::printf("%s", kUsage);
      return 0;
    } else if (a == "--root" && has_value) {
      root = argv[++i];
    } else if (a == "--out" && has_value) {
      out_path = argv[++i];
    } else if (a == "--check" && has_value) {
      check_path = argv[++i];
    } else {
      std::fprintf(stderr, "hermes_config_doc: bad argument '%s'\n%s", a.c_str(), kUsage);
      return 2;
    }
  }
  if (!out_path.empty() && !check_path.empty()) {
    std::fprintf(stderr, "hermes_config_doc: --out and --check exclude each other\n");
    return 2;
  }
  ConfigWriter writer;
  system::SystemParams().write(writer);
  const std::map<std::string, std::string>& defaults = writer.values();

  std::vector<std::string> problems;
  std::vector<CommentedYaml> files;
  for (const char* name : {"config/hermes.yaml", "config/fault_injection.yaml"}) {
    auto y = readCommentedYaml(root + "/" + name);
    if (!y.ok()) {
      std::fprintf(stderr, "hermes_config_doc: %s\n", y.error().c_str());
      return 1;
    }
    auto config = loadConfig(y->path, {});
    if (!config.ok()) {
      problems.push_back(config.error());
    } else if (auto read = system::readSystemParams(*config); !read.ok()) {
      problems.push_back(read.error());
    }
    files.push_back(std::move(*y));
  }
  const CommentedYaml& user = files[0];
  const CommentedYaml& hooks = files[1];
  std::map<std::string, std::string> where;  // key -> file:line
  for (const CommentedYaml& y : files)
    for (const FileKey& k : y.keys) {
      const std::string at = y.path + ":" + std::to_string(k.line);
      if (!defaults.count(k.key)) continue;  // reported by readSystemParams above
      if (where.count(k.key)) problems.push_back(at + ": " + k.key + " is also at " + where[k.key]);
      where[k.key] = at;
      std::string unit, meaning;
      splitUnit(k.comment, &unit, &meaning);
      if (meaning.empty())
        problems.push_back(at + ": " + k.key + " has no comment giving its meaning (and unit)");
    }
  for (const auto& [key, value] : defaults)
    if (!where.count(key))
      problems.push_back(key + " (default " + value + ") is in neither config/hermes.yaml nor "
                         "config/fault_injection.yaml: add it with a comment giving its meaning and unit");
  for (std::size_t i = 0; i < user.lines.size(); ++i)
    if (user.lines[i].size() > 160)
      problems.push_back(user.path + ":" + std::to_string(i + 1) + ": line over 160 characters");
  for (const std::string& p : problems) std::fprintf(stderr, "hermes_config_doc: %s\n", p.c_str());
  if (!problems.empty()) return 1;

  const std::string doc = document(user, hooks, defaults);
  if (!check_path.empty()) {
    std::ifstream in(check_path);
    std::stringstream have;
    if (in) have << in.rdbuf();
    if (have.str() == doc) return 0;
    std::istringstream a(have.str()), b(doc);
    int line = 1;
    for (std::string x, y; std::getline(a, x) && std::getline(b, y) && x == y;) ++line;
    std::fprintf(stderr,
                 "hermes_config_doc: %s is not what the code and the configuration files give (line %d "
                 "differs); regenerate it: cmake --build build --target hermes_config_doc && "
                 "build/bin/hermes_config_doc --out %s\n",
                 check_path.c_str(), line, check_path.c_str());
    return 1;
  }
  if (out_path.empty()) {
    std::fwrite(doc.data(), 1, doc.size(), stdout);
    return 0;
  }
  std::ofstream out(out_path);
  out << doc;
  if (!out) {
    std::fprintf(stderr, "hermes_config_doc: cannot write %s\n", out_path.c_str());
    return 1;
  }
  return 0;
}
