// m2s_server: the Mesh2SLAM SLAM server on LCM.
//
//   m2s_server [--lcm-url URL] [--config FILE] [--max-sessions N] [--session-timeout S]
//              [--save-maps DIR] [--max-features N] [--budget N] [--stats-period S]
//              [--key-file FILE [--encrypt] [--max-message-age S]] [--stats-out FILE.json]
//              [--shard K/N] [--max-groups N] [--load-map GROUP=FILE]... [--resume-maps]
//              [--save-period S] [--method NAME [--method-config FILE.json]]
//
// --method NAME: the localisation method of every session: vertex_slam (default, the built-in
// SLAM) or a plug-in, by name (libm2s_plugin_NAME.so in M2S_PLUGIN_PATH, <build>/plugins, the
// install's lib/m2s/plugins) or path (docs/design/plugins.md); --method-config: the plug-in's
// options (a JSON object). With a plug-in, map groups are refused: a HELLO naming one is
// REJECTED, and --load-map / --resume-maps / --save-maps are refused at start.
//
// --shard K/N: this server is K of N on one bus (common/shard.h): it answers only the HELLOs
// whose map group (or, without a group, session id) hashes to K, creates sessions only from
// HELLOs when N > 1, and ignores (and counts) what belongs to the others.
// --load-map GROUP=FILE (repeatable): map group GROUP starts localisation-only in the map FILE
// (saved by --save-maps as DIR/group-GROUP.m2smap) with that map's camera. A file that cannot
// be loaded ends the server with exit code 1.
// --save-maps DIR: session maps when sessions end; group maps every --save-period seconds and
// at exit. --resume-maps: at start, the group maps in DIR (this shard's) are served again with
// mapping on: a server restarted after it died continues its groups.
//
// --key-file: the bus's shared secret (head -c 32 /dev/urandom > key); every message in and
// out is authenticated and replay-checked (common/bus_auth.h). Without it the bus is open.
//
// --config reads a JSON object whose keys are the flag names with underscores (max_sessions,
// session_timeout, max_features, budget, stats_period, lcm_url, save_maps,
// deterministic, max_groups, shard) plus map_rate_hz, queue_capacity, num_ba_threads,
// max_keyframes, drift_correction and mapping_nice; flags given on the command line win; an unknown
// key or a value of the wrong type is an error. SIGINT / SIGTERM stop the server cleanly.
#include <csignal>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "m2s/plugin/plugin_system.h"
#include "m2s/server_app/lcm_server.h"

