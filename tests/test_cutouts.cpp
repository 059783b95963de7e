// [cutouts] Alpha cut-outs (Material::mAlphaMode, Scene::IsSolidAt): the coverage rule of
// MASK and BLEND at a point, the same answer for nearest-hit and shadow rays, and whole
// scenes: a checkerboard-masked plane between a light and a floor passes half the light
// for every estimator, a fully cut-out plane is invisible and casts no shadow, and a
// plane masked with alpha 1 everywhere renders bit for bit like an opaque one. (The BVH's
// part, against brute force, is in test_geometry; the loader's in test_gltf.)
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <array>
#include <cmath>
#include <string>
#include <vector>

using namespace smallvcm;
using namespace testutil;

namespace {

// A 2 x 2 white texture with the given alphas (row by row from the top), repeated.
Texture AlphaTexture(float aTopLeft, float aTopRight, float aBottomLeft, float aBottomRight) {
    Texture t;
    t.mWidth = t.mHeight = 2;
    t.mTexels.assign(4, Vec3(1.f));
    t.mAlpha = {aTopLeft, aTopRight, aBottomLeft, aBottomRight};
    return t;
}

// The plane z = aZ over [-1, 1]^2 as two triangles facing +z, with texture coordinates
// uv = aPeriods ((x + 1) / 2, (y + 1) / 2): a 2 x 2 texture repeats aPeriods times across.
void AddPlane(Scene& ioScene, float aZ, int aMaterial, float aPeriods) {
    const Vec3 p[4] = {Vec3(-1.f, -1.f, aZ), Vec3(1.f, -1.f, aZ), Vec3(1.f, 1.f, aZ), Vec3(-1.f, 1.f, aZ)};
    const Vec2 uv[4] = {Vec2(0.f), Vec2(aPeriods, 0.f), Vec2(aPeriods), Vec2(0.f, aPeriods)};
    for (const auto& corners : {std::array<int, 3>{0, 1, 2}, std::array<int, 3>{0, 2, 3}}) {
        Triangle& t = ioScene.mTriangles[size_t(ioScene.AddTriangle(p[corners[0]], p[corners[1]], p[corners[2]], aMaterial))];
        t.mUv0 = uv[corners[0]];
        t.mUv1 = uv[corners[1]];
        t.mUv2 = uv[corners[2]];
    }
}

// A white floor (z = 0, [-1, 1]^2) under a 0.5 x 0.5 area light at z = 1 facing down.
// Nothing else: every light path is light -> floor (-> camera), direct light only.
Scene LitFloor() {
    Scene scene;
    const int white = scene.AddMaterial(DiffuseMaterial(0.8f, 0.8f, 0.8f));
    const int black = scene.AddMaterial(DiffuseMaterial(0.f, 0.f, 0.f));
    AddQuadFacing(scene, Vec3(-1, -1, 0), Vec3(1, -1, 0), Vec3(1, 1, 0), Vec3(-1, 1, 0), Vec3(0, 0, 1), white);
    std::vector<int> light;
    const float h = 0.25f;
    AddQuadFacing(scene, Vec3(-h, -h, 1), Vec3(h, -h, 1), Vec3(h, h, 1), Vec3(-h, h, 1), Vec3(0, 0, 0), black, &light);
    scene.AddAreaLight(light, Vec3(4.f));
    return scene;
}

// LitFloor with a plane at z = 0.5 between the light and the floor, of the given
// material (added after everything else, so the other primitives keep their indices,
// inside the floor's and light's bounding box, so the scene sphere stays the same).
Scene LitFloorUnder(const Material& aPlane, const Texture* aTexture, float aPeriods) {
    Scene scene = LitFloor();
    Material plane = aPlane;
    if (aTexture) {
        scene.mTextures.push_back(*aTexture);
        plane.mAlphaTexture = int(scene.mTextures.size()) - 1;
    }
    AddPlane(scene, 0.5f, scene.AddMaterial(plane), aPeriods);
    return scene;
}

Material WithAlpha(Material aMaterial, AlphaMode aMode, float aFactor, float aCutoff = 0.5f) {
    aMaterial.mAlphaMode = aMode;
    aMaterial.mBaseColorAlpha = aFactor;
    aMaterial.mAlphaCutoff = aCutoff;
    return aMaterial;
}

// What a ray straight down at (aX, aY) from z = 0.9 meets first: the plane (z = 0.5) or the floor.
float HeightHit(const Scene& aScene, float aX, float aY) {
    const SurfacePoint hit = aScene.Intersect(Ray{Vec3(aX, aY, 0.9f), Vec3(0.f, 0.f, -1.f)});
    REQUIRE(hit.IsValid());
    return hit.mPosition.z;
}
// Whether the segment from the floor at (aX, aY) straight up to z = 0.9 is blocked.
bool BlockedAbove(const Scene& aScene, float aX, float aY) {
    return aScene.Occluded(Vec3(aX, aY, 0.f), Vec3(0.f, 0.f, 1.f), 0.9f);
}

void Finalize(Scene& ioScene, int aSize) {
    ioScene.mCamera.SetResolution(aSize, aSize);
    ioScene.Finalize();
}

} // namespace

