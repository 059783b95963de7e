// [shading] Smooth shading normals: the interpolated normal at a hit, the loader's NORMAL
// checks, the adjoint factor of the Bsdf, the no-leak rule, and (tagged [integrators],
// so `make unit` skips it) the agreement of path tracing with the estimators that
// transport importance on a smooth-shaded low-polygon sphere, and of path tracing with
// BPT and VCM on a box with checker-textured walls.
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <cstdio>

using namespace smallvcm;
using namespace testutil;

namespace {

// Mean radiance (channel average) of two regions of the image, per batch of iterations.
struct RegionMeans {
    std::vector<double> mSphere, mRest, mImage;
};
enum class Region { kSphere, kRest, kNone };

// The two regions' batch means (RegionBatchMeans: aBatches renders, seeds aSeed, ...).
RegionMeans RenderRegions(const Scene& aScene, Algorithm aAlgorithm, int aBatches, int aIterations, uint64_t aSeed,
                          const std::vector<Region>& aRegions) {
    std::vector<int> regionOfPixel;
    for (Region region : aRegions) regionOfPixel.push_back(region == Region::kSphere ? 0 : region == Region::kRest ? 1 : -1);
    std::vector<std::vector<double>> means = RegionBatchMeans(aScene, aAlgorithm, aBatches, aIterations, aSeed, regionOfPixel, 2);
    return RegionMeans{std::move(means[0]), std::move(means[1]), std::move(means[2])};
}

// The sphere: pixels whose centre sees a smooth (vertex-normal) triangle first. The
// rest: every other pixel except those that see the light, whose edges make path
// tracing's (and only its) pixel estimates very noisy.
std::vector<Region> Regions(const Scene& aScene) {
    const Camera& camera = aScene.mCamera;
    std::vector<Region> regions(size_t(camera.PixelCount()), Region::kRest);
    for (int p = 0; p < camera.PixelCount(); p++) {
        const Vec2 corner(float(p % camera.Width()), float(p / camera.Width()));
        for (const Vec2 offset : {Vec2(0.5f), Vec2(0.f), Vec2(1.f, 0.f), Vec2(0.f, 1.f), Vec2(1.f)}) {
            const SurfacePoint hit = aScene.Intersect(camera.GenerateRay(corner + offset * 0.999f));
            if (!hit.IsValid()) continue;
            if (hit.mLightId >= 0) regions[size_t(p)] = Region::kNone;
            const bool smooth = hit.mPrimitiveId < int(aScene.mTriangles.size()) &&
                                aScene.mTriangles[size_t(hit.mPrimitiveId)].mHasVertexNormals;
            if (offset == Vec2(0.5f) && smooth) regions[size_t(p)] = Region::kSphere;
        }
    }
    return regions;
}

// The point straight below aOrigin where a downward ray meets aScene.
SurfacePoint HitBelow(const Scene& aScene, const Vec3& aOrigin) {
    const SurfacePoint hit = aScene.Intersect(Ray{aOrigin, Vec3(0.f, 0.f, -1.f)});
    REQUIRE(hit.IsValid());
    return hit;
}

void RequireNear(const Vec3& aActual, const Vec3& aExpected, float aMargin = 1e-5f) {
    INFO("actual (" << aActual.x << ", " << aActual.y << ", " << aActual.z << "), expected (" << aExpected.x << ", "
                    << aExpected.y << ", " << aExpected.z << ")");
    REQUIRE(glm::length(aActual - aExpected) < aMargin);
}

} // namespace

