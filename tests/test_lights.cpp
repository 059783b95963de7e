// [lights] The lights of the Scene section against their analytic definitions: the spot
// light's falloff as next-event estimation sees it, the power its light sub-paths carry,
// two-sided area lights (glTF doubleSided), and next-event estimation, hits and emission
// describing the same light. [lights][integrators]
// (excluded from `make unit` with the other whole-scene checks): the estimators agree on
// scenes lit by these lights, region by region.
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <cmath>
#include <memory>
#include <vector>

using namespace smallvcm;
using namespace testutil;

namespace {

constexpr double kPiD = 3.14159265358979323846;

// The KHR_lights_punctual reference falloff, written out again in double from the
// extension's text (not from the header): clamp((c - cos outer) / d, 0, 1)^2 with
// d = max(0.001, cos inner - cos outer).
double ReferenceSpotFalloff(double aCos, double aInner, double aOuter) {
    const double d = std::max(0.001, std::cos(aInner) - std::cos(aOuter));
    const double ramp = std::min(std::max((aCos - std::cos(aOuter)) / d, 0.0), 1.0);
    return ramp * ramp;
}

// Integral of the reference falloff over the directions whose cosine to the axis lies in
// [aCosLow, aCosHigh]: 2 pi Integral s(c) dc, by Simpson's rule on 20000 intervals (the
// integrand is piecewise quadratic, so this is exact up to rounding within each piece
// and 1e-9 across the two kinks).
double ReferenceSpotFlux(double aCosLow, double aCosHigh, double aInner, double aOuter) {
    const int n = 20000;
    const double h = (aCosHigh - aCosLow) / n;
    double sum = ReferenceSpotFalloff(aCosLow, aInner, aOuter) + ReferenceSpotFalloff(aCosHigh, aInner, aOuter);
    for (int i = 1; i < n; i++) sum += (i % 2 ? 4.0 : 2.0) * ReferenceSpotFalloff(aCosLow + i * h, aInner, aOuter);
    return 2.0 * kPiD * sum * h / 3.0;
}

// A scene holding one spot light at the origin shining down -z (and a floor far below,
// since a scene needs geometry).
Scene SpotScene(float aInner, float aOuter, const Vec3& aIntensity) {
    Scene scene;
    Material white;
    white.mDiffuseReflectance = Vec3(0.5f);
    const int material = scene.AddMaterial(white);
    scene.AddTriangle(Vec3(-10.f, -10.f, -5.f), Vec3(10.f, -10.f, -5.f), Vec3(0.f, 10.f, -5.f), material);
    scene.AddSpotLight(Vec3(0.f), Vec3(0.f, 0.f, -1.f), aIntensity, aInner, aOuter);
    scene.Finalize();
    return scene;
}

// A unit square at z = 0 whose front faces +z, one area light of radiance aRadiance,
// one- or two-sided (and a floor far below, away from the square).
Scene SquareLightScene(bool aTwoSided, const Vec3& aRadiance) {
    Scene scene;
    Material black;
    const int lamp = scene.AddMaterial(black);
    const int a = scene.AddTriangle(Vec3(-0.5f, -0.5f, 0.f), Vec3(0.5f, -0.5f, 0.f), Vec3(0.5f, 0.5f, 0.f), lamp);
    const int b = scene.AddTriangle(Vec3(0.5f, 0.5f, 0.f), Vec3(-0.5f, 0.5f, 0.f), Vec3(-0.5f, -0.5f, 0.f), lamp);
    scene.AddAreaLight({a, b}, aRadiance, aTwoSided);
    Material white;
    white.mDiffuseReflectance = Vec3(0.5f);
    scene.AddTriangle(Vec3(-10.f, -10.f, -5.f), Vec3(10.f, -10.f, -5.f), Vec3(0.f, 10.f, -5.f), scene.AddMaterial(white));
    scene.Finalize();
    return scene;
}

// The largest |z| = |m_a - m_b| / sqrt(se_a^2 + se_b^2) over blocks and channels.
double WorstZ(const BlockStatistics& aA, const BlockStatistics& aB) {
    double worst = 0.0;
    for (int b = 0; b < aA.BlockCount(); b++) {
        const glm::dvec3 difference = aA.Mean(b) - aB.Mean(b);
        const glm::dvec3 se = glm::sqrt(aA.StandardError(b) * aA.StandardError(b) + aB.StandardError(b) * aB.StandardError(b));
        for (int c = 0; c < 3; c++) {
            if (se[c] == 0.0) {
                CHECK(difference[c] == Approx(0.0).margin(1e-6));
                continue;
            }
            worst = std::max(worst, std::abs(difference[c]) / se[c]);
        }
    }
    return worst;
}

// pt, lt and vcm against bpt, per 4x4 block and channel. SEs from 256 independent
// iterations (1024 for pt); 192 z-values per comparison: |z| < 5 keeps a false alarm
// near 1e-4 per comparison for normal errors, as in test_integrators.cpp. Only scenes
// whose surfaces are all diffuse come here, so every estimator samples every path.
void CheckEstimatorsAgree(const Scene& aScene, const char* aWhat) {
    const BlockStatistics bpt = RenderBlocks(aScene, Algorithm::kBidirectionalPathTracing, 256, 4, 101);
    for (Algorithm other : {Algorithm::kPathTracing, Algorithm::kLightTracing, Algorithm::kVertexConnectionMerging}) {
        const int iterations = other == Algorithm::kPathTracing ? 1024 : 256;
        const double worstZ = WorstZ(RenderBlocks(aScene, other, iterations, 4, 202), bpt);
        INFO(aWhat << ": " << AlgorithmShortName(other) << " vs bpt, worst |z| " << worstZ);
        CHECK(worstZ < 5.0);
    }
}

} // namespace

