// figure_kit.hpp — what the figure programs (figures/fig_*.cpp) share.
//
// Each figure program reproduces one or a few of the course figures (../FIGURES list in
// docs/figures.md) and, per figure, writes into the output folder
//   <ID>_<panel>.png   the images the figure shows (sRGB PNG)
//   <ID>.json          the record: slide, caption, claim, scene, settings, the reference
//                      used, per panel its time and error, the numbers that support the
//                      claim and whether the claim held in this run
// figures/make_gallery.py turns the records into docs/figures.md.
//
// Command line of every figure program:
//   --quick          low settings (small images, short budgets) for CI: a couple of minutes
//                    for all programs together; the claims are then only indicative
//   --out DIR        output folder (default docs/figures, or build/figures-quick with --quick)
//   --threads N      threads per render (default: every core)
//   --only ID[,ID]   only these figures of the program (e.g. --only F02)
//
// REFERENCES. Every error is measured against a reference image of the same scene at the
// same resolution, made by GetReference: a long run of an estimator that handles the
// scene, in two independent halves A and B (different seeds), so that the reference's own
// noise is known: reference = (A + B) / 2, its noise RMSE ~ Rmse(A, B) / 2. It is kept as
// <out>/references/<scene>_<W>x<H>.pfm with a .json of its settings, and re-used while
// those settings match (they include a hash of the scene file, so editing the scene
// renders it again); delete it to render it again. Its seeds differ from every seed
// the figures use, so a figure's noise is never hidden by sharing random numbers.
#pragma once
#include "smallvcm.hpp"
#include "examples/command_line.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

namespace figures {

using smallvcm::Algorithm;
using smallvcm::Error;
using smallvcm::Image;
using smallvcm::RenderOptions;
using smallvcm::RenderResult;
using smallvcm::Scene;
using smallvcm::Vec3;
using Json = nlohmann::ordered_json;
namespace fs = std::filesystem;

// ------------------------------------------------------------------------------------
// The command line and the settings every figure reads from it
// ------------------------------------------------------------------------------------

struct Kit {
    bool mQuick = false;
    std::string mOut;         // where images and records go
    std::string mScenes;      // the repository's scenes/ folder
    int mThreads = 0;         // 0: every core
    std::vector<std::string> mOnly;
    std::string mCommand;     // as typed, for the records

