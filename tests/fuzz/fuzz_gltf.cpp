// A libFuzzer target over the glTF loader and the scene it builds.
//
// Each input is written to a file in a temporary folder of this process (input.glb when
// the bytes start with the binary glTF magic "glTF", input.gltf otherwise) and loaded
// with LoadGltfScene. The contract under test (docs/scene_format.md, "errors"): every
// bad file is a smallvcm::Error whose message is one line starting with the path. A file
// that loads is rendered once by the eye light at 8x8 (one thread, one iteration), which
// walks the BVH, the camera and every visible normal of the scene that was built.
//
// Findings (the process aborts, libFuzzer saves the input):
//   * any sanitizer report (AddressSanitizer, UndefinedBehaviorSanitizer) or a crash;
//   * an exception other than smallvcm::Error escaping LoadGltfScene;
//   * an Error whose message does not start with "<path>: " or spans several lines;
//   * a loaded scene with a non-finite or degenerate camera, light, triangle or sphere,
//     or a material outside the documented ranges (CheckScene: it would render NaN or
//     nothing where the file has something);
//   * Render throwing for a scene the loader accepted (the loader should have said no);
//   * an eye-light pixel that is not finite or not in [0, 1] (a wrong picture);
//   * a hang (libFuzzer's -timeout) or an out-of-memory (-rss_limit_mb).
//
// Mutations: half of them are libFuzzer's own (bytes, the dictionary tests/fuzz/gltf.dict),
// the other half come from LLVMFuzzerCustomMutator below, which parses the input as JSON
// (the JSON chunk of a .glb) and changes its values: numbers to edge values (-5, 2^32,
// 1e300, 1e-300, 3.5e38, ...), arrays shorter or longer, keys removed or added, values
// replaced by other types, the floats of a base64 data URI to NaN/inf/huge; a .glb is
// then reassembled with correct (or, sometimes, wrong) chunk lengths. Byte mutations
// alone rarely turn a valid scene into a different valid one.
//
// Build and run: tests/fuzz/run_fuzzer.sh [SECONDS]. One translation unit: the header
// is included with SMALLVCM_IMPLEMENTATION here.
#define SMALLVCM_IMPLEMENTATION
#include "smallvcm.hpp"

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <iterator>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <unistd.h>

