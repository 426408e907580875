// The compiled loop's controllers (controllers/: one header per law) and method families
// (methods/: one header per family), each registering itself in its registry: a translation unit
// of their own, which the build compiles beside kernel.cpp on another core (CMakeLists.txt).

#include "kernel.hpp"  // first: eigenpy before any boost.python header
#include "registered_controllers.hpp"
#include "registered_methods.hpp"
