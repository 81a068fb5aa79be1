// Statistics and determinism of ApplyFeatureNoise.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <set>
#include <vector>

#include <gtest/gtest.h>

#include "m2s/common/feature_noise.h"

namespace m2s {
namespace {

const Camera kCamera = Camera::FromHorizontalFov(640, 480, 90.0);
constexpr uint32_t kNumSceneVertices = 1000000;

// n features with distinct ids (0, 7, 14, ...) and distinct positions away from the border.
std::vector<ProjectedVertex> MakeFeatures(int n, double margin = 50.0) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(margin, kCamera.width - margin);
  std::uniform_real_distribution<float> v(margin, kCamera.height - margin);
  std::vector<ProjectedVertex> features;
  for (int i = 0; i < n; ++i)
    features.push_back({static_cast<VertexId>(7 * i), u(rng), v(rng), 2.f});
  return features;
}

TEST(FeatureNoiseTest, PixelNoiseHasTheRequestedSigmaAndZeroMean) {
  FeatureNoiseOptions options;
  options.pixel_noise_sigma = 0.7;
  options.seed = 42;
  const std::vector<ProjectedVertex> input = MakeFeatures(40000);
  std::vector<ProjectedVertex> noisy = input;
  ApplyFeatureNoise(options, kCamera, kNumSceneVertices, 3, &noisy);
  ASSERT_EQ(noisy.size(), input.size());  // far from the border: nothing leaves the image
  double sum = 0, sum_sq = 0, cross = 0;
  for (size_t i = 0; i < input.size(); ++i) {
    ASSERT_EQ(noisy[i].id, input[i].id);
    EXPECT_EQ(noisy[i].depth, input[i].depth);
    const double du = noisy[i].u - input[i].u, dv = noisy[i].v - input[i].v;
    sum += du + dv;
    sum_sq += du * du + dv * dv;
    cross += du * dv;
  }
  const double n = 2.0 * input.size();
  const double mean = sum / n, sigma = std::sqrt(sum_sq / n - mean * mean);
  // Bounds of about 4 standard errors of each estimate over the 80000 offsets (measured:
  // mean -0.0015, sigma 0.6981, correlation -0.0045, each within 1.1 standard errors).
  EXPECT_NEAR(mean, 0.0, 4 * 0.7 / std::sqrt(n));
  EXPECT_NEAR(sigma, 0.7, 4 * 0.7 / std::sqrt(2 * n));
  EXPECT_NEAR(cross / input.size() / (0.7 * 0.7), 0.0, 4 / std::sqrt(n / 2));  // u, v independent
}

TEST(FeatureNoiseTest, NoiseNeverLeavesTheImage) {
  FeatureNoiseOptions options;
  options.pixel_noise_sigma = 20.0;
  std::vector<ProjectedVertex> features = MakeFeatures(5000, 0.0);
  ApplyFeatureNoise(options, kCamera, kNumSceneVertices, 0, &features);
  // Uniform in [0, L) with N(0, s) noise, a point leaves across the two edges with probability
  // 2 s / (L sqrt(2 pi)): 2.49 % across u, 3.32 % across v, so 4713 of the 5000 stay (measured
  // 4702); the bound is 4 standard errors.
  const double stay =
      (1 - 2 * 20.0 / (640 * std::sqrt(2 * M_PI))) * (1 - 2 * 20.0 / (480 * std::sqrt(2 * M_PI)));
  EXPECT_NEAR(static_cast<double>(features.size()), 5000 * stay,
              4 * std::sqrt(5000 * stay * (1 - stay)));
  for (const ProjectedVertex& f : features) EXPECT_TRUE(kCamera.InImage(f.u, f.v));
}

TEST(FeatureNoiseTest, DropoutRemovesTheRequestedFraction) {
  FeatureNoiseOptions options;
  options.dropout_probability = 0.3;
  const std::vector<ProjectedVertex> input = MakeFeatures(40000);
  std::vector<ProjectedVertex> kept = input;
  ApplyFeatureNoise(options, kCamera, kNumSceneVertices, 0, &kept);
  EXPECT_NEAR(1.0 - static_cast<double>(kept.size()) / input.size(), 0.3, 0.01);
  // Survivors are untouched.
  std::map<VertexId, ProjectedVertex> by_id;
  for (const ProjectedVertex& f : input) by_id[f.id] = f;
  for (const ProjectedVertex& f : kept) {
    ASSERT_EQ(by_id.count(f.id), 1u);
    EXPECT_EQ(by_id[f.id].u, f.u);
    EXPECT_EQ(by_id[f.id].v, f.v);
  }
  options.dropout_probability = 1.0;
  kept = input;
  ApplyFeatureNoise(options, kCamera, kNumSceneVertices, 0, &kept);
  EXPECT_TRUE(kept.empty());
}

TEST(FeatureNoiseTest, WrongIdsHaveTheRequestedFractionAndStayUnique) {
  FeatureNoiseOptions options;
  options.wrong_id_fraction = 0.1;
  options.seed = 9;
  const std::vector<ProjectedVertex> input = MakeFeatures(40000);
  std::map<std::pair<float, float>, VertexId> id_at;
  std::set<VertexId> input_ids;
  for (const ProjectedVertex& f : input) {
    id_at[{f.u, f.v}] = f.id;
    input_ids.insert(f.id);
  }
  ASSERT_EQ(id_at.size(), input.size());
  std::vector<ProjectedVertex> out = input;
  ApplyFeatureNoise(options, kCamera, kNumSceneVertices, 5, &out);
  ASSERT_EQ(out.size(), input.size());
  std::set<VertexId> out_ids;
  int wrong = 0;
  for (const ProjectedVertex& f : out) {
    EXPECT_TRUE(out_ids.insert(f.id).second) << "duplicate id " << f.id;
    EXPECT_LT(f.id, kNumSceneVertices);
    if (f.id != id_at.at({f.u, f.v})) {
      ++wrong;
      EXPECT_EQ(input_ids.count(f.id), 0u) << "wrong id taken from the frame";
    }
  }
  // Measured 0.1022; the bound is 4 standard errors of a fraction over 40000 features.
  EXPECT_NEAR(static_cast<double>(wrong) / input.size(), 0.1, 4 * std::sqrt(0.1 * 0.9 / 40000));

  // With no free id in the scene, features chosen for a wrong id are dropped.
  std::vector<ProjectedVertex> full;
  for (VertexId id = 0; id < 1000; ++id) full.push_back({id, 100.f + id * 0.1f, 100.f, 1.f});
  options.wrong_id_fraction = 0.5;
  ApplyFeatureNoise(options, kCamera, 1000, 0, &full);
  EXPECT_NEAR(full.size(), 500.0, 60.0);
  for (const ProjectedVertex& f : full) EXPECT_FLOAT_EQ(f.u, 100.f + f.id * 0.1f);

  // With few free ids, all of them can be used.
  std::vector<ProjectedVertex> dense;
  for (VertexId id = 0; id < 990; ++id) dense.push_back({id, 100.f + id * 0.1f, 100.f, 1.f});
  options.wrong_id_fraction = 1.0;
  ApplyFeatureNoise(options, kCamera, 1000, 0, &dense);
  EXPECT_EQ(dense.size(), 10u);
  for (const ProjectedVertex& f : dense) EXPECT_GE(f.id, 990u);
}

TEST(FeatureNoiseTest, WrongIdsOfAViewThatSeesMostOfTheSceneComeFromTheFreeIds) {
  // 8706 of 10000 ids in view (13 % free), a tenth of them wrong: the replacements use up the
  // free ids until fewer than an eighth are left, and go on from the list of the rest.
  std::vector<ProjectedVertex> view;
  std::set<VertexId> in_view;
  for (VertexId id = 0; id < 10000; ++id) {
    if (id % 8 == 3 || id >= 9950) continue;  // 1294 ids out of view
    view.push_back({id, 50.f + (id % 500), 50.f + (id / 500) * 10.f, 1.f});
    in_view.insert(id);
  }
  ASSERT_EQ(view.size(), 8706u);
  FeatureNoiseOptions options;
  options.wrong_id_fraction = 0.1;
  options.seed = 4;
  std::vector<ProjectedVertex> out = view;
  ApplyFeatureNoise(options, kCamera, 10000, 3, &out);
  ASSERT_EQ(out.size(), view.size());
  std::set<VertexId> out_ids, replacements;
  for (const ProjectedVertex& f : out) {
    ASSERT_LT(f.id, 10000u);
    EXPECT_TRUE(out_ids.insert(f.id).second) << "duplicate id " << f.id;
    if (in_view.count(f.id) == 0) replacements.insert(f.id);
  }
  // Measured 880 replacements (4 standard errors of the fraction: +-112).
  EXPECT_NEAR(static_cast<double>(replacements.size()), 870.6, 4 * std::sqrt(8706 * 0.1 * 0.9));
  // They are spread over the free ids, not the lowest ones.
  std::vector<VertexId> free_ids;
  for (VertexId id = 0; id < 10000; ++id) {
    if (in_view.count(id) == 0) free_ids.push_back(id);
  }
  EXPECT_GT(*replacements.rbegin(), free_ids[free_ids.size() * 9 / 10]);
  EXPECT_LT(*replacements.begin(), free_ids[free_ids.size() / 10]);
  // The input order does not matter.
  std::vector<ProjectedVertex> reversed(view.rbegin(), view.rend());
  ApplyFeatureNoise(options, kCamera, 10000, 3, &reversed);
  ASSERT_EQ(reversed.size(), out.size());
  for (size_t i = 0; i < out.size(); ++i) EXPECT_EQ(reversed[i].id, out[i].id);
}

TEST(FeatureNoiseTest, QuantisationSnapsToCellCentres) {
  for (const double q : {1.0, 2.5}) {
    FeatureNoiseOptions options;
    options.quantization_px = q;
    const std::vector<ProjectedVertex> input = MakeFeatures(5000);
    std::vector<ProjectedVertex> out = input;
    ApplyFeatureNoise(options, kCamera, kNumSceneVertices, 0, &out);
    ASSERT_EQ(out.size(), input.size());
    double mean_error = 0;
    for (size_t i = 0; i < out.size(); ++i) {
      for (const auto& [quantised, original] :
           {std::pair{out[i].u, input[i].u}, std::pair{out[i].v, input[i].v}}) {
        const double cell = quantised / q - 0.5;
        EXPECT_NEAR(cell, std::round(cell), 1e-4);
        EXPECT_LE(std::abs(quantised - original), q / 2 + 1e-4);
        EXPECT_EQ(std::floor(original / q), std::round(cell));  // the cell the point was in
        mean_error += quantised - original;
      }
    }
    // Unbiased: the error is uniform in [-q/2, q/2) (standard deviation q / sqrt(12)); the
    // bound is 4 standard errors of the mean of the 10000 errors (measured -0.0002 q and
    // -0.0041 q).
    EXPECT_NEAR(mean_error / (2.0 * out.size()), 0.0, 4 * q / std::sqrt(12.0 * 2 * out.size()));
  }
}

TEST(FeatureNoiseTest, DeterministicGivenSeedAndFrameWhateverTheInputOrder) {
  FeatureNoiseOptions options;
  options.pixel_noise_sigma = 1.0;
  options.dropout_probability = 0.2;
  options.wrong_id_fraction = 0.05;
  options.quantization_px = 0.25;
  options.seed = 123;
  const std::vector<ProjectedVertex> input = MakeFeatures(3000);
  auto run = [&](std::vector<ProjectedVertex> features, uint64_t seed, uint64_t frame) {
    FeatureNoiseOptions o = options;
    o.seed = seed;
    ApplyFeatureNoise(o, kCamera, kNumSceneVertices, frame, &features);
    return features;
  };
  auto same = [](const std::vector<ProjectedVertex>& a, const std::vector<ProjectedVertex>& b) {
    if (a.size() != b.size()) return false;
    for (size_t i = 0; i < a.size(); ++i) {
      if (a[i].id != b[i].id || a[i].u != b[i].u || a[i].v != b[i].v) return false;
    }
    return true;
  };
  const std::vector<ProjectedVertex> first = run(input, 123, 7);
  EXPECT_LT(first.size(), input.size());  // dropout removed some
  EXPECT_TRUE(same(first, run(input, 123, 7)));
  std::vector<ProjectedVertex> shuffled = input;
  std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(4));
  EXPECT_TRUE(same(first, run(shuffled, 123, 7)));
  EXPECT_FALSE(same(first, run(input, 124, 7)));
  EXPECT_FALSE(same(first, run(input, 123, 8)));
  for (size_t i = 1; i < first.size(); ++i) EXPECT_LT(first[i - 1].id, first[i].id);
}

TEST(FeatureNoiseTest, CheckRejectsBadOptions) {
  EXPECT_TRUE(FeatureNoiseOptions{}.Check());
  EXPECT_FALSE(FeatureNoiseOptions{}.Enabled());
  auto bad = [](auto mutate) {
    FeatureNoiseOptions o;
    mutate(o);
    const Status valid = o.Check();
    EXPECT_TRUE(valid || !valid.message().empty());  // a refusal says why
    return !valid.ok();
  };
  EXPECT_TRUE(bad([](FeatureNoiseOptions& o) { o.pixel_noise_sigma = -1; }));
  EXPECT_TRUE(bad([](FeatureNoiseOptions& o) { o.pixel_noise_sigma = INFINITY; }));
  EXPECT_TRUE(bad([](FeatureNoiseOptions& o) { o.quantization_px = -0.5; }));
  EXPECT_TRUE(bad([](FeatureNoiseOptions& o) { o.dropout_probability = 1.5; }));
  EXPECT_TRUE(bad([](FeatureNoiseOptions& o) { o.dropout_probability = NAN; }));
  EXPECT_TRUE(bad([](FeatureNoiseOptions& o) { o.wrong_id_fraction = -0.1; }));
}

}  // namespace
}  // namespace m2s
