// bench — how fast is smallvcm, and how much memory does it use? (`make bench` part of
// the issue "speed against accuracy").
//
//   build/bench                           the full run (~10 minutes on 2 cores)
//   build/bench --quick                   a smoke test: 64x64, no warm-up, one iteration per thread,
//                                         meshes up to 10^4 triangles (about 20 s)
//   build/bench --scenes 4 --algorithms vcm,bpt --threads 1,2 --markdown vcm.md
//   build/bench --markdown docs/performance/bench.md --csv docs/performance/bench
//                                         also the numbers as CSV, for benchmarks/plot_bench.py
//
// Five measurements, then a one-page markdown report on stdout (and in --markdown FILE):
//   1. Render speed. For every Cornell scene, estimator and thread count: one warm-up
//      iteration per thread, then enough iterations to cover --min-seconds (at least
//      --min-iterations, rounded up to a multiple of the thread count), all through
//      smallvcm::Render. Reported: wall seconds per iteration, rays per second
//      (RenderResult::mRays / wall seconds), the speed-up over one thread, and the CPU
//      utilisation (CPU seconds / (wall seconds x threads)): well below 1 means the
//      threads waited, on each other or on another program using the cores.
//   2. Peak memory. Every measurement of 1. runs in its own process (this program,
//      started again by fork + exec with --child), and its peak resident set size is the
//      ru_maxrss that wait4() returns for it; the process's own ru_maxrss after loading
//      the scene is the baseline. Nothing else ever ran in that process, so the number
//      is the peak of that one (scene, algorithm, threads) and nothing more.
//      Bytes per stored light vertex: sizeof(VertexCM::LightVertex); the vertices kept
//      by the last iteration: VertexCM::LightVertexCount() and LightVertexCapacity().
//   3. BVH scaling. Bumpy spheres (a latitude-longitude mesh with smooth bumps and a
//      fixed-seed random offset per vertex, see BuildBumpySphere) of exactly 10^2 .. 10^6
//      triangles,
//      with a point light and a camera: Scene::Finalize time (best of a few), node count
//      and depth, and single-thread throughput of nearest-hit rays (Scene::Intersect from
//      random points of the bounding box in random directions) and of shadow rays
//      (Scene::Occluded between two random points of the bounding box).
//   4. Loading a large glTF file. The bumpy sphere of 3. at --gltf-triangles triangles
//      (10^6 by default) written to a temporary folder as a model from the wild would
//      come: a .gltf beside a .bin with POSITION, NORMAL and UNSIGNED_INT indices, one
//      material, no camera, no light (the file is made by the benchmark and deleted
//      after it, never checked in). Reported: LoadGltfScene's wall and CPU time on this
//      one thread, the fastest of --repeat runs (at least 2), split as the load report
//      splits it into reading (parsing the file, reading the buffer, building the
//      triangles) and Scene::Finalize (validation, light data and the BVH build).
//      `build/bench --no-render --no-bvh` runs this part alone (about 10 s).
//   5. The environment light's cost. Cornell scene 3 (lit by its constant background
//      alone) rendered by pt and vcm on one thread as in 1., once with its background and
//      once with the background replaced by an environment map (--envmap, by default
//      scenes/hdri/royal_esplanade_1k.hdr, 1024x512): seconds per iteration of each and
//      their ratio, so the price of importance-sampling the map (a binary search in each
//      of two cumulative tables per sample, a texel lookup per escaped ray) against the
//      uniform sphere and a constant is read off directly. The two runs of a pair are
//      measured one after the other in their own processes; the map's distribution is
//      built while the scene loads, outside the measured iterations.
//      `build/bench --no-render --no-bvh --no-gltf` runs this part alone (about 30 s).
// With --csv PREFIX the numbers behind the charts are also written as data (the charts
// are drawn by benchmarks/plot_bench.py with matplotlib, not here):
//   PREFIX_bvh.csv     one row per mesh of 3.: triangles, build ms, nodes, depth, BVH MiB,
//                      rays per wall second and per CPU second, hit fractions, peak RSS
//   PREFIX_render.csv  one row per successful measurement of 1. and 2.: scene, algorithm,
//                      threads, iterations, wall and CPU seconds per iteration, rays per
//                      second, CPU utilisation, peak RSS, resolution
// Only the files of the parts that ran are written (--no-bvh, --no-render leave the other
// one alone), each through FILE.partial and a rename, so that an interrupted run never
// leaves half a table under the real name.
// Progress goes to stderr. Timings are wall-clock (std::chrono::steady_clock); CPU times
// (getrusage, CLOCK_THREAD_CPUTIME_ID) are reported beside them, as on a shared machine
// they are the figures that stay comparable between runs.
// Build: make build/bench. Run with --help for the options.

#include "smallvcm.hpp"
#include "examples/command_line.hpp"

#include <charconv>
#include <cstdarg>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include <sys/resource.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

namespace {

using smallvcm::Algorithm;
using smallvcm::Error;
using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point aStart) {
    return std::chrono::duration<double>(Clock::now() - aStart).count();
}

// ---------------------------------------------------------------------------------------
// Sizes of the stored light vertices
// ---------------------------------------------------------------------------------------
constexpr long kLightVertexBytes = long(sizeof(smallvcm::VertexCM::LightVertex));

// Vertices stored by the last iteration of aRenderer (-1: not a VertexCM).
void LightVertexCount(smallvcm::AbstractRenderer& aRenderer, long& oSize, long& oCapacity) {
    oSize = oCapacity = -1;
    if (auto* vcm = dynamic_cast<smallvcm::VertexCM*>(&aRenderer)) {
        oSize = long(vcm->LightVertexCount());
        oCapacity = long(vcm->LightVertexCapacity());
    }
}
constexpr long kPhotonBytes = long(sizeof(smallvcm::Photon));

// ---------------------------------------------------------------------------------------
// Options
// ---------------------------------------------------------------------------------------

const char* const kCornellScenes[] = {
    "cornell_0_sun.gltf", "cornell_1_mirror_ceiling.gltf", "cornell_2_point.gltf",
    "cornell_3_background.gltf", "cornell_4_default.gltf",
};
const char* const kCornellShort[] = {"0 sun", "1 mirror ceiling", "2 point", "3 background", "4 default"};

const Algorithm kAllAlgorithms[] = {
    Algorithm::kPathTracing, Algorithm::kLightTracing, Algorithm::kProgressivePhotonMapping,
    Algorithm::kBidirectionalPhotonMapping, Algorithm::kBidirectionalPathTracing,
    Algorithm::kVertexConnectionMerging, Algorithm::kPhotonMapping, Algorithm::kPhotonMappingFinalGather,
};

struct Options {
    std::vector<int> mScenes{0, 1, 2, 3, 4};
    std::vector<Algorithm> mAlgorithms{std::begin(kAllAlgorithms), std::end(kAllAlgorithms)};
    std::vector<int> mThreads{1, 2};
    int mWidth = 512, mHeight = 512;
    double mMinSeconds = 2.0;   // measured time per (scene, algorithm, threads)
    int mMinIterations = 2;     // at least this many measured iterations
    int mWarmup = 1;            // warm-up iterations per thread
    int mRepeat = 1;            // measured runs per configuration; the fastest is reported
    bool mRender = true, mBvh = true, mGltf = true, mEnvironment = true;
    std::string mEnvironmentMap;  // --envmap: the map of 5. (default: scenes/hdri/royal_esplanade_1k.hdr)
    long mGltfTriangles = 1000000;  // the glTF loading measurement's mesh
    int mBvhMaxExponent = 6;    // meshes of 10^2 .. 10^this triangles
    int mBvhRays = 131072;      // rays per batch (each batch is traced at least once)
    double mBvhSeconds = 0.5;   // tracing time per mesh and ray kind
    std::string mMarkdown;
    std::string mCsvPrefix;     // --csv: PREFIX_bvh.csv and PREFIX_render.csv
    std::string mNote;
    std::string mCommand;
    bool mQuick = false;
    smallvcm::SamplerType mSampler = smallvcm::SamplerType::kIndependent;
};

void PrintHelp() {
    std::printf(
        "Usage: bench [options]\n"
        "  --quick                smoke test: 64x64, no warm-up, one iteration per thread, meshes up to 10^4\n"
        "  --scenes LIST          Cornell scenes, e.g. 0,2,4 (default 0,1,2,3,4)\n"
        "  --algorithms LIST      e.g. pt,vcm (default pt,lt,ppm,bpm,bpt,vcm,pm,pmfg)\n"
        "  --threads LIST         thread counts, e.g. 1,2 (default 1,2; the first is the speed-up's base)\n"
        "  --resolution WxH       image size (default 512x512)\n"
        "  --sampler S            the estimators' sampler: independent (default) or sobol\n"
        "  --min-seconds S        measured time per configuration (default 2)\n"
        "  --min-iterations N     measured iterations at least (default 2)\n"
        "  --warmup N             warm-up iterations per thread (default 1; 0: none)\n"
        "  --repeat N             measured runs per configuration, the fastest reported (default 1)\n"
        "  --bvh-max-exponent E   largest mesh: 10^E triangles, 2..7 (default 6)\n"
        "  --bvh-rays N           rays per batch (default 131072, at least 100000 are traced)\n"
        "  --bvh-seconds S        tracing time per mesh and ray kind (default 0.5)\n"
        "  --no-render            skip the render and memory measurements\n"
        "  --no-bvh               skip the BVH scaling\n"
        "  --gltf-triangles N     the glTF loading measurement's mesh (default 1000000, 100..10^7)\n"
        "  --no-gltf              skip the glTF loading measurement\n"
        "  --envmap FILE          the environment map of the environment-light measurement\n"
        "                         (default scenes/hdri/royal_esplanade_1k.hdr)\n"
        "  --no-environment       skip the environment-light measurement (pt and vcm, scene 3,\n"
        "                         its constant background against an environment map)\n"
        "  --note TEXT            a line for the report (e.g. the commit measured)\n"
        "  --markdown FILE        also write the report to FILE\n"
        "  --csv PREFIX           also write the numbers to PREFIX_bvh.csv (BVH scaling) and\n"
        "                         PREFIX_render.csv (render speed), for benchmarks/plot_bench.py;\n"
        "                         only the files of the parts that run (see --no-render, --no-bvh)\n"
        "  --help                 this text\n");
}

