// Map groups on one server: how many agents one group serves in real time, how fast an agent's
// own map merges, the joint ATE of the group, and the bytes each agent sends and receives.
//
// Each agent walks the same generated head motion through the default scene, starting one
// second further along it than the previous agent (so each starts where no one has mapped yet
// and the agents behind it arrive there later). Frames are projected beforehand (the headset's
// work), then every agent submits its frames in real time from its own thread to its
// slam::System of one slam::MapGroup (mapping in the group's thread), as the server's session
// workers do, and takes map deltas at the server's 15 Hz. A frame the agent's latest-wins queue
// drops is skipped. For each frame rate the agent count grows until frames are skipped.
//
//   bench_map_groups --rates 30,60,120 --max-agents 12 --duration 10 --out groups.json
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "m2s/common/alignment.h"
#include "m2s/common/feature_rank.h"
#include "m2s/common/scene.h"
#include "m2s/common/trajectory.h"
#include "m2s/common/wire_format.h"
#include "m2s/server_app/messages.h"
#include "m2s/slam/system.h"
#include "sequence.h"

namespace m2s::bench {
namespace {

constexpr double kMapRateHz = 15.0;    // map deltas per agent per second (ServerOptions)
constexpr double kAgentOffsetS = 1.0;  // each agent starts this much further along the walk
constexpr int kFeatureBudget = 1000;   // features per frame (the client's balanced selection)

struct GroupRun {
  int agents = 0;
  double rate_hz = 0.0;
  int64_t frames = 0;
  int64_t skipped = 0;
  int64_t lost = 0;
  int64_t unmerged = 0;
  double joint_ate_m = NAN;
  int64_t merges = 0;
  double max_merge_ms = 0.0;
  double up_bytes_per_s = 0.0;    // per agent
  double down_bytes_per_s = 0.0;  // per agent: pose estimates and map deltas
};

// Frames [first, first + count) of the source, numbered from 0; `reverse`: the same places
// walked backwards (at the same times).
std::vector<slam::Frame> AgentFrames(FrameSource* source, size_t first, size_t count,
                                     bool reverse) {
  std::vector<slam::Frame> frames(count);
  for (size_t i = 0; i < count; ++i) {
    slam::Frame& f = frames[i];
    const size_t index = first + (reverse ? count - 1 - i : i);
    const Status made = source->MakeFrame(index, &f);
    if (!made.ok()) std::fprintf(stderr, "frame %zu: %s\n", index, made.message().c_str());
    f.seq = static_cast<int64_t>(i);
    f.timestamp = source->ground_truth()[first + i].timestamp;
    if (f.features.size() > static_cast<size_t>(kFeatureBudget)) {
      const Camera camera = BenchCamera();
      KeepBalanced(kFeatureBudget, FeatureGrid::ForImage(camera.width, camera.height), &f.features);
    }
  }
  return frames;
}

double JointAte(const std::vector<std::vector<slam::TrajectoryEntry>>& trajectories) {
  std::vector<Eigen::Vector3d> est, truth;
  for (const auto& trajectory : trajectories) {
    for (const slam::TrajectoryEntry& e : trajectory) {
      const bool posed =
          e.state == slam::TrackingState::kOk || e.state == slam::TrackingState::kRelocalized;
      if (!posed || e.map_id != 0 || !e.ground_truth_world_from_camera) continue;
      est.push_back(e.world_from_camera.translation());
      truth.push_back(e.ground_truth_world_from_camera->translation());
    }
  }
  const auto s = AlignPoints(est, truth, /*with_scale=*/true);
  if (!s) return NAN;
  double sse = 0.0;
  for (size_t i = 0; i < est.size(); ++i) sse += ((*s) * est[i] - truth[i]).squaredNorm();
  return std::sqrt(sse / static_cast<double>(est.size()));
}

// `opposite`: two agents, the second walking the first one's path backwards (it starts where
// the first ends: the two build their own maps, which merge where the walks meet).
Expected<GroupRun> RunGroup(const Scene& scene, const Trajectory& walk_at_rate, double rate_hz,
                            int num_agents, double duration_s, bool opposite) {
  FrameSourceOptions source_options;
  auto source = FrameSource::Create(scene, BenchCamera(), walk_at_rate, source_options);
  if (!source.ok()) return source.status();
  const size_t count = static_cast<size_t>(duration_s * rate_hz);
  const size_t offset = static_cast<size_t>(kAgentOffsetS * rate_hz);
  if ((*source)->size() < offset * (num_agents - 1) + count)
    return Status::Error("walk too short for " + std::to_string(num_agents) + " agents");
  std::vector<std::vector<slam::Frame>> frames;
  for (int k = 0; k < num_agents; ++k) {
    if (opposite) {
      frames.push_back(AgentFrames(source->get(), 0, count, /*reverse=*/k % 2 == 1));
    } else {
      frames.push_back(AgentFrames(source->get(), offset * static_cast<size_t>(k), count, false));
    }
  }

  slam::Options options;
  options.camera = BenchCamera();
  options.pixel_sigma = 0.5;
  auto group = slam::MapGroup::Create(options);
  if (!group.ok()) return group.status();
  std::vector<std::unique_ptr<slam::System>> agents;
  for (int k = 0; k < num_agents; ++k) {
    auto agent = (*group)->Join();
    if (!agent.ok()) return agent.status();
    agents.push_back(std::move(*agent));
  }

  std::vector<double> down_bytes(num_agents, 0.0), up_bytes(num_agents, 0.0);
  const pose_estimate_t pose_message = server_app::ToPoseMessage(slam::TrackResult(), {}, 0, 0);
  const double pose_bytes = pose_message.getEncodedSize();
  const auto start = std::chrono::steady_clock::now() + std::chrono::milliseconds(100);
  auto feed = [&](int k) {
    slam::System& agent = *agents[k];
    const int map_every = std::max(1, static_cast<int>(std::lround(rate_hz / kMapRateHz)));
    for (size_t i = 0; i < count; ++i) {
      std::this_thread::sleep_until(start + std::chrono::duration_cast<std::chrono::nanoseconds>(
                                                std::chrono::duration<double>(i / rate_hz)));
      up_bytes[k] +=
          static_cast<double>(wire::FeatureFrameEncodedSize(frames[k][i].features.size()));
      agent.Submit(frames[k][i]);
      if (static_cast<int>(i) % map_every == 0) {
        const slam::MapDelta delta = agent.TakeMapDelta();
        if (!delta.empty() || delta.full) {
          down_bytes[k] +=
              server_app::ToMapMessage(delta, 1, 1, static_cast<int64_t>(delta.base_revision),
                                       static_cast<int64_t>(delta.revision))
                  .getEncodedSize();
        }
      }
    }
  };
  auto drain = [&](int k) {
    slam::TrackResult r;
    // Results of frames that were not skipped; the queue stops when the agent shuts down.
    while (agents[k]->WaitForResult(&r, 5.0)) {
      down_bytes[k] += pose_bytes;
      if (r.seq + 1 == static_cast<int64_t>(count)) break;
    }
  };
  std::vector<std::thread> threads;
  for (int k = 0; k < num_agents; ++k) {
    threads.emplace_back(feed, k);
    threads.emplace_back(drain, k);
  }
  for (std::thread& t : threads) t.join();

  GroupRun run;
  run.agents = num_agents;
  run.rate_hz = rate_hz;
  std::vector<std::vector<slam::TrajectoryEntry>> trajectories;
  for (int k = 0; k < num_agents; ++k) {
    const slam::SystemStats s = agents[k]->Stats();
    run.frames += static_cast<int64_t>(count);
    run.skipped += s.frames_dropped_queue;
    run.lost += s.frames_lost;
    run.unmerged += s.frames_in_unmerged_maps;
    trajectories.push_back(agents[k]->Trajectory());
    run.up_bytes_per_s += up_bytes[k] / duration_s / num_agents;
    run.down_bytes_per_s += down_bytes[k] / duration_s / num_agents;
  }
  for (auto& agent : agents) agent->Shutdown();
  const slam::GroupStats stats = (*group)->Stats();
  run.merges = stats.merges;
  for (double ms : stats.merge_ms) run.max_merge_ms = std::max(run.max_merge_ms, ms);
  run.joint_ate_m = JointAte(trajectories);
  return run;
}

}  // namespace
}  // namespace m2s::bench

