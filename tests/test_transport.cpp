// [transport] Tests that name the broken piece of the transport: each checks one quantity
// per path length, per technique or per light against an analytic value, so that a
// failure says which length, which (s, t) technique or which light is wrong.
//   * per length (--min = --max path length k): every estimator renders the emissive
//     furnace's L_k = Le a^(k-1), k = 1..4 (merging path length, connection and light
//     tracing lengths, next-event estimation at the last vertex);
//   * per technique: the unweighted image of every BPT technique (s, t) of lengths 1..4
//     is an unbiased estimate of the same L_k (geometry terms, camera pdfs, emission);
//   * light picking: furnaces whose emission is split over two lights;
//   * one-sidedness: an emitter seen and sampled only from behind lights nothing, for
//     every estimator and technique.
// Statistical tolerances: 5 standard errors of the image mean plus 1e-3 relative (the
// geodesic sphere's facets and float rounding). The standard error comes from 16
// independent one-iteration renders (different seeds): the pixels of one iteration are
// not independent when they share a photon map or light sub-paths (PPM's pixel spread
// understated its error by a factor of 2-3). With 15 degrees of freedom a 5 SE
// deviation has probability ~1.6e-4 (Student t), ~1 % over the ~80 checks here; the
// seeds are fixed, so the outcome is reproducible. At 16 x 16 pixels the standard error
// is 0.3-3 % of L_k (printed), so a bug that changes a length or a technique by a few
// percent fails.
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <cstdio>
#include <string>

using namespace smallvcm;
using namespace testutil;

namespace {

RenderResult RenderLengths(const Scene& aScene, Algorithm aAlgorithm, int aMinLength, int aMaxLength, int aIterations,
                           uint64_t aSeed, bool aLayers = false) {
    RenderOptions options;
    options.mAlgorithm = aAlgorithm;
    options.mIterations = aIterations;
    options.mSeed = aSeed;
    options.mMinPathLength = aMinLength;
    options.mMaxPathLength = aMaxLength;
    options.mTechniqueLayers = aLayers;
    // A merging radius of 5 % of the scene: at 16 x 16 (256 light sub-paths) the default
    // 0.3 % finds so few photons that the pixel spread underestimates PPM's noise. In the
    // furnaces the photon density is uniform over the sphere, so the radius adds no bias
    // (a disc of radius r on a unit sphere has area exactly pi r^2, Archimedes).
    options.mRadiusFactor = 0.05f;
    options.mProgress = false;
    return Render(aScene, options);
}

// |mean - expected| <= 5 SE + 1e-3 expected (see the file's note).
bool WithinNoise(const MeanAndError& aStats, double aExpected) {
    return std::abs(aStats.mean - aExpected) <= 5.0 * aStats.standardError + 1e-3 * aExpected;
}

constexpr int kRenders = 16;

double ImageMean(const Image& aImage) { return PixelStatistics(aImage).mean; }

// The mean of kRenders independent one-iteration renders and its standard error.
MeanAndError IndependentRenders(const Scene& aScene, Algorithm aAlgorithm, int aMinLength, int aMaxLength, uint64_t aSeed) {
    std::vector<double> means;
    for (int r = 0; r < kRenders; r++)
        means.push_back(ImageMean(RenderLengths(aScene, aAlgorithm, aMinLength, aMaxLength, 1, aSeed + 1000u * uint64_t(r)).mImage));
    return MeanOf(means);
}

// The emissive furnace with its triangles dealt alternately to aLightCount area lights of
// the same radiance: the same radiance field, but every light is picked with 1/aLightCount.
Scene MakeSplitEmissiveFurnace(float aAlbedo, float aEmitted, int aLightCount, int aSize) {
    Scene scene;
    scene.mName = "split emissive furnace";
    Material wall;
    wall.mDiffuseReflectance = Vec3(aAlbedo);
    const int material = scene.AddMaterial(wall);
    std::vector<std::vector<int>> ids(static_cast<size_t>(aLightCount));
    int t = 0;
    for (const auto& tri : InwardGeodesicSphere(1.f, 3))
        ids[size_t(t++ % aLightCount)].push_back(scene.AddTriangle(tri[0], tri[1], tri[2], material));
    for (const auto& group : ids) scene.AddAreaLight(group, Vec3(aEmitted));
    scene.mCamera.Setup(Vec3(0.1f, -0.2f, 0.05f), Vec3(0.3f, 1.f, 0.2f), Vec3(0.f, 0.f, 1.f), 60.f);
    scene.mCamera.SetResolution(aSize, aSize);
    scene.Finalize();
    return scene;
}

// A diffuse floor (z = 0, facing up) under a square emitter at height 1 whose front faces
// aEmitterFacesFloor ? down : up, seen from the side below the emitter: with the emitter
// facing up, nothing in the scene can receive its light, and the camera sees its back.
Scene MakeFloorAndEmitter(bool aEmitterFacesFloor, int aSize) {
    Scene scene;
    scene.mName = aEmitterFacesFloor ? "emitter facing the floor" : "emitter facing away";
    Material floor;
    floor.mDiffuseReflectance = Vec3(0.8f);
    const int floorMaterial = scene.AddMaterial(floor);
    Material black;
    const int lightMaterial = scene.AddMaterial(black);
    scene.AddTriangle(Vec3(-4, -4, 0), Vec3(4, -4, 0), Vec3(4, 4, 0), floorMaterial);
    scene.AddTriangle(Vec3(-4, -4, 0), Vec3(4, 4, 0), Vec3(-4, 4, 0), floorMaterial);
    const Vec3 a(-0.5f, -0.5f, 1.f), b(0.5f, -0.5f, 1.f), c(0.5f, 0.5f, 1.f), d(-0.5f, 0.5f, 1.f);
    std::vector<int> light;
    if (aEmitterFacesFloor) {  // wound clockwise seen from above: the normal is -z
        light.push_back(scene.AddTriangle(a, c, b, lightMaterial));
        light.push_back(scene.AddTriangle(a, d, c, lightMaterial));
    } else {
        light.push_back(scene.AddTriangle(a, b, c, lightMaterial));
        light.push_back(scene.AddTriangle(a, c, d, lightMaterial));
    }
    scene.AddAreaLight(light, Vec3(5.f));
    scene.mCamera.Setup(Vec3(0.f, -3.f, 0.7f), Vec3(0.f, 1.f, -0.1f), Vec3(0.f, 0.f, 1.f), 70.f);
    scene.mCamera.SetResolution(aSize, aSize);
    scene.Finalize();
    return scene;
}

double ImageSum(const Image& aImage) {
    double sum = 0.0;
    for (const Vec3& p : aImage.mPixels) sum += double(p.x) + double(p.y) + double(p.z);
    return sum;
}

} // namespace

