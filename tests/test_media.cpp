// [media] Participating media ([SECTION] Participating media): the transmittance, the
// free-flight sampler and the Henyey-Greenstein phase function against their formulas;
// media boundaries, nesting and bad media; whole scenes with media against analytic
// answers (the per-length agreement of the estimators in a medium room is in
// test_transport.cpp, the MIS brute force with medium vertices in test_vcm_mis.cpp).
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <cstdio>

using namespace smallvcm;
using namespace testutil;

namespace {

// A closed box [aMin, aMax] of 12 triangles with shared corners, wound outwards.
void AddClosedBox(Scene& aScene, const Vec3& aMin, const Vec3& aMax, int aMaterial) {
    const Vec3 c = 0.5f * (aMin + aMax);
    for (int axis = 0; axis < 3; axis++)
        for (int side = 0; side < 2; side++) {
            const int u = (axis + 1) % 3, v = (axis + 2) % 3;
            Vec3 corner[4];
            for (int k = 0; k < 4; k++) {
                corner[k][axis] = side ? aMax[axis] : aMin[axis];
                corner[k][u] = (k == 1 || k == 2) ? aMax[u] : aMin[u];
                corner[k][v] = (k >= 2) ? aMax[v] : aMin[v];
            }
            Vec3 outside = c;
            outside[axis] = side ? aMax[axis] + 1.f : aMin[axis] - 1.f;
            // AddQuadFacing turns the front towards its point: the front faces outside.
            AddQuadFacing(aScene, corner[0], corner[1], corner[2], corner[3], outside, aMaterial);
        }
}

Medium MakeMedium(const Vec3& aSigmaA, const Vec3& aSigmaS, float aG, const char* aName = "test medium") {
    Medium m;
    m.mName = aName;
    m.mSigmaA = aSigmaA;
    m.mSigmaS = aSigmaS;
    m.mG = aG;
    return m;
}

// An index-matched boundary around medium aMedium.
Material IndexMatched(int aMedium) {
    Material m;
    m.mMedium = aMedium;
    return m;
}

// A scene for geometric checks: a box of index-matched medium aMedium in [-1, 1]^3, a
// point light, and the camera at aCamera looking at the box.
Scene MakeMediumBoxScene(const Medium& aMedium, const Vec3& aCamera) {
    Scene scene;
    scene.mName = "medium box";
    const int medium = scene.AddMedium(aMedium);
    AddClosedBox(scene, Vec3(-1.f), Vec3(1.f), scene.AddMaterial(IndexMatched(medium)));
    scene.AddPointLight(Vec3(0.f, 3.f, 0.f), Vec3(1.f));
    scene.mCamera.Setup(aCamera, -aCamera + Vec3(0.01f, 0.02f, 0.f), Vec3(0.f, 1.f, 0.f), 40.f);
    scene.mCamera.SetResolution(4, 4);
    scene.Finalize();
    return scene;
}

double Average(const Vec3& aV) { return (double(aV.x) + double(aV.y) + double(aV.z)) / 3.0; }

} // namespace

TEST_CASE("Transmittance through a slab of medium is Beer-Lambert per channel, and a connection's pdfs are its pieces' free-flight pdfs", "[media]") {
    // Exact formulas, so the tolerance is float rounding (1e-5 relative).
    const Vec3 sigmaA(0.1f, 0.4f, 1.2f), sigmaS(0.5f, 0.3f, 0.1f);
    const Medium medium = MakeMedium(sigmaA, sigmaS, 0.2f);
    const Scene scene = MakeMediumBoxScene(medium, Vec3(0.f, 0.f, -5.f));
    const Vec3 sigmaT = sigmaA + sigmaS;
    REQUIRE(scene.HasMedia());
    REQUIRE(scene.CameraMedium() == -1);
    // From outside through the whole box: 2 units inside, 4 in empty space.
    const SegmentMedia through = TraceConnection(scene, Vec3(-3.f, 0.1f, 0.2f), Vec3(1.f, 0.f, 0.f), 6.f, -1);
    REQUIRE_FALSE(through.mOccluded);
    double averageT = 0.0, averageDensity = 0.0;
    for (int c = 0; c < 3; c++) {
        const double t = std::exp(-double(sigmaT[c]) * 2.0);
        CHECK(std::abs(through.mTransmittance[c] - t) <= 1e-5 * t);
        averageT += t / 3.0;
    }
    const SegmentPdfs pdfs = through.Pdfs(false, false);
    CHECK(std::abs(pdfs.mForward - averageT) <= 1e-5 * averageT);
    CHECK(std::abs(pdfs.mReverse - averageT) <= 1e-5 * averageT);
    // From a point in the medium (0.5 inside the box) to a surface 2.5 away: the start is
    // reached backwards with density sigma_t T(0.5), averaged; forwards it is flown through.
    const SegmentMedia out = TraceConnection(scene, Vec3(0.5f, 0.1f, 0.2f), Vec3(1.f, 0.f, 0.f), 2.5f, 0);
    averageT = 0.0;
    for (int c = 0; c < 3; c++) {
        const double t = std::exp(-double(sigmaT[c]) * 0.5);
        averageT += t / 3.0;
        averageDensity += double(sigmaT[c]) * t / 3.0;
        CHECK(std::abs(out.mTransmittance[c] - t) <= 1e-5 * t);
    }
    CHECK(std::abs(out.Pdfs(true, false).mReverse - averageDensity) <= 1e-5 * averageDensity);
    CHECK(std::abs(out.Pdfs(true, false).mForward - averageT) <= 1e-5 * averageT);
    // A solid surface in the way occludes; an index-matched one does not.
    CHECK(MediumTransmittance(medium, 0.f) == Vec3(1.f));
    CHECK(MediumTransmittance(MakeMedium(Vec3(0.f, 1.f, 0.f), Vec3(0.f), 0.f), std::numeric_limits<float>::infinity()) ==
          Vec3(1.f, 0.f, 1.f));
}