TEST_CASE("A smooth triangle interpolates its vertex normals; flat triangles and spheres shade with the geometric normal", "[shading][geometry]") {
    // Triangle (0,0,0), (1,0,0), (0,1,0), front +z, its vertex normals tilted three ways.
    const Vec3 n0 = glm::normalize(Vec3(-0.3f, -0.3f, 1.f)), n1 = glm::normalize(Vec3(0.4f, 0.f, 1.f)),
               n2 = glm::normalize(Vec3(0.f, 0.5f, 1.f));
    Scene scene;
    Material white;
    white.mDiffuseReflectance = Vec3(0.5f);
    const int material = scene.AddMaterial(white);
    scene.AddTriangle(Vec3(0.f), Vec3(1.f, 0.f, 0.f), Vec3(0.f, 1.f, 0.f), material);
    scene.mTriangles.back().mHasVertexNormals = true;
    // Given at other lengths: Finalize normalises them.
    scene.mTriangles.back().mN0 = 2.f * n0;
    scene.mTriangles.back().mN1 = 0.5f * n1;
    scene.mTriangles.back().mN2 = n2;
    scene.AddTriangle(Vec3(3.f, 0.f, 0.f), Vec3(4.f, 0.f, 0.f), Vec3(3.f, 1.f, 0.f), material);  // flat
    scene.AddSphere(Vec3(-3.f, 0.f, 0.f), 0.5f, material);
    scene.AddPointLight(Vec3(0.f, 0.f, 3.f), Vec3(1.f));
    scene.Finalize();

    // At (just inside) each vertex, the vertex normal; at the centroid, their normalised mean.
    RequireNear(HitBelow(scene, Vec3(1e-6f, 1e-6f, 1.f)).ShadingNormal(), n0, 1e-5f);
    RequireNear(HitBelow(scene, Vec3(1.f - 2e-6f, 1e-6f, 1.f)).ShadingNormal(), n1, 1e-5f);
    RequireNear(HitBelow(scene, Vec3(1e-6f, 1.f - 2e-6f, 1.f)).ShadingNormal(), n2, 1e-5f);
    const SurfacePoint centroid = HitBelow(scene, Vec3(1.f / 3.f, 1.f / 3.f, 1.f));
    RequireNear(centroid.ShadingNormal(), glm::normalize(n0 + n1 + n2));
    REQUIRE(centroid.GeometricNormal() == Vec3(0.f, 0.f, 1.f));
    REQUIRE(std::abs(glm::length(centroid.ShadingNormal()) - 1.f) < 1e-6f);
    // Half way along the edge from vertex 1 to vertex 2.
    RequireNear(HitBelow(scene, Vec3(0.5f, 0.5f - 1e-6f, 1.f)).ShadingNormal(), glm::normalize(n1 + n2));

    const SurfacePoint flat = HitBelow(scene, Vec3(3.25f, 0.25f, 1.f));
    REQUIRE(flat.ShadingNormal() == flat.GeometricNormal());  // bit for bit: a Bsdf then computes as before
    const SurfacePoint sphere = scene.Intersect(Ray{Vec3(-3.f, -2.f, 0.1f), Vec3(0.f, 1.f, 0.f)});
    REQUIRE(sphere.IsValid());
    REQUIRE(sphere.ShadingNormal() == sphere.GeometricNormal());
}

