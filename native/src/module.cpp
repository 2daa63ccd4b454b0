// Python bindings of the compiled core (nanobind): batch-first numpy arrays in and out.
// manifoldgen/native.py builds a Space from a ConstrainedSpace (its constraint: manifoldgen/core_terms.py).
#include "core.hpp"

#include <pinocchio/config.hpp>

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

// A new numpy array (rows, cols) holding a copy of the row-major Eigen matrix a.
template <typename M>
nb::ndarray<nb::numpy, typename M::Scalar> array_of(const M& a) {
  return owned(std::vector<typename M::Scalar>(a.data(), a.data() + a.size()),
               {static_cast<std::size_t>(a.rows()), static_cast<std::size_t>(a.cols())});
}

Vec vec_of(const In1& a) { return Eigen::Map<const Vec>(a.data(), static_cast<long>(a.shape(0))); }

// A constraint term's fields from a Python dict (Space::add_term).
struct DictFields final : mgcore::TermFields {
  const nb::dict& fields;
  explicit DictFields(const nb::dict& fields) : fields(fields) {}
  nb::handle at(const char* name) const {
    if (!fields.contains(name))
      throw std::invalid_argument(std::string("constraint term lacks its field '") + name + "'");
    return fields[name];
  }
  int integer(const char* name) const override { return nb::cast<int>(at(name)); }
  double number(const char* name) const override { return nb::cast<double>(at(name)); }
  std::vector<int> ints(const char* name) const override { return nb::cast<std::vector<int>>(at(name)); }
  Vec vector(const char* name) const override {
    const auto v = nb::cast<std::vector<double>>(at(name));
    return Eigen::Map<const Vec>(v.data(), static_cast<long>(v.size()));
  }
  RowMat rows(const char* name) const override {
    const auto rows = nb::cast<std::vector<std::vector<double>>>(at(name));
    const Eigen::Index cols = rows.empty() ? 0 : static_cast<Eigen::Index>(rows[0].size());
    RowMat out(static_cast<Eigen::Index>(rows.size()), cols);
    for (std::size_t i = 0; i < rows.size(); ++i) {
      if (static_cast<Eigen::Index>(rows[i].size()) != cols)
        throw std::invalid_argument(std::string("constraint term field '") + name + "' has rows of unequal length");
      out.row(static_cast<Eigen::Index>(i)) = Eigen::Map<const Vec>(rows[i].data(), cols).transpose();
    }
    return out;
  }
};

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
  d["sweep_checks"] = s.counts.sweep_checks;
  d["hull_tests"] = s.counts.hull_tests;
  d["mesh_tests"] = s.counts.mesh_tests;
  d["callback_calls"] = s.counts.callback_calls;
  d["callback_rows"] = s.counts.callback_rows;
  d["stopped"] = stopped;
  return d;
}

// A (B, cols) float64 C-contiguous array returned by a Python callback, checked and copied into out.
void take(const nb::handle& value, std::size_t B, std::size_t cols, std::size_t depth, double* out, const char* what) {
  auto a = nb::cast<nb::ndarray<const double, nb::c_contig, nb::device::cpu>>(value);
  const bool ok = depth == 2 ? a.ndim() == 2 && a.shape(0) == B && a.shape(1) == cols
                             : a.ndim() == 3 && a.shape(0) == B && a.shape(1) * a.shape(2) == cols;
  if (!ok) throw std::runtime_error(std::string("the constraint callback returned ") + what + " of the wrong shape");
  std::copy_n(a.data(), B * cols, out);
}

// q (B, n) as a numpy array of its own (the callback may keep it).
nb::object rows_of(const double* q, long B, int n) {
  std::vector<double> copy(q, q + B * n);
  return nb::cast(owned(std::move(copy), {static_cast<std::size_t>(B), static_cast<std::size_t>(n)}));
}

