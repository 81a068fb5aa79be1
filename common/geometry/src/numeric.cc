#include "m2s/common/numeric.h"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace m2s {
namespace {

template <typename T>
T PercentileOf(std::vector<T> values, double q, PercentileMethod method) {
  if (values.empty()) return T(0);
  const size_t n = values.size();
  size_t k = 0;
  switch (method) {
    case PercentileMethod::kInterpolated: {
      std::sort(values.begin(), values.end());
      const double position = q * static_cast<double>(n - 1);
      const size_t lo = static_cast<size_t>(std::floor(position));
      const size_t hi = std::min(lo + 1, n - 1);
      return values[lo] + (values[hi] - values[lo]) * (position - static_cast<double>(lo));
    }
    case PercentileMethod::kRoundedRank:
      k = std::min(n - 1, static_cast<size_t>(q * static_cast<double>(n - 1) + 0.5));
      break;
    case PercentileMethod::kFlooredRank:
      k = std::min(n - 1, static_cast<size_t>(q * static_cast<double>(n)));
      break;
  }
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(k), values.end());
  return values[k];
}

}  // namespace

std::vector<size_t> EvenlySpacedIndices(size_t n, size_t max_count, IndexRounding rounding) {
  std::vector<size_t> out;
  if (max_count == 0 || n <= max_count) {
    out.resize(n);
    std::iota(out.begin(), out.end(), size_t{0});
    return out;
  }
  out.reserve(max_count + 1);
  const double end = static_cast<double>(n);
  const double step = end / static_cast<double>(max_count);
  for (double position = 0.0; position < end; position += step) {
    const double index =
        rounding == IndexRounding::kDown ? std::floor(position) : std::ceil(position);
    if (index >= end) break;
    out.push_back(static_cast<size_t>(index));
  }
  return out;
}

double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const auto middle = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), middle, values.end());
  return *middle;
}

double MedianDepth(const Pose3& camera_from_world,
                   const std::vector<Eigen::Vector3d>& points_world) {
  std::vector<double> depths;
  depths.reserve(points_world.size());
  for (const Eigen::Vector3d& p : points_world) depths.push_back((camera_from_world * p).z());
  return Median(std::move(depths));
}

double Percentile(std::vector<double> values, double q, PercentileMethod method) {
  return PercentileOf(std::move(values), q, method);
}

float Percentile(std::vector<float> values, double q, PercentileMethod method) {
  return PercentileOf(std::move(values), q, method);
}

Pose3 LookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = (target - eye).normalized();
  Eigen::Vector3d x = z.cross(up);
  if (x.norm() < 1e-9) x = z.unitOrthogonal();
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d r;
  r.col(0) = x;
  r.col(1) = y;
  r.col(2) = z;
  return Pose3(r, eye);
}

}  // namespace m2s
