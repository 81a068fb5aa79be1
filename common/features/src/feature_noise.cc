#include "m2s/common/feature_noise.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <unordered_set>

#include "m2s/common/check.h"

namespace m2s {
namespace {

constexpr int kMaxGridCells = 4096;

enum class Stage : uint64_t {
  kDropout = 1,
  kPixelNoise,
  kBudget,
  kBudgetCells,
  kWrongId,
  kWrongIdValue
};

uint64_t Mix(uint64_t x) {  // SplitMix64 finaliser
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// A small generator seeded by a hash of (seed, frame, key, stage): the same key always gives
// the same stream, on every platform (no std:: distributions, whose output is unspecified).
class Rng {
 public:
  Rng(uint64_t seed, uint64_t frame, uint64_t key, Stage stage)
      : state_(Mix(Mix(Mix(seed) ^ frame) ^ key) ^ static_cast<uint64_t>(stage)) {}
  uint64_t Next() {
    state_ += 0x9E3779B97F4A7C15ull;
    uint64_t z = state_;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  double Uniform() { return static_cast<double>(Next() >> 11) * 0x1.0p-53; }  // [0, 1)
  // Two independent standard normals (Box-Muller).
  std::pair<double, double> Normal2() {
    const double radius = std::sqrt(-2.0 * std::log(1.0 - Uniform()));
    const double angle = 2.0 * M_PI * Uniform();
    return {radius * std::cos(angle), radius * std::sin(angle)};
  }
  // Uniform in [0, n), n > 0, without modulo bias (Lemire's method).
  uint32_t Below(uint32_t n) {
    for (;;) {
      const uint64_t product = (Next() >> 32) * static_cast<uint64_t>(n);
      const uint32_t low = static_cast<uint32_t>(product);
      if (low >= (0x100000000ull % n)) return static_cast<uint32_t>(product >> 32);
    }
  }

 private:
  uint64_t state_;
};

bool InImage(const ProjectedVertex& f, const Camera& camera) {
  return f.u >= 0.f && f.v >= 0.f && f.u < static_cast<float>(camera.width) &&
         f.v < static_cast<float>(camera.height);
}

void ApplyBudget(const FeatureNoiseOptions& o, const Camera& camera, uint64_t frame,
                 std::vector<ProjectedVertex>* features) {
  const size_t budget = static_cast<size_t>(o.budget);
  if (features->size() <= budget) return;
  const int num_cells = o.grid_cols * o.grid_rows;
  struct Entry {
    int cell;
    uint64_t key;
    size_t index;
  };
  std::vector<Entry> entries;
  entries.reserve(features->size());
  for (size_t i = 0; i < features->size(); ++i) {
    const ProjectedVertex& f = (*features)[i];
    const int col = std::min(o.grid_cols - 1, static_cast<int>(f.u * o.grid_cols / camera.width));
    const int row = std::min(o.grid_rows - 1, static_cast<int>(f.v * o.grid_rows / camera.height));
    entries.push_back(
        {row * o.grid_cols + col, Rng(o.seed, frame, f.id, Stage::kBudget).Next(), i});
  }
  std::sort(entries.begin(), entries.end(), [features](const Entry& a, const Entry& b) {
    if (a.cell != b.cell) return a.cell < b.cell;
    if (a.key != b.key) return a.key < b.key;
    return (*features)[a.index].id < (*features)[b.index].id;
  });
  std::vector<size_t> cell_begin(num_cells + 1, 0);
  for (const Entry& e : entries) ++cell_begin[e.cell + 1];
  std::partial_sum(cell_begin.begin(), cell_begin.end(), cell_begin.begin());
  // A random cell order for this frame, so the last partial round favours no image region.
  std::vector<std::pair<uint64_t, int>> order(num_cells);
  for (int c = 0; c < num_cells; ++c) {
    order[c] = {Rng(o.seed, frame, static_cast<uint64_t>(c), Stage::kBudgetCells).Next(), c};
  }
  std::sort(order.begin(), order.end());
  std::vector<ProjectedVertex> kept;
  kept.reserve(budget);
  for (size_t round = 0; kept.size() < budget; ++round) {
    for (const auto& [key, cell] : order) {
      if (cell_begin[cell] + round < cell_begin[cell + 1]) {
        kept.push_back((*features)[entries[cell_begin[cell] + round].index]);
        if (kept.size() == budget) break;
      }
    }
  }
  features->swap(kept);
}

void ApplyWrongIds(const FeatureNoiseOptions& o, uint32_t num_vertices, uint64_t frame,
                   std::vector<ProjectedVertex>* features) {
  // Process in id order so the assignment of replacement ids is order-independent.
  std::sort(features->begin(), features->end(),
            [](const ProjectedVertex& a, const ProjectedVertex& b) { return a.id < b.id; });
  std::unordered_set<VertexId> taken;
  taken.reserve(features->size() * 2);
  for (const ProjectedVertex& f : *features) taken.insert(f.id);
  std::vector<ProjectedVertex> out;
  out.reserve(features->size());
  for (ProjectedVertex f : *features) {
    if (Rng(o.seed, frame, f.id, Stage::kWrongId).Uniform() >= o.wrong_id_fraction) {
      out.push_back(f);
      continue;
    }
    if (taken.size() >= num_vertices) continue;  // no unused id left: drop the feature
    Rng rng(o.seed, frame, f.id, Stage::kWrongIdValue);
    const size_t free_ids = num_vertices - taken.size();
    VertexId id;
    if (free_ids * 8 >= num_vertices) {
      do {
        id = rng.Below(num_vertices);
      } while (taken.count(id) != 0);  // expected fewer than 8 draws
    } else {
      // Few free ids: pick the k-th free one directly.
      uint32_t k = rng.Below(static_cast<uint32_t>(free_ids));
      for (id = 0;; ++id) {
        if (taken.count(id) == 0 && k-- == 0) break;
      }
    }
    taken.insert(id);
    f.id = id;
    out.push_back(f);
  }
  features->swap(out);
}

}  // namespace

bool FeatureNoiseOptions::Enabled() const {
  return pixel_noise_sigma > 0 || quantization_px > 0 || dropout_probability > 0 ||
         wrong_id_fraction > 0 || budget > 0;
}

bool FeatureNoiseOptions::Check(std::string* why) const {
  auto fail = [why](const char* msg) {
    if (why) *why = msg;
    return false;
  };
  if (!std::isfinite(pixel_noise_sigma) || pixel_noise_sigma < 0)
    return fail("pixel noise sigma must be finite and >= 0");
  if (!std::isfinite(quantization_px) || quantization_px < 0)
    return fail("quantization step must be finite and >= 0 (0: off)");
  if (!(dropout_probability >= 0 && dropout_probability <= 1))
    return fail("dropout probability must be in [0, 1]");
  if (!(wrong_id_fraction >= 0 && wrong_id_fraction <= 1))
    return fail("wrong id fraction must be in [0, 1]");
  if (budget < 0) return fail("feature budget must be >= 0 (0: unlimited)");
  if (grid_cols < 1 || grid_rows < 1 || grid_cols * static_cast<int64_t>(grid_rows) > kMaxGridCells)
    return fail("budget grid must have >= 1 column and row and at most 4096 cells");
  return true;
}

void ApplyFeatureNoise(const FeatureNoiseOptions& o, const Camera& camera,
                       uint32_t num_scene_vertices, uint64_t frame_index,
                       std::vector<ProjectedVertex>* features) {
  std::string why;
  M2S_CHECK(o.Check(&why)) << why;
  M2S_CHECK(features != nullptr);
  if (!o.Enabled()) {
    std::sort(features->begin(), features->end(),
              [](const ProjectedVertex& a, const ProjectedVertex& b) { return a.id < b.id; });
    return;
  }
  const double q = o.quantization_px;
  auto quantize = [q](float x) {
    return static_cast<float>((std::floor(static_cast<double>(x) / q) + 0.5) * q);
  };
  size_t kept = 0;
  for (size_t i = 0; i < features->size(); ++i) {
    ProjectedVertex f = (*features)[i];
    if (o.dropout_probability > 0 &&
        Rng(o.seed, frame_index, f.id, Stage::kDropout).Uniform() < o.dropout_probability) {
      continue;
    }
    if (o.pixel_noise_sigma > 0) {
      const auto [nu, nv] = Rng(o.seed, frame_index, f.id, Stage::kPixelNoise).Normal2();
      f.u = static_cast<float>(f.u + o.pixel_noise_sigma * nu);
      f.v = static_cast<float>(f.v + o.pixel_noise_sigma * nv);
    }
    if (q > 0) {
      f.u = quantize(f.u);
      f.v = quantize(f.v);
    }
    if (!InImage(f, camera)) continue;
    (*features)[kept++] = f;
  }
  features->resize(kept);
  if (o.budget > 0) ApplyBudget(o, camera, frame_index, features);
  if (o.wrong_id_fraction > 0) ApplyWrongIds(o, num_scene_vertices, frame_index, features);
  std::sort(features->begin(), features->end(),
            [](const ProjectedVertex& a, const ProjectedVertex& b) { return a.id < b.id; });
}

}  // namespace m2s