TEST_CASE("A surface point carries unit geometric and shading normals with orthonormal frames, and a Bsdf set up from it equals one set up from its normals", "[shading][geometry]") {
    // A smooth triangle (front +z), a flat one, a sphere, and a two-sided smooth triangle
    // seen from behind (whose Bsdf turns the shading frame around).
    Scene scene;
    Material white;
    white.mDiffuseReflectance = Vec3(0.5f);
    white.mPhongReflectance = Vec3(0.3f);
    white.mPhongExponent = 20.f;
    Material twoSided = white;
    twoSided.mTwoSided = true;
    const int oneSidedId = scene.AddMaterial(white), twoSidedId = scene.AddMaterial(twoSided);
    for (const float x : {0.f, 6.f}) {
        scene.AddTriangle(Vec3(x, 0.f, 0.f), Vec3(x + 1.f, 0.f, 0.f), Vec3(x, 1.f, 0.f), x == 0.f ? oneSidedId : twoSidedId);
        Triangle& triangle = scene.mTriangles.back();
        triangle.mHasVertexNormals = true;
        triangle.mN0 = glm::normalize(Vec3(-0.3f, -0.3f, 1.f));
        triangle.mN1 = glm::normalize(Vec3(0.4f, 0.f, 1.f));
        triangle.mN2 = glm::normalize(Vec3(0.f, 0.5f, 1.f));
    }
    scene.AddTriangle(Vec3(3.f, 0.f, 0.f), Vec3(4.f, 0.f, 0.f), Vec3(3.f, 1.f, 0.f), oneSidedId);
    scene.AddSphere(Vec3(-3.f, 0.f, 0.f), 0.5f, oneSidedId);
    scene.AddPointLight(Vec3(0.f, 0.f, 3.f), Vec3(1.f));
    scene.Finalize();

    const auto sameFrame = [](const Frame& aA, const Frame& aB) { return aA.mX == aB.mX && aA.mY == aB.mY && aA.mZ == aB.mZ; };
    const Ray smoothRay{Vec3(0.3f, 0.2f, 1.f), Vec3(0.f, 0.f, -1.f)}, flatRay{Vec3(3.25f, 0.25f, 1.f), Vec3(0.f, 0.f, -1.f)};
    const Ray sphereRay{Vec3(-3.1f, -2.f, 0.2f), Vec3(0.f, 1.f, 0.f)}, behindRay{Vec3(6.3f, 0.2f, -1.f), Vec3(0.f, 0.f, 1.f)};
    for (const Ray& ray : {smoothRay, flatRay, sphereRay, behindRay}) {
        const SurfacePoint hit = scene.Intersect(ray);
        REQUIRE(hit.IsValid());
        for (const Frame& frame : {Frame(hit.GeometricNormal()), Frame(hit.ShadingNormal())}) {
            CHECK(std::abs(glm::length(frame.mX) - 1.f) < 1e-6f);
            CHECK(std::abs(glm::length(frame.mY) - 1.f) < 1e-6f);
            CHECK(std::abs(glm::length(frame.mZ) - 1.f) < 1e-6f);
            CHECK(std::abs(glm::dot(frame.mX, frame.mY)) < 1e-6f);
            RequireNear(glm::cross(frame.mX, frame.mY), frame.mZ, 1e-6f);  // right-handed
        }
        const bool smooth = hit.mPrimitiveId < int(scene.mTriangles.size()) && scene.mTriangles[size_t(hit.mPrimitiveId)].mHasVertexNormals;
        CHECK((hit.ShadingNormal() == hit.GeometricNormal()) == !smooth);
        CHECK(sameFrame(Frame(hit.ShadingNormal()), Frame(hit.GeometricNormal())) == !smooth);

        // The Bsdf from the surface point and from the two normals compute the same bits.
        const Material& material = scene.GetMaterial(hit.mMaterialId);
        for (const Transport transport : {Transport::kRadiance, Transport::kImportance}) {
            Bsdf fromPoint, fromNormals;
            fromPoint.Setup(ray, hit, scene, transport);
            fromNormals.Setup(-ray.mDirection, hit.GeometricNormal(), hit.ShadingNormal(), material, transport);
            REQUIRE(fromPoint.IsValid());
            REQUIRE(fromNormals.IsValid());
            CHECK(fromPoint.WorldDirFix() == fromNormals.WorldDirFix());
            CHECK(fromPoint.CosThetaFixGeometric() == fromNormals.CosThetaFixGeometric());
            Rng rng(7);
            for (int i = 0; i < 64; i++) {
                const Vec3 gen = SampleUniformSphereW(rng.GetVec2());
                const BsdfEval evalA = fromPoint.Evaluate(gen), evalB = fromNormals.Evaluate(gen);
                CHECK(evalA.mValue == evalB.mValue);
                CHECK(evalA.mCosThetaGen == evalB.mCosThetaGen);
                CHECK(evalA.mDirPdfW == evalB.mDirPdfW);
                CHECK(evalA.mRevPdfW == evalB.mRevPdfW);
            }
        }
    }
}

TEST_CASE("Vertex normals that point against the winding are turned to its side", "[shading][geometry]") {
    Scene scene;
    Material white;
    white.mDiffuseReflectance = Vec3(0.5f);
    scene.AddTriangle(Vec3(0.f), Vec3(1.f, 0.f, 0.f), Vec3(0.f, 1.f, 0.f), scene.AddMaterial(white));
    Triangle& triangle = scene.mTriangles.back();
    triangle.mHasVertexNormals = true;
    const Vec3 down = glm::normalize(Vec3(0.2f, 0.f, -1.f));
    triangle.mN0 = triangle.mN1 = triangle.mN2 = down;
    scene.AddPointLight(Vec3(0.f, 0.f, 3.f), Vec3(1.f));
    scene.Finalize();
    const SurfacePoint hit = HitBelow(scene, Vec3(0.25f, 0.25f, 1.f));
    REQUIRE(hit.GeometricNormal() == Vec3(0.f, 0.f, 1.f));
    RequireNear(hit.ShadingNormal(), -down);
}