namespace {

[[noreturn]] void Finding(const std::string& aWhat) {
    std::fprintf(stderr, "\n==fuzz_gltf== FINDING: %s\n", aWhat.c_str());
    std::fflush(stderr);
    std::abort();
}

// A folder of this process, made once, so that relative buffer URIs of an input resolve
// inside it (where nothing else lives) and parallel workers never share a file.
const std::string& Folder() {
    static const std::string folder = [] {
        const char* base = std::getenv("TMPDIR");
        std::string pattern = std::string(base && *base ? base : "/tmp") + "/fuzz_gltf." + std::to_string(getpid()) + ".XXXXXX";
        if (!mkdtemp(&pattern[0])) {
            std::perror("fuzz_gltf: mkdtemp");
            std::exit(2);
        }
        return pattern;
    }();
    return folder;
}

// Removes the folder at a normal exit (a crash leaves it behind, with the input in it).
void RemoveFolder() {
    std::remove((Folder() + "/input.gltf").c_str());
    std::remove((Folder() + "/input.glb").c_str());
    rmdir(Folder().c_str());
}

bool WriteFile(const std::string& aPath, const uint8_t* aData, size_t aSize) {
    FILE* file = std::fopen(aPath.c_str(), "wb");
    if (!file) return false;
    const bool written = aSize == 0 || std::fwrite(aData, 1, aSize, file) == aSize;
    return std::fclose(file) == 0 && written;
}

void CheckErrorMessage(const std::string& aPath, const std::string& aMessage) {
    if (aMessage.compare(0, aPath.size() + 2, aPath + ": ") != 0)
        Finding("Error message does not start with the path: " + aMessage);
    if (aMessage.find('\n') != std::string::npos) Finding("Error message spans several lines: " + aMessage);
}

bool Finite(const smallvcm::Vec3& aV) { return std::isfinite(aV.x) && std::isfinite(aV.y) && std::isfinite(aV.z); }
bool Unit(const smallvcm::Vec3& aV) { return Finite(aV) && std::abs(glm::length(aV) - 1.f) < 1e-3f; }
bool NonNegative(const smallvcm::Vec3& aV) { return Finite(aV) && aV.x >= 0.f && aV.y >= 0.f && aV.z >= 0.f; }
bool Reflectance(const smallvcm::Vec3& aV) { return NonNegative(aV) && aV.x <= 1.f && aV.y <= 1.f && aV.z <= 1.f; }

// What a loaded scene must satisfy so that every estimator renders a finite picture of
// what the file says: the loader's checks (docs/scene_format.md) as seen from outside.
// A loaded scene that breaks one of these renders NaN, or nothing, where the file has
// something: a wrong picture.
void CheckScene(const smallvcm::Scene& aScene) {
    using namespace smallvcm;
    const Camera& camera = aScene.mCamera;
    if (!Finite(camera.Position())) Finding("the camera position is not finite");
    if (!Unit(camera.Forward()) || !Unit(camera.Right()) || !Unit(camera.Up()))
        Finding("the camera basis is not made of finite unit vectors");
    if (std::abs(glm::dot(camera.Forward(), camera.Right())) > 1e-3f || std::abs(glm::dot(camera.Forward(), camera.Up())) > 1e-3f ||
        std::abs(glm::dot(camera.Right(), camera.Up())) > 1e-3f)
        Finding("the camera basis is not orthogonal");
    if (!(camera.HorizontalFovDegrees() > 0.f && camera.HorizontalFovDegrees() < 180.f))
        Finding("the camera's horizontal field of view is " + std::to_string(camera.HorizontalFovDegrees()) + " degrees");
    if (!(camera.ImagePlaneDist() > 0.f) || !std::isfinite(camera.ImagePlaneDist())) Finding("the camera's image plane distance is not positive and finite");
    const SceneSphere& bounds = aScene.GetSceneSphere();
    if (!Finite(bounds.mCenter) || !(bounds.mRadius > 0.f) || !std::isfinite(bounds.mRadius)) Finding("the scene's bounding sphere is not finite");
    for (const Material& m : aScene.mMaterials) {
        if (!Reflectance(m.mDiffuseReflectance) || !Reflectance(m.mPhongReflectance) || !Reflectance(m.mMirrorReflectance) ||
            !Reflectance(m.mDiffuseReflectance + m.mPhongReflectance))
            Finding("material '" + m.mName + "' has a reflectance outside [0, 1]");
        if (!std::isfinite(m.mPhongExponent) || m.mPhongExponent < 0.f) Finding("material '" + m.mName + "' has a bad Phong exponent");
        if (!std::isfinite(m.mIor) || (m.mIor >= 0.f && m.mIor < 1e-3f)) Finding("material '" + m.mName + "' has a bad ior");
    }
    const int materials = int(aScene.mMaterials.size()), lights = int(aScene.mLights.size());
    for (const Triangle& t : aScene.mTriangles) {
        if (!Finite(t.mP0) || !Finite(t.mP1) || !Finite(t.mP2) || !Unit(t.mNormal)) Finding("a triangle is not finite or has no unit normal");
        if (t.mMaterialId < 0 || t.mMaterialId >= materials || t.mLightId < -1 || t.mLightId >= lights) Finding("a triangle has a bad material or light id");
    }
    for (const Sphere& s : aScene.mSpheres) {
        if (!Finite(s.mCenter) || !(s.mRadius > 0.f) || !std::isfinite(s.mRadius)) Finding("a sphere is not finite");
        if (s.mMaterialId < 0 || s.mMaterialId >= materials || s.mLightId < -1 || s.mLightId >= lights) Finding("a sphere has a bad material or light id");
    }
    if (lights == 0) Finding("a loaded scene without lights");
    for (const Light& l : aScene.mLights) {
        if (!NonNegative(l.mEmission)) Finding("a light's emission is negative or not finite");
        switch (l.mType) {
        case LightType::kPoint:
            if (!Finite(l.mPosition)) Finding("a point light's position is not finite");
            break;
        case LightType::kSpot:
            if (!Finite(l.mPosition) || !Unit(l.mDirection)) Finding("a spot light's position or axis is not finite");
            if (!(l.mSpotInnerConeAngle >= 0.f && l.mSpotInnerConeAngle < l.mSpotOuterConeAngle &&
                  l.mSpotOuterConeAngle <= 0.5f * kPi)) Finding("a spot light's cone angles are out of range");
            break;
        case LightType::kDirectional:
            if (!Unit(l.mDirection)) Finding("a directional light's direction is not a finite unit vector");
            break;
        case LightType::kArea:
        case LightType::kSphere:
            if (!(l.mArea > 0.f) || !std::isfinite(l.mArea)) Finding("an area or sphere light's area is not positive and finite");
            break;
        case LightType::kBackground:
            break;
        }
    }
}

void RenderOnce(smallvcm::Scene& aScene) {
    aScene.mCamera.SetResolution(8, 8);
    smallvcm::RenderOptions options;
    options.mAlgorithm = smallvcm::Algorithm::kEyeLight;
    options.mIterations = 1;
    options.mThreads = 1;
    options.mProgress = false;
    smallvcm::RenderResult result;
    try {
        result = smallvcm::Render(aScene, options);
    } catch (const std::exception& e) {
        Finding(std::string("Render threw for a scene the loader accepted: ") + e.what());
    }
    if (result.mImage.mWidth != 8 || result.mImage.mHeight != 8 || result.mImage.mPixels.size() != 64)
        Finding("the eye-light image is not 8x8");
    for (size_t i = 0; i < result.mImage.mPixels.size(); i++) {
        const smallvcm::Vec3& p = result.mImage.mPixels[i];
        for (int c = 0; c < 3; c++)
            if (!std::isfinite(p[c]) || p[c] < 0.f || p[c] > 1.001f)
                Finding("eye-light pixel " + std::to_string(i) + " channel " + std::to_string(c) + " is " +
                        std::to_string(p[c]) + " (expected a finite value in [0, 1])");
    }
}

} // namespace