std::vector<std::string> SplitList(const std::string& aText) {
    std::vector<std::string> items;
    std::string item;
    std::istringstream stream(aText);
    while (std::getline(stream, item, ','))
        if (!item.empty()) items.push_back(item);
    return items;
}

void ParseResolution(const std::string& aOption, const std::string& aText, int& oWidth, int& oHeight) {
    const size_t x = aText.find('x');
    if (x == std::string::npos) throw Error(aOption + ": '" + aText + "' is not WIDTHxHEIGHT (e.g. 512x512)");
    oWidth = ParseNumber<int>(aOption, aText.substr(0, x), 1, 16384);
    oHeight = ParseNumber<int>(aOption, aText.substr(x + 1), 1, 16384);
}

Options ParseOptions(int argc, char** argv) {
    Options o;
    for (int i = 0; i < argc; i++) o.mCommand += (i ? " " : "") + std::string(argv[i]);
    // --quick first, so that explicit options given with it still win.
    for (int i = 1; i < argc; i++)
        if (std::string(argv[i]) == "--quick") {
            o.mQuick = true;
            o.mWidth = o.mHeight = 64;
            o.mMinSeconds = 0.0;
            o.mMinIterations = 1;
            o.mWarmup = 0;
            o.mBvhMaxExponent = 4;
            o.mBvhRays = 100000;
            o.mBvhSeconds = 0.0;
            o.mGltfTriangles = 10000;
        }
    auto value = [&](int& i) -> std::string {
        if (i + 1 >= argc) throw Error(std::string(argv[i]) + ": needs a value");
        return argv[++i];
    };
    for (int i = 1; i < argc; i++) {
        const std::string arg = argv[i];
        if (arg == "--help" || arg == "-h") { PrintHelp(); std::exit(0); }
        else if (arg == "--quick") {}
        else if (arg == "--scenes") {
            o.mScenes.clear();
            for (const std::string& s : SplitList(value(i))) o.mScenes.push_back(ParseNumber<int>(arg, s, 0, 4));
            if (o.mScenes.empty()) throw Error(arg + ": no scene given");
        } else if (arg == "--algorithms") {
            o.mAlgorithms.clear();
            for (const std::string& name : SplitList(value(i))) {
                const std::optional<Algorithm> a = smallvcm::ParseAlgorithm(name);
                if (!a) throw Error(arg + ": unknown algorithm '" + name + "' (pt, lt, ppm, bpm, bpt, vcm, pm, pmfg, el)");
                o.mAlgorithms.push_back(*a);
            }
            if (o.mAlgorithms.empty()) throw Error(arg + ": no algorithm given");
        } else if (arg == "--threads") {
            o.mThreads.clear();
            for (const std::string& t : SplitList(value(i))) o.mThreads.push_back(ParseNumber<int>(arg, t, 1, 256));
            if (o.mThreads.empty()) throw Error(arg + ": no thread count given");
        }
        else if (arg == "--resolution") ParseResolution(arg, value(i), o.mWidth, o.mHeight);
        else if (arg == "--sampler") {
            const std::optional<smallvcm::SamplerType> sampler = smallvcm::ParseSampler(value(i));
            if (!sampler) throw Error("--sampler: independent or sobol");
            o.mSampler = *sampler;
        }
        else if (arg == "--min-seconds") o.mMinSeconds = ParseNumber<double>(arg, value(i), 0.0, 3600.0);
        else if (arg == "--min-iterations") o.mMinIterations = ParseNumber<int>(arg, value(i), 1, 100000);
        else if (arg == "--warmup") o.mWarmup = ParseNumber<int>(arg, value(i), 0, 1000);
        else if (arg == "--repeat") o.mRepeat = ParseNumber<int>(arg, value(i), 1, 100);
        else if (arg == "--bvh-max-exponent") o.mBvhMaxExponent = ParseNumber<int>(arg, value(i), 2, 7);
        else if (arg == "--bvh-rays") o.mBvhRays = ParseNumber<int>(arg, value(i), 1000, 100000000);
        else if (arg == "--bvh-seconds") o.mBvhSeconds = ParseNumber<double>(arg, value(i), 0.0, 3600.0);
        else if (arg == "--no-render") o.mRender = false;
        else if (arg == "--no-bvh") o.mBvh = false;
        else if (arg == "--no-gltf") o.mGltf = false;
        else if (arg == "--no-environment") o.mEnvironment = false;
        else if (arg == "--envmap") {
            o.mEnvironmentMap = value(i);
            if (o.mEnvironmentMap.empty()) throw Error(arg + ": needs a file name");
        }
        else if (arg == "--gltf-triangles") o.mGltfTriangles = ParseNumber<long>(arg, value(i), 100, 10000000);
        else if (arg == "--note") o.mNote = value(i);
        else if (arg == "--markdown") o.mMarkdown = value(i);
        else if (arg == "--csv") {
            o.mCsvPrefix = value(i);
            if (o.mCsvPrefix.empty()) throw Error(arg + ": needs a non-empty PREFIX");
        }
        else throw Error(arg + ": unknown option (see --help)");
    }
    return o;
}

// Folder of this executable's parent (build/ -> the repository), to find scenes/.
std::string ScenesFolder() {
    if (const char* fromEnvironment = std::getenv("SMALLVCM_SCENES")) return fromEnvironment;
    char buffer[4096];
    const ssize_t length = readlink("/proc/self/exe", buffer, sizeof(buffer) - 1);
    if (length > 0) {
        const std::string exe(buffer, size_t(length));
        const size_t slash = exe.find_last_of('/');
        if (slash != std::string::npos) {
            const std::string candidate = exe.substr(0, slash) + "/../scenes";
            char resolved[4096];
            if (access((candidate + "/" + kCornellScenes[0]).c_str(), R_OK) == 0 && realpath(candidate.c_str(), resolved))
                return resolved;
        }
    }
    return "scenes";
}

// ---------------------------------------------------------------------------------------
// Process measurements
// ---------------------------------------------------------------------------------------

long MaxRssKb() {
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    return usage.ru_maxrss;  // kilobytes on Linux
}

