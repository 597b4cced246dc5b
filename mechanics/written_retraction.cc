// The compiled part of mechanics/written_retraction.h: parsing, the axiom check, and
// with them the vtable of WrittenRetraction and its evaluations for every scalar type.
#include "mechanics/written_retraction.h"

#include <cmath>
#include <stdexcept>
#include <utility>

#include "core/manifold_maps.h"
#include "mechanics/written_map.h"  // show_number

namespace dvm {

WrittenRetraction::WrittenRetraction(Space space, const std::vector<std::string>& texts, const Params& params,
                                     std::string name)
    : space_(space), name_(std::move(name)) {
  const std::size_t n = space == Space::sphere ? 3 : 9;
  if (texts.size() != n)
    throw std::invalid_argument("retraction: expected " + std::to_string(n) + " expressions (" +
                                (space == Space::sphere ? "the components of f(x, v) in R^3"
                                                        : "the entries of f(R, w), row by row") +
                                "), got " + std::to_string(texts.size()));
  ExpressionSymbols s;
  if (space == Space::sphere) {
    for (int i = 0; i < 3; ++i) {
      s.variables.push_back({"x" + std::to_string(i + 1), 0, i});
      s.variables.push_back({"v" + std::to_string(i + 1), 1, i});
    }
  } else {
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i)
        s.variables.push_back({"R" + std::to_string(i + 1) + std::to_string(j + 1), 0, 3 * j + i});
    for (int i = 0; i < 3; ++i) s.variables.push_back({"w" + std::to_string(i + 1), 1, i});
  }
  s.constants = params;
  components_.resize(n);
  texts_ = texts;
  for (std::size_t k = 0; k < n; ++k) {
    // the text is row by row, the storage column-major (as Eigen's matrices)
    const std::size_t at = space == Space::sphere ? k : 3 * (k % 3) + k / 3;
    try {
      components_[at] = Expression::parse(texts[k], s);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument("retraction[" + std::to_string(k) + "]: " + e.what());
    }
  }
  check_axioms();
}

WrittenRetraction::~WrittenRetraction() = default;

std::string WrittenRetraction::text() const {
  std::string out = "f = (";
  for (std::size_t k = 0; k < texts_.size(); ++k) out += (k ? ", " : "") + texts_[k];
  return out + ")";
}

void WrittenRetraction::check_axioms() {
  using J = ceres::Jet<double, 1>;
  auto self = std::shared_ptr<const EmbeddedRetraction>(std::shared_ptr<const EmbeddedRetraction>{}, this);
  const Vec<double, 3> dirs[4] = {{0.48, -0.6, 0.64}, {-0.36, 0.8, 0.48}, {0.8, 0.36, -0.48}, {0.0, 0.0, 1.0}};
  residual_ = 0.0;
  const SphereMap sphere(self, 0.0, "written");
  const SO3Map rotation(self, 0.0, "written");
  for (const Vec<double, 3>& d : dirs) {
    if (space_ == Space::sphere) {
      const SphereMap& R = sphere;
      const Vec<double, 3> x = d.normalized();
      const Vec<double, 3> r0 = R.retract(x, Vec<double, 3>(Vec<double, 3>::Zero()));
      refuse_if((r0 - x).norm(), "R_x(0) = x", x.data());
      // two tangent directions at x
      const Vec<double, 3> a = (std::fabs(x[0]) < 0.9 ? Vec<double, 3>::UnitX() : Vec<double, 3>::UnitY()).cross(x).normalized();
      for (const Vec<double, 3>& u : {a, Vec<double, 3>(x.cross(a))}) {
        Vec<J, 3> xj, vj;
        for (int i = 0; i < 3; ++i) {
          xj[i] = J(x[i]);
          vj[i] = J(0.0);
          vj[i].v[0] = u[i];
        }
        const Vec<J, 3> r = R.retract(xj, vj);
        Vec<double, 3> slope;
        for (int i = 0; i < 3; ++i) slope[i] = r[i].v[0];
        refuse_if((slope - u).norm(), "d/dt R_x(t u) = u at t = 0", x.data());
      }
    } else {
      const SO3Map& R = rotation;
      const Mat<double, 3, 3> X = SO3::exp(Vec<double, 3>(1.3 * d));
      const Mat<double, 3, 3> r0 = R.retract(X, Vec<double, 3>(Vec<double, 3>::Zero()));
      refuse_if((r0 - X).norm(), "R_R(0) = R", d.data());
      for (int k = 0; k < 3; ++k) {
        Mat<J, 3, 3> Xj;
        Vec<J, 3> wj;
        for (int i = 0; i < 3; ++i) {
          wj[i] = J(0.0);
          wj[i].v[0] = i == k ? 1.0 : 0.0;
          for (int j = 0; j < 3; ++j) Xj(i, j) = J(X(i, j));
        }
        const Mat<J, 3, 3> r = R.retract(Xj, wj);
        Mat<double, 3, 3> slope;
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) slope(i, j) = r(i, j).v[0];
        refuse_if((slope - X * SO3::hat(Vec<double, 3>(Vec<double, 3>::Unit(k)))).norm(),
                  "d/dt R_R(t e_k) = R hat(e_k) at t = 0", d.data());
      }
    }
  }
}

void WrittenRetraction::refuse_if(double residual, const char* axiom, const double* at) {
  if (!std::isfinite(residual) || !(residual <= 1e-12))
    throw std::invalid_argument("retraction: not a retraction (Def. 2.2 through Prop. 2.3): " + std::string(axiom) +
                                " fails by " + show_number(residual) + " at " +
                                (space_ == Space::sphere ? "x = (" : "R = exp(1.3 (") + show_number(at[0]) + ", " +
                                show_number(at[1]) + ", " + show_number(at[2]) + (space_ == Space::sphere ? ")" : "))"));
  residual_ = std::fmax(residual_, residual);
}

}  // namespace dvm