int main(int argc, char** argv) {
  using namespace m2s;
  CLI::App app{"Map groups on one server: agents served in real time, merges, joint ATE, bytes"};
  std::vector<double> rates = {30.0, 60.0, 120.0};
  int max_agents = 12;
  double duration_s = 10.0;
  uint64_t seed = 1;
  std::string out;
  app.add_option("--rates", rates, "frame rates (Hz)")->delimiter(',');
  app.add_option("--max-agents", max_agents, "largest group tried")->check(CLI::Range(1, 64));
  app.add_option("--duration", duration_s, "seconds each agent walks")
      ->check(CLI::Range(2.0, 600.0));
  app.add_option("--seed", seed, "head-motion seed");
  app.add_option("--out", out, "JSON file of every run");
  CLI11_PARSE(app, argc, argv);

  const Scene scene = MakeDefaultScene();
  HeadMotionOptions motion = DefaultHeadMotionOptions();
  motion.seed = seed;
  motion.duration_s = duration_s + bench::kAgentOffsetS * max_agents + 1.0;
  auto walk = GenerateHeadMotion(motion);
  if (!walk.ok()) {
    std::fprintf(stderr, "bench_map_groups: %s\n", walk.error().c_str());
    return 1;
  }
  nlohmann::json runs = nlohmann::json::array();
  std::printf(
      "| rate | layout | agents | frames | skipped | lost | unmerged | joint ATE (mm) | merges | "
      "max merge (ms) | up (kB/s per agent) | down (kB/s per agent) |\n"
      "|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const double rate : rates) {
    auto at_rate = walk->Resample(rate);
    if (!at_rate.ok()) {
      std::fprintf(stderr, "bench_map_groups: %s\n", at_rate.error().c_str());
      return 1;
    }
    // Capacity: agents one second apart along the path, more until frames are skipped; then
    // two agents in opposite directions (their maps merge).
    for (int n = 1; n <= max_agents + 1; ++n) {
      const bool opposite = n == max_agents + 1;
      const int agents = opposite ? 2 : n;
      auto run = bench::RunGroup(scene, *at_rate, rate, agents, duration_s, opposite);
      if (!run.ok()) {
        std::fprintf(stderr, "bench_map_groups: %s\n", run.error().c_str());
        return 1;
      }
      const char* layout = opposite ? "opposite" : "along";
      std::printf(
          "| %.0f | %s | %d | %lld | %lld | %lld | %lld | %.4f | %lld | %.1f | %.1f | %.1f |\n",
          rate, layout, agents, static_cast<long long>(run->frames),
          static_cast<long long>(run->skipped), static_cast<long long>(run->lost),
          static_cast<long long>(run->unmerged), run->joint_ate_m * 1e3,
          static_cast<long long>(run->merges), run->max_merge_ms, run->up_bytes_per_s / 1e3,
          run->down_bytes_per_s / 1e3);
      std::fflush(stdout);
      runs.push_back({{"rate_hz", rate},
                      {"layout", layout},
                      {"agents", agents},
                      {"frames", run->frames},
                      {"skipped", run->skipped},
                      {"lost", run->lost},
                      {"unmerged", run->unmerged},
                      {"joint_ate_m", run->joint_ate_m},
                      {"merges", run->merges},
                      {"max_merge_ms", run->max_merge_ms},
                      {"up_bytes_per_s_per_agent", run->up_bytes_per_s},
                      {"down_bytes_per_s_per_agent", run->down_bytes_per_s}});
      // This rate's capacity is the previous count: go on with the opposite walks.
      if (!opposite && run->skipped > 0) n = max_agents;
    }
  }
  if (!out.empty()) std::ofstream(out) << runs.dump(2) << "\n";
  return 0;
}
