// Statistics and determinism of ApplyFeatureNoise.
#include <algorithm>
#include <cmath>
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
  EXPECT_NEAR(mean, 0.0, 0.01);
  EXPECT_NEAR(sigma, 0.7, 0.7 * 0.02);
  EXPECT_NEAR(cross / input.size() / (0.7 * 0.7), 0.0, 0.03);  // u and v independent
}

TEST(FeatureNoiseTest, NoiseNeverLeavesTheImage) {
  FeatureNoiseOptions options;
  options.pixel_noise_sigma = 20.0;
  std::vector<ProjectedVertex> features = MakeFeatures(5000, 0.0);
  ApplyFeatureNoise(options, kCamera, kNumSceneVertices, 0, &features);
  EXPECT_LT(features.size(), 5000u);
  EXPECT_GT(features.size(), 4000u);
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
  EXPECT_NEAR(static_cast<double>(wrong) / input.size(), 0.1, 0.01);

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
    EXPECT_NEAR(mean_error / (2.0 * out.size()), 0.0, 0.05 * q);  // unbiased
  }
}

TEST(FeatureNoiseTest, BudgetSpreadsFeaturesEvenlyOverTheGrid) {
  FeatureNoiseOptions options;
  options.budget = 100;
  options.grid_cols = 4;
  options.grid_rows = 3;
  // Cell (0, 0) holds 2000 features, each other cell 5: sparse cells keep all theirs.
  std::vector<ProjectedVertex> features;
  std::mt19937 rng(2);
  std::uniform_real_distribution<float> unit(0.01f, 0.99f);
  VertexId id = 0;
  for (int cell = 0; cell < 12; ++cell) {
    const int col = cell % 4, row = cell / 4;
    for (int k = 0; k < (cell == 0 ? 2000 : 5); ++k) {
      features.push_back({id++, (col + unit(rng)) * 160.f, (row + unit(rng)) * 160.f, 1.f});
    }
  }
  auto count_per_cell = [](const std::vector<ProjectedVertex>& fs) {
    std::vector<int> counts(12, 0);
    for (const ProjectedVertex& f : fs)
      ++counts[static_cast<int>(f.v / 160) * 4 + static_cast<int>(f.u / 160)];
    return counts;
  };
  std::vector<ProjectedVertex> out = features;
  ApplyFeatureNoise(options, kCamera, kNumSceneVertices, 0, &out);
  ASSERT_EQ(out.size(), 100u);
  std::vector<int> counts = count_per_cell(out);
  EXPECT_EQ(counts[0], 100 - 11 * 5);
  for (int cell = 1; cell < 12; ++cell) EXPECT_EQ(counts[cell], 5);

  // Every cell dense: the budget splits evenly, at most one apart.
  features.clear();
  for (int cell = 0; cell < 12; ++cell) {
    for (int k = 0; k < 300; ++k) {
      features.push_back(
          {id++, (cell % 4 + unit(rng)) * 160.f, (cell / 4 + unit(rng)) * 160.f, 1.f});
    }
  }
  options.budget = 130;
  out = features;
  ApplyFeatureNoise(options, kCamera, kNumSceneVertices, 0, &out);
  ASSERT_EQ(out.size(), 130u);
  counts = count_per_cell(out);
  EXPECT_EQ(*std::max_element(counts.begin(), counts.end()), 11);
  EXPECT_EQ(*std::min_element(counts.begin(), counts.end()), 10);

  // Under budget: untouched.
  out = MakeFeatures(50);
  ApplyFeatureNoise(options, kCamera, kNumSceneVertices, 0, &out);
  EXPECT_EQ(out.size(), 50u);
}

TEST(FeatureNoiseTest, DeterministicGivenSeedAndFrameWhateverTheInputOrder) {
  FeatureNoiseOptions options;
  options.pixel_noise_sigma = 1.0;
  options.dropout_probability = 0.2;
  options.wrong_id_fraction = 0.05;
  options.budget = 500;
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
  EXPECT_EQ(first.size(), 500u);
  EXPECT_TRUE(same(first, run(input, 123, 7)));
  std::vector<ProjectedVertex> shuffled = input;
  std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(4));
  EXPECT_TRUE(same(first, run(shuffled, 123, 7)));
  EXPECT_FALSE(same(first, run(input, 124, 7)));
  EXPECT_FALSE(same(first, run(input, 123, 8)));
  for (size_t i = 1; i < first.size(); ++i) EXPECT_LT(first[i - 1].id, first[i].id);
}

TEST(FeatureNoiseTest, CheckRejectsBadOptions) {
  std::string why;
  EXPECT_TRUE(FeatureNoiseOptions{}.Check(&why));
  EXPECT_FALSE(FeatureNoiseOptions{}.Enabled());
  auto bad = [](auto mutate) {
    FeatureNoiseOptions o;
    mutate(o);
    std::string reason;
    const bool ok = o.Check(&reason);
    EXPECT_FALSE(reason.empty() && !ok);
    return !ok;
  };
  EXPECT_TRUE(bad([](FeatureNoiseOptions& o) { o.pixel_noise_sigma = -1; }));
  EXPECT_TRUE(bad([](FeatureNoiseOptions& o) { o.pixel_noise_sigma = INFINITY; }));
  EXPECT_TRUE(bad([](FeatureNoiseOptions& o) { o.quantization_px = -0.5; }));
  EXPECT_TRUE(bad([](FeatureNoiseOptions& o) { o.dropout_probability = 1.5; }));
  EXPECT_TRUE(bad([](FeatureNoiseOptions& o) { o.dropout_probability = NAN; }));
  EXPECT_TRUE(bad([](FeatureNoiseOptions& o) { o.wrong_id_fraction = -0.1; }));
  EXPECT_TRUE(bad([](FeatureNoiseOptions& o) { o.budget = -1; }));
  EXPECT_TRUE(bad([](FeatureNoiseOptions& o) { o.grid_cols = 0; }));
  EXPECT_TRUE(bad([](FeatureNoiseOptions& o) { o.grid_rows = 100000; }));
}

}  // namespace
}  // namespace m2s
