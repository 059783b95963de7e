// [integrators] Whole-scene checks of every estimator: analytic furnaces, agreement of
// the estimators with each other on the Cornell scenes (per-region z-tests), no NaN /
// Inf / negative pixels, technique layers that sum to the image, splat placement and
// determinism. Slow variants at higher settings carry the hidden tag [.slow].
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <cstdio>
#include <cstring>

using namespace smallvcm;
using namespace testutil;

namespace {

// Blocks whose every pixel sees, first, a purely diffuse surface. Light tracing cannot
// render specular surfaces seen directly, and on glossy ones (the Cornell floor, Phong
// exponent 90, reflecting the spheres) its estimate is right in expectation but so
// heavy-tailed that a z-test would need far more iterations; it is compared elsewhere.
std::vector<bool> BlocksSeeingOnlyDiffuse(const Scene& aScene, int aBlockSize) {
    const Camera& camera = aScene.mCamera;
    const int blocksX = camera.Width() / aBlockSize, blocksY = camera.Height() / aBlockSize;
    std::vector<bool> usable(size_t(blocksX * blocksY), true);
    for (int y = 0; y < blocksY * aBlockSize; y++)
        for (int x = 0; x < blocksX * aBlockSize; x++)
            for (float sub : {0.1f, 0.5f, 0.9f}) {
                const Ray ray = camera.GenerateRay(Vec2(float(x) + sub, float(y) + 1.f - sub));
                const SurfacePoint hit = aScene.Intersect(ray);
                if (hit.IsValid() && (aScene.GetMaterial(hit.mMaterialId).HasSpecular() ||
                                                   !IsBlack(aScene.GetMaterial(hit.mMaterialId).mPhongReflectance)))
                    usable[size_t((y / aBlockSize) * blocksX + x / aBlockSize)] = false;
            }
    return usable;
}

void CheckFinitePositive(const Image& aImage, const std::string& aWhat) {
    int bad = 0;
    for (const Vec3& p : aImage.mPixels)
        if (!IsFinite(p) || p.x < 0.f || p.y < 0.f || p.z < 0.f) bad++;
    INFO(aWhat);
    CHECK(bad == 0);
}

} // namespace

TEST_CASE("Every estimator renders the emissive furnace's analytic radiance", "[integrators]") {
    // A closed sphere, albedo a, emitting Le everywhere: L = Le (1 - a^k) / (1 - a) for
    // paths of at most k segments. Tolerance: 4 standard errors of the image mean,
    // measured from the pixels (independent samples of one value), plus 1e-3 relative
    // for the geodesic sphere's facets (not a perfect sphere; the answer is the same for
    // any closed surface, so this only covers float rounding).
    const float albedo = 0.5f, emitted = 1.f;
    const int maxPathLength = 6;
    const double expected = emitted * (1.0 - std::pow(albedo, maxPathLength)) / (1.0 - albedo);
    const Scene scene = MakeEmissiveFurnace(albedo, emitted, 32, 32);
    for (Algorithm algorithm : kTransportEstimators) {
        const RenderResult result = RenderWith(scene, algorithm, 8, 11, maxPathLength);
        const MeanAndError stats = PixelStatistics(result.mImage);
        INFO(AlgorithmShortName(algorithm) << ": mean " << stats.mean << " +- " << stats.standardError << ", expected " << expected);
        CHECK(std::abs(stats.mean - expected) <= 4.0 * stats.standardError + 1e-3 * expected);
    }
}

