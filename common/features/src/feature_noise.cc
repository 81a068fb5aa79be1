#include "m2s/common/feature_noise.h"

#include <algorithm>
#include <cmath>
#include <unordered_set>

#include "m2s/common/check.h"

namespace m2s {
namespace {

// The stage keys the random streams: the values are fixed so that a seed keeps its noise.
enum class Stage : uint64_t {
  kDropout = 1,
  kPixelNoise = 2,
  kWrongId = 5,
  kWrongIdValue = 6,
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

bool ById(const ProjectedVertex& a, const ProjectedVertex& b) { return a.id < b.id; }

// Sorts by id (ids are distinct, so the order is unique); projectors mostly deliver that order.
void SortById(std::vector<ProjectedVertex>* features) {
  if (!std::is_sorted(features->begin(), features->end(), ById))
    std::sort(features->begin(), features->end(), ById);
}

void ApplyWrongIds(const FeatureNoiseOptions& o, uint32_t num_vertices, uint64_t frame,
                   std::vector<ProjectedVertex>* features) {
  // Process in id order so the assignment of replacement ids is order-independent. An id is
  // taken when a feature of the frame has it or it was handed out as a replacement.
  SortById(features);
  std::vector<VertexId> frame_ids(features->size());
  for (size_t i = 0; i < features->size(); ++i) frame_ids[i] = (*features)[i].id;
  std::unordered_set<VertexId> handed_out;
  auto taken = [&](VertexId id) {
    return std::binary_search(frame_ids.begin(), frame_ids.end(), id) || handed_out.count(id) != 0;
  };
  // Once fewer than 1/8 of the ids are free (a view that sees most of the scene), the free ids
  // are listed once, in increasing order, and each replacement takes the k-th of them (the same
  // id the scan for the k-th free id gives, without a scan of every id per feature).
  std::vector<VertexId> free_list;
  bool listed = false;
  size_t kept = 0;
  std::vector<ProjectedVertex> replaced;
  for (size_t i = 0; i < features->size(); ++i) {
    ProjectedVertex f = (*features)[i];
    if (Rng(o.seed, frame, f.id, Stage::kWrongId).Uniform() >= o.wrong_id_fraction) {
      (*features)[kept++] = f;
      continue;
    }
    const size_t num_taken = frame_ids.size() + handed_out.size();
    if (num_taken >= num_vertices) continue;  // no unused id left: drop the feature
    Rng rng(o.seed, frame, f.id, Stage::kWrongIdValue);
    const size_t free_ids = num_vertices - num_taken;
    VertexId id;
    if (free_ids * 8 >= num_vertices) {
      do {
        id = rng.Below(num_vertices);
      } while (taken(id));  // expected fewer than 8 draws
    } else {
      // Few free ids: pick the k-th free one directly.
      if (!listed) {
        free_list.reserve(free_ids);
        for (VertexId v = 0; v < num_vertices; ++v) {
          if (!taken(v)) free_list.push_back(v);
        }
        listed = true;
      }
      const uint32_t k = rng.Below(static_cast<uint32_t>(free_ids));
      id = free_list[k];
      free_list.erase(free_list.begin() + k);
    }
    handed_out.insert(id);
    f.id = id;
    replaced.push_back(f);
  }
  // The kept features are still in id order: merge the (few) replaced ones in.
  features->resize(kept);
  std::sort(replaced.begin(), replaced.end(), ById);
  const auto middle = static_cast<std::ptrdiff_t>(features->size());
  features->insert(features->end(), replaced.begin(), replaced.end());
  std::inplace_merge(features->begin(), features->begin() + middle, features->end(), ById);
}

}  // namespace

bool FeatureNoiseOptions::Enabled() const {
  return pixel_noise_sigma > 0 || quantization_px > 0 || dropout_probability > 0 ||
         wrong_id_fraction > 0;
}

Status FeatureNoiseOptions::Check() const {
  if (!std::isfinite(pixel_noise_sigma) || pixel_noise_sigma < 0)
    return Status::Error("pixel noise sigma must be finite and >= 0");
  if (!std::isfinite(quantization_px) || quantization_px < 0)
    return Status::Error("quantization step must be finite and >= 0 (0: off)");
  if (!(dropout_probability >= 0 && dropout_probability <= 1))
    return Status::Error("dropout probability must be in [0, 1]");
  if (!(wrong_id_fraction >= 0 && wrong_id_fraction <= 1))
    return Status::Error("wrong id fraction must be in [0, 1]");
  return Status::Ok();
}

void ApplyFeatureNoise(const FeatureNoiseOptions& o, const Camera& camera,
                       uint32_t num_scene_vertices, uint64_t frame_index,
                       std::vector<ProjectedVertex>* features) {
  const Status valid = o.Check();
  M2S_CHECK(valid) << valid.message();
  M2S_CHECK(features != nullptr);
  if (!o.Enabled()) {
    SortById(features);
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
  if (o.wrong_id_fraction > 0) ApplyWrongIds(o, num_scene_vertices, frame_index, features);
  SortById(features);
}

}  // namespace m2s