double ThreadCpuSeconds() {
    timespec t{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

double CpuSeconds() {
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);  // all threads of the process
    return double(usage.ru_utime.tv_sec) + 1e-6 * double(usage.ru_utime.tv_usec) +
           double(usage.ru_stime.tv_sec) + 1e-6 * double(usage.ru_stime.tv_usec);
}

std::string ReadFirstMatch(const char* aPath, const std::string& aKey) {
    std::ifstream file(aPath);
    std::string line;
    while (std::getline(file, line))
        if (line.compare(0, aKey.size(), aKey) == 0) {
            const size_t colon = line.find(':');
            std::string value = colon == std::string::npos ? line : line.substr(colon + 1);
            const size_t first = value.find_first_not_of(" \t");
            return first == std::string::npos ? "" : value.substr(first);
        }
    return "";
}

std::string LoadAverage() {
    std::ifstream file("/proc/loadavg");
    std::string one, five, fifteen;
    file >> one >> five >> fifteen;
    return one.empty() ? "n/a" : one + " " + five + " " + fifteen;
}

std::string Format(const char* aFormat, ...) __attribute__((format(printf, 1, 2)));
std::string Format(const char* aFormat, ...) {
    char buffer[1024];
    va_list args;
    va_start(args, aFormat);
    std::vsnprintf(buffer, sizeof(buffer), aFormat, args);
    va_end(args);
    return buffer;
}

// ---------------------------------------------------------------------------------------
// 1 and 2: one (scene, algorithm, threads) measurement, in a child process
// ---------------------------------------------------------------------------------------

struct Measurement {
    int mScene = 0;
    Algorithm mAlgorithm = Algorithm::kPathTracing;
    int mThreads = 1;
    std::string mEnvironmentMap;  // the map that replaced the scene's background, or empty
    bool mOk = false;
    std::string mError;
    int mIterations = 0;
    double mSeconds = 0.0;       // wall, of the fastest measured run
    double mCpuSeconds = 0.0;    // of the same run, all threads
    double mSlowestSeconds = 0.0;// per iteration, of the slowest measured run (spread with --repeat)
    uint64_t mRays = 0;
    double mWarmupSeconds = 0.0;
    long mBaselineKb = 0;        // child's ru_maxrss after loading the scene
    long mPeakKb = 0;            // child's ru_maxrss from wait4
    long mLightVertices = -1;    // stored by one iteration (1-thread runs of VertexCM only)
    long mLightVertexCapacity = -1;

    double SecondsPerIteration() const { return mIterations > 0 ? mSeconds / mIterations : 0.0; }
    double RaysPerSecond() const { return mSeconds > 0.0 ? double(mRays) / mSeconds : 0.0; }
    double Utilisation() const { return mSeconds > 0.0 ? mCpuSeconds / (mSeconds * mThreads) : 0.0; }
};

// The child: loads the scene, warms up, measures, prints one line "RESULT key=value ...".
int RunChild(int argc, char** argv) {
    // bench --child SCENE ALGORITHM THREADS WIDTH HEIGHT MIN_SECONDS MIN_ITERATIONS WARMUP REPEAT SAMPLER [ENVMAP]
    if (argc != 12 && argc != 13) { std::fprintf(stderr, "bench --child: wrong arguments\n"); return 2; }
    try {
        const std::string scenePath = argv[2];
        const std::optional<Algorithm> parsed = smallvcm::ParseAlgorithm(argv[3]);
        if (!parsed) throw Error(std::string("unknown algorithm ") + argv[3]);
        const Algorithm algorithm = *parsed;
        const int threads = std::atoi(argv[4]);
        const int width = std::atoi(argv[5]), height = std::atoi(argv[6]);
        const double minSeconds = std::atof(argv[7]);
        const int minIterations = std::atoi(argv[8]);
        const int warmup = std::atoi(argv[9]);
        const int repeat = std::atoi(argv[10]);
        const std::optional<smallvcm::SamplerType> samplerType = smallvcm::ParseSampler(argv[11]);
        if (!samplerType) throw Error(std::string("unknown sampler ") + argv[11]);

        smallvcm::GltfLoadOptions loadOptions;
        if (argc == 13) loadOptions.mEnvironmentMap = argv[12];
        smallvcm::Scene scene = smallvcm::LoadGltfScene(scenePath, nullptr, loadOptions);
        scene.mCamera.SetResolution(width, height);
        const long baselineKb = MaxRssKb();

        smallvcm::RenderOptions options;
        options.mAlgorithm = algorithm;
        options.mThreads = threads;
        options.mProgress = false;
        options.mSampler = *samplerType;

        // Warm-up: one iteration per thread (index 0.. so that PPM's radius schedule is
        // the one of a fresh render). With one thread the bench runs the renderer itself,
        // to read how many light vertices an iteration stores.
        double warmupPerIteration = 0.0;
        long lightVertices = -1, lightVertexCapacity = -1;
        if (warmup > 0) {
            const auto start = Clock::now();
            if (threads == 1) {
                std::unique_ptr<smallvcm::AbstractRenderer> renderer = smallvcm::CreateRenderer(scene, options);
                for (int i = 0; i < warmup; i++) {
                    smallvcm::Sampler sampler = smallvcm::IterationSampler(options.mSampler, options.mSeed, i);
                    renderer->RunIteration(i, sampler);
                }
                LightVertexCount(*renderer, lightVertices, lightVertexCapacity);
            } else {
                options.mIterations = warmup * threads;
                smallvcm::Render(scene, options);
            }
            warmupPerIteration = SecondsSince(start) / warmup;  // wall per round of one iteration per thread
        }

        // Iterations: cover minSeconds at the warm-up's pace, at least minIterations,
        // a multiple of the thread count so that no thread idles at the end.
        int iterations = std::max(minIterations, 1);
        if (warmupPerIteration > 0.0 && minSeconds > 0.0)
            iterations = std::max(iterations, int(std::ceil(minSeconds / warmupPerIteration * threads)));
        iterations = (iterations + threads - 1) / threads * threads;
        options.mIterations = iterations;

        double bestSeconds = 0.0, bestCpu = 0.0, slowest = 0.0;
        uint64_t bestRays = 0;
        for (int r = 0; r < repeat; r++) {
            const double cpuBefore = CpuSeconds();
            const auto start = Clock::now();
            const smallvcm::RenderResult result = smallvcm::Render(scene, options);
            const double seconds = SecondsSince(start);
            const double cpu = CpuSeconds() - cpuBefore;
            if (result.mIterations != iterations) throw Error("Render ran " + std::to_string(result.mIterations) + " iterations");
            if (r == 0 || seconds < bestSeconds) { bestSeconds = seconds; bestCpu = cpu; bestRays = result.mRays; }
            slowest = std::max(slowest, seconds);
        }
        std::printf("RESULT ok=1 iterations=%d seconds=%.6f cpu=%.6f slowest=%.6f rays=%llu warmup=%.6f baseline_kb=%ld "
                    "light_vertices=%ld light_vertex_capacity=%ld\n",
                    iterations, bestSeconds, bestCpu, slowest / iterations, (unsigned long long)bestRays,
                    warmupPerIteration, baselineKb, lightVertices, lightVertexCapacity);
        std::fflush(stdout);
        return 0;
    } catch (const std::exception& e) {
        std::string message = e.what();
        for (char& c : message) if (c == '\n') c = ' ';
        std::printf("RESULT ok=0 error=%s\n", message.c_str());
        std::fflush(stdout);
        return 1;
    }
}

// Starts this program again with --child, reads its RESULT line, and takes its peak RSS
// from wait4(). With aEnvironmentMap, that map replaces the scene's background.
Measurement MeasureInChild(const Options& aOptions, int aScene, Algorithm aAlgorithm, int aThreads,
                           const std::string& aEnvironmentMap = "") {
    Measurement m;
    m.mScene = aScene;
    m.mAlgorithm = aAlgorithm;
    m.mThreads = aThreads;
    m.mEnvironmentMap = aEnvironmentMap;
    const std::string scenePath = ScenesFolder() + "/" + kCornellScenes[aScene];
    std::vector<std::string> args = {
        "bench", "--child", scenePath, smallvcm::AlgorithmShortName(aAlgorithm), std::to_string(aThreads),
        std::to_string(aOptions.mWidth), std::to_string(aOptions.mHeight), Format("%.6f", aOptions.mMinSeconds),
        std::to_string(aOptions.mMinIterations), std::to_string(aOptions.mWarmup), std::to_string(aOptions.mRepeat),
        smallvcm::SamplerName(aOptions.mSampler)};
    if (!aEnvironmentMap.empty()) args.push_back(aEnvironmentMap);
    std::vector<char*> argvChild;
    for (std::string& a : args) argvChild.push_back(a.data());
    argvChild.push_back(nullptr);

    int pipeFds[2];
    if (pipe(pipeFds) != 0) { m.mError = std::string("pipe: ") + std::strerror(errno); return m; }
    std::fflush(stdout);
    std::fflush(stderr);
    const pid_t pid = fork();
    if (pid < 0) {
        m.mError = std::string("fork: ") + std::strerror(errno);
        close(pipeFds[0]);
        close(pipeFds[1]);
        return m;
    }
    if (pid == 0) {
        dup2(pipeFds[1], 1);
        close(pipeFds[0]);
        close(pipeFds[1]);
        execv("/proc/self/exe", argvChild.data());
        std::fprintf(stderr, "bench: exec /proc/self/exe: %s\n", std::strerror(errno));
        _exit(127);
    }
    close(pipeFds[1]);
    std::string output;
    char buffer[4096];
    for (;;) {
        const ssize_t n = read(pipeFds[0], buffer, sizeof(buffer));
        if (n > 0) { output.append(buffer, size_t(n)); continue; }
        if (n < 0 && errno == EINTR) continue;
        break;
    }
    close(pipeFds[0]);
    int status = 0;
    rusage usage{};
    while (wait4(pid, &status, 0, &usage) < 0 && errno == EINTR) {}
    m.mPeakKb = usage.ru_maxrss;

    const size_t at = output.find("RESULT ");
    if (at == std::string::npos) {
        m.mError = WIFSIGNALED(status) ? "child killed by signal " + std::to_string(WTERMSIG(status))
                                       : "child exited with status " + std::to_string(WEXITSTATUS(status)) + " and no result";
        return m;
    }
    std::map<std::string, std::string> fields;
    std::istringstream line(output.substr(at + 7));
    std::string token;
    while (line >> token) {
        const size_t eq = token.find('=');
        if (eq != std::string::npos) fields[token.substr(0, eq)] = token.substr(eq + 1);
    }
    if (fields["ok"] != "1") {
        const size_t e = output.find("error=", at);
        m.mError = e == std::string::npos ? "failed" : output.substr(e + 6, output.find('\n', e) - e - 6);
        return m;
    }
    m.mOk = true;
    m.mIterations = std::atoi(fields["iterations"].c_str());
    m.mSeconds = std::atof(fields["seconds"].c_str());
    m.mCpuSeconds = std::atof(fields["cpu"].c_str());
    m.mSlowestSeconds = std::atof(fields["slowest"].c_str());
    m.mRays = std::strtoull(fields["rays"].c_str(), nullptr, 10);
    m.mWarmupSeconds = std::atof(fields["warmup"].c_str());
    m.mBaselineKb = std::atol(fields["baseline_kb"].c_str());
    m.mLightVertices = std::atol(fields["light_vertices"].c_str());
    m.mLightVertexCapacity = std::atol(fields["light_vertex_capacity"].c_str());
    return m;
}

// ---------------------------------------------------------------------------------------
// 3: BVH scaling
// ---------------------------------------------------------------------------------------

// Deterministic random numbers for the meshes and rays (SplitMix64: fixed on every
// platform, and independent of the renderer's Rng, which may change).
struct BenchRandom {
    uint64_t mState;
    explicit BenchRandom(uint64_t aSeed) : mState(aSeed) {}
    uint64_t Next() {
        uint64_t z = (mState += 0x9E3779B97F4A7C15ull);
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        return z ^ (z >> 31);
    }
    float Float() { return float(Next() >> 40) * (1.f / 16777216.f); }  // [0, 1)
    smallvcm::Vec3 InBox(const smallvcm::Vec3& aMin, const smallvcm::Vec3& aMax) {
        return aMin + (aMax - aMin) * smallvcm::Vec3(Float(), Float(), Float());
    }
    smallvcm::Vec3 Direction() {
        const float z = 1.f - 2.f * Float();
        const float r = std::sqrt(std::max(0.f, 1.f - z * z));
        const float phi = 2.f * 3.14159265358979f * Float();
        return smallvcm::Vec3(r * std::cos(phi), r * std::sin(phi), z);
    }
};

// A bumpy sphere of exactly aTriangles triangles: a latitude-longitude mesh of
// `segments` columns and `bands` bands (2 segments (bands - 1) triangles: a fan at each
// pole, two per quad elsewhere, columns about twice as many as bands so that the cells
// near the equator are square). Each vertex sits at radius
//     1 + 0.1 sin(4 theta) sin(5 phi) + 0.25 h (u - 1/2),
// smooth bumps plus a fixed-seed random u in [0, 1) scaled by the spacing h of the rings,
// so that the surface is equally rough at every resolution (a random offset of fixed
// size would turn a fine mesh into needles, whose boxes all overlap). Vertices are
// computed once and shared, so the mesh is closed (watertight).
struct BumpySphereMesh {
    std::vector<smallvcm::Vec3> mVertices;
    std::vector<uint32_t> mIndices;  // three per triangle
};
BumpySphereMesh MakeBumpySphere(long aTriangles) {
    const long half = aTriangles / 2;  // = segments * (bands - 1)
    long bandsMinusOne = 1;
    double bestScore = std::numeric_limits<double>::infinity();
    for (long d = 1; d <= half; d++)
        if (half % d == 0) {
            const double score = std::abs(std::log(double(half / d) / double(d) / 2.0));
            if (score < bestScore) { bestScore = score; bandsMinusOne = d; }
        }
    const long segments = half / bandsMinusOne;
    const long bands = bandsMinusOne + 1;
    const float pi = 3.14159265358979f;
    const float spacing = pi / float(bands);
    BenchRandom random(12345);
    auto radius = [&](float aTheta, float aPhi) {
        return 1.f + 0.1f * std::sin(4.f * aTheta) * std::sin(5.f * aPhi) + 0.25f * spacing * (random.Float() - 0.5f);
    };
    std::vector<smallvcm::Vec3> vertices;  // pole, rings 1..bands-1, pole
    vertices.push_back(smallvcm::Vec3(0.f, 0.f, radius(0.f, 0.f)));
    for (long ring = 1; ring < bands; ring++) {
        const float theta = pi * float(ring) / float(bands);
        for (long s = 0; s < segments; s++) {
            const float phi = 2.f * pi * float(s) / float(segments);
            const smallvcm::Vec3 d(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta));
            vertices.push_back(d * radius(theta, phi));
        }
    }
    vertices.push_back(smallvcm::Vec3(0.f, 0.f, -radius(pi, 0.f)));
    const long south = long(vertices.size()) - 1;
    auto at = [&](long aRing, long aSegment) { return uint32_t(1 + (aRing - 1) * segments + (aSegment % segments)); };

    BumpySphereMesh mesh;
    mesh.mIndices.reserve(size_t(3 * aTriangles));
    auto triangle = [&](uint32_t aA, uint32_t aB, uint32_t aC) { mesh.mIndices.insert(mesh.mIndices.end(), {aA, aB, aC}); };
    for (long s = 0; s < segments; s++) {
        triangle(0, at(1, s), at(1, s + 1));
        for (long ring = 1; ring + 1 < bands; ring++) {
            triangle(at(ring, s), at(ring + 1, s), at(ring + 1, s + 1));
            triangle(at(ring, s), at(ring + 1, s + 1), at(ring, s + 1));
        }
        triangle(uint32_t(south), at(bands - 1, s + 1), at(bands - 1, s));
    }
    mesh.mVertices = std::move(vertices);
    return mesh;
}

