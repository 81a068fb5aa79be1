// OrbFrontEnd: grey images in, features with track ids out, so that an image front end (ORB
// keypoints and descriptors, OpenCV features2d) feeds the same id-associating SLAM back end as
// vertex features do.
//
// Each frame's ORB keypoints get ids in three steps:
//  1. Frame to frame: a keypoint takes the id of a feature of the previous frame when that
//     feature's predicted position (its last position plus its last image motion, or the
//     median image motion of its frame for a feature not matched frame to frame) lies within
//     `search_radius_px`, the Hamming distance of their descriptors is at most `max_hamming`,
//     and the best distance is below `ratio` times the second best among the candidates. A
//     previous feature claimed by several keypoints goes to the closest descriptor.
//  2. Re-identification: a keypoint left over is matched by descriptor alone (no position
//     gate; `reid_max_hamming`, `reid_ratio`) against the map: the ids seen in the last
//     `map_frames` frames (at most `map_max_ids`, the most recently seen), each with the
//     descriptor it was last seen with, and not used yet in this frame.
//  3. Any keypoint still without an id gets a new one from a counter (0, 1, 2...).
// A frame never holds the same id twice (the back end refuses such frames). A wrong match
// is a wrong id: the back end's robust tracking has to reject it as an outlier.
// Positions follow the project's pixel convention (pixel (0,0) spans [0,1) x [0,1), so a
// keypoint at OpenCV's integer pixel centre x is at u = x + 0.5).
//
// Deterministic: the same images in the same order give the same features and ids.
// Thread-safety: not thread-safe (one per image stream).
//
//   OrbFrontEnd front_end(OrbFrontEnd::Options{});   // options.Check() first
//   std::vector<VertexFeature> features;
//   OrbTimings timings;
//   Status s = front_end.Process(gray, &features, &timings);
#pragma once

#include <array>
#include <cstdint>
#include <map>
#include <vector>

#include <opencv2/core.hpp>

#include "m2s/common/status.h"
#include "m2s/common/types.h"

namespace cv {
class Feature2D;
}

namespace m2s::image_features {

// What one Process() call did, and how long it took (wall clock).
struct OrbTimings {
  double extract_ms = 0.0;  // ORB keypoints and descriptors
  double match_ms = 0.0;    // frame-to-frame matching, re-identification, id assignment
  int keypoints = 0;
  int tracked = 0;       // ids from the previous frame
  int reidentified = 0;  // ids from the map
  int new_ids = 0;
};

// A 256-bit ORB descriptor.
using OrbDescriptor = std::array<uint64_t, 4>;
int HammingDistance(const OrbDescriptor& a, const OrbDescriptor& b);

class OrbFrontEnd {
 public:
  struct Options {
    // cv::ORB: the most keypoints a frame, the pyramid, the FAST threshold and the border
    // (pixels) where no keypoint is detected (at least the 31 px descriptor patch / 2).
    // Four levels, not ORB-SLAM's eight: a keypoint of level L is located to about 1.2^L px,
    // and the back end weighs every feature with one pixel sigma; on the test's warped
    // texture, 96 % of kept ids stay within 2 px with four levels, 88 % with eight.
    int num_features = 1000;
    double scale_factor = 1.2;
    int num_levels = 4;
    int fast_threshold = 20;
    int edge_threshold = 19;
    // Frame to frame: pixels around the predicted position, the largest Hamming distance of
    // a match (of 256 bits) and the ratio test of best to second best.
    double search_radius_px = 40.0;
    int max_hamming = 50;
    double ratio = 0.8;
    // Re-identification against the map (stricter: no position gate).
    int reid_max_hamming = 40;
    double reid_ratio = 0.7;
    // The map: ids seen in the last map_frames frames, at most map_max_ids of them.
    int map_frames = 30;
    int map_max_ids = 2000;

    Status Check() const;
  };

  explicit OrbFrontEnd(const Options& options);
  ~OrbFrontEnd();
  OrbFrontEnd(const OrbFrontEnd&) = delete;
  OrbFrontEnd& operator=(const OrbFrontEnd&) = delete;

  // The features of `gray8` (CV_8UC1, non-empty), at most one per id; `timings` may be null.
  // Error (and no change of state) on a wrong image type, or when the ids are used up (2^31:
  // the wire carries ids as int32).
  Status Process(const cv::Mat& gray8, std::vector<VertexFeature>* features,
                 OrbTimings* timings = nullptr);

  // Forgets the previous frame and the map; ids keep counting (never reused).
  void Reset();
  const Options& options() const { return options_; }
  // The id the next new feature gets (= the number of ids given so far).
  VertexId next_id() const { return next_id_; }

 private:
  // A feature of the previous frame.
  struct Track {
    VertexId id = 0;
    Eigen::Vector2f uv = Eigen::Vector2f::Zero();
    Eigen::Vector2f predicted = Eigen::Vector2f::Zero();  // uv + its last image motion
    OrbDescriptor descriptor{};
  };
  struct MapEntry {
    OrbDescriptor descriptor{};
    int64_t last_frame = 0;
  };
  // Detects keypoints; fills uvs_ and descriptors_.
  void Extract(const cv::Mat& gray8);
  // (*track_of_keypoint)[i]: the index in previous_ of keypoint i's match, or -1.
  void MatchPrevious(int width, int height, std::vector<int>* track_of_keypoint) const;
  // Fills the ids of the keypoints without one (kNoId) from the map, ids not used yet.
  void MatchMap(std::vector<int64_t>* id_of_keypoint) const;
  // Makes the current frame the previous one and refreshes the map.
  void Advance(const std::vector<int64_t>& id_of_keypoint,
               const std::vector<int>& track_of_keypoint);

  const Options options_;
  cv::Ptr<cv::Feature2D> orb_;
  VertexId next_id_ = 0;
  int64_t frame_index_ = 0;
  std::vector<Track> previous_;
  std::map<VertexId, MapEntry> map_;  // ordered: deterministic iteration
  // Scratch of the current frame.
  std::vector<Eigen::Vector2f> uvs_;
  std::vector<OrbDescriptor> descriptors_;
};

}  // namespace m2s::image_features
