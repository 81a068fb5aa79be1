// The parts of the mesh2slam module, each registering its functions and classes.
#pragma once

#include <pybind11/pybind11.h>

namespace m2s::python {

void RegisterScene(pybind11::module_& m);       // scene_bindings.cc
void RegisterSlam(pybind11::module_& m);        // slam_bindings.cc
void RegisterEvaluation(pybind11::module_& m);  // evaluation_bindings.cc

}  // namespace m2s::python
