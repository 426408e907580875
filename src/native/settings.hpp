// Reading a compiled component's settings: the dict that coopdyn/compiled.py writes from a
// component's compiled_spec(), read by field name, each read checked (a missing field or a
// vector of the wrong length is an invalid_argument naming the field).
#pragma once

#include "kernel.hpp"

#include <stdexcept>
#include <string>
#include <vector>

namespace coopdyn_native {

template <class T> T get(const bp::dict & cfg, const char * key) {
  if (!cfg.has_key(key)) throw std::invalid_argument(std::string("compiled loop: missing setting ") + key);
  return bp::extract<T>(cfg[key])();
}

// A vector setting of exactly n entries (n < 0: any).
inline VectorXd vec(const bp::dict & cfg, const char * key, Eigen::Index n) {
  const VectorXd x = get<VectorXd>(cfg, key);
  if (n >= 0 && x.size() != n)
    throw std::invalid_argument(std::string("compiled loop: setting ") + key + " has " + std::to_string(x.size()) +
                                " entries, expected " + std::to_string(n));
  return x;
}

inline MatrixXd mat3(const bp::dict & cfg, const char * key) {
  const MatrixXd x = get<MatrixXd>(cfg, key);
  if (x.rows() != 3 || x.cols() != 3) throw std::invalid_argument(std::string("compiled loop: setting ") + key + " must be 3x3");
  return x;
}

inline std::vector<double> doubles(bp::object seq) {
  std::vector<double> out;
  for (bp::ssize_t i = 0; i < bp::len(seq); ++i) out.push_back(bp::extract<double>(seq[i]));
  return out;
}

}  // namespace coopdyn_native
