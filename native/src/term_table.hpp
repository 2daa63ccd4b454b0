// The built-in constraint terms by name: one table that the binding (Space.add_term) and the C++ OMPL baseline
// (benchmarks/ompl_native/problem.cpp) both build a space's constraint from. A term is its type and its fields,
// as manifoldgen.core_terms.constraint_terms writes them (Constraint.core_terms in Python); each caller reads the
// fields through its own accessor (a Python dict, a JSON object). A new built-in term: its Space::add_* (space.cpp),
// its rows (terms.cpp) and one entry here.
#pragma once

#include "core.hpp"

#include <stdexcept>
#include <string>
#include <vector>

namespace mgcore {

// Eigen values of a term's fields, whatever the accessor; each refuses a field of the wrong size.
inline Eigen::Vector3d vector3_of(const Vec& v, const char* field) {
  if (v.size() != 3) throw std::invalid_argument(std::string("constraint term field '") + field + "' needs 3 numbers");
  return v;
}

inline Eigen::Matrix3d rotation_of(const Vec& v, const char* field) {  // row-major 3 x 3
  if (v.size() != 9)
    throw std::invalid_argument(std::string("constraint term field '") + field + "' needs 9 numbers (row-major 3 x 3)");
  return Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(v.data());
}

// Add the built-in term ``kind`` with the fields ``f`` gives to ``space``. Fields: an accessor with
// integer(name), number(name), ints(name) (std::vector<int>), vector(name) (Vec) and rows(name) (RowMat).
template <class Fields>
void add_term(Space& space, const std::string& kind, const Fields& f) {
  if (kind == "pose") {
    space.add_pose(f.integer("frame_id"), rotation_of(f.vector("rotation"), "rotation"), f.ints("position_axes"),
                   f.ints("orientation_axes"), f.vector("y"));
  } else if (kind == "chain") {
    space.add_chain(f.integer("frame_a_id"), f.integer("frame_b_id"), rotation_of(f.vector("rotation"), "rotation"),
                    vector3_of(f.vector("offset"), "offset"));
  } else if (kind == "sphere") {
    space.add_sphere(f.integer("frame_id"), vector3_of(f.vector("center"), "center"), f.number("radius"));
  } else if (kind == "orientation") {
    const RowMat basis = f.rows("basis");
    if (basis.rows() != 2 || basis.cols() != 3) throw std::invalid_argument("orientation needs basis (2, 3)");
    space.add_orientation(f.integer("frame_id"), vector3_of(f.vector("axis"), "axis"), basis);
  } else if (kind == "linear") {
    space.add_linear(f.rows("A"), f.vector("y"));
  } else if (kind == "com_polygon") {
    space.add_com_polygon(f.rows("normals"), f.vector("bounds"));
  } else if (kind == "hemisphere") {
    space.add_hemisphere(f.integer("frame_id"), vector3_of(f.vector("axis"), "axis"),
                         vector3_of(f.vector("direction"), "direction"));
  } else {
    throw std::invalid_argument("unknown constraint term type '" + kind +
                                "' (built in: pose, chain, sphere, orientation, linear, com_polygon, hemisphere)");
  }
}

// A list of equal-length rows (a term's matrix field) as a row-major matrix.
inline RowMat rows_of(const std::vector<std::vector<double>>& rows, const char* field) {
  const Eigen::Index cols = rows.empty() ? 0 : static_cast<Eigen::Index>(rows[0].size());
  RowMat out(static_cast<Eigen::Index>(rows.size()), cols);
  for (std::size_t i = 0; i < rows.size(); ++i) {
    if (static_cast<Eigen::Index>(rows[i].size()) != cols)
      throw std::invalid_argument(std::string("constraint term field '") + field + "' has rows of unequal length");
    out.row(static_cast<Eigen::Index>(i)) = Eigen::Map<const Vec>(rows[i].data(), cols).transpose();
  }
  return out;
}

}  // namespace mgcore
