// Reading a compiled component's settings: the dict that coopdyn/compiled.py writes from a
// component's typed spec (coopdyn/_spec.py), or an element's parameters
// (Element.native_parameters()), read by field name. Every read is checked (a missing field, one
// of the wrong type, a vector of the wrong length is an invalid_argument naming it), and every
// field given must be read: check_all_read() refuses a field the C++ side does not know, so the
// Python spec and its C++ reader cannot drift apart in silence.
#pragma once

#include <Eigen/Core>
#include <boost/python.hpp>

#include <set>
#include <stdexcept>
#include <string>
#include <vector>

namespace coopdyn_native {

namespace bp = boost::python;
using Eigen::MatrixXd;
using Eigen::VectorXd;

// The numbers of a Python sequence.
inline std::vector<double> to_doubles(bp::object seq) {
  std::vector<double> out;
  for (bp::ssize_t i = 0; i < bp::len(seq); ++i) out.push_back(bp::extract<double>(seq[i]));
  return out;
}

class Settings {
public:
  // `what` names the component in messages ("compiled loop", "controller 'gravity_pd'",
  // "element 'se3'"); `noun` what it calls a field ("setting", "parameter").
  Settings(std::string what, bp::dict values, std::string noun = "setting")
    : what_(std::move(what)), noun_(std::move(noun)), values_(std::move(values)) {}

  bool has(const char * key) const { return values_.has_key(key); }

  template <class T> T get(const char * key) {
    bp::extract<T> x(value(key));
    if (!x.check()) throw std::invalid_argument(what_ + ": " + noun_ + " " + key + " has the wrong type");
    return x();
  }

  // A vector setting of exactly n entries (n < 0: any).
  VectorXd vec(const char * key, Eigen::Index n) {
    const VectorXd x = get<VectorXd>(key);
    if (n >= 0 && x.size() != n)
      throw std::invalid_argument(what_ + ": " + noun_ + " " + key + " has " + std::to_string(x.size()) + " entries, expected " +
                                  std::to_string(n));
    return x;
  }

  MatrixXd mat3(const char * key) { return matrix(key, 3, 3); }

  // A rows x cols matrix.
  MatrixXd matrix(const char * key, Eigen::Index rows, Eigen::Index cols) {
    bp::extract<MatrixXd> x(value(key));
    if (!x.check()) throw std::invalid_argument(what_ + ": " + noun_ + " " + key + " must be a matrix of numbers");
    const MatrixXd m = x();
    if (m.rows() != rows || m.cols() != cols)
      throw std::invalid_argument(what_ + ": " + noun_ + " " + key + " must be " + std::to_string(rows) + "x" +
                                  std::to_string(cols));
    return m;
  }

  double number(const char * key) {
    bp::extract<double> x(value(key));
    if (!x.check()) throw std::invalid_argument(what_ + ": " + noun_ + " " + key + " must be a number");
    return x();
  }

  std::vector<double> doubles(const char * key) { return to_doubles(value(key)); }

  bp::object object(const char * key) { return value(key); }

  // A nested table, read by its own Settings (check it with its own check_all_read()).
  Settings sub(const char * key) { return Settings(what_ + ": " + key, get<bp::dict>(key), noun_); }

  // Every field given was read (after the component is built).
  void check_all_read() const {
    const bp::list keys = values_.keys();
    std::string unread;
    for (bp::ssize_t i = 0; i < bp::len(keys); ++i) {
      const std::string key = bp::extract<std::string>(keys[i]);
      if (!read_.count(key)) unread += (unread.empty() ? "" : ", ") + key;
    }
    if (!unread.empty())
      throw std::invalid_argument(what_ + ": the kernel does not read the " + noun_ + "(s) " + unread +
                                  " (the Python spec and its C++ reader disagree)");
  }

private:
  bp::object value(const char * key) {
    if (!values_.has_key(key)) throw std::invalid_argument(what_ + ": missing " + noun_ + " " + key);
    read_.insert(key);
    return values_[key];
  }
  std::string what_, noun_;
  bp::dict values_;
  std::set<std::string> read_;
};

}  // namespace coopdyn_native
