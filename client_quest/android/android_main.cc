// The native activity's entry point on Android / Quest: routes the log to logcat, reads the
// config file the user pushed to the app's external files folder, and runs the same
// RunXrClient as the desktop app. The Android event queue is pumped from the render loop
// (XrClientOptions::platform_events), so activity lifecycle events are never starved.
#if defined(__ANDROID__)

#include <android/log.h>
#include <android_native_app_glue.h>

#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

#include "m2s/common/logging.h"
#include "m2s/xr/xr_client.h"

namespace {

void ApplyConfig(const std::string& path, m2s::xr::XrClientOptions* options) {
  std::ifstream file(path);
  if (!file) return;  // defaults: on-device SLAM on the embedded scene
  const nlohmann::json j = nlohmann::json::parse(file, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded()) {
    M2S_LOG(kError) << "ignoring malformed config " << path;
    return;
  }
  options->mesh_path = j.value("mesh", options->mesh_path);
  options->on_device = j.value("transport", std::string("on-device")) != "lcm";
  options->lcm_url = j.value("lcm_url", options->lcm_url);
  options->projector = j.value("projector", options->projector);
  options->stage_space = j.value("stage", options->stage_space);
  options->overlay = j.value("overlay", options->overlay);
  options->show_other_keyframes = j.value("other_keyframes", options->show_other_keyframes);
  options->map_group = j.value("map_group", options->map_group);
  options->draw_mesh = j.value("mesh_visible", options->draw_mesh);
  if (auto events = m2s::xr::ParseControlEvents(j.value("events", std::string())); events) {
    options->events = *events;
  }
}

}  // namespace

void android_main(android_app* app) {
  m2s::SetLogSink([](m2s::LogLevel level, std::string_view message) {
    const int priority = level >= m2s::LogLevel::kError     ? ANDROID_LOG_ERROR
                         : level >= m2s::LogLevel::kWarning ? ANDROID_LOG_WARN
                                                            : ANDROID_LOG_INFO;
    __android_log_print(priority, "m2s_xr", "%.*s", static_cast<int>(message.size()),
                        message.data());
  });
  const std::string files = app->activity->externalDataPath ? app->activity->externalDataPath : "";
  m2s::xr::XrClientOptions options;
  options.out_dir = files + "/out";
  ApplyConfig(files + "/m2s_xr_client.json", &options);
  options.platform_events = [app]() {
    int events = 0;
    android_poll_source* source = nullptr;
    while (ALooper_pollAll(0, nullptr, &events, reinterpret_cast<void**>(&source)) >= 0) {
      if (source != nullptr) source->process(app, source);
    }
    return app->destroyRequested == 0;
  };
  auto platform = m2s::xr::MakePlatform(app);
  auto result = m2s::xr::RunXrClient(options, platform.get());
  if (!result) {
    M2S_LOG(kError) << result.error();
  } else {
    M2S_LOG(kInfo) << result->summary;
  }
  ANativeActivity_finish(app->activity);
}

#endif  // __ANDROID__
