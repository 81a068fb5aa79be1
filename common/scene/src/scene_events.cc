// Scene events: see scene_events.h.
#include "m2s/common/scene_events.h"

#include <cmath>
#include <fstream>
#include <sstream>
#include <unordered_map>

namespace m2s {
namespace {

// Reads "DX DY DZ [QW QX QY QZ]" from the rest of a line.
bool ReadMotion(std::istringstream& in, Pose3* motion) {
  double d[3];
  if (!(in >> d[0] >> d[1] >> d[2])) return false;
  double q[4] = {1, 0, 0, 0};
  if (in >> q[0]) {
    if (!(in >> q[1] >> q[2] >> q[3])) return false;
  }
  for (double v : d)
    if (!std::isfinite(v)) return false;
  const Eigen::Quaterniond rotation(q[0], q[1], q[2], q[3]);
  if (!rotation.coeffs().allFinite() || rotation.norm() < 1e-9) return false;
  *motion = Pose3(rotation, Eigen::Vector3d(d[0], d[1], d[2]));
  return true;
}

}  // namespace

Expected<std::vector<SceneEvent>> ParseSceneEvents(const std::string& text,
                                                   const std::string& where) {
  std::vector<SceneEvent> events;
  std::istringstream lines(text);
  std::string line;
  for (int number = 1; std::getline(lines, line); ++number) {
    if (const size_t hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    std::istringstream in(line);
    std::string action;
    SceneEvent event;
    if (!(in >> event.time_s)) {
      std::string word;
      if (std::istringstream(line) >> word) {
        return Status::Error(where + " line " + std::to_string(number) +
                             ": expected 'TIME ACTION PART ...'");
      }
      continue;  // blank or comment
    }
    const std::string at = where + " line " + std::to_string(number) + ": ";
    if (!std::isfinite(event.time_s)) return Status::Error(at + "time is not finite");
    if (!events.empty() && event.time_s < events.back().time_s)
      return Status::Error(at + "times must not decrease");
    if (!(in >> action >> event.part)) return Status::Error(at + "expected an action and a part");
    bool ok = true;
    if (action == "move") {
      event.action = SceneEvent::Action::kMove;
      ok = ReadMotion(in, &event.motion);
    } else if (action == "remove") {
      event.action = SceneEvent::Action::kRemove;
    } else if (action == "add") {
      event.action = SceneEvent::Action::kAdd;
      ok = static_cast<bool>(in >> event.source) && ReadMotion(in, &event.motion);
    } else {
      return Status::Error(at + "unknown action '" + action + "' (move, remove or add)");
    }
    std::string extra;
    if (!ok) return Status::Error(at + "expected DX DY DZ [QW QX QY QZ] (finite numbers)");
    if (in >> extra) return Status::Error(at + "unexpected '" + extra + "'");
    events.push_back(std::move(event));
  }
  return events;
}

Expected<std::vector<SceneEvent>> ReadSceneEvents(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Status::Error("scene events '" + path + "': cannot be opened for reading");
  std::stringstream text;
  text << in.rdbuf();
  return ParseSceneEvents(text.str(), "scene events '" + path + "'");
}

Expected<SceneChange> ApplySceneEvent(const SceneEvent& event, SceneEditor* editor) {
  switch (event.action) {
    case SceneEvent::Action::kMove:
      return editor->MovePart(event.part, event.motion);
    case SceneEvent::Action::kRemove:
      return editor->RemovePart(event.part);
    case SceneEvent::Action::kAdd:
      break;
  }
  const ScenePart* source = editor->FindPart(event.source);
  if (source == nullptr) return editor->MovePart(event.source, Pose3());  // names the parts
  const Scene& scene = editor->scene();
  const std::vector<VertexId> ids = source->Ids();
  std::unordered_map<VertexId, uint32_t> local;
  std::vector<Eigen::Vector3f> positions;
  positions.reserve(ids.size());
  for (VertexId id : ids) {
    local.emplace(id, static_cast<uint32_t>(positions.size()));
    positions.push_back(scene.positions[id]);
  }
  std::vector<uint32_t> triangles;
  const size_t end = size_t{source->first_triangle} + source->num_triangles;
  for (size_t i = 3 * size_t{source->first_triangle}; i < 3 * end; ++i)
    triangles.push_back(local.at(scene.triangles[i]));
  return editor->AddPart(event.part, positions, triangles, event.motion);
}

}  // namespace m2s