// The bumpy sphere as a scene: its triangles (diffuse), a point light inside, a camera.
void BuildBumpySphere(smallvcm::Scene& oScene, long aTriangles) {
    const BumpySphereMesh mesh = MakeBumpySphere(aTriangles);
    smallvcm::Material diffuse;
    diffuse.mDiffuseReflectance = smallvcm::Vec3(0.8f);
    const int material = oScene.AddMaterial(diffuse);
    oScene.mTriangles.reserve(size_t(aTriangles));
    for (size_t i = 0; i + 2 < mesh.mIndices.size(); i += 3)
        oScene.AddTriangle(mesh.mVertices[mesh.mIndices[i]], mesh.mVertices[mesh.mIndices[i + 1]],
                           mesh.mVertices[mesh.mIndices[i + 2]], material);
    oScene.AddPointLight(smallvcm::Vec3(0.f), smallvcm::Vec3(10.f));
    oScene.mCamera.Setup(smallvcm::Vec3(0.f, -4.f, 0.f), smallvcm::Vec3(0.f, 1.f, 0.f), smallvcm::Vec3(0.f, 0.f, 1.f), 45.f);
    oScene.mCamera.SetResolution(256, 256);
}

struct BvhRow {
    long mTriangles = 0;
    double mBuildSeconds = 0.0;  // best Finalize, wall
    double mBuildCpuShare = 0.0;    // CPU time of the thread / wall time, over all the builds
    int mBuildRuns = 0;
    size_t mNodes = 0;
    size_t mBvhBytes = 0;  // inner nodes and primitive records
    int mDepth = 0;
    double mNearestRaysPerSecond = 0.0, mNearestHitFraction = 0.0;
    double mShadowRaysPerSecond = 0.0, mShadowOccludedFraction = 0.0;
    double mNearestRaysPerCpuSecond = 0.0, mShadowRaysPerCpuSecond = 0.0;
    uint64_t mNearestRays = 0, mShadowRays = 0;
    long mPeakKb = 0;
};

BvhRow MeasureBvh(const Options& aOptions, long aTriangles) {
    BvhRow row;
    row.mTriangles = aTriangles;
    smallvcm::Scene scene;
    BuildBumpySphere(scene, aTriangles);
    if (long(scene.mTriangles.size()) != aTriangles) throw Error("bumpy sphere: wrong triangle count");

    // Finalize, best of several runs: until 0.3 s have passed (at least 3 runs while
    // that is cheap), at most 1000 runs. Finalize rebuilds everything each time.
    double total = 0.0, totalCpu = 0.0;
    for (int run = 0; run < 1000; run++) {
        const double cpuStart = ThreadCpuSeconds();
        const auto start = Clock::now();
        scene.Finalize();
        const double seconds = SecondsSince(start);
        const double cpu = ThreadCpuSeconds() - cpuStart;
        row.mBuildSeconds = run == 0 ? seconds : std::min(row.mBuildSeconds, seconds);
        totalCpu += cpu;
        row.mBuildRuns = run + 1;
        total += seconds;
        if (total >= 0.3 && (run >= 2 || seconds > 0.1)) break;
    }
    row.mBuildCpuShare = total > 0.0 ? totalCpu / total : 0.0;
    row.mNodes = scene.GetBvh().NodeCount();
    row.mBvhBytes = scene.GetBvh().StorageBytes();
    row.mDepth = scene.GetBvh().Depth();

    // Rays from the bounding box of the mesh (it holds the whole sphere; its corners are
    // outside, so some nearest-hit rays miss).
    smallvcm::Vec3 lo(std::numeric_limits<float>::infinity()), hi(-std::numeric_limits<float>::infinity());
    for (const smallvcm::Triangle& t : scene.mTriangles)
        for (const smallvcm::Vec3& p : {t.mP0, t.mP1, t.mP2}) { lo = glm::min(lo, p); hi = glm::max(hi, p); }
    BenchRandom random(777);
    const size_t count = size_t(std::max(aOptions.mBvhRays, 100000));
    std::vector<smallvcm::Ray> rays(count);
    for (smallvcm::Ray& r : rays) r = smallvcm::Ray{random.InBox(lo, hi), random.Direction()};
    struct Segment { smallvcm::Vec3 mFrom, mDirection; float mDistance; };
    std::vector<Segment> segments;
    segments.reserve(count);
    while (segments.size() < count) {
        const smallvcm::Vec3 a = random.InBox(lo, hi), b = random.InBox(lo, hi);
        const float distance = glm::length(b - a);
        if (distance > 1e-3f) segments.push_back(Segment{a, (b - a) / distance, distance});
    }

    {
        uint64_t traced = 0, hits = 0;
        double checksum = 0.0;
        const double cpuStart = ThreadCpuSeconds();
        const auto start = Clock::now();
        do {
            for (const smallvcm::Ray& r : rays) {
                const smallvcm::SurfacePoint hit = scene.Intersect(r);
                if (hit.IsValid()) { hits++; checksum += hit.mDist; }
            }
            traced += count;
        } while (SecondsSince(start) < aOptions.mBvhSeconds);
        const double seconds = SecondsSince(start);
        row.mNearestRays = traced;
        row.mNearestRaysPerSecond = double(traced) / seconds;
        row.mNearestRaysPerCpuSecond = double(traced) / std::max(1e-9, ThreadCpuSeconds() - cpuStart);
        row.mNearestHitFraction = double(hits) / double(traced);
        if (checksum < 0.0) std::fprintf(stderr, "?\n");  // keeps the hits alive
    }
    {
        uint64_t traced = 0, occluded = 0;
        const double cpuStart = ThreadCpuSeconds();
        const auto start = Clock::now();
        do {
            for (const Segment& s : segments) occluded += scene.Occluded(s.mFrom, s.mDirection, s.mDistance) ? 1 : 0;
            traced += count;
        } while (SecondsSince(start) < aOptions.mBvhSeconds);
        const double seconds = SecondsSince(start);
        row.mShadowRays = traced;
        row.mShadowRaysPerSecond = double(traced) / seconds;
        row.mShadowRaysPerCpuSecond = double(traced) / std::max(1e-9, ThreadCpuSeconds() - cpuStart);
        row.mShadowOccludedFraction = double(occluded) / double(traced);
    }
    row.mPeakKb = MaxRssKb();
    return row;
}