TEST_CASE("Every estimator renders the point-light furnace's analytic radiance", "[integrators]") {
    // Point light of intensity pi at the centre of a unit sphere of albedo 0.5:
    // L = 1 - 0.5^(k-1) for at most k segments (the camera segment is one of them).
    // Same tolerance rule as above. Photon mapping is unbiased here: on a sphere the
    // photons within distance r of a point lie on a cap of area exactly pi r^2
    // (Archimedes), and the photon density is uniform.
    const int maxPathLength = 8;
    const double expected = 1.0 - std::pow(0.5, maxPathLength - 1);
    const Scene scene = MakePointLightFurnace(32, 32);
    for (Algorithm algorithm : kTransportEstimators) {
        const RenderResult result = RenderWith(scene, algorithm, 8, 13, maxPathLength);
        const MeanAndError stats = PixelStatistics(result.mImage);
        INFO(AlgorithmShortName(algorithm) << ": mean " << stats.mean << " +- " << stats.standardError << ", expected " << expected);
        CHECK(std::abs(stats.mean - expected) <= 4.0 * stats.standardError + 1e-3 * expected);
    }
}

TEST_CASE("Photon mapping's bias shrinks with the radius on the Cornell box", "[integrators]") {
    // In the furnaces the constant kernel is unbiased, so the bias is shown on the
    // Cornell box (corners, light falloff, caustics): PPM with a fixed radius against a
    // BPT reference, per 4x4 block. At these radii (0.2, 0.1, 0.05 of the scene radius)
    // and 256 iterations the bias dominates the noise, so the mean absolute block error
    // must fall with the radius; the printed numbers show it.
    const Scene scene = LoadCornell(4, 32, 32);
    const BlockStatistics reference = RenderBlocks(scene, Algorithm::kBidirectionalPathTracing, 256, 4, 101);
    double previousError = 1e30;
    for (float factor : {0.2f, 0.1f, 0.05f}) {
        RenderOptions options;
        options.mAlgorithm = Algorithm::kProgressivePhotonMapping;
        options.mRadiusFactor = factor;
        options.mRadiusAlpha = 1.f;  // fixed radius: the bias of that radius, not of a schedule
        options.mIterations = 256;
        options.mSeed = 202;
        options.mProgress = false;
        const Image image = Render(scene, options).mImage;
        double error = 0.0;
        for (int b = 0; b < reference.mBlocksX * reference.mBlocksY; b++) {
            glm::dvec3 block(0.0);
            const int bx = b % reference.mBlocksX, by = b / reference.mBlocksX;
            for (int y = 0; y < 4; y++) for (int x = 0; x < 4; x++) block += glm::dvec3(image.At(4 * bx + x, 4 * by + y)) / 16.0;
            const glm::dvec3 d = glm::abs(block - reference.Mean(b));
            error += (d.x + d.y + d.z) / 3.0;
        }
        error /= double(reference.mBlocksX * reference.mBlocksY);
        UNSCOPED_INFO("radius factor " << factor << ": mean absolute block error " << error);
        CHECK(error < previousError);
        previousError = error;
    }
}