TEST_CASE("A spot light's next-event estimate is I s(cos theta) cos / d^2 inside the inner cone, in the falloff ring, and zero outside", "[lights]") {
    const float inner = 0.3f, outer = 0.6f;
    const Vec3 intensity(2.f, 3.f, 5.f);
    const Scene scene = SpotScene(inner, outer, intensity);
    const Light& light = scene.GetLight(0);
    REQUIRE(light.mType == LightType::kSpot);
    CHECK(light.IsDelta());
    CHECK(light.IsFinite());
    const double distance = 1.7;
    // 0 and 0.2: inside the inner cone (s = 1); 0.35, 0.45, 0.55: the falloff ring;
    // 0.65 and 1.2: outside the outer cone (no sample).
    for (double theta : {0.0, 0.2, 0.35, 0.45, 0.55, 0.65, 1.2}) {
        const Vec3 direction(float(std::sin(theta)), 0.f, float(-std::cos(theta)));
        const Vec3 receiver = float(distance) * direction;
        const std::optional<LightSample> lit = light.Illuminate(scene.GetSceneSphere(), receiver, Vec2(0.3f, 0.7f));
        const double falloff = ReferenceSpotFalloff(std::cos(theta), inner, outer);
        INFO("theta " << theta << ", reference falloff " << falloff);
        if (theta < inner) CHECK(falloff == 1.0);
        if (theta > inner && theta < outer) CHECK((falloff > 0.0 && falloff < 1.0));
        if (falloff == 0.0) {
            CHECK_FALSE(lit.has_value());
            continue;
        }
        REQUIRE(lit.has_value());
        const LightSample& sample = *lit;
        // A receiver facing the light: irradiance E = radiance * cos(0) / pdf = I s / d^2.
        const glm::dvec3 irradiance = glm::dvec3(sample.mRadiance) / double(sample.mDirectPdfW);
        for (int c = 0; c < 3; c++)
            CHECK(irradiance[c] == Approx(double(intensity[c]) * falloff / (distance * distance)).epsilon(2e-5));
        CHECK(glm::length(sample.mDirToLight + direction) < 1e-6f);
        CHECK(sample.mDistance == Approx(distance).epsilon(1e-6));
        // Emission starts light sub-paths uniformly inside the outer cone.
        CHECK(sample.mEmissionPdfW == Approx(1.0 / (2.0 * kPiD * (1.0 - std::cos(double(outer))))).epsilon(1e-5));
        CHECK(sample.mCosAtLight == 1.f);
    }
}