// Python constraint callbacks (Space::add_callback, set_inequalities): residuals(q (B, n), jacobian: bool)
// -> F (B, rows) or (F, J (B, rows, n)); inequalities(q (B, n)) -> G (B, p). Called with the GIL held
// (the core never releases it).
void add_callback(Space& s, int rows, nb::callable fn) {
  const int n = s.n();
  s.add_callback(rows, [fn, rows, n](const double* q, long B, double* F, double* J) {
    nb::object out = fn(rows_of(q, B, n), J != nullptr);
    if (!J) return take(out, B, rows, 2, F, "residuals");
    nb::tuple pair = nb::cast<nb::tuple>(out);
    if (pair.size() != 2) throw std::runtime_error("the constraint callback must return (F, J) when asked for J");
    take(pair[0], B, rows, 2, F, "residuals");
    take(pair[1], B, static_cast<std::size_t>(rows) * n, 3, J, "a Jacobian");
  });
}

// A compiled expression from Python's lowering (manifoldgen/core_terms.py): code as (Op, a, b) rows, constants,
// frame ids by slot, output registers.
mgcore::Expression expression_of(const Space& s, const std::vector<std::tuple<mgcore::Op, int, int>>& code,
                                 const std::vector<double>& constants, const std::vector<int>& frames,
                                 const std::vector<int>& outputs) {
  std::vector<mgcore::Instruction> program;
  program.reserve(code.size());
  for (const auto& [op, a, b] : code) program.push_back({op, a, b});
  try {
    return mgcore::Expression(std::move(program), constants, frames, outputs, s.n());
  } catch (const std::invalid_argument& e) {
    throw nb::value_error(e.what());
  }
}

void set_inequalities(Space& s, int p, nb::callable fn) {
  const int n = s.n();
  s.set_inequalities(p, [fn, p, n](const double* q, long B, double* G) {
    take(fn(rows_of(q, B, n)), B, p, 2, G, "inequalities");
  });
}

}  // namespace