// ---------------------------------------------------------------------------------------
// 4: loading a large glTF file
// ---------------------------------------------------------------------------------------

// Writes the bumpy sphere of aTriangles triangles to aFolder/bumpy.gltf + bumpy.bin
// (see the file's note 4) and returns the path of the .gltf; oBytes gets both files' size.
std::string WriteBumpySphereGltf(const std::string& aFolder, long aTriangles, uint64_t& oBytes) {
    const BumpySphereMesh mesh = MakeBumpySphere(aTriangles);
    std::vector<float> positions, normals;
    smallvcm::Vec3 lo(std::numeric_limits<float>::infinity()), hi(-std::numeric_limits<float>::infinity());
    for (const smallvcm::Vec3& v : mesh.mVertices) {
        const smallvcm::Vec3 n = glm::normalize(v);  // smooth: the direction from the centre
        positions.insert(positions.end(), {v.x, v.y, v.z});
        normals.insert(normals.end(), {n.x, n.y, n.z});
        lo = glm::min(lo, v);
        hi = glm::max(hi, v);
    }
    const size_t positionBytes = positions.size() * sizeof(float), indexBytes = mesh.mIndices.size() * sizeof(uint32_t);
    {
        std::ofstream bin(aFolder + "/bumpy.bin", std::ios::binary);
        bin.write(reinterpret_cast<const char*>(positions.data()), std::streamsize(positionBytes));
        bin.write(reinterpret_cast<const char*>(normals.data()), std::streamsize(positionBytes));
        bin.write(reinterpret_cast<const char*>(mesh.mIndices.data()), std::streamsize(indexBytes));
        if (!bin) throw Error(aFolder + "/bumpy.bin: cannot write it");
    }
    std::ostringstream json;
    json << R"({"asset": {"version": "2.0", "generator": "smallvcm bench"}, "scene": 0, "scenes": [{"nodes": [0]}],
  "nodes": [{"mesh": 0}],
  "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2, "material": 0}]}],
  "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1], "metallicFactor": 0, "roughnessFactor": 1}}],
  "buffers": [{"uri": "bumpy.bin", "byteLength": )" << 2 * positionBytes + indexBytes << R"(}],
  "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": )" << positionBytes << R"(},
                  {"buffer": 0, "byteOffset": )" << positionBytes << R"(, "byteLength": )" << positionBytes << R"(},
                  {"buffer": 0, "byteOffset": )" << 2 * positionBytes << R"(, "byteLength": )" << indexBytes << R"(}],
  "accessors": [{"bufferView": 0, "componentType": 5126, "count": )" << mesh.mVertices.size() << R"(, "type": "VEC3",
                 "min": [)" << lo.x << ", " << lo.y << ", " << lo.z << "], \"max\": [" << hi.x << ", " << hi.y << ", " << hi.z << R"(]},
                {"bufferView": 1, "componentType": 5126, "count": )" << mesh.mVertices.size() << R"(, "type": "VEC3"},
                {"bufferView": 2, "componentType": 5125, "count": )" << mesh.mIndices.size() << R"(, "type": "SCALAR"}]}
)";
    const std::string path = aFolder + "/bumpy.gltf";
    std::ofstream(path) << json.str();
    oBytes = uint64_t(2 * positionBytes + indexBytes + json.str().size());
    return path;
}

struct GltfRow {
    long mTriangles = 0;        // in the file (all of them non-degenerate)
    size_t mLoadedTriangles = 0;
    uint64_t mFileBytes = 0;    // .gltf + .bin
    double mSeconds = 0.0, mCpuSeconds = 0.0;           // LoadGltfScene, the fastest run
    double mReadSeconds = 0.0, mFinalizeSeconds = 0.0;  // that run's GltfLoadReport
    int mRuns = 0;
};

GltfRow MeasureGltfLoad(const Options& aOptions, long aTriangles) {
    GltfRow row;
    row.mTriangles = aTriangles;
    const char* temporary = std::getenv("TMPDIR");
    std::string folder = std::string(temporary && *temporary ? temporary : "/tmp") + "/smallvcm-bench-XXXXXX";
    if (!mkdtemp(folder.data())) throw Error(folder + ": cannot make a temporary folder (" + std::strerror(errno) + ")");
    struct Cleanup {
        std::string mFolder;
        ~Cleanup() {
            std::remove((mFolder + "/bumpy.gltf").c_str());
            std::remove((mFolder + "/bumpy.bin").c_str());
            rmdir(mFolder.c_str());
        }
    } cleanup{folder};
    const std::string path = WriteBumpySphereGltf(folder, aTriangles, row.mFileBytes);
    for (int run = 0; run < std::max(2, aOptions.mRepeat); run++) {
        smallvcm::GltfLoadReport report;
        const double cpuStart = ThreadCpuSeconds();
        const auto start = Clock::now();
        const smallvcm::Scene scene = smallvcm::LoadGltfScene(path, &report);
        const double seconds = SecondsSince(start);
        if (run == 0 || seconds < row.mSeconds) {
            row.mSeconds = seconds;
            row.mCpuSeconds = ThreadCpuSeconds() - cpuStart;
            row.mReadSeconds = report.mReadSeconds;
            row.mFinalizeSeconds = report.mFinalizeSeconds;
            row.mLoadedTriangles = scene.mTriangles.size();
        }
        row.mRuns = run + 1;
    }
    return row;
}

// ---------------------------------------------------------------------------------------
// Report
// ---------------------------------------------------------------------------------------

std::string Mib(long aKb) { return aKb > 0 ? Format("%.1f", double(aKb) / 1024.0) : "n/a"; }

std::string Rate(double aPerSecond) {
    if (aPerSecond >= 1e6) return Format("%.2f M", aPerSecond / 1e6);
    if (aPerSecond >= 1e3) return Format("%.1f k", aPerSecond / 1e3);
    return Format("%.0f", aPerSecond);
}

std::string Seconds(double aSeconds) {
    if (aSeconds >= 10.0) return Format("%.1f", aSeconds);
    if (aSeconds >= 0.1) return Format("%.3f", aSeconds);
    if (aSeconds >= 0.001) return Format("%.4f", aSeconds);
    return Format("%.2e", aSeconds);
}

const Measurement* Find(const std::vector<Measurement>& aAll, int aScene, Algorithm aAlgorithm, int aThreads) {
    for (const Measurement& m : aAll)
        if (m.mScene == aScene && m.mAlgorithm == aAlgorithm && m.mThreads == aThreads) return &m;
    return nullptr;
}

// A table with one row per algorithm and one column per scene (and a last column: the
// mean over scenes, where that makes sense).
template <class Cell>
void AlgorithmSceneTable(std::ostringstream& aOut, const Options& aOptions, const char* aCorner, Cell&& aCell) {
    aOut << "| " << aCorner << " |";
    for (int s : aOptions.mScenes) aOut << " " << kCornellShort[s] << " |";
    aOut << "\n|---|";
    for (size_t i = 0; i < aOptions.mScenes.size(); i++) aOut << "---:|";
    aOut << "\n";
    for (Algorithm a : aOptions.mAlgorithms) {
        aOut << "| " << smallvcm::AlgorithmShortName(a) << " |";
        for (int s : aOptions.mScenes) aOut << " " << aCell(s, a) << " |";
        aOut << "\n";
    }
    aOut << "\n";
}

