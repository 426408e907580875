// The element protocol in C++: the twin of coopdyn/model/elements/base.py.
#pragma once

#include "../lie.hpp"

#include <memory>
#include <string>

namespace coopdyn {

// What an element contributes at one relative pose T_M_G and relative body twist ξ (see base.py).
struct ElementEval {
  double energy = 0.0;      // [J]
  double power = 0.0;       // dissipated [W]
  double theta = 0.0;       // rotation angle of T_M_G [rad]
  Vector6 deformation;      // the element's deformation, zero-padded to 6
  Vector6 f;                // wrench on G at G, in G axes [N, N·m]
  Matrix6 SK, SD;           // Gauss–Newton stiffness / damping in relative-twist coordinates
};

class Element {
public:
  virtual ~Element() = default;
  // Whether the element dissipates (lets the kernel skip the damping terms).
  virtual bool damped() const = 0;
  // Fill `out` at (T_M_G, ξ); with `jacobians`, also out.SK and out.SD.
  virtual void evaluate(const pinocchio::SE3 & T_M_G, const Vector6 & xi, bool jacobians, ElementEval & out) const = 0;
};

}  // namespace coopdyn
