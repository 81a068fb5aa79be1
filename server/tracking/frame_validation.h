// Validation of incoming frames, and their features sorted by vertex id.
//
// A frame is rejected (whole) when it is empty, has more features than allowed, a non-finite
// uv or timestamp, a feature farther than the margin outside the image, a duplicated id, or
// when its seq / timestamp goes back. Each rejection carries its DropReason (the code shared
// with the wire decoders), counted by name in SystemStats::rejected_by_reason.
//
//   FrameValidator validator(camera, max_features_per_frame, image_margin_px);
//   SortedFeatures features;
//   if (Status valid = validator.Validate(frame, &features); !valid) reject(*valid.reason());
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "m2s/common/status.h"
#include "m2s/slam/system.h"

namespace m2s::slam {

// Features of one frame, sorted by id (parallel arrays).
struct SortedFeatures {
  std::vector<VertexId> ids;
  std::vector<Eigen::Vector2d> uvs;
  size_t size() const { return ids.size(); }
};

// The positions (in a, in b) of the ids two frames share, ascending by id.
std::vector<std::pair<size_t, size_t>> SharedIndices(const SortedFeatures& a,
                                                     const SortedFeatures& b);

class FrameValidator {
 public:
  // Frames with more than `max_features` features, or one farther than `image_margin_px`
  // outside the camera's image, are rejected.
  FrameValidator(const Camera& camera, int max_features, double image_margin_px)
      : camera_(camera), max_features_(max_features), image_margin_px_(image_margin_px) {}

  // OK when the frame is valid (then `out` holds its sorted features and the frame becomes the
  // latest accepted one); otherwise an error with its reason code, and nothing changes.
  Status Validate(const Frame& frame, SortedFeatures* out);
  void Reset() { last_seq_.reset(), last_timestamp_.reset(); }

 private:
  Camera camera_;
  int max_features_;
  double image_margin_px_;
  std::optional<int64_t> last_seq_;
  std::optional<double> last_timestamp_;
  std::vector<std::pair<VertexId, uint32_t>> order_;  // reused scratch
};

}  // namespace m2s::slam