TEST_CASE("A double-sided smooth mesh wound against its normals still reflects from the side the normals face", "[shading][geometry]") {
    // The triangle is wound to face -z, its vertex normals say +z (a reversed winding).
    Scene scene;
    Material white;
    white.mDiffuseReflectance = Vec3(0.5f);
    white.mTwoSided = true;
    scene.AddTriangle(Vec3(0.f), Vec3(0.f, 1.f, 0.f), Vec3(1.f, 0.f, 0.f), scene.AddMaterial(white));
    Triangle& triangle = scene.mTriangles.back();
    triangle.mHasVertexNormals = true;
    triangle.mN0 = glm::normalize(Vec3(-0.2f, 0.f, 1.f));
    triangle.mN1 = glm::normalize(Vec3(0.f, 0.2f, 1.f));
    triangle.mN2 = glm::normalize(Vec3(0.2f, 0.f, 1.f));
    scene.AddPointLight(Vec3(0.f, 0.f, 3.f), Vec3(1.f));
    scene.Finalize();
    const Ray ray{Vec3(0.25f, 0.25f, 1.f), Vec3(0.f, 0.f, -1.f)};
    const SurfacePoint hit = scene.Intersect(ray);
    REQUIRE(hit.IsValid());
    REQUIRE(hit.GeometricNormal().z < 0.f);
    REQUIRE(hit.ShadingNormal().z < 0.f);  // turned to the winding's side
    for (const Transport transport : {Transport::kRadiance, Transport::kImportance}) {
        Bsdf bsdf;
        bsdf.Setup(ray, hit, scene, transport);
        REQUIRE(bsdf.IsValid());
        CHECK(!IsBlack(bsdf.Evaluate(glm::normalize(Vec3(0.3f, 0.1f, 1.f))).mValue));
        CHECK(IsBlack(bsdf.Evaluate(glm::normalize(Vec3(0.3f, 0.1f, -1.f))).mValue));
    }
}

TEST_CASE("NORMAL is normalised, noted and carried to world space by the inverse transpose", "[shading][gltf]") {
    // tests/data/make_bad_gltf.py: the 2 x 2 floor stretched to 4 x 2 by a node scale
    // (2, 1, 1); its normals lean by (-+0.6, 0, 0.8) at x = -+1 (two given twice as long).
    GltfLoadReport report;
    const Scene scene = LoadGltfScene("data/gltf/normals_scaled.gltf", &report);
    bool noted = false;
    for (const std::string& note : report.mNotes)
        noted = noted || note.find("NORMAL of 2 of 4 vertices is not of unit length") != std::string::npos;
    REQUIRE(noted);
    // World normals: diag(1/2, 1, 1) (-+0.6, 0, 0.8), normalised: the lean halves.
    const Vec3 left = glm::normalize(Vec3(-0.3f, 0.f, 0.8f)), right = glm::normalize(Vec3(0.3f, 0.f, 0.8f));
    RequireNear(HitBelow(scene, Vec3(-2.f + 1e-5f, 0.5f, 0.5f)).ShadingNormal(), left, 1e-4f);
    RequireNear(HitBelow(scene, Vec3(2.f - 1e-5f, -0.5f, 0.5f)).ShadingNormal(), right, 1e-4f);
    // The vertex normals depend on x only, so interpolation is linear in x: at x = 1,
    // a quarter of the left normal and three quarters of the right one.
    RequireNear(HitBelow(scene, Vec3(1.f, 0.5f, 0.5f)).ShadingNormal(), glm::normalize(0.25f * left + 0.75f * right), 1e-5f);
    RequireNear(HitBelow(scene, Vec3(0.f, -0.5f, 0.5f)).ShadingNormal(), Vec3(0.f, 0.f, 1.f), 1e-5f);
}

