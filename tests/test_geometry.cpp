// [geometry] Ray-sphere and ray-triangle intersection (known answers, grazing rays,
// edges, far-away origins) and the BVH, checked against brute force over every
// primitive on a random scene and on degenerate primitive distributions.
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

using namespace smallvcm;

namespace {

constexpr float kInfinity = std::numeric_limits<float>::infinity();

// An orthonormal pair perpendicular to aAxis (built here, not with the header's Frame).
void Perpendiculars(const Vec3& aAxis, Vec3& oA, Vec3& oB) {
    const Vec3 helper = std::abs(aAxis.x) < 0.9f ? Vec3(1.f, 0.f, 0.f) : Vec3(0.f, 1.f, 0.f);
    oA = glm::normalize(glm::cross(aAxis, helper));
    oB = glm::cross(aAxis, oA);
}

using Triangle3 = std::array<Vec3, 3>;

// The one place that knows IntersectTriangle's signature (the three vertices).
std::optional<float> HitTriangle(const Triangle3& aTriangle, const Ray& aRay, float aTMin, float aTMax) {
    return IntersectTriangle(aTriangle[0], aTriangle[1], aTriangle[2], aRay, aTMin, aTMax);
}

// Primitives kept as plain vertices and spheres; Soup() is the one place that knows the
// BVH's storage layout. Primitive indices: triangles first, then spheres, as in Scene.
struct Primitives {
    std::vector<Triangle3> triangles;
    std::vector<Vec3> centers;
    std::vector<float> radii;

    void AddTriangle(const Vec3& aP0, const Vec3& aP1, const Vec3& aP2) { triangles.push_back({aP0, aP1, aP2}); }
    void AddSphere(const Vec3& aCenter, float aRadius) { centers.push_back(aCenter); radii.push_back(aRadius); }
    PrimitiveSoup Soup() const {
        PrimitiveSoup soup;
        for (const Triangle3& t : triangles) {
            soup.mTriangleP0.push_back(t[0]);
            soup.mTriangleP1.push_back(t[1]);
            soup.mTriangleP2.push_back(t[2]);
        }
        soup.mSphereCenter = centers;
        soup.mSphereRadius = radii;
        return soup;
    }
    static Primitives Of(const Scene& aScene) {
        Primitives p;
        for (const Triangle& t : aScene.mTriangles) p.AddTriangle(t.mP0, t.mP1, t.mP2);
        for (const Sphere& s : aScene.mSpheres) p.AddSphere(s.mCenter, s.mRadius);
        return p;
    }
};

// Nearest hit over every primitive by brute force, with the intersection routines called
// directly; returns the primitive index or -1.
int BruteForceNearest(const Primitives& aPrimitives, const Ray& aRay, float aTMin, float& ioTMax) {
    int nearest = -1;
    for (size_t i = 0; i < aPrimitives.triangles.size(); i++) {
        if (const std::optional<float> t = HitTriangle(aPrimitives.triangles[i], aRay, aTMin, ioTMax)) {
            ioTMax = *t;
            nearest = int(i);
        }
    }
    for (size_t s = 0; s < aPrimitives.centers.size(); s++) {
        if (const std::optional<float> t = IntersectSphere(aPrimitives.centers[s], aPrimitives.radii[s], aRay, aTMin, ioTMax)) {
            ioTMax = *t;
            nearest = int(aPrimitives.triangles.size() + s);
        }
    }
    return nearest;
}

bool BruteForceAny(const Primitives& aPrimitives, const Ray& aRay, float aTMin, float aTMax) {
    float tMax = aTMax;
    return BruteForceNearest(aPrimitives, aRay, aTMin, tMax) >= 0;
}

// The same brute force, made cheap for many rays: each primitive is still visited, in the
// same order, but the ray skips the intersection routine of a primitive whose bounding
// sphere it misses or that lies wholly outside (aTMin, ioTMax). Each sphere bounds its
// primitive with a margin (1e-3 relative plus 1e-4 absolute, in double) far above the
// routines' float rounding, so a skipped primitive is one the routine would not have hit,
// and the answer is BruteForceNearest's bit for bit (checked on the first rays of every
// test that uses it). The 100,000-ray comparison below took 6.3 s with BruteForceNearest
// and takes 0.6 s with this, its self-check on the first 2,000 rays included.
class CulledBruteForce {
public:
    explicit CulledBruteForce(const Primitives& aPrimitives) : mPrimitives(aPrimitives) {
        for (const Triangle3& t : aPrimitives.triangles) {
            const glm::dvec3 center = (glm::dvec3(t[0]) + glm::dvec3(t[1]) + glm::dvec3(t[2])) / 3.0;
            double radius = 0.0;
            for (const Vec3& p : t) radius = std::max(radius, glm::length(glm::dvec3(p) - center));
            AddBound(center, radius);
        }
        for (size_t s = 0; s < aPrimitives.centers.size(); s++) AddBound(glm::dvec3(aPrimitives.centers[s]), aPrimitives.radii[s]);
    }

    int Nearest(const Ray& aRay, float aTMin, float& ioTMax) const {
        const glm::dvec3 origin(aRay.mOrigin), direction(aRay.mDirection);
        const double lengthSquared = glm::dot(direction, direction);
        const size_t triangleCount = mPrimitives.triangles.size();
        int nearest = -1;
        for (size_t i = 0; i < mCenters.size(); i++) {
            // Where the ray comes closest to the centre (t along the ray), and how close.
            const glm::dvec3 toCenter = mCenters[i] - origin;
            const double tClosest = glm::dot(toCenter, direction) / lengthSquared;
            const glm::dvec3 offset = toCenter - tClosest * direction;
            if (glm::dot(offset, offset) > mRadii[i] * mRadii[i]) continue;
            const double tHalfWidth = mRadii[i] / std::sqrt(lengthSquared);
            if (tClosest + tHalfWidth < double(aTMin) || tClosest - tHalfWidth > double(ioTMax)) continue;
            const std::optional<float> t = i < triangleCount
                                               ? HitTriangle(mPrimitives.triangles[i], aRay, aTMin, ioTMax)
                                               : IntersectSphere(mPrimitives.centers[i - triangleCount],
                                                                 mPrimitives.radii[i - triangleCount], aRay, aTMin, ioTMax);
            if (t) {
                ioTMax = *t;
                nearest = int(i);
            }
        }
        return nearest;
    }

    bool Any(const Ray& aRay, float aTMin, float aTMax) const {
        float tMax = aTMax;
        return Nearest(aRay, aTMin, tMax) >= 0;
    }

private:
    void AddBound(const glm::dvec3& aCenter, double aRadius) {
        mCenters.push_back(aCenter);
        mRadii.push_back(aRadius * (1.0 + 1e-3) + 1e-4);
    }

    const Primitives& mPrimitives;
    std::vector<glm::dvec3> mCenters;
    std::vector<double> mRadii;
};

// Random rays through a BVH built over aPrimitives: it must find the same nearest hit as
// brute force (the same primitive, or for an exact tie the same distance). Returns the
// number of rays that hit something.
int CompareBvhWithBruteForce(const Primitives& aPrimitives, const Bvh& aBvh, int aRays, float aBoxHalfSize, uint64_t aSeed) {
    Rng rng(aSeed, 0);
    int hits = 0;
    for (int i = 0; i < aRays; i++) {
        const Ray ray{(2.f * rng.GetVec3() - Vec3(1.f)) * aBoxHalfSize, SampleUniformSphereW(rng.GetVec2())};
        float bruteT = kInfinity, bvhT = kInfinity;
        const int brute = BruteForceNearest(aPrimitives, ray, 0.f, bruteT);
        const int bvh = aBvh.Intersect(ray, 0.f, bvhT);
        REQUIRE((bvh >= 0) == (brute >= 0));
        if (brute < 0) continue;
        hits++;
        REQUIRE(bvhT == Approx(bruteT).epsilon(1e-6));
        if (bvh != brute) REQUIRE(bvhT == Approx(bruteT).epsilon(1e-5));  // an exact tie
    }
    return hits;
}

} // namespace