TEST_CASE("MASK keeps the surface where alpha >= alphaCutoff, BLEND where alpha >= 1/2, for nearest-hit and shadow rays alike",
          "[cutouts]") {
    const Material white = DiffuseMaterial(0.8f, 0.8f, 0.8f);
    const struct { AlphaMode mMode; float mFactor, mCutoff; bool mSolid; const char* mWhy; } cases[] = {
        {AlphaMode::kOpaque, 0.f, 0.5f, true, "OPAQUE ignores alpha"},
        {AlphaMode::kMask, 0.5f, 0.5f, true, "MASK: alpha equal to the cutoff is opaque"},
        {AlphaMode::kMask, 0.49f, 0.5f, false, "MASK: alpha below the cutoff is a hole"},
        {AlphaMode::kMask, 0.6f, 0.9f, false, "MASK: the cutoff is the material's"},
        {AlphaMode::kMask, 1.f, 1.5f, false, "MASK: a cutoff above 1 cuts everything"},
        {AlphaMode::kMask, 0.f, 0.f, true, "MASK: cutoff 0 keeps everything"},
        {AlphaMode::kBlend, 0.5f, 0.9f, true, "BLEND: thresholded at 1/2, its cutoff ignored"},
        {AlphaMode::kBlend, 0.49f, 0.1f, false, "BLEND: below 1/2 a hole, its cutoff ignored"},
    };
    for (const auto& c : cases) {
        INFO(c.mWhy);
        Scene scene = LitFloorUnder(WithAlpha(white, c.mMode, c.mFactor, c.mCutoff), nullptr, 1.f);
        Finalize(scene, 8);
        CHECK(scene.GetBvh().HasCutOuts() == (c.mMode != AlphaMode::kOpaque));
        CHECK(HeightHit(scene, 0.1f, 0.2f) == Approx(c.mSolid ? 0.5f : 0.f).margin(1e-5));
        CHECK(BlockedAbove(scene, 0.1f, 0.2f) == c.mSolid);
    }
}

TEST_CASE("The coverage multiplies the factor's alpha by the texture's at the hit's texture coordinates", "[cutouts]") {
    // Texture alphas 1, 0.3 over 0.7, 0.5, one period over the plane: uv = ((x + 1) / 2,
    // (y + 1) / 2) and row 0 at v = 0, so texel centres lie at x, y = +-0.5 (top row at y < 0).
    const Texture texture = AlphaTexture(1.f, 0.3f, 0.7f, 0.5f);
    Scene scene = LitFloorUnder(WithAlpha(DiffuseMaterial(0.8f, 0.8f, 0.8f), AlphaMode::kMask, 0.8f, 0.5f), &texture, 1.f);
    Finalize(scene, 8);
    // alpha x 0.8: 0.8, 0.24, 0.56, 0.4 against the cutoff 0.5.
    const struct { float mX, mY; bool mSolid; } points[] = {
        {-0.5f, -0.5f, true}, {0.5f, -0.5f, false}, {-0.5f, 0.5f, true}, {0.5f, 0.5f, false}};
    for (const auto& p : points) {
        INFO("(" << p.mX << ", " << p.mY << ")");
        CHECK(HeightHit(scene, p.mX, p.mY) == Approx(p.mSolid ? 0.5f : 0.f).margin(1e-5));
        CHECK(BlockedAbove(scene, p.mX, p.mY) == p.mSolid);
    }
    // A sphere of the same material has no cut-out: only triangles have one.
    Scene withSphere = LitFloor();
    withSphere.AddSphere(Vec3(0.f, 0.f, 0.5f), 0.1f,
                         withSphere.AddMaterial(WithAlpha(DiffuseMaterial(0.8f, 0.8f, 0.8f), AlphaMode::kMask, 0.f)));
    Finalize(withSphere, 8);
    CHECK(!withSphere.GetBvh().HasCutOuts());
    CHECK(HeightHit(withSphere, 0.f, 0.f) == Approx(0.6f));
}

