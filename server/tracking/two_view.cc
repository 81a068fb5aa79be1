#include "tracking/two_view.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <Eigen/Eigenvalues>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>

#include "m2s/common/logging.h"
#include "m2s/common/numeric.h"
#include "mapping/triangulation.h"

namespace m2s::slam {
namespace {

constexpr double kHomographyRatio = 0.40;      // ORB-SLAM2: RH > 0.40 selects the homography
constexpr double kAmbiguityRatio = 0.75;       // second best motion must explain fewer points
constexpr double kMinGoodFraction = 0.9;       // of the model's inliers
constexpr double kMinExplainedFraction = 0.9;  // of all shared features
constexpr int kMaxMatches = 1000;              // subsampled beyond this (RANSAC cost)
constexpr int kMotionCheckPoints = 200;        // inliers that rank the candidate motions
// Refusals of the cheap gates, before any RANSAC (Process treats them apart).
using RefusalKind = TwoViewRefusal::Kind;
// Second opinions are asked only when the motion's rotation deviation exceeds this fraction of
// InitializerOptions::max_rotation_sigma_deg.
constexpr double kSecondOpinionSigmaFraction = 0.7;
// Two candidate motions are the same solution when they differ by less than this many times the
// largest standard deviations the motion may have (InitializerOptions::max_*_sigma_deg).
constexpr double kDistinctSigmas = 2.0;

struct Matches {
  std::vector<VertexId> ids;
  std::vector<cv::Point2d> p0, p1;
};

// The features two views share, a subset of kMaxMatches of them evenly spaced by id when there
// are more.
Matches Intersect(const SortedFeatures& a, const SortedFeatures& b) {
  const std::vector<std::pair<size_t, size_t>> shared = SharedIndices(a, b);
  const bool subsample = shared.size() > static_cast<size_t>(kMaxMatches);
  const size_t count = subsample ? static_cast<size_t>(kMaxMatches) : shared.size();
  const double step = subsample ? static_cast<double>(shared.size()) / kMaxMatches : 1.0;
  Matches m;
  for (size_t k = 0; k < count; ++k) {
    const auto [i, j] = shared[static_cast<size_t>(static_cast<double>(k) * step)];
    m.ids.push_back(a.ids[i]);
    m.p0.emplace_back(a.uvs[i].x(), a.uvs[i].y());
    m.p1.emplace_back(b.uvs[j].x(), b.uvs[j].y());
  }
  return m;
}

double ScoreHomography(const Eigen::Matrix3d& h, const Matches& m, double sigma) {
  const Eigen::Matrix3d h_inv = h.inverse();
  const double inv_var = 1.0 / (sigma * sigma);
  double score = 0.0;
  auto transfer = [](const Eigen::Matrix3d& t, const cv::Point2d& p) {
    const Eigen::Vector3d q = t * Eigen::Vector3d(p.x, p.y, 1.0);
    return Eigen::Vector2d(q.x() / q.z(), q.y() / q.z());
  };
  for (size_t i = 0; i < m.ids.size(); ++i) {
    const double c1 =
        (transfer(h, m.p0[i]) - Eigen::Vector2d(m.p1[i].x, m.p1[i].y)).squaredNorm() * inv_var;
    const double c0 =
        (transfer(h_inv, m.p1[i]) - Eigen::Vector2d(m.p0[i].x, m.p0[i].y)).squaredNorm() * inv_var;
    if (!(c1 < kChi2TwoDof95) || !(c0 < kChi2TwoDof95)) continue;
    score += (kChi2TwoDof95 - c1) + (kChi2TwoDof95 - c0);
  }
  return score;
}

double ScoreFundamental(const Eigen::Matrix3d& f, const Matches& m, double sigma) {
  const double inv_var = 1.0 / (sigma * sigma);
  double score = 0.0;
  for (size_t i = 0; i < m.ids.size(); ++i) {
    const Eigen::Vector3d x0(m.p0[i].x, m.p0[i].y, 1.0), x1(m.p1[i].x, m.p1[i].y, 1.0);
    const Eigen::Vector3d l1 = f * x0, l0 = f.transpose() * x1;
    const double d1 = x1.dot(l1), d0 = x0.dot(l0);
    const double c1 = d1 * d1 / (l1.head<2>().squaredNorm()) * inv_var;
    const double c0 = d0 * d0 / (l0.head<2>().squaredNorm()) * inv_var;
    if (!(c1 < kChi2OneDof95) || !(c0 < kChi2OneDof95)) continue;
    score += (kChi2TwoDof95 - c1) + (kChi2TwoDof95 - c0);
  }
  return score;
}

bool DistinctRotations(const Pose3& a, const Pose3& b, const InitializerOptions& options) {
  return RotationAngle(a.rotation().conjugate() * b.rotation()) >
         kDistinctSigmas * DegToRad(options.max_rotation_sigma_deg);
}

bool DistinctMotions(const Pose3& a, const Pose3& b, const InitializerOptions& options) {
  const double rotation = RotationAngle(a.rotation().conjugate() * b.rotation());
  const double direction = std::acos(
      std::clamp(a.translation().normalized().dot(b.translation().normalized()), -1.0, 1.0));
  return rotation > kDistinctSigmas * DegToRad(options.max_rotation_sigma_deg) ||
         direction > kDistinctSigmas * DegToRad(options.max_direction_sigma_deg);
}

// A point is good for a motion when it triangulates in front of both cameras and reprojects
// within this many sigma^2 in each view.
constexpr double kMaxErrorSigmas2 = 4.0;

struct MotionCheck {
  Pose3 camera1_from_camera0;
  int good = 0;
  // Sum over the checked points of the squared reprojection errors in sigma^2 units, a point
  // that is not good counting as the bound (2 kMaxErrorSigmas2).
  double cost = 0.0;
  double median_parallax_deg = 0.0;
  std::vector<int> indices;  // into matches
  std::vector<Eigen::Vector3d> points;
  std::vector<double> parallax;
};

MotionCheck CheckMotion(const MeasurementModel& model, const Matches& m,
                        const std::vector<int>& inliers, const Eigen::Matrix3d& r,
                        const Eigen::Vector3d& t) {
  MotionCheck out;
  out.camera1_from_camera0 = Pose3(r, t);
  const std::vector<Pose3> poses = {Pose3::Identity(), out.camera1_from_camera0};
  const Eigen::Vector3d c0 = Eigen::Vector3d::Zero();
  const Eigen::Vector3d c1 = out.camera1_from_camera0.Inverse().translation();
  const double max_err_sq = kMaxErrorSigmas2 * model.pixel_sigma * model.pixel_sigma;
  const double inv_var = 1.0 / (model.pixel_sigma * model.pixel_sigma);
  for (const int i : inliers) {
    out.cost += 2.0 * kMaxErrorSigmas2;  // replaced below by a good point's error
    const std::vector<Eigen::Vector2d> uv = {{m.p0[i].x, m.p0[i].y}, {m.p1[i].x, m.p1[i].y}};
    const auto p = TriangulateDlt(model.camera, poses, uv);
    if (!p) continue;
    const double e0 = ReprojectionErrorSq(model.camera, poses[0], *p, uv[0]);
    const double e1 = ReprojectionErrorSq(model.camera, poses[1], *p, uv[1]);
    if (e0 > max_err_sq || e1 > max_err_sq) continue;
    out.cost += (e0 + e1) * inv_var - 2.0 * kMaxErrorSigmas2;
    ++out.good;
    out.indices.push_back(i);
    out.points.push_back(*p);
    out.parallax.push_back(ParallaxDeg(*p, c0, c1));
  }
  out.median_parallax_deg = Median(out.parallax);
  return out;
}

using Motions = std::vector<std::pair<Eigen::Matrix3d, Eigen::Vector3d>>;  // rotation, t

// `motions` with a translation, the translations made unit length, appended to `out`.
void AppendUnitMotions(const Motions& motions, std::vector<Pose3>* out) {
  for (const auto& [r, t] : motions) {
    if (t.norm() > 1e-12) out->emplace_back(r, t.normalized());
  }
}

// The four motions (two rotations, the translation's two signs) of an essential matrix.
Motions EssentialMotions(const cv::Mat& e) {
  cv::Mat r1_cv, r2_cv, t_cv;
  cv::decomposeEssentialMat(e, r1_cv, r2_cv, t_cv);
  Eigen::Matrix3d r1, r2;
  Eigen::Vector3d t;
  cv::cv2eigen(r1_cv, r1);
  cv::cv2eigen(r2_cv, r2);
  cv::cv2eigen(t_cv, t);
  return {{r1, t}, {r1, -t}, {r2, t}, {r2, -t}};
}

// Second opinions: the motions of the essential matrices of two other robust estimators (least
// median of squares; OpenCV's USAC with local optimisation). Where the views leave a valley of
// motions that fit them within the noise, each estimator settles somewhere in it, often far
// from RANSAC's pick (a hand-held camera circling a compact object: 6.2 degrees of parallax
// picked where the truth has 1.8, and a 0.9-degree motion fitting as well).
Motions SecondOpinionMotions(const Matches& m, const cv::Mat& k_cv, double sigma) {
  Motions opinions;
  for (const int method : {cv::LMEDS, cv::USAC_ACCURATE}) {
    cv::Mat mask;
    const cv::Mat es = cv::findEssentialMat(m.p0, m.p1, k_cv, method, 0.999, sigma, mask);
    // Several solutions come stacked, 3 rows each.
    for (int row = 0; row + 3 <= es.rows && es.cols == 3; row += 3) {
      const auto motions = EssentialMotions(es.rowRange(row, row + 3));
      opinions.insert(opinions.end(), motions.begin(), motions.end());
    }
  }
  return opinions;
}

// ReconstructTwoView without the boundary that turns OpenCV's exceptions into a refusal.
std::optional<TwoViewReconstruction> ReconstructTwoViewUnguarded(
    const MeasurementModel& model, const InitializerOptions& options, const SortedFeatures& view0,
    const SortedFeatures& view1, TwoViewRefusal* refusal, double* median_parallax_deg,
    bool second_opinions) {
  auto fail = [refusal](RefusalKind kind, const std::string& message,
                        bool by_second_opinion = false) -> std::optional<TwoViewReconstruction> {
    if (refusal) *refusal = {kind, message, by_second_opinion, {}};
    return std::nullopt;
  };
  if (median_parallax_deg) *median_parallax_deg = 0.0;
  const Matches m = Intersect(view0, view1);
  const int n = static_cast<int>(m.ids.size());
  if (n < options.min_points) return fail(RefusalKind::kTooFewShared, "too few shared features");
  // Cheap gate: with less image motion than a fraction of the parallax bound there is no
  // chance of enough parallax (rotation can only add image motion, not parallax).
  std::vector<double> flow(n);
  for (int i = 0; i < n; ++i) flow[i] = cv::norm(m.p1[i] - m.p0[i]);
  const double min_flow = 0.25 * model.camera.fx * DegToRad(options.min_parallax_deg);
  if (Median(std::move(flow)) < min_flow)
    return fail(RefusalKind::kTooLittleMotion, "too little image motion");

  cv::Mat k_cv;
  cv::eigen2cv(model.camera.K(), k_cv);
  const double sigma = model.pixel_sigma;
  cv::Mat e_mask, h_mask;
  const cv::Mat e_cv = cv::findEssentialMat(m.p0, m.p1, k_cv, cv::RANSAC, 0.999, sigma, e_mask);
  const cv::Mat h_cv = cv::findHomography(m.p0, m.p1, cv::RANSAC, 2.0 * sigma, h_mask, 2000, 0.999);
  if (e_cv.rows != 3 && h_cv.empty())
    return fail(RefusalKind::kNoModel, "no epipolar or homography model");

  Eigen::Matrix3d k = model.camera.K();
  double score_e = 0.0, score_h = 0.0;
  Eigen::Matrix3d e, h;
  if (e_cv.rows == 3 && e_cv.cols == 3) {
    cv::cv2eigen(e_cv, e);
    const Eigen::Matrix3d f = k.inverse().transpose() * e * k.inverse();
    score_e = ScoreFundamental(f, m, sigma);
  }
  if (!h_cv.empty()) {
    cv::cv2eigen(h_cv, h);
    score_h = ScoreHomography(h, m, sigma);
  }
  if (score_e + score_h <= 0.0) return fail(RefusalKind::kNoModel, "no model explains the matches");
  const bool prefer_h = score_h / (score_e + score_h) > kHomographyRatio;

  std::vector<int> all_subset;
  for (const size_t i : EvenlySpacedIndices(static_cast<size_t>(n), kMotionCheckPoints))
    all_subset.push_back(static_cast<int>(i));
  // The candidate motions of one model (none when it has no estimate).
  auto motions_of = [&](bool homography) {
    Motions motions;
    if (homography && !h_cv.empty()) {
      std::vector<cv::Mat> rs, ts, normals;
      cv::decomposeHomographyMat(h_cv, k_cv, rs, ts, normals);
      for (size_t i = 0; i < rs.size(); ++i) {
        Eigen::Matrix3d r;
        Eigen::Vector3d t;
        cv::cv2eigen(rs[i], r);
        cv::cv2eigen(ts[i], t);
        motions.emplace_back(r, t);
      }
    } else if (!homography && e_cv.rows == 3) {
      motions = EssentialMotions(e_cv);
    }
    return motions;
  };
  // Second opinions (SecondOpinionMotions), asked at most once.
  std::optional<Motions> opinions;
  auto other_estimates = [&]() -> const Motions& {
    if (!opinions) opinions = SecondOpinionMotions(m, k_cv, sigma);
    return *opinions;
  };
  // Motions of one model, checked by triangulation; the best must be unique, among the motions
  // of both models and the second opinions. When the preferred model is ambiguous (a homography
  // fitted to a non-planar scene at low parallax has two valid decompositions), the other model is
  // tried.
  struct Refused {
    RefusalKind kind = RefusalKind::kNoModel;
    std::string reason;
    bool by_second_opinion = false;
    std::vector<Pose3> rivals;
  };
  auto try_model = [&](bool homography, Refused* refused) -> std::optional<MotionCheck> {
    const cv::Mat& mask = homography ? h_mask : e_mask;
    const auto motions = motions_of(homography);
    if (motions.empty() || mask.empty()) {
      refused->reason = "no model";
      return std::nullopt;
    }
    std::vector<int> inliers;
    for (int i = 0; i < n; ++i) {
      if (mask.at<uchar>(i)) inliers.push_back(i);
    }
    if (static_cast<int>(inliers.size()) < options.min_points) {
      refused->reason = "too few model inliers";
      return std::nullopt;
    }
    // The candidate motions are ranked on an even subset of the inliers (the triangulations
    // are most of an attempt's cost); the best one is then checked on all of them.
    std::vector<int> subset;
    for (const size_t i : EvenlySpacedIndices(inliers.size(), kMotionCheckPoints))
      subset.push_back(inliers[i]);
    std::vector<MotionCheck> checks;
    for (const auto& [r, t] : motions) {
      if (t.norm() < 1e-12) continue;
      checks.push_back(CheckMotion(model, m, subset, r, t.normalized()));
    }
    if (checks.empty()) {
      refused->reason = "no translation between the views";
      return std::nullopt;
    }
    std::sort(checks.begin(), checks.end(),
              [](const auto& a, const auto& b) { return a.good > b.good; });
    if (median_parallax_deg)
      *median_parallax_deg = std::max(*median_parallax_deg, checks[0].median_parallax_deg);
    // A refusal for weak geometry proposes the best motion, the twins and every motion of
    // both models as starts for more views (TwoViewRefusal::rivals).
    auto propose = [&](const std::vector<Pose3>& twins) {
      refused->rivals = {checks[0].camera1_from_camera0};
      refused->rivals.insert(refused->rivals.end(), twins.begin(), twins.end());
      AppendUnitMotions(motions_of(true), &refused->rivals);
      AppendUnitMotions(motions_of(false), &refused->rivals);
    };
    if (checks.size() > 1 && checks[1].good > kAmbiguityRatio * checks[0].good) {
      refused->reason = "ambiguous motion (rotation only or too little parallax)";
      // A plane's two decompositions: starts for more views, when the parallax is there.
      if (checks[0].median_parallax_deg >= options.min_parallax_deg) {
        std::vector<Pose3> close;
        for (size_t i = 1; i < checks.size(); ++i) {
          if (checks[i].good > kAmbiguityRatio * checks[0].good)
            close.push_back(checks[i].camera1_from_camera0);
        }
        propose(close);
      }
      return std::nullopt;
    }
    // A motion of the other model that differs from the best and fits these inliers about as
    // well (a likelihood-ratio test on the truncated reprojection costs) is a second solution,
    // a plane's twin: the views do not decide between them, however exact the data. A second
    // opinion is such a solution when its rotation differs (a valley trades rotation against
    // translation; its translation direction alone may differ at low parallax).
    auto twin = [&](const Motions& others, bool rotation_only) {
      std::vector<Pose3> twins;
      for (const auto& [r, t] : others) {
        if (t.norm() < 1e-12) continue;
        const Pose3 other(r, t.normalized());
        const bool distinct =
            rotation_only ? DistinctRotations(other, checks[0].camera1_from_camera0, options)
                          : DistinctMotions(other, checks[0].camera1_from_camera0, options);
        if (distinct && CheckMotion(model, m, subset, r, t.normalized()).cost - checks[0].cost <
                            kChi2FiveDof999) {
          twins.push_back(other);
        }
      }
      if (twins.empty()) return false;
      propose(twins);
      return true;
    };
    if (twin(motions_of(!homography), false)) {
      refused->kind = RefusalKind::kWeakGeometry;
      refused->reason = "two distinct motions explain the views";
      return std::nullopt;
    }
    // Association is by id, so nearly every match is a true correspondence: a motion that
    // leaves many of them unexplained fits only part of the scene (a dense cluster that a wrong
    // motion fits within the noise, the sparse points rejected as RANSAC outliers).
    const int explained =
        CheckMotion(model, m, all_subset, checks[0].camera1_from_camera0.RotationMatrix(),
                    checks[0].camera1_from_camera0.translation())
            .good;
    if (explained < kMinExplainedFraction * static_cast<double>(all_subset.size())) {
      refused->reason = "the best motion explains too few of the shared features";
      return std::nullopt;
    }
    if (subset.size() < inliers.size()) {
      checks[0] = CheckMotion(model, m, inliers, checks[0].camera1_from_camera0.RotationMatrix(),
                              checks[0].camera1_from_camera0.translation());
    }
    const int min_good =
        std::max(options.min_points,
                 static_cast<int>(kMinGoodFraction * static_cast<double>(inliers.size())));
    if (checks[0].good < min_good) {
      refused->reason = "too few points triangulate with the best motion";
      return std::nullopt;
    }
    if (checks[0].median_parallax_deg < options.min_parallax_deg) {
      refused->reason = "too little parallax";
      return std::nullopt;
    }
    // A loosely determined rotation: ask the other estimators. checks[0] is now checked on all
    // the model's inliers while twin() checks the other motions on the subset: a second
    // opinion is a twin when its cost on the subset is below the best motion's on all the
    // inliers plus the chi-square margin, a looser test than on the same points
    // (design/two_view_initialisation.md, Limits).
    if (second_opinions) {
      const std::optional<MotionUncertainty> u = TwoViewMotionUncertainty(
          model.camera, model.pixel_sigma, checks[0].camera1_from_camera0, checks[0].points);
      if (u &&
          u->rotation_rad >
              kSecondOpinionSigmaFraction * DegToRad(options.max_rotation_sigma_deg) &&
          twin(other_estimates(), true)) {
        refused->kind = RefusalKind::kWeakGeometry;
        refused->reason = "another estimator's motion explains the views as well";
        refused->by_second_opinion = true;
        return std::nullopt;
      }
    }
    return std::move(checks[0]);
  };
  Refused refused_preferred, refused_other;
  bool use_h = prefer_h;
  auto chosen = try_model(prefer_h, &refused_preferred);
  if (!chosen) {
    chosen = try_model(!prefer_h, &refused_other);
    use_h = !prefer_h;
  }
  if (!chosen) {
    const Refused& refused =
        refused_other.kind == RefusalKind::kWeakGeometry ? refused_other : refused_preferred;
    fail(refused.kind, refused.reason, refused.by_second_opinion);
    if (refusal) refusal->rivals = refused.rivals;
    return std::nullopt;
  }
  const MotionCheck& best = *chosen;

  TwoViewReconstruction out;
  out.camera1_from_camera0 = best.camera1_from_camera0;
  out.median_parallax_deg = best.median_parallax_deg;
  out.used_homography = use_h;
  const double min_point_parallax = 0.5 * model.min_triangulation_parallax_deg;
  for (size_t i = 0; i < best.indices.size(); ++i) {
    if (best.parallax[i] < min_point_parallax) continue;
    out.ids.push_back(m.ids[best.indices[i]]);
    out.points.push_back(best.points[i]);
  }
  if (static_cast<int>(out.ids.size()) < options.min_points) {
    return fail(RefusalKind::kNoModel, "too few points with enough parallax");
  }
  // The motion must be determined by the views, not merely consistent with them: bunched or
  // distant points leave a valley of motions that fit them within the noise (exact data too),
  // and RANSAC's pick in it is arbitrary.
  const std::optional<MotionUncertainty> uncertainty = TwoViewMotionUncertainty(
      model.camera, model.pixel_sigma, out.camera1_from_camera0, best.points);
  if (!WellDetermined(uncertainty, options)) {
    std::ostringstream why;
    why << "the views leave the motion undetermined";
    if (uncertainty) {
      why << " (" << Describe(*uncertainty) << ")";
    }
    fail(RefusalKind::kWeakGeometry, why.str());
    if (refusal) {
      refusal->rivals = {out.camera1_from_camera0};
      AppendUnitMotions(motions_of(true), &refusal->rivals);
      AppendUnitMotions(motions_of(false), &refusal->rivals);
    }
    return std::nullopt;
  }
  // The candidates, the second opinions asked only when the initialiser needs them (their
  // estimators cost as much as the rest of the reconstruction).
  std::vector<Pose3> proposed;
  AppendUnitMotions(motions_of(true), &proposed);
  AppendUnitMotions(motions_of(false), &proposed);
  out.candidate_motions = [proposed = std::move(proposed), opinions = std::move(opinions), m, k_cv,
                           sigma]() {
    std::vector<Pose3> motions = proposed;
    try {
      AppendUnitMotions(opinions ? *opinions : SecondOpinionMotions(m, k_cv, sigma), &motions);
    } catch (const cv::Exception& e) {
      M2S_LOG(kWarning) << "two-view candidate motions: OpenCV error: " << e.what();
    }
    return motions;
  };
  return out;
}

}  // namespace

bool WellDetermined(const std::optional<MotionUncertainty>& u, const InitializerOptions& options) {
  return u && u->rotation_rad <= DegToRad(options.max_rotation_sigma_deg) &&
         u->direction_rad <= DegToRad(options.max_direction_sigma_deg);
}

std::optional<TwoViewReconstruction> ReconstructTwoView(
    const MeasurementModel& model, const InitializerOptions& options, const SortedFeatures& view0,
    const SortedFeatures& view1, TwoViewRefusal* refusal, double* median_parallax_deg,
    bool second_opinions) {
  try {
    return ReconstructTwoViewUnguarded(model, options, view0, view1, refusal, median_parallax_deg,
                                       second_opinions);
  } catch (const cv::Exception& e) {
    // Degenerate input (OpenCV asserts on it): a refused attempt, never a thrown frame.
    M2S_LOG(kWarning) << "two-view reconstruction: OpenCV error: " << e.what();
    if (refusal)
      *refusal = {RefusalKind::kSolverError, std::string("OpenCV error: ") + e.what(), false, {}};
    return std::nullopt;
  }
}

}  // namespace m2s::slam
