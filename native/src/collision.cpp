// The collision test and the validity rule of the constrained space (see space_impl.hpp): the sphere models as a
// per-pair broad phase, the convex outer shapes (mesh hulls, primitives) as the mid phase before coal's exact test,
// and the per-state verdicts built on them and on the terms (code, codes, valid_prefix).
#include "space_impl.hpp"

#include <pinocchio/algorithm/geometry.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/collision/broadphase.hpp>
#include <pinocchio/collision/collision.hpp>

#include <coal/BVH/BVH_model.h>
#include <coal/collision.h>
#include <coal/shape/convex.h>
#include <coal/shape/geometric_shapes.h>
#include <pinocchio/collision/coal-pinocchio-conversions.hpp>

#include <algorithm>
#include <map>
#include <mutex>
#include <sstream>
#include <stdexcept>

namespace mgcore {

namespace {

// The convex hull of a mesh (with its triangles, for coal's hill-climbing support), built once per mesh content
// and process: qhull costs about 1 ms a mesh, and every plan builds a new Space. Null when qhull fails or the
// mesh cannot have a hull (fewer than 4 vertices, no triangles, a non-finite vertex: qhull would crash on it):
// such a mesh's pairs go from the spheres straight to coal. (buildConvexHull's return value says whether the mesh
// was convex itself, not whether the hull was built: a concave mesh's hull holds it all the same.)
std::shared_ptr<coal::ConvexBase> mesh_hull(coal::BVHModelBase& mesh) {
  static std::mutex guard;
  static std::map<std::string, std::shared_ptr<coal::ConvexBase>> built;
  if (!mesh.vertices || mesh.num_vertices < 4 || mesh.num_tris < 1) return nullptr;
  for (unsigned int i = 0; i < mesh.num_vertices; ++i)
    if (!(*mesh.vertices)[i].allFinite()) return nullptr;
  std::string key(reinterpret_cast<const char*>(mesh.vertices->data()), mesh.num_vertices * sizeof(coal::Vec3s));
  std::lock_guard<std::mutex> hold(guard);
  auto found = built.find(key);
  if (found != built.end()) return found->second;
  std::shared_ptr<coal::ConvexBase> hull;
  try {  // coal refuses some meshes with an exception (e.g. "Too many neighbors": a vertex of over 255 edges)
    mesh.buildConvexHull(true, "Qt");
    hull = mesh.convex;
  } catch (const std::exception&) {
    try {  // the hull's facets as qhull merges them, not triangulated: fewer edges per vertex (centauro's pelvis)
      mesh.buildConvexHull(false, "");
      hull = mesh.convex;
    } catch (const std::exception&) {
    }
  }
  built.emplace(std::move(key), hull);
  return hull;
}

Shape shape_of(const pinocchio::GeometryObject& g) {
  Shape s;
  if (auto box = std::dynamic_pointer_cast<coal::Box>(g.geometry)) {
    s.kind = BOX;
    s.size = box->halfSide;
    s.outer = s.size.norm();
  } else if (auto sphere = std::dynamic_pointer_cast<coal::Sphere>(g.geometry)) {
    s.kind = SPHERE;
    s.size[0] = sphere->radius;
    s.outer = s.size[0];
  } else if (auto cyl = std::dynamic_pointer_cast<coal::Cylinder>(g.geometry)) {
    s.kind = CYLINDER;
    s.size[0] = cyl->radius;
    s.size[1] = cyl->halfLength;
    s.outer = std::hypot(s.size[0], s.size[1]);
  }
  return s;
}

}  // namespace

// A geometry's convex outer shape (a mesh's hull with its triangles, for coal's hill-climbing support;
// a box, sphere, cylinder, capsule or convex itself); null when none.
const coal::CollisionGeometry* Space::Impl::outer_of(int g) {
  if (outer_ready[g]) return outer[g].get();
  outer_ready[g] = true;
  const auto& shape = geom.geometryObjects[g].geometry;
  if (auto mesh = std::dynamic_pointer_cast<coal::BVHModelBase>(shape)) {
    outer[g] = mesh_hull(*mesh);
  } else if (shape && shape->getObjectType() == coal::OT_GEOM) {
    outer[g] = shape;
  }
  return outer[g].get();
}

// Exact verdict of one collision pair at the latest collision kinematics: coal's test, after a mid
// phase on the two geometries' convex outer shapes (each holds its geometry, so outer shapes apart by
// more than HULL_MARGIN mean geometries apart: the verdict is coal's either way).
bool Space::Impl::pair_collides(std::size_t k) {
  if (!placed_geometries) {
    pinocchio::updateGeometryPlacements(model, cdata, geom, *geom_data);
    placed_geometries = true;
  }
  const pinocchio::CollisionPair& pair = geom.collisionPairs[k];
  const coal::CollisionGeometry* oa = outer_of(static_cast<int>(pair.first));
  const coal::CollisionGeometry* ob = outer_of(static_cast<int>(pair.second));
  if (oa && ob) {
    ++tally->hull_tests;
    coal::CollisionRequest& request = outer_requests[k];
    coal::CollisionResult result;
    coal::collide(oa, pinocchio::toCoalTransform3s(geom_data->oMg[pair.first]), ob,
                  pinocchio::toCoalTransform3s(geom_data->oMg[pair.second]), request, result);
    request.updateGuess(result);
    if (!result.isCollision()) return false;
  }
  ++tally->mesh_tests;
  return pinocchio::computeCollision(geom, *geom_data, static_cast<pinocchio::PairIndex>(k));
}

// Exact collision test with the sphere models as a per-pair broad phase: a pair whose spheres touch
// nothing is free; every other pair (spheres touching, exact pairs) gets pair_collides. flagged: some
// pair's spheres touched (the sphere test alone would have called the state in collision).
bool Space::Impl::pairs_collide(const double* q, bool& flagged) {
  place_kinematics(q);
  flagged = false;
  for (const PairTest& t : tests) {
    if (t.kind == SPHERES_SPHERES) {
      if ((bound_world[t.a] - bound_world[t.b]).norm() > bound_radius[t.a] + bound_radius[t.b]) continue;
      place(t.a);
      place(t.b);
      if (!spheres_touch(t.a, t.b)) continue;
    } else if (t.kind == SPHERES_PRIMITIVE) {
      const pinocchio::SE3& pose = pose_of(t.b);
      if (beyond(t.b, pose, bound_world[t.a], bound_radius[t.a])) continue;
      place(t.a);
      if (!spheres_touch_shape(t.a, t.b, pose)) continue;
    } else if (!spheres_of[t.a].empty() && !spheres_of[t.b].empty()) {
      // a pair left to coal because its spheres often touch while the meshes are apart: where they do not
      // touch, the pair is free all the same (the sphere-only verdict, spheres_hit, still sends it to coal)
      if ((bound_world[t.a] - bound_world[t.b]).norm() > bound_radius[t.a] + bound_radius[t.b]) continue;
      place(t.a);
      place(t.b);
      if (!spheres_touch(t.a, t.b)) continue;
    }
    if (t.kind != 2) flagged = true;
    if (pair_collides(t.pair)) return true;
  }
  return false;
}

// Collision kinematics at q, bounding balls placed; sphere centres placed lazily by place().
// jacobians: the joint Jacobians too (cdata.J, world frame), for the certified sweeps' rates.
void Space::Impl::place_kinematics(const double* q, bool jacobians) {
  if (jacobians) pinocchio::computeJointJacobians(model, cdata, to_full(q));
  else pinocchio::forwardKinematics(model, cdata, to_full(q));
  std::fill(placed_spheres.begin(), placed_spheres.end(), false);
  std::fill(shape_placed.begin(), shape_placed.end(), false);
  placed_geometries = false;
  for (std::size_t g = 0; g < bound_joint.size(); ++g)
    if (bound_joint[g] >= 0) bound_world[g] = cdata.oMi[bound_joint[g]].act(bound_center[g]);
}

bool Space::Impl::spheres_touch(int a, int b) const {
  for (int i : spheres_of[a])
    for (int j : spheres_of[b])
      if ((world[i] - world[j]).squaredNorm() <= std::pow(sphere_radius[i] + sphere_radius[j], 2)) return true;
  return false;
}

bool Space::Impl::spheres_touch_shape(int a, int b, const pinocchio::SE3& pose) const {
  for (int i : spheres_of[a])
    if (!beyond(b, pose, world[i], sphere_radius[i])) return true;
  return false;
}

// Sphere test of the latest collision kinematics (cdata): true when some tested pair may collide.
bool Space::Impl::spheres_hit(const double* q) {
  place_kinematics(q);
  for (const PairTest& t : tests) {
    if (t.kind == SPHERES_SPHERES) {
      if ((bound_world[t.a] - bound_world[t.b]).norm() > bound_radius[t.a] + bound_radius[t.b]) continue;
      place(t.a);
      place(t.b);
      if (spheres_touch(t.a, t.b)) return true;
    } else if (t.kind == SPHERES_PRIMITIVE) {
      const pinocchio::SE3& pose = pose_of(t.b);
      if (beyond(t.b, pose, bound_world[t.a], bound_radius[t.a])) continue;
      place(t.a);
      if (spheres_touch_shape(t.a, t.b, pose)) return true;
    } else {
      if (!placed_geometries) {
        pinocchio::updateGeometryPlacements(model, cdata, geom, *geom_data);
        placed_geometries = true;
      }
      ++tally->mesh_tests;
      if (pinocchio::computeCollision(geom, *geom_data, static_cast<pinocchio::PairIndex>(t.pair))) return true;
    }
  }
  return false;
}

void Space::set_spheres(const std::vector<int>& joint, const RowMat& center, const Vec& radius,
                        const std::vector<int>& geometry, const std::vector<std::pair<int, int>>& exact) {
  Impl& p = *impl_;
  const std::size_t S = joint.size();
  if (center.rows() != static_cast<long>(S) || center.cols() != 3 || radius.size() != static_cast<long>(S) ||
      geometry.size() != S)
    throw std::runtime_error("spheres need joint (S,), center (S, 3), radius (S,) and geometry (S,) of one length S");
  const int ng = static_cast<int>(p.geom.ngeoms);
  p.spheres_of.assign(ng, {});
  for (std::size_t s = 0; s < S; ++s) {
    if (joint[s] < 0 || joint[s] >= static_cast<int>(p.model.njoints))
      throw std::runtime_error("sphere joint id out of range");
    if (geometry[s] < 0 || geometry[s] >= ng) throw std::runtime_error("sphere geometry index out of range");
    if (!(radius[s] >= 0)) throw std::runtime_error("sphere radii must be >= 0");
    if (static_cast<int>(p.geom.geometryObjects[geometry[s]].parentJoint) != joint[s])
      throw std::runtime_error("a sphere's joint must be the parent joint of the geometry it covers");
    p.spheres_of[geometry[s]].push_back(static_cast<int>(s));
  }
  p.sphere_joint = joint;
  p.sphere_center = center;
  p.sphere_radius = radius;
  p.world.assign(S, Eigen::Vector3d::Zero());
  p.placed_spheres.assign(ng, false);
  p.bound_center.assign(ng, Eigen::Vector3d::Zero());
  p.bound_world.assign(ng, Eigen::Vector3d::Zero());
  p.bound_radius.assign(ng, 0.0);
  p.bound_joint.assign(ng, -1);
  for (int g = 0; g < ng; ++g) {
    if (p.spheres_of[g].empty()) continue;
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int s : p.spheres_of[g]) c += center.row(s).transpose();
    c /= static_cast<double>(p.spheres_of[g].size());
    double r = 0.0;
    for (int s : p.spheres_of[g]) r = std::max(r, (Eigen::Vector3d(center.row(s).transpose()) - c).norm() + radius[s]);
    p.bound_center[g] = c;
    p.bound_radius[g] = r;
    p.bound_joint[g] = joint[p.spheres_of[g].front()];
  }
  p.shapes.clear();
  for (const auto& g : p.geom.geometryObjects) p.shapes.push_back(shape_of(g));
  p.shape_pose.assign(ng, pinocchio::SE3::Identity());
  p.shape_placed.assign(ng, false);
  p.outer.assign(ng, nullptr);
  p.outer_ready.assign(ng, false);
  p.outer_requests.clear();
  for (std::size_t k = 0; k < p.geom.collisionPairs.size(); ++k) {
    coal::CollisionRequest request(coal::NO_REQUEST, 1);
    request.security_margin = p.geom_data->collisionRequests[k].security_margin + HULL_MARGIN;
    request.gjk_initial_guess = coal::GJKInitialGuess::CachedGuess;
    request.distance_upper_bound = 0.0;  // GJK stops once it proves the hulls farther apart than the margin
    p.outer_requests.push_back(request);
  }
  p.tests.clear();
  for (std::size_t k = 0; k < p.geom.collisionPairs.size(); ++k) {
    const int a = static_cast<int>(p.geom.collisionPairs[k].first), b = static_cast<int>(p.geom.collisionPairs[k].second);
    const bool sa = !p.spheres_of[a].empty(), sb = !p.spheres_of[b].empty();
    const bool forced = std::find(exact.begin(), exact.end(), std::make_pair(a, b)) != exact.end() ||
                        std::find(exact.begin(), exact.end(), std::make_pair(b, a)) != exact.end();
    // a primitive (box, sphere, cylinder: an obstacle, a held tray) is tested exactly against the other's
    // spheres, tighter than its own spheres would be
    if (forced) p.tests.push_back({EXACT_PAIR, a, b, k});
    else if (sa && p.shapes[b].kind != NO_SHAPE) p.tests.push_back({SPHERES_PRIMITIVE, a, b, k});
    else if (sb && p.shapes[a].kind != NO_SHAPE) p.tests.push_back({SPHERES_PRIMITIVE, b, a, k});
    else if (sa && sb) p.tests.push_back({SPHERES_SPHERES, a, b, k});
    else p.tests.push_back({EXACT_PAIR, a, b, k});
  }
  // cheapest first: primitives, then sphere pairs, exact pairs last
  std::stable_sort(p.tests.begin(), p.tests.end(), [](const PairTest& x, const PairTest& y) {
    static const int rank[3] = {1, 0, 2};  // by PairKind: spheres-primitive first, then sphere pairs, exact last
    return rank[x.kind] < rank[y.kind];
  });
  for (const auto& pair : p.geom.collisionPairs) {  // the hulls now, not in the first plan's checks
    p.outer_of(static_cast<int>(pair.first));
    p.outer_of(static_cast<int>(pair.second));
  }
  p.span_d = Vec::Zero(p.n());
  p.last_stop = -1;
  p.build_holders();
  prepare();  // the rates too, as the hulls: not in the first plan's checks
}