TEST_CASE("A spot light's power and falloff solid angle follow the closed form, with the reference code's guard for nearly equal angles", "[lights]") {
    struct Cone { float inner, outer; };
    // glTF's defaults; a typical cone; the widest allowed; nearly equal angles, where
    // cos inner - cos outer = 4.8e-4 < 0.001 and the reference code's max() applies.
    for (const Cone& cone : {Cone{0.f, 0.25f * kPi}, Cone{0.3f, 0.6f}, Cone{1.2f, 0.5f * kPi}, Cone{0.5f, 0.501f}}) {
        const Scene scene = SpotScene(cone.inner, cone.outer, Vec3(1.f));
        const double numeric = ReferenceSpotFlux(std::cos(double(cone.outer)), 1.0, cone.inner, cone.outer);
        INFO("inner " << cone.inner << ", outer " << cone.outer << ": numeric " << numeric);
        CHECK(scene.GetLight(0).SpotFalloffSolidAngle() == Approx(numeric).epsilon(1e-5));
    }
}

TEST_CASE("Light sub-paths from a spot light carry its analytic power, ring by ring, and next-event estimation sees each emitted direction with the same intensity and pdf", "[lights]") {
    struct Cone { float inner, outer; };
    for (const Cone& cone : {Cone{0.f, 0.25f * kPi}, Cone{0.3f, 0.6f}, Cone{0.5f, 0.501f}}) {
        const Vec3 intensity(4.f);
        const Scene scene = SpotScene(cone.inner, cone.outer, intensity);
        const Light& light = scene.GetLight(0);
        const double cosOuter = std::cos(double(cone.outer));
        // Eight rings of equal width in cos theta over the outer cone, plus the whole.
        const int rings = 8, samples = 200000;
        std::vector<std::vector<double>> flux(rings + 1, std::vector<double>(size_t(samples), 0.0));
        Rng rng(12345, 3);
        int mismatches = 0;
        float worstDifference = 0.f;
        for (int i = 0; i < samples; i++) {
            const Vec2 rndDirection = rng.GetVec2(), rndPosition = rng.GetVec2();
            const std::optional<LightEmission> emitted = light.Emit(scene.GetSceneSphere(), rndDirection, rndPosition);
            if (!emitted) continue;
            const LightEmission& emission = *emitted;
            // Emitted flux estimate of this sample: energy / pdf (one channel: grey light).
            const double value = double(emission.mEnergy.x) / double(emission.mEmissionPdfW);
            const double cosTheta = -double(emission.mDirection.z);
            const int ring = std::min(rings - 1, int((cosTheta - cosOuter) / (1.0 - cosOuter) * rings));
            flux[size_t(std::max(0, ring))][size_t(i)] = value;
            flux[size_t(rings)][size_t(i)] = value;
            // The same direction, seen by next-event estimation from a point along it.
            // The falloff is evaluated from two float cosines of the same direction (the
            // sampled one, and the axis dotted with the normalised direction to the light):
            // they differ by ~1e-7, times ds/dc <= 2 / d <= 2000 (d >= 0.001).
            const std::optional<LightSample> sample =
                light.Illuminate(scene.GetSceneSphere(), emission.mPosition + 1.5f * emission.mDirection, Vec2(0.5f));
            const float difference = std::abs((sample ? sample->mRadiance.x : 0.f) - emission.mEnergy.x) / intensity.x;
            worstDifference = std::max(worstDifference, difference);
            if (difference > 1e-3f || (sample && std::abs(sample->mEmissionPdfW - emission.mEmissionPdfW) > 1e-6f * emission.mEmissionPdfW) ||
                emission.mDirectPdfA != 1.f || emission.mCosAtLight != 1.f)
                mismatches++;
        }
        INFO("largest |NEE intensity - emitted intensity| / I: " << worstDifference);
        CHECK(mismatches == 0);
        for (int r = 0; r <= rings; r++) {
            const double low = r < rings ? cosOuter + (1.0 - cosOuter) * r / rings : cosOuter;
            const double high = r < rings ? cosOuter + (1.0 - cosOuter) * (r + 1) / rings : 1.0;
            const double analytic = double(intensity.x) * ReferenceSpotFlux(low, high, cone.inner, cone.outer);
            const MeanAndError estimate = MeanOf(flux[size_t(r)]);
            // 4 standard errors of the mean of 200000 independent samples (measured from
            // their spread), plus 1e-5 relative for float rounding of cos(outer).
            INFO("inner " << cone.inner << ", outer " << cone.outer << ", ring " << r << ": estimate " << estimate.mean
                 << " +- " << estimate.standardError << ", analytic " << analytic << ", z "
                 << (estimate.mean - analytic) / estimate.standardError);
            CHECK(std::abs(estimate.mean - analytic) <= 4.0 * estimate.standardError + 1e-5 * analytic);
        }
        CHECK(double(intensity.x) * light.SpotFalloffSolidAngle() ==
              Approx(double(intensity.x) * ReferenceSpotFlux(cosOuter, 1.0, cone.inner, cone.outer)).epsilon(1e-5));
    }
}

