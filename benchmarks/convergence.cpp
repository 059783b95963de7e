// convergence — speed against accuracy: how fast each estimator's error falls, per
// iteration and per second, on the Cornell scenes.
//
//   build/convergence --make-references                  # the full study (see below)
//   build/convergence --scenes 4 --algorithms pt,bpt,vcm --max-iterations 64
//   build/convergence --quick --out /tmp/quick.csv       # tiny, for the test
//   python3 benchmarks/plot_convergence.py convergence.csv     # charts and efficiency table
//
// For every scene and estimator ONE renderer (CreateRenderer) runs iterations 0, 1, 2, ...
// with IterationSampler(sampler, seed, i), exactly as Render() would, and at the checkpoints
// 1, 2, 4, 8, ... up to --max-iterations (and the last iteration, if it is not a power
// of two, or the iteration at which --max-seconds ran out) the film is resolved and
// compared with the scene's reference image. One CSV row per checkpoint:
//
//   scene,algorithm,iterations,seconds,rmse,relmse,rmse_diffuse
//
//   scene      Cornell scene index (0..4, as build/smallvcm -s)
//   seconds    rendering time since the renderer was created, summed over the
//              iterations: building the renderer and running iterations count, resolving
//              the film and computing the metrics do not. --clock wall (default) is
//              wall-clock time; --clock cpu is the rendering thread's CPU time (only with
//              --threads 1), which other processes on a shared machine do not inflate.
//   rmse       Rmse(image, reference): root mean squared error over pixels and channels
//   relmse     RelativeMse(image, reference): mean of (x - ref)^2 / (ref^2 + 0.01)
//   rmse_diffuse  the RMSE over the diffuse region only: the pixels whose whole footprint
//              (rays through its four corners and its centre) first meets a purely
//              Lambertian surface, no light, no Phong lobe, no mirror or glass. There the
//              pixel integral is the smoothest, so it is where a low-discrepancy sampler
//              can gain the most (edges, caustics and what mirrors show gain less).
//
// Next to the CSV, FILE.txt (FILE.csv -> FILE.txt) records the settings, the command
// line and, per scene, the reference used and its estimated noise.
//
// REFERENCES. --references DIR holds cornell_<i>_<W>x<H>.pfm, one per scene and
// resolution, each with cornell_<i>_<W>x<H>.txt (its settings, time and estimated noise).
// --make-references renders them first (overwriting), with --reference-iterations
// iterations (default 4096) on every core, and a seed different from the study's (the
// same random numbers in the reference and in an estimator would hide that estimator's
// noise). The estimator of a reference is
//   * BPT where it can converge: every light path has at least one BPT technique when
//     every light has an area (area, sphere and background lights): scenes 1, 3 and 4;
//   * VCM where BPT cannot: with a delta light (point light, sun) and a specular surface,
//     the paths light -> specular -> diffuse -> specular -> camera (a caustic of the glass
//     sphere seen in the mirror sphere) have no BPT technique at all -- no camera sub-path
//     can hit a delta light, the light sub-path cannot reach the pinhole through a
//     specular bounce, and a connection needs two non-specular ends. BPT's image misses
//     them however long it runs; VCM's merging at the diffuse vertex finds them, and its
//     bias vanishes as the radius shrinks (consistent). Scenes 0 (sun) and 2 (point).
//   The rule is applied to the loaded scene (a delta light and a specular material ->
//   VCM), not to the scene index.
// --reference-sampler sobol renders the reference with Owen-scrambled Sobol points (its
// noise falls faster); its halves then have their own seeds (the reference seed and that
// seed + 1), each running iterations 0, 1, ... M/2 - 1: the even and odd iterations of
// ONE scrambled sequence are not independent, and their difference would overstate the
// noise of their mean.
// A reference's noise is estimated from two independent halves A and B (even and odd
// iterations): reference = (A + B) / 2, so its noise RMSE is about Rmse(A, B) / 2 (on the
// whole image, and on the diffuse region: noise_rmse_diffuse). The
// measured error of an estimator is sqrt(its own MSE + that noise^2): a curve flattens
// when it approaches the reference's noise floor.
//
// --quick: 16x16, checkpoints up to 128 iterations, the references rendered on the fly
// (same rule, 1024 iterations, written next to the CSV unless --references is given),
// pm/pmfg with 1024 photons per iteration, and a merging radius of 0.1 x the scene
// radius for ppm/bpm/vcm: with only 256 light sub-paths per iteration SmallVCM's 0.003
// would catch a photon once per few hundred pixel-iterations; 0.1 is the 512x512 default
// scaled by the ratio of pixel sizes (512 / 16 = 32, 0.003 x 32 ~ 0.1). Any option given
// explicitly wins over what --quick sets. Takes a few seconds.
//
// The study in docs/performance.md (128x128, all scenes and estimators, 10 s of CPU time
// each, references of 2048 iterations; about 17 CPU-minutes) was made with
//   build/convergence --make-references --reference-iterations 2048 --max-iterations 4096
//       --max-seconds 10 --clock cpu --out docs/performance/convergence.csv
//
// Exit codes: 0 done, 1 a problem with a scene, a reference or an output file, 2 a bad
// option; each problem is one line "convergence: ..." on stderr.
// Build: make build/convergence. Run with --help for the options.