// ---------------------------------------------------------------------------------
// Sphere
// ---------------------------------------------------------------------------------

TEST_CASE("A ray along a sphere's axis hits it at distance d - r", "[geometry]") {
    const Vec3 center(1.f, 2.f, 3.f);
    std::optional<float> t;
    t = IntersectSphere(center, 0.5f, Ray{center - Vec3(0.f, 0.f, 10.f), Vec3(0.f, 0.f, 1.f)}, 0.f, kInfinity);
    REQUIRE(t);
    REQUIRE(*t == Approx(9.5f).epsilon(1e-6));
    t = IntersectSphere(center, 2.f, Ray{center + Vec3(7.f, 0.f, 0.f), Vec3(-1.f, 0.f, 0.f)}, 0.f, kInfinity);
    REQUIRE(t);
    REQUIRE(*t == Approx(5.f).epsilon(1e-6));
    // A sphere behind the origin is not hit, nor one beyond aTMax.
    REQUIRE_FALSE(IntersectSphere(center, 0.5f, Ray{center - Vec3(0.f, 0.f, 10.f), Vec3(0.f, 0.f, -1.f)}, 0.f, kInfinity));
    REQUIRE_FALSE(IntersectSphere(center, 0.5f, Ray{center - Vec3(0.f, 0.f, 10.f), Vec3(0.f, 0.f, 1.f)}, 0.f, 9.f));
    // With aTMin past the near root, the far root is returned.
    t = IntersectSphere(center, 0.5f, Ray{center - Vec3(0.f, 0.f, 10.f), Vec3(0.f, 0.f, 1.f)}, 9.6f, kInfinity);
    REQUIRE(t);
    REQUIRE(*t == Approx(10.5f).epsilon(1e-6));
}

TEST_CASE("A ray starting inside a sphere returns the far root", "[geometry]") {
    const Vec3 center(-1.f, 0.5f, 2.f);
    std::optional<float> t;
    t = IntersectSphere(center, 1.f, Ray{center + Vec3(0.25f, 0.f, 0.f), Vec3(1.f, 0.f, 0.f)}, 0.f, kInfinity);
    REQUIRE(t);
    REQUIRE(*t == Approx(0.75f).epsilon(1e-6));
    t = IntersectSphere(center, 1.f, Ray{center + Vec3(0.25f, 0.f, 0.f), Vec3(-1.f, 0.f, 0.f)}, 0.f, kInfinity);
    REQUIRE(t);
    REQUIRE(*t == Approx(1.25f).epsilon(1e-6));
    // From the centre, in any direction, the exit is at distance r.
    Rng rng(101, 0);
    for (int i = 0; i < 1000; i++) {
        t = IntersectSphere(center, 1.f, Ray{center, SampleUniformSphereW(rng.GetVec2())}, 0.f, kInfinity);
        REQUIRE(t);
        REQUIRE(*t == Approx(1.f).epsilon(1e-6));
    }
}

TEST_CASE("Nearly tangent rays hit a sphere just inside its radius and miss it just outside", "[geometry]") {
    // Rays in random directions passing the centre at distance h = r (1 -+ 1e-4). Inside,
    // the chord's half length is sqrt(r^2 - h^2) ~ 0.0141 r, and the expected distance
    // (in double, from the same float ray) is s minus that, with s = 5 r the distance
    // along the ray to the closest point. Tolerance 1e-4: the perpendicular f - (f.d) d
    // comes out of a cancellation in float, with an absolute error of about one ulp of
    // |f| = s (9.5e-7 for r = 1.5); the chord then errs by h dh / chord = 6.7e-5 per ulp.
    Rng rng(102, 0);
    const Vec3 center(0.3f, -0.2f, 0.1f);
    const float radius = 1.5f;
    for (int i = 0; i < 1000; i++) {
        const Vec3 direction = SampleUniformSphereW(rng.GetVec2());
        Vec3 a, b;
        Perpendiculars(direction, a, b);
        const float s = 5.f * radius;
        for (const double offsetFactor : {1.0 - 1e-4, 1.0 + 1e-4}) {
            const Vec3 closest = center + float(offsetFactor * radius) * a;
            const Ray ray{closest - s * direction, direction};
            // The expected answer from the float ray, in double.
            const glm::dvec3 f = glm::dvec3(ray.mOrigin) - glm::dvec3(center);
            const glm::dvec3 d = glm::dvec3(ray.mDirection);
            const double along = -glm::dot(f, d) / glm::dot(d, d);
            const glm::dvec3 perpendicular = f + along * d;
            const double h2 = glm::dot(perpendicular, perpendicular);
            const std::optional<float> t = IntersectSphere(center, radius, ray, 0.f, kInfinity);
            const bool hit = t.has_value();
            if (offsetFactor < 1.0) {
                REQUIRE(hit);
                const double expected = along - std::sqrt(double(radius) * radius - h2);
                REQUIRE(std::abs(double(*t) - expected) <= 1e-4);
            } else {
                REQUIRE_FALSE(hit);
            }
        }
    }
}

TEST_CASE("A ray from 1e4 units away hits a sphere at a point that lies on the sphere", "[geometry]") {
    // The hit point o + t d, in double from the float ray and t, must lie on the sphere
    // within 1e-3 r. At 1e4 the float t has an ulp of 9.8e-4, and c = |f|^2 - r^2 ~ 1e8
    // (from which the near root c/q comes) errs by a few ulps of 1e8, i.e. ~1e-3 in t:
    // with r = 5 the bound allows about 5 ulps of t. A textbook quadratic, whose
    // discriminant b^2 - c subtracts two numbers ~1e8 known to +-8, errs by ~0.4 here.
    Rng rng(103, 0);
    const Vec3 center(2.f, -1.f, 0.5f);
    const float radius = 5.f;
    double worst = 0.0;
    for (int i = 0; i < 2000; i++) {
        // Aim at a random point of the visible cap, from a random direction 1e4 away.
        const Vec3 away = SampleUniformSphereW(rng.GetVec2());
        const Vec3 origin = center + 1e4f * away;
        Vec3 a, b;
        Perpendiculars(away, a, b);
        const Vec2 disc = SampleConcentricDisc(rng.GetVec2()) * 0.95f;
        const Vec3 target = center + radius * (disc.x * a + disc.y * b);
        const Ray ray{origin, glm::normalize(target - origin)};
        const std::optional<float> t = IntersectSphere(center, radius, ray, 0.f, kInfinity);
        REQUIRE(t);
        const glm::dvec3 hit = glm::dvec3(ray.mOrigin) + double(*t) * glm::dvec3(ray.mDirection);
        const double error = std::abs(glm::length(hit - glm::dvec3(center)) - radius) / radius;
        worst = std::max(worst, error);
    }
    INFO("worst relative distance error " << worst);
    REQUIRE(worst <= 1e-3);
}

// ---------------------------------------------------------------------------------
// Triangle
// ---------------------------------------------------------------------------------

TEST_CASE("A ray hits a triangle at the known distance from either side", "[geometry]") {
    const Triangle3 tri = {Vec3(0.f, 0.f, 0.f), Vec3(1.f, 0.f, 0.f), Vec3(0.f, 1.f, 0.f)};
    std::optional<float> t;
    t = HitTriangle(tri, Ray{Vec3(0.25f, 0.25f, 1.f), Vec3(0.f, 0.f, -1.f)}, 0.f, kInfinity);
    REQUIRE(t);
    REQUIRE(*t == Approx(1.f).epsilon(1e-6));
    // Back faces are hit too (the intersection is two-sided).
    t = HitTriangle(tri, Ray{Vec3(0.25f, 0.25f, -2.f), Vec3(0.f, 0.f, 1.f)}, 0.f, kInfinity);
    REQUIRE(t);
    REQUIRE(*t == Approx(2.f).epsilon(1e-6));
    // An oblique ray: from (0.2, 0.1, 3) along (0.05, 0.1, -1), normalised: it crosses the
    // plane at (0.35, 0.4), at distance 3 |(0.05, 0.1, -1)|.
    const Vec3 oblique = glm::normalize(Vec3(0.05f, 0.1f, -1.f));
    t = HitTriangle(tri, Ray{Vec3(0.2f, 0.1f, 3.f), oblique}, 0.f, kInfinity);
    REQUIRE(t);
    REQUIRE(*t == Approx(3.0 * std::sqrt(1.0125)).epsilon(1e-6));
    // Outside each of the three edges: miss.
    for (const Vec3 origin : {Vec3(-0.1f, 0.5f, 1.f), Vec3(0.5f, -0.1f, 1.f), Vec3(0.6f, 0.6f, 1.f)})
        REQUIRE_FALSE(HitTriangle(tri, Ray{origin, Vec3(0.f, 0.f, -1.f)}, 0.f, kInfinity));
}

