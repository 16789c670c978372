// SPDX-License-Identifier: Apache-2.0
// Unit tests for the implicit-function nodes: primitives, quadrics, CSG and transforms.
// Every value is checked against a closed form written here, independently of the library.

#include <ivdb/implicit/Blend.h>
#include <ivdb/implicit/Csg.h>
#include <ivdb/implicit/GridShape.h>
#include <ivdb/implicit/Implicit.h>
#include <ivdb/implicit/Modifiers.h>
#include <ivdb/implicit/Primitives.h>
#include <ivdb/implicit/Quadric.h>

#include <openvdb/Exceptions.h>
#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

using namespace ivdb::implicit;
using Ptr = Implicit::Ptr;

namespace {

const double kPi = 3.14159265358979323846;
using Mat3 = std::array<std::array<double, 3>, 3>;

Mat3 mul(const Mat3& a, const Mat3& b)
{
    Mat3 c{};
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            for (int k = 0; k < 3; ++k) c[i][j] += a[i][k] * b[k][j];
    return c;
}

/// R = Rz Ry Rx (fixed axes x, then y, then z), built from the three elementary rotations.
Mat3 rotation(const Vec3d& deg)
{
    const double x = deg[0] * kPi / 180, y = deg[1] * kPi / 180, z = deg[2] * kPi / 180;
    const Mat3 rx{{{1, 0, 0}, {0, std::cos(x), -std::sin(x)}, {0, std::sin(x), std::cos(x)}}};
    const Mat3 ry{{{std::cos(y), 0, std::sin(y)}, {0, 1, 0}, {-std::sin(y), 0, std::cos(y)}}};
    const Mat3 rz{{{std::cos(z), -std::sin(z), 0}, {std::sin(z), std::cos(z), 0}, {0, 0, 1}}};
    return mul(rz, mul(ry, rx));
}

Vec3d rotate(const Mat3& r, const Vec3d& v)
{
    return Vec3d(r[0][0] * v[0] + r[0][1] * v[1] + r[0][2] * v[2],
                 r[1][0] * v[0] + r[1][1] * v[1] + r[1][2] * v[2],
                 r[2][0] * v[0] + r[2][1] * v[1] + r[2][2] * v[2]);
}

Vec3d rotateBack(const Mat3& r, const Vec3d& v)
{
    return Vec3d(r[0][0] * v[0] + r[1][0] * v[1] + r[2][0] * v[2],
                 r[0][1] * v[0] + r[1][1] * v[1] + r[2][1] * v[2],
                 r[0][2] * v[0] + r[1][2] * v[1] + r[2][2] * v[2]);
}

// ---- Reference closed forms ----------------------------------------------------------------

double refSphere(const Vec3d& p, const Vec3d& c, double r) { return (p - c).length() - r; }

/// Box SDF by brute force: outside, the distance to the clamped (nearest) point of the box;
/// inside, minus the distance to the nearest of the six face planes.
double refBox(const Vec3d& p, const Vec3d& c, const Vec3d& size)
{
    const Vec3d lo = c - size * 0.5, hi = c + size * 0.5;
    Vec3d nearest;
    bool inside = true;
    for (int i = 0; i < 3; ++i) {
        nearest[i] = std::min(std::max(p[i], lo[i]), hi[i]);
        inside = inside && p[i] > lo[i] && p[i] < hi[i];
    }
    if (!inside) return (p - nearest).length();
    double d = std::numeric_limits<double>::max();
    for (int i = 0; i < 3; ++i) d = std::min(d, std::min(p[i] - lo[i], hi[i] - p[i]));
    return -d;
}

Vec3d refBoxGradient(const Vec3d& p, const Vec3d& c, const Vec3d& size)
{
    const Vec3d lo = c - size * 0.5, hi = c + size * 0.5;
    Vec3d nearest;
    for (int i = 0; i < 3; ++i) nearest[i] = std::min(std::max(p[i], lo[i]), hi[i]);
    const Vec3d d = p - nearest;
    if (d.length() > 0) return d / d.length();
    int axis = 0;
    double best = std::numeric_limits<double>::max(), sign = 1;
    for (int i = 0; i < 3; ++i) {
        if (p[i] - lo[i] < best) { best = p[i] - lo[i]; axis = i; sign = -1; }
        if (hi[i] - p[i] < best) { best = hi[i] - p[i]; axis = i; sign = 1; }
    }
    Vec3d g(0.0);
    g[axis] = sign;
    return g;
}

/// Torus about the z axis: distance to the nearest point of the core circle, minus the minor radius.
Vec3d torusCorePoint(const Vec3d& p, const Vec3d& c, double major)
{
    const Vec3d d(p[0] - c[0], p[1] - c[1], 0.0);
    return c + d * (major / d.length());
}
double refTorus(const Vec3d& p, const Vec3d& c, double major, double minor)
{
    return (p - torusCorePoint(p, c, major)).length() - minor;
}

double refQuadric(const Mat4& q, const Vec3d& p, double* scale = nullptr)
{
    const double h[4] = {p[0], p[1], p[2], 1.0};
    double f = 0, s = 0;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) {
            f += h[i] * q[i][j] * h[j];
            s += std::abs(h[i] * q[i][j] * h[j]);
        }
    if (scale) *scale = s;
    return f;
}

Vec3d refQuadricGradient(const Mat4& q, const Vec3d& p)
{
    Vec3d g;
    for (int i = 0; i < 3; ++i) g[i] = 2 * (q[i][0] * p[0] + q[i][1] * p[1] + q[i][2] * p[2] + q[i][3]);
    return g;
}

Vec3d centralDifference(const Implicit& f, const Vec3d& p, double h = 1e-6)
{
    Vec3d g;
    for (int i = 0; i < 3; ++i) {
        Vec3d a = p, b = p;
        a[i] += h;
        b[i] -= h;
        g[i] = (f.value(a) - f.value(b)) / (2 * h);
    }
    return g;
}

void expectVecNear(const Vec3d& a, const Vec3d& b, double tol, const std::string& what)
{
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(a[i], b[i], tol) << what << " component " << i;
}

/// An orthonormal right-handed basis (u, v, axis/|axis|), built without the library.
std::array<Vec3d, 3> someFrame(const Vec3d& axis)
{
    const Vec3d w = axis / axis.length();
    const Vec3d helper = std::abs(w[0]) < 0.6 ? Vec3d(1, 0, 0) : Vec3d(0, 1, 0);
    const Vec3d u = helper.cross(w).unit();
    return {u, w.cross(u), w};
}

/// Translation t, rotation R, scale s of a child: q = S^-1 R^T (p - t); the value is min(s) f(q).
struct RefTransform
{
    Vec3d t, deg, s;
    Vec3d toLocal(const Vec3d& p) const
    {
        const Vec3d q = rotateBack(rotation(deg), p - t);
        return Vec3d(q[0] / s[0], q[1] / s[1], q[2] / s[2]);
    }
    double valueScale() const { return std::min(s[0], std::min(s[1], s[2])); }
};

/// One node of each type, with a predicate that says where its gradient has a kink.
struct Case
{
    std::string name;
    Ptr f;
    std::function<bool(const Vec3d&)> nearKink;
};

const Vec3d kSphereC(0.3, -0.2, 0.5), kBoxC(-0.4, 0.1, 0.2), kBoxSize(2.0, 1.4, 3.0),
    kTorusC(0.2, 0.1, -0.3);
const double kSphereR = 1.7, kMajor = 2.0, kMinor = 0.6;
const RefTransform kXf{Vec3d(0.5, -0.3, 0.8), Vec3d(30, -45, 70), Vec3d(1.5, 0.7, 1.2)};

bool boxKink(const Vec3d& p)
{
    if (std::abs(refBox(p, kBoxC, kBoxSize)) < 1e-3) return true; // edges on the surface
    double q[3];
    for (int i = 0; i < 3; ++i) q[i] = std::abs(p[i] - kBoxC[i]) - 0.5 * kBoxSize[i];
    if (q[0] >= 0 || q[1] >= 0 || q[2] >= 0) return false;
    std::sort(q, q + 3);
    return q[2] - q[1] < 1e-3; // medial surface inside
}

Mat4 randomSymmetric(std::mt19937& rng)
{
    std::uniform_real_distribution<double> u(-1, 1);
    Mat4 q{};
    for (int i = 0; i < 4; ++i)
        for (int j = i; j < 4; ++j) q[i][j] = q[j][i] = u(rng);
    return q;
}