#include "smallvcm.hpp"
#include "examples/command_line.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <unistd.h>

namespace {

using smallvcm::Algorithm;
using smallvcm::Error;
namespace fs = std::filesystem;

const char* const kCornellScenes[] = {
    "cornell_0_sun.gltf", "cornell_1_mirror_ceiling.gltf", "cornell_2_point.gltf",
    "cornell_3_background.gltf", "cornell_4_default.gltf",
};
const char* const kAllEstimators = "pt,lt,ppm,bpm,bpt,vcm,pm,pmfg";

void PrintHelp() {
    std::printf(
        "Usage: convergence [options]\n"
        "  --scenes LIST             Cornell scenes, e.g. 0,1,2,3,4 (default: all)\n"
        "  --algorithms LIST         estimators among pt,lt,ppm,bpm,bpt,vcm,pm,pmfg (default: all)\n"
        "  --resolution WxH          image size (default 128x128; --quick: 16x16)\n"
        "  --max-iterations N        last checkpoint; checkpoints 1, 2, 4, ... N (default 256; --quick: 128)\n"
        "  --max-seconds S           also stop an estimator once it has rendered S seconds (default: no limit)\n"
        "  --threads T               rendering threads (default 1, so that seconds compare fairly)\n"
        "  --clock wall|cpu          seconds as wall-clock time or the thread's CPU time (cpu: --threads 1)\n"
        "  --seed N                  base seed of the estimators (default 1234)\n"
        "  --sampler S               the estimators' sampler: independent (default) or sobol\n"
        "  --out FILE.csv            output (default convergence.csv); settings go to FILE.txt\n"
        "  --references DIR          reference images cornell_<i>_<W>x<H>.pfm\n"
        "                            (default docs/performance/references; --quick: the folder of --out)\n"
        "  --make-references         render the references first (BPT, or VCM where BPT cannot converge)\n"
        "  --reference-iterations M  iterations of a reference (default 4096; --quick: 1024)\n"
        "  --reference-seed N        base seed of the references (default 20240917)\n"
        "  --reference-sampler S     the references' sampler: independent (default) or sobol\n"
        "  --photons N               pm, pmfg: photons per iteration (default: the library's; --quick: 1024)\n"
        "  --radius-factor F         ppm, bpm, vcm: merging radius / scene radius (default: the library's;\n"
        "                            --quick: 0.1)\n"
        "  --quick                   tiny run with on-the-fly references, for the test (a few seconds)\n"
        "  -q                        no progress lines on stderr\n"
        "  --help                    this text\n");
}

std::vector<std::string> SplitList(const std::string& aOption, const std::string& aText) {
    std::vector<std::string> items;
    std::string item;
    std::stringstream stream(aText);
    while (std::getline(stream, item, ',')) {
        if (item.empty()) throw Error(aOption + ": '" + aText + "' has an empty item");
        items.push_back(item);
    }
    if (items.empty()) throw Error(aOption + ": needs at least one item");
    return items;
}

// The repository's folder, from this executable's location (build/ -> ..), or ".".
std::string RepositoryFolder() {
    char buffer[4096];
    const ssize_t length = readlink("/proc/self/exe", buffer, sizeof(buffer) - 1);
    if (length > 0) {
        const fs::path exe(std::string(buffer, size_t(length)));
        const fs::path candidate = exe.parent_path().parent_path();
        std::error_code ignored;
        if (fs::exists(candidate / "scenes" / kCornellScenes[0], ignored)) {
            // Relative to the working folder when possible, so that the recorded
            // settings read "docs/performance/..." when run from the repository.
            const fs::path relative = fs::proximate(candidate, ignored);
            const bool outside = relative.empty() || *relative.begin() == "..";
            return outside ? candidate.string() : relative.string();
        }
    }
    return ".";
}

std::string ScenePath(int aIndex) {
    if (const char* fromEnvironment = std::getenv("SMALLVCM_SCENES"))
        return std::string(fromEnvironment) + "/" + kCornellScenes[aIndex];
    return RepositoryFolder() + "/scenes/" + kCornellScenes[aIndex];
}

struct CommandLine {
    std::vector<int> mScenes;
    std::vector<Algorithm> mAlgorithms;
    std::optional<int> mWidth, mHeight, mMaxIterations, mReferenceIterations, mPhotons;
    std::optional<float> mRadiusFactor;
    std::optional<std::string> mReferences;
    double mMaxSeconds = 0.0;
    int mThreads = 1;
    bool mCpuClock = false;
    uint64_t mSeed = 1234;
    smallvcm::SamplerType mSampler = smallvcm::SamplerType::kIndependent;
    uint64_t mReferenceSeed = 20240917;
    smallvcm::SamplerType mReferenceSampler = smallvcm::SamplerType::kIndependent;
    std::string mOut = "convergence.csv";
    bool mMakeReferences = false;
    bool mQuick = false;
    bool mQuiet = false;
    std::string mCommand;  // as typed, for the settings file
};

CommandLine Parse(int argc, char** argv) {
    CommandLine cl;
    for (int i = 0; i < argc; i++) cl.mCommand += (i ? " " : "") + std::string(argv[i]);
    auto value = [&](int& i) -> std::string {
        const std::string option = argv[i];
        if (i + 1 >= argc) throw Error(option + ": needs a value");
        return argv[++i];
    };
    std::string scenes = "0,1,2,3,4", algorithms = kAllEstimators;
    for (int i = 1; i < argc; i++) {
        const std::string arg = argv[i];
        if (arg == "--help" || arg == "-h") { PrintHelp(); std::exit(0); }
        else if (arg == "--scenes") scenes = value(i);
        else if (arg == "--algorithms") algorithms = value(i);
        else if (arg == "--resolution") {
            const std::string text = value(i);
            const size_t x = text.find('x');
            if (x == std::string::npos) throw Error("--resolution: '" + text + "' is not WIDTHxHEIGHT (e.g. 128x128)");
            cl.mWidth = ParseNumber<int>(arg, text.substr(0, x), 1, 8192, "WIDTHxHEIGHT with sizes in [1, 8192]");
            cl.mHeight = ParseNumber<int>(arg, text.substr(x + 1), 1, 8192, "WIDTHxHEIGHT with sizes in [1, 8192]");
        }
        else if (arg == "--max-iterations") cl.mMaxIterations = ParseNumber<int>(arg, value(i), 1, 1 << 24, "an integer in [1, 16777216]");
        else if (arg == "--max-seconds") cl.mMaxSeconds = ParseNumber<double>(arg, value(i), 1e-3, 1e7, "a number of seconds in [0.001, 1e7]");
        else if (arg == "--threads") cl.mThreads = ParseNumber<int>(arg, value(i), 1, 1024, "an integer in [1, 1024]");
        else if (arg == "--clock") {
            const std::string name = value(i);
            if (name == "wall") cl.mCpuClock = false;
            else if (name == "cpu") cl.mCpuClock = true;
            else throw Error("--clock: unknown clock '" + name + "' (wall, cpu)");
        }
        else if (arg == "--sampler") {
            const std::optional<smallvcm::SamplerType> sampler = smallvcm::ParseSampler(value(i));
            if (!sampler) throw smallvcm::Error("--sampler: independent or sobol");
            cl.mSampler = *sampler;
        }
        else if (arg == "--seed") cl.mSeed = ParseNumber<uint64_t>(arg, value(i), 0, UINT64_MAX, "a non-negative integer");
        else if (arg == "--out") cl.mOut = value(i);
        else if (arg == "--references") cl.mReferences = value(i);
        else if (arg == "--make-references") cl.mMakeReferences = true;
        else if (arg == "--reference-iterations") cl.mReferenceIterations = ParseNumber<int>(arg, value(i), 2, 1 << 24, "an integer in [2, 16777216]");
        else if (arg == "--reference-sampler") {
            const std::optional<smallvcm::SamplerType> sampler = smallvcm::ParseSampler(value(i));
            if (!sampler) throw smallvcm::Error("--reference-sampler: independent or sobol");
            cl.mReferenceSampler = *sampler;
        }
        else if (arg == "--reference-seed") cl.mReferenceSeed = ParseNumber<uint64_t>(arg, value(i), 0, UINT64_MAX, "a non-negative integer");
        else if (arg == "--photons") cl.mPhotons = ParseNumber<int>(arg, value(i), 1, 100000000, "an integer in [1, 1e8]");
        else if (arg == "--radius-factor") cl.mRadiusFactor = ParseNumber<float>(arg, value(i), 1e-7f, 10.f, "a number in [1e-7, 10]");
        else if (arg == "--quick") cl.mQuick = true;
        else if (arg == "-q") cl.mQuiet = true;
        else throw Error(arg + ": unknown option (see --help)");
    }
    for (const std::string& item : SplitList("--scenes", scenes)) {
        const int index = ParseNumber<int>("--scenes", item, 0, 4, "a Cornell scene index in [0, 4]");
        if (std::find(cl.mScenes.begin(), cl.mScenes.end(), index) != cl.mScenes.end())
            throw Error("--scenes: scene " + item + " is listed twice");
        cl.mScenes.push_back(index);
    }
    for (const std::string& item : SplitList("--algorithms", algorithms)) {
        const std::optional<Algorithm> parsed = smallvcm::ParseAlgorithm(item);
        if (!parsed || *parsed == Algorithm::kEyeLight)
            throw Error("--algorithms: '" + item + "' is not an estimator (" + kAllEstimators + ")");
        const Algorithm algorithm = *parsed;
        if (std::find(cl.mAlgorithms.begin(), cl.mAlgorithms.end(), algorithm) != cl.mAlgorithms.end())
            throw Error("--algorithms: '" + item + "' is listed twice");
        cl.mAlgorithms.push_back(algorithm);
    }
    if (cl.mCpuClock && cl.mThreads != 1) throw Error("--clock: cpu needs --threads 1 (a thread's CPU time)");
    if (cl.mSeed == cl.mReferenceSeed || cl.mSeed == cl.mReferenceSeed + 1)
        throw Error("--seed: must differ from --reference-seed and --reference-seed + 1 (the reference would share the "
                    "estimators' random numbers)");
    // --quick's defaults, then the library's and the study's; explicit options win.
    if (!cl.mWidth) { cl.mWidth = cl.mQuick ? 16 : 128; cl.mHeight = cl.mWidth; }
    if (!cl.mMaxIterations) cl.mMaxIterations = cl.mQuick ? 128 : 256;
    if (!cl.mReferenceIterations) cl.mReferenceIterations = cl.mQuick ? 1024 : 4096;
    if (cl.mQuick && !cl.mPhotons) cl.mPhotons = 1024;
    if (cl.mQuick && !cl.mRadiusFactor) cl.mRadiusFactor = 0.1f;
    if (!cl.mReferences) {
        if (cl.mQuick) {
            const fs::path parent = fs::path(cl.mOut).parent_path();
            cl.mReferences = parent.empty() ? std::string(".") : parent.string();
        } else {
            cl.mReferences = RepositoryFolder() + "/docs/performance/references";
        }
    }
    return cl;
}

// ------------------------------------------------------------------------------------
// Clocks
// ------------------------------------------------------------------------------------
double WallSeconds() {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
double ThreadCpuSeconds() {
    timespec t{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

std::string Now() {
    const std::time_t t = std::time(nullptr);
    char text[64];
    std::strftime(text, sizeof(text), "%Y-%m-%d %H:%M:%S %Z", std::localtime(&t));
    return text;
}

std::string Format(const char* aFormat, double aValue) {
    char text[64];
    std::snprintf(text, sizeof(text), aFormat, aValue);
    return text;
}

// Writes aText to aPath through a temporary file and a rename.
void WriteTextFile(const std::string& aPath, const std::string& aText) {
    const std::string temporary = aPath + ".partial";
    {
        std::ofstream file(temporary, std::ios::binary);
        if (!file) throw Error(aPath + ": cannot open for writing (" + std::strerror(errno) + ")");
        file << aText;
        if (!file.flush()) throw Error(aPath + ": write failed");
    }
    if (std::rename(temporary.c_str(), aPath.c_str()) != 0) throw Error(aPath + ": cannot rename the temporary file into place");
}

// ------------------------------------------------------------------------------------
// References
// ------------------------------------------------------------------------------------
struct Reference {
    smallvcm::Image mImage;
    std::string mPath, mAlgorithm;
    double mNoiseRmse = -1.0;    // estimated from the two halves; < 0: unknown
    double mNoiseRelMse = -1.0;
    double mNoiseRmseDiffuse = -1.0;
};

// ------------------------------------------------------------------------------------
// The diffuse region (see rmse_diffuse at the top)
// ------------------------------------------------------------------------------------
using Mask = std::vector<char>;

Mask DiffuseRegion(const smallvcm::Scene& aScene) {
    const smallvcm::Camera& camera = aScene.mCamera;
    Mask mask(size_t(camera.PixelCount()), 0);
    for (int y = 0; y < camera.Height(); y++)
        for (int x = 0; x < camera.Width(); x++) {
            bool diffuse = true;
            for (const smallvcm::Vec2 offset : {smallvcm::Vec2(0.f, 0.f), smallvcm::Vec2(1.f, 0.f), smallvcm::Vec2(0.f, 1.f),
                                                smallvcm::Vec2(1.f, 1.f), smallvcm::Vec2(0.5f, 0.5f)}) {
                const smallvcm::SurfacePoint hit = aScene.Intersect(camera.GenerateRay(smallvcm::Vec2(float(x), float(y)) + offset));
                if (!hit.IsValid() || hit.mLightId >= 0) { diffuse = false; break; }
                const smallvcm::Material& material = aScene.GetMaterial(hit.mMaterialId);
                diffuse = diffuse && !material.HasSpecular() && smallvcm::IsBlack(material.mPhongReflectance) &&
                          !smallvcm::IsBlack(material.mDiffuseReflectance);
            }
            mask[size_t(y * camera.Width() + x)] = diffuse;
        }
    return mask;
}

// The RMSE over the masked pixels and their channels (Rmse() on the mask); NaN for an empty mask.
double MaskedRmse(const smallvcm::Image& aImage, const smallvcm::Image& aReference, const Mask& aMask) {
    double sum = 0.0;
    long count = 0;
    for (size_t i = 0; i < aImage.mPixels.size(); i++)
        if (aMask[i]) {
            for (int c = 0; c < 3; c++) {
                const double d = double(aImage.mPixels[i][c]) - double(aReference.mPixels[i][c]);
                sum += d * d;
            }
            count += 3;
        }
    return count > 0 ? std::sqrt(sum / double(count)) : NAN;
}

std::string ReferenceStem(const CommandLine& aCl, int aScene) {
    return (fs::path(*aCl.mReferences) / ("cornell_" + std::to_string(aScene) + "_" + std::to_string(*aCl.mWidth) + "x" +
                                          std::to_string(*aCl.mHeight))).string();
}

// BPT can converge unless a delta light meets a specular surface (see the header comment).
bool BptCanConverge(const smallvcm::Scene& aScene, std::string* oReason) {
    bool deltaLight = false, specular = false;
    for (const smallvcm::Light& light : aScene.mLights) deltaLight = deltaLight || light.IsDelta();
    for (const smallvcm::Material& material : aScene.mMaterials) specular = specular || material.HasSpecular();
    if (deltaLight && specular) {
        *oReason = "the scene has a delta light (point or sun) and specular surfaces: the paths light -> specular -> "
                   "diffuse -> specular -> camera (caustics seen in a mirror) have no BPT technique, so BPT would "
                   "miss them however long it ran; VCM's merging samples them and is consistent";
        return false;
    }
    *oReason = "every light has an area (area, sphere or background light), so every path has a BPT technique: "
               "BPT is unbiased here";
    return true;
}

Reference MakeReference(const CommandLine& aCl, int aScene, const smallvcm::Scene& aSceneData) {
    std::string reason;
    smallvcm::RenderOptions options;
    options.mAlgorithm = BptCanConverge(aSceneData, &reason) ? Algorithm::kBidirectionalPathTracing
                                                              : Algorithm::kVertexConnectionMerging;
    options.mSeed = aCl.mReferenceSeed;
    options.mSampler = aCl.mReferenceSampler;
    options.mProgress = false;
    if (aCl.mRadiusFactor) options.mRadiusFactor = *aCl.mRadiusFactor;
    const int iterations = *aCl.mReferenceIterations;
    // An even number of workers, at least two: worker w runs iterations w, w + W, ...;
    // the even workers' films make half A, the odd workers' half B. With Sobol points
    // (see the top) the halves have seeds of their own: worker w runs iterations w / 2,
    // w / 2 + W / 2, ... < M / 2 of the seed + w mod 2.
    int workers = int(std::max(2u, std::thread::hardware_concurrency()));
    workers += workers % 2;
    const bool sobol = options.mSampler == smallvcm::SamplerType::kSobol;
    const double start = WallSeconds();
    std::vector<std::unique_ptr<smallvcm::AbstractRenderer>> renderers;
    for (int w = 0; w < workers; w++) renderers.push_back(smallvcm::CreateRenderer(aSceneData, options));
    std::vector<std::thread> threads;
    for (int w = 0; w < workers; w++)
        threads.emplace_back([&, w] {
            if (sobol) {
                for (int i = w / 2; i < iterations / 2; i += workers / 2) {
                    smallvcm::Sampler sampler = smallvcm::IterationSampler(options.mSampler, options.mSeed + uint64_t(w % 2), i);
                    renderers[size_t(w)]->RunIteration(i, sampler);
                }
                return;
            }
            for (int i = w; i < iterations; i += workers) {
                smallvcm::Sampler sampler = smallvcm::IterationSampler(options.mSampler, options.mSeed, i);
                renderers[size_t(w)]->RunIteration(i, sampler);
            }
        });
    for (std::thread& thread : threads) thread.join();
    const double seconds = WallSeconds() - start;

    smallvcm::Film halves[2] = {renderers[0]->GetFilm(), renderers[1]->GetFilm()};
    for (int w = 2; w < workers; w++) halves[w % 2].Accumulate(renderers[size_t(w)]->GetFilm());
    int counts[2] = {0, 0};
    if (sobol) counts[0] = counts[1] = iterations / 2;
    else
        for (int i = 0; i < iterations; i++) counts[(i % workers) % 2]++;
    smallvcm::Film total = halves[0];
    total.Accumulate(halves[1]);
    Reference reference;
    reference.mImage = total.Resolve(1.0 / (counts[0] + counts[1]));
    const smallvcm::Image a = halves[0].Resolve(1.0 / counts[0]);
    const smallvcm::Image b = halves[1].Resolve(1.0 / counts[1]);
    // Var(ref) = Var(A) / 2 and E|A - B|^2 = 2 Var(A): Var(ref) = E|A - B|^2 / 4.
    reference.mNoiseRmse = smallvcm::Rmse(a, b) / 2.0;
    reference.mNoiseRelMse = smallvcm::RelativeMse(a, reference.mImage);  // E|A - ref|^2 = E|A - B|^2 / 4
    const Mask diffuse = DiffuseRegion(aSceneData);
    reference.mNoiseRmseDiffuse = MaskedRmse(a, b, diffuse) / 2.0;
    reference.mAlgorithm = smallvcm::AlgorithmShortName(options.mAlgorithm);
    const std::string stem = ReferenceStem(aCl, aScene);
    reference.mPath = stem + ".pfm";
    std::error_code ignored;
    fs::create_directories(*aCl.mReferences, ignored);
    smallvcm::WriteImage(reference.mPath, reference.mImage);
    // The diffuse region beside it (1 inside, 0 outside), for scripts that measure there.
    smallvcm::Image maskImage(aSceneData.mCamera.Width(), aSceneData.mCamera.Height());
    for (size_t p = 0; p < diffuse.size(); p++) maskImage.mPixels[p] = smallvcm::Vec3(diffuse[p] ? 1.f : 0.f);
    smallvcm::WriteImage(stem + "_diffuse.pfm", maskImage);

    std::ostringstream text;
    text << "reference image " << fs::path(reference.mPath).filename().string() << " (PFM, linear radiance)\n"
         << "scene = " << kCornellScenes[aScene] << " (Cornell scene " << aScene << ")\n"
         << "resolution = " << *aCl.mWidth << "x" << *aCl.mHeight << "\n"
         << "algorithm = " << reference.mAlgorithm << "\n"
         << "why = " << reason << "\n"
         << "iterations = " << counts[0] + counts[1] << "\n"
         << "sampler = " << smallvcm::SamplerName(options.mSampler) << "\n"
         << "seed = " << options.mSeed
         << (sobol ? " (half A: seed, half B: seed + 1, iterations 0 .. iterations / 2 - 1 each)\n"
                   : " (IterationRng(seed, i) for iteration i)\n")
         << "max_path_length = " << options.mMaxPathLength << "\n"
         << "min_path_length = " << options.mMinPathLength << "\n"
         << "mis = balance\n";
    if (options.mAlgorithm == Algorithm::kVertexConnectionMerging)
        text << "radius_factor = " << options.mRadiusFactor << "\nradius_alpha = " << options.mRadiusAlpha << "\n";
    text << "threads = " << workers << "\n"
         << "seconds = " << Format("%.2f", seconds) << " (wall clock)\n"
         << "mean = " << Format("%.6g", smallvcm::MeanValue(reference.mImage)) << "\n"
         << "noise_rmse = " << Format("%.6g", reference.mNoiseRmse)
         << " (estimated: Rmse(half A, half B) / 2, halves = even and odd workers' iterations"
         << (sobol ? ", each with its own seed" : "") << ")\n"
         << "noise_rmse_diffuse = " << Format("%.6g", reference.mNoiseRmseDiffuse)
         << " (the same on the diffuse region, see build/convergence's rmse_diffuse)\n"
         << "noise_relmse = " << Format("%.6g", reference.mNoiseRelMse) << " (estimated: RelativeMse(half A, reference))\n"
         << "made_by = " << aCl.mCommand << "\n"
         << "date = " << Now() << "\n";
    WriteTextFile(stem + ".txt", text.str());
    if (!aCl.mQuiet)
        std::fprintf(stderr, "convergence: reference %s: %s, %d iterations, %.1f s, noise rmse %.3g\n", reference.mPath.c_str(),
                     reference.mAlgorithm.c_str(), iterations, seconds, reference.mNoiseRmse);
    return reference;
}

// "key = value" from a reference's .txt; empty when absent.
std::string SettingsValue(const std::string& aPath, const std::string& aKey) {
    std::ifstream file(aPath);
    std::string line;
    while (std::getline(file, line)) {
        if (line.compare(0, aKey.size() + 3, aKey + " = ") == 0) {
            std::string valueText = line.substr(aKey.size() + 3);
            const size_t space = valueText.find(' ');
            return space == std::string::npos ? valueText : valueText.substr(0, space);
        }
    }
    return "";
}

Reference LoadReference(const CommandLine& aCl, int aScene) {
    const std::string stem = ReferenceStem(aCl, aScene);
    Reference reference;
    reference.mPath = stem + ".pfm";
    std::error_code ignored;
    if (!fs::exists(reference.mPath, ignored))
        throw Error(reference.mPath + ": no such reference (render it with --make-references)");
    reference.mImage = smallvcm::ReadPfm(reference.mPath);
    if (reference.mImage.mWidth != *aCl.mWidth || reference.mImage.mHeight != *aCl.mHeight)
        throw Error(reference.mPath + ": the reference is " + std::to_string(reference.mImage.mWidth) + "x" +
                    std::to_string(reference.mImage.mHeight) + ", not the requested resolution");
    const std::string settings = stem + ".txt";
    reference.mAlgorithm = SettingsValue(settings, "algorithm");
    const std::string seed = SettingsValue(settings, "seed");
    if (!seed.empty() && seed == std::to_string(aCl.mSeed))
        throw Error(settings + ": the reference was rendered with seed " + seed +
                    ", the study's seed: choose another --seed (or remake the reference)");
    const std::string noise = SettingsValue(settings, "noise_rmse");
    const std::string noiseRel = SettingsValue(settings, "noise_relmse");
    const std::string noiseDiffuse = SettingsValue(settings, "noise_rmse_diffuse");
    if (!noiseDiffuse.empty()) reference.mNoiseRmseDiffuse = std::atof(noiseDiffuse.c_str());
    if (!noise.empty()) reference.mNoiseRmse = std::atof(noise.c_str());
    if (!noiseRel.empty()) reference.mNoiseRelMse = std::atof(noiseRel.c_str());
    return reference;
}

// ------------------------------------------------------------------------------------
// The study
// ------------------------------------------------------------------------------------
std::vector<int> Checkpoints(int aMaxIterations) {
    std::vector<int> checkpoints;
    for (int n = 1; n <= aMaxIterations; n *= 2) {
        checkpoints.push_back(n);
        if (n > aMaxIterations / 2) break;  // no overflow
    }
    if (checkpoints.back() != aMaxIterations) checkpoints.push_back(aMaxIterations);
    return checkpoints;
}

struct Row {
    int mIterations;
    double mSeconds, mRmse, mRelMse, mRmseDiffuse;
};

// Runs one estimator progressively on one scene and returns its checkpoints.
std::vector<Row> Study(const CommandLine& aCl, const smallvcm::Scene& aScene, Algorithm aAlgorithm,
                       const smallvcm::Image& aReference, const Mask& aDiffuse) {
    smallvcm::RenderOptions options;
    options.mAlgorithm = aAlgorithm;
    options.mSeed = aCl.mSeed;
    options.mSampler = aCl.mSampler;
    options.mThreads = aCl.mThreads;
    options.mProgress = false;
    if (aCl.mPhotons) options.mPhotonCount = *aCl.mPhotons;
    if (aCl.mRadiusFactor) options.mRadiusFactor = *aCl.mRadiusFactor;
    smallvcm::ValidateRenderOptions(options);
    const int threadCount = aCl.mThreads;
    auto clock = aCl.mCpuClock ? ThreadCpuSeconds : WallSeconds;

    double rendering = 0.0;  // seconds spent rendering so far
    double start = clock();
    std::vector<std::unique_ptr<smallvcm::AbstractRenderer>> renderers;
    for (int t = 0; t < threadCount; t++) renderers.push_back(smallvcm::CreateRenderer(aScene, options));
    // Runs iterations [aBegin, aEnd): iteration i on renderer i mod T, as Render() does.
    auto run = [&](int aBegin, int aEnd) {
        auto work = [&](int aThread) {
            for (int i = aBegin; i < aEnd; i++) {
                if (i % threadCount != aThread) continue;
                smallvcm::Sampler sampler = smallvcm::IterationSampler(options.mSampler, options.mSeed, i);
                renderers[size_t(aThread)]->RunIteration(i, sampler);
            }
        };
        if (threadCount == 1) { work(0); return; }
        std::vector<std::thread> threads;
        for (int t = 1; t < threadCount; t++) threads.emplace_back(work, t);
        work(0);
        for (std::thread& thread : threads) thread.join();
    };

    std::vector<Row> rows;
    int done = 0;
    for (int checkpoint : Checkpoints(*aCl.mMaxIterations)) {
        bool outOfTime = false;
        if (aCl.mMaxSeconds > 0.0) {
            // Batches of T iterations, so that the time limit is looked at often.
            while (done < checkpoint) {
                const int end = std::min(checkpoint, done + threadCount);
                run(done, end);
                done = end;
                if (rendering + (clock() - start) >= aCl.mMaxSeconds) { outOfTime = true; break; }
            }
        } else {
            run(done, checkpoint);
            done = checkpoint;
        }
        rendering += clock() - start;

        // Not timed: the sum of the threads' films, resolved, and the metrics.
        smallvcm::Film film = renderers[0]->GetFilm();
        for (int t = 1; t < threadCount; t++) film.Accumulate(renderers[size_t(t)]->GetFilm());
        const smallvcm::Image image = film.Resolve(1.0 / done);
        rows.push_back({done, rendering, smallvcm::Rmse(image, aReference), smallvcm::RelativeMse(image, aReference),
                        MaskedRmse(image, aReference, aDiffuse)});
        if (outOfTime) break;
        start = clock();
    }
    return rows;
}

std::string SettingsPath(const std::string& aCsv) {
    const fs::path path(aCsv);
    if (path.extension() == ".csv") return fs::path(path).replace_extension(".txt").string();
    return aCsv + ".txt";
}

int RunStudy(const CommandLine& aCl) {
    const std::string settingsPath = SettingsPath(aCl.mOut);
    const std::string partial = aCl.mOut + ".partial";
    std::ofstream csv(partial, std::ios::binary);
    if (!csv) throw Error(aCl.mOut + ": cannot write here (" + std::strerror(errno) + ")");
    csv << "scene,algorithm,iterations,seconds,rmse,relmse,rmse_diffuse\n";

    std::ostringstream settings;
    settings << "convergence study " << fs::path(aCl.mOut).filename().string() << "\n"
             << "command = " << aCl.mCommand << "\n"
             << "date = " << Now() << "\n"
             << "resolution = " << *aCl.mWidth << "x" << *aCl.mHeight << "\n"
             << "max_iterations = " << *aCl.mMaxIterations << "\n"
             << "max_seconds = " << (aCl.mMaxSeconds > 0.0 ? Format("%g", aCl.mMaxSeconds) : std::string("none")) << "\n"
             << "threads = " << aCl.mThreads << "\n"
             << "clock = " << (aCl.mCpuClock ? "cpu (the rendering thread's CPU time)" : "wall") << "\n"
             << "seed = " << aCl.mSeed << "\n"
             << "sampler = " << smallvcm::SamplerName(aCl.mSampler) << "\n"
             << "hardware_threads = " << std::thread::hardware_concurrency() << "\n";
    {
        const smallvcm::RenderOptions defaults;
        settings << "photons = " << (aCl.mPhotons ? *aCl.mPhotons : defaults.mPhotonCount) << " (pm, pmfg, per iteration)\n"
                 << "radius_factor = " << (aCl.mRadiusFactor ? *aCl.mRadiusFactor : defaults.mRadiusFactor)
                 << " (ppm, bpm, vcm), radius_alpha = " << defaults.mRadiusAlpha << "\n"
                 << "max_path_length = " << defaults.mMaxPathLength << "\n";
    }
    settings << "quick = " << (aCl.mQuick ? "yes" : "no") << "\n";

    for (int sceneIndex : aCl.mScenes) {
        const std::string scenePath = ScenePath(sceneIndex);
        smallvcm::Scene scene = smallvcm::LoadGltfScene(scenePath);
        scene.mCamera.SetResolution(*aCl.mWidth, *aCl.mHeight);
        const Reference reference = (aCl.mMakeReferences || aCl.mQuick) ? MakeReference(aCl, sceneIndex, scene)
                                                                        : LoadReference(aCl, sceneIndex);
        const std::string key = "reference." + std::to_string(sceneIndex);
        settings << key << ".file = " << reference.mPath << "\n"
                 << key << ".algorithm = " << (reference.mAlgorithm.empty() ? "unknown" : reference.mAlgorithm) << "\n"
                 << key << ".noise_rmse = " << Format("%.6g", reference.mNoiseRmse) << "\n"
                 << key << ".noise_relmse = " << Format("%.6g", reference.mNoiseRelMse) << "\n"
                 << key << ".noise_rmse_diffuse = " << Format("%.6g", reference.mNoiseRmseDiffuse) << "\n";
        const Mask diffuse = DiffuseRegion(scene);
        settings << "diffuse_region." << sceneIndex << ".pixels = " << std::count(diffuse.begin(), diffuse.end(), char(1)) << " of "
                 << diffuse.size() << "\n";
        for (Algorithm algorithm : aCl.mAlgorithms) {
            const std::vector<Row> rows = Study(aCl, scene, algorithm, reference.mImage, diffuse);
            for (const Row& row : rows) {
                char line[256];
                std::snprintf(line, sizeof(line), "%d,%s,%d,%.6f,%.9g,%.9g,%.9g\n", sceneIndex,
                              smallvcm::AlgorithmShortName(algorithm), row.mIterations, row.mSeconds, row.mRmse, row.mRelMse,
                              row.mRmseDiffuse);
                csv << line;
            }
            csv.flush();
            if (!aCl.mQuiet)
                std::fprintf(stderr, "convergence: scene %d %-4s %6d iterations %8.2f s  rmse %.4g -> %.4g\n", sceneIndex,
                             smallvcm::AlgorithmShortName(algorithm), rows.back().mIterations, rows.back().mSeconds,
                             rows.front().mRmse, rows.back().mRmse);
        }
    }
    csv.close();
    if (!csv) throw Error(aCl.mOut + ": write failed");
    WriteTextFile(settingsPath, settings.str());
    if (std::rename(partial.c_str(), aCl.mOut.c_str()) != 0) throw Error(aCl.mOut + ": cannot rename the temporary file into place");
    return 0;
}

} // namespace

int main(int argc, char** argv) {
    CommandLine cl;
    try {
        cl = Parse(argc, argv);
    } catch (const Error& e) {
        std::fprintf(stderr, "convergence: %s\n", e.what());
        return 2;
    }
    try {
        return RunStudy(cl);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "convergence: %s\n", e.what());
        std::remove((cl.mOut + ".partial").c_str());
        return 1;
    }
}
