// fig_report — the SmallVCM report:
//   F19  every algorithm (el, pt, lt, ppm, bpm, bpt, vcm, and the classic photon mappers
//        pm and pmfg) on every scene of SmallVCM's Cornell-box family, each render with
//        the same time budget, on one page with images, iterations, seconds and errors,
//        as SmallVCM's own report page shows its algorithms side by side
// Scenes: scenes/cornell_0_sun.gltf ... scenes/cornell_4_default.gltf, 256x256.
//
//   build/fig_report [--quick] [--out DIR] [--threads N]
// writes F19_s<i>_<alg>.png (scene i, algorithm alg), F19_s<i>_reference.png, F19.json
// (see figures/figure_kit.hpp) and report.md: a markdown table, a row per scene and a
// column per algorithm, each cell the image with its iterations, seconds and RMSE.
//
// The figure makes no claim: it is the overview. Its verdict names, per scene, the
// estimator with the lowest RMSE (measured; eye light is left out: it shades by the angle
// to the camera, it is not an estimator of the light transport).
//
// Settings:
//  * equal time: every estimator gets the same budget per render (RenderSeconds; an
//    iteration started before the budget ends is finished, so pm/pmfg, whose iterations
//    are long, can overshoot a little: the seconds shown are the measured ones). Eye
//    light gets a fixed few iterations: it converges to its shading at once and would
//    only waste the budget;
//  * the merging radius of ppm, bpm and vcm: SmallVCM's 0.003 x the scene radius is meant
//    for its 512x512 images, with 512^2 light sub-paths per iteration; at width W it is
//    scaled by 512 / W, which keeps both the photons per merging disk ((light paths) x r^2)
//    and the radius in pixels as in SmallVCM's report;
//  * pm, pmfg: the library's 200000 photons per iteration (--quick: 20000, so that one
//    iteration fits the short budget);
//  * one seed per render (1900 + 10 x scene + the algorithm's index), none shared with
//    another render or a reference.

#include "figure_kit.hpp"

#include <thread>

using namespace figures;