TEST_CASE("The adjoint shading factor and the Bsdf of both transport directions", "[shading][bsdf]") {
    // |fix.Ns| |gen.Ng| / (|fix.Ng| |gen.Ns|), signs ignored.
    REQUIRE(AdjointShadingFactor(0.8f, 0.6f, 0.5f, 0.9f) == Approx(0.8 * 0.9 / (0.6 * 0.5)).epsilon(1e-6));
    REQUIRE(AdjointShadingFactor(-0.8f, -0.6f, 0.5f, 0.9f) == Approx(2.4).epsilon(1e-6));
    REQUIRE(AdjointShadingFactor(0.3f, 0.3f, 0.7f, 0.7f) == 1.f);

    // Lambert on a surface whose shading normal leans 25 degrees from the geometric one.
    Material lambert;
    lambert.mDiffuseReflectance = Vec3(0.6f);
    const Vec3 ng(0.f, 0.f, 1.f), ns = glm::normalize(Vec3(std::sin(0.436f), 0.f, std::cos(0.436f)));
    Rng rng(5, 0);
    int compared = 0;
    for (int i = 0; i < 2000; i++) {
        const Vec3 a = SampleUniformSphereW(rng.GetVec2()), b = SampleUniformSphereW(rng.GetVec2());
        // a: towards the light, b: towards the eye. Both must be on the front of both normals.
        const bool valid = glm::dot(a, ng) > 0.01f && glm::dot(a, ns) > 0.01f && glm::dot(b, ng) > 0.01f && glm::dot(b, ns) > 0.01f;
        Bsdf camera, light;
        camera.Setup(b, ng, ns, lambert, Transport::kRadiance);
        light.Setup(a, ng, ns, lambert, Transport::kImportance);
        const BsdfEval evalCamera = camera.Evaluate(a), evalLight = light.Evaluate(b);
        const Vec3 fCamera = evalCamera.mValue, fLight = evalLight.mValue;
        const float cosCamera = evalCamera.mCosThetaGen, cosLight = evalLight.mCosThetaGen;
        if (!valid) continue;
        compared++;
        // f_path(a -> b) = f_s |a.Ns| / |a.Ng|; each side's f cos must be f_path times the
        // geometric cosine of its generated direction (section notes of the BSDF).
        const float fPath = 0.6f / kPi * glm::dot(a, ns) / glm::dot(a, ng);
        REQUIRE(fCamera.x * cosCamera == Approx(fPath * glm::dot(a, ng)).epsilon(1e-4));
        REQUIRE(fLight.x * cosLight == Approx(fPath * glm::dot(b, ng)).epsilon(1e-4));
        REQUIRE(camera.EvaluatePath(a).x == Approx(fPath).epsilon(1e-4));
        REQUIRE(light.EvaluatePath(b).x == Approx(fPath).epsilon(1e-4));
        REQUIRE(camera.GeometricCos(a, cosCamera) == Approx(glm::dot(a, ng)).epsilon(1e-5));
        REQUIRE(light.CosThetaFixGeometric() == Approx(glm::dot(a, ng)).epsilon(1e-5));
        // Sample returns the same f as Evaluate for the direction it picks.
        const std::optional<ScatterSample> sample = light.Sample(rng.GetVec3());
        if (!sample) continue;
        REQUIRE(sample->mValue.x == Approx(light.Evaluate(sample->mDirection).mValue.x).epsilon(1e-4));
        REQUIRE(sample->mPdfW == Approx(light.Pdf(sample->mDirection)).epsilon(1e-4));
    }
    REQUIRE(compared > 250);  // about a fifth of the pairs are on the front of both normals
}