TEST_CASE("Free-flight distances follow their pdf, the channels' average (chi-square)", "[media]") {
    // Threshold: the chi-square quantile at significance 1e-3 (ChiSquareThreshold). The
    // cells: 40 distance bins of 0.1 on [0, 4) and the rest, with a clear channel whose
    // samples fly to infinity (P(infinity) = 1/3 there).
    for (const Vec3& sigmaT : {Vec3(0.5f, 1.f, 3.f), Vec3(0.f, 1.f, 2.f)}) {
        const Medium medium = MakeMedium(sigmaT, Vec3(0.f), 0.f);
        const int samples = 200000, bins = 40;
        std::vector<double> observed(size_t(bins) + 2, 0.0), expected(size_t(bins) + 2, 0.0);
        Rng rng(91);
        for (int i = 0; i < samples; i++) {
            const float t = SampleFreeFlight(medium, rng.GetFloat());
            REQUIRE(t >= 0.f);
            const size_t cell = std::isinf(t) ? size_t(bins) + 1 : std::min(size_t(bins), size_t(t / 0.1f));
            observed[cell] += 1.0;
        }
        const auto cdf = [&](double aT) {
            double survive = 0.0;
            for (int c = 0; c < 3; c++) survive += std::exp(-double(sigmaT[c]) * aT) / 3.0;
            return 1.0 - survive;
        };
        for (int b = 0; b < bins; b++) expected[size_t(b)] = samples * (cdf(0.1 * (b + 1)) - cdf(0.1 * b));
        const double clear = (sigmaT.x == 0.f) ? 1.0 / 3.0 : 0.0;
        expected[size_t(bins)] = samples * (1.0 - clear - cdf(0.1 * bins));
        expected[size_t(bins) + 1] = samples * clear;
        const ChiSquare chi = ComputeChiSquare(observed, expected);
        INFO("sigma_t " << sigmaT.x << " " << sigmaT.y << " " << sigmaT.z << ": chi2 " << chi.statistic << " dof " << chi.dof
                        << " threshold " << chi.threshold);
        CHECK(chi.statistic < chi.threshold);
        // The pdfs the estimators divide by: the derivative of the cdf, and 1 - cdf.
        for (float t : {0.05f, 0.7f, 2.5f}) {
            const double h = 1e-3;
            const double derivative = (cdf(t + h) - cdf(t - h)) / (2.0 * h);
            CHECK(std::abs(FreeFlightDensity(medium, t) - derivative) <= 1e-4 * derivative);
            CHECK(std::abs(FreeFlightProbability(medium, t) - (1.0 - cdf(t))) <= 1e-5);
        }
    }
}

TEST_CASE("Henyey-Greenstein sampling follows its pdf (chi-square), which integrates to 1, and a medium point's Bsdf is reciprocal", "[media]") {
    // Threshold: the chi-square quantile at significance 1e-3; 50 cells in cos theta.
    for (float g : {-0.7f, 0.f, 0.3f, 0.9f}) {
        const int samples = 200000, bins = 50;
        // The cell probabilities from HG's cdf in cos theta, integrated by hand:
        //   P(cos <= m) = (1 - g^2) / (2 g) ((1 + g^2 - 2 g m)^(-1/2) - 1 / (1 + g)), (m + 1) / 2 at g = 0;
        // and, as a check of the pdf itself, Simpson's rule on 2 pi p over 20,000 steps
        // equals 1 (its error at g = 0.9 is below 1e-6).
        const auto cdf = [g](double aCos) {
            if (g == 0.f) return 0.5 * (aCos + 1.0);
            const double gg = double(g);
            return (1.0 - gg * gg) / (2.0 * gg) * (1.0 / std::sqrt(1.0 + gg * gg - 2.0 * gg * aCos) - 1.0 / (1.0 + gg));
        };
        std::vector<double> observed(size_t(bins), 0.0), expected(size_t(bins), 0.0);
        for (int b = 0; b < bins; b++) expected[size_t(b)] = samples * (cdf(-1.0 + 2.0 * (b + 1) / bins) - cdf(-1.0 + 2.0 * b / bins));
        double total = 0.0;
        const int steps = 20000;
        for (int i = 0; i <= steps; i++) {
            const double weight = (i == 0 || i == steps) ? 1.0 : (i % 2 ? 4.0 : 2.0);
            total += weight * HenyeyGreensteinPdf(float(-1.0 + 2.0 * i / steps), g);
        }
        total *= 2.0 * double(kPi) * (2.0 / steps) / 3.0;
        CHECK(std::abs(total - 1.0) < 1e-4);
        const Vec3 travel = glm::normalize(Vec3(0.3f, -0.5f, 0.8f));
        Rng rng(17);
        for (int i = 0; i < samples; i++) {
            const Vec3 direction = SampleHenyeyGreenstein(travel, g, rng.GetVec2());
            REQUIRE(std::abs(glm::length(direction) - 1.f) < 1e-4f);
            const float cosTheta = glm::dot(travel, direction);
            observed[std::min(size_t(bins) - 1, size_t((cosTheta + 1.f) * 0.5f * float(bins)))] += 1.0;
        }
        const ChiSquare chi = ComputeChiSquare(observed, expected);
        INFO("g " << g << ": chi2 " << chi.statistic << " dof " << chi.dof << " threshold " << chi.threshold);
        CHECK(chi.statistic < chi.threshold);
    }
    // The Bsdf at a medium point: f = sigma_s p, the sampled pdf is the evaluated one, and
    // both directions have one pdf (exact: one formula of one cosine).
    const Medium medium = MakeMedium(Vec3(0.2f), Vec3(0.6f, 0.4f, 0.2f), 0.5f);
    const Vec3 fix = glm::normalize(Vec3(-0.2f, 0.1f, 1.f));
    Bsdf bsdf;
    bsdf.SetupInMedium(fix, medium, Transport::kRadiance);
    REQUIRE(bsdf.IsValid());
    REQUIRE(bsdf.IsInMedium());
    CHECK_FALSE(bsdf.IsDelta());
    CHECK(std::abs(bsdf.ContinuationProb() - 0.75f) < 1e-6f);  // the largest albedo, 0.6 / 0.8
    Rng rng(5);
    for (int i = 0; i < 100; i++) {
        const std::optional<ScatterSample> sample = bsdf.Sample(rng.GetVec3());
        REQUIRE(sample);
        const BsdfEval eval = bsdf.Evaluate(sample->mDirection);
        CHECK(std::abs(eval.mDirPdfW - sample->mPdfW) <= 1e-5f * sample->mPdfW);
        CHECK(eval.mDirPdfW == eval.mRevPdfW);
        CHECK(eval.mCosThetaGen == 1.f);
        CHECK(glm::length(eval.mValue - medium.mSigmaS * eval.mDirPdfW) <= 1e-6f * glm::length(eval.mValue));
        Bsdf reverse;
        reverse.SetupInMedium(sample->mDirection, medium, Transport::kImportance);
        const BsdfEval back = reverse.Evaluate(fix);
        CHECK(glm::length(back.mValue - eval.mValue) <= 1e-5f * glm::length(eval.mValue));
    }
}

