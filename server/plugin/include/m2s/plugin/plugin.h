// The C++ side of the Mesh2SLAM plug-in ABI (m2s_plugin.h): implement m2s::plugin::Method,
// write a factory, and M2S_DEFINE_PLUGIN exports the C table. Header-only; needs only
// m2s_plugin.h and the standard library, so a plug-in built outside the tree needs just these
// two headers.
//
// Contract of a Method (the host calls one instance from one thread at a time):
//  - the factory builds it for a camera and a JSON object's text (its own options; "{}" when
//    none) and throws (any std::exception) when it cannot, e.g. on an unknown key;
//  - ProcessFrame() takes one frame (features as sent: (id, u, v), sorted by id, validated) and
//    returns its result; it throws on an error, and that frame counts as rejected;
//  - CurrentPose(), MapPoints(), Trajectory() report the current estimate;
//  - the destructor is the shutdown: it stops the method's threads.
// Every exception is caught at the ABI boundary and handed to the host as the one-line error.
//
//   class MyOdometry : public m2s::plugin::Method { ... };
//   std::unique_ptr<m2s::plugin::Method> MakeMyOdometry(const m2s_camera& camera,
//                                                       const std::string& config_json) {
//     return std::make_unique<MyOdometry>(camera, config_json);
//   }
//   M2S_DEFINE_PLUGIN("my_odometry", "frame-to-frame odometry", MakeMyOdometry)
#pragma once

#include <cstdio>
#include <cstring>
#include <exception>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "m2s/plugin/m2s_plugin.h"

namespace m2s::plugin {

enum class TrackState : int32_t {
  kNotInitialized = M2S_TRACK_NOT_INITIALIZED,
  kOk = M2S_TRACK_OK,
  kLost = M2S_TRACK_LOST,
  kRelocalized = M2S_TRACK_RELOCALIZED,
  kRejected = M2S_TRACK_REJECTED,
};

// What ProcessFrame() returns; `world_from_camera` counts when state is kOk or kRelocalized.
struct FrameResult {
  TrackState state = TrackState::kNotInitialized;
  m2s_pose world_from_camera{{1.0, 0.0, 0.0, 0.0}, {0.0, 0.0, 0.0}};
  int num_inliers = 0;
  bool keyframe_created = false;
};

// A localisation method behind the plug-in ABI. Not thread-safe: the host serialises calls.
class Method {
 public:
  // Set to true in a derived class that overrides Trajectory(); M2S_DEFINE_PLUGIN then exports
  // the `trajectory` function (otherwise NULL: the host keeps each frame's result).
  static constexpr bool kHasTrajectory = false;

  virtual ~Method() = default;  // shutdown

