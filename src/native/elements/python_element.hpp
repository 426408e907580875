// An element without a C++ twin, evaluated in Python from the kernel: the scene's other elements,
// its dynamics and the compiled loop stay in C++, and each evaluation of this element calls its
// Python `evaluate` (coopdyn/model/elements/base.py), taking the GIL for the call (the compiled
// loop runs without it). coopdyn/dynamics/native.py passes {"element": the Python element,
// "evaluate": a wrapper that returns its evaluation (and its tangent, matrix_tangent), or None
// after keeping what it raised — a Ctrl-C too — for Python to re-raise once the kernel has
// returned}.
#pragma once

#include "element.hpp"

#include <Python.h>

#include <stdexcept>
#include <string>

namespace coopdyn {

class PythonElement : public Element {
public:
  PythonElement(boost::python::object element, boost::python::object evaluate)
    : element_(std::move(element)), evaluate_(std::move(evaluate)),
      damped_(boost::python::extract<bool>(element_.attr("has_damping"))()),
      size_(boost::python::extract<int>(element_.attr("deformation_size"))()) {
    if (size_ < 0 || size_ > 6) throw std::invalid_argument("a Python element's deformation_size must be 0 to 6");
  }

  static std::unique_ptr<Element> make(Parameters & p) {
    return std::make_unique<PythonElement>(p.object("element"), p.object("evaluate"));
  }

  bool damped() const override { return damped_; }

  void evaluate(const pinocchio::SE3 & T_M_G, const Vector6 & xi, bool jacobians, ElementEval & out) const override {
    namespace bp = boost::python;
    const struct Gil {  // taken for the call, given back on every way out
      PyGILState_STATE state = PyGILState_Ensure();
      ~Gil() { PyGILState_Release(state); }
    } gil;
    try {
      const bp::object ev = evaluate_(T_M_G, Eigen::VectorXd(xi), jacobians);
      if (ev.is_none()) throw std::runtime_error("the Python element " + describe() + " raised (re-raised by Python)");
      out.energy = bp::extract<double>(ev[0]);
      const Eigen::VectorXd deformation = bp::extract<Eigen::VectorXd>(ev[1]);
      if (deformation.size() != size_) throw std::invalid_argument("evaluate returned a deformation of the wrong size");
      out.deformation.setZero();
      out.deformation.head(size_) = deformation;
      const Eigen::VectorXd f = bp::extract<Eigen::VectorXd>(ev[2]);
      if (f.size() != 6) throw std::invalid_argument("evaluate returned a G_f_G that is not 6 values");
      out.f = f;
      out.power = bp::extract<double>(ev[3]);
      if (jacobians) {
        out.SK = matrix6(ev[4], "evaluate returned an S_K");
        const bp::object S_D = ev[5];
        out.SD = S_D.is_none() ? Matrix6::Zero().eval() : matrix6(S_D, "evaluate returned an S_D");
      }
      out.theta = bp::extract<double>(ev[6]);
    } catch (const bp::error_already_set &) {
      throw std::runtime_error("the Python element " + describe() + " raised " + fetch_error());
    } catch (const std::invalid_argument & e) {
      throw std::runtime_error("the Python element " + describe() + ": " + e.what());
    }
  }

  // Its Python tangent (its own, or base.py's central differences) and its exact_tangent; what it
  // raises is kept for Python, as evaluate's.
  bool tangent(const pinocchio::SE3 & T_M_G, const Vector6 & xi, Matrix6 & F_d, Matrix6 & F_x) const override {
    return derivative_pair("tangent", "exact_tangent", F_d, F_x, T_M_G, Eigen::VectorXd(xi));
  }

  // Its Python matrix_tangent (its own, or base.py's central differences) and whether that is
  // exact; what it raises is kept for Python, as evaluate's.
  bool matrix_tangent(const pinocchio::SE3 & T_M_G, const Vector6 & xi, const Vector6 & w_K, const Vector6 & w_D,
                      Matrix6 & G_d, Matrix6 & G_x) const override {
    return derivative_pair("matrix_tangent", "exact_matrix_tangent", G_d, G_x, T_M_G, Eigen::VectorXd(xi),
                           Eigen::VectorXd(w_K), Eigen::VectorXd(w_D));
  }

private:
  // The callback's `method` (what the element's own raises is kept: None comes back) with `args`:
  // its two 6x6 derivatives (with respect to the pose, to the twist) and the element's `exact`.
  template <class... Args>
  bool derivative_pair(const char * method, const char * exact, Matrix6 & pose, Matrix6 & twist, const Args &... args) const {
    namespace bp = boost::python;
    const struct Gil {
      PyGILState_STATE state = PyGILState_Ensure();
      ~Gil() { PyGILState_Release(state); }
    } gil;
    const std::string what = "the Python element " + describe() + "'s " + method;
    try {
      const bp::object out = evaluate_.attr(method)(args...);
      if (out.is_none()) throw std::runtime_error(what + " raised (re-raised by Python)");
      pose = matrix6(out[0], (std::string(method) + " returned a derivative with respect to the pose").c_str());
      twist = matrix6(out[1], (std::string(method) + " returned a derivative with respect to the twist").c_str());
      return bp::extract<bool>(element_.attr(exact))();
    } catch (const bp::error_already_set &) {
      throw std::runtime_error(what + " raised " + fetch_error());
    } catch (const std::invalid_argument & e) {
      throw std::runtime_error(what + ": " + e.what());
    }
  }

  static Matrix6 matrix6(const boost::python::object & value, const char * name) {
    const Eigen::MatrixXd m = boost::python::extract<Eigen::MatrixXd>(value);
    if (m.rows() != 6 || m.cols() != 6) throw std::invalid_argument(std::string(name) + " that is not 6x6");
    return m;
  }
  std::string describe() const {
    return boost::python::extract<std::string>(boost::python::str(element_.attr("__class__").attr("__name__")))();
  }
  // The pending Python exception as "Type: message", cleared.
  static std::string fetch_error() {
    PyObject *type = nullptr, *value = nullptr, *trace = nullptr;
    PyErr_Fetch(&type, &value, &trace);
    PyErr_NormalizeException(&type, &value, &trace);
    std::string text = "an exception";
    if (type && value) {
      PyObject * name = PyObject_GetAttrString(type, "__name__");
      PyObject * message = PyObject_Str(value);
      if (name && message) text = std::string(PyUnicode_AsUTF8(name)) + ": " + PyUnicode_AsUTF8(message);
      Py_XDECREF(name);
      Py_XDECREF(message);
    }
    Py_XDECREF(type);
    Py_XDECREF(value);
    Py_XDECREF(trace);
    return text;
  }

  boost::python::object element_, evaluate_;
  bool damped_;
  int size_;
};

inline const bool python_registered = register_element("python", &PythonElement::make);

}  // namespace coopdyn