std::string Report(const Options& aOptions, const std::vector<Measurement>& aRuns, const std::vector<BvhRow>& aBvh,
                   const std::vector<GltfRow>& aGltf, const std::vector<std::pair<Measurement, Measurement>>& aEnvironment,
                   const std::string& aDate, double aTotalSeconds, const std::string& aLoadStart, const std::string& aLoadEnd) {
    std::ostringstream out;
    const long cores = sysconf(_SC_NPROCESSORS_ONLN);
    std::string cpu = ReadFirstMatch("/proc/cpuinfo", "model name");
    if (cpu.empty()) cpu = "unknown";
    out << "### Summary\n\n";
    out << "| | |\n|---|---|\n";
    out << "| date | " << aDate << " |\n";
    out << "| machine | " << cores << " cores online (nproc), " << cpu << " |\n";
    out << "| compiler | "
#if defined(__clang__)
        << "clang "
#elif defined(__GNUC__)
        << "g++ "
#endif
        << __VERSION__
#ifdef __OPTIMIZE__
        << ", optimised"
#else
        << ", NOT optimised"
#endif
        << " |\n";
    out << "| command | `" << aOptions.mCommand << "` |\n";
    if (!aOptions.mNote.empty()) out << "| note | " << aOptions.mNote << " |\n";
    const smallvcm::RenderOptions defaults;
    out << "| image | " << aOptions.mWidth << "x" << aOptions.mHeight << ", default RenderOptions (max path length "
        << defaults.mMaxPathLength << ", seed " << defaults.mSeed << ", sampler " << smallvcm::SamplerName(aOptions.mSampler) << "; pm/pmfg: " << defaults.mPhotonCount
        << " photons per iteration, k = " << defaults.mNearestPhotons << ") |\n";
    out << "| per configuration | " << aOptions.mWarmup << " warm-up iteration(s) per thread, then >= "
        << aOptions.mMinIterations << " iterations and >= " << aOptions.mMinSeconds
        << " s (a multiple of the thread count)" << (aOptions.mRepeat > 1 ? ", fastest of " + std::to_string(aOptions.mRepeat) + " runs" : "")
        << " |\n";
    out << "| load average (1, 5, 15 min) | at start " << aLoadStart << "; at end " << aLoadEnd << " |\n";
    {
        std::ifstream autogroup("/proc/sys/kernel/sched_autogroup_enabled");
        int enabled = -1;
        autogroup >> enabled;
        if (enabled == 1) out << "| scheduler | autogroup on: the cores are shared equally between sessions, not threads |\n";
    }
    out << "| total run time | " << Format("%.0f s", aTotalSeconds) << " |\n\n";
    std::vector<double> utilisation;
    for (const Measurement& m : aRuns)
        if (m.mOk) utilisation.push_back(m.Utilisation());
    if (!utilisation.empty()) {
        std::sort(utilisation.begin(), utilisation.end());
        const double median = utilisation[utilisation.size() / 2];
        if (median < 0.9)
            out << "**Warning: the cores were shared with other programs** (median CPU utilisation of the render runs "
                << Format("%.0f%%", 100.0 * median) << "; 100% = every thread always on a core). Wall-clock seconds "
                   "and rays per second are then slower than this machine can do, and the thread speed-ups say little; "
                   "the CPU seconds per iteration are the figures to compare.\n\n";
    }

    if (aOptions.mRender) {
        for (int threads : aOptions.mThreads) {
            out << "### Seconds per iteration, " << threads << (threads == 1 ? " thread" : " threads") << "\n\n";
            AlgorithmSceneTable(out, aOptions, "s/iteration", [&](int s, Algorithm a) {
                const Measurement* m = Find(aRuns, s, a, threads);
                return !m ? std::string("-") : m->mOk ? Seconds(m->SecondsPerIteration()) : std::string("failed");
            });
        }
        const int base = aOptions.mThreads.front();
        for (size_t t = 1; t < aOptions.mThreads.size(); t++) {
            const int threads = aOptions.mThreads[t];
            out << "### Speed-up of " << threads << " threads over " << base << "\n\n";
            out << "(s/iteration at " << base << " / s/iteration at " << threads
                << "; in parentheses the CPU utilisation of the " << threads << "-thread run)\n\n";
            AlgorithmSceneTable(out, aOptions, "speed-up", [&](int s, Algorithm a) {
                const Measurement* m1 = Find(aRuns, s, a, base);
                const Measurement* m2 = Find(aRuns, s, a, threads);
                if (!m1 || !m2 || !m1->mOk || !m2->mOk) return std::string("-");
                return Format("%.2f (%.0f%%)", m1->SecondsPerIteration() / m2->SecondsPerIteration(), 100.0 * m2->Utilisation());
            });
        }
        for (int threads : aOptions.mThreads) {
            out << "### CPU seconds per iteration, " << threads << (threads == 1 ? " thread" : " threads")
                << " (user + system time of all threads / iterations)\n\n";
            AlgorithmSceneTable(out, aOptions, "CPU s/iteration", [&](int s, Algorithm a) {
                const Measurement* m = Find(aRuns, s, a, threads);
                return !m || !m->mOk || m->mIterations == 0 ? std::string("-") : Seconds(m->mCpuSeconds / m->mIterations);
            });
        }
        for (int threads : aOptions.mThreads) {
            out << "### Rays per second, " << threads << (threads == 1 ? " thread" : " threads")
                << " (nearest-hit + shadow rays / wall seconds)\n\n";
            AlgorithmSceneTable(out, aOptions, "rays/s", [&](int s, Algorithm a) {
                const Measurement* m = Find(aRuns, s, a, threads);
                return !m || !m->mOk ? std::string("-") : Rate(m->RaysPerSecond());
            });
        }

        // Memory.
        out << "### Peak memory\n\n";
        out << "Method: every (scene, algorithm, threads) measurement above ran in its own process (this program "
               "started again by fork + exec); peak RSS is the ru_maxrss of that process as wait4() returns it, and "
               "the baseline is its ru_maxrss after loading the scene, before rendering. Peaks are the largest over "
               "the scenes measured.\n\n";
        const int memoryScene = std::find(aOptions.mScenes.begin(), aOptions.mScenes.end(), 4) != aOptions.mScenes.end()
                                    ? 4 : aOptions.mScenes.front();
        out << "| algorithm | baseline MiB |";
        for (int threads : aOptions.mThreads) out << " peak MiB, " << threads << "T |";
        out << " light vertices / iteration (vector capacity), scene " << kCornellShort[memoryScene]
            << " | bytes / stored vertex | stored vertices MiB (capacity) |\n|---|---:|";
        for (size_t i = 0; i < aOptions.mThreads.size(); i++) out << "---:|";
        out << "---:|---:|---:|\n";
        for (Algorithm a : aOptions.mAlgorithms) {
            long baseline = 0;
            out << "| " << smallvcm::AlgorithmShortName(a) << " |";
            std::ostringstream peaks;
            for (int threads : aOptions.mThreads) {
                long peak = 0;
                int peakScene = -1;
                for (int s : aOptions.mScenes)
                    if (const Measurement* m = Find(aRuns, s, a, threads); m && m->mOk) {
                        baseline = std::max(baseline, m->mBaselineKb);
                        if (m->mPeakKb > peak) { peak = m->mPeakKb; peakScene = s; }
                    }
                peaks << " " << Mib(peak) << (peakScene >= 0 && aOptions.mScenes.size() > 1 ? " (s" + std::to_string(peakScene) + ")" : "") << " |";
            }
            out << " " << Mib(baseline) << " |" << peaks.str();
            const bool vertexCm = a != Algorithm::kPathTracing && a != Algorithm::kEyeLight &&
                                  a != Algorithm::kPhotonMapping && a != Algorithm::kPhotonMappingFinalGather;
            const bool photons = a == Algorithm::kPhotonMapping || a == Algorithm::kPhotonMappingFinalGather;
            const Measurement* m = Find(aRuns, memoryScene, a, 1);
            if (vertexCm) {
                const long count = m && m->mOk ? m->mLightVertices : -1;
                const long capacity = m && m->mOk ? m->mLightVertexCapacity : -1;
                out << " " << (count >= 0 ? std::to_string(count) + " (" + std::to_string(capacity) + ")" : std::string("n/a")) << " | "
                    << (kLightVertexBytes > 0 ? std::to_string(kLightVertexBytes) + " (light vertex)" : std::string("n/a")) << " | "
                    << (count >= 0 && kLightVertexBytes > 0
                            ? Format("%.1f (%.1f)", double(count) * double(kLightVertexBytes) / 1048576.0,
                                     double(capacity) * double(kLightVertexBytes) / 1048576.0)
                            : std::string("n/a"))
                    << " |\n";
            } else if (photons) {
                out << " n/a | " << kPhotonBytes << " (Photon) | n/a |\n";
            } else {
                out << " - | - | - |\n";
            }
        }
        out << "\nNotes: light vertices are counted after one iteration of a renderer the bench runs itself "
               "(the 1-thread warm-up); \"stored vertices MiB\" is that count (and the vector's capacity) times the "
               "size of one stored vertex, for one thread (the hash grid adds its own arrays). VertexCM reserves room for "
               "4 vertices per light path before its first iteration, so the vector rarely grows by copying itself; "
               "reserved pages that are never written take no physical memory: the capacity is address space, the "
               "peak RSS what is used. Bytes per vertex: sizeof(VertexCM::LightVertex); the count "
               "and capacity: VertexCM::LightVertexCount() and LightVertexCapacity(). Photons (pm, pmfg) are public: sizeof(Photon); their count per iteration is not visible "
               "from outside the renderer (n/a); the kd-tree keeps a further position and an axis byte per photon.\n\n";

        out << "### Every configuration\n\n";
        out << "| scene | algorithm | threads | iterations | s/iteration | slowest s/it. | warm-up s/it. | CPU s/it. | rays/s | "
               "CPU util. | peak RSS MiB |\n|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
        for (const Measurement& m : aRuns) {
            out << "| " << kCornellShort[m.mScene] << " | " << smallvcm::AlgorithmShortName(m.mAlgorithm) << " | " << m.mThreads << " | ";
            if (!m.mOk) { out << "failed: " << m.mError << " | | | | | | | |\n"; continue; }
            out << m.mIterations << " | " << Seconds(m.SecondsPerIteration()) << " | " << Seconds(m.mSlowestSeconds) << " | "
                << (m.mWarmupSeconds > 0.0 ? Seconds(m.mWarmupSeconds / m.mThreads) : std::string("-")) << " | "
                << Seconds(m.mCpuSeconds / std::max(1, m.mIterations)) << " | " << Rate(m.RaysPerSecond()) << " | " << Format("%.0f%%", 100.0 * m.Utilisation()) << " | " << Mib(m.mPeakKb) << " |\n";
        }
        out << "\n(warm-up s/it. = wall time of the warm-up round divided by the thread count.)\n\n";
    }

    if (aOptions.mBvh) {
        out << "### BVH scaling\n\n";
        out << "Bumpy sphere (latitude-longitude mesh; vertex radius 1 + 0.1 sin(4 theta) sin(5 phi) + a fixed-seed "
               "random offset of up to +-1/8 of the ring spacing) + a point light + a camera; one thread. Build = Scene::Finalize (validation, normals, bounding sphere, BVH), the fastest "
               "of the runs shown (wall clock; CPU util. = CPU time / wall time over all of them). Nearest-hit rays: Scene::Intersect from a random point of the bounding box in a uniformly "
               "random direction. Shadow rays: Scene::Occluded between two random points of the bounding box. "
               "Rays per second are per wall second and, after the slash, per CPU second of the tracing thread "
               "(the two differ when other programs share the cores). Nodes count leaves too; BVH MiB is what the tree stores: its inner nodes ("
            << smallvcm::Bvh::NodeBytes() << " bytes each, the boxes of its four children) and the leaves' primitives in blocks of four (160 bytes a block).\n\n";
        out << "| triangles | build ms (runs, CPU util.) | nodes | depth | BVH MiB | nearest-hit rays/s, wall / CPU (hit %) | "
               "shadow rays/s, wall / CPU (occluded %) | rays traced | process peak RSS MiB |\n"
               "|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
        for (const BvhRow& r : aBvh)
            out << "| " << r.mTriangles << " | " << Format("%.3f (%d, %.0f%%)", 1e3 * r.mBuildSeconds, r.mBuildRuns, 100.0 * r.mBuildCpuShare) << " | " << r.mNodes << " | "
                << r.mDepth << " | " << Format("%.2f", double(r.mBvhBytes) / 1048576.0) << " | "
                << Rate(r.mNearestRaysPerSecond) << " / " << Rate(r.mNearestRaysPerCpuSecond)
                << Format(" (%.0f%%)", 100.0 * r.mNearestHitFraction) << " | " << Rate(r.mShadowRaysPerSecond) << " / "
                << Rate(r.mShadowRaysPerCpuSecond) << Format(" (%.0f%%)", 100.0 * r.mShadowOccludedFraction) << " | "
                << (r.mNearestRays + r.mShadowRays) << " | " << Mib(r.mPeakKb) << " |\n";
        out << "\n";
    }
    if (aOptions.mGltf) {
        out << "### Loading a large glTF file\n\n";
        out << "The bumpy sphere above written as a .gltf + .bin (POSITION, NORMAL, UNSIGNED_INT indices; no camera, no "
               "light), loaded by LoadGltfScene on one thread: the fastest of the runs shown (wall clock), split as its "
               "load report splits it into reading (file, JSON, buffer, triangles, default camera) and Scene::Finalize "
               "(validation, light data and the BVH build).\n\n";
        out << "| triangles | file MiB | load s (runs) | CPU s | reading s | Finalize + BVH s |\n"
               "|---:|---:|---:|---:|---:|---:|\n";
        for (const GltfRow& r : aGltf)
            out << "| " << r.mLoadedTriangles << " | " << Format("%.1f", double(r.mFileBytes) / 1048576.0) << " | "
                << Format("%.3f (%d)", r.mSeconds, r.mRuns) << " | " << Format("%.3f", r.mCpuSeconds) << " | "
                << Format("%.3f", r.mReadSeconds) << " | " << Format("%.3f", r.mFinalizeSeconds) << " |\n";
        out << "\n";
    }
    if (aOptions.mEnvironment) {
        out << "### The environment light's cost\n\n";
        out << "Cornell scene 3 (lit by its background alone), one thread, measured as above: with its constant "
               "background, and with the background replaced by the environment map `"
            << aOptions.mEnvironmentMap << "` (GltfLoadOptions::mEnvironmentMap, as `--envmap`). The two runs of a row "
               "ran one after the other.\n\n";
        out << "| algorithm | constant: wall / CPU s per iteration | environment map: wall / CPU s per iteration | ratio, wall | "
               "ratio, CPU | rays per iteration, constant / environment map |\n"
               "|---|---:|---:|---:|---:|---:|\n";
        for (const auto& [constant, environment] : aEnvironment) {
            out << "| " << smallvcm::AlgorithmShortName(constant.mAlgorithm) << " | ";
            if (!constant.mOk || !environment.mOk) {
                out << "failed: " << (constant.mOk ? environment.mError : constant.mError) << " | | | | |\n";
                continue;
            }
            const auto cpuPerIteration = [](const Measurement& aM) { return aM.mCpuSeconds / std::max(1, aM.mIterations); };
            const auto rays = [](const Measurement& aM) { return double(aM.mRays) / std::max(1, aM.mIterations); };
            out << Seconds(constant.SecondsPerIteration()) << " / " << Seconds(cpuPerIteration(constant)) << " | "
                << Seconds(environment.SecondsPerIteration()) << " / " << Seconds(cpuPerIteration(environment)) << " | "
                << Format("%.2f", environment.SecondsPerIteration() / constant.SecondsPerIteration()) << " | "
                << Format("%.2f", cpuPerIteration(environment) / cpuPerIteration(constant)) << " | " << Rate(rays(constant)) << " / "
                << Rate(rays(environment)) << " |\n";
        }
        out << "\n(CPU: the measured process's user + system time; on a shared machine the figure that compares.)\n";
        out << "\n";
    }
    return out.str();
}

