// The method families the compiled loop knows: one line per family (its header registers it).
// The Python registry is coopdyn/integrators/__init__.py: INTEGRATORS; each built-in's
// compiled_spec()["method"] names one of these (tests/test_structure.py checks both ways).
#pragma once

#include "exponential.hpp"
#include "generalized_alpha.hpp"
#include "implicit_euler.hpp"
#include "rosenbrock.hpp"
#include "runge_kutta.hpp"
#include "symplectic_euler.hpp"
