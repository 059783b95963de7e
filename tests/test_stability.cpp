// [stability] Numerical stability over long runs and in awkward geometry: thousands of
// iterations with the merging radius shrinking, very long paths, grazing views, a camera
// inside a glass sphere, lights touching walls. Every pixel of every image must be finite
// and non-negative. Built with SMALLVCM_CHECKS (make check) the same runs also check every
// film contribution and every MIS quantity as it is made, and abort on the first bad one.
#include "test_util.hpp"

#include <catch2/catch.hpp>

using namespace smallvcm;
using namespace testutil;

namespace {

const Algorithm kAll[] = {Algorithm::kPathTracing, Algorithm::kLightTracing, Algorithm::kProgressivePhotonMapping,
                          Algorithm::kBidirectionalPhotonMapping, Algorithm::kBidirectionalPathTracing,
                          Algorithm::kVertexConnectionMerging, Algorithm::kPhotonMapping,
                          Algorithm::kPhotonMappingFinalGather};

int BadPixels(const Image& aImage) {
    int bad = 0;
    for (const Vec3& p : aImage.mPixels) bad += !(IsFinite(p) && p.x >= 0.f && p.y >= 0.f && p.z >= 0.f);
    return bad;
}

RenderOptions Options(Algorithm aAlgorithm, int aIterations) {
    RenderOptions options;
    options.mAlgorithm = aAlgorithm;
    options.mIterations = aIterations;
    options.mPhotonCount = 2000;
    options.mProgress = false;
    return options;
}

// aOnlySpecularVisible: everything the camera sees lies behind a specular surface, which
// light tracing cannot connect through, so its image is black by construction.
void CheckEveryAlgorithm(const Scene& aScene, const std::string& aWhat, int aIterations, int aMaxPathLength = 10,
                         bool aOnlySpecularVisible = false) {
    for (Algorithm algorithm : kAll) {
        RenderOptions options = Options(algorithm, aIterations);
        options.mMaxPathLength = aMaxPathLength;
        const RenderResult result = Render(aScene, options);
        INFO(aWhat << ", " << AlgorithmShortName(algorithm));
        CHECK(BadPixels(result.mImage) == 0);
        if (aOnlySpecularVisible && algorithm == Algorithm::kLightTracing) CHECK(MeanValue(result.mImage) == 0.0);
        else CHECK(MeanValue(result.mImage) > 0.0);
    }
}

} // namespace

TEST_CASE("Thousands of iterations with a shrinking radius stay finite and do not drift", "[stability]") {
    // 3000 iterations: the radius falls to r0 * 3000^-0.125 = 0.37 r0. The image after 1500
    // iterations and after 3000 estimate the same value: their means agree within 5
    // standard errors of the difference (measured from per-iteration means), so the
    // accumulation has not drifted.
    const Scene scene = LoadCornell(4, 8, 8);
    for (Algorithm algorithm : {Algorithm::kProgressivePhotonMapping, Algorithm::kBidirectionalPhotonMapping,
                                Algorithm::kVertexConnectionMerging}) {
        RenderOptions options = Options(algorithm, 0);
        std::unique_ptr<AbstractRenderer> renderer = CreateRenderer(scene, options);
        std::vector<double> means;
        double previous = 0.0;
        for (int i = 0; i < 3000; i++) {
            Sampler sampler = IterationSampler(options.mSampler, 17, i);
            renderer->RunIteration(i, sampler);
            if (i % 500 == 499) REQUIRE(BadPixels(renderer->GetFilm().Resolve(1.0 / (i + 1))) == 0);
            const double cumulative = MeanValue(renderer->GetFilm().Resolve(1.0));
            means.push_back(cumulative - previous);
            previous = cumulative;
        }
        auto halfStatistics = [&](size_t aBegin, size_t aEnd) {
            double mean = 0.0, variance = 0.0;
            const double n = double(aEnd - aBegin);
            for (size_t i = aBegin; i < aEnd; i++) mean += means[i] / n;
            for (size_t i = aBegin; i < aEnd; i++) variance += (means[i] - mean) * (means[i] - mean) / (n - 1.0);
            return std::make_pair(mean, variance / n);
        };
        const auto first = halfStatistics(0, 1500), second = halfStatistics(1500, 3000);
        INFO(AlgorithmShortName(algorithm) << ": first half " << first.first << ", second half " << second.first);
        CHECK(std::abs(first.first - second.first) <= 5.0 * std::sqrt(first.second + second.second));
    }
}

TEST_CASE("Very long paths stay finite and still match the furnace", "[stability]") {
    // Albedo 0.95 and paths up to 200 segments: Russian roulette keeps paths finite, and
    // the image is Le (1 - a^200) / (1 - a) = 19.9993 (4 standard errors, as in the
    // furnace tests). The estimators without merging are checked against the value.
    const Scene scene = MakeEmissiveFurnace(0.95f, 1.f, 12, 12);
    const double expected = (1.0 - std::pow(0.95, 200)) / 0.05;
    for (Algorithm algorithm : {Algorithm::kPathTracing, Algorithm::kBidirectionalPathTracing, Algorithm::kVertexConnectionMerging}) {
        RenderOptions options = Options(algorithm, 16);
        options.mMaxPathLength = 200;
        const RenderResult result = Render(scene, options);
        REQUIRE(BadPixels(result.mImage) == 0);
        const MeanAndError stats = PixelStatistics(result.mImage);
        INFO(AlgorithmShortName(algorithm) << ": " << stats.mean << " +- " << stats.standardError << ", expected " << expected);
        CHECK(std::abs(stats.mean - expected) <= 4.0 * stats.standardError + 1e-3 * expected);
    }
    CheckEveryAlgorithm(scene, "albedo 0.95, 200 segments", 2, 200);
}