// ---------------------------------------------------------------------------------------
// CSV (--csv): the same numbers as data, for benchmarks/plot_bench.py
// ---------------------------------------------------------------------------------------

std::string BvhCsvPath(const Options& aOptions) { return aOptions.mCsvPrefix + "_bvh.csv"; }
std::string RenderCsvPath(const Options& aOptions) { return aOptions.mCsvPrefix + "_render.csv"; }

// The CSV files this run will write: only those of the parts that run, so that
// --no-bvh does not overwrite a BVH table measured earlier with an empty one.
std::vector<std::string> CsvPaths(const Options& aOptions) {
    std::vector<std::string> paths;
    if (aOptions.mCsvPrefix.empty()) return paths;
    if (aOptions.mBvh) paths.push_back(BvhCsvPath(aOptions));
    if (aOptions.mRender) paths.push_back(RenderCsvPath(aOptions));
    return paths;
}

// Fails early, before minutes of measuring, if aPath cannot be written: creates and
// removes aPath.partial, the file the real write goes through (aPath itself is left
// untouched, so an earlier result survives a run that fails).
void CheckWritable(const std::string& aPath) {
    const std::string probe = aPath + ".partial";
    FILE* file = std::fopen(probe.c_str(), "wb");
    if (!file) throw Error(aPath + ": cannot write here (" + std::strerror(errno) + ")");
    std::fclose(file);
    std::remove(probe.c_str());
}

// Writes aText to aPath through aPath.partial and a rename (the project's rule: no half
// file under the real name); on failure the .partial is removed too.
void WriteFileAtomically(const std::string& aPath, const std::string& aText) {
    const std::string partial = aPath + ".partial";
    {
        std::ofstream file(partial, std::ios::binary | std::ios::trunc);
        if (!file) throw Error(aPath + ": cannot open " + partial + " for writing (" + std::strerror(errno) + ")");
        file << aText;
        if (!file.flush()) {
            std::remove(partial.c_str());
            throw Error(aPath + ": write failed (" + std::strerror(errno) + ")");
        }
    }
    if (std::rename(partial.c_str(), aPath.c_str()) != 0) {
        const std::string reason = std::strerror(errno);
        std::remove(partial.c_str());
        throw Error(aPath + ": cannot rename " + partial + " into place (" + reason + ")");
    }
}

