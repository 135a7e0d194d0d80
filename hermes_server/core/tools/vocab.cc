// hermes_vocab: trains the bag-of-words vocabulary from folders of images.
// Usage: tools/help/hermes_vocab.txt (`hermes_vocab --help`).
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "hermes/server/vocabulary.h"
#include "hermes_help/hermes_vocab.h"  // tools/help/hermes_vocab.txt

namespace fs = std::filesystem;

namespace {

const char* const kUsage = hermes_help::kText;

int badArgs(const std::string& why) {
  std::fprintf(stderr, "hermes_vocab: %s\n(see --help)\n", why.c_str());
  return 2;
}

bool parseInt(const std::string& s, long long* out) {
  try {
    std::size_t pos = 0;
    *out = std::stoll(s, &pos);
    return pos == s.size();
  } catch (...) {
    return false;
  }
}

bool isImage(const fs::path& p) {
  std::string ext = p.extension().string();
  for (auto& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext == ".png" || ext == ".jpg" || ext == ".jpeg";
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> dirs;
  std::string out, json_path;
  long long k = 10, levels = 4, max_features = 1000, max_images = 0, seed = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&](long long* v) -> bool {
      if (i + 1 >= argc) return false;
      return parseInt(argv[++i], v);
    };
    if (a == "--help" || a == "-h") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (a == "--images") {
      while (i + 1 < argc && std::string(argv[i + 1]).rfind("--", 0) != 0) dirs.push_back(argv[++i]);
    } else if (a == "--out") {
      if (i + 1 >= argc) return badArgs("--out needs a file");
      out = argv[++i];
    } else if (a == "--json") {
      if (i + 1 >= argc) return badArgs("--json needs a file or -");
      json_path = argv[++i];
    } else if (a == "--k") {
      if (!value(&k)) return badArgs("--k needs an integer");
    } else if (a == "--levels") {
      if (!value(&levels)) return badArgs("--levels needs an integer");
    } else if (a == "--max-features") {
      if (!value(&max_features) || max_features < 10)
        return badArgs("--max-features needs an integer >= 10");
    } else if (a == "--max-images") {
      if (!value(&max_images) || max_images < 1) return badArgs("--max-images needs an integer >= 1");
    } else if (a == "--seed") {
      if (!value(&seed) || seed < 0) return badArgs("--seed needs a non-negative integer");
    } else {
      return badArgs("unknown argument '" + a + "'");
    }
  }
  if (dirs.empty()) return badArgs("--images needs at least one folder");
  if (out.empty()) return badArgs("--out is required");
  hermes::VocabularyParams params;
  params.k = static_cast<int>(k);
  params.levels = static_cast<int>(levels);
  params.seed = static_cast<std::uint64_t>(seed);
  if (auto s = params.validate(); !s) return badArgs(s.error());

  std::vector<fs::path> files;
  for (const auto& d : dirs) {
    std::error_code ec;
    if (!fs::is_directory(d, ec)) return badArgs("'" + d + "' is not a folder");
    for (fs::recursive_directory_iterator it(d, ec), end; it != end && !ec; it.increment(ec))
      if (it->is_regular_file() && isImage(it->path())) files.push_back(it->path());
    if (ec) return badArgs("cannot list '" + d + "': " + ec.message());
  }
  std::sort(files.begin(), files.end());
  if (files.empty()) return badArgs("no png/jpg images under the given folders");
  if (max_images > 0 && static_cast<std::size_t>(max_images) < files.size()) {
    std::vector<fs::path> picked;
    for (long long j = 0; j < max_images; ++j)
      picked.push_back(files[static_cast<std::size_t>(j * static_cast<long long>(files.size()) / max_images)]);
    files.swap(picked);
  }

  const auto t0 = std::chrono::steady_clock::now();
  cv::Ptr<cv::ORB> orb = cv::ORB::create(static_cast<int>(max_features));
  std::vector<std::vector<hermes::Descriptor>> images;
  std::size_t total = 0, unreadable = 0;
  for (std::size_t j = 0; j < files.size(); ++j) {
    cv::Mat img = cv::imread(files[j].string(), cv::IMREAD_GRAYSCALE);
    if (img.empty()) {
      std::fprintf(stderr, "hermes_vocab: warning: cannot read %s, skipped\n", files[j].c_str());
      ++unreadable;
      continue;
    }
    std::vector<cv::KeyPoint> kps;
    cv::Mat desc;
    orb->detectAndCompute(img, cv::noArray(), kps, desc);
    images.push_back(hermes::descriptorsFromMat(desc));
    total += images.back().size();
    if ((j + 1) % 10 == 0 || j + 1 == files.size())
      std::fprintf(stderr, "hermes_vocab: features %zu/%zu images (%zu descriptors)\n", j + 1,
                   files.size(), total);
  }
  const auto t1 = std::chrono::steady_clock::now();
  auto voc = hermes::Vocabulary::train(
      images, params, [](const std::string& m) { std::fprintf(stderr, "hermes_vocab: %s\n", m.c_str()); });
  if (!voc) {
    std::fprintf(stderr, "hermes_vocab: %s\n", voc.error().c_str());
    return 1;
  }
  const auto t2 = std::chrono::steady_clock::now();
  if (auto s = voc->save(out); !s) {
    std::fprintf(stderr, "hermes_vocab: %s\n", s.error().c_str());
    return 1;
  }
  std::error_code ec;
  const auto bytes = fs::file_size(out, ec);
  auto secs = [](auto a, auto b) { return std::chrono::duration<double>(b - a).count(); };
  std::fprintf(stderr, "hermes_vocab: wrote %s: %zu words, %zu nodes, %llu bytes (%.1f s)\n",
               out.c_str(), voc->wordCount(), voc->nodeCount(),
               static_cast<unsigned long long>(bytes), secs(t0, t2));
  if (!json_path.empty()) {
    nlohmann::json j = {{"out", out},
                        {"images", images.size()},
                        {"unreadable", unreadable},
                        {"descriptors", total},
                        {"k", k},
                        {"levels", levels},
                        {"max_features", max_features},
                        {"seed", seed},
                        {"words", voc->wordCount()},
                        {"nodes", voc->nodeCount()},
                        {"bytes", ec ? 0 : bytes},
                        {"features_s", secs(t0, t1)},
                        {"training_s", secs(t1, t2)}};
    if (json_path == "-") {
      std::cout << j.dump(2) << "\n";
    } else {
      std::ofstream f(json_path);
      f << j.dump(2) << "\n";
      if (!f) return badArgs("cannot write " + json_path);
    }
  }
  return 0;
}