void Space::clear_spheres() {
  impl_->sphere_joint.clear();
  impl_->tests.clear();
}

bool Space::has_spheres() const { return !impl_->sphere_joint.empty(); }

RowMat Space::sphere_centers(const double* q) {
  Impl& p = *impl_;
  p.place_kinematics(q);
  RowMat out(p.sphere_joint.size(), 3);
  for (int g = 0; g < static_cast<int>(p.spheres_of.size()); ++g) p.place(g);
  for (std::size_t s = 0; s < p.sphere_joint.size(); ++s) out.row(s) = p.world[s].transpose();
  return out;
}

std::string Space::sphere_report() const {
  int counts[3] = {0, 0, 0};
  for (const PairTest& t : impl_->tests) ++counts[t.kind];
  std::ostringstream out;
  out << impl_->sphere_joint.size() << " spheres; pairs: " << counts[0] << " sphere-sphere, " << counts[1]
      << " sphere-primitive, " << counts[2] << " exact";
  return out.str();
}

bool Space::within_limits(const double* q) const {
  const Impl& p = *impl_;
  for (int i = 0; i < p.n(); ++i)
    if (!(q[i] >= p.lower[i] - 1e-9 && q[i] <= p.upper[i] + 1e-9)) return false;  // NaN: outside
  return true;
}