namespace {

// Applies the JSON config file's values to the options that were not given as flags. Unknown
// keys and values of the wrong type are errors (a misspelt option must not pass silently).
m2s::Status ReadConfig(const std::string& path, const CLI::App& app,
                       m2s::server_app::LcmServerOptions* o) {
  std::ifstream file(path);
  if (!file) return m2s::Status::Error("cannot open config file " + path);
  m2s::server_app::ServerOptions& s = o->server;
  auto given = [&app](const char* flag) { return app.count(flag) > 0; };
  try {
    const nlohmann::json j = nlohmann::json::parse(file);
    if (!j.is_object()) return m2s::Status::Error("config file " + path + ": not a JSON object");
    auto read = [&j](const char* key, auto* value) {
      if (j.contains(key)) j.at(key).get_to(*value);
    };
    if (!given("--max-sessions")) read("max_sessions", &s.max_sessions);
    if (!given("--session-timeout")) read("session_timeout", &s.session_timeout_s);
    if (!given("--max-features")) read("max_features", &s.max_features);
    if (!given("--budget")) read("budget", &s.slam.feature_budget);
    if (!given("--stats-period")) read("stats_period", &o->stats_period_s);
    if (!given("--lcm-url")) read("lcm_url", &o->lcm_url);
    if (!given("--save-maps")) read("save_maps", &s.save_maps_dir);
    if (!given("--deterministic")) read("deterministic", &s.slam.deterministic);
    if (!given("--max-groups")) read("max_groups", &s.max_groups);
    if (!given("--shard") && j.contains("shard")) {
      auto shard = m2s::ShardSpec::Parse(j.at("shard").get<std::string>());
      if (!shard) return m2s::Status::Error("config file " + path + ": " + shard.error());
      s.shard = *shard;
    }
    read("map_rate_hz", &s.map_rate_hz);
    read("queue_capacity", &s.queue_capacity);
    read("num_ba_threads", &s.slam.mapper.num_ba_threads);
    read("max_keyframes", &s.slam.mapper.max_keyframes);
    read("drift_correction", &s.slam.drift.enabled);
    read("mapping_nice", &s.slam.mapping_nice);
    static const std::set<std::string> kKeys = {
        "max_sessions",     "session_timeout", "max_features",   "budget",
        "stats_period",     "lcm_url",         "save_maps",      "deterministic",
        "map_rate_hz",      "queue_capacity",  "num_ba_threads", "max_keyframes",
        "drift_correction", "mapping_nice",    "max_groups",     "shard"};
    for (const auto& [key, value] : j.items()) {
      if (!kKeys.contains(key)) {
        return m2s::Status::Error("config file " + path + ": unknown key \"" + key + "\"");
      }
    }
  } catch (const nlohmann::json::exception& e) {
    return m2s::Status::Error("config file " + path + ": " + e.what());
  }
  return m2s::Status::Ok();
}

// Parses the --load-map values GROUP=FILE; the file must be readable (its content is checked
// when the group loads it).
m2s::Status ParseGroupMaps(const std::vector<std::string>& values,
                           std::map<std::string, std::string>* group_maps) {
  for (const std::string& value : values) {
    const size_t eq = value.find('=');
    if (eq == std::string::npos || eq == 0 || eq + 1 == value.size()) {
      return m2s::Status::Error("--load-map " + value + ": expected GROUP=FILE");
    }
    const std::string group = value.substr(0, eq), file = value.substr(eq + 1);
    if (m2s::Status name = m2s::wire::CheckMapGroupName(group); !name) {
      return name.Prefixed("--load-map " + value + ": ");
    }
    if (!std::ifstream(file))
      return m2s::Status::Error("--load-map " + value + ": cannot open " + file);
    if (!group_maps->emplace(group, file).second) {
      return m2s::Status::Error("--load-map: map group " + group + " given twice");
    }
  }
  return m2s::Status::Ok();
}

}  // namespace

