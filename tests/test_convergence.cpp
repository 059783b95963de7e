// [convergence] The convergence tool build/convergence (benchmarks/convergence.cpp), run as a
// child process in its --quick form: 16x16 pixels, the five Cornell scenes, all eight
// estimators, checkpoints 1, 2, 4, ..., 128 iterations, references rendered on the fly
// (BPT, or VCM where BPT cannot converge) into a temporary folder. About 5-10 s.
//
// What it checks:
//   * exit code 0, the CSV header, exactly one row per (scene, estimator, checkpoint), in
//     order, with finite positive errors and non-decreasing seconds; the references and
//     their settings files exist, and the reference estimator follows the tool's rule;
//   * every consistent estimator ends with a lower RMSE than it started with: ppm, bpm,
//     vcm on every scene; pt and bpt only where they converge to the reference (scenes
//     1, 3, 4 -- with the sun or the point light they miss the caustics seen in the
//     mirror, or all caustics for pt). lt (misses everything seen through a mirror or
//     glass) and pm/pmfg (a fixed photon count per iteration: iterations average their
//     noise, never their bias) have no limit equal to the reference and are not checked;
//   * unbiased estimators fall like 1/sqrt(N): the least-squares slope of log RMSE
//     against log iterations over all eight checkpoints, for pt and bpt on scenes 1, 3, 4.
//
// The margins come from the noise of such a fit, measured by running the same quick
// configuration with 40 different seeds (same references): the slopes of these six
// (scene, estimator) pairs average -0.49 with a standard deviation per pair of 0.017
// (scene 3) to 0.085 (bpt on scene 4; the worst value seen was -0.30); the mean of the
// six slopes of one run averages -0.489 with a standard deviation of 0.028. So each
// slope must be below -0.20 (at least 3.4 standard deviations from its mean) and their
// mean below -0.35 (5 standard deviations): a run fails by chance about once in a
// thousand, while an estimator whose error does not fall (slope ~0) or a wrong reference
// (the curve flattens onto its bias) fails clearly. The last/first RMSE ratio of the
// consistent estimators was at most 0.78 in those 40 runs (bpm on the sun scene, whose
// error at 16x16 is dominated by rare bright paths); the check is ratio < 1.
// Tests run from tests/, so the program is ../build/convergence (built by `make all`).
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;

const char* const kProgram = "../build/convergence";
const std::vector<std::string> kEstimators = {"pt", "lt", "ppm", "bpm", "bpt", "vcm", "pm", "pmfg"};
const std::vector<int> kCheckpoints = {1, 2, 4, 8, 16, 32, 64, 128};  // --quick's

using testutil::ExitCode;
using testutil::Quote;
using testutil::SplitCsvLine;
using testutil::ReadText;
using testutil::TemporaryFolder;

struct Row {
    int mScene = -1;
    std::string mAlgorithm;
    int mIterations = 0;
    double mSeconds = 0.0, mRmse = 0.0, mRelMse = 0.0;
};


// Least-squares slope of log(rmse) against log(iterations).
double LogLogSlope(const std::vector<Row>& aRows) {
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    const double n = double(aRows.size());
    for (const Row& row : aRows) {
        const double x = std::log(double(row.mIterations)), y = std::log(row.mRmse);
        sx += x; sy += y; sxx += x * x; sxy += x * y;
    }
    return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

std::string SettingsValue(const std::string& aText, const std::string& aKey) {
    std::stringstream stream(aText);
    std::string line;
    while (std::getline(stream, line))
        if (line.compare(0, aKey.size() + 3, aKey + " = ") == 0) return line.substr(aKey.size() + 3);
    return "";
}

} // namespace