std::vector<Case> allCases()
{
    std::mt19937 rng(7);
    const Ptr sphere = std::make_shared<Sphere>(kSphereC, kSphereR);
    const Ptr box = std::make_shared<Box>(kBoxC, kBoxSize);
    const Ptr torus = std::make_shared<Torus>(kTorusC, kMajor, kMinor);
    const auto smooth = [](const Vec3d&) { return false; };
    const auto sphereKink = [](const Vec3d& p) { return (p - kSphereC).length() < 1e-3; };
    const auto torusKink = [](const Vec3d& p) {
        const Vec3d d = p - kTorusC;
        return std::hypot(d[0], d[1]) < 1e-3 || refTorus(p, kTorusC, kMajor, kMinor) + kMinor < 1e-3;
    };
    // A CSG kink is where the deciding term and the runner-up are (nearly) equal.
    const auto csgKink = [=](Csg::Op op, std::vector<Case> kids) {
        return [=](const Vec3d& p) {
            std::vector<double> t;
            for (std::size_t i = 0; i < kids.size(); ++i) {
                const double v = kids[i].f->value(p);
                t.push_back(op == Csg::Op::Union ? -v : (op == Csg::Op::Difference && i ? -v : v));
            }
            const std::size_t best = std::max_element(t.begin(), t.end()) - t.begin();
            for (std::size_t i = 0; i < t.size(); ++i)
                if (i != best && t[best] - t[i] < 1e-3) return true;
            return kids[best].nearKink(p);
        };
    };
    std::vector<Case> c = {
        {"sphere", sphere, sphereKink},
        {"box", box, boxKink},
        {"torus", torus, torusKink},
        {"quadric", std::make_shared<Quadric>(randomSymmetric(rng)), smooth},
        {"plane", makePlane(Vec3d(1, -2, 0.5), 0.7), smooth},
        {"cylinder", makeCylinder(Vec3d(0.1, 0.2, 0.3), Vec3d(1, 1, 2), 1.1), smooth},
        {"ellipsoid", makeEllipsoid(Vec3d(0.5, -0.5, 0.2), Vec3d(2.0, 1.0, 1.5)), smooth},
        {"cone", makeCone(Vec3d(0.2, 0.0, -0.4), Vec3d(-1, 0.5, 1), 25.0), smooth},
        {"paraboloid", makeParaboloid(Vec3d(0, 0.3, -1), Vec3d(0.2, 1, 0.3), false, 1.0, 0.5), smooth},
        {"hyperbolic paraboloid", makeParaboloid(Vec3d(0.1, 0, 0), Vec3d(0, 0, 1), true, 0.8, 1.3),
         smooth},
        {"hyperboloid1", makeHyperboloid(Vec3d(0, 0, 0.5), Vec3d(1, 0, 1), false, Vec3d(1, 1, 0.7)),
         smooth},
        {"hyperboloid2", makeHyperboloid(Vec3d(0.3, 0, 0), Vec3d(0, 1, 0), true, Vec3d(0.9, 1.2, 0.6)),
         smooth},
    };
    const std::vector<Case> kids = {c[0], c[1], c[5]};
    for (auto op : {Csg::Op::Union, Csg::Op::Intersection, Csg::Op::Difference}) {
        std::vector<Ptr> ptrs = {sphere, box, c[5].f};
        const auto node = std::make_shared<Csg>(op, ptrs);
        c.push_back({node->typeName(), node, csgKink(op, kids)});
    }
    const Ptr xf = std::make_shared<Transform>(box, kXf.t, kXf.deg, kXf.s);
    c.push_back({"transform(box)", xf, [](const Vec3d& p) { return boxKink(kXf.toLocal(p)); }});
    const Ptr xcsg = std::make_shared<Transform>(c[12].f, Vec3d(1, 2, -1), Vec3d(-20, 10, 100),
                                                 Vec3d(0.9, 0.9, 0.9));
    c.push_back({"transform(union)", xcsg, smooth}); // only used where kinks do not matter
    return c;
}

/// @a cases and blends of every operation (no kink model: for the batch checks): super-elliptic
/// of two and three children, and the polynomial smooth CSG.
std::vector<Case> withBlends(std::vector<Case> cases)
{
    const Ptr sphere = std::make_shared<Sphere>(kSphereC, kSphereR);
    const Ptr box = std::make_shared<Box>(kBoxC, kBoxSize);
    const Ptr torus = std::make_shared<Torus>(kTorusC, kMajor, kMinor);
    for (auto op : {Csg::Op::Union, Csg::Op::Intersection, Csg::Op::Difference}) {
        cases.push_back({"blend2", std::make_shared<Blend>(op, 4.0, std::vector<Ptr>{sphere, box}),
                         nullptr});
        cases.push_back({"blend3", std::make_shared<Blend>(op, 30.0,
                                                           std::vector<Ptr>{sphere, box, torus}),
                         nullptr});
        cases.push_back({"smooth", std::make_shared<Blend>(op, BlendKernel::polynomial(0.3),
                                                           std::vector<Ptr>{sphere, torus}),
                         nullptr});
    }
    return cases;
}

} // namespace

class TestImplicit: public ::testing::Test
{
protected:
    void SetUp() override { openvdb::initialize(); }
    std::mt19937 rng{12345};
    double uniform(double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng); }
    Vec3d randomPoint(double lo = -4, double hi = 4)
    {
        return Vec3d(uniform(lo, hi), uniform(lo, hi), uniform(lo, hi));
    }
    Vec3d randomIn(const BBoxd& b)
    {
        return Vec3d(uniform(b.min()[0], b.max()[0]), uniform(b.min()[1], b.max()[1]),
                     uniform(b.min()[2], b.max()[2]));
    }
    BBoxd randomBox(double maxSize)
    {
        const Vec3d lo = randomPoint();
        return BBoxd(lo, lo + Vec3d(uniform(0.001, maxSize), uniform(0.001, maxSize),
                                    uniform(0.001, maxSize)));
    }
};

// ---- Values against closed forms ---------------------------------------------------------------

TEST_F(TestImplicit, PrimitiveValues)
{
    const Sphere sphere(kSphereC, kSphereR);
    const Box box(kBoxC, kBoxSize);
    const Torus torus(kTorusC, kMajor, kMinor);
    for (int k = 0; k < 500; ++k) {
        const Vec3d p = randomPoint();
        EXPECT_NEAR(sphere.value(p), refSphere(p, kSphereC, kSphereR), 1e-12) << p;
        EXPECT_NEAR(box.value(p), refBox(p, kBoxC, kBoxSize), 1e-12) << p;
        EXPECT_NEAR(torus.value(p), refTorus(p, kTorusC, kMajor, kMinor), 1e-12) << p;
    }
    // Points on the box surface and at its corners are at distance zero.
    EXPECT_NEAR(box.value(kBoxC + kBoxSize * 0.5), 0.0, 1e-15);
    EXPECT_NEAR(box.value(kBoxC - Vec3d(0, 0, 1.5)), 0.0, 1e-15);
    EXPECT_NEAR(box.value(kBoxC), -0.7, 1e-15); // nearest face is the y face (half size 0.7)
}

TEST_F(TestImplicit, RawQuadricValues)
{
    for (int m = 0; m < 4; ++m) {
        const Mat4 q = randomSymmetric(rng);
        const Quadric f(q);
        for (int k = 0; k < 200; ++k) {
            const Vec3d p = randomPoint();
            double scale;
            const double ref = refQuadric(q, p, &scale);
            EXPECT_NEAR(f.value(p), ref, 1e-13 * scale) << p;
        }
    }
}

TEST_F(TestImplicit, EllipsoidValues)
{
    const Vec3d c(0.5, -0.5, 0.2), r(2.0, 1.0, 1.5);
    const Ptr f = makeEllipsoid(c, r);
    for (int k = 0; k < 500; ++k) {
        const Vec3d p = randomPoint();
        const Vec3d d = p - c;
        const double ref = std::pow(d[0] / r[0], 2) + std::pow(d[1] / r[1], 2) +
                           std::pow(d[2] / r[2], 2) - 1.0;
        EXPECT_NEAR(f->value(p), ref, 1e-12 * (1 + std::abs(ref))) << p;
    }
}