TEST_CASE("The unbiased estimators agree region by region on every Cornell scene", "[integrators]") {
    // Per 4x4-pixel block and channel, z = (m_a - m_b) / sqrt(se_a^2 + se_b^2), with each
    // standard error measured from the spread of 256 independent iterations (1024 for
    // PT, whose caustic estimates are heavy-tailed). About 600 z-values per scene: |z| < 5
    // keeps the chance of a false alarm per scene near 1e-3 for normal errors, and a
    // systematic error of a few percent in a region still fails.
    // What is compared with BPT: VCM (its merging bias is far below the noise at r =
    // 0.003 R); LT where every pixel sees a diffuse surface first; PT where it can
    // sample every path: not on scenes 0 and 2, where a delta light (sun, point) casts
    // caustics through the glass and mirror spheres that no path tracer can find.
    const int blockSize = 4;
    for (int sceneIndex = 0; sceneIndex < 5; sceneIndex++) {
        const Scene scene = LoadCornell(sceneIndex, 32, 32);
        const BlockStatistics bpt = RenderBlocks(scene, Algorithm::kBidirectionalPathTracing, 256, blockSize, 1000 + sceneIndex);
        const std::vector<bool> onlyDiffuse = BlocksSeeingOnlyDiffuse(scene, blockSize);
        const bool deltaLightCaustics = sceneIndex == 0 || sceneIndex == 2;
        for (Algorithm other : {Algorithm::kPathTracing, Algorithm::kLightTracing, Algorithm::kVertexConnectionMerging}) {
            if (other == Algorithm::kPathTracing && deltaLightCaustics) continue;
            const int iterations = other == Algorithm::kPathTracing ? 1024 : 256;
            const BlockStatistics stats = RenderBlocks(scene, other, iterations, blockSize, 2000 + sceneIndex);
            double worstZ = 0.0;
            int compared = 0;
            for (int b = 0; b < bpt.mBlocksX * bpt.mBlocksY; b++) {
                if (other == Algorithm::kLightTracing && !onlyDiffuse[size_t(b)]) continue;
                const glm::dvec3 difference = stats.Mean(b) - bpt.Mean(b);
                const glm::dvec3 se = glm::sqrt(stats.StandardError(b) * stats.StandardError(b) + bpt.StandardError(b) * bpt.StandardError(b));
                for (int c = 0; c < 3; c++) {
                    if (se[c] == 0.0) { CHECK(difference[c] == Approx(0.0).margin(1e-6)); continue; }
                    worstZ = std::max(worstZ, std::abs(difference[c]) / se[c]);
                }
                compared++;
            }
            INFO("scene " << sceneIndex << ", " << AlgorithmShortName(other) << " vs bpt: worst |z| " << worstZ << " over " << compared << " blocks");
            CHECK(compared > 0);
            CHECK(worstZ < 5.0);
        }
    }
}

TEST_CASE("No estimator writes NaN, infinity or a negative value on any scene", "[integrators]") {
    for (int sceneIndex = 0; sceneIndex < 5; sceneIndex++) {
        const Scene scene = LoadCornell(sceneIndex, 24, 16);
        for (Algorithm algorithm : kTransportEstimators) {
            RenderOptions options;
            options.mAlgorithm = algorithm;
            options.mIterations = 4;
            options.mTechniqueLayers = true;
            options.mProgress = false;
            const RenderResult result = Render(scene, options);
            const std::string what = "scene " + std::to_string(sceneIndex) + " " + AlgorithmShortName(algorithm);
            CheckFinitePositive(result.mImage, what);
            for (const auto& layer : result.mLayers) CheckFinitePositive(layer.second, what + " layer " + layer.first);
        }
    }
}

