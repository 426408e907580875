// The element protocol in C++: the twin of coopdyn/model/elements/base.py, and the registry of
// elements. Each header in this folder defines one element and registers it under its Python
// twin's kind (CMakeLists.txt includes every header of the folder: adding one is adding a file).
#pragma once

#include "../lie.hpp"

#include <boost/python.hpp>

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
};

// An element's parameters as its Python twin gives them (Element.native_parameters(): a dict of
// name → number or matrix), read by name. Every name given must be read: a parameter the C++
// twin does not know (misspelled, or added in Python only) is an error, not ignored.
class Parameters {
public:
  Parameters(std::string kind, boost::python::dict values) : kind_(std::move(kind)), values_(std::move(values)) {}

  Eigen::MatrixXd matrix(const char * name, Eigen::Index rows, Eigen::Index cols) {
    boost::python::extract<Eigen::MatrixXd> x(value(name));
    if (!x.check()) throw std::invalid_argument("element '" + kind_ + "': parameter " + name + " must be a matrix of numbers");
    const Eigen::MatrixXd m = x();
    if (m.rows() != rows || m.cols() != cols)
      throw std::invalid_argument("element '" + kind_ + "': parameter " + name + " must be " + std::to_string(rows) + "x" +
                                  std::to_string(cols));
    return m;
  }
  double number(const char * name) {
    boost::python::extract<double> x(value(name));
    if (!x.check()) throw std::invalid_argument("element '" + kind_ + "': parameter " + name + " must be a number");
    return x();
  }
  boost::python::object object(const char * name) { return value(name); }

  // After the element is built: every given name was read.
  void check_all_read() const {
    const boost::python::list keys = values_.keys();
    std::string unread;
    for (boost::python::ssize_t i = 0; i < boost::python::len(keys); ++i) {
      const std::string key = boost::python::extract<std::string>(keys[i]);
      if (!read_.count(key)) unread += (unread.empty() ? "" : ", ") + key;
    }
    if (!unread.empty())
      throw std::invalid_argument("element '" + kind_ + "': its C++ twin does not read the parameter(s) " + unread);
  }

private:
  boost::python::object value(const char * name) {
    if (!values_.has_key(name)) throw std::invalid_argument("element '" + kind_ + "': missing parameter " + name);
    read_.insert(name);
    return values_[name];
  }
  std::string kind_;
  boost::python::dict values_;
  std::set<std::string> read_;
};

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
  Parameters parameters(kind, values);
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