/// Named quadrics are checked through their defining equation in a local frame: same sign away
/// from the surface, |f| < 1e-9 * scale on points built on the surface, and a gradient parallel
/// to the defining equation's gradient (f = lambda * equation with lambda > 0).
TEST_F(TestImplicit, NamedQuadricsMatchDefiningEquations)
{
    struct Named
    {
        std::string name;
        Ptr f;
        Vec3d origin;
        std::array<Vec3d, 3> frame;
        std::function<double(const Vec3d&)> eq;      // local defining equation, < 0 inside
        std::function<Vec3d(const Vec3d&)> eqGrad;   // its local gradient
        std::function<Vec3d(double, double)> onSurf; // local surface point from 2 parameters
    };
    const double ta = std::tan(25.0 * kPi / 180);
    const Vec3d axCyl(1, 1, 2), axCone(-1, 0.5, 1), axHyp(1, 0, 1), nPlane(1, -2, 0.5);
    const double pa = 0.8, pb = 1.3;
    const Vec3d h1(1, 1, 0.7), h2(0.9, 1.2, 0.6);
    // The hyperbolic paraboloid and two-sheet hyperboloid are not rotationally symmetric, so
    // their frame comes from frameFromAxis (checked independently in FrameFromAxis).
    const Vec3d axPara(0.2, 1, 0.3), axH2(0, 1, 0);
    std::vector<Named> cases = {
        {"plane", makePlane(nPlane, 0.7), nPlane * (0.7 / nPlane.lengthSqr()), someFrame(nPlane),
         [](const Vec3d& q) { return q[2]; }, [](const Vec3d&) { return Vec3d(0, 0, 1); },
         [](double s, double t) { return Vec3d(3 * s, 3 * t, 0); }},
        {"cylinder", makeCylinder(Vec3d(0.1, 0.2, 0.3), axCyl, 1.1), Vec3d(0.1, 0.2, 0.3),
         someFrame(axCyl), [](const Vec3d& q) { return q[0] * q[0] + q[1] * q[1] - 1.21; },
         [](const Vec3d& q) { return Vec3d(2 * q[0], 2 * q[1], 0); },
         [](double s, double t) { return Vec3d(1.1 * std::cos(7 * s), 1.1 * std::sin(7 * s), 3 * t); }},
        {"cone", makeCone(Vec3d(0.2, 0, -0.4), axCone, 25.0), Vec3d(0.2, 0, -0.4), someFrame(axCone),
         [=](const Vec3d& q) { return q[0] * q[0] + q[1] * q[1] - ta * ta * q[2] * q[2]; },
         [=](const Vec3d& q) { return Vec3d(2 * q[0], 2 * q[1], -2 * ta * ta * q[2]); },
         [=](double s, double t) {
             return Vec3d(ta * 3 * t * std::cos(7 * s), ta * 3 * t * std::sin(7 * s), 3 * t);
         }},
        {"paraboloid", makeParaboloid(Vec3d(0, 0.3, -1), axPara, false, 1.0, 1.0), Vec3d(0, 0.3, -1),
         someFrame(axPara),
         [](const Vec3d& q) { return q[0] * q[0] + q[1] * q[1] - q[2]; },
         [](const Vec3d& q) { return Vec3d(2 * q[0], 2 * q[1], -1); },
         [](double s, double t) { return Vec3d(2 * s, 2 * t, 4 * (s * s + t * t)); }},
        {"hyperbolic paraboloid", makeParaboloid(Vec3d(0.1, 0, 0), axPara, true, pa, pb),
         Vec3d(0.1, 0, 0), frameFromAxis(axPara),
         [=](const Vec3d& q) { return q[0] * q[0] / (pa * pa) - q[1] * q[1] / (pb * pb) - q[2]; },
         [=](const Vec3d& q) { return Vec3d(2 * q[0] / (pa * pa), -2 * q[1] / (pb * pb), -1); },
         [=](double s, double t) {
             return Vec3d(2 * s, 2 * t, 4 * (s * s / (pa * pa) - t * t / (pb * pb)));
         }},
        {"hyperboloid1", makeHyperboloid(Vec3d(0, 0, 0.5), axHyp, false, h1), Vec3d(0, 0, 0.5),
         someFrame(axHyp),
         [=](const Vec3d& q) { return q[0] * q[0] + q[1] * q[1] - q[2] * q[2] / 0.49 - 1; },
         [=](const Vec3d& q) { return Vec3d(2 * q[0], 2 * q[1], -2 * q[2] / 0.49); },
         [=](double s, double t) {
             const double z = 3 * t, w = std::sqrt(1 + z * z / 0.49);
             return Vec3d(w * std::cos(7 * s), w * std::sin(7 * s), z);
         }},
        {"hyperboloid2", makeHyperboloid(Vec3d(0.3, 0, 0), axH2, true, h2), Vec3d(0.3, 0, 0),
         frameFromAxis(axH2),
         [=](const Vec3d& q) {
             return std::pow(q[0] / h2[0], 2) + std::pow(q[1] / h2[1], 2) - std::pow(q[2] / h2[2], 2) + 1;
         },
         [=](const Vec3d& q) {
             return Vec3d(2 * q[0] / (h2[0] * h2[0]), 2 * q[1] / (h2[1] * h2[1]),
                          -2 * q[2] / (h2[2] * h2[2]));
         },
         [=](double s, double t) {
             const double x = 2 * s, y = 2 * t;
             const double z = h2[2] * std::sqrt(1 + std::pow(x / h2[0], 2) + std::pow(y / h2[1], 2));
             return Vec3d(x, y, s + t > 0 ? z : -z);
         }},
    };
    for (const Named& n : cases) {
        const auto* quadric = dynamic_cast<const Quadric*>(n.f.get());
        ASSERT_NE(quadric, nullptr) << n.name;
        double qmax = 0;
        for (const auto& row : quadric->matrix()) for (double v : row) qmax = std::max(qmax, std::abs(v));
        const auto toLocal = [&](const Vec3d& p) {
            const Vec3d d = p - n.origin;
            return Vec3d(d.dot(n.frame[0]), d.dot(n.frame[1]), d.dot(n.frame[2]));
        };
        const auto toWorld = [&](const Vec3d& q) {
            return n.origin + n.frame[0] * q[0] + n.frame[1] * q[1] + n.frame[2] * q[2];
        };
        int signChecks = 0;
        for (int k = 0; k < 300; ++k) {
            const Vec3d p = randomPoint();
            const Vec3d q = toLocal(p);
            const double e = n.eq(q);
            if (std::abs(e) > 1e-6) {
                ++signChecks;
                EXPECT_EQ(n.f->value(p) < 0, e < 0) << n.name << " at " << p;
            }
            const Vec3d g = n.f->gradient(p), ge = n.eqGrad(q);
            const Vec3d geWorld = n.frame[0] * ge[0] + n.frame[1] * ge[1] + n.frame[2] * ge[2];
            if (ge.length() > 1e-6) {
                EXPECT_NEAR(g.unit().dot(geWorld.unit()), 1.0, 1e-9) << n.name << " at " << p;
            }
            const Vec3d s = toWorld(n.onSurf(uniform(-1, 1), uniform(-1, 1)));
            EXPECT_LT(std::abs(n.f->value(s)), 1e-9 * qmax * (1 + s.lengthSqr())) << n.name << " " << s;
        }
        EXPECT_GE(signChecks, 250) << n.name;
    }
}

TEST_F(TestImplicit, TransformValues)
{
    // Rotated, translated, uniformly scaled sphere = sphere at t + s R c with radius s r.
    const Vec3d deg(30, -45, 70), t(0.5, -0.3, 0.8);
    const Ptr sphere = std::make_shared<Sphere>(kSphereC, kSphereR);
    const Transform uniformXf(sphere, t, deg, Vec3d(1.6));
    const Vec3d worldC = t + rotate(rotation(deg), kSphereC) * 1.6;
    // Non-uniformly scaled rotated box: min(s) * box(S^-1 R^T (p - t)); sign of the ellipsoid.
    const Ptr box = std::make_shared<Box>(kBoxC, kBoxSize);
    const Transform boxXf(box, kXf.t, kXf.deg, kXf.s);
    const Ptr unit = std::make_shared<Sphere>(Vec3d(0.0), 1.0);
    const Transform ellXf(unit, t, deg, Vec3d(2.0, 1.0, 0.5));
    const RefTransform ell{t, deg, Vec3d(2.0, 1.0, 0.5)};
    for (int k = 0; k < 500; ++k) {
        const Vec3d p = randomPoint();
        EXPECT_NEAR(uniformXf.value(p), refSphere(p, worldC, 1.6 * kSphereR), 1e-12) << p;
        EXPECT_NEAR(boxXf.value(p), kXf.valueScale() * refBox(kXf.toLocal(p), kBoxC, kBoxSize), 1e-12)
            << p;
        const Vec3d q = ell.toLocal(p);
        const double e = q.lengthSqr() - 1; // (x/a)^2 + (y/b)^2 + (z/c)^2 - 1 in the rotated frame
        EXPECT_NEAR(ellXf.value(p), 0.5 * (std::sqrt(e + 1) - 1), 1e-12) << p;
        if (std::abs(e) > 1e-9) {
            EXPECT_EQ(ellXf.value(p) < 0, e < 0) << p;
        }
        // toWorld inverts toLocal.
        expectVecNear(boxXf.toWorld(boxXf.toLocal(p)), p, 1e-12, "round trip");
    }
}

TEST_F(TestImplicit, CsgValues)
{
    const Ptr a = std::make_shared<Sphere>(kSphereC, kSphereR);
    const Ptr b = std::make_shared<Box>(kBoxC, kBoxSize);
    const Ptr c = std::make_shared<Torus>(kTorusC, kMajor, kMinor);
    const Csg u(Csg::Op::Union, {a, b, c}), i(Csg::Op::Intersection, {a, b, c}),
        d(Csg::Op::Difference, {a, b, c});
    for (int k = 0; k < 500; ++k) {
        const Vec3d p = randomPoint();
        const double va = refSphere(p, kSphereC, kSphereR), vb = refBox(p, kBoxC, kBoxSize),
                     vc = refTorus(p, kTorusC, kMajor, kMinor);
        EXPECT_NEAR(u.value(p), std::min({va, vb, vc}), 1e-12);
        EXPECT_NEAR(i.value(p), std::max({va, vb, vc}), 1e-12);
        EXPECT_NEAR(d.value(p), std::max({va, -vb, -vc}), 1e-12);
    }
}

// ---- Gradients ---------------------------------------------------------------------------------

TEST_F(TestImplicit, AnalyticGradients)
{
    const Sphere sphere(kSphereC, kSphereR);
    const Box box(kBoxC, kBoxSize);
    const Torus torus(kTorusC, kMajor, kMinor);
    const Mat4 q = randomSymmetric(rng);
    const Quadric quadric(q);
    const Vec3d deg(30, -45, 70), t(0.5, -0.3, 0.8);
    const Transform xf(std::make_shared<Sphere>(kSphereC, kSphereR), t, deg, Vec3d(1.6));
    const Vec3d worldC = t + rotate(rotation(deg), kSphereC) * 1.6;
    const Csg diff(Csg::Op::Difference, {std::make_shared<Box>(kBoxC, kBoxSize),
                                         std::make_shared<Sphere>(kSphereC, kSphereR)});
    for (int k = 0; k < 300; ++k) {
        const Vec3d p = randomPoint();
        expectVecNear(sphere.gradient(p), (p - kSphereC).unit(), 1e-12, "sphere");
        if (!boxKink(p)) {
            expectVecNear(box.gradient(p), refBoxGradient(p, kBoxC, kBoxSize), 1e-12, "box");
            const double vb = refBox(p, kBoxC, kBoxSize), vs = -refSphere(p, kSphereC, kSphereR);
            if (std::abs(vb - vs) > 1e-3) {
                const Vec3d ref = vb > vs ? refBoxGradient(p, kBoxC, kBoxSize) : -(p - kSphereC).unit();
                expectVecNear(diff.gradient(p), ref, 1e-12, "difference");
            }
        }
        const Vec3d core = torusCorePoint(p, kTorusC, kMajor);
        expectVecNear(torus.gradient(p), (p - core).unit(), 1e-12, "torus");
        expectVecNear(quadric.gradient(p), refQuadricGradient(q, p), 1e-12, "quadric");
        expectVecNear(xf.gradient(p), (p - worldC).unit(), 1e-12, "transform");
    }
}

TEST_F(TestImplicit, GradientsMatchCentralDifferences)
{
    for (const Case& c : allCases()) {
        if (c.name == "transform(union)") continue; // its kinks are not modelled
        int checked = 0;
        for (int k = 0; k < 400; ++k) {
            const Vec3d p = randomPoint();
            if (c.nearKink(p)) continue;
            ++checked;
            const Vec3d g = c.f->gradient(p);
            expectVecNear(g, centralDifference(*c.f, p), 1e-5 * std::max(1.0, g.length()), c.name);
        }
        EXPECT_GE(checked, 200) << c.name;
    }
}