TEST_CASE("Nested media: each boundary's outside is the medium around its closed mesh, and the camera and lights find theirs", "[media]") {
    // A fog box [-2, 2]^3 (index-matched) holds an ink sphere (glass around ink) and a
    // clear glass ball; the scene medium fills the rest.
    Scene scene;
    scene.mName = "nested media";
    const int haze = scene.AddMedium(MakeMedium(Vec3(0.01f), Vec3(0.01f), 0.f, "haze"));
    const int fog = scene.AddMedium(MakeMedium(Vec3(0.1f), Vec3(0.2f), 0.3f, "fog"));
    const int ink = scene.AddMedium(MakeMedium(Vec3(1.f), Vec3(0.5f), -0.2f, "ink"));
    scene.mSceneMedium = haze;
    AddClosedBox(scene, Vec3(-2.f), Vec3(2.f), scene.AddMaterial(IndexMatched(fog)));
    Material inkGlass = GlassMaterial(1.33f);
    inkGlass.mMedium = ink;
    const int inkSphere = scene.AddSphere(Vec3(0.5f, 0.f, 0.f), 0.5f, scene.AddMaterial(inkGlass));
    const int clearBall = scene.AddSphere(Vec3(3.f, 0.f, 0.f), 0.5f, scene.AddMaterial(GlassMaterial(1.5f)));
    scene.AddPointLight(Vec3(-1.f, 1.f, 0.f), Vec3(1.f));   // in the fog
    scene.AddPointLight(Vec3(0.5f, 0.1f, 0.f), Vec3(1.f));  // in the ink
    scene.AddPointLight(Vec3(5.f, 5.f, 5.f), Vec3(1.f));    // in the haze
    scene.mCamera.Setup(Vec3(0.5f, 0.2f, 0.1f), Vec3(1.f, 0.f, 0.f), Vec3(0.f, 1.f, 0.f), 40.f);
    scene.mCamera.SetResolution(4, 4);
    scene.Finalize();
    CHECK(scene.CameraMedium() == ink);
    CHECK(scene.LightMedium(0) == fog);
    CHECK(scene.LightMedium(1) == ink);
    CHECK(scene.LightMedium(2) == haze);
    // Leaving the ink sphere leads into the fog; leaving the clear ball into the haze;
    // entering the clear ball into empty space.
    const auto hitOf = [&](const Vec3& aOrigin, const Vec3& aDirection) { return scene.Intersect(Ray{aOrigin, aDirection}); };
    const SurfacePoint inkHit = hitOf(Vec3(0.5f, 0.f, 0.f), Vec3(1.f, 0.f, 0.f));
    REQUIRE(inkHit.mPrimitiveId == int(scene.mTriangles.size()) + inkSphere);
    CHECK(scene.MediumAfter(inkHit, Vec3(1.f, 0.f, 0.f), ink) == fog);
    CHECK(scene.MediumAfter(inkHit, Vec3(-1.f, 0.f, 0.f), ink) == ink);
    const SurfacePoint ballHit = hitOf(Vec3(2.2f, 0.f, 0.f), Vec3(1.f, 0.f, 0.f));
    REQUIRE(ballHit.mPrimitiveId == int(scene.mTriangles.size()) + clearBall);
    CHECK(scene.MediumAfter(ballHit, Vec3(1.f, 0.f, 0.f), haze) == -1);
    CHECK(scene.MediumAfter(ballHit, Vec3(-1.f, 0.f, 0.f), -1) == haze);
    // A diffuse surface changes no medium.
    CHECK(!scene.IsIndexMatchedBoundary(ballHit));
}