TEST_CASE("Technique layers sum to the image for PT, BPT and VCM", "[integrators]") {
    // Each contribution is written to exactly one weighted layer, so the sum matches the
    // image up to float rounding of the resolve (relative 1e-5 of the pixel, 1e-7 abs).
    // Scenes: the default Cornell box, and the background scene lit by the default sky (an
    // environment map) and sun instead of its uniform background.
    Scene sky = LoadCornell(3, 24, 24);
    sky.mLights.erase(std::remove_if(sky.mLights.begin(), sky.mLights.end(),
                                     [](const Light& aLight) { return aLight.mType == LightType::kBackground; }),
                      sky.mLights.end());
    AddDefaultSkyAndSun(sky, sky.mCamera);
    sky.Finalize();
    const Scene cornell = LoadCornell(4, 24, 24);
    for (const Scene* scene : {&cornell, static_cast<const Scene*>(&sky)}) {
        for (Algorithm algorithm : {Algorithm::kPathTracing, Algorithm::kBidirectionalPathTracing, Algorithm::kVertexConnectionMerging,
                                    Algorithm::kBidirectionalPhotonMapping, Algorithm::kLightTracing}) {
            RenderOptions options;
            options.mAlgorithm = algorithm;
            options.mIterations = 3;
            options.mTechniqueLayers = true;
            options.mProgress = false;
            const RenderResult result = Render(*scene, options);
            // BPT writes two families: the five classes and the (s, t) pyramid (+ longer
            // paths). Each family alone must sum to the image; unweighted layers sum to more.
            std::vector<std::vector<std::string>> families;
            if (algorithm == Algorithm::kPathTracing) {
                families.push_back({"emitted", "direct_nonspecular", "direct_specular", "indirect_nonspecular", "indirect_specular"});
            } else {
                families.push_back({"unidirectional", "nee", "light_tracing", "connection", "merging"});
                if (algorithm == Algorithm::kBidirectionalPathTracing) {
                    std::vector<std::string> pyramid = {"longer_than_5"};
                    for (int length = 1; length <= 5; length++)
                        for (int s = 0; s <= length; s++) pyramid.push_back("s" + std::to_string(s) + "_t" + std::to_string(length + 1 - s));
                    families.push_back(pyramid);
                }
            }
            for (const auto& family : families) {
                Image sum(result.mImage.mWidth, result.mImage.mHeight);
                int found = 0;
                for (const auto& layer : result.mLayers)
                    if (std::find(family.begin(), family.end(), layer.first) != family.end()) {
                        found++;
                        for (size_t i = 0; i < sum.mPixels.size(); i++) sum.mPixels[i] += layer.second.mPixels[i];
                    }
                INFO(scene->mName << ", " << AlgorithmShortName(algorithm) << ": family of " << family.size() << " layers, found " << found);
                REQUIRE(found == int(family.size()));
                double worst = 0.0;
                for (size_t i = 0; i < sum.mPixels.size(); i++)
                    for (int c = 0; c < 3; c++) {
                        const double image = result.mImage.mPixels[i][c];
                        worst = std::max(worst, std::abs(double(sum.mPixels[i][c]) - image) / (1e-5 * std::abs(image) + 1e-7));
                    }
                CHECK(worst <= 1.0);
            }
        }
    }
}

TEST_CASE("Light tracing splats land in the pixels that see the lit surface, also on non-square images", "[integrators]") {
    // A small lit square in front of a black backdrop: the pixels light tracing reaches
    // must be exactly the pixels where the eye light sees the square (up to the pixels its
    // edges cross, which both may or may not reach).
    Scene scene;
    Material white;
    white.mDiffuseReflectance = Vec3(0.8f);
    const int m = scene.AddMaterial(white);
    const Vec3 a(-0.3f, 2.f, -0.1f), b(0.1f, 2.f, -0.1f), c(0.1f, 2.f, 0.2f), d(-0.3f, 2.f, 0.2f);
    scene.AddTriangle(a, b, c, m);  // wound to face the camera (normal -y)
    scene.AddTriangle(a, c, d, m);
    scene.AddPointLight(Vec3(0.f, 0.f, 0.f), Vec3(10.f));
    scene.mCamera.Setup(Vec3(0.f), Vec3(0.f, 1.f, 0.f), Vec3(0.f, 0.f, 1.f), 50.f);
    scene.mCamera.SetResolution(48, 20);
    scene.Finalize();
    // The square subtends ~0.25% of the light's sphere: 1024 iterations of 960 light paths put
    // ~2500 photons on it, enough to reach each of its ~50 interior pixels many times.
    const Image lt = RenderWith(scene, Algorithm::kLightTracing, 1024).mImage;
    const Image eye = RenderWith(scene, Algorithm::kEyeLight, 16).mImage;
    const std::optional<Vec2> rasterA = scene.mCamera.WorldToRaster(a);
    const std::optional<Vec2> rasterC = scene.mCamera.WorldToRaster(c);
    REQUIRE(rasterA.has_value());
    REQUIRE(rasterC.has_value());
    const Vec2 cornerA = *rasterA, cornerC = *rasterC;
    int inside = 0, mismatched = 0;
    for (int y = 0; y < 20; y++)
        for (int x = 0; x < 48; x++) {
            const bool onEdge = std::abs(float(x) + 0.5f - cornerA.x) < 1.f || std::abs(float(x) + 0.5f - cornerC.x) < 1.f ||
                                std::abs(float(y) + 0.5f - cornerA.y) < 1.f || std::abs(float(y) + 0.5f - cornerC.y) < 1.f;
            if (onEdge) continue;
            const bool litByLt = lt.At(x, y).x > 0.f;
            const bool seenByEye = eye.At(x, y).x > 0.f;
            inside += seenByEye;
            mismatched += litByLt != seenByEye;
        }
    INFO("interior pixels of the square: " << inside);
    CHECK(inside > 20);
    CHECK(mismatched == 0);
}

