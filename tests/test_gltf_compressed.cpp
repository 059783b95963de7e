// [gltf][compressed] Scene loading of compressed geometry: one model (the Avocado's
// geometry with generated textures, tests/data/compressed, written by
// make_compressed.py there) plain, quantized (KHR_mesh_quantization), meshopt-compressed
// by gltf-transform and by gltfpack (EXT_meshopt_compression with its octahedral and
// exponential filters) and Draco-compressed (KHR_draco_mesh_compression) loads to the
// same triangles, within the quantization steps, and renders the same image within
// noise; damaged compressed bytes are refused with an Error naming the file. Tests run
// from tests/.
#include "test_util.hpp"

#include <catch2/catch.hpp>
#include <meshoptimizer.h>

#include <cstring>
#include <fstream>
#include <iterator>

namespace {

using namespace smallvcm;

const char* const kCompressed[] = {"data/compressed/avocado_quantized.glb", "data/compressed/avocado_meshopt.glb",
                                   "data/compressed/avocado_gltfpack.glb", "data/compressed/avocado_draco.glb"};
const char* const kPlain = "data/compressed/avocado_plain.glb";

// The largest distance between corresponding corners of two triangles, the second's
// corners taken in the cyclic order (aRotation) that a compressor may have started at.
float CornerDistance(const Triangle& aA, const Triangle& aB, int aRotation) {
    const Vec3 a[3] = {aA.mP0, aA.mP1, aA.mP2}, b[3] = {aB.mP0, aB.mP1, aB.mP2};
    float largest = 0.f;
    for (int c = 0; c < 3; c++) largest = std::max(largest, glm::length(a[c] - b[(c + aRotation) % 3]));
    return largest;
}

}  // namespace

TEST_CASE("A model quantized, meshopt-compressed or Draco-compressed loads to the triangles of its plain file", "[gltf][compressed]") {
    const Scene plain = LoadGltfScene(kPlain);
    REQUIRE(plain.mTriangles.size() == 682);
    // The model is 0.063 high; the compressors keep positions to 14 bits of its extent (a
    // step of 4e-6), gltfpack's exponential filter to 14 bits of each coordinate. 2^-12
    // of the box's diagonal holds both with room; normals (8 to 10 bits) and texture
    // coordinates (12 bits) are compared at steps a little coarser than theirs.
    Vec3 lowest(std::numeric_limits<float>::max()), highest(-std::numeric_limits<float>::max());
    for (const Triangle& t : plain.mTriangles)
        for (const Vec3& p : {t.mP0, t.mP1, t.mP2}) {
            lowest = glm::min(lowest, p);
            highest = glm::max(highest, p);
        }
    const float positionTolerance = glm::length(highest - lowest) / 4096.f;
    for (const char* path : kCompressed) {
        INFO(path);
        GltfLoadReport report;
        const Scene scene = LoadGltfScene(path, &report);
        REQUIRE(scene.mTriangles.size() == plain.mTriangles.size());
        // Compressors reorder triangles and vertices: each triangle is matched to the plain
        // file's nearest one (brute force: 682 x 682).
        float worstPosition = 0.f, worstNormal = 0.f, worstUv = 0.f;
        for (const Triangle& t : scene.mTriangles) {
            float best = std::numeric_limits<float>::max();
            const Triangle* match = nullptr;
            int rotation = 0;
            for (const Triangle& u : plain.mTriangles)
                for (int r = 0; r < 3; r++) {
                    const float d = CornerDistance(u, t, r);
                    if (d < best) { best = d; match = &u; rotation = r; }
                }
            worstPosition = std::max(worstPosition, best);
            REQUIRE(t.mHasVertexNormals == match->mHasVertexNormals);
            REQUIRE(t.mHasTangents == match->mHasTangents);
            const Vec3 n[3] = {match->mN0, match->mN1, match->mN2}, m[3] = {t.mN0, t.mN1, t.mN2};
            // Texture coordinates as the texture reads them: gltfpack stores them quantized
            // and dequantizes them by a KHR_texture_transform on the textures.
            const UvTransform& plainUv = plain.mTextures[size_t(plain.GetMaterial(match->mMaterialId).mBaseColorTexture)].mUvTransform;
            const UvTransform& ownUv = scene.mTextures[size_t(scene.GetMaterial(t.mMaterialId).mBaseColorTexture)].mUvTransform;
            const Vec2 uv[3] = {plainUv.Apply(match->mUv0), plainUv.Apply(match->mUv1), plainUv.Apply(match->mUv2)};
            const Vec2 tuv[3] = {ownUv.Apply(t.mUv0), ownUv.Apply(t.mUv1), ownUv.Apply(t.mUv2)};
            for (int c = 0; c < 3; c++) {
                worstNormal = std::max(worstNormal, glm::length(n[c] - m[(c + rotation) % 3]));
                worstUv = std::max(worstUv, glm::length(uv[c] - tuv[(c + rotation) % 3]));
            }
        }
        CHECK(worstPosition <= positionTolerance);
        CHECK(worstNormal <= 0.02f);
        CHECK(worstUv <= 1.f / 1024.f);
        // The compression extensions are read, not noted as ignored.
        for (const std::string& note : report.mNotes) CHECK(note.find("ignored extensions") == std::string::npos);
    }
}

