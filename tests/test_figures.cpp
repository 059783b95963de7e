// [figures] The claims of the course figures (docs/figures.md, figures/fig_*.cpp) that can
// be checked quickly at low resolution, one test case per figure (tags [F02], [F04], ...).
// The figure programs print the same claims at publication settings; these tests check
// that the claims hold, with tolerances derived from measured standard errors:
//
//   F02       path tracing: 36 samples per pixel have 1/6 of the RMSE of 1 sample
//   F04       MIS on Veach's plates: as good as the better technique in every region (up to
//             Veach's bound), and the three direct-light modes agree in expectation
//   F05       BPT's path pyramid: the weighted layers of each path length are that length
//             (the sums over all layers, and VCM's stage layers of F15, are already checked
//             in test_integrators.cpp, "Technique layers sum to the image for PT, BPT and VCM")
//   F07       light tracing: black on specular surfaces seen directly, better than path
//             tracing on the caustic of a small light
//   F08, F13  the SDS scene: BPT's mean lacks the light on specular-diffuse-specular paths
//             and its error stays, while VCM's falls
//   F16       VCM within a factor 2 of the better of BPT and PPM on both F16 scenes
//   F18       fitted convergence slopes: -1/2 for PT, BPT and VCM, -1/3 for PPM (alpha = 2/3), with
//             independent numbers; with Sobol points PT converges faster, BPT and VCM reach a
//             lower error, PPM keeps its rate
//
// SCALE. The environment variable SMALLVCM_FIGURE_TEST_SCALE (an integer >= 1, default 1)
// multiplies every resolution and the iteration counts of the renders (references, runs,
// checkpoints), so the same claims can be checked at higher settings:
//   SMALLVCM_FIGURE_TEST_SCALE=2 build/tests/run_tests "[figures]"     (from tests/)
// At scale 1 the whole file took 30 s of CPU time and 45 s of wall time on a shared 2-core
// machine under a load of ~5 (the renders run on every core); the cost grows about as
// scale^3.
//
// HOW THE TOLERANCES ARE MADE. Every compared quantity comes with a standard error (SE)
// measured in the same run: from K independent renders with different seeds (the spread of
// the per-render values), or, where the renders are long, from the spread of the
// per-iteration values (each iteration draws its own random stream, so iterations are
// independent). A claim "A < B" is checked as B - A > 4 SE or "A <= B" as A - B <= 4 SE
// unless a comment says otherwise; where a theory gives an exact expectation the test
// compares with it. The numbers measured while writing the tests are quoted next to each
// bound. Seeds are fixed, so a run is reproducible.
//
// MERGING RADIUS. SmallVCM's 0.003 x scene radius is made for 512x512 images; at 32x32 with
// 1024 light paths per iteration it would catch a photon once per many pixel-iterations. As
// benchmarks/convergence.cpp --quick does, the radius is scaled by the ratio of pixel sizes:
// 0.003 x 512 / width (0.048 at 32x32, 0.096 at 16x16).
//
// Scenes are read from ../scenes/ (the tests run from tests/, as test_util.hpp assumes).
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

using namespace smallvcm;

