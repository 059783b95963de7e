// [cli] The command-line renderer build/smallvcm, run as a child process: bad options
// exit with code 2, a bad scene or output file with code 1, each with exactly one line
// "smallvcm: <option or file>: <problem>" on stderr, and a failed run leaves no output
// file (nor a .partial). One tiny good run writes a PFM of the requested size. Every
// rejected file of the glTF corpus (tests/data/bad) and the hostile files
// (tests/data/hostile, which crash or hang the loader in-process) run through it too.
// Then what people look at and combine: PNG exposure and tone curves, the JSON sidecar
// written with every image, `smallvcm merge` (its refusals, and a statistical test that a
// merge of runs equals one longer run), -q, "1 iteration", -i with -t, and --layers.
// Last, --envmap and its settings: every format, the sidecar's fields, what rotation and
// scale do to the image, the refused combinations and values, bad maps, and merge.
// Tests run from tests/, so the program is ../build/smallvcm.
#include "gltf_corpus.hpp"
#include "smallvcm.hpp"
#include "examples/my_path_tracer.hpp"

#include "test_util.hpp"

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <sstream>

namespace {

namespace fs = std::filesystem;
using corpus::StartsWith;

const char* const kProgram = "../build/smallvcm";

using testutil::Quote;
using testutil::ReadText;
using testutil::TemporaryFolder;
using testutil::ExitCode;

struct Run {
    int mExitCode = -1;      // the program's exit code; 124 when it ran out of time
    int mSignal = 0;         // the signal that ended it, if one did
    std::string mStdout, mStderr;
    std::string mCommand;
};

std::ostream& operator<<(std::ostream& aOut, const Run& aRun) {
    return aOut << aRun.mCommand << "\n  exit code " << aRun.mExitCode
                << (aRun.mSignal ? "  signal " + std::to_string(aRun.mSignal) : std::string())
                << "\n  stderr: " << aRun.mStderr;
}

// Runs build/smallvcm with aArguments (already quoted) under `timeout aSeconds`.
Run RunProgram(const std::string& aArguments, int aSeconds = 60) {
    TemporaryFolder streams;
    Run run;
    run.mCommand = std::string(kProgram) + " " + aArguments;
    const std::string command = "ulimit -c 0; timeout " + std::to_string(aSeconds) + " " + run.mCommand + " >" +
                                Quote(streams / "stdout") + " 2>" + Quote(streams / "stderr");
    const int status = std::system(command.c_str());
    if (WIFEXITED(status)) {
        run.mExitCode = WEXITSTATUS(status);
        // timeout reports a child killed by signal s as 128 + s.
        if (run.mExitCode > 128 && run.mExitCode != 124) run.mSignal = run.mExitCode - 128;
    } else if (WIFSIGNALED(status)) {
        run.mSignal = WTERMSIG(status);
    }
    run.mStdout = ReadText(streams / "stdout");
    run.mStderr = ReadText(streams / "stderr");
    return run;
}

int LineCount(const std::string& aText) {
    int lines = 0;
    for (char c : aText) lines += c == '\n' ? 1 : 0;
    return lines;
}

// A failed run: the exit code, one line "smallvcm: <aNamed>: ..." on stderr, and neither
// aOutput nor aOutput.partial on disk.
void CheckFailure(const Run& aRun, int aExitCode, const std::string& aNamed, const std::string& aOutput) {
    INFO(aRun);
    CHECK(aRun.mSignal == 0);
    CHECK(aRun.mExitCode == aExitCode);
    CHECK(LineCount(aRun.mStderr) == 1);
    CHECK(StartsWith(aRun.mStderr, "smallvcm: " + aNamed + ": "));
    CHECK_FALSE(fs::exists(aOutput));
    CHECK_FALSE(fs::exists(aOutput + ".partial"));
    CHECK_FALSE(fs::exists(aOutput + ".json"));  // nor its sidecar
}

// Small, fast settings placed before each case's own arguments (later values win).
std::string Tiny(const std::string& aOutput) { return "-a el -i 1 -r 8x8 -j 1 -q -o " + Quote(aOutput); }

struct BadCommandLine {
    std::string mArguments;  // appended after Tiny()
    int mExitCode;
    std::string mNamed;      // the option or file the message must start with
};

} // namespace

TEST_CASE("Bad options exit with code 2 and one line naming the option", "[cli]") {
    TemporaryFolder folder;
    const std::vector<BadCommandLine> cases = {
        {"-a xyz", 2, "-a"},
        {"-i -3", 2, "-i"},
        {"-i 0", 2, "-i"},
        {"-i abc", 2, "-i"},
        {"-r 0x10", 2, "-r"},
        {"-r 100", 2, "-r"},
        {"-j 0", 2, "-j"},
        {"--radius-alpha 0", 2, "--radius-alpha"},
        {"--radius-alpha 2", 2, "--radius-alpha"},
        {"--mis foo", 2, "--mis"},
        {"--sampler halton", 2, "--sampler"},
        {"--sampler", 2, "--sampler"},
        {"--min-path-length 5 --max-path-length 3", 2, "--min-path-length"},
        {"--frobnicate", 2, "--frobnicate"},
        {"-i", 2, "-i"},  // missing value
        {"-s 9", 2, "-s"},
        {"--exposure nan", 2, "--exposure"},
        {"--exposure inf", 2, "--exposure"},
        {"--exposure -inf", 2, "--exposure"},
        {"--exposure 33", 2, "--exposure"},
        {"--exposure -40", 2, "--exposure"},
        {"--exposure 1e9", 2, "--exposure"},
        {"--exposure 2EV", 2, "--exposure"},
        {"--exposure", 2, "--exposure"},
        {"--tonemap reinhard", 2, "--tonemap"},
        {"--tonemap ACES", 2, "--tonemap"},
        {"--tonemap", 2, "--tonemap"},
    };
    int index = 0;
    for (const BadCommandLine& c : cases) {
        const std::string output = folder / ("out" + std::to_string(index++) + ".png");  // one per run
        const Run run = RunProgram(Tiny(output) + " " + c.mArguments);
        CheckFailure(run, c.mExitCode, c.mNamed, output);
    }
}

TEST_CASE("Bad --medium values exit with code 2, one line naming the option, and no output", "[cli][media]") {
    TemporaryFolder folder;
    const std::vector<std::string> values = {
        "1,2", "1", "", "1,2,3,4", "a,b,c", "0.1,0.1,0.3x", ",0.1,0.3", "-1,0,0", "0,-0.5,0", "nan,0,0", "0,inf,0", "1e31,0,0",
        "0,0,1", "0,0,-1", "0,0,1.5", "0,0,nan", "0.1;0.1;0.3",
    };
    int index = 0;
    for (const std::string& value : values) {
        const std::string output = folder / ("out" + std::to_string(index++) + ".png");
        const Run run = RunProgram(Tiny(output) + " -s 2 --medium " + Quote(value));
        CheckFailure(run, 2, "--medium", output);
    }
    CheckFailure(RunProgram(Tiny(folder / "missing.png") + " -s 2 --medium"), 2, "--medium", folder / "missing.png");
    const Run one = RunProgram(Tiny(folder / "g.png") + " -s 2 --medium 0.1,0.01,1");
    CHECK(one.mStderr == "smallvcm: --medium: '1' is not SIGMA_S,SIGMA_A,G (three numbers: scattering and absorption in [0, 1e30] "
                         "per scene unit, Henyey-Greenstein asymmetry in (-1, 1))\n");
}

TEST_CASE("--medium S,A,G is accepted, and the sidecar records the grey scene-wide medium the scene carried", "[cli][media]") {
    // The loader puts the medium into the scene before its Finalize (tests/test_gltf.cpp
    // checks the scene's numbers, "[gltf][media]"); here the program takes it and says so.
    TemporaryFolder folder;
    const std::string output = folder / "fog.pfm";
    const Run run = RunProgram("-s 2 -a el -i 1 -r 8x8 -j 1 -q --medium 0.125,0.0625,-0.25 -o " + Quote(output));
    INFO(run);
    REQUIRE(run.mExitCode == 0);
    const nlohmann::json sidecar = nlohmann::json::parse(ReadText(output + ".json"));
    INFO(sidecar.dump(2));
    const nlohmann::json& medium = sidecar["estimator"]["medium"];
    CHECK(medium["sigma_s"] == 0.125);
    CHECK(medium["sigma_a"] == 0.0625);
    CHECK(medium["g"] == -0.25);
    // Without --medium the estimator has no "medium" (older sidecars merge as before).
    const std::string plain = folder / "plain.pfm";
    REQUIRE(RunProgram("-s 2 -a el -i 1 -r 8x8 -j 1 -q -o " + Quote(plain)).mExitCode == 0);
    CHECK_FALSE(nlohmann::json::parse(ReadText(plain + ".json"))["estimator"].contains("medium"));
    // --help lists the option.
    CHECK(RunProgram("--help").mStdout.find("--medium S,A,G") != std::string::npos);
}

TEST_CASE("A missing scene or an unwritable output exits with code 1 and one line naming the file", "[cli]") {
    TemporaryFolder folder;
    const std::string output = folder / "out.png";
    SECTION("-s names a file that does not exist") {
        CheckFailure(RunProgram(Tiny(output) + " -s nothere.gltf"), 1, "nothere.gltf", output);
    }
    SECTION("-o names a folder that does not exist") {
        const std::string missing = folder / "no_such_folder/out.png";
        CheckFailure(RunProgram(Tiny(output) + " -s 2 -o " + Quote(missing)), 1, missing, missing);
        CHECK_FALSE(fs::exists(folder / "no_such_folder"));
    }
    SECTION("a scene of the bad-input corpus") {
        CheckFailure(RunProgram(Tiny(output) + " -s data/bad/emission_negative.gltf"), 1, "data/bad/emission_negative.gltf", output);
    }
}

TEST_CASE("An output name with an unknown image extension is a bad option value (code 2)", "[cli]") {
    // The program's contract (examples/smallvcm.cpp): a bad option value gives
    // "smallvcm: <option>: <problem>" and exit code 2; the extension is known before any
    // file is touched, and the message already names -o.
    TemporaryFolder folder;
    const std::string jpg = folder / "out.jpg";
    CheckFailure(RunProgram(Tiny(jpg) + " -s 2"), 2, "-o", jpg);
}

