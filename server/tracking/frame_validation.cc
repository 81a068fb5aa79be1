#include "tracking/frame_validation.h"

#include <algorithm>
#include <cmath>

namespace m2s::slam {

std::string FrameValidator::Validate(const Frame& frame, SortedFeatures* out) {
  const size_t n = frame.features.size();
  if (n == 0) return "empty";
  if (n > static_cast<size_t>(max_features_)) return "too_many_features";
  if (!std::isfinite(frame.timestamp)) return "non_finite_timestamp";
  if (last_seq_ && frame.seq <= *last_seq_) return "seq_not_increasing";
  if (last_timestamp_ && frame.timestamp < *last_timestamp_) return "timestamp_going_back";
  const double margin = image_margin_px_;
  const double max_u = camera_.width + margin;
  const double max_v = camera_.height + margin;
  for (const VertexFeature& f : frame.features) {
    if (!std::isfinite(f.uv.x()) || !std::isfinite(f.uv.y())) return "non_finite_uv";
    if (f.uv.x() < -margin || f.uv.y() < -margin || f.uv.x() >= max_u || f.uv.y() >= max_v) {
      return "out_of_image";
    }
  }
  order_.resize(n);
  for (size_t i = 0; i < n; ++i) order_[i] = {frame.features[i].id, static_cast<uint32_t>(i)};
  std::sort(order_.begin(), order_.end());
  for (size_t i = 1; i < n; ++i) {
    if (order_[i].first == order_[i - 1].first) return "duplicate_id";
  }
  out->ids.resize(n);
  out->uvs.resize(n);
  for (size_t i = 0; i < n; ++i) {
    out->ids[i] = order_[i].first;
    out->uvs[i] = frame.features[order_[i].second].uv.cast<double>();
  }
  last_seq_ = frame.seq;
  last_timestamp_ = frame.timestamp;
  return {};
}

}  // namespace m2s::slam