// --- the structure-aware mutator ---------------------------------------------------------

namespace {

using Json = nlohmann::json;
using Random = std::mt19937;

size_t Pick(Random& aRandom, size_t aCount) { return aCount == 0 ? 0 : size_t(aRandom() % aCount); }

const char* const kBase64 = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

std::string EncodeBase64(const std::vector<uint8_t>& aBytes) {
    std::string text;
    for (size_t i = 0; i < aBytes.size(); i += 3) {
        uint32_t chunk = uint32_t(aBytes[i]) << 16;
        if (i + 1 < aBytes.size()) chunk |= uint32_t(aBytes[i + 1]) << 8;
        if (i + 2 < aBytes.size()) chunk |= aBytes[i + 2];
        text += kBase64[(chunk >> 18) & 63];
        text += kBase64[(chunk >> 12) & 63];
        text += i + 1 < aBytes.size() ? kBase64[(chunk >> 6) & 63] : '=';
        text += i + 2 < aBytes.size() ? kBase64[chunk & 63] : '=';
    }
    return text;
}

std::vector<uint8_t> DecodeBase64(const std::string& aText) {
    std::vector<uint8_t> bytes;
    uint32_t chunk = 0;
    int bits = 0;
    for (char c : aText) {
        const char* at = std::strchr(kBase64, c);
        if (c == '\0' || !at) continue;  // '=' and anything else
        chunk = (chunk << 6) | uint32_t(at - kBase64);
        bits += 6;
        if (bits >= 8) {
            bits -= 8;
            bytes.push_back(uint8_t((chunk >> bits) & 0xff));
        }
    }
    return bytes;
}

double EdgeNumber(Random& aRandom, double aOld) {
    static const double kValues[] = {0.0, -0.0, 1.0, -1.0, -2.0, -5.0, 2.0, 3.0, 4.0, 5.0, 16.0, 0.5, 1e-7, 3.1, 3.2,
                                     255.0, 65535.0, 2147483647.0, -2147483648.0, 4294967295.0, 4294967296.0,
                                     9007199254740993.0, 1e19, 1e30, 1e38, 3.5e38, -3.5e38, 1e300, -1e300, 1e-30,
                                     1e-45, 1e-300, 1.7976931348623157e308};
    switch (aRandom() % 6) {
    case 0: return aOld + 1.0;
    case 1: return aOld - 1.0;
    case 2: return -aOld;
    case 3: return aOld * (aRandom() % 2 ? 1e30 : 1e-30);
    default: return kValues[Pick(aRandom, sizeof(kValues) / sizeof(kValues[0]))];
    }
}

Json EdgeValue(Random& aRandom) {
    switch (aRandom() % 8) {
    case 0: return Json("x");
    case 1: return Json(nullptr);
    case 2: return Json::array();
    case 3: return Json::object();
    case 4: return Json(true);
    case 5: return Json::array({1.0, 2.0, 3.0});
    case 6: return Json(int64_t(aRandom() % 8) - 2);
    default: return Json(EdgeNumber(aRandom, 1.0));
    }
}

// Writes a float32 edge value (NaN, inf, huge, tiny, -0) into the bytes of a data URI.
void MutateDataUri(Random& aRandom, Json& aValue) {
    const std::string text = aValue.get<std::string>();
    const size_t comma = text.find(',');
    if (comma == std::string::npos) return;
    std::vector<uint8_t> bytes = DecodeBase64(text.substr(comma + 1));
    if (bytes.size() < 4) return;
    static const float kFloats[] = {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                                    -std::numeric_limits<float>::infinity(), 3.4e38f, -3.4e38f, 1e-45f, -0.f, 1e20f};
    const int edits = 1 + int(aRandom() % 3);
    for (int e = 0; e < edits; e++) {
        const size_t at = 4 * Pick(aRandom, bytes.size() / 4);
        if (aRandom() % 2) {
            const float value = kFloats[Pick(aRandom, sizeof(kFloats) / sizeof(kFloats[0]))];
            std::memcpy(&bytes[at], &value, 4);
        } else {
            bytes[at + Pick(aRandom, 4)] ^= uint8_t(1u << Pick(aRandom, 8));  // an index or a bit of a float
        }
    }
    aValue = text.substr(0, comma + 1) + EncodeBase64(bytes);
}

void Collect(Json& aValue, std::vector<Json*>& oAll, int aDepth) {
    oAll.push_back(&aValue);
    if (aDepth > 64) return;
    if (aValue.is_array() || aValue.is_object())
        for (Json& child : aValue) Collect(child, oAll, aDepth + 1);
}

void MutateJson(Random& aRandom, Json& aDocument) {
    static const char* const kKeys[] = {"mesh", "camera", "children", "matrix", "translation", "rotation", "scale",
                                        "material", "indices", "mode", "count", "byteOffset", "byteStride",
                                        "byteLength", "bufferView", "buffer", "uri", "scene", "nodes", "type",
                                        "componentType", "sparse", "skin", "targets", "extensions", "color",
                                        "intensity", "range", "yfov", "aspectRatio", "radius", "light"};
    std::vector<Json*> all;
    Collect(aDocument, all, 0);
    Json& value = *all[Pick(aRandom, all.size())];
    if (value.is_number()) {
        const double old = value.get<double>();
        if (value.is_number_integer() && std::abs(old) < 1e18 && aRandom() % 2) value = int64_t(old) + int64_t(aRandom() % 7) - 3;
        else value = EdgeNumber(aRandom, old);
    } else if (value.is_string() && value.get<std::string>().compare(0, 5, "data:") == 0 && aRandom() % 4) {
        MutateDataUri(aRandom, value);
    } else if (value.is_array() && !value.empty() && aRandom() % 4 != 0) {
        switch (aRandom() % 3) {
        case 0: value.erase(value.begin() + std::ptrdiff_t(Pick(aRandom, value.size()))); break;
        case 1: value.push_back(value[Pick(aRandom, value.size())]); break;
        default: value.push_back(EdgeValue(aRandom)); break;
        }
    } else if (value.is_object() && aRandom() % 4 != 0) {
        if (!value.empty() && aRandom() % 2) {
            auto it = value.begin();
            std::advance(it, std::ptrdiff_t(Pick(aRandom, value.size())));
            value.erase(it);
        } else {
            const char* key = kKeys[Pick(aRandom, sizeof(kKeys) / sizeof(kKeys[0]))];
            // Another value of the document (an index, an array, an object) or an edge value.
            value[key] = aRandom() % 2 ? Json(*all[Pick(aRandom, all.size())]) : EdgeValue(aRandom);
        }
    } else {
        value = EdgeValue(aRandom);
    }
}

void PutU32(std::string& aBytes, size_t aAt, uint32_t aValue) { std::memcpy(&aBytes[aAt], &aValue, 4); }

} // namespace

