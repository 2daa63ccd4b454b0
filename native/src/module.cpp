// Python bindings of the compiled core (nanobind): batch-first numpy arrays in and out.
// manifoldgen/native.py builds a Space from a ConstrainedSpace; keep this API additive.
#include "core.hpp"

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/pair.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/vector.h>

namespace nb = nanobind;
using namespace nb::literals;
using mgcore::RowMat;
using mgcore::Space;
using mgcore::Vec;

namespace {

using In2 = nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using In1 = nb::ndarray<const double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;

// A new numpy array owning its data.
template <typename T>
nb::ndarray<nb::numpy, T> owned(std::vector<T>&& data, std::initializer_list<std::size_t> shape) {
  auto* store = new std::vector<T>(std::move(data));
  nb::capsule owner(store, [](void* p) noexcept { delete static_cast<std::vector<T>*>(p); });
  return nb::ndarray<nb::numpy, T>(store->data(), shape.size(), shape.begin(), owner);
}

Vec vec_of(const In1& a) { return Eigen::Map<const Vec>(a.data(), static_cast<long>(a.shape(0))); }

void check_cols(const In2& q, const Space& s) {
  if (static_cast<int>(q.shape(1)) != s.n())
    throw nb::value_error(("configurations must have " + std::to_string(s.n()) + " columns").c_str());
}

nb::dict counts_of(const Space& s) {
  nb::dict d, stopped;
  static const char* reasons[4] = {"limits", "constraint", "inequality", "collision"};
  for (int r = 0; r < 4; ++r) stopped[reasons[r]] = s.counts.stopped[r + 1];
  d["evaluations"] = s.counts.evaluations;
  d["jacobians"] = s.counts.jacobians;
  d["projection_steps"] = s.counts.projection_steps;
  d["collision_checks"] = s.counts.collision_checks;
  d["sphere_checks"] = s.counts.sphere_checks;
  d["stopped"] = stopped;
  return d;
}

}  // namespace