TEST_CASE("A model quantized, meshopt-compressed or Draco-compressed renders the image of its plain file within noise", "[gltf][compressed]") {
    // 4 x 4 regions of a 32 x 32 path-traced image (default camera, sky and sun), each
    // region's mean over 8 independent batches of 8 iterations. The tolerance comes from
    // the measured noise: the difference of two independent means has the standard error
    // sqrt(se_a^2 + se_b^2), each se from the spread of its batch means (MeanOf); 5 of
    // them give a false alarm about once in 10^6 per region (64 regions here), while a
    // misread attribute (a wrong sign, scale or filter) moves whole regions by far more.
    const int kSize = 32, kRegions = 16, kBatches = 8, kIterations = 8;
    std::vector<int> regionOfPixel(size_t(kSize * kSize));
    for (int y = 0; y < kSize; y++)
        for (int x = 0; x < kSize; x++) regionOfPixel[size_t(y * kSize + x)] = (y / 8) * 4 + x / 8;
    const auto regionMeans = [&](const char* aPath, uint64_t aSeed) {
        Scene scene = LoadGltfScene(aPath);
        scene.mCamera.SetResolution(kSize, kSize);
        return testutil::RegionBatchMeans(scene, Algorithm::kPathTracing, kBatches, kIterations, aSeed, regionOfPixel, kRegions);
    };
    const auto plain = regionMeans(kPlain, 100);
    uint64_t seed = 200;
    for (const char* path : kCompressed) {
        INFO(path);
        const auto other = regionMeans(path, seed += 100);
        for (int r = 0; r <= kRegions; r++) {
            const testutil::MeanAndError a = testutil::MeanOf(plain[size_t(r)]), b = testutil::MeanOf(other[size_t(r)]);
            INFO("region " << r << ": " << a.mean << " +- " << a.standardError << " against " << b.mean << " +- " << b.standardError);
            CHECK(std::abs(a.mean - b.mean) <= 5.0 * std::sqrt(a.standardError * a.standardError + b.standardError * b.standardError) + 1e-6);
        }
    }
}

TEST_CASE("Damaged compressed geometry is refused with an Error naming the file, however it is damaged", "[gltf][compressed]") {
    // Bit flips, truncations and lying counts of the compressed files: each either loads
    // (a flip in a texture byte, in padding, or in a value that stays plausible) or throws
    // smallvcm::Error naming the file -- never anything else (under make check's
    // sanitizers: never a memory error either). The mutations are fixed (a seeded Rng).
    testutil::TemporaryFolder folder;
    Rng rng(46);
    for (const char* source : kCompressed) {
        std::ifstream in(source, std::ios::binary);
        const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        REQUIRE(bytes.size() > 1000);
        uint32_t jsonLength;
        std::memcpy(&jsonLength, bytes.data() + 12, 4);
        const size_t binStart = 20 + size_t(jsonLength) + 8;  // the BIN chunk's data
        int refused = 0;
        for (int trial = 0; trial < 60; trial++) {
            std::string damaged = bytes;
            const int kind = trial % 3;
            if (kind == 0) {  // flip 1 to 8 bits of the binary chunk
                const int flips = 1 + int(rng.GetFloat() * 8.f);
                for (int f = 0; f < flips; f++) {
                    const size_t at = binStart + size_t(rng.GetFloat() * float(bytes.size() - binStart - 1));
                    damaged[at] = char(damaged[at] ^ (1 << int(rng.GetFloat() * 8.f)));
                }
            } else if (kind == 1) {  // overwrite a run of the binary chunk with noise
                const size_t at = binStart + size_t(rng.GetFloat() * float(bytes.size() - binStart - 64));
                for (size_t i = 0; i < 32; i++) damaged[at + i] = char(rng.GetFloat() * 256.f);
            } else {  // a count in the JSON that lies (the first "count": N made N * k or N / k)
                std::vector<size_t> counts;
                for (size_t at = bytes.find("\"count\":", 20); at < 20 + jsonLength; at = bytes.find("\"count\":", at + 1))
                    counts.push_back(at);
                REQUIRE(!counts.empty());
                const size_t at = counts[size_t(rng.GetFloat() * float(counts.size()))];
                const size_t begin = at + 8, end = bytes.find_first_not_of("0123456789", begin);
                const uint64_t count = std::stoull(bytes.substr(begin, end - begin));
                const uint64_t lie = trial % 2 ? count * 7 + 1 : count / 3;
                damaged.replace(begin, end - begin, std::to_string(lie));
                // The JSON chunk's length changes with the digits: pad it with spaces.
                const size_t grown = std::to_string(lie).size() - (end - begin);
                std::string text = damaged.substr(20, jsonLength + grown);
                while (text.size() % 4 != 0) text += ' ';
                const uint32_t newLength = uint32_t(text.size());
                damaged = damaged.substr(0, 20) + text + bytes.substr(20 + jsonLength);
                std::memcpy(&damaged[12], &newLength, 4);
                const uint32_t total = uint32_t(damaged.size());
                std::memcpy(&damaged[8], &total, 4);
            }
            const std::string path = (folder.mPath / "damaged.glb").string();
            std::ofstream(path, std::ios::binary) << damaged;
            try {
                LoadGltfScene(path);
            } catch (const Error& error) {
                CHECK_THAT(error.what(), Catch::StartsWith(path + ": "));
                refused++;
            }
        }
        INFO(source << ": " << refused << " of 60 damaged copies refused");
        CHECK(refused > 0);
    }
}