TEST_CASE("A fully cut-out plane is invisible and casts no shadow: every estimator renders the scene without it bit for bit",
          "[cutouts][integrators]") {
    // A white plane of alpha 0 between the light and the floor, seen from above at an
    // angle: were any ray to stop on it, the image would differ (its own light, its shadow).
    Scene without = LitFloor();
    Scene with = LitFloorUnder(WithAlpha(DiffuseMaterial(0.8f, 0.8f, 0.8f), AlphaMode::kMask, 0.f), nullptr, 1.f);
    for (Scene* scene : {&without, &with}) {
        scene->mCamera.Setup(Vec3(0.f, -0.95f, 0.95f), Vec3(0.f, 1.f, -1.2f), Vec3(0.f, 0.f, 1.f), 70.f);
        Finalize(*scene, 16);
    }
    REQUIRE(with.GetBvh().HasCutOuts());
    for (const Algorithm algorithm : kTransportEstimators) {
        INFO(AlgorithmShortName(algorithm));
        const Image a = RenderWith(without, algorithm, 4).mImage;
        const Image b = RenderWith(with, algorithm, 4).mImage;
        REQUIRE(PixelStatistics(a).mean > 0.0);
        CHECK(a.mPixels == b.mPixels);
    }
}

TEST_CASE("A plane masked with alpha 1 everywhere renders bit for bit like the opaque plane, for every estimator",
          "[cutouts][integrators]") {
    const Texture opaqueTexture = AlphaTexture(1.f, 1.f, 1.f, 1.f);
    Scene opaque = LitFloorUnder(DiffuseMaterial(0.8f, 0.8f, 0.8f), nullptr, 1.f);
    Scene masked = LitFloorUnder(WithAlpha(DiffuseMaterial(0.8f, 0.8f, 0.8f), AlphaMode::kMask, 1.f), &opaqueTexture, 4.f);
    for (Scene* scene : {&opaque, &masked}) {
        scene->mCamera.Setup(Vec3(0.f, -0.95f, 0.95f), Vec3(0.f, 1.f, -1.2f), Vec3(0.f, 0.f, 1.f), 70.f);
        Finalize(*scene, 16);
    }
    REQUIRE(masked.GetBvh().HasCutOuts());
    for (const Algorithm algorithm : kTransportEstimators) {
        INFO(AlgorithmShortName(algorithm));
        const Image a = RenderWith(opaque, algorithm, 4).mImage;
        const Image b = RenderWith(masked, algorithm, 4).mImage;
        REQUIRE(PixelStatistics(a).mean > 0.0);
        CHECK(a.mPixels == b.mPixels);
    }
}

