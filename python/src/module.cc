// The mesh2slam Python module: scenes and projection, SLAM frame by frame, evaluation.
//
//   import mesh2slam, numpy as np
//   scene = mesh2slam.load_scene()                       # the default room
//   times, poses = mesh2slam.default_trajectory()
//   f = mesh2slam.project(scene, mesh2slam.default_camera(), poses[0])
//   f["id"], f["u"], f["v"], f["depth"]                  # numpy arrays, sorted by id
#include <pybind11/pybind11.h>

#include "bindings.h"

PYBIND11_MODULE(mesh2slam, m) {
  m.doc() = "Mesh2SLAM: vertex features of a scene, the SLAM system and trajectory evaluation";
  m2s::python::RegisterScene(m);
  m2s::python::RegisterSlam(m);
  m2s::python::RegisterEvaluation(m);
}