bool Space::collision_free(const double* q) {
  Impl& p = *impl_;
  if (p.geom.collisionPairs.empty()) return true;
  if (!p.sphere_joint.empty()) {  // spheres as a per-pair broad phase: coal only for pairs whose spheres touch
    ++counts.sphere_checks;
    bool flagged = false;
    const bool hit = p.pairs_collide(q, flagged);
    if (flagged) ++counts.collision_checks;  // counted as before: states the spheres sent on to coal
    return !hit;
  }
  ++counts.collision_checks;
  return !pinocchio::computeCollisions(p.model, p.cdata, *p.manager, p.to_full(q), true);
}

bool Space::spheres_free(const double* q) {
  if (impl_->sphere_joint.empty()) return collision_free(q);
  ++counts.sphere_checks;
  return !impl_->spheres_hit(q);
}

int Space::code(const double* q, double limit, bool collision, bool exact) {
  if (!within_limits(q)) return LIMITS;
  if (!batched()) {
    bool hold;
    if (impl_->state_check(q, limit, hold) > limit) return CONSTRAINT;
    if (!hold) return INEQUALITY;
  } else {
    if (violation(q) > limit) return CONSTRAINT;
    if (!inequalities_hold(q)) return INEQUALITY;
  }
  if (impl_->p) {
    std::vector<double> G(impl_->p);
    inequalities(q, 1, G.data());
    if (*std::max_element(G.begin(), G.end()) > 0) return INEQUALITY;
  }
  if (collision && !(exact ? collision_free(q) : spheres_free(q))) return COLLISION;
  return VALID;
}