TEST_CASE("A triangle behind the ray origin, or outside (tMin, tMax), is not hit", "[geometry]") {
    const Triangle3 tri = {Vec3(0.f, 0.f, 0.f), Vec3(1.f, 0.f, 0.f), Vec3(0.f, 1.f, 0.f)};
    REQUIRE_FALSE(HitTriangle(tri, Ray{Vec3(0.25f, 0.25f, -1.f), Vec3(0.f, 0.f, -1.f)}, 0.f, kInfinity));
    const Ray ray{Vec3(0.25f, 0.25f, 1.f), Vec3(0.f, 0.f, -1.f)};  // hit at t = 1
    REQUIRE_FALSE(HitTriangle(tri, ray, 1.5f, kInfinity));
    REQUIRE_FALSE(HitTriangle(tri, ray, 0.f, 0.5f));
    REQUIRE_FALSE(HitTriangle(tri, ray, 1.f, kInfinity));  // the interval is open
    REQUIRE(HitTriangle(tri, ray, 0.999f, 1.001f));
    // An origin on the triangle itself (t = 0) is not a hit with tMin = 0.
    REQUIRE_FALSE(HitTriangle(tri, Ray{Vec3(0.25f, 0.25f, 0.f), Vec3(0.f, 0.f, 1.f)}, 0.f, kInfinity));
}

TEST_CASE("Rays parallel to a triangle's plane miss it, even when they lie in the plane", "[geometry]") {
    const Triangle3 tri = {Vec3(0.f, 0.f, 0.f), Vec3(1.f, 0.f, 0.f), Vec3(0.f, 1.f, 0.f)};
    for (const Vec3 direction : {Vec3(1.f, 0.f, 0.f), Vec3(0.f, -1.f, 0.f), glm::normalize(Vec3(1.f, 1.f, 0.f))}) {
        REQUIRE_FALSE(HitTriangle(tri, Ray{Vec3(-1.f, 0.2f, 0.5f), direction}, 0.f, kInfinity));
        REQUIRE_FALSE(HitTriangle(tri, Ray{Vec3(-1.f, 0.2f, 0.f), direction}, 0.f, kInfinity));
        REQUIRE_FALSE(HitTriangle(tri, Ray{Vec3(0.2f, 0.2f, 0.f), direction}, 0.f, kInfinity));
    }
}

TEST_CASE("Grazing rays nearly parallel to a triangle still hit it at the right distance", "[geometry]") {
    // Unit right triangles in random planes; rays that travel 10 units while descending
    // towards the plane with a slope of 1e-2 .. 1e-4 and cross it at an interior point.
    // Every such ray must hit. The distance is compared with the exact intersection of the
    // same float ray with the plane of the same float vertices, computed in double.
    // Tolerance: rounding o - p0 (|o - p0| <= 11) moves the origin off the plane by up to
    // ~2 ulps of 11 (2e-6), and along a ray of slope s that is 2e-6 / s of distance:
    // tolerance 4e-6 / s (4e-2 at s = 1e-4, where the ray covers 10 units to drop 1e-3).
    Rng rng(104, 0);
    double worstInUnits = 0.0;  // worst error in units of 1e-6 / s
    for (const float slope : {1e-2f, 1e-3f, 1e-4f}) {
        for (int i = 0; i < 300; i++) {
            const Vec3 normal = SampleUniformSphereW(rng.GetVec2());
            Vec3 u, v;
            Perpendiculars(normal, u, v);
            const Vec3 corner = 2.f * rng.GetVec3() - Vec3(1.f);
            const Triangle3 tri = {corner, corner + u, corner + v};
            const Vec3 target = corner + (0.1f + 0.3f * rng.GetFloat()) * u + (0.1f + 0.3f * rng.GetFloat()) * v;
            const float phi = 2.f * kPi * rng.GetFloat();
            const Vec3 direction = glm::normalize(std::cos(phi) * u + std::sin(phi) * v - slope * normal);
            const Vec3 origin = target - 10.f * direction;
            INFO("slope " << slope);
            const std::optional<float> t = HitTriangle(tri, Ray{origin, direction}, 0.f, kInfinity);
            REQUIRE(t);
            const glm::dvec3 p0(tri[0]), planeNormal = glm::cross(glm::dvec3(tri[1]) - p0, glm::dvec3(tri[2]) - p0);
            const double exact = glm::dot(p0 - glm::dvec3(origin), planeNormal) / glm::dot(glm::dvec3(direction), planeNormal);
            const double error = std::abs(double(*t) - exact);
            REQUIRE(error <= 4e-6 / slope);
            worstInUnits = std::max(worstInUnits, error * slope / 1e-6);
        }
    }
    INFO("worst error " << worstInUnits << " x 1e-6 / slope");
    REQUIRE(worstInUnits <= 4.0);
}

TEST_CASE("A ray through the edge shared by the two triangles of a quad hits at least one of them", "[geometry]") {
    // Random planar quads p0 p1 p2 p3 in random orientations, split along the diagonal
    // p0-p2, in the two vertex orders meshes use: fan (p0 p1 p2)(p0 p2 p3) and strip
    // (p0 p1 p2)(p2 p3 p0). Each quad is a scene of its own, queried through
    // Scene::Intersect, so the check covers whatever the scene stores per triangle. Rays
    // from random points on either side aim at random points of the diagonal: rounded to
    // float, each crosses the plane within ~1e-7 of the edge, on one side or the other,
    // and must not slip between the two triangles.
    Rng rng(105, 0);
    int misses[2] = {0, 0}, rays = 0;
    for (int q = 0; q < 100; q++) {
        const Vec3 origin = 4.f * rng.GetVec3() - Vec3(2.f);
        const Vec3 u = SampleUniformSphereW(rng.GetVec2());
        Vec3 v, normal;
        Perpendiculars(u, v, normal);
        const float a = 0.2f + 2.f * rng.GetFloat(), b = 0.2f + 2.f * rng.GetFloat();
        const Vec3 p0 = origin, p1 = origin + a * u, p2 = origin + a * u + b * v, p3 = origin + b * v;
        Scene quads[2];
        for (int order = 0; order < 2; order++) {
            Scene& scene = quads[order];
            const int material = scene.AddMaterial(Material{});
            scene.AddTriangle(p0, p1, p2, material);
            if (order == 0) scene.AddTriangle(p0, p2, p3, material);
            else            scene.AddTriangle(p2, p3, p0, material);
            scene.AddPointLight(origin + normal, Vec3(1.f));
            scene.mCamera.Setup(origin + 3.f * normal, -normal, u, 45.f);
            scene.Finalize();
        }
        for (int i = 0; i < 1000; i++) {
            const Vec3 onEdge = p0 + (0.01f + 0.98f * rng.GetFloat()) * (p2 - p0);
            const float side = rng.GetFloat() < 0.5f ? -1.f : 1.f;
            const Vec3 start = onEdge + side * (0.3f + 2.f * rng.GetFloat()) * normal + (rng.GetVec3() - Vec3(0.5f));
            const Ray ray{start, glm::normalize(onEdge - start)};
            rays++;
            for (int order = 0; order < 2; order++) {
                if (!quads[order].Intersect(ray).IsValid()) misses[order]++;
            }
        }
    }
    INFO(misses[0] << " (fan order) and " << misses[1] << " (strip order) of " << rays
                   << " rays through a shared edge missed both triangles");
    CHECK(misses[0] == 0);
    CHECK(misses[1] == 0);
}