TEST_CASE("A failed run leaves an existing output file as it was", "[cli]") {
    TemporaryFolder folder;
    const std::string output = folder / "out.png";
    std::ofstream(output) << "the previous image";
    const Run run = RunProgram(Tiny(output) + " -s data/bad/mode_lines.gltf");
    INFO(run);
    CHECK(run.mExitCode == 1);
    CHECK(ReadText(output) == "the previous image");
    CHECK_FALSE(fs::exists(output + ".partial"));
}

TEST_CASE("Every rejected file of the glTF corpus exits with code 1 and one line naming it", "[cli]") {
    TemporaryFolder folder;
    int files = 0;
    for (const corpus::Row& row : corpus::ReadTable("data/bad/README.md")) {
        if (row.mFragment.empty()) continue;
        files++;
        const std::string path = "data/bad/" + row.mFile;
        const std::string output = folder / (row.mFile + ".png");  // one per run
        const Run run = RunProgram(Tiny(output) + " -s " + Quote(path));
        INFO(row.mWhat << ", expected fragment: " << row.mFragment);
        CheckFailure(run, 1, path, output);
        CHECK(run.mStderr.find(row.mFragment, 10 + path.size()) != std::string::npos);
    }
    CHECK(files >= 32);
}

TEST_CASE("Files that crash or hang the loader in-process end with code 1 in time", "[cli]") {
    // tests/data/hostile/README.md: a stack overflow in the JSON-to-value conversion of
    // tinygltf, and a node graph with 2^40 paths. 5 s is plenty for a loader that
    // rejects them; a hang shows as exit code 124, a crash as a signal.
    TemporaryFolder folder;
    for (const corpus::Row& row : corpus::ReadTable("data/hostile/README.md")) {
        const std::string path = "data/hostile/" + row.mFile;
        const std::string output = folder / (row.mFile + ".png");
        const Run run = RunProgram(Tiny(output) + " -s " + Quote(path), 5);
        INFO(row.mWhat << ", expected fragment: " << row.mFragment);
        CheckFailure(run, 1, path, output);
        CHECK(run.mStderr.find(row.mFragment, 10 + path.size()) != std::string::npos);
    }
}

TEST_CASE("A scene with zero-area triangles renders and the note names the file and the count", "[cli]") {
    TemporaryFolder folder;
    const std::string output = folder / "out.png";
    const Run run = RunProgram("-a el -i 1 -r 8x8 -j 1 -o " + Quote(output) + " -s data/bad/degenerate_repeated_index.gltf");
    INFO(run);
    CHECK(run.mExitCode == 0);
    CHECK(LineCount(run.mStderr) == 1);
    CHECK(StartsWith(run.mStderr, "smallvcm: data/bad/degenerate_repeated_index.gltf: note: skipped 1 degenerate"));
    CHECK(fs::exists(output));
    // -q: nothing at all on success, the note included.
    const Run quiet = RunProgram(Tiny(output) + " -s data/bad/degenerate_repeated_index.gltf");
    INFO(quiet);
    CHECK(quiet.mExitCode == 0);
    CHECK(quiet.mStderr.empty());
    CHECK(quiet.mStdout.empty());
}

TEST_CASE("A tiny good run writes a PFM of the requested size", "[cli]") {
    TemporaryFolder folder;
    const std::string output = folder / "eye_light.pfm";
    const Run run = RunProgram("-s 2 -a el -i 1 -r 64x48 -o " + Quote(output));
    INFO(run);
    REQUIRE(run.mExitCode == 0);
    CHECK(run.mStderr.empty());
    CHECK(LineCount(run.mStdout) == 1);  // the summary line
    CHECK_FALSE(fs::exists(output + ".partial"));
    const smallvcm::Image image = smallvcm::ReadPfm(output);
    CHECK(image.mWidth == 64);
    CHECK(image.mHeight == 48);
    bool finite = true;
    for (const smallvcm::Vec3& pixel : image.mPixels) finite = finite && smallvcm::IsFinite(pixel);
    CHECK(finite);
    CHECK(smallvcm::MeanValue(image) > 0.0);
}

TEST_CASE("The sampler is sobol by default; --sampler independent renders the same seed differently, each reproducibly, and the sidecar records it", "[cli][sidecar]") {
    TemporaryFolder folder;
    const std::string independent = folder / "independent.pfm", sobol = folder / "sobol.pfm", again = folder / "again.pfm",
                      byDefault = folder / "default.pfm";
    for (const auto& [arguments, output] : {std::pair<std::string, std::string>{"--sampler independent", independent},
                                            {"--sampler sobol", sobol}, {"--sampler sobol", again}, {"", byDefault}}) {
        const Run run = RunProgram("-s 4 -a pt -i 2 -r 32x32 -j 2 " + arguments + " -o " + Quote(output));
        INFO(run);
        REQUIRE(run.mExitCode == 0);
    }
    const smallvcm::Image a = smallvcm::ReadPfm(independent), b = smallvcm::ReadPfm(sobol), c = smallvcm::ReadPfm(again);
    CHECK(a.mPixels != b.mPixels);
    CHECK(b.mPixels == c.mPixels);
    CHECK(smallvcm::ReadPfm(byDefault).mPixels == b.mPixels);
    CHECK(nlohmann::json::parse(ReadText(sobol + ".json"))["run"]["sampler"] == "sobol");
    CHECK(nlohmann::json::parse(ReadText(independent + ".json"))["run"]["sampler"] == "independent");
}

TEST_CASE("--help lists every built-in and the linked-in integrators with their descriptions", "[cli][integrator_api]") {
    const Run run = RunProgram("--help");
    INFO(run);
    REQUIRE(run.mExitCode == 0);
    std::vector<smallvcm::Integrator> expected;
    for (const smallvcm::Integrator* registered : smallvcm::RegisteredIntegrators())
        if (smallvcm::ParseAlgorithm(registered->mName)) expected.push_back(*registered);  // the built-ins
    expected.push_back(MyPathTracerIntegrator());  // linked in by the Makefile's default INTEGRATORS
    for (const smallvcm::Integrator& integrator : expected) {
        INFO(integrator.mName);
        CHECK(run.mStdout.find(" " + integrator.mName + " ") != std::string::npos);
        CHECK(run.mStdout.find(integrator.mDescription + "\n") != std::string::npos);
    }
    const Run unknown = RunProgram("-a nosuch -q");
    CHECK(unknown.mExitCode == 2);
    CHECK(unknown.mStderr == "smallvcm: -a: unknown algorithm 'nosuch' (el, pt, lt, pm, pmfg, ppm, bpm, bpt, vcm, pb2d, bb1d, upbp, mypt)\n");
}

TEST_CASE("-a mypt renders the student's path tracer, the same image as Render in this process", "[cli][integrator_api]") {
    TemporaryFolder folder;
    const std::string output = folder / "mypt.pfm";
    const Run run = RunProgram("-s 2 -a mypt -i 2 -j 1 -r 16x12 -q -o " + Quote(output));
    INFO(run);
    REQUIRE(run.mExitCode == 0);
    smallvcm::Scene scene = testutil::LoadCornell(2, 16, 12);
    smallvcm::RenderOptions options;
    options.mIterations = 2;
    options.mThreads = 1;
    options.mProgress = false;
    options.mSampler = smallvcm::SamplerType::kSobol;  // the command line's default
    const smallvcm::Image expected = smallvcm::Render(scene, options, MyPathTracerIntegrator()).mImage;
    const smallvcm::Image image = smallvcm::ReadPfm(output);
    REQUIRE(image.mPixels.size() == expected.mPixels.size());
    CHECK(image.mPixels == expected.mPixels);
    CHECK(smallvcm::MeanValue(image) > 0.0);
}

TEST_CASE("The scene is the argument that is not an option, anywhere among the options, or -s SCENE: the same image", "[cli]") {
    TemporaryFolder folder;
    const auto render = [&](const std::string& aName, const std::string& aArguments) {
        const std::string output = folder / aName;
        const Run run = RunProgram(aArguments + " -o " + Quote(output));
        INFO(run);
        REQUIRE(run.mExitCode == 0);
        return smallvcm::ReadPfm(output).mPixels;
    };
    // A Cornell scene number first, between options or last; a glTF file first or last.
    // (Images are compared whole: a failure says false rather than list every pixel.)
    const std::vector<smallvcm::Vec3> cornell = render("s4.pfm", "-a el -i 1 -r 16x12 -j 1 -q -s 4");
    CHECK((render("first.pfm", "4 -a el -i 1 -r 16x12 -j 1 -q") == cornell));
    CHECK((render("between.pfm", "-a el -i 1 4 -r 16x12 -j 1 -q") == cornell));
    CHECK((render("last.pfm", "-a el -i 1 -r 16x12 -j 1 -q 4") == cornell));
    const std::string file = testutil::CornellPath(1);
    const std::vector<smallvcm::Vec3> gltf = render("s1.pfm", "-a el -i 1 -r 16x12 -j 1 -q -s " + file);
    CHECK((gltf != cornell));
    CHECK((render("file_first.pfm", file + " -a el -i 1 -r 16x12 -j 1 -q") == gltf));
    CHECK((render("file_last.pfm", "-a el -i 1 -r 16x12 -j 1 -q " + file) == gltf));
    // -s given twice keeps the last, as every option does.
    CHECK((render("twice.pfm", "-a el -i 1 -r 16x12 -j 1 -q -s 4 -s " + file) == gltf));
}

TEST_CASE("A positional scene beside another is refused naming both; an argument starting with '-' that is no option stays unknown", "[cli]") {
    TemporaryFolder folder;
    const std::string output = folder / "out.png";
    const std::string file = testutil::CornellPath(1);
    for (const std::string& scenes : {"4 " + file, "-s 4 " + file, file + " -s 4", std::string("4 4")}) {
        const Run run = RunProgram(Tiny(output) + " " + scenes);
        CheckFailure(run, 2, "scene", output);
        CHECK_THAT(run.mStderr, Catch::StartsWith("smallvcm: scene: two given, '") && Catch::Contains("': a run renders one scene"));
        if (scenes != "4 4") CHECK_THAT(run.mStderr, Catch::Contains("'4'") && Catch::Contains("'" + file + "'"));
    }
    // merge away from the front reads as a scene: the message says where merge goes.
    const Run merge = RunProgram("-q merge " + Quote(folder / "merged.pfm") + " run.pfm");
    CheckFailure(merge, 2, "scene", folder / "merged.pfm");
    CHECK_THAT(merge.mStderr, Catch::Contains("merge is a subcommand only as the first argument"));
    for (const std::string option : {"--frobnicate", "-x", "-", "--s"}) {
        const Run run = RunProgram(Tiny(output) + " 4 " + option);
        CheckFailure(run, 2, option, output);
        CHECK(run.mStderr == "smallvcm: " + option + ": unknown option (see --help)\n");
    }
    // A number that is no Cornell scene is refused as -s refuses it, named as given.
    const Run nine = RunProgram(Tiny(output) + " 9");
    CheckFailure(nine, 2, "scene", output);
    CHECK(nine.mStderr == "smallvcm: scene: '9' is not a Cornell scene index (0..4) nor a .gltf/.glb file\n");
}