TEST_CASE("The spot scene's light points down its node's -Z with the file's cone and intensity", "[lights]") {
    const Scene scene = LoadGltfScene("../scenes/spot_light.gltf");
    REQUIRE(scene.LightCount() == 1);
    const Light& light = scene.GetLight(0);
    REQUIRE(light.mType == LightType::kSpot);
    CHECK(glm::length(light.mPosition - Vec3(0.f, -0.3f, 1.2f)) < 1e-6f);
    CHECK(glm::length(light.mDirection - glm::normalize(Vec3(0.35f, 0.45f, -1.f))) < 1e-6f);
    CHECK(light.mSpotInnerConeAngle == Approx(0.35f));
    CHECK(light.mSpotOuterConeAngle == Approx(0.6f));
    CHECK(light.mEmission == Vec3(20.f));
}

TEST_CASE("A spot light with angles outside the extension's ranges is refused when the scene is finalized", "[lights]") {
    struct Cone { float inner, outer; const char* problem; };
    for (const Cone& cone : {Cone{-0.1f, 0.5f, "innerConeAngle is negative"}, Cone{0.5f, 0.5f, "is not less than"},
                             Cone{0.2f, 1.6f, "exceeds pi/2"}, Cone{0.f, 0.005f, "below 0.01 rad"},
                             Cone{0.f, std::nanf(""), "not finite"}}) {
        INFO("inner " << cone.inner << ", outer " << cone.outer);
        CHECK_THROWS_WITH(SpotScene(cone.inner, cone.outer, Vec3(1.f)),
                          Catch::Contains("light 0 (spot)") && Catch::Contains(cone.problem));
    }
}

TEST_CASE("pt, lt, bpt and vcm agree region by region on the spot-light scene", "[lights][integrators]") {
    Scene scene = LoadGltfScene("../scenes/spot_light.gltf");
    scene.mCamera.SetResolution(32, 32);
    CheckEstimatorsAgree(scene, "spot_light.gltf");
}

TEST_CASE("A two-sided area light is seen alike from both sides by next-event estimation and by a hit, with half the one-sided emission pdf; a one-sided one is dark from behind", "[lights]") {
    const Vec3 radiance(3.f);
    for (bool twoSided : {false, true}) {
        const Scene scene = SquareLightScene(twoSided, radiance);
        const Light& light = scene.GetLight(0);
        CHECK(light.mTwoSided == twoSided);
        for (float side : {1.f, -1.f}) {
            INFO((twoSided ? "two-sided" : "one-sided") << ", receiver on the " << (side > 0.f ? "front" : "back"));
            // A receiver 1 above or below (0.1, 0.2); the sample lands somewhere on the square.
            const Vec3 receiver(0.1f, 0.2f, side);
            const std::optional<LightSample> lit = light.Illuminate(scene.GetSceneSphere(), receiver, Vec2(0.3f, 0.6f));
            const bool emits = twoSided || side > 0.f;
            REQUIRE(lit.has_value() == emits);
            // The ray from the receiver hits the square's side that faces it.
            const Light::RadianceAtHit received =
                light.GetRadiance(scene.GetSceneSphere(), Vec3(0.f, 0.f, -side), Vec3(0.f, 0.f, 1.f), Vec2(0.f));
            const Vec3 hitRadiance = received.mRadiance;
            const float directPdfA = received.mDirectPdfA, emissionPdfW = received.mEmissionPdfW;
            if (!emits) {
                CHECK(IsBlack(hitRadiance));
                continue;
            }
            const LightSample& sample = *lit;
            CHECK(sample.mRadiance == radiance);
            CHECK(hitRadiance == radiance);
            const float cosAtLight = std::abs(sample.mDirToLight.z);
            CHECK(sample.mCosAtLight == Approx(cosAtLight));
            CHECK(sample.mDirectPdfW == Approx(sample.mDistance * sample.mDistance / cosAtLight).epsilon(1e-5));
            const float sideProbability = twoSided ? 0.5f : 1.f;
            CHECK(sample.mEmissionPdfW == Approx(cosAtLight / kPi * sideProbability).epsilon(1e-5));
            CHECK(directPdfA == Approx(1.f));
            CHECK(emissionPdfW == Approx(1.f / kPi * sideProbability).epsilon(1e-6));  // cos = 1 for this ray
        }
    }
}