// ---- Batches and intervals ---------------------------------------------------------------------

TEST_F(TestImplicit, BatchValuesMatchValueBitForBit)
{
    for (const Case& c : allCases()) {
        for (std::size_t n : {std::size_t(1), std::size_t(37), kMaxBatch}) {
            std::vector<double> x(n), y(n), z(n), out(n);
            for (std::size_t i = 0; i < n; ++i) {
                x[i] = uniform(-4, 4);
                y[i] = uniform(-4, 4);
                z[i] = uniform(-4, 4);
            }
            c.f->values(x.data(), y.data(), z.data(), out.data(), n);
            for (std::size_t i = 0; i < n; ++i) {
                EXPECT_EQ(out[i], c.f->value(Vec3d(x[i], y[i], z[i]))) << c.name << " i=" << i;
            }
        }
    }
}

TEST_F(TestImplicit, BatchGradientsAndTheFusedCallMatchBitForBit)
{
    // gradients() equals gradient() at each point, and valuesAndGradients() equals values() and
    // gradients(), bit for bit: for every node, and for blends of every operation (the
    // super-elliptic kernel's own fused loop shares the exponentials).
    for (const Case& c : withBlends(allCases())) {
        for (std::size_t n : {std::size_t(1), std::size_t(37), kMaxBatch}) {
            std::vector<double> x(n), y(n), z(n), gx(n), gy(n), gz(n), v(n), fv(n), fx(n),
                fy(n), fz(n);
            for (std::size_t i = 0; i < n; ++i) {
                x[i] = uniform(-4, 4);
                y[i] = uniform(-4, 4);
                z[i] = uniform(-4, 4);
            }
            // A point at the sphere's centre, where its gradient is a convention.
            x[0] = kSphereC[0], y[0] = kSphereC[1], z[0] = kSphereC[2];
            c.f->gradients(x.data(), y.data(), z.data(), gx.data(), gy.data(), gz.data(), n);
            c.f->values(x.data(), y.data(), z.data(), v.data(), n);
            c.f->valuesAndGradients(x.data(), y.data(), z.data(), fv.data(), fx.data(), fy.data(),
                                    fz.data(), n);
            for (std::size_t i = 0; i < n; ++i) {
                const Vec3d g = c.f->gradient(Vec3d(x[i], y[i], z[i]));
                ASSERT_EQ(gx[i], g[0]) << c.name << " i=" << i;
                ASSERT_EQ(gy[i], g[1]) << c.name << " i=" << i;
                ASSERT_EQ(gz[i], g[2]) << c.name << " i=" << i;
                ASSERT_EQ(fv[i], v[i]) << c.name << " i=" << i;
                ASSERT_EQ(fx[i], gx[i]) << c.name << " i=" << i;
                ASSERT_EQ(fy[i], gy[i]) << c.name << " i=" << i;
                ASSERT_EQ(fz[i], gz[i]) << c.name << " i=" << i;
            }
        }
    }
}

TEST_F(TestImplicit, ValuesAndFootPointsMatchTheTwoCallsBitForBit)
{
    // valuesAndFootPoints() (one evaluation of a blend's children for the values, the lead rule
    // and the iteration's start) gives values() and then footPoints() of those values, bit for
    // bit: for every node and for blends of every operation and both kernels. Without foot
    // points asked for (what the rasterizer asks; a blend then evaluates its children's
    // gradients only where it iterates), the same distances and certificates as with them.
    FootQuery query;
    query.tolerance = 1e-6;
    query.far = 0.5;
    FootQuery noFeet = query;
    noFeet.feet = false;
    for (const Case& c : withBlends(allCases())) {
        for (std::size_t n : {std::size_t(1), std::size_t(37), kMaxBatch}) {
            std::vector<double> x(n), y(n), z(n), v(n), fv(n);
            for (std::size_t i = 0; i < n; ++i) {
                x[i] = uniform(-4, 4);
                y[i] = uniform(-4, 4);
                z[i] = uniform(-4, 4);
            }
            auto two = std::make_unique<FootPoints>(), one = std::make_unique<FootPoints>();
            c.f->values(x.data(), y.data(), z.data(), v.data(), n);
            c.f->footPoints(x.data(), y.data(), z.data(), v.data(), n, query, *two);
            c.f->valuesAndFootPoints(x.data(), y.data(), z.data(), n, query, fv.data(), *one);
            for (std::size_t i = 0; i < n; ++i) {
                ASSERT_EQ(fv[i], v[i]) << c.name << " i=" << i;
                ASSERT_EQ(one->ok[i], two->ok[i]) << c.name << " i=" << i;
                ASSERT_EQ(one->distance[i], two->distance[i]) << c.name << " i=" << i;
                ASSERT_EQ(one->x[i], two->x[i]) << c.name << " i=" << i;
                ASSERT_EQ(one->y[i], two->y[i]) << c.name << " i=" << i;
                ASSERT_EQ(one->z[i], two->z[i]) << c.name << " i=" << i;
            }
            auto bare = std::make_unique<FootPoints>(), both = std::make_unique<FootPoints>();
            c.f->footPoints(x.data(), y.data(), z.data(), v.data(), n, noFeet, *bare);
            c.f->valuesAndFootPoints(x.data(), y.data(), z.data(), n, noFeet, fv.data(), *both);
            for (std::size_t i = 0; i < n; ++i) {
                ASSERT_EQ(fv[i], v[i]) << c.name << " i=" << i;
                ASSERT_EQ(bare->ok[i], two->ok[i]) << c.name << " i=" << i;
                ASSERT_EQ(bare->distance[i], two->distance[i]) << c.name << " i=" << i;
                ASSERT_EQ(both->ok[i], two->ok[i]) << c.name << " i=" << i;
                ASSERT_EQ(both->distance[i], two->distance[i]) << c.name << " i=" << i;
            }
        }
    }
}

TEST_F(TestImplicit, LipschitzNodesCertifyFarPointsFromTheirValue)
{
    // A blend of exact SDFs and a non-uniform scale of one are 1-Lipschitz, so where |f| >= far
    // a point is at least |f| from the surface and footPoints() certifies it from the value
    // alone (the rasterizer then only needs "farther than the band"). Checked independently:
    // the field is 1-Lipschitz on random pairs; no sign change lies within |f| of such a point,
    // along 32 rays from it; and every nearer certified distance is the
    // generic smooth iteration's (Implicit::footPoints: no lead rule, no Lipschitz bound)
    // within 1e-5, where that certifies the point too.
    const Ptr a = std::make_shared<Sphere>(Vec3d(-0.35, 0.0, 0.0), 0.6),
              b = std::make_shared<Sphere>(Vec3d(0.35, 0.1, 0.0), 0.6),
              c = std::make_shared<Box>(Vec3d(0.0, 0.3, 0.2), Vec3d(0.5, 0.7, 0.9));
    std::vector<std::pair<std::string, Ptr>> nodes;
    for (auto op : {Csg::Op::Union, Csg::Op::Intersection, Csg::Op::Difference}) {
        for (const BlendKernel& kernel :
             {BlendKernel::superElliptic(1.0), BlendKernel::superElliptic(4.0),
              BlendKernel::superElliptic(50.0), BlendKernel::polynomial(0.1),
              BlendKernel::polynomial(0.5)}) {
            const auto node = std::make_shared<Blend>(op, kernel, std::vector<Ptr>{a, b, c});
            nodes.push_back({node->typeName() + " " + kernel.describe(), node});
        }
    }
    nodes.push_back({"scaled sphere", std::make_shared<Transform>(a, Vec3d(0.1, 0, 0), Vec3d(10, 20, 30),
                                                                  Vec3d(1.4, 0.6, 1.0))});
    // A scaled torus iterates (a scaled sphere or box takes its exact surface's route, with
    // the rule only where that leaves a point uncertified).
    nodes.push_back({"scaled torus", std::make_shared<Transform>(std::make_shared<Torus>(Vec3d(0.0, 0.1, 0.0), 0.7, 0.25),
                                                                 Vec3d(0, -0.1, 0), Vec3d(-30, 5, 60),
                                                                 Vec3d(0.7, 1.3, 1.1))});
    nodes.push_back({"scaled box", std::make_shared<Transform>(c, Vec3d(0, -0.1, 0), Vec3d(-30, 5, 60),
                                                               Vec3d(0.7, 1.3, 1.1))});
    FootQuery query;
    query.tolerance = 1e-6;
    query.far = 0.15;
    const std::size_t n = kMaxBatch;
    std::vector<double> x(n), y(n), z(n), v(n);
    auto feet = std::make_unique<FootPoints>(), ref = std::make_unique<FootPoints>();
    std::normal_distribution<double> normal(0.0, 1.0);
    auto direction = [&] {
        Vec3d d(normal(rng), normal(rng), normal(rng));
        while (d.length() < 1e-6) d = Vec3d(normal(rng), normal(rng), normal(rng));
        return d / d.length();
    };
    std::vector<Vec3d> dirs;
    for (int k = 0; k < 32; ++k) dirs.push_back(direction());
    int near = 0; // over all nodes: some blends of small p leave little or no surface
    for (const auto& [what, f] : nodes) {
        double worstRatio = 0.0;
        for (int i = 0; i < 2000; ++i) {
            const Vec3d p(uniform(-1.6, 1.6), uniform(-1.6, 1.6), uniform(-1.6, 1.6));
            const Vec3d q = p + direction() * uniform(1e-3, 0.3);
            worstRatio = std::max(worstRatio, std::abs(f->value(q) - f->value(p)) / (q - p).length());
        }
        EXPECT_LE(worstRatio, 1.0 + 1e-9) << what;
        int far = 0;
        for (int batch = 0; batch < 4; ++batch) {
            // Half the points anywhere, half within about far of the surface (a random point's
            // first-order projection, moved along the normal).
            for (std::size_t i = 0; i < n; ++i) {
                Vec3d p(uniform(-1.6, 1.6), uniform(-1.6, 1.6), uniform(-1.6, 1.6));
                const Vec3d g = f->gradient(p);
                if (i % 2 && g.lengthSqr() > 0.01) {
                    p -= g * (f->value(p) / g.lengthSqr());
                    p += g * (uniform(-1.0, 1.0) * query.far / g.length());
                }
                x[i] = p[0], y[i] = p[1], z[i] = p[2];
            }
            f->values(x.data(), y.data(), z.data(), v.data(), n);
            f->footPoints(x.data(), y.data(), z.data(), v.data(), n, query, *feet);
            f->Implicit::footPoints(x.data(), y.data(), z.data(), v.data(), n, query, *ref);
            for (std::size_t i = 0; i < n; ++i) {
                const double d = feet->distance[i];
                if (std::abs(v[i]) >= query.far) {
                    ASSERT_TRUE(feet->ok[i]) << what << " f=" << v[i];
                }
                if (!feet->ok[i]) continue;
                ASSERT_EQ(d > 0.0, v[i] > 0.0) << what;
                if (std::abs(d) < query.far) {
                    // Where the generic iteration certifies the point too (it stops short of
                    // some near the box's edges, where the lead rule does not).
                    if (!ref->ok[i]) continue;
                    ++near;
                    const Vec3d p(x[i], y[i], z[i]);
                    if (what == "scaled box" ||
                        f->mayKinkWithin(p, std::abs(ref->distance[i]) + query.tolerance)) {
                        // The scaled box's exact distance (its own closed form is checked in
                        // tests/raster/TestTrueDistances.cc), or a blend's near a kink of the
                        // box's distance (from its sheets): at least |f| (1-Lipschitz), and no
                        // farther than the iteration's certified surface point, which near the
                        // box's inner medial planes can be a farther local answer (2.4e-5
                        // farther, smooth k = 0.1); a sheet's point is on the surface within the
                        // tolerance.
                        ASSERT_GE(std::abs(d), std::abs(v[i]) - (what == "scaled box" ? 1e-12 : query.tolerance))
                            << what;
                        ASSERT_LE(std::abs(d), std::abs(ref->distance[i]) + 1e-5) << what;
                        continue;
                    }
                    ASSERT_NEAR(d, ref->distance[i], 1e-5) << what << " f=" << v[i];
                    continue;
                }
                // Reported as far from |f| >= far: no surface within |f| (the Lipschitz
                // bound), short of it by twice the tolerance, which a led distance may have.
                // (The others reported as far are local answers of the iteration, which near a
                // medial axis can miss a nearer part of the surface.)
                if (std::abs(v[i]) < query.far) continue;
                ++far;
                const Vec3d p(x[i], y[i], z[i]);
                const double reach = std::abs(v[i]) - 2.0 * query.tolerance;
                for (const Vec3d& dir : dirs) {
                    for (int s = 1; s <= 16; ++s) {
                        ASSERT_EQ(f->value(p + dir * (reach * s / 16.0)) > 0.0, v[i] > 0.0)
                            << what << ": a sign change within " << reach << " of " << p;
                    }
                }
            }
        }
        EXPECT_GE(far, 100) << what;
    }
    EXPECT_GE(near, 1000);
}

