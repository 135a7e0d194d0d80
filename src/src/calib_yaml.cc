#include "calib_yaml.h"

#include <algorithm>
#include <cmath>

#include "dataset_text.h"

namespace hermes {
namespace calib_yaml {
namespace {

std::string countText(const std::vector<int>& counts) {
  std::string s;
  for (auto it = counts.begin(); it != counts.end(); ++it) {
    if (it != counts.begin()) s += std::next(it) == counts.end() ? " or " : ", ";
    s += std::to_string(*it);
  }
  return s;
}

}  // namespace

std::string Where::at(const YAML::Node& n) const {
  if (n && n.Mark().line >= 0) return file + ":" + std::to_string(n.Mark().line + 1);
  return file;
}

Error Where::bad(const YAML::Node& n, const std::string& k, const std::string& what) const {
  return Error{at(n) + ": key '" + key(k) + "' " + what};
}

Error Where::missing(const std::string& k) const {
  return Error{file + ": missing key '" + key(k) + "'"};
}

Expected<YAML::Node> loadMap(const std::string& path) {
  auto text = dataset_text::readTextFile(path);
  if (!text) return Error{text.error()};
  // OpenCV-style "%YAML:1.0" is not a valid YAML 1.2 directive; comment it out
  // (keeping line numbers).
  if (text->rfind("%YAML", 0) == 0) (*text)[0] = '#';
  YAML::Node root;
  try {
    root = YAML::Load(*text);
  } catch (const YAML::Exception& e) {
    return Error{path + ":" + std::to_string(e.mark.line + 1) + ": not valid YAML: " + e.msg};
  }
  if (!root.IsMap()) return Error{path + ": not a YAML map of keys"};
  return root;
}

YAML::Node get(const YAML::Node& map, const std::string& key) {
  if (!map.IsMap()) return YAML::Node(YAML::NodeType::Undefined);
  return map[key];
}

Expected<YAML::Node> subMap(const YAML::Node& map, const std::string& key, const Where& w) {
  const YAML::Node n = get(map, key);
  if (!n) return w.missing(key);
  if (!n.IsMap()) return w.bad(n, key, "must be a map");
  return n;
}

Expected<std::string> text(const YAML::Node& map, const std::string& key, const Where& w) {
  const YAML::Node n = get(map, key);
  if (!n) return w.missing(key);
  if (!n.IsScalar()) return w.bad(n, key, "must be a single value");
  return n.Scalar();
}

Expected<double> number(const YAML::Node& map, const std::string& key, const Where& w,
                        std::optional<double> fallback) {
  const YAML::Node n = get(map, key);
  if (!n) {
    if (fallback) return *fallback;
    return w.missing(key);
  }
  double v = 0;
  try {
    v = n.as<double>();
  } catch (const YAML::Exception&) {
    return w.bad(n, key, "must be a number");
  }
  if (!std::isfinite(v)) return w.bad(n, key, "must be finite");
  return v;
}

Expected<std::vector<double>> numbers(const YAML::Node& map, const std::string& key,
                                      const Where& w, std::initializer_list<int> counts) {
  const YAML::Node n = get(map, key);
  if (!n) return w.missing(key);
  const std::string want =
      counts.size() == 0 ? "a list of numbers" : countText(std::vector<int>(counts)) + " numbers";
  if (!n.IsSequence()) return w.bad(n, key, "must be " + want);
  const int size = static_cast<int>(n.size());
  if (counts.size() > 0 && std::find(counts.begin(), counts.end(), size) == counts.end())
    return w.bad(n, key, "must be " + want + " (has " + std::to_string(size) + ")");
  std::vector<double> v;
  for (const YAML::Node& e : n) {
    try {
      v.push_back(e.as<double>());
    } catch (const YAML::Exception&) {
      return w.bad(e, key, "must be " + want + " (holds a non-number)");
    }
    if (!std::isfinite(v.back())) return w.bad(e, key, "holds a non-finite value");
  }
  return v;
}

Expected<std::vector<double>> matrix(const YAML::Node& map, const std::string& key,
                                     const Where& w, int rows, int cols) {
  auto m = subMap(map, key, w);
  if (!m) return Error{m.error()};
  const Where in = w.child(key);
  auto r = number(*m, "rows", in);
  if (!r) return Error{r.error()};
  auto c = number(*m, "cols", in);
  if (!c) return Error{c.error()};
  const std::string shape = std::to_string(rows) + "x" + (cols < 0 ? "N" : std::to_string(cols));
  if (*r != rows || (cols >= 0 && *c != cols) || *c < 0 || *c != std::floor(*c))
    return w.bad(*m, key, "must be a " + shape + " matrix (is " + std::to_string(int(*r)) + "x" +
                              std::to_string(int(*c)) + ")");
  const int n = rows * static_cast<int>(*c);
  auto data = numbers(*m, "data", in, {n});
  if (!data) return Error{data.error()};
  return data;
}

Status resolution(const YAML::Node& map, const std::string& key, const Where& w, int* width,
                  int* height) {
  auto v = numbers(map, key, w, {2});
  if (!v) return Error{v.error()};
  const double a = (*v)[0], b = (*v)[1];
  if (!(a >= 1 && b >= 1 && a < 1e5 && b < 1e5 && a == std::floor(a) && b == std::floor(b)))
    return w.bad(get(map, key), key, "must be two positive integers [width, height]");
  *width = static_cast<int>(a);
  *height = static_cast<int>(b);
  return Status::Ok();
}

Expected<SE3> transform(const YAML::Node& map, const std::string& key, const Where& w) {
  const YAML::Node n = get(map, key);
  if (!n) return w.missing(key);
  const Error shape = w.bad(n, key, "must be a 4x4 transform (16 numbers or 4 rows of 4)");
  if (!n.IsSequence()) return shape;
  // Kalibr writes 4 rows of 4, EuRoC-style files 16 numbers row-major.
  std::vector<YAML::Node> cells;
  if (n.size() == 4 && n[0].IsSequence()) {
    for (const YAML::Node& row : n) {
      if (!row.IsSequence() || row.size() != 4) return shape;
      for (const YAML::Node& e : row) cells.push_back(e);
    }
  } else {
    for (const YAML::Node& e : n) cells.push_back(e);
  }
  if (cells.size() != 16) return shape;
  std::vector<double> v;
  for (const YAML::Node& e : cells) {
    try {
      v.push_back(e.as<double>());
    } catch (const YAML::Exception&) {
      return w.bad(e, key, "holds a non-number");
    }
  }
  Mat4 T;
  for (int i = 0; i < 16; ++i) T(i / 4, i % 4) = v[i];
  return rigid(T, w.bad(n, key, "is not a rigid transform"));
}

Expected<SE3> rigid(const Mat4& T, const Error& bad) {
  const Mat3 R = T.topLeftCorner<3, 3>();
  const double ortho = (R.transpose() * R - Mat3::Identity()).norm();
  if (!T.allFinite() || !(ortho < 1e-4) || R.determinant() < 0 ||
      (T.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).norm() > 1e-9)
    return bad;
  return SE3(T);
}

Expected<Mat3> rotation(const std::vector<double>& v, const Error& bad) {
  Mat4 T = Mat4::Identity();
  for (int i = 0; i < 9; ++i) T(i / 3, i % 3) = v[i];
  auto se3 = rigid(T, bad);
  if (!se3) return Error{se3.error()};
  return se3->rotation();
}

Status setDistortion(const std::string& name, const std::vector<double>& coeffs,
                     const YAML::Node& map, const std::string& model_key,
                     const std::string& coeff_key, const Where& w, PinholeRadtan* cam) {
  struct Model {
    const char* name;
    DistortionModel model;
    std::vector<int> counts;
  };
  static const Model kModels[] = {
      {"none", DistortionModel::kRadtan, {0}},
      {"radtan", DistortionModel::kRadtan, {4}},
      {"radial-tangential", DistortionModel::kRadtan, {4}},
      {"plumb_bob", DistortionModel::kRadtan, {4, 5}},
      {"rational_polynomial", DistortionModel::kRadtan, {8}},
      {"equidistant", DistortionModel::kEquidistant, {4}},
  };
  for (const Model& m : kModels) {
    if (name != m.name) continue;
    const int n = static_cast<int>(coeffs.size());
    if (std::find(m.counts.begin(), m.counts.end(), n) == m.counts.end())
      return w.bad(get(map, coeff_key), coeff_key,
                   "must be " + countText(m.counts) + " numbers for distortion_model " + name +
                       " (has " + std::to_string(n) + ")");
    cam->model = m.model;
    cam->dist.fill(0.0);
    std::copy(coeffs.begin(), coeffs.end(), cam->dist.begin());
    return Status::Ok();
  }
  return w.bad(get(map, model_key), model_key,
               "'" + name + "' is not supported (none, radtan, plumb_bob, rational_polynomial, "
               "equidistant)");
}

std::string distortionName(const PinholeRadtan& cam) {
  if (cam.model == DistortionModel::kEquidistant) return "equidistant";
  if (!cam.hasDistortion()) return "none";
  switch (cam.distortionCount()) {
    case 4: return "radtan";
    case 5: return "plumb_bob";
    default: return "rational_polynomial";
  }
}

}  // namespace calib_yaml
}  // namespace hermes
