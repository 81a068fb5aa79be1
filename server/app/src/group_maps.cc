// SessionManager's map groups on disk: saved maps loaded (localisation-only) or resumed at
// start, group maps saved periodically and at shutdown, and the groups' reports.
#include <algorithm>
#include <filesystem>

#include "m2s/common/logging.h"
#include "m2s/server_app/session_manager.h"

namespace m2s::server_app {

Status SessionManager::LoadGroupMap(const std::string& name, const std::string& path) {
  return AddGroupFromFile(name, path, /*resume=*/false);
}

Expected<int> SessionManager::ResumeGroupMaps() {
  if (options_.save_maps_dir.empty()) return Status::Error("no save_maps_dir to resume from");
  const std::string prefix = "group-";
  std::vector<std::pair<std::string, std::string>> found;  // name, path
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(options_.save_maps_dir, ec)) {
    const std::string file = entry.path().filename().string();
    if (!entry.is_regular_file() || file.rfind(prefix, 0) != 0 ||
        entry.path().extension() != kMapFileExtension) {
      continue;
    }
    const std::string name = file.substr(
        prefix.size(), file.size() - prefix.size() - std::string(kMapFileExtension).size());
    // Another shard's group: its own server resumes it.
    if (!wire::CheckMapGroupName(name).ok() || !options_.shard.Owns(ShardKeyOfGroup(name))) {
      continue;
    }
    found.emplace_back(name, entry.path().string());
  }
  if (ec) return Status::Error("cannot read " + options_.save_maps_dir + ": " + ec.message());
  std::sort(found.begin(), found.end());
  for (const auto& [name, path] : found) {
    if (Status resumed = AddGroupFromFile(name, path, /*resume=*/true); !resumed) return resumed;
  }
  return static_cast<int>(found.size());
}

Status SessionManager::AddGroupFromFile(const std::string& name, const std::string& path,
                                        bool resume) {
  if (name.empty()) return Status::Error("map group name is empty");
  if (Status valid = wire::CheckMapGroupName(name); !valid) return valid;
  // The group's camera is the one the map was made with.
  auto camera = slam::ReadMapFileCamera(path);
  if (!camera) return Status::Error("map group " + name + ": " + camera.error());
  std::lock_guard<std::mutex> lock(mutex_);
  if (groups_.count(name)) return Status::Error("map group " + name + " exists already");
  if (static_cast<int>(groups_.size()) >= options_.max_groups) {
    return Status::Error("more than max_groups (" + std::to_string(options_.max_groups) +
                         ") map groups");
  }
  slam::Options slam_options = options_.slam;
  slam_options.camera = *camera;
  slam_options.max_features_per_frame = options_.max_features;
  auto group = group_factory_(slam_options);
  if (!group) return Status::Error("map group " + name + " not created: " + group.error());
  const Status loaded = resume ? (*group)->ResumeMap(path) : (*group)->LoadMap(path);
  if (!loaded) return loaded.Prefixed("map group " + name + ": " + path + ": ");
  groups_.emplace(name, std::move(*group));
  ++counters_.groups_created;
  M2S_LOG(kInfo) << "map group " << name << (resume ? " resumed from " : " loaded from ") << path;
  return Status::Ok();
}

std::vector<GroupReport> SessionManager::Groups() const {
  std::vector<std::pair<std::string, std::shared_ptr<slam::MapGroup>>> groups;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    groups.assign(groups_.begin(), groups_.end());
  }
  std::vector<GroupReport> reports;
  for (const auto& [name, group] : groups) reports.push_back({name, group->Stats()});
  return reports;
}

void SessionManager::SaveGroupMaps(bool final) {
  std::vector<std::pair<std::string, std::shared_ptr<slam::MapGroup>>> groups;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (groups_saved_ || options_.save_maps_dir.empty()) return;
    if (final) groups_saved_ = true;
    groups.assign(groups_.begin(), groups_.end());
  }
  for (const auto& [name, group] : groups) {
    if (group->Stats().localization_only) continue;  // a loaded anchor never changes
    const std::filesystem::path path =
        std::filesystem::path(options_.save_maps_dir) / ("group-" + name + kMapFileExtension);
    // Written next to the file and renamed over it: a server killed while saving leaves the
    // previous map whole.
    std::filesystem::path partial = path;
    partial += ".partial";
    Status saved = group->SaveMap(partial.string());
    if (saved) {
      std::error_code ec;
      std::filesystem::rename(partial, path, ec);
      if (ec) saved = Status::Error("cannot rename " + partial.string() + ": " + ec.message());
    }
    if (saved) {
      if (final) M2S_LOG(kInfo) << "map group " << name << ": map saved to " << path.string();
    } else {
      M2S_LOG(kWarning) << "map group " << name << ": saving the map failed: " << saved.message();
    }
  }
}

}  // namespace m2s::server_app
