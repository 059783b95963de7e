// [mis] The recursive VCM MIS weights (namespace VcmMis, driven with exactly the arguments
// class VertexCM passes, and the weights VertexCM itself used on its recorded paths) against
// a brute-force sum over all techniques of each path: the harness (path generation, the
// brute force, the replayed recursion, the path space conventions) is mis_brute_force.hpp.
#include "mis_brute_force.hpp"

#include <catch2/catch.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

using namespace smallvcm;
using namespace misbf;

TEST_CASE("The path generator yields at least 1000 valid paths per Cornell scene, of lengths 1 to 8, through mirrors and glass", "[mis]") {
    const auto start = std::chrono::steady_clock::now();
    for (int s = 0; s < kSceneCount; s++) {
        const ScenePaths& scenePaths = CornellPaths(s);
        const GeneratorStats& stats = scenePaths.stats;
        std::ostringstream lengths;
        for (int k = 1; k <= kMaxSegments; k++) lengths << " k" << k << ":" << stats.byLength[k];
        std::printf("[mis] scene %-14s %5zu paths (%d walks, %d rejected);%s; %d closed by a light sample; "
                    "%d with specular vertices (%d reflections, %d refractions); smallest |cos| %.1e\n",
                    kSceneNames[s], scenePaths.paths.size(), stats.attempts, stats.rejected, lengths.str().c_str(),
                    stats.closedByLightSample, stats.withSpecular, stats.reflectVertices, stats.refractVertices,
                    stats.minCosine);
        INFO("scene " << kSceneNames[s]);
        CHECK(scenePaths.paths.size() >= 1000);
        for (int k = 2; k <= kMaxSegments; k++) CHECK(stats.byLength[k] > 0);
        // The camera sees the area lights of scenes 1 and 4 directly: the only k = 1 paths.
        if (s == 1 || s == 4) CHECK(stats.byLength[1] > 0);
        CHECK(stats.withSpecular >= 50);
        CHECK(stats.reflectVertices > 0);
        if (s != 1) CHECK(stats.refractVertices > 0);  // scene 1 has no glass
        CHECK(stats.closedByLightSample > 0);
        if (s != 0 && s != 2) CHECK(stats.closedByLightSample < int(scenePaths.paths.size()));  // some hit an emitter
    }
    std::printf("[mis] path generation took %.2f s\n",
                std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
}

TEST_CASE("At a specular vertex the light and the camera sub-path pick the specular component with the same probability", "[mis]") {
    int vertices = 0;
    double maxDifference = 0.0, maxDirectionError = 0.0;
    for (int s = 0; s < kSceneCount; s++) {
        const Scene& scene = CornellScene(s);
        for (const FullPath& path : CornellPaths(s).paths) {
            PathBsdfs bsdfs;
            REQUIRE(SetupBsdfs(scene, path, bsdfs));
            for (int i = 1; i < path.K(); i++) {
                if (!path.Specular(i)) continue;
                vertices++;
                Vec3 lightDirection, cameraDirection;
                const float forward = SpecularSelectionProbability(bsdfs.light[size_t(i)], path.event[size_t(i)], &lightDirection);
                const float reverse = SpecularSelectionProbability(bsdfs.camera[size_t(i)], path.event[size_t(i)], &cameraDirection);
                INFO("scene " << kSceneNames[s] << ", " << DescribePath(scene, path) << ", vertex " << i);
                REQUIRE(forward > 0.f);
                REQUIRE(reverse > 0.f);
                // Equal in exact arithmetic (reflection: the same |cos|; refraction: Fresnel's
                // reflectance is the same from both sides). In float the two sides evaluate
                // different expressions (1/ior vs ior, cos inside vs outside): ~1e-5 relative.
                maxDifference = std::max(maxDifference, std::abs(double(forward) - double(reverse)) / double(reverse));
                CHECK(forward == Approx(reverse).epsilon(1e-4));
                // Each sub-path's specular direction leads to the other's previous vertex.
                maxDirectionError = std::max({maxDirectionError, double(glm::length(lightDirection - Dir(path, i, i + 1))),
                                              double(glm::length(cameraDirection - Dir(path, i, i - 1)))});
                CHECK(glm::length(lightDirection - Dir(path, i, i + 1)) < 1e-3f);
                CHECK(glm::length(cameraDirection - Dir(path, i, i - 1)) < 1e-3f);
            }
        }
    }
    std::printf("[mis] %d specular vertices: max |p_forward - p_reverse| / p_reverse = %.3g, max direction mismatch %.3g\n",
                vertices, maxDifference, maxDirectionError);
    CHECK(vertices > 500);
}

TEST_CASE("The recursive VCM, BPT and BPM weights equal a brute-force sum over all techniques of the same path", "[mis]") {
    const auto start = std::chrono::steady_clock::now();
    double overallMax = 0.0;
    for (int s = 0; s < kSceneCount; s++) {
        for (const MisCase& misCase : kMisCases) {
            const Comparison c = CompareScene(s, misCase);
            overallMax = std::max(overallMax, c.maxRelError);
            std::printf("[mis] scene %-14s %-18s %5d paths %6d techniques  max rel. error %.2e  failures %d\n",
                        kSceneNames[s], misCase.name, c.paths, c.techniques, c.maxRelError, c.failures);
            INFO("scene " << kSceneNames[s] << ", " << misCase.name << ": " << c.paths << " paths, " << c.techniques
                          << " techniques, " << c.failures << " disagree; largest relative error: " << c.worst);
            CHECK(c.paths >= 1000);
            CHECK(c.outOfRange == 0);
            CHECK(c.failures == 0);
        }
    }
    std::printf("[mis] largest relative error overall %.2e; comparison took %.2f s\n", overallMax,
                std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
}

TEST_CASE("The recursive MIS weights of all techniques of a path sum to one", "[mis]") {
    for (int s = 0; s < kSceneCount; s++) {
        for (const MisCase& misCase : kMisCases) {
            const Comparison c = CompareScene(s, misCase);
            INFO("scene " << kSceneNames[s] << ", " << misCase.name << ": largest |sum - 1| = " << c.maxSumError);
            CHECK(c.maxSumError <= 1e-4);
        }
    }
}
namespace {

struct RecordedComparison {
    int records = 0, compared = 0, unusable = 0, failures = 0, mergesAcrossEdges = 0;
    int byTechnique[5] = {};
    int byLength[kMaxSegments + 1] = {};  // compared paths of 1 .. kMaxSegments segments
    double maxRelError = 0.0;
    std::string worst;
};

// Renders one iteration of aCase's algorithm on Cornell scene aSceneIndex at aSize x aSize
// with the path records on, and compares each recorded weight with the brute force.
// Scene 5 is scene 3 under an environment map (mis_brute_force.hpp). Scene 6 is scene 1
// (area light, mirror ceiling) with a point light added near the centre of the box: two
// lights of two kinds, each picked with probability 1/2. Scenes 7-9 are test_util's
// rooms: Phong surfaces under a sphere light and a two-sided panel; a spot light; the
// camera inside a glass ball.
constexpr int kRecordingSceneCount = kSceneCount + 4;
const char* const kRecordingSceneNames[kRecordingSceneCount] = {
    "0 sun", "1 mirror+area", "2 point", "3 background", "4 default", "5 envmap", "6 area+point", "7 phong room",
    "8 spot room", "9 in glass"};

Scene RecordingScene(int aSceneIndex, int aSize) {
    if (aSceneIndex == 5) return MakeCornellUnderEnvironment(aSize, aSize);
    if (aSceneIndex < kSceneCount) return testutil::LoadCornell(aSceneIndex, aSize, aSize);
    if (aSceneIndex == 7) return testutil::MakeGlossyRoom(aSize);
    if (aSceneIndex == 8) return testutil::MakeSpotRoom(aSize);
    if (aSceneIndex == 9) return testutil::MakeCameraInGlassRoom(aSize);
    Scene scene = testutil::LoadCornell(1, aSize, aSize);
    scene.AddPointLight(scene.GetSceneSphere().mCenter + Vec3(0.1f, 0.2f, 0.3f) * scene.GetSceneSphere().mRadius, Vec3(3.f));
    scene.Finalize();
    return scene;
}

RecordedComparison CompareRecordedWeights(int aSceneIndex, const MisCase& aCase, int aSize, uint64_t aSeed,
                                          SamplerType aSampler = SamplerType::kIndependent) {
    const Scene scene = RecordingScene(aSceneIndex, aSize);
    RenderOptions options;
    options.mAlgorithm = aCase.useVC && aCase.useVM ? Algorithm::kVertexConnectionMerging
                         : aCase.useVC             ? Algorithm::kBidirectionalPathTracing
                                                   : Algorithm::kBidirectionalPhotonMapping;
    options.mMisHeuristic = aCase.heuristic;
    options.mRadiusFactor = aCase.radiusFactor;
    options.mMaxPathLength = kMaxSegments;
    options.mProgress = false;
    options.mSampler = aSampler;
    VertexCM renderer(scene, options);
    std::vector<VertexCM::PathRecord> records;
    renderer.SetPathRecords(&records);
    Sampler sampler = IterationSampler(options.mSampler, aSeed, 0);
    renderer.RunIteration(0, sampler);

    // The constants of the path space, from the scene and the options alone: N_L light
    // sub-paths (one per pixel) and the radius of iteration 0, r_0 = factor x scene radius.
    const double lightPathCount = double(aSize) * double(aSize);
    const double radius = double(aCase.radiusFactor) * double(scene.GetSceneSphere().mRadius);
    const double eta = 3.14159265358979323846 * radius * radius * lightPathCount;
    RecordedComparison result;
    for (const VertexCM::PathRecord& record : records) {
        result.records++;
        FullPath path;
        Technique technique{Kind::kCameraHitsLight, 0};
        PathBsdfs bsdfs;
        BruteForcePdfs pdfs;
        if (record.mTechnique == VertexCM::kMerging && record.mLightVertexCount >= 1 &&
            size_t(record.mLightVertexCount) < record.mVertices.size() &&
            record.mVertices[size_t(record.mLightVertexCount) - 1].mMaterialId !=
                record.mVertices[size_t(record.mLightVertexCount)].mMaterialId) {
            result.mergesAcrossEdges++;  // two surfaces within r (a corner): no single path to weigh
            continue;
        }
        if (!PathFromRecord(scene, record, path, technique) || !SetupBsdfs(scene, path, bsdfs) ||
            !ComputeBruteForcePdfs(scene, path, bsdfs, pdfs)) {
            result.unusable++;
            continue;
        }
        const std::vector<Technique> techniques = Techniques(path, aCase.useVC, aCase.useVM);
        size_t index = techniques.size();
        for (size_t t = 0; t < techniques.size(); t++)
            if (techniques[t].kind == technique.kind && techniques[t].index == technique.index) index = t;
        const double w = double(record.mWeight);
        double expected = -1.0;
        if (index < techniques.size())
            expected = BruteForceWeights(pdfs, techniques, path.K(), aCase.heuristic, lightPathCount, eta)[index];
        result.compared++;
        result.byTechnique[int(technique.kind)]++;
        if (path.K() <= kMaxSegments) result.byLength[path.K()]++;
        const double diff = std::abs(w - expected);
        const double relError = expected > 0.0 ? diff / expected : (diff > 0.0 ? 1.0 : 0.0);
        const bool ok = expected >= 0.0 && diff <= kRecordedRelTolerance * expected + kAbsTolerance;
        if (!ok) result.failures++;
        if (relError > result.maxRelError || (!ok && result.worst.empty())) {
            result.maxRelError = std::max(result.maxRelError, relError);
            std::ostringstream out;
            out << TechniqueName(technique) << ": the renderer used " << w << ", brute force " << expected
                << " (rel. error " << relError << ") on " << DescribePath(scene, path);
            result.worst = out.str();
        }
    }
    return result;
}

} // namespace

TEST_CASE("The weights VertexCM gives its own paths equal a brute-force sum over all techniques of those paths", "[mis]") {
    // Every Cornell scene (sun, area + mirror ceiling, point, background, default: mirrors,
    // glass, glossy floor), one with two lights (the pick probability), and test_util's
    // rooms (Phong, a sphere light, a two-sided emitter, a spot light, the camera inside
    // glass): every light type and material. VCM, BPT and BPM with both heuristics, one
    // iteration at 24 x 24 with paths of up to kMaxSegments segments; every technique,
    // merges included (FullPath::mergeAt). The radius x10 cases merge 100 times as often.
    const MisCase cases[] = {kMisCases[0], kMisCases[1], kMisCases[2], kMisCases[3], kMisCases[4], kMisCases[5], kMisCases[6],
                             {"vcm power r x10", MisHeuristic::kPower, true, true, 0.03f},
                             {"bpm power r x10", MisHeuristic::kPower, false, true, 0.03f}};
    int total = 0, merges = 0;
    int byLength[kMaxSegments + 1] = {};
    for (int s = 0; s < kRecordingSceneCount; s++) {
        for (const MisCase& misCase : cases) {
            const RecordedComparison c = CompareRecordedWeights(s, misCase, 24, 11u + uint64_t(s));
            total += c.compared;
            merges += c.byTechnique[int(Kind::kMerge)];
            for (int k = 1; k <= kMaxSegments; k++) byLength[k] += c.byLength[k];
            std::printf("[mis] recorded: scene %-14s %-12s %5d paths (hit %d, nee %d, connection %d, lt %d, merge %d; %d merges across edges), %d unusable, "
                        "max rel. error %.2e, %d failures\n", kRecordingSceneNames[s], misCase.name,
                        c.compared, c.byTechnique[int(Kind::kCameraHitsLight)], c.byTechnique[int(Kind::kNextEvent)],
                        c.byTechnique[int(Kind::kConnection)], c.byTechnique[int(Kind::kLightTracing)],
                        c.byTechnique[int(Kind::kMerge)], c.mergesAcrossEdges, c.unusable, c.maxRelError, c.failures);
            INFO("scene " << kRecordingSceneNames[s] << ", " << misCase.name << ": " << c.compared << " recorded paths, "
                          << c.failures << " disagree; largest relative error: " << c.worst);
            CHECK(c.failures == 0);
            // A record the brute force cannot read (a sampled light point hidden from
            // its probe ray by float rounding at an edge, a merge across an edge) must
            // stay rare.
            CHECK(c.unusable <= c.records / 100);
            // Merges across edges are left out; they must stay a minority of the merges.
            CHECK(c.mergesAcrossEdges <= c.byTechnique[int(Kind::kMerge)] / 4);
        }
    }
    std::printf("[mis] recorded: %d paths, %d of them merges\n", total, merges);
    INFO("paths by length 1..6: " << byLength[1] << " " << byLength[2] << " " << byLength[3] << " " << byLength[4]
                                  << " " << byLength[5] << " " << byLength[6] << "; merges " << merges);
    CHECK(total >= 10000);
    CHECK(merges >= 1000);
    // Length 1 (the camera sees a light) has one technique, weight 1: a few suffice.
    CHECK(byLength[1] >= 10);
    for (int k = 2; k <= 6; k++) CHECK(byLength[k] >= 1000);
}

namespace {

// Scenes with participating media for the recorded weights ([SECTION] Participating
// media): 10 is Cornell scene 4 (mirror and glass balls, area light) filled with a
// chromatic, forward-scattering fog; 11 is scene 4 with a dense, chromatic,
// back-scattering medium inside the glass ball and empty space around it (medium points
// reached only through refraction: merges, no connections); 12 is scene 2 (point light)
// in a thin grey fog with a ball of chromatic medium behind an index-matched boundary
// in the middle of the box, so that segments cross boundaries between two media; 13 is
// scene 3 (open towards a background light) with that ball and no fog, so that camera
// paths leave the ball and the scene: the background found through a medium.
constexpr int kMediaSceneCount = 4;
const char* const kMediaSceneNames[kMediaSceneCount] = {"10 fog", "11 medium in glass", "12 index-matched ball",
                                                        "13 ball, background"};

Scene MediaScene(int aIndex, int aSize) {
    Scene scene = testutil::LoadCornell(aIndex == 2 ? 2 : aIndex == 3 ? 3 : 4, aSize, aSize);
    Medium medium;
    if (aIndex == 0) {
        medium.mName = "chromatic fog";
        medium.mSigmaA = Vec3(0.02f, 0.04f, 0.06f);
        medium.mSigmaS = Vec3(0.12f, 0.22f, 0.32f);
        medium.mG = 0.5f;
        scene.mSceneMedium = scene.AddMedium(medium);
    } else if (aIndex == 1) {
        medium.mName = "dense inside glass";
        medium.mSigmaA = Vec3(0.1f, 0.2f, 0.3f);
        medium.mSigmaS = Vec3(2.0f, 1.4f, 0.8f);
        medium.mG = -0.3f;
        const int id = scene.AddMedium(medium);
        for (Material& material : scene.mMaterials)
            if (material.mIor > 0.f) material.mMedium = id;
    } else {
        if (aIndex == 2) {
            Medium fog;
            fog.mName = "thin grey fog";
            fog.mSigmaA = Vec3(0.02f);
            fog.mSigmaS = Vec3(0.12f);
            scene.mSceneMedium = scene.AddMedium(fog);
        }
        medium.mName = "chromatic ball";
        medium.mSigmaA = Vec3(0.05f, 0.1f, 0.15f);
        medium.mSigmaS = Vec3(0.9f, 0.6f, 0.3f);
        medium.mG = 0.3f;
        Material boundary;
        boundary.mName = "index-matched boundary";
        boundary.mDiffuseReflectance = Vec3(0.f);
        boundary.mMedium = scene.AddMedium(medium);
        scene.AddSphere(Vec3(0.f, 0.2f, 0.35f), 0.55f, scene.AddMaterial(boundary));
    }
    scene.Finalize();
    return scene;
}

struct MediaComparison {
    int records = 0, compared = 0, unusable = 0, failures = 0, acrossEdges = 0;
    int byTechnique[7] = {};
    int withMediumVertex = 0, mediumMerges = 0, crossingPaths = 0;
    int replayed = 0, notReplayed = 0, replayFailures = 0;
    double maxRelError = 0.0, maxReplayRelError = 0.0, maxSumError = 0.0;
    std::string worst, worstReplay;
};

// One iteration of aCase's algorithm on media scene aSceneIndex with the path records on
// (merging in media at radius aMediumRadiusFactor x scene radius); each recorded weight
// against the brute force (kRecordedRelTolerance), and every technique of the same path
// replayed (RecursiveWeights with VertexCM's media arguments: a merge's path taken
// through the light's end of the merged vertex) against the brute force (kRelTolerance)
// with the replayed weights of all techniques summing to one.
// With aUpbp (a set of UpbpTechnique bits) the algorithm is upbp with those techniques
// instead (aCase's heuristic and radius; photon beams of radius aBeamRadiusFactor from
// every light sub-path), and the replay is left out (RecursiveWeights knows no beams).
MediaComparison CompareRecordedWeightsInMedia(int aSceneIndex, const MisCase& aCase, float aMediumRadiusFactor, int aSize,
                                              uint64_t aSeed, uint32_t aUpbp = 0, float aBeamRadiusFactor = 0.f) {
    const Scene scene = MediaScene(aSceneIndex, aSize);
    RenderOptions options;
    options.mAlgorithm = aCase.useVC && aCase.useVM ? Algorithm::kVertexConnectionMerging
                         : aCase.useVC             ? Algorithm::kBidirectionalPathTracing
                                                   : Algorithm::kBidirectionalPhotonMapping;
    if (aUpbp) {
        options.mAlgorithm = Algorithm::kUpbp;
        options.mUpbpTechniques = aUpbp;
        options.mBeamRadiusFactor = aBeamRadiusFactor;
        options.mBeamPaths = aSize * aSize;
    }
    options.mMisHeuristic = aCase.heuristic;
    options.mRadiusFactor = aCase.radiusFactor;
    options.mMediumRadiusFactor = aMediumRadiusFactor;
    options.mMaxPathLength = kMaxSegments;
    options.mProgress = false;
    options.mSampler = SamplerType::kIndependent;
    VertexCM renderer(scene, options);
    std::vector<VertexCM::PathRecord> records;
    renderer.SetPathRecords(&records);
    Sampler sampler = IterationSampler(options.mSampler, aSeed, 0);
    renderer.RunIteration(0, sampler);

    // The path space's constants from the scene and the options: N_L, r_0 and the radius
    // in media r_m,0 = medium factor x scene radius; the replay's constants as VertexCM
    // forms them (in float).
    const double pi = 3.14159265358979323846;
    const double lightPathCount = double(aSize) * double(aSize);
    const double sceneRadius = double(scene.GetSceneSphere().mRadius);
    const double radius = double(aCase.radiusFactor) * sceneRadius, mediumRadius = double(aMediumRadiusFactor) * sceneRadius;
    const double eta = pi * radius * radius * lightPathCount;
    const double etaMedium = 4.0 / 3.0 * pi * mediumRadius * mediumRadius * mediumRadius * lightPathCount;
    const double beamRadius = double(aBeamRadiusFactor) * sceneRadius;
    const double etaPb2d = pi * mediumRadius * mediumRadius * lightPathCount, etaBb1d = 2.0 * beamRadius * lightPathCount;
    const float floatRadius = aCase.radiusFactor * scene.GetSceneSphere().mRadius;
    const VcmMisConstants mis = VcmMisConstants::Make(aCase.heuristic, aCase.useVC, aCase.useVM, float(aSize * aSize), floatRadius);
    const VcmMisConstants misMedium = mis.ForMedium(floatRadius * (aMediumRadiusFactor / aCase.radiusFactor));

    MediaComparison result;
    for (const VertexCM::PathRecord& record : records) {
        result.records++;
        const std::vector<VertexCM::PathVertex>& v = record.mVertices;
        const size_t s = size_t(record.mLightVertexCount);
        const bool merge = record.mTechnique == VertexCM::kMerging || record.mTechnique == VertexCM::kPointBeamMerging ||
                           record.mTechnique == VertexCM::kBeamBeamMerging;
        if (merge && s >= 1 && s < v.size() && (v[s - 1].mMaterialId != v[s].mMaterialId || v[s - 1].mMedium != v[s].mMedium)) {
            result.acrossEdges++;  // two surfaces, or two media, within the radius: no single path
            continue;
        }
        FullPath path;
        Technique technique{Kind::kCameraHitsLight, 0};
        PathBsdfs bsdfs;
        BruteForcePdfs pdfs;
        if (!PathFromRecord(scene, record, path, technique) || !SetupBsdfs(scene, path, bsdfs) ||
            !ComputeBruteForcePdfs(scene, path, bsdfs, pdfs)) {
            result.unusable++;
            continue;
        }
        const std::vector<Technique> techniques = aUpbp ? UpbpTechniques(path, aUpbp) : Techniques(path, aCase.useVC, aCase.useVM);
        size_t index = techniques.size();
        for (size_t t = 0; t < techniques.size(); t++)
            if (techniques[t].kind == technique.kind && techniques[t].index == technique.index) index = t;
        const double w = double(record.mWeight);
        double expected = -1.0;
        if (index < techniques.size())
            expected = BruteForceWeights(pdfs, techniques, path.K(), aCase.heuristic, lightPathCount, eta, etaMedium, etaPb2d, etaBb1d)[index];
        result.compared++;
        result.byTechnique[int(technique.kind)]++;
        bool anyMedium = false;
        for (int i = 1; i < path.K(); i++) anyMedium = anyMedium || path.InMedium(i);
        if (anyMedium) result.withMediumVertex++;
        if (technique.kind != Kind::kCameraHitsLight && technique.kind >= Kind::kMerge && path.InMedium(technique.index)) result.mediumMerges++;
        {
            std::vector<double> f, r;
            int crossing = 0;
            if (SegmentFlights(scene, path, f, r, &crossing) && crossing > 0) result.crossingPaths++;
        }
        const double diff = std::abs(w - expected);
        const double relError = expected > 0.0 ? diff / expected : (diff > 0.0 ? 1.0 : 0.0);
        const bool ok = expected >= 0.0 && diff <= kRecordedRelTolerance * expected + kAbsTolerance;
        if (!ok) result.failures++;
        if (relError > result.maxRelError || (!ok && result.worst.empty())) {
            result.maxRelError = std::max(result.maxRelError, relError);
            std::ostringstream out;
            out << TechniqueName(technique) << ": the renderer used " << w << ", brute force " << expected << " (rel. error "
                << relError << ") on " << DescribePath(scene, path);
            result.worst = out.str();
        }

        // The replay of every technique of the path. A merged vertex is taken at its light
        // end, which keeps the path a path unless a neighbour is specular (its specular
        // direction then misses the camera's end): those merges are left out of the replay.
        if (aUpbp || (path.mergeAt >= 0 && (path.Specular(path.mergeAt - 1) || path.Specular(path.mergeAt + 1)))) {
            result.notReplayed++;
            continue;
        }
        FullPath single = path;
        single.mergeAt = -1;
        PathBsdfs singleBsdfs;
        BruteForcePdfs singlePdfs;
        if (!SetupBsdfs(scene, single, singleBsdfs) || !ComputeBruteForcePdfs(scene, single, singleBsdfs, singlePdfs)) continue;
        const std::vector<double> singleExpected =
            BruteForceWeights(singlePdfs, techniques, single.K(), aCase.heuristic, lightPathCount, eta, etaMedium);
        const RecursiveWeights recursive(scene, single, singleBsdfs, mis, misMedium, singlePdfs.flightForward, singlePdfs.flightReverse);
        result.replayed++;
        double sum = 0.0;
        for (size_t t = 0; t < techniques.size(); t++) {
            const double replayed = double(recursive.Weight(techniques[t]));
            sum += replayed;
            const double replayDiff = std::abs(replayed - singleExpected[t]);
            const double replayRel = singleExpected[t] > 0.0 ? replayDiff / singleExpected[t] : (replayDiff > 0.0 ? 1.0 : 0.0);
            const bool replayOk = std::isfinite(replayed) && replayDiff <= kRelTolerance * singleExpected[t] + kAbsTolerance;
            if (!replayOk) result.replayFailures++;
            if (replayRel > result.maxReplayRelError || (!replayOk && result.worstReplay.empty())) {
                result.maxReplayRelError = std::max(result.maxReplayRelError, replayRel);
                std::ostringstream out;
                out << TechniqueName(techniques[t]) << ": replayed " << replayed << ", brute force " << singleExpected[t]
                    << " (rel. error " << replayRel << ") on " << DescribePath(scene, single);
                result.worstReplay = out.str();
            }
        }
        result.maxSumError = std::max(result.maxSumError, std::isfinite(sum) ? std::abs(sum - 1.0) : 1e30);
    }
    return result;
}

} // namespace

TEST_CASE("In scenes with media the weights VertexCM gives its own paths equal a brute-force sum over all techniques, 3D merges included", "[mis][media]") {
    // The three media scenes above; VCM, BPT and BPM with both heuristics, one iteration
    // at 24 x 24, paths of up to kMaxSegments segments. Merging in media at the default
    // radius (3 % of the scene radius) and at 10 % (more 3D merges, larger kernels).
    // Tolerances: the recorded weights against the brute force keep kRecordedRelTolerance
    // (1e-3): measured up to 7.3e-5 in the fog and the glass scenes and 4.9e-4 in the
    // index-matched ball scene, on a path whose segment from the floor to a point in the
    // fog is 2.6e-3 long (float positions: a relative error of ~1e-4 in its d^2). The
    // replay (the same pdfs in float through VcmMis) keeps kRelTolerance: up to 4.4e-5.
    // The replayed weights of a path sum to one within 1e-4 (measured up to 3.2e-6) as on
    // the generated paths. The segments' free-flight pdfs are the brute force's own, in
    // double; when the renderer took them over the distance flown from the offset ray
    // origin (not the whole segment, as its connections do) the recorded weights were off
    // by up to 3.2e-3 (TraceSegment's aGap).
    const MisCase cases[] = {kMisCases[0], kMisCases[1], kMisCases[2], kMisCases[3], kMisCases[4], kMisCases[5]};
    int total = 0, mediumPaths = 0, mediumMerges = 0, crossing = 0, replayed = 0;
    for (int s = 0; s < kMediaSceneCount; s++) {
        for (const MisCase& misCase : cases) {
            for (float mediumFactor : {0.03f, 0.1f}) {
                if (!misCase.useVM && mediumFactor != 0.03f) continue;  // BPT does not merge
                const MediaComparison c = CompareRecordedWeightsInMedia(s, misCase, mediumFactor, 24, 101u + uint64_t(s));
                total += c.compared;
                mediumPaths += c.withMediumVertex;
                mediumMerges += c.mediumMerges;
                crossing += c.crossingPaths;
                replayed += c.replayed;
                std::printf("[mis] media: scene %-22s %-12s r_m %.2f %5d paths (%d with medium vertices, %d crossing boundaries; hit %d, "
                            "nee %d, connection %d, lt %d, merge %d of which %d in media; %d across edges), %d unusable, max rel. error "
                            "%.2e, %d failures; replayed %d, max rel. error %.2e, max |sum - 1| %.2e\n",
                            kMediaSceneNames[s], misCase.name, double(mediumFactor), c.compared, c.withMediumVertex, c.crossingPaths,
                            c.byTechnique[int(Kind::kCameraHitsLight)], c.byTechnique[int(Kind::kNextEvent)],
                            c.byTechnique[int(Kind::kConnection)], c.byTechnique[int(Kind::kLightTracing)],
                            c.byTechnique[int(Kind::kMerge)], c.mediumMerges, c.acrossEdges, c.unusable, c.maxRelError, c.failures,
                            c.replayed, c.maxReplayRelError, c.maxSumError);
                INFO("scene " << kMediaSceneNames[s] << ", " << misCase.name << ", r_m factor " << mediumFactor << ": " << c.compared
                              << " recorded paths, " << c.failures << " disagree; largest relative error: " << c.worst
                              << "; replay: " << c.replayFailures << " disagree, worst: " << c.worstReplay);
                CHECK(c.failures == 0);
                CHECK(c.replayFailures == 0);
                CHECK(c.maxSumError <= 1e-4);
                CHECK(c.unusable <= c.records / 100);
                CHECK(c.acrossEdges <= c.byTechnique[int(Kind::kMerge)] / 4 + 10);
            }
        }
    }
    std::printf("[mis] media: %d recorded paths, %d with medium vertices, %d crossing index-matched boundaries, %d merges in media; "
                "%d replayed\n", total, mediumPaths, crossing, mediumMerges, replayed);
    CHECK(mediumPaths >= 5000);
    CHECK(mediumMerges >= 500);
    CHECK(crossing >= 500);
}

TEST_CASE("Under UPBP the weights VertexCM gives its own paths equal a brute-force sum over all techniques, merges along beams included", "[mis][media][upbp]") {
    // -a upbp in the four media scenes with every technique (bpt, surf, pp3d, pb2d, bb1d)
    // and with subsets, balance and power heuristic, one iteration at 24 x 24; radii larger
    // than the defaults (points and pb2d 10 %, bb1d 3 % of the scene radius) so that many
    // paths are made by merges along beams. Each recorded weight against the brute force
    // (kRecordedRelTolerance: the recursion of VcmMis with the beam merges' deferred terms
    // and the replayed segments of points on beams, against explicit products in double).
    // A weight equal to the brute force for every technique that made a path is what makes
    // the weights of all techniques of a path sum to one.
    const uint32_t sets[] = {kUpbpAll, kUpbpBpt | kUpbpPb2d, kUpbpBpt | kUpbpBb1d, kUpbpSurface | kUpbpPp3d | kUpbpBb1d,
                             kUpbpPb2d | kUpbpBb1d};
    int total = 0, beamMerges[2] = {0, 0};
    for (int s = 0; s < kMediaSceneCount; s++)
        for (const MisCase& misCase : {kMisCases[0], kMisCases[1]})
            for (uint32_t set : sets) {
                if (misCase.heuristic == MisHeuristic::kPower && set != kUpbpAll) continue;
                const MediaComparison c = CompareRecordedWeightsInMedia(s, misCase, 0.1f, 24, 201u + uint64_t(s), set, 0.03f);
                total += c.compared;
                beamMerges[0] += c.byTechnique[int(Kind::kMergePb2d)];
                beamMerges[1] += c.byTechnique[int(Kind::kMergeBb1d)];
                std::printf("[mis] upbp: scene %-22s %-12s techniques %2u: %5d paths (merges %d, pb2d %d, bb1d %d; %d across edges), "
                            "%d unusable, max rel. error %.2e, %d failures\n",
                            kMediaSceneNames[s], misCase.name, set, c.compared, c.byTechnique[int(Kind::kMerge)],
                            c.byTechnique[int(Kind::kMergePb2d)], c.byTechnique[int(Kind::kMergeBb1d)], c.acrossEdges, c.unusable,
                            c.maxRelError, c.failures);
                INFO("scene " << kMediaSceneNames[s] << ", " << misCase.name << ", techniques " << set << ": " << c.compared
                              << " recorded paths, " << c.failures << " disagree; largest relative error: " << c.worst);
                CHECK(c.failures == 0);
                CHECK(c.unusable <= c.records / 100 + 5);
            }
    std::printf("[mis] upbp: %d recorded paths, %d made by pb2d, %d by bb1d\n", total, beamMerges[0], beamMerges[1]);
    CHECK(beamMerges[0] >= 1000);
    CHECK(beamMerges[1] >= 1000);
}

TEST_CASE("With Sobol points, each pixel connecting to the light sub-path the sampler pairs it with, the recorded weights equal the brute force", "[mis]") {
    // Under the sobol sampler pixel q connects to light sub-path LightPathOfPixel(q, N),
    // not q: the connections, the BSDF cache of the light vertices and the path records
    // must all follow the same light sub-path.
    for (int s : {1, 4})
        for (const MisCase& misCase : {kMisCases[0], kMisCases[4]}) {
            const RecordedComparison c = CompareRecordedWeights(s, misCase, 24, 31u + uint64_t(s), SamplerType::kSobol);
            INFO("scene " << kRecordingSceneNames[s] << ", " << misCase.name << ": " << c.compared << " recorded paths, "
                          << c.failures << " disagree; largest relative error: " << c.worst);
            CHECK(c.failures == 0);
            CHECK(c.unusable <= c.records / 100);
            CHECK(c.byTechnique[int(Kind::kConnection)] >= 100);
        }
}

TEST_CASE("Degenerate paths and pdfs give finite weights in [0, 1], never NaN", "[mis]") {
    SECTION("a zero pdf, e.g. a connection direction below a one-sided surface") {
        // Real sub-path states of scene 4's paths with every pdf argument of each weight
        // function set to zero (alone and together): a technique that cannot build the
        // path drops out of the sums, it must not produce NaN.
        const Scene& scene = CornellScene(4);
        int checked = 0, belowSurface = 0;
        for (const MisCase& misCase : kMisCases) {
            const VcmMisConstants mis = MakeConstants(scene, misCase);
            for (const FullPath& path : CornellPaths(4).paths) {
                if (path.K() < 3) continue;
                PathBsdfs bsdfs;
                REQUIRE(SetupBsdfs(scene, path, bsdfs));
                const RecursiveWeights recursive(scene, path, bsdfs, mis);
                for (int s = 2; s <= path.K() - 1; s++) {
                    if (path.Specular(s - 1) || path.Specular(s)) continue;
                    const SubpathMis& light = recursive.LightMis(s - 1);
                    const SubpathMis& camera = recursive.CameraMis(s);
                    for (int mask = 0; mask < 16; mask++) {
                        const float w = VcmMis::WeightConnection(mis, light, camera, (mask & 1) ? 0.f : 1.f, (mask & 2) ? 0.f : 0.3f,
                                                                 (mask & 4) ? 0.f : 2.f, (mask & 8) ? 0.f : 0.5f,
                                                                 mis.mVmWeightFactor, mis.mVmWeightFactor);
                        CHECK(FiniteUnitInterval(w));
                        checked++;
                    }
                    // The geometric case: the light vertex mirrored below the camera vertex's
                    // one-sided surface; the camera BSDF gives pdf 0 both ways.
                    const Vec3 normal = path.n[size_t(s)];
                    Vec3 direction = Dir(path, s, s - 1);
                    direction = direction - 2.f * glm::dot(direction, normal) * normal;
                    const BsdfEval cameraEval = bsdfs.camera[size_t(s)].Evaluate(direction);
                    const float cosCamera = cameraEval.mCosThetaGen;
                    const float cameraDirPdfW = cameraEval.mDirPdfW, cameraRevPdfW = cameraEval.mRevPdfW;
                    if (cameraDirPdfW == 0.f && cameraRevPdfW == 0.f) belowSurface++;
                    const float w = VcmMis::WeightConnection(mis, light, camera, PdfWtoA(cameraDirPdfW, 1.f, cosCamera),
                                                             cameraRevPdfW, 0.f, 0.f, mis.mVmWeightFactor, mis.mVmWeightFactor);
                    CHECK(FiniteUnitInterval(w));
                }
                for (int i = 1; i < path.K(); i++) {
                    if (path.Specular(i)) continue;
                    for (int mask = 0; mask < 4; mask++)
                        CHECK(FiniteUnitInterval(VcmMis::WeightMerge(mis, recursive.LightMis(i), recursive.CameraMis(i),
                                                                     (mask & 1) ? 0.f : 0.4f, (mask & 2) ? 0.f : 0.4f)));
                    CHECK(FiniteUnitInterval(VcmMis::WeightLightTracing(mis, recursive.LightMis(i), 0.f, 0.f)));
                    CHECK(FiniteUnitInterval(VcmMis::WeightNextEvent(mis, recursive.CameraMis(i), 0.f, 0.f, 1.f, 0.f, 0.5f, 0.5f, false)));
                    SubpathMis scattered = recursive.LightMis(i);
                    VcmMis::AfterScatter(mis, scattered, 0.5f, 0.3f, 0.f, false);  // reverse pdf 0
                    CHECK(std::isfinite(scattered.dVCM));
                    CHECK(std::isfinite(scattered.dVC));
                    CHECK(std::isfinite(scattered.dVM));
                    CHECK(FiniteUnitInterval(VcmMis::WeightMerge(mis, scattered, recursive.CameraMis(i), 0.4f, 0.4f)));
                    checked += 8;
                }
                CHECK(FiniteUnitInterval(VcmMis::WeightCameraHitsLight(mis, recursive.CameraMis(1), 0.f, 0.f)));
            }
        }
        INFO(checked << " weights with zero pdfs, " << belowSurface << " connections below a surface");
        CHECK(checked > 10000);
        CHECK(belowSurface > 100);
    }

    SECTION("grazing cosines at a wall and at the light") {
        // Hand-built paths in scene 4 (white floor and walls, area light): the camera sees
        // the floor at F just in front of the back wall; F connects to B on the back wall
        // right above it, so B sees the segment at |cos| = delta / |B - F|; B is lit by the
        // light's centre. A second family grazes the light itself: a left-wall point W
        // just below the light's plane. Both are valid for the integrator as long as the
        // cosine stays above kEpsCosine = 1e-6.
        const Scene& scene = CornellScene(4);
        const Vec3 eye = scene.mCamera.Position();
        Vec3 floorProbe, wallProbe, lightProbe, leftProbe;
        const SurfacePoint floorHit = Probe(scene, eye, Vec3(0.f, 0.f, -1.28002f), floorProbe);
        const SurfacePoint wallHit = Probe(scene, eye, Vec3(0.f, 1.30455f, 0.f), wallProbe);
        const SurfacePoint lightHit = Probe(scene, Vec3(0.01f, 0.02f, 0.f), Vec3(0.01f, 0.02f, 2.f), lightProbe);
        const SurfacePoint leftHit = Probe(scene, Vec3(0.f, 0.f, 0.f), Vec3(-2.f, 0.f, 0.f), leftProbe);
        REQUIRE(floorHit.IsValid());
        REQUIRE(wallHit.IsValid());
        REQUIRE(lightHit.mLightId >= 0);
        REQUIRE(leftHit.IsValid());
        auto makePath = [&](const std::vector<Vec3>& aInterior, const std::vector<const SurfacePoint*>& aHits) {
            FullPath path;
            path.lightId = lightHit.mLightId;
            path.x.push_back(lightProbe);
            path.n.push_back(lightHit.GeometricNormal());
            path.material.push_back(-1);
            path.event.push_back(0);
            for (size_t i = 0; i < aInterior.size(); i++) {
                path.x.push_back(aInterior[i]);
                path.n.push_back(aHits[i]->GeometricNormal());
                path.material.push_back(aHits[i]->mMaterialId);
                path.event.push_back(0);
            }
            path.x.push_back(eye);
            path.n.push_back(Vec3(0.f));
            path.material.push_back(-1);
            path.event.push_back(0);
            return path;
        };
        int checked = 0;
        double worstSumError = 0.0;
        std::vector<std::pair<float, double>> bruteForceErrors;  // (delta, largest relative error)
        for (float delta : {1e-2f, 1e-3f, 1e-4f, 1e-5f, 3e-6f}) {
            Comparison agreement;
            const float backY = wallProbe.y, floorZ = floorProbe.z, leftX = leftProbe.x, lightZ = lightProbe.z;
            const Vec3 f(0.1f, backY - delta, floorZ), b(0.1f, backY, floorZ + 1.f);
            const Vec3 w(leftX, 0.f, lightZ - delta * 1.3f);
            std::vector<FullPath> paths = {makePath({b, f}, {&wallHit, &floorHit}),   // grazing at B
                                           makePath({w}, {&leftHit}),                  // grazing at the light
                                           makePath({w, f}, {&leftHit, &floorHit})};  // both at once
            for (const FullPath& path : paths) {
                for (const MisCase& misCase : kMisCases) {
                    const std::vector<float> weights =
                        AllRecursiveWeights(scene, path, MakeConstants(scene, misCase), misCase.useVC, misCase.useVM);
                    INFO("delta " << delta << ", " << misCase.name << ", " << DescribePath(scene, path));
                    REQUIRE(!weights.empty());
                    double sum = 0.0;
                    for (float weight : weights) {
                        CHECK(FiniteUnitInterval(weight));
                        sum += double(weight);
                        checked++;
                    }
                    // Every technique reads the grazing cosine from the same float directions
                    // and frames, so the recursive weights still sum to 1 tightly; only the
                    // comparison with the double brute force loses ~1e-7 / |cos| (printed).
                    worstSumError = std::max(worstSumError, std::abs(sum - 1.0));
                    CHECK(sum == Approx(1.0).margin(1e-4));
                    ComparePath(scene, path, misCase, agreement);
                }
            }
            INFO("delta " << delta << ": " << agreement.worst);
            CHECK(agreement.outOfRange == 0);
            bruteForceErrors.push_back({delta, agreement.maxRelError});
        }
        std::ostringstream errors;
        for (const auto& e : bruteForceErrors) errors << " " << e.first << ":" << e.second;
        std::printf("[mis] grazing paths: %d weights, largest |sum - 1| = %.2e; largest relative error vs brute force "
                    "per |cos| (informative, float cosines):%s\n", checked, worstSumError, errors.str().c_str());
    }

    SECTION("delta lights: no camera-hits-light technique, no light-side term in NEE") {
        int paths = 0;
        for (int s : {0, 2}) {
            const Scene& scene = CornellScene(s);
            for (const MisCase& misCase : kMisCases) {
                const VcmMisConstants mis = MakeConstants(scene, misCase);
                for (const FullPath& path : CornellPaths(s).paths) {
                    REQUIRE(path.deltaLight);
                    for (const Technique& t : Techniques(path, misCase.useVC, misCase.useVM))
                        CHECK(t.kind != Kind::kCameraHitsLight);
                    PathBsdfs bsdfs;
                    REQUIRE(SetupBsdfs(scene, path, bsdfs));
                    const RecursiveWeights recursive(scene, path, bsdfs, mis);
                    // The emission start: no unidirectional technique to remember.
                    const SubpathMis start = VcmMis::AtLightEmission(mis, 1.f, 0.1f, 1.f, true, s == 2);
                    CHECK(start.dVC == 0.f);
                    CHECK(start.dVM == 0.f);
                    CHECK(std::isfinite(start.dVCM));
                    if (path.Specular(1) || !misCase.useVC) continue;
                    // NEE's weight ignores the BSDF pdf towards the light: nothing could hit it.
                    const LightSample sample = recursive.NextEventSample();
                    const float pick = 1.f / float(scene.LightCount());
                    float weights[3];
                    const float bsdfDirPdfs[3] = {0.f, 0.7f, 1e20f};
                    for (int i = 0; i < 3; i++)
                        weights[i] = VcmMis::WeightNextEvent(mis, recursive.CameraMis(1), bsdfDirPdfs[i], 0.3f,
                                                             sample.mDirectPdfW * pick, sample.mEmissionPdfW * pick, 0.5f,
                                                             sample.mCosAtLight, true);
                    CHECK(FiniteUnitInterval(weights[0]));
                    CHECK(weights[0] == weights[1]);
                    CHECK(weights[0] == weights[2]);
                    paths++;
                }
            }
        }
        CHECK(paths > 1000);
    }

    SECTION("specular vertices: pure caustic paths have weight 1, chains of specular vertices stay finite") {
        int causticPaths = 0, chains = 0;
        for (int s = 0; s < kSceneCount; s++) {
            const Scene& scene = CornellScene(s);
            for (const MisCase& misCase : kMisCases) {
                const VcmMisConstants mis = MakeConstants(scene, misCase);
                for (const FullPath& path : CornellPaths(s).paths) {
                    bool allSpecular = true, chain = false;
                    for (int i = 1; i < path.K(); i++) {
                        allSpecular = allSpecular && path.Specular(i);
                        if (i >= 2 && path.Specular(i) && path.Specular(i - 1)) chain = true;
                    }
                    if (!(allSpecular && path.K() >= 2) && !chain) continue;
                    const std::vector<float> weights = AllRecursiveWeights(scene, path, mis, misCase.useVC, misCase.useVM);
                    INFO("scene " << kSceneNames[s] << ", " << misCase.name << ", " << DescribePath(scene, path));
                    for (float w : weights) CHECK(FiniteUnitInterval(w));
                    if (allSpecular && path.K() >= 2 && !path.deltaLight) {
                        // Only the camera path can find it (light x_0 -> specular ... -> camera).
                        REQUIRE(weights.size() == 1);
                        CHECK(weights[0] == Approx(1.f).epsilon(1e-6));
                        causticPaths++;
                    }
                    if (chain) chains++;
                }
            }
        }
        INFO(causticPaths << " purely specular paths, " << chains << " with two specular vertices in a row");
        CHECK(causticPaths > 0);
        CHECK(chains > 0);
    }
}

// =======================================================================================
// The graders of the coursework kit's MIS exercises (docs/exercises/06-bpt-mis.md and
// 07-vcm-mis.md): the same brute-force comparison as above, split by algorithm, with a
// diagnosis a student can act on. BPT's weights use no merging quantity, so exercise 06
// is graded by BPT alone; VCM and BPM build on exercise 06's dVCM and dVC.
// =======================================================================================

// A check whose failure message is the diagnosis `make grade` shows to the student.
#define GRADE_MIS(aDiagnosis)                          \
    do {                                               \
        if ((aDiagnosis).empty()) SUCCEED();           \
        else FAIL_CHECK(aDiagnosis);                   \
    } while (false)

namespace {

// Every path of the five Cornell scenes under one MIS case; "" when every weight equals
// the brute force (same tolerances as above) and every path's weights sum to one,
// otherwise what is wrong, worst path first.
std::string DiagnoseMis(const MisCase& aCase) {
    int paths = 0, wrongPaths = 0;
    double worstSumError = -1.0, worstSum = 0.0;
    std::string worstSumPath, worstTechnique;
    double worstRelError = -1.0;
    for (int s = 0; s < kSceneCount; s++) {
        const Scene& scene = CornellScene(s);
        const VcmMisConstants mis = MakeConstants(scene, aCase);
        const double lightPathCount = double(scene.mCamera.PixelCount());
        const double radius = double(aCase.radiusFactor) * double(scene.GetSceneSphere().mRadius);
        const double eta = 3.14159265358979323846 * radius * radius * lightPathCount;
        for (const FullPath& path : CornellPaths(s).paths) {
            const std::vector<Technique> techniques = Techniques(path, aCase.useVC, aCase.useVM);
            PathBsdfs bsdfs;
            BruteForcePdfs pdfs;
            if (techniques.empty() || !SetupBsdfs(scene, path, bsdfs) || !ComputeBruteForcePdfs(scene, path, bsdfs, pdfs)) continue;
            const std::vector<double> expected = BruteForceWeights(pdfs, techniques, path.K(), aCase.heuristic, lightPathCount, eta);
            const RecursiveWeights recursive(scene, path, bsdfs, mis);
            paths++;
            double sum = 0.0;
            bool wrong = false;
            for (size_t t = 0; t < techniques.size(); t++) {
                const double w = double(recursive.Weight(techniques[t]));
                sum += w;
                const double diff = std::abs(w - expected[t]);
                const bool ok = std::isfinite(w) && w >= 0.0 && w <= 1.0 + 1e-6 && diff <= kRelTolerance * expected[t] + kAbsTolerance;
                if (ok) continue;
                wrong = true;
                const double relError = expected[t] > 0.0 ? diff / expected[t] : 1.0;
                if (!(relError <= worstRelError)) {
                    worstRelError = relError;
                    std::ostringstream out;
                    out << TechniqueName(techniques[t]) << " has weight " << w << ", brute force " << expected[t] << " (scene "
                        << kSceneNames[s] << ", " << DescribePath(scene, path) << ")";
                    worstTechnique = out.str();
                }
            }
            const double sumError = std::isfinite(sum) ? std::abs(sum - 1.0) : std::numeric_limits<double>::infinity();
            if (sumError > 1e-4) wrong = true;
            if (wrong) wrongPaths++;
            if (sumError > worstSumError) {
                worstSumError = sumError;
                worstSum = sum;
                std::ostringstream out;
                out << "a length-" << path.K() << " path with " << techniques.size() << " techniques (scene " << kSceneNames[s]
                    << ", " << DescribePath(scene, path) << ")";
                worstSumPath = out.str();
            }
        }
    }
    if (wrongPaths == 0 && paths >= 1000) return "";
    std::ostringstream out;
    out << aCase.name << ": " << wrongPaths << " of " << paths << " paths have wrong weights";
    if (!worstTechnique.empty()) out << "; e.g. " << worstTechnique;
    if (worstSumError > 1e-4) out << "; the MIS weights of " << worstSumPath << " sum to " << worstSum << ", expected 1";
    else out << "; every path's weights sum to one, but they are not the heuristic's";
    if (paths < 1000) out << "; only " << paths << " valid paths (expected >= 1000)";
    return out.str();
}

} // namespace

TEST_CASE("Exercise 06: the recursive BPT weights (balance and power) equal the brute-force heuristics and sum to one",
          "[exercise][ex:bpt_mis]") {
    for (const MisCase& misCase : kMisCases) {
        if (misCase.useVM) continue;
        const std::string diagnosis = DiagnoseMis(misCase);
        GRADE_MIS(diagnosis);
    }
}

TEST_CASE("Exercise 07: the recursive VCM and BPM weights (with merging) equal the brute-force heuristics and sum to one",
          "[exercise][ex:vcm_mis]") {
    for (const MisCase& misCase : kMisCases) {
        if (!misCase.useVM) continue;
        const std::string diagnosis = DiagnoseMis(misCase);
        GRADE_MIS(diagnosis);
    }
}
