// fig_path_tracing — the path-tracing figures of the "Monte Carlo III" lecture (seed 001):
//   F01  local vs. global illumination: direct light only against the full image
//   F02  path tracing with next-event estimation, 1 and 36 paths per pixel
//   F03  partitioning the rendering equation: emitted, direct and indirect light, split
//        by the component (specular or not) sampled at the first vertex
// Scene: scenes/cornell_4_default.gltf (SmallVCM's default Cornell box).
//
//   build/fig_path_tracing [--quick] [--out DIR] [--threads N] [--only F01,F02,F03]
// writes F01_*.png ... F03.json (see figures/figure_kit.hpp).

#include "figure_kit.hpp"

using namespace figures;

namespace {

const char* const kScene = "cornell_4_default.gltf";

void FigureLocalGlobal(const Kit& aKit, int aSize) {
    Figure figure(aKit, "F01", "Local vs. global illumination",
                  "Local vs. global illumination (Monte Carlo III, seed 001)",
                  "indirect light is a large share of the image");
    const Scene scene = LoadScene(aKit, kScene, aSize, aSize);
    const int iterations = aKit.Pick(256, 32);
    figure.Settings() = {{"scene", std::string("scenes/") + kScene}, {"resolution", aSize},
                         {"algorithm", "pt"}, {"iterations", iterations}, {"seed", 1}};
    RenderOptions options = BaseOptions(aKit, Algorithm::kPathTracing);
    options.mSeed = 1;
    // Path length counts segments: 1 is the light seen directly, 2 adds light that
    // reached the first surface straight from a light.
    options.mMaxPathLength = 2;
    const RenderResult direct = RenderIterations(scene, options, iterations);
    options.mMaxPathLength = 10;
    const RenderResult full = RenderIterations(scene, options, iterations);
    const double directMean = smallvcm::MeanValue(direct.mImage), fullMean = smallvcm::MeanValue(full.mImage);
    const double share = 1.0 - directMean / fullMean;
    figure.AddRender("direct", direct, "direct light only (paths of at most 2 segments)")["mean"] = directMean;
    figure.AddRender("global", full, "global illumination (paths of up to 10 segments)")["mean"] = fullMean;
    figure.Numbers()["indirect_share"] = share;
    // "Large": more than a fifth of the light the camera sees.
    figure.Verdict(share > 0.2, "indirect light is " + Num(100.0 * share, "%.1f") +
                                    "% of the image's mean (direct only " + Num(directMean) + ", full " +
                                    Num(fullMean) + ")");
    figure.Write();
}

void FigureSamples(const Kit& aKit, int aSize) {
    Figure figure(aKit, "F02", "Path tracing, 1 vs 36 paths per pixel",
                  "Path tracing: 1 vs 36 paths per pixel (Monte Carlo III, seed 001)",
                  "RMSE falls by about sqrt(36) = 6");
    const Scene scene = LoadScene(aKit, kScene, aSize, aSize);
    const Reference reference = GetReference(aKit, StandardReference(aKit, kScene, aSize, aSize));
    figure.SetReference(reference);
    // One image's squared error is itself random, and heavy-tailed for path tracing (a
    // few bright paths), so each error is the mean over independent renders: 36 at one
    // sample per pixel, 8 at 36. Their spread gives the standard error of each mean.
    const int rendersAtOne = 36, rendersAtMany = 8;
    figure.Settings() = {{"scene", std::string("scenes/") + kScene}, {"resolution", aSize},
                         {"algorithm", "pt (next-event estimation + BSDF sampling, balance heuristic)"},
                         {"renders_at_1spp", rendersAtOne}, {"renders_at_36spp", rendersAtMany},
                         {"seeds", "1000 + k"}};
    RenderOptions options = BaseOptions(aKit, Algorithm::kPathTracing);
    struct MeanMse { double mMean = 0.0, mStandardError = 0.0; };
    auto meanMse = [&](int aIterations, int aRenders, const std::string& aPanel, const std::string& aCaption) {
        std::vector<double> mse;
        for (int k = 0; k < aRenders; k++) {
            options.mSeed = uint64_t(1000 + k);
            const RenderResult result = RenderIterations(scene, options, aIterations);
            const double rmse = smallvcm::Rmse(result.mImage, reference.mImage);
            mse.push_back(rmse * rmse);
            if (k == 0) figure.AddRender(aPanel, result, aCaption, &reference.mImage);
        }
        MeanMse out;
        for (double m : mse) out.mMean += m / aRenders;
        double variance = 0.0;
        for (double m : mse) variance += (m - out.mMean) * (m - out.mMean) / (aRenders - 1);
        out.mStandardError = std::sqrt(variance / aRenders);
        return out;
    };
    const MeanMse one = meanMse(1, rendersAtOne, "1spp", "1 path per pixel");
    const MeanMse many = meanMse(36, rendersAtMany, "36spp", "36 paths per pixel");
    // The measured error includes the reference's own noise n: mse = sigma^2 / N + n^2.
    // Taking n^2 out of both gives the ratio of the estimator's own errors.
    const double noise2 = reference.mNoiseRmse * reference.mNoiseRmse;
    const double ownOne = std::max(1e-30, one.mMean - noise2), ownMany = std::max(1e-30, many.mMean - noise2);
    const double ratio = std::sqrt(one.mMean / many.mMean);
    const double ownRatio = std::sqrt(ownOne / ownMany);
    // Standard error of the ratio, to first order: half the relative SEs in quadrature.
    const double ratioError = 0.5 * ownRatio * std::hypot(one.mStandardError / ownOne, many.mStandardError / ownMany);
    figure.Numbers()["rmse_1spp"] = std::sqrt(one.mMean);
    figure.Numbers()["rmse_36spp"] = std::sqrt(many.mMean);
    figure.Numbers()["rmse_ratio"] = ratio;
    figure.Numbers()["rmse_ratio_without_reference_noise"] = ownRatio;
    figure.Numbers()["rmse_ratio_standard_error"] = ratioError;
    figure.Numbers()["reference_noise_rmse"] = reference.mNoiseRmse;
    figure.Verdict(std::abs(ownRatio - 6.0) <= 3.0 * ratioError,
                   "RMSE " + Num(std::sqrt(one.mMean)) + " at 1 spp, " + Num(std::sqrt(many.mMean)) +
                       " at 36 spp (means over " + std::to_string(rendersAtOne) + " and " +
                       std::to_string(rendersAtMany) + " renders): ratio " + Num(ratio) + ", " + Num(ownRatio) +
                       " +- " + Num(ratioError) + " without the reference's noise; sqrt(36) = 6");
    figure.Write();
}

void FigurePartition(const Kit& aKit, int aSize) {
    Figure figure(aKit, "F03", "Partitioning the rendering equation",
                  "Partitioning the rendering equation (Monte Carlo III, seed 001)",
                  "the parts add up to the full image (no double counting)");
    const Scene scene = LoadScene(aKit, kScene, aSize, aSize);
    const Reference reference = GetReference(aKit, StandardReference(aKit, kScene, aSize, aSize));
    figure.SetReference(reference);
    const int iterations = aKit.Pick(256, 32);
    figure.Settings() = {{"scene", std::string("scenes/") + kScene}, {"resolution", aSize},
                         {"algorithm", "pt with technique layers"}, {"iterations", iterations}, {"seed", 3}};
    RenderOptions options = BaseOptions(aKit, Algorithm::kPathTracing);
    options.mSeed = 3;
    options.mTechniqueLayers = true;
    const RenderResult result = RenderIterations(scene, options, iterations);
    const std::pair<const char*, const char*> parts[] = {
        {"emitted", "light seen directly"},
        {"direct_nonspecular", "direct light at a diffuse/glossy first vertex"},
        {"direct_specular", "direct light through a specular first vertex"},
        {"indirect_nonspecular", "indirect light at a diffuse/glossy first vertex"},
        {"indirect_specular", "indirect light through a specular first vertex"}};
    std::vector<const Image*> layers;
    for (const auto& [name, caption] : parts) {
        const Image& layer = Layer(result, name);
        layers.push_back(&layer);
        figure.AddPanel(name, layer, caption)["mean"] = smallvcm::MeanValue(layer);
    }
    const Image sum = Sum(layers);
    figure.AddPanel("sum", sum, "the sum of the five parts")["mean"] = smallvcm::MeanValue(sum);
    figure.AddRender("image", result, "the path-traced image", &reference.mImage);
    double largest = 0.0;
    for (size_t i = 0; i < sum.mPixels.size(); i++)
        for (int c = 0; c < 3; c++)
            largest = std::max(largest, double(std::abs(sum.mPixels[i][c] - result.mImage.mPixels[i][c])) /
                                            std::max(1e-3, double(std::abs(result.mImage.mPixels[i][c]))));
    figure.Numbers()["largest_relative_difference_sum_vs_image"] = largest;
    // The layers and the image are accumulated separately in double and resolved to
    // float: they agree to float rounding (1e-5 relative is far above it, far below noise).
    figure.Verdict(largest < 1e-5, "the five parts sum to the image within " + Num(largest) +
                                       " (relative, largest over pixels)");
    figure.Write();
}

}  // namespace

int main(int argc, char** argv) {
    return RunFigureProgram(argc, argv, "fig_path_tracing: figures F01-F03 (path tracing)", [](const Kit& aKit) {
        const int size = aKit.Pick(256, 64);
        if (aKit.Wants("F01")) FigureLocalGlobal(aKit, size);
        if (aKit.Wants("F02")) FigureSamples(aKit, size);
        if (aKit.Wants("F03")) FigurePartition(aKit, size);
    });
}