NB_MODULE(manifoldgen_core, m) {
  m.doc() = "manifoldgen's compiled planning core (pinocchio + coal): constrained space and RRT-Connect";

  nb::class_<Space>(m, "Space")
      .def(
          "__init__",
          [](Space* self, const std::string& model_file, const std::string& geometry_file, const In1& reference,
             const std::vector<std::tuple<int, int, int>>& active, const In1& lower, const In1& upper, double margin,
             double resolution) {
            std::vector<mgcore::Active> a;
            for (const auto& [q, v, nq] : active) a.push_back({q, v, nq});
            new (self) Space(model_file, geometry_file, vec_of(reference), a, vec_of(lower), vec_of(upper), margin,
                             resolution);
          },
          "model_file"_a, "geometry_file"_a, "reference"_a, "active"_a, "lower"_a, "upper"_a, "margin"_a,
          "resolution"_a,
          "A constrained space from pinocchio binary serializations of the model and the collision model; "
          "active: (idx_q, idx_v, nq) per coordinate.")
      .def(
          "add_pose",
          [](Space& s, int frame, const In2& rotation, const std::vector<int>& position_axes,
             const std::vector<int>& orientation_axes, const In1& y) {
            Eigen::Matrix3d R;
            for (int i = 0; i < 3; ++i)
              for (int j = 0; j < 3; ++j) R(i, j) = rotation(i, j);
            s.add_pose(frame, R, position_axes, orientation_axes, vec_of(y));
          },
          "frame"_a, "rotation"_a, "position_axes"_a, "orientation_axes"_a, "y"_a,
          "F = [p[position_axes] - y; log3(rotation^T R)[orientation_axes]] of frame.")
      .def(
          "add_chain",
          [](Space& s, int frame_a, int frame_b, const In2& rotation, const In1& offset) {
            Eigen::Matrix3d R;
            for (int i = 0; i < 3; ++i)
              for (int j = 0; j < 3; ++j) R(i, j) = rotation(i, j);
            s.add_chain(frame_a, frame_b, R, Eigen::Vector3d(offset(0), offset(1), offset(2)));
          },
          "frame_a"_a, "frame_b"_a, "rotation"_a, "offset"_a,
          "F = [Ra^T (pb - pa) - offset; log3(rotation^T Ra^T Rb)].")
      .def(
          "add_sphere",
          [](Space& s, int frame, const In1& center, double radius) {
            s.add_sphere(frame, Eigen::Vector3d(center(0), center(1), center(2)), radius);
          },
          "frame"_a, "center"_a, "radius"_a, "F = |p - center| - radius of frame.")
      .def("set_tolerance", [](Space& s, const In1& t) { s.set_tolerance(vec_of(t)); }, "tolerance"_a)
      .def(
          "set_spheres",
          [](Space& s, const std::vector<int>& joint, const In2& center, const In1& radius,
             const std::vector<int>& geometry, const std::vector<std::pair<int, int>>& exact) {
            if (center.shape(1) != 3) throw nb::value_error("sphere centers must be (S, 3)");
            RowMat c = Eigen::Map<const RowMat>(center.data(), static_cast<long>(center.shape(0)), 3);
            s.set_spheres(joint, c, vec_of(radius), geometry, exact);
          },
          "joint"_a, "center"_a, "radius"_a, "geometry"_a, "exact"_a = std::vector<std::pair<int, int>>(),
          "Conservative sphere models: every collision check tests them first and runs coal only where they touch.")
      .def("clear_spheres", &Space::clear_spheres)
      .def_prop_ro("has_spheres", &Space::has_spheres)
      .def("sphere_report", &Space::sphere_report)
      .def_prop_ro("n", &Space::n)
      .def_prop_ro("m", &Space::m)
      .def_prop_ro("stop", [](const Space& s) { return s.stop; }, "reason of the latest motion check (0: passed)")
      .def("counts", &counts_of, "the operation counters")
      .def(
          "residual",
          [](Space& s, const In2& q) {
            check_cols(q, s);
            const std::size_t B = q.shape(0), mm = s.m();
            std::vector<double> F(B * mm);
            for (std::size_t b = 0; b < B; ++b) s.residual(q.data() + b * s.n(), F.data() + b * mm);
            return owned(std::move(F), {B, mm});
          },
          "q"_a, "(B, m) residuals of q (B, n).")
      .def(
          "jacobian",
          [](Space& s, const In2& q) {
            check_cols(q, s);
            const std::size_t B = q.shape(0), mm = s.m(), nn = s.n();
            std::vector<double> F(B * mm), J(B * mm * nn);
            for (std::size_t b = 0; b < B; ++b) s.jacobian(q.data() + b * nn, F.data() + b * mm, J.data() + b * mm * nn);
            return nb::make_tuple(owned(std::move(F), {B, mm}), owned(std::move(J), {B, mm, nn}));
          },
          "q"_a, "(F (B, m), J (B, m, n)) of q (B, n).")
      .def(
          "violation",
          [](Space& s, const In2& q) {
            check_cols(q, s);
            const std::size_t B = q.shape(0);
            std::vector<double> v(B);
            for (std::size_t b = 0; b < B; ++b) v[b] = s.violation(q.data() + b * s.n());
            return owned(std::move(v), {B});
          },
          "q"_a, "(B,) max |F_i| / tol_i.")
      .def(
          "codes",
          [](Space& s, const In2& q, const In1& limit, bool collision, bool exact) {
            check_cols(q, s);
            const std::size_t B = q.shape(0);
            if (limit.shape(0) != B) throw nb::value_error("limit must have one value per configuration");
            std::vector<int8_t> c(B);
            for (std::size_t b = 0; b < B; ++b) c[b] = static_cast<int8_t>(s.code(q.data() + b * s.n(), limit(b), collision, exact));
            return owned(std::move(c), {B});
          },
          "q"_a, "limit"_a, "collision"_a = true, "exact"_a = true,
          "(B,) first failed test per row (0 valid, 1 limits, 2 constraint, 3 inequality, 4 collision), evaluated lazily.")
      .def(
          "valid_prefix",
          [](Space& s, const In2& states, bool last_is_node) {
            check_cols(states, s);
            return s.valid_prefix(states.data(), static_cast<int>(states.shape(0)), last_is_node);
          },
          "states"_a, "last_is_node"_a, "Leading valid rows of a motion's states (k, n); sets stop.")
      .def(
          "project",
          [](Space& s, const In2& q, double tol, int max_iters, double damping, double max_step) {
            check_cols(q, s);
            const std::size_t B = q.shape(0), nn = s.n();
            std::vector<double> x(q.data(), q.data() + B * nn), res(B);
            std::vector<bool> conv(B);
            std::vector<int64_t> it(B);
            std::vector<uint8_t> ok(B);
            for (std::size_t b = 0; b < B; ++b) {
              const mgcore::Projection p = s.project(x.data() + b * nn, tol, max_iters, damping, max_step);
              ok[b] = p.converged;
              it[b] = p.iterations;
              res[b] = p.residual;
            }
            return nb::make_tuple(owned(std::move(x), {B, nn}), owned(std::move(ok), {B}), owned(std::move(it), {B}),
                                  owned(std::move(res), {B}));
          },
          "q"_a, "tol"_a = 1e-6, "max_iters"_a = 50, "damping"_a = 1e-6, "max_step"_a = 0.5,
          "Levenberg-Marquardt projection of q (B, n): (q, converged (uint8), iterations, residual).")
      .def(
          "validate_path",
          [](Space& s, const In2& path) {
            check_cols(path, s);
            const mgcore::PathCheck c = s.validate_path(path.data(), static_cast<int>(path.shape(0)));
            return nb::make_tuple(c.valid, c.worst, c.first_invalid, c.reason, c.segment, c.states);
          },
          "path"_a, "Dense check of path (K, n): (valid, worst, first invalid state, reason, segment, states).");

  m.def(
      "rrt_connect",
      [](Space& space, const In1& start, const In1& goal, nb::callable draw, double time_limit, double range,
         double resolution, double step, bool partial, int pool, int pool_batch, int candidates,
         const std::string& local, int target_batch, bool lazy, int refine) {
        mgcore::PlannerSettings st;
        st.range = range, st.resolution = resolution, st.step = step, st.partial = partial, st.pool = pool;
        st.pool_batch = pool_batch, st.candidates = candidates, st.local = local, st.target_batch = target_batch;
        st.lazy = lazy;
        st.refine = refine;
        const int nn = space.n();
        mgcore::Draw fetch = [&](int count) {
          nb::object rows = draw(count);
          auto a = nb::cast<nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>>(rows);
          if (static_cast<int>(a.shape(1)) != nn) throw std::runtime_error("sampler rows have the wrong width");
          return RowMat(Eigen::Map<const RowMat>(a.data(), static_cast<long>(a.shape(0)), nn));
        };
        const mgcore::PlanOutput out = mgcore::rrt_connect(space, vec_of(start), vec_of(goal), fetch, st, time_limit);
        std::vector<double> path(out.path.data(), out.path.data() + out.path.size());
        nb::dict d;
        d["path"] = owned(std::move(path), {static_cast<std::size_t>(out.path.rows()), static_cast<std::size_t>(nn)});
        d["iterations"] = out.iterations;
        d["samples"] = out.samples;
        d["rejected_paths"] = out.rejected;
        d["out_of_reach"] = out.out_of_reach;
        d["projections"] = out.projections;
        d["cut_edges"] = out.cut_edges;
        d["refined"] = out.refined;
        d["accepted"] = out.accepted;
        d["nodes"] = out.nodes;
        return d;
      },
      "space"_a, "start"_a, "goal"_a, "draw"_a, "time_limit"_a, "range"_a, "resolution"_a, "step"_a, "partial"_a,
      "pool"_a, "pool_batch"_a, "candidates"_a, "local"_a, "target_batch"_a, "lazy"_a = false, "refine"_a = -1,
      "RRT-Connect from start to goal (n,) in space; draw(count) -> (count, n) valid samples. A dict: path (K, n) "
      "(0 rows: unsolved), iterations, samples, rejected_paths, out_of_reach, projections, cut_edges, nodes. "
      "lazy: tree edges are checked for collision only on candidate paths. refine >= 0: draw gives raw candidates, "
      "each refined (refine projection iterations) and checked when the search first uses it (counts: refined, "
      "accepted).");
}