namespace {

// ------------------------------------------------------------------------------------
// Settings, scenes, renders
// ------------------------------------------------------------------------------------

int FigureTestScale() {
    const char* value = std::getenv("SMALLVCM_FIGURE_TEST_SCALE");
    if (!value || !*value) return 1;
    char* end = nullptr;
    const long scale = std::strtol(value, &end, 10);
    if (*end != '\0' || scale < 1 || scale > 64) return 1;
    return int(scale);
}

Scene LoadFigureScene(const std::string& aFile, int aWidth, int aHeight) {
    Scene scene = LoadGltfScene("../scenes/" + aFile);
    scene.mCamera.SetResolution(aWidth, aHeight);
    scene.Finalize();
    return scene;
}

// SmallVCM's radius factor for 512 pixels across, scaled to this width (see the top).
float ScaledRadiusFactor(int aWidth) { return 0.003f * 512.f / float(aWidth); }

// Single-threaded options: the tests run independent renders in parallel instead.
RenderOptions SerialOptions(Algorithm aAlgorithm, uint64_t aSeed) {
    RenderOptions options;
    options.mAlgorithm = aAlgorithm;
    options.mSeed = aSeed;
    options.mThreads = 1;
    options.mProgress = false;
    return options;
}

// Runs aBody(0) ... aBody(aCount - 1) on every core; the first exception is rethrown here.
// Catch's assertions are not thread-safe, so bodies only compute; tests check afterwards.
void ParallelFor(int aCount, const std::function<void(int)>& aBody) {
    std::atomic<int> next{0};
    std::exception_ptr failure;
    std::mutex failureMutex;
    auto work = [&] {
        for (int job = next++; job < aCount; job = next++) {
            try {
                aBody(job);
            } catch (...) {
                std::lock_guard<std::mutex> lock(failureMutex);
                if (!failure) failure = std::current_exception();
            }
        }
    };
    const int threads = std::max(1, std::min(aCount, int(std::thread::hardware_concurrency())));
    std::vector<std::thread> pool;
    for (int t = 1; t < threads; t++) pool.emplace_back(work);
    work();
    for (std::thread& thread : pool) thread.join();
    if (failure) std::rethrow_exception(failure);
}

// Runs iterations 0 .. aIterations-1 of one renderer exactly as Render() does (iteration i
// draws from IterationRng(seed, i); the merging radius follows the iteration index) and
// after each calls aVisit(i, iteration, estimate): the iteration's own image and the
// running estimate (the mean of the iterations so far).
template <class Visit>
void RunIterations(const Scene& aScene, const RenderOptions& aOptions, int aIterations, Visit&& aVisit) {
    std::unique_ptr<AbstractRenderer> renderer = CreateRenderer(aScene, aOptions);
    Image previousSum(aScene.mCamera.Width(), aScene.mCamera.Height());
    for (int i = 0; i < aIterations; i++) {
        Sampler sampler = IterationSampler(aOptions.mSampler, aOptions.mSeed, i);
        renderer->RunIteration(i, sampler);
        Image sum = renderer->GetFilm().Resolve(1.0);
        Image iteration = sum;
        for (size_t p = 0; p < iteration.mPixels.size(); p++) iteration.mPixels[p] -= previousSum.mPixels[p];
        const Image estimate = renderer->GetFilm().Resolve(1.0 / double(i + 1));
        aVisit(i, iteration, estimate);
        previousSum = std::move(sum);
    }
}

// ------------------------------------------------------------------------------------
// Pixel masks and masked metrics
// ------------------------------------------------------------------------------------

using Mask = std::vector<char>;

int Count(const Mask& aMask) { return int(std::count(aMask.begin(), aMask.end(), char(1))); }

bool IsDeltaMaterial(const Material& aMaterial) { return aMaterial.HasSpecular() && !aMaterial.HasNonSpecular(); }

// Pixels whose whole footprint passes aTest(ray, hit, hitFound): the rays through the four
// corners and the centre. For a convex object (the glass spheres) four corners inside its
// outline put the whole pixel inside.
template <class Test>
Mask PixelsWhoseFootprint(const Scene& aScene, Test&& aTest) {
    const Camera& camera = aScene.mCamera;
    Mask mask(size_t(camera.PixelCount()), 0);
    for (int y = 0; y < camera.Height(); y++)
        for (int x = 0; x < camera.Width(); x++) {
            bool all = true;
            for (const Vec2 offset : {Vec2(0.f, 0.f), Vec2(1.f, 0.f), Vec2(0.f, 1.f), Vec2(1.f, 1.f), Vec2(0.5f, 0.5f)}) {
                const Ray ray = camera.GenerateRay(Vec2(float(x), float(y)) + offset);
                const SurfacePoint hit = aScene.Intersect(ray);
                const bool found = hit.IsValid();
                all = all && aTest(ray, hit, found);
            }
            mask[size_t(y * camera.Width() + x)] = all;
        }
    return mask;
}

Mask PixelsSeeingOnlyDeltaSurfaces(const Scene& aScene) {
    return PixelsWhoseFootprint(aScene, [&](const Ray&, const SurfacePoint& aHit, bool aFound) {
        return aFound && aHit.mLightId < 0 && IsDeltaMaterial(aScene.GetMaterial(aHit.mMaterialId));
    });
}

// Pixels where no part of the footprint sees a light directly: there every estimator uses
// the same technique (the camera ray hits the emitter) and, at 16-32 pixels across, the
// light's jagged outline makes most of the image's error, the same for all of them.
Mask PixelsNotSeeingALight(const Scene& aScene) {
    return PixelsWhoseFootprint(aScene, [](const Ray&, const SurfacePoint& aHit, bool aFound) { return !aFound || aHit.mLightId < 0; });
}

double ChannelMean(const Vec3& aColor) { return (double(aColor.x) + double(aColor.y) + double(aColor.z)) / 3.0; }

double MaskedMean(const Image& aImage, const Mask& aMask) {
    double sum = 0.0;
    for (size_t i = 0; i < aImage.mPixels.size(); i++)
        if (aMask[i]) sum += ChannelMean(aImage.mPixels[i]);
    return sum / double(std::max(1, Count(aMask)));
}

// Mean squared error over the masked pixels and their channels (Rmse()^2 on the mask).
double MaskedMse(const Image& aImage, const Image& aReference, const Mask& aMask) {
    double sum = 0.0;
    for (size_t i = 0; i < aImage.mPixels.size(); i++)
        if (aMask[i]) {
            const glm::dvec3 d = glm::dvec3(aImage.mPixels[i]) - glm::dvec3(aReference.mPixels[i]);
            sum += glm::dot(d, d);
        }
    return sum / (3.0 * double(std::max(1, Count(aMask))));
}

double Mse(const Image& aImage, const Image& aReference) {
    const double rmse = Rmse(aImage, aReference);
    return rmse * rmse;
}

// ------------------------------------------------------------------------------------
// Statistics
// ------------------------------------------------------------------------------------

struct Estimate {
    double mMean = 0.0, mStandardError = 0.0, mDeviation = 0.0;
};

// Mean, its standard error and the standard deviation of independent values.
Estimate Estimated(const std::vector<double>& aValues) {
    Estimate e;
    const double n = double(aValues.size());
    for (double v : aValues) e.mMean += v / n;
    double variance = 0.0;
    for (double v : aValues) variance += (v - e.mMean) * (v - e.mMean) / std::max(1.0, n - 1.0);
    e.mDeviation = std::sqrt(variance);
    e.mStandardError = std::sqrt(variance / n);
    return e;
}

double CombinedError(const Estimate& aA, const Estimate& aB) {
    return std::sqrt(aA.mStandardError * aA.mStandardError + aB.mStandardError * aB.mStandardError);
}

// Least-squares slope of log(y) against log(x).
double LogLogSlope(const std::vector<double>& aX, const std::vector<double>& aY) {
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    const double n = double(aX.size());
    for (size_t i = 0; i < aX.size(); i++) {
        const double x = std::log(aX[i]), y = std::log(aY[i]);
        sx += x; sy += y; sxx += x * x; sxy += x * y;
    }
    return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

// ------------------------------------------------------------------------------------
// References: long renders in two halves with their own seeds, in parallel
// ------------------------------------------------------------------------------------

constexpr uint64_t kReferenceSeedA = 880001, kReferenceSeedB = 880002;

struct Reference {
    Image mImage;                              // the mean of both halves
    std::vector<Image> mHalves;                // the two halves (independent seeds)
    std::vector<std::vector<double>> mSeries;  // per mask: the mask mean of every iteration
};

Reference RenderReference(const Scene& aScene, RenderOptions aOptions, int aIterations,
                          const std::vector<const Mask*>& aMasks = {}) {
    std::vector<Image> halves(2);
    std::vector<std::vector<std::vector<double>>> series(2, std::vector<std::vector<double>>(aMasks.size()));
    ParallelFor(2, [&](int aHalf) {
        RenderOptions options = aOptions;
        options.mThreads = 1;
        options.mProgress = false;
        options.mSeed = aHalf == 0 ? kReferenceSeedA : kReferenceSeedB;
        const int iterations = std::max(1, aIterations / 2);
        RunIterations(aScene, options, iterations, [&](int i, const Image& aIteration, const Image& aEstimate) {
            for (size_t m = 0; m < aMasks.size(); m++) series[size_t(aHalf)][m].push_back(MaskedMean(aIteration, *aMasks[m]));
            if (i == iterations - 1) halves[size_t(aHalf)] = aEstimate;
        });
    });
    Reference reference;
    reference.mHalves = halves;
    reference.mImage = halves[0];
    for (size_t p = 0; p < reference.mImage.mPixels.size(); p++)
        reference.mImage.mPixels[p] = 0.5f * (halves[0].mPixels[p] + halves[1].mPixels[p]);
    for (size_t m = 0; m < aMasks.size(); m++) {
        std::vector<double> both = series[0][m];
        both.insert(both.end(), series[1][m].begin(), series[1][m].end());
        reference.mSeries.push_back(both);
    }
    return reference;
}

} // namespace

// ======================================================================================
// F02: path tracing, 1 vs 36 samples per pixel
// ======================================================================================

TEST_CASE("F02: path tracing's RMSE with 36 samples per pixel is about 1/6 of its RMSE with 1", "[figures][F02]") {
    // Against a reference of N_ref path-tracing iterations (other seeds), an image of n
    // samples has expected MSE = V/n + V/N_ref (V: the per-sample variance summed over the
    // image), so the expected ratio of the MSEs at 1 and 36 samples is exactly
    // (1 + 1/N_ref) / (1/36 + 1/N_ref) (35.4 for N_ref = 2048; RMSE ratio 5.95). That PT
    // converges to the right image (no bias that this would hide) is checked against BPT
    // in test_integrators.cpp. PT's per-image MSE is heavy-tailed (caustics through the
    // glass sphere), so both MSEs are averaged over K renders of 36 iterations each: the
    // 36 single iterations give the 1-sample MSEs, their mean the 36-sample MSE. The SE of
    // the ratio of the two means comes from a jackknife over the K renders.
    // Measured at scale 1: ratio 37.5 +- 2.1 against 35.4 expected (RMSE ratio 6.12 against
    // 5.95); while writing the test, six repetitions with other seeds gave |z| <= 0.9.
    const int scale = FigureTestScale();
    const int size = 32 * scale, renders = 32 * scale, referenceIterations = 2048 * scale, samples = 36;
    const Scene scene = LoadFigureScene("cornell_4_default.gltf", size, size);
    const Reference reference = RenderReference(scene, SerialOptions(Algorithm::kPathTracing, 0), referenceIterations);

    std::vector<double> mseOne(static_cast<size_t>(renders)), mseMany(static_cast<size_t>(renders));
    ParallelFor(renders, [&](int k) {
        double one = 0.0;
        RunIterations(scene, SerialOptions(Algorithm::kPathTracing, uint64_t(2000 + k)), samples,
                      [&](int i, const Image& aIteration, const Image& aEstimate) {
                          one += Mse(aIteration, reference.mImage) / samples;
                          if (i == samples - 1) mseMany[size_t(k)] = Mse(aEstimate, reference.mImage);
                      });
        mseOne[size_t(k)] = one;
    });
    double sumOne = 0.0, sumMany = 0.0;
    for (int k = 0; k < renders; k++) { sumOne += mseOne[size_t(k)]; sumMany += mseMany[size_t(k)]; }
    const double ratio = sumOne / sumMany;
    std::vector<double> leaveOneOut;
    for (int k = 0; k < renders; k++) leaveOneOut.push_back((sumOne - mseOne[size_t(k)]) / (sumMany - mseMany[size_t(k)]));
    const double jackknifeError = Estimated(leaveOneOut).mDeviation * double(renders - 1) / std::sqrt(double(renders));
    const double expected = (1.0 + 1.0 / referenceIterations) / (1.0 / samples + 1.0 / referenceIterations);
    INFO("MSE at 1 sample " << sumOne / renders << ", at 36 samples " << sumMany / renders << ": ratio " << ratio << " +- "
         << jackknifeError << " (RMSE ratio " << std::sqrt(ratio) << "), expected " << expected << " (RMSE ratio "
         << std::sqrt(expected) << ")");
    // The measurement must be able to tell 6 from, say, 5 (MSE ratio 36 from 25).
    CHECK(jackknifeError < 0.1 * expected);
    CHECK(std::abs(ratio - expected) <= 4.0 * jackknifeError);
}

// ======================================================================================
// F04: multiple importance sampling on Veach's plates
// ======================================================================================

TEST_CASE("F04: on Veach's plates MIS is as good as the better of light and BSDF sampling in every region", "[figures][F04]") {
    // Direct light only (paths of 2 segments), path tracing with next-event estimation
    // only, BSDF sampling only, and both combined by MIS (balance and power heuristics).
    // The image is cut into 6 x 4 blocks; in each, the error of each mode is the squared
    // error against a reference (MIS, balance, other seeds), summed over the block's
    // pixels and channels, averaged over K renders; its SE is the spread over the renders.
    //
    // Why the error and not the sample variance: where a technique is hopeless its
    // estimate is carried by samples so rare that K x n samples miss them. Light sampling
    // of the sharpest plate (Phong exponent 10000) reflecting the largest light returns
    // ~1e4 with probability ~1e-5 and 0 otherwise, so its images are black where the
    // highlight is, while the per-pixel variance measured from them is SMALLER than MIS's
    // (14.8 against 24.8 in block (5,0) when tried). The error against the reference
    // counts the missing highlight.
    //
    // The bound: the balance heuristic is not always strictly better than the best single
    // technique. Veach (1997, theorem 9.2) bounds its variance by that of ANY other
    // combination of the same samples (e.g. the light sample alone) plus
    // (1/min_i n_i - 1/sum_i n_i) mu^2 = mu^2 / 2 for one sample of each technique, mu the
    // pixel's value. For an image of n samples that adds sum(mu^2) / (2n) to the block's
    // error (with mu from the reference; mu^2 <= the mean of mu(x)^2 over the pixel, so this
    // is the smaller, stricter allowance). Veach proves the bound for the balance
    // heuristic; the power heuristic is held to the same one. Check:
    //   error(MIS) - error(better technique) <= sum(mu^2) / (2n) + 4 SE.
    // Measured at scale 1 (K = 8): MIS is above the better technique in a few blocks, by
    // 0.1-10% (z <= 0.7), and by 65% (z = 1.2, SE 30%) in block (0,1) (column, row), whose
    // error is dominated by the highlight of the smallest, brightest light on the sharpest
    // plate, where BSDF sampling is nearly perfect; elsewhere MIS is better than
    // both (down to 0.37 of the better technique's error, block (5,3)). A broken
    // combination (e.g. weights 1/2 and 1/2 instead of MIS) would put a share of the worse
    // technique's error, 3x to 2000x the better one's in these blocks, into the sum.
    //
    // Agreement in expectation (a check of RenderOptions::mDirectLight): per block and
    // channel, |mean difference| < 5 SE between the power and balance heuristics everywhere,
    // and between each single technique and MIS in the blocks where that technique is the
    // better one. Where it is the worse one its mean is carried by the rare samples above
    // and cannot be measured with this budget (light sampling's mean in block (5,0) was
    // 100 "SE" too low: that is the figure's point, not a bug). 5 SE over ~150 z-values
    // keeps a false alarm near 1e-4 for normal errors.
    const int scale = FigureTestScale();
    const int width = 96 * scale, height = 64 * scale, blocksX = 6, blocksY = 4, blockSize = 16 * scale;
    const int renders = 8, iterations = 32 * scale, referenceIterations = 512 * scale;
    const Scene scene = LoadFigureScene("veach_plates.gltf", width, height);
    RenderOptions referenceOptions = SerialOptions(Algorithm::kPathTracing, 0);
    referenceOptions.mMaxPathLength = 2;
    const Reference reference = RenderReference(scene, referenceOptions, referenceIterations);

    struct Mode {
        const char* mName;
        DirectLightSampling mDirectLight;
        MisHeuristic mHeuristic;
    };
    const Mode modes[] = {{"light sampling", DirectLightSampling::kLightOnly, MisHeuristic::kBalance},
                          {"BSDF sampling", DirectLightSampling::kBsdfOnly, MisHeuristic::kBalance},
                          {"MIS (balance)", DirectLightSampling::kMis, MisHeuristic::kBalance},
                          {"MIS (power)", DirectLightSampling::kMis, MisHeuristic::kPower}};
    const int modeCount = 4, blockCount = blocksX * blocksY;
    // [mode][render][block] squared error, [mode][render][block * 3 + channel] mean value
    std::vector<std::vector<std::vector<double>>> error(modeCount, std::vector<std::vector<double>>(renders, std::vector<double>(blockCount, 0.0)));
    std::vector<std::vector<std::vector<double>>> mean(modeCount, std::vector<std::vector<double>>(renders, std::vector<double>(3 * blockCount, 0.0)));
    ParallelFor(modeCount * renders, [&](int aJob) {
        const int m = aJob / renders, k = aJob % renders;
        RenderOptions options = SerialOptions(Algorithm::kPathTracing, uint64_t(4000 + k));
        options.mMaxPathLength = 2;
        options.mDirectLight = modes[m].mDirectLight;
        options.mMisHeuristic = modes[m].mHeuristic;
        options.mIterations = iterations;
        const Image image = Render(scene, options).mImage;
        for (int y = 0; y < height; y++)
            for (int x = 0; x < width; x++) {
                const int b = (y / blockSize) * blocksX + x / blockSize;
                const glm::dvec3 d = glm::dvec3(image.At(x, y)) - glm::dvec3(reference.mImage.At(x, y));
                error[size_t(m)][size_t(k)][size_t(b)] += glm::dot(d, d);
                for (int c = 0; c < 3; c++) mean[size_t(m)][size_t(k)][size_t(3 * b + c)] += image.At(x, y)[c] / double(blockSize * blockSize);
            }
    });
    auto across = [&](const std::vector<std::vector<std::vector<double>>>& aData, int aMode, int aIndex) {
        std::vector<double> values;
        for (int k = 0; k < renders; k++) values.push_back(aData[size_t(aMode)][size_t(k)][size_t(aIndex)]);
        return Estimated(values);
    };

    int comparedMeans = 0;
    for (int b = 0; b < blockCount; b++) {
        Estimate blockError[modeCount];
        for (int m = 0; m < modeCount; m++) blockError[m] = across(error, m, b);
        const int better = blockError[0].mMean <= blockError[1].mMean ? 0 : 1;
        double allowance = 0.0;  // Veach: sum of mu^2 / (2n) over the block's pixels and channels
        for (int y = (b / blocksX) * blockSize; y < (b / blocksX + 1) * blockSize; y++)
            for (int x = (b % blocksX) * blockSize; x < (b % blocksX + 1) * blockSize; x++) {
                const glm::dvec3 mu(reference.mImage.At(x, y));
                allowance += glm::dot(mu, mu) / (2.0 * iterations);
            }
        for (int m : {2, 3}) {
            const double excess = blockError[m].mMean - blockError[better].mMean;
            const double se = CombinedError(blockError[m], blockError[better]);
            INFO("block (" << b % blocksX << ", " << b / blocksX << "): " << modes[m].mName << " error " << blockError[m].mMean
                 << " +- " << blockError[m].mStandardError << ", " << modes[better].mName << " (the better) "
                 << blockError[better].mMean << " +- " << blockError[better].mStandardError << ", the other "
                 << blockError[1 - better].mMean << "; ratio " << blockError[m].mMean / blockError[better].mMean
                 << ", Veach's allowance " << allowance);
            CHECK(excess <= allowance + 4.0 * se);
        }
        // Agreement in expectation, per channel.
        for (int c = 0; c < 3; c++) {
            const Estimate balance = across(mean, 2, 3 * b + c);
            for (int m : {better, 3}) {
                const Estimate other = across(mean, m, 3 * b + c);
                const double difference = other.mMean - balance.mMean, se = CombinedError(other, balance);
                INFO("block (" << b % blocksX << ", " << b / blocksX << ") channel " << c << ": " << modes[m].mName << " mean "
                     << other.mMean << " +- " << other.mStandardError << ", MIS (balance) " << balance.mMean << " +- "
                     << balance.mStandardError);
                if (se == 0.0) CHECK(std::abs(difference) <= 1e-6);
                else CHECK(std::abs(difference) < 5.0 * se);
                comparedMeans++;
            }
        }
    }
    CHECK(comparedMeans == blockCount * 3 * 2);
}

// ======================================================================================
// F05: the path pyramid of BPT
// ======================================================================================

TEST_CASE("F05: each length's weighted BPT pyramid layers are exactly that length's part of the image", "[figures][F05]") {
    // test_integrators.cpp checks that ALL weighted pyramid layers (s<S>_t<T> for lengths
    // 1..5, plus longer_than_5) sum to BPT's image, and VCM's five stage layers (F15) to
    // VCM's. What the figure adds is the rows: the weighted images of ONE length sum to that
    // length's part of the image. Rendering with min = max path length = L gives exactly
    // that part as the image, with the integrator's own path-length test (not the
    // pyramid's S + T - 1): the length-L layers must sum to it (float rounding of the
    // resolve: 1e-5 relative + 1e-7) and every other layer must stay exactly zero. Length 1
    // (the light seen directly) also checks that no 2-segment path (e.g. a light-tracing
    // connection of the first light vertex) is added when the maximum is 1.
    const int scale = FigureTestScale();
    const Scene scene = LoadFigureScene("cornell_4_default.gltf", 24 * scale, 24 * scale);
    for (int length = 1; length <= 7; length++) {
        RenderOptions options = SerialOptions(Algorithm::kBidirectionalPathTracing, uint64_t(5000 + length));
        options.mThreads = 0;
        options.mIterations = 2 * scale;
        options.mMinPathLength = length;
        options.mMaxPathLength = length;
        options.mTechniqueLayers = true;
        const RenderResult result = Render(scene, options);
        Image sum(result.mImage.mWidth, result.mImage.mHeight);
        int row = 0, others = 0;
        bool othersZero = true;
        for (const auto& layer : result.mLayers) {
            const std::string& name = layer.first;
            int s = -1, t = -1;
            const bool pyramid = std::sscanf(name.c_str(), "s%d_t%d", &s, &t) == 2 && name.find("unweighted") == std::string::npos;
            const bool longer = name == "longer_than_5";
            if (!pyramid && !longer) continue;
            const bool thisRow = pyramid ? s + t - 1 == length : length > 5;
            if (thisRow) {
                row++;
                for (size_t i = 0; i < sum.mPixels.size(); i++) sum.mPixels[i] += layer.second.mPixels[i];
            } else {
                others++;
                for (const Vec3& p : layer.second.mPixels) othersZero = othersZero && p == Vec3(0.f);
            }
        }
        double worst = 0.0, total = 0.0;
        for (size_t i = 0; i < sum.mPixels.size(); i++)
            for (int c = 0; c < 3; c++) {
                const double image = result.mImage.mPixels[i][c];
                total += image;
                worst = std::max(worst, std::abs(double(sum.mPixels[i][c]) - image) / (1e-5 * std::abs(image) + 1e-7));
            }
        INFO("path length " << length << ": " << row << " layers in the row, " << others << " others; worst sum error "
             << worst << " (1 = the tolerance); image total " << total);
        CHECK(row == (length <= 5 ? length + 1 : 1));
        CHECK(others > 0);
        CHECK(total > 0.0);  // every length carries light in this scene, so the check has something to sum
        CHECK(worst <= 1.0);
        CHECK(othersZero);
    }
}

// ======================================================================================
// F07: tracing paths from the lights
// ======================================================================================

TEST_CASE("F07: light tracing is black on specular surfaces seen directly and beats path tracing on the caustic", "[figures][F07]") {
    // scenes/caustic_glass_sphere.gltf: a large glass sphere under the small area light.
    // (1) Pixels whose whole footprint sees the glass first: light tracing connects light
    //     vertices to the camera only from non-specular surfaces, so these pixels must be
    //     exactly 0 in every light-tracing render, while the reference (BPT) shows the room
    //     through the glass: its mean there must exceed 10 SE (SE from its iterations).
    // (2) Caustic pixels: the floor (footprint on upward-facing diffuse surfaces) where the
    //     light's centre is seen only through the glass: the sphere's shadow, into which the
    //     light arrives focused by the glass. There light tracing's error must be lower than
    //     path tracing's: MSE(pt) - MSE(lt) > 4 SE, both over K renders. Equal number of
    //     paths (one light path or one camera path per pixel and iteration), not equal time:
    //     a time budget would make the test depend on the machine's load; the two cost
    //     about the same per iteration here (1.2 and 1.5 ms at 32x32 when measured).
    // Measured at scale 1: 148 glass pixels, the reference's mean there 0.223 +- 0.0023;
    // 112 caustic pixels, MSE lt 0.00155 +- 0.00008 vs pt 0.089 +- 0.014 (ratio 0.017,
    // z = 6.2).
    const int scale = FigureTestScale();
    const int size = 32 * scale, renders = 16, iterations = 16 * scale, referenceIterations = 1024 * scale;
    const Scene scene = LoadFigureScene("caustic_glass_sphere.gltf", size, size);

    const Mask glass = PixelsSeeingOnlyDeltaSurfaces(scene);
    Vec3 lightCentre(0.f);  // the area-weighted centroid of the emitting triangles (the light's two halves)
    {
        float area = 0.f;
        for (int l = 0; l < scene.LightCount(); l++) {
            const Light& light = scene.GetLight(l);
            REQUIRE(light.mType == LightType::kArea);
            for (size_t t = 0; t < light.mTriangleP0.size(); t++) {
                const float a = 0.5f * glm::length(glm::cross(light.mTriangleE1[t], light.mTriangleE2[t]));
                lightCentre += a * (light.mTriangleP0[t] + (light.mTriangleE1[t] + light.mTriangleE2[t]) / 3.f);
                area += a;
            }
        }
        REQUIRE(area > 0.f);
        lightCentre /= area;
    }
    const Mask floor = PixelsWhoseFootprint(scene, [&](const Ray&, const SurfacePoint& aHit, bool aFound) {
        return aFound && aHit.mLightId < 0 && aHit.GeometricNormal().z > 0.9f && !IsDeltaMaterial(scene.GetMaterial(aHit.mMaterialId));
    });
    Mask caustic(floor.size(), 0);
    for (int pixel = 0; pixel < scene.mCamera.PixelCount(); pixel++) {
        if (!floor[size_t(pixel)]) continue;
        const Ray ray = scene.mCamera.GenerateRay(Vec2(float(pixel % size) + 0.5f, float(pixel / size) + 0.5f));
        const SurfacePoint hit = scene.Intersect(ray);
        const Vec3 point = ray.mOrigin + ray.mDirection * hit.mDist;
        const Vec3 toLight = lightCentre - point;
        const SurfacePoint blocker = scene.Intersect(scene.SpawnRay(point, glm::normalize(toLight)));
        caustic[size_t(pixel)] = blocker.IsValid() &&
                                 blocker.mDist < glm::length(toLight) && IsDeltaMaterial(scene.GetMaterial(blocker.mMaterialId));
    }
    REQUIRE(Count(glass) > 10 * scale * scale);
    REQUIRE(Count(caustic) > 10 * scale * scale);

    const Reference reference = RenderReference(scene, SerialOptions(Algorithm::kBidirectionalPathTracing, 0), referenceIterations, {&glass});
    std::vector<double> ltError(static_cast<size_t>(renders)), ptError(static_cast<size_t>(renders)), ltOnGlass(static_cast<size_t>(renders));
    ParallelFor(2 * renders, [&](int aJob) {
        const bool lightTracing = aJob < renders;
        const int k = aJob % renders;
        RenderOptions options = SerialOptions(lightTracing ? Algorithm::kLightTracing : Algorithm::kPathTracing, uint64_t(7000 + k));
        options.mIterations = iterations;
        const Image image = Render(scene, options).mImage;
        (lightTracing ? ltError : ptError)[size_t(k)] = MaskedMse(image, reference.mImage, caustic);
        if (lightTracing) {
            double sum = 0.0;
            for (size_t i = 0; i < image.mPixels.size(); i++)
                if (glass[i]) sum += double(image.mPixels[i].x) + double(image.mPixels[i].y) + double(image.mPixels[i].z);
            ltOnGlass[size_t(k)] = sum;
        }
    });

    const Estimate referenceOnGlass = Estimated(reference.mSeries[0]);
    double ltGlassTotal = 0.0;
    for (double v : ltOnGlass) ltGlassTotal += v;
    INFO(Count(glass) << " pixels see only glass: light tracing's total there " << ltGlassTotal << ", the reference's mean "
         << referenceOnGlass.mMean << " +- " << referenceOnGlass.mStandardError);
    CHECK(ltGlassTotal == 0.0);
    CHECK(referenceOnGlass.mMean > 10.0 * referenceOnGlass.mStandardError);

    const Estimate lt = Estimated(ltError), pt = Estimated(ptError);
    INFO(Count(caustic) << " caustic pixels, " << iterations << " iterations: MSE light tracing " << lt.mMean << " +- "
         << lt.mStandardError << ", path tracing " << pt.mMean << " +- " << pt.mStandardError << " (ratio " << lt.mMean / pt.mMean << ")");
    CHECK(pt.mMean - lt.mMean > 4.0 * CombinedError(lt, pt));
}

// ======================================================================================
// F08, F13: the SDS scene
// ======================================================================================

TEST_CASE("F08, F13: on the SDS scene BPT's error stays where VCM's falls", "[figures][F08][F13]") {
    // scenes/sds_glass_sphere.gltf: a point light and a large glass sphere; the caustic the
    // sphere casts is seen through the sphere, so the light in those pixels travels on
    // specular-diffuse-specular (SDS) paths, which no BPT technique samples (no camera path
    // hits a point light, no light path reaches the pinhole through glass, a connection
    // needs two non-specular ends). VCM's merging does. SDS pixels: the whole footprint
    // sees the glass. Reference: VCM with other seeds (BPT cannot converge here).
    // Over K renders of 4n iterations, with the RMSE on the SDS pixels at n and at 4n:
    //   (1) BPT's mean over the SDS pixels is below the reference's by more than 4 SE (SEs
    //       from the per-iteration values of both): the light it misses;
    //   (2) BPT's RMSE ratio from n to 4n stays far below sqrt(4) = 2: below 4^0.25 = 1.41
    //       by more than 4 SE. 1.41 is the slowest ratio of a consistent estimator here:
    //       VCM with radius alpha = 0.75 when its bias dominates (bias ~ r^2 ~ N^-0.25;
    //       its merging variance gives 4^0.375 = 1.68, its connections 2);
    //   (3) VCM's ratio exceeds 1 by more than 4 SE, and is consistent with >= 1.41 (not
    //       below it by more than 4 SE).
    // Measured at scale 1 (K = 8, n = 16): SDS-pixel mean reference 2.36 +- 0.03, BPT
    // 0.200 +- 0.002 (92% of the light missing); RMSE ratio BPT 1.002 +- 0.001, VCM 1.79 +-
    // 0.13 (6 SE above 1). VCM's own mean after 64 iterations is 2.33 +- 0.03 (not
    // checked: with other seeds it was 1.5% above the reference, z ~ 2-3, from its larger
    // radius early in the schedule).
    const int scale = FigureTestScale();
    const int size = 32 * scale, renders = 8, n = 16 * scale, referenceIterations = 1024 * scale;
    const Scene scene = LoadFigureScene("sds_glass_sphere.gltf", size, size);
    const Mask sds = PixelsSeeingOnlyDeltaSurfaces(scene);
    REQUIRE(Count(sds) > size * size / 20);
    const float radiusFactor = ScaledRadiusFactor(size);

    RenderOptions referenceOptions = SerialOptions(Algorithm::kVertexConnectionMerging, 0);
    referenceOptions.mRadiusFactor = radiusFactor;
    const Reference reference = RenderReference(scene, referenceOptions, referenceIterations, {&sds});

    struct Run {
        std::vector<double> mIterationMeans;  // the SDS-pixel mean of every iteration
        double mErrorAtN = 0.0, mErrorAt4N = 0.0;
    };
    const Algorithm algorithms[] = {Algorithm::kBidirectionalPathTracing, Algorithm::kVertexConnectionMerging};
    std::vector<std::vector<Run>> runs(2, std::vector<Run>(size_t(renders)));
    ParallelFor(2 * renders, [&](int aJob) {
        const int a = aJob / renders, k = aJob % renders;
        RenderOptions options = SerialOptions(algorithms[a], uint64_t(8000 + k));
        options.mRadiusFactor = radiusFactor;
        Run& run = runs[size_t(a)][size_t(k)];
        RunIterations(scene, options, 4 * n, [&](int i, const Image& aIteration, const Image& aEstimate) {
            run.mIterationMeans.push_back(MaskedMean(aIteration, sds));
            if (i == n - 1) run.mErrorAtN = std::sqrt(MaskedMse(aEstimate, reference.mImage, sds));
            if (i == 4 * n - 1) run.mErrorAt4N = std::sqrt(MaskedMse(aEstimate, reference.mImage, sds));
        });
    });
    auto pooledMean = [&](int a) {
        std::vector<double> all;
        for (const Run& run : runs[size_t(a)]) all.insert(all.end(), run.mIterationMeans.begin(), run.mIterationMeans.end());
        return Estimated(all);
    };
    auto errorRatio = [&](int a) {
        std::vector<double> ratios;
        for (const Run& run : runs[size_t(a)]) ratios.push_back(run.mErrorAtN / run.mErrorAt4N);
        return Estimated(ratios);
    };
    const Estimate truth = Estimated(reference.mSeries[0]), bpt = pooledMean(0), vcm = pooledMean(1);
    const Estimate bptRatio = errorRatio(0), vcmRatio = errorRatio(1);
    const double slowestConsistent = std::pow(4.0, 0.25);
    INFO(Count(sds) << " SDS pixels. Mean there: reference (VCM, " << referenceIterations << " iterations) " << truth.mMean
         << " +- " << truth.mStandardError << ", BPT " << bpt.mMean << " +- " << bpt.mStandardError << ", VCM " << vcm.mMean
         << " +- " << vcm.mStandardError << ". RMSE ratio from " << n << " to " << 4 * n << " iterations: BPT "
         << bptRatio.mMean << " +- " << bptRatio.mStandardError << ", VCM " << vcmRatio.mMean << " +- " << vcmRatio.mStandardError);
    CHECK(truth.mMean - bpt.mMean > 4.0 * CombinedError(truth, bpt));
    CHECK(slowestConsistent - bptRatio.mMean > 4.0 * bptRatio.mStandardError);
    CHECK(vcmRatio.mMean - 1.0 > 4.0 * vcmRatio.mStandardError);
    CHECK(slowestConsistent - vcmRatio.mMean <= 4.0 * vcmRatio.mStandardError);
}

// ======================================================================================
// F16: BPT, PPM and VCM on an SDS scene and a diffuse scene
// ======================================================================================

TEST_CASE("F16: VCM's error is within a factor 2 of the better of BPT and PPM on both scenes", "[figures][F16]") {
    // Equal numbers of iterations (the figure's equal-time version, whose outcome depends
    // on the machine, is figures/fig_vcm.cpp). Per scene, K renders of n iterations of
    // each method; the error is the MSE over the pixels that do not see the light directly
    // (see PixelsNotSeeingALight) against a reference: VCM on the SDS scene (BPT cannot
    // converge there), BPT on the diffuse box. The reference's own noise adds the same
    // amount to every method's MSE, so it may be short (512 iterations).
    // Why a factor 2 (in RMSE, 4 in MSE): the claim is "close to the better", not "better".
    // At equal iterations VCM runs a superset of both methods' techniques and weights them
    // by MIS, so its variance can exceed the better method's only by MIS's overhead
    // (Veach's bound, see F04) and its merging bias; a factor 2 leaves room for that at
    // any scale, while a VCM that lost the better method's strength on a scene (the worse
    // method's RMSE is 2x (diffuse) and 7x (SDS) the better one's here) would fail.
    // Check: MSE(VCM) - 4 MSE(better) <= 4 SE, the SE from the K paired differences (render
    // k of every method has the same seed).
    // Also the other half of the figure's point, each of the two others fails on one
    // scene: MSE(BPT) - MSE(VCM) > 4 SE on the SDS scene (BPT misses the SDS light, F08),
    // MSE(PPM) - MSE(VCM) > 4 SE on the diffuse box (photon density estimation blurs and is
    // noisier where connections work well).
    // Measured at scale 1 (K = 8, n = 32), RMSE: SDS scene BPT 0.85, PPM 0.175, VCM 0.150
    // (VCM / better = 0.86); diffuse box BPT 0.0197, PPM 0.039, VCM 0.0208 (1.06).
    const int scale = FigureTestScale();
    const int size = 32 * scale, renders = 8, iterations = 32 * scale, referenceIterations = 512 * scale;
    const float radiusFactor = ScaledRadiusFactor(size);
    const Algorithm methods[] = {Algorithm::kBidirectionalPathTracing, Algorithm::kProgressivePhotonMapping,
                                 Algorithm::kVertexConnectionMerging};
    struct SceneCase {
        const char* mFile;
        Algorithm mReference;
    };
    for (const SceneCase& sceneCase : {SceneCase{"sds_glass_sphere.gltf", Algorithm::kVertexConnectionMerging},
                                       SceneCase{"diffuse_box.gltf", Algorithm::kBidirectionalPathTracing}}) {
        const Scene scene = LoadFigureScene(sceneCase.mFile, size, size);
        const Mask measured = PixelsNotSeeingALight(scene);
        RenderOptions referenceOptions = SerialOptions(sceneCase.mReference, 0);
        referenceOptions.mRadiusFactor = radiusFactor;
        const Reference reference = RenderReference(scene, referenceOptions, referenceIterations);
        std::vector<std::vector<double>> mse(3, std::vector<double>(size_t(renders)));
        ParallelFor(3 * renders, [&](int aJob) {
            const int m = aJob / renders, k = aJob % renders;
            RenderOptions options = SerialOptions(methods[m], uint64_t(16000 + k));
            options.mRadiusFactor = radiusFactor;
            options.mIterations = iterations;
            mse[size_t(m)][size_t(k)] = MaskedMse(Render(scene, options).mImage, reference.mImage, measured);
        });
        const Estimate bpt = Estimated(mse[0]), ppm = Estimated(mse[1]), vcm = Estimated(mse[2]);
        const bool bptBetter = bpt.mMean <= ppm.mMean;
        const Estimate& better = bptBetter ? bpt : ppm;
        std::vector<double> margin;  // per render k: MSE(VCM) - 4 MSE(better), same seeds paired
        for (int k = 0; k < renders; k++) margin.push_back(mse[2][size_t(k)] - 4.0 * (bptBetter ? mse[0] : mse[1])[size_t(k)]);
        const Estimate excess = Estimated(margin);
        INFO(sceneCase.mFile << ", " << Count(measured) << " pixels, " << iterations << " iterations: RMSE BPT "
             << std::sqrt(bpt.mMean) << ", PPM " << std::sqrt(ppm.mMean) << ", VCM " << std::sqrt(vcm.mMean) << "; VCM / "
             << (bptBetter ? "BPT" : "PPM") << " = " << std::sqrt(vcm.mMean / better.mMean) << "; MSE(VCM) - 4 MSE(better) = "
             << excess.mMean << " +- " << excess.mStandardError);
        CHECK(excess.mMean <= 4.0 * excess.mStandardError);
        const Estimate& worse = std::string(sceneCase.mFile) == "diffuse_box.gltf" ? ppm : bpt;
        CHECK(worse.mMean - vcm.mMean > 4.0 * CombinedError(worse, vcm));
    }
}

// ======================================================================================
// F18: convergence rates
// ======================================================================================


TEST_CASE("F18: fitted convergence slopes are near -1/2 for PT, BPT and VCM and near -1/3 for PPM; Sobol points make PT, BPT and VCM converge faster", "[figures][F18]") {
    // RMSE against a reference (BPT, 4096 iterations, other seeds) at 1, 2, 4, ..., 256
    // iterations, on scenes/diffuse_box.gltf at 16x16 (no specular surface, so no caustic
    // fireflies: on cornell_4 single-run slopes scatter with SD 0.16); pixels that see the
    // light are left out (the same for every method, see F16), so what is measured is the
    // diffuse region. Slope: least squares of log RMSE against log iterations, per
    // render; K renders per method.
    // Rates: BPT and VCM are unbiased or nearly so: RMSE ~ N^-1/2. PPM with radius
    // r_i ~ i^((alpha-1)/2): variance ~ N^-alpha, squared bias ~ r^4 ~ N^(2(alpha-1)); with
    // alpha = 2/3 both are ~ N^-2/3, so RMSE ~ N^-1/3 whichever dominates (with the
    // library's alpha = 0.75 it lies between N^-0.375 and N^-0.25: measured -0.387). VCM
    // keeps alpha = 0.75 (its merging carries little of this scene).
    // Margin: |mean slope - rate| <= 0.05. Measured at scale 1 (K = 6): BPT -0.488 +- 0.007
    // (SD per render 0.017), VCM -0.486 +- 0.008 (0.021), PPM -0.362 +- 0.006 (0.015); with
    // 8 other seeds: -0.497, -0.486, -0.356. PPM's fit over
    // 8..1024 iterations gives -0.337 (4 renders), so its offset of 0.02-0.03 comes from
    // the finite range of the fit, not from noise. 0.05 covers that offset plus ~3 SE of
    // the mean of K = 6 renders and is under a third of the gap between the two rates
    // (0.167): a method converging at the other rate fails. The test also requires
    // SE <= 0.0125 (the band >= 4 SE wide). The same margin holds the two rates added with
    // the sampler dimension, for the same reasons: PT with independent numbers is plain
    // Monte Carlo like BPT (measured -0.494 +- 0.004), and PPM with Sobol points keeps its
    // radius's rate, -1/3 with the same finite-range offset as with independent numbers
    // (measured -0.351 +- 0.006; docs/performance.md, "Samplers").
    //
    // THE SAMPLER. The same methods with Owen-scrambled Sobol points (--sampler sobol, the
    // same seeds). Sobol points stratify a pixel's camera sub-paths across iterations, and
    // the light sub-paths of all iterations together (one sequence, see the header's
    // Sampler), while a pixel connects to one light sub-path per iteration paired at
    // random: what a camera sub-path alone finds (PT, and BPT's camera-side techniques)
    // converges faster than N^-1/2, and light tracing and merging, which sum over all
    // light sub-paths, a little faster too. So the claims are, per method:
    //   * PT, BPT, VCM: the slope is steeper than with independent numbers, by more than
    //     4 SE of the difference (the SE from the run-to-run spread of the K slopes of
    //     each), and BPT's and VCM's MSE at the last checkpoint is lower, by more than 4 SE;
    //   * PPM: its rate is set by the radius shrinkage, so it stays near -1/3 within the
    //     same margin as above, and its error is not claimed lower.
    // The numbers measured are in docs/performance.md ("Samplers"). These comparisons fit
    // the estimator's own error: the reference's noise on the measured pixels (from its
    // two halves) is subtracted from each MSE before the fit, for both samplers alike;
    // with Sobol points it is at most an eighth of the error at the last checkpoint.
    const int scale = FigureTestScale();
    const int size = 16 * scale, renders = 6, referenceIterations = 4096 * scale;
    int lastCheckpoint = 1;
    while (lastCheckpoint < 256 * scale) lastCheckpoint *= 2;
    const Scene scene = LoadFigureScene("diffuse_box.gltf", size, size);
    const Mask measured = PixelsNotSeeingALight(scene);
    const Reference reference = RenderReference(scene, SerialOptions(Algorithm::kBidirectionalPathTracing, 0), referenceIterations);
    // Var(reference) = E|A - B|^2 / 4 for its independent halves A and B.
    const double referenceNoise2 = MaskedMse(reference.mHalves[0], reference.mHalves[1], measured) / 4.0;

    struct Method {
        Algorithm mAlgorithm;
        SamplerType mSampler;
        float mAlpha;
        double mRate;
    };
    const Algorithm kPt = Algorithm::kPathTracing, kBpt = Algorithm::kBidirectionalPathTracing,
                    kVcm = Algorithm::kVertexConnectionMerging, kPpm = Algorithm::kProgressivePhotonMapping;
    const SamplerType kIndependent = SamplerType::kIndependent, kSobol = SamplerType::kSobol;
    const std::vector<Method> methods = {{kBpt, kIndependent, 0.75f, -0.5}, {kVcm, kIndependent, 0.75f, -0.5},
                                         {kPpm, kIndependent, 2.f / 3.f, -1.0 / 3.0}, {kPt, kIndependent, 0.75f, -0.5},
                                         {kBpt, kSobol, 0.75f, -0.5}, {kVcm, kSobol, 0.75f, -0.5},
                                         {kPpm, kSobol, 2.f / 3.f, -1.0 / 3.0}, {kPt, kSobol, 0.75f, -0.5}};
    const size_t methodCount = methods.size();
    std::vector<std::vector<double>> slopes(methodCount, std::vector<double>(size_t(renders), 0.0));
    std::vector<std::vector<double>> ownSlopes = slopes, lastOwnMse = slopes, ownCheckpoints = slopes;
    ParallelFor(int(methodCount) * renders, [&](int aJob) {
        const size_t m = size_t(aJob / renders), k = size_t(aJob % renders);
        RenderOptions options = SerialOptions(methods[m].mAlgorithm, uint64_t(18000 + k));
        options.mSampler = methods[m].mSampler;
        options.mRadiusFactor = ScaledRadiusFactor(size);
        options.mRadiusAlpha = methods[m].mAlpha;
        std::vector<double> iterations, rmse, ownIterations, ownRmse;
        double lastMse = 0.0;
        RunIterations(scene, options, lastCheckpoint, [&](int i, const Image&, const Image& aEstimate) {
            const int done = i + 1;
            if ((done & (done - 1)) != 0) return;  // checkpoints at powers of two
            const double mse = MaskedMse(aEstimate, reference.mImage, measured);
            iterations.push_back(done);
            rmse.push_back(std::sqrt(mse));
            lastMse = mse;
            // The own error is fitted only where it is at least half the reference's noise^2:
            // below, the subtraction leaves mostly the reference's noise (as fig_convergence).
            if (mse - referenceNoise2 >= 0.5 * referenceNoise2) {
                ownIterations.push_back(done);
                ownRmse.push_back(std::sqrt(mse - referenceNoise2));
            }
        });
        slopes[m][k] = LogLogSlope(iterations, rmse);
        ownSlopes[m][k] = LogLogSlope(ownIterations, ownRmse);
        ownCheckpoints[m][k] = double(ownIterations.size());
        lastOwnMse[m][k] = lastMse - referenceNoise2;
    });
    auto find = [&](Algorithm aAlgorithm, SamplerType aSampler) {
        for (size_t m = 0; m < methodCount; m++)
            if (methods[m].mAlgorithm == aAlgorithm && methods[m].mSampler == aSampler) return m;
        return methodCount;
    };
    // The rates with independent numbers (and PPM's with both samplers).
    for (size_t m = 0; m < methodCount; m++) {
        if (methods[m].mSampler == kSobol && methods[m].mAlgorithm != kPpm) continue;
        const Estimate slope = Estimated(slopes[m]);
        INFO(AlgorithmShortName(methods[m].mAlgorithm) << " " << SamplerName(methods[m].mSampler) << " (alpha "
             << methods[m].mAlpha << "): mean slope " << slope.mMean << " +- " << slope.mStandardError << " (SD per render "
             << slope.mDeviation << "), expected " << methods[m].mRate);
        CHECK(slope.mStandardError <= 0.0125);
        CHECK(std::abs(slope.mMean - methods[m].mRate) <= 0.05);
    }
    // Sobol against independent, method by method (own error, see THE SAMPLER). Every
    // render's own-error fit has at least 6 of its 9 checkpoints, and at the last one the
    // own MSE is at least half the reference's noise^2: else the comparison would measure
    // the reference.
    for (size_t m = 0; m < methodCount; m++)
        for (int k = 0; k < renders; k++) {
            INFO(AlgorithmShortName(methods[m].mAlgorithm) << " " << SamplerName(methods[m].mSampler) << " render " << k);
            CHECK(ownCheckpoints[m][size_t(k)] >= 6.0);
            CHECK(lastOwnMse[m][size_t(k)] >= 0.5 * referenceNoise2);
        }
    for (Algorithm algorithm : {kPt, kBpt, kVcm, kPpm}) {
        const size_t a = find(algorithm, kIndependent), b = find(algorithm, kSobol);
        const Estimate independentSlope = Estimated(ownSlopes[a]), sobolSlope = Estimated(ownSlopes[b]);
        const Estimate independentMse = Estimated(lastOwnMse[a]), sobolMse = Estimated(lastOwnMse[b]);
        const double slopeError = CombinedError(independentSlope, sobolSlope);
        INFO(AlgorithmShortName(algorithm) << ": own-error slope sobol " << sobolSlope.mMean << " +- "
             << sobolSlope.mStandardError << ", independent " << independentSlope.mMean << " +- "
             << independentSlope.mStandardError << "; own MSE at " << lastCheckpoint << " iterations sobol " << sobolMse.mMean
             << " +- " << sobolMse.mStandardError << ", independent " << independentMse.mMean << " +- "
             << independentMse.mStandardError << " (reference noise^2 " << referenceNoise2 << ")");
        if (algorithm == kPpm) continue;
        CHECK(independentSlope.mMean - sobolSlope.mMean > 4.0 * slopeError);
        if (algorithm == kBpt || algorithm == kVcm)
            CHECK(independentMse.mMean - sobolMse.mMean > 4.0 * CombinedError(independentMse, sobolMse));
    }
}