TEST_CASE("No light leaks: a direction on different sides of the shading and the geometric surface is black", "[shading][bsdf]") {
    Material lambert;
    lambert.mDiffuseReflectance = Vec3(0.6f);
    const Vec3 ng(0.f, 0.f, 1.f), ns = glm::normalize(Vec3(0.5f, 0.f, 1.f));  // leans 26.6 degrees to +x
    // Just below the geometric surface but above the shading one (it leans towards +x).
    const Vec3 wedge = glm::normalize(Vec3(1.f, 0.f, -0.2f));
    REQUIRE(glm::dot(wedge, ns) > 0.f);
    REQUIRE(glm::dot(wedge, ng) < 0.f);
    const Vec3 up = glm::normalize(Vec3(0.f, 0.3f, 1.f));
    for (const Transport transport : {Transport::kRadiance, Transport::kImportance}) {
        Bsdf bsdf;
        bsdf.Setup(up, ng, ns, lambert, transport);
        REQUIRE(bsdf.IsValid());
        const BsdfEval eval = bsdf.Evaluate(wedge);
        REQUIRE(IsBlack(eval.mValue));
        REQUIRE(eval.mDirPdfW == 0.f);
        REQUIRE(eval.mRevPdfW == 0.f);
        REQUIRE(!IsBlack(bsdf.Evaluate(up).mValue));
        // Sample never returns a direction below the geometric surface (some fall in the wedge).
        Rng rng(11, 0);
        int black = 0;
        for (int i = 0; i < 20000; i++) {
            const std::optional<ScatterSample> sample = bsdf.Sample(rng.GetVec3());
            if (!sample) { black++; continue; }
            REQUIRE(glm::dot(sample->mDirection, ng) > 0.f);
        }
        REQUIRE(black > 0);
        // Arriving from the wedge: nothing (the one-sided Lambert's back, seen by Ng).
        Bsdf fromWedge;
        fromWedge.Setup(wedge, ng, ns, lambert, transport);
        REQUIRE(!fromWedge.IsValid());
    }
}

TEST_CASE("A two-sided smooth surface seen from behind turns both normals; a one-sided one is black there", "[shading][bsdf]") {
    Material material;
    material.mDiffuseReflectance = Vec3(0.6f);
    const Vec3 ng(0.f, 0.f, 1.f), ns = glm::normalize(Vec3(0.3f, 0.f, 1.f));
    const Vec3 behind = glm::normalize(Vec3(0.1f, 0.2f, -1.f)), alsoBehind = glm::normalize(Vec3(-0.3f, 0.f, -1.f));
    Bsdf oneSided;
    oneSided.Setup(behind, ng, ns, material, Transport::kRadiance);
    REQUIRE(!oneSided.IsValid());
    material.mTwoSided = true;
    for (const Transport transport : {Transport::kRadiance, Transport::kImportance}) {
        Bsdf twoSided;
        twoSided.Setup(behind, ng, ns, material, transport);
        REQUIRE(twoSided.IsValid());
        REQUIRE(twoSided.CosThetaFix() == Approx(glm::dot(behind, -ns)).epsilon(1e-5));
        REQUIRE(twoSided.CosThetaFixGeometric() == Approx(glm::dot(behind, -ng)).epsilon(1e-5));
        const BsdfEval eval = twoSided.Evaluate(alsoBehind);
        const Vec3 f = eval.mValue;
        REQUIRE(eval.mCosThetaGen == Approx(glm::dot(alsoBehind, -ns)).epsilon(1e-5));
        const float adjoint = transport == Transport::kImportance ? AdjointShadingFactor(glm::dot(behind, ns), glm::dot(behind, ng),
                                                                glm::dot(alsoBehind, ns), glm::dot(alsoBehind, ng)) : 1.f;
        REQUIRE(f.x == Approx(0.6f / kPi * adjoint).epsilon(1e-5));
        // The front is on the other side now: a direction in front of Ng is black.
        REQUIRE(IsBlack(twoSided.Evaluate(glm::normalize(Vec3(0.f, 0.2f, 1.f))).mValue));
    }
}