// ---------------------------------------------------------------------------------
// BVH
// ---------------------------------------------------------------------------------

namespace {

// 2000 small random triangles and 50 spheres in [-1, 1]^3, one Lambert material, a point
// light and a camera: a complete scene, finalized.
Scene MakeRandomScene() {
    Scene scene;
    scene.mName = "random BVH scene";
    Material grey;
    grey.mDiffuseReflectance = Vec3(0.5f);
    const int material = scene.AddMaterial(grey);
    Rng rng(201, 0);
    while (scene.mTriangles.size() < 2000) {
        const Vec3 center = 2.f * rng.GetVec3() - Vec3(1.f);
        const float size = 0.02f + 0.2f * rng.GetFloat();
        const Vec3 p0 = center + size * (rng.GetVec3() - Vec3(0.5f));
        const Vec3 p1 = center + size * (rng.GetVec3() - Vec3(0.5f));
        const Vec3 p2 = center + size * (rng.GetVec3() - Vec3(0.5f));
        if (glm::length(glm::cross(p1 - p0, p2 - p0)) < 1e-5f) continue;
        scene.AddTriangle(p0, p1, p2, material);
    }
    for (int i = 0; i < 50; i++) scene.AddSphere(2.f * rng.GetVec3() - Vec3(1.f), 0.02f + 0.1f * rng.GetFloat(), material);
    scene.AddPointLight(Vec3(0.f, 0.f, 3.f), Vec3(10.f));
    scene.mCamera.Setup(Vec3(0.f, -4.f, 0.f), Vec3(0.f, 1.f, 0.f), Vec3(0.f, 0.f, 1.f), 45.f);
    scene.mCamera.SetResolution(64, 64);
    scene.Finalize();
    return scene;
}

} // namespace

TEST_CASE("Scene::Intersect finds the same nearest hit as brute force for 100,000 random rays", "[geometry]") {
    const Scene scene = MakeRandomScene();
    const Primitives primitives = Primitives::Of(scene);
    REQUIRE(primitives.triangles.size() == 2000);
    REQUIRE(primitives.centers.size() == 50);
    REQUIRE(scene.GetBvh().PrimitiveCount() == 2050);
    REQUIRE(scene.GetBvh().Depth() <= 64);
    const CulledBruteForce bruteForce(primitives);
    Rng rng(202, 0);
    int hits = 0, sphereHits = 0, ties = 0;
    for (int i = 0; i < 100000; i++) {
        // Origins in a box a little larger than the scene's, directions uniform.
        const Ray ray{3.f * rng.GetVec3() - Vec3(1.5f), SampleUniformSphereW(rng.GetVec2())};
        float bruteT = kInfinity;
        const int brute = bruteForce.Nearest(ray, 0.f, bruteT);
        if (i < 2000) {  // the culled brute force is the plain one, bit for bit
            float plainT = kInfinity;
            REQUIRE(BruteForceNearest(primitives, ray, 0.f, plainT) == brute);
            REQUIRE(plainT == bruteT);
        }
        const SurfacePoint hit = scene.Intersect(ray);
        const bool found = hit.IsValid();
        REQUIRE(found == (brute >= 0));
        if (!found) continue;
        hits++;
        REQUIRE(hit.mDist == Approx(bruteT).epsilon(1e-6));
        if (hit.mPrimitiveId != brute) {
            ties++;
            REQUIRE(hit.mDist == Approx(bruteT).epsilon(1e-5));
        }
        // The hit record describes the primitive that was hit.
        REQUIRE(hit.mMaterialId == 0);
        REQUIRE(hit.mLightId == -1);
        if (hit.mPrimitiveId < 2000) {
            REQUIRE(hit.GeometricNormal() == scene.mTriangles[size_t(hit.mPrimitiveId)].mNormal);
        } else {
            sphereHits++;
            const Sphere& sphere = scene.mSpheres[size_t(hit.mPrimitiveId - 2000)];
            const Vec3 outward = glm::normalize(ray.mOrigin + hit.mDist * ray.mDirection - sphere.mCenter);
            REQUIRE(glm::length(hit.GeometricNormal()) == Approx(1.f).epsilon(1e-5));
            REQUIRE(glm::dot(hit.GeometricNormal(), outward) > 0.9999f);
        }
    }
    INFO(hits << " hits, " << sphereHits << " on spheres, " << ties << " exact ties");
    // The scene is dense enough that the comparison is not vacuous.
    REQUIRE(hits > 10000);
    REQUIRE(sphereHits > 2000);
}

TEST_CASE("Scene::Occluded agrees with brute force for 10,000 segments", "[geometry]") {
    const Scene scene = MakeRandomScene();
    const Primitives primitives = Primitives::Of(scene);
    const CulledBruteForce bruteForce(primitives);
    const float epsilon = scene.RayEpsilon();
    REQUIRE(epsilon > 0.f);
    Rng rng(203, 0);
    int occluded = 0;
    for (int i = 0; i < 10000; i++) {
        const Vec3 from = 3.f * rng.GetVec3() - Vec3(1.5f);
        Vec3 to;
        if (i % 2 == 0) {
            to = 3.f * rng.GetVec3() - Vec3(1.5f);
        } else {
            // Shadow rays as integrators cast them: to a point on a triangle.
            const Triangle& tri = scene.mTriangles[size_t(rng.NextUint() % 2000u)];
            const Vec2 b = SampleUniformTriangle(rng.GetVec2());
            to = b.x * tri.mP0 + b.y * tri.mP1 + (1.f - b.x - b.y) * tri.mP2;
        }
        const float distance = glm::length(to - from);
        const Vec3 direction = (to - from) / distance;
        // Scene::Occluded's contract: the segment shrunk by the ray epsilon at both ends.
        const Ray ray{from + direction * epsilon, direction};
        const bool expected = bruteForce.Any(ray, 0.f, distance - 2.f * epsilon);
        if (i < 1000) REQUIRE(BruteForceAny(primitives, ray, 0.f, distance - 2.f * epsilon) == expected);
        REQUIRE(scene.Occluded(from, direction, distance) == expected);
        if (expected) occluded++;
    }
    INFO(occluded << " of 10000 segments occluded");
    REQUIRE(occluded > 2000);
    REQUIRE(occluded < 8000);
}

