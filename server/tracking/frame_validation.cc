#include "tracking/frame_validation.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace m2s::slam {
namespace {

Status Reject(DropReason reason, const std::string& detail) {
  return Status::Error(reason, std::string(ToString(reason)) + ": " + detail);
}

}  // namespace

std::vector<std::pair<size_t, size_t>> SharedIndices(const SortedFeatures& a,
                                                     const SortedFeatures& b) {
  std::vector<std::pair<size_t, size_t>> shared;
  size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    if (a.ids[i] < b.ids[j]) {
      ++i;
    } else if (b.ids[j] < a.ids[i]) {
      ++j;
    } else {
      shared.emplace_back(i++, j++);
    }
  }
  return shared;
}

Status FrameValidator::Validate(const Frame& frame, SortedFeatures* out) {
  const size_t n = frame.features.size();
  if (n == 0) return Reject(DropReason::kEmptyFrame, "no features");
  if (n > static_cast<size_t>(max_features_))
    return Reject(DropReason::kTooManyFeatures, std::to_string(n) + " features");
  if (!std::isfinite(frame.timestamp))
    return Reject(DropReason::kNonFiniteTimestamp, "timestamp not finite");
  if (last_seq_ && frame.seq <= *last_seq_)
    return Reject(DropReason::kSeqNotIncreasing, "seq " + std::to_string(frame.seq));
  if (last_timestamp_ && frame.timestamp < *last_timestamp_)
    return Reject(DropReason::kTimestampGoingBack, "timestamp going back");
  const double margin = image_margin_px_;
  const double max_u = camera_.width + margin;
  const double max_v = camera_.height + margin;
  for (const VertexFeature& f : frame.features) {
    if (!std::isfinite(f.uv.x()) || !std::isfinite(f.uv.y()))
      return Reject(DropReason::kNonFiniteUv, "feature not finite");
    if (f.uv.x() < -margin || f.uv.y() < -margin || f.uv.x() >= max_u || f.uv.y() >= max_v) {
      return Reject(DropReason::kOutOfImage, "feature outside the image");
    }
  }
  order_.resize(n);
  for (size_t i = 0; i < n; ++i) order_[i] = {frame.features[i].id, static_cast<uint32_t>(i)};
  std::sort(order_.begin(), order_.end());
  for (size_t i = 1; i < n; ++i) {
    if (order_[i].first == order_[i - 1].first)
      return Reject(DropReason::kDuplicateId,
                    "vertex id " + std::to_string(order_[i].first) + " twice");
  }
  out->ids.resize(n);
  out->uvs.resize(n);
  for (size_t i = 0; i < n; ++i) {
    out->ids[i] = order_[i].first;
    out->uvs[i] = frame.features[order_[i].second].uv.cast<double>();
  }
  last_seq_ = frame.seq;
  last_timestamp_ = frame.timestamp;
  return Status::Ok();
}

}  // namespace m2s::slam