TEST_CASE("Path tracing, light tracing, BPT and VCM agree on a smooth-shaded low-polygon sphere", "[integrators][shading]") {
    // scenes/smooth_sphere_box.gltf: an 80-triangle sphere with exact sphere normals as
    // NORMAL (up to ~21 degrees from its faces) in the Cornell box, 32 x 32 pixels.
    // Compared with path tracing, per region (the sphere; the rest without the light):
    // z = (m_other - m_pt) / sqrt(se_other^2 + se_pt^2), each standard error measured from
    // the spread of 24 independent batches (23 degrees of freedom); |z| < 4.5 gives each
    // of the 6 comparisons a false-alarm chance near 1.6e-4 (Student t). Iterations per
    // batch are split by each estimator's measured variance per iteration on the sphere
    // and its CPU cost per iteration (pt shares its side with all three comparisons), so
    // that every comparison's combined standard error on the sphere is about 2.5e-4,
    // 0.08 % of the image mean: 4.5 SE resolve 0.36-0.37 % of it (checked: < 0.5 %).
    // Measured 2026-11-27 (this seed): |z| <= 1.1 everywhere; with the adjoint factor
    // removed (AdjointShadingFactor returning 1) the sphere comes out 3-5 % too bright:
    // z = 23 (lt), 28 (bpt, vcm). About 25 s of CPU, ~12 s on 2 idle cores (with pt 256,
    // lt 512, bpt and vcm 160 iterations per batch: 35 s, and 4.5 SE resolved 0.38 % for
    // bpt and vcm but 0.46 % for lt).
    Scene scene = LoadGltfScene("../scenes/smooth_sphere_box.gltf");
    scene.mCamera.SetResolution(32, 32);
    const std::vector<Region> regions = Regions(scene);
    const int batches = 24;
    const RegionMeans pt = RenderRegions(scene, Algorithm::kPathTracing, batches, 448, 100, regions);
    const MeanAndError ptSphere = MeanOf(pt.mSphere), ptRest = MeanOf(pt.mRest), imageMean = MeanOf(pt.mImage);
    for (Algorithm other : {Algorithm::kLightTracing, Algorithm::kBidirectionalPathTracing, Algorithm::kVertexConnectionMerging}) {
        const RegionMeans stats = RenderRegions(scene, other, batches, other == Algorithm::kLightTracing ? 576 : 96, 200, regions);
        const MeanAndError sphere = MeanOf(stats.mSphere), rest = MeanOf(stats.mRest);
        const double seSphere = std::hypot(sphere.standardError, ptSphere.standardError);
        const double seRest = std::hypot(rest.standardError, ptRest.standardError);
        const double zSphere = (sphere.mean - ptSphere.mean) / seSphere, zRest = (rest.mean - ptRest.mean) / seRest;
        INFO(AlgorithmShortName(other) << " vs pt: sphere " << sphere.mean << " vs " << ptSphere.mean << " (z " << zSphere
             << "), rest " << rest.mean << " vs " << ptRest.mean << " (z " << zRest << "), image mean " << imageMean.mean);
        std::printf("[shading] smooth sphere, %-3s vs pt: z sphere %+.2f, rest %+.2f; 4.5 SE sphere %.3f %%, rest %.3f %% of the "
                    "image mean\n",
                    AlgorithmShortName(other), zSphere, zRest, 450.0 * seSphere / imageMean.mean, 450.0 * seRest / imageMean.mean);
        CHECK(std::abs(zSphere) < 4.5);
        CHECK(std::abs(zRest) < 4.5);
        CHECK(4.5 * seSphere < 0.005 * imageMean.mean);
        CHECK(4.5 * seRest < 0.005 * imageMean.mean);
    }
}

TEST_CASE("The textured torus loads smooth and textured, with the default camera and background", "[shading][gltf]") {
    GltfLoadReport report;
    const Scene scene = LoadGltfScene("../scenes/textured_torus.gltf", &report);
    CHECK(report.mDefaultCamera);
    CHECK(report.mDefaultBackground);
    REQUIRE(scene.mTriangles.size() == 2304);
    for (const Triangle& triangle : scene.mTriangles) {
        REQUIRE(triangle.mHasVertexNormals);
        REQUIRE(scene.GetMaterial(triangle.mMaterialId).mBaseColorTexture >= 0);
    }
}

