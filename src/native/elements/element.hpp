// The element protocol in C++: the twin of coopdyn/model/elements/base.py, and the registry of
// elements. Each header in this folder defines one element and registers it under its Python
// twin's kind (CMakeLists.txt includes every header of the folder: adding one is adding a file).
#pragma once

#include "../lie.hpp"
#include "../settings.hpp"

#include <boost/python.hpp>

#include <algorithm>
#include <map>
#include <memory>
#include <set>
#include <stdexcept>
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
  // The exact derivatives of out.f with respect to a right perturbation T_M_G·exp6(δ) (F_d) and
  // to ξ (F_x), as Element.tangent in Python; true when exact. This default takes central
  // differences of evaluate (as base.py's default, same steps) and returns false.
  virtual bool tangent(const pinocchio::SE3 & T_M_G, const Vector6 & xi, Matrix6 & F_d, Matrix6 & F_x) const {
    constexpr double step = 6e-6;  // base.py's _FD_STEP
    const double h_d = step * std::max(1.0, T_M_G.translation().norm()), h_x = step * std::max(1.0, xi.norm());
    ElementEval plus, minus;
    for (int k = 0; k < 6; ++k) {
      Vector6 d = Vector6::Zero();
      d[k] = h_d;
      evaluate(T_M_G * pinocchio::exp6(pinocchio::Motion(d)), xi, false, plus);
      evaluate(T_M_G * pinocchio::exp6(pinocchio::Motion(-d)), xi, false, minus);
      F_d.col(k) = (plus.f - minus.f) / (2.0 * h_d);
      d[k] = h_x;
      evaluate(T_M_G, xi + d, false, plus);
      evaluate(T_M_G, xi - d, false, minus);
      F_x.col(k) = (plus.f - minus.f) / (2.0 * h_x);
    }
    return false;
  }
  // The derivatives of SK w_K + SD w_D — the Gauss–Newton matrices applied to two fixed twists —
  // with respect to T_M_G·exp6(δ) (G_d) and to ξ (G_x), as Element.matrix_tangent in Python; true
  // when exact. This default takes central differences of evaluate (base.py's, same steps).
  virtual bool matrix_tangent(const pinocchio::SE3 & T_M_G, const Vector6 & xi, const Vector6 & w_K, const Vector6 & w_D,
                              Matrix6 & G_d, Matrix6 & G_x) const {
    constexpr double step = 6e-6;  // base.py's _FD_STEP
    const double h_d = step * std::max(1.0, T_M_G.translation().norm()), h_x = step * std::max(1.0, xi.norm());
    ElementEval plus, minus;
    auto applied = [&](const ElementEval & ev) -> Vector6 { return ev.SK * w_K + ev.SD * w_D; };
    for (int k = 0; k < 6; ++k) {
      Vector6 d = Vector6::Zero();
      d[k] = h_d;
      evaluate(T_M_G * pinocchio::exp6(pinocchio::Motion(d)), xi, true, plus);
      evaluate(T_M_G * pinocchio::exp6(pinocchio::Motion(-d)), xi, true, minus);
      G_d.col(k) = (applied(plus) - applied(minus)) / (2.0 * h_d);
      d[k] = h_x;
      evaluate(T_M_G, xi + d, true, plus);
      evaluate(T_M_G, xi - d, true, minus);
      G_x.col(k) = (applied(plus) - applied(minus)) / (2.0 * h_x);
    }
    return false;
  }
};

// An element's parameters as its Python twin gives them (Element.native_parameters(): a dict of
// name → number or matrix), read by name through the settings reader (../settings.hpp): every
// name given must be read, so a parameter the C++ twin does not know is an error, not ignored.
using Parameters = coopdyn_native::Settings;

using ElementFactory = std::unique_ptr<Element> (*)(Parameters & parameters);

inline std::map<std::string, ElementFactory> & element_registry() {
  static std::map<std::string, ElementFactory> registry;
  return registry;
}

// One line in an element's header: `inline const bool registered = register_element("kind", make);`
inline bool register_element(const char * kind, ElementFactory make) {
  element_registry()[kind] = make;
  return true;
}

// The element `kind` built from its parameters (every one read).
inline std::unique_ptr<Element> make_element(const std::string & kind, const boost::python::dict & values) {
  const auto found = element_registry().find(kind);
  if (found == element_registry().end()) {
    std::string known;
    for (const auto & entry : element_registry()) known += (known.empty() ? "" : ", ") + entry.first;
    throw std::invalid_argument("the kernel has no element '" + kind + "' (registered: " + known + ")");
  }
  Parameters parameters("element '" + kind + "'", values, "parameter");
  std::unique_ptr<Element> out = found->second(parameters);
  parameters.check_all_read();
  return out;
}

// The kinds registered (exposed as coopdyn._native.ELEMENTS).
inline boost::python::list element_kinds() {
  boost::python::list out;
  for (const auto & entry : element_registry()) out.append(entry.first);
  return out;
}

}  // namespace coopdyn
