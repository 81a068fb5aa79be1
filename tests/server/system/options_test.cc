// The options' checks: every struct's defaults pass, each rule refuses its field by name, and
// slam::Options::Check checks its own fields, the cross-stage rule and every stage's struct.
#include "m2s/slam/options.h"

#include <cmath>
#include <functional>
#include <limits>
#include <string>

#include <gtest/gtest.h>

namespace m2s::slam {
namespace {

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();

// Applies `change` to default options and expects Check to refuse them, naming `field`.
template <typename T>
void ExpectRefused(const std::function<void(T*)>& change, const std::string& field) {
  T options;
  change(&options);
  Status why;
  EXPECT_FALSE((why = options.Check())) << field;
  EXPECT_NE(why.message().find(field), std::string::npos)
      << "'" << why.message() << "' does not name " << field;
}

TEST(Options, DefaultsPass) {
  Status why;
  EXPECT_TRUE((why = InitializerOptions().Check())) << why.message();
  EXPECT_TRUE((why = TrackerOptions().Check())) << why.message();
  EXPECT_TRUE((why = MapperOptions().Check())) << why.message();
  EXPECT_TRUE((why = DriftOptions().Check())) << why.message();
  EXPECT_TRUE((why = Options().Check())) << why.message();
}

TEST(Options, InitializerRules) {
  using O = InitializerOptions;
  ExpectRefused<O>([](O* o) { o->min_points = 7; }, "min_points");
  ExpectRefused<O>([](O* o) { o->min_parallax_deg = 0.0; }, "min_parallax_deg");
  ExpectRefused<O>([](O* o) { o->min_parallax_deg = kNan; }, "min_parallax_deg");
  ExpectRefused<O>([](O* o) { o->max_reference_age = 1; }, "max_reference_age");
}

TEST(Options, TrackerRules) {
  using O = TrackerOptions;
  ExpectRefused<O>([](O* o) { o->max_points = -1; }, "max_points");
  ExpectRefused<O>([](O* o) { o->min_inliers = 5; }, "min_inliers");
  ExpectRefused<O>([](O* o) { o->keyframe_tracked_ratio = 0.0; }, "keyframe_tracked_ratio");
  ExpectRefused<O>([](O* o) { o->keyframe_tracked_ratio = 1.5; }, "keyframe_tracked_ratio");
  ExpectRefused<O>([](O* o) { o->keyframe_min_new_points = 0; }, "keyframe_min_new_points");
  ExpectRefused<O>([](O* o) { o->keyframe_baseline_ratio = -0.1; }, "keyframe_baseline_ratio");
  ExpectRefused<O>([](O* o) { o->keyframe_max_interval_s = kNan; }, "keyframe_max_interval_s");
  ExpectRefused<O>([](O* o) { o->min_constrained_points = -1; }, "min_constrained_points");
  TrackerOptions all_points;
  all_points.max_points = 0;  // 0: every associated point
  EXPECT_TRUE(all_points.Check());
}

TEST(Options, MapperRules) {
  using O = MapperOptions;
  ExpectRefused<O>([](O* o) { o->local_ba_window = 1; }, "local_ba_window");
  ExpectRefused<O>([](O* o) { o->local_ba_max_points = -1; }, "local_ba_max_points");
  ExpectRefused<O>([](O* o) { o->num_ba_threads = 0; }, "num_ba_threads");
  ExpectRefused<O>([](O* o) { o->keyframe_redundancy = 0.0; }, "keyframe_redundancy");
  ExpectRefused<O>([](O* o) { o->keyframe_redundancy = 1.01; }, "keyframe_redundancy");
  ExpectRefused<O>([](O* o) { o->keyframe_redundancy_observers = 0; },
                   "keyframe_redundancy_observers");
  ExpectRefused<O>([](O* o) { o->max_keyframes = 1; }, "max_keyframes");
  ExpectRefused<O>([](O* o) { o->max_point_uncertainty = 0.0; }, "max_point_uncertainty");
  ExpectRefused<O>([](O* o) { o->max_point_uncertainty = kNan; }, "max_point_uncertainty");
}

TEST(Options, DriftRules) {
  using O = DriftOptions;
  ExpectRefused<O>([](O* o) { o->min_points = 5; }, "min_points");
  ExpectRefused<O>([](O* o) { o->min_keyframe_gap = 1; }, "min_keyframe_gap");
  ExpectRefused<O>([](O* o) { o->min_error = 0.0; }, "min_error");
  DriftOptions disabled;
  disabled.enabled = false;
  EXPECT_TRUE(disabled.Check());
}

TEST(Options, SystemRules) {
  using O = Options;
  ExpectRefused<O>([](O* o) { o->pixel_sigma = 0.0; }, "pixel_sigma");
  ExpectRefused<O>([](O* o) { o->pixel_sigma = INFINITY; }, "pixel_sigma");
  ExpectRefused<O>([](O* o) { o->min_triangulation_parallax_deg = 0.0; },
                   "min_triangulation_parallax_deg");
  ExpectRefused<O>([](O* o) { o->max_features_per_frame = 0; }, "max_features_per_frame");
  ExpectRefused<O>([](O* o) { o->image_margin_px = -1.0; }, "image_margin_px");
  ExpectRefused<O>([](O* o) { o->feature_budget = -1; }, "feature_budget");
  ExpectRefused<O>([](O* o) { o->input_queue_capacity = 0; }, "input_queue_capacity");
  ExpectRefused<O>([](O* o) { o->mapping_queue_capacity = 0; }, "mapping_queue_capacity");
  ExpectRefused<O>([](O* o) { o->mapping_nice = 20; }, "mapping_nice");
  ExpectRefused<O>([](O* o) { o->refine_acceleration_sigma = -1.0; }, "refine_acceleration_sigma");
  ExpectRefused<O>([](O* o) { o->refine_acceleration_sigma = NAN; }, "refine_acceleration_sigma");
  ExpectRefused<O>([](O* o) { o->refine_acceleration_sigma = INFINITY; },
                   "refine_acceleration_sigma");
  // The camera checks itself.
  ExpectRefused<O>([](O* o) { o->camera.width = 0; }, "width");
}

TEST(Options, FeatureBudgetMustFeedTheInitialiser) {
  Options options;
  options.feature_budget = options.initializer.min_points - 1;
  Status why;
  EXPECT_FALSE((why = options.Check()));
  EXPECT_NE(why.message().find("initializer.min_points"), std::string::npos) << why.message();
  options.feature_budget = 0;  // 0: every feature
  EXPECT_TRUE((why = options.Check())) << why.message();
}

TEST(Options, ChecksEveryStage) {
  using O = Options;
  ExpectRefused<O>([](O* o) { o->initializer.min_points = 2; }, "InitializerOptions: min_points");
  ExpectRefused<O>([](O* o) { o->initializer.max_rotation_sigma_deg = 0.0; },
                   "InitializerOptions: max_rotation_sigma_deg");
  ExpectRefused<O>([](O* o) { o->initializer.max_direction_sigma_deg = kNan; },
                   "InitializerOptions: max_direction_sigma_deg");
  ExpectRefused<O>([](O* o) { o->tracker.min_inliers = 2; }, "TrackerOptions: min_inliers");
  ExpectRefused<O>([](O* o) { o->mapper.max_keyframes = 0; }, "MapperOptions: max_keyframes");
  ExpectRefused<O>([](O* o) { o->drift.min_error = kNan; }, "DriftOptions: min_error");
}

TEST(Options, MeasurementGathersTheSharedModel) {
  Options options;
  options.camera.fx = 321.0;
  options.pixel_sigma = 0.7;
  options.min_triangulation_parallax_deg = 2.5;
  const MeasurementModel model = options.measurement();
  EXPECT_EQ(model.camera.fx, 321.0);
  EXPECT_EQ(model.pixel_sigma, 0.7);
  EXPECT_EQ(model.min_triangulation_parallax_deg, 2.5);
}

}  // namespace
}  // namespace m2s::slam