TEST_CASE("Path tracing, BPT and VCM agree on a box whose diffuse walls carry a black-and-white checker texture", "[integrators][texture]") {
    // scenes/diffuse_box.gltf (the empty Cornell box under its area light), 24 x 24 pixels,
    // with every diffuse surface textured by an 8 x 8 checker of texels 0.05 and 0.95, so
    // a light vertex's reflectance differs from the untextured one by a factor of up to
    // 19. A connection rebuilds the light vertex's Bsdf from what the vertex stored, so it
    // must carry the texel (LightVertex::mUv). Compared with path tracing over the pixels
    // that do not see the light: z = (m_other - m_pt) / sqrt(se_other^2 + se_pt^2), each
    // standard error measured from the spread of 16 independent batches (15 degrees of
    // freedom); |z| < 4.5 gives each of the 2 comparisons a false-alarm chance near 4e-4
    // (Student t). The last CHECK makes sure the test resolves 1% of the mean.
    // Measured (this seed): z = -0.96 (bpt), -0.98 (vcm), standard error 0.16% of the
    // mean; with the connection's light-side Bsdf rebuilt without the texel (the bug
    // this guards) BPT and VCM come out 8.5% too bright: z = 47 (both). About 3 s.
    Scene scene = LoadGltfScene("../scenes/diffuse_box.gltf");
    scene.mCamera.SetResolution(24, 24);
    const int checkerSize = 8;
    Texture checker;
    checker.mWidth = checker.mHeight = checkerSize;
    for (int y = 0; y < checkerSize; y++)
        for (int x = 0; x < checkerSize; x++) checker.mTexels.push_back(Vec3((x + y) % 2 ? 0.95f : 0.05f));
    scene.mTextures.push_back(checker);
    for (Material& material : scene.mMaterials)
        if (!IsBlack(material.mDiffuseReflectance)) material.mBaseColorTexture = int(scene.mTextures.size()) - 1;
    // Planar texture coordinates: each triangle projected along its normal's largest axis,
    // one checker repeat per scene-sphere radius.
    const float scale = 1.f / scene.GetSceneSphere().mRadius;
    for (Triangle& triangle : scene.mTriangles) {
        const Vec3 n = glm::abs(triangle.mNormal);
        const int axis = n.x > n.y && n.x > n.z ? 0 : n.y > n.z ? 1 : 2;
        const auto project = [&](const Vec3& aPoint) {
            return Vec2(aPoint[(axis + 1) % 3], aPoint[(axis + 2) % 3]) * scale;
        };
        triangle.mUv0 = project(triangle.mP0);
        triangle.mUv1 = project(triangle.mP1);
        triangle.mUv2 = project(triangle.mP2);
    }
    scene.Finalize();  // the materials changed (Render refuses otherwise)
    std::vector<int> regionOfPixel(size_t(scene.mCamera.PixelCount()), 0);
    for (int p = 0; p < scene.mCamera.PixelCount(); p++) {
        const Vec2 corner(float(p % scene.mCamera.Width()), float(p / scene.mCamera.Width()));
        for (const Vec2 offset : {Vec2(0.5f), Vec2(0.f), Vec2(1.f, 0.f), Vec2(0.f, 1.f), Vec2(1.f)}) {
            const SurfacePoint hit = scene.Intersect(scene.mCamera.GenerateRay(corner + offset * 0.999f));
            if (hit.IsValid() && hit.mLightId >= 0)
                regionOfPixel[size_t(p)] = -1;
        }
    }
    const int batches = 16;
    const MeanAndError pt = MeanOf(RegionBatchMeans(scene, Algorithm::kPathTracing, batches, 64, 100, regionOfPixel, 1)[0]);
    for (Algorithm other : {Algorithm::kBidirectionalPathTracing, Algorithm::kVertexConnectionMerging}) {
        const MeanAndError walls = MeanOf(RegionBatchMeans(scene, other, batches, 32, 200, regionOfPixel, 1)[0]);
        const double se = std::hypot(walls.standardError, pt.standardError);
        const double z = (walls.mean - pt.mean) / se;
        INFO(AlgorithmShortName(other) << " vs pt: " << walls.mean << " +- " << walls.standardError << " vs " << pt.mean
                                       << " +- " << pt.standardError << " (z " << z << ")");
        CHECK(std::abs(z) < 4.5);
        CHECK(4.5 * se < 0.01 * pt.mean);
    }
}