int main(int argc, char** argv) {
  m2s::server_app::LcmServerOptions options;
  std::string config;
  CLI::App app{"Mesh2SLAM server: vertex-feature frames in, poses and map deltas out, over LCM"};
  app.add_option("--lcm-url", options.lcm_url, "LCM URL (udpm://...?ttl=0, memq://, file://)");
  app.add_option("--config", config,
                 "JSON file with server options (keys: the flags' names with _)");
  app.add_option("--max-sessions", options.server.max_sessions, "Concurrent sessions");
  app.add_option("--session-timeout", options.server.session_timeout_s,
                 "End a session after this many seconds without messages");
  app.add_option("--save-maps", options.server.save_maps_dir,
                 "Save each session's map into this folder when it ends, and each map group's "
                 "(group-NAME.m2smap) when the server stops");
  app.add_option("--max-features", options.server.max_features, "Largest frame accepted");
  app.add_option("--budget", options.server.slam.feature_budget,
                 "SLAM uses at most N features a frame, chosen by id hash (0: all)");
  app.add_option("--stats-period", options.stats_period_s, "Seconds between stats (0: never)");
  app.add_flag("--deterministic", options.server.slam.deterministic,
               "Run every session's SLAM deterministically");
  std::string shard = "0/1";
  app.add_option("--shard", shard, "Serve share K of N servers on this bus (K/N)")
      ->capture_default_str();
  app.add_option("--max-groups", options.server.max_groups, "Map groups held at most")
      ->capture_default_str();
  std::vector<std::string> load_maps;
  app.add_option("--load-map", load_maps,
                 "GROUP=FILE: start map group GROUP localisation-only in a saved map (repeatable)");
  app.add_flag("--resume-maps", options.resume_maps,
               "Resume the group maps saved in --save-maps DIR (this shard's) and keep mapping "
               "into them: a restarted server continues its groups");
  app.add_option("--save-period", options.server.save_period_s,
                 "Seconds between saves of the group maps to --save-maps DIR (0: only at exit)")
      ->capture_default_str();
  std::string key_file, stats_out;
  bool encrypt = false;
  app.add_option("--stats-out", stats_out, "Write the server's counters (JSON) here at exit");
  double max_message_age_s = options.bus.opener.max_age_s;
  app.add_option("--key-file", key_file, "Shared secret of the bus: authenticate every message");
  app.add_flag("--encrypt", encrypt, "Also encrypt payloads (needs --key-file)");
  app.add_option("--max-message-age", max_message_age_s,
                 "Keyed bus: refuse messages older than S seconds (0: no check)")
      ->capture_default_str();
  std::string method = m2s::plugin::kBuiltinMethod, method_config;
  app.add_option("--method", method,
                 "Localisation method: vertex_slam (built in) or a plug-in's name or path")
      ->capture_default_str();
  app.add_option("--method-config", method_config, "The plug-in's options (JSON object file)");
  CLI11_PARSE(app, argc, argv);
  auto security = m2s::wire::MakeBusSecurity(key_file, encrypt, max_message_age_s);
  if (!security) {
    std::cerr << "m2s_server: " << security.error() << "\n";
    return 2;
  }
  options.bus = *security;
  if (app.count("--shard")) {
    auto parsed = m2s::ShardSpec::Parse(shard);
    if (!parsed) {
      std::cerr << "m2s_server: --shard: " << parsed.error() << "\n";
      return 2;
    }
    options.server.shard = *parsed;
  }
  if (m2s::Status parsed = ParseGroupMaps(load_maps, &options.group_maps); !parsed) {
    std::cerr << "m2s_server: " << parsed.message() << "\n";
    return 1;
  }

  if (!config.empty()) {
    if (m2s::Status read = ReadConfig(config, app, &options); !read) {
      std::cerr << "m2s_server: " << read.message() << "\n";
      return 2;
    }
  }
  if (!options.server.save_maps_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(options.server.save_maps_dir, ec);
    if (ec) {
      std::cerr << "m2s_server: cannot create " << options.server.save_maps_dir << ": "
                << ec.message() << "\n";
      return 2;
    }
  }
  if (options.resume_maps && options.server.save_maps_dir.empty()) {
    std::cerr << "m2s_server: --resume-maps needs --save-maps DIR\n";
    return 2;
  }
  if (m2s::Status valid = options.server.Check(); !valid) {
    std::cerr << "m2s_server: " << valid.message() << "\n";
    return 2;
  }

  std::string method_config_json;
  if (!method_config.empty()) {
    auto text = m2s::plugin::ReadMethodConfig(method_config);
    if (!text) {
      std::cerr << "m2s_server: " << text.error() << "\n";
      return 2;
    }
    method_config_json = *text;
  }
  if (!m2s::plugin::IsBuiltinMethod(method) &&
      (!options.group_maps.empty() || options.resume_maps ||
       !options.server.save_maps_dir.empty())) {
    std::cerr << "m2s_server: --load-map, --resume-maps and --save-maps need the built-in SLAM "
                 "(--method vertex_slam)\n";
    return 2;
  }
  auto factories = m2s::plugin::LoadMethod(method, method_config_json);
  if (!factories) {
    std::cerr << "m2s_server: " << factories.error() << "\n";
    return 2;
  }
  if (!factories->path.empty()) {
    std::cerr << "m2s_server: method " << factories->name << " (" << factories->path << ")\n";
  }

  // Block the stop signals in every thread; this thread waits for them below.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  m2s::server_app::LcmServer server(options, factories->system, factories->group);
  if (m2s::Status started = server.Start(); !started) {
    std::cerr << "m2s_server: " << started.message() << "\n";
    return 1;
  }
  int signal_number = 0;
  sigwait(&signals, &signal_number);
  std::cerr << "m2s_server: " << (signal_number == SIGINT ? "SIGINT" : "SIGTERM") << ", stopping\n";
  server.Stop();
  if (!stats_out.empty()) {
    std::ofstream out(stats_out);
    out << server.CountersJson();
    if (!out) {
      std::cerr << "m2s_server: cannot write " << stats_out << "\n";
      return 1;
    }
  }
  return 0;
}