NB_MODULE(manifoldgen_core, m) {
  m.doc() = "manifoldgen's compiled planning core (pinocchio + coal): constrained space and RRT-Connect";
  // the pinocchio whose headers this module was compiled with: manifoldgen.core_extension refuses the module when
  // the installed pinocchio differs (its libraries would not match the inline code compiled in here)
  m.attr("PINOCCHIO_VERSION") = PINOCCHIO_VERSION;
  // the built-in constraint term types Space.add_term builds (native/src/builtin_terms.cpp)
  m.attr("BUILT_IN_TERMS") = nb::cast(Space::built_in_terms());

  // the operations of compiled expressions (core.hpp), the one definition of their codes
  nb::enum_<mgcore::Op>(m, "Op", "Operations of a compiled expression (register i: instruction i's result)")
      .value("Q", mgcore::Op::Q, "q[a]")
      .value("CONST", mgcore::Op::CONST, "constants[a]")
      .value("POS", mgcore::Op::POS, "frame slot a's world position [b]")
      .value("ROT", mgcore::Op::ROT, "frame slot a's world rotation (b // 3, b % 3)")
      .value("COM", mgcore::Op::COM, "the centre of mass [b]")
      .value("NEG", mgcore::Op::NEG)
      .value("SQRT", mgcore::Op::SQRT)
      .value("SIN", mgcore::Op::SIN)
      .value("COS", mgcore::Op::COS)
      .value("TAN", mgcore::Op::TAN)
      .value("ASIN", mgcore::Op::ASIN)
      .value("ACOS", mgcore::Op::ACOS)
      .value("ATAN", mgcore::Op::ATAN)
      .value("EXP", mgcore::Op::EXP)
      .value("LOG", mgcore::Op::LOG)
      .value("ABS", mgcore::Op::ABS)
      .value("TANH", mgcore::Op::TANH)
      .value("ADD", mgcore::Op::ADD)
      .value("SUB", mgcore::Op::SUB)
      .value("MUL", mgcore::Op::MUL)
      .value("DIV", mgcore::Op::DIV)
      .value("POW", mgcore::Op::POW)
      .value("ATAN2", mgcore::Op::ATAN2, "atan2(a, b)")
      .value("MAX", mgcore::Op::MAX)
      .value("MIN", mgcore::Op::MIN);

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
          "active: (idx_q, idx_v, nq) per joint (nq 7: the free flyer, first, six coordinates x y z yaw pitch roll).")
      .def(
          "add_term",
          [](Space& s, const std::string& kind, const nb::dict& fields) { s.add_term(kind, DictFields(fields)); },
          "kind"_a, "fields"_a,
          "Add the built-in constraint term kind (BUILT_IN_TERMS) with its fields as "
          "manifoldgen.core_terms.constraint_terms writes them (native/src/builtin_terms.cpp).")
      .def_prop_ro("g", &Space::g, "built-in inequality rows (CoM polygon, hemisphere)")
      .def(
          "inequality",
          [](Space& s, const In2& q) {
            check_cols(q, s);
            const std::size_t B = q.shape(0), gg = s.g();
            std::vector<double> G(B * gg);
            for (std::size_t b = 0; b < B; ++b) s.inequality(q.data() + b * s.n(), G.data() + b * gg);
            return owned(std::move(G), {B, gg});
          },
          "q"_a, "(B, g) built-in inequality values of q (B, n) (<= 0: holds).")
      .def(
          "add_expression",
          [](Space& s, const std::vector<std::tuple<mgcore::Op, int, int>>& code, const std::vector<double>& constants,
             const std::vector<int>& frames, const std::vector<int>& outputs) {
            s.add_expression(expression_of(s, code, constants, frames, outputs));
          },
          "code"_a, "constants"_a, "frames"_a, "outputs"_a,
          "A compiled residual: code [(Op, a, b)] (register i: instruction i's result), constants, pinocchio frame ids "
          "by slot, the output registers (its rows); evaluated per configuration with forward-mode derivatives.")
      .def(
          "add_expression_inequality",
          [](Space& s, const std::vector<std::tuple<mgcore::Op, int, int>>& code, const std::vector<double>& constants,
             const std::vector<int>& frames, const std::vector<int>& outputs) {
            s.add_expression_inequality(expression_of(s, code, constants, frames, outputs));
          },
          "code"_a, "constants"_a, "frames"_a, "outputs"_a, "Compiled inequalities G <= 0 (as add_expression).")
      .def("add_callback", &add_callback, "rows"_a, "residuals"_a,
           "A term of `rows` residual components from Python: residuals(q (B, n), jacobian) -> F (B, rows), or "
           "(F, J (B, rows, n)) when jacobian is True; called on batches of configurations.")
      .def("set_inequalities", &set_inequalities, "p"_a, "inequalities"_a,
           "G(q) <= 0 from Python: inequalities(q (B, n)) -> G (B, p), called on batches.")
      .def_prop_ro("p", &Space::p, "inequality components from Python (set_inequalities)")
      .def_prop_ro("batched", &Space::batched, "Python callbacks take part (configurations evaluated in batches)")
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
      .def("set_sweeps", &Space::set_sweeps, "on"_a,
           "Certified sweeps in validate_path (on by default; used only with sphere models): the same reports, "
           "fewer collision checks.")
      .def_prop_ro("sweeps", &Space::sweeps, "validate_path uses certified sweeps")
      .def("prepare", &Space::prepare,
           "Build now what the first certified path check would (the constraint's rate bounds): call it once the "
           "terms are added, so that no query pays for it.")
      .def("sweep_report", &Space::sweep_report, "why certified sweeps are unavailable ('' when they are)")
      .def(
          "sweep_free",
          [](Space& s, const In2& states) {
            check_cols(states, s);
            return s.sweep_free(states.data(), static_cast<int>(states.shape(0)));
          },
          "states"_a, "One sweep test of states (k, n) as consecutive path states: True when the polyline through "
          "them is certified collision-free.")
      .def(
          "sweep_bounds",
          [](Space& s, const In2& states, int common, bool rates) {
            check_cols(states, s);
            std::vector<double> b = s.sweep_bounds(states.data(), static_cast<int>(states.shape(0)), common, rates);
            const std::size_t S = b.size();
            return owned(std::move(b), {S});
          },
          "states"_a, "common"_a = -1, "rates"_a = false,
          "(S,) bounds on each sphere centre's motion from the middle state (k // 2) along states (k, n); common >= 0: "
          "relative to the frame of its joint's support at that depth (NaN where the chain is shorter); rates: the "
          "rate bound over every coordinate.")
      .def(
          "sphere_centers",
          [](Space& s, const In1& q) {
            if (static_cast<int>(q.shape(0)) != s.n()) throw nb::value_error("q must have n entries");
            return array_of(s.sphere_centers(q.data()));
          },
          "q"_a, "(S, 3) world centres of the spheres at q (n,).")
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
            s.residuals(q.data(), static_cast<long>(B), F.data());
            return owned(std::move(F), {B, mm});
          },
          "q"_a, "(B, m) residuals of q (B, n).")
      .def(
          "jacobian",
          [](Space& s, const In2& q) {
            check_cols(q, s);
            const std::size_t B = q.shape(0), mm = s.m(), nn = s.n();
            std::vector<double> F(B * mm), J(B * mm * nn);
            s.jacobians(q.data(), static_cast<long>(B), F.data(), J.data());
            return nb::make_tuple(owned(std::move(F), {B, mm}), owned(std::move(J), {B, mm, nn}));
          },
          "q"_a, "(F (B, m), J (B, m, n)) of q (B, n).")
      .def(
          "violation",
          [](Space& s, const In2& q) {
            check_cols(q, s);
            const std::size_t B = q.shape(0);
            std::vector<double> v(B);
            s.violations(q.data(), static_cast<long>(B), v.data());
            return owned(std::move(v), {B});
          },
          "q"_a, "(B,) max |F_i| / tol_i.")
      .def(
          "codes",
          [](Space& s, const In2& q, const In1& limit, bool collision, bool exact) {
            check_cols(q, s);
            const std::size_t B = q.shape(0);
            if (limit.shape(0) != B) throw nb::value_error("limit must have one value per configuration");
            std::vector<int> codes(B);
            s.codes(q.data(), static_cast<long>(B), limit.data(), collision, exact, codes.data());
            std::vector<int8_t> c(codes.begin(), codes.end());
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
                        std::vector<int64_t> it(B);
            std::vector<uint8_t> ok(B);
            std::vector<mgcore::Projection> out(B);
            s.project_many(x.data(), static_cast<long>(B), tol, max_iters, damping, max_step, out.data());
            for (std::size_t b = 0; b < B; ++b) {
              ok[b] = out[b].converged;
              it[b] = out[b].iterations;
              res[b] = out[b].residual;
            }
            return nb::make_tuple(owned(std::move(x), {B, nn}), owned(std::move(ok), {B}), owned(std::move(it), {B}),
                                  owned(std::move(res), {B}));
          },
          "q"_a, "tol"_a = 1e-6, "max_iters"_a = 50, "damping"_a = 1e-6, "max_step"_a = 0.5,
          "Levenberg-Marquardt projection of q (B, n): (q, converged (uint8), iterations, residual).")
      .def(
          "validate_path",
          [](Space& s, const In2& path, bool certify) {
            check_cols(path, s);
            const mgcore::PathCheck c = s.validate_path(path.data(), static_cast<int>(path.shape(0)), certify);
            return nb::make_tuple(c.valid, c.worst, c.first_invalid, c.reason, c.segment, c.states);
          },
          "path"_a, "certify"_a = false,
          "Dense check of path (K, n): (valid, worst, first invalid state, reason, segment, states). certify: states "
          "the constraint's rates certify from the latest evaluated one pass unevaluated (the same report; worst over "
          "the evaluated states).");

  using Decoder = mgcore::Decoder;
  using InF2 = nb::ndarray<const float, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
  using InF1 = nb::ndarray<const float, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
  nb::class_<Decoder>(m, "Decoder")
      .def(
          "__init__",
          [](Decoder* self, const std::vector<InF2>& weights, const std::vector<InF1>& biases, int latent, bool uniform,
             const In1& q_mean, const In1& q_std, const In1& y_mean, const In1& y_std, const In1& lower, const In1& upper,
             int steps, const std::vector<InF2>& prior_weights, const std::vector<InF1>& prior_biases, int prior_steps) {
            const auto matrices = [](const std::vector<InF2>& arrays) {
              std::vector<Decoder::MatF> out;
              for (const InF2& a : arrays)
                out.emplace_back(Eigen::Map<const Decoder::MatF>(a.data(), static_cast<long>(a.shape(0)), static_cast<long>(a.shape(1))));
              return out;
            };
            const auto vectors = [](const std::vector<InF1>& arrays) {
              std::vector<Decoder::VecF> out;
              for (const InF1& a : arrays) out.emplace_back(Eigen::Map<const Decoder::VecF>(a.data(), static_cast<long>(a.shape(0))));
              return out;
            };
            new (self) Decoder(matrices(weights), vectors(biases), latent, uniform, vec_of(q_mean), vec_of(q_std), vec_of(y_mean),
                               vec_of(y_std), vec_of(lower), vec_of(upper), steps, matrices(prior_weights),
                               vectors(prior_biases), prior_steps);
          },
          "weights"_a, "biases"_a, "latent"_a, "uniform"_a, "q_mean"_a, "q_std"_a, "y_mean"_a, "y_std"_a, "lower"_a, "upper"_a,
          "steps"_a = 0, "prior_weights"_a = std::vector<InF2>{}, "prior_biases"_a = std::vector<InF1>{}, "prior_steps"_a = 0,
          "A sampling network: float32 weights (out, in) and biases (out,) of Linear layers with SiLU between them, the "
          "latent size, uniform (U(-1, 1) latent rows, else N(0, I)), the model's normalisation and joint limits; "
          "steps > 0: a velocity field v([x, y, t]) integrated from the latent rows in that many steps (Heun, the last Euler); "
          "prior_steps > 0: the latent rows first carried by the velocity field prior_weights/prior_biases ([z, y, t] -> "
          "latent) in that many steps.")
      .def(
          "latent_rows", [](const Decoder& d, long count, std::uint64_t seed) { return array_of(d.latent_rows(count, seed)); },
          "count"_a, "seed"_a, "(count, latent) float32 latent rows drawn from seed.")
      .def(
          "decode",
          [](const Decoder& d, const InF2& z, const In1& y) {
            return array_of(d.decode(
                Eigen::Map<const Decoder::MatF>(z.data(), static_cast<long>(z.shape(0)), static_cast<long>(z.shape(1))),
                vec_of(y)));
          },
          "z"_a, "y"_a, "(B, d) configurations decoded from latent rows z (B, latent) float32 at condition y (k,).")
      .def(
          "sample",
          [](const Decoder& d, const In1& y, long count, std::uint64_t seed) {
            return array_of(d.sample(vec_of(y), count, seed));
          },
          "y"_a, "count"_a, "seed"_a, "(count, d) configurations at condition y (k,): decode(latent_rows(count, seed), y).");

  m.def(
      "nearest_queries",
      [](const In2& points, const std::vector<bool>& alive, const In2& queries, double radius) {
        const auto rows = [](const In2& a) {
          return RowMat(Eigen::Map<const RowMat>(a.data(), static_cast<long>(a.shape(0)), static_cast<long>(a.shape(1))));
        };
        const mgcore::NearestAnswers a =
            mgcore::nearest_queries(rows(points), std::vector<char>(alive.begin(), alive.end()), rows(queries), radius);
        return nb::make_tuple(a.nearest, std::vector<bool>(a.within.begin(), a.within.end()));
      },
      "points"_a, "alive"_a, "queries"_a, "radius"_a,
      "The search's nearest-neighbour index over points (N, n) (rows inserted in order), for each query (Q, n): "
      "(nearest alive row, lowest index on ties, -1 if none; whether an alive row is within radius). For tests.");

  nb::class_<mgcore::PlannerSettings>(m, "PlannerSettings")
      .def(
          "__init__",
          [](mgcore::PlannerSettings* s, double range, double resolution, double step, bool partial, int pool,
             int pool_batch, int candidates, int target_batch, const std::string& local, int edge_stride,
             bool dense_edges, int refine, double reach, int shortcut, double precision, int max_iters, double tol,
             double damping, double max_step) {
            if (edge_stride < 1) throw std::invalid_argument("edge_stride must be at least 1 (1: every state checked at once)");
            if (refine < 0) throw std::invalid_argument("refine must be at least 0 (iterations refining a raw row)");
            new (s) mgcore::PlannerSettings{range, resolution, step, partial, pool, pool_batch, candidates,
                                            target_batch, local, edge_stride, dense_edges, refine, reach, shortcut,
                                            precision, max_iters, tol, damping, max_step};
          },
          nb::kw_only(), "range"_a, "resolution"_a, "step"_a, "partial"_a, "pool"_a, "pool_batch"_a, "candidates"_a,
          "target_batch"_a, "local"_a, "edge_stride"_a, "dense_edges"_a, "refine"_a, "reach"_a, "shortcut"_a,
          "precision"_a, "max_iters"_a, "tol"_a, "damping"_a, "max_step"_a,
          "RRT-Connect's settings, every field given (no defaults: manifoldgen.planning.rrt_connect.core_settings fills them from "
          "the planner's settings). edge_stride > 1: motions are checked for collision at every edge_stride-th state "
          "and at nodes while searching, the rest on candidate paths; dense_edges: each motion passes the path check "
          "when it is made (after a pre-check of every edge_stride-th state), so no candidate path is rejected; "
          "draw gives raw candidates, each refined (refine projection iterations) and checked when the search "
          "first uses it; reach > 0: a pooled sample is a stepping stone of a tree within min(reach, range) "
          "of its nodes (else range); shortcut > 0: that many shortcut attempts on a found path, each kept when "
          "its stretch passes the path check, then relaxation sweeps; precision, max_iters: a projected walk's projections (to precision x "
          "the smallest tolerance); tol: a raw row's refinement; damping, max_step: both projections'.")
      .def_ro("range", &mgcore::PlannerSettings::range)
      .def_ro("pool", &mgcore::PlannerSettings::pool)
      .def_ro("pool_batch", &mgcore::PlannerSettings::pool_batch)
      .def_ro("edge_stride", &mgcore::PlannerSettings::edge_stride)
      .def_ro("dense_edges", &mgcore::PlannerSettings::dense_edges)
      .def_ro("refine", &mgcore::PlannerSettings::refine)
      .def_ro("reach", &mgcore::PlannerSettings::reach)
      .def_ro("shortcut", &mgcore::PlannerSettings::shortcut);

  m.def(
      "rrt_connect",
      [](Space& space, const In1& start, const In1& goal, nb::callable draw, double time_limit,
         const mgcore::PlannerSettings& st) {
        const int nn = space.n();
        mgcore::Draw fetch = [&](int count) {
          nb::object rows = draw(count);
          auto a = nb::cast<nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>>(rows);
          if (static_cast<int>(a.shape(1)) != nn) throw std::runtime_error("sampler rows have the wrong width");
          return RowMat(Eigen::Map<const RowMat>(a.data(), static_cast<long>(a.shape(0)), nn));
        };
        const mgcore::PlanOutput out = mgcore::rrt_connect(space, vec_of(start), vec_of(goal), fetch, st, time_limit);
        nb::dict d;
        d["path"] = array_of(out.path);
        d["iterations"] = out.iterations;
        d["samples"] = out.samples;
        d["rejected_paths"] = out.rejected;
        d["out_of_reach"] = out.out_of_reach;
        d["projections"] = out.projections;
        d["cut_edges"] = out.cut_edges;
        d["verified_states"] = out.verified_states;
        d["reattached"] = out.reattached;
        d["refined"] = out.refined;
        d["accepted"] = out.accepted;
        d["shortcuts"] = out.shortcuts;
        d["relaxed"] = out.relaxed;
        d["found_length"] = out.found_length;
        d["nodes"] = out.nodes;
        return d;
      },
      "space"_a, "start"_a, "goal"_a, "draw"_a, "time_limit"_a, "settings"_a,
      "RRT-Connect from start to goal (n,) in space with settings (PlannerSettings); draw(count) -> (count, n) rows "
      "(raw candidates, refined and checked as the search uses them). A dict: path (K, n) (0 rows: unsolved), "
      "iterations, samples, rejected_paths, out_of_reach, projections, cut_edges, verified_states (coarse edges' "
      "states checked on candidate paths), reattached (cut edges whose node got another parent), refined, "
      "accepted (raw candidates made samples, and of those valid), shortcuts (kept), relaxed (waypoint "
      "moves kept after them), found_length (before both), nodes.");
}