TEST_CASE("With cut-outs the BVH finds the nearest solid hit and any solid occluder, as brute force does", "[geometry][cutouts]") {
    // The random scene with two triangles in three cut out by a 3D checkerboard of cells
    // 0.05 wide (a test of the hit point alone, as the contract asks): the nearest hit
    // the test accepts, over every primitive, must be the BVH's (the same primitive, or an
    // exact tie), and a segment is occluded exactly when brute force finds such a hit on
    // it. Copies of the random scene's triangles that are cut out are kept as distinct
    // primitives too (a leaf must not merge them with their plain originals).
    const Scene scene = MakeRandomScene();
    Primitives primitives = Primitives::Of(scene);
    for (int i = 0; i < 40; i++) primitives.triangles.push_back(primitives.triangles[size_t(7 * i)]);
    PrimitiveSoup soup = primitives.Soup();
    const size_t triangleCount = primitives.triangles.size();
    for (size_t t = 0; t < triangleCount; t++) soup.mTriangleCutOut.push_back(t % 3 != 0);
    Bvh bvh;
    bvh.Build(soup);
    REQUIRE(bvh.HasCutOuts());
    const auto solidAt = [](const Vec3& aPoint) {
        const int cells = int(std::floor(aPoint.x / 0.05f)) + int(std::floor(aPoint.y / 0.05f)) + int(std::floor(aPoint.z / 0.05f));
        return (cells & 1) == 0;
    };
    const auto bruteForce = [&](const Ray& aRay, float aTMin, float& ioTMax) {
        int nearest = -1;
        for (size_t i = 0; i < triangleCount; i++) {
            const std::optional<float> t = HitTriangle(primitives.triangles[i], aRay, aTMin, ioTMax);
            if (t && (i % 3 == 0 || solidAt(aRay.mOrigin + *t * aRay.mDirection))) {
                ioTMax = *t;
                nearest = int(i);
            }
        }
        for (size_t s = 0; s < primitives.centers.size(); s++) {
            if (const std::optional<float> t = IntersectSphere(primitives.centers[s], primitives.radii[s], aRay, aTMin, ioTMax)) {
                ioTMax = *t;
                nearest = int(triangleCount + s);
            }
        }
        return nearest;
    };
    Rng rng(204, 0);
    int hits = 0, throughHoles = 0;
    for (int i = 0; i < 20000; i++) {
        const Ray ray{3.f * rng.GetVec3() - Vec3(1.5f), SampleUniformSphereW(rng.GetVec2())};
        const auto isSolid = [&](int aTriangle, float aT) {
            REQUIRE(aTriangle % 3 != 0);  // asked about cut-out triangles only
            return solidAt(ray.mOrigin + aT * ray.mDirection);
        };
        float bruteT = kInfinity, bvhT = kInfinity, plainT = kInfinity;
        const int brute = bruteForce(ray, 0.f, bruteT);
        const int found = bvh.Intersect(ray, 0.f, bvhT, isSolid);
        REQUIRE((found >= 0) == (brute >= 0));
        if (bvh.Intersect(ray, 0.f, plainT) >= 0 && plainT < bruteT) throughHoles++;
        if (brute < 0) continue;
        hits++;
        REQUIRE(bvhT == bruteT);
        if (found != brute) REQUIRE(bvhT == Approx(bruteT).epsilon(1e-5));
        // A shadow segment to just before the hit is free; one just past it is blocked.
        REQUIRE(!bvh.Occluded(ray, 0.f, 0.999f * bruteT, isSolid));
        REQUIRE(bvh.Occluded(ray, 0.f, 1.001f * bruteT, isSolid));
    }
    INFO(hits << " hits, " << throughHoles << " rays whose nearest hit without the cut-outs was in a hole");
    // Not vacuous: a seventh of the rays hit something, and some of those only past a hole.
    REQUIRE(hits > 2000);
    REQUIRE(throughHoles > 500);
}

TEST_CASE("The BVH handles primitives that all share one centroid", "[geometry]") {
    // Triangles whose bounding boxes are all centred on the origin (vertex offsets
    // (-a,-b,-d), (a, y1, z1), (x2, b, d) with |x2| <= a etc.): no split can separate them.
    Primitives primitives;
    Rng rng(204, 0);
    for (int i = 0; i < 300; i++) {
        const float a = 0.1f + rng.GetFloat(), b = 0.1f + rng.GetFloat(), d = 0.1f + rng.GetFloat();
        const auto within = [&](float aLimit) { return (2.f * rng.GetFloat() - 1.f) * aLimit; };
        primitives.AddTriangle(Vec3(-a, -b, -d), Vec3(a, within(b), within(d)), Vec3(within(a), b, d));
    }
    const PrimitiveSoup soup = primitives.Soup();
    for (int i = 0; i < soup.Count(); i++) REQUIRE(soup.Bounds(i).Centroid() == Vec3(0.f));
    Bvh bvh;
    bvh.Build(soup);
    REQUIRE(bvh.NodeCount() >= 1);
    REQUIRE(bvh.Depth() <= 64);
    REQUIRE(CompareBvhWithBruteForce(primitives, bvh, 5000, 2.f, 205) > 300);
}

TEST_CASE("The BVH stays within its depth bound when centroids form geometric progressions", "[geometry]") {
    // Along each axis, triangles whose centroids lie at 2^-k on that axis and at 0 on the
    // other two (k < 120; a triangle spans [0.75, 1.25] 2^-k along its axis and [-h, h]
    // across, so every centroid is exact). In a node, the few largest centroids of the
    // longest axis fall into the upper bins and all the others share the first bin, so
    // each SAH split peels off a handful of primitives: about 25 levels per axis, 75 in
    // all, more than the traversal stacks (64 entries per level of tree) hold without the
    // builder's depth cap. The 4-wide tree collapsed from it is shallower, never deeper.
    Primitives primitives;
    const float h = 0.5f;
    for (int axis = 0; axis < 3; axis++)
        for (int k = 0; k < 120; k++) {
            const float x = std::ldexp(1.f, -k);
            auto place = [axis](float aAlong, float aAcross1, float aAcross2) {
                Vec3 p;
                p[axis] = aAlong;
                p[(axis + 1) % 3] = aAcross1;
                p[(axis + 2) % 3] = aAcross2;
                return p;
            };
            primitives.AddTriangle(place(0.75f * x, -h, -h), place(1.25f * x, h, -h), place(x, 0.f, h));
        }
    Bvh bvh;
    bvh.Build(primitives.Soup());
    INFO("binary depth " << bvh.BuildDepth() << ", 4-wide depth " << bvh.Depth() << ", " << bvh.NodeCount() << " nodes");
    REQUIRE(bvh.BuildDepth() >= 50);  // the distribution really is pathological
    REQUIRE(bvh.BuildDepth() <= 64);  // and the traversal stacks are safe
    REQUIRE(bvh.Depth() <= bvh.BuildDepth());
    REQUIRE(CompareBvhWithBruteForce(primitives, bvh, 3000, 1.5f, 206) > 100);
}

TEST_CASE("The BVH over a million coincident triangles builds and finds the nearest of them and of the rest", "[geometry]") {
    // 10^6 copies of one triangle (a mesh exported many times over itself, a hostile
    // file): no split can separate them, so they form one leaf, which keeps one copy (a
    // ray would otherwise test all 10^6: 25 minutes per iteration of a 4 M-copy scene).
    // The build must not lose the distinct triangles beside them. Rays through the stack
    // hit it at its known distance; rays through the other triangles hit those.
    Primitives primitives;
    const Vec3 a(-1.f, -1.f, 0.f), b(1.f, -1.f, 0.f), c(0.f, 1.f, 0.f);
    for (int i = 0; i < 1000000; i++) primitives.AddTriangle(a, b, c);
    primitives.AddTriangle(Vec3(3.f, -1.f, 0.5f), Vec3(5.f, -1.f, 0.5f), Vec3(4.f, 1.f, 0.5f));  // beside the stack
    primitives.AddTriangle(Vec3(-1.f, -1.f, 2.f), Vec3(0.f, 1.f, 2.f), Vec3(1.f, -1.f, 2.f));    // above it
    Bvh bvh;
    bvh.Build(primitives.Soup());
    REQUIRE(bvh.PrimitiveCount() == 1000002);
    REQUIRE(bvh.BuildDepth() <= 64);
    // The stack's leaf keeps one copy; the two other triangles may share a leaf (the SAH
    // isolates the stack first, then finds one block for the two cheaper than a split).
    REQUIRE(bvh.LargestLeaf() <= 2);
    const Vec3 down(0.f, 0.f, -1.f);
    for (float x : {-0.3f, 0.f, 0.2f}) {
        float t = 100.f;  // from z = 5 straight down: the triangle at z = 2 first
        REQUIRE(bvh.Intersect(Ray{Vec3(x, -0.5f, 5.f), down}, 0.f, t) == 1000001);
        CHECK(t == Approx(3.f));
        t = 100.f;        // from z = 1: the stack at z = 0, one of its copies
        const int hit = bvh.Intersect(Ray{Vec3(x, -0.5f, 1.f), down}, 0.f, t);
        CHECK(hit >= 0);
        CHECK(hit < 1000000);
        CHECK(t == Approx(1.f));
        CHECK(bvh.Occluded(Ray{Vec3(x, -0.5f, 1.f), down}, 0.f, 2.f));
        CHECK_FALSE(bvh.Occluded(Ray{Vec3(x, -0.5f, 1.f), down}, 0.f, 0.99f));
    }
    float t = 100.f;
    CHECK(bvh.Intersect(Ray{Vec3(4.f, 0.f, 5.f), down}, 0.f, t) == 1000000);
    CHECK(t == Approx(4.5f));
    t = 100.f;
    CHECK(bvh.Intersect(Ray{Vec3(2.f, 0.f, 5.f), down}, 0.f, t) == -1);
}