extern "C" size_t LLVMFuzzerMutate(uint8_t* aData, size_t aSize, size_t aMaxSize);

extern "C" size_t LLVMFuzzerCustomMutator(uint8_t* aData, size_t aSize, size_t aMaxSize, unsigned int aSeed) {
    Random random(aSeed);
    if (random() % 2) return LLVMFuzzerMutate(aData, aSize, aMaxSize);
    const bool binary = aSize >= 20 && std::memcmp(aData, "glTF", 4) == 0;
    std::string json, tail;  // tail: what follows the JSON chunk of a .glb
    if (binary) {
        uint32_t length;
        std::memcpy(&length, aData + 12, 4);
        if (uint64_t(length) + 20 > aSize) return LLVMFuzzerMutate(aData, aSize, aMaxSize);
        json.assign(reinterpret_cast<const char*>(aData) + 20, length);
        tail.assign(reinterpret_cast<const char*>(aData) + 20 + length, aSize - 20 - length);
    } else {
        json.assign(reinterpret_cast<const char*>(aData), aSize);
    }
    // nlohmann's copy and dump recurse: leave deeply nested inputs to the byte mutations.
    int depth = 0, deepest = 0;
    for (char c : json) {
        if (c == '[' || c == '{') deepest = std::max(deepest, ++depth);
        else if (c == ']' || c == '}') depth--;
    }
    if (deepest > 256) return LLVMFuzzerMutate(aData, aSize, aMaxSize);
    Json document = Json::parse(json, nullptr, false);
    if (document.is_discarded()) return LLVMFuzzerMutate(aData, aSize, aMaxSize);
    const int mutations = 1 + int(random() % 3);
    for (int m = 0; m < mutations; m++) MutateJson(random, document);
    std::string out = document.dump(-1, ' ', false, Json::error_handler_t::replace);
    if (binary) {
        while (out.size() % 4 != 0) out += ' ';
        std::string glb = std::string("glTF") + std::string(16, '\0') + out + tail;
        PutU32(glb, 4, 2);
        PutU32(glb, 8, uint32_t(glb.size()));
        PutU32(glb, 12, uint32_t(out.size()));
        PutU32(glb, 16, 0x4E4F534Au);  // "JSON"
        if (tail.size() >= 8) PutU32(glb, 20 + out.size(), uint32_t(tail.size() - 8));  // the BIN chunk's length
        if (random() % 8 == 0) {  // a header or chunk length that lies
            static const size_t kFields[] = {8, 12, 0};
            size_t at = kFields[Pick(random, 3)];
            if (at == 0) at = 20 + out.size();
            if (at + 4 <= glb.size()) {
                uint32_t value;
                std::memcpy(&value, &glb[at], 4);
                value += uint32_t(int(random() % 17) - 8);
                PutU32(glb, at, value);
            }
        }
        out = glb;
    }
    if (out.size() > aMaxSize) return LLVMFuzzerMutate(aData, aSize, aMaxSize);
    std::memcpy(aData, out.data(), out.size());
    return out.size();
}

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    Folder();
    std::atexit(RemoveFolder);
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* aData, size_t aSize) {
    const bool binary = aSize >= 4 && std::memcmp(aData, "glTF", 4) == 0;
    const std::string path = Folder() + (binary ? "/input.glb" : "/input.gltf");
    if (!WriteFile(path, aData, aSize)) {
        std::perror("fuzz_gltf: cannot write the input file");
        std::exit(2);
    }
    try {
        smallvcm::GltfLoadReport report;
        smallvcm::Scene scene = smallvcm::LoadGltfScene(path, &report);
        if (report.mSkippedDegenerateTriangles < 0) Finding("negative skipped-triangle count");
        CheckScene(scene);
        RenderOnce(scene);
    } catch (const smallvcm::Error& e) {
        CheckErrorMessage(path, e.what());  // expected: a bad file, rejected
    } catch (const std::exception& e) {
        Finding(std::string("an exception other than smallvcm::Error escaped: ") + e.what());
    } catch (...) {
        Finding("a non-standard exception escaped");
    }
    std::remove(path.c_str());
    return 0;
}
