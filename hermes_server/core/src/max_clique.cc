// Maximum clique (exact branch and bound / greedy) and the chi-square quantile
// used by PCM.
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "hermes/server/pcm.h"

namespace hermes {
namespace server {

namespace {

using Mask = std::uint64_t;

inline int lowestBit(Mask m) { return __builtin_ctzll(m); }

/// Branch and bound with a greedy-colouring upper bound (Tomita's MCQ ordering,
/// bitset form): vertices of P are greedily coloured; a branch whose clique size
/// plus the colour number cannot beat the best is cut.
class ExactClique {
 public:
  explicit ExactClique(const std::vector<Mask>& nbr) : nbr_(nbr) {}

  std::vector<int> solve() {
    const int n = static_cast<int>(nbr_.size());
    const Mask all = n == 64 ? ~Mask{0} : ((Mask{1} << n) - 1);
    std::vector<int> current;
    expand(&current, all);
    return best_;
  }

 private:
  void expand(std::vector<int>* current, Mask P) {
    std::vector<int> order;
    std::vector<int> colour;
    colourSort(P, &order, &colour);
    for (int i = static_cast<int>(order.size()) - 1; i >= 0; --i) {
      if (static_cast<int>(current->size()) + colour[i] <= static_cast<int>(best_.size())) return;
      const int v = order[i];
      current->push_back(v);
      const Mask next = P & nbr_[v];
      if (next == 0) {
        if (current->size() > best_.size()) best_ = *current;
      } else {
        expand(current, next);
      }
      current->pop_back();
      P &= ~(Mask{1} << v);
    }
  }

  void colourSort(Mask P, std::vector<int>* order, std::vector<int>* colour) const {
    int k = 0;
    while (P) {
      ++k;
      Mask Q = P;
      while (Q) {
        const int v = lowestBit(Q);
        Q &= ~(Mask{1} << v);
        Q &= ~nbr_[v];
        P &= ~(Mask{1} << v);
        order->push_back(v);
        colour->push_back(k);
      }
    }
  }

  const std::vector<Mask>& nbr_;
  std::vector<int> best_;
};

/// The greedy heuristic on adjacency bitsets: the same choices as counting
/// neighbours pair by pair (ties to the lowest index), n/64 times fewer steps
/// (a whole-mission group of 800 loops took minutes per merge counted plainly).
/// Cloned for POPCNT: baseline x86-64 builds call libgcc's table popcount
/// otherwise (15 % of the server's time in the soak's last wave, 3500 loops).
#if defined(__x86_64__) && defined(__GNUC__)
__attribute__((target_clones("popcnt", "default")))
#endif
std::vector<int> greedyClique(const std::vector<std::vector<char>>& adj) {
  const int n = static_cast<int>(adj.size());
  const int words = (n + 63) / 64;
  using Bits = std::vector<std::uint64_t>;
  std::vector<Bits> nbr(n, Bits(words, 0));  // row i: j with adj[i][j], never i itself
  std::vector<int> degree(n, 0);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      if (i == j || !adj[i][j]) continue;
      nbr[i][j >> 6] |= std::uint64_t{1} << (j & 63);
      ++degree[i];
    }
  }
  auto common = [words](const Bits& a, const Bits& b) {
    int c = 0;
    for (int w = 0; w < words; ++w) c += __builtin_popcountll(a[w] & b[w]);
    return c;
  };
  std::vector<int> best;
  for (int start = 0; start < n; ++start) {
    if (degree[start] + 1 <= static_cast<int>(best.size())) continue;
    std::vector<int> clique{start};
    Bits cand = nbr[start];
    for (;;) {
      // Candidate with the most neighbours among the other candidates.
      int v = -1, best_deg = -1;
      for (int w = 0; w < words; ++w) {
        for (std::uint64_t bits = cand[w]; bits; bits &= bits - 1) {
          const int c = w * 64 + __builtin_ctzll(bits);
          const int d = common(nbr[c], cand);
          if (d > best_deg) best_deg = d, v = c;
        }
      }
      if (v < 0) break;
      clique.push_back(v);
      for (int w = 0; w < words; ++w) cand[w] &= nbr[v][w];
    }
    if (clique.size() > best.size()) best = clique;
  }
  return best;
}

/// Regularised lower incomplete gamma P(a, x) (series / continued fraction).
double gammaP(double a, double x) {
  if (x <= 0) return 0.0;
  const double lg = std::lgamma(a);
  if (x < a + 1) {
    double sum = 1.0 / a, term = sum, ap = a;
    for (int n = 0; n < 1000; ++n) {
      ap += 1;
      term *= x / ap;
      sum += term;
      if (std::abs(term) < std::abs(sum) * 1e-15) break;
    }
    return sum * std::exp(-x + a * std::log(x) - lg);
  }
  // Lentz's continued fraction for Q(a, x).
  double b = x + 1 - a, c = 1e300, d = 1 / b, h = d;
  for (int i = 1; i < 1000; ++i) {
    const double an = -i * (i - a);
    b += 2;
    d = an * d + b;
    if (std::abs(d) < 1e-300) d = 1e-300;
    c = b + an / c;
    if (std::abs(c) < 1e-300) c = 1e-300;
    d = 1 / d;
    const double del = d * c;
    h *= del;
    if (std::abs(del - 1) < 1e-15) break;
  }
  return 1.0 - std::exp(-x + a * std::log(x) - lg) * h;
}

}  // namespace

double chi2Quantile(double p, int dof) {
  HERMES_CHECK(p > 0 && p < 1 && dof >= 1, "chi2Quantile needs p in (0,1) and dof >= 1");
  double lo = 0, hi = 1;
  while (gammaP(0.5 * dof, 0.5 * hi) < p) hi *= 2;
  for (int it = 0; it < 200; ++it) {
    const double mid = 0.5 * (lo + hi);
    (gammaP(0.5 * dof, 0.5 * mid) < p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

std::vector<int> maximumClique(const std::vector<std::vector<char>>& adjacency, int exact_max,
                               bool* exact) {
  const int n = static_cast<int>(adjacency.size());
  const bool use_exact = n <= std::min(exact_max, 64);
  if (exact) *exact = use_exact;
  if (n == 0) return {};
  std::vector<int> clique;
  if (use_exact) {
    std::vector<Mask> nbr(n, 0);
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < n; ++j) {
        if (i != j && adjacency[i][j] && adjacency[j][i]) nbr[i] |= Mask{1} << j;
      }
    }
    clique = ExactClique(nbr).solve();
  } else {
    clique = greedyClique(adjacency);
  }
  std::sort(clique.begin(), clique.end());
  return clique;
}

}  // namespace server
}  // namespace hermes
