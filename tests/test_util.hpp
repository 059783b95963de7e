// Shared helpers of the tests: scenes (the Cornell files and the analytic furnaces built
// in code) and small statistics. Tests run from the tests/ folder.
#pragma once
#include "smallvcm.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <sys/wait.h>
#include <unistd.h>

namespace testutil {

using namespace smallvcm;

inline std::string CornellPath(int aIndex) {
    static const char* const kFiles[] = {"cornell_0_sun.gltf", "cornell_1_mirror_ceiling.gltf", "cornell_2_point.gltf",
                                         "cornell_3_background.gltf", "cornell_4_default.gltf"};
    return std::string("../scenes/") + kFiles[aIndex];
}

inline Scene LoadCornell(int aIndex, int aWidth, int aHeight) {
    Scene scene = LoadGltfScene(CornellPath(aIndex));
    scene.mCamera.SetResolution(aWidth, aHeight);
    return scene;
}

// A geodesic sphere (subdivided icosahedron) of radius aRadius around the origin with
// its triangles wound to face INWARDS, so that one-sided Lambert and one-sided emission
// work from inside. aSubdivisions = 3 gives 1280 triangles.
inline std::vector<std::array<Vec3, 3>> InwardGeodesicSphere(float aRadius, int aSubdivisions) {
    const float t = (1.f + std::sqrt(5.f)) / 2.f;
    std::vector<Vec3> v = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                           {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
    std::vector<std::array<int, 3>> f = {{0, 11, 5}, {0, 5, 1}, {0, 1, 7}, {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                                         {11, 10, 2}, {10, 7, 6}, {7, 1, 8}, {3, 9, 4}, {3, 4, 2}, {3, 2, 6}, {3, 6, 8},
                                         {3, 8, 9}, {4, 9, 5}, {2, 4, 11}, {6, 2, 10}, {8, 6, 7}, {9, 8, 1}};
    std::vector<std::array<Vec3, 3>> triangles;
    for (const auto& face : f) triangles.push_back({glm::normalize(v[face[0]]), glm::normalize(v[face[1]]), glm::normalize(v[face[2]])});
    for (int s = 0; s < aSubdivisions; s++) {
        std::vector<std::array<Vec3, 3>> finer;
        for (const auto& tri : triangles) {
            const Vec3 a = glm::normalize(tri[0] + tri[1]), b = glm::normalize(tri[1] + tri[2]), c = glm::normalize(tri[2] + tri[0]);
            finer.push_back({tri[0], a, c});
            finer.push_back({tri[1], b, a});
            finer.push_back({tri[2], c, b});
            finer.push_back({a, b, c});
        }
        triangles = finer;
    }
    // The icosahedron above is wound outwards; swap two vertices to face inwards.
    for (auto& tri : triangles) {
        std::swap(tri[1], tri[2]);
        for (Vec3& p : tri) p *= aRadius;
    }
    return triangles;
}

// Furnace 1: a closed diffuse sphere of albedo aAlbedo whose whole inside emits aEmitted.
// Every camera ray sees L = Le (1 - a^k) / (1 - a) for a maximum path length k.
inline Scene MakeEmissiveFurnace(float aAlbedo, float aEmitted, int aWidth, int aHeight) {
    Scene scene;
    scene.mName = "emissive furnace";
    Material wall;
    wall.mDiffuseReflectance = Vec3(aAlbedo);
    const int material = scene.AddMaterial(wall);
    std::vector<int> ids;
    for (const auto& tri : InwardGeodesicSphere(1.f, 3)) ids.push_back(scene.AddTriangle(tri[0], tri[1], tri[2], material));
    scene.AddAreaLight(ids, Vec3(aEmitted));
    scene.mCamera.Setup(Vec3(0.1f, -0.2f, 0.05f), Vec3(0.3f, 1.f, 0.2f), Vec3(0.f, 0.f, 1.f), 60.f);
    scene.mCamera.SetResolution(aWidth, aHeight);
    scene.Finalize();
    return scene;
}

// Furnace 1 filled with a medium (the scene medium: the diffuse sphere bounds none) of
// scattering coefficient aSigmaS, no absorption, asymmetry aG: scattering neither adds
// nor removes light where the radiance is the same in every direction, so every camera
// ray still sees L = Le / (1 - a) for unbounded paths.
inline Scene MakeMediumFurnace(float aAlbedo, float aEmitted, float aSigmaS, float aG, int aWidth, int aHeight) {
    Scene scene = MakeEmissiveFurnace(aAlbedo, aEmitted, aWidth, aHeight);
    Medium fog;
    fog.mName = "furnace fog";
    fog.mSigmaS = Vec3(aSigmaS);
    fog.mG = aG;
    scene.mSceneMedium = scene.AddMedium(fog);
    scene.Finalize();
    return scene;
}

// Furnace 2: a point light of intensity pi at the centre of a diffuse sphere of radius 1
// and albedo 0.5. Direct: a E / pi = 0.5; with bounces L = 0.5 + 0.5 L = 1; with a
// maximum path length k (the camera segment counts): L = 1 - 0.5^(k-1).
inline Scene MakePointLightFurnace(int aWidth, int aHeight) {
    Scene scene;
    scene.mName = "point light furnace";
    Material wall;
    wall.mDiffuseReflectance = Vec3(0.5f);
    const int material = scene.AddMaterial(wall);
    for (const auto& tri : InwardGeodesicSphere(1.f, 4)) scene.AddTriangle(tri[0], tri[1], tri[2], material);
    scene.AddPointLight(Vec3(0.f), Vec3(kPi));
    scene.mCamera.Setup(Vec3(0.05f, -0.1f, 0.02f), Vec3(-0.2f, 1.f, 0.1f), Vec3(0.f, 0.f, 1.f), 60.f);
    scene.mCamera.SetResolution(aWidth, aHeight);
    scene.Finalize();
    return scene;
}

// Small rooms of every kind of surface and light, built in code (the per-length tests of
// test_transport and the recorded-weight MIS test of test_vcm_mis use them).
// A quad from two triangles, wound so that its front faces aInside.
inline void AddQuadFacing(Scene& aScene, const Vec3& aA, const Vec3& aB, const Vec3& aC, const Vec3& aD, const Vec3& aInside,
                   int aMaterial, std::vector<int>* oIds = nullptr) {
    const bool flip = glm::dot(glm::cross(aB - aA, aC - aA), aInside - aA) < 0.f;
    const int t0 = flip ? aScene.AddTriangle(aA, aC, aB, aMaterial) : aScene.AddTriangle(aA, aB, aC, aMaterial);
    const int t1 = flip ? aScene.AddTriangle(aA, aD, aC, aMaterial) : aScene.AddTriangle(aA, aC, aD, aMaterial);
    if (oIds) { oIds->push_back(t0); oIds->push_back(t1); }
}

inline Material DiffuseMaterial(float aR, float aG, float aB) {
    Material m;
    m.mDiffuseReflectance = Vec3(aR, aG, aB);
    return m;
}

// A room x in [-1, 1], y in [-1, 1], z in [0, 2], open at the front (y = -1, behind the
// camera, so that paths leave it), with diffuse walls and ceiling and the given floor;
// the camera at (0, -0.9, 1) looks at the back wall and sees the floor and the ceiling
// from y = 0.3 on (80 degrees).
inline Scene MakeOpenRoom(const Material& aFloor, int aSize) {
    Scene scene;
    const Vec3 inside(0.f, 0.f, 1.f);
    const int white = scene.AddMaterial(DiffuseMaterial(0.7f, 0.7f, 0.7f));
    const int red = scene.AddMaterial(DiffuseMaterial(0.7f, 0.25f, 0.2f));
    const int green = scene.AddMaterial(DiffuseMaterial(0.2f, 0.6f, 0.25f));
    const int floor = scene.AddMaterial(aFloor);
    AddQuadFacing(scene, Vec3(-1, -1, 0), Vec3(1, -1, 0), Vec3(1, 1, 0), Vec3(-1, 1, 0), inside, floor);
    AddQuadFacing(scene, Vec3(-1, -1, 2), Vec3(1, -1, 2), Vec3(1, 1, 2), Vec3(-1, 1, 2), inside, white);
    AddQuadFacing(scene, Vec3(-1, 1, 0), Vec3(1, 1, 0), Vec3(1, 1, 2), Vec3(-1, 1, 2), inside, white);
    AddQuadFacing(scene, Vec3(-1, -1, 0), Vec3(-1, 1, 0), Vec3(-1, 1, 2), Vec3(-1, -1, 2), inside, red);
    AddQuadFacing(scene, Vec3(1, -1, 0), Vec3(1, 1, 0), Vec3(1, 1, 2), Vec3(1, -1, 2), inside, green);
    scene.mCamera.Setup(Vec3(0.f, -0.9f, 1.f), Vec3(0.f, 1.f, 0.f), Vec3(0.f, 0.f, 1.f), 80.f);
    scene.mCamera.SetResolution(aSize, aSize);
    return scene;
}

inline Material PhongMaterial(float aDiffuse, float aPhong, float aExponent) {
    Material m;
    m.mDiffuseReflectance = Vec3(aDiffuse);
    m.mPhongReflectance = Vec3(aPhong);
    m.mPhongExponent = aExponent;
    return m;
}

inline Material GlassMaterial(float aIor) {
    Material m;
    m.mMirrorReflectance = Vec3(1.f);
    m.mIor = aIor;
    return m;
}

// Glossy: a Phong floor and a Phong ball, lit by a sphere light and by a two-sided
// panel seen from the camera on one side and lighting the room from both.
inline Scene MakeGlossyRoom(int aSize) {
    Scene scene = MakeOpenRoom(PhongMaterial(0.25f, 0.45f, 20.f), aSize);
    scene.mName = "glossy room (sphere light, two-sided panel)";
    const int black = scene.AddMaterial(Material());
    scene.AddSphere(Vec3(0.45f, 0.4f, 0.35f), 0.35f, scene.AddMaterial(PhongMaterial(0.2f, 0.6f, 30.f)));
    scene.AddSphereLight(scene.AddSphere(Vec3(-0.4f, 0.4f, 1.55f), 0.3f, black), Vec3(2.f));
    std::vector<int> panel;  // vertical, facing +-x, at x = 0.3
    AddQuadFacing(scene, Vec3(0.3f, 0.f, 0.9f), Vec3(0.3f, 0.6f, 0.9f), Vec3(0.3f, 0.6f, 1.4f), Vec3(0.3f, 0.f, 1.4f),
                  Vec3(-1.f, 0.3f, 1.1f), black, &panel);
    scene.AddAreaLight(panel, Vec3(2.f), true);
    scene.Finalize();
    return scene;
}

// A spot light from the ceiling onto the Phong floor and a diffuse ball.
inline Scene MakeSpotRoom(int aSize) {
    Scene scene = MakeOpenRoom(PhongMaterial(0.3f, 0.4f, 15.f), aSize);
    scene.mName = "spot room";
    scene.AddSphere(Vec3(0.3f, 0.3f, 0.3f), 0.3f, scene.AddMaterial(DiffuseMaterial(0.6f, 0.6f, 0.3f)));
    scene.AddSpotLight(Vec3(-0.2f, 0.f, 1.95f), Vec3(0.3f, 0.3f, -1.f), Vec3(3.f), 0.35f, 0.7f);
    scene.Finalize();
    return scene;
}

// A one-sided 0.8 x 0.7 panel just under the ceiling, facing down, radiance 4 (black
// material): the light of the rooms below.
inline void AddCeilingPanelLight(Scene& ioScene) {
    const int black = ioScene.AddMaterial(Material());
    std::vector<int> light;
    AddQuadFacing(ioScene, Vec3(-0.4f, 0.2f, 1.99f), Vec3(0.4f, 0.2f, 1.99f), Vec3(0.4f, 0.9f, 1.99f),
                  Vec3(-0.4f, 0.9f, 1.99f), Vec3(0.f, 0.f, 0.f), black, &light);
    ioScene.AddAreaLight(light, Vec3(4.f));
}

// Specular: a mirror wall (right) and a glass ball, a one-sided ceiling light.
inline Scene MakeSpecularRoom(int aSize) {
    Scene scene = MakeOpenRoom(DiffuseMaterial(0.6f, 0.6f, 0.6f), aSize);
    scene.mName = "specular room (mirror, glass)";
    Material mirror;
    mirror.mMirrorReflectance = Vec3(0.85f);
    AddQuadFacing(scene, Vec3(0.98f, -0.6f, 0.1f), Vec3(0.98f, 0.9f, 0.1f), Vec3(0.98f, 0.9f, 1.7f), Vec3(0.98f, -0.6f, 1.7f),
                  Vec3(0.f, 0.f, 1.f), scene.AddMaterial(mirror));
    scene.AddSphere(Vec3(-0.35f, 0.35f, 0.4f), 0.4f, scene.AddMaterial(GlassMaterial(1.5f)));
    AddCeilingPanelLight(scene);
    scene.Finalize();
    return scene;
}

// The camera inside a glass ball: every camera ray leaves through the glass.
inline Scene MakeCameraInGlassRoom(int aSize) {
    Scene scene = MakeOpenRoom(PhongMaterial(0.4f, 0.3f, 10.f), aSize);
    scene.mName = "camera inside glass";
    scene.AddSphere(scene.mCamera.Position(), 0.08f, scene.AddMaterial(GlassMaterial(1.5f)));
    AddCeilingPanelLight(scene);
    scene.Finalize();
    return scene;
}

// The six estimators of light transport that every whole-scene agreement test compares
// (the eye light estimates nothing; the classic photon maps pm and pmfg are biased).
inline constexpr Algorithm kTransportEstimators[] = {
    Algorithm::kPathTracing, Algorithm::kLightTracing, Algorithm::kProgressivePhotonMapping,
    Algorithm::kBidirectionalPhotonMapping, Algorithm::kBidirectionalPathTracing, Algorithm::kVertexConnectionMerging};

inline RenderResult RenderWith(const Scene& aScene, Algorithm aAlgorithm, int aIterations, uint64_t aSeed = 7,
                               int aMaxPathLength = 10) {
    RenderOptions options;
    options.mAlgorithm = aAlgorithm;
    options.mIterations = aIterations;
    options.mSeed = aSeed;
    options.mMaxPathLength = aMaxPathLength;
    options.mProgress = false;
    return Render(aScene, options);
}

// Mean and standard error of the mean of per-pixel values (one channel average each):
// pixels are independent samples of the same value in a furnace.
struct MeanAndError { double mean = 0.0, standardError = 0.0; };
inline MeanAndError PixelStatistics(const Image& aImage) {
    double sum = 0.0, sumSqr = 0.0;
    const double n = double(aImage.mPixels.size());
    for (const Vec3& p : aImage.mPixels) {
        const double v = (double(p.x) + double(p.y) + double(p.z)) / 3.0;
        sum += v;
        sumSqr += v * v;
    }
    MeanAndError r;
    r.mean = sum / n;
    const double variance = std::max(0.0, sumSqr / n - r.mean * r.mean) * n / (n - 1.0);
    r.standardError = std::sqrt(variance / n);
    return r;
}

// Mean of a sample and the standard error of that mean (from the sample variance), for
// Monte Carlo estimates whose tolerance is a multiple of their own measured noise.
inline MeanAndError MeanOf(const std::vector<double>& aValues) {
    double sum = 0.0, sumSqr = 0.0;
    for (double v : aValues) { sum += v; sumSqr += v * v; }
    const double n = double(aValues.size());
    MeanAndError e;
    e.mean = sum / n;
    e.standardError = std::sqrt(std::max(0.0, sumSqr / n - e.mean * e.mean) / (n - 1.0));
    return e;
}

// Mean radiance (channel average) over regions of the image, per batch: aBatches
// independent renders (seeds aSeed, aSeed + 1, ...) of aIterations each on 2 threads, so
// that the spread of the batch means gives each region's standard error (MeanOf).
// aRegionOfPixel[p] is pixel p's region in [0, aRegionCount), or -1 for none. Returns
// [region][batch], and one more row, index aRegionCount, for the whole image.
inline std::vector<std::vector<double>> RegionBatchMeans(const Scene& aScene, Algorithm aAlgorithm, int aBatches,
                                                         int aIterations, uint64_t aSeed,
                                                         const std::vector<int>& aRegionOfPixel, int aRegionCount) {
    std::vector<std::vector<double>> means(size_t(aRegionCount) + 1);
    for (int b = 0; b < aBatches; b++) {
        RenderOptions options;
        options.mAlgorithm = aAlgorithm;
        options.mIterations = aIterations;
        options.mSeed = aSeed + uint64_t(b);
        options.mThreads = 2;
        options.mProgress = false;
        const RenderResult result = Render(aScene, options);
        std::vector<double> sums(size_t(aRegionCount) + 1, 0.0);
        std::vector<int> counts(size_t(aRegionCount), 0);
        for (size_t p = 0; p < result.mImage.mPixels.size(); p++) {
            const Vec3& c = result.mImage.mPixels[p];
            const double value = (double(c.x) + double(c.y) + double(c.z)) / 3.0;
            sums[size_t(aRegionCount)] += value;
            const int region = aRegionOfPixel[p];
            if (region < 0) continue;
            sums[size_t(region)] += value;
            counts[size_t(region)]++;
        }
        for (int r = 0; r < aRegionCount; r++) means[size_t(r)].push_back(sums[size_t(r)] / counts[size_t(r)]);
        means[size_t(aRegionCount)].push_back(sums[size_t(aRegionCount)] / double(result.mImage.mPixels.size()));
    }
    return means;
}

// Upper quantile of the chi-square distribution with aDof degrees of freedom at
// significance 1e-3, by the Wilson-Hilferty approximation: (X / k)^(1/3) is nearly
// normal with mean 1 - 2/(9k) and variance 2/(9k), so the quantile is
// k (1 - 2/(9k) + z sqrt(2/(9k)))^3 with z = 3.0902, the standard normal quantile at
// 1 - 1e-3. It errs on the safe side in the tail: k = 3 gives 16.55 (exact 16.27),
// k = 100 gives 149.5 (exact 149.4).
inline double ChiSquareThreshold(int aDof) {
    const double z = 3.090232306167813;
    const double k = double(aDof);
    const double a = 2.0 / (9.0 * k);
    return k * std::pow(1.0 - a + z * std::sqrt(a), 3.0);
}

struct ChiSquare {
    double statistic = 0.0;
    int dof = 0;
    double threshold = 0.0;
};

// Pearson's statistic over the cells. Cells expecting fewer than 5 samples are pooled
// into one (the usual validity condition of the chi-square approximation); if the pool
// itself still expects fewer than 5 it is merged into the smallest remaining cell.
inline ChiSquare ComputeChiSquare(const std::vector<double>& aObserved, const std::vector<double>& aExpected) {
    std::vector<double> observed, expected;
    double pooledObserved = 0.0, pooledExpected = 0.0;
    for (size_t i = 0; i < aExpected.size(); i++) {
        if (aExpected[i] < 5.0) {
            pooledObserved += aObserved[i];
            pooledExpected += aExpected[i];
        } else {
            observed.push_back(aObserved[i]);
            expected.push_back(aExpected[i]);
        }
    }
    if (pooledExpected >= 5.0 || expected.empty()) {
        observed.push_back(pooledObserved);
        expected.push_back(pooledExpected);
    } else if (pooledObserved > 0.0 || pooledExpected > 0.0) {
        size_t smallest = 0;
        for (size_t i = 1; i < expected.size(); i++)
            if (expected[i] < expected[smallest]) smallest = i;
        observed[smallest] += pooledObserved;
        expected[smallest] += pooledExpected;
    }
    ChiSquare result;
    for (size_t i = 0; i < expected.size(); i++) {
        const double d = observed[i] - expected[i];
        // A cell that expects nothing but receives samples is an outright failure.
        result.statistic += expected[i] > 0.0 ? d * d / expected[i] : (observed[i] > 0.0 ? 1e30 : 0.0);
    }
    result.dof = std::max(1, int(expected.size()) - 1);
    result.threshold = ChiSquareThreshold(result.dof);
    return result;
}

// For tests that run programs: a fresh folder under the system's temporary folder,
// removed with everything in it; shell quoting; a whole file as text.
struct TemporaryFolder {
    std::filesystem::path mPath;
    TemporaryFolder() {
        static int counter = 0;
        mPath = std::filesystem::temp_directory_path() /
                ("smallvcm_test_" + std::to_string(getpid()) + "_" + std::to_string(counter++));
        std::filesystem::remove_all(mPath);
        std::filesystem::create_directories(mPath);
    }
    ~TemporaryFolder() {
        std::error_code ignored;
        std::filesystem::remove_all(mPath, ignored);
    }
    TemporaryFolder(const TemporaryFolder&) = delete;
    TemporaryFolder& operator=(const TemporaryFolder&) = delete;
    std::string operator/(const std::string& aName) const { return (mPath / aName).string(); }
};

inline std::string Quote(const std::string& aText) {
    std::string quoted = "'";
    for (char c : aText) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return quoted + "'";
}

inline std::string ReadText(const std::string& aPath) {
    std::ifstream file(aPath, std::ios::binary);
    std::stringstream text;
    text << file.rdbuf();
    return text.str();
}

// The exit code of a std::system() status (128 + the signal for a killed child).
inline int ExitCode(int aStatus) {
    return WIFEXITED(aStatus) ? WEXITSTATUS(aStatus) : 128 + (WIFSIGNALED(aStatus) ? WTERMSIG(aStatus) : 0);
}

// The comma-separated fields of one CSV line (the tools' CSVs quote nothing).
inline std::vector<std::string> SplitCsvLine(const std::string& aLine) {
    std::vector<std::string> fields;
    std::string field;
    std::stringstream stream(aLine);
    while (std::getline(stream, field, ',')) fields.push_back(field);
    return fields;
}

// Per-iteration statistics of block means: each iteration is an independent estimate of
// the image, so the spread of a block's per-iteration values gives its standard error.
struct BlockStatistics {
    int mBlocksX = 0, mBlocksY = 0, mIterations = 0;
    std::vector<glm::dvec3> mSum, mSumSqr;

    int BlockCount() const { return mBlocksX * mBlocksY; }

    glm::dvec3 Mean(int aBlock) const { return mSum[size_t(aBlock)] / double(mIterations); }
    glm::dvec3 StandardError(int aBlock) const {
        const glm::dvec3 mean = Mean(aBlock);
        const glm::dvec3 variance = (mSumSqr[size_t(aBlock)] / double(mIterations) - mean * mean) *
                                    (double(mIterations) / double(mIterations - 1));
        return glm::sqrt(glm::max(variance, glm::dvec3(0.0)) / double(mIterations));
    }
};

// Runs aIterations single iterations of one renderer and records, per block of
// aBlockSize x aBlockSize pixels, the sum and sum of squares of the block's mean.
inline BlockStatistics RenderBlocks(const Scene& aScene, Algorithm aAlgorithm, int aIterations, int aBlockSize, uint64_t aSeed,
                                    SamplerType aSampler = SamplerType::kIndependent) {
    RenderOptions options;
    options.mAlgorithm = aAlgorithm;
    options.mSampler = aSampler;
    options.mProgress = false;
    std::unique_ptr<AbstractRenderer> renderer = CreateRenderer(aScene, options);
    const int width = aScene.mCamera.Width(), height = aScene.mCamera.Height();
    BlockStatistics stats;
    stats.mBlocksX = width / aBlockSize;
    stats.mBlocksY = height / aBlockSize;
    stats.mIterations = aIterations;
    stats.mSum.assign(size_t(stats.mBlocksX * stats.mBlocksY), glm::dvec3(0.0));
    stats.mSumSqr = stats.mSum;
    Image previous(width, height);
    for (int i = 0; i < aIterations; i++) {
        Sampler sampler = IterationSampler(aSampler, aSeed, i);
        renderer->RunIteration(i, sampler);
        const Image cumulative = renderer->GetFilm().Resolve(1.0);
        std::vector<glm::dvec3> blocks(stats.mSum.size(), glm::dvec3(0.0));
        for (int y = 0; y < stats.mBlocksY * aBlockSize; y++)
            for (int x = 0; x < stats.mBlocksX * aBlockSize; x++) {
                const glm::dvec3 value = glm::dvec3(cumulative.At(x, y)) - glm::dvec3(previous.At(x, y));
                blocks[size_t((y / aBlockSize) * stats.mBlocksX + x / aBlockSize)] += value / double(aBlockSize * aBlockSize);
            }
        for (size_t b = 0; b < blocks.size(); b++) {
            stats.mSum[b] += blocks[b];
            stats.mSumSqr[b] += blocks[b] * blocks[b];
        }
        previous = cumulative;
    }
    return stats;
}

} // namespace testutil