namespace {

// Rays aimed at each primitive in turn, a thousandth of its size outside its surface and
// straight at it (into a random point of a sphere, along either normal of a triangle),
// so each distinct primitive is the nearest hit of some of them however the others
// overlap it. The BVH must find brute force's nearest primitive at its distance, and
// Occluded must agree on a segment that ends past that hit but before the next surface
// (only that primitive, or its copies, can block it) and on one that ends before it.
// Exact copies hit at the same t and may stand in for each other; brute force returns
// the first of them, and each first must be the nearest hit of some ray.
void CheckEveryPrimitiveIsFound(const Primitives& aPrimitives, const Bvh& aBvh, int aRaysPerPrimitive, uint64_t aSeed) {
    const size_t triangleCount = aPrimitives.triangles.size();
    const size_t count = triangleCount + aPrimitives.centers.size();
    const auto same = [&](size_t a, size_t b) {
        if ((a < triangleCount) != (b < triangleCount)) return false;
        if (a < triangleCount) return aPrimitives.triangles[a] == aPrimitives.triangles[b];
        return aPrimitives.centers[a - triangleCount] == aPrimitives.centers[b - triangleCount] &&
               aPrimitives.radii[a - triangleCount] == aPrimitives.radii[b - triangleCount];
    };
    std::vector<int> nearestCount(count, 0);
    Rng rng(aSeed, 0);
    for (size_t p = 0; p < count; p++)
        for (int i = 0; i < aRaysPerPrimitive; i++) {
            Vec3 surface, outward;
            float size;
            if (p < triangleCount) {
                const Triangle3& triangle = aPrimitives.triangles[p];
                const Vec2 b = SampleUniformTriangle(rng.GetVec2());
                surface = b.x * triangle[0] + b.y * triangle[1] + (1.f - b.x - b.y) * triangle[2];
                outward = glm::normalize(glm::cross(triangle[1] - triangle[0], triangle[2] - triangle[0]));
                if (rng.GetFloat() < 0.5f) outward = -outward;
                size = glm::length(triangle[1] - triangle[0]);
            } else {
                const size_t s = p - triangleCount;
                outward = SampleUniformSphereW(rng.GetVec2());
                surface = aPrimitives.centers[s] + aPrimitives.radii[s] * outward;
                size = aPrimitives.radii[s];
            }
            const Ray ray{surface + 1e-3f * size * outward, -outward};
            float bruteT = kInfinity, bvhT = kInfinity;
            const int brute = BruteForceNearest(aPrimitives, ray, 0.f, bruteT);
            const int bvh = aBvh.Intersect(ray, 0.f, bvhT);
            INFO("ray " << i << " aimed at primitive " << p << ": brute force finds " << brute << " at t = " << bruteT
                        << ", the BVH " << bvh << " at t = " << bvhT);
            REQUIRE(brute >= 0);
            nearestCount[size_t(brute)]++;
            REQUIRE(bvh >= 0);
            REQUIRE((bvh == brute || same(size_t(bvh), size_t(brute))));
            REQUIRE(bvhT == Approx(bruteT).epsilon(1e-6));
            float nextT = kInfinity;  // the next surface along the ray (a copy's is this one)
            BruteForceNearest(aPrimitives, ray, bruteT * (1.f + 1e-4f), nextT);
            const float pastHit = std::isfinite(nextT) ? 0.5f * (bruteT + nextT) : 2.f * bruteT;
            REQUIRE(BruteForceAny(aPrimitives, ray, 0.f, pastHit));
            REQUIRE(aBvh.Occluded(ray, 0.f, pastHit));
            REQUIRE_FALSE(BruteForceAny(aPrimitives, ray, 0.f, 0.5f * bruteT));
            REQUIRE_FALSE(aBvh.Occluded(ray, 0.f, 0.5f * bruteT));
        }
    for (size_t p = 0; p < count; p++) {
        size_t first = 0;
        while (!same(first, p)) first++;
        INFO("primitive " << p << " (first copy " << first << ") is the nearest hit of no ray");
        REQUIRE(nearestCount[first] > 0);
    }
}

} // namespace

TEST_CASE("The BVH tests every distinct sphere of a leaf: same radius, same centre, beside copies and triangles", "[geometry]") {
    // A leaf's spheres share blocks of kBvhLanes lanes (4, 8 with AVX2, 4 scalar) that
    // are tested one sphere at a time, up to the lanes filled with copies of the last one;
    // a leaf of primitives sharing one centroid keeps one of each group of exact copies.
    // Each scene below is one leaf in every build (NodeCount() == 1: up to kBvhLanes
    // primitives cost one block, which no split beats, and the SAH does not split a few
    // overlapping primitives whose halves would each cost nearly the whole box), so a
    // block that skips a distinct sphere (taken for a copy by its centre, its radius or
    // its kind) misses the rays aimed at it. Together, 10 apart, they check the same
    // leaves below inner nodes.
    struct Case {
        const char* name;
        Primitives primitives;
        uint32_t leafSize;  // its copies included when it has at most eight primitives
    };
    std::vector<Case> cases;
    {
        // Radius 1, centres 0.1 apart at the corners of a small cube.
        Primitives p;
        for (int corner = 0; corner < 8; corner++)
            p.AddSphere(0.05f * Vec3(corner & 1 ? 1.f : -1.f, corner & 2 ? 1.f : -1.f, corner & 4 ? 1.f : -1.f), 1.f);
        cases.push_back({"eight spheres of one radius, centres 0.1 apart", p, 8});
    }
    {
        Primitives p;
        for (float radius : {1.f, 0.4f, 1.6f, 0.6f, 1.2f, 0.8f, 1.4f}) p.AddSphere(Vec3(0.3f, -0.2f, 0.1f), radius);
        cases.push_back({"seven concentric spheres", p, 7});
    }
    {
        // More than eight primitives on one centroid (centre and radii in eighths, so
        // every bounding box has it exactly): the leaf keeps one of each copy group,
        // seven spheres sorted by radius, and fills its last block with the largest.
        Primitives p;
        for (float radius : {0.75f, 0.5f, 1.25f, 0.5f, 0.625f, 1.5f, 0.75f, 0.875f, 1.25f, 0.5f, 1.f, 1.25f, 0.75f})
            p.AddSphere(Vec3(-0.125f, 0.25f, 0.375f), radius);
        cases.push_back({"thirteen concentric spheres, seven distinct", p, 7});
    }
    {
        // A sphere and its exact copy (two primitives of a leaf of at most eight, both
        // kept), then spheres of the same centre, of the same radius and of neither.
        Primitives p;
        p.AddSphere(Vec3(0.f), 1.f);
        p.AddSphere(Vec3(0.f), 1.f);
        p.AddSphere(Vec3(0.f), 0.7f);
        p.AddSphere(Vec3(0.1f, 0.f, 0.f), 1.f);
        p.AddSphere(Vec3(0.f, -0.05f, 0.08f), 0.9f);
        p.AddSphere(Vec3(0.f, 0.1f, 0.f), 1.f);
        cases.push_back({"a sphere, its copy, and spheres of its centre and of its radius", p, 6});
    }
    {
        // Triangles first in the leaf's blocks, then the spheres.
        Primitives p;
        p.AddTriangle(Vec3(-1.f, -1.f, 0.f), Vec3(1.f, -1.f, 0.f), Vec3(0.f, 1.f, 0.f));
        p.AddTriangle(Vec3(-1.f, 0.f, -1.f), Vec3(0.f, 0.f, 1.f), Vec3(1.f, 0.f, -1.f));
        p.AddTriangle(Vec3(0.f, -1.f, -1.f), Vec3(0.f, 1.f, -1.f), Vec3(0.f, 0.f, 1.f));
        p.AddSphere(Vec3(0.1f, 0.1f, 0.f), 0.5f);
        p.AddSphere(Vec3(0.1f, 0.1f, 0.f), 0.3f);
        p.AddSphere(Vec3(-0.1f, 0.f, 0.1f), 0.5f);
        p.AddSphere(Vec3(0.f, -0.1f, -0.1f), 0.6f);
        p.AddSphere(Vec3(0.f, -0.1f, -0.1f), 0.6f);
        cases.push_back({"three triangles and five spheres, one a copy", p, 8});
    }
    Primitives together;
    uint64_t seed = 209;
    for (size_t c = 0; c < cases.size(); c++) {
        const Case& one = cases[c];
        INFO(one.name);
        Bvh bvh;
        bvh.Build(one.primitives.Soup());
        REQUIRE(bvh.NodeCount() == 1);
        REQUIRE(bvh.LargestLeaf() == one.leafSize);
        CheckEveryPrimitiveIsFound(one.primitives, bvh, 200, seed++);
        const Vec3 offset(10.f * float(c), 0.f, 0.f);
        for (const Triangle3& t : one.primitives.triangles) together.AddTriangle(t[0] + offset, t[1] + offset, t[2] + offset);
        for (size_t s = 0; s < one.primitives.centers.size(); s++)
            together.AddSphere(one.primitives.centers[s] + offset, one.primitives.radii[s]);
    }
    Bvh bvh;
    bvh.Build(together.Soup());
    REQUIRE(bvh.NodeCount() > 1);
    CheckEveryPrimitiveIsFound(together, bvh, 50, seed);
}