TEST_CASE("Light sub-paths from a two-sided area light leave both sides equally often and carry twice the one-sided power", "[lights]") {
    const Vec3 radiance(2.f);
    for (bool twoSided : {false, true}) {
        const Scene scene = SquareLightScene(twoSided, radiance);
        const Light& light = scene.GetLight(0);
        const int samples = 100000;
        std::vector<double> flux, down;
        Rng rng(777, 5);
        int mismatches = 0;
        for (int i = 0; i < samples; i++) {
            const Vec2 rndDirection = rng.GetVec2(), rndPosition = rng.GetVec2();
            const std::optional<LightEmission> emitted = light.Emit(scene.GetSceneSphere(), rndDirection, rndPosition);
            REQUIRE(emitted.has_value());
            const LightEmission& emission = *emitted;
            flux.push_back(double(emission.mEnergy.x) / double(emission.mEmissionPdfW));
            down.push_back(emission.mDirection.z < 0.f ? 1.0 : 0.0);
            // A camera ray arriving along the emitted direction reversed, at this point,
            // must find the same radiance and report the same emission pdf.
            const Light::RadianceAtHit received =
                light.GetRadiance(scene.GetSceneSphere(), -emission.mDirection, Vec3(0.f, 0.f, 1.f), Vec2(0.f));
            const Vec3 hitRadiance = received.mRadiance;
            const float directPdfA = received.mDirectPdfA, emissionPdfW = received.mEmissionPdfW;
            if (hitRadiance != radiance || std::abs(emissionPdfW - emission.mEmissionPdfW) > 1e-5f * emission.mEmissionPdfW ||
                std::abs(emission.mDirectPdfA - directPdfA) > 1e-6f)
                mismatches++;
        }
        CHECK(mismatches == 0);
        // Energy / pdf = L cos / (cos side-probability / (pi A)) = L pi A / side-probability
        // for every sample (the horizon clamp aside): the power, 2 pi A L when two-sided.
        const MeanAndError power = MeanOf(flux);
        const double expected = double(radiance.x) * kPiD * 1.0 * (twoSided ? 2.0 : 1.0);
        INFO((twoSided ? "two-sided" : "one-sided") << ": power " << power.mean << " +- " << power.standardError
             << ", expected " << expected);
        CHECK(power.mean == Approx(expected).epsilon(1e-5));
        // The share leaving the back: 1/2 within 4 binomial standard errors (0.0016 at
        // 1e5 samples), or none at all.
        const MeanAndError backShare = MeanOf(down);
        INFO("share leaving the back " << backShare.mean << " +- " << backShare.standardError);
        if (twoSided) CHECK(std::abs(backShare.mean - 0.5) <= 4.0 * std::sqrt(0.25 / samples));
        else CHECK(backShare.mean == 0.0);
    }
}

TEST_CASE("A glTF emissive material with doubleSided makes a two-sided light; the Cornell lights stay one-sided", "[lights]") {
    const Scene scene = LoadGltfScene("../scenes/two_sided_emitter.gltf");
    REQUIRE(scene.LightCount() == 1);
    CHECK(scene.GetLight(0).mType == LightType::kArea);
    CHECK(scene.GetLight(0).mTwoSided);
    for (int i = 0; i < 5; i++)
        for (const Light& light : LoadGltfScene(CornellPath(i)).mLights) CHECK_FALSE(light.mTwoSided);
}

TEST_CASE("pt, lt, bpt and vcm agree region by region on the two-sided emitter scene", "[lights][integrators]") {
    Scene scene = LoadGltfScene("../scenes/two_sided_emitter.gltf");
    scene.mCamera.SetResolution(32, 32);
    CheckEstimatorsAgree(scene, "two_sided_emitter.gltf");
}