TEST_CASE("Bad media are refused by Finalize with a message that names the problem", "[media]") {
    const auto finalizeError = [](Scene aScene) -> std::string {
        try {
            aScene.Finalize();
        } catch (const Error& e) {
            return e.what();
        }
        return "";
    };
    const auto boxScene = [](const Medium& aMedium) {
        Scene scene;
        scene.mName = "bad";
        const int medium = scene.AddMedium(aMedium);
        AddClosedBox(scene, Vec3(-1.f), Vec3(1.f), scene.AddMaterial(IndexMatched(medium)));
        scene.AddPointLight(Vec3(0.f, 3.f, 0.f), Vec3(1.f));
        scene.mCamera.Setup(Vec3(0.f, 0.f, -5.f), Vec3(0.f, 0.f, 1.f), Vec3(0.f, 1.f, 0.f), 40.f);
        return scene;
    };
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    CHECK_THAT(finalizeError(boxScene(MakeMedium(Vec3(-0.1f), Vec3(0.f), 0.f))), Catch::Contains("negative or not finite"));
    CHECK_THAT(finalizeError(boxScene(MakeMedium(Vec3(0.f), Vec3(nan), 0.f))), Catch::Contains("negative or not finite"));
    CHECK_THAT(finalizeError(boxScene(MakeMedium(Vec3(inf), Vec3(0.f), 0.f))), Catch::Contains("negative or not finite"));
    CHECK_THAT(finalizeError(boxScene(MakeMedium(Vec3(0.f), Vec3(1.f), 1.f))), Catch::Contains("g outside (-1, 1)"));
    CHECK_THAT(finalizeError(boxScene(MakeMedium(Vec3(0.f), Vec3(1.f), nan))), Catch::Contains("g outside (-1, 1)"));
    Scene open = boxScene(MakeMedium(Vec3(0.1f), Vec3(0.1f), 0.f));
    open.mTriangles.pop_back();  // a hole in the box
    CHECK_THAT(finalizeError(open), Catch::Contains("is not closed"));
    Scene inward = boxScene(MakeMedium(Vec3(0.1f), Vec3(0.1f), 0.f));
    for (Triangle& t : inward.mTriangles) std::swap(t.mP1, t.mP2);
    CHECK_THAT(finalizeError(inward), Catch::Contains("wound inwards"));
    Scene opaque = boxScene(MakeMedium(Vec3(0.1f), Vec3(0.1f), 0.f));
    opaque.mMaterials[0].mDiffuseReflectance = Vec3(0.5f);
    CHECK_THAT(finalizeError(opaque), Catch::Contains("light could not enter it"));
    Scene missing = boxScene(MakeMedium(Vec3(0.1f), Vec3(0.1f), 0.f));
    missing.mMaterials[0].mMedium = 3;
    CHECK_THAT(finalizeError(missing), Catch::Contains("which does not exist"));
    Scene badSceneMedium = boxScene(MakeMedium(Vec3(0.1f), Vec3(0.1f), 0.f));
    badSceneMedium.mSceneMedium = 7;
    CHECK_THAT(finalizeError(badSceneMedium), Catch::Contains("does not exist"));
    // In a scene with media an open glass sheet has no inside: refused too.
    Scene sheet = boxScene(MakeMedium(Vec3(0.1f), Vec3(0.1f), 0.f));
    AddQuadFacing(sheet, Vec3(2.f, -1.f, -1.f), Vec3(2.f, 1.f, -1.f), Vec3(2.f, 1.f, 1.f), Vec3(2.f, -1.f, 1.f), Vec3(3.f, 0.f, 0.f),
                  sheet.AddMaterial(GlassMaterial(1.5f)));
    CHECK_THAT(finalizeError(sheet), Catch::Contains("is not closed"));
    // Without media the same sheet is fine, as before.
    Scene noMedia = sheet;
    noMedia.mMaterials[0] = Material();
    noMedia.mMaterials[0].mDiffuseReflectance = Vec3(0.5f);
    noMedia.mMedia.clear();
    CHECK(finalizeError(noMedia).empty());
    // Classic photon mapping has no volume photon map: it refuses a scene with media.
    Scene fine = boxScene(MakeMedium(Vec3(0.1f), Vec3(0.1f), 0.f));
    fine.mCamera.SetResolution(4, 4);
    fine.Finalize();
    for (Algorithm algorithm : {Algorithm::kPhotonMapping, Algorithm::kPhotonMappingFinalGather}) {
        RenderOptions options;
        options.mAlgorithm = algorithm;
        options.mProgress = false;
        CHECK_THROWS_WITH(Render(fine, options), Catch::Contains("does not render participating media"));
    }
}

TEST_CASE("A scattering medium in the emissive furnace keeps its radiance Le / (1 - a) in every estimator", "[media]") {
    // Tolerance: 4 standard errors of the image mean (pixels are independent samples of
    // one value), plus 1e-3 relative for the geodesic sphere's facets, as the furnaces
    // of test_integrators. Paths of up to 64 vertices: the rest, a^k with ~k/3 wall
    // bounces, is below 1e-6 of the answer. (Merging in the medium uses the default
    // medium radius, 3 % of the scene radius.)
    const float albedo = 0.5f, emitted = 1.f;
    const double expected = emitted / (1.0 - albedo);
    const Scene scene = MakeMediumFurnace(albedo, emitted, 1.f, 0.4f, 24, 24);
    for (Algorithm algorithm : kTransportEstimators) {
        const RenderResult result = RenderWith(scene, algorithm, 32, 17, 64);
        const MeanAndError stats = PixelStatistics(result.mImage);
        INFO(AlgorithmShortName(algorithm) << ": mean " << stats.mean << " +- " << stats.standardError << ", expected " << expected);
        CHECK(std::abs(stats.mean - expected) <= 4.0 * stats.standardError + 1e-3 * expected);
    }
}

namespace {

// Single scattering along one ray: the camera at the origin looks along +x (a 0.01 degree
// field of view) past a point light of intensity 2 at (1, 0.6, 0), in a chromatic
// absorbing scene medium; a black sphere of radius 50 closes the scene (T there is below
// 1e-10). Paths of 2 segments are single scattering:
//   L = int_0^inf T(t) sigma_s p(cos) I T(d) / d^2 dt,
// d the distance of the ray's point to the light, cos between the ray and the direction
// to the light.
struct SingleScattering {
    Vec3 mSigmaA{0.2f, 0.4f, 0.8f}, mSigmaS{0.6f, 0.5f, 0.3f};
    float mG = 0.4f;
    glm::dvec3 mLight{1.0, 0.6, 0.0};