TEST_CASE("The same seed and thread count give a bit-identical image", "[integrators]") {
    const Scene scene = LoadCornell(1, 24, 24);
    RenderOptions options;
    options.mAlgorithm = Algorithm::kVertexConnectionMerging;
    options.mIterations = 4;
    options.mThreads = 2;
    options.mSeed = 99;
    options.mProgress = false;
    const Image first = Render(scene, options).mImage;
    const Image second = Render(scene, options).mImage;
    CHECK(std::memcmp(first.mPixels.data(), second.mPixels.data(), first.mPixels.size() * sizeof(Vec3)) == 0);
    options.mSeed = 100;
    const Image other = Render(scene, options).mImage;
    CHECK(std::memcmp(first.mPixels.data(), other.mPixels.data(), first.mPixels.size() * sizeof(Vec3)) != 0);
}

TEST_CASE("The beam radiance estimate's RaySearch visits exactly the points within r of a ray's stretch, each once", "[integrators]") {
    // Brute force against RaySearch::Process: points uniform in a box, a cluster much
    // smaller than r, copies of one point; rays from inside and outside the box, in random
    // directions, along the axes (directions with zero components: the slab test's
    // parallel case) and nearly so, of lengths 0, short, long and infinite. The brute force
    // computes t and the distance as the contract states them, in the same float
    // operations, so the visited sets and their t must be equal exactly.
    Rng rng(47, 0);
    const auto randomVec = [&]() { return Vec3(rng.GetFloat(), rng.GetFloat(), rng.GetFloat()) * 2.f - 1.f; };
    for (const int count : {1, 9, 200, 5000}) {
        for (const float radius : {0.003f, 0.05f, 0.4f}) {
            std::vector<Vec3> points;
            for (int i = 0; i < count; i++) {
                const float kind = rng.GetFloat();
                if (kind < 0.7f) points.push_back(randomVec());
                else if (kind < 0.85f) points.push_back(Vec3(0.2f, -0.1f, 0.3f) + 0.1f * radius * randomVec());
                else points.push_back(Vec3(-0.5f, 0.25f, 0.f));
            }
            RaySearch<int> search;
            search.Build(points.size(), radius, [&](size_t i) { return points[i]; }, [](size_t i) { return int(i); });
            int wrong = 0, visits = 0;
            for (int q = 0; q < 200; q++) {
                Vec3 origin = q % 2 ? randomVec() * 1.5f : points[size_t(q) % points.size()] + 0.5f * radius * randomVec();
                Vec3 direction;
                if (q % 5 == 0) {
                    direction = Vec3(0.f);
                    direction[q % 3] = q % 2 ? 1.f : -1.f;
                } else if (q % 5 == 1) {
                    direction = glm::normalize(Vec3(1.f, 1e-6f * rng.GetFloat(), 0.f));
                } else {
                    direction = glm::normalize(randomVec() + Vec3(1e-3f));
                }
                const float lengths[4] = {0.f, 0.1f, 2.5f, std::numeric_limits<float>::infinity()};
                const float length = lengths[q % 4];
                std::vector<int> seen(points.size(), 0);
                std::vector<float> seenT(points.size(), -1.f);
                search.Process(origin, direction, length, [&](int aIndex, float aT) {
                    seen[size_t(aIndex)]++;
                    seenT[size_t(aIndex)] = aT;
                    visits++;
                });
                for (size_t i = 0; i < points.size(); i++) {
                    const Vec3 toPoint = points[i] - origin;
                    const float t = glm::dot(toPoint, direction);
                    const Vec3 across = toPoint - t * direction;
                    const int expected = t >= 0.f && t <= length && glm::dot(across, across) <= radius * radius ? 1 : 0;
                    wrong += seen[i] != expected || (expected && seenT[i] != t);
                }
            }
            INFO(count << " points, radius " << radius << ": " << visits << " visits");
            CHECK(visits > 0);
            CHECK(wrong == 0);
        }
    }
    RaySearch<int> empty;
    int calls = 0;
    empty.Process(Vec3(0.f), Vec3(1.f, 0.f, 0.f), 1.f, [&](int, float) { calls++; });
    empty.Build(0, 0.1f, [](size_t) { return Vec3(0.f); }, [](size_t i) { return int(i); });
    empty.Process(Vec3(0.f), Vec3(1.f, 0.f, 0.f), 1.f, [&](int, float) { calls++; });
    CHECK(calls == 0);
}