// One row per mesh. Full precision (%.6g and integers), unlike the report's rounded
// cells: the charts take logarithms and fit lines through these numbers.
std::string BvhCsv(const std::vector<BvhRow>& aBvh) {
    std::ostringstream out;
    out << "triangles,build_ms,build_runs,build_cpu_utilisation,nodes,depth,bvh_mib,"
           "nearest_rays_per_s,shadow_rays_per_s,nearest_rays_per_cpu_s,shadow_rays_per_cpu_s,"
           "nearest_hit_fraction,shadow_occluded_fraction,peak_rss_mib\n";
    for (const BvhRow& r : aBvh)
        out << r.mTriangles << "," << Format("%.6g", 1e3 * r.mBuildSeconds) << "," << r.mBuildRuns << ","
            << Format("%.4f", r.mBuildCpuShare) << "," << r.mNodes << "," << r.mDepth << ","
            << Format("%.6g", double(r.mBvhBytes) / 1048576.0) << "," << Format("%.6g", r.mNearestRaysPerSecond) << ","
            << Format("%.6g", r.mShadowRaysPerSecond) << "," << Format("%.6g", r.mNearestRaysPerCpuSecond) << ","
            << Format("%.6g", r.mShadowRaysPerCpuSecond) << "," << Format("%.4f", r.mNearestHitFraction) << ","
            << Format("%.4f", r.mShadowOccludedFraction) << "," << Format("%.2f", double(r.mPeakKb) / 1024.0) << "\n";
    return out.str();
}

// One row per successful (scene, algorithm, threads) measurement, in the order measured.
// Failed ones are left out (the report names them and the exit code is 1): a CSV cell
// that is not a number would only make the chart script refuse the whole file. The scene
// name is the scene file's stem, which holds no comma.
std::string RenderCsv(const Options& aOptions, const std::vector<Measurement>& aRuns) {
    std::ostringstream out;
    out << "scene,scene_name,algorithm,threads,iterations,s_per_iteration,cpu_s_per_iteration,rays_per_s,"
           "cpu_utilisation,peak_rss_mib,resolution\n";
    for (const Measurement& m : aRuns) {
        if (!m.mOk || m.mIterations <= 0) continue;
        std::string name = kCornellScenes[m.mScene];
        name = name.substr(0, name.rfind(".gltf"));
        out << m.mScene << "," << name << "," << smallvcm::AlgorithmShortName(m.mAlgorithm) << "," << m.mThreads << ","
            << m.mIterations << "," << Format("%.6g", m.SecondsPerIteration()) << ","
            << Format("%.6g", m.mCpuSeconds / m.mIterations) << "," << Format("%.6g", m.RaysPerSecond()) << ","
            << Format("%.4f", m.Utilisation()) << "," << Format("%.2f", double(m.mPeakKb) / 1024.0) << ","
            << aOptions.mWidth << "x" << aOptions.mHeight << "\n";
    }
    return out.str();
}

std::string Now() {
    const std::time_t t = std::time(nullptr);
    char buffer[64];
    std::strftime(buffer, sizeof(buffer), "%Y-%m-%d %H:%M:%S %Z", std::localtime(&t));
    return buffer;
}

} // namespace

int main(int argc, char** argv) {
    if (argc > 1 && std::string(argv[1]) == "--child") return RunChild(argc, argv);
    Options options;
    try {
        options = ParseOptions(argc, argv);
        // Fail now, not after minutes of measuring, if an output cannot be written.
        if (!options.mMarkdown.empty()) CheckWritable(options.mMarkdown);
        for (const std::string& path : CsvPaths(options)) CheckWritable(path);
    } catch (const Error& e) {
        std::fprintf(stderr, "bench: %s\n", e.what());
        return 2;
    }
    const auto start = Clock::now();
    const std::string date = Now();
    const std::string loadStart = LoadAverage();
    std::fprintf(stderr, "bench: load average at start %s\n", loadStart.c_str());

    std::vector<Measurement> runs;
    if (options.mRender) {
        const size_t total = options.mScenes.size() * options.mAlgorithms.size() * options.mThreads.size();
        size_t done = 0;
        for (int scene : options.mScenes)
            for (Algorithm algorithm : options.mAlgorithms)
                for (int threads : options.mThreads) {
                    const Measurement m = MeasureInChild(options, scene, algorithm, threads);
                    runs.push_back(m);
                    done++;
                    if (m.mOk)
                        std::fprintf(stderr,
                                     "[%zu/%zu] scene %s, %s, %d thread%s: %d iterations, %.4f s/iteration, %s rays/s, "
                                     "CPU %.0f%%%s, peak %s MiB (%.0f s)\n",
                                     done, total, kCornellShort[scene], smallvcm::AlgorithmShortName(algorithm), threads,
                                     threads == 1 ? "" : "s", m.mIterations, m.SecondsPerIteration(),
                                     Rate(m.RaysPerSecond()).c_str(), 100.0 * m.Utilisation(),
                                     m.Utilisation() < 0.9 ? " (cores shared with another program?)" : "", Mib(m.mPeakKb).c_str(),
                                     SecondsSince(start));
                    else
                        std::fprintf(stderr, "[%zu/%zu] scene %s, %s, %d threads: FAILED: %s\n", done, total,
                                     kCornellShort[scene], smallvcm::AlgorithmShortName(algorithm), threads, m.mError.c_str());
                }
    }

    std::vector<BvhRow> bvh;
    if (options.mBvh) {
        long triangles = 100;
        for (int exponent = 2; exponent <= options.mBvhMaxExponent; exponent++, triangles *= 10) {
            try {
                bvh.push_back(MeasureBvh(options, triangles));
                const BvhRow& r = bvh.back();
                std::fprintf(stderr, "[bvh] %ld triangles: build %.3f ms, %zu nodes, depth %d, %s nearest-hit rays/s, "
                                     "%s shadow rays/s; per CPU second %s and %s (%.0f s)\n",
                             triangles, 1e3 * r.mBuildSeconds, r.mNodes, r.mDepth, Rate(r.mNearestRaysPerSecond).c_str(),
                             Rate(r.mShadowRaysPerSecond).c_str(), Rate(r.mNearestRaysPerCpuSecond).c_str(),
                             Rate(r.mShadowRaysPerCpuSecond).c_str(), SecondsSince(start));
            } catch (const std::exception& e) {
                std::fprintf(stderr, "[bvh] %ld triangles: FAILED: %s\n", triangles, e.what());
            }
        }
    }

    std::vector<GltfRow> gltf;
    if (options.mGltf) {
        try {
            gltf.push_back(MeasureGltfLoad(options, options.mGltfTriangles));
            const GltfRow& r = gltf.back();
            std::fprintf(stderr, "[gltf] %zu triangles (%.1f MiB): loaded in %.3f s (CPU %.3f s): reading %.3f s, "
                                 "Finalize + BVH %.3f s (%.0f s)\n",
                         r.mLoadedTriangles, double(r.mFileBytes) / 1048576.0, r.mSeconds, r.mCpuSeconds, r.mReadSeconds,
                         r.mFinalizeSeconds, SecondsSince(start));
        } catch (const std::exception& e) {
            std::fprintf(stderr, "[gltf] %ld triangles: FAILED: %s\n", options.mGltfTriangles, e.what());
        }
    }

    // 5: the same scene and estimator with the constant background and with the map.
    std::vector<std::pair<Measurement, Measurement>> environment;
    if (options.mEnvironment) {
        if (options.mEnvironmentMap.empty()) options.mEnvironmentMap = ScenesFolder() + "/hdri/royal_esplanade_1k.hdr";
        for (Algorithm algorithm : {Algorithm::kPathTracing, Algorithm::kVertexConnectionMerging}) {
            const Measurement constant = MeasureInChild(options, 3, algorithm, 1);
            const Measurement lit = MeasureInChild(options, 3, algorithm, 1, options.mEnvironmentMap);
            environment.emplace_back(constant, lit);
            if (constant.mOk && lit.mOk)
                std::fprintf(stderr, "[environment] scene 3, %s, 1 thread: constant %.4f s/iteration (CPU %.4f), environment "
                                     "map %.4f s/iteration (CPU %.4f): x%.2f wall, x%.2f CPU (%.0f s)\n",
                             smallvcm::AlgorithmShortName(algorithm), constant.SecondsPerIteration(),
                             constant.mCpuSeconds / constant.mIterations, lit.SecondsPerIteration(), lit.mCpuSeconds / lit.mIterations,
                             lit.SecondsPerIteration() / constant.SecondsPerIteration(),
                             (lit.mCpuSeconds / lit.mIterations) / (constant.mCpuSeconds / constant.mIterations), SecondsSince(start));
            else
                std::fprintf(stderr, "[environment] scene 3, %s: FAILED: %s\n", smallvcm::AlgorithmShortName(algorithm),
                             (constant.mOk ? lit.mError : constant.mError).c_str());
        }
    }

    const std::string report = Report(options, runs, bvh, gltf, environment, date, SecondsSince(start), loadStart, LoadAverage());
    std::fputs(report.c_str(), stdout);
    std::fflush(stdout);
    // The report first, then the CSVs: if one cannot be written, the report is already safe.
    try {
        if (!options.mMarkdown.empty()) {
            WriteFileAtomically(options.mMarkdown, report);
            std::fprintf(stderr, "bench: report written to %s\n", options.mMarkdown.c_str());
        }
        for (const std::string& path : CsvPaths(options)) {
            WriteFileAtomically(path, path == BvhCsvPath(options) ? BvhCsv(bvh) : RenderCsv(options, runs));
            std::fprintf(stderr, "bench: CSV written to %s\n", path.c_str());
        }
    } catch (const Error& e) {
        std::fprintf(stderr, "bench: %s\n", e.what());
        return 1;
    }
    for (const Measurement& m : runs)
        if (!m.mOk) return 1;
    for (const auto& [constant, lit] : environment)
        if (!constant.mOk || !lit.mOk) return 1;
    return 0;
}