TEST_F(TestImplicit, IntervalContainsValues)
{
    // Intervals are not outward-rounded (documented), so allow rounding slack of 1e-12 relative.
    for (const Case& c : allCases()) {
        int points = 0;
        for (int b = 0; b < 120; ++b) {
            const BBoxd box = randomBox(b % 2 ? 0.2 : 3.0);
            const Interval iv = c.f->interval(box);
            ASSERT_LE(iv.lo, iv.hi) << c.name;
            for (int k = 0; k < 17; ++k, ++points) {
                // The 8 corners, then random interior points.
                const Vec3d p = k < 8 ? Vec3d(k & 1 ? box.max()[0] : box.min()[0],
                                              k & 2 ? box.max()[1] : box.min()[1],
                                              k & 4 ? box.max()[2] : box.min()[2])
                                      : randomIn(box);
                const double v = c.f->value(p), slack = 1e-12 * (1 + std::abs(v));
                EXPECT_TRUE(iv.lo - slack <= v && v <= iv.hi + slack)
                    << c.name << ": " << v << " not in [" << iv.lo << ", " << iv.hi << "] at " << p;
            }
        }
        EXPECT_GE(points, 1000);
    }
}

TEST_F(TestImplicit, BatchIntervalsAgreeWithIntervalAndContainValues)
{
    // intervals() over boxes of one size (the loops of quadrics, spheres and blends, the default
    // elsewhere) equals interval() per box up to rounding, and so contains the values in each box.
    for (const Case& c : withBlends(allCases())) {
        for (double size : {0.01, 0.2, 3.0}) {
            const Vec3d half(0.5 * size, 0.3 * size, 0.7 * size);
            std::vector<double> x(kMaxBatch), y(kMaxBatch), z(kMaxBatch), lo(kMaxBatch),
                hi(kMaxBatch);
            for (std::size_t i = 0; i < kMaxBatch; ++i) {
                x[i] = uniform(-4, 4);
                y[i] = uniform(-4, 4);
                z[i] = uniform(-4, 4);
            }
            c.f->intervals(x.data(), y.data(), z.data(), half, kMaxBatch, lo.data(), hi.data());
            for (std::size_t i = 0; i < kMaxBatch; ++i) {
                const Vec3d m(x[i], y[i], z[i]);
                const BBoxd box(m - half, m + half);
                const Interval iv = c.f->interval(box);
                const double scale = 1e-12 * (1.0 + std::abs(iv.lo) + std::abs(iv.hi));
                ASSERT_NEAR(lo[i], iv.lo, scale) << c.name << " size " << size << " i=" << i;
                ASSERT_NEAR(hi[i], iv.hi, scale) << c.name << " size " << size << " i=" << i;
                for (int k = 0; k < 8; ++k) {
                    const Vec3d p = k < 4 ? randomIn(box)
                                          : Vec3d(k & 1 ? box.max()[0] : box.min()[0],
                                                  k & 2 ? box.max()[1] : box.min()[1],
                                                  box.max()[2]);
                    const double v = c.f->value(p), slack = 1e-12 * (1 + std::abs(v));
                    ASSERT_TRUE(lo[i] - slack <= v && v <= hi[i] + slack)
                        << c.name << ": " << v << " not in [" << lo[i] << ", " << hi[i] << "]";
                }
            }
        }
    }
}

TEST_F(TestImplicit, SphereIntervalIsTight)
{
    const Sphere sphere(kSphereC, kSphereR);
    for (int b = 0; b < 300; ++b) {
        const BBoxd box = randomBox(b % 2 ? 0.5 : 4.0);
        const Interval iv = sphere.interval(box);
        double far = -std::numeric_limits<double>::max();
        for (int k = 0; k < 8; ++k) {
            const Vec3d corner(k & 1 ? box.max()[0] : box.min()[0], k & 2 ? box.max()[1] : box.min()[1],
                               k & 4 ? box.max()[2] : box.min()[2]);
            far = std::max(far, refSphere(corner, kSphereC, kSphereR));
        }
        Vec3d nearest;
        for (int i = 0; i < 3; ++i)
            nearest[i] = std::min(std::max(kSphereC[i], box.min()[i]), box.max()[i]);
        EXPECT_NEAR(iv.hi, far, 1e-12);
        EXPECT_NEAR(iv.lo, refSphere(nearest, kSphereC, kSphereR), 1e-12);
    }
}

// ---- Bounds and exactness ----------------------------------------------------------------------

void expectBoxNear(const BBoxd& a, const Vec3d& lo, const Vec3d& hi, double tol, const std::string& w)
{
    expectVecNear(a.min(), lo, tol, w + " min");
    expectVecNear(a.max(), hi, tol, w + " max");
}