    Scene MakeScene(int aResolution) const {
        Scene scene;
        scene.mName = "single scattering";
        scene.mSceneMedium = scene.AddMedium(MakeMedium(mSigmaA, mSigmaS, mG, "absorbing fog"));
        scene.AddSphere(Vec3(0.f), 50.f, scene.AddMaterial(Material()));
        scene.AddPointLight(Vec3(mLight), Vec3(2.f));
        scene.mCamera.Setup(Vec3(0.f), Vec3(1.f, 0.f, 0.f), Vec3(0.f, 1.f, 0.f), 0.01f);
        scene.mCamera.SetResolution(aResolution, aResolution);
        scene.Finalize();
        return scene;
    }
    // sigma_s p I T(d) / d^2 at aX, seen along the ray, in channel aC.
    double Scattered(const glm::dvec3& aX, int aC) const {
        const glm::dvec3 toLight = mLight - aX;
        const double d = glm::length(toLight);
        const double cosTheta = toLight.x / d;
        const double g = mG;
        const double phase = (1.0 - g * g) / (4.0 * 3.14159265358979 * std::pow(1.0 + g * g - 2.0 * g * cosTheta, 1.5));
        return double(mSigmaS[aC]) * phase * 2.0 * std::exp(-double(mSigmaA[aC] + mSigmaS[aC]) * d) / (d * d);
    }
    // int_0^50 T(t) aAt(t, channel) dt by Simpson's rule in aSteps steps, per channel.
    template <class At>
    Vec3 AlongTheRay(At&& aAt, int aSteps) const {
        Vec3 result(0.f);
        for (int c = 0; c < 3; c++) {
            const double st = double(mSigmaA[c] + mSigmaS[c]), h = 50.0 / aSteps;
            const auto f = [&](double aT) { return std::exp(-st * aT) * aAt(aT, c); };
            double sum = f(0.0) + f(50.0);
            for (int i = 1; i < aSteps; i++) sum += (i % 2 ? 4.0 : 2.0) * f(i * h);
            result[c] = float(sum * h / 3.0);
        }
        return result;
    }
    // The limit r -> 0 (converged to 1e-7 at 400,000 steps).
    Vec3 Expected() const {
        return AlongTheRay([&](double aT, int aC) { return Scattered(glm::dvec3(aT, 0.0, 0.0), aC); }, 400000);
    }
};

// The image means of 16 renders of seeds aSeed + 0..15 (paths of exactly 2 segments, one
// thread), per channel: means[c][r].
std::vector<std::vector<double>> SixteenRenders(const Scene& aScene, RenderOptions aOptions, uint64_t aSeed) {
    std::vector<std::vector<double>> means(3);
    for (int r = 0; r < 16; r++) {
        aOptions.mSeed = aSeed + uint64_t(r);
        aOptions.mMinPathLength = 2;
        aOptions.mMaxPathLength = 2;
        aOptions.mProgress = false;
        aOptions.mThreads = 1;
        const Image image = Render(aScene, aOptions).mImage;
        for (int c = 0; c < 3; c++) {
            double mean = 0.0;
            for (const Vec3& pixel : image.mPixels) mean += double(pixel[c]) / double(image.mPixels.size());
            means[size_t(c)].push_back(mean);
        }
    }
    return means;
}

} // namespace

TEST_CASE("Single scattering of a point light in a chromatic absorbing medium matches a 1D quadrature in every estimator", "[media]") {
    // SingleScattering's ray, at 1 x 1 pixel. Tolerance: 4 standard errors of the mean of
    // 16 renders of independent seeds (+ 1e-5 relative for the quadrature).
    // Estimators: pt, bpt and vcm (with a merging radius of 0.005, whose merges MIS then
    // weights low). Light tracing can hardly splat into a 0.01 degree view, and photon
    // points alone are hopeless along one ray in a thin medium (a ball of radius r holds
    // ~1e-3 photons at r = 0.025, and a larger one is biased near the light): they are
    // checked in the furnace above, in the medium room's per-length agreement
    // (test_transport.cpp) and by the MIS brute force (test_vcm_mis.cpp); camera beams
    // gather them below.
    const SingleScattering setup;
    const Scene scene = setup.MakeScene(1);
    const Vec3 expected = setup.Expected();
    for (Algorithm algorithm : {Algorithm::kPathTracing, Algorithm::kBidirectionalPathTracing, Algorithm::kVertexConnectionMerging}) {
        RenderOptions options;
        options.mAlgorithm = algorithm;
        options.mIterations = 4000;
        options.mMediumRadiusFactor = 1e-4f;
        const std::vector<std::vector<double>> means = SixteenRenders(scene, options, 900);
        for (int c = 0; c < 3; c++) {
            const MeanAndError e = MeanOf(means[size_t(c)]);
            INFO(AlgorithmShortName(algorithm) << " channel " << c << ": " << e.mean << " +- " << e.standardError << ", expected "
                                               << expected[c]);
            CHECK(std::abs(e.mean - expected[c]) <= 4.0 * e.standardError + 1e-5 * expected[c]);
        }
    }
}