  virtual FrameResult ProcessFrame(const m2s_frame& frame) = 0;
  // The pose of the last frame with a pose; nullopt before the first one.
  virtual std::optional<m2s_pose> CurrentPose() const = 0;
  // The map (empty for a method without one).
  virtual std::vector<m2s_map_point> MapPoints() const = 0;
  // The whole trajectory as the method now estimates it (e.g. refined by bundle adjustment).
  virtual std::vector<m2s_trajectory_entry> Trajectory() const { return {}; }
  // Drops the tracking state and relocalises against the map from the next frames.
  virtual void Relocalise() { throw std::runtime_error("relocalise is not supported"); }
  // Forgets map and trajectory in place and returns true; the default returns false and the
  // host side of the ABI recreates the method from its factory (same camera and config).
  virtual bool Reset() { return false; }
};

using Factory = std::unique_ptr<Method> (*)(const m2s_camera& camera,
                                            const std::string& config_json);

namespace internal {

inline void WriteError(const char* message, char* error, size_t error_size) {
  if (error == nullptr || error_size == 0) return;
  std::snprintf(error, error_size, "%s", message);
  // One line: a message with a newline is cut there.
  if (char* newline = std::strchr(error, '\n')) *newline = '\0';
}

// Runs f(); an exception becomes the error message and a nonzero return.
template <typename F>
int Guard(char* error, size_t error_size, F&& f) {
  try {
    f();
    return 0;
  } catch (const std::exception& e) {
    WriteError(e.what(), error, error_size);
  } catch (...) {
    WriteError("unknown C++ exception", error, error_size);
  }
  return 1;
}

struct Instance {
  m2s_camera camera;
  std::string config_json;
  std::unique_ptr<Method> method;
};

template <typename T>
size_t CopyOut(const std::vector<T>& items, T* out, size_t capacity) {
  const size_t n = items.size() < capacity ? items.size() : capacity;
  if (n > 0) std::memcpy(out, items.data(), n * sizeof(T));
  return items.size();
}

// The C table of a factory; MethodT is the class the factory returns (for kHasTrajectory).
template <Factory kFactory, typename MethodT>
struct Trampolines {
  static void* Create(const m2s_camera* camera, const char* config_json, char* error,
                      size_t error_size) {
    Instance* created = nullptr;
    Guard(error, error_size, [&] {
      if (camera == nullptr) throw std::invalid_argument("no camera");
      auto instance = std::make_unique<Instance>();
      instance->camera = *camera;
      instance->config_json = config_json != nullptr ? config_json : "{}";
      instance->method = kFactory(instance->camera, instance->config_json);
      if (!instance->method) throw std::runtime_error("the factory returned no method");
      created = instance.release();
    });
    return created;
  }
  static int ProcessFrame(void* instance, const m2s_frame* frame, m2s_track_result* result,
                          char* error, size_t error_size) {
    return Guard(error, error_size, [&] {
      const FrameResult r = static_cast<Instance*>(instance)->method->ProcessFrame(*frame);
      result->state = static_cast<int32_t>(r.state);
      result->world_from_camera = r.world_from_camera;
      result->num_inliers = r.num_inliers;
      result->keyframe_created = r.keyframe_created ? 1 : 0;
    });
  }
  static int CurrentPose(void* instance, m2s_pose* pose) {
    int missing = 0;
    const int failed = Guard(nullptr, 0, [&] {
      const auto current = static_cast<Instance*>(instance)->method->CurrentPose();
      if (current) *pose = *current;
      missing = current ? 0 : 1;
    });
    return failed != 0 ? failed : missing;
  }
  static size_t MapPoints(void* instance, m2s_map_point* points, size_t capacity) {
    size_t total = 0;
    Guard(nullptr, 0, [&] {
      total = CopyOut(static_cast<Instance*>(instance)->method->MapPoints(), points, capacity);
    });
    return total;
  }
  static size_t Trajectory(void* instance, m2s_trajectory_entry* entries, size_t capacity) {
    size_t total = 0;
    Guard(nullptr, 0, [&] {
      total = CopyOut(static_cast<Instance*>(instance)->method->Trajectory(), entries, capacity);
    });
    return total;
  }
  static int Relocalise(void* instance, char* error, size_t error_size) {
    return Guard(error, error_size,
                 [&] { static_cast<Instance*>(instance)->method->Relocalise(); });
  }
  static int Reset(void* instance, char* error, size_t error_size) {
    return Guard(error, error_size, [&] {
      auto* self = static_cast<Instance*>(instance);
      if (self->method->Reset()) return;
      self->method.reset();  // the old one stops before the new one starts
      self->method = kFactory(self->camera, self->config_json);
      if (!self->method) throw std::runtime_error("the factory returned no method");
    });
  }
  static void Destroy(void* instance) {
    try {
      delete static_cast<Instance*>(instance);
    } catch (...) {  // a destructor that throws must not cross the C boundary
    }
  }

  static const m2s_plugin* Table(const char* name, const char* description) {
    static const m2s_plugin table = {
        M2S_PLUGIN_ABI_VERSION,
        name,
        description,
        &Create,
        &ProcessFrame,
        &CurrentPose,
        &MapPoints,
        MethodT::kHasTrajectory ? &Trajectory : nullptr,
        &Relocalise,
        &Reset,
        &Destroy,
    };
    return &table;
  }
};

// The Method class a factory returns: std::unique_ptr<MethodT>.
template <typename Ptr>
using MethodOf = typename Ptr::element_type;

}  // namespace internal
}  // namespace m2s::plugin

// Defines the exported entry point m2s_plugin_entry() of a plug-in whose instances `factory`
// makes: std::unique_ptr<MethodT> factory(const m2s_camera&, const std::string& config_json),
// MethodT derived from m2s::plugin::Method. Use once per shared library, at namespace scope.
#define M2S_DEFINE_PLUGIN(name, description, factory)                                 \
  namespace m2s_plugin_definition {                                                   \
  inline std::unique_ptr<::m2s::plugin::Method> M2sDefinedPluginFactory(              \
      const m2s_camera& camera, const std::string& config_json) {                     \
    return factory(camera, config_json);                                              \
  }                                                                                   \
  using M2sDefinedPluginMethod = ::m2s::plugin::internal::MethodOf<decltype(factory(  \
      std::declval<const m2s_camera&>(), std::declval<const std::string&>()))>;       \
  static_assert(std::is_base_of_v<::m2s::plugin::Method, M2sDefinedPluginMethod>,     \
                "the factory must return std::unique_ptr<T>, T derived from Method"); \
  }                                                                                   \
  extern "C" M2S_PLUGIN_EXPORT const m2s_plugin* m2s_plugin_entry(void) {             \
    return ::m2s::plugin::internal::Trampolines<                                      \
        &m2s_plugin_definition::M2sDefinedPluginFactory,                              \
        m2s_plugin_definition::M2sDefinedPluginMethod>::Table(name, description);     \
  }
