// smallvcm — the command-line renderer, with SmallVCM's options and a few more.
//
//   build/smallvcm scenes/cornell_1_mirror_ceiling.gltf -a bpt -t 10 -r 640x480 -o bpt.hdr
//   build/smallvcm -s 4 -a vcm -i 32 -o vcm.png
//
// The scene is the one argument that is not an option (as pbrt and Mitsuba take it),
// anywhere among the options, or SmallVCM's -s SCENE; a Cornell scene number 0..4 works
// either way. A positional scene beside another scene is an error naming both.
//
// Every bad value gives one line "smallvcm: <option>: <problem>" on stderr and exit code 2;
// a problem with the scene or the output file gives "smallvcm: <file>: <problem>" and
// exit code 1. No output file is written unless the render succeeded. Ctrl-C (SIGINT) or
// SIGTERM stops the render after the iterations in flight, writes what was accumulated
// and exits with 130 or 143; a second signal ends it at once, leaving no temporary file.
// Every image is written with a JSON sidecar IMAGE.json (examples/sidecar.hpp says what
// it holds); `smallvcm merge OUT RUN...` averages runs of one scene by their iterations.
// -a takes any registered integrator: the built-ins, and those of the .cpp files the
// Makefile's INTEGRATORS variable links in (each registers itself with a
// smallvcm::IntegratorRegistration; docs/writing-an-integrator.md shows how).
// Build: make build/smallvcm [INTEGRATORS="mine.cpp ..."]. Run with --help for the options.

#include "smallvcm.hpp"
#include "command_line.hpp"
#include "sidecar.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <charconv>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <initializer_list>
#include <algorithm>
#include <string>
#include <thread>
#include <vector>

