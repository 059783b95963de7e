// smallvcm — the command-line renderer, with SmallVCM's options and a few more.
//
//   build/smallvcm -s 4 -a vcm -i 32 -o vcm.png
//   build/smallvcm -s scenes/cornell_1_mirror_ceiling.gltf -a bpt -t 10 -r 640x480 -o bpt.hdr
//
// Every bad value gives one line "smallvcm: <option>: <problem>" on stderr and exit code 2;
// a problem with the scene or the output file gives "smallvcm: <file>: <problem>" and
// exit code 1. No output file is written unless the render succeeded. Ctrl-C stops the
// render after the iterations in flight, writes what was accumulated and exits with 130.
// Build: make build/smallvcm. Run with --help for the options.

#include "smallvcm.hpp"
#include "command_line.hpp"

#include <atomic>
#include <charconv>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

namespace {

using smallvcm::Error;

// Ctrl-C asks the render to stop after the iterations in flight; a second Ctrl-C kills
// the program at once (the default handler is back by then). A lock-free atomic store is
// what a signal handler may do.
std::atomic<bool> gStopRequested{false};
extern "C" void OnInterrupt(int) {
    gStopRequested.store(true);
    std::signal(SIGINT, SIG_DFL);
}

const char* const kCornellScenes[] = {
    "cornell_0_sun.gltf",            // -s 0: glossy floor, small spheres, sun
    "cornell_1_mirror_ceiling.gltf", // -s 1: glossy floor, large mirror sphere, ceiling light
    "cornell_2_point.gltf",          // -s 2: glossy floor, small spheres, point light
    "cornell_3_background.gltf",     // -s 3: glossy floor, small spheres, background light
    "cornell_4_default.gltf",        // -s 4: SmallVCM's kDefault: small spheres, ceiling light
};

void PrintHelp() {
    std::printf(
        "Usage: smallvcm [options]\n"
        "  -s SCENE            a glTF file, or a Cornell scene 0..4 (default 4):\n"
        "                        0 glossy + small spheres + sun      1 glossy + large mirror + ceiling light\n"
        "                        2 glossy + small spheres + point    3 glossy + small spheres + background\n"
        "                        4 small mirror and glass spheres + ceiling light (SmallVCM's default)\n"
        "  -a ALGORITHM        el, pt, lt, ppm, bpm, bpt, vcm, pm, pmfg (default vcm)\n"
        "  -i ITERATIONS       number of iterations, one sample per pixel each (default 1)\n"
        "  -t SECONDS          time budget; with -t and no -i, runs until the time is up\n"
        "  -o FILE             output image: .png, .hdr or .pfm (default smallvcm.png)\n"
        "  -r WIDTHxHEIGHT     resolution (default 512x512)\n"
        "  -j THREADS          threads (default: all cores)\n"
        "  --seed N            base random seed (default 1234)\n"
        "  --min-path-length N shortest path length rendered, in segments (default 0)\n"
        "  --max-path-length N longest path length rendered, in segments (default 10)\n"
        "  --radius-factor F   merging radius as a fraction of the scene radius (default 0.003)\n"
        "  --radius-alpha A    radius shrinking exponent in (0, 1] (default 0.75)\n"
        "  --mis balance|power MIS heuristic (default balance)\n"
        "  --photons N         pm, pmfg: photons traced per iteration (default 200000)\n"
        "  --knn K             pm, pmfg: nearest photons per estimate (default 100)\n"
        "  --max-radius F      pm, pmfg: largest search radius, fraction of the scene radius (default 0.05)\n"
        "  --layers            also write per-technique layers as FILE-stem.LAYER.ext\n"
        "  -q                  quiet: no summary line, no progress\n"
        "  --help              this text\n");
}

// The repository's scenes/ folder: $SMALLVCM_SCENES if set, else found by walking up
// from this executable (build/smallvcm, build/check/smallvcm), else ./scenes.
std::string ScenesFolder() {
    if (const char* fromEnvironment = std::getenv("SMALLVCM_SCENES")) return fromEnvironment;
    char buffer[4096];
    const ssize_t length = readlink("/proc/self/exe", buffer, sizeof(buffer) - 1);
    if (length > 0) {
        std::string folder(buffer, size_t(length));
        for (int up = 0; up < 3; up++) {
            const size_t slash = folder.find_last_of('/');
            if (slash == std::string::npos) break;
            folder.resize(slash);
            const std::string candidate = folder + "/scenes";
            char resolved[4096];
            if (access((candidate + "/" + kCornellScenes[0]).c_str(), R_OK) == 0 && realpath(candidate.c_str(), resolved))
                return resolved;
        }
    }
    return "scenes";
}

std::string ResolveScene(const std::string& aScene) {
    if (aScene.size() == 1 && aScene[0] >= '0' && aScene[0] <= '4')
        return ScenesFolder() + "/" + kCornellScenes[aScene[0] - '0'];
    if (aScene.find_first_not_of("0123456789-") == std::string::npos)
        throw Error("-s: '" + aScene + "' is not a Cornell scene index (0..4) nor a .gltf/.glb file");
    return aScene;
}

std::string WithLayerName(const std::string& aPath, const std::string& aLayer) {
    const size_t dot = aPath.find_last_of('.');
    return aPath.substr(0, dot) + "." + aLayer + aPath.substr(dot);
}

// Fails early, before a long render, if the output cannot be written.
void CheckOutputWritable(const std::string& aPath) {
    if (!smallvcm::IsSupportedImagePath(aPath))
        throw Error("-o: '" + aPath + "' has an unknown image format (use .png, .hdr or .pfm)");
    const std::string probe = aPath + ".partial";
    FILE* file = std::fopen(probe.c_str(), "wb");
    if (!file) throw Error(aPath + ": cannot write here (" + std::strerror(errno) + ")");
    std::fclose(file);
    std::remove(probe.c_str());
}

struct CommandLine {
    std::string mScene = "4";
    std::string mOutput = "smallvcm.png";
    int mWidth = 512, mHeight = 512;
    bool mQuiet = false;
    bool mIterationsGiven = false;
    smallvcm::RenderOptions mOptions;
};

CommandLine Parse(int argc, char** argv) {
    CommandLine cl;
    cl.mOptions.mIterations = 1;
    auto value = [&](int& i) -> std::string {
        const std::string option = argv[i];
        if (i + 1 >= argc) throw Error(option + ": needs a value");
        return argv[++i];
    };
    for (int i = 1; i < argc; i++) {
        const std::string arg = argv[i];
        if (arg == "--help" || arg == "-h") { PrintHelp(); std::exit(0); }
        else if (arg == "-s") cl.mScene = value(i);
        else if (arg == "-a") {
            const std::string name = value(i);
            if (!smallvcm::ParseAlgorithm(name, cl.mOptions.mAlgorithm))
                throw Error("-a: unknown algorithm '" + name + "' (el, pt, lt, ppm, bpm, bpt, vcm, pm, pmfg)");
        }
        else if (arg == "-i") { cl.mOptions.mIterations = ParseNumber<int>(arg, value(i), 1, 100000000, "an integer in [1, 1e8]"); cl.mIterationsGiven = true; }
        else if (arg == "-t") cl.mOptions.mSeconds = ParseNumber<double>(arg, value(i), 1e-3, 1e7, "a number of seconds in [0.001, 1e7]");
        else if (arg == "-o") {
            cl.mOutput = value(i);
            if (!smallvcm::IsSupportedImagePath(cl.mOutput))
                throw Error("-o: '" + cl.mOutput + "' has an unknown image format (use .png, .hdr or .pfm)");
        }
        else if (arg == "-r") {
            const std::string text = value(i);
            const size_t x = text.find('x');
            if (x == std::string::npos) throw Error("-r: '" + text + "' is not WIDTHxHEIGHT (e.g. 512x512)");
            cl.mWidth = ParseNumber<int>(arg, text.substr(0, x), 1, 16384, "WIDTHxHEIGHT with sizes in [1, 16384]");
            cl.mHeight = ParseNumber<int>(arg, text.substr(x + 1), 1, 16384, "WIDTHxHEIGHT with sizes in [1, 16384]");
        }
        else if (arg == "-j") cl.mOptions.mThreads = ParseNumber<int>(arg, value(i), 1, 1024, "an integer in [1, 1024]");
        else if (arg == "--seed") cl.mOptions.mSeed = ParseNumber<uint64_t>(arg, value(i), 0, UINT64_MAX, "a non-negative integer");
        else if (arg == "--min-path-length") cl.mOptions.mMinPathLength = ParseNumber<int>(arg, value(i), 0, 1000, "an integer in [0, 1000]");
        else if (arg == "--max-path-length") cl.mOptions.mMaxPathLength = ParseNumber<int>(arg, value(i), 1, 1000, "an integer in [1, 1000]");
        else if (arg == "--radius-factor") cl.mOptions.mRadiusFactor = ParseNumber<float>(arg, value(i), 1e-7f, 10.f, "a number in [1e-7, 10]");
        else if (arg == "--radius-alpha") {
            cl.mOptions.mRadiusAlpha = ParseNumber<float>(arg, value(i), 0.f, 1.f, "a number in (0, 1]");
            if (!(cl.mOptions.mRadiusAlpha > 0.f)) throw Error("--radius-alpha: '0' is not a number in (0, 1]");
        }
        else if (arg == "--mis") {
            const std::string name = value(i);
            if (name == "balance") cl.mOptions.mMis = smallvcm::MisHeuristic::kBalance;
            else if (name == "power") cl.mOptions.mMis = smallvcm::MisHeuristic::kPower;
            else throw Error("--mis: unknown heuristic '" + name + "' (balance, power)");
        }
        else if (arg == "--photons") cl.mOptions.mPhotonCount = ParseNumber<int>(arg, value(i), 1, 100000000, "an integer in [1, 1e8]");
        else if (arg == "--knn") cl.mOptions.mNearestPhotons = ParseNumber<int>(arg, value(i), 1, 100000, "an integer in [1, 100000]");
        else if (arg == "--max-radius") cl.mOptions.mMaxPhotonRadiusFactor = ParseNumber<float>(arg, value(i), 1e-6f, 10.f, "a number in [1e-6, 10]");
        else if (arg == "--layers") cl.mOptions.mTechniqueLayers = true;
        else if (arg == "-q") cl.mQuiet = true;
        else throw Error(arg + ": unknown option (see --help)");
    }
    if (cl.mOptions.mSeconds > 0.0 && !cl.mIterationsGiven) cl.mOptions.mIterations = 0;  // until time is up
    if (cl.mOptions.mMinPathLength > cl.mOptions.mMaxPathLength)
        throw Error("--min-path-length: must not exceed --max-path-length (" + std::to_string(cl.mOptions.mMaxPathLength) + ")");
    if (cl.mOptions.mTechniqueLayers &&
        (cl.mOptions.mAlgorithm == smallvcm::Algorithm::kEyeLight))
        throw Error("--layers: the eye light has no techniques to separate");
    cl.mOptions.mProgress = !cl.mQuiet;
    cl.mScene = ResolveScene(cl.mScene);
    return cl;
}

} // namespace