TEST_CASE("The beam radiance estimate (pb2d) matches single scattering's quadrature along one ray, its kernel included", "[media]") {
    // SingleScattering's ray at 32 x 32 pixels (all of them the same ray to within 2e-4
    // rad; 1024 light sub-paths an iteration): the camera ray gathers the photon points of
    // one segment within r = 0.05 of it. The expected value is the estimator's own, kernel
    // included: the in-scattered radiance averaged over the disc of radius r across the ray
    // at each t, int_0^50 T(t) (1 / pi r^2) int_disc sigma_s p I T(d) / d^2 dA dt (x = (t,
    // rho cos phi, rho sin phi), d and p from x to the light), by Simpson's rule in t
    // (20,000 steps), 8-point Gauss-Legendre in rho and 16 angles (converged to 1e-6).
    // Printed beside it, the limit r -> 0: the kernel's bias, which this check does not
    // need to bound. Tolerance: 4 standard errors of the mean of 16 renders of independent
    // seeds, plus 1e-5 relative for the quadrature.
    const SingleScattering setup;
    const Scene scene = setup.MakeScene(32);
    const double radius = 0.05, pi = 3.14159265358979;
    const double gaussX[8] = {-0.9602898564975363, -0.7966664774136267, -0.5255324099163290, -0.1834346424956498,
                              0.1834346424956498, 0.5255324099163290, 0.7966664774136267, 0.9602898564975363};
    const double gaussW[8] = {0.1012285362903763, 0.2223810344533745, 0.3137066458778873, 0.3626837833783620,
                              0.3626837833783620, 0.3137066458778873, 0.2223810344533745, 0.1012285362903763};
    const auto onDisc = [&](double aT, int aC) {  // the average over the disc of radius r at t
        double sum = 0.0;
        for (int k = 0; k < 8; k++) {
            const double rho = 0.5 * radius * (1.0 + gaussX[k]);
            for (int j = 0; j < 16; j++) {
                const double phi = 2.0 * pi * (j + 0.5) / 16.0;
                sum += gaussW[k] * 0.5 * radius * rho * (2.0 * pi / 16.0) *
                       setup.Scattered(glm::dvec3(aT, rho * std::cos(phi), rho * std::sin(phi)), aC);
            }
        }
        return sum / (pi * radius * radius);
    };
    const Vec3 expected = setup.AlongTheRay(onDisc, 20000), limit = setup.Expected();
    RenderOptions options;
    options.mAlgorithm = Algorithm::kBeamRadianceEstimate;
    options.mIterations = 640;
    options.mMediumRadiusFactor = float(radius) / scene.GetSceneSphere().mRadius;
    options.mRadiusAlpha = 1.f;
    const std::vector<std::vector<double>> means = SixteenRenders(scene, options, 1900);
    for (int c = 0; c < 3; c++) {
        const MeanAndError e = MeanOf(means[size_t(c)]);
        std::printf("[media] pb2d single scattering, channel %d: %.6f +- %.6f, expected %.6f (r -> 0: %.6f)\n", c, e.mean,
                    e.standardError, double(expected[c]), double(limit[c]));
        INFO("pb2d channel " << c << ": " << e.mean << " +- " << e.standardError << ", expected " << expected[c]);
        CHECK(std::abs(e.mean - expected[c]) <= 4.0 * e.standardError + 1e-5 * expected[c]);
        CHECK(e.standardError < 0.015 * expected[c]);  // the check resolves a few percent
    }
}

TEST_CASE("Photon beams (bb1d) match single scattering's quadrature along one ray, within their kernel's bias", "[media]") {
    // SingleScattering's ray at 32 x 32 pixels: the camera ray gathers the photon beams of
    // every light sub-path's first segment (N_B = N_L = 1024) passing within r = 0.01 of
    // it. Expected: the limit r -> 0. The 1D kernel averages the in-scattered radiance f
    // over offsets in [-r, r] across the two lines, which changes it by r^2/6 |f''| +
    // O(r^4); with f ~ exp(-sigma_t d) / d^2 times the phase at d >= 0.6 from the light
    // (sigma_t <= 1, g = 0.4), |f''| / f < 40 along any direction (radial 6/d^2, 4
    // sigma_t/d, sigma_t^2, the phase's change ~8, their cross terms): at most 7 r^2 = 7e-4
    // of it. Tolerance: that, plus 4 standard errors of the mean of 16 renders.
    const SingleScattering setup;
    const Scene scene = setup.MakeScene(32);
    const double radius = 0.01;
    const Vec3 expected = setup.Expected();
    RenderOptions options;
    options.mAlgorithm = Algorithm::kPhotonBeams;
    options.mIterations = 320;
    options.mBeamRadiusFactor = float(radius) / scene.GetSceneSphere().mRadius;
    options.mRadiusAlpha = 1.f;
    const std::vector<std::vector<double>> means = SixteenRenders(scene, options, 2900);
    for (int c = 0; c < 3; c++) {
        const MeanAndError e = MeanOf(means[size_t(c)]);
        std::printf("[media] bb1d single scattering, channel %d: %.6f +- %.6f, expected %.6f\n", c, e.mean, e.standardError,
                    double(expected[c]));
        INFO("bb1d channel " << c << ": " << e.mean << " +- " << e.standardError << ", expected " << expected[c]);
        CHECK(std::abs(e.mean - expected[c]) <= 4.0 * e.standardError + 7.0 * radius * radius * expected[c]);
        CHECK(e.standardError < 0.015 * expected[c]);  // the check resolves a few percent
    }
}

