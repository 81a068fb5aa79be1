// Scene events: a scripted list of run-time edits of a scene's parts (m2s_client
// --scene-events FILE), applied through SceneEditor at their times.
//
// The file is text, one event a line; '#' starts a comment, blank lines are skipped:
//   TIME move PART DX DY DZ [QW QX QY QZ]   rigid motion x' = q * x + d (world frame, metres)
//   TIME remove PART                        the part's ids are retired
//   TIME add NAME SOURCE DX DY DZ [QW QX QY QZ]
//                                           a new part NAME: a copy of live part SOURCE's
//                                           geometry moved by (q, d), with fresh ids
// TIME is in seconds from the trajectory's first pose: an event applies before the first frame
// at or after it. The quaternion (w first) is normalised and
// defaults to the identity. Events keep the file's order (times must not decrease). Part
// names are the ScenePart names (LoadScene: the node path, e.g. "RootNode/door").
//
// Thread-safety: the functions are pure (ApplySceneEvent edits the given editor).
//
//   auto events = ReadSceneEvents("events.txt");
//   SceneEditor editor(std::move(scene));
//   for (const SceneEvent& e : *events) {
//     Expected<SceneChange> change = ApplySceneEvent(e, &editor);
//     if (change) (*projector)->ApplyChange(editor.scene(), *change);
//   }
#pragma once

#include <string>
#include <vector>

#include "m2s/common/geometry.h"
#include "m2s/common/scene_editor.h"
#include "m2s/common/status.h"

namespace m2s {

struct SceneEvent {
  enum class Action { kMove, kRemove, kAdd };
  double time_s = 0.0;
  Action action = Action::kMove;
  std::string part;    // the part moved or removed; for kAdd, the new part's name
  std::string source;  // kAdd: the part whose geometry is copied
  Pose3 motion;        // kMove, kAdd
};

// Errors name the file and the line (a bad action, a missing or non-finite number, times that
// decrease, a zero quaternion).
Expected<std::vector<SceneEvent>> ParseSceneEvents(const std::string& text,
                                                   const std::string& where = "scene events");
Expected<std::vector<SceneEvent>> ReadSceneEvents(const std::string& path);

// Applies one event to the editor (errors as SceneEditor's, e.g. an unknown part).
Expected<SceneChange> ApplySceneEvent(const SceneEvent& event, SceneEditor* editor);

}  // namespace m2s