TEST_CASE("TriangleNormal: unit normal by the winding in double precision, false for lines and points", "[geometry]") {
    std::optional<Vec3> n = TriangleNormal(Vec3(0.f), Vec3(1.f, 0.f, 0.f), Vec3(0.f, 1.f, 0.f));
    REQUIRE(n);
    CHECK(*n == Vec3(0.f, 0.f, 1.f));
    n = TriangleNormal(Vec3(0.f), Vec3(0.f, 1.f, 0.f), Vec3(1.f, 0.f, 0.f));
    REQUIRE(n);
    CHECK(*n == Vec3(0.f, 0.f, -1.f));
    // A needle 1e6 long and 1e-3 wide, far from the origin: float's cross product of its
    // edges keeps about one digit, double's all of them.
    const Vec3 base(1e4f, 2e4f, 3e4f);
    n = TriangleNormal(base, base + Vec3(1e6f, 0.f, 0.f), base + Vec3(5e5f, 1e-3f, 0.f));
    REQUIRE(n);
    CHECK(std::abs(n->z - 1.f) < 1e-6f);
    CHECK(std::abs(n->x) < 1e-6f);
    CHECK(std::abs(n->y) < 1e-6f);
    // Degenerate: a repeated vertex, three collinear points (also at large coordinates),
    // a single point.
    CHECK_FALSE(TriangleNormal(Vec3(1.f), Vec3(1.f), Vec3(2.f, 0.f, 0.f)));
    CHECK_FALSE(TriangleNormal(Vec3(0.f), Vec3(1.f, 2.f, 3.f), Vec3(2.f, 4.f, 6.f)));
    CHECK_FALSE(TriangleNormal(Vec3(1e7f, 1e7f, 0.f), Vec3(2e7f, 2e7f, 0.f), Vec3(4e7f, 4e7f, 0.f)));
    CHECK_FALSE(TriangleNormal(Vec3(0.5f), Vec3(0.5f), Vec3(0.5f)));
    // Edges longer than float's range are still exact in double: a valid normal.
    n = TriangleNormal(Vec3(-3e38f, 0.f, 0.f), Vec3(3e38f, 0.f, 0.f), Vec3(0.f, 3e38f, 0.f));
    REQUIRE(n);
    CHECK(*n == Vec3(0.f, 0.f, 1.f));
}

TEST_CASE("Scene::Finalize names a degenerate triangle by index", "[geometry]") {
    Scene scene;
    scene.mName = "hand-made";
    const int material = scene.AddMaterial(Material{});
    scene.AddTriangle(Vec3(0.f), Vec3(1.f, 0.f, 0.f), Vec3(0.f, 1.f, 0.f), material);
    scene.AddTriangle(Vec3(0.f), Vec3(1.f, 1.f, 1.f), Vec3(3.f, 3.f, 3.f), material);
    scene.AddPointLight(Vec3(0.f, 0.f, 1.f), Vec3(1.f));
    REQUIRE_THROWS_WITH(scene.Finalize(), "hand-made: triangle 1 is degenerate (zero area: its vertices coincide or lie on a line)");
}

TEST_CASE("Scene::Finalize refuses lights whose power or area pdf would overflow single precision", "[geometry]") {
    // The bounds (kMaxLightPower, kMinLightArea) leave headroom that test_stability
    // measures: all estimators stay finite just inside them.
    auto scene = [](float aRadiance, float aSphereRadius) {
        Scene s;
        s.mName = "lights";
        const int material = s.AddMaterial(Material{});
        s.AddTriangle(Vec3(-1.f, -1.f, 0.f), Vec3(1.f, -1.f, 0.f), Vec3(0.f, 1.f, 0.f), material);
        s.AddSphereLight(s.AddSphere(Vec3(0.f, 0.f, 0.5f), aSphereRadius, material), Vec3(aRadiance));
        return s;
    };
    // Radius 0.1: area 0.126, power = pi * area * L = 0.395 L.
    REQUIRE_NOTHROW(scene(2e30f, 0.1f).Finalize());
    REQUIRE_THROWS_WITH(scene(3e30f, 0.1f).Finalize(), Catch::Contains("lights: light 0 (sphere) emits a power of 1.18e+30") &&
                                                       Catch::Contains("scale its emission down"));
    REQUIRE_NOTHROW(scene(1.f, 3e-16f).Finalize());  // area 1.13e-30
    REQUIRE_THROWS_WITH(scene(1.f, 2e-16f).Finalize(), Catch::Contains("light 0 (sphere) has an area of 5.03e-31") &&
                                                       Catch::Contains("use a point light"));
    Scene point = scene(1.f, 0.1f);
    point.mLights.clear();
    point.mSpheres[0].mLightId = -1;
    point.AddPointLight(Vec3(0.f, 0.f, 1.f), Vec3(1e29f));  // power 4 pi 1e29 = 1.26e30
    REQUIRE_THROWS_WITH(point.Finalize(), Catch::Contains("light 0 (point) emits a power of 1.26e+30"));
}

TEST_CASE("A BVH over a single triangle or a single sphere is one leaf and finds it", "[geometry]") {
    Primitives oneTriangle;
    oneTriangle.AddTriangle(Vec3(0.f), Vec3(1.f, 0.f, 0.f), Vec3(0.f, 1.f, 0.f));
    Bvh triangleBvh;
    triangleBvh.Build(oneTriangle.Soup());
    REQUIRE(triangleBvh.NodeCount() == 1);
    REQUIRE(triangleBvh.Depth() == 1);
    float t = kInfinity;
    REQUIRE(triangleBvh.Intersect(Ray{Vec3(0.2f, 0.2f, 1.f), Vec3(0.f, 0.f, -1.f)}, 0.f, t) == 0);
    REQUIRE(t == Approx(1.f).epsilon(1e-6));
    REQUIRE(triangleBvh.Occluded(Ray{Vec3(0.2f, 0.2f, 1.f), Vec3(0.f, 0.f, -1.f)}, 0.f, 2.f));
    REQUIRE_FALSE(triangleBvh.Occluded(Ray{Vec3(0.2f, 0.2f, 1.f), Vec3(0.f, 0.f, -1.f)}, 0.f, 0.5f));
    REQUIRE(CompareBvhWithBruteForce(oneTriangle, triangleBvh, 2000, 1.5f, 207) > 0);

    Primitives oneSphere;
    oneSphere.AddSphere(Vec3(0.5f, 0.f, 0.f), 0.7f);
    Bvh sphereBvh;
    sphereBvh.Build(oneSphere.Soup());
    REQUIRE(sphereBvh.NodeCount() == 1);
    REQUIRE(sphereBvh.Depth() == 1);
    t = kInfinity;
    REQUIRE(sphereBvh.Intersect(Ray{Vec3(0.5f, 0.f, -5.f), Vec3(0.f, 0.f, 1.f)}, 0.f, t) == 0);
    REQUIRE(t == Approx(4.3f).epsilon(1e-6));
    REQUIRE(CompareBvhWithBruteForce(oneSphere, sphereBvh, 2000, 1.5f, 208) > 100);

    // And an empty BVH finds nothing.
    Bvh empty;
    empty.Build(PrimitiveSoup{});
    t = kInfinity;
    REQUIRE(empty.Intersect(Ray{}, 0.f, t) == -1);
    REQUIRE_FALSE(empty.Occluded(Ray{}, 0.f, kInfinity));
}

