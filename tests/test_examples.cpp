// [examples] Examples that cannot rot: examples/minimal.cpp is the header's first-screen
// example character for character, and the program it builds (build/minimal, made by
// `make`) renders what it says. Tests run from tests/.
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <cstdlib>
#include <filesystem>
#include <sstream>

namespace {

// The lines of the header's comment block that follows "A minimal program", without the
// comment's "//      " indentation (a bare "//" is an empty line of the program).
std::string FirstScreenExample() {
    std::istringstream header(testutil::ReadText("../smallvcm.hpp"));
    std::string line, program;
    bool inside = false;
    while (std::getline(header, line)) {
        if (!inside) {
            inside = line.rfind("//  A minimal program", 0) == 0;
            if (inside) {  // the sentence may continue on the next comment lines
                while (std::getline(header, line) && line.rfind("//      ", 0) != 0) {}
            } else {
                continue;
            }
        }
        if (line.rfind("//      ", 0) == 0) program += line.substr(8) + "\n";
        else if (line == "//" && !program.empty()) program += "\n";
        else break;
    }
    while (program.size() >= 2 && program.compare(program.size() - 2, 2, "\n\n") == 0) program.pop_back();
    return program;
}

} // namespace

TEST_CASE("examples/minimal.cpp is the header's first-screen example, character for character", "[examples]") {
    const std::string example = FirstScreenExample();
    REQUIRE(example.find("int main()") != std::string::npos);
    CHECK(testutil::ReadText("../examples/minimal.cpp") == example);
}

TEST_CASE("The minimal program renders the default scene into vcm.png", "[examples]") {
    testutil::TemporaryFolder folder;
    std::filesystem::create_directory_symlink(std::filesystem::absolute("../scenes"), folder / "scenes");
    const std::string command = "cd " + testutil::Quote(folder.mPath.string()) + " && " +
                                testutil::Quote(std::filesystem::absolute("../build/minimal").string()) + " 2>&1";
    REQUIRE(testutil::ExitCode(std::system(command.c_str())) == 0);
    // A PNG of 256 x 256: the signature, then IHDR with the big-endian width and height.
    const std::string png = testutil::ReadText(folder / "vcm.png");
    REQUIRE(png.size() > 24);
    CHECK(png.compare(1, 3, "PNG") == 0);
    CHECK(png.compare(16, 8, std::string("\0\0\1\0\0\0\1\0", 8)) == 0);
}
