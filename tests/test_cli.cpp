// [cli] The command-line renderer build/smallvcm, run as a child process: bad options
// exit with code 2, a bad scene or output file with code 1, each with exactly one line
// "smallvcm: <option or file>: <problem>" on stderr, and a failed run leaves no output
// file (nor a .partial). One tiny good run writes a PFM of the requested size. Every
// rejected file of the glTF corpus (tests/data/bad) and the hostile files
// (tests/data/hostile, which crash or hang the loader in-process) run through it too.
// Tests run from tests/, so the program is ../build/smallvcm.
#include "gltf_corpus.hpp"
#include "smallvcm.hpp"
#include "examples/my_path_tracer.hpp"

#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
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
        {"--min-path-length 5 --max-path-length 3", 2, "--min-path-length"},
        {"--frobnicate", 2, "--frobnicate"},
        {"-i", 2, "-i"},  // missing value
        {"-s 9", 2, "-s"},
    };
    int index = 0;
    for (const BadCommandLine& c : cases) {
        const std::string output = folder / ("out" + std::to_string(index++) + ".png");  // one per run
        const Run run = RunProgram(Tiny(output) + " " + c.mArguments);
        CheckFailure(run, c.mExitCode, c.mNamed, output);
    }
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
    const Run run = RunProgram(Tiny(output) + " -s data/bad/degenerate_repeated_index.gltf");
    INFO(run);
    CHECK(run.mExitCode == 0);
    CHECK(LineCount(run.mStderr) == 1);
    CHECK(StartsWith(run.mStderr, "smallvcm: data/bad/degenerate_repeated_index.gltf: note: skipped 1 degenerate"));
    CHECK(fs::exists(output));
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

TEST_CASE("--help lists every built-in and the linked-in integrators with their descriptions", "[cli][integrator_api]") {
    const Run run = RunProgram("--help");
    INFO(run);
    REQUIRE(run.mExitCode == 0);
    std::vector<smallvcm::Integrator> expected;
    smallvcm::Algorithm algorithm = smallvcm::Algorithm::kEyeLight;
    for (const smallvcm::Integrator* registered : smallvcm::RegisteredIntegrators())
        if (smallvcm::ParseAlgorithm(registered->mName, algorithm)) expected.push_back(*registered);  // the built-ins
    expected.push_back(MyPathTracerIntegrator());  // linked in by the Makefile's default INTEGRATORS
    for (const smallvcm::Integrator& integrator : expected) {
        INFO(integrator.mName);
        CHECK(run.mStdout.find(" " + integrator.mName + " ") != std::string::npos);
        CHECK(run.mStdout.find(integrator.mDescription + "\n") != std::string::npos);
    }
    const Run unknown = RunProgram("-a nosuch -q");
    CHECK(unknown.mExitCode == 2);
    CHECK(unknown.mStderr == "smallvcm: -a: unknown algorithm 'nosuch' (el, pt, lt, pm, pmfg, ppm, bpm, bpt, vcm, mypt)\n");
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
    const smallvcm::Image expected = smallvcm::Render(scene, options, MyPathTracerIntegrator()).mImage;
    const smallvcm::Image image = smallvcm::ReadPfm(output);
    REQUIRE(image.mPixels.size() == expected.mPixels.size());
    CHECK(image.mPixels == expected.mPixels);
    CHECK(smallvcm::MeanValue(image) > 0.0);
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
