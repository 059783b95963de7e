// [photon_mapping] Classic photon mapping: the kd-tree's k nearest neighbours against
// brute force, the density estimate's bias shrinking as photons grow, both algorithms on
// the analytic furnaces and against path tracing on the Cornell box, layers summing.
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <cstdio>

using namespace smallvcm;
using namespace testutil;

namespace {

// Brute force: every accepted point within the radius, sorted by distance, first k.
std::vector<float> BruteForceDistances(const std::vector<Vec3>& aPoints, const Vec3& aQuery, int aK, float aMaxDistSqr) {
    std::vector<float> distances;
    for (const Vec3& p : aPoints) {
        const float d = glm::dot(p - aQuery, p - aQuery);
        if (d <= aMaxDistSqr) distances.push_back(d);
    }
    std::sort(distances.begin(), distances.end());
    if (int(distances.size()) > aK) distances.resize(size_t(aK));
    return distances;
}

// Mean and standard error of the per-iteration image means (each iteration has its own
// photon map, so iterations are the independent samples, not pixels).
MeanAndError IterationStatistics(const Scene& aScene, Algorithm aAlgorithm, int aIterations, int aMaxPathLength,
                                 int aPhotons, int aNearest) {
    RenderOptions options;
    options.mAlgorithm = aAlgorithm;
    options.mMaxPathLength = aMaxPathLength;
    options.mPhotonCount = aPhotons;
    options.mNearestPhotons = aNearest;
    options.mMaxPhotonRadiusFactor = 0.5f;
    std::unique_ptr<AbstractRenderer> renderer = CreateRenderer(aScene, options);
    std::vector<double> means;
    double previous = 0.0;
    for (int i = 0; i < aIterations; i++) {
        Sampler sampler = IterationSampler(options.mSampler, 31, i);
        renderer->RunIteration(i, sampler);
        const double cumulative = MeanValue(renderer->GetFilm().Resolve(1.0));
        means.push_back(cumulative - previous);
        previous = cumulative;
    }
    MeanAndError r;
    for (double m : means) r.mean += m / double(aIterations);
    double variance = 0.0;
    for (double m : means) variance += (m - r.mean) * (m - r.mean) / double(aIterations - 1);
    r.standardError = std::sqrt(variance / double(aIterations));
    return r;
}

} // namespace

TEST_CASE("The kd-tree's k nearest neighbours equal brute force, with ties and a maximum radius", "[photon_mapping]") {
    Rng rng(5, 1);
    for (int trial = 0; trial < 3; trial++) {
        std::vector<Vec3> points;
        // Random points, plus points on a coarse lattice (many exactly equal distances).
        for (int i = 0; i < 3000; i++) points.push_back(rng.GetVec3() * 4.f - 2.f);
        for (int x = -3; x <= 3; x++) for (int y = -3; y <= 3; y++) for (int z = -3; z <= 3; z++) points.push_back(Vec3(float(x), float(y), float(z)) * 0.25f);
        points.push_back(points[17]);  // an exact duplicate
        NearestSearch::KdTree tree;
        std::vector<uint32_t> order;
        tree.Build(points.size(), [&](size_t i) { return points[i]; }, order);
        REQUIRE(tree.Size() == points.size());
        std::vector<NearestSearch::Neighbor> neighbors;
        for (int q = 0; q < 300; q++) {
            const Vec3 query = q % 3 == 0 ? Vec3(0.f) : (q % 3 == 1 ? points[size_t(q)] : rng.GetVec3() * 4.f - 2.f);
            const int k = 1 + q % 40;
            const float maxDistSqr = q % 5 == 0 ? 0.01f : 100.f;
            tree.KNearest(query, k, maxDistSqr, [](size_t) { return true; }, neighbors);
            const std::vector<float> expected = BruteForceDistances(points, query, k, maxDistSqr);
            REQUIRE(neighbors.size() == expected.size());
            for (size_t i = 0; i < neighbors.size(); i++) {
                // The i-th distance matches; with ties the indices may differ, but each
                // returned index must really be at the distance it claims.
                CHECK(neighbors[i].mDistSqr == expected[i]);
                const Vec3 d = tree.Position(neighbors[i].mIndex) - query;
                CHECK(glm::dot(d, d) == neighbors[i].mDistSqr);
            }
        }
    }
}