int main(int argc, char** argv) {
    CommandLine cl;
    try {
        cl = Parse(argc, argv);
    } catch (const Error& e) {
        std::fprintf(stderr, "smallvcm: %s\n", e.what());
        return 2;
    }
    try {
        CheckOutputWritable(cl.mOutput);
        const std::string& scenePath = cl.mScene;
        smallvcm::GltfLoadReport report;
        smallvcm::Scene scene = smallvcm::LoadGltfScene(scenePath, &report);
        if (report.mSkippedDegenerateTriangles > 0)
            std::fprintf(stderr, "smallvcm: %s: note: skipped %d degenerate (zero-area) triangles\n", scenePath.c_str(),
                         report.mSkippedDegenerateTriangles);
        scene.mCamera.SetResolution(cl.mWidth, cl.mHeight);
        cl.mOptions.mStopRequested = &gStopRequested;
        std::signal(SIGINT, OnInterrupt);
        const smallvcm::RenderResult result = smallvcm::Render(scene, cl.mOptions);
        std::signal(SIGINT, SIG_DFL);
        if (result.mStopped && result.mIterations == 0) {
            std::fprintf(stderr, "smallvcm: interrupted before the first iteration finished; nothing written\n");
            return 130;
        }
        if (result.mStopped)
            std::fprintf(stderr, "smallvcm: interrupted: writing the %d iterations accumulated so far\n", result.mIterations);
        smallvcm::WriteImage(cl.mOutput, result.mImage);
        for (const auto& layer : result.mLayers) smallvcm::WriteImage(WithLayerName(cl.mOutput, layer.first), layer.second);
        if (!cl.mQuiet)
            std::printf("%s: %s, %dx%d, %d iterations in %.2f s (%.3f s/iteration), mean %.6f -> %s\n", scenePath.c_str(),
                        smallvcm::AlgorithmShortName(cl.mOptions.mAlgorithm), cl.mWidth, cl.mHeight, result.mIterations,
                        result.mSeconds, result.mSeconds / std::max(1, result.mIterations),
                        smallvcm::MeanValue(result.mImage), cl.mOutput.c_str());
        if (result.mStopped) return 130;  // the conventional status of a program ended by SIGINT
    } catch (const Error& e) {
        std::fprintf(stderr, "smallvcm: %s\n", e.what());
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "smallvcm: unexpected error: %s\n", e.what());
        return 1;
    }
    return 0;
}
