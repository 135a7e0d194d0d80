// Private YAML helpers of the calibration readers (not a public header). Every
// error names the file, the line when known, and the key as a dotted path
// ("cam1.intrinsics").
#pragma once

#include <yaml-cpp/yaml.h>

#include <initializer_list>
#include <optional>
#include <string>
#include <vector>

#include "hermes/core/camera.h"
#include "hermes/core/geometry.h"
#include "hermes/core/status.h"

namespace hermes {
namespace calib_yaml {

/// A file and the dotted path of the map being read ("" at the top level).
struct Where {
  std::string file;
  std::string prefix;
  std::string key(const std::string& k) const { return prefix.empty() ? k : prefix + "." + k; }
  Where child(const std::string& k) const { return {file, key(k)}; }
  /// "FILE:LINE" for a node read from the file, "FILE" otherwise.
  std::string at(const YAML::Node& n) const;
  /// "FILE[:LINE]: key 'KEY' " + what.
  Error bad(const YAML::Node& n, const std::string& k, const std::string& what) const;
  Error missing(const std::string& k) const;
};

/// Reads a whole file as one YAML map; OpenCV's "%YAML:1.0" first line is
/// tolerated. Errors name the file (and line for syntax errors).
Expected<YAML::Node> loadMap(const std::string& path);

/// map[key] when present (invalid node otherwise); `map` must be a map.
YAML::Node get(const YAML::Node& map, const std::string& key);
/// A sub-map that must exist.
Expected<YAML::Node> subMap(const YAML::Node& map, const std::string& key, const Where& w);
/// A scalar string that must exist.
Expected<std::string> text(const YAML::Node& map, const std::string& key, const Where& w);
/// A finite number; when absent: `fallback` if given, else a missing-key error.
Expected<double> number(const YAML::Node& map, const std::string& key, const Where& w,
                        std::optional<double> fallback = std::nullopt);
/// A list of finite numbers whose length is one of `counts` (empty: any length).
Expected<std::vector<double>> numbers(const YAML::Node& map, const std::string& key,
                                      const Where& w, std::initializer_list<int> counts);
/// An OpenCV/ROS matrix {rows, cols, data} with exactly rows x cols values;
/// cols < 0 accepts any column count.
Expected<std::vector<double>> matrix(const YAML::Node& map, const std::string& key,
                                     const Where& w, int rows, int cols);
/// [width, height]: two positive integers.
Status resolution(const YAML::Node& map, const std::string& key, const Where& w, int* width,
                  int* height);
/// A rigid 4x4 transform: 16 numbers row-major, or 4 rows of 4 (Kalibr).
Expected<SE3> transform(const YAML::Node& map, const std::string& key, const Where& w);
/// Checks that a row-major 4x4 is rigid; the error uses `bad`.
Expected<SE3> rigid(const Mat4& T, const Error& bad);
/// A 3x3 rotation from 9 row-major numbers; the error uses `bad`.
Expected<Mat3> rotation(const std::vector<double>& v, const Error& bad);

/// Sets cam->model and cam->dist from a distortion model name (none, radtan /
/// radial-tangential: 4, plumb_bob: 4 or 5, rational_polynomial: 8,
/// equidistant: 4 coefficients) and its coefficients. `map`, `model_key` and
/// `coeff_key` only locate errors (unknown model, wrong count).
Status setDistortion(const std::string& name, const std::vector<double>& coeffs,
                     const YAML::Node& map, const std::string& model_key,
                     const std::string& coeff_key, const Where& w, PinholeRadtan* cam);
/// The name writeHermesCameraFile uses for cam's distortion: none, radtan,
/// plumb_bob, rational_polynomial or equidistant.
std::string distortionName(const PinholeRadtan& cam);

}  // namespace calib_yaml
}  // namespace hermes