TEST_CASE("FindNearest returns the k nearest by (distance, index), the k-th last, whatever the first guess", "[photon_mapping]") {
    // FindNearest leaves its result unsorted and may start from a guessed bound (the
    // k-th distance of the previous query): the set must still be exactly the first k of
    // the total order (distance, then index), and the k-th must be last, since the density
    // estimate divides by the disc through it. Guesses far too small (widened in steps),
    // far too large, and none; k from 1 to 150 (cut-backs at 1.5 k inside the search,
    // and exactly k candidates found, where no cut-back happens); an accept filter.
    Rng rng(11, 2);
    std::vector<Vec3> points;
    for (int i = 0; i < 5000; i++) points.push_back(rng.GetVec3() * 2.f - 1.f);
    for (int x = -4; x <= 4; x++) for (int y = -4; y <= 4; y++) points.push_back(Vec3(float(x), float(y), 0.f) * 0.125f);
    NearestSearch::KdTree tree;
    std::vector<uint32_t> order;
    tree.Build(points.size(), [&](size_t i) { return points[i]; }, order);
    auto accept = [&](size_t aIndex) { return order[aIndex] % 7 != 3; };  // drops one point in seven
    std::vector<NearestSearch::Neighbor> found;
    float hint = 0.f;
    for (int q = 0; q < 400; q++) {
        const Vec3 query = q % 4 == 0 ? Vec3(0.f) : rng.GetVec3() * 2.f - 1.f;
        const int k = 1 + (q * 37) % 150;
        const float maxDistSqr = q % 6 == 0 ? 0.002f : 10.f;
        // The brute-force answer: every accepted point within the radius, in the total order.
        std::vector<NearestSearch::Neighbor> all;
        for (size_t i = 0; i < tree.Size(); i++) {
            const Vec3 d = tree.Position(i) - query;
            const float distSqr = glm::dot(d, d);
            if (distSqr <= maxDistSqr && accept(i)) all.push_back(NearestSearch::Neighbor{uint32_t(i), distSqr});
        }
        std::sort(all.begin(), all.end());
        if (all.size() > size_t(k)) all.resize(size_t(k));
        const float guesses[4] = {0.f, 1e-9f, 5.f, hint};
        const float guess = guesses[q % 4];
        float ioHint = guess;
        tree.FindNearest(query, k, maxDistSqr, accept, found, &ioHint);
        INFO("query " << q << ", k " << k << ", first guess " << guess << ", found " << found.size() << " of " << all.size());
        REQUIRE(found.size() == all.size());
        if (found.size() == size_t(k)) {
            CHECK(found.back().mIndex == all.back().mIndex);  // the k-th nearest is last
            CHECK(found.back().mDistSqr == all.back().mDistSqr);
        }
        std::sort(found.begin(), found.end());
        for (size_t i = 0; i < found.size(); i++) CHECK(found[i].mIndex == all[i].mIndex);
        hint = ioHint;  // 0 (no guess) when the k-th nearest lies on the query point
    }
}