    // A setting at publication quality, or at --quick quality.
    template <class T>
    T Pick(T aPublication, T aQuick) const { return mQuick ? aQuick : aPublication; }
    bool Wants(const std::string& aId) const {
        return mOnly.empty() || std::find(mOnly.begin(), mOnly.end(), aId) != mOnly.end();
    }
    std::string ReferenceFolder() const { return mOut + "/references"; }
};

// The repository folder: two levels above build/fig_x, found through /proc/self/exe;
// "." when that fails (run from the repository).
inline std::string RepositoryFolder() {
    std::error_code ignored;
    const fs::path exe = fs::read_symlink("/proc/self/exe", ignored);
    if (!ignored) {
        const fs::path candidate = exe.parent_path().parent_path();
        if (fs::exists(candidate / "scenes" / "cornell_4_default.gltf", ignored)) {
            const fs::path relative = fs::proximate(candidate, ignored);
            const bool outside = relative.empty() || *relative.begin() == "..";
            return outside ? candidate.string() : relative.string();
        }
    }
    return ".";
}

inline Kit ParseKit(int argc, char** argv, const char* aUsage) {
    Kit kit;
    std::string out;
    kit.mCommand = argv[0];
    for (int i = 1; i < argc; i++) kit.mCommand += std::string(" ") + argv[i];
    for (int i = 1; i < argc; i++) {
        const std::string option = argv[i];
        auto value = [&]() -> std::string {
            if (i + 1 >= argc) throw Error(option + ": needs a value");
            return argv[++i];
        };
        if (option == "--quick") kit.mQuick = true;
        else if (option == "--out") out = value();
        else if (option == "--threads") kit.mThreads = ParseNumber<int>(option, value(), 0, 1024, "a thread count in [0, 1024]");
        else if (option == "--only") {
            std::stringstream list(value());
            for (std::string id; std::getline(list, id, ',');) kit.mOnly.push_back(id);
        } else if (option == "--help" || option == "-h") {
            std::printf("%s\nOptions: --quick, --out DIR, --threads N, --only ID[,ID...] (see figures/figure_kit.hpp)\n", aUsage);
            std::exit(0);
        } else throw Error(option + ": unknown option (try --help)");
    }
    const std::string repository = RepositoryFolder();
    kit.mScenes = repository + "/scenes";
    kit.mOut = !out.empty() ? out : repository + (kit.mQuick ? "/build/figures-quick" : "/docs/figures");
    std::error_code failed;
    fs::create_directories(kit.ReferenceFolder(), failed);
    if (failed) throw Error(kit.mOut + ": cannot create the output folder (" + failed.message() + ")");
    return kit;
}

// Runs a figure program: option errors exit with 2, any other failure with 1, each as
// one line "<program>: <problem>" on stderr.
inline int RunFigureProgram(int argc, char** argv, const char* aUsage, const std::function<void(const Kit&)>& aBody) {
    const std::string program = fs::path(argv[0]).filename().string();
    Kit kit;
    try {
        kit = ParseKit(argc, argv, aUsage);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s: %s\n", program.c_str(), e.what());
        return 2;
    }
    try {
        aBody(kit);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s: %s\n", program.c_str(), e.what());
        return 1;
    }
    return 0;
}

// ------------------------------------------------------------------------------------
// Scenes, renders and images
// ------------------------------------------------------------------------------------

// A scene of scenes/ (by file name) at a resolution, ready to render.
inline Scene LoadScene(const Kit& aKit, const std::string& aFile, int aWidth, int aHeight) {
    Scene scene = smallvcm::LoadGltfScene(aKit.mScenes + "/" + aFile);
    scene.mCamera.SetResolution(aWidth, aHeight);
    scene.Finalize();
    return scene;
}

// Options with the kit's threads and no progress line; the caller sets the rest.
inline RenderOptions BaseOptions(const Kit& aKit, Algorithm aAlgorithm) {
    RenderOptions options;
    options.mAlgorithm = aAlgorithm;
    options.mThreads = aKit.mThreads;
    options.mProgress = false;
    return options;
}

inline RenderResult RenderIterations(const Scene& aScene, RenderOptions aOptions, int aIterations) {
    aOptions.mIterations = aIterations;
    aOptions.mSeconds = 0.0;
    return smallvcm::Render(aScene, aOptions);
}

// Equal-time comparisons: as many iterations as fit in the budget (at least one).
inline RenderResult RenderSeconds(const Scene& aScene, RenderOptions aOptions, double aSeconds) {
    aOptions.mIterations = 0;
    aOptions.mSeconds = aSeconds;
    RenderResult result = smallvcm::Render(aScene, aOptions);
    if (result.mIterations == 0) result = RenderIterations(aScene, aOptions, 1);
    return result;
}

inline Image Scaled(const Image& aImage, float aFactor) {
    Image out = aImage;
    for (Vec3& p : out.mPixels) p *= aFactor;
    return out;
}

inline Image Sum(const std::vector<const Image*>& aImages) {
    Image out(aImages.at(0)->mWidth, aImages.at(0)->mHeight);
    for (const Image* image : aImages)
        for (size_t i = 0; i < out.mPixels.size(); i++) out.mPixels[i] += image->mPixels[i];
    return out;
}

// The layer of a render by name; an Error names it when the integrator did not write it.
inline const Image& Layer(const RenderResult& aResult, const std::string& aName) {
    for (const auto& layer : aResult.mLayers)
        if (layer.first == aName) return layer.second;
    throw Error("no layer named '" + aName + "' in the render");
}

// What the camera sees first through each pixel's centre (top row first): the masks
// that tell the figures which pixels show a specular surface, a plate, a light.
inline std::vector<smallvcm::SurfacePoint> FirstHits(const Scene& aScene) {
    const smallvcm::Camera& camera = aScene.mCamera;
    std::vector<smallvcm::SurfacePoint> hits(size_t(camera.PixelCount()));
    for (int pixel = 0; pixel < camera.PixelCount(); pixel++) {
        const smallvcm::Vec2 centre(float(pixel % camera.Width()) + 0.5f, float(pixel / camera.Width()) + 0.5f);
        hits[size_t(pixel)] = aScene.Intersect(camera.GenerateRay(centre));
    }
    return hits;
}

// Pixel masks: which pixels a number is measured on (1 = counted).
using Mask = std::vector<char>;

inline int CountOf(const Mask& aMask) { return int(std::count(aMask.begin(), aMask.end(), char(1))); }

// Mean over the masked pixels and the three channels (MeanValue restricted to a mask).
inline double MaskedMean(const Image& aImage, const Mask& aMask) {
    double sum = 0.0;
    for (size_t i = 0; i < aImage.mPixels.size(); i++)
        if (aMask[i]) sum += double(aImage.mPixels[i].x) + double(aImage.mPixels[i].y) + double(aImage.mPixels[i].z);
    return sum / std::max(1.0, 3.0 * double(CountOf(aMask)));
}

// RMSE over the masked pixels and the three channels (Rmse restricted to a mask).
inline double MaskedRmse(const Image& aImage, const Image& aReference, const Mask& aMask) {
    double sum = 0.0;
    for (size_t i = 0; i < aImage.mPixels.size(); i++)
        if (aMask[i]) {
            const glm::dvec3 d = glm::dvec3(aImage.mPixels[i]) - glm::dvec3(aReference.mPixels[i]);
            sum += glm::dot(d, d);
        }
    return std::sqrt(sum / std::max(1.0, 3.0 * double(CountOf(aMask))));
}

// A mask to look at: the masked pixels magenta, the others the image darkened to a quarter.
inline Image MaskPanel(const Mask& aMask, const Image& aBackground) {
    Image panel = Scaled(aBackground, 0.25f);
    for (size_t i = 0; i < panel.mPixels.size(); i++)
        if (aMask[i]) panel.mPixels[i] = Vec3(1.f, 0.f, 1.f);
    return panel;
}

inline double Median(std::vector<double> aValues) {
    if (aValues.empty()) return 0.0;
    const size_t middle = aValues.size() / 2;
    std::nth_element(aValues.begin(), aValues.begin() + long(middle), aValues.end());
    return aValues[middle];
}

// Least-squares slope of log(y) against log(x): the convergence rate of an error curve.
inline double LogLogSlope(const std::vector<double>& aX, const std::vector<double>& aY) {
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    const double n = double(aX.size());
    for (size_t i = 0; i < aX.size(); i++) {
        const double x = std::log(aX[i]), y = std::log(aY[i]);
        sx += x; sy += y; sxx += x * x; sxy += x * y;
    }
    return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

// ------------------------------------------------------------------------------------
// References
// ------------------------------------------------------------------------------------

struct ReferenceSpec {
    std::string mScene;          // file in scenes/
    int mWidth = 0, mHeight = 0;
    Algorithm mAlgorithm = Algorithm::kBidirectionalPathTracing;
    int mIterations = 0;         // in total, half per seed
    std::string mWhy;            // why this estimator is trustworthy on this scene
    int mMaxPathLength = 10;
    // Options that differ from the defaults only for some references (recorded then):
    float mMediumRadiusFactor = RenderOptions().mMediumRadiusFactor;  // photon points in media
    uint32_t mUpbpTechniques = RenderOptions().mUpbpTechniques;       // upbp's techniques
    int mBeamPaths = RenderOptions().mBeamPaths;                       // light sub-paths storing beams
    std::string mTag;            // a second reference of the same scene and size: its file's suffix
};

struct Reference {
    Image mImage;
    double mNoiseRmse = 0.0;     // estimated RMSE of the reference itself
    Json mRecord;                // its settings, for the figure records
};

inline constexpr uint64_t kReferenceSeedA = 777001, kReferenceSeedB = 777002;

// FNV-1a (64 bit) of a scene file's bytes, in hex: a reference made from an older
// version of the scene no longer matches and is rendered again.
inline std::string SceneFingerprint(const std::string& aPath) {
    std::ifstream file(aPath, std::ios::binary);
    if (!file) throw Error(aPath + ": cannot read the scene file");
    uint64_t hash = 1469598103934665603ull;
    for (char c; file.get(c);) hash = (hash ^ uint64_t(uint8_t(c))) * 1099511628211ull;
    char text[17];
    std::snprintf(text, sizeof(text), "%016llx", static_cast<unsigned long long>(hash));
    return text;
}

inline Json ReferenceSettings(const Kit& aKit, const ReferenceSpec& aSpec) {
    Json settings;
    settings["scene"] = "scenes/" + aSpec.mScene;
    settings["scene_fnv1a"] = SceneFingerprint(aKit.mScenes + "/" + aSpec.mScene);
    settings["resolution"] = std::to_string(aSpec.mWidth) + "x" + std::to_string(aSpec.mHeight);
    settings["algorithm"] = smallvcm::AlgorithmShortName(aSpec.mAlgorithm);
    settings["iterations"] = aSpec.mIterations;
    settings["max_path_length"] = aSpec.mMaxPathLength;
    settings["seeds"] = {kReferenceSeedA, kReferenceSeedB};
    // Recorded only where it differs from the default, so the other references' records
    // still match.
    const RenderOptions defaults;
    if (aSpec.mMediumRadiusFactor != defaults.mMediumRadiusFactor) settings["medium_radius_factor"] = aSpec.mMediumRadiusFactor;
    if (aSpec.mUpbpTechniques != defaults.mUpbpTechniques) settings["upbp_techniques"] = aSpec.mUpbpTechniques;
    if (aSpec.mBeamPaths != defaults.mBeamPaths) settings["beam_paths"] = aSpec.mBeamPaths;
    return settings;
}

inline Reference GetReference(const Kit& aKit, const ReferenceSpec& aSpec) {
    const std::string stem = aKit.ReferenceFolder() + "/" + fs::path(aSpec.mScene).stem().string() + "_" +
                             std::to_string(aSpec.mWidth) + "x" + std::to_string(aSpec.mHeight) +
                             (aSpec.mTag.empty() ? "" : "_" + aSpec.mTag);
    const Json settings = ReferenceSettings(aKit, aSpec);
    Reference reference;
    std::ifstream recordFile(stem + ".json");
    if (recordFile) {
        try {
            Json record = Json::parse(recordFile);
            if (record.at("settings") == settings && fs::exists(stem + ".pfm")) {
                reference.mImage = smallvcm::ReadPfm(stem + ".pfm");
                reference.mNoiseRmse = record.at("noise_rmse").get<double>();
                reference.mRecord = record;
                return reference;
            }
        } catch (const nlohmann::json::exception&) {
            // An unreadable record: render the reference again.
        }
    }
    std::printf("  reference %s: %s, %d iterations ...\n", fs::path(stem).filename().c_str(),
                smallvcm::AlgorithmShortName(aSpec.mAlgorithm), aSpec.mIterations);
    std::fflush(stdout);
    const Scene scene = LoadScene(aKit, aSpec.mScene, aSpec.mWidth, aSpec.mHeight);
    RenderOptions options = BaseOptions(aKit, aSpec.mAlgorithm);
    options.mMaxPathLength = aSpec.mMaxPathLength;
    options.mMediumRadiusFactor = aSpec.mMediumRadiusFactor;
    options.mUpbpTechniques = aSpec.mUpbpTechniques;
    options.mBeamPaths = aSpec.mBeamPaths;
    options.mSeed = kReferenceSeedA;
    const RenderResult a = RenderIterations(scene, options, std::max(1, aSpec.mIterations / 2));
    options.mSeed = kReferenceSeedB;
    const RenderResult b = RenderIterations(scene, options, std::max(1, aSpec.mIterations / 2));
    reference.mImage = Scaled(Sum({&a.mImage, &b.mImage}), 0.5f);
    reference.mNoiseRmse = smallvcm::Rmse(a.mImage, b.mImage) / 2.0;
    Json record;
    record["settings"] = settings;
    record["why"] = aSpec.mWhy;
    record["seconds"] = a.mSeconds + b.mSeconds;
    record["noise_rmse"] = reference.mNoiseRmse;
    record["mean"] = smallvcm::MeanValue(reference.mImage);
    record["file"] = fs::path(stem).filename().string() + ".pfm";
    smallvcm::WriteImage(stem + ".pfm", reference.mImage);
    std::ofstream(stem + ".json") << record.dump(2) << "\n";
    reference.mRecord = record;
    return reference;
}

// The one reference of each scene, shared by every figure that uses the scene (so that
// two programs never overwrite each other's reference with different settings).
//  * BPT where it converges: every light has an area (area, sphere, background lights),
//    so every path has at least one BPT technique;
//  * VCM where BPT cannot: with a point or directional light and a specular surface,
//    light -> specular -> diffuse -> specular -> camera paths have no BPT technique (no
//    camera path hits a delta light, no light path reaches the pinhole through a
//    specular bounce, a connection needs two non-specular ends); VCM's merging finds
//    them and its bias vanishes as the radius shrinks (consistent);
//  * path tracing with MIS on the plates, whose figure shows direct light only.
inline ReferenceSpec StandardReference(const Kit& aKit, const std::string& aScene, int aWidth, int aHeight) {
    ReferenceSpec spec;
    spec.mScene = aScene;
    spec.mWidth = aWidth;
    spec.mHeight = aHeight;
    const bool deltaLight = aScene == "cornell_0_sun.gltf" || aScene == "cornell_2_point.gltf" ||
                            aScene == "sds_glass_sphere.gltf" || aScene == "fog_caustic_box.gltf";
    if (aScene == "veach_plates.gltf") {
        spec.mAlgorithm = Algorithm::kPathTracing;
        spec.mIterations = aKit.Pick(4096, 512);
        spec.mMaxPathLength = 2;
        spec.mWhy = "path tracing with MIS of light and BSDF sampling: unbiased, and on this scene (direct light "
                    "only, path length 2) each highlight is found well by one of its two techniques";
    } else if (aScene == "spot_in_thin_fog.gltf" || aScene == "spot_in_dense_block.gltf") {
        spec.mAlgorithm = Algorithm::kBidirectionalPathTracing;
        spec.mIterations = aKit.Pick(aScene == "spot_in_thin_fog.gltf" ? 8192 : 2048, 256);
        spec.mWhy = "BPT: unbiased; the spot is a delta light, but no surface is specular (black walls, an "
                    "index-matched boundary), so every path has a BPT technique: the medium's vertices connect";
    } else if (deltaLight) {
        spec.mAlgorithm = Algorithm::kVertexConnectionMerging;
        spec.mIterations = aKit.Pick(512, 256);
        spec.mWhy = "VCM: the scene has a delta light and specular surfaces, so some light travels on "
                    "specular-diffuse-specular paths that no BPT technique samples; VCM's merging does, with a "
                    "bias that vanishes as its radius shrinks";
    } else {
        spec.mAlgorithm = Algorithm::kBidirectionalPathTracing;
        spec.mIterations = aKit.Pick(512, 256);
        spec.mWhy = "BPT: unbiased, and every light has an area, so every light path has at least one BPT "
                    "technique (it converges to the right image)";
    }
    // A smaller image gets proportionally more iterations, at the same cost (half the
    // noise each time the side halves): the convergence figure runs many more
    // iterations per pixel there, and its reference must stay well ahead of them.
    const int fullPixels = aKit.Pick(256 * 256, 64 * 64);
    spec.mIterations *= std::max(1, fullPixels / (aWidth * aHeight));
    return spec;
}

// ------------------------------------------------------------------------------------
// The record of one figure
// ------------------------------------------------------------------------------------

class Figure {
public:
    // aSlide: the slide (and seed file) the figure comes from; aClaim: what it shows.
    Figure(const Kit& aKit, std::string aId, const std::string& aTitle, const std::string& aSlide,
           const std::string& aClaim)
        : mKit(aKit), mId(std::move(aId)), mStart(std::chrono::steady_clock::now()) {
        mRecord["id"] = mId;
        mRecord["title"] = aTitle;
        mRecord["slide"] = aSlide;
        mRecord["claim"] = aClaim;
        mRecord["command"] = aKit.mCommand;
        mRecord["quick"] = aKit.mQuick;
        mRecord["settings"] = Json::object();
        mRecord["panels"] = Json::array();
        mRecord["numbers"] = Json::object();
        std::printf("%s: %s\n", mId.c_str(), aTitle.c_str());
        std::fflush(stdout);
    }

    Json& Settings() { return mRecord["settings"]; }
    void SetReference(const Reference& aReference) { mRecord["references"].push_back(aReference.mRecord); }

    // Writes <out>/<ID>_<name>.png (scaled by aExposure before the sRGB encoding) and
    // adds a panel; the returned object takes the panel's numbers.
    Json& AddPanel(const std::string& aName, const Image& aImage, const std::string& aCaption, float aExposure = 1.f) {
        const std::string file = mId + "_" + aName + ".png";
        smallvcm::WriteImage(mKit.mOut + "/" + file, aExposure == 1.f ? aImage : Scaled(aImage, aExposure));
        Json panel;
        panel["file"] = file;
        panel["caption"] = aCaption;
        if (aExposure != 1.f) panel["exposure"] = aExposure;
        panel["numbers"] = Json::object();
        mRecord["panels"].push_back(panel);
        return mRecord["panels"].back()["numbers"];
    }
    // A panel of a render: its time, iterations and (with a reference) its errors.
    Json& AddRender(const std::string& aName, const RenderResult& aResult, const std::string& aCaption,
                    const Image* aReference = nullptr, float aExposure = 1.f) {
        Json& numbers = AddPanel(aName, aResult.mImage, aCaption, aExposure);
        numbers["seconds"] = aResult.mSeconds;
        numbers["iterations"] = aResult.mIterations;
        if (aReference) {
            numbers["rmse"] = smallvcm::Rmse(aResult.mImage, *aReference);
            numbers["relmse"] = smallvcm::RelativeMse(aResult.mImage, *aReference);
        }
        return numbers;
    }

    Json& Numbers() { return mRecord["numbers"]; }

    // A chart drawn later from this figure's CSV by figures/plot_figures.py (the gallery
    // shows it above the panels), and a page of its own the gallery links to (F19).
    void AddChart(const std::string& aFile) { mRecord["charts"].push_back(aFile); }
    void SetPage(const std::string& aFile) { mRecord["page"] = aFile; }

    // The outcome: whether the claim held in this run, in one sentence with the numbers.
    void Verdict(bool aHolds, const std::string& aSentence) {
        mRecord["claim_holds"] = aHolds;
        mRecord["verdict"] = aSentence;
        std::printf("  %s %s\n", aHolds ? "[claim holds]" : "[claim does NOT hold]", aSentence.c_str());
    }

    // For a figure that makes no claim (F19): a summary sentence, no verdict.
    void Summary(const std::string& aSentence) {
        mRecord["verdict"] = aSentence;
        std::printf("  %s\n", aSentence.c_str());
    }

    // Writes <out>/<ID>.json (through a temporary file, so a failure leaves no half record).
    void Write() {
        mRecord["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - mStart).count();
        const std::string path = mKit.mOut + "/" + mId + ".json";
        {
            std::ofstream file(path + ".partial");
            file << mRecord.dump(2) << "\n";
            if (!file) throw Error(path + ": cannot write the figure record");
        }
        fs::rename(path + ".partial", path);
        std::printf("  %s written (%.1f s)\n", path.c_str(), mRecord["seconds"].get<double>());
        std::fflush(stdout);
    }

private:
    const Kit& mKit;
    std::string mId;
    std::chrono::steady_clock::time_point mStart;
    Json mRecord;
};

// "%.3g" of a number, for verdict sentences.
inline std::string Num(double aValue, const char* aFormat = "%.3g") {
    char buffer[64];
    std::snprintf(buffer, sizeof(buffer), aFormat, aValue);
    return buffer;
}

}  // namespace figures