int Space::valid_prefix(const double* states, int k, bool last_is_node, bool collision) {
  const int nn = n();
  const double inner = 1.0 - impl_->margin;
  std::vector<int> batch;  // batched(): every state's verdict before collision, one callback for all
  if (batched() && k > 0) {
    std::vector<double> limit(k, inner);
    if (last_is_node) limit[k - 1] = 1.0;
    batch.resize(k);
    codes(states, k, limit.data(), false, true, batch.data());
  }
  for (int i = 0; i < k; ++i) {
    const double* q = states + static_cast<long>(i) * nn;
    const int c = batch.empty() ? code(q, (last_is_node && i == k - 1) ? 1.0 : inner, collision, true)
                  : batch[i] != VALID || !collision || collision_free(q) ? batch[i] : static_cast<int>(COLLISION);
    if (c != VALID) {
      stop = c;
      ++counts.stopped[c];
      return i;
    }
  }
  stop = VALID;
  return k;
}

void Space::codes(const double* q, long B, const double* limit, bool collision, bool exact, int* out) {
  const int nn = n(), pp = impl_->p;
  if (!batched()) {
    for (long b = 0; b < B; ++b) out[b] = code(q + b * nn, limit[b], collision, exact);
    return;
  }
  std::vector<double> v(B), G(B * pp);
  violations(q, B, v.data());
  inequalities(q, B, G.data());
  for (long b = 0; b < B; ++b) {
    const double* x = q + b * nn;
    if (!within_limits(x)) out[b] = LIMITS;
    else if (v[b] > limit[b]) out[b] = CONSTRAINT;
    else if (!inequalities_hold(x)) out[b] = INEQUALITY;
    else if (pp && *std::max_element(G.begin() + b * pp, G.begin() + (b + 1) * pp) > 0) out[b] = INEQUALITY;
    else if (collision && !(exact ? collision_free(x) : spheres_free(x))) out[b] = COLLISION;
    else out[b] = VALID;
  }
}

}  // namespace mgcore