TEST_CASE("NearestSearch finds the same k nearest as its kd-tree's KNearest, query after query, and Build returns a permutation",
          "[photon_mapping]") {
    // The contract (NearestSearch) keeps its own guess of the k-th distance from one query
    // to the next; whatever it guesses, each answer must be the set KdTree::KNearest (no
    // guess) gives for the same points, with the k-th nearest last.
    Rng rng(13, 3);
    std::vector<Vec3> points;
    for (int i = 0; i < 4000; i++) points.push_back(rng.GetVec3() * 2.f - 1.f);
    for (int x = -4; x <= 4; x++) for (int y = -4; y <= 4; y++) points.push_back(Vec3(float(x), float(y), 0.f) * 0.125f);
    points.push_back(points[5]);  // an exact duplicate
    const auto positionOf = [&](size_t i) { return points[i]; };
    const auto acceptAll = [](size_t) { return true; };

    NearestSearch search;
    CHECK(search.Size() == 0);  // nothing built yet: nothing found
    CHECK(search.FindNearest(Vec3(0.f), 5, 1.f, acceptAll).empty());
    CHECK(search.KNearest(Vec3(0.f), 5, 1.f, acceptAll).empty());
    const std::vector<uint32_t> order = search.Build(points.size(), positionOf);
    REQUIRE(order.size() == points.size());
    REQUIRE(search.Size() == points.size());
    std::vector<uint32_t> sortedOrder = order;
    std::sort(sortedOrder.begin(), sortedOrder.end());
    for (size_t i = 0; i < sortedOrder.size(); i++) REQUIRE(sortedOrder[i] == uint32_t(i));  // each point once
    for (size_t i = 0; i < order.size(); i++) REQUIRE(search.Position(i) == points[order[i]]);

    NearestSearch::KdTree tree;
    std::vector<uint32_t> treeOrder;
    tree.Build(points.size(), positionOf, treeOrder);
    REQUIRE(treeOrder == order);
    const auto accept = [&](size_t aIndex) { return order[aIndex] % 5 != 2; };  // drops one point in five
    std::vector<NearestSearch::Neighbor> expected;
    for (int q = 0; q < 400; q++) {
        // Queries near the last one (the kept guess fits), far jumps, changing k and radius.
        const Vec3 query = q % 5 == 4 ? Vec3(0.f)
                           : q % 2    ? rng.GetVec3() * 2.f - 1.f
                                      : points[size_t(q * 7)] + 0.01f * rng.GetVec3();
        const int k = 1 + (q * 29) % 120;
        const float maxDistSqr = q % 7 == 0 ? 0.003f : 10.f;
        tree.KNearest(query, k, maxDistSqr, accept, expected);
        std::vector<NearestSearch::Neighbor> found = search.FindNearest(query, k, maxDistSqr, accept);
        INFO("query " << q << ", k " << k << ", found " << found.size() << " of " << expected.size());
        REQUIRE(found.size() == expected.size());
        if (found.size() == size_t(k)) {  // the k-th nearest is last
            CHECK(found.back().mIndex == expected.back().mIndex);
            CHECK(found.back().mDistSqr == expected.back().mDistSqr);
        }
        std::sort(found.begin(), found.end());
        for (size_t i = 0; i < found.size(); i++) {
            CHECK(found[i].mIndex == expected[i].mIndex);
            CHECK(found[i].mDistSqr == expected[i].mDistSqr);
        }
        // KNearest: the same, sorted.
        const std::vector<NearestSearch::Neighbor> sorted = search.KNearest(query, k, maxDistSqr, accept);
        REQUIRE(sorted.size() == expected.size());
        for (size_t i = 0; i < sorted.size(); i++) {
            CHECK(sorted[i].mIndex == expected[i].mIndex);
            CHECK(sorted[i].mDistSqr == expected[i].mDistSqr);
        }
    }
}

TEST_CASE("The density estimate on a plane under a point light converges to the analytic radiance", "[photon_mapping]") {
    // A Lambert plane (rho = 0.5) at distance 1 below a point light of intensity 1:
    // straight below, E = I / h^2 = 1 and L = rho E / pi. The irradiance falls off as
    // (1 + r^2)^(-3/2), so the k-NN disc (radius^2 ~ 4k/N) blurs the peak: the relative
    // bias is about -0.75 r^2, i.e. -30%, -7.5%, -1.9% for N = 4k, 16k, 64k photons at
    // k = 400. Each estimate has ~5% noise (1/sqrt(k)); averaging 32 independent maps
    // gives ~0.9%, so the shrinking bias is seen clearly. Checked: |bias| falls with N,
    // and the last is within 3% (its expected -1.9% plus 3 standard errors of ~0.9%).
    Scene scene;
    Material floor;
    floor.mDiffuseReflectance = Vec3(0.5f);
    const int m = scene.AddMaterial(floor);
    scene.AddTriangle(Vec3(-50, -50, 0), Vec3(50, -50, 0), Vec3(50, 50, 0), m);
    scene.AddTriangle(Vec3(-50, -50, 0), Vec3(50, 50, 0), Vec3(-50, 50, 0), m);
    scene.AddPointLight(Vec3(0, 0, 1), Vec3(1.f));
    scene.mCamera.Setup(Vec3(0, -3, 2), Vec3(0, 1, -0.5f), Vec3(0, 0, 1), 45.f);
    scene.Finalize();
    const double expected = 0.5 / kPi;
    Bsdf bsdf;
    bsdf.Setup(Vec3(0, 0, 1), Vec3(0, 0, 1), scene.GetMaterial(m), Transport::kRadiance);
    double previousBias = 1e30;
    for (int photons : {4000, 16000, 64000}) {
        double sum = 0.0;
        const int maps = 32;
        for (int i = 0; i < maps; i++) {
            Sampler sampler(Rng(77, uint64_t(photons + i)));
            const PhotonMaps photonMaps = TracePhotons(scene, photons, 10, sampler);
            sum += double(Luminance(photonMaps.mGlobal.EstimateRadiance(Vec3(0.f), bsdf, 400, 100.f, 10)));
        }
        const double bias = sum / maps / expected - 1.0;
        UNSCOPED_INFO(photons << " photons: relative bias " << bias);
        std::printf("photon mapping, plane under a point light: %6d photons, relative error of the estimate %+.4f\n", photons, bias);
        CHECK(std::abs(bias) < std::abs(previousBias));
        previousBias = bias;
    }
    CHECK(std::abs(previousBias) < 0.03);
}