TEST_F(TestImplicit, BoundingBoxes)
{
    const Vec3d c(0.5, -1.5, 2.0);
    expectBoxNear(Sphere(c, 1.5).boundingBox(), c - Vec3d(1.5), c + Vec3d(1.5), 1e-15, "sphere");
    expectBoxNear(Box(c, Vec3d(1, 2, 3)).boundingBox(), c - Vec3d(0.5, 1, 1.5),
                  c + Vec3d(0.5, 1, 1.5), 1e-15, "box");
    expectBoxNear(Torus(c, 2.0, 0.5).boundingBox(), c - Vec3d(2.5, 2.5, 0.5),
                  c + Vec3d(2.5, 2.5, 0.5), 1e-15, "torus");
    expectBoxNear(makeEllipsoid(c, Vec3d(1, 2, 3))->boundingBox(), c - Vec3d(1, 2, 3),
                  c + Vec3d(1, 2, 3), 1e-12, "ellipsoid");

    // A rotated, translated ellipsoid given as a raw matrix Q = M^T diag(1/a^2, 1/b^2, 1/c^2, -1) M
    // with M = [[R^T, -R^T c], [0, 1]]; its box half-extents are sqrt(sum_j R_ij^2 r_j^2).
    for (int k = 0; k < 20; ++k) {
        const Vec3d center = randomPoint(-3, 3), r(uniform(0.2, 3), uniform(0.2, 3), uniform(0.2, 3));
        const Mat3 rot = rotation(Vec3d(uniform(-180, 180), uniform(-180, 180), uniform(-180, 180)));
        double m[4][4] = {};
        for (int i = 0; i < 3; ++i) {
            for (int j = 0; j < 3; ++j) m[i][j] = rot[j][i];
            m[i][3] = -(rot[0][i] * center[0] + rot[1][i] * center[1] + rot[2][i] * center[2]);
        }
        m[3][3] = 1;
        const double d[4] = {1 / (r[0] * r[0]), 1 / (r[1] * r[1]), 1 / (r[2] * r[2]), -1};
        Mat4 q{};
        for (int i = 0; i < 4; ++i)
            for (int j = 0; j < 4; ++j)
                for (int l = 0; l < 4; ++l) q[i][j] += m[l][i] * d[l] * m[l][j];
        for (int i = 0; i < 4; ++i)
            for (int j = i + 1; j < 4; ++j) q[i][j] = q[j][i] = 0.5 * (q[i][j] + q[j][i]);
        const Quadric f(q);
        Vec3d half;
        for (int i = 0; i < 3; ++i) {
            half[i] = std::sqrt(std::pow(rot[i][0] * r[0], 2) + std::pow(rot[i][1] * r[1], 2) +
                                std::pow(rot[i][2] * r[2], 2));
        }
        EXPECT_TRUE(f.isBounded());
        EXPECT_FALSE(f.isEmpty());
        expectBoxNear(f.boundingBox(), center - half, center + half, 1e-9, "rotated ellipsoid");
    }
    Mat4 empty{};
    empty[0][0] = empty[1][1] = empty[2][2] = empty[3][3] = 1; // x^2 + y^2 + z^2 + 1 > 0
    EXPECT_TRUE(Quadric(empty).isEmpty());

    const Ptr cyl = makeCylinder(Vec3d(0), Vec3d(0, 0, 1), 1.0);
    EXPECT_FALSE(cyl->isBounded());
    EXPECT_FALSE(makeCone(Vec3d(0), Vec3d(1, 0, 0), 30)->isBounded());
    EXPECT_FALSE(makeParaboloid(Vec3d(0), Vec3d(0, 1, 0), false, 1, 1)->isBounded());
    EXPECT_FALSE(makeParaboloid(Vec3d(0), Vec3d(0, 1, 0), true, 1, 1)->isBounded());
    EXPECT_FALSE(makeHyperboloid(Vec3d(0), Vec3d(0, 0, 1), false, Vec3d(1))->isBounded());
    EXPECT_FALSE(makeHyperboloid(Vec3d(0), Vec3d(0, 0, 1), true, Vec3d(1))->isBounded());
    EXPECT_FALSE(makePlane(Vec3d(0, 0, 1), 0)->isBounded());

    const Ptr sphere = std::make_shared<Sphere>(c, 1.5);
    const Ptr box = std::make_shared<Box>(Vec3d(0), Vec3d(4, 4, 4));
    expectBoxNear(Csg(Csg::Op::Difference, {sphere, cyl}).boundingBox(), c - Vec3d(1.5),
                  c + Vec3d(1.5), 0, "difference");
    EXPECT_FALSE(Csg(Csg::Op::Difference, {cyl, sphere}).isBounded());
    expectBoxNear(Csg(Csg::Op::Intersection, {cyl, box}).boundingBox(), Vec3d(-2), Vec3d(2), 0,
                  "intersection");
    expectBoxNear(Csg(Csg::Op::Union, {sphere, box}).boundingBox(), Vec3d(-2, -3, -2),
                  Vec3d(2, 2, 3.5), 0, "union");
    EXPECT_FALSE(Csg(Csg::Op::Union, {sphere, cyl}).isBounded());

    // Translated, uniformly scaled sphere: exact box; rotated shapes: every inside point in the box.
    expectBoxNear(Transform(sphere, Vec3d(1, 2, 3), Vec3d(0), Vec3d(2)).boundingBox(),
                  Vec3d(1, 2, 3) + c * 2 - Vec3d(3), Vec3d(1, 2, 3) + c * 2 + Vec3d(3), 1e-12,
                  "transform");
    EXPECT_FALSE(Transform(cyl, Vec3d(1), Vec3d(10), Vec3d(1)).isBounded());
    for (const Case& cs : allCases()) {
        if (!cs.f->isBounded()) continue;
        const BBoxd bb = cs.f->boundingBox();
        const BBoxd around(bb.min() - Vec3d(0.5), bb.max() + Vec3d(0.5));
        int inside = 0;
        for (int k = 0; k < 2000; ++k) {
            const Vec3d p = randomIn(around);
            if (cs.f->value(p) < 0) {
                ++inside;
                EXPECT_TRUE(bb.isInside(p)) << cs.name << " " << p;
            }
        }
        EXPECT_GT(inside, 100) << cs.name;
    }
}

TEST_F(TestImplicit, IsExactSdf)
{
    const Ptr sphere = std::make_shared<Sphere>(Vec3d(0), 1.0);
    const Ptr box = std::make_shared<Box>(Vec3d(0), Vec3d(1));
    EXPECT_TRUE(sphere->isExactSdf());
    EXPECT_TRUE(box->isExactSdf());
    EXPECT_TRUE(Torus(Vec3d(0), 2, 1).isExactSdf());
    EXPECT_TRUE(makePlane(Vec3d(3, -1, 2), 0.4)->isExactSdf());
    EXPECT_TRUE(Transform(sphere, Vec3d(1), Vec3d(10, 20, 30), Vec3d(2.5)).isExactSdf());
    EXPECT_FALSE(makeCylinder(Vec3d(0), Vec3d(0, 0, 1), 1)->isExactSdf());
    EXPECT_FALSE(makeEllipsoid(Vec3d(0), Vec3d(1))->isExactSdf());
    EXPECT_FALSE(makeCone(Vec3d(0), Vec3d(0, 0, 1), 30)->isExactSdf());
    EXPECT_FALSE(makeParaboloid(Vec3d(0), Vec3d(0, 0, 1), false, 1, 1)->isExactSdf());
    EXPECT_FALSE(makeHyperboloid(Vec3d(0), Vec3d(0, 0, 1), false, Vec3d(1))->isExactSdf());
    EXPECT_FALSE(Csg(Csg::Op::Union, {sphere, box}).isExactSdf());
    EXPECT_FALSE(Csg(Csg::Op::Intersection, {sphere, box}).isExactSdf());
    EXPECT_FALSE(Csg(Csg::Op::Difference, {sphere, box}).isExactSdf());
    EXPECT_FALSE(Transform(sphere, Vec3d(0), Vec3d(0), Vec3d(1, 2, 1)).isExactSdf());
    Mat4 linear{};
    linear[0][3] = linear[3][0] = 1.0; // f = 2x: the right zero set, but twice the distance
    EXPECT_FALSE(Quadric(linear).isExactSdf());
    linear[0][3] = linear[3][0] = 0.5; // f = x
    EXPECT_TRUE(Quadric(linear).isExactSdf());

    // A plane really is a distance: |f| equals the distance to its nearest point.
    const Ptr plane = makePlane(Vec3d(3, -1, 2), 0.4);
    const Vec3d n = Vec3d(3, -1, 2).unit();
    for (int k = 0; k < 200; ++k) {
        const Vec3d p = randomPoint();
        EXPECT_NEAR(plane->value(p), n.dot(p) - 0.4 / std::sqrt(14.0), 1e-12);
    }
}

TEST_F(TestImplicit, IsDistanceBoundWhereTheFieldIs1Lipschitz)
{
    // isDistanceBound() lets the rasterizer skip every voxel with |f| >= band without finding
    // its distance: it must hold only where f is 1-Lipschitz. Checked on random pairs of points
    // (|f(p) - f(q)| <= |p - q|) for every node that claims it; the nodes that do not claim it
    // here are not 1-Lipschitz, and the same check finds a pair that shows it.
    const Ptr a = std::make_shared<Sphere>(Vec3d(-0.35, 0.0, 0.0), 0.6),
              b = std::make_shared<Sphere>(Vec3d(0.35, 0.1, 0.0), 0.6),
              box = std::make_shared<Box>(Vec3d(0.0, 0.3, 0.2), Vec3d(0.5, 0.7, 0.9));
    const Ptr quadric = makeEllipsoid(Vec3d(0.1, 0.0, 0.0), Vec3d(1.0, 0.8, 0.6));
    const Ptr onion = std::make_shared<Csg>(Csg::Op::Difference, std::vector<Ptr>{a, b, box});
    const Ptr blend = std::make_shared<Blend>(Csg::Op::Union, 20.0, std::vector<Ptr>{a, b, box});
    const Ptr smooth = std::make_shared<Blend>(Csg::Op::Intersection, BlendKernel::polynomial(0.3),
                                               std::vector<Ptr>{a, box});
    const Vec3d squash(1.4, 0.6, 1.0);
    const std::vector<std::pair<std::string, Ptr>> bounds = {
        {"sphere", a},
        {"box", box},
        {"difference", onion},
        {"blend", blend},
        {"smooth", smooth},
        {"scaled sphere", std::make_shared<Transform>(a, Vec3d(0.1, 0, 0), Vec3d(10, 20, 30), squash)},
        {"scaled blend", std::make_shared<Transform>(blend, Vec3d(0), Vec3d(-30, 5, 60), squash)},
        {"offset of a difference", std::make_shared<Offset>(onion, -0.05)},
        {"shell of a smooth CSG", std::make_shared<Shell>(smooth, 0.1)},
        {"blend of scaled spheres", std::make_shared<Blend>(
            Csg::Op::Union, 8.0, std::vector<Ptr>{std::make_shared<Transform>(a, Vec3d(0), Vec3d(0), squash),
                                                  std::make_shared<Transform>(b, Vec3d(0), Vec3d(0), squash)})},
    };
    const std::vector<std::pair<std::string, Ptr>> others = {
        {"ellipsoid", quadric},
        {"scaled ellipsoid", std::make_shared<Transform>(quadric, Vec3d(0), Vec3d(0), squash)},
        {"union with an ellipsoid", std::make_shared<Csg>(Csg::Op::Union, std::vector<Ptr>{a, quadric})},
        {"blend with an ellipsoid", std::make_shared<Blend>(Csg::Op::Union, 20.0, std::vector<Ptr>{a, quadric})},
        {"offset of an ellipsoid", std::make_shared<Offset>(quadric, 0.1)},
    };
    auto worstRatio = [&](const Implicit& f) {
        double worst = 0.0;
        for (int i = 0; i < 20000; ++i) {
            const Vec3d p(uniform(-1.6, 1.6), uniform(-1.6, 1.6), uniform(-1.6, 1.6));
            const Vec3d q = p + Vec3d(uniform(-0.2, 0.2), uniform(-0.2, 0.2), uniform(-0.2, 0.2));
            if ((q - p).length() < 1e-6) continue;
            worst = std::max(worst, std::abs(f.value(q) - f.value(p)) / (q - p).length());
        }
        return worst;
    };
    for (const auto& [what, f] : bounds) {
        EXPECT_TRUE(f->isDistanceBound()) << what;
        EXPECT_EQ(f->lipschitzBound(), 1.0) << what;
        EXPECT_LE(worstRatio(*f), 1.0 + 1e-9) << what;
        // And so is its pruned node, which the rasterizer evaluates.
        const Ptr pruned = f->prune(BBoxd(Vec3d(-0.2, -0.1, 0.0), Vec3d(0.1, 0.2, 0.3)));
        EXPECT_TRUE(pruned->isDistanceBound()) << what;
    }
    for (const auto& [what, f] : others) {
        EXPECT_FALSE(f->isDistanceBound()) << what;
        EXPECT_GT(worstRatio(*f), 1.05) << what;
    }
}

