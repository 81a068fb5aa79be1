/* The Mesh2SLAM plug-in ABI: a localisation method (a tracker, an odometry or a full SLAM)
 * built as a shared library, loaded with dlopen by name, fed the same vertex-feature frames as
 * the built-in SLAM.
 *
 * Plain C (C99 and C++), no dependency but <stddef.h> and <stdint.h>, so a plug-in builds
 * anywhere with this header alone. A C++ plug-in can implement m2s::plugin::Method instead
 * (m2s/plugin/plugin.h), which defines the entry point below.
 *
 * A plug-in exports exactly one symbol:
 *
 *   M2S_PLUGIN_EXPORT const m2s_plugin* m2s_plugin_entry(void);
 *
 * returning a table that lives as long as the library is loaded. The loader checks
 * abi_version == M2S_PLUGIN_ABI_VERSION and that every required function is set, and refuses
 * the library otherwise with a message naming it.
 *
 * Conventions:
 *  - Poses are world_from_camera: a point p_c in the camera frame (OpenCV axes: x right,
 *    y down, z forward) is p_w = R * p_c + t. R is the unit quaternion (w, x, y, z).
 *  - A feature is (id, u, v): pixel coordinates with (0, 0) the top-left corner of the
 *    top-left pixel; the id is the scene vertex the feature belongs to (or, for an image front
 *    end, a track id), so association across frames is an integer compare.
 *  - Functions returning int return 0 on success; on failure they return nonzero and write a
 *    one-line, NUL-terminated message of at most error_size bytes (error_size >= 1) into error.
 *  - The host calls one instance from one thread at a time (never concurrently); a plug-in may
 *    run threads of its own. Pointers handed in are valid only during the call.
 *  - Lifetime: create -> process_frame* (interleaved with the queries) -> destroy.
 */
#ifndef M2S_PLUGIN_M2S_PLUGIN_H_
#define M2S_PLUGIN_M2S_PLUGIN_H_

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Bumped on every incompatible change of the structures or the table below. */
#define M2S_PLUGIN_ABI_VERSION 1u

#if defined(_WIN32)
#define M2S_PLUGIN_EXPORT __declspec(dllexport)
#else
#define M2S_PLUGIN_EXPORT __attribute__((visibility("default")))
#endif

/* The pinhole camera of every frame of a run (CAMERA.json's keys). */
typedef struct m2s_camera {
  int32_t width;
  int32_t height;
  double fx, fy, cx, cy;
  double near_m, far_m; /* the projector's depth range, metres */
} m2s_camera;

typedef struct m2s_feature {
  uint32_t id;
  float u, v;
} m2s_feature;

typedef struct m2s_frame {
  int64_t seq;      /* strictly increasing within a run */
  double timestamp; /* capture time, seconds */
  const m2s_feature* features;
  uint32_t num_features;
} m2s_frame;

typedef struct m2s_pose {
  double rotation_wxyz[4]; /* unit quaternion */
  double translation[3];   /* metres (or the method's own scale for monocular methods) */
} m2s_pose;

/* The values of slam::TrackingState. */
typedef enum m2s_track_state {
  M2S_TRACK_NOT_INITIALIZED = 0, /* no pose yet (initialising) */
  M2S_TRACK_OK = 1,
  M2S_TRACK_LOST = 2,
  M2S_TRACK_RELOCALIZED = 3,
  M2S_TRACK_REJECTED = 4 /* the frame was not used */
} m2s_track_state;

typedef struct m2s_track_result {
  int32_t state;              /* an m2s_track_state */
  m2s_pose world_from_camera; /* valid when state is OK or RELOCALIZED */
  int32_t num_inliers;        /* features the pose agrees with (0 when unknown) */
  int32_t keyframe_created;   /* nonzero when the frame became a keyframe */
} m2s_track_result;

typedef struct m2s_map_point {
  uint32_t id; /* the feature id it was built from */
  float x, y, z;
} m2s_map_point;

/* One pose of the method's own (refined) trajectory, e.g. after bundle adjustment. */
typedef struct m2s_trajectory_entry {
  int64_t seq;
  double timestamp;
  int32_t state; /* an m2s_track_state */
  m2s_pose world_from_camera;
} m2s_trajectory_entry;

typedef struct m2s_plugin {
  uint32_t abi_version;    /* M2S_PLUGIN_ABI_VERSION */
  const char* name;        /* short name, [a-z0-9_]+ (what users type after --method) */
  const char* description; /* one line */

  /* Configuration and init: an instance for this camera. config_json is a JSON object's text
   * (the method's own options; "{}" when none); unknown keys should be refused. NULL on
   * failure, with the message in error. Required. */
  void* (*create)(const m2s_camera* camera, const char* config_json, char* error,
                  size_t error_size);

  /* Processes one frame synchronously and fills result. Required. */
  int (*process_frame)(void* instance, const m2s_frame* frame, m2s_track_result* result,
                       char* error, size_t error_size);

  /* The latest pose estimate (of the last frame with a pose); nonzero when there is none.
   * Required. */
  int (*current_pose)(void* instance, m2s_pose* pose);

  /* Map points: writes min(total, capacity) of them and returns the total, so a call with
   * capacity 0 sizes the buffer. Required (a method without a map returns 0). */
  size_t (*map_points)(void* instance, m2s_map_point* points, size_t capacity);

  /* Optional (may be NULL): the whole trajectory as the method now estimates it, same calling
   * convention as map_points. Without it the host uses each frame's result. */
  size_t (*trajectory)(void* instance, m2s_trajectory_entry* entries, size_t capacity);

  /* Optional (may be NULL): drop the tracking state and relocalise from the next frames
   * against the existing map. */
  int (*relocalise)(void* instance, char* error, size_t error_size);

  /* Optional (may be NULL): forget map and trajectory; the next frames initialise again. */
  int (*reset)(void* instance, char* error, size_t error_size);

  /* Shutdown: stops the method's threads and frees the instance. Required. */
  void (*destroy)(void* instance);
} m2s_plugin;

/* The entry point every plug-in exports. */
typedef const m2s_plugin* (*m2s_plugin_entry_fn)(void);
#define M2S_PLUGIN_ENTRY_SYMBOL "m2s_plugin_entry"

#ifdef __cplusplus
} /* extern "C" */
#endif

#endif /* M2S_PLUGIN_M2S_PLUGIN_H_ */