TEST_CASE("Every estimator renders the emissive furnace's L_k = Le a^(k-1) for each path length k = 1..4 alone", "[transport]") {
    // --min-path-length = --max-path-length = k keeps only paths of k segments: the camera
    // ray and k - 1 bounces of albedo a, each seeing the emission Le.
    const float albedo = 0.5f, emitted = 1.f;
    const Scene scene = MakeEmissiveFurnace(albedo, emitted, 16, 16);
    for (int k = 1; k <= 4; k++) {
        const double expected = emitted * std::pow(albedo, k - 1);
        for (Algorithm algorithm : kTransportEstimators) {
            const MeanAndError stats = IndependentRenders(scene, algorithm, k, k, 100u + uint64_t(k));
            std::printf("[transport] length %d %-4s mean %.5f +- %.5f (expected %.5f)\n", k, AlgorithmShortName(algorithm),
                        stats.mean, stats.standardError, expected);
            INFO("path length " << k << ", " << AlgorithmShortName(algorithm) << ": mean " << stats.mean << " +- "
                                << stats.standardError << ", expected " << expected);
            CHECK(WithinNoise(stats, expected));
        }
    }
}

TEST_CASE("Every BPT technique (s, t) of lengths 1..4, unweighted, renders the emissive furnace's L_k", "[transport]") {
    // The unweighted layer s<s>_t<t>_unweighted holds f / p of technique (s, t) alone: each
    // is an unbiased estimate of L_k (k = s + t - 1) wherever the technique can sample
    // every path, which in a closed diffuse furnace is everywhere.
    const float albedo = 0.5f, emitted = 1.f;
    const Scene scene = MakeEmissiveFurnace(albedo, emitted, 16, 16);
    std::vector<RenderResult> results;
    for (int r = 0; r < kRenders; r++)
        results.push_back(RenderLengths(scene, Algorithm::kBidirectionalPathTracing, 0, 4, 1, 77u + 1000u * uint64_t(r), true));
    int checked = 0;
    for (int k = 1; k <= 4; k++) {
        const double expected = emitted * std::pow(albedo, k - 1);
        for (int s = 0; s <= k; s++) {
            if (k == 1 && s == 1) continue;  // the emitter splatted by light tracing: lt alone does it
            const std::string name = "s" + std::to_string(s) + "_t" + std::to_string(k + 1 - s) + "_unweighted";
            std::vector<double> means;
            for (const RenderResult& result : results)
                for (const auto& entry : result.mLayers)
                    if (entry.first == name) means.push_back(ImageMean(entry.second));
            INFO("technique " << name);
            REQUIRE(means.size() == size_t(kRenders));
            const MeanAndError stats = MeanOf(means);
            std::printf("[transport] %-16s mean %.5f +- %.5f (expected %.5f)\n", name.c_str(), stats.mean,
                        stats.standardError, expected);
            INFO("mean " << stats.mean << " +- " << stats.standardError << ", expected " << expected);
            CHECK(WithinNoise(stats, expected));
            checked++;
        }
    }
    CHECK(checked == 13);
}