TEST_CASE("Photon points, the beam radiance estimate and photon beams alone lose their bias as their radius shrinks (a radius sweep)", "[media]") {
    // F21's dense block lit by a spot, single scattering only (paths of 2 segments), 16 x 16.
    // A kernel of radius r averages the in-scattered light over a ball (pp3d), a disc
    // across the camera ray (pb2d) or offsets across two lines (bb1d); where the light
    // falls off within r -- at the block's lit face and where its kernel reaches out of
    // the block into empty space -- the average is too low, and the bias shrinks with r.
    // Each estimator alone (fixed radius, alpha = 1) at three radii, 4x apart for beams
    // and 2x for points (whose noise grows as 1 / r^3), against bpt. Per render the image
    // mean; each estimate is the mean of 16 renders of independent seeds, its SE from
    // their spread. Checks, with tolerances from those SEs: the largest radius's bias is
    // resolved (beyond 6 SE of estimator and reference: the sweep can see it), and each
    // smaller radius has a smaller bias, by more than 3 SE of the two estimates'
    // difference. Shown able to fail: bb1d's kernel 1 / (2 r N_B) made 10 % too bright
    // fails the last step (docs/testing.md has the measured biases). (The per-length
    // agreement at the default radii is the medium room's test in test_transport.cpp.)
    Scene scene = LoadGltfScene("../scenes/spot_in_dense_block.gltf");
    scene.mCamera.SetResolution(16, 16);
    scene.Finalize();
    const auto sixteen = [&](RenderOptions aOptions, uint64_t aSeed) {
        std::vector<double> means;
        for (int r = 0; r < 16; r++) {
            aOptions.mSeed = aSeed + uint64_t(r);
            aOptions.mMinPathLength = 2;
            aOptions.mMaxPathLength = 2;
            aOptions.mRadiusAlpha = 1.f;
            aOptions.mProgress = false;
            aOptions.mThreads = 1;
            const Image image = Render(scene, aOptions).mImage;
            double mean = 0.0;
            for (const Vec3& pixel : image.mPixels) mean += double(Average(pixel)) / double(image.mPixels.size());
            means.push_back(mean);
        }
        return MeanOf(means);
    };
    RenderOptions bpt;
    bpt.mAlgorithm = Algorithm::kBidirectionalPathTracing;
    bpt.mIterations = 512;
    const MeanAndError reference = sixteen(bpt, 5100);
    REQUIRE(reference.mean > 0.0);
    struct Sweep { Algorithm algorithm; bool beamRadius; float factors[3]; };
    const Sweep sweeps[] = {{Algorithm::kProgressivePhotonMapping, false, {0.04f, 0.02f, 0.01f}},
                            {Algorithm::kBeamRadianceEstimate, false, {0.04f, 0.01f, 0.0025f}},
                            {Algorithm::kPhotonBeams, true, {0.04f, 0.01f, 0.0025f}}};
    for (const Sweep& sweep : sweeps) {
        MeanAndError estimates[3];
        for (int i = 0; i < 3; i++) {
            RenderOptions options;
            options.mAlgorithm = sweep.algorithm;
            options.mIterations = 256 << i;  // the noise grows as r shrinks
            (sweep.beamRadius ? options.mBeamRadiusFactor : options.mMediumRadiusFactor) = sweep.factors[i];
            estimates[i] = sixteen(options, 5200 + 100 * uint64_t(i));
            std::printf("[media] radius sweep %s r = %g of the scene radius: bias %+.2f %% +- %.2f %%\n",
                        AlgorithmShortName(sweep.algorithm), double(sweep.factors[i]),
                        100.0 * (estimates[i].mean / reference.mean - 1.0), 100.0 * estimates[i].standardError / reference.mean);
        }
        INFO(AlgorithmShortName(sweep.algorithm) << ": means " << estimates[0].mean << ", " << estimates[1].mean << ", "
                                                 << estimates[2].mean << " against bpt's " << reference.mean);
        const double firstBias = estimates[0].mean - reference.mean;
        CHECK(std::abs(firstBias) > 6.0 * std::hypot(estimates[0].standardError, reference.standardError));
        for (int i = 0; i < 2; i++) {
            const double larger = std::abs(estimates[i].mean - reference.mean), smaller = std::abs(estimates[i + 1].mean - reference.mean);
            CHECK(larger - smaller > 3.0 * std::hypot(estimates[i].standardError, estimates[i + 1].standardError));
        }
    }
}

TEST_CASE("A medium that neither absorbs nor scatters renders as empty space, within noise", "[media]") {
    // The glossy room with an index-matched ball of a clear medium at its centre: paths
    // step through its boundary (no random number is drawn in a clear medium), so the
    // images differ only where rays start again from the boundary, by the ray epsilon.
    // Tolerance: 4 SE of the difference of the two images' per-pixel means.
    Scene plain = MakeGlossyRoom(16);
    Scene clear = plain;
    const int medium = clear.AddMedium(MakeMedium(Vec3(0.f), Vec3(0.f), 0.f, "clear"));
    clear.AddSphere(Vec3(-0.2f, 0.3f, 0.9f), 0.4f, clear.AddMaterial(IndexMatched(medium)));
    clear.Finalize();
    REQUIRE(clear.HasMedia());
    for (Algorithm algorithm : {Algorithm::kPathTracing, Algorithm::kBidirectionalPathTracing, Algorithm::kVertexConnectionMerging}) {
        const Image a = RenderWith(plain, algorithm, 64, 3).mImage, b = RenderWith(clear, algorithm, 64, 3).mImage;
        std::vector<double> differences;
        for (size_t i = 0; i < a.mPixels.size(); i++) differences.push_back(Average(b.mPixels[i]) - Average(a.mPixels[i]));
        const MeanAndError d = MeanOf(differences);
        INFO(AlgorithmShortName(algorithm) << ": difference " << d.mean << " +- " << d.standardError);
        CHECK(std::abs(d.mean) <= 4.0 * d.standardError + 1e-6);
    }
}

TEST_CASE("An integrator that does not say it traces media refuses a scene with media, and media changed after Finalize are an error", "[media]") {
    Scene scene = MakeMediumFurnace(0.5f, 1.f, 1.f, 0.f, 4, 4);
    RenderOptions options;
    options.mProgress = false;
    // A user's integrator (here the built-in path tracer's class under another name)
    // has mHandlesMedia false unless it sets it.
    Integrator mine = MakeIntegrator<PathTracer>("mine", "a path tracer that never heard of media");
    CHECK_THROWS_WITH(Render(scene, options, mine), Catch::Contains("participating media"));
    mine.mHandlesMedia = true;
    CHECK_NOTHROW(Render(scene, options, mine));
    scene.mMedia[0].mSigmaS = Vec3(2.f);
    CHECK_THROWS_WITH(Render(scene, options), Catch::Contains("changed after Finalize()"));
    scene.Finalize();
    CHECK_NOTHROW(Render(scene, options));
}

