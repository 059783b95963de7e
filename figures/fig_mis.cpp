// fig_mis — F04, multiple importance sampling, w_i = p_i / sum_j p_j (the VCM talk,
// seed 000): Veach's glossy plates (scenes/veach_plates.gltf: four plates of Phong
// exponents 20 to 10000, four sphere lights of radii 0.03 to 0.9 with equal power) lit
// directly (paths of at most 2 segments), rendered with light sampling only, BSDF
// sampling only, and both combined by MIS with the balance and the power heuristic.
//
// Claim: MIS is at least as good as the better technique in every region. A region is
// one plate times one quarter of the image's width (each quarter holds the highlight of
// one light), so the 16 regions cover every plate-light pair: small light on a rough
// plate (light sampling wins), large light on a sharp plate (BSDF sampling wins), and
// the pairs in between.
//
//   build/fig_mis [--quick] [--out DIR] [--threads N]
// writes F04_*.png and F04.json (see figures/figure_kit.hpp).

#include "figure_kit.hpp"

#include <map>

using namespace figures;

namespace {

const char* const kScene = "veach_plates.gltf";

struct Technique {
    const char* mName;
    const char* mCaption;
    smallvcm::DirectLightSampling mSampling;
    smallvcm::MisHeuristic mHeuristic;
};

const Technique kTechniques[] = {
    {"light", "light sampling only", smallvcm::DirectLightSampling::kLightOnly, smallvcm::MisHeuristic::kBalance},
    {"bsdf", "BSDF sampling only", smallvcm::DirectLightSampling::kBsdfOnly, smallvcm::MisHeuristic::kBalance},
    {"mis_balance", "MIS, balance heuristic", smallvcm::DirectLightSampling::kMis, smallvcm::MisHeuristic::kBalance},
    {"mis_power", "MIS, power heuristic", smallvcm::DirectLightSampling::kMis, smallvcm::MisHeuristic::kPower},
};

// Region of each pixel: plate (0..3, by Phong exponent, roughest first) * 4 + image
// quarter, or -1 where the pixel does not see a plate.
std::vector<int> PlateRegions(const Scene& aScene) {
    const std::vector<smallvcm::SurfacePoint> hits = FirstHits(aScene);
    std::map<float, int> plateOfExponent;  // the plates are the Phong materials, ordered by exponent
    for (const smallvcm::SurfacePoint& hit : hits)
        if (hit.IsValid() && !smallvcm::IsBlack(aScene.GetMaterial(hit.mMaterialId).mPhongReflectance))
            plateOfExponent[aScene.GetMaterial(hit.mMaterialId).mPhongExponent] = 0;
    if (plateOfExponent.size() != 4) throw Error("scenes/veach_plates.gltf: expected 4 plates in view");
    int index = 0;
    for (auto& entry : plateOfExponent) entry.second = index++;
    std::vector<int> regions(hits.size(), -1);
    const int width = aScene.mCamera.Width();
    for (size_t pixel = 0; pixel < hits.size(); pixel++) {
        const smallvcm::SurfacePoint& hit = hits[pixel];
        if (!hit.IsValid() || smallvcm::IsBlack(aScene.GetMaterial(hit.mMaterialId).mPhongReflectance)) continue;
        const int quarter = std::min(3, int(pixel % size_t(width)) * 4 / width);
        regions[pixel] = plateOfExponent[aScene.GetMaterial(hit.mMaterialId).mPhongExponent] * 4 + quarter;
    }
    return regions;
}

// Mean squared error of each of the 16 regions.
std::vector<double> RegionMse(const Image& aImage, const Image& aReference, const std::vector<int>& aRegions) {
    std::vector<double> sum(16, 0.0), count(16, 0.0);
    for (size_t pixel = 0; pixel < aRegions.size(); pixel++) {
        if (aRegions[pixel] < 0) continue;
        const glm::dvec3 d = glm::dvec3(aImage.mPixels[pixel]) - glm::dvec3(aReference.mPixels[pixel]);
        sum[size_t(aRegions[pixel])] += glm::dot(d, d) / 3.0;
        count[size_t(aRegions[pixel])] += 1.0;
    }
    for (size_t r = 0; r < 16; r++) sum[r] /= std::max(1.0, count[r]);
    return sum;
}

void FigureMis(const Kit& aKit) {
    Figure figure(aKit, "F04", "Multiple importance sampling on Veach's plates",
                  "Multiple importance sampling, w_i = p_i / sum p (VCM course talk, seed 000)",
                  "MIS is at least as good as the better technique in every region");
    const int width = aKit.Pick(384, 96), height = aKit.Pick(256, 64);
    const Scene scene = LoadScene(aKit, kScene, width, height);
    const Reference reference = GetReference(aKit, StandardReference(aKit, kScene, width, height));
    figure.SetReference(reference);
    // K independent renders per technique: the spread of their region errors is the
    // standard error the comparison allows for.
    const int seeds = 4;
    const int iterations = aKit.Pick(64, 16);
    figure.Settings() = {{"scene", std::string("scenes/") + kScene},
                         {"resolution", std::to_string(width) + "x" + std::to_string(height)},
                         {"algorithm", "pt, direct light only (max path length 2)"},
                         {"iterations_per_render", iterations},
                         {"renders_per_technique", seeds},
                         {"seeds", "1..4 (the same for every technique)"}};
    const std::vector<int> regions = PlateRegions(scene);

    std::map<std::string, std::vector<double>> meanMse, standardError;
    for (const Technique& technique : kTechniques) {
        RenderOptions options = BaseOptions(aKit, Algorithm::kPathTracing);
        options.mMaxPathLength = 2;
        options.mDirectLight = technique.mSampling;
        options.mMisHeuristic = technique.mHeuristic;
        std::vector<std::vector<double>> perSeed;
        for (int seed = 1; seed <= seeds; seed++) {
            options.mSeed = uint64_t(seed);
            const RenderResult result = RenderIterations(scene, options, iterations);
            perSeed.push_back(RegionMse(result.mImage, reference.mImage, regions));
            if (seed == 1) figure.AddRender(technique.mName, result, technique.mCaption, &reference.mImage);
        }
        std::vector<double>& mean = meanMse[technique.mName];
        std::vector<double>& error = standardError[technique.mName];
        mean.assign(16, 0.0);
        error.assign(16, 0.0);
        for (size_t r = 0; r < 16; r++) {
            for (const auto& mse : perSeed) mean[r] += mse[r] / seeds;
            double variance = 0.0;
            for (const auto& mse : perSeed) variance += (mse[r] - mean[r]) * (mse[r] - mean[r]) / (seeds - 1);
            error[r] = std::sqrt(variance / seeds);
        }
        figure.Numbers()["region_mse_" + std::string(technique.mName)] = mean;
    }
    figure.AddPanel("reference", reference.mImage, "reference (path tracing with MIS, long run)");

    // MIS holds in a region when its mean error is at most the better technique's plus
    // two standard errors of the difference (the region errors are averages over K
    // independent renders; their spread gives the SE).
    int holds = 0;
    int regionsCounted = 0;
    double worstRatio = 0.0;
    Json table = Json::array();
    for (size_t r = 0; r < 16; r++) {
        const bool lightBetter = meanMse["light"][r] <= meanMse["bsdf"][r];
        const std::string better = lightBetter ? "light" : "bsdf";
        const double best = meanMse[better][r];
        bool regionHolds = true;
        for (const char* mis : {"mis_balance", "mis_power"}) {
            const double allowance = 2.0 * std::hypot(standardError[mis][r], standardError[better][r]);
            regionHolds = regionHolds && meanMse[mis][r] <= best + allowance;
            worstRatio = std::max(worstRatio, meanMse[mis][r] / best);
        }
        table.push_back({{"plate", r / 4}, {"quarter", r % 4}, {"better_technique", better},
                         {"mse_light", meanMse["light"][r]}, {"mse_bsdf", meanMse["bsdf"][r]},
                         {"mse_mis_balance", meanMse["mis_balance"][r]}, {"mse_mis_power", meanMse["mis_power"][r]},
                         {"holds", regionHolds}});
        holds += regionHolds ? 1 : 0;
        regionsCounted++;
    }
    figure.Numbers()["regions"] = table;
    figure.Numbers()["regions_where_mis_is_no_worse"] = holds;
    figure.Numbers()["largest_mis_to_better_ratio"] = worstRatio;
    figure.Verdict(holds == regionsCounted,
                   "MIS (balance and power) is no worse than the better single technique in " + std::to_string(holds) +
                       " of " + std::to_string(regionsCounted) +
                       " plate/light regions (within 2 SE); largest MSE ratio MIS / better technique " + Num(worstRatio));
    figure.Write();
}

}  // namespace

int main(int argc, char** argv) {
    return RunFigureProgram(argc, argv, "fig_mis: figure F04 (multiple importance sampling)", [](const Kit& aKit) {
        if (aKit.Wants("F04")) FigureMis(aKit);
    });
}
