// Texture synthesis for the renderer: multi-scale noise, bricks, tiles, blobs,
// text-like marks and randomly cropped / scaled / rotated / tinted photographs,
// laid out in panels, plus near-uniform (texture-poor) regions.
#include "hermes/core/render/texture.h"

#include <algorithm>
#include <cmath>
#include <fstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace hermes {
namespace render {

MipTexture MipTexture::fromImage(const cv::Mat& grey8) {
  MipTexture t;
  t.levels.push_back(grey8.isContinuous() ? grey8 : grey8.clone());
  while (t.levels.back().cols > 4 && t.levels.back().rows > 4) {
    cv::Mat next;
    cv::pyrDown(t.levels.back(), next);
    t.levels.push_back(next);
  }
  return t;
}

std::string PhotoLibrary::defaultFolder() { return "/usr/share/doc/opencv-doc/examples/data"; }

PhotoLibrary PhotoLibrary::load(const std::string& folder) {
  // Natural photographs (no calibration boards, no synthetic drawings).
  static const char* kNames[] = {
      "building.jpg",     "home.jpg",       "graf1.png",        "graf3.png",
      "leuvenA.jpg",      "leuvenB.jpg",    "aero1.jpg",        "aero3.jpg",
      "fruits.jpg",       "baboon.jpg",     "lena.jpg",         "box_in_scene.png",
      "messi5.jpg",       "starry_night.jpg", "stuff.jpg",      "orange.jpg",
      "apple.jpg",        "butterfly.jpg",  "HappyFish.jpg",    "board.jpg",
      "smarties.png",     "squirrel_cls.jpg", "rubberwhale1.png", "basketball1.png",
      "aloeL.jpg",        "ela_original.jpg", "licenseplate_motion.jpg", "pic1.png",
      "pic3.png",         "pic5.png",       "blox.jpg",         "notes.png"};
  PhotoLibrary lib;
  lib.folder = folder;
  for (const char* n : kNames) {
    const std::string path = folder + "/" + n;
    if (!std::ifstream(path).good()) continue;
    cv::Mat img = cv::imread(path, cv::IMREAD_GRAYSCALE);
    if (img.empty() || img.cols < 64 || img.rows < 64) continue;
    lib.photos.push_back(img);
    lib.names.push_back(n);
  }
  return lib;
}

namespace {

/// Smooth noise of the given feature size [texels], zero mean, unit-ish amplitude.
cv::Mat smoothNoise(cv::Size size, double feature_texels, cv::RNG& rng) {
  const int gw = std::max(2, static_cast<int>(size.width / feature_texels) + 2);
  const int gh = std::max(2, static_cast<int>(size.height / feature_texels) + 2);
  cv::Mat g(gh, gw, CV_32F);
  rng.fill(g, cv::RNG::UNIFORM, -1.0, 1.0);
  cv::Mat out;
  cv::resize(g, out, size, 0, 0, cv::INTER_CUBIC);
  return out;
}

/// Sum of noise octaves between `fine` and `coarse` feature sizes [texels].
cv::Mat multiScaleNoise(cv::Size size, double fine, double coarse, cv::RNG& rng) {
  cv::Mat acc = cv::Mat::zeros(size, CV_32F);
  double amp = 1.0, total = 0;
  for (double f = coarse; f >= fine; f *= 0.5) {
    acc += amp * smoothNoise(size, f, rng);
    total += amp;
    amp *= 0.75;
  }
  return acc / std::max(total, 1e-6) * 2.0;
}

void addTo(cv::Mat& dst8, const cv::Mat& f32, double gain) {
  cv::Mat tmp;
  dst8.convertTo(tmp, CV_32F);
  tmp += gain * f32;
  tmp.convertTo(dst8, CV_8U);
}

void paintPhoto(cv::Mat cell, double texel_m, const PhotoLibrary& lib, cv::RNG& rng) {
  const cv::Mat& photo = lib.photos[rng.uniform(0, static_cast<int>(lib.photos.size()))];
  // Photo texels per cell texel: show between ~35 % and 100 % of the photo's
  // short side across the cell's long side, at a random rotation and offset.
  const double cell_long = std::max(cell.cols, cell.rows);
  const double frac = rng.uniform(0.35, 1.0);
  const double s = frac * std::min(photo.cols, photo.rows) / cell_long;
  const double th = rng.uniform(-0.6, 0.6) + (rng.uniform(0, 4) == 0 ? CV_PI / 2 : 0.0);
  const double cs = std::cos(th) * s, sn = std::sin(th) * s;
  const double margin = 0.5 * (1.0 - frac) * std::min(photo.cols, photo.rows);
  const double pcx = photo.cols / 2.0 + rng.uniform(-margin, margin + 1e-9);
  const double pcy = photo.rows / 2.0 + rng.uniform(-margin, margin + 1e-9);
  const double ccx = cell.cols / 2.0, ccy = cell.rows / 2.0;
  const double flip = rng.uniform(0, 2) ? -1.0 : 1.0;
  // dst -> src map (WARP_INVERSE_MAP).
  cv::Matx23d M(flip * cs, -sn, pcx - flip * cs * ccx + sn * ccy,
                flip * sn, cs, pcy - flip * sn * ccx - cs * ccy);
  cv::Mat warped;
  cv::warpAffine(photo, warped, M, cell.size(), cv::INTER_AREA | cv::WARP_INVERSE_MAP,
                 cv::BORDER_REFLECT_101);
  (void)texel_m;
  const double a = rng.uniform(0.55, 1.05);
  const double b = rng.uniform(110.0, 150.0) - a * cv::mean(warped)[0];
  warped.convertTo(cell, CV_8U, a, b);
}

void paintBricks(cv::Mat cell, double texel_m, cv::RNG& rng) {
  const int bh = std::max(4, static_cast<int>(rng.uniform(0.06, 0.10) / texel_m));
  const int bw = std::max(8, static_cast<int>(rng.uniform(0.18, 0.30) / texel_m));
  const int mortar = std::max(1, static_cast<int>(0.012 / texel_m));
  const int base = rng.uniform(70, 150);
  cell.setTo(cv::Scalar(std::min(255, base + rng.uniform(40, 80))));
  for (int r = 0, row = 0; r < cell.rows; r += bh, ++row) {
    const int off = (row % 2) ? bw / 2 : 0;
    for (int c = -off; c < cell.cols; c += bw) {
      const int g = std::clamp(base + rng.uniform(-30, 30), 0, 255);
      cv::rectangle(cell, cv::Rect(c + mortar, r + mortar, bw - mortar, bh - mortar),
                    cv::Scalar(g), cv::FILLED);
    }
  }
  addTo(cell, multiScaleNoise(cell.size(), 2, 16, rng), 10);
}

void paintTiles(cv::Mat cell, double texel_m, cv::RNG& rng) {
  const int ts = std::max(6, static_cast<int>(rng.uniform(0.15, 0.4) / texel_m));
  const int grout = std::max(1, static_cast<int>(0.01 / texel_m));
  const int base = rng.uniform(80, 180);
  const int contrast = rng.uniform(10, 60);
  cell.setTo(cv::Scalar(std::max(0, base - 50)));
  for (int r = 0; r < cell.rows; r += ts)
    for (int c = 0; c < cell.cols; c += ts) {
      const bool odd = ((r / ts) + (c / ts)) % 2;
      const int g = std::clamp(base + (odd ? contrast : -contrast) + rng.uniform(-12, 12), 0, 255);
      cv::rectangle(cell, cv::Rect(c + grout, r + grout, ts - grout, ts - grout), cv::Scalar(g),
                    cv::FILLED);
    }
  addTo(cell, multiScaleNoise(cell.size(), 2, 32, rng), 6);
}

void paintBlobs(cv::Mat cell, double texel_m, cv::RNG& rng) {
  cell.setTo(cv::Scalar(rng.uniform(90, 170)));
  const double area_m2 = cell.total() * texel_m * texel_m;
  const int n = static_cast<int>(area_m2 * rng.uniform(15.0, 40.0)) + 3;
  for (int i = 0; i < n; ++i) {
    const cv::Point c(rng.uniform(0, cell.cols), rng.uniform(0, cell.rows));
    const double rad_m = std::exp(rng.uniform(std::log(0.02), std::log(0.25)));
    const int ra = std::max(2, static_cast<int>(rad_m / texel_m));
    const int rb = std::max(2, static_cast<int>(ra * rng.uniform(0.4, 1.0)));
    cv::ellipse(cell, c, cv::Size(ra, rb), rng.uniform(0.0, 180.0), 0, 360,
                cv::Scalar(rng.uniform(10, 245)), cv::FILLED, cv::LINE_AA);
  }
  addTo(cell, multiScaleNoise(cell.size(), 2, 16, rng), 5);
}

void paintText(cv::Mat cell, double texel_m, cv::RNG& rng) {
  const int paper = rng.uniform(170, 235);
  cell.setTo(cv::Scalar(paper));
  const double char_m = rng.uniform(0.03, 0.09);
  const double scale = char_m / texel_m / 22.0;  // Hershey simplex: ~22 px cap height at scale 1
  const int thick = std::max(1, static_cast<int>(scale * 2));
  const int line_h = static_cast<int>(char_m / texel_m * 1.8) + 2;
  const int ink = rng.uniform(0, 70);
  static const char kChars[] = "ABCDEFGHJKLMNPRSTUVWXYZ0123456789#+-=%&";
  for (int y = line_h; y < cell.rows; y += line_h) {
    if (rng.uniform(0, 6) == 0) continue;
    int x = rng.uniform(0, std::max(1, line_h));
    while (x < cell.cols) {
      std::string word;
      const int len = rng.uniform(2, 9);
      for (int i = 0; i < len; ++i) word += kChars[rng.uniform(0, static_cast<int>(sizeof(kChars) - 1))];
      cv::putText(cell, word, cv::Point(x, y), cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(ink),
                  thick, cv::LINE_AA);
      x += static_cast<int>((len + 1.5) * scale * 20);
    }
  }
}

void paintNoise(cv::Mat cell, cv::RNG& rng) {
  cell.setTo(cv::Scalar(rng.uniform(90, 170)));
  addTo(cell, multiScaleNoise(cell.size(), 2, rng.uniform(16.0, 128.0), rng), rng.uniform(25.0, 60.0));
}

}  // namespace

cv::Mat synthesizeTexture(int w, int h, double texel_m, TextureStyle style, double poor_fraction,
                          std::uint64_t seed, const PhotoLibrary& photos) {
  cv::RNG rng(seed ? seed : 0x9e3779b97f4a7c15ULL);
  // Near-uniform base: faint large-scale gradient and very faint fine noise.
  cv::Mat base(h, w, CV_8U, cv::Scalar(rng.uniform(95, 165)));
  addTo(base, smoothNoise(base.size(), 2.0 / texel_m, rng), rng.uniform(4.0, 10.0));
  if (style == TextureStyle::kPoor) {
    addTo(base, smoothNoise(base.size(), 4, rng), 1.5);
    return base;
  }
  cv::Mat tex = base;
  // Panels: columns 1.2-3.5 m wide, rows 0.8-2.5 m high, with a small gap.
  const int gap = std::max(1, static_cast<int>(rng.uniform(0.03, 0.08) / texel_m));
  for (int x0 = 0; x0 < w;) {
    const int pw = std::min(w - x0, static_cast<int>(rng.uniform(1.2, 3.5) / texel_m));
    for (int y0 = 0; y0 < h;) {
      const int ph = std::min(h - y0, static_cast<int>(rng.uniform(0.8, 2.5) / texel_m));
      const cv::Rect r(x0 + gap, y0 + gap, pw - 2 * gap, ph - 2 * gap);
      y0 += ph;
      if (r.width < 8 || r.height < 8) continue;
      const double u = rng.uniform(0.0, 1.0);
      if (u < poor_fraction) continue;
      const double v = (u - poor_fraction) / std::max(1e-9, 1.0 - poor_fraction);
      cv::Mat cell = tex(r);
      if (v < 0.45 && !photos.photos.empty()) paintPhoto(cell, texel_m, photos, rng);
      else if (v < 0.55) paintBricks(cell, texel_m, rng);
      else if (v < 0.65) paintTiles(cell, texel_m, rng);
      else if (v < 0.78) paintBlobs(cell, texel_m, rng);
      else if (v < 0.88) paintText(cell, texel_m, rng);
      else paintNoise(cell, rng);
    }
    x0 += pw;
  }
  // Soften texel-level steps (drawn edges) and add faint fine grain everywhere.
  cv::GaussianBlur(tex, tex, cv::Size(3, 3), 0.6);
  addTo(tex, smoothNoise(tex.size(), 3, rng), 2.0);
  return tex;
}

}  // namespace render
}  // namespace hermes