TEST_CASE("The photon beams' BeamSearch visits exactly the beams BeamSearch::Closest takes, each once", "[integrators]") {
    // Brute force against BeamSearch::Process: beams of random directions and lengths
    // (short, long across the box, of length 0), axis-parallel ones, copies of one beam;
    // queries as for RaySearch. The brute force applies Closest to every beam, so the
    // visited sets and their pairs must be equal exactly; beams are cut into pieces inside
    // the search, so a beam visited twice (from two pieces) or never shows here. Closest
    // itself against the closest points of the lines in double: t, u, the distance and
    // sin theta.
    Rng rng(53, 0);
    const auto randomVec = [&]() { return Vec3(rng.GetFloat(), rng.GetFloat(), rng.GetFloat()) * 2.f - 1.f; };
    int closestChecked = 0;
    for (const int count : {1, 9, 200, 3000}) {
        for (const float radius : {0.003f, 0.05f, 0.4f}) {
            std::vector<Beam> beams;
            for (int i = 0; i < count; i++) {
                Beam beam;
                beam.mStart = randomVec();
                beam.mDirection = glm::normalize(randomVec() + Vec3(1e-3f));
                const float kind = rng.GetFloat();
                if (kind < 0.1f) beam.mDirection = Vec3(0.f, 0.f, 1.f);
                beam.mLength = kind < 0.05f ? 0.f : (kind < 0.5f ? 0.2f * rng.GetFloat() : 3.f * rng.GetFloat());
                if (kind > 0.9f && !beams.empty()) beam = beams.front();
                beams.push_back(beam);
            }
            BeamSearch<int> search;
            search.Build(beams.size(), radius, [&](size_t i) { return beams[i]; }, [](size_t i) { return int(i); });
            int wrong = 0, visits = 0;
            for (int q = 0; q < 150; q++) {
                const Beam& near = beams[size_t(q) % beams.size()];
                const Vec3 origin = q % 2 ? randomVec() * 1.5f : near.mStart + 0.5f * near.mLength * near.mDirection - randomVec();
                Vec3 direction = glm::normalize(randomVec() + Vec3(1e-3f));
                if (q % 7 == 0) direction = Vec3(1.f, 0.f, 0.f);
                const float lengths[4] = {0.f, 0.5f, 3.f, std::numeric_limits<float>::infinity()};
                const float length = lengths[q % 4];
                std::vector<int> seen(beams.size(), 0);
                std::vector<BeamPair> pairs(beams.size());
                search.Process(origin, direction, length, [&](int aIndex, const BeamPair& aPair) {
                    seen[size_t(aIndex)]++;
                    pairs[size_t(aIndex)] = aPair;
                    visits++;
                });
                for (size_t i = 0; i < beams.size(); i++) {
                    const std::optional<BeamPair> expected = BeamSearch<int>::Closest(origin, direction, length, beams[i], radius);
                    wrong += seen[i] != (expected ? 1 : 0);
                    if (expected && seen[i] == 1)
                        wrong += pairs[i].mT != expected->mT || pairs[i].mU != expected->mU || pairs[i].mSinTheta != expected->mSinTheta;
                    if (!expected || !(length < 1e30f)) continue;
                    // Closest against double precision.
                    const glm::dvec3 o(origin), w(direction), a(beams[i].mStart), wb(beams[i].mDirection);
                    const double b = glm::dot(w, wb), p = glm::dot(w, o - a), qq = glm::dot(wb, o - a);
                    const double t = (b * qq - p) / (1.0 - b * b), u = (qq - b * p) / (1.0 - b * b);
                    const double distance = glm::length(o + t * w - a - u * wb);
                    const double scale = 1.0 + std::abs(t) + std::abs(u);
                    wrong += std::abs(t - expected->mT) > 1e-3 * scale || std::abs(u - expected->mU) > 1e-3 * scale;
                    wrong += distance > double(radius) * (1.0 + 1e-3) + 1e-4 * scale;
                    wrong += std::abs(std::sqrt(1.0 - b * b) - expected->mSinTheta) > 1e-4;
                    closestChecked++;
                }
            }
            INFO(count << " beams, radius " << radius << ": " << visits << " visits");
            CHECK(wrong == 0);
        }
    }
    CHECK(closestChecked > 100);
}