// ---------------------------------------------------------------------------------
// Textured area lights (glTF emissiveTexture): radiance = emission x texel(uv)
// ---------------------------------------------------------------------------------

namespace {

// A 2 x 2 texture of one colour.
Texture ConstantTexture(const Vec3& aColor) {
    Texture texture;
    texture.mWidth = texture.mHeight = 2;
    texture.mTexels.assign(4, aColor);
    return texture;
}

// Gives every triangle of light aLightId texture coordinates by projecting it onto the
// plane of its normal's largest axis, scaled by aScale (so they may leave [0, 1]), makes
// aTexture the light's emission texture and finalizes the scene again.
void TextureLight(Scene& aScene, int aLightId, const Texture& aTexture, float aScale) {
    aScene.mTextures.push_back(aTexture);
    aScene.mLights[size_t(aLightId)].mEmissionTexture = int(aScene.mTextures.size()) - 1;
    for (Triangle& triangle : aScene.mTriangles) {
        if (triangle.mLightId != aLightId) continue;
        const Vec3 n = glm::abs(triangle.mNormal);
        const int axis = n.x > n.y && n.x > n.z ? 0 : n.y > n.z ? 1 : 2;
        const auto project = [&](const Vec3& aPoint) { return Vec2(aPoint[(axis + 1) % 3], aPoint[(axis + 2) % 3]) * aScale; };
        triangle.mUv0 = project(triangle.mP0);
        triangle.mUv1 = project(triangle.mP1);
        triangle.mUv2 = project(triangle.mP2);
    }
    aScene.Finalize();
}

bool CloseRelative(const Vec3& aA, const Vec3& aB, float aTolerance) {
    for (int c = 0; c < 3; c++)
        if (std::abs(aA[c] - aB[c]) > aTolerance * std::max(std::abs(aA[c]), std::abs(aB[c]))) return false;
    return true;
}

} // namespace

TEST_CASE("A constant emission texture gives next-event samples, light sub-paths and hits what its colour as emission factor gives", "[lights]") {
    const Vec3 factor(2.f, 1.f, 4.f), color(0.3f, 0.6f, 0.9f);
    for (bool twoSided : {false, true}) {
        INFO((twoSided ? "two-sided" : "one-sided"));
        const Scene plain = SquareLightScene(twoSided, factor * color);
        Scene textured = SquareLightScene(twoSided, factor);
        TextureLight(textured, 0, ConstantTexture(color), 1.7f);
        const Light& a = plain.GetLight(0);
        const Light& b = textured.GetLight(0);
        REQUIRE(b.mEmissionTexture == 0);
        Rng rng(4242, 1);
        int compared = 0;
        for (int i = 0; i < 2000; i++) {
            const Vec2 r1 = rng.GetVec2(), r2 = rng.GetVec2();
            const Vec3 receiver(rng.GetFloat() - 0.5f, rng.GetFloat() - 0.5f, twoSided && i % 2 ? -1.f : 1.f);
            const std::optional<LightSample> sa = a.Illuminate(plain.GetSceneSphere(), receiver, r1);
            const std::optional<LightSample> sb = b.Illuminate(textured.GetSceneSphere(), receiver, r1);
            REQUIRE(sa.has_value() == sb.has_value());
            if (sa) {
                CHECK(CloseRelative(sa->mRadiance, sb->mRadiance, 1e-6f));
                CHECK(sa->mDirToLight == sb->mDirToLight);
                CHECK(sa->mDirectPdfW == sb->mDirectPdfW);
                CHECK(sa->mEmissionPdfW == sb->mEmissionPdfW);
            }
            const std::optional<LightEmission> emittedA = a.Emit(plain.GetSceneSphere(), r1, r2);
            REQUIRE(emittedA.has_value());
            const std::optional<LightEmission> emittedB = b.Emit(textured.GetSceneSphere(), r1, r2);
            REQUIRE(emittedB.has_value());
            const LightEmission& ea = *emittedA;
            const LightEmission& eb = *emittedB;
            CHECK(CloseRelative(ea.mEnergy, eb.mEnergy, 1e-6f));
            CHECK(CloseRelative(ea.mRadiance, eb.mRadiance, 1e-6f));  // what light tracing splats for the point itself
            CHECK(ea.mPosition == eb.mPosition);
            CHECK(ea.mEmissionPdfW == eb.mEmissionPdfW);
            CHECK(ea.mDirectPdfA == eb.mDirectPdfA);
            // A ray from the receiver to the emitted point hits the square there: the hit
            // carries the texture coordinates the light looks its texel up with.
            const Vec3 toPoint = glm::normalize(eb.mPosition - receiver);
            const SurfacePoint hit = textured.Intersect(Ray{receiver, toPoint});
            REQUIRE(hit.IsValid());
            const Light::RadianceAtHit ha = a.GetRadiance(plain.GetSceneSphere(), toPoint, hit.GeometricNormal(), Vec2(0.f));
            const Light::RadianceAtHit hb = b.GetRadiance(textured.GetSceneSphere(), toPoint, hit.GeometricNormal(), hit.mUv);
            CHECK(CloseRelative(ha.mRadiance, hb.mRadiance, 1e-6f));
            CHECK(ha.mDirectPdfA == hb.mDirectPdfA);
            CHECK(ha.mEmissionPdfW == hb.mEmissionPdfW);
            compared++;
        }
        CHECK(compared == 2000);
    }
}

