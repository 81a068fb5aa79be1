/* Plug-ins for the loader and PluginSystem tests, in plain C (the ABI is C). One source, one
 * variant per TEST_PLUGIN_VARIANT:
 *   1 no_entry:   no m2s_plugin_entry symbol
 *   2 abi999:     abi_version 999
 *   3 null_fn:    process_frame is NULL
 *   4 null_table: m2s_plugin_entry returns NULL
 *   5 faulty:     works, but process_frame fails on seq % 4 == 1 and returns a NaN pose on
 *                 seq % 4 == 2; counts its instances (m2s_test_live_instances). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "m2s/plugin/m2s_plugin.h"

/* Some variants leave some of these unused. */
#define MAYBE_UNUSED __attribute__((unused))

typedef struct instance {
  m2s_pose pose;
  int has_pose;
  int64_t frames;
} instance;

static int live_instances = 0;
static int destroyed = 0;

M2S_PLUGIN_EXPORT int m2s_test_live_instances(void) { return live_instances; }
M2S_PLUGIN_EXPORT int m2s_test_destroyed(void) { return destroyed; }

static MAYBE_UNUSED void* create(const m2s_camera* camera, const char* config_json, char* error,
                                 size_t error_size) {
  instance* self;
  if (config_json[0] != '{' || config_json[1] != '}') {
    snprintf(error, error_size, "config: unknown key (this plug-in takes none)");
    return NULL;
  }
  self = (instance*)calloc(1, sizeof(instance));
  (void)camera;
  ++live_instances;
  return self;
}

static MAYBE_UNUSED int process_frame(void* p, const m2s_frame* frame, m2s_track_result* result,
                                      char* error, size_t error_size) {
  instance* self = (instance*)p;
  ++self->frames;
  if (frame->seq % 4 == 1) {
    snprintf(error, error_size, "cannot process frame %lld", (long long)frame->seq);
    return 1;
  }
  result->state = M2S_TRACK_OK;
  result->num_inliers = (int32_t)frame->num_features;
  result->keyframe_created = 0;
  result->world_from_camera.rotation_wxyz[0] = 1.0;
  result->world_from_camera.rotation_wxyz[1] = 0.0;
  result->world_from_camera.rotation_wxyz[2] = 0.0;
  result->world_from_camera.rotation_wxyz[3] = 0.0;
  result->world_from_camera.translation[0] = (double)frame->seq;
  result->world_from_camera.translation[1] = 0.0;
  result->world_from_camera.translation[2] = frame->seq % 4 == 2 ? NAN : 0.0;
  if (frame->seq % 4 != 2) {
    self->pose = result->world_from_camera;
    self->has_pose = 1;
  }
  return 0;
}

static MAYBE_UNUSED int current_pose(void* p, m2s_pose* pose) {
  instance* self = (instance*)p;
  if (!self->has_pose) return 1;
  *pose = self->pose;
  return 0;
}

/* Points 0..n-1 at x = id, y = frames processed (every call after a frame moves them all), with
 * n = min(frames, 5). */
static MAYBE_UNUSED size_t map_points(void* p, m2s_map_point* points, size_t capacity) {
  instance* self = (instance*)p;
  size_t n = self->frames < 5 ? (size_t)self->frames : 5, i;
  for (i = 0; i < n && i < capacity; ++i) {
    points[i].id = (uint32_t)i;
    points[i].x = (float)i;
    points[i].y = (float)self->frames;
    points[i].z = 1.0f;
  }
  return n;
}

static MAYBE_UNUSED void destroy(void* p) {
  free(p);
  --live_instances;
  ++destroyed;
}

#if TEST_PLUGIN_VARIANT != 1
static MAYBE_UNUSED const m2s_plugin table = {
#if TEST_PLUGIN_VARIANT == 2
    999u,
#else
    M2S_PLUGIN_ABI_VERSION,
#endif
    TEST_PLUGIN_NAME,
    "a plug-in for the tests",
    create,
#if TEST_PLUGIN_VARIANT == 3
    NULL,
#else
    process_frame,
#endif
    current_pose,
    map_points,
    NULL,
    NULL,
    NULL,
    destroy};

M2S_PLUGIN_EXPORT const m2s_plugin* m2s_plugin_entry(void) {
#if TEST_PLUGIN_VARIANT == 4
  return NULL;
#else
  return &table;
#endif
}
#endif
