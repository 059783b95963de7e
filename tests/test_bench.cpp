// [bench] The benchmark program build/bench (benchmarks/bench.cpp) and its chart script
// benchmarks/plot_bench.py, run as child processes on a small configuration: scene 4, pt and pm,
// 1 and 2 threads, at --quick's 64x64, the BVH scaling up to 10^4 triangles, the loading of a 10^4-triangle glTF file
// and the environment light's cost (scene 3, pt and vcm, its background against the HDRI). About
// 5-10 s. Benchmarks report and never fail on time, so nothing here checks a speed; what
// is checked is that the reports are complete and well formed, that the CSVs hold exactly
// the rows measured, that the charts are drawn from them, and that a bad output path is
// refused before any measuring, with nothing left behind.
// Tests run from tests/, so the programs are ../build/bench and ../benchmarks/plot_bench.py.
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;

using testutil::ExitCode;
using testutil::Quote;
using testutil::ReadText;
using testutil::SplitCsvLine;
using testutil::TemporaryFolder;

// The lines of a CSV file: the header, then one vector of fields per row.
std::vector<std::vector<std::string>> ReadCsv(const std::string& aPath) {
    std::vector<std::vector<std::string>> rows;
    std::stringstream text(ReadText(aPath));
    std::string line;
    while (std::getline(text, line))
        if (!line.empty()) rows.push_back(SplitCsvLine(line));
    return rows;
}

double Number(const std::string& aField) {
    char* end = nullptr;
    const double value = std::strtod(aField.c_str(), &end);
    return end != aField.c_str() && *end == '\0' ? value : std::nan("");
}

} // namespace

TEST_CASE("The benchmark writes its report and CSVs, and the chart script draws them", "[bench]") {
    TemporaryFolder folder;
    const std::string command = "../build/bench --quick --scenes 4 --algorithms pt,pm --threads 1,2 --markdown " +
                                Quote(folder / "bench.md") + " --csv " + Quote(folder / "bench") + " > " +
                                Quote(folder / "stdout.txt") + " 2> " + Quote(folder / "stderr.txt");
    REQUIRE(ExitCode(std::system(command.c_str())) == 0);
    const std::string report = ReadText(folder / "bench.md");
    CHECK(report.find("Seconds per iteration, 1 thread") != std::string::npos);
    CHECK(report.find("BVH scaling") != std::string::npos);
    // The glTF loading part: --quick's 10^4-triangle file, loaded whole.
    CHECK(report.find("### Loading a large glTF file") != std::string::npos);
    CHECK(report.find("\n| 10000 | ") != std::string::npos);
    // The environment light's cost: scene 3 with its constant background and with the
    // checked-in HDRI, pt and vcm, both measured.
    CHECK(report.find("### The environment light's cost") != std::string::npos);
    CHECK(report.find("hdri/royal_esplanade_1k.hdr") != std::string::npos);
    CHECK(report.find("\n| pt | ") != std::string::npos);
    CHECK(report.find("\n| vcm | ") != std::string::npos);
    CHECK(report.find("failed") == std::string::npos);

    // Render rows: exactly the four configurations measured, every number positive.
    const auto render = ReadCsv(folder / "bench_render.csv");
    REQUIRE(render.size() == 5);
    CHECK(render[0] == SplitCsvLine("scene,scene_name,algorithm,threads,iterations,s_per_iteration,cpu_s_per_iteration,"
                                    "rays_per_s,cpu_utilisation,peak_rss_mib,resolution"));
    const std::vector<std::pair<std::string, std::string>> expected = {{"pt", "1"}, {"pt", "2"}, {"pm", "1"}, {"pm", "2"}};
    for (size_t i = 0; i < expected.size(); i++) {
        const std::vector<std::string>& row = render[i + 1];
        INFO("render row " << i + 1);
        REQUIRE(row.size() == render[0].size());
        CHECK(row[0] == "4");
        CHECK(row[1] == "cornell_4_default");
        CHECK(row[2] == expected[i].first);
        CHECK(row[3] == expected[i].second);
        CHECK(row[10] == "64x64");
        for (size_t c : {4u, 5u, 6u, 7u, 9u}) CHECK(Number(row[c]) > 0.0);
    }

    // BVH rows: 10^2, 10^3, 10^4 triangles (--quick), rates positive, the tree deepening.
    const auto bvh = ReadCsv(folder / "bench_bvh.csv");
    REQUIRE(bvh.size() == 4);
    double previousDepth = 0.0;
    for (size_t i = 1; i < bvh.size(); i++) {
        INFO("bvh row " << i);
        REQUIRE(bvh[i].size() == bvh[0].size());
        CHECK(Number(bvh[i][0]) == std::pow(10.0, double(i + 1)));
        for (size_t c : {1u, 4u, 6u, 7u, 8u}) CHECK(Number(bvh[i][c]) > 0.0);
        CHECK(Number(bvh[i][5]) > previousDepth);
        previousDepth = Number(bvh[i][5]);
    }
    for (const auto& entry : fs::directory_iterator(folder.mPath))
        CHECK(entry.path().extension() != ".partial");

    // The charts, drawn from those CSVs (matplotlib: make test installs it).
    const std::string plot = "/usr/bin/python3 ../benchmarks/plot_bench.py " + Quote(folder / "bench_bvh.csv") + " " +
                             Quote(folder / "bench_render.csv") + " --out-dir " + Quote(folder.mPath.string()) +
                             " > " + Quote(folder / "plot.txt") + " 2>&1";
    REQUIRE(ExitCode(std::system(plot.c_str())) == 0);
    for (const char* chart : {"bvh_scaling.png", "speed_per_iteration.png"}) {
        INFO(chart);
        CHECK(ReadText(folder / chart).rfind("\x89PNG", 0) == 0);
    }
}

TEST_CASE("The benchmark refuses an output it cannot write before measuring, and the chart script a bad CSV", "[bench]") {
    TemporaryFolder folder;
    for (const std::string& option : {std::string("--csv ") + Quote(folder / "missing/bench"),
                                      std::string("--markdown ") + Quote(folder / "missing/bench.md")}) {
        INFO(option);
        const std::string command = "../build/bench --quick " + option + " > /dev/null 2> " + Quote(folder / "err.txt");
        CHECK(ExitCode(std::system(command.c_str())) == 2);
        CHECK(ReadText(folder / "err.txt").find("missing/bench") != std::string::npos);  // names the file
        CHECK_FALSE(fs::exists(folder.mPath / "missing"));
    }
    std::ofstream(folder / "bad.csv") << "triangles,something\n1,2\n";
    const std::string plot = "/usr/bin/python3 ../benchmarks/plot_bench.py " + Quote(folder / "bad.csv") + " --out-dir " +
                             Quote(folder.mPath.string()) + " > /dev/null 2> " + Quote(folder / "err.txt");
    CHECK(ExitCode(std::system(plot.c_str())) == 1);
    CHECK(ReadText(folder / "err.txt").find("bad.csv") != std::string::npos);
}
