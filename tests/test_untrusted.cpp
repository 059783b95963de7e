// [untrusted] A scene file is a document from anyone (docs/testing.md, "Threat model"):
// the loader reads only regular files, opened without blocking, sizes checked before a
// byte is read; a URI reads only files inside the scene's folder (after ".." and
// symlinks), and its refusal reads the same whether an outside file exists or not; user
// text in a message is a short excerpt; a .glb must be version 2. Every hostile file
// (FIFOs, symlinks, sparse files) is made here, in a temporary folder.
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>

namespace {

namespace fs = std::filesystem;
using namespace smallvcm;
using testutil::TemporaryFolder;

// Two triangles of a floor (y = 0, facing +y), as 6 float32 VEC3: 72 bytes.
std::string FloorBytes() {
    const float floor[18] = {-1, 0, -1, -1, 0, 1, 1, 0, 1, -1, 0, -1, 1, 0, 1, 1, 0, -1};
    return std::string(reinterpret_cast<const char*>(floor), sizeof(floor));
}

// A valid scene (camera, floor, point light) whose one buffer is aUri, declared
// aByteLength long. aExtra is spliced into the top-level object (e.g. a second buffer).
std::string SceneJson(const std::string& aUri, uint64_t aByteLength = 72, const std::string& aExtraBuffer = "") {
    return R"({"asset": {"version": "2.0"}, "extensionsUsed": ["KHR_lights_punctual"],
  "extensions": {"KHR_lights_punctual": {"lights": [{"type": "point", "intensity": 10}]}},
  "scene": 0, "scenes": [{"nodes": [0, 1, 2]}],
  "nodes": [{"mesh": 0}, {"camera": 0, "translation": [0, 1, 5]},
            {"extensions": {"KHR_lights_punctual": {"light": 0}}, "translation": [0, 2, 0]}],
  "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.1}}],
  "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
  "accessors": [{"bufferView": 0, "componentType": 5126, "count": 6, "type": "VEC3",
                 "min": [-1, 0, -1], "max": [1, 0, 1]}],
  "bufferViews": [{"buffer": 0, "byteLength": 72}],
  "buffers": [{"byteLength": )" + std::to_string(aByteLength) + R"(, "uri": ")" + aUri + "\"}" + aExtraBuffer + "]}";
}

void WriteFile(const std::string& aPath, const std::string& aBytes) {
    std::ofstream(aPath, std::ios::binary) << aBytes;
}

// The Error message of loading aPath ("" if it loads).
std::string LoadProblem(const std::string& aPath, const GltfLoadOptions& aOptions = {}) {
    try {
        LoadGltfScene(aPath, nullptr, aOptions);
        return "";
    } catch (const Error& e) {
        return e.what();
    }
}

// A folder "scene" holding scene.gltf, with a sibling file outside.bin (72 valid bytes).
struct SceneFolder {
    TemporaryFolder mTop;
    std::string mFolder = mTop / "scene";
    std::string mScene = mFolder + "/scene.gltf";
    std::string mOutside = mTop / "outside.bin";
    SceneFolder() {
        fs::create_directories(mFolder);
        WriteFile(mOutside, FloorBytes());
    }
    std::string WithUri(const std::string& aUri, uint64_t aByteLength = 72) {
        WriteFile(mScene, SceneJson(aUri, aByteLength));
        return LoadProblem(mScene);
    }
};

const char* const kNotInside = "no readable file of that name inside the scene's folder";

} // namespace

TEST_CASE("A buffer file inside the scene's folder loads, also through a symlink that stays inside", "[untrusted]") {
    SceneFolder folder;
    WriteFile(folder.mFolder + "/floor.bin", FloorBytes());
    CHECK(folder.WithUri("floor.bin") == "");
    fs::create_directories(folder.mFolder + "/data");
    fs::create_symlink("../floor.bin", folder.mFolder + "/data/link.bin");
    CHECK(folder.WithUri("data/link.bin") == "");
    CHECK(folder.WithUri("data/../floor.bin") == "");
}

TEST_CASE("URIs that leave the scene's folder are refused, with the same words whether the file exists or not", "[untrusted]") {
    SceneFolder folder;
    fs::create_symlink(folder.mOutside, folder.mFolder + "/escape.bin");
    fs::create_symlink(folder.mTop.mPath, folder.mFolder + "/up");
    for (const std::string& uri : {std::string("../outside.bin"), std::string("../no_such_file.bin"), folder.mOutside,
                                  std::string("escape.bin"), std::string("up/outside.bin"), std::string("../scene/../outside.bin"),
                                  std::string("%2e%2e/outside.bin"), std::string("..%2Foutside.bin"), std::string("/etc/passwd")}) {
        INFO("uri " << uri);
        const std::string problem = folder.WithUri(uri);
        // The message names the scene, the URI and the rule, and says nothing of the
        // outside file: not its size, not whether it exists, not what went wrong opening it.
        const std::string decoded = uri.find('%') != std::string::npos ? "../outside.bin" : uri;  // %-escapes decoded
        CHECK(problem == folder.mScene + ": buffer URI '" + decoded + "': " + kNotInside);
    }
}

TEST_CASE("GltfLoadOptions::mResourceRoot allows another folder", "[untrusted]") {
    SceneFolder folder;
    WriteFile(folder.mScene, SceneJson("../outside.bin"));
    GltfLoadOptions options;
    options.mResourceRoot = folder.mTop.mPath;
    CHECK(LoadProblem(folder.mScene, options) == "");
    options.mResourceRoot = folder.mTop / "no_such_folder";
    CHECK_THAT(LoadProblem(folder.mScene, options), Catch::Contains("the resource folder") && Catch::Contains("does not exist"));
}

TEST_CASE("Scene and buffer paths that are not regular files are refused without blocking", "[untrusted]") {
    SceneFolder folder;
    // A FIFO with no writer: a blocking open would wait forever.
    REQUIRE(mkfifo((folder.mFolder + "/pipe.bin").c_str(), 0600) == 0);
    CHECK(folder.WithUri("pipe.bin") == folder.mScene + ": buffer URI 'pipe.bin': is not a regular file (a FIFO, socket or device is never read)");
    fs::create_directories(folder.mFolder + "/folder.bin");
    CHECK(folder.WithUri("folder.bin") == folder.mScene + ": buffer URI 'folder.bin': is a directory, not a file");
    // The scene file itself.
    const std::string pipe = folder.mFolder + "/pipe.gltf";
    REQUIRE(mkfifo(pipe.c_str(), 0600) == 0);
    CHECK(LoadProblem(pipe) == pipe + ": is not a regular file (a FIFO, socket or device is never read)");
    CHECK(LoadProblem("/dev/zero") == "/dev/zero: is not a regular file (a FIFO, socket or device is never read)");
    CHECK(LoadProblem(folder.mFolder) == folder.mFolder + ": is a directory, not a file");
}

TEST_CASE("File sizes are checked against byteLength and the limits before a byte is read", "[untrusted]") {
    SceneFolder folder;
    SECTION("a 4 GiB buffer file (sparse: nothing is on disk) whose buffer declares 72 bytes") {
        const std::string big = folder.mFolder + "/big.bin";
        WriteFile(big, "");
        REQUIRE(truncate(big.c_str(), off_t(4) << 30) == 0);
        CHECK(folder.WithUri("big.bin") == folder.mScene + ": buffer URI 'big.bin': its size, 4096.0 MiB, is no buffer's byteLength (not read)");
    }
    SECTION("a buffer file as long as it says, but over the per-file limit") {
        WriteFile(folder.mFolder + "/floor.bin", FloorBytes());
        WriteFile(folder.mScene, SceneJson("floor.bin"));
        GltfLoadOptions options;
        options.mMaxFileBytes = 71;
        CHECK_THAT(LoadProblem(folder.mScene, options), Catch::StartsWith(folder.mScene + ": the file is") &&
                                                            Catch::Contains("more than the loader's limit of 71 bytes per file"));
        options.mMaxFileBytes = uint64_t(1) << 20;
        options.mMaxTotalBytes = fs::file_size(folder.mScene) + 71;  // the scene file fits, the buffer does not
        CHECK(LoadProblem(folder.mScene, options) ==
              folder.mScene + ": buffer URI 'floor.bin': the scene's files together exceed the loader's limit of " +
                  std::to_string(options.mMaxTotalBytes) + " bytes (GltfLoadOptions::mMaxTotalBytes)");
        options.mMaxTotalBytes += 1;
        CHECK(LoadProblem(folder.mScene, options) == "");
    }
    SECTION("the same file named by many buffers counts once per read against the total") {
        WriteFile(folder.mFolder + "/floor.bin", FloorBytes());
        std::string more;
        for (int b = 0; b < 50; b++) more += R"(, {"byteLength": 72, "uri": "floor.bin"})";
        WriteFile(folder.mScene, SceneJson("floor.bin", 72, more));
        GltfLoadOptions options;
        options.mMaxTotalBytes = fs::file_size(folder.mScene) + 72 * 10;
        CHECK_THAT(LoadProblem(folder.mScene, options), Catch::Contains("the scene's files together exceed"));
    }
    SECTION("a data URI longer than its byteLength is refused before it is decoded, and not echoed") {
        const std::string payload(80000, 'A');  // 60,000 decoded bytes
        WriteFile(folder.mScene, SceneJson("data:application/octet-stream;base64," + payload));
        const std::string problem = LoadProblem(folder.mScene);
        CHECK(problem == folder.mScene + ": buffer 0: its data URI holds about 60000 bytes, more than its byteLength of 72 bytes (not decoded)");
        CHECK(problem.size() < 300);
    }
    SECTION("the scene file over the limit") {
        WriteFile(folder.mScene, SceneJson("floor.bin"));
        GltfLoadOptions options;
        options.mMaxFileBytes = 100;
        CHECK_THAT(LoadProblem(folder.mScene, options), Catch::StartsWith(folder.mScene + ": the file is") &&
                                                            Catch::Contains("more than the loader's limit of 100 bytes per file"));
    }
}

TEST_CASE("User text in messages is a short excerpt", "[untrusted]") {
    SceneFolder folder;
    SECTION("a parser message quoting a 60 KB data URI") {
        // Invalid base64 of the right length: tinygltf fails to decode it and quotes the URI.
        const std::string payload(96, '!');
        WriteFile(folder.mScene, SceneJson("data:application/octet-stream;base64," + payload + std::string(60000, ' ')));
        const std::string problem = LoadProblem(folder.mScene);
        CHECK(problem != "");
        CHECK(problem.size() < 400);
    }
    SECTION("a 10,000-character light type and node name") {
        std::string json = SceneJson("floor.bin");
        const std::string longName(10000, 'x');
        json.replace(json.find("\"point\""), 7, "\"" + longName + "\"");
        WriteFile(folder.mFolder + "/floor.bin", FloorBytes());
        WriteFile(folder.mScene, json);
        const std::string problem = LoadProblem(folder.mScene);
        CHECK_THAT(problem, Catch::Contains("light type 'xxxxxxxx") && Catch::Contains("(10000 characters)"));
        CHECK(problem.size() < 300);
    }
}

TEST_CASE("A binary glTF of a version other than 2 is refused by name", "[untrusted]") {
    TemporaryFolder folder;
    for (uint32_t version : {0u, 1u, 3u}) {
        std::string bytes = "glTF";
        const uint32_t header[2] = {version, 20};
        bytes.append(reinterpret_cast<const char*>(header), 8);
        const uint32_t chunk[2] = {2, 0x4E4F534Au};  // an (empty) JSON chunk
        bytes.append(reinterpret_cast<const char*>(chunk), 8);
        bytes += "{}";
        const std::string path = folder / ("v" + std::to_string(version) + ".glb");
        WriteFile(path, bytes);
        CHECK(LoadProblem(path) == path + ": a binary glTF (.glb) of version " + std::to_string(version) +
                                       " is not supported (glTF 2.0 binaries have version 2)");
    }
}
