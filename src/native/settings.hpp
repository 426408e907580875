// Reading a compiled component's settings: the dict that coopdyn/compiled.py writes from a
// component's compiled_spec(), read by field name. Every read is checked (a missing field or a
// vector of the wrong length is an invalid_argument naming it), and every field given must be
// read: check_all_read() refuses a field the C++ side does not know, so the Python spec and its
// C++ reader cannot drift apart in silence.
#pragma once

#include "kernel.hpp"

#include <set>
#include <stdexcept>
#include <string>
#include <vector>

namespace coopdyn_native {

// The numbers of a Python sequence.
inline std::vector<double> to_doubles(bp::object seq) {
  std::vector<double> out;
  for (bp::ssize_t i = 0; i < bp::len(seq); ++i) out.push_back(bp::extract<double>(seq[i]));
  return out;
}

class Settings {
public:
  // `what` names the component in messages ("compiled loop", "controller 'gravity_pd'").
  Settings(std::string what, bp::dict values) : what_(std::move(what)), values_(std::move(values)) {}

  bool has(const char * key) const { return values_.has_key(key); }

  template <class T> T get(const char * key) {
    bp::extract<T> x(value(key));
    if (!x.check()) throw std::invalid_argument(what_ + ": setting " + key + " has the wrong type");
    return x();
  }

  // A vector setting of exactly n entries (n < 0: any).
  VectorXd vec(const char * key, Eigen::Index n) {
    const VectorXd x = get<VectorXd>(key);
    if (n >= 0 && x.size() != n)
      throw std::invalid_argument(what_ + ": setting " + key + " has " + std::to_string(x.size()) + " entries, expected " +
                                  std::to_string(n));
    return x;
  }

  MatrixXd mat3(const char * key) {
    const MatrixXd x = get<MatrixXd>(key);
    if (x.rows() != 3 || x.cols() != 3) throw std::invalid_argument(what_ + ": setting " + key + " must be 3x3");
    return x;
  }

  std::vector<double> doubles(const char * key) { return to_doubles(value(key)); }

  bp::object object(const char * key) { return value(key); }

  // A nested table, read by its own Settings (check it with its own check_all_read()).
  Settings sub(const char * key) { return Settings(what_ + ": " + key, get<bp::dict>(key)); }

  // Every field given was read (after the component is built).
  void check_all_read() const {
    const bp::list keys = values_.keys();
    std::string unread;
    for (bp::ssize_t i = 0; i < bp::len(keys); ++i) {
      const std::string key = bp::extract<std::string>(keys[i]);
      if (!read_.count(key)) unread += (unread.empty() ? "" : ", ") + key;
    }
    if (!unread.empty())
      throw std::invalid_argument(what_ + ": the kernel does not read the setting(s) " + unread +
                                  " (the Python spec and its C++ reader disagree)");
  }

private:
  bp::object value(const char * key) {
    if (!values_.has_key(key)) throw std::invalid_argument(what_ + ": missing setting " + key);
    read_.insert(key);
    return values_[key];
  }
  std::string what_;
  bp::dict values_;
  std::set<std::string> read_;
};

}  // namespace coopdyn_native