TEST_CASE("convergence --quick: one row per checkpoint, errors that fall, unbiased slopes near -1/2", "[convergence]") {
    REQUIRE(fs::exists(kProgram));

    TemporaryFolder folder;
    const std::string csvPath = folder / "quick.csv";
    const std::string command = "ulimit -c 0; timeout 120 " + std::string(kProgram) + " --quick -q --out " + Quote(csvPath) +
                                " > " + Quote(folder / "stdout") + " 2> " + Quote(folder / "stderr");
    const int status = std::system(command.c_str());
    INFO(command << "\nstderr: " << ReadText(folder / "stderr"));
    REQUIRE(ExitCode(status) == 0);
    REQUIRE(fs::exists(csvPath));
    CHECK_FALSE(fs::exists(csvPath + ".partial"));

    // The settings file and the references with their settings.
    const std::string settings = ReadText(folder / "quick.txt");
    CHECK(SettingsValue(settings, "resolution") == "16x16");
    for (int scene = 0; scene < 5; scene++) {
        const std::string stem = folder / ("cornell_" + std::to_string(scene) + "_16x16");
        CHECK(fs::exists(stem + ".pfm"));
        const std::string referenceSettings = ReadText(stem + ".txt");
        INFO("scene " << scene << " reference settings:\n" << referenceSettings);
        // BPT where every light has an area; VCM with the sun (0) and the point light (2).
        CHECK(SettingsValue(referenceSettings, "algorithm") == (scene == 0 || scene == 2 ? "vcm" : "bpt"));
        CHECK_FALSE(SettingsValue(referenceSettings, "why").empty());
        CHECK(SettingsValue(settings, "reference." + std::to_string(scene) + ".algorithm") ==
              SettingsValue(referenceSettings, "algorithm"));
    }

    // The CSV: header and rows.
    std::ifstream csv(csvPath);
    std::string line;
    REQUIRE(std::getline(csv, line));
    CHECK(line == "scene,algorithm,iterations,seconds,rmse,relmse,rmse_diffuse");
    std::map<std::pair<int, std::string>, std::vector<Row>> runs;
    int rowCount = 0;
    while (std::getline(csv, line)) {
        const std::vector<std::string> fields = SplitCsvLine(line);
        INFO("row: " << line);
        REQUIRE(fields.size() == 7);
        Row row;
        row.mScene = std::stoi(fields[0]);
        row.mAlgorithm = fields[1];
        row.mIterations = std::stoi(fields[2]);
        row.mSeconds = std::stod(fields[3]);
        row.mRmse = std::stod(fields[4]);
        row.mRelMse = std::stod(fields[5]);
        const double rmseDiffuse = std::stod(fields[6]);
        CHECK(std::isfinite(row.mSeconds));
        CHECK(row.mSeconds >= 0.0);
        CHECK(std::isfinite(row.mRmse));
        CHECK(row.mRmse > 0.0);
        CHECK(std::isfinite(row.mRelMse));
        CHECK(row.mRelMse > 0.0);
        // Every Cornell scene shows Lambert walls: the diffuse region is never empty.
        CHECK(std::isfinite(rmseDiffuse));
        CHECK(rmseDiffuse > 0.0);
        runs[{row.mScene, row.mAlgorithm}].push_back(row);
        rowCount++;
    }
    CHECK(rowCount == 5 * int(kEstimators.size()) * int(kCheckpoints.size()));
    CHECK(runs.size() == 5 * kEstimators.size());
    for (int scene = 0; scene < 5; scene++)
        for (const std::string& algorithm : kEstimators) {
            INFO("scene " << scene << ", " << algorithm);
            const auto run = runs.find({scene, algorithm});
            REQUIRE(run != runs.end());
            const std::vector<Row>& rows = run->second;
            REQUIRE(rows.size() == kCheckpoints.size());
            for (size_t i = 0; i < rows.size(); i++) {
                CHECK(rows[i].mIterations == kCheckpoints[i]);
                if (i > 0) CHECK(rows[i].mSeconds >= rows[i - 1].mSeconds);
            }
        }

    // Consistent estimators: the error falls from the first checkpoint to the last.
    auto converges = [](int aScene, const std::string& aAlgorithm) {
        if (aAlgorithm == "ppm" || aAlgorithm == "bpm" || aAlgorithm == "vcm") return true;
        if (aAlgorithm == "pt" || aAlgorithm == "bpt") return aScene == 1 || aScene == 3 || aScene == 4;
        return false;  // lt, pm, pmfg
    };
    for (const auto& [key, rows] : runs) {
        if (!converges(key.first, key.second)) continue;
        INFO("scene " << key.first << ", " << key.second << ": RMSE " << rows.front().mRmse << " at 1 iteration, "
                      << rows.back().mRmse << " at " << rows.back().mIterations);
        CHECK(rows.back().mRmse < rows.front().mRmse);
    }

    // Unbiased estimators where the reference is their limit: slope of about -1/2.
    double slopeSum = 0.0;
    int slopeCount = 0;
    for (int scene : {1, 3, 4})
        for (const std::string algorithm : {"pt", "bpt"}) {
            const double slope = LogLogSlope(runs[{scene, algorithm}]);
            INFO("scene " << scene << ", " << algorithm << ": fitted slope " << slope);
            CHECK(slope < -0.20);
            slopeSum += slope;
            slopeCount++;
        }
    INFO("mean slope of pt and bpt on scenes 1, 3, 4: " << slopeSum / slopeCount);
    CHECK(slopeSum / slopeCount < -0.35);
}

TEST_CASE("convergence: bad options exit with code 2 and one line naming the option", "[convergence]") {
    REQUIRE(fs::exists(kProgram));
    TemporaryFolder folder;
    const std::vector<std::pair<std::string, std::string>> cases = {
        {"--scenes 7", "--scenes"}, {"--algorithms xyz", "--algorithms"}, {"--algorithms el", "--algorithms"},
        {"--resolution 0x4", "--resolution"}, {"--threads 2 --clock cpu", "--clock"},
        {"--max-iterations 0", "--max-iterations"}, {"--seed 5 --reference-seed 5", "--seed"},
        {"--frobnicate", "--frobnicate"}};
    for (const auto& [arguments, named] : cases) {
        const std::string out = folder / "out.csv";
        const std::string command = std::string(kProgram) + " -q --quick --out " + Quote(out) + " " + arguments + " 2> " +
                                    Quote(folder / "stderr");
        const int status = std::system(command.c_str());
        const std::string message = ReadText(folder / "stderr");
        INFO(command << "\nstderr: " << message);
        CHECK(ExitCode(status) == 2);
        const std::string prefix = "convergence: " + named + ": ";
        CHECK(message.compare(0, prefix.size(), prefix) == 0);
        CHECK(std::count(message.begin(), message.end(), '\n') == 1);
        CHECK_FALSE(fs::exists(out));
    }
}