TEST_CASE("Meshopt index sequences (mode INDICES) decode to the indices they encode", "[gltf][compressed]") {
    // A square of two triangles whose indices are an EXT_meshopt_compression view of mode
    // INDICES (gltfpack and gltf-transform write TRIANGLES for triangle lists): written as a
    // .glb here, with meshoptimizer's own encoder.
    const float positions[12] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
    const uint32_t indices[6] = {0, 1, 2, 0, 2, 3};
    std::vector<unsigned char> encoded(meshopt_encodeIndexSequenceBound(6, 4));
    encoded.resize(meshopt_encodeIndexSequence(encoded.data(), encoded.size(), indices, 6));
    std::string binary(reinterpret_cast<const char*>(positions), sizeof(positions));
    const size_t compressedAt = binary.size();
    binary.append(encoded.begin(), encoded.end());
    while (binary.size() % 4 != 0) binary += '\0';
    std::string json = R"({"asset": {"version": "2.0"}, "extensionsUsed": ["EXT_meshopt_compression"],
        "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
                      {"bufferView": 1, "componentType": 5125, "count": 6, "type": "SCALAR"}],
        "bufferViews": [{"buffer": 0, "byteLength": 48},
                        {"buffer": 1, "byteLength": 24, "extensions": {"EXT_meshopt_compression": {"buffer": 0, "byteOffset": )" +
                       std::to_string(compressedAt) + R"(, "byteLength": )" + std::to_string(encoded.size()) +
                       R"(, "byteStride": 4, "count": 6, "mode": "INDICES"}}}],
        "buffers": [{"byteLength": )" + std::to_string(binary.size()) + R"(},
                    {"byteLength": 24, "extensions": {"EXT_meshopt_compression": {"fallback": true}}}]})";
    while (json.size() % 4 != 0) json += ' ';
    const auto u32 = [](uint32_t aValue) { return std::string(reinterpret_cast<const char*>(&aValue), 4); };
    const std::string glb = "glTF" + u32(2) + u32(uint32_t(12 + 8 + json.size() + 8 + binary.size())) + u32(uint32_t(json.size())) +
                            "JSON" + json + u32(uint32_t(binary.size())) + std::string("BIN\0", 4) + binary;
    testutil::TemporaryFolder folder;
    const std::string path = (folder.mPath / "indices.glb").string();
    std::ofstream(path, std::ios::binary) << glb;
    const Scene scene = LoadGltfScene(path);
    REQUIRE(scene.mTriangles.size() == 2);
    CHECK(scene.mTriangles[0].mP2 == Vec3(1.f, 1.f, 0.f));
    CHECK(scene.mTriangles[1].mP1 == Vec3(1.f, 1.f, 0.f));
    CHECK(scene.mTriangles[1].mP2 == Vec3(0.f, 1.f, 0.f));
}