TEST_CASE("VCM's hash grid visits exactly the light vertices within the merge radius, each once", "[integrators]") {
    // Brute force against HashGrid::Process: points uniform in a box, plus a cluster much
    // smaller than a cell (a bucket with many points) and points exactly on cell borders
    // (cells are 2r wide, so multiples of 2r). Few points give a small table, so distinct
    // cells often share a bucket: such a bucket must still be visited once.
    Rng rng(31, 0);
    for (const int count : {1, 7, 100, 5000}) {
        for (const float radius : {0.01f, 0.1f, 0.5f}) {
            std::vector<Vec3> points;
            for (int i = 0; i < count; i++) {
                const float kind = rng.GetFloat();
                if (kind < 0.6f) points.push_back(Vec3(rng.GetFloat(), rng.GetFloat(), rng.GetFloat()) * 2.f - 1.f);
                else if (kind < 0.8f) points.push_back(Vec3(0.3f) + 0.01f * radius * Vec3(rng.GetFloat(), rng.GetFloat(), rng.GetFloat()));
                else points.push_back(2.f * radius * Vec3(float(int(rng.GetFloat() * 8.f) - 4), float(int(rng.GetFloat() * 8.f) - 4), 0.f));
            }
            HashGrid grid;
            grid.Build(points.size(), radius, [&](size_t i) { return points[i]; });
            int wrong = 0, visits = 0;
            for (int q = 0; q < 300; q++) {
                // Queries near the points (some exactly on one) and anywhere in the box.
                Vec3 query = q % 3 == 0 ? points[size_t(rng.GetFloat() * float(count)) % points.size()]
                                        : Vec3(rng.GetFloat(), rng.GetFloat(), rng.GetFloat()) * 2.2f - 1.1f;
                if (q % 3 == 1) query = points[size_t(q) % points.size()] + radius * 0.9f * Vec3(1.f, 0.f, 0.f);
                std::vector<int> seen(points.size(), 0);
                grid.Process(query, [&](uint32_t aIndex) { seen[aIndex]++; visits++; });
                for (size_t i = 0; i < points.size(); i++) {
                    const Vec3 d = points[i] - query;
                    const int expected = glm::dot(d, d) <= radius * radius ? 1 : 0;
                    wrong += seen[i] != expected;
                }
            }
            INFO(count << " points, radius " << radius << ": " << visits << " visits");
            CHECK(wrong == 0);
        }
    }
}
