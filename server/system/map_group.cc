#include "m2s/slam/system.h"

namespace m2s::slam {

Expected<std::shared_ptr<MapGroup>> MapGroup::Create(const Options& options) {
  if (Status valid = options.Check(); !valid) return valid.Prefixed("invalid SLAM options: ");
  return Status::Error("map groups are not available in this build");
}

}  // namespace m2s::slam