TEST_CASE("A grazing view of a floor stays finite", "[stability]") {
    // The camera sits 1e-3 above a large floor and looks along it: most first hits are at
    // cosines of 1e-3 and below, down to the rejected ones under kEpsCosine.
    Scene scene;
    Material floor;
    floor.mDiffuseReflectance = Vec3(0.3f);
    floor.mPhongReflectance = Vec3(0.6f);
    floor.mPhongExponent = 200.f;
    const int m = scene.AddMaterial(floor);
    scene.AddTriangle(Vec3(-100, -100, 0), Vec3(100, -100, 0), Vec3(100, 100, 0), m);
    scene.AddTriangle(Vec3(-100, -100, 0), Vec3(100, 100, 0), Vec3(-100, 100, 0), m);
    scene.AddPointLight(Vec3(0, 30, 0.01f), Vec3(100.f));
    scene.AddBackgroundLight(Vec3(0.2f));
    scene.mCamera.Setup(Vec3(0, 0, 1e-3f), Vec3(0, 1, 0), Vec3(0, 0, 1), 60.f);
    scene.mCamera.SetResolution(12, 8);
    scene.Finalize();
    CheckEveryAlgorithm(scene, "grazing floor", 4);
}

TEST_CASE("A camera inside a glass sphere stays finite", "[stability]") {
    Scene scene = LoadCornell(4, 12, 12);
    Material glass;
    glass.mMirrorReflectance = Vec3(1.f);
    glass.mIor = 1.6f;
    scene.AddSphere(scene.mCamera.Position(), 0.3f, scene.AddMaterial(glass));
    scene.Finalize();
    CheckEveryAlgorithm(scene, "camera inside glass", 4, 10, true);
}

TEST_CASE("Lights touching walls stay finite", "[stability]") {
    // A point light 1e-6 above the floor and an area light whose edge lies on the back
    // wall: distances to the light go to zero at those contacts.
    Scene scene = LoadCornell(2, 12, 12);
    scene.mLights[0].mPosition = Vec3(0.f, 0.f, -1.28002f + 1e-6f);
    Material emitter;
    const int m = scene.AddMaterial(emitter);
    const float y = 1.30455f;  // the back wall's plane
    const int t0 = scene.AddTriangle(Vec3(-0.3f, y, 0.5f), Vec3(0.3f, y, 0.5f), Vec3(0.3f, y - 0.4f, 0.5f), m);
    scene.AddAreaLight({t0}, Vec3(5.f));
    scene.Finalize();
    CheckEveryAlgorithm(scene, "lights touching walls", 4);
}

TEST_CASE("Lights at the limits Scene::Finalize allows render finite images with every estimator", "[stability]") {
    // Finalize refuses a light emitting more than kMaxLightPower or smaller than
    // kMinLightArea. Just inside those limits every estimator, with either MIS heuristic,
    // must stay finite (measured before the limits existed: power 1e36 overflowed light
    // tracing on the background scene, area 1e-39 the path tracer).
    auto checkAll = [](const Scene& aScene, const std::string& aWhat) {
        for (Algorithm algorithm : kAll)
            for (MisHeuristic heuristic : {MisHeuristic::kBalance, MisHeuristic::kPower}) {
                RenderOptions options = Options(algorithm, 2);
                options.mMisHeuristic = heuristic;
                INFO(aWhat << ", " << AlgorithmShortName(algorithm) << (heuristic == MisHeuristic::kPower ? ", power" : ", balance"));
                CHECK(BadPixels(Render(aScene, options).mImage) == 0);
            }
    };
    for (int cornell = 0; cornell < 5; cornell++) {
        // Double every emission until Finalize refuses, and render the last accepted scene:
        // within a factor of 2 of the power limit.
        Scene scene = LoadCornell(cornell, 12, 12);
        int doublings = 0;
        for (;; doublings++) {
            Scene brighter = scene;
            for (Light& light : brighter.mLights) light.mEmission *= 2.f;
            try { brighter.Finalize(); } catch (const Error&) { break; }
            scene = brighter;
        }
        REQUIRE(doublings > 50);
        checkAll(scene, "Cornell " + std::to_string(cornell) + " at the power limit");
    }
    // A sphere light of area 1.01e-30 (radius 2.835e-16) below the ceiling of scene 4.
    Scene tiny = LoadCornell(4, 12, 12);
    tiny.mLights.clear();
    for (Triangle& triangle : tiny.mTriangles) triangle.mLightId = -1;
    tiny.AddSphereLight(tiny.AddSphere(Vec3(0.f, 0.f, 1.f), 2.835e-16f, tiny.AddMaterial(Material{})), Vec3(1e3f));
    REQUIRE_NOTHROW(tiny.Finalize());
    checkAll(tiny, "sphere light of area 1e-30");
}