TEST_CASE("A checkerboard-masked plane between the light and the floor passes half the light, for every estimator",
          "[cutouts][integrators]") {
    // A black plane at z = 0.5 masked by a checkerboard of 64 x 64 periods (alpha 1 and 0
    // texels, bilinear: alpha >= 1/2 exactly on the texels of alpha 1), the floor seen from
    // a camera under the plane. All light reaches the floor directly, along segments that
    // cross the plane (nothing else reflects: plane and emitter are black), so the masked
    // floor receives T times the light of the open one, T the fraction of the light's
    // crossings that fall into holes: 1/2, up to how the integrand (cosines over squared
    // distance) varies across one period of 1/64 of the plane, a relative error far below
    // the noise here.
    // Tolerance: z = (masked - open / 2) / SE < 4, the SE measured from 8 independent
    // renders of each scene (disjoint seeds): SE^2 = SE_masked^2 + SE_open^2 / 4.
    const Texture checker = AlphaTexture(1.f, 0.f, 0.f, 1.f);
    const Material black = DiffuseMaterial(0.f, 0.f, 0.f);
    Scene open = LitFloorUnder(WithAlpha(black, AlphaMode::kMask, 0.f), nullptr, 1.f);
    Scene masked = LitFloorUnder(WithAlpha(black, AlphaMode::kMask, 1.f), &checker, 64.f);
    for (Scene* scene : {&open, &masked}) {
        scene->mCamera.Setup(Vec3(0.f, 0.f, 0.3f), Vec3(0.f, 0.f, -1.f), Vec3(0.f, 1.f, 0.f), 90.f);
        Finalize(*scene, 16);
    }
    for (const Algorithm algorithm : kTransportEstimators) {
        // Iterations so that each resolves about 2 % of the mean: light tracing and the
        // merging estimators put fewer samples on this small view of the floor.
        const int iterations = algorithm == Algorithm::kProgressivePhotonMapping ? 1024
                               : algorithm == Algorithm::kLightTracing || algorithm == Algorithm::kBidirectionalPhotonMapping ? 128
                                                                                                                               : 16;
        std::vector<double> openMeans, maskedMeans;
        for (uint64_t seed = 1; seed <= 8; seed++) {
            openMeans.push_back(PixelStatistics(RenderWith(open, algorithm, iterations, seed).mImage).mean);
            maskedMeans.push_back(PixelStatistics(RenderWith(masked, algorithm, iterations, 100 + seed).mImage).mean);
        }
        const MeanAndError o = MeanOf(openMeans), m = MeanOf(maskedMeans);
        const double se = std::sqrt(Sqr(m.standardError) + Sqr(0.5 * o.standardError));
        const double z = (m.mean - 0.5 * o.mean) / se;
        INFO(AlgorithmShortName(algorithm) << ": open " << o.mean << " +- " << o.standardError << ", masked " << m.mean
                                           << " +- " << m.standardError << ", ratio " << m.mean / o.mean << ", z " << z);
        CHECK(o.mean > 0.0);
        CHECK(std::abs(z) < 4.0);
    }
}

TEST_CASE("Shadow rays through a checkerboard mask: Occluded says solid exactly where the crossing lands on an alpha-1 texel",
          "[cutouts]") {
    // 10,000 segments from random floor points to random points on the light; each
    // crosses the plane at a point whose texel the checker's parity names (64 periods of
    // 2 texels over [-1, 1]: texel size 1/64). Bilinear filtering thresholded at 1/2 keeps
    // the texels' own squares, so the answer is exact away from texel edges (segments
    // crossing within 1/100 of a texel of an edge are skipped), and half the segments pass.
    const Texture checker = AlphaTexture(1.f, 0.f, 0.f, 1.f);
    Scene scene = LitFloorUnder(WithAlpha(DiffuseMaterial(0.f, 0.f, 0.f), AlphaMode::kMask, 1.f), &checker, 64.f);
    Finalize(scene, 8);
    Rng rng(35, 0);
    int tested = 0, blocked = 0;
    for (int i = 0; i < 10000; i++) {
        const Vec3 from(2.f * rng.GetFloat() - 1.f, 2.f * rng.GetFloat() - 1.f, 0.f);
        const Vec3 to(0.5f * rng.GetFloat() - 0.25f, 0.5f * rng.GetFloat() - 0.25f, 1.f);
        const Vec3 crossing = 0.5f * (from + to);
        const double tx = (double(crossing.x) + 1.0) * 64.0, ty = (double(crossing.y) + 1.0) * 64.0;
        if (std::abs(tx - std::round(tx)) < 1e-2 || std::abs(ty - std::round(ty)) < 1e-2) continue;
        const bool solid = ((int(std::floor(tx)) + int(std::floor(ty))) % 2) == 0;
        const float distance = glm::length(to - from);
        const bool occluded = scene.Occluded(from, (to - from) / distance, distance);
        INFO("segment " << i << " crosses the plane at (" << crossing.x << ", " << crossing.y << ")");
        REQUIRE(occluded == solid);
        tested++;
        blocked += occluded;
    }
    // Binomial: 1/2 of the tested segments, within 5 standard deviations sqrt(n) / 2.
    INFO(blocked << " of " << tested << " blocked");
    CHECK(tested > 9000);
    CHECK(std::abs(blocked - 0.5 * tested) < 2.5 * std::sqrt(double(tested)));
}
