#include "m2s/common/projector.h"

#include <utility>

namespace m2s {

Status Projector::ProjectBalanced(const Pose3& world_from_camera, const Camera& camera,
                                  const FeatureGrid& grid, int budget,
                                  std::vector<ProjectedVertex>* out) {
  if (Status s = Project(world_from_camera, camera, out); !s) return s;
  std::erase_if(*out, [&camera](const ProjectedVertex& p) { return !camera.InImage(p.u, p.v); });
  const std::vector<uint32_t>& kept = selector_.Select(
      out->size(), [out](size_t i) { return (*out)[i].id; },
      [out](size_t i) { return std::pair((*out)[i].u, (*out)[i].v); }, grid, budget);
  for (size_t k = 0; k < kept.size(); ++k) (*out)[k] = (*out)[kept[k]];
  out->resize(kept.size());
  return Status::Ok();
}

}  // namespace m2s