TEST_CASE("An axis-parallel ray lying in the plane of a bounding-box face still finds the triangle it hits", "[geometry]") {
    // A triangle with one edge in the plane {axis} = 0 and its third vertex at
    // {axis} = +1 or -1, so that this plane is the min or the max face of its bounding
    // box. A ray inside that plane with a direction component of exactly +0 or -0 along
    // {axis} hits the edge; the slab test then sees 0 * inf = NaN for that face, which
    // must count as "inside the slab", not as a miss.
    int failures = 0, cases = 0;
    std::string missed;
    for (const float side : {1.f, -1.f})
        for (const float zeroSign : {1.f, -1.f})
            for (int axis = 0; axis < 3; axis++) {
                auto place = [axis](const Vec3& aP) {
                    Vec3 q;
                    q[axis] = aP.x;
                    q[(axis + 1) % 3] = aP.y;
                    q[(axis + 2) % 3] = aP.z;
                    return q;
                };
                Primitives primitives;
                primitives.AddTriangle(place(Vec3(0.f, -1.f, -1.f)), place(Vec3(0.f, 1.f, -1.f)), place(Vec3(side, 0.f, 1.f)));
                Bvh bvh;
                bvh.Build(primitives.Soup());
                const Ray ray{place(Vec3(0.f, 0.3f, -5.f)), place(Vec3(zeroSign * 0.f, 0.f, 1.f))};
                float bruteT = kInfinity, bvhT = kInfinity;
                REQUIRE(BruteForceNearest(primitives, ray, 0.f, bruteT) == 0);  // the edge is inclusive
                REQUIRE(bruteT == Approx(4.f).epsilon(1e-6));
                const bool found = bvh.Intersect(ray, 0.f, bvhT) == 0;
                const bool occluded = bvh.Occluded(ray, 0.f, kInfinity);
                cases++;
                if (!found || !occluded) {
                    failures++;
                    missed += "\n  axis " + std::to_string(axis) + ", " + (side > 0.f ? "min" : "max") + " face, direction component " +
                              (zeroSign > 0.f ? "+0" : "-0");
                }
            }
    INFO(failures << " of " << cases << " configurations missed:" << missed);
    CHECK(failures == 0);
}

TEST_CASE("The BVH's hits are IntersectTriangle's bit for bit, for directions with ties, zeros and -0", "[geometry]") {
    // The BVH derives the watertight test's axis order and shear in its own way (vector
    // lanes per candidate axis, [SECTION] Appendix: BVH); it must pick the same axes on
    // ties (|x| = |y|, ...), zero and negative-zero components as WatertightRay and
    // divide the same numbers. Inside a closed cube of 12 triangles (one leaf) and of 768
    // (a tree), from several origins, every direction of components in {-1, -0.5, -0, 0,
    // 0.5, 1} and random ones: the same distance exactly, and a hit exactly when brute force has one.
    for (int subdivisions : {1, 8}) {
        Primitives cube;
        for (int axis = 0; axis < 3; axis++)
            for (float side : {-1.f, 1.f})
                for (int i = 0; i < subdivisions; i++)
                    for (int j = 0; j < subdivisions; j++) {
                        const auto corner = [&](int aI, int aJ) {
                            Vec3 p;
                            p[axis] = side;
                            p[(axis + 1) % 3] = -1.f + 2.f * float(aI) / float(subdivisions);
                            p[(axis + 2) % 3] = -1.f + 2.f * float(aJ) / float(subdivisions);
                            return p;
                        };
                        cube.AddTriangle(corner(i, j), corner(i + 1, j), corner(i + 1, j + 1));
                        cube.AddTriangle(corner(i, j), corner(i + 1, j + 1), corner(i, j + 1));
                    }
        Bvh bvh;
        bvh.Build(cube.Soup());
        INFO(cube.triangles.size() << " triangles, " << bvh.NodeCount() << " nodes");
        std::vector<Vec3> directions;
        const float components[] = {-1.f, -0.5f, -0.f, 0.f, 0.5f, 1.f};
        for (float x : components)
            for (float y : components)
                for (float z : components)
                    if (x != 0.f || y != 0.f || z != 0.f) directions.push_back(Vec3(x, y, z));
        Rng rng(211, 0);
        for (int i = 0; i < 500; i++) directions.push_back(SampleUniformSphereW(rng.GetVec2()));
        int hits = 0;
        for (const Vec3& origin : {Vec3(0.f), Vec3(0.25f, -0.5f, 0.125f), Vec3(-0.75f, 0.5f, 0.5f)})
            for (const Vec3& direction : directions) {
                const Ray ray{origin, direction};
                float bruteT = kInfinity, bvhT = kInfinity;
                const int brute = BruteForceNearest(cube, ray, 0.f, bruteT);
                const int found = bvh.Intersect(ray, 0.f, bvhT);
                INFO("direction " << direction.x << " " << direction.y << " " << direction.z);
                REQUIRE((found >= 0) == (brute >= 0));
                REQUIRE(std::memcmp(&bvhT, &bruteT, sizeof(float)) == 0);
                REQUIRE(bvh.Occluded(ray, 0.f, kInfinity) == (brute >= 0));
                hits += found >= 0;
            }
        REQUIRE(hits == 3 * int(directions.size()));
    }
}

// Finalize keeps per-material constants and per-triangle hit records that the renderers
// read instead of the materials and triangles; a change after it must not render with the
// old values unnoticed.
TEST_CASE("A material or a triangle's material changed after Finalize is an error until Finalize runs again", "[geometry]") {
    Scene scene = testutil::LoadCornell(4, 8, 8);
    RenderOptions options;
    options.mIterations = 1;
    options.mThreads = 1;
    options.mProgress = false;
    const std::optional<Algorithm> pt = ParseAlgorithm("pt");
    REQUIRE(pt);
    options.mAlgorithm = *pt;
    REQUIRE_NOTHROW(Render(scene, options));
    const auto message = [&]() -> std::string {
        try { Render(scene, options); } catch (const Error& error) { return error.what(); }
        return "";
    };
    scene.mMaterials[0].mDiffuseReflectance = scene.mMaterials[0].mDiffuseReflectance * 0.5f + Vec3(0.05f);
    CHECK_THAT(message(), Catch::Contains("material 0") && Catch::Contains("changed after Finalize(); call Finalize() again"));
    scene.Finalize();
    CHECK(message().empty());
    scene.mTriangles[0].mMaterialId = (scene.mTriangles[0].mMaterialId + 1) % int(scene.mMaterials.size());
    CHECK_THAT(message(), Catch::Contains("triangle 0"));
    scene.Finalize();
    CHECK(message().empty());
    // An emission texture given to an area light: only its triangles' records change.
    const auto lit = std::find_if(scene.mTriangles.begin(), scene.mTriangles.end(),
                                  [](const Triangle& aTriangle) { return aTriangle.mLightId >= 0; });
    REQUIRE(lit != scene.mTriangles.end());
    Texture white;
    white.mWidth = white.mHeight = 1;
    white.mTexels = {Vec3(1.f)};
    scene.mTextures.push_back(white);
    scene.mLights[size_t(lit->mLightId)].mEmissionTexture = int(scene.mTextures.size()) - 1;
    CHECK_THAT(message(), Catch::Contains("triangle " + std::to_string(lit - scene.mTriangles.begin())));
    scene.Finalize();
    CHECK(message().empty());
    scene.mMaterials.push_back(scene.mMaterials[0]);
    CHECK_THAT(message(), Catch::Contains("the number of materials"));
}