TEST_F(TestImplicit, DistanceFactorBoundsTheDistanceByTheValue)
{
    // distanceFactor() K: every point within K |f| of the surface, outside and inside. An
    // exact SDF 1; a sphere scaled by (1.5, 1, 0.75) (an ellipsoid, its field
    // 0.75 (|S^-1 (p - t)| - r)) 2, and the point q = t + (p - t) r / |S^-1 (p - t)| on its
    // surface within K |f| of p at 20,000 random points (near and far, inside and out); scaled
    // again by 2 uniformly and rotated, still 2; a union of exact SDFs 1 outside (its value the
    // distance) but not inside (a point deep in one child may be far from the union's surface),
    // an intersection and a difference the other way round, and not for a union of the scaled
    // sphere; shapes with no known factor (a quadric, a blend) infinite.
    const auto sphere = std::make_shared<Sphere>(Vec3d(0.0), 0.4);
    EXPECT_EQ(sphere->distanceFactor(true), 1.0);
    EXPECT_EQ(sphere->distanceFactor(false), 1.0);
    const Vec3d t(0.1, -0.2, 0.05), scale(1.5, 1.0, 0.75);
    const auto scaled = std::make_shared<Transform>(sphere, t, Vec3d(0.0), scale);
    EXPECT_DOUBLE_EQ(scaled->distanceFactor(true), 2.0);
    EXPECT_DOUBLE_EQ(scaled->distanceFactor(false), 2.0);
    const auto again = std::make_shared<Transform>(scaled, Vec3d(0.3, 0, 0),
                                                             Vec3d(10, 20, 30), Vec3d(2.0));
    EXPECT_DOUBLE_EQ(again->distanceFactor(true), 2.0);
    std::mt19937 rng(20261205);
    std::uniform_real_distribution<double> at(-1.2, 1.2);
    int checked = 0;
    for (int k = 0; k < 20000; ++k) {
        const Vec3d p(at(rng), at(rng), at(rng));
        const Vec3d local((p - t).x() / scale.x(), (p - t).y() / scale.y(), (p - t).z() / scale.z());
        if (!(local.length() > 1e-9)) continue;
        const Vec3d q = t + (p - t) * (0.4 / local.length());
        EXPECT_LE((p - q).length(), scaled->distanceFactor(scaled->value(p) > 0.0) * std::abs(scaled->value(p)) + 1e-12)
            << "at " << p;
        ++checked;
    }
    EXPECT_GT(checked, 19000);
    const auto quadric = makeEllipsoid(Vec3d(0.0), Vec3d(1.0, 0.8, 0.6));
    EXPECT_TRUE(std::isinf(quadric->distanceFactor(true)));
    const auto box = std::make_shared<Box>(Vec3d(0.2, 0.0, 0.0), Vec3d(0.5, 0.3, 0.4));
    const std::vector<Implicit::Ptr> two{sphere, box};
    const auto unite = std::make_shared<Csg>(CsgOp::Union, two);
    const auto cut = std::make_shared<Csg>(CsgOp::Intersection, two);
    const auto minus = std::make_shared<Csg>(CsgOp::Difference, two);
    EXPECT_EQ(unite->distanceFactor(true), 1.0);
    EXPECT_TRUE(std::isinf(unite->distanceFactor(false)));
    EXPECT_EQ(cut->distanceFactor(false), 1.0);
    EXPECT_TRUE(std::isinf(cut->distanceFactor(true)));
    EXPECT_EQ(minus->distanceFactor(false), 1.0);
    EXPECT_TRUE(std::isinf(minus->distanceFactor(true)));
    EXPECT_TRUE(std::isinf(std::make_shared<Csg>(CsgOp::Union, std::vector<Implicit::Ptr>{scaled, box})
                               ->distanceFactor(true)));
    const auto blend = std::make_shared<Blend>(CsgOp::Union, 20.0,
                                                         std::vector<Implicit::Ptr>{sphere, scaled});
    EXPECT_TRUE(std::isinf(blend->distanceFactor(true)));
}

TEST_F(TestImplicit, GridShapesChangeNoFasterThanTheirLipschitzBound)
{
    // A grid shape's values at its voxels are distances, but its interpolation between them can
    // change faster than 1 (its Catmull-Rom weights overshoot where the distance has a kink):
    // the rasterizer's test of a group of voxels at its centre takes lipschitzBound(), not 1
    // (with 1 it dropped 2 band voxels of data/knot_smooth.json). A box's exact distance sampled
    // at 0.05 (kinks on its medial planes inside), alone and in a blend: the worst ratio
    // |f(p) - f(q)| / |p - q| over close pairs exceeds 1 and stays within the bound.
    const double dx = 0.05, half = 0.3;
    auto grid = openvdb::FloatGrid::create(0.25f);
    grid->setTransform(openvdb::math::Transform::createLinearTransform(dx));
    auto acc = grid->getAccessor();
    for (int i = -10; i <= 10; ++i) {
        for (int j = -10; j <= 10; ++j) {
            for (int k = -10; k <= 10; ++k) {
                const Vec3d d = Vec3d(std::abs(i), std::abs(j), std::abs(k)) * dx - Vec3d(half);
                const Vec3d out(std::max(d[0], 0.0), std::max(d[1], 0.0), std::max(d[2], 0.0));
                const double sdf = out.length() + std::min(std::max({d[0], d[1], d[2]}), 0.0);
                acc.setValue(openvdb::Coord(i, j, k), float(sdf));
            }
        }
    }
    const Ptr box = std::make_shared<GridShape>(grid, "vdb");
    const Ptr blend = std::make_shared<Blend>(Csg::Op::Union, 20.0, std::vector<Ptr>{
        box, std::make_shared<Sphere>(Vec3d(0.3, 0.0, 0.0), 0.2)});
    for (const auto& [what, f] : std::vector<std::pair<std::string, Ptr>>{{"grid box", box},
                                                                         {"blend with it", blend}}) {
        ASSERT_TRUE(f->isDistanceBound()) << what;
        double worst = 0.0;
        for (int n = 0; n < 200000; ++n) {
            const Vec3d p(uniform(-0.3, 0.3), uniform(-0.3, 0.3), uniform(-0.3, 0.3));
            const Vec3d q = p + Vec3d(uniform(-0.5, 0.5), uniform(-0.5, 0.5), uniform(-0.5, 0.5)) * dx;
            if ((q - p).length() < 1e-6 * dx) continue;
            worst = std::max(worst, std::abs(f->value(q) - f->value(p)) / (q - p).length());
        }
        std::printf("%s: worst ratio %.3f, bound %.3f\n", what.c_str(), worst, f->lipschitzBound());
        EXPECT_GT(worst, 1.0) << what;
        EXPECT_LE(worst, f->lipschitzBound()) << what;
    }
}