namespace {

struct SceneEntry {
    const char* mFile;
    const char* mDescription;
};

const SceneEntry kScenes[] = {
    {"cornell_0_sun.gltf", "sun (directional light), mirror + glass spheres"},
    {"cornell_1_mirror_ceiling.gltf", "area light, large mirror sphere"},
    {"cornell_2_point.gltf", "point light, mirror + glass spheres"},
    {"cornell_3_background.gltf", "background light, mirror + glass spheres"},
    {"cornell_4_default.gltf", "area light, mirror + glass spheres (SmallVCM's default)"},
};

const Algorithm kAlgorithms[] = {
    Algorithm::kEyeLight,
    Algorithm::kPathTracing,
    Algorithm::kLightTracing,
    Algorithm::kProgressivePhotonMapping,
    Algorithm::kBidirectionalPhotonMapping,
    Algorithm::kBidirectionalPathTracing,
    Algorithm::kVertexConnectionMerging,
    Algorithm::kPhotonMapping,
    Algorithm::kPhotonMappingFinalGather,
};

struct Cell {
    std::string mAlgorithm;
    int mIterations = 0;
    double mSeconds = 0.0, mRmse = 0.0, mRelMse = 0.0;
};

struct Row {
    std::string mScene, mDescription, mReferenceText;
    std::vector<Cell> mCells;
    std::string mLowestRmse, mLowestRelMse;  // algorithm names
};

float RadiusFactor(int aWidth) { return 0.003f * 512.f / float(aWidth); }

std::string PanelName(int aScene, const std::string& aAlgorithm) {
    return "s" + std::to_string(aScene) + "_" + aAlgorithm;
}

// <out>/report.md: SmallVCM's report page as a markdown table (images by relative link).
void WriteReportPage(const Kit& aKit, const std::vector<Row>& aRows, int aSize, double aSeconds,
                     int aEyeLightIterations) {
    std::ostringstream page;
    page << "# The SmallVCM report (F19)\n\n"
         << "Every algorithm on every Cornell scene, " << aSize << "x" << aSize << ", " << Num(aSeconds)
         << " s per render (equal time; eye light: " << aEyeLightIterations
         << " iterations, it is not an estimator of the light transport). Under each image: iterations, "
            "seconds, RMSE and relative MSE against the scene's reference (first column: its estimator, "
            "iterations and own noise RMSE). **Bold**: the lowest RMSE of the scene.\n\n"
         << "Made by `" << aKit.mCommand << "`" << (aKit.mQuick ? " (quick settings: indicative only)" : "")
         << "; the numbers are in F19.json.\n\n";
    page << "| scene | reference |";
    for (Algorithm algorithm : kAlgorithms) page << " " << smallvcm::AlgorithmShortName(algorithm) << " |";
    page << "\n|---|---|";
    for (size_t i = 0; i < std::size(kAlgorithms); i++) page << "---|";
    page << "\n";
    for (size_t s = 0; s < aRows.size(); s++) {
        const Row& row = aRows[s];
        page << "| " << row.mScene << "<br>" << row.mDescription << " | ![reference](F19_"
             << PanelName(int(s), "reference") << ".png)<br>" << row.mReferenceText << " |";
        for (const Cell& cell : row.mCells) {
            const bool lowest = cell.mAlgorithm == row.mLowestRmse;
            page << " ![" << cell.mAlgorithm << "](F19_" << PanelName(int(s), cell.mAlgorithm) << ".png)<br>"
                 << cell.mIterations << " it, " << Num(cell.mSeconds, "%.1f") << " s<br>"
                 << (lowest ? "**" : "") << "RMSE " << Num(cell.mRmse) << (lowest ? "**" : "") << "<br>relMSE "
                 << Num(cell.mRelMse) << " |";
        }
        page << "\n";
    }
    page << "\n| scene | lowest RMSE | lowest relative MSE |\n|---|---|---|\n";
    for (const Row& row : aRows)
        page << "| " << row.mScene << " | " << row.mLowestRmse << " | " << row.mLowestRelMse << " |\n";
    const std::string path = aKit.mOut + "/report.md";
    {
        std::ofstream file(path + ".partial");
        file << page.str();
        if (!file) throw Error(path + ": cannot write the report page");
    }
    fs::rename(path + ".partial", path);
    std::printf("  %s written\n", path.c_str());
}

void FigureReport(const Kit& aKit) {
    Figure figure(aKit, "F19", "The SmallVCM report", "The SmallVCM report (SmallVCM's report page)", "—");
    const int size = aKit.Pick(256, 48);
    const double seconds = aKit.Pick(8.0, 0.2);
    const int eyeLightIterations = aKit.Pick(16, 4);
    const int photons = aKit.Pick(200000, 20000);
    Json scenes = Json::array();
    for (const SceneEntry& entry : kScenes) scenes.push_back(std::string("scenes/") + entry.mFile);
    figure.Settings() = {
        {"scenes", scenes},
        {"resolution", size},
        {"seconds_per_render", seconds},
        {"eye_light_iterations", eyeLightIterations},
        {"threads", aKit.mThreads > 0 ? aKit.mThreads : int(std::max(1u, std::thread::hardware_concurrency()))},
        {"radius_factor", RadiusFactor(size)},
        {"radius_factor_why", "SmallVCM's 0.003 at 512x512, scaled by 512 / width: the same photons per merging "
                              "disk and radius in pixels as SmallVCM's report"},
        {"radius_alpha", RenderOptions().mRadiusAlpha},
        {"photons_per_iteration", photons},
        {"seeds", "1900 + 10 x scene + the algorithm's index in el, pt, lt, ppm, bpm, bpt, vcm, pm, pmfg"}};

    std::vector<Row> rows;
    for (size_t s = 0; s < std::size(kScenes); s++) {
        const std::string file = kScenes[s].mFile;
        const Scene scene = LoadScene(aKit, file, size, size);
        const Reference reference = GetReference(aKit, StandardReference(aKit, file, size, size));
        figure.SetReference(reference);
        Row row;
        row.mScene = fs::path(file).stem().string();
        row.mDescription = kScenes[s].mDescription;
        const Json& referenceSettings = reference.mRecord["settings"];
        row.mReferenceText = referenceSettings["algorithm"].get<std::string>() + ", " +
                             std::to_string(referenceSettings["iterations"].get<int>()) + " it<br>noise " +
                             Num(reference.mNoiseRmse);
        figure.AddPanel(PanelName(int(s), "reference"), reference.mImage,
                        row.mScene + ": the reference (" + referenceSettings["algorithm"].get<std::string>() + ")")
            ["noise_rmse"] = reference.mNoiseRmse;
        Json sceneNumbers;
        double lowestRmse = INFINITY, lowestRelMse = INFINITY;
        for (size_t a = 0; a < std::size(kAlgorithms); a++) {
            const Algorithm algorithm = kAlgorithms[a];
            const std::string name = smallvcm::AlgorithmShortName(algorithm);
            RenderOptions options = BaseOptions(aKit, algorithm);
            options.mSeed = 1900 + 10 * s + a;
            options.mRadiusFactor = RadiusFactor(size);
            options.mPhotonCount = photons;
            const bool eyeLight = algorithm == Algorithm::kEyeLight;
            const RenderResult result = eyeLight ? RenderIterations(scene, options, eyeLightIterations)
                                                 : RenderSeconds(scene, options, seconds);
            Cell cell;
            cell.mAlgorithm = name;
            cell.mIterations = result.mIterations;
            cell.mSeconds = result.mSeconds;
            cell.mRmse = smallvcm::Rmse(result.mImage, reference.mImage);
            cell.mRelMse = smallvcm::RelativeMse(result.mImage, reference.mImage);
            figure.AddRender(PanelName(int(s), name), result,
                             row.mScene + ", " + name + ": " + std::to_string(result.mIterations) + " iterations in " +
                                 Num(result.mSeconds, "%.1f") + " s" + (eyeLight ? " (not an estimator)" : ""),
                             &reference.mImage);
            sceneNumbers[name] = {{"iterations", cell.mIterations}, {"seconds", cell.mSeconds},
                                  {"rmse", cell.mRmse}, {"relmse", cell.mRelMse}};
            if (!eyeLight && cell.mRmse < lowestRmse) { lowestRmse = cell.mRmse; row.mLowestRmse = name; }
            if (!eyeLight && cell.mRelMse < lowestRelMse) { lowestRelMse = cell.mRelMse; row.mLowestRelMse = name; }
            row.mCells.push_back(cell);
        }
        sceneNumbers["lowest_rmse"] = row.mLowestRmse;
        sceneNumbers["lowest_relmse"] = row.mLowestRelMse;
        figure.Numbers()["scenes"][row.mScene] = sceneNumbers;
        std::printf("  %-26s lowest RMSE: %-4s (%.4g), lowest relMSE: %s\n", row.mScene.c_str(),
                    row.mLowestRmse.c_str(), lowestRmse, row.mLowestRelMse.c_str());
        std::fflush(stdout);
        rows.push_back(std::move(row));
    }
    WriteReportPage(aKit, rows, size, seconds, eyeLightIterations);

    // No claim: the verdict is the overview's summary, always "holding".
    std::string summary;
    for (const Row& row : rows) {
        const auto cell = std::find_if(row.mCells.begin(), row.mCells.end(),
                                       [&](const Cell& c) { return c.mAlgorithm == row.mLowestRmse; });
        summary += (summary.empty() ? "" : "; ") + row.mScene + " " + row.mLowestRmse + " (" + Num(cell->mRmse) + ")";
    }
    figure.SetPage("report.md");
    figure.Summary("lowest RMSE at " + Num(seconds) + " s per render: " + summary);
    figure.Write();
}

}  // namespace

int main(int argc, char** argv) {
    return RunFigureProgram(argc, argv, "fig_report: figure F19 (the SmallVCM report)", [](const Kit& aKit) {
        if (aKit.Wants("F19")) FigureReport(aKit);
    });
}