TEST_CASE("--background 0,0,0 on a file without lights is refused as --background none is, and writes nothing", "[cli]") {
    TemporaryFolder folder;
    // One triangle, no light, no camera.
    const std::string scene = folder / "unlit.gltf";
    std::ofstream(scene) << R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}],
      "bufferViews": [{"buffer": 0, "byteLength": 36}],
      "buffers": [{"byteLength": 36, "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}]})";
    const std::string output = folder / "out.png";
    const Run black = RunProgram(Tiny(output) + " " + Quote(scene) + " --background 0,0,0");
    CheckFailure(black, 1, scene, output);
    CHECK(black.mStderr == "smallvcm: " + scene + ": the scene has no light: --background 0,0,0 is black and the file has no other "
                                                  "light; give a non-black --background R,G,B, or add lights to the file\n");
    const Run none = RunProgram(Tiny(output) + " " + Quote(scene) + " --background none");
    CheckFailure(none, 1, scene, output);
    CHECK_THAT(none.mStderr, Catch::Contains(": the scene has no light: --background none removes the background"));
    // The same file renders with the default sky and sun, or any non-black background.
    const Run grey = RunProgram(Tiny(output) + " " + Quote(scene) + " --background 0,0,0.5");
    INFO(grey);
    CHECK(grey.mExitCode == 0);
    CHECK(fs::exists(output));
}

namespace {

// build/smallvcm started in the background, its output streams in files of aFolder.
struct Child {
    pid_t mPid = -1;
    std::string mStderrPath;
};

Child StartProgram(const std::vector<std::string>& aArguments, const TemporaryFolder& aFolder, const std::string& aName) {
    Child child;
    child.mStderrPath = aFolder / (aName + ".stderr");
    const std::string stdoutPath = aFolder / (aName + ".stdout");
    std::fflush(stdout);  // or the child would print the parent's buffered output again
    std::fflush(stderr);
    child.mPid = fork();
    if (child.mPid == 0) {
        std::freopen(stdoutPath.c_str(), "w", stdout);
        std::freopen(child.mStderrPath.c_str(), "w", stderr);
        std::vector<char*> argv{const_cast<char*>(kProgram)};
        for (const std::string& argument : aArguments) argv.push_back(const_cast<char*>(argument.c_str()));
        argv.push_back(nullptr);
        execv(kProgram, argv.data());
        _exit(127);
    }
    return child;
}

// Waits up to aSeconds for the child; returns its wait status, or -1 (then kills it).
int WaitProgram(const Child& aChild, double aSeconds) {
    for (int waited = 0; waited < int(aSeconds * 100); waited++) {
        int status = 0;
        if (waitpid(aChild.mPid, &status, WNOHANG) == aChild.mPid) return status;
        usleep(10000);
    }
    kill(aChild.mPid, SIGKILL);
    waitpid(aChild.mPid, nullptr, 0);
    return -1;
}

std::vector<std::string> FolderEntries(const TemporaryFolder& aFolder) {
    std::vector<std::string> names;
    for (const auto& entry : fs::directory_iterator(aFolder.mPath)) names.push_back(entry.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
}

bool AnyPartial(const TemporaryFolder& aFolder) {
    for (const std::string& name : FolderEntries(aFolder))
        if (name.find(".partial") != std::string::npos) return true;
    return false;
}

} // namespace

TEST_CASE("SIGTERM and SIGINT stop the render, write what was accumulated and exit 128 + the signal", "[cli][signals]") {
    for (int signal : {SIGTERM, SIGINT}) {
        TemporaryFolder folder;
        const std::string output = folder / "interrupted.pfm";
        const Child child = StartProgram({"-s", "2", "-a", "pt", "-t", "100", "-r", "32x32", "-j", "2", "-o", output}, folder, "run");
        usleep(1500000);  // loading takes milliseconds, an iteration well under one
        kill(child.mPid, signal);
        const int status = WaitProgram(child, 20);
        const std::string stderrText = ReadText(child.mStderrPath);
        INFO("signal " << signal << ", stderr: " << stderrText);
        REQUIRE(status != -1);
        REQUIRE(WIFEXITED(status));
        CHECK(WEXITSTATUS(status) == 128 + signal);
        CHECK(StartsWith(stderrText, std::string("smallvcm: interrupted (") + (signal == SIGTERM ? "SIGTERM" : "SIGINT") +
                                         "): writing the "));
        const smallvcm::Image image = smallvcm::ReadPfm(output);
        CHECK(image.mWidth == 32);
        CHECK(smallvcm::MeanValue(image) > 0.0);
        CHECK_FALSE(AnyPartial(folder));
        const nlohmann::json sidecar = nlohmann::json::parse(ReadText(output + ".json"));
        CHECK(sidecar["run"]["stopped_early"] == true);
        CHECK(sidecar["run"]["stop_signal"] == (signal == SIGTERM ? "SIGTERM" : "SIGINT"));
        CHECK(sidecar["iterations"].get<int>() >= 1);
    }
}

TEST_CASE("A second signal ends the program at once and leaves no temporary file", "[cli][signals]") {
    TemporaryFolder folder;
    const std::string output = folder / "never.png";
    // One iteration of 2048x2048 takes seconds: the first signal waits for it, the second does not.
    const Child child = StartProgram({"-s", "2", "-a", "pt", "-i", "4", "-r", "2048x2048", "-j", "1", "-o", output}, folder, "run");
    usleep(500000);
    kill(child.mPid, SIGINT);
    usleep(200000);
    kill(child.mPid, SIGINT);
    const int status = WaitProgram(child, 5);
    INFO("stderr: " << ReadText(child.mStderrPath));
    REQUIRE(status != -1);
    CHECK(WIFSIGNALED(status));
    CHECK(WTERMSIG(status) == SIGINT);
    CHECK_FALSE(fs::exists(output));
    CHECK_FALSE(AnyPartial(folder));
}

TEST_CASE("Two renders writing the same output both finish with a valid image", "[cli]") {
    TemporaryFolder folder;
    const std::string output = folder / "same.pfm";
    const Child first = StartProgram({"-s", "2", "-a", "pt", "-i", "30", "-r", "48x48", "-j", "1", "-q", "-o", output}, folder, "first");
    const Child second = StartProgram({"-s", "2", "-a", "pt", "-i", "30", "-r", "48x48", "-j", "1", "-q", "--seed", "9", "-o", output}, folder, "second");
    const int firstStatus = WaitProgram(first, 60), secondStatus = WaitProgram(second, 60);
    CHECK(ExitCode(firstStatus) == 0);
    CHECK(ExitCode(secondStatus) == 0);
    CHECK(smallvcm::ReadPfm(output).mWidth == 48);
    CHECK_FALSE(AnyPartial(folder));
}

TEST_CASE("Hostile scene and output paths are refused before rendering, in time", "[cli]") {
    TemporaryFolder folder;
    const std::string output = folder / "out.png";
    SECTION("a FIFO as the scene") {
        const std::string pipe = folder / "pipe.gltf";
        REQUIRE(mkfifo(pipe.c_str(), 0600) == 0);
        CheckFailure(RunProgram(Tiny(output) + " -s " + Quote(pipe), 10), 1, pipe, output);
    }
    SECTION("/dev/zero as the scene") {
        CheckFailure(RunProgram(Tiny(output) + " -s /dev/zero", 10), 1, "/dev/zero", output);
    }
    SECTION("an output that is a directory, found before a 100-second render") {
        const std::string directory = folder / "taken.png";
        fs::create_directories(directory);
        const Run run = RunProgram(Tiny(output) + " -s 2 -t 100 -i 100000000 -o " + Quote(directory), 20);
        CheckFailure(run, 1, directory, directory + "/none");
        CHECK(run.mStderr.find("is a directory") != std::string::npos);
    }
}

TEST_CASE("Resource options beyond what the machine can do are refused with the reason", "[cli]") {
    TemporaryFolder folder;
    const std::string output = folder / "out.png";
    const Run threads = RunProgram(Tiny(output) + " -s 2 -j 1024");
    CheckFailure(threads, 2, "-j", output);
    CHECK(threads.mStderr.find("at most 4 threads per core") != std::string::npos);
    const Run radius = RunProgram(Tiny(output) + " -s 2 --radius-factor 10");
    CheckFailure(radius, 2, "--radius-factor", output);
    CHECK(radius.mStderr.find("hundreds of times slower") != std::string::npos);
    CheckFailure(RunProgram(Tiny(output) + " -s 2 --max-radius 10"), 2, "--max-radius", output);
    // The beams' radii and count: zero, NaN, negative and huge are refused by name.
    for (const char* bad : {"--beam-radius-factor 0", "--beam-radius-factor nan", "--beam-radius-factor 1",
                            "--medium-radius-factor 0", "--medium-radius-factor nan", "--beam-paths 0",
                            "--beam-paths -5", "--beam-paths 99999999999"}) {
        const std::string option = std::string(bad).substr(0, std::string(bad).find(' '));
        CheckFailure(RunProgram(Tiny(output) + " -s 2 -a bb1d " + bad), 2, option, output);
    }
    // upbp's techniques: an empty list, unknown, repeated or empty names.
    for (const char* bad : {"''", "bpt,", "bpt,bpt", "bpt,beams", "BPT", ",surf", "bpt,,pb2d"})
        CheckFailure(RunProgram(Tiny(output) + " -s 2 -a upbp --techniques " + bad), 2, "--techniques", output);
    CHECK(smallvcm::ParseUpbpTechniques("bb1d,bpt") == std::optional<uint32_t>(smallvcm::kUpbpBb1d | smallvcm::kUpbpBpt));
    CHECK(smallvcm::ParseUpbpTechniques("bpt,surf,pp3d,pb2d,bb1d") == std::optional<uint32_t>(smallvcm::kUpbpAll));
    // 2^28 pixels of VCM: refused before any allocation wherever it would not fit in 3/4
    // of the memory (the estimate is the library's own, EstimateRenderBytes).
    smallvcm::Camera camera;
    camera.SetResolution(16384, 16384);
    smallvcm::RenderOptions options;
    options.mAlgorithm = smallvcm::Algorithm::kVertexConnectionMerging;
    const uint64_t needed = smallvcm::EstimateRenderBytes(camera, options, 1);
    CHECK(needed > uint64_t(16384) * 16384 * 24);  // at least the film
    if (needed > smallvcm::PhysicalMemoryBytes() / 4 * 3) {
        const Run big = RunProgram(Tiny(output) + " -s 2 -a vcm -r 16384x16384");
        CheckFailure(big, 2, "-r", output);
        CHECK(big.mStderr.find("needs about") != std::string::npos);
    }
}

// -------------------------------------------------------------------------------------
// Exposure, tone curves and sidecars
// -------------------------------------------------------------------------------------

namespace {

using Json = nlohmann::json;

Json ReadJson(const std::string& aPath) {
    std::ifstream file(aPath, std::ios::binary);
    REQUIRE(file);
    return Json::parse(file);
}

std::vector<unsigned char> ReadFileBytes(const std::string& aPath) {
    std::ifstream file(aPath, std::ios::binary);
    return std::vector<unsigned char>((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
}

// FNV-1a (64 bits) in hex, as the sidecar's fingerprints are written.
std::string Fnv1a64(const std::vector<unsigned char>& aBytes) {
    uint64_t hash = 1469598103934665603ull;
    for (unsigned char byte : aBytes) hash = (hash ^ byte) * 1099511628211ull;
    char text[17];
    std::snprintf(text, sizeof(text), "%016llx", static_cast<unsigned long long>(hash));
    return text;
}

} // namespace

TEST_CASE("--exposure and --tonemap change the PNG only, exactly as the library's encoder does", "[cli][sidecar]") {
    TemporaryFolder folder;
    // One thread and one seed: the same image bit for bit, so the PFM is the PNG's radiance.
    const std::string common = "-s 4 -a pt -i 2 -r 24x16 -j 1 -q --seed 5 ";
    const std::string pfm = folder / "radiance.pfm";
    REQUIRE(RunProgram(common + "--exposure 3 --tonemap aces -o " + Quote(pfm)).mExitCode == 0);
    const smallvcm::Image radiance = smallvcm::ReadPfm(pfm);
    const std::string plainPfm = folder / "plain.pfm";
    REQUIRE(RunProgram(common + "-o " + Quote(plainPfm)).mExitCode == 0);
    CHECK(ReadFileBytes(pfm) == ReadFileBytes(plainPfm));  // linear radiance, whatever the PNG options
    struct Case { std::string mArguments; float mExposure; smallvcm::ToneMap mToneMap; };
    for (const Case& c : {Case{"", 0.f, smallvcm::ToneMap::kClamp}, Case{"--exposure 1.5", 1.5f, smallvcm::ToneMap::kClamp},
                          Case{"--tonemap aces", 0.f, smallvcm::ToneMap::kAces}, Case{"--exposure -2 --tonemap aces", -2.f, smallvcm::ToneMap::kAces},
                          Case{"--tonemap clamp --exposure 0", 0.f, smallvcm::ToneMap::kClamp}}) {
        INFO(c.mArguments);
        const std::string png = folder / "tone.PNG";
        const Run run = RunProgram(common + c.mArguments + " -o " + Quote(png));
        REQUIRE(run.mExitCode == 0);
        smallvcm::ImageWriteOptions options;
        options.mExposure = c.mExposure;
        options.mToneMap = c.mToneMap;
        CHECK(ReadFileBytes(png) == smallvcm::EncodeImage(png, radiance, options));
        const Json sidecar = ReadJson(png + ".json");
        CHECK(sidecar["png"]["exposure"].get<double>() == c.mExposure);
        CHECK(sidecar["png"]["tonemap"] == smallvcm::ToneMapName(c.mToneMap));
    }
}

TEST_CASE("Every image gets a sidecar saying how it was made, fingerprinting the image", "[cli][sidecar]") {
    TemporaryFolder folder;
    const std::string output = folder / "run.pfm";
    const Run run = RunProgram("-s 2 -a vcm -i 3 -r 20x12 -j 2 -q --seed 77 --max-path-length 7 --min-path-length 1 "
                               "--mis power --radius-factor 0.01 --background 0.5,0.25,0 -o " + Quote(output));
    INFO(run);
    REQUIRE(run.mExitCode == 0);
    const Json s = ReadJson(output + ".json");
    INFO(s.dump(2));
    CHECK(s["format"] == "smallvcm image sidecar 1");
    CHECK(s["image"] == "run.pfm");
    CHECK(s["image_fnv1a64"] == Fnv1a64(ReadFileBytes(output)));
    CHECK(StartsWith(s["scene"].get<std::string>(), "/"));  // -s 2 resolved to its file
    CHECK(s["scene"].get<std::string>().find("cornell_2_point.gltf") != std::string::npos);
    const Json& e = s["estimator"];
    CHECK(e["algorithm"] == "vcm");
    CHECK(e["scene_fnv1a64"] == Fnv1a64(ReadFileBytes("../scenes/cornell_2_point.gltf")));
    CHECK(e["width"] == 20);
    CHECK(e["height"] == 12);
    CHECK(e["max_path_length"] == 7);
    CHECK(e["min_path_length"] == 1);
    CHECK(e["mis"] == "power");
    CHECK(e["radius_factor"].get<double>() == 0.01);
    CHECK(e["background"] == Json::array({0.5, 0.25, 0.0}));
    CHECK(e["layer"].is_null());
    CHECK_FALSE(e.contains("photons"));  // only the settings vcm uses
    CHECK(s["seed"] == 77);
    CHECK(s["iterations"] == 3);
    CHECK(s["seconds"].get<double>() > 0.0);
    CHECK(s["run"]["iterations_requested"] == 3);
    CHECK(s["run"]["seconds_budget"].is_null());
    CHECK(s["run"]["threads"] == 2);
    CHECK(s["run"]["stopped_early"] == false);
    CHECK(s["run"]["sampler"] == "sobol");  // the command line's default
    CHECK(s["mean"].get<double>() == Approx(smallvcm::MeanValue(smallvcm::ReadPfm(output))).epsilon(1e-12));
    CHECK((s["smallvcm_commit"].is_null() || s["smallvcm_commit"].is_string()));
}

TEST_CASE("A scene path with quotes, backslashes and a newline is escaped in the sidecar", "[cli][sidecar]") {
    TemporaryFolder folder;
    const std::string scene = folder / "we\"ird\\name\nwith 'quotes'.gltf";
    fs::copy_file("../scenes/cornell_2_point.gltf", scene);
    const std::string output = folder / "out.pfm";
    const Run run = RunProgram("-s " + Quote(scene) + " -a el -i 1 -r 8x8 -j 1 -q -o " + Quote(output));
    INFO(run);
    REQUIRE(run.mExitCode == 0);
    CHECK(ReadJson(output + ".json")["scene"] == scene);
}

TEST_CASE("Something in the way of the sidecar is found before rendering; a late failure leaves neither file", "[cli][sidecar]") {
    TemporaryFolder folder;
    const std::string output = folder / "out.pfm";
    SECTION("a directory where the sidecar goes") {
        fs::create_directories(output + ".json");
        const Run run = RunProgram(Tiny(output) + " -s 2 -t 100 -i 100000000", 20);
        INFO(run);
        CHECK(run.mExitCode == 1);
        CHECK(LineCount(run.mStderr) == 1);
        CHECK(StartsWith(run.mStderr, "smallvcm: " + output + ".json: is in the way"));
        CHECK_FALSE(fs::exists(output));
        CHECK_FALSE(AnyPartial(folder));
    }
    SECTION("a layer's name taken by a non-empty directory: the rename fails after the render, nothing is left") {
        fs::create_directories(folder / "out.direct_nonspecular.pfm/inside");
        const Run run = RunProgram(Tiny(output) + " -s 2 -a pt --layers");
        INFO(run);
        CHECK(run.mExitCode == 1);
        CHECK(LineCount(run.mStderr) == 1);
        CHECK(StartsWith(run.mStderr, "smallvcm: " + folder / "out.direct_nonspecular.pfm: cannot put the file in place"));
        CHECK(FolderEntries(folder) == std::vector<std::string>{"out.direct_nonspecular.pfm"});
    }
}

// -------------------------------------------------------------------------------------
// smallvcm merge
// -------------------------------------------------------------------------------------

namespace {

// A merge that must fail: the exit code, one line naming aNamed, and neither OUT nor its
// sidecar (nor a temporary) in the folder afterwards.
void CheckMergeFailure(const Run& aRun, int aExitCode, const std::string& aNamed, const std::string& aOutput, const std::string& aProblem) {
    CheckFailure(aRun, aExitCode, aNamed, aOutput);
    INFO(aRun);
    CHECK(aRun.mStderr.find(aProblem) != std::string::npos);
}

// Runs of the point-light Cornell scene by path tracing; aExtra may change any setting.
std::string RenderRun(const TemporaryFolder& aFolder, const std::string& aName, int aIterations, int aSeed, const std::string& aExtra = "") {
    const std::string path = aFolder / aName;
    const Run run = RunProgram("-s 2 -a pt -r 16x12 -j 1 -q -i " + std::to_string(aIterations) + " --seed " + std::to_string(aSeed) + " " +
                               aExtra + " -o " + Quote(path));
    INFO(run);
    REQUIRE(run.mExitCode == 0);
    return path;
}

std::string MergeCommand(const std::string& aOutput, const std::vector<std::string>& aInputs) {
    std::string command = "merge " + Quote(aOutput);
    for (const std::string& input : aInputs) command += " " + Quote(input);
    return command;
}

} // namespace

TEST_CASE("merge weights runs by their iterations and writes a sidecar listing them", "[cli][merge]") {
    TemporaryFolder folder;
    const std::string a = RenderRun(folder, "a.pfm", 1, 1), b = RenderRun(folder, "b.pfm", 3, 2), c = RenderRun(folder, "c.hdr", 4, 3);
    const std::string output = folder / "merged.pfm";
    const Run run = RunProgram(MergeCommand(output, {a, b, c}));
    INFO(run);
    REQUIRE(run.mExitCode == 0);
    CHECK(run.mStderr.empty());
    CHECK(StartsWith(run.mStdout, "merged 3 runs of pt: 8 iterations, mean "));
    const smallvcm::Image merged = smallvcm::ReadPfm(output);
    const smallvcm::Image ia = smallvcm::ReadImage(a), ib = smallvcm::ReadImage(b), ic = smallvcm::ReadImage(c);
    double worst = 0.0;
    for (size_t i = 0; i < merged.mPixels.size(); i++)
        for (int k = 0; k < 3; k++) {
            const double expected = (1.0 * ia.mPixels[i][k] + 3.0 * ib.mPixels[i][k] + 4.0 * ic.mPixels[i][k]) / 8.0;
            worst = std::max(worst, std::abs(double(merged.mPixels[i][k]) - expected) / std::max(expected, 1e-30));
        }
    CHECK(worst < 1e-6);  // float rounding of the stored result
    const Json s = ReadJson(output + ".json");
    INFO(s.dump(2));
    CHECK(s["iterations"] == 8);
    CHECK(s["seeds"] == Json::array({1, 2, 3}));
    CHECK(s["estimator"] == ReadJson(a + ".json")["estimator"]);
    CHECK(s["image_fnv1a64"] == Fnv1a64(ReadFileBytes(output)));
    REQUIRE(s["merged_from"].size() == 3);
    CHECK(s["merged_from"][2]["file"] == c);
    CHECK(s["merged_from"][2]["iterations"] == 4);
    // A merged image merges again (its seeds count as used), and -q prints nothing.
    const std::string d = RenderRun(folder, "d.pfm", 2, 4);
    const std::string again = folder / "again.pfm";
    const Run second = RunProgram("merge -q " + Quote(again) + " " + Quote(output) + " " + Quote(d));
    INFO(second);
    REQUIRE(second.mExitCode == 0);
    CHECK(second.mStdout.empty());
    CHECK(ReadJson(again + ".json")["iterations"] == 10);
    CHECK(ReadJson(again + ".json")["seeds"] == Json::array({1, 2, 3, 4}));
    // To PNG, with exposure and tone curve: a picture of the merged radiance.
    const std::string png = folder / "merged.png";
    REQUIRE(RunProgram("merge -q --exposure 1 --tonemap aces " + Quote(png) + " " + Quote(a) + " " + Quote(b)).mExitCode == 0);
    CHECK(ReadJson(png + ".json")["png"]["tonemap"] == "aces");
}

TEST_CASE("merge refuses mismatched runs, bad sidecars, PNGs and bad paths with one line naming the file", "[cli][merge]") {
    TemporaryFolder folder;
    const std::string output = folder / "out.pfm";
    const std::string a = RenderRun(folder, "a.pfm", 2, 1), b = RenderRun(folder, "b.pfm", 2, 2);
    auto copyRun = [&](const std::string& aFrom, const std::string& aName) {
        fs::copy_file(aFrom, folder / aName);
        fs::copy_file(aFrom + ".json", folder / (aName + ".json"));
        return folder / aName;
    };
    SECTION("another scene") {
        const std::string other = RenderRun(folder, "other.pfm", 2, 3, "-s 3");
        CheckMergeFailure(RunProgram(MergeCommand(output, {a, other})), 1, other, output, "its scene_fnv1a64");
    }
    SECTION("another resolution") {
        const std::string other = RenderRun(folder, "other.pfm", 2, 3, "-r 12x16");
        CheckMergeFailure(RunProgram(MergeCommand(output, {a, other})), 1, other, output, "its width (12) differs");
    }
    SECTION("another algorithm") {
        const std::string other = RenderRun(folder, "other.pfm", 2, 3, "-a bpt");
        CheckMergeFailure(RunProgram(MergeCommand(output, {a, other})), 1, other, output, "its algorithm (\"bpt\") differs");
    }
    SECTION("another setting of the estimator") {
        const std::string other = RenderRun(folder, "other.pfm", 2, 3, "--max-path-length 4");
        CheckMergeFailure(RunProgram(MergeCommand(output, {a, other})), 1, other, output, "its max_path_length (4) differs");
    }
    SECTION("a setting the algorithm does not use differs: the runs merge") {
        const std::string other = RenderRun(folder, "other.pfm", 2, 3, "--photons 5000 --radius-factor 0.1");
        const Run run = RunProgram(MergeCommand(output, {a, other}));
        INFO(run);
        CHECK(run.mExitCode == 0);
        CHECK_FALSE(ReadJson(a + ".json")["estimator"].contains("radius_factor"));
    }
    SECTION("a layer with the image") {
        RenderRun(folder, "layered.pfm", 2, 3, "--layers");
        const std::string layer = folder / "layered.direct_nonspecular.pfm";
        CheckMergeFailure(RunProgram(MergeCommand(output, {a, layer})), 1, layer, output, "its layer");
    }
    SECTION("the same seed twice") {
        const std::string same = copyRun(a, "same.pfm");
        CheckMergeFailure(RunProgram(MergeCommand(output, {a, b, same})), 1, same, output, "seed 1 was used by an earlier input");
    }
    SECTION("a PNG") {
        const std::string png = RenderRun(folder, "run.png", 2, 3);
        CheckMergeFailure(RunProgram(MergeCommand(output, {a, png})), 1, png, output, "not radiance");
    }
    SECTION("a missing run") {
        const std::string missing = folder / "missing.pfm";
        CheckMergeFailure(RunProgram(MergeCommand(output, {a, missing})), 1, missing, output, "does not exist");
    }
    SECTION("a missing sidecar") {
        const std::string lonely = folder / "lonely.pfm";
        fs::copy_file(b, lonely);
        CheckMergeFailure(RunProgram(MergeCommand(output, {a, lonely})), 1, lonely + ".json", output, "the sidecar does not exist");
    }
    SECTION("malformed sidecars") {
        const std::string broken = copyRun(b, "broken.pfm");
        Json good = ReadJson(b + ".json");
        const struct { std::string mText, mProblem; } cases[] = {
            {"{\"format\": ", "not valid JSON"},
            {"[1, 2]", "no \"format\""},
            {[&] { Json j = good; j["format"] = "something else"; return j.dump(); }(), "no \"format\""},
            {[&] { Json j = good; j.erase("iterations"); return j.dump(); }(), "\"iterations\" is not an integer"},
            {[&] { Json j = good; j["iterations"] = 0; return j.dump(); }(), "\"iterations\" is not an integer"},
            {[&] { Json j = good; j["iterations"] = "2"; return j.dump(); }(), "\"iterations\" is not an integer"},
            {[&] { Json j = good; j.erase("seed"); return j.dump(); }(), "no \"seed\""},
            {[&] { Json j = good; j["seed"] = -1; return j.dump(); }(), "no \"seed\""},
            {[&] { Json j = good; j.erase("estimator"); return j.dump(); }(), "no \"estimator\""},
            {[&] { Json j = good; j["estimator"]["width"] = "16"; return j.dump(); }(), "no integer estimator.width"},
            {[&] { Json j = good; j["image_fnv1a64"] = "0000000000000000"; return j.dump(); }(), "describes another image"},
            {[&] { Json j = good; j["estimator"]["width"] = 15; return j.dump(); }(), "but its sidecar says 15x12"},
        };
        for (const auto& c : cases) {
            std::ofstream(broken + ".json", std::ios::trunc) << c.mText;
            const Run run = RunProgram(MergeCommand(output, {a, broken}));
            const bool namesImage = c.mProblem == "describes another image" || c.mProblem.rfind("but its", 0) == 0;
            CheckMergeFailure(run, 1, namesImage ? broken : broken + ".json", output, c.mProblem);
        }
    }
    SECTION("a sidecar paired with another run's image") {
        const std::string swapped = folder / "swapped.pfm";
        fs::copy_file(a, swapped);
        fs::copy_file(b + ".json", swapped + ".json");
        CheckMergeFailure(RunProgram(MergeCommand(output, {b, swapped})), 1, swapped, output, "describes another image");
    }
    SECTION("a truncated run") {
        const std::string cut = copyRun(b, "cut.pfm");
        fs::resize_file(cut, fs::file_size(cut) - 5);
        CheckMergeFailure(RunProgram(MergeCommand(output, {a, cut})), 1, cut, output, "truncated");
    }
    SECTION("a FIFO as a run's sidecar") {
        const std::string piped = folder / "piped.pfm";
        fs::copy_file(b, piped);
        REQUIRE(mkfifo((piped + ".json").c_str(), 0600) == 0);
        CheckMergeFailure(RunProgram(MergeCommand(output, {a, piped}), 10), 1, piped + ".json", output, "not a regular file");
    }
    SECTION("output problems") {
        CheckMergeFailure(RunProgram(MergeCommand(folder / "out.jpg", {a, b})), 2, folder / "out.jpg", folder / "out.jpg", "unknown image format");
        const std::string nowhere = folder / "no_such_folder/out.pfm";
        CheckMergeFailure(RunProgram(MergeCommand(nowhere, {a, b})), 1, nowhere, nowhere, "does not exist");
        fs::create_directories(output + ".json");
        const Run inTheWay = RunProgram(MergeCommand(output, {a, b}));
        INFO(inTheWay);
        CHECK(inTheWay.mExitCode == 1);
        CHECK(LineCount(inTheWay.mStderr) == 1);
        CHECK(StartsWith(inTheWay.mStderr, "smallvcm: " + output + ".json: is in the way"));
        CHECK_FALSE(fs::exists(output));
        CHECK_FALSE(AnyPartial(folder));
    }
    SECTION("bad merge command lines") {
        CheckMergeFailure(RunProgram("merge " + Quote(output)), 2, "merge", output, "needs an output and at least one run");
        CheckMergeFailure(RunProgram("merge --seed 3 " + Quote(output) + " " + Quote(a)), 2, "--seed", output, "unknown option of merge");
        CheckMergeFailure(RunProgram("merge --exposure 99 " + Quote(output) + " " + Quote(a)), 2, "--exposure", output, "[-32, 32]");
        CheckMergeFailure(RunProgram("merge --tonemap gamma " + Quote(output) + " " + Quote(a)), 2, "--tonemap", output, "clamp, aces");
    }
}

TEST_CASE("merge reads and writes OpenEXR: two runs as .exr merge to the image the same runs as .pfm merge to, bit for bit; "
          "a bad .exr is refused in one line", "[cli][merge]") {
    TemporaryFolder folder;
    // One thread and the same seed: a run's .exr and .pfm hold the same floats.
    const std::string a = RenderRun(folder, "a.exr", 2, 1), b = RenderRun(folder, "b.exr", 3, 2);
    const std::string pa = RenderRun(folder, "a.pfm", 2, 1), pb = RenderRun(folder, "b.pfm", 3, 2);
    const std::string merged = folder / "merged.exr", mergedPfm = folder / "merged.pfm";
    const Run run = RunProgram(MergeCommand(merged, {a, b}));
    INFO(run);
    REQUIRE(run.mExitCode == 0);
    CHECK(StartsWith(run.mStdout, "merged 2 runs of pt: 5 iterations, mean "));
    REQUIRE(RunProgram(MergeCommand(mergedPfm, {pa, pb})).mExitCode == 0);
    const smallvcm::Image fromExr = smallvcm::ReadExr(merged), fromPfm = smallvcm::ReadPfm(mergedPfm);
    REQUIRE(fromExr.mPixels.size() == fromPfm.mPixels.size());
    CHECK(std::memcmp(fromExr.mPixels.data(), fromPfm.mPixels.data(), fromExr.mPixels.size() * sizeof(smallvcm::Vec3)) == 0);
    const Json s = ReadJson(merged + ".json");
    CHECK(s["iterations"] == 5);
    CHECK(s["image"] == "merged.exr");
    CHECK(s["image_fnv1a64"] == Fnv1a64(ReadFileBytes(merged)));
    CHECK(s["mean"] == ReadJson(mergedPfm + ".json")["mean"]);
    // Formats mix: an .exr and a .pfm run merge too.
    const std::string mixed = folder / "mixed.exr";
    REQUIRE(RunProgram(MergeCommand(mixed, {a, pb})).mExitCode == 0);
    // A truncated .exr, with a sidecar that fingerprints the truncated bytes (so the image
    // itself is what is refused), and a file that is not an OpenEXR file at all.
    std::vector<unsigned char> bytes = ReadFileBytes(b);
    bytes.resize(bytes.size() / 2);
    const std::string cut = folder / "cut.exr";
    std::ofstream(cut, std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()), long(bytes.size()));
    Json sidecar = ReadJson(b + ".json");
    sidecar["image_fnv1a64"] = Fnv1a64(bytes);
    std::ofstream(cut + ".json") << sidecar.dump(2);
    const std::string output = folder / "out.exr";
    CheckMergeFailure(RunProgram(MergeCommand(output, {a, cut})), 1, cut, output, "its OpenEXR pixel data is truncated or corrupt");
    const std::string foreign = folder / "foreign.exr";
    fs::copy_file(pa, foreign);
    fs::copy_file(pa + ".json", foreign + ".json");
    CheckMergeFailure(RunProgram(MergeCommand(output, {a, foreign})), 1, foreign, output, "not an OpenEXR file");
}

TEST_CASE("A merge of runs of 4, 12, 24 and 88 iterations agrees with one run of 128 within the per-pixel noise; "
          "an unweighted average does not", "[cli][merge]") {
    // Path tracing of the diffuse box (diffuse walls, an area light: light-tailed noise, so
    // 128-iteration averages are close to normal) at 32x32. Each pixel's per-iteration
    // variance s^2 is measured from 1000 independent one-iteration renders (in this
    // process, the same estimator as the program's). Merged and single run each average
    // 128 independent iterations, so their difference has variance 2 s^2 / 128 and
    // z = difference / sqrt(2 s^2 / 128) has E[z^2] = 1 at every pixel. The statistic is
    // the mean of z^2 over the pixels, T, with its standard error measured from the spread
    // of the z^2 themselves, SE = sd(z^2) / sqrt(pixels). T must lie within 4 SE of 1, plus
    // 0.03 for the noise of s^2 itself (1000 samples: E[1/s^2] exceeds 1/sigma^2 by about
    // 2/1000 for normal values, more for heavier tails; measured T is printed). An
    // unweighted average of the four runs has variance s^2 (1/4 + 1/12 + 1/24 + 1/88) / 16
    // instead of s^2 / 128: E[T] = 2.05, which must fail the same bound. The runs use
    // --sampler independent: with Sobol points N iterations do not have variance s^2 / N.
    TemporaryFolder folder;
    const int width = 32, height = 32;
    const std::vector<int> iterations = {4, 12, 24, 88};
    const std::string scenePath = "../scenes/diffuse_box.gltf";
    std::vector<std::string> runs;
    for (size_t k = 0; k < iterations.size(); k++) {
        const std::string path = folder / ("run" + std::to_string(k) + ".pfm");
        const Run run = RunProgram("-s " + scenePath + " -a pt -r 32x32 -q --sampler independent -i " + std::to_string(iterations[k]) +
                                   " --seed " + std::to_string(100 + k) + " -o " + Quote(path));
        REQUIRE(run.mExitCode == 0);
        runs.push_back(path);
    }
    const std::string merged = folder / "merged.pfm", single = folder / "single.pfm";
    REQUIRE(RunProgram(MergeCommand(merged, runs)).mExitCode == 0);
    REQUIRE(RunProgram("-s " + scenePath + " -a pt -r 32x32 -q --sampler independent -i 128 --seed 200 -o " + Quote(single)).mExitCode == 0);

    smallvcm::Scene scene = smallvcm::LoadGltfScene(scenePath);
    scene.mCamera.SetResolution(width, height);
    const int samples = 1000;
    std::vector<double> sum(size_t(width * height), 0.0), sumSquares(size_t(width * height), 0.0);
    for (int r = 0; r < samples; r++) {
        const smallvcm::Image image = testutil::RenderWith(scene, smallvcm::Algorithm::kPathTracing, 1, uint64_t(1000 + r)).mImage;
        for (size_t i = 0; i < sum.size(); i++) {
            const smallvcm::Vec3& p = image.mPixels[i];
            const double value = (double(p.x) + double(p.y) + double(p.z)) / 3.0;
            sum[i] += value;
            sumSquares[i] += value * value;
        }
    }
    auto channelMean = [](const smallvcm::Vec3& aPixel) { return (double(aPixel.x) + double(aPixel.y) + double(aPixel.z)) / 3.0; };
    const smallvcm::Image mergedImage = smallvcm::ReadPfm(merged), singleImage = smallvcm::ReadPfm(single);
    std::vector<smallvcm::Image> runImages;
    for (const std::string& run : runs) runImages.push_back(smallvcm::ReadPfm(run));
    struct Statistic { double mMeanZ2 = 0.0, mStandardError = 0.0, mMaxAbsZ = 0.0; int mPixels = 0; };
    auto statistic = [&](const std::function<double(size_t)>& aCombined) {
        std::vector<double> z2;
        Statistic result;
        for (size_t i = 0; i < sum.size(); i++) {
            const double variance = (sumSquares[i] - sum[i] * sum[i] / samples) / (samples - 1);
            if (variance <= 0.0) continue;  // a pixel that sees nothing varying (none here: checked below)
            const double z = (aCombined(i) - channelMean(singleImage.mPixels[i])) / std::sqrt(2.0 * variance / 128.0);
            z2.push_back(z * z);
            result.mMaxAbsZ = std::max(result.mMaxAbsZ, std::abs(z));
        }
        result.mPixels = int(z2.size());
        double total = 0.0, totalSquares = 0.0;
        for (double v : z2) total += v, totalSquares += v * v;
        result.mMeanZ2 = total / double(z2.size());
        result.mStandardError = std::sqrt((totalSquares / double(z2.size()) - result.mMeanZ2 * result.mMeanZ2) / double(z2.size()));
        return result;
    };
    const Statistic weighted = statistic([&](size_t i) { return channelMean(mergedImage.mPixels[i]); });
    const Statistic unweighted = statistic([&](size_t i) {
        double average = 0.0;
        for (const smallvcm::Image& image : runImages) average += channelMean(image.mPixels[i]) / double(runImages.size());
        return average;
    });
    auto within = [](const Statistic& aStatistic) { return std::abs(aStatistic.mMeanZ2 - 1.0) <= 4.0 * aStatistic.mStandardError + 0.03; };
    WARN("weighted merge: mean z^2 " << weighted.mMeanZ2 << " +- " << weighted.mStandardError << ", max |z| " << weighted.mMaxAbsZ
                                     << " over " << weighted.mPixels << " pixels; unweighted average: mean z^2 " << unweighted.mMeanZ2
                                     << " +- " << unweighted.mStandardError << ", max |z| " << unweighted.mMaxAbsZ);
    CHECK(weighted.mPixels == width * height);
    CHECK(within(weighted));
    CHECK_FALSE(within(unweighted));
}

TEST_CASE("--layers writes only layers that received a contribution, each with a sidecar, and an index", "[cli][sidecar]") {
    // Path tracing of the point-light scene: a point light is never seen directly, nor in
    // a mirror, so the "emitted" and specular layers stay black; the direct and indirect
    // non-specular ones do not.
    TemporaryFolder folder;
    const std::string output = folder / "pt.pfm";
    const Run run = RunProgram("-s 2 -a pt -i 2 -r 16x12 -j 1 -q --layers -o " + Quote(output));
    INFO(run);
    REQUIRE(run.mExitCode == 0);
    const Json index = ReadJson(folder / "pt.layers.json");
    INFO(index.dump(2));
    CHECK(index["image"] == "pt.pfm");
    std::vector<std::string> expected = {"pt.layers.json", "pt.pfm", "pt.pfm.json"};
    for (const Json& layer : index["layers"]) {
        const std::string file = layer["file"];
        expected.push_back(file);
        expected.push_back(file + ".json");
        const smallvcm::Image image = smallvcm::ReadPfm(folder / file);
        CHECK(smallvcm::MeanValue(image) > 0.0);
        CHECK(layer["mean"].get<double>() == Approx(smallvcm::MeanValue(image)).epsilon(1e-12));
        const Json sidecar = ReadJson(folder / (file + ".json"));
        CHECK(sidecar["estimator"]["layer"] == layer["layer"]);
        CHECK(sidecar["image"] == file);
    }
    CHECK(index["layers"].size() == 2);
    CHECK(index["layers_without_contribution"] == Json::array({"emitted", "direct_specular", "indirect_specular"}));
    std::sort(expected.begin(), expected.end());
    CHECK(FolderEntries(folder) == expected);
}

TEST_CASE("--layers with an .exr writes one multi-layer file, channels LAYER.R, LAYER.G, LAYER.B, and an index naming them",
          "[cli][sidecar]") {
    TemporaryFolder folder;
    // The same render as separate .pfm files first, to compare with; the .exr run's index
    // then replaces theirs (both are pt.layers.json).
    const std::string pfm = folder / "pt.pfm";
    REQUIRE(RunProgram("-s 2 -a pt -i 2 -r 16x12 -j 1 -q --layers -o " + Quote(pfm)).mExitCode == 0);
    const std::string output = folder / "pt.exr";
    const Run run = RunProgram("-s 2 -a pt -i 2 -r 16x12 -j 1 --layers -o " + Quote(output));
    INFO(run);
    REQUIRE(run.mExitCode == 0);
    CHECK(run.mStdout.find("-> " + output + " (+ 2 layers, listed in " + folder / "pt.layers.json" + ")") != std::string::npos);
    const Json exrIndex = ReadJson(folder / "pt.layers.json");
    INFO(exrIndex.dump(2));
    CHECK(exrIndex["image"] == "pt.exr");
    REQUIRE(exrIndex["layers"].size() == 2);
    CHECK(exrIndex["layers_without_contribution"] == Json::array({"emitted", "direct_specular", "indirect_specular"}));
    CHECK(smallvcm::ReadExr(output).mPixels == smallvcm::ReadPfm(pfm).mPixels);
    for (const Json& layer : exrIndex["layers"]) {
        const std::string name = layer["layer"];
        CHECK(layer["file"] == "pt.exr");
        CHECK(layer["channels"] == Json::array({name + ".R", name + ".G", name + ".B"}));
        const smallvcm::Image image = smallvcm::ReadExr(output, name);
        CHECK(image.mPixels == smallvcm::ReadPfm(folder / ("pt." + name + ".pfm")).mPixels);
        CHECK(layer["mean"].get<double>() == Approx(smallvcm::MeanValue(image)).epsilon(1e-12));
    }
    // The one sidecar describes the image (R, G, B); no file per layer was written.
    const Json sidecar = ReadJson(output + ".json");
    CHECK(sidecar["estimator"]["layer"] == nullptr);
    CHECK(sidecar["image_fnv1a64"] == Fnv1a64(ReadFileBytes(output)));
    for (const std::string& entry : FolderEntries(folder)) CHECK(entry.find("pt.direct_nonspecular.exr") == std::string::npos);
}

TEST_CASE("The sidecar of a linked-in integrator names it and records every setting it might read", "[cli][sidecar]") {
    TemporaryFolder folder;
    const std::string output = folder / "mine.pfm";
    const Run run = RunProgram("-s 2 -a mypt -i 1 -r 8x8 -j 1 -q -o " + Quote(output));
    INFO(run);
    REQUIRE(run.mExitCode == 0);
    const Json e = ReadJson(output + ".json")["estimator"];
    CHECK(e["algorithm"] == "mypt");
    for (const char* key : {"max_path_length", "mis", "radius_factor", "radius_alpha", "photons", "knn", "max_radius"}) CHECK(e.contains(key));
}

// -------------------------------------------------------------------------------------
// Command-line rough edges
// -------------------------------------------------------------------------------------

TEST_CASE("The summary line says 1 iteration, 2 iterations, and counts the layers written", "[cli]") {
    TemporaryFolder folder;
    const std::string output = folder / "out.pfm";
    const Run one = RunProgram("-s 2 -a pt -i 1 -r 8x8 -j 1 -o " + Quote(output));
    INFO(one);
    CHECK(one.mStdout.find(", 1 iteration in ") != std::string::npos);
    CHECK(one.mStdout.find("iterations") == std::string::npos);
    const Run two = RunProgram("-s 2 -a pt -i 2 -r 8x8 -j 1 --layers -o " + Quote(output));
    INFO(two);
    CHECK(two.mStdout.find(", 2 iterations in ") != std::string::npos);
    CHECK(two.mStdout.find("-> " + output + " (+ 2 layers, listed in " + folder / "out.layers.json" + ")") != std::string::npos);
}

TEST_CASE("-i with -t stops at whichever limit comes first", "[cli]") {
    // Render's rule (the render loop): a thread takes no new iteration once the iteration
    // budget is used up or the time is up. So -i 3 -t 100 ends after 3 iterations, long
    // before 100 s, and -i 1e8 -t 0.5 ends when the time is up, long before 1e8
    // iterations. The 60-second limit only catches a program that ignores one of them;
    // no speed is asserted.
    TemporaryFolder folder;
    const std::string first = folder / "iterations_first.pfm";
    const Run fewIterations = RunProgram("-s 2 -a pt -r 8x8 -j 2 -q -i 3 -t 100 -o " + Quote(first), 60);
    INFO(fewIterations);
    REQUIRE(fewIterations.mExitCode == 0);
    const Json a = ReadJson(first + ".json");
    CHECK(a["iterations"] == 3);
    CHECK(a["seconds"].get<double>() < 100.0);
    CHECK(a["run"]["seconds_budget"] == 100.0);
    const std::string second = folder / "time_first.pfm";
    const Run shortTime = RunProgram("-s 2 -a pt -r 8x8 -j 2 -q -i 100000000 -t 0.5 -o " + Quote(second), 60);
    INFO(shortTime);
    REQUIRE(shortTime.mExitCode == 0);
    const Json b = ReadJson(second + ".json");
    CHECK(b["iterations"].get<int64_t>() >= 1);
    CHECK(b["iterations"].get<int64_t>() < 100000000);
    CHECK(b["seconds"].get<double>() >= 0.5);
    CHECK(b["run"]["stopped_early"] == false);  // the budget ended it, not a signal
}

TEST_CASE("The gallery's real model (the Khronos Avocado, no camera, no light) renders with every default, and the summary line splits the loading time", "[cli]") {
    // What `make model-image` runs, at 16x16 and one iteration.
    TemporaryFolder folder;
    const std::string output = folder / "avocado.png";
    const Run run = RunProgram("-s ../scenes/avocado/Avocado.gltf -i 1 -r 16x16 -j 1 -o " + Quote(output));
    INFO(run.mCommand << "\n" << run.mStdout << run.mStderr);
    REQUIRE(run.mExitCode == 0);
    CHECK(fs::exists(output));
    CHECK(fs::exists(output + ".json"));
    CHECK(run.mStdout.find("682 triangles and 0 spheres loaded in ") != std::string::npos);
    CHECK(run.mStdout.find(" (reading ") != std::string::npos);
    CHECK(run.mStdout.find(", BVH build and checks ") != std::string::npos);
    CHECK(run.mStdout.find("a default camera (the file has none)") != std::string::npos);
    CHECK(run.mStderr.find("the scene has no light: added the default sky and sun (a sun from above, behind and left of the "
                           "camera; --envmap FILE, --background R,G,B or --background none replace them)") != std::string::npos);
}

// -------------------------------------------------------------------------------------
// --envmap, --envmap-rotate, --envmap-scale
// -------------------------------------------------------------------------------------

namespace {

// One triangle, no light, no camera (the file of the --background test above): lit by the
// map alone, which the default camera also sees around the triangle.
std::string WriteUnlitTriangle(const TemporaryFolder& aFolder) {
    const std::string scene = aFolder / "unlit.gltf";
    std::ofstream(scene) << R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}],
      "bufferViews": [{"buffer": 0, "byteLength": 36}],
      "buffers": [{"byteLength": 36, "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}]})";
    return scene;
}

// A 16 x 8 map whose four quadrants (left/right half, upper/lower half) differ in colour,
// times aBrightness, written by the library's own writer (the format from the extension).
std::string WriteQuadrantMap(const TemporaryFolder& aFolder, const std::string& aName, float aBrightness = 1.f) {
    smallvcm::Image map(16, 8);
    const smallvcm::Vec3 colours[4] = {{1.f, 0.2f, 0.1f}, {0.1f, 1.f, 0.2f}, {0.2f, 0.1f, 1.f}, {0.8f, 0.8f, 0.2f}};
    for (int y = 0; y < 8; y++)
        for (int x = 0; x < 16; x++) map.mPixels[size_t(y * 16 + x)] = aBrightness * colours[(x < 8 ? 0 : 1) + (y < 4 ? 0 : 2)];
    const std::string path = aFolder / aName;
    smallvcm::WriteImage(path, map);
    return path;
}

// A PFM written byte by byte: aWidth x aHeight, with aPixels (3 floats each, possibly fewer
// than the header claims).
std::string WriteRawPfm(const TemporaryFolder& aFolder, const std::string& aName, int aWidth, int aHeight, const std::vector<float>& aPixels) {
    const std::string path = aFolder / aName;
    std::ofstream file(path, std::ios::binary);
    file << "PF\n" << aWidth << " " << aHeight << "\n-1\n";
    file.write(reinterpret_cast<const char*>(aPixels.data()), std::streamsize(aPixels.size() * sizeof(float)));
    return path;
}

// A path-traced run of the unlit triangle under a map (aExtra: --envmap and its settings).
Run RenderUnderMap(const std::string& aScene, const std::string& aOutput, const std::string& aExtra) {
    return RunProgram("-a pt -i 2 -r 16x8 -j 1 -q --seed 5 -o " + Quote(aOutput) + " " + Quote(aScene) + " " + aExtra);
}

} // namespace

TEST_CASE("--envmap lights a file with a map in each format and the sidecar records which map, turned and scaled how", "[cli][sidecar][envmap]") {
    TemporaryFolder folder;
    const std::string scene = WriteUnlitTriangle(folder);
    for (const char* format : {"pfm", "exr", "hdr"}) {
        const std::string map = WriteQuadrantMap(folder, std::string("map.") + format);
        const std::string output = folder / (std::string("out_") + format + ".pfm");
        const Run run = RenderUnderMap(scene, output, "--envmap " + Quote(map) + " --envmap-rotate 30 --envmap-scale 1.5");
        INFO(run);
        REQUIRE(run.mExitCode == 0);
        CHECK(run.mStderr.empty());  // no note: the map replaces the default sky and sun
        const Json s = ReadJson(output + ".json");
        INFO(s.dump(2));
        CHECK(s["envmap"] == map);
        const Json& environment = s["estimator"]["background"]["envmap"];
        CHECK(environment["fnv1a64"] == Fnv1a64(ReadFileBytes(map)));
        CHECK(environment["rotate_degrees"].get<double>() == 30.0);
        CHECK(environment["scale"].get<double>() == 1.5);
        CHECK(smallvcm::MeanValue(smallvcm::ReadPfm(output)) > 0.0);
    }
    // Without the rotation and scale options, their defaults are recorded.
    const std::string output = folder / "plain.pfm";
    REQUIRE(RenderUnderMap(scene, output, "--envmap " + Quote(folder / "map.pfm")).mExitCode == 0);
    const Json environment = ReadJson(output + ".json")["estimator"]["background"]["envmap"];
    CHECK(environment["rotate_degrees"].get<double>() == 0.0);
    CHECK(environment["scale"].get<double>() == 1.0);
    // The help text names the three options.
    const Run help = RunProgram("--help");
    CHECK(help.mExitCode == 0);
    CHECK_THAT(help.mStdout, Catch::Contains("--envmap FILE") && Catch::Contains("--envmap-rotate DEG") &&
                             Catch::Contains("--envmap-scale S"));
}

TEST_CASE("--envmap-rotate turns the environment: another image, and a whole turn the same one bit for bit", "[cli][envmap]") {
    TemporaryFolder folder;
    const std::string scene = WriteUnlitTriangle(folder);
    const std::string map = WriteQuadrantMap(folder, "map.pfm");
    std::map<std::string, std::vector<unsigned char>> images;
    for (const char* rotation : {"0", "90", "360", "-360"}) {
        const std::string output = folder / (std::string("rotated_") + rotation + ".pfm");
        const Run run = RenderUnderMap(scene, output, "--envmap " + Quote(map) + " --envmap-rotate " + rotation);
        INFO(run);
        REQUIRE(run.mExitCode == 0);
        images[rotation] = ReadFileBytes(output);
    }
    CHECK(images["90"] != images["0"]);
    CHECK(images["360"] == images["0"]);
    CHECK(images["-360"] == images["0"]);
}

TEST_CASE("--envmap-scale 2 doubles every pixel of a path-traced run of the same seed", "[cli][envmap]") {
    // The map is the only light, and pt's paths, pdfs and MIS weights do not depend on the
    // light's brightness: the same random numbers give twice the radiance, and doubling a
    // float is exact (only the film's sums in a different order could round otherwise).
    TemporaryFolder folder;
    const std::string scene = WriteUnlitTriangle(folder);
    const std::string map = WriteQuadrantMap(folder, "map.exr");
    const std::string one = folder / "one.pfm", two = folder / "two.pfm";
    REQUIRE(RenderUnderMap(scene, one, "--envmap " + Quote(map)).mExitCode == 0);
    REQUIRE(RenderUnderMap(scene, two, "--envmap " + Quote(map) + " --envmap-scale 2").mExitCode == 0);
    const smallvcm::Image a = smallvcm::ReadPfm(one), b = smallvcm::ReadPfm(two);
    REQUIRE(a.mPixels.size() == b.mPixels.size());
    double worst = 0.0;
    int nonzero = 0;
    for (size_t i = 0; i < a.mPixels.size(); i++)
        for (int k = 0; k < 3; k++) {
            const double expected = 2.0 * double(a.mPixels[i][k]);
            nonzero += expected > 0.0 ? 1 : 0;
            worst = std::max(worst, std::abs(double(b.mPixels[i][k]) - expected) / std::max(expected, 1e-30));
        }
    INFO("worst relative difference " << worst);
    CHECK(nonzero == int(a.mPixels.size()) * 3);
    CHECK(worst < 1e-6);
}

TEST_CASE("Bad --envmap option combinations and values exit with code 2 and one line naming the option", "[cli][envmap]") {
    TemporaryFolder folder;
    const std::string scene = WriteUnlitTriangle(folder);
    const std::string map = WriteQuadrantMap(folder, "map.pfm");
    const std::string withMap = Quote(scene) + " --envmap " + Quote(map) + " ";
    const std::vector<BadCommandLine> cases = {
        {withMap + "--background 1,1,1", 2, "--envmap"},
        {withMap + "--background none", 2, "--envmap"},
        {Quote(scene) + " --background 0.5,0.5,0.5 --envmap " + Quote(map), 2, "--envmap"},
        {Quote(scene) + " --envmap-rotate 30", 2, "--envmap-rotate"},
        {Quote(scene) + " --envmap-scale 2", 2, "--envmap-scale"},
        {withMap + "--envmap-scale nan", 2, "--envmap-scale"},
        {withMap + "--envmap-scale 0", 2, "--envmap-scale"},
        {withMap + "--envmap-scale -0", 2, "--envmap-scale"},
        {withMap + "--envmap-scale -1", 2, "--envmap-scale"},
        {withMap + "--envmap-scale inf", 2, "--envmap-scale"},
        {withMap + "--envmap-scale", 2, "--envmap-scale"},
        {withMap + "--envmap-rotate nan", 2, "--envmap-rotate"},
        {withMap + "--envmap-rotate 1e9", 2, "--envmap-rotate"},
        {withMap + "--envmap-rotate -inf", 2, "--envmap-rotate"},
        {withMap + "--envmap-rotate 90deg", 2, "--envmap-rotate"},
        {Quote(scene) + " --envmap ''", 2, "--envmap"},
    };
    int index = 0;
    for (const BadCommandLine& c : cases) {
        const std::string output = folder / ("out" + std::to_string(index++) + ".png");
        const Run run = RunProgram(Tiny(output) + " " + c.mArguments);
        CheckFailure(run, c.mExitCode, c.mNamed, output);
    }
    const Run both = RunProgram(Tiny(folder / "both.png") + " " + withMap + "--background 1,1,1");
    CHECK(both.mStderr == "smallvcm: --envmap: --background replaces the background too: give one of them\n");
    const Run alone = RunProgram(Tiny(folder / "alone.png") + " " + Quote(scene) + " --envmap-scale 2");
    CHECK(alone.mStderr == "smallvcm: --envmap-scale: applies to an environment map: give --envmap FILE too\n");
    const Run zero = RunProgram(Tiny(folder / "zero.png") + " " + withMap + "--envmap-scale -0");
    CHECK(zero.mStderr == "smallvcm: --envmap-scale: '-0' is not a number in (0, 1e30]\n");
}

TEST_CASE("A missing, truncated, not 2:1, NaN-texel or oversized map exits with code 1, one line naming it, and no image", "[cli][envmap]") {
    TemporaryFolder folder;
    const std::string scene = WriteUnlitTriangle(folder);
    const float nan = std::numeric_limits<float>::quiet_NaN();
    std::vector<float> withNan(8 * 4 * 3, 1.f);
    withNan[3 * 9 + 1] = nan;
    std::string truncated = WriteQuadrantMap(folder, "truncated.exr");
    fs::resize_file(truncated, fs::file_size(truncated) / 2);
    const struct {
        std::string mMap, mProblem;
    } cases[] = {
        {folder / "missing.hdr", "cannot open"},
        {WriteRawPfm(folder, "truncated.pfm", 8, 4, std::vector<float>(48, 1.f)), "truncated"},
        {truncated, ""},
        {WriteRawPfm(folder, "three_by_two.pfm", 3, 2, std::vector<float>(18, 1.f)), "twice as wide as high; this one is 3x2"},
        // PFM stores the bottom row first: the file's second row is the map's third from the top.
        {WriteRawPfm(folder, "nan.pfm", 8, 4, withNan), "texel (1, 2) is negative or not finite"},
        {WriteRawPfm(folder, "huge.pfm", 16384, 8192, {}), "16384x8192 pixels, more than the 33554432"},
        {WriteQuadrantMap(folder, "black.pfm", 0.f), "the environment map is black"},
        {WriteQuadrantMap(folder, "map.png"), "a PNG holds exposed"},
    };
    int index = 0;
    for (const auto& c : cases) {
        const std::string output = folder / ("out" + std::to_string(index++) + ".pfm");
        const Run run = RenderUnderMap(scene, output, "--envmap " + Quote(c.mMap));
        INFO(run);
        CHECK(run.mSignal == 0);
        CHECK(run.mExitCode == 1);
        CHECK(LineCount(run.mStderr) == 1);
        CHECK(StartsWith(run.mStderr, "smallvcm: environment map " + c.mMap + ": "));
        CHECK(run.mStderr.find(c.mProblem) != std::string::npos);
        CHECK_FALSE(fs::exists(output));
        CHECK_FALSE(fs::exists(output + ".partial"));
        CHECK_FALSE(fs::exists(output + ".json"));
    }
}

TEST_CASE("merge combines seeded runs under the same map and refuses runs under different maps", "[cli][merge][envmap]") {
    TemporaryFolder folder;
    const std::string scene = WriteUnlitTriangle(folder);
    const std::string map = WriteQuadrantMap(folder, "map.pfm"), brighter = WriteQuadrantMap(folder, "brighter.pfm", 2.f);
    auto render = [&](const std::string& aName, int aSeed, const std::string& aExtra) {
        const std::string path = folder / aName;
        const Run run = RunProgram("-a pt -i 2 -r 16x8 -j 1 -q --seed " + std::to_string(aSeed) + " -o " + Quote(path) + " " +
                                   Quote(scene) + " " + aExtra);
        INFO(run);
        REQUIRE(run.mExitCode == 0);
        return path;
    };
    const std::string a = render("a.pfm", 1, "--envmap " + Quote(map)), b = render("b.pfm", 2, "--envmap " + Quote(map));
    const std::string merged = folder / "merged.pfm";
    const Run run = RunProgram(MergeCommand(merged, {a, b}));
    INFO(run);
    REQUIRE(run.mExitCode == 0);
    CHECK(ReadJson(merged + ".json")["estimator"] == ReadJson(a + ".json")["estimator"]);
    // Another map (other bytes), the same map turned or scaled otherwise, or the default sky: refused.
    const std::string output = folder / "refused.pfm";
    const std::string others[] = {render("c.pfm", 3, "--envmap " + Quote(brighter)),
                                  render("d.pfm", 4, "--envmap " + Quote(map) + " --envmap-rotate 10"),
                                  render("e.pfm", 5, "--envmap " + Quote(map) + " --envmap-scale 3"),
                                  render("f.pfm", 6, "")};
    for (const std::string& other : others)
        CheckMergeFailure(RunProgram(MergeCommand(output, {a, other})), 1, other, output, "its background");
}