namespace {

using smallvcm::Error;

// SIGINT (Ctrl-C) and SIGTERM (a batch scheduler's time limit) ask the render to stop
// after the iterations in flight; the image accumulated so far is written and the program
// exits with 128 + the signal's number, the conventional status. The handler puts the
// default action back, so a second signal ends the program at once; WriteImage holds
// signals back while its temporary file exists, so even then none is left behind. A
// lock-free atomic store is what a signal handler may do.
std::atomic<bool> gStopRequested{false};
std::atomic<int> gStopSignal{0};
extern "C" void OnStopSignal(int aSignal) {
    gStopSignal.store(aSignal);
    gStopRequested.store(true);
    std::signal(SIGINT, SIG_DFL);
    std::signal(SIGTERM, SIG_DFL);
}

const char* const kCornellScenes[] = {
    "cornell_0_sun.gltf",            // -s 0: glossy floor, small spheres, sun
    "cornell_1_mirror_ceiling.gltf", // -s 1: glossy floor, large mirror sphere, ceiling light
    "cornell_2_point.gltf",          // -s 2: glossy floor, small spheres, point light
    "cornell_3_background.gltf",     // -s 3: glossy floor, small spheres, background light
    "cornell_4_default.gltf",        // -s 4: SmallVCM's kDefault: small spheres, ceiling light
};

// "el, pt, ...": every registered integrator's name.
std::string IntegratorNames() {
    std::string names;
    for (const smallvcm::Integrator* integrator : smallvcm::RegisteredIntegrators())
        names += (names.empty() ? "" : ", ") + integrator->mName;
    return names;
}

void PrintHelp() {
    std::printf(
        "Usage: smallvcm [SCENE] [options]\n"
        "  SCENE, -s SCENE     a glTF file (.gltf or .glb), or a Cornell scene 0..4 (default 4):\n"
        "                        0 glossy + small spheres + sun      1 glossy + large mirror + ceiling light\n"
        "                        2 glossy + small spheres + point    3 glossy + small spheres + background\n"
        "                        4 small mirror and glass spheres + ceiling light (SmallVCM's default)\n"
        "  -a ALGORITHM        a registered integrator (default vcm):\n");
    int nameWidth = 0;
    for (const smallvcm::Integrator* integrator : smallvcm::RegisteredIntegrators())
        nameWidth = std::max(nameWidth, int(integrator->mName.size()));
    for (const smallvcm::Integrator* integrator : smallvcm::RegisteredIntegrators())
        std::printf("                        %-*s %s\n", nameWidth, integrator->mName.c_str(), integrator->mDescription.c_str());
    std::printf(
        "  -i ITERATIONS       number of iterations, one sample per pixel each (default 1)\n"
        "  -t SECONDS          time budget: without -i, runs until the time is up; with -i too, stops\n"
        "                        at whichever limit comes first (iterations done or time up)\n"
        "  -o FILE             output image: .png, .hdr, .pfm or .exr, in any case (default smallvcm.png),\n"
        "                        written with a sidecar FILE.json saying how it was made; .exr holds\n"
        "                        R, G, B as 32-bit floats (not half: the values bit for bit, as .pfm)\n"
        "  --exposure EV       PNG only: scale radiance by 2^EV before tone mapping (default 0, in [-32, 32])\n"
        "  --tonemap T         PNG only: clamp (default: to [0, 1]) or aces (a filmic curve that keeps\n"
        "                        highlights); .hdr, .pfm and .exr always hold linear radiance\n"
        "  -r WIDTHxHEIGHT     resolution (default 512x512)\n"
        "  -j THREADS          threads (default: all cores; at most 4 per core)\n"
        "  --seed N            base random seed (default 1234)\n"
        "  --sampler S         sobol (default: Owen-scrambled Sobol points, each pixel's samples over the\n"
        "                        iterations stratified) or independent (plain Monte Carlo: the iterations\n"
        "                        are independent samples, so their spread gives an error bar)\n"
        "  --min-path-length N shortest path length rendered, in segments (default 0)\n"
        "  --max-path-length N longest path length rendered, in segments (default 10)\n"
        "  --radius-factor F   merging radius as a fraction of the scene radius (default 0.003, at most 0.25)\n"
        "  --medium-radius-factor F\n"
        "                      the radius of merging photon points in media, likewise (default 0.03);\n"
        "                        pb2d: the radius of its camera beams\n"
        "  --beam-radius-factor F\n"
        "                      bb1d: the radius of photon beams, likewise (default 0.003)\n"
        "  --beam-paths N      bb1d: light sub-paths per iteration that store photon beams (default 4096)\n"
        "  --techniques LIST   upbp: the techniques it combines, of bpt,surf,pp3d,pb2d,bb1d (default all);\n"
        "                        a camera path hitting a light always counts\n"
        "  --radius-alpha A    radius shrinking exponent in (0, 1] (default 0.75)\n"
        "  --mis balance|power MIS heuristic (default balance)\n"
        "  --photons N         pm, pmfg: photons traced per iteration (default 200000)\n"
        "  --knn K             pm, pmfg: nearest photons per estimate (default 100)\n"
        "  --max-radius F      pm, pmfg: largest search radius, fraction of the scene radius (default 0.05, at most 1)\n"
        "  --layers            also write per-technique layers as FILE-stem.LAYER.ext (those that received\n"
        "                        any contribution) and their list, FILE-stem.layers.json; with -o FILE.exr\n"
        "                        the layers go into FILE.exr itself, as channels LAYER.R, LAYER.G, LAYER.B\n"
        "  --camera N          the N-th camera node of the file (default: the first; a file without\n"
        "                        cameras gets one that frames the whole scene from the front, or,\n"
        "                        when the geometry encloses its centre, one inside: docs/scene_format.md 7.1)\n"
        "  --background R,G,B  add (or replace the file's) uniform background of this linear radiance;\n"
        "  --background none     none (or black, 0,0,0): no background. Default: the file's, and when\n"
        "                        the file has no light at all, a neutral sky and a sun (docs/scene_format.md)\n"
        "  --envmap FILE       light the scene with an equirectangular environment map (.hdr, .exr, .pfm;\n"
        "                        at most 8192x4096) instead of the file's background or the default sky\n"
        "  --envmap-rotate DEG turn the environment about the up axis, counter-clockwise seen from above\n"
        "                        (default 0: the image's centre faces +X)\n"
        "  --envmap-scale S    multiply the environment's radiance by S > 0 (default 1)\n"
        "  --medium S,A,G      fill all space outside the closed meshes with a grey medium (or replace the\n"
        "                        file's scene medium): scattering S >= 0 and absorption A >= 0 per scene\n"
        "                        unit, Henyey-Greenstein asymmetry G in (-1, 1) (docs/scene_format.md 4.4)\n"
        "  -q                  quiet: nothing on success (no summary, notes or progress); errors still go to stderr\n"
        "  --help              this text\n"
        "Ctrl-C or SIGTERM writes the iterations done so far (exit 130 or 143); a second one stops at once.\n"
        "\n"
        "Usage: smallvcm merge [-q] [--exposure EV] [--tonemap clamp|aces] OUT RUN1 RUN2 ...\n"
        "  Averages runs (.pfm, .hdr or .exr, each with its sidecar) of one scene, algorithm, resolution\n"
        "  and settings, with different --seed, weighted by their iterations; OUT (.pfm, .hdr, .exr or\n"
        "  .png) gets a sidecar too. From an .exr only R, G, B are read: its layers are not merged.\n");
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

// aScene as given (aOption: "-s", or "scene" for the positional argument): a Cornell
// scene number becomes its file's path.
std::string ResolveScene(const std::string& aScene, const std::string& aOption) {
    if (aScene.size() == 1 && aScene[0] >= '0' && aScene[0] <= '4')
        return ScenesFolder() + "/" + kCornellScenes[aScene[0] - '0'];
    if (aScene.find_first_not_of("0123456789-") == std::string::npos)
        throw Error(aOption + ": '" + aScene + "' is not a Cornell scene index (0..4) nor a .gltf/.glb file");
    return aScene;
}

std::string WithLayerName(const std::string& aPath, const std::string& aLayer) {
    const size_t dot = aPath.find_last_of('.');
    return aPath.substr(0, dot) + "." + aLayer + aPath.substr(dot);
}

// --layers: FILE-stem.layers.json lists the layer files written.
std::string LayerIndexPath(const std::string& aPath) { return aPath.substr(0, aPath.find_last_of('.')) + ".layers.json"; }

// Before a long render: the image can be written, and nothing that is not a plain file
// (a directory, say) sits where its sidecar goes.
void CheckOutputPaths(const std::string& aPath) {
    smallvcm::CheckOutputPath(aPath);
    struct stat info;
    const std::string sidecarPath = sidecar::SidecarPath(aPath);
    if (::lstat(sidecarPath.c_str(), &info) == 0 && !S_ISREG(info.st_mode))
        throw Error(sidecarPath + ": is in the way of the image's sidecar (not a regular file)");
}

struct CommandLine {
    std::string mScene = "4";
    std::string mSceneOption;  // how the scene was given: "-s", "scene" (the positional argument), or "" (the default)
    std::string mOutput = "smallvcm.png";
    int mWidth = 512, mHeight = 512;
    bool mQuiet = false;
    bool mIterationsGiven = false;
    smallvcm::ImageWriteOptions mWrite;
    smallvcm::RenderOptions mOptions;
    const smallvcm::Integrator* mIntegrator = &smallvcm::BuiltInIntegrator(mOptions.mAlgorithm);
    smallvcm::GltfLoadOptions mLoad;
};

// --exposure and --tonemap, shared by rendering and merging; false if aArg is neither.
bool ParseWriteOption(const std::string& aArg, const std::function<std::string()>& aValue, smallvcm::ImageWriteOptions& oWrite) {
    if (aArg == "--exposure") {
        oWrite.mExposure = ParseNumber<float>(aArg, aValue(), -smallvcm::kMaxExposure, smallvcm::kMaxExposure,
                                              "a finite number of stops in [-32, 32]");
        return true;
    }
    if (aArg == "--tonemap") {
        const std::string name = aValue();
        if (!smallvcm::ParseToneMap(name, oWrite.mToneMap)) throw Error("--tonemap: unknown tone curve '" + name + "' (clamp, aces)");
        return true;
    }
    return false;
}

// "R,G,B" (three finite numbers >= 0: linear radiance) or "none".
void ParseBackground(const std::string& aText, smallvcm::GltfLoadOptions& oLoad) {
    using Background = smallvcm::GltfLoadOptions::Background;
    if (aText == "none") {
        oLoad.mBackground = Background::kNone;
        return;
    }
    const std::string range = "R,G,B (three numbers in [0, 1e30]: linear radiance) or none";
    size_t begin = 0;
    for (int c = 0; c < 3; c++) {
        const size_t comma = aText.find(',', begin);
        if ((c < 2) != (comma != std::string::npos)) throw Error("--background: '" + aText + "' is not " + range);
        const std::string part = aText.substr(begin, c < 2 ? comma - begin : std::string::npos);
        oLoad.mBackgroundRadiance[c] = ParseNumber<float>("--background", part, 0.f, 1e30f, range.c_str());
        begin = comma + 1;
    }
    oLoad.mBackground = Background::kRadiance;
}

// "SIGMA_S,SIGMA_A,G": a grey scene-wide medium. The loader puts it into the scene before
// its Scene::Finalize, which validates media, so the scene is finalized with it.
void ParseMedium(const std::string& aText, smallvcm::GltfLoadOptions& oLoad) {
    const std::string range = "SIGMA_S,SIGMA_A,G (three numbers: scattering and absorption in [0, 1e30] per scene unit, "
                              "Henyey-Greenstein asymmetry in (-1, 1))";
    float values[3];
    size_t begin = 0;
    for (int k = 0; k < 3; k++) {
        const size_t comma = aText.find(',', begin);
        if ((k < 2) != (comma != std::string::npos)) throw Error("--medium: '" + aText + "' is not " + range);
        const std::string part = aText.substr(begin, k < 2 ? comma - begin : std::string::npos);
        values[k] = k < 2 ? ParseNumber<float>("--medium", part, 0.f, 1e30f, range.c_str())
                          : ParseNumber<float>("--medium", part, -1.f, 1.f, range.c_str());
        if (k == 2 && !(std::abs(values[k]) < 1.f)) throw Error("--medium: '" + part + "' is not " + range);
        begin = comma + 1;
    }
    oLoad.mReplaceSceneMedium = true;
    oLoad.mSceneMedium = smallvcm::Medium();
    oLoad.mSceneMedium.mName = "scene medium (--medium)";
    oLoad.mSceneMedium.mSigmaS = smallvcm::Vec3(values[0]);
    oLoad.mSceneMedium.mSigmaA = smallvcm::Vec3(values[1]);
    oLoad.mSceneMedium.mG = values[2];
}

CommandLine Parse(int argc, char** argv) {
    CommandLine cl;
    cl.mOptions.mIterations = 1;
    // Sobol points lower pt's, bpt's and vcm's error at equal time on SmallVCM's scenes
    // (docs/performance.md, "Samplers"); the library's RenderOptions keep independent
    // numbers, which the course's derivations and the tests' error bars assume.
    cl.mOptions.mSampler = smallvcm::SamplerType::kSobol;
    auto value = [&](int& i) -> std::string {
        const std::string option = argv[i];
        if (i + 1 >= argc) throw Error(option + ": needs a value");
        return argv[++i];
    };
    bool backgroundGiven = false;
    std::string envmapSettingGiven;  // --envmap-rotate or --envmap-scale, if either was given
    for (int i = 1; i < argc; i++) {
        const std::string arg = argv[i];
        if (arg == "--help" || arg == "-h") { PrintHelp(); std::exit(0); }
        else if (arg == "-s" || arg.empty() || arg[0] != '-') {
            // -s given again replaces the scene, as every option does; a positional scene
            // beside any other is a mistake.
            const bool positional = arg != "-s";
            const std::string scene = positional ? arg : value(i);
            if (cl.mSceneOption == "scene" || (positional && !cl.mSceneOption.empty())) {
                const bool merge = cl.mScene == "merge" || scene == "merge";
                throw Error("scene: two given, '" + cl.mScene + "' and '" + scene + "': a run renders one scene (give SCENE or -s SCENE once)" +
                            (merge ? "; merge is a subcommand only as the first argument (smallvcm merge OUT RUN...)" : ""));
            }
            cl.mScene = scene;
            cl.mSceneOption = positional ? "scene" : "-s";
        }
        else if (arg == "-a") {
            const std::string name = value(i);
            cl.mIntegrator = smallvcm::FindIntegrator(name);
            if (!cl.mIntegrator) throw Error("-a: unknown algorithm '" + name + "' (" + IntegratorNames() + ")");
            // A built-in's name also sets the Algorithm, so the options read as they would in code.
            if (const auto algorithm = smallvcm::ParseAlgorithm(name)) cl.mOptions.mAlgorithm = *algorithm;
        }
        else if (arg == "-i") { cl.mOptions.mIterations = ParseNumber<int>(arg, value(i), 1, 100000000, "an integer in [1, 1e8]"); cl.mIterationsGiven = true; }
        else if (arg == "-t") cl.mOptions.mSeconds = ParseNumber<double>(arg, value(i), 1e-3, 1e7, "a number of seconds in [0.001, 1e7]");
        else if (arg == "-o") {
            cl.mOutput = value(i);
            if (!smallvcm::IsSupportedImagePath(cl.mOutput))
                throw Error("-o: '" + cl.mOutput + "' has an unknown image format (use .png, .hdr, .pfm or .exr, in any case)");
        }
        else if (arg == "-r") {
            const std::string text = value(i);
            const size_t x = text.find('x');
            if (x == std::string::npos) throw Error("-r: '" + text + "' is not WIDTHxHEIGHT (e.g. 512x512)");
            cl.mWidth = ParseNumber<int>(arg, text.substr(0, x), 1, 16384, "WIDTHxHEIGHT with sizes in [1, 16384]");
            cl.mHeight = ParseNumber<int>(arg, text.substr(x + 1), 1, 16384, "WIDTHxHEIGHT with sizes in [1, 16384]");
        }
        else if (arg == "-j") {
            const int most = smallvcm::MaxThreads();
            const std::string range = "an integer in [1, " + std::to_string(most) + "] (at most 4 threads per core: more only cost memory and time)";
            cl.mOptions.mThreads = ParseNumber<int>(arg, value(i), 1, most, range.c_str());
        }
        else if (arg == "--seed") cl.mOptions.mSeed = ParseNumber<uint64_t>(arg, value(i), 0, UINT64_MAX, "a non-negative integer");
        else if (arg == "--min-path-length") cl.mOptions.mMinPathLength = ParseNumber<int>(arg, value(i), 0, 1000, "an integer in [0, 1000]");
        else if (arg == "--max-path-length") cl.mOptions.mMaxPathLength = ParseNumber<int>(arg, value(i), 1, 1000, "an integer in [1, 1000]");
        else if (arg == "--radius-factor")
            cl.mOptions.mRadiusFactor = ParseNumber<float>(arg, value(i), 1e-7f, smallvcm::kMaxRadiusFactor,
                "a number in [1e-7, 0.25] (a larger merging radius blurs light across whole surfaces and makes every lookup "
                "visit most light vertices: hundreds of times slower)");
        else if (arg == "--medium-radius-factor")
            cl.mOptions.mMediumRadiusFactor = ParseNumber<float>(arg, value(i), 1e-7f, smallvcm::kMaxRadiusFactor,
                "a number in [1e-7, 0.25]");
        else if (arg == "--beam-radius-factor")
            cl.mOptions.mBeamRadiusFactor = ParseNumber<float>(arg, value(i), 1e-7f, smallvcm::kMaxRadiusFactor,
                "a number in [1e-7, 0.25]");
        else if (arg == "--beam-paths")
            cl.mOptions.mBeamPaths = ParseNumber<int>(arg, value(i), 1, 1 << 30, "an integer in [1, 2^30]");
        else if (arg == "--techniques") {
            const std::string list = value(i);
            const std::optional<uint32_t> techniques = smallvcm::ParseUpbpTechniques(list);
            if (!techniques)
                throw Error("--techniques: '" + list + "' is not a comma-separated list of distinct names of bpt, surf, pp3d, pb2d, bb1d");
            cl.mOptions.mUpbpTechniques = *techniques;
        }
        else if (arg == "--radius-alpha") {
            cl.mOptions.mRadiusAlpha = ParseNumber<float>(arg, value(i), 0.f, 1.f, "a number in (0, 1]");
            if (!(cl.mOptions.mRadiusAlpha > 0.f)) throw Error("--radius-alpha: '0' is not a number in (0, 1]");
        }
        else if (arg == "--sampler") {
            const std::string name = value(i);
            const std::optional<smallvcm::SamplerType> sampler = smallvcm::ParseSampler(name);
            if (!sampler) throw Error("--sampler: unknown sampler '" + name + "' (independent, sobol)");
            cl.mOptions.mSampler = *sampler;
        }
        else if (arg == "--mis") {
            const std::string name = value(i);
            if (name == "balance") cl.mOptions.mMisHeuristic = smallvcm::MisHeuristic::kBalance;
            else if (name == "power") cl.mOptions.mMisHeuristic = smallvcm::MisHeuristic::kPower;
            else throw Error("--mis: unknown heuristic '" + name + "' (balance, power)");
        }
        else if (arg == "--photons") cl.mOptions.mPhotonCount = ParseNumber<int>(arg, value(i), 1, 100000000, "an integer in [1, 1e8]");
        else if (arg == "--knn") cl.mOptions.mNearestPhotons = ParseNumber<int>(arg, value(i), 1, 100000, "an integer in [1, 100000]");
        else if (arg == "--max-radius")
            cl.mOptions.mMaxPhotonRadiusFactor = ParseNumber<float>(arg, value(i), 1e-6f, smallvcm::kMaxPhotonRadiusFactor,
                "a number in [1e-6, 1] (a search beyond the scene's radius finds nothing more)");
        else if (arg == "--layers") cl.mOptions.mTechniqueLayers = true;
        else if (arg == "--camera") cl.mLoad.mCamera = ParseNumber<int>(arg, value(i), 0, 1000000, "a camera number in [0, 1e6]");
        else if (arg == "--background") { ParseBackground(value(i), cl.mLoad); backgroundGiven = true; }
        else if (arg == "--medium") ParseMedium(value(i), cl.mLoad);
        else if (arg == "--envmap") {
            cl.mLoad.mEnvironmentMap = value(i);
            if (cl.mLoad.mEnvironmentMap.empty()) throw Error("--envmap: needs a file name");
        }
        else if (arg == "--envmap-rotate") {
            cl.mLoad.mEnvironmentRotationDegrees = ParseNumber<float>(arg, value(i), -3600.f, 3600.f, "a number of degrees in [-3600, 3600]");
            envmapSettingGiven = arg;
        }
        else if (arg == "--envmap-scale") {
            const std::string text = value(i);
            cl.mLoad.mEnvironmentScale = ParseNumber<float>(arg, text, 0.f, 1e30f, "a number in (0, 1e30]");
            if (!(cl.mLoad.mEnvironmentScale > 0.f)) throw Error(arg + ": '" + text + "' is not a number in (0, 1e30]");
            envmapSettingGiven = arg;
        }
        else if (arg == "-q") cl.mQuiet = true;
        else if (ParseWriteOption(arg, [&] { return value(i); }, cl.mWrite)) {}
        else throw Error(arg + ": unknown option (see --help)");
    }
    if (cl.mOptions.mSeconds > 0.0 && !cl.mIterationsGiven) cl.mOptions.mIterations = 0;  // until time is up
    if (!cl.mLoad.mEnvironmentMap.empty() && backgroundGiven)
        throw Error("--envmap: --background replaces the background too: give one of them");
    if (cl.mLoad.mEnvironmentMap.empty() && !envmapSettingGiven.empty())
        throw Error(envmapSettingGiven + ": applies to an environment map: give --envmap FILE too");
    if (cl.mOptions.mMinPathLength > cl.mOptions.mMaxPathLength)
        throw Error("--min-path-length: must not exceed --max-path-length (" + std::to_string(cl.mOptions.mMaxPathLength) + ")");
    if (cl.mOptions.mTechniqueLayers && cl.mIntegrator == &smallvcm::BuiltInIntegrator(smallvcm::Algorithm::kEyeLight))
        throw Error("--layers: the eye light has no techniques to separate");
    cl.mOptions.mProgress = !cl.mQuiet;
    cl.mScene = ResolveScene(cl.mScene, cl.mSceneOption.empty() ? "-s" : cl.mSceneOption);
    return cl;
}

// The sidecar of the main image; a layer's differs only in estimator.layer.
sidecar::Json RenderRecord(const CommandLine& aCl, const smallvcm::GltfLoadReport& aReport, const smallvcm::RenderResult& aResult,
                           int aThreads, int aStopSignal) {
    using sidecar::Json;
    using sidecar::Shortest;
    using Background = smallvcm::GltfLoadOptions::Background;
    const smallvcm::RenderOptions& o = aCl.mOptions;
    const smallvcm::Vec3& radiance = aCl.mLoad.mBackgroundRadiance;
    Json estimator;
    estimator["algorithm"] = aCl.mIntegrator->mName;
    estimator["scene_fnv1a64"] = sidecar::FileFnv1a64(aCl.mScene);
    estimator["width"] = aCl.mWidth;
    estimator["height"] = aCl.mHeight;
    estimator["camera"] = aReport.mCamera;
    estimator["background"] = aCl.mLoad.mBackground == Background::kFromFile ? Json("from file")
                              : aCl.mLoad.mBackground == Background::kNone   ? Json("none")
                                                                             : Json{Shortest(radiance.x), Shortest(radiance.y), Shortest(radiance.z)};
    if (!aCl.mLoad.mEnvironmentMap.empty()) {
        // The map's bytes, not its name, decide whether two runs lit the scene alike.
        Json environment;
        environment["fnv1a64"] = sidecar::FileFnv1a64(aCl.mLoad.mEnvironmentMap);
        environment["rotate_degrees"] = Shortest(aCl.mLoad.mEnvironmentRotationDegrees);
        environment["scale"] = Shortest(aCl.mLoad.mEnvironmentScale);
        estimator["background"] = Json{{"envmap", environment}};
    }
    if (aCl.mLoad.mReplaceSceneMedium) {  // the file's medium is in its fingerprint; this one is not
        const smallvcm::Medium& medium = aCl.mLoad.mSceneMedium;
        estimator["medium"] = {{"sigma_s", Shortest(medium.mSigmaS.x)}, {"sigma_a", Shortest(medium.mSigmaA.x)}, {"g", Shortest(medium.mG)}};
    }
    // Only the settings a built-in algorithm uses: runs that differ in one it ignores still
    // merge. An integrator linked in from elsewhere may read any of them: all are recorded.
    using smallvcm::Algorithm;
    const bool builtIn = aCl.mIntegrator == &smallvcm::BuiltInIntegrator(o.mAlgorithm);
    auto uses = [&](std::initializer_list<Algorithm> aAlgorithms) {
        return !builtIn || std::find(aAlgorithms.begin(), aAlgorithms.end(), o.mAlgorithm) != aAlgorithms.end();
    };
    const bool merges = uses({Algorithm::kProgressivePhotonMapping, Algorithm::kBidirectionalPhotonMapping, Algorithm::kVertexConnectionMerging,
                              Algorithm::kBeamRadianceEstimate, Algorithm::kPhotonBeams});
    const bool photonMaps = uses({Algorithm::kPhotonMapping, Algorithm::kPhotonMappingFinalGather});
    if (!builtIn || o.mAlgorithm != Algorithm::kEyeLight) {
        estimator["min_path_length"] = o.mMinPathLength;
        estimator["max_path_length"] = o.mMaxPathLength;
        estimator["mis"] = o.mMisHeuristic == smallvcm::MisHeuristic::kPower ? "power" : "balance";
    }
    if (merges) {
        estimator["radius_factor"] = Shortest(o.mRadiusFactor);
        estimator["medium_radius_factor"] = Shortest(o.mMediumRadiusFactor);
        estimator["beam_radius_factor"] = Shortest(o.mBeamRadiusFactor);
        estimator["beam_paths"] = o.mBeamPaths;
        estimator["radius_alpha"] = Shortest(o.mRadiusAlpha);
    }
    if (photonMaps) {
        estimator["photons"] = o.mPhotonCount;
        estimator["knn"] = o.mNearestPhotons;
        estimator["max_radius"] = Shortest(o.mMaxPhotonRadiusFactor);
    }
    estimator["layer"] = nullptr;
    Json run;
    run["iterations_requested"] = o.mIterations > 0 ? Json(o.mIterations) : Json(nullptr);
    run["seconds_budget"] = o.mSeconds > 0.0 ? Json(o.mSeconds) : Json(nullptr);
    run["threads"] = aThreads;
    run["sampler"] = smallvcm::SamplerName(o.mSampler);
    run["stopped_early"] = aResult.mStopped;
    run["stop_signal"] = aStopSignal == SIGTERM ? Json("SIGTERM") : aStopSignal == SIGINT ? Json("SIGINT") : Json(nullptr);
    Json record;
    record["format"] = sidecar::kFormat;
    record["image"] = nullptr;  // sidecar::AddImage fills in the image's name, fingerprint and mean
    record["image_fnv1a64"] = nullptr;
    record["scene"] = aCl.mScene;
    if (!aCl.mLoad.mEnvironmentMap.empty()) record["envmap"] = aCl.mLoad.mEnvironmentMap;
    record["estimator"] = estimator;
    record["seed"] = o.mSeed;
    record["iterations"] = aResult.mIterations;
    record["seconds"] = aResult.mSeconds;
    record["run"] = run;
    record["png"] = sidecar::PngRecord(aCl.mWrite);
    record["mean"] = nullptr;
    record["smallvcm_commit"] = sidecar::Commit();
    return record;
}

// What a render writes: the files (all or none) and how many layers they hold.
struct Outputs {
    std::vector<smallvcm::OutputFile> mFiles;
    size_t mLayers = 0;
};

// The image, each layer that received any contribution and, with --layers, the index
// FILE-stem.layers.json of what was written, every image with its sidecar. A layer is a
// file of its own, FILE-stem.LAYER.ext with its sidecar, except with an .exr: there all
// layers go into the one file, as channels LAYER.R, LAYER.G, LAYER.B beside the image's
// R, G, B, and the index names the file and the channels of each.
Outputs OutputFiles(const CommandLine& aCl, const smallvcm::RenderResult& aResult, const sidecar::Json& aRecord) {
    Outputs outputs;
    if (!aCl.mOptions.mTechniqueLayers) {
        sidecar::AddImage(outputs.mFiles, aCl.mOutput, aResult.mImage, aCl.mWrite, aRecord);
        return outputs;
    }
    const bool oneFile = smallvcm::ImageFormatOf(aCl.mOutput) == smallvcm::ImageFormat::kExr;
    std::vector<smallvcm::ExrLayer> exrLayers;
    std::vector<smallvcm::OutputFile> layerFiles;
    sidecar::Json written = sidecar::Json::array(), empty = sidecar::Json::array();
    for (const auto& [name, image] : aResult.mLayers) {
        const bool contributed = std::any_of(image.mPixels.begin(), image.mPixels.end(),
                                             [](const smallvcm::Vec3& aPixel) { return aPixel != smallvcm::Vec3(0.f); });
        if (!contributed) {
            empty.push_back(name);
            continue;
        }
        sidecar::Json entry = {{"layer", name}};
        if (oneFile) {
            exrLayers.push_back({name, &image});
            entry["file"] = sidecar::FileName(aCl.mOutput);
            entry["channels"] = {name + ".R", name + ".G", name + ".B"};
        } else {
            const std::string path = WithLayerName(aCl.mOutput, name);
            sidecar::Json record = aRecord;
            record["estimator"]["layer"] = name;
            sidecar::AddImage(layerFiles, path, image, aCl.mWrite, record);
            entry["file"] = sidecar::FileName(path);
        }
        entry["mean"] = smallvcm::MeanValue(image);
        written.push_back(entry);
    }
    sidecar::AddImage(outputs.mFiles, aCl.mOutput, aResult.mImage, aCl.mWrite, aRecord, exrLayers);
    for (smallvcm::OutputFile& file : layerFiles) outputs.mFiles.push_back(std::move(file));
    const sidecar::Json index = {{"image", sidecar::FileName(aCl.mOutput)}, {"layers", written}, {"layers_without_contribution", empty}};
    const std::string text = index.dump(2) + "\n";
    outputs.mFiles.push_back({LayerIndexPath(aCl.mOutput), std::vector<unsigned char>(text.begin(), text.end())});
    outputs.mLayers = written.size();
    return outputs;
}

// For the summary line: " (+ N layers, listed in FILE-stem.layers.json)" when --layers.
std::string LayersWritten(const CommandLine& aCl, const Outputs& aOutputs) {
    if (!aCl.mOptions.mTechniqueLayers) return "";
    const size_t layers = aOutputs.mLayers;
    return " (+ " + std::to_string(layers) + " layer" + (layers == 1 ? "" : "s") + ", listed in " + LayerIndexPath(aCl.mOutput) + ")";
}

// smallvcm merge [-q] [--exposure EV] [--tonemap clamp|aces] OUT RUN1 RUN2 ...
int MergeMain(int argc, char** argv) {
    bool quiet = false;
    smallvcm::ImageWriteOptions write;
    std::vector<std::string> paths;
    try {
        for (int i = 2; i < argc; i++) {
            const std::string arg = argv[i];
            auto value = [&]() -> std::string {
                if (i + 1 >= argc) throw Error(arg + ": needs a value");
                return argv[++i];
            };
            if (arg == "-q") quiet = true;
            else if (ParseWriteOption(arg, value, write)) {}
            else if (arg.size() > 1 && arg[0] == '-') throw Error(arg + ": unknown option of merge (-q, --exposure, --tonemap)");
            else paths.push_back(arg);
        }
        if (paths.size() < 2) throw Error("merge: needs an output and at least one run (smallvcm merge OUT.pfm RUN1.pfm RUN2.pfm ...)");
        if (!smallvcm::IsSupportedImagePath(paths[0]))
            throw Error(paths[0] + ": unknown image format for the merged image (use .pfm, .hdr, .exr or .png)");
    } catch (const Error& e) {
        std::fprintf(stderr, "smallvcm: %s\n", e.what());
        return 2;
    }
    try {
        CheckOutputPaths(paths[0]);
        const std::vector<std::string> inputs(paths.begin() + 1, paths.end());
        const sidecar::MergeResult merged = sidecar::Merge(paths[0], inputs, write);
        if (!quiet)
            std::printf("merged %zu run%s of %s: %lld iteration%s, mean %.6f -> %s\n", inputs.size(), inputs.size() == 1 ? "" : "s",
                        merged.mAlgorithm.c_str(), static_cast<long long>(merged.mIterations), merged.mIterations == 1 ? "" : "s",
                        merged.mMean, paths[0].c_str());
    } catch (const Error& e) {
        std::fprintf(stderr, "smallvcm: %s\n", e.what());
        return 1;
    } catch (const std::bad_alloc&) {
        std::fprintf(stderr, "smallvcm: out of memory while merging\n");
        return 1;
    }
    return 0;
}

} // namespace

int main(int argc, char** argv) {
    if (argc >= 2 && std::string(argv[1]) == "merge") return MergeMain(argc, argv);
    CommandLine cl;
    try {
        cl = Parse(argc, argv);
    } catch (const Error& e) {
        std::fprintf(stderr, "smallvcm: %s\n", e.what());
        return 2;
    }
    try {
        CheckOutputPaths(cl.mOutput);  // before a long render, not after it
        const std::string& scenePath = cl.mScene;
        smallvcm::GltfLoadReport report;
        cl.mLoad.mDefaultCameraAspect = float(cl.mWidth) / float(cl.mHeight);
        const auto loadStart = std::chrono::steady_clock::now();
        smallvcm::Scene scene = smallvcm::LoadGltfScene(scenePath, &report, cl.mLoad);  // parsing and the BVH build
        const double loadSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - loadStart).count();
        if (report.mSkippedDegenerateTriangles > 0 && !cl.mQuiet)
            std::fprintf(stderr, "smallvcm: %s: note: skipped %d degenerate (zero-area) triangles\n", scenePath.c_str(),
                         report.mSkippedDegenerateTriangles);
        if (!cl.mQuiet)
            for (const std::string& note : report.mNotes) std::fprintf(stderr, "smallvcm: %s: note: %s\n", scenePath.c_str(), note.c_str());
        scene.mCamera.SetResolution(cl.mWidth, cl.mHeight);
        const int threads = cl.mOptions.mThreads > 0 ? cl.mOptions.mThreads : int(std::max(1u, std::thread::hardware_concurrency()));
        try {
            smallvcm::CheckRenderMemory(scene.mCamera, cl.mOptions, *cl.mIntegrator, threads);
        } catch (const Error& e) {
            std::fprintf(stderr, "smallvcm: -r: %s\n", e.what() + std::strlen("memory: "));
            return 2;
        }
        cl.mOptions.mStopRequested = &gStopRequested;
        std::signal(SIGINT, OnStopSignal);
        std::signal(SIGTERM, OnStopSignal);
        const smallvcm::RenderResult result = smallvcm::Render(scene, cl.mOptions, *cl.mIntegrator);
        const int stopSignal = gStopSignal.load();
        if (result.mStopped && result.mIterations == 0) {
            std::fprintf(stderr, "smallvcm: interrupted (%s) before the first iteration finished; nothing written\n",
                         stopSignal == SIGTERM ? "SIGTERM" : "SIGINT");
            return 128 + stopSignal;
        }
        if (result.mStopped)
            std::fprintf(stderr, "smallvcm: interrupted (%s): writing the %d iteration%s accumulated so far\n",
                         stopSignal == SIGTERM ? "SIGTERM" : "SIGINT", result.mIterations, result.mIterations == 1 ? "" : "s");
        const Outputs outputs = OutputFiles(cl, result, RenderRecord(cl, report, result, threads, stopSignal));
        smallvcm::WriteFilesTogether(outputs.mFiles);
        if (!cl.mQuiet)
            std::printf("%s: %s, %dx%d, %d iteration%s in %.2f s (%.3f s/iteration), mean %.6f -> %s%s; %zu triangles and %zu "
                        "spheres loaded in %.2f s (reading %.2f s, BVH build and checks %.2f s); %s\n", scenePath.c_str(),
                        cl.mIntegrator->mName.c_str(), cl.mWidth, cl.mHeight, result.mIterations,
                        result.mIterations == 1 ? "" : "s", result.mSeconds, result.mSeconds / std::max(1, result.mIterations),
                        smallvcm::MeanValue(result.mImage), cl.mOutput.c_str(), LayersWritten(cl, outputs).c_str(),
                        scene.mTriangles.size(), scene.mSpheres.size(), loadSeconds, report.mReadSeconds,
                        report.mFinalizeSeconds, report.mCamera.c_str());
        // A signal that came while the image was written (held back until then) counts too.
        if (gStopSignal.load() != 0) return 128 + gStopSignal.load();
    } catch (const Error& e) {
        std::fprintf(stderr, "smallvcm: %s\n", e.what());
        return 1;
    } catch (const std::bad_alloc&) {
        std::fprintf(stderr, "smallvcm: out of memory (use fewer threads, a smaller resolution or a smaller scene)\n");
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "smallvcm: unexpected error: %s\n", e.what());
        return 1;
    }
    return 0;
}
