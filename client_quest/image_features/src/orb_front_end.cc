#include "m2s/image_features/orb_front_end.h"

#include <algorithm>
#include <chrono>
#include <climits>
#include <cmath>
#include <cstring>
#include <string>
#include <utility>

#include <opencv2/core/hal/hal.hpp>
#include <opencv2/features2d.hpp>

#include "m2s/common/check.h"

namespace m2s::image_features {
namespace {

using Clock = std::chrono::steady_clock;

constexpr int64_t kNoId = -1;
// Ids travel as int32 on the wire.
constexpr int64_t kIdLimit = int64_t{1} << 31;
constexpr int kDescriptorBytes = 32;

double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// The best and second-best distances offered.
struct BestMatch {
  int index = -1;
  int distance = INT_MAX;
  int second = INT_MAX;

  void Offer(int candidate, int d) {
    if (d < distance) {
      second = distance;
      distance = d;
      index = candidate;
    } else if (d < second) {
      second = d;
    }
  }
  bool Accepted(int max_distance, double ratio) const {
    if (index < 0 || distance > max_distance) return false;
    return second == INT_MAX || distance < ratio * second;
  }
};

// Of the keypoints that chose the same candidate, the one with the smallest distance keeps it
// (then the lowest index); returns, per keypoint, its candidate or -1.
std::vector<int> OneKeypointPerCandidate(const std::vector<int>& choice,
                                         const std::vector<int>& distance, size_t num_candidates) {
  std::vector<int> owner(num_candidates, -1);
  for (size_t i = 0; i < choice.size(); ++i) {
    const int c = choice[i];
    if (c < 0) continue;
    if (owner[c] < 0 || distance[i] < distance[owner[c]]) owner[c] = static_cast<int>(i);
  }
  std::vector<int> kept(choice.size(), -1);
  for (size_t c = 0; c < num_candidates; ++c) {
    if (owner[c] >= 0) kept[owner[c]] = static_cast<int>(c);
  }
  return kept;
}

Eigen::Vector2f Median(std::vector<float> xs, std::vector<float> ys) {
  if (xs.empty()) return Eigen::Vector2f::Zero();
  const size_t mid = xs.size() / 2;
  std::nth_element(xs.begin(), xs.begin() + mid, xs.end());
  std::nth_element(ys.begin(), ys.begin() + mid, ys.end());
  return {xs[mid], ys[mid]};
}

}  // namespace

int HammingDistance(const OrbDescriptor& a, const OrbDescriptor& b) {
  // OpenCV's kernel: SIMD population counts where the CPU has them.
  return cv::hal::normHamming(reinterpret_cast<const uchar*>(a.data()),
                              reinterpret_cast<const uchar*>(b.data()), kDescriptorBytes);
}

Status OrbFrontEnd::Options::Check() const {
  if (num_features < 1) return Status::Error("num_features must be >= 1");
  if (!(scale_factor > 1.0 && scale_factor <= 2.0))
    return Status::Error("scale_factor must be in (1, 2]");
  if (num_levels < 1 || num_levels > 16) return Status::Error("num_levels must be in [1, 16]");
  if (fast_threshold < 1 || fast_threshold > 255)
    return Status::Error("fast_threshold must be in [1, 255]");
  if (edge_threshold < 16)
    return Status::Error("edge_threshold must be >= 16 (half the descriptor patch)");
  if (!(search_radius_px > 0.0)) return Status::Error("search_radius_px must be > 0");
  if (max_hamming < 0 || max_hamming > 256 || reid_max_hamming < 0 || reid_max_hamming > 256)
    return Status::Error("max_hamming and reid_max_hamming must be in [0, 256]");
  if (!(ratio > 0.0 && ratio <= 1.0) || !(reid_ratio > 0.0 && reid_ratio <= 1.0))
    return Status::Error("ratio and reid_ratio must be in (0, 1]");
  if (map_frames < 0 || map_max_ids < 0)
    return Status::Error("map_frames and map_max_ids must be >= 0 (0: no re-identification)");
  return Status::Ok();
}

OrbFrontEnd::OrbFrontEnd(const Options& options) : options_(options) {
  const Status valid = options_.Check();
  M2S_CHECK(valid.ok()) << "OrbFrontEnd options: " << valid.message();
  orb_ = cv::ORB::create(options_.num_features, static_cast<float>(options_.scale_factor),
                         options_.num_levels, options_.edge_threshold, /*firstLevel=*/0,
                         /*WTA_K=*/2, cv::ORB::HARRIS_SCORE, /*patchSize=*/31,
                         options_.fast_threshold);
}

OrbFrontEnd::~OrbFrontEnd() = default;

void OrbFrontEnd::Reset() {
  previous_.clear();
  map_.clear();
}

void OrbFrontEnd::Extract(const cv::Mat& gray8) {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
  orb_->detectAndCompute(gray8, cv::noArray(), keypoints, descriptors);
  uvs_.resize(keypoints.size());
  descriptors_.resize(keypoints.size());
  for (size_t i = 0; i < keypoints.size(); ++i) {
    // OpenCV puts pixel centres at integers; ours are at +0.5.
    uvs_[i] = {keypoints[i].pt.x + 0.5f, keypoints[i].pt.y + 0.5f};
    std::memcpy(descriptors_[i].data(), descriptors.ptr<uint8_t>(static_cast<int>(i)),
                kDescriptorBytes);
  }
}

void OrbFrontEnd::MatchPrevious(int width, int height, std::vector<int>* track_of_keypoint) const {
  const size_t n = uvs_.size();
  track_of_keypoint->assign(n, -1);
  if (previous_.empty() || n == 0) return;
  // The previous features in a grid of search_radius cells, by predicted position.
  const float radius = static_cast<float>(options_.search_radius_px);
  const int cols = std::max(1, static_cast<int>(std::ceil(width / radius)));
  const int rows = std::max(1, static_cast<int>(std::ceil(height / radius)));
  const auto cell_x = [&](float u) {
    return std::clamp(static_cast<int>(std::floor(u / radius)), 0, cols - 1);
  };
  const auto cell_y = [&](float v) {
    return std::clamp(static_cast<int>(std::floor(v / radius)), 0, rows - 1);
  };
  std::vector<std::vector<int>> grid(static_cast<size_t>(cols) * rows);
  for (size_t t = 0; t < previous_.size(); ++t) {
    const Eigen::Vector2f& p = previous_[t].predicted;
    grid[cell_y(p.y()) * cols + cell_x(p.x())].push_back(static_cast<int>(t));
  }
  std::vector<int> choice(n, -1), distance(n, INT_MAX);
  for (size_t i = 0; i < n; ++i) {
    const int cx = cell_x(uvs_[i].x()), cy = cell_y(uvs_[i].y());
    BestMatch best;
    for (int y = std::max(0, cy - 1); y <= std::min(rows - 1, cy + 1); ++y) {
      for (int x = std::max(0, cx - 1); x <= std::min(cols - 1, cx + 1); ++x) {
        for (const int t : grid[y * cols + x]) {
          if ((previous_[t].predicted - uvs_[i]).squaredNorm() > radius * radius) continue;
          best.Offer(t, HammingDistance(previous_[t].descriptor, descriptors_[i]));
        }
      }
    }
    if (best.Accepted(options_.max_hamming, options_.ratio)) {
      choice[i] = best.index;
      distance[i] = best.distance;
    }
  }
  *track_of_keypoint = OneKeypointPerCandidate(choice, distance, previous_.size());
}

void OrbFrontEnd::MatchMap(std::vector<int64_t>* id_of_keypoint) const {
  std::vector<VertexId> used;
  for (const int64_t id : *id_of_keypoint) {
    if (id != kNoId) used.push_back(static_cast<VertexId>(id));
  }
  std::sort(used.begin(), used.end());
  std::vector<const std::pair<const VertexId, MapEntry>*> candidates;
  for (const auto& entry : map_) {
    if (!std::binary_search(used.begin(), used.end(), entry.first)) candidates.push_back(&entry);
  }
  if (candidates.empty()) return;
  const size_t n = id_of_keypoint->size();
  std::vector<int> choice(n, -1), distance(n, INT_MAX);
  for (size_t i = 0; i < n; ++i) {
    if ((*id_of_keypoint)[i] != kNoId) continue;
    BestMatch best;
    for (size_t c = 0; c < candidates.size(); ++c) {
      best.Offer(static_cast<int>(c),
                 HammingDistance(candidates[c]->second.descriptor, descriptors_[i]));
    }
    if (best.Accepted(options_.reid_max_hamming, options_.reid_ratio)) {
      choice[i] = best.index;
      distance[i] = best.distance;
    }
  }
  const std::vector<int> kept = OneKeypointPerCandidate(choice, distance, candidates.size());
  for (size_t i = 0; i < n; ++i) {
    if (kept[i] >= 0) (*id_of_keypoint)[i] = candidates[kept[i]]->first;
  }
}

void OrbFrontEnd::Advance(const std::vector<int64_t>& id_of_keypoint,
                          const std::vector<int>& track_of_keypoint) {
  // Image motion of the features matched frame to frame; the others are predicted to move
  // with the median of it.
  std::vector<float> dx, dy;
  for (size_t i = 0; i < uvs_.size(); ++i) {
    if (track_of_keypoint[i] < 0) continue;
    const Eigen::Vector2f motion = uvs_[i] - previous_[track_of_keypoint[i]].uv;
    dx.push_back(motion.x());
    dy.push_back(motion.y());
  }
  const Eigen::Vector2f median_motion = Median(std::move(dx), std::move(dy));
  std::vector<Track> current(uvs_.size());
  for (size_t i = 0; i < uvs_.size(); ++i) {
    const int t = track_of_keypoint[i];
    const Eigen::Vector2f motion =
        t >= 0 ? Eigen::Vector2f(uvs_[i] - previous_[t].uv) : median_motion;
    current[i] = {static_cast<VertexId>(id_of_keypoint[i]), uvs_[i], uvs_[i] + motion,
                  descriptors_[i]};
    map_[current[i].id] = {descriptors_[i], frame_index_};
  }
  previous_ = std::move(current);

  // The map keeps the ids seen in the last map_frames frames, at most map_max_ids of them.
  std::vector<std::pair<int64_t, VertexId>> by_age;
  for (auto it = map_.begin(); it != map_.end();) {
    if (it->second.last_frame <= frame_index_ - options_.map_frames) {
      it = map_.erase(it);
    } else {
      by_age.push_back({it->second.last_frame, it->first});
      ++it;
    }
  }
  const size_t limit = static_cast<size_t>(options_.map_max_ids);
  if (by_age.size() > limit) {
    const auto cut = by_age.end() - static_cast<std::ptrdiff_t>(limit);
    std::nth_element(by_age.begin(), cut, by_age.end());
    for (auto it = by_age.begin(); it != cut; ++it) map_.erase(it->second);
  }
  ++frame_index_;
}

Status OrbFrontEnd::Process(const cv::Mat& gray8, std::vector<VertexFeature>* features,
                            OrbTimings* timings) {
  if (gray8.empty() || gray8.type() != CV_8UC1) {
    return Status::Error("the ORB front end needs a non-empty 8-bit grey image");
  }
  if (static_cast<int64_t>(next_id_) + options_.num_features > kIdLimit) {
    return Status::Error("the ORB front end used up its 2^31 track ids; start a new run");
  }
  OrbTimings local;
  OrbTimings& t = timings ? *timings : local;
  t = OrbTimings{};
  const auto start = Clock::now();
  Extract(gray8);
  t.extract_ms = MsSince(start);
  t.keypoints = static_cast<int>(uvs_.size());

  const auto match_start = Clock::now();
  std::vector<int> track_of_keypoint;
  MatchPrevious(gray8.cols, gray8.rows, &track_of_keypoint);
  std::vector<int64_t> id_of_keypoint(uvs_.size(), kNoId);
  for (size_t i = 0; i < uvs_.size(); ++i) {
    if (track_of_keypoint[i] >= 0) {
      id_of_keypoint[i] = previous_[track_of_keypoint[i]].id;
      ++t.tracked;
    }
  }
  MatchMap(&id_of_keypoint);
  features->clear();
  features->reserve(uvs_.size());
  for (size_t i = 0; i < uvs_.size(); ++i) {
    if (id_of_keypoint[i] == kNoId) {
      id_of_keypoint[i] = next_id_++;
      ++t.new_ids;
    } else if (track_of_keypoint[i] < 0) {
      ++t.reidentified;
    }
    features->push_back({static_cast<VertexId>(id_of_keypoint[i]), uvs_[i]});
  }
  Advance(id_of_keypoint, track_of_keypoint);
  t.match_ms = MsSince(match_start);
  return Status::Ok();
}

}  // namespace m2s::image_features
