// The System tests' fixture: 12 s of head motion in the light synthetic point room (every
// vertex visible, no noise, no budget) and a System for it.
#pragma once

#include <memory>

#include <gtest/gtest.h>

#include "slam_sim.h"

namespace m2s::slam::testing {

inline const SimSequence& PointRoomSequence() {
  static const SimSequence seq = [] {
    static const Scene room = MakePointRoom();
    SimOptions sim;
    sim.duration_s = 12.0;
    sim.budget = 0;
    sim.occlusion = false;
    return MakeSequence(sim, &room);
  }();
  return seq;
}

inline std::unique_ptr<System> MakePointRoomSystem(bool deterministic = true) {
  Options options = DefaultOptions(PointRoomSequence().camera);
  options.deterministic = deterministic;
  auto system = System::Create(options);
  EXPECT_TRUE(system.ok()) << system.error();
  return std::move(*system);
}

}  // namespace m2s::slam::testing