TEST_CASE("Photon mapping renders both furnaces within its bias", "[photon_mapping]") {
    // Photons are uniform in both furnaces, so the only systematic error is the k-NN
    // estimator's own: for a uniform (Poisson) density, E[k / (pi r_k^2)] = density *
    // k / (k - 1), +1% at k = 100, on the reflected (photon) part of the light. The
    // tolerance: 4 standard errors of the mean over 8 independent iterations (each its
    // own photon map) plus that 1% of the expected value.
    const int maxPathLength = 6;
    const Scene emissive = MakeEmissiveFurnace(0.5f, 1.f, 24, 24);
    const double emissiveExpected = (1.0 - std::pow(0.5, maxPathLength)) / 0.5;
    const Scene point = MakePointLightFurnace(24, 24);
    const double pointExpected = 1.0 - std::pow(0.5, maxPathLength - 1);
    for (Algorithm algorithm : {Algorithm::kPhotonMapping, Algorithm::kPhotonMappingFinalGather}) {
        for (int which = 0; which < 2; which++) {
            const MeanAndError stats = IterationStatistics(which == 0 ? emissive : point, algorithm, 8, maxPathLength, 20000, 100);
            const double expected = which == 0 ? emissiveExpected : pointExpected;
            INFO(AlgorithmShortName(algorithm) << (which == 0 ? " emissive" : " point-light") << " furnace: " << stats.mean
                 << " +- " << stats.standardError << ", expected " << expected);
            CHECK(std::abs(stats.mean - expected) <= 4.0 * stats.standardError + 0.01 * expected);
        }
    }
}

TEST_CASE("The partitioned estimator agrees with path tracing on the default Cornell box and its parts sum to it", "[photon_mapping]") {
    // Light seen directly (path length 1) is left out of both (--min-path-length 2): at
    // 32x32 the light covers two pixels and its jittered coverage alone varies the image
    // mean by several percent. Tolerance: the image mean within 2% of a 512-iteration PT
    // reference (k-NN bias ~1% plus noise), and per 8x8-pixel block within 15% (the
    // corner and shadow-edge blur of k = 100 photons at 200k photons per map is the
    // largest term; the worst block is printed).
    const Scene scene = LoadCornell(4, 32, 32);
    RenderOptions options;
    options.mAlgorithm = Algorithm::kPathTracing;
    options.mIterations = 512;
    options.mMinPathLength = 2;
    options.mProgress = false;
    const Image reference = Render(scene, options).mImage;
    options.mAlgorithm = Algorithm::kPhotonMappingFinalGather;
    options.mIterations = 16;
    options.mTechniqueLayers = true;
    const RenderResult result = Render(scene, options);
    const double meanReference = MeanValue(reference), mean = MeanValue(result.mImage);
    INFO("pmfg mean " << mean << ", pt mean " << meanReference);
    CHECK(std::abs(mean - meanReference) <= 0.02 * meanReference);
    double worst = 0.0;
    for (int by = 0; by < 4; by++)
        for (int bx = 0; bx < 4; bx++) {
            double a = 0.0, b = 0.0;
            for (int y = 0; y < 8; y++)
                for (int x = 0; x < 8; x++) {
                    const Vec3 p = result.mImage.At(8 * bx + x, 8 * by + y), r = reference.At(8 * bx + x, 8 * by + y);
                    a += double(p.x + p.y + p.z);
                    b += double(r.x + r.y + r.z);
                }
            worst = std::max(worst, std::abs(a - b) / b);
        }
    INFO("worst 8x8 block relative difference " << worst);
    CHECK(worst < 0.15);
    // The five parts sum to the image.
    Image sum(32, 32);
    int parts = 0;
    for (const auto& layer : result.mLayers)
        if (layer.first != "photons") {
            parts++;
            for (size_t i = 0; i < sum.mPixels.size(); i++) sum.mPixels[i] += layer.second.mPixels[i];
        }
    CHECK(parts == 5);
    for (size_t i = 0; i < sum.mPixels.size(); i++)
        for (int c = 0; c < 3; c++)
            CHECK(sum.mPixels[i][c] == Approx(result.mImage.mPixels[i][c]).epsilon(1e-5).margin(1e-7));
}