TEST_CASE("Furnaces whose emission is split over several lights render the same radiance with every estimator", "[transport]") {
    // Light picking: the same emission dealt to 3 area lights (each picked with 1/3), and
    // the point-light furnace's intensity pi shared by two coincident point lights: the
    // analytic values of test_integrators' furnaces hold unchanged, at maximum length 4.
    const int maxLength = 4;
    SECTION("three area lights") {
        const Scene scene = MakeSplitEmissiveFurnace(0.5f, 1.f, 3, 16);
        const double expected = (1.0 - std::pow(0.5, maxLength)) / 0.5;
        for (Algorithm algorithm : kTransportEstimators) {
            const MeanAndError stats = IndependentRenders(scene, algorithm, 0, maxLength, 31u);
            INFO(AlgorithmShortName(algorithm) << ": mean " << stats.mean << " +- " << stats.standardError << ", expected " << expected);
            CHECK(WithinNoise(stats, expected));
        }
    }
    SECTION("two point lights") {
        Scene scene = MakePointLightFurnace(16, 16);
        scene.mLights[0].mEmission = Vec3(0.25f * kPi);
        scene.AddPointLight(Vec3(0.f), Vec3(0.75f * kPi));
        scene.Finalize();
        const double expected = 1.0 - std::pow(0.5, maxLength - 1);
        for (Algorithm algorithm : kTransportEstimators) {
            const MeanAndError stats = IndependentRenders(scene, algorithm, 0, maxLength, 37u);
            INFO(AlgorithmShortName(algorithm) << ": mean " << stats.mean << " +- " << stats.standardError << ", expected " << expected);
            CHECK(WithinNoise(stats, expected));
        }
    }
}

TEST_CASE("An emitter is one-sided for every estimator: seen and sampled only from behind, it lights nothing", "[transport]") {
    // The emitter faces up, away from the floor, the camera and everything else: no
    // technique may find light (NEE from the floor, the camera ray or a BSDF sample
    // hitting its back, light sub-paths leaving its front into the empty sky). The same
    // emitter turned towards the floor must light it in every estimator (the control: it
    // shows the scene sees the light at all).
    const Scene away = MakeFloorAndEmitter(false, 16);
    const Scene towards = MakeFloorAndEmitter(true, 16);
    for (Algorithm algorithm : kTransportEstimators) {
        const double dark = ImageSum(RenderLengths(away, algorithm, 0, 6, 4, 5u).mImage);
        const double lit = ImageSum(RenderLengths(towards, algorithm, 0, 6, 4, 5u).mImage);
        INFO(AlgorithmShortName(algorithm) << ": sum of the image " << dark << " facing away, " << lit << " facing the floor");
        CHECK(dark == 0.0);
        CHECK(lit > 0.0);
    }
}