TEST_CASE("UPBP: without its beam techniques it is bpt or vcm bit for bit; with them its technique layers sum to its image", "[media][upbp]") {
    // The glass sphere in fog (a caustic in the medium, surfaces and glass): --techniques
    // bpt is bpt, bpt,surf,pp3d is vcm (the beam merges' eta is 0, and nothing else
    // changes), exactly, pixel by pixel. With every technique the layers (unidirectional,
    // nee, light tracing, connection, merging, merging in media, pb2d, bb1d) partition the
    // contributions, so they sum to the image within float rounding (1e-5 relative).
    Scene scene = LoadGltfScene("../scenes/fog_caustic_box.gltf");
    scene.mCamera.SetResolution(24, 24);
    scene.Finalize();
    RenderOptions options;
    options.mIterations = 2;
    options.mThreads = 1;
    options.mProgress = false;
    const auto render = [&](Algorithm aAlgorithm, uint32_t aTechniques) {
        RenderOptions o = options;
        o.mAlgorithm = aAlgorithm;
        o.mUpbpTechniques = aTechniques;
        return Render(scene, o);
    };
    const std::pair<Algorithm, uint32_t> pairs[] = {{Algorithm::kBidirectionalPathTracing, kUpbpBpt},
                                                    {Algorithm::kVertexConnectionMerging, kUpbpBpt | kUpbpSurface | kUpbpPp3d}};
    for (const auto& [algorithm, techniques] : pairs) {
        const Image expected = render(algorithm, kUpbpAll).mImage;
        const Image upbp = render(Algorithm::kUpbp, techniques).mImage;
        int different = 0;
        for (int y = 0; y < 24; y++)
            for (int x = 0; x < 24; x++) different += expected.At(x, y) != upbp.At(x, y);
        INFO(AlgorithmShortName(algorithm) << ": " << different << " of 576 pixels differ");
        CHECK(different == 0);
    }
    options.mTechniqueLayers = true;
    const RenderResult all = render(Algorithm::kUpbp, kUpbpAll);
    std::vector<std::string> names;
    for (const auto& layer : all.mLayers) names.push_back(layer.first);
    for (const char* name : {"pb2d", "bb1d", "merging_in_media", "connection"})
        CHECK(std::find(names.begin(), names.end(), name) != names.end());
    double worst = 0.0;
    for (int y = 0; y < 24; y++)
        for (int x = 0; x < 24; x++) {
            Vec3 sum(0.f);
            for (const auto& layer : all.mLayers) sum += layer.second.At(x, y);
            const Vec3 pixel = all.mImage.At(x, y);
            for (int c = 0; c < 3; c++) worst = std::max(worst, std::abs(double(sum[c]) - double(pixel[c])) / (std::abs(double(pixel[c])) + 1e-6));
        }
    INFO("largest relative difference between the layers' sum and the image: " << worst);
    CHECK(worst <= 1e-5);
}

TEST_CASE("UPBP keeps the medium furnace's radiance Le / (1 - a) with every technique and with beams alone beside bpt", "[media][upbp]") {
    // As the furnace test above (4 standard errors of the image mean + 1e-3 relative).
    const float albedo = 0.5f, emitted = 1.f;
    const double expected = emitted / (1.0 - albedo);
    const Scene scene = MakeMediumFurnace(albedo, emitted, 1.f, 0.4f, 24, 24);
    for (uint32_t techniques : {uint32_t(kUpbpAll), uint32_t(kUpbpBpt | kUpbpPb2d | kUpbpBb1d)}) {
        RenderOptions options;
        options.mAlgorithm = Algorithm::kUpbp;
        options.mUpbpTechniques = techniques;
        options.mIterations = 16;
        options.mSeed = 19;
        options.mMaxPathLength = 64;
        options.mProgress = false;
        const MeanAndError stats = PixelStatistics(Render(scene, options).mImage);
        std::printf("[media] upbp furnace, techniques %u: mean %.5f +- %.5f, expected %.5f\n", techniques, stats.mean, stats.standardError, expected);
        INFO("techniques " << techniques << ": mean " << stats.mean << " +- " << stats.standardError << ", expected " << expected);
        CHECK(std::abs(stats.mean - expected) <= 4.0 * stats.standardError + 1e-3 * expected);
    }
}

TEST_CASE("UPBP renders finite images where a medium fills all space under the sun and a background", "[media][upbp]") {
    // Cornell 0 (the sun through an open box) and 3 (a background) filled with fog: next-event
    // estimation towards a light at infinity crosses an infinite medium, where the beam
    // ratio's P and p both underflow to 0 (this once made upbp's weights NaN).
    for (int cornell : {0, 3}) {
        Scene scene = testutil::LoadCornell(cornell, 16, 16);
        Medium fog;
        fog.mName = "fog";
        fog.mSigmaA = Vec3(0.02f);
        fog.mSigmaS = Vec3(0.2f);
        fog.mG = 0.3f;
        scene.mSceneMedium = scene.AddMedium(fog);
        scene.Finalize();
        RenderOptions options;
        options.mAlgorithm = Algorithm::kUpbp;
        options.mIterations = 2;
        options.mThreads = 1;
        options.mProgress = false;
        const Image image = Render(scene, options).mImage;
        int bad = 0;
        for (const Vec3& p : image.mPixels) bad += !(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z) && p.x >= 0.f);
        INFO("Cornell " << cornell << " in fog: " << bad << " pixels not finite or negative");
        CHECK(bad == 0);
    }
}
