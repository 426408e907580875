// The C++ element registry: element kind → constructor from its Python parameters
// (Element.native_parameters()). One line per element; the Python registry is
// coopdyn/model/elements/__init__.py.
#pragma once

#include "ball_spring.hpp"
#include "se3_spring.hpp"

#include <boost/python.hpp>
#include <stdexcept>

namespace coopdyn {

namespace bp = boost::python;

inline Eigen::MatrixXd matrix_param(const bp::tuple & params, long i, Eigen::Index rows, Eigen::Index cols,
                                    const std::string & kind) {
  const Eigen::MatrixXd m = bp::extract<Eigen::MatrixXd>(params[i])();
  if (m.rows() != rows || m.cols() != cols)
    throw std::invalid_argument("element '" + kind + "': parameter " + std::to_string(i) + " must be " +
                                std::to_string(rows) + "x" + std::to_string(cols));
  return m;
}

inline std::unique_ptr<Element> make_element(const std::string & kind, const bp::tuple & params) {
  if (kind == "se3")
    return std::make_unique<SE3Spring>(matrix_param(params, 0, 6, 6, kind), matrix_param(params, 1, 6, 6, kind));
  if (kind == "ball")
    return std::make_unique<BallSpring>(matrix_param(params, 0, 3, 3, kind), matrix_param(params, 1, 3, 3, kind));
  throw std::invalid_argument("the kernel has no element '" + kind + "'");
}

// The kinds make_element knows (exposed as coopdyn._native.ELEMENTS).
inline bp::list element_kinds() {
  bp::list out;
  out.append("se3");
  out.append("ball");
  return out;
}

}  // namespace coopdyn