TEST_F(TestImplicit, BoundingBoxBelowHoldsEveryPointBelowTheLevel)
{
    // Offsets, shells and blends grow their children's surfaces, so their boxes ask the children
    // for the points below a level (boundingBoxBelow). A non-uniformly scaled child is not the
    // distance outside; its box below a level is its child's below level / min(scale), mapped.
    // Before, such a child in a blend or an offset left the node unbounded, and the scene was
    // refused without "bounds". Every node here is bounded, and every point of 400,000 in
    // [-3, 3]^3 whose value is below the level lies in the box.
    const Vec3d squash(1.6, 0.5, 1.0);
    const Ptr capsule = std::make_shared<Transform>(
        std::make_shared<Capsule>(Vec3d(-0.3, 0.1, 0.0), Vec3d(0.4, -0.2, 0.3), 0.2), Vec3d(0.2, 0, 0),
        Vec3d(20, -30, 45), squash);
    const Ptr sphere = std::make_shared<Sphere>(Vec3d(0.5, 0.2, -0.1), 0.4);
    const Ptr box = std::make_shared<Box>(Vec3d(0.0, 0.3, 0.2), Vec3d(0.5, 0.7, 0.9));
    const Ptr scaledSphere = std::make_shared<Transform>(sphere, Vec3d(0), Vec3d(0, 10, 0), squash);
    const std::vector<std::pair<std::string, Ptr>> nodes = {
        {"scaled capsule", capsule},
        {"blend with a scaled capsule", std::make_shared<Blend>(Csg::Op::Union, 8.0, std::vector<Ptr>{capsule, sphere})},
        {"smooth union with a scaled capsule", std::make_shared<Blend>(
            Csg::Op::Union, BlendKernel::polynomial(0.3), std::vector<Ptr>{capsule, box})},
        {"offset of an intersection with a scaled sphere", std::make_shared<Offset>(
            std::make_shared<Csg>(Csg::Op::Intersection, std::vector<Ptr>{box, scaledSphere}), 0.15)},
        {"shell of a scaled difference", std::make_shared<Shell>(std::make_shared<Transform>(
            std::make_shared<Csg>(Csg::Op::Difference, std::vector<Ptr>{box, sphere}), Vec3d(0),
            Vec3d(0), squash), 0.1)},
        {"scaled blend", std::make_shared<Transform>(
            std::make_shared<Blend>(Csg::Op::Union, 5.0, std::vector<Ptr>{capsule, box}), Vec3d(0.1, 0, 0),
            Vec3d(0, 0, 30), Vec3d(0.7, 1.2, 1.0))},
    };
    for (const auto& [what, f] : nodes) {
        ASSERT_TRUE(f->isBounded()) << what;
        for (const double level : {0.0, 0.05, 0.3}) {
            const BBoxd b = f->boundingBoxBelow(level);
            ASSERT_TRUE(isFinite(b)) << what << " at " << level;
            std::size_t below = 0, outside = 0;
            for (int i = 0; i < 400000; ++i) {
                const Vec3d p(uniform(-3.0, 3.0), uniform(-3.0, 3.0), uniform(-3.0, 3.0));
                if (!(f->value(p) < level)) continue;
                ++below;
                bool in = true;
                for (int k = 0; k < 3; ++k) in = in && p[k] >= b.min()[k] - 1e-12 && p[k] <= b.max()[k] + 1e-12;
                outside += in ? 0 : 1;
            }
            EXPECT_GT(below, 100u) << what << " at " << level;
            EXPECT_EQ(outside, 0u) << what << " at " << level;
        }
    }
    // A quadric's offset is still unbounded: nothing bounds an ellipsoid's field by its distance.
    EXPECT_FALSE(std::make_shared<Offset>(makeEllipsoid(Vec3d(0.0), Vec3d(1.0, 0.8, 0.6)), 0.1)->isBounded());
}

// ---- Pruning -----------------------------------------------------------------------------------

TEST_F(TestImplicit, PruneUnionOfSpheres)
{
    std::vector<Ptr> spheres;
    for (int i = 0; i < 50; ++i)
        spheres.push_back(std::make_shared<Sphere>(randomPoint(-10, 10), uniform(0.5, 2.0)));
    const auto full = std::make_shared<Csg>(Csg::Op::Union, spheres);
    std::size_t total = 0;
    for (int b = 0; b < 100; ++b) {
        // Small boxes, half of them around a sphere center, the rest anywhere (also far outside).
        const Vec3d lo = b % 2 ? randomPoint(-14, 14)
                               : dynamic_cast<const Sphere&>(*spheres[b % 50]).center() - Vec3d(0.25);
        const BBoxd box(lo, lo + Vec3d(0.5));
        const Ptr pruned = full->prune(box);
        const auto* csg = dynamic_cast<const Csg*>(pruned.get());
        const std::vector<Ptr> kept = csg ? csg->children() : std::vector<Ptr>{pruned};
        EXPECT_LT(kept.size(), 50u) << "box at " << lo;
        total += kept.size();
        for (int k = 0; k < 200; ++k) {
            const Vec3d p = randomIn(box);
            EXPECT_EQ(pruned->value(p), full->value(p)) << p;
            // The sphere that is the minimum at p must have been kept.
            std::size_t arg = 0;
            for (std::size_t i = 1; i < spheres.size(); ++i)
                if (spheres[i]->value(p) < spheres[arg]->value(p)) arg = i;
            EXPECT_NE(std::find(kept.begin(), kept.end(), spheres[arg]), kept.end());
        }
    }
    EXPECT_LT(total, 100u * 5); // on average far fewer than 5 of 50 children survive
    // A box that meets every sphere's interval range keeps the node itself.
    EXPECT_EQ(full->prune(BBoxd(Vec3d(-20), Vec3d(20))), full);
}

TEST_F(TestImplicit, PruneDifferenceAndTransform)
{
    std::vector<Ptr> kids = {std::make_shared<Box>(Vec3d(0), Vec3d(8))};
    for (int i = 0; i < 20; ++i)
        kids.push_back(std::make_shared<Sphere>(randomPoint(-4, 4), uniform(0.3, 1.0)));
    const Ptr diff = std::make_shared<Csg>(Csg::Op::Difference, kids);
    const Ptr xf = std::make_shared<Transform>(diff, Vec3d(1, 0, -1), Vec3d(15, 25, 35), Vec3d(1.3, 0.8, 1));
    for (const Ptr& f : {diff, xf}) {
        for (int b = 0; b < 50; ++b) {
            const Vec3d lo = randomPoint(-5, 5);
            const BBoxd box(lo, lo + Vec3d(0.4));
            const Ptr pruned = f->prune(box);
            for (int k = 0; k < 100; ++k) {
                const Vec3d p = randomIn(box);
                EXPECT_EQ(pruned->value(p), f->value(p)) << p;
            }
        }
    }
}

// ---- Errors ------------------------------------------------------------------------------------

TEST_F(TestImplicit, InvalidInputsThrow)
{
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const Ptr sphere = std::make_shared<Sphere>(Vec3d(0), 1.0);
    EXPECT_THROW(Sphere(Vec3d(0), 0.0), openvdb::ValueError);
    EXPECT_THROW(Sphere(Vec3d(0), -1.0), openvdb::ValueError);
    EXPECT_THROW(Sphere(Vec3d(nan, 0, 0), 1.0), openvdb::ValueError);
    EXPECT_THROW(Box(Vec3d(0), Vec3d(1, 0, 1)), openvdb::ValueError);
    EXPECT_THROW(Box(Vec3d(0, 0, nan), Vec3d(1)), openvdb::ValueError);
    EXPECT_THROW(Torus(Vec3d(0), 1.0, 1.0), openvdb::ValueError);
    EXPECT_THROW(Torus(Vec3d(0), 1.0, 2.0), openvdb::ValueError);
    EXPECT_THROW(Torus(Vec3d(0), 1.0, 0.0), openvdb::ValueError);

    Mat4 q{};
    EXPECT_THROW(Quadric{q}, openvdb::ValueError); // all zero
    q[0][0] = 1;
    q[0][1] = 0.5; // q[1][0] stays 0
    EXPECT_THROW(Quadric{q}, openvdb::ValueError);
    q[1][0] = 0.5;
    q[2][2] = nan;
    EXPECT_THROW(Quadric{q}, openvdb::ValueError);

    EXPECT_THROW(makePlane(Vec3d(0), 1.0), openvdb::ValueError);
    EXPECT_THROW(makeCylinder(Vec3d(0), Vec3d(0), 1.0), openvdb::ValueError);
    EXPECT_THROW(makeCylinder(Vec3d(0), Vec3d(0, 0, 1), 0.0), openvdb::ValueError);
    EXPECT_THROW(makeCone(Vec3d(0), Vec3d(0, 0, 1), 0.0), openvdb::ValueError);
    EXPECT_THROW(makeCone(Vec3d(0), Vec3d(0, 0, 1), 90.0), openvdb::ValueError);
    EXPECT_THROW(makeEllipsoid(Vec3d(0), Vec3d(1, -1, 1)), openvdb::ValueError);
    EXPECT_THROW(makeParaboloid(Vec3d(0), Vec3d(0, 0, 1), false, 0.0, 1.0), openvdb::ValueError);
    EXPECT_THROW(makeHyperboloid(Vec3d(0), Vec3d(0, 0, 1), true, Vec3d(1, 1, 0)), openvdb::ValueError);

    EXPECT_THROW(Transform(sphere, Vec3d(0), Vec3d(0), Vec3d(1, 0, 1)), openvdb::ValueError);
    EXPECT_THROW(Transform(sphere, Vec3d(0), Vec3d(0), Vec3d(-1)), openvdb::ValueError);
    EXPECT_THROW(Transform(sphere, Vec3d(nan), Vec3d(0), Vec3d(1)), openvdb::ValueError);
    EXPECT_THROW(Transform(nullptr, Vec3d(0), Vec3d(0), Vec3d(1)), openvdb::ValueError);
    EXPECT_THROW(Csg(Csg::Op::Union, {}), openvdb::ValueError);
    EXPECT_THROW(Csg(Csg::Op::Union, {sphere, nullptr}), openvdb::ValueError);
}

TEST_F(TestImplicit, FrameFromAxis)
{
    // Orthonormal, right-handed, third column along the axis, and the smallest rotation: it
    // fixes the direction z x axis.
    for (int k = 0; k < 200; ++k) {
        const Vec3d a = k == 0 ? Vec3d(0, 0, 1) : (k == 1 ? Vec3d(0, 0, -2) : randomPoint(-1, 1));
        const auto f = frameFromAxis(a);
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) EXPECT_NEAR(f[i].dot(f[j]), i == j ? 1.0 : 0.0, 1e-12);
        expectVecNear(f[0].cross(f[1]), f[2], 1e-12, "right-handed");
        expectVecNear(f[2], a.unit(), 1e-12, "axis");
        const Vec3d w = Vec3d(0, 0, 1).cross(a.unit());
        if (w.length() > 1e-6) {
            const Vec3d rw = f[0] * w[0] + f[1] * w[1] + f[2] * w[2];
            expectVecNear(rw, w, 1e-12, "rotation axis fixed");
        }
    }
}