TEST_CASE("Every estimator renders the emissive furnace with a constant emission texture at the analytic value of its colour as emission", "[lights][integrators]") {
    // The emissive furnace (test_util.hpp) at maximum path length 4: L = Le (1 - a^4) /
    // (1 - a) per channel, here with Le = factor x colour, the colour coming from a
    // texture whose coordinates run over 1.3 periods of each triangle's projection (so
    // every wrap of repeat is crossed). Tolerance as in test_transport.cpp: the mean of
    // 16 independent one-iteration renders (seeds 500, 1500, ...) within 5 of its
    // standard errors measured from their spread (Student t, 15 dof: a false alarm near
    // 2e-4 per estimator) plus 1e-3 of the value for float rounding; PPM and BPM merge
    // with a radius of 5 % of the scene (uniform photon density: no bias, see
    // test_transport.cpp). Ignoring the texel anywhere (hits, next-event samples or
    // light sub-paths) makes that estimator off by a factor 1 / 0.6 = 1.67 on its share.
    const float albedo = 0.5f, factor = 2.f;
    const Vec3 color(0.3f, 0.6f, 0.9f);
    Scene scene = MakeEmissiveFurnace(albedo, factor, 16, 16);
    TextureLight(scene, 0, ConstantTexture(color), 1.3f);
    const int maxLength = 4;
    const double expected = factor * (color.x + color.y + color.z) / 3.0 * (1.0 - std::pow(albedo, maxLength)) / (1.0 - albedo);
    for (Algorithm algorithm : kTransportEstimators) {
        std::vector<double> means;
        for (int r = 0; r < 16; r++) {
            RenderOptions options;
            options.mAlgorithm = algorithm;
            options.mIterations = 1;
            options.mSeed = 500u + 1000u * uint64_t(r);
            options.mMaxPathLength = maxLength;
            options.mRadiusFactor = 0.05f;
            options.mProgress = false;
            means.push_back(PixelStatistics(Render(scene, options).mImage).mean);
        }
        const MeanAndError stats = MeanOf(means);
        INFO(AlgorithmShortName(algorithm) << ": mean " << stats.mean << " +- " << stats.standardError << ", expected " << expected);
        CHECK(std::abs(stats.mean - expected) <= 5.0 * stats.standardError + 1e-3 * expected);
    }
}

