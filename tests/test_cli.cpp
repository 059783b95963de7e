// [cli] The command-line renderer build/smallvcm, run as a child process: bad options
// exit with code 2, a bad scene or output file with code 1, each with exactly one line
// "smallvcm: <option or file>: <problem>" on stderr, and a failed run leaves no output
// file (nor a .partial). One tiny good run writes a PFM of the requested size. Every
// rejected file of the glTF corpus (tests/data/bad) and the hostile files
// (tests/data/hostile, which crash or hang the loader in-process) run through it too.
// Tests run from tests/, so the program is ../build/smallvcm.
#include "gltf_corpus.hpp"
#include "smallvcm.hpp"

#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <sys/wait.h>
#include <unistd.h>

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
        CheckFailure(RunProgram(Tiny(output) + " -s data/bad/no_light.gltf"), 1, "data/bad/no_light.gltf", output);
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
    const Run run = RunProgram(Tiny(output) + " -s data/bad/camera_missing.gltf");
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