TEST_CASE("A checkerboard emission texture seen directly by the camera shows its texels, pixel for pixel", "[lights]") {
    // A 48 x 48 square at z = -24 in front of a 90-degree camera at the origin: raster
    // (x, y) sees the point (x - 24, 24 - y, -24), so the texture coordinates
    // u = (X + 24) / 48, v = (24 - Y) / 48 put the 12 x 12 texels on 4 x 4-pixel squares
    // (v runs down the image, as in glTF). The checker has 4 x 4 checks of 3 x 3 texels,
    // each light check brighter than the last (a transposed or mirrored lookup cannot
    // match). In a check's middle texel the bilinear filter blends only texels of that
    // check, so its 16 pixels show factor x texel up to float rounding; every other pixel
    // lies between the darkest and brightest texel. Path length 1 only: the emission seen.
    const int size = 48, texels = 12;
    const Vec3 factor(1.f, 0.5f, 2.f);
    const auto checkValue = [](int aI, int aJ) { return (aI + aJ) % 2 ? 0.02f : 0.2f + 0.05f * float(aI + 4 * aJ); };
    Texture checker;
    checker.mWidth = checker.mHeight = texels;
    for (int y = 0; y < texels; y++)
        for (int x = 0; x < texels; x++) checker.mTexels.push_back(Vec3(checkValue(x / 3, y / 3)));
    Scene scene;
    const int black = scene.AddMaterial(Material{});
    const float h = 0.5f * float(size), z = -0.5f * float(size);
    const int a = scene.AddTriangle(Vec3(-h, -h, z), Vec3(h, -h, z), Vec3(h, h, z), black);
    const int b = scene.AddTriangle(Vec3(h, h, z), Vec3(-h, h, z), Vec3(-h, -h, z), black);
    for (int t : {a, b}) {
        Triangle& triangle = scene.mTriangles[size_t(t)];
        const auto uv = [&](const Vec3& aPoint) { return Vec2((aPoint.x + h) / float(size), (h - aPoint.y) / float(size)); };
        triangle.mUv0 = uv(triangle.mP0);
        triangle.mUv1 = uv(triangle.mP1);
        triangle.mUv2 = uv(triangle.mP2);
    }
    scene.mTextures.push_back(checker);
    scene.AddAreaLight({a, b}, factor, false, 0);
    scene.mCamera.Setup(Vec3(0.f), Vec3(0.f, 0.f, -1.f), Vec3(0.f, 1.f, 0.f), 90.f);
    scene.mCamera.SetResolution(size, size);
    scene.Finalize();
    RenderOptions options;
    options.mAlgorithm = Algorithm::kPathTracing;
    options.mIterations = 4;
    options.mMaxPathLength = 1;
    options.mProgress = false;
    const Image image = Render(scene, options).mImage;
    int exact = 0;
    for (int y = 0; y < size; y++) {
        for (int x = 0; x < size; x++) {
            const Vec3 pixel = image.mPixels[size_t(y * size + x)];
            const int texelX = x / 4, texelY = y / 4;
            INFO("pixel (" << x << ", " << y << ") " << pixel.x << " " << pixel.y << " " << pixel.z);
            if (texelX % 3 == 1 && texelY % 3 == 1) {
                CHECK(CloseRelative(pixel, factor * checkValue(texelX / 3, texelY / 3), 1e-5f));
                exact++;
            } else {
                for (int c = 0; c < 3; c++) {
                    CHECK(pixel[c] >= factor[c] * 0.02f * (1.f - 1e-5f));
                    CHECK(pixel[c] <= factor[c] * checkValue(3, 3) * (1.f + 1e-5f));  // the brightest check, 0.95
                }
            }
        }
    }
    CHECK(exact == 16 * 16);
}

TEST_CASE("pt, lt, bpt and vcm agree region by region on a box lit only by checker-textured emitters", "[lights][integrators]") {
    // scenes/diffuse_box.gltf (diffuse walls under two area lights), both lights given a
    // 4 x 4 checker emission texture of texels 0.05 and 1 over their planar projection:
    // the lit floor and the emitters seen directly both depend on the texel at each
    // point. CheckEstimatorsAgree: per 4 x 4 block and channel, |z| < 5 with standard
    // errors measured from 256 independent iterations (1024 for pt).
    Scene scene = LoadGltfScene("../scenes/diffuse_box.gltf");
    scene.mCamera.SetResolution(32, 32);
    Texture checker;
    checker.mWidth = checker.mHeight = 4;
    for (int y = 0; y < 4; y++)
        for (int x = 0; x < 4; x++) checker.mTexels.push_back(Vec3((x + y) % 2 ? 0.05f : 1.f));
    REQUIRE(scene.LightCount() == 2);
    const float scale = 2.f / scene.GetSceneSphere().mRadius;
    for (int light = 0; light < scene.LightCount(); light++) TextureLight(scene, light, checker, scale);
    CheckEstimatorsAgree(scene, "diffuse_box.gltf with checker-textured lights");
}
