// [gltf] Scene loading: the Cornell files load with SmallVCM's numbers
// (shared/SMALLVCM_SCENES.md), every file of the bad-input corpus (tests/data/bad, table
// in its README.md) is rejected with an Error naming the file and the problem, files
// with zero-area triangles load with the skipped ones counted, the pbrMetallicRoughness
// mapping of docs/scene_format.md section 4.2 is what the loader does, and node
// transforms place and orient meshes as glTF says. Inputs are written by
// tests/data/make_bad_gltf.py; tests run from tests/, so paths are data/... and ../scenes/...
#include "gltf_corpus.hpp"
#include "test_util.hpp"

#include <catch2/catch.hpp>
#include <meshoptimizer.h>

#include <filesystem>
#include <map>
#include <set>
#include <sstream>
#include <tuple>

namespace {

using namespace smallvcm;
using testutil::CornellPath;
using testutil::ReadText;
using testutil::TemporaryFolder;

std::string Str(const Vec3& aV) {
    std::ostringstream out;
    out << "(" << aV.x << ", " << aV.y << ", " << aV.z << ")";
    return out.str();
}

// Component-wise |a - b| <= tol, with both vectors printed on failure.
#define CHECK_VEC3(aActual, aExpected, aTolerance)                                                  \
    do {                                                                                            \
        const Vec3 actual_ = (aActual), expected_ = (aExpected);                                    \
        INFO(#aActual " = " << Str(actual_) << ", expected " << Str(expected_));                   \
        CHECK(std::abs(actual_.x - expected_.x) <= (aTolerance));                                    \
        CHECK(std::abs(actual_.y - expected_.y) <= (aTolerance));                                    \
        CHECK(std::abs(actual_.z - expected_.z) <= (aTolerance));                                    \
    } while (0)

using corpus::StartsWith;

// --- the Cornell files ------------------------------------------------------------

// SmallVCM's material table (SMALLVCM_SCENES.md section 3), by SmallVCM id.
struct ExpectedMaterial {
    Vec3 mDiffuse, mPhong;
    float mExponent;  // checked only where the Phong lobe exists
    Vec3 mMirror;
    float mIor;
};
const std::map<int, ExpectedMaterial>& SmallVcmMaterials() {
    static const std::map<int, ExpectedMaterial> kMaterials = {
        {0, {Vec3(0.f), Vec3(0.f), 1.f, Vec3(0.f), -1.f}},
        {1, {Vec3(0.f), Vec3(0.f), 1.f, Vec3(0.f), -1.f}},
        {2, {Vec3(0.1f), Vec3(0.7f), 90.f, Vec3(0.f), -1.f}},
        {3, {Vec3(0.156863f, 0.803922f, 0.172549f), Vec3(0.f), 1.f, Vec3(0.f), -1.f}},
        {4, {Vec3(0.803922f, 0.152941f, 0.152941f), Vec3(0.f), 1.f, Vec3(0.f), -1.f}},
        {5, {Vec3(0.803922f), Vec3(0.f), 1.f, Vec3(0.f), -1.f}},
        {6, {Vec3(0.f), Vec3(0.f), 1.f, Vec3(1.f), -1.f}},
        {7, {Vec3(0.f), Vec3(0.f), 1.f, Vec3(1.f), 1.6f}},
        {8, {Vec3(0.156863f, 0.172549f, 0.803922f), Vec3(0.f), 1.f, Vec3(0.f), -1.f}},
    };
    return kMaterials;
}

// The SmallVCM id of a Cornell material: its name starts "SmallVCM material N: ".
int SmallVcmId(const Material& aMaterial) {
    const std::string prefix = "SmallVCM material ";
    if (!StartsWith(aMaterial.mName, prefix)) return -1;
    return std::atoi(aMaterial.mName.c_str() + prefix.size());
}

int SmallVcmIdOf(const Scene& aScene, int aMaterialIndex) {
    return SmallVcmId(aScene.mMaterials.at(size_t(aMaterialIndex)));
}

struct CornellExpectation {
    int mIndex;
    size_t mTriangles, mSpheres;
    int mArea, mPoint, mDirectional, mBackground;
    std::set<int> mMaterialIds;  // SmallVCM ids present
    bool mGlossy;                // glossy floor (2) and blue back wall (8)
};

const std::vector<CornellExpectation>& CornellExpectations() {
    static const std::vector<CornellExpectation> kScenes = {
        {0, 20, 2, 0, 0, 1, 0, {2, 3, 4, 5, 6, 7, 8}, true},
        {1, 20, 1, 2, 0, 0, 0, {0, 1, 2, 3, 4, 5, 6, 8}, true},
        {2, 10, 2, 0, 1, 0, 0, {2, 3, 4, 5, 6, 7, 8}, true},
        {3, 20, 2, 0, 0, 0, 1, {2, 3, 4, 5, 6, 7, 8}, true},
        {4, 20, 2, 2, 0, 0, 0, {0, 1, 3, 4, 5, 6, 7}, false},
    };
    return kScenes;
}

int CountLights(const Scene& aScene, LightType aType) {
    int count = 0;
    for (const Light& light : aScene.mLights) count += light.mType == aType ? 1 : 0;
    return count;
}

} // namespace

TEST_CASE("Every Cornell scene loads with SmallVCM's primitive, light and material counts", "[gltf]") {
    for (const CornellExpectation& e : CornellExpectations()) {
        const std::string path = CornellPath(e.mIndex);
        INFO(path);
        GltfLoadReport report;
        report.mSkippedDegenerateTriangles = -1;
        const Scene scene = LoadGltfScene(path, &report);
        CHECK(scene.IsFinalized());
        CHECK(scene.mName == path);
        CHECK(report.mSkippedDegenerateTriangles == 0);
        CHECK(scene.mTriangles.size() == e.mTriangles);
        CHECK(scene.mSpheres.size() == e.mSpheres);
        CHECK(CountLights(scene, LightType::kArea) == e.mArea);
        CHECK(CountLights(scene, LightType::kPoint) == e.mPoint);
        CHECK(CountLights(scene, LightType::kDirectional) == e.mDirectional);
        CHECK(CountLights(scene, LightType::kBackground) == e.mBackground);
        CHECK(CountLights(scene, LightType::kSphere) == 0);
        CHECK(scene.LightCount() == e.mArea + e.mPoint + e.mDirectional + e.mBackground);
        CHECK(scene.mMaterials.size() == e.mMaterialIds.size());
        std::set<int> ids;
        for (const Material& material : scene.mMaterials) ids.insert(SmallVcmId(material));
        CHECK(ids == e.mMaterialIds);
    }
}

TEST_CASE("Cornell materials are SmallVCM's materials 0-8", "[gltf]") {
    for (const CornellExpectation& e : CornellExpectations()) {
        const Scene scene = LoadGltfScene(CornellPath(e.mIndex));
        for (const Material& material : scene.mMaterials) {
            INFO(CornellPath(e.mIndex) << ": " << material.mName);
            const int id = SmallVcmId(material);
            REQUIRE(SmallVcmMaterials().count(id) == 1);
            const ExpectedMaterial& expected = SmallVcmMaterials().at(id);
            CHECK_VEC3(material.mDiffuseReflectance, expected.mDiffuse, 1e-6f);
            CHECK_VEC3(material.mPhongReflectance, expected.mPhong, 1e-6f);
            if (!IsBlack(expected.mPhong)) CHECK(material.mPhongExponent == Approx(expected.mExponent));
            CHECK_VEC3(material.mMirrorReflectance, expected.mMirror, 1e-6f);
            CHECK(material.mIor == Approx(expected.mIor));
            CHECK_FALSE(material.mTwoSided);  // SmallVCM's surfaces are one-sided
        }
        // Walls in SmallVCM's order: floor, back, ceiling, left, right (2 triangles each).
        const std::vector<std::pair<int, Vec3>> walls = {
            {e.mGlossy ? 2 : 5, Vec3(0, 0, 1)}, {e.mGlossy ? 8 : 5, Vec3(0, -1, 0)}, {5, Vec3(0, 0, -1)},
            {3, Vec3(1, 0, 0)}, {4, Vec3(-1, 0, 0)}};
        for (size_t w = 0; w < walls.size(); w++)
            for (size_t t = 2 * w; t < 2 * w + 2; t++) {
                INFO(CornellPath(e.mIndex) << ": triangle " << t);
                const Triangle& triangle = scene.mTriangles.at(t);
                CHECK(SmallVcmIdOf(scene, triangle.mMaterialId) == walls[w].first);
                CHECK_VEC3(triangle.mNormal, walls[w].second, 2e-6f);
                CHECK(triangle.Area() == Approx(3.276902f).epsilon(1e-5));
                CHECK(triangle.mLightId == -1);
            }
    }
}

TEST_CASE("Cornell spheres, scene radius and camera are SmallVCM's", "[gltf]") {
    const Vec3 large(0.00972998f, 0.02453005f, -0.48002f);
    const Vec3 smallLeft(-0.53885f, 0.02453005f, -0.78002f), smallRight(0.55831f, 0.02453005f, -0.78002f);
    for (const CornellExpectation& e : CornellExpectations()) {
        INFO(CornellPath(e.mIndex));
        const Scene scene = LoadGltfScene(CornellPath(e.mIndex));
        const SceneSphere& bounds = scene.GetSceneSphere();
        CHECK(std::abs(bounds.mRadius - 2.2170596f) <= 1e-5f);
        CHECK_VEC3(bounds.mCenter, Vec3(0.00972998f, 0.02453005f, 0.f), 1e-5f);

        if (e.mIndex == 1) {
            REQUIRE(scene.mSpheres.size() == 1);
            CHECK_VEC3(scene.mSpheres[0].mCenter, large, 1e-6f);
            CHECK(scene.mSpheres[0].mRadius == 0.8f);
            CHECK(SmallVcmIdOf(scene, scene.mSpheres[0].mMaterialId) == 6);
        } else {
            REQUIRE(scene.mSpheres.size() == 2);
            CHECK_VEC3(scene.mSpheres[0].mCenter, smallLeft, 1e-6f);
            CHECK_VEC3(scene.mSpheres[1].mCenter, smallRight, 1e-6f);
            CHECK(scene.mSpheres[0].mRadius == 0.5f);
            CHECK(scene.mSpheres[1].mRadius == 0.5f);
            CHECK(SmallVcmIdOf(scene, scene.mSpheres[0].mMaterialId) == 6);
            CHECK(SmallVcmIdOf(scene, scene.mSpheres[1].mMaterialId) == 7);
        }
        for (const Sphere& sphere : scene.mSpheres) CHECK(sphere.mLightId == -1);

        // SMALLVCM_SCENES.md section 5: position, basis, horizontal field of view 45 degrees.
        const Camera& camera = scene.mCamera;
        CHECK_VEC3(camera.Position(), Vec3(-0.0439815f, -4.12529f, 0.222539f), 1e-6f);
        CHECK_VEC3(camera.Forward(), glm::normalize(Vec3(0.00688625f, 0.998505f, -0.0542161f)), 1e-6f);
        CHECK_VEC3(camera.Right(), Vec3(0.999976f, -0.006896f, 0.f), 1e-5f);
        CHECK_VEC3(camera.Up(), Vec3(3.739e-4f, 0.054215f, 0.998529f), 1e-5f);
        CHECK(camera.HorizontalFovDegrees() == Approx(45.f).epsilon(1e-6));
    }
}

TEST_CASE("Cornell light emission matches SmallVCM's lights", "[gltf]") {
    const float areaRadiance = 25.03329895614464f;
    for (const CornellExpectation& e : CornellExpectations()) {
        INFO(CornellPath(e.mIndex));
        const Scene scene = LoadGltfScene(CornellPath(e.mIndex));
        for (const Light& light : scene.mLights) {
            switch (light.mType) {
            case LightType::kArea:
                // The light-box bottom: one triangle per light, area 0.125, facing down,
                // radiance 25.0333 per channel (power pi A L = 9.83 per triangle).
                CHECK_VEC3(light.mEmission, Vec3(areaRadiance), 1e-5f);
                REQUIRE(light.mTriangleNormal.size() == 1);
                CHECK(light.mArea == Approx(0.125f).epsilon(1e-4));
                CHECK_VEC3(light.mTriangleNormal[0], Vec3(0.f, 0.f, -1.f), 1e-6f);
                break;
            case LightType::kDirectional:
                CHECK_VEC3(light.mEmission, Vec3(10.f, 4.f, 0.f), 1e-5f);
                CHECK_VEC3(light.mDirection, Vec3(-0.485071f, 0.727607f, -0.485071f), 1e-5f);
                break;
            case LightType::kPoint:
                CHECK_VEC3(light.mEmission, Vec3(5.570423f), 1e-5f);
                CHECK_VEC3(light.mPosition, Vec3(0.f, -0.5f, 1.f), 1e-6f);
                break;
            case LightType::kBackground:
                CHECK_VEC3(light.mEmission, Vec3(135.f, 206.f, 250.f) / 255.f, 1e-6f);
                CHECK(scene.GetBackground() == &light);
                break;
            case LightType::kSphere:
                FAIL("no Cornell scene has a sphere light");
            case LightType::kSpot:
                FAIL("no Cornell scene has a spot light");
            }
        }
        // The emitting triangles are the last two (light-box bottom), one light each.
        if (e.mArea == 2) {
            const Triangle& a = scene.mTriangles[18];
            const Triangle& b = scene.mTriangles[19];
            CHECK(a.mLightId >= 0);
            CHECK(b.mLightId >= 0);
            CHECK(a.mLightId != b.mLightId);
            CHECK(SmallVcmIdOf(scene, a.mMaterialId) == 0);
            CHECK(SmallVcmIdOf(scene, b.mMaterialId) == 1);
            // SmallVCM's vertex order: (lb0, lb5, lb4) and (lb5, lb0, lb1).
            CHECK_VEC3(a.mP0, Vec3(-0.25f, 0.25f, 1.26002f), 1e-6f);
            CHECK_VEC3(a.mP1, Vec3(0.25f, -0.25f, 1.26002f), 1e-6f);
            CHECK_VEC3(a.mP2, Vec3(-0.25f, -0.25f, 1.26002f), 1e-6f);
            CHECK_VEC3(b.mP0, Vec3(0.25f, -0.25f, 1.26002f), 1e-6f);
            CHECK_VEC3(b.mP1, Vec3(-0.25f, 0.25f, 1.26002f), 1e-6f);
            CHECK_VEC3(b.mP2, Vec3(0.25f, 0.25f, 1.26002f), 1e-6f);
            for (int t = 0; t < 18; t++) CHECK(scene.mTriangles[size_t(t)].mLightId == -1);
        }
    }
}

// --- the bad-input corpus -------------------------------------------------------------

namespace {

using CorpusRow = corpus::Row;

std::vector<CorpusRow> ReadCorpusTable(const std::string& aReadme) { return corpus::ReadTable(aReadme); }

std::set<std::string> SceneFilesIn(const std::string& aFolder) {
    std::set<std::string> names;
    for (const auto& entry : std::filesystem::directory_iterator(aFolder)) {
        const std::string name = entry.path().filename().string();
        const std::string extension = entry.path().extension().string();
        if (extension == ".gltf" || extension == ".glb") names.insert(name);
    }
    return names;
}

// Loads aPath and describes the outcome: "loaded", "Error", or the other exception.
struct LoadOutcome {
    std::string mKind, mMessage;
};
LoadOutcome TryLoad(const std::string& aPath) {
    try {
        LoadGltfScene(aPath);
        return {"loaded", ""};
    } catch (const Error& e) {
        return {"Error", e.what()};
    } catch (const std::exception& e) {
        return {"another std::exception", e.what()};
    } catch (...) {
        return {"a non-standard exception", ""};
    }
}

} // namespace

TEST_CASE("The bad-input corpus table lists every file of tests/data/bad", "[gltf]") {
    const std::vector<CorpusRow> rows = ReadCorpusTable("data/bad/README.md");
    std::set<std::string> listed;
    int rejected = 0, loading = 0;
    for (const CorpusRow& row : rows) {
        INFO(row.mFile);
        CHECK(listed.insert(row.mFile).second);  // no duplicates
        (row.mFragment.empty() ? loading : rejected)++;
    }
    CHECK(listed == SceneFilesIn("data/bad"));
    CHECK(rejected >= 32);
    CHECK(loading >= 1);
}

TEST_CASE("Every bad input is rejected with an Error naming the file and the problem", "[gltf]") {
    for (const CorpusRow& row : ReadCorpusTable("data/bad/README.md")) {
        if (row.mFragment.empty()) continue;
        const std::string path = "data/bad/" + row.mFile;
        const LoadOutcome outcome = TryLoad(path);
        INFO(path << " (" << row.mWhat << ")\n  expected: Error containing '" << row.mFragment << "'\n  got: "
                  << outcome.mKind << (outcome.mMessage.empty() ? "" : ": " + outcome.mMessage));
        CHECK(outcome.mKind == "Error");
        CHECK(StartsWith(outcome.mMessage, path + ": "));
        // The fragment must be in the problem, not in the path ("directory.gltf").
        const std::string problem = outcome.mMessage.substr(std::min(outcome.mMessage.size(), path.size() + 2));
        CHECK(problem.find(row.mFragment) != std::string::npos);
        CHECK(outcome.mMessage.find('\n') == std::string::npos);  // one line
    }
}

TEST_CASE("A path that does not exist is an Error naming the path", "[gltf]") {
    const LoadOutcome outcome = TryLoad("data/bad/no_such_file.gltf");
    CHECK(outcome.mKind == "Error");
    CHECK(StartsWith(outcome.mMessage, "data/bad/no_such_file.gltf: cannot open the file"));
}

// --- degenerate triangles ---------------------------------------------------------------

TEST_CASE("Zero-area triangles are skipped and counted, the rest of the scene loads", "[gltf]") {
    int files = 0;
    for (const CorpusRow& row : ReadCorpusTable("data/bad/README.md")) {
        if (!row.mFragment.empty()) continue;
        files++;
        const std::string path = "data/bad/" + row.mFile;
        INFO(path << " (" << row.mWhat << ")");
        GltfLoadReport report;
        Scene scene;
        REQUIRE_NOTHROW(scene = LoadGltfScene(path, &report));
        CHECK(report.mSkippedDegenerateTriangles == row.mSkipped);
        // Kept = the floor's good triangles plus the emitter's two.
        CHECK(int(scene.mTriangles.size()) == row.mKept);
        for (const Triangle& triangle : scene.mTriangles) CHECK(triangle.Area() > 0.f);
        CHECK(scene.LightCount() == 1);
        // Without a report the same file loads too.
        CHECK_NOTHROW(LoadGltfScene(path));
    }
    CHECK(files == 2);
}

// --- pbrMetallicRoughness mapping, SMALLVCM_material, indices, .glb ----------------------

namespace {

// The floor's material (the floor is the first primitive, triangles 0 and 1).
Material FloorMaterial(const std::string& aFile, Scene* oScene = nullptr) {
    Scene scene = LoadGltfScene("data/gltf/" + aFile);
    REQUIRE(scene.mTriangles.size() == 4);
    CHECK(scene.mTriangles[0].mMaterialId == scene.mTriangles[1].mMaterialId);
    const Material material = scene.mMaterials.at(size_t(scene.mTriangles[0].mMaterialId));
    if (oScene) *oScene = std::move(scene);
    return material;
}

void CheckMaterial(const Material& aMaterial, const Vec3& aDiffuse, const Vec3& aPhong, float aExponent,
                   const Vec3& aMirror, float aIor, bool aTwoSided) {
    CHECK_VEC3(aMaterial.mDiffuseReflectance, aDiffuse, 1e-6f);
    CHECK_VEC3(aMaterial.mPhongReflectance, aPhong, 1e-6f);
    if (!IsBlack(aPhong)) CHECK(aMaterial.mPhongExponent == Approx(aExponent).epsilon(1e-5));
    CHECK_VEC3(aMaterial.mMirrorReflectance, aMirror, 1e-6f);
    CHECK(aMaterial.mIor == Approx(aIor));
    CHECK(aMaterial.mTwoSided == aTwoSided);
}

} // namespace

TEST_CASE("pbrMetallicRoughness maps to Lambert + Phong + mirror as docs/scene_format.md says", "[gltf]") {
    // ks = lerp(0.04, b, m), rho_d = (1 - m) 0.96 b; r = 0: mirror ks; r > 0: Phong ks, n = 2/r^4 - 2.
    SECTION("dielectric, roughness 1: Lambert 0.96 b plus a Phong lobe 0.04 with n = 0") {
        CheckMaterial(FloorMaterial("material_lambert.gltf"), 0.96f * Vec3(0.5f, 0.25f, 1.f), Vec3(0.04f), 0.f,
                      Vec3(0.f), -1.f, false);
    }
    SECTION("metal, roughness 0: a perfect mirror of reflectance b") {
        CheckMaterial(FloorMaterial("material_mirror.gltf"), Vec3(0.f), Vec3(0.f), 1.f, Vec3(0.9f, 0.8f, 0.7f),
                      -1.f, false);
    }
    SECTION("metal, roughness 0.5: Phong of reflectance b, exponent 2/0.5^4 - 2 = 30") {
        CheckMaterial(FloorMaterial("material_rough_metal.gltf"), Vec3(0.f), Vec3(0.9f, 0.6f, 0.3f), 30.f,
                      Vec3(0.f), -1.f, false);
    }
    SECTION("metallic 0.25, roughness 0.5: both lobes") {
        // ks = 0.04 * 0.75 + 0.5 * 0.25 = 0.155, rho_d = 0.75 * 0.96 * 0.5 = 0.36.
        CheckMaterial(FloorMaterial("material_dielectric_glossy.gltf"), Vec3(0.36f), Vec3(0.155f), 30.f, Vec3(0.f),
                      -1.f, false);
    }
    SECTION("KHR_materials_transmission: clear glass, ior from KHR_materials_ior") {
        CheckMaterial(FloorMaterial("material_glass.gltf"), Vec3(0.f), Vec3(0.f), 1.f, Vec3(1.f), 1.6f, false);
    }
    SECTION("KHR_materials_transmission without KHR_materials_ior: ior 1.5") {
        CheckMaterial(FloorMaterial("material_glass_default_ior.gltf"), Vec3(0.f), Vec3(0.f), 1.f, Vec3(1.f), 1.5f,
                      false);
    }
    SECTION("a material with no factors: glTF defaults b = 1, m = 1, r = 1 -> Phong 1, n = 0") {
        CheckMaterial(FloorMaterial("material_default.gltf"), Vec3(0.f), Vec3(1.f), 0.f, Vec3(0.f), -1.f, false);
    }
    SECTION("a primitive without a material gets glTF's default material, mapped the same way") {
        Scene scene;
        const Material material = FloorMaterial("material_none.gltf", &scene);
        CHECK(scene.mMaterials.size() == 3);  // the file's two plus the default
        CheckMaterial(material, Vec3(0.f), Vec3(1.f), 0.f, Vec3(0.f), -1.f, false);
    }
    SECTION("doubleSided: diffuse and Phong reflect on both sides") {
        CheckMaterial(FloorMaterial("material_double_sided.gltf"), Vec3(0.48f), Vec3(0.04f), 0.f, Vec3(0.f), -1.f,
                      true);
    }
}

TEST_CASE("SMALLVCM_material overrides pbrMetallicRoughness", "[gltf]") {
    SECTION("Lambert + Phong where the pbr factors say mirror") {
        CheckMaterial(FloorMaterial("material_override.gltf"), Vec3(0.1f, 0.2f, 0.3f), Vec3(0.4f, 0.3f, 0.2f), 90.f,
                      Vec3(0.f), -1.f, false);
    }
    SECTION("glass where the pbr factors say Lambert") {
        CheckMaterial(FloorMaterial("material_override_glass.gltf"), Vec3(0.f), Vec3(0.f), 1.f, Vec3(1.f), 1.6f,
                      false);
    }
}

TEST_CASE("Emitters are black unless a SMALLVCM_material gives them a reflectance", "[gltf]") {
    // The emitter is material 1 of the test scenes (emissive strength 10).
    SECTION("white pbr factors, no SMALLVCM_material: black") {
        const Scene scene = LoadGltfScene("data/gltf/emitter_pbr_white.gltf");
        const Material& emitter = scene.mMaterials.at(1);
        CHECK(IsBlack(emitter.mDiffuseReflectance));
        CHECK(IsBlack(emitter.mPhongReflectance));
        CHECK(IsBlack(emitter.mMirrorReflectance));
        CHECK(emitter.mIor < 0.f);
        REQUIRE(scene.LightCount() == 1);
        CHECK_VEC3(scene.mLights[0].mEmission, Vec3(10.f), 1e-6f);
    }
    SECTION("SMALLVCM_material with diffuse 0.3: kept") {
        const Scene scene = LoadGltfScene("data/gltf/emitter_with_reflectance.gltf");
        CHECK_VEC3(scene.mMaterials.at(1).mDiffuseReflectance, Vec3(0.3f), 1e-6f);
        REQUIRE(scene.LightCount() == 1);
        CHECK_VEC3(scene.mLights[0].mEmission, Vec3(10.f), 1e-6f);
        CHECK(scene.mLights[0].mArea == Approx(0.25f));
    }
}

TEST_CASE("Indices may be absent or UNSIGNED_BYTE/SHORT/INT, and .glb files load", "[gltf]") {
    const Scene reference = LoadGltfScene("data/gltf/material_lambert.gltf");
    for (const char* file : {"indices_none.gltf", "indices_unsigned_byte.gltf", "indices_unsigned_short.gltf",
                             "minimal.glb"}) {
        INFO(file);
        const Scene scene = LoadGltfScene(std::string("data/gltf/") + file);
        REQUIRE(scene.mTriangles.size() == reference.mTriangles.size());
        for (size_t t = 0; t < scene.mTriangles.size(); t++) {
            CHECK_VEC3(scene.mTriangles[t].mP0, reference.mTriangles[t].mP0, 0.f);
            CHECK_VEC3(scene.mTriangles[t].mP1, reference.mTriangles[t].mP1, 0.f);
            CHECK_VEC3(scene.mTriangles[t].mP2, reference.mTriangles[t].mP2, 0.f);
        }
        CHECK(scene.LightCount() == 1);
    }
}

// --- node transforms ----------------------------------------------------------------------

namespace {

// World positions of the floor's first triangle (local (-1,-1,0), (1,-1,0), (1,1,0)),
// normal of both floor triangles; the light (triangles 2, 3) must be where it was.
void CheckFloor(const std::string& aFile, const Vec3& aP0, const Vec3& aP1, const Vec3& aP2, const Vec3& aNormal) {
    INFO(aFile);
    const Scene scene = LoadGltfScene("data/gltf/" + aFile);
    REQUIRE(scene.mTriangles.size() == 4);
    const Triangle& first = scene.mTriangles[0];
    CHECK_VEC3(first.mP0, aP0, 1e-5f);
    CHECK_VEC3(first.mP1, aP1, 1e-5f);
    CHECK_VEC3(first.mP2, aP2, 1e-5f);
    CHECK_VEC3(scene.mTriangles[0].mNormal, aNormal, 1e-6f);
    CHECK_VEC3(scene.mTriangles[1].mNormal, aNormal, 1e-6f);
    CHECK_VEC3(scene.mTriangles[2].mP0, Vec3(-0.25f, -0.25f, 1.f), 0.f);
    CHECK_VEC3(scene.mTriangles[2].mNormal, Vec3(0.f, 0.f, -1.f), 1e-6f);
}

} // namespace

TEST_CASE("Node transforms place meshes at their world coordinates", "[gltf]") {
    SECTION("translation (1,2,3), rotation 90 degrees about +z, scale (2, 0.5, 1.5): p -> (1 - 0.5 y, 2 + 2 x, 3 + 1.5 z)") {
        CheckFloor("transform_trs.gltf", Vec3(1.5f, 0.f, 3.f), Vec3(1.5f, 4.f, 3.f), Vec3(0.5f, 4.f, 3.f), Vec3(0, 0, 1));
    }
    SECTION("the same rotation and translation as a column-major matrix: p -> (1 - y, 2 + x, 3 + z)") {
        CheckFloor("transform_matrix.gltf", Vec3(2.f, 1.f, 3.f), Vec3(2.f, 3.f, 3.f), Vec3(0.f, 3.f, 3.f), Vec3(0, 0, 1));
    }
    SECTION("parent (translation (0,0,1), 90 degrees about +z) times child (translation (1,0,0))") {
        // world = parent * child: p -> (-y, x + 1, z + 1)
        CheckFloor("transform_parent_child.gltf", Vec3(1.f, 0.f, 1.f), Vec3(1.f, 2.f, 1.f), Vec3(-1.f, 2.f, 1.f),
                   Vec3(0, 0, 1));
    }
    SECTION("a sphere node: centre = world translation, radius times the uniform scale") {
        const Scene scene = LoadGltfScene("data/gltf/sphere_scaled.gltf");
        REQUIRE(scene.mSpheres.size() == 1);
        CHECK_VEC3(scene.mSpheres[0].mCenter, Vec3(0.1f, 0.2f, 0.3f), 1e-6f);
        CHECK(scene.mSpheres[0].mRadius == Approx(0.3f));
    }
}

TEST_CASE("A mirroring node transform keeps the front face where glTF puts it", "[gltf]") {
    // glTF: with a negative determinant the front faces are clockwise, i.e. the front
    // normal is the local one transformed by the inverse transpose. The floor's local
    // front is +z.
    SECTION("scale (-1, 1, 1): vertices mirrored in x, the front stays +z") {
        const Scene scene = LoadGltfScene("data/gltf/transform_mirror_x.gltf");
        const std::set<std::array<float, 3>> expected = {{1, -1, 0}, {-1, -1, 0}, {-1, 1, 0}};
        const Triangle& first = scene.mTriangles.at(0);
        CHECK(std::set<std::array<float, 3>>{{first.mP0.x, first.mP0.y, first.mP0.z},
                                            {first.mP1.x, first.mP1.y, first.mP1.z},
                                            {first.mP2.x, first.mP2.y, first.mP2.z}} == expected);
        CHECK_VEC3(scene.mTriangles.at(0).mNormal, Vec3(0, 0, 1), 1e-6f);
        CHECK_VEC3(scene.mTriangles.at(1).mNormal, Vec3(0, 0, 1), 1e-6f);
    }
    SECTION("scale (1, 1, -1): the plane z = 0 maps to itself, the front turns to -z") {
        const Scene scene = LoadGltfScene("data/gltf/transform_mirror_z.gltf");
        CHECK_VEC3(scene.mTriangles.at(0).mNormal, Vec3(0, 0, -1), 1e-6f);
        CHECK_VEC3(scene.mTriangles.at(1).mNormal, Vec3(0, 0, -1), 1e-6f);
    }
}

// --- fuzz regressions (tests/data/fuzz, table in its README.md) ---------------------------
// Inputs found by fuzzing the loader (tests/fuzz/fuzz_gltf.cpp, docs/testing.md) or made
// by hand for the same classes of problem: each must be rejected with an Error naming the
// file and the problem, or load as a scene that renders what the file says (finite camera
// and lights). Several fail until the fixes proposed with them are in smallvcm.hpp.

namespace {

bool FiniteVec(const Vec3& aV) { return std::isfinite(aV.x) && std::isfinite(aV.y) && std::isfinite(aV.z); }
bool UnitVec(const Vec3& aV) { return FiniteVec(aV) && std::abs(glm::length(aV) - 1.f) < 1e-4f; }

// What the fuzz target (CheckScene) requires of a scene that loads.
void CheckSaneScene(const Scene& aScene) {
    const Camera& camera = aScene.mCamera;
    CHECK(FiniteVec(camera.Position()));
    CHECK(UnitVec(camera.Forward()));
    CHECK(UnitVec(camera.Right()));
    CHECK(UnitVec(camera.Up()));
    CHECK(camera.HorizontalFovDegrees() > 0.f);
    CHECK(camera.HorizontalFovDegrees() < 180.f);
    for (const Light& light : aScene.mLights) {
        CHECK(FiniteVec(light.mEmission));
        if (light.mType == LightType::kPoint) CHECK(FiniteVec(light.mPosition));
        if (light.mType == LightType::kDirectional) CHECK(UnitVec(light.mDirection));
    }
    for (const Triangle& triangle : aScene.mTriangles) {
        CHECK(FiniteVec(triangle.mP0));
        CHECK(FiniteVec(triangle.mP1));
        CHECK(FiniteVec(triangle.mP2));
        CHECK(UnitVec(triangle.mNormal));
    }
}

} // namespace

TEST_CASE("The fuzz regression table lists every file of tests/data/fuzz", "[gltf][fuzz]") {
    std::set<std::string> listed;
    for (const CorpusRow& row : ReadCorpusTable("data/fuzz/README.md")) {
        INFO(row.mFile);
        CHECK(listed.insert(row.mFile).second);
    }
    CHECK(listed == SceneFilesIn("data/fuzz"));
    CHECK(listed.size() >= 1);
}

TEST_CASE("Every fuzz regression input is rejected with an Error naming the file, or loads sanely", "[gltf][fuzz]") {
    for (const CorpusRow& row : ReadCorpusTable("data/fuzz/README.md")) {
        const std::string path = "data/fuzz/" + row.mFile;
        if (row.mFragment.empty()) {
            INFO(path << " (" << row.mWhat << ")\n  expected: loads, skipped " << row.mSkipped << ", kept " << row.mKept);
            GltfLoadReport report;
            Scene scene;
            REQUIRE_NOTHROW(scene = LoadGltfScene(path, &report));
            CHECK(report.mSkippedDegenerateTriangles == row.mSkipped);
            CHECK(int(scene.mTriangles.size()) == row.mKept);
            CheckSaneScene(scene);
            continue;
        }
        const LoadOutcome outcome = TryLoad(path);
        INFO(path << " (" << row.mWhat << ")\n  expected: Error containing '" << row.mFragment << "'\n  got: "
                  << outcome.mKind << (outcome.mMessage.empty() ? "" : ": " + outcome.mMessage));
        CHECK(outcome.mKind == "Error");
        CHECK(StartsWith(outcome.mMessage, path + ": "));
        const std::string problem = outcome.mMessage.substr(std::min(outcome.mMessage.size(), path.size() + 2));
        CHECK(problem.find(row.mFragment) != std::string::npos);
        CHECK(outcome.mMessage.find('\n') == std::string::npos);
    }
}

TEST_CASE("A rotation quaternion with huge components turns a node like its normalised self", "[gltf][fuzz]") {
    // (1e300, 1e300, 1e300, 1e300) is (0.5, 0.5, 0.5, 0.5): 120 degrees about (1, 1, 1),
    // which takes +z to +x. Its squared norm overflows; the floor must not stay unrotated.
    const Scene scene = LoadGltfScene("data/fuzz/rotation_huge_quaternion.gltf");
    REQUIRE(scene.mTriangles.size() == 4);
    CHECK_VEC3(scene.mTriangles[0].mNormal, Vec3(1, 0, 0), 1e-5f);
    CHECK_VEC3(scene.mTriangles[0].mP0, Vec3(0, -1, -1), 1e-5f);  // local (-1, -1, 0)
}

// ---------------------------------------------------------------------------------------
// Real-world files: default camera and light, camera choice, extension refusals, notes.
// ---------------------------------------------------------------------------------------
namespace {

std::string Base64(const std::string& aBytes) {
    static const char* const kDigits = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string text;
    for (size_t i = 0; i < aBytes.size(); i += 3) {
        const size_t count = std::min<size_t>(3, aBytes.size() - i);  // bytes in this group
        uint32_t group = 0;
        for (size_t k = 0; k < 3; k++) group = (group << 8) | (k < count ? uint8_t(aBytes[i + k]) : 0u);
        for (size_t k = 0; k < 4; k++) text += k <= count ? kDigits[(group >> (18 - 6 * k)) & 63] : '=';
    }
    return text;
}

// A glTF of one mesh (non-indexed triangles, 9 floats each) with aNodes spliced in
// after the mesh node (node 0), and aTopLevel spliced into the top-level object.
std::string MeshGltf(const std::vector<float>& aTriangles, const std::string& aNodes = "", const std::string& aTopLevel = "",
                     const std::string& aMaterial = R"({"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1]}})") {
    const std::string bytes(reinterpret_cast<const char*>(aTriangles.data()), aTriangles.size() * sizeof(float));
    return R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
  "nodes": [{"mesh": 0)" + std::string(aNodes.empty() ? "" : ", \"children\": [1]") + "}" + aNodes + R"(],
  "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}]}],
  "materials": [)" + aMaterial + R"(],
  "accessors": [{"bufferView": 0, "componentType": 5126, "count": )" + std::to_string(aTriangles.size() / 3) + R"(, "type": "VEC3"}],
  "bufferViews": [{"buffer": 0, "byteLength": )" + std::to_string(bytes.size()) + R"(}],
  "buffers": [{"byteLength": )" + std::to_string(bytes.size()) + R"(, "uri": "data:application/octet-stream;base64,)" + Base64(bytes) + "\"}]" +
           aTopLevel + "}";
}

// A unit cube [-1, 1]^3 moved by aOffset, as 12 triangles wound outwards (or inwards).
std::vector<float> Cube(const Vec3& aOffset, bool aInwards = false) {
    const int faces[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    std::vector<float> triangles;
    auto corner = [&](int aIndex) { return aOffset + Vec3(aIndex & 1 ? 1.f : -1.f, aIndex & 2 ? 1.f : -1.f, aIndex & 4 ? 1.f : -1.f); };
    for (const auto& face : faces) {
        const int order[2][3] = {{face[0], face[1], face[2]}, {face[0], face[2], face[3]}};
        for (const auto& t : order)
            for (int k = 0; k < 3; k++) {
                const Vec3 p = corner(t[aInwards ? 2 - k : k]);
                triangles.insert(triangles.end(), {p.x, p.y, p.z});
            }
    }
    return triangles;
}

std::string WriteTemporary(const testutil::TemporaryFolder& aFolder, const std::string& aName, const std::string& aText) {
    const std::string path = aFolder / aName;
    std::ofstream(path) << aText;
    return path;
}

std::string LoadError(const std::string& aPath, const GltfLoadOptions& aOptions = {}) {
    try {
        LoadGltfScene(aPath, nullptr, aOptions);
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

// aText with its one occurrence of aFrom replaced by aTo.
std::string Replaced(std::string aText, const std::string& aFrom, const std::string& aTo) {
    const size_t at = aText.find(aFrom);
    REQUIRE(at != std::string::npos);
    REQUIRE(aText.find(aFrom, at + 1) == std::string::npos);
    return aText.replace(at, aFrom.size(), aTo);
}

} // namespace

TEST_CASE("The test cube is closed and wound outwards", "[gltf]") {
    const std::vector<float> cube = Cube(Vec3(0.f));
    REQUIRE(cube.size() == 12 * 9);
    double volume = 0.0;
    for (size_t t = 0; t < cube.size(); t += 9) {
        const glm::dvec3 a(cube[t], cube[t + 1], cube[t + 2]), b(cube[t + 3], cube[t + 4], cube[t + 5]), c(cube[t + 6], cube[t + 7], cube[t + 8]);
        volume += glm::dot(a, glm::cross(b, c)) / 6.0;
    }
    CHECK(volume == Approx(8.0));
}

TEST_CASE("A file without a camera gets one that frames every corner of the scene at the image's aspect", "[gltf]") {
    testutil::TemporaryFolder folder;
    const Vec3 offset(3.f, -2.f, 5.f);  // the default camera must follow the geometry, not the origin
    const std::string path = WriteTemporary(folder, "cube.gltf", MeshGltf(Cube(offset)));
    for (const int width : {64, 128, 32}) {
        INFO("aspect " << width << ":64");
        GltfLoadOptions options;
        options.mDefaultCameraAspect = float(width) / 64.f;
        GltfLoadReport report;
        Scene scene = LoadGltfScene(path, &report, options);
        scene.mCamera.SetResolution(width, 64);
        CHECK(report.mDefaultCamera);
        CHECK_THAT(report.mCamera, Catch::StartsWith("a default camera"));
        const Camera& camera = scene.mCamera;
        const Vec3 toCenter = offset - camera.Position();
        CHECK(glm::dot(glm::normalize(toCenter), camera.Forward()) == Approx(1.f).margin(1e-5));
        CHECK(camera.Position().y > offset.y);  // a little above
        CHECK(camera.Position().z > offset.z);  // in front: glTF's front is +Z
        for (int c = 0; c < 8; c++) {
            const Vec3 corner = offset + Vec3(c & 1 ? 1.f : -1.f, c & 2 ? 1.f : -1.f, c & 4 ? 1.f : -1.f);
            const std::optional<Vec2> raster = camera.WorldToRaster(corner);
            REQUIRE(raster.has_value());
            CHECK(raster->x >= 0.f);
            CHECK(raster->x <= float(width));
            CHECK(raster->y >= 0.f);
            CHECK(raster->y <= 64.f);
        }
    }
}

namespace {

// An axis-aligned box of aCenter +- aHalf, as 12 triangles wound outwards (or inwards).
std::vector<float> Box(const Vec3& aCenter, const Vec3& aHalf, bool aInwards = false) {
    std::vector<float> triangles = Cube(Vec3(0.f), aInwards);
    for (size_t i = 0; i < triangles.size(); i++) triangles[i] = aCenter[int(i % 3)] + aHalf[int(i % 3)] * triangles[i];
    return triangles;
}

// A closed room, x in [-4, 4], y in [0, 3], z in [-3, 3], wound inwards, with a table (a
// top at y 0.75-0.85 and a leg) in the middle, wound outwards; without its ceiling (the
// two triangles at y = 3) when aOpenTop, as an atrium or a courtyard.
std::vector<float> RoomWithTable(bool aOpenTop = false) {
    std::vector<float> room = Box(Vec3(0.f, 1.5f, 0.f), Vec3(4.f, 1.5f, 3.f), true);
    if (aOpenTop) room.erase(room.begin() + 6 * 9, room.begin() + 8 * 9);  // Cube's fourth face is +y
    for (const std::vector<float>& part : {Box(Vec3(0.f, 0.8f, 0.f), Vec3(0.6f, 0.05f, 0.4f)),
                                           Box(Vec3(0.f, 0.375f, 0.f), Vec3(0.05f, 0.375f, 0.05f))})
        room.insert(room.end(), part.begin(), part.end());
    return room;
}

} // namespace

TEST_CASE("A file without a camera whose geometry encloses its centre gets a camera inside that sees the inner faces", "[gltf][interior]") {
    testutil::TemporaryFolder folder;
    for (const bool openTop : {false, true}) {
        INFO((openTop ? "open to the sky" : "closed room"));
        const std::string path = WriteTemporary(folder, openTop ? "court.gltf" : "room.gltf", MeshGltf(RoomWithTable(openTop)));
        GltfLoadOptions options;
        options.mDefaultCameraAspect = 1.5f;
        GltfLoadReport report;
        Scene scene = LoadGltfScene(path, &report, options);
        scene.mCamera.SetResolution(48, 32);
        CHECK(report.mDefaultCamera);
        REQUIRE(report.mInteriorCamera);
        CHECK_THAT(report.mCamera, Catch::Contains("inside") && Catch::Contains("looking along -X"));
        // Level along the longer axis (x), back from the centre towards +x and lowered
        // to half way between the centre (y 1.5) and the table top below it (y 0.85).
        const Camera& camera = scene.mCamera;
        CHECK_VEC3(camera.Forward(), Vec3(-1.f, 0.f, 0.f), 1e-6f);
        CHECK_VEC3(camera.Position(), Vec3(0.6f * 4.f, 1.5f - 0.5f * 0.65f, 0.f), 1e-5f);
        // Every primary ray meets a surface that faces the camera (no outside of a wall),
        // and some meet the table.
        int tableHits = 0;
        for (int y = 0; y < 32; y += 3)
            for (int x = 0; x < 48; x += 3) {
                const Ray ray = camera.GenerateRay(Vec2(float(x) + 0.5f, float(y) + 0.5f));
                const SurfacePoint hit = scene.Intersect(ray);
                if (openTop && !hit.IsValid()) continue;  // the sky through the open top
                REQUIRE(hit.IsValid());
                INFO("raster " << x << ", " << y);
                CHECK(glm::dot(hit.GeometricNormal(), ray.mDirection) < 0.f);
                const Vec3 point = hit.mPosition;
                if (point.y > 1e-3f && point.y < 0.851f && std::abs(point.x) < 0.601f && std::abs(point.z) < 0.401f) tableHits++;
            }
        CHECK(tableHits > 0);
        // The room has no light: the default sky and sun, and the note says they reach an
        // interior only through its openings.
        bool noted = false, shellNoted = false;
        for (const std::string& note : report.mNotes) {
            noted = noted || note.find("inside an interior") != std::string::npos;
            // The room is a closed mesh wound inwards (only when closed): its note says why.
            shellNoted = shellNoted || (note.find("looks inside-out") != std::string::npos &&
                                        note.find("for the shell of an interior, facing inwards is right") != std::string::npos);
        }
        CHECK(noted);
        CHECK(shellNoted != openTop);
    }
}

TEST_CASE("The interior test passes through doubleSided sheets and keeps the outside camera for closed objects", "[gltf][interior]") {
    testutil::TemporaryFolder folder;
    GltfLoadReport report;
    // A closed room with a curtain across it at x = 2, a doubleSided sheet whose front
    // (its winding's side, +x) faces away from the centre: the room is still an interior.
    std::vector<float> triangles = Box(Vec3(0.f, 1.5f, 0.f), Vec3(4.f, 1.5f, 3.f), true);
    const std::vector<float> curtain = {2.f, 0.f, -3.f, 2.f, 3.f, 3.f, 2.f, 0.f, 3.f, 2.f, 0.f, -3.f, 2.f, 3.f, -3.f, 2.f, 3.f, 3.f};
    REQUIRE(glm::cross(Vec3(0.f, 3.f, 6.f), Vec3(0.f, 0.f, 6.f)).x > 0.f);  // the first curtain triangle's normal
    triangles.insert(triangles.end(), curtain.begin(), curtain.end());
    const std::string bytes(reinterpret_cast<const char*>(triangles.data()), triangles.size() * sizeof(float));
    const std::string file = R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
  "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}, {"attributes": {"POSITION": 1}, "material": 1}]}],
  "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1]}},
                {"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.1, 0.1, 1]}, "doubleSided": true}],
  "accessors": [{"bufferView": 0, "componentType": 5126, "count": 36, "type": "VEC3"},
                {"bufferView": 0, "byteOffset": 432, "componentType": 5126, "count": 6, "type": "VEC3"}],
  "bufferViews": [{"buffer": 0, "byteLength": )" + std::to_string(bytes.size()) + R"(}],
  "buffers": [{"byteLength": )" + std::to_string(bytes.size()) + R"(, "uri": "data:application/octet-stream;base64,)" +
                             Base64(bytes) + "\"}]}";
    const Scene room = LoadGltfScene(WriteTemporary(folder, "curtain.gltf", file), &report);
    CHECK(report.mInteriorCamera);
    // The camera looks along -X (the longer axis) and steps back towards +X: not past the
    // curtain, which would fill its view with the sheet's back.
    CHECK(room.mCamera.Forward().x < -0.99f);
    CHECK(room.mCamera.Position().x < 2.f);
    // A closed object (the centre inside it sees only back faces) keeps the outside camera.
    LoadGltfScene(WriteTemporary(folder, "block.gltf", MeshGltf(Box(Vec3(0.f, 1.5f, 0.f), Vec3(4.f, 1.5f, 3.f)))), &report);
    CHECK(report.mDefaultCamera);
    CHECK_FALSE(report.mInteriorCamera);
    CHECK_THAT(report.mCamera, Catch::Contains("from the front"));
}

TEST_CASE("The repository's files without a camera keep the outside default camera, to the bit", "[gltf][interior]") {
    // Position and forward as the loader gave them before interiors were detected (8a62683),
    // printed with 9 significant digits, which give a float back exactly.
    const struct {
        const char* mPath;
        Vec3 mPosition, mForward;
    } cases[] = {{"../scenes/textured_torus.gltf", Vec3(0.f, 1.43331516f, 5.34920502f), Vec3(0.f, -0.258819073f, -0.965925932f)},
                 {"../scenes/avocado/Avocado.gltf", Vec3(0.f, 0.0581622794f, 0.099877581f), Vec3(0.f, -0.258819073f, -0.965925932f)}};
    for (const auto& c : cases) {
        INFO(c.mPath);
        GltfLoadReport report;
        const Scene scene = LoadGltfScene(c.mPath, &report);
        CHECK(report.mDefaultCamera);
        CHECK_FALSE(report.mInteriorCamera);
        CHECK(scene.mCamera.Position() == c.mPosition);
        CHECK(scene.mCamera.Forward() == c.mForward);
    }
}

TEST_CASE("GltfLoadOptions::mCamera picks the N-th camera node and refuses one out of range", "[gltf]") {
    testutil::TemporaryFolder folder;
    const std::string cameras = R"(, {"camera": 0, "translation": [0, 0, 10], "children": [2]}, {"camera": 1, "translation": [0, 0, 5]})";
    const std::string path = WriteTemporary(folder, "two.gltf", MeshGltf(Cube(Vec3(0.f)), cameras, R"(, "cameras": [
        {"type": "perspective", "name": "far", "perspective": {"yfov": 0.5, "znear": 0.1}},
        {"type": "perspective", "name": "near", "perspective": {"yfov": 0.5, "znear": 0.1}}])"));
    GltfLoadOptions options;
    GltfLoadReport report;
    CHECK(LoadGltfScene(path, &report, options).mCamera.Position().z == Approx(10.f));
    CHECK_THAT(report.mCamera, Catch::StartsWith("camera node 0") && Catch::Contains("'far'"));
    options.mCamera = 1;
    // Node 2 is a child of node 1: its world position is 10 + 5.
    CHECK(LoadGltfScene(path, &report, options).mCamera.Position().z == Approx(15.f));
    CHECK_THAT(report.mCamera, Catch::StartsWith("camera node 1") && Catch::Contains("'near'"));
    options.mCamera = 2;
    CHECK(LoadError(path, options) == path + ": camera 2 was asked for, but the scene has 2 camera node(s) (0..1)");
}

namespace {

// The default light of a file without one (AddDefaultSkyAndSun): exactly one background
// light with an environment map (the sky) and one directional light (the sun), from above
// (50 degrees up: y = sin 50 > 0.7), from behind the camera and from its left.
void CheckDefaultSkyAndSun(const Scene& aScene) {
    const Light* sky = nullptr;
    const Light* sun = nullptr;
    int backgrounds = 0, directionals = 0;
    for (const Light& light : aScene.mLights) {
        if (light.mType == LightType::kBackground) { backgrounds++; sky = &light; }
        if (light.mType == LightType::kDirectional) { directionals++; sun = &light; }
    }
    REQUIRE(backgrounds == 1);
    REQUIRE(directionals == 1);
    REQUIRE(sky->mEnvironment != nullptr);
    CHECK(sky->mEmission == Vec3(1.f));
    // The sky: bluish at the zenith, brighter at the horizon, a darker ground; never white,
    // so that a white model stands out from it.
    const Vec3 zenith = sky->mEnvironment->Radiance(Vec3(0.f, 1.f, 0.f));
    const Vec3 nadir = sky->mEnvironment->Radiance(Vec3(0.f, -1.f, 0.f));
    const Vec3 horizon = sky->mEnvironment->Radiance(glm::normalize(Vec3(1.f, 0.02f, 0.f)));
    CHECK_VEC3(zenith, Vec3(0.22f, 0.3f, 0.45f), 1e-3f);
    CHECK_VEC3(nadir, Vec3(0.2f, 0.19f, 0.18f), 1e-6f);
    CHECK(Luminance(horizon) > Luminance(zenith));
    CHECK(Luminance(nadir) < Luminance(zenith));
    CHECK(sky->mEnvironment->BrightestTexel().x < 0.7f);
    // The sun: its irradiance, and where it comes from relative to the camera.
    CHECK(sun->mEmission == Vec3(3.f, 2.9f, 2.7f));
    const Vec3 toSun = -sun->mDirection;
    INFO("to the sun " << toSun.x << " " << toSun.y << " " << toSun.z);
    CHECK(toSun.y > 0.7f);
    CHECK(toSun.y == Approx(std::sin(50.f * kPi / 180.f)).margin(1e-5));
    CHECK(glm::dot(toSun, aScene.mCamera.Forward()) < 0.f);
    CHECK(glm::dot(toSun, aScene.mCamera.Right()) < 0.f);
}

} // namespace

TEST_CASE("A file without an emitter gets the default sky and sun, which the options replace or remove", "[gltf]") {
    testutil::TemporaryFolder folder;
    const std::string path = WriteTemporary(folder, "unlit.gltf", MeshGltf(Cube(Vec3(0.f))));
    GltfLoadReport report;
    const Scene scene = LoadGltfScene(path, &report);
    CHECK(report.mDefaultBackground);
    REQUIRE(scene.mLights.size() == 2);
    CheckDefaultSkyAndSun(scene);
    // One note, which names what was added and how to change it.
    REQUIRE(report.mNotes.size() == 1);
    CHECK(report.mNotes[0] == "the scene has no light: added the default sky and sun (a sun from above, behind and left of the "
                              "camera; --envmap FILE, --background R,G,B or --background none replace them)");

    // The sun follows the camera: a camera node turned 90 degrees about +Y (it looks along
    // -X) gets a sun from +X (behind it) and +Z (its left).
    const std::string turned = WriteTemporary(folder, "turned.gltf", MeshGltf(Cube(Vec3(0.f)),
        R"(, {"camera": 0, "translation": [10, 0, 0], "rotation": [0, 0.70710678, 0, 0.70710678]})",
        R"(, "cameras": [{"type": "perspective", "perspective": {"yfov": 0.5, "znear": 0.1}}])"));
    const Scene turnedScene = LoadGltfScene(turned, &report);
    CHECK(report.mDefaultBackground);
    CHECK(turnedScene.mCamera.Forward().x == Approx(-1.f).margin(1e-5));
    CheckDefaultSkyAndSun(turnedScene);
    const Vec3 toSun = -turnedScene.mLights[1].mDirection;
    CHECK(toSun.x > 0.f);
    CHECK(toSun.z > 0.f);

    GltfLoadOptions options;
    options.mBackground = GltfLoadOptions::Background::kNone;
    CHECK(LoadError(path, options) == path + ": the scene has no light: --background none removes the background and the file "
                                              "has no other light; give a non-black --background R,G,B, or add lights to the file");
    // A background radiance replaces sky and sun: one uniform background, no sun.
    options.mBackground = GltfLoadOptions::Background::kRadiance;
    options.mBackgroundRadiance = Vec3(0.25f, 0.5f, 2.f);
    {
        const Scene uniform = LoadGltfScene(path, &report, options);
        CHECK_FALSE(report.mDefaultBackground);
        REQUIRE(uniform.mLights.size() == 1);
        CHECK(uniform.mLights[0].mType == LightType::kBackground);
        CHECK(uniform.mLights[0].mEnvironment == nullptr);
        CHECK(uniform.mLights[0].mEmission == options.mBackgroundRadiance);
        CHECK(report.mNotes.empty());
    }
    // So does an environment map: one background light with the map, no sun.
    {
        Image map(8, 4);
        for (Vec3& texel : map.mPixels) texel = Vec3(0.5f, 1.f, 2.f);
        WriteImage(folder / "map.pfm", map);
        GltfLoadOptions environment;
        environment.mEnvironmentMap = folder / "map.pfm";
        environment.mEnvironmentScale = 3.f;
        const Scene lit = LoadGltfScene(path, &report, environment);
        CHECK_FALSE(report.mDefaultBackground);
        REQUIRE(lit.mLights.size() == 1);
        CHECK(lit.mLights[0].mType == LightType::kBackground);
        REQUIRE(lit.mLights[0].mEnvironment != nullptr);
        CHECK(lit.mLights[0].mEmission == Vec3(3.f));
        CHECK(lit.mLights[0].mEnvironment->Radiance(Vec3(0.f, 0.f, 1.f)) == Vec3(0.5f, 1.f, 2.f));
        CHECK(report.mNotes.empty());
        // With a background option as well it is refused, not guessed.
        environment.mBackground = GltfLoadOptions::Background::kNone;
        CHECK_THAT(LoadError(path, environment), Catch::Contains("an environment map and a background radiance (or none) both replace the background"));
    }
    // Replacing the background of a scene that has one (Cornell scene 3), and adding one to
    // a scene lit otherwise (Cornell scene 4: its ceiling light stays); neither gets a sun.
    for (int cornell : {3, 4}) {
        const size_t lightsInFile = LoadGltfScene(CornellPath(cornell)).mLights.size();
        const Scene lit = LoadGltfScene(CornellPath(cornell), &report, options);
        int backgrounds = 0;
        for (const Light& light : lit.mLights)
            if (light.mType == LightType::kBackground) {
                backgrounds++;
                CHECK(light.mEmission == options.mBackgroundRadiance);
            }
        CHECK(backgrounds == 1);
        CHECK_FALSE(report.mDefaultBackground);
        CHECK(lit.mLights.size() == (cornell == 3 ? lightsInFile : lightsInFile + 1));
    }
}

TEST_CASE("A black background is no light: refused as none is when nothing else emits, and not added beside other lights", "[gltf]") {
    testutil::TemporaryFolder folder;
    const std::string unlit = WriteTemporary(folder, "unlit.gltf", MeshGltf(Cube(Vec3(0.f))));
    GltfLoadOptions black;
    black.mBackground = GltfLoadOptions::Background::kRadiance;
    black.mBackgroundRadiance = Vec3(0.f);
    CHECK(LoadError(unlit, black) == unlit + ": the scene has no light: --background 0,0,0 is black and the file has no other "
                                             "light; give a non-black --background R,G,B, or add lights to the file");
    // Cornell scene 3 is lit by its background alone: replaced by a black one, nothing emits.
    CHECK_THAT(LoadError(CornellPath(3), black), Catch::StartsWith(CornellPath(3) + ": the scene has no light: --background 0,0,0"));
    // Cornell scene 4 keeps its ceiling light, and no black background is added to be sampled.
    const Scene lit = LoadGltfScene(CornellPath(4), nullptr, black);
    CHECK(lit.mLights.size() == LoadGltfScene(CornellPath(4)).mLights.size());
    CHECK(lit.GetBackground() == nullptr);
    // The file's own lights that emit nothing count as none, whatever the option.
    const std::string blackInFile = WriteTemporary(folder, "black_background.gltf", MeshGltf(Cube(Vec3(0.f)), "",
        R"(, "extensionsUsed": ["SMALLVCM_background"], "extensions": {"SMALLVCM_background": {"radiance": [0, 0, 0]}})"));
    CHECK(LoadError(blackInFile) == blackInFile + ": the scene has no light: the file's 1 light emits nothing (zero intensity or "
                                                  "black radiance); give a non-black --background R,G,B, or lights that emit");
    GltfLoadOptions white;
    white.mBackground = GltfLoadOptions::Background::kRadiance;
    CHECK(LoadGltfScene(blackInFile, nullptr, white).GetBackground()->mEmission == Vec3(1.f));
}

TEST_CASE("Every unsupported required extension is named in one line, each with its hint", "[gltf]") {
    testutil::TemporaryFolder folder;
    // KHR_lights_punctual and KHR_mesh_quantization are modelled; KHR_texture_basisu, listed twice, is named once.
    const std::string path = WriteTemporary(folder, "several.gltf", R"({"asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_lights_punctual", "KHR_texture_basisu", "EXT_unknown_feature", "EXT_texture_webp", "KHR_mesh_quantization"],
        "extensionsRequired": ["KHR_lights_punctual", "KHR_texture_basisu", "EXT_unknown_feature", "EXT_texture_webp",
                               "KHR_mesh_quantization", "KHR_texture_basisu"],
        "buffers": [{"byteLength": 100, "uri": "missing.bin"}], "scenes": [{"nodes": []}]})");
    CHECK(LoadError(path) == path + ": required extensions KHR_texture_basisu, 'EXT_unknown_feature' and EXT_texture_webp "
                                    "are not supported: KHR_texture_basisu: its textures are KTX2/Basis: convert them to PNG or "
                                    "JPEG first (e.g. re-export with PNG textures); EXT_texture_webp: its textures are WebP: "
                                    "convert them to PNG or JPEG first");
    // A list longer than a line ends in how many more there are.
    std::string many;
    for (int e = 0; e < 11; e++) many += std::string(e > 0 ? ", " : "") + "\"EXT_unknown_" + std::to_string(e) + "\"";
    const std::string manyPath = WriteTemporary(folder, "many.gltf", R"({"asset": {"version": "2.0"}, "extensionsRequired": [)" +
                                                                     many + R"(], "scenes": [{"nodes": []}]})");
    CHECK(LoadError(manyPath) == manyPath + ": required extensions 'EXT_unknown_0', 'EXT_unknown_1', 'EXT_unknown_2', "
                                            "'EXT_unknown_3', 'EXT_unknown_4', 'EXT_unknown_5', 'EXT_unknown_6', "
                                            "'EXT_unknown_7' and 3 more are not supported");
}

TEST_CASE("A meshopt-compressed buffer view is decoded, its fallback buffer holding the plain bytes or nothing", "[gltf][compressed]") {
    testutil::TemporaryFolder folder;
    const std::vector<float> cube = Cube(Vec3(0.f));
    const std::string bytes(reinterpret_cast<const char*>(cube.data()), cube.size() * sizeof(float));
    std::vector<unsigned char> encoded(meshopt_encodeVertexBufferBound(36, 12));
    encoded.resize(meshopt_encodeVertexBuffer(encoded.data(), encoded.size(), cube.data(), 36, 12));
    const std::string compressed(encoded.begin(), encoded.end());
    // The view's compressed bytes are buffer 0; its own buffer, 1, is the fallback.
    const std::string meshopt = Replaced(MeshGltf(cube, "", R"(, "extensionsUsed": ["EXT_meshopt_compression"])"),
        R"("bufferViews": [{"buffer": 0, )",
        R"("bufferViews": [{"buffer": 1, "byteStride": 12, "extensions": {"EXT_meshopt_compression": {"buffer": 0, "byteLength": )" +
            std::to_string(compressed.size()) + R"(, "byteStride": 12, "count": 36, "mode": "ATTRIBUTES"}}, )");
    const std::string withCompressed = Replaced(Replaced(meshopt, Base64(bytes), Base64(compressed)),
                                                R"("buffers": [{"byteLength": 432, )",
                                                R"("buffers": [{"byteLength": )" + std::to_string(compressed.size()) + ", ");
    const std::string marked = R"("extensions": {"EXT_meshopt_compression": {"fallback": true}})";
    const auto sameCube = [&](const std::string& aPath) {
        const Scene scene = LoadGltfScene(aPath);
        REQUIRE(scene.mTriangles.size() == 12);
        for (size_t t = 0; t < 12; t++) CHECK(scene.mTriangles[t].mP0 == Vec3(cube[9 * t], cube[9 * t + 1], cube[9 * t + 2]));
    };
    SECTION("the fallback holds the plain bytes: they are not what is read") {
        sameCube(WriteTemporary(folder, "meshopt_fallback.gltf", Replaced(withCompressed, R"("}], "extensionsUsed")",
            R"("}, {"byteLength": 432, "uri": "data:application/octet-stream;base64,)" + Base64(std::string(432, '\0')) + "\", " +
                marked + R"(}], "extensionsUsed")")));
    }
    SECTION("the fallback holds nothing (no URI), in a .gltf") {
        sameCube(WriteTemporary(folder, "meshopt_only.gltf", Replaced(withCompressed, R"("}], "extensionsUsed")",
            R"("}, {"byteLength": 432, )" + marked + R"(}], "extensionsUsed")")));
    }
    SECTION("a buffer without a URI that is no fallback is refused") {
        const std::string path = WriteTemporary(folder, "unmarked.gltf", Replaced(MeshGltf(cube), R"("}]})", R"("}, {"byteLength": 4}]})"));
        CHECK_THAT(LoadError(path), Catch::StartsWith(path + ": buffer 1 has no URI"));
    }
}

TEST_CASE("Required extensions that are not modelled are refused before any buffer is read, with how to get a plain file", "[gltf]") {
    testutil::TemporaryFolder folder;
    // The buffer names a file that does not exist: reading buffers first would report that.
    const std::string base = R"({"asset": {"version": "2.0"}, "extensionsUsed": ["EXT"], "extensionsRequired": ["EXT"],
        "buffers": [{"byteLength": 100, "uri": "missing.bin"}], "scenes": [{"nodes": []}]})";
    const struct {
        const char* mExtension;
        const char* mAdvice;
    } cases[] = {{"KHR_texture_basisu", "KTX2/Basis: convert them to PNG or JPEG"},
                 {"EXT_texture_webp", "WebP: convert them to PNG or JPEG"}};
    for (const auto& c : cases) {
        std::string json = base;
        for (size_t at; (at = json.find("\"EXT\"")) != std::string::npos;) json.replace(at, 5, std::string("\"") + c.mExtension + "\"");
        const std::string path = WriteTemporary(folder, std::string(c.mExtension) + ".gltf", json);
        CHECK_THAT(LoadError(path), Catch::StartsWith(path + ": required extension " + c.mExtension + " is not supported: "));
        CHECK_THAT(LoadError(path), Catch::Contains(c.mAdvice));
    }
}

TEST_CASE("Extensions used but not required and not modelled are listed in one note", "[gltf]") {
    testutil::TemporaryFolder folder;
    const std::string path = WriteTemporary(folder, "used.gltf", MeshGltf(Cube(Vec3(0.f)), "",
        R"(, "extensionsUsed": ["KHR_materials_clearcoat", "KHR_materials_sheen", "KHR_materials_emissive_strength"])"));
    GltfLoadReport report;
    LoadGltfScene(path, &report);
    int listing = 0;
    for (const std::string& note : report.mNotes)
        if (note.find("ignored extensions") != std::string::npos) {
            listing++;
            CHECK_THAT(note, Catch::Contains("KHR_materials_clearcoat, KHR_materials_sheen"));
            CHECK_THAT(note, !Catch::Contains("emissive_strength"));  // that one is modelled
        }
    CHECK(listing == 1);
}

TEST_CASE("A closed mesh wound inwards is noted as inside-out; outward, open and non-manifold meshes are not", "[gltf]") {
    testutil::TemporaryFolder folder;
    std::vector<float> open = Cube(Vec3(0.f), true);
    open.resize(open.size() - 9);  // one triangle less: a hole
    std::vector<float> doubled = Cube(Vec3(0.f), true);
    doubled.insert(doubled.end(), doubled.begin(), doubled.begin() + 9);  // one triangle twice: not a 2-manifold
    const struct {
        std::vector<float> mTriangles;
        bool mInsideOut;
    } cases[] = {{Cube(Vec3(0.f)), false}, {Cube(Vec3(0.f), true), true}, {open, false}, {doubled, false}};
    int index = 0;
    for (const auto& c : cases) {
        const std::string path = WriteTemporary(folder, "mesh" + std::to_string(index++) + ".gltf", MeshGltf(c.mTriangles));
        GltfLoadReport report;
        LoadGltfScene(path, &report);
        bool noted = false;
        for (const std::string& note : report.mNotes) noted = noted || note.find("looks inside-out") != std::string::npos;
        CHECK(noted == c.mInsideOut);
    }
}

TEST_CASE("A note about a mesh is made once however many nodes place it, with the count of the others", "[gltf]") {
    testutil::TemporaryFolder folder;
    // Three nodes place the inside-out cube (node 0, its child node 1 and node 1's child).
    const std::string nodes = R"(, {"mesh": 0, "translation": [5, 0, 0], "children": [2]}, {"mesh": 0, "translation": [0, 5, 0]})";
    const std::string path = WriteTemporary(folder, "three.gltf", MeshGltf(Cube(Vec3(0.f), true), nodes));
    GltfLoadReport report;
    LoadGltfScene(path, &report);
    std::vector<std::string> notes;
    for (const std::string& note : report.mNotes)
        if (note.find("looks inside-out") != std::string::npos) notes.push_back(note);
    REQUIRE(notes.size() == 1);
    CHECK_THAT(notes[0], Catch::StartsWith("node 0, mesh 0 primitive 0 looks inside-out") &&
                             Catch::EndsWith("(and in 2 more placements of mesh 0)"));
}

TEST_CASE("An inside-out mesh reflects outside only with a doubleSided material, and the note says which", "[gltf][shading]") {
    testutil::TemporaryFolder folder;
    for (bool doubleSided : {false, true}) {
        const std::string material = std::string(R"({"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1], )"
                                                 R"("metallicFactor": 0, "roughnessFactor": 1}, "doubleSided": )") +
                                     (doubleSided ? "true}" : "false}");
        const std::string path = WriteTemporary(folder, doubleSided ? "two.gltf" : "one.gltf",
                                                MeshGltf(Cube(Vec3(0.f), true), "", "", material));
        GltfLoadReport report;
        const Scene scene = LoadGltfScene(path, &report);
        std::string note;
        for (const std::string& n : report.mNotes)
            if (n.find("looks inside-out") != std::string::npos) note = n;
        INFO(note);
        CHECK_THAT(note, Catch::Contains(doubleSided ? "doubleSided material reflects on both sides" : "its outside is black"));
        // Seen from outside (+z above the cube, whose top faces down): black or not.
        const Ray ray{Vec3(0.1f, 0.2f, 3.f), Vec3(0.f, 0.f, -1.f)};
        const SurfacePoint hit = scene.Intersect(ray);
        REQUIRE(hit.IsValid());
        REQUIRE(hit.GeometricNormal().z < 0.f);
        Bsdf bsdf;
        bsdf.Setup(ray, hit, scene, Transport::kRadiance);
        CHECK(bsdf.IsValid() == doubleSided);
    }
}

// ---------------------------------------------------------------------------------
// Textures
// ---------------------------------------------------------------------------------

namespace {

// A 2x1 texture: red on the left (u < 0.5), blue on the right.
Texture RedBlue(TextureWrap aWrap) {
    Texture t;
    t.mWidth = 2;
    t.mHeight = 1;
    t.mTexels = {Vec3(1.f, 0.f, 0.f), Vec3(0.f, 0.f, 1.f)};
    t.mWrapU = t.mWrapV = aWrap;
    return t;
}

// A textured unit floor (z = 0, [0,1]^2, uv = (x, 1 - y): glTF's v runs down the image)
// under a background, written to aFolder as floor.gltf + floor.bin + the PNG aImage
// (through the renderer's own PNG writer: linear in, sRGB out), with the given wrap mode
// and the floor's uv scaled by aUvScale.
std::string WriteTexturedFloor(const TemporaryFolder& aFolder, const Image& aImage, int aGltfWrap, float aUvScale) {
    WriteImage(aFolder / "base colour.png", aImage);
    const float positions[12] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
    const float uvs[8] = {0, aUvScale, aUvScale, aUvScale, aUvScale, 0, 0, 0};
    const uint32_t indices[6] = {0, 1, 2, 2, 3, 0};
    std::string bin(reinterpret_cast<const char*>(positions), sizeof positions);
    bin.append(reinterpret_cast<const char*>(uvs), sizeof uvs);
    bin.append(reinterpret_cast<const char*>(indices), sizeof indices);
    std::ofstream(aFolder / "floor.bin", std::ios::binary) << bin;
    std::ostringstream json;
    json << R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0}]}],
      "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.5, 1, 1, 1], "metallicFactor": 0,
                     "roughnessFactor": 1, "baseColorTexture": {"index": 0}}}],
      "textures": [{"source": 0, "sampler": 0}], "images": [{"uri": "base%20colour.png"}],
      "samplers": [{"wrapS": )" << aGltfWrap << R"(, "wrapT": )" << aGltfWrap << R"(}],
      "buffers": [{"uri": "floor.bin", "byteLength": )" << bin.size() << R"(}],
      "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 32},
                      {"buffer": 0, "byteOffset": 80, "byteLength": 24}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
                    {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
                    {"bufferView": 2, "componentType": 5125, "count": 6, "type": "SCALAR"}]})";
    std::ofstream(aFolder / "floor.gltf") << json.str();
    return aFolder / "floor.gltf";
}

// The base-colour texel the scene finds at (x, y) on the floor, seen from above.
Vec3 TexelAt(const Scene& aScene, float aX, float aY) {
    const SurfacePoint hit = aScene.Intersect(Ray{Vec3(aX, aY, 1.f), Vec3(0.f, 0.f, -1.f)});
    REQUIRE(hit.IsValid());
    return aScene.BaseColorTexel(hit);
}

} // namespace

TEST_CASE("Texture lookup: bilinear between texel centres, and each wrap mode outside [0, 1]", "[gltf][textures]") {
    const Vec3 red(1.f, 0.f, 0.f), blue(0.f, 0.f, 1.f), half(0.5f, 0.f, 0.5f);
    for (TextureWrap wrap : {TextureWrap::kRepeat, TextureWrap::kClampToEdge, TextureWrap::kMirroredRepeat}) {
        const Texture t = RedBlue(wrap);
        CHECK(t.Lookup(Vec2(0.25f, 0.5f)) == red);   // texel centres
        CHECK(t.Lookup(Vec2(0.75f, 0.5f)) == blue);
        CHECK(t.Lookup(Vec2(0.5f, 0.5f)) == half);   // halfway between them
        const Vec3 extreme = t.Lookup(Vec2(1e30f, std::numeric_limits<float>::quiet_NaN()));
        CHECK(IsFinite(extreme));
    }
    // At u = 0 the left neighbour is the wrapped texel: blue for repeat, red otherwise.
    CHECK(RedBlue(TextureWrap::kRepeat).Lookup(Vec2(0.f, 0.5f)) == half);
    CHECK(RedBlue(TextureWrap::kClampToEdge).Lookup(Vec2(0.f, 0.5f)) == red);
    CHECK(RedBlue(TextureWrap::kMirroredRepeat).Lookup(Vec2(0.f, 0.5f)) == red);
    // Beyond 1: repeat starts over (1.25 = 0.25: red), clamp stays at the edge (blue),
    // mirrored runs back (1.25 -> 0.75: blue), and two periods on, mirrored is red again.
    CHECK(RedBlue(TextureWrap::kRepeat).Lookup(Vec2(1.25f, 0.5f)) == red);
    CHECK(RedBlue(TextureWrap::kClampToEdge).Lookup(Vec2(1.25f, 0.5f)) == blue);
    CHECK(RedBlue(TextureWrap::kMirroredRepeat).Lookup(Vec2(1.25f, 0.5f)) == blue);
    CHECK(RedBlue(TextureWrap::kMirroredRepeat).Lookup(Vec2(2.25f, 0.5f)) == red);
    CHECK(RedBlue(TextureWrap::kRepeat).Lookup(Vec2(-0.75f, 0.5f)) == red);
}

TEST_CASE("A glTF base-colour texture is read from a PNG file, sRGB-decoded and mapped by TEXCOORD_0", "[gltf][textures]") {
    TemporaryFolder folder;
    // 2x2 image, linear colours: top row red and 0.2 grey, bottom row blue and white.
    Image image(2, 2);
    image.mPixels = {Vec3(1.f, 0.f, 0.f), Vec3(0.2f), Vec3(0.f, 0.f, 1.f), Vec3(1.f)};
    const std::string path = WriteTexturedFloor(folder, image, 33071 /* clamp */, 1.f);
    GltfLoadReport report;
    const Scene scene = LoadGltfScene(path, &report);
    REQUIRE(scene.mTextures.size() == 1);
    // uv = (x, 1 - y): the top row of the image is at y near 1. Texel centres: x, y in {0.25, 0.75}.
    CHECK(TexelAt(scene, 0.25f, 0.75f) == Vec3(1.f, 0.f, 0.f));
    CHECK(TexelAt(scene, 0.25f, 0.25f) == Vec3(0.f, 0.f, 1.f));
    CHECK(TexelAt(scene, 0.75f, 0.25f) == Vec3(1.f));
    // 0.2 linear is stored as sRGB 124/255 (0.2 -> 0.4845 -> 124); decoding gives 0.2016.
    const Vec3 grey = TexelAt(scene, 0.75f, 0.75f);
    CHECK(grey.x == Approx(0.2016f).epsilon(1e-3));
    CHECK(grey.x == grey.y);
    // The BSDF sees base colour x texel: diffuse = 0.96 x (0.5, 1, 1) x texel / pi, plus
    // the untinted dielectric specular of metallic 0 (0.04, Phong exponent 0 at roughness
    // 1: 0.04 (0 + 2) / (2 pi) = 0.04 / pi), which the texel does not colour.
    const Ray down{Vec3(0.25f, 0.75f, 1.f), Vec3(0.f, 0.f, -1.f)};
    const SurfacePoint hit = scene.Intersect(down);
    REQUIRE(hit.IsValid());
    Bsdf bsdf;
    bsdf.Setup(down, hit, scene, Transport::kRadiance);
    const Vec3 f = bsdf.Evaluate(Vec3(0.f, 0.f, 1.f)).mValue;
    CHECK(f.x == Approx((0.96f * 0.5f + 0.04f) / kPi));
    CHECK(f.y == Approx(0.04f / kPi));
    CHECK(f.z == Approx(0.04f / kPi));
    // The file has no light and no camera: both are made up, and the report says so.
    CHECK(report.mDefaultBackground);
}

TEST_CASE("The sampler's wrap mode applies to texture coordinates beyond 1", "[gltf][textures]") {
    // uv scaled by 3 across the floor: at x = 0.5, u = 1.5; 1.5 repeat -> 0.5 (half and
    // half, also in v), clamp -> 1 (the bottom-right texel), mirrored -> 0.5.
    Image image(2, 2);
    image.mPixels = {Vec3(1.f, 0.f, 0.f), Vec3(0.f, 1.f, 0.f), Vec3(0.f, 0.f, 1.f), Vec3(1.f)};
    const Vec3 average = 0.25f * (image.mPixels[0] + image.mPixels[1] + image.mPixels[2] + image.mPixels[3]);
    // u = 3x, v = 3 (1 - y); at (x, y) = (0.5, 0.5): u = v = 1.5.
    const struct { int gltf; Vec3 expected; } cases[] = {{10497, average}, {33071, Vec3(1.f)}, {33648, average}};
    for (const auto& c : cases) {
        TemporaryFolder folder;
        const Scene scene = LoadGltfScene(WriteTexturedFloor(folder, image, c.gltf, 3.f));
        INFO("wrap mode " << c.gltf);
        const Vec3 texel = TexelAt(scene, 0.5f, 0.5f);
        for (int k = 0; k < 3; k++) CHECK(texel[k] == Approx(c.expected[k]).margin(1e-5));
        // Inside the first period no wrap mode changes anything: at (x, y) = (0.1, 0.9),
        // u = v = 0.3, bilinear weights 0.9 and 0.1 on texels 0 and 1 of each axis, wholly
        // inside the image (texel centres 0.25 and 0.75).
        const Vec3 inside = TexelAt(scene, 0.1f, 0.9f);
        const Vec3 expected = 0.9f * (0.9f * image.mPixels[0] + 0.1f * image.mPixels[1]) +
                              0.1f * (0.9f * image.mPixels[2] + 0.1f * image.mPixels[3]);
        for (int k = 0; k < 3; k++) CHECK(inside[k] == Approx(expected[k]).margin(1e-5));
    }
}

namespace {

// The textured floor of WriteTexturedFloor (uv = (x, 1 - y)) with a second set of texture
// coordinates, TEXCOORD_1 = (1 - x, 1 - y) (the floor mirrored left to right), and the
// base-colour texture described by aTextureInfo (JSON, e.g. {"index": 0, "texCoord": 1}).
// aMaterialExtra goes into the material (e.g. an emissive texture).
std::string WriteFloorWithTextureInfo(const TemporaryFolder& aFolder, const Image& aImage, const std::string& aTextureInfo,
                                      const std::string& aMaterialExtra = "", int aImages = 1) {
    WriteImage(aFolder / "base colour.png", aImage);
    const float positions[12] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
    const float uv0[8] = {0, 1, 1, 1, 1, 0, 0, 0};
    const float uv1[8] = {1, 1, 0, 1, 0, 0, 1, 0};
    const uint32_t indices[6] = {0, 1, 2, 2, 3, 0};
    std::string bin(reinterpret_cast<const char*>(positions), sizeof positions);
    bin.append(reinterpret_cast<const char*>(uv0), sizeof uv0);
    bin.append(reinterpret_cast<const char*>(uv1), sizeof uv1);
    bin.append(reinterpret_cast<const char*>(indices), sizeof indices);
    std::ofstream(aFolder / "floor.bin", std::ios::binary) << bin;
    std::ostringstream json;
    json << R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
      "extensionsUsed": ["KHR_texture_transform"],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1, "TEXCOORD_1": 2}, "indices": 3, "material": 0}]}],
      "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0,
                     "roughnessFactor": 1, "baseColorTexture": )" << aTextureInfo << "}" << aMaterialExtra << R"(}],
      "textures": [)" << (aImages == 1 ? R"({"source": 0, "sampler": 0})" : R"({"source": 0, "sampler": 0}, {"source": 0, "sampler": 0})") << R"(],
      "images": [{"uri": "base%20colour.png"}],
      "samplers": [{"wrapS": 33071, "wrapT": 33071}],
      "buffers": [{"uri": "floor.bin", "byteLength": )" << bin.size() << R"(}],
      "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 32},
                      {"buffer": 0, "byteOffset": 80, "byteLength": 32}, {"buffer": 0, "byteOffset": 112, "byteLength": 24}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
                    {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
                    {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2"},
                    {"bufferView": 3, "componentType": 5125, "count": 6, "type": "SCALAR"}]})";
    std::ofstream(aFolder / "floor.gltf") << json.str();
    return aFolder / "floor.gltf";
}

// A 4 x 4 image, black but for its lower-left quadrant: from the top, blue and white,
// then red and green (colours that survive the PNG's sRGB encoding exactly).
Image QuadrantImage() {
    Image image(4, 4);
    image.mPixels.assign(16, Vec3(0.f));
    image.mPixels[2 * 4 + 0] = Vec3(0.f, 0.f, 1.f);  // column 0, row 2
    image.mPixels[2 * 4 + 1] = Vec3(1.f);            // column 1, row 2
    image.mPixels[3 * 4 + 0] = Vec3(1.f, 0.f, 0.f);  // column 0, row 3 (the bottom row)
    image.mPixels[3 * 4 + 1] = Vec3(0.f, 1.f, 0.f);  // column 1, row 3
    return image;
}

void CheckTexel(const Scene& aScene, float aX, float aY, const Vec3& aExpected) {
    const Vec3 texel = TexelAt(aScene, aX, aY);
    INFO("floor point (" << aX << ", " << aY << "): texel " << Str(texel) << ", expected " << Str(aExpected));
    for (int k = 0; k < 3; k++) CHECK(texel[k] == Approx(aExpected[k]).margin(1e-4));
}

} // namespace

TEST_CASE("KHR_texture_transform: the extension's example shows the image's lower-left quadrant turned clockwise", "[gltf][textures]") {
    // The specification's example: offset (0, 1), rotation pi/2, scale (1/2, 1/2) "utilizes
    // only the lower left quadrant of the source image, rotated clockwise 90 degrees". On
    // the floor (uv = (x, 1 - y), the image upright when seen from above) the quadrant's
    // four texels -- blue, white over red, green -- turned clockwise put red top left,
    // blue top right, green bottom left and white bottom right. A rotation the other way,
    // or u and v swapped, puts other colours (or black) there.
    TemporaryFolder folder;
    const Scene scene = LoadGltfScene(WriteFloorWithTextureInfo(folder, QuadrantImage(),
        R"({"index": 0, "extensions": {"KHR_texture_transform": {"offset": [0, 1], "rotation": 1.5707963268, "scale": [0.5, 0.5]}}})"));
    CheckTexel(scene, 0.25f, 0.75f, Vec3(1.f, 0.f, 0.f));  // top left: red
    CheckTexel(scene, 0.75f, 0.75f, Vec3(0.f, 0.f, 1.f));  // top right: blue
    CheckTexel(scene, 0.25f, 0.25f, Vec3(0.f, 1.f, 0.f));  // bottom left: green
    CheckTexel(scene, 0.75f, 0.25f, Vec3(1.f));            // bottom right: white
    // Without the extension the same points show the image's black upper-left quadrant.
    TemporaryFolder plain;
    const Scene untransformed = LoadGltfScene(WriteFloorWithTextureInfo(plain, QuadrantImage(), R"({"index": 0})"));
    CheckTexel(untransformed, 0.25f, 0.75f, Vec3(0.f));
}

TEST_CASE("KHR_texture_transform: offset and scale alone, and the texture is shared only where the transform is", "[gltf][textures]") {
    // scale (0.5, 0.5) then offset (0, 0.5): uv' = (x / 2, 1/2 + (1 - y) / 2), the lower-left
    // quadrant upright: blue top left, white top right, red bottom left, green bottom right.
    TemporaryFolder folder;
    const Scene scene = LoadGltfScene(WriteFloorWithTextureInfo(folder, QuadrantImage(),
        R"({"index": 0, "extensions": {"KHR_texture_transform": {"offset": [0, 0.5], "scale": [0.5, 0.5]}}})"));
    CheckTexel(scene, 0.25f, 0.75f, Vec3(0.f, 0.f, 1.f));
    CheckTexel(scene, 0.75f, 0.75f, Vec3(1.f));
    CheckTexel(scene, 0.25f, 0.25f, Vec3(1.f, 0.f, 0.f));
    CheckTexel(scene, 0.75f, 0.25f, Vec3(0.f, 1.f, 0.f));
    CHECK(scene.mTextures.size() == 1);
    // The same image as base colour (transformed) and as emission (not): two scene textures.
    TemporaryFolder two;
    const Scene both = LoadGltfScene(WriteFloorWithTextureInfo(two, QuadrantImage(),
        R"({"index": 0, "extensions": {"KHR_texture_transform": {"scale": [0.5, 0.5]}}})",
        R"(, "emissiveFactor": [1, 1, 1], "emissiveTexture": {"index": 1})", 2));
    CHECK(both.mTextures.size() == 2);
}

TEST_CASE("A texture reads the TEXCOORD set its textureInfo names, or KHR_texture_transform's texCoord", "[gltf][textures]") {
    // TEXCOORD_1 mirrors the floor left to right: the lower-left quadrant's red (image
    // column 0, bottom row) moves from the floor's bottom left to its bottom right.
    const Image image = QuadrantImage();
    for (const char* info : {R"({"index": 0, "texCoord": 1})",
                             R"({"index": 0, "texCoord": 0, "extensions": {"KHR_texture_transform": {"texCoord": 1}}})"}) {
        INFO(info);
        TemporaryFolder folder;
        const Scene scene = LoadGltfScene(WriteFloorWithTextureInfo(folder, image, info));
        CheckTexel(scene, 7.f / 8.f, 1.f / 8.f, Vec3(1.f, 0.f, 0.f));  // texel (0, 3) through TEXCOORD_1
        CheckTexel(scene, 1.f / 8.f, 1.f / 8.f, Vec3(0.f));            // texel (3, 3): black
    }
    TemporaryFolder folder;
    const Scene scene = LoadGltfScene(WriteFloorWithTextureInfo(folder, image, R"({"index": 0})"));
    CheckTexel(scene, 1.f / 8.f, 1.f / 8.f, Vec3(1.f, 0.f, 0.f));  // TEXCOORD_0: red bottom left
}

TEST_CASE("Bad texture transforms and texture coordinate sets are refused in one line naming the material", "[gltf][textures]") {
    const Image image = QuadrantImage();
    const struct { const char* mInfo; const char* mExtra; const char* mMessage; } cases[] = {
        {R"({"index": 0, "extensions": {"KHR_texture_transform": {"offset": [1e39, 0]}}})", "",
         "material 0: its baseColorTexture: KHR_texture_transform.offset is not finite"},
        {R"({"index": 0, "extensions": {"KHR_texture_transform": {"scale": [1, 2, 3]}}})", "",
         "material 0: its baseColorTexture: KHR_texture_transform.scale must be an array of 2 numbers"},
        {R"({"index": 0, "extensions": {"KHR_texture_transform": {"rotation": "90"}}})", "",
         "material 0: its baseColorTexture: KHR_texture_transform.rotation must be a finite number (radians)"},
        {R"({"index": 0, "extensions": {"KHR_texture_transform": {"texCoord": -1}}})", "",
         "material 0: its baseColorTexture: KHR_texture_transform.texCoord must be a non-negative integer"},
        {R"({"index": 0, "texCoord": 2})", "", ""},  // a set the primitive lacks: the primitive is named
        {R"({"index": 0, "texCoord": 99})", "", "material 0: its baseColorTexture uses TEXCOORD_99; sets 0 to 7 are read"},
        {R"({"index": 0})", R"(, "emissiveFactor": [1, 1, 1], "emissiveTexture": {"index": 0, "texCoord": 1})",
         "material 0: its baseColorTexture reads TEXCOORD_0 and its emissiveTexture TEXCOORD_1"},
    };
    for (const auto& c : cases) {
        INFO(c.mInfo << c.mExtra);
        TemporaryFolder folder;
        const std::string path = WriteFloorWithTextureInfo(folder, image, c.mInfo, c.mExtra);
        const std::string error = LoadError(path);
        if (std::string(c.mMessage).empty())
            CHECK_THAT(error, Catch::StartsWith(path + ": ") &&
                              Catch::EndsWith("mesh 0 primitive 0: its material has a baseColorTexture but the primitive has no TEXCOORD_2"));
        else
            CHECK_THAT(error, Catch::StartsWith(path + ": " + c.mMessage));
        CHECK(error.find('\n') == std::string::npos);
    }
}

namespace {

// A normal map of one texel whose stored bytes are aBytes (through the PNG writer, which
// sRGB-encodes: the linear value whose encoding is each byte), and the unit normal the
// renderer makes of it in the tangent frame (T, B, N) = (+x, +y, +z) of the floor below.
Image NormalMapImage(const glm::ivec3& aBytes) {
    const auto linear = [](int aByte) {
        const float e = float(aByte) / 255.f;
        return e <= 0.04045f ? e / 12.92f : std::pow((e + 0.055f) / 1.055f, 2.4f);
    };
    Image image(1, 1);
    image.mPixels = {Vec3(linear(aBytes.x), linear(aBytes.y), linear(aBytes.z))};
    return image;
}
Vec3 MappedNormal(const glm::ivec3& aBytes, float aScale = 1.f) {
    const Vec3 local((2.f * float(aBytes.x) / 255.f - 1.f) * aScale, (2.f * float(aBytes.y) / 255.f - 1.f) * aScale,
                     2.f * float(aBytes.z) / 255.f - 1.f);
    return glm::normalize(local);
}

// The unit floor [0,1]^2 at z = 0 with uv = (x, 1 - y) (the image upright seen from
// above), a normal map (normalTexture, JSON aNormalTexture) and, optionally, TANGENT
// (aTangent, the same at every vertex) and NORMAL (aNormal, likewise; then no normal map).
std::string WriteNormalMappedFloor(const TemporaryFolder& aFolder, const Image& aMap, const std::string& aNormalTexture,
                                   const Vec4* aTangent = nullptr, const Vec3* aNormal = nullptr) {
    WriteImage(aFolder / "normal.png", aMap);
    const float positions[12] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
    const float uvs[8] = {0, 1, 1, 1, 1, 0, 0, 0};
    const uint32_t indices[6] = {0, 1, 2, 2, 3, 0};
    std::string bin(reinterpret_cast<const char*>(positions), sizeof positions);
    bin.append(reinterpret_cast<const char*>(uvs), sizeof uvs);
    bin.append(reinterpret_cast<const char*>(indices), sizeof indices);
    std::string attributes = R"("POSITION": 0, "TEXCOORD_0": 1)", views, accessors;
    if (aTangent) {
        const size_t offset = bin.size();
        for (int v = 0; v < 4; v++) bin.append(reinterpret_cast<const char*>(aTangent), sizeof(Vec4));
        attributes += R"(, "TANGENT": 3)";
        views += R"(, {"buffer": 0, "byteOffset": )" + std::to_string(offset) + R"(, "byteLength": 64})";
        accessors += R"(, {"bufferView": 3, "componentType": 5126, "count": 4, "type": "VEC4"})";
    }
    if (aNormal) {
        const size_t offset = bin.size();
        for (int v = 0; v < 4; v++) bin.append(reinterpret_cast<const char*>(aNormal), sizeof(Vec3));
        const int index = aTangent ? 4 : 3;
        attributes += R"(, "NORMAL": )" + std::to_string(index);
        views += R"(, {"buffer": 0, "byteOffset": )" + std::to_string(offset) + R"(, "byteLength": 48})";
        accessors += R"(, {"bufferView": )" + std::to_string(index) + R"(, "componentType": 5126, "count": 4, "type": "VEC3"})";
    }
    std::ofstream(aFolder / "floor.bin", std::ios::binary) << bin;
    std::ostringstream json;
    json << R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
      "meshes": [{"primitives": [{"attributes": {)" << attributes << R"(}, "indices": 2, "material": 0}]}],
      "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1], "metallicFactor": 0,
                     "roughnessFactor": 1})" << (aNormal ? "" : R"(, "normalTexture": )" + aNormalTexture) << R"(}],
      "textures": [{"source": 0}], "images": [{"uri": "normal.png"}],
      "buffers": [{"uri": "floor.bin", "byteLength": )" << bin.size() << R"(}],
      "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 32},
                      {"buffer": 0, "byteOffset": 80, "byteLength": 24})" << views << R"(],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
                    {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
                    {"bufferView": 2, "componentType": 5125, "count": 6, "type": "SCALAR"})" << accessors << R"(]})";
    std::ofstream(aFolder / "floor.gltf") << json.str();
    return aFolder / "floor.gltf";
}

Vec3 ShadingNormalAt(const Scene& aScene, float aX, float aY) {
    const SurfacePoint hit = aScene.Intersect(Ray{Vec3(aX, aY, 1.f), Vec3(0.f, 0.f, -1.f)});
    REQUIRE(hit.IsValid());
    return hit.mShadingNormal;
}

void CheckNormal(const Vec3& aActual, const Vec3& aExpected) {
    INFO("shading normal " << Str(aActual) << ", expected " << Str(aExpected));
    for (int k = 0; k < 3; k++) CHECK(aActual[k] == Approx(aExpected[k]).margin(1e-5));
}

const glm::ivec3 kTiltRight(191, 128, 238);  // tangent space (0.5, 0.004, 0.87): towards +u
const glm::ivec3 kTiltUp(128, 191, 238);     // towards the image's up

} // namespace

TEST_CASE("A normal map tilts the shading normal: the image's right along +u, its up along the image's up", "[gltf][textures][normal_map]") {
    // On the floor, +u is +x and the image's up (decreasing v) is +y, the normal +z. A frame
    // flipped in u or in v turns one of the two tilts the wrong way.
    for (const glm::ivec3& bytes : {kTiltRight, kTiltUp}) {
        const Vec3 expected = MappedNormal(bytes);
        INFO("texel " << bytes.x << " " << bytes.y << " " << bytes.z);
        {   // tangents generated (no TANGENT), flat floor
            TemporaryFolder folder;
            const Scene scene = LoadGltfScene(WriteNormalMappedFloor(folder, NormalMapImage(bytes), R"({"index": 0})"));
            CheckNormal(ShadingNormalAt(scene, 0.3f, 0.6f), expected);
            CheckNormal(ShadingNormalAt(scene, 0.8f, 0.1f), expected);
        }
        {   // TANGENT given, right-handed: the same
            TemporaryFolder folder;
            const Vec4 tangent(1.f, 0.f, 0.f, 1.f);
            const Scene scene = LoadGltfScene(WriteNormalMappedFloor(folder, NormalMapImage(bytes), R"({"index": 0})", &tangent));
            CheckNormal(ShadingNormalAt(scene, 0.3f, 0.6f), expected);
        }
        {   // TANGENT with w = -1: the bitangent, and so the up tilt, turns over
            TemporaryFolder folder;
            const Vec4 tangent(1.f, 0.f, 0.f, -1.f);
            const Scene scene = LoadGltfScene(WriteNormalMappedFloor(folder, NormalMapImage(bytes), R"({"index": 0})", &tangent));
            CheckNormal(ShadingNormalAt(scene, 0.3f, 0.6f), Vec3(expected.x, -expected.y, expected.z));
        }
    }
    // normalTexture.scale scales the tilt's x and y.
    TemporaryFolder folder;
    const Scene scene = LoadGltfScene(WriteNormalMappedFloor(folder, NormalMapImage(kTiltRight), R"({"index": 0, "scale": 0.5})"));
    CheckNormal(ShadingNormalAt(scene, 0.5f, 0.5f), MappedNormal(kTiltRight, 0.5f));
}

TEST_CASE("A normal-mapped floor renders as the same floor with the tilted normal as its vertex normals", "[gltf][textures][normal_map]") {
    // The normal map and vertex normals are two ways to the same shading normal, so every
    // estimator -- path tracing, and light tracing and BPT, where light sub-paths need the
    // adjoint shading factor -- must render the two floors alike (the same random numbers:
    // the images differ only where float rounding of the normal changes a decision). The
    // untilted floor differs by far more (a point light off to the -x side: tilting the
    // normal towards +x turns the floor away from it), so the test can fail.
    const Vec3 tilted = MappedNormal(kTiltRight);
    const Vec3 flat(0.f, 0.f, 1.f);
    auto render = [&](const char* aKind, Algorithm aAlgorithm) {
        TemporaryFolder folder;
        const std::string kind = aKind;
        const std::string path = kind == "map" ? WriteNormalMappedFloor(folder, NormalMapImage(kTiltRight), R"({"index": 0})")
                                 : kind == "normals" ? WriteNormalMappedFloor(folder, NormalMapImage(kTiltRight), "", nullptr, &tilted)
                                                     : WriteNormalMappedFloor(folder, NormalMapImage(kTiltRight), "", nullptr, &flat);
        Scene scene = LoadGltfScene(path);  // lit by the default sky, and:
        scene.AddPointLight(Vec3(-0.5f, 0.5f, 0.8f), Vec3(20.f));
        scene.mCamera.Setup(Vec3(0.5f, -1.f, 1.5f), Vec3(0.f, 1.5f, -1.5f), Vec3(0.f, 0.f, 1.f), 50.f);
        scene.mCamera.SetResolution(24, 24);
        scene.Finalize();
        return testutil::PixelStatistics(testutil::RenderWith(scene, aAlgorithm, 8, 21).mImage).mean;
    };
    for (Algorithm algorithm : {Algorithm::kPathTracing, Algorithm::kLightTracing, Algorithm::kBidirectionalPathTracing}) {
        INFO(AlgorithmShortName(algorithm));
        const double map = render("map", algorithm), normals = render("normals", algorithm), untilted = render("flat", algorithm);
        INFO("normal map " << map << ", vertex normals " << normals << ", untilted " << untilted);
        CHECK(map == Approx(normals).epsilon(1e-3));
        CHECK(std::abs(untilted - normals) > 0.05 * normals);
    }
}

TEST_CASE("Features the renderer approximates are listed in one note", "[gltf][textures]") {
    TemporaryFolder folder;
    Image image(1, 1);
    image.mPixels = {Vec3(0.5f)};
    std::string text = ReadText(WriteTexturedFloor(folder, image, 10497, 1.f));
    const std::string material = R"("materials": [{)";
    text.replace(text.find(material), material.size(),
                 material + R"("alphaMode": "BLEND", "normalTexture": {"index": 0}, "occlusionTexture": {"index": 0}, "emissiveTexture": {"index": 0}, )");
    std::ofstream(folder / "floor.gltf") << text;
    GltfLoadReport report;
    LoadGltfScene(folder / "floor.gltf", &report);
    int notes = 0;
    for (const std::string& note : report.mNotes) {
        if (note.find("approximated (not modelled)") == std::string::npos) continue;
        notes++;
        // The emissiveTexture is modelled: with the floor's black emissiveFactor (glTF's
        // default) it changes nothing, and nothing about it is approximated. So is the
        // normalTexture (a normal map).
        CHECK_THAT(note, Catch::Contains("alphaMode BLEND (thresholded: a hole where alpha < 0.5)") && Catch::Contains("occlusionTexture") &&
                         !Catch::Contains("normalTexture") && !Catch::Contains("emissiveTexture"));
    }
    CHECK(notes == 1);
}

namespace {

// Whether the surface of a loaded tests/data/gltf/alpha_*.gltf floor is there at (aX, aY):
// a ray straight down from z = 0.5 (under the light) hits the floor, or passes a hole.
bool FloorSolidAt(const Scene& aScene, float aX, float aY) {
    const Ray down{Vec3(aX, aY, 0.5f), Vec3(0.f, 0.f, -1.f)};
    const bool hit = aScene.Intersect(down).IsValid();
    CHECK(aScene.Occluded(down.mOrigin, down.mDirection, 1.f) == hit);  // shadow rays agree
    return hit;
}

} // namespace

TEST_CASE("alphaMode MASK: alpha is baseColorFactor's times the texture's, linear, against alphaCutoff (default 0.5)",
          "[gltf][textures][cutouts]") {
    // The floors of tests/data/make_bad_gltf.py's alpha_floor: a 2 x 2 white RGBA texture
    // upright on the floor, texel centres at x, y = +-0.5 (top row at y = +0.5).
    SECTION("the default cutoff 0.5: alpha bytes 128 (0.502) solid, 127 (0.498) a hole") {
        const Scene scene = LoadGltfScene("data/gltf/alpha_mask_default.gltf");
        REQUIRE(scene.mMaterials[0].mAlphaMode == AlphaMode::kMask);
        CHECK(scene.mMaterials[0].mAlphaCutoff == 0.5f);
        CHECK(FloorSolidAt(scene, -0.5f, 0.5f));    // 255
        CHECK(FloorSolidAt(scene, 0.5f, 0.5f));     // 128
        CHECK(!FloorSolidAt(scene, -0.5f, -0.5f));  // 127
        CHECK(!FloorSolidAt(scene, 0.5f, -0.5f));   // 0
    }
    SECTION("cutoff 0.45 and factor alpha 0.8: 0.8 x 128/255 = 0.40 a hole; 0.8 x 191/255 = 0.60 solid, "
            "where an sRGB-decoded alpha (0.8 x 0.52 = 0.42) would be a hole") {
        const Scene scene = LoadGltfScene("data/gltf/alpha_mask_cutoff.gltf");
        CHECK(scene.mMaterials[0].mAlphaCutoff == 0.45f);
        CHECK(scene.mMaterials[0].mBaseColorAlpha == 0.8f);
        REQUIRE(scene.mMaterials[0].mAlphaTexture >= 0);
        const Texture& texture = scene.mTextures[size_t(scene.mMaterials[0].mAlphaTexture)];
        CHECK(texture.mAlpha == std::vector<float>{1.f, 128.f / 255.f, 191.f / 255.f, 0.f});
        CHECK(FloorSolidAt(scene, -0.5f, 0.5f));    // 255
        CHECK(!FloorSolidAt(scene, 0.5f, 0.5f));    // 128
        CHECK(FloorSolidAt(scene, -0.5f, -0.5f));   // 191
        CHECK(!FloorSolidAt(scene, 0.5f, -0.5f));   // 0
        // The base colour is the same texture (its RGB sRGB-decoded as before).
        CHECK(scene.mMaterials[0].mBaseColorTexture == scene.mMaterials[0].mAlphaTexture);
    }
    SECTION("BLEND: thresholded at 0.5, its alphaCutoff (0.9) ignored, and named in the note") {
        GltfLoadReport report;
        const Scene scene = LoadGltfScene("data/gltf/alpha_blend.gltf", &report);
        CHECK(scene.mMaterials[0].mAlphaMode == AlphaMode::kBlend);
        CHECK(FloorSolidAt(scene, 0.5f, 0.5f));     // 128: 0.502 >= 0.5
        CHECK(!FloorSolidAt(scene, -0.5f, -0.5f));  // 127
        bool noted = false;
        for (const std::string& note : report.mNotes) noted = noted || note.find("alphaMode BLEND (thresholded") != std::string::npos;
        CHECK(noted);
    }
    SECTION("textures of opaque materials keep no alpha") {
        const Scene scene = LoadGltfScene("../scenes/textured_torus.gltf");
        REQUIRE(!scene.mTextures.empty());
        for (const Texture& texture : scene.mTextures) CHECK(texture.mAlpha.empty());
        CHECK(!scene.GetBvh().HasCutOuts());
    }
}

TEST_CASE("A glTF emissiveTexture is sRGB-decoded and multiplies emissiveFactor x emissiveStrength where the light is hit", "[gltf][textures]") {
    // The textured floor of the tests above turned into an emitter: emissiveFactor
    // (2, 1, 0.5) x strength 3, the same 2 x 2 image as its emissiveTexture, no
    // baseColorTexture. A ray down onto a texel centre sees factor x strength x texel.
    // A glow map, not a lamp: the floor keeps its reflectance (base colour 0.5, metallic
    // 0: diffuse 0.96 x 0.5, Phong 0.04) and, being the file's only light, gets the default
    // sky and sun beside it.
    TemporaryFolder folder;
    Image image(2, 2);
    image.mPixels = {Vec3(1.f, 0.f, 0.f), Vec3(0.2f), Vec3(0.f, 0.f, 1.f), Vec3(1.f)};
    std::string text = ReadText(WriteTexturedFloor(folder, image, 33071 /* clamp */, 1.f));
    const std::string texture = R"("baseColorTexture": {"index": 0}}}],)";
    REQUIRE(text.find(texture) != std::string::npos);
    text.replace(text.find(texture), texture.size(),
                 R"("baseColorFactor": [0.5, 0.5, 0.5, 1]}, "emissiveFactor": [2, 1, 0.5], "emissiveTexture": {"index": 0},
                    "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 3}}}],)");
    std::ofstream(folder / "floor.gltf") << text;
    GltfLoadReport report;
    const Scene scene = LoadGltfScene(folder / "floor.gltf", &report);
    CHECK(report.mDefaultBackground);
    int glowNotes = 0;
    for (const std::string& note : report.mNotes) {
        CHECK_THAT(note, !Catch::Contains("approximated") || !Catch::Contains("emissiveTexture"));
        if (note == "the scene's only lights are emissive textures (glow maps): added the default sky and sun (a sun from above, "
                    "behind and left of the camera; --envmap FILE, --background R,G,B or --background none replace them)")
            glowNotes++;
    }
    CHECK(glowNotes == 1);
    CHECK_VEC3(scene.mMaterials.at(0).mDiffuseReflectance, Vec3(0.48f), 1e-6f);
    CHECK_VEC3(scene.mMaterials.at(0).mPhongReflectance, Vec3(0.04f), 1e-6f);
    REQUIRE(scene.LightCount() == 3);
    CheckDefaultSkyAndSun(scene);
    // --background none or R,G,B replaces both: the glow map alone, or beside a uniform
    // background, and no sun.
    {
        GltfLoadOptions none;
        none.mBackground = GltfLoadOptions::Background::kNone;
        const Scene glowOnly = LoadGltfScene(folder / "floor.gltf", &report, none);
        CHECK_FALSE(report.mDefaultBackground);
        REQUIRE(glowOnly.LightCount() == 1);
        CHECK(glowOnly.GetLight(0).mEmissionTexture >= 0);
        GltfLoadOptions grey;
        grey.mBackground = GltfLoadOptions::Background::kRadiance;
        grey.mBackgroundRadiance = Vec3(0.5f);
        const Scene withBackground = LoadGltfScene(folder / "floor.gltf", &report, grey);
        CHECK_FALSE(report.mDefaultBackground);
        REQUIRE(withBackground.LightCount() == 2);
        CHECK(withBackground.GetLight(1).mType == LightType::kBackground);
        CHECK(withBackground.GetLight(1).mEnvironment == nullptr);
    }
    const Light& light = scene.GetLight(0);
    REQUIRE(light.mEmissionTexture >= 0);
    const Vec3 scale = 3.f * Vec3(2.f, 1.f, 0.5f);
    const auto radianceAt = [&](float aX, float aY) {
        const Ray down{Vec3(aX, aY, 1.f), Vec3(0.f, 0.f, -1.f)};
        const SurfacePoint hit = scene.Intersect(down);
        REQUIRE(hit.IsValid());
        REQUIRE(hit.mLightId == 0);
        return light.GetRadiance(scene.GetSceneSphere(), down.mDirection, hit.GeometricNormal(), hit.mUv).mRadiance;
    };
    CHECK(radianceAt(0.25f, 0.75f) == scale * Vec3(1.f, 0.f, 0.f));
    CHECK(radianceAt(0.25f, 0.25f) == scale * Vec3(0.f, 0.f, 1.f));
    // 0.2 linear, stored as sRGB 124/255, decodes to 0.2016 (as for the base colour).
    const Vec3 grey = radianceAt(0.75f, 0.75f);
    for (int c = 0; c < 3; c++) CHECK(grey[c] == Approx(scale[c] * 0.2016f).epsilon(1e-3));
}

TEST_CASE("An emission texture on a non-area light, a missing one, or non-finite texture coordinates on a textured light are refused by Finalize", "[gltf][textures]") {
    const auto square = [](int aTexture, float aU) {
        Scene scene;
        const int black = scene.AddMaterial(Material{});
        const int a = scene.AddTriangle(Vec3(0.f), Vec3(1.f, 0.f, 0.f), Vec3(1.f, 1.f, 0.f), black);
        scene.mTriangles[size_t(a)].mUv1 = Vec2(aU, 0.f);
        Texture texture;
        texture.mWidth = texture.mHeight = 1;
        texture.mTexels = {Vec3(1.f)};
        scene.mTextures.push_back(texture);
        scene.AddAreaLight({a}, Vec3(1.f), false, aTexture);
        return scene;
    };
    CHECK_NOTHROW(square(0, 1.f).Finalize());
    CHECK_THROWS_WITH(square(1, 1.f).Finalize(), Catch::Contains("light 0 (area) refers to a missing or empty emission texture"));
    CHECK_THROWS_WITH(square(0, std::nanf("")).Finalize(), Catch::Contains("non-finite texture coordinates"));
    Scene sphere = square(-1, 1.f);
    sphere.AddSphereLight(sphere.AddSphere(Vec3(0.f, 0.f, 2.f), 0.5f, 0), Vec3(1.f));
    sphere.mLights.back().mEmissionTexture = 0;
    CHECK_THROWS_WITH(sphere.Finalize(), Catch::Contains("light 1 (sphere) has an emission texture; only area lights take one"));
    Scene negative = square(0, 1.f);
    negative.mTextures[0].mTexels[0] = Vec3(-1.f);
    CHECK_THROWS_WITH(negative.Finalize(), Catch::Contains("its emission texture has a negative or non-finite texel"));
}

TEST_CASE("The load report says how long reading and Scene::Finalize took", "[gltf]") {
    // Not a speed test: the two parts are measured, finite, and within the whole call.
    GltfLoadReport report;
    const auto start = std::chrono::steady_clock::now();
    const Scene scene = LoadGltfScene("../scenes/textured_torus.gltf", &report);
    const double total = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    CHECK(report.mReadSeconds > 0.0);
    CHECK(report.mFinalizeSeconds > 0.0);
    CHECK(report.mReadSeconds + report.mFinalizeSeconds <= total);
}

TEST_CASE("Buffer and image URIs name files exactly as they percent-decode: spaces, trailing spaces and '+' stay", "[gltf][textures]") {
    // The textured floor above with its two files renamed: {image file, its URI, buffer
    // file, its URI}. tinygltf decodes a buffer URI's '+' to a space, as HTML forms do; a
    // URI's '+' is a plus (RFC 3986).
    const struct {
        const char *mImage, *mImageUri, *mBuffer, *mBufferUri;
    } cases[] = {
        {"tex.png ", "tex.png ", "floor.bin ", "floor.bin "},
        {"name with trailing space .png", "name with trailing space .png", "a b.bin", "a%20b.bin"},
        {"x+y.png", "x+y.png", "c++.bin", "c++.bin"},
        {"my image.png", "my%20image.png", "50%.bin", "50%25.bin"},
    };
    Image image(1, 1);
    image.mPixels = {Vec3(1.f, 0.f, 0.f)};
    for (const auto& c : cases) {
        INFO("image '" << c.mImage << "', buffer '" << c.mBuffer << "'");
        TemporaryFolder folder;
        std::string text = ReadText(WriteTexturedFloor(folder, image, 10497, 1.f));
        std::filesystem::rename(folder / "base colour.png", folder / c.mImage);
        std::filesystem::rename(folder / "floor.bin", folder / c.mBuffer);
        text = Replaced(text, R"("base%20colour.png")", std::string("\"") + c.mImageUri + "\"");
        std::ofstream(folder / "floor.gltf") << Replaced(text, R"("floor.bin")", std::string("\"") + c.mBufferUri + "\"");
        const Scene scene = LoadGltfScene(folder / "floor.gltf");
        CHECK(scene.mTriangles.size() == 2);
        CHECK(TexelAt(scene, 0.5f, 0.5f) == image.mPixels[0]);
    }
}

TEST_CASE("Two buffer URIs that tinygltf decodes alike each read their own file", "[gltf]") {
    // "p+q.bin" and "p%20q.bin" both reach the file reader as "p q.bin": buffer 0 must get
    // p+q.bin (the cube), buffer 1 p q.bin (the cube moved by 10, unused).
    TemporaryFolder folder;
    const auto write = [&](const std::string& aName, const std::vector<float>& aFloats) {
        std::ofstream(folder / aName, std::ios::binary).write(reinterpret_cast<const char*>(aFloats.data()),
                                                               std::streamsize(aFloats.size() * sizeof(float)));
    };
    write("p+q.bin", Cube(Vec3(0.f)));
    write("p q.bin", Cube(Vec3(10.f)));
    const std::string gltf = MeshGltf(Cube(Vec3(0.f)));
    const size_t uri = gltf.find(R"("uri": ")");
    const size_t end = gltf.find('"', uri + 8);
    const std::string path = WriteTemporary(folder, "twins.gltf", gltf.substr(0, uri) + R"("uri": "p+q.bin"}, {"byteLength": 432,
        "uri": "p%20q.bin")" + gltf.substr(end + 1));
    const Scene scene = LoadGltfScene(path);
    REQUIRE(scene.mTriangles.size() == 12);
    for (const Triangle& triangle : scene.mTriangles) CHECK(MaxComponent(triangle.mP0) <= 1.f);
}

TEST_CASE("A URI that decodes to a NUL byte is refused: no file name holds one", "[gltf][textures]") {
    TemporaryFolder folder;
    Image image(1, 1);
    image.mPixels = {Vec3(1.f)};
    const std::string text = ReadText(WriteTexturedFloor(folder, image, 10497, 1.f));
    // Read up to the NUL, "floor.bin%00.txt" would name floor.bin, which exists.
    std::ofstream(folder / "buffer.gltf") << Replaced(text, R"("floor.bin")", R"("floor.bin%00.txt")");
    CHECK(LoadError(folder / "buffer.gltf") == folder / "buffer.gltf" + ": buffer URI 'floor.bin?.txt': the URI decodes to a NUL "
                                                                       "byte, which no file name holds");
    std::ofstream(folder / "image.gltf") << Replaced(text, R"("base%20colour.png")", R"("base%20colour.png%00.txt")");
    CHECK(LoadError(folder / "image.gltf") == folder / "image.gltf" + ": image 0 'base%20colour.png%00.txt': the URI decodes to a "
                                                                     "NUL byte, which no file name holds");
}

// --- KHR_materials_transmission: the glass share, its tint, and what is not modelled --------

namespace {

// material_glass.gltf with its floor material replaced by aMaterial (a JSON object),
// written into aFolder.
std::string GlassFloorFile(const TemporaryFolder& aFolder, const std::string& aMaterial) {
    const std::string text = ReadText("data/gltf/material_glass.gltf");
    const size_t materials = text.find(R"("materials")");
    const size_t begin = text.find(R"({
      "name": "floor",)", materials);
    const size_t end = text.find(R"({
      "name": "light",)", materials);
    REQUIRE(materials != std::string::npos);
    REQUIRE(begin != std::string::npos);
    REQUIRE(end != std::string::npos);
    const std::string replaced = text.substr(0, begin) + aMaterial + ",\n    " + text.substr(end);
    return WriteTemporary(aFolder, "glass.gltf", replaced);
}
Material GlassFloor(const std::string& aMaterial, GltfLoadReport* oReport = nullptr) {
    TemporaryFolder folder;
    const Scene scene = LoadGltfScene(GlassFloorFile(folder, aMaterial), oReport);
    REQUIRE(scene.mTriangles.size() == 4);
    return scene.mMaterials.at(size_t(scene.mTriangles[0].mMaterialId));
}
std::string GlassFloorError(const std::string& aMaterial) {
    TemporaryFolder folder;
    return LoadError(GlassFloorFile(folder, aMaterial));
}
// One material: base colour b, metallic m, roughness r, the transmission and ior extensions.
std::string PbrGlass(const std::string& aBase, float aMetallic, float aRoughness, const std::string& aExtensions) {
    std::ostringstream json;
    json << R"({"name": "floor", "pbrMetallicRoughness": {"baseColorFactor": [)" << aBase << R"(, 1], "metallicFactor": )"
         << aMetallic << R"(, "roughnessFactor": )" << aRoughness << R"(}, "extensions": {)" << aExtensions << "}}";
    return json.str();
}
std::string ApproximatedNote(const GltfLoadReport& aReport) {
    for (const std::string& note : aReport.mNotes)
        if (note.find("approximated (not modelled)") != std::string::npos) return note;
    return "";
}

} // namespace

TEST_CASE("KHR_materials_transmission: g = (1 - m) t of the surface is glass tinted by b, the rest the opaque mapping, number by number", "[gltf][glass]") {
    // docs/scene_format.md 4.3: g = (1 - m) t; glass: mirror g (times F), transmittance
    // g b, ior; the rest: diffuse (1 - m)(1 - t) 0.96 b, specular ks = (1 - m)(1 - t) 0.04
    // + m b, a mirror F does not weight (r = 0) or Phong (r > 0).
    const std::string tint = "0.8, 0.5, 0.2";
    const Vec3 b(0.8f, 0.5f, 0.2f);
    SECTION("t = 0: the opaque mapping, no glass") {
        const Material m = GlassFloor(PbrGlass(tint, 0.f, 0.f, R"("KHR_materials_transmission": {"transmissionFactor": 0})"));
        CheckMaterial(m, 0.96f * b, Vec3(0.f), 1.f, Vec3(0.04f), -1.f, false);
        CHECK_VEC3(m.mOpaqueMirror, Vec3(0.f), 0.f);
    }
    SECTION("t = 0.5, r = 0: half glass (mirror 0.5, transmittance 0.5 b), half the opaque mapping") {
        const Material m = GlassFloor(PbrGlass(tint, 0.f, 0.f,
                                               R"("KHR_materials_transmission": {"transmissionFactor": 0.5}, "KHR_materials_ior": {"ior": 1.4})"));
        CheckMaterial(m, 0.48f * b, Vec3(0.f), 1.f, Vec3(0.5f), 1.4f, false);
        CHECK_VEC3(m.mTransmittance, Vec3(0.4f, 0.25f, 0.1f), 1e-7f);
        CHECK_VEC3(m.mOpaqueMirror, Vec3(0.02f), 1e-8f);
    }
    SECTION("t = 1: tinted glass (transmittance b), nothing opaque") {
        const Material m = GlassFloor(PbrGlass(tint, 0.f, 0.f, R"("KHR_materials_transmission": {"transmissionFactor": 1})"));
        CheckMaterial(m, Vec3(0.f), Vec3(0.f), 1.f, Vec3(1.f), 1.5f, false);
        CHECK_VEC3(m.mTransmittance, b, 0.f);
        CHECK_VEC3(m.mOpaqueMirror, Vec3(0.f), 0.f);
    }
    SECTION("t = 1, m = 0.25, r = 0.5: glass 0.75, the metal a Phong lobe 0.25 b with n = 30") {
        const Material m = GlassFloor(PbrGlass(tint, 0.25f, 0.5f, R"("KHR_materials_transmission": {"transmissionFactor": 1})"));
        CheckMaterial(m, Vec3(0.f), 0.25f * b, 30.f, Vec3(0.75f), 1.5f, false);
        CHECK_VEC3(m.mTransmittance, 0.75f * b, 1e-7f);
        CHECK_VEC3(m.mOpaqueMirror, Vec3(0.f), 0.f);
    }
    SECTION("t = 0.6, m = 0.5, r = 0.25: glass 0.3, diffuse 0.2 0.96 b, Phong 0.2 0.04 + 0.5 b with n = 510") {
        const Material m = GlassFloor(PbrGlass(tint, 0.5f, 0.25f, R"("KHR_materials_transmission": {"transmissionFactor": 0.6})"));
        CheckMaterial(m, 0.2f * 0.96f * b, Vec3(0.008f) + 0.5f * b, 510.f, Vec3(0.3f), 1.5f, false);
        CHECK_VEC3(m.mTransmittance, 0.3f * b, 1e-7f);
    }
    SECTION("m = 1: a metal, whatever t says (glTF: metals do not transmit)") {
        const Material m = GlassFloor(PbrGlass(tint, 1.f, 0.f, R"("KHR_materials_transmission": {"transmissionFactor": 1})"));
        CheckMaterial(m, Vec3(0.f), Vec3(0.f), 1.f, b, -1.f, false);
    }
    SECTION("ior 0 (KHR_materials_ior: F = 1): the glass share is a mirror") {
        const Material m = GlassFloor(PbrGlass(tint, 0.f, 0.f,
                                               R"("KHR_materials_transmission": {"transmissionFactor": 0.5}, "KHR_materials_ior": {"ior": 0})"));
        CheckMaterial(m, 0.48f * b, Vec3(0.f), 1.f, Vec3(0.52f), -1.f, false);
        // Rough, the whole specular (the glass share's g = 0.5 with it) is the Phong lobe; a
        // base-colour texture tints neither (untinted share 0.02 + 0.5 = 0.52).
        const Material rough = GlassFloor(PbrGlass(tint, 0.f, 0.5f,
                                                   R"("KHR_materials_transmission": {"transmissionFactor": 0.5}, "KHR_materials_ior": {"ior": 0})"));
        CHECK_VEC3(rough.mPhongReflectance, Vec3(0.52f), 1e-7f);
        CHECK(IsBlack(rough.mMirrorReflectance));
    }
    SECTION("doubleSided on partly transmissive glass: one-sided (glass tells inside from outside)") {
        std::string json = PbrGlass(tint, 0.f, 0.f, R"("KHR_materials_transmission": {"transmissionFactor": 0.5})");
        json.insert(1, R"("doubleSided": true, )");
        CHECK_FALSE(GlassFloor(json).mTwoSided);
    }
}

TEST_CASE("What the glass rule does not model is named in the load note; clear glass adds nothing to it", "[gltf][glass]") {
    GltfLoadReport report;
    GlassFloor(PbrGlass("1, 1, 1", 0.f, 0.f, R"("KHR_materials_transmission": {"transmissionFactor": 1})"), &report);
    CHECK(ApproximatedNote(report).empty());
    GltfLoadReport rough;
    const Material m = GlassFloor(PbrGlass("1, 1, 1", 0.f, 0.4f,
                                           R"("KHR_materials_transmission": {"transmissionFactor": 1, "transmissionTexture": {"index": 0}}, "KHR_materials_volume": {"thicknessFactor": 0.1})"),
                                  &rough);
    CHECK(m.mIor == 1.5f);
    CHECK(IsBlack(m.mPhongReflectance));  // t = 1, m = 0: no opaque share for the roughness to shape
    const std::string note = ApproximatedNote(rough);
    CHECK_THAT(note, Catch::Contains("roughnessFactor on transmission (rendered as smooth glass)"));
    CHECK_THAT(note, Catch::Contains("transmissionTexture (transmissionFactor is used)"));
    // A volume without attenuationDistance absorbs nothing (thicknessFactor is not read): no medium, no note.
    CHECK(m.mMedium == -1);
    CHECK(note.find("KHR_materials_volume") == std::string::npos);
    // Transmission on a metal (metallicFactor 1, glTF's default) is no glass: said, not hidden.
    GltfLoadReport metal;
    const Material m1 = GlassFloor(PbrGlass("1, 1, 1", 1.f, 0.f, R"("KHR_materials_transmission": {"transmissionFactor": 1})"), &metal);
    CHECK(m1.mIor < 0.f);
    CHECK_THAT(ApproximatedNote(metal), Catch::Contains("KHR_materials_transmission on a fully metallic material"));
}

TEST_CASE("A transmissionFactor outside [0, 1] or not a number, and an ior below 1 other than 0, are one clear error", "[gltf][glass]") {
    for (const std::string factor : {"-0.1", "1.5", "\"half\"", "1e39"}) {
        INFO("transmissionFactor " << factor);
        const std::string error =
            GlassFloorError(PbrGlass("1, 1, 1", 0.f, 0.f, R"("KHR_materials_transmission": {"transmissionFactor": )" + factor + "}"));
        CHECK_THAT(error, Catch::Contains("material 0 'floor': KHR_materials_transmission.transmissionFactor must be a number in [0, 1]"));
        CHECK(error.find('\n') == std::string::npos);
    }
    for (const std::string ior : {"0.5", "-1", "\"glass\""}) {
        INFO("ior " << ior);
        const std::string error = GlassFloorError(PbrGlass(
            "1, 1, 1", 0.f, 0.f, R"("KHR_materials_transmission": {"transmissionFactor": 1}, "KHR_materials_ior": {"ior": )" + ior + "}"));
        CHECK_THAT(error, Catch::Contains("material 0 'floor': KHR_materials_ior.ior must be a number >= 1, or 0"));
    }
    // An ior on an opaque material is not read (as before): no error.
    CHECK(GlassFloorError(PbrGlass("1, 1, 1", 0.f, 0.f, R"("KHR_materials_ior": {"ior": 0.5})")).empty());
}

TEST_CASE("A base-colour texture on glass tints the refraction and the opaque share, never the Fresnel reflection", "[gltf][glass][textures]") {
    TemporaryFolder folder;
    Image image(1, 1);
    image.mPixels = {Vec3(0.5f)};
    std::string text = ReadText(WriteTexturedFloor(folder, image, 10497, 1.f));
    text = Replaced(text, R"("roughnessFactor": 1, )", R"("roughnessFactor": 0, )");
    text = Replaced(text, R"("baseColorTexture": {"index": 0}}}])",
                    R"("baseColorTexture": {"index": 0}}, "extensions": {"KHR_materials_transmission": {"transmissionFactor": 0.5}}}])");
    std::ofstream(folder / "floor.gltf") << text;
    GltfLoadReport report;
    const Scene scene = LoadGltfScene(folder / "floor.gltf", &report);
    const Material& m = scene.mMaterials.at(0);
    CHECK(m.mBaseColorTexture >= 0);
    CHECK(m.mIor == 1.5f);
    // Tolerances: the rule's few float products (a relative error of a few 1e-8).
    CHECK_VEC3(m.mSpecularUntinted, Vec3(0.02f), 1e-8f);
    CHECK_VEC3(m.mTransmittance, Vec3(0.25f, 0.5f, 0.5f), 1e-7f);
    // The Fresnel reflection is glass's mirror g = 0.5, which Bsdf::SetupWith never tints
    // on glass (it tints the opaque mirror, zero here: r = 0 puts 0.02 there).
    CHECK_VEC3(m.mMirrorReflectance, Vec3(0.5f), 1e-7f);
    CHECK_VEC3(m.mOpaqueMirror, Vec3(0.02f), 1e-8f);
    CHECK(ApproximatedNote(report).empty());
    // ior 0: the glass share is a mirror and joins the specular; its untinted share keeps
    // the texture off it (0.02 + 0.5 untinted of 0.52: a texel tints nothing).
    std::ofstream(folder / "mirror.gltf") << Replaced(text, R"("transmissionFactor": 0.5}})",
                                                      R"("transmissionFactor": 0.5}, "KHR_materials_ior": {"ior": 0}})");
    const Material mirror = LoadGltfScene(folder / "mirror.gltf").mMaterials.at(0);
    CHECK(mirror.mIor < 0.f);
    CHECK_VEC3(mirror.mMirrorReflectance, Vec3(0.52f), 1e-7f);
    CHECK_VEC3(mirror.mSpecularUntinted, Vec3(0.52f), 1e-7f);
}

// ---------------------------------------------------------------------------------------
// Participating media: KHR_materials_volume, SMALLVCM_medium on materials and scenes
// (docs/scene_format.md 4.4). Each medium sits in the closed test cube.
// ---------------------------------------------------------------------------------------
namespace {

// The test cube with one material aMaterial and a point light above it; aSceneExtensions
// (if any) become the scene's "extensions".
std::string MediumCubeGltf(const std::string& aMaterial, const std::string& aSceneExtensions = "") {
    std::string text = MeshGltf(Cube(Vec3(0.f)), R"(, {"translation": [0, 3, 0], "extensions": {"KHR_lights_punctual": {"light": 0}}})",
                                R"(, "extensions": {"KHR_lights_punctual": {"lights": [{"type": "point", "intensity": 10}]}})", aMaterial);
    if (!aSceneExtensions.empty())
        text = Replaced(text, R"("scenes": [{"nodes": [0]}])", R"("scenes": [{"nodes": [0], "extensions": {)" + aSceneExtensions + "}}]");
    return text;
}
Scene LoadMediumCube(const std::string& aMaterial, GltfLoadReport* oReport = nullptr, const std::string& aSceneExtensions = "",
                     const GltfLoadOptions& aOptions = {}) {
    TemporaryFolder folder;
    return LoadGltfScene(WriteTemporary(folder, "cube.gltf", MediumCubeGltf(aMaterial, aSceneExtensions)), oReport, aOptions);
}
// A glass material (transmission 1, metallic 0) named aName with aExtensions beside.
std::string GlassWith(const std::string& aName, const std::string& aExtensions) {
    return R"({"name": ")" + aName + R"(", "pbrMetallicRoughness": {"metallicFactor": 0, "roughnessFactor": 0}, "extensions": {)"
           R"("KHR_materials_transmission": {"transmissionFactor": 1})" + (aExtensions.empty() ? "" : ", " + aExtensions) + "}}";
}

} // namespace

TEST_CASE("KHR_materials_volume on glass: sigma_a = -ln(attenuationColor) / attenuationDistance per channel, no scattering, inside the glass", "[gltf][media]") {
    GltfLoadReport report;
    const Scene scene = LoadMediumCube(GlassWith("amber", R"("KHR_materials_volume": {"attenuationColor": [0.9, 0.5, 0.2], )"
                                                          R"("attenuationDistance": 0.5, "thicknessFactor": 2})"), &report);
    const Material& m = scene.mMaterials.at(0);
    REQUIRE(scene.mMedia.size() == 1);
    CHECK(m.mMedium == 0);
    CHECK(m.mIor == 1.5f);  // still the glass of 4.3 around it
    CHECK_VEC3(m.mMirrorReflectance, Vec3(1.f), 0.f);
    CHECK(scene.mSceneMedium == -1);
    const Medium& medium = scene.mMedia[0];
    CHECK(medium.mName == "amber");
    // -ln(0.9) / 0.5, -ln(0.5) / 0.5, -ln(0.2) / 0.5; colours are read as float.
    CHECK_VEC3(medium.mSigmaA, Vec3(0.2107210f, 1.3862944f, 3.2188758f), 1e-6f);
    CHECK_VEC3(medium.mSigmaS, Vec3(0.f), 0.f);
    CHECK(medium.mG == 0.f);
    CHECK(ApproximatedNote(report).empty());  // thicknessFactor's value does not matter (only whether it is 0)
}

TEST_CASE("KHR_materials_volume without absorption adds no medium; attenuationColor 0 is clamped and noted; without refraction or thin-walled it is noted and ignored", "[gltf][media]") {
    SECTION("attenuationDistance absent: infinity, no absorption") {
        const Scene scene = LoadMediumCube(GlassWith("clear", R"("KHR_materials_volume": {"attenuationColor": [0.5, 0.5, 0.5]})"));
        CHECK(scene.mMaterials.at(0).mMedium == -1);
        CHECK(scene.mMedia.empty());
    }
    SECTION("attenuationColor white (the default)") {
        const Scene scene = LoadMediumCube(GlassWith("clear", R"("KHR_materials_volume": {"attenuationDistance": 2})"));
        CHECK(scene.mMaterials.at(0).mMedium == -1);
        CHECK(scene.mMedia.empty());
    }
    SECTION("a channel 0: sigma_a = -ln(1e-38) / d = 87.5 / d, and the note says so") {
        GltfLoadReport report;
        const Scene scene = LoadMediumCube(GlassWith("red", R"("KHR_materials_volume": {"attenuationColor": [1, 0, 0], "attenuationDistance": 2, )"
                                                            R"("thicknessFactor": 1})"),
                                           &report);
        REQUIRE(scene.mMedia.size() == 1);
        CHECK_VEC3(scene.mMedia[0].mSigmaA, Vec3(0.f, 43.749f, 43.749f), 1e-3f);
        CHECK(std::isfinite(scene.mMedia[0].mSigmaA.y));
        CHECK_THAT(ApproximatedNote(report), Catch::Contains("KHR_materials_volume attenuationColor 0 (sigma_a clamped to 87.5 / attenuationDistance)"));
    }
    SECTION("on a material that does not refract (no transmission, or a metal): ignored, with one note") {
        GltfLoadReport report;
        const Scene scene = LoadMediumCube(R"({"name": "opaque", "pbrMetallicRoughness": {"metallicFactor": 0}, "extensions": {)"
                                           R"("KHR_materials_volume": {"attenuationColor": [0.5, 0.5, 0.5], "attenuationDistance": 1}}})", &report);
        CHECK(scene.mMaterials.at(0).mMedium == -1);
        CHECK(scene.mMedia.empty());
        CHECK_THAT(ApproximatedNote(report), Catch::Contains("KHR_materials_volume on a material that does not refract (ignored"));
    }
    SECTION("thicknessFactor 0, absent or given (glTF's thin-walled): no volume, one note, and an open mesh is no error") {
        for (const std::string thickness : {"", R"(, "thicknessFactor": 0)"}) {
            GltfLoadReport report;
            const Scene scene = LoadMediumCube(GlassWith("pane", R"("KHR_materials_volume": {"attenuationColor": [0.5, 0.5, 0.5], )"
                                                                 R"("attenuationDistance": 1)" + thickness + "}"), &report);
            CHECK(scene.mMaterials.at(0).mMedium == -1);
            CHECK(scene.mMedia.empty());
            CHECK_THAT(ApproximatedNote(report), Catch::Contains("KHR_materials_volume with thicknessFactor 0 (glTF's thin-walled surface"));
            CHECK_THAT(ApproximatedNote(report), !Catch::Contains("attenuationColor 0"));
        }
        // An open refracting mesh that is thin-walled loads: no medium, so nothing needs it
        // closed (with the volume it would be refused, as a medium's mesh must be closed).
        TemporaryFolder folder;
        const std::string pane = GlassWith("pane", R"("KHR_materials_volume": {"attenuationColor": [0, 0.5, 0.5], "attenuationDistance": 1})");
        std::vector<float> open = Cube(Vec3(0.f));
        open.resize(open.size() - 9 * 2);  // two triangles (one face) fewer
        const Scene scene = LoadGltfScene(WriteTemporary(folder, "pane.gltf", MeshGltf(open, "", "", pane)));
        CHECK(scene.mMedia.empty());
    }
}

TEST_CASE("SMALLVCM_medium: read as given; with transmission the glass holds it, without it the surface is an index-matched boundary", "[gltf][media]") {
    const std::string fog = R"("SMALLVCM_medium": {"sigmaA": [0.01, 0.02, 0.03], "sigmaS": [0.5, 0.6, 0.7], "g": 0.3})";
    auto checkFog = [](const Medium& aMedium, const std::string& aName) {
        CHECK(aMedium.mName == aName);
        CHECK_VEC3(aMedium.mSigmaA, Vec3(0.01f, 0.02f, 0.03f), 0.f);
        CHECK_VEC3(aMedium.mSigmaS, Vec3(0.5f, 0.6f, 0.7f), 0.f);
        CHECK(aMedium.mG == 0.3f);
    };
    SECTION("without transmission: no component at all (Mitsuba's null BSDF), whatever pbrMetallicRoughness says") {
        const Scene scene = LoadMediumCube(R"({"name": "marble", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1], )"
                                           R"("metallicFactor": 0, "roughnessFactor": 0.5}, "extensions": {)" + fog + "}}");
        const Material& m = scene.mMaterials.at(0);
        REQUIRE(scene.mMedia.size() == 1);
        CHECK(m.mMedium == 0);
        CHECK(m.IsIndexMatchedBoundary());
        CHECK(m.mIor == -1.f);
        CHECK(IsBlack(m.mDiffuseReflectance + m.mPhongReflectance + m.mMirrorReflectance + m.mOpaqueMirror));
        CHECK_FALSE(m.HasSpecular());
        CHECK_FALSE(m.HasNonSpecular());
        checkFog(scene.mMedia[0], "marble");
    }
    SECTION("with transmission and KHR_materials_ior: glass of that ior around the medium") {
        const Scene scene = LoadMediumCube(GlassWith("jelly", R"("KHR_materials_ior": {"ior": 1.33}, )" + fog));
        const Material& m = scene.mMaterials.at(0);
        REQUIRE(scene.mMedia.size() == 1);
        CHECK(m.mMedium == 0);
        CHECK(m.mIor == 1.33f);
        CHECK_FALSE(m.IsIndexMatchedBoundary());
        checkFog(scene.mMedia[0], "jelly");
    }
    SECTION("with SMALLVCM_material's glass (ior > 0)") {
        const Scene scene = LoadMediumCube(R"({"name": "exact", "extensions": {"SMALLVCM_material": {"mirror": [1, 1, 1], "ior": 1.6}, )" + fog + "}}");
        CHECK(scene.mMaterials.at(0).mIor == 1.6f);
        CHECK(scene.mMaterials.at(0).mMedium == 0);
    }
    SECTION("an unnamed material's medium is named as the material is in messages; members default to 0") {
        const Scene scene = LoadMediumCube(R"({"extensions": {"SMALLVCM_medium": {}}})");
        REQUIRE(scene.mMedia.size() == 1);
        CHECK(scene.mMedia[0].mName == "material 0");
        CHECK_FALSE(scene.mMedia[0].Attenuates());
        CHECK(scene.mMedia[0].mG == 0.f);
        CHECK(scene.mMaterials.at(0).IsIndexMatchedBoundary());
    }
    SECTION("beside KHR_materials_volume, SMALLVCM_medium wins and the note says so") {
        GltfLoadReport report;
        const Scene scene = LoadMediumCube(GlassWith("both", R"("KHR_materials_volume": {"attenuationColor": [0.1, 0.1, 0.1], "attenuationDistance": 1}, )" + fog),
                                           &report);
        REQUIRE(scene.mMedia.size() == 1);
        checkFog(scene.mMedia[0], "both");
        CHECK_THAT(ApproximatedNote(report), Catch::Contains("KHR_materials_volume beside SMALLVCM_medium (ignored: SMALLVCM_medium is used)"));
    }
}

TEST_CASE("SMALLVCM_medium on the scene fills space outside the meshes; GltfLoadOptions::mSceneMedium replaces it", "[gltf][media]") {
    const std::string sceneFog = R"("SMALLVCM_medium": {"sigmaA": [0.01, 0.01, 0.01], "sigmaS": [0.1, 0.2, 0.3], "g": -0.2})";
    const std::string grey = R"({"pbrMetallicRoughness": {"metallicFactor": 0}})";
    const Scene scene = LoadMediumCube(grey, nullptr, sceneFog);
    REQUIRE(scene.mMedia.size() == 1);
    CHECK(scene.mSceneMedium == 0);
    CHECK(scene.mMedia[0].mName == "scene medium");
    CHECK_VEC3(scene.mMedia[0].mSigmaS, Vec3(0.1f, 0.2f, 0.3f), 0.f);
    CHECK(scene.mMedia[0].mG == -0.2f);
    CHECK(scene.mMaterials.at(0).mMedium == -1);
    CHECK(scene.IsFinalized());

    GltfLoadOptions options;
    options.mReplaceSceneMedium = true;
    options.mSceneMedium.mSigmaS = Vec3(0.05f);
    options.mSceneMedium.mSigmaA = Vec3(0.002f);
    options.mSceneMedium.mG = 0.5f;
    for (const std::string& extensions : {sceneFog, std::string()}) {
        INFO("the file's scene extensions: " << extensions);
        const Scene replaced = LoadMediumCube(grey, nullptr, extensions, options);
        REQUIRE(replaced.mMedia.size() == 1);  // the file's, replaced, is not kept
        CHECK(replaced.mSceneMedium == 0);
        CHECK(replaced.mMedia[0].mName == "scene medium");
        CHECK_VEC3(replaced.mMedia[0].mSigmaS, Vec3(0.05f), 0.f);
        CHECK_VEC3(replaced.mMedia[0].mSigmaA, Vec3(0.002f), 0.f);
        CHECK(replaced.mMedia[0].mG == 0.5f);
        CHECK(replaced.IsFinalized());
    }
    // Without either, space is empty.
    CHECK(LoadMediumCube(grey).mSceneMedium == -1);
}

TEST_CASE("Bad media are one clear error naming the file and the material or scene", "[gltf][media]") {
    struct BadMedium {
        std::string mMaterialExtensions, mSceneExtensions, mFragment;
    };
    const std::string v = R"("KHR_materials_transmission": {"transmissionFactor": 1}, "KHR_materials_volume": )";
    const std::string what = "material 0 'm': ";
    const std::vector<BadMedium> cases = {
        {R"("SMALLVCM_medium": [0.1, 0.1, 0.1])", "", what + "SMALLVCM_medium must be an object"},
        {R"("SMALLVCM_medium": "fog")", "", what + "SMALLVCM_medium must be an object"},
        {R"("SMALLVCM_medium": {"sigmaS": [1, 2]})", "", what + "SMALLVCM_medium: 'sigmaS' must be an array of 3 numbers"},
        {R"("SMALLVCM_medium": {"sigmaS": [1, 2, 3, 4]})", "", what + "SMALLVCM_medium: 'sigmaS' must be an array of 3 numbers"},
        {R"("SMALLVCM_medium": {"sigmaA": ["0.1", 0, 0]})", "", what + "SMALLVCM_medium: 'sigmaA' must be an array of 3 numbers"},
        {R"("SMALLVCM_medium": {"sigmaA": 0.1})", "", what + "SMALLVCM_medium: 'sigmaA' must be an array of 3 numbers"},
        {R"("SMALLVCM_medium": {"sigmaS": [0.1, -0.1, 0]})", "", what + "SMALLVCM_medium.sigmaS must be finite and non-negative"},
        {R"("SMALLVCM_medium": {"sigmaA": [1e39, 0, 0]})", "", what + "SMALLVCM_medium.sigmaA must be finite and non-negative"},
        {R"("SMALLVCM_medium": {"g": 1})", "", what + "SMALLVCM_medium.g must be a number in (-1, 1)"},
        {R"("SMALLVCM_medium": {"g": -1})", "", what + "SMALLVCM_medium.g must be a number in (-1, 1)"},
        {R"("SMALLVCM_medium": {"g": 0.999999999})", "", what + "SMALLVCM_medium.g must be a number in (-1, 1)"},  // 1 in float
        {R"("SMALLVCM_medium": {"g": "0.5"})", "", what + "SMALLVCM_medium.g must be a number in (-1, 1)"},
        {R"("SMALLVCM_medium": {"sigma_s": [1, 1, 1]})", "", what + "SMALLVCM_medium has an unknown member 'sigma_s'"},
        {v + R"({"attenuationDistance": 0})", "", what + "KHR_materials_volume.attenuationDistance must be a number > 0"},
        {v + R"({"attenuationDistance": -2})", "", what + "KHR_materials_volume.attenuationDistance must be a number > 0"},
        {v + R"({"attenuationDistance": 1, "thicknessFactor": -1})", "", what + "KHR_materials_volume.thicknessFactor must be a finite number >= 0"},
        {v + R"({"attenuationDistance": 1, "thicknessFactor": "thick"})", "", what + "KHR_materials_volume.thicknessFactor must be a finite number >= 0"},
        {v + R"({"attenuationDistance": "far"})", "", what + "KHR_materials_volume.attenuationDistance must be a number > 0"},
        {v + R"({"attenuationDistance": 1e-300, "attenuationColor": [0.5, 0.5, 0.5]})", "",
         what + "KHR_materials_volume: sigma_a = -ln(attenuationColor) / attenuationDistance must be finite"},
        {v + R"({"attenuationColor": [1.5, 0.5, 0.5], "attenuationDistance": 1})", "", what + "KHR_materials_volume.attenuationColor must be 3 numbers in [0, 1]"},
        {v + R"({"attenuationColor": [0.5, -0.1, 0.5], "attenuationDistance": 1})", "", what + "KHR_materials_volume.attenuationColor must be 3 numbers in [0, 1]"},
        {v + R"({"attenuationColor": [0.5, 0.5], "attenuationDistance": 1})", "", what + "KHR_materials_volume: 'attenuationColor' must be an array of 3 numbers"},
        {v + R"([1])", "", what + "KHR_materials_volume must be an object"},
        {"", R"("SMALLVCM_medium": {"g": 2})", "scene 0: SMALLVCM_medium.g must be a number in (-1, 1)"},
        {"", R"("SMALLVCM_medium": {"sigmaS": [-1, 0, 0]})", "scene 0: SMALLVCM_medium.sigmaS must be finite and non-negative"},
        {"", R"("SMALLVCM_medium": 7)", "scene 0: SMALLVCM_medium must be an object"},
    };
    TemporaryFolder folder;
    for (const BadMedium& c : cases) {
        INFO(c.mMaterialExtensions << " / " << c.mSceneExtensions);
        const std::string material = R"({"name": "m", "pbrMetallicRoughness": {"metallicFactor": 0}, "extensions": {)" + c.mMaterialExtensions + "}}";
        const std::string path = WriteTemporary(folder, "bad.gltf", MediumCubeGltf(material, c.mSceneExtensions));
        const std::string error = LoadError(path);
        CHECK(StartsWith(error, path + ": "));
        CHECK_THAT(error, Catch::Contains(c.mFragment));
        CHECK(error.find('\n') == std::string::npos);
    }
}

namespace {

// Whether the triangles of aScene with material aMaterialId form a closed surface wound
// outwards: each directed edge (by its end points) once, its reverse once, and a positive
// signed volume.
bool ClosedAndOutwards(const Scene& aScene, int aMaterialId, double* oVolume) {
    using Point = std::tuple<float, float, float>;
    auto key = [](const Vec3& aP) { return Point(aP.x, aP.y, aP.z); };
    std::set<std::pair<Point, Point>> edges;
    double volume = 0.0;
    for (const Triangle& t : aScene.mTriangles) {
        if (t.mMaterialId != aMaterialId) continue;
        const Vec3 p[3] = {t.mP0, t.mP1, t.mP2};
        for (int k = 0; k < 3; k++)
            if (!edges.insert({key(p[k]), key(p[(k + 1) % 3])}).second) return false;
        volume += glm::dot(glm::dvec3(p[0]), glm::cross(glm::dvec3(p[1]), glm::dvec3(p[2]))) / 6.0;
    }
    for (const auto& [from, to] : edges)
        if (!edges.count({to, from})) return false;
    *oVolume = volume;
    return !edges.empty() && volume > 0.0;
}

} // namespace

TEST_CASE("The media scenes load with their media, and each medium's mesh is closed and wound outwards", "[gltf][media]") {
    SECTION("fog_caustic_box: fog as the scene medium, clear glass sphere, a mirror") {
        GltfLoadReport report;
        const Scene scene = LoadGltfScene("../scenes/fog_caustic_box.gltf", &report);
        REQUIRE(scene.mMedia.size() == 1);
        REQUIRE(scene.mSceneMedium == 0);
        CHECK_VEC3(scene.mMedia[0].mSigmaS, Vec3(0.1f), 0.f);
        CHECK_VEC3(scene.mMedia[0].mSigmaA, Vec3(0.01f), 0.f);
        CHECK(scene.mMedia[0].mG == 0.3f);
        REQUIRE(scene.mSpheres.size() == 1);
        const Material& glass = scene.mMaterials.at(size_t(scene.mSpheres[0].mMaterialId));
        CHECK(glass.mIor == 1.5f);
        CHECK(glass.mMedium == -1);
        CHECK(report.mNotes.empty());
    }
    SECTION("dense_scattering_sphere: an index-matched boundary around albedo ~0.95") {
        const Scene scene = LoadGltfScene("../scenes/dense_scattering_sphere.gltf");
        REQUIRE(scene.mMedia.size() == 1);
        CHECK(scene.mSceneMedium == -1);
        const Medium& medium = scene.mMedia[0];
        const Vec3 albedo = medium.mSigmaS / medium.SigmaT();
        CHECK(albedo.x == Approx(0.97).margin(0.01));
        CHECK(albedo.y == Approx(0.95).margin(0.01));
        CHECK(albedo.z == Approx(0.92).margin(0.01));
        int boundaries = 0;
        for (size_t m = 0; m < scene.mMaterials.size(); m++) {
            if (scene.mMaterials[m].mMedium < 0) continue;
            boundaries++;
            CHECK(scene.mMaterials[m].IsIndexMatchedBoundary());
            double volume = 0.0;
            CHECK(ClosedAndOutwards(scene, int(m), &volume));
            CHECK(volume == Approx(4.0 / 3.0 * 3.14159265 * 0.4 * 0.4 * 0.4).epsilon(0.02));  // the icosphere is a little smaller
        }
        CHECK(boundaries == 1);
    }
    SECTION("absorbing_glass: KHR_materials_volume in a closed wedge and a closed sphere") {
        const Scene scene = LoadGltfScene("../scenes/absorbing_glass.gltf");
        REQUIRE(scene.mMedia.size() == 1);
        CHECK_VEC3(scene.mMedia[0].mSigmaA, Vec3(0.3512017f, 2.3104906f, 5.3647929f), 1e-5f);  // -ln(0.9, 0.5, 0.2) / 0.3
        int glass = 0;
        for (size_t m = 0; m < scene.mMaterials.size(); m++) {
            if (scene.mMaterials[m].mMedium < 0) continue;
            glass++;
            CHECK(scene.mMaterials[m].mIor == 1.5f);
            double volume = 0.0;
            CHECK(ClosedAndOutwards(scene, int(m), &volume));  // the wedge and the sphere together
            CHECK(volume == Approx(0.5 * 0.9 * 0.45 * 0.5 + 4.0 / 3.0 * 3.14159265 * 0.027).epsilon(0.02));
        }
        CHECK(glass == 1);
    }
    SECTION("spot_in_thin_fog and spot_in_dense_block (F21): one spot, black walls, a thin scene medium or a dense closed block") {
        const Scene thin = LoadGltfScene("../scenes/spot_in_thin_fog.gltf");
        REQUIRE(thin.mMedia.size() == 1);
        CHECK(thin.mSceneMedium == 0);
        CHECK_VEC3(thin.mMedia[0].SigmaT(), Vec3(0.1f), 1e-6f);
        const Scene dense = LoadGltfScene("../scenes/spot_in_dense_block.gltf");
        REQUIRE(dense.mMedia.size() == 1);
        CHECK(dense.mSceneMedium == -1);
        CHECK_VEC3(dense.mMedia[0].SigmaT(), Vec3(10.f), 1e-5f);
        for (const Scene* scene : {&thin, &dense}) {
            CHECK(scene->mMedia[0].mSigmaS.x / scene->mMedia[0].SigmaT().x == Approx(0.95f));
            REQUIRE(scene->mLights.size() == 1);
            CHECK(scene->mLights[0].IsDelta());
            for (size_t m = 0; m < scene->mMaterials.size(); m++)
                if (scene->mMaterials[m].mMedium < 0) CHECK(IsBlack(scene->mMaterials[m].mDiffuseReflectance));
        }
        int blocks = 0;
        for (size_t m = 0; m < dense.mMaterials.size(); m++) {
            if (dense.mMaterials[m].mMedium < 0) continue;
            blocks++;
            CHECK(dense.mMaterials[m].IsIndexMatchedBoundary());
            double volume = 0.0;
            CHECK(ClosedAndOutwards(dense, int(m), &volume));
            CHECK(volume == Approx(0.8 * 0.8 * 0.799).epsilon(1e-4));
        }
        CHECK(blocks == 1);
    }
}

TEST_CASE("A metallicRoughnessTexture makes each texel the written rule's material of its metal and roughness", "[gltf]") {
    // data/gltf/metal_roughness_texture.gltf (make_bad_gltf.py): the floor's texture has 3 x 3
    // cells of metal 0, 128/255, 1 (columns) and roughness 0, 128/255, 1 (rows), factors 1;
    // materials 2 to 10 are each cell's factor-only material, which the mapping tests above
    // check number by number. At each cell's centre the textured floor's Bsdf must be that
    // material's: the same value and pdfs in every direction, the same sampled directions
    // and weights, the same continuation probability.
    const Scene scene = LoadGltfScene("data/gltf/metal_roughness_texture.gltf");
    REQUIRE(scene.mMaterials.size() >= 11);
    REQUIRE(scene.GetMaterial(0).mMetallicRoughnessTexture >= 0);
    const Vec3 directions[] = {glm::normalize(Vec3(0.3f, -0.2f, 1.f)), glm::normalize(Vec3(-0.3f, 0.2f, 1.f)),
                               glm::normalize(Vec3(-0.35f, 0.25f, 1.f)), glm::normalize(Vec3(0.8f, 0.1f, 0.3f)), Vec3(0.f, 0.f, 1.f)};
    const auto near = [](float aA, float aB) { return std::abs(aA - aB) <= 1e-5f * std::max(1.f, std::abs(aB)); };
    for (int row = 0; row < 3; row++)
        for (int column = 0; column < 3; column++) {
            INFO("cell: metal column " << column << ", roughness row " << row);
            // Floor corner 0 (-1, -1) has uv (0, 0) and corner 2 (1, 1) uv (1, 1).
            const Vec3 point(2.f * (float(column) + 0.5f) / 3.f - 1.f, 2.f * (float(row) + 0.5f) / 3.f - 1.f, 0.f);
            const Ray ray{point + Vec3(0.3f, -0.2f, 0.5f), glm::normalize(Vec3(-0.3f, 0.2f, -0.5f))};
            const SurfacePoint hit = scene.Intersect(ray);
            REQUIRE(hit.IsValid());
            REQUIRE(hit.mMaterialId == 0);
            Bsdf textured, reference;
            textured.Setup(ray, hit, scene, Transport::kRadiance);
            reference.Setup(-ray.mDirection, hit.GeometricNormal(), scene.GetMaterial(2 + 3 * row + column), Transport::kRadiance);
            REQUIRE(textured.IsValid() == reference.IsValid());
            CHECK(textured.IsDelta() == reference.IsDelta());
            CHECK(near(textured.ContinuationProb(), reference.ContinuationProb()));
            for (const Vec3& direction : directions) {
                const BsdfEval a = textured.Evaluate(direction), b = reference.Evaluate(direction);
                for (int c = 0; c < 3; c++) CHECK(near(a.mValue[c], b.mValue[c]));
                CHECK(near(a.mDirPdfW, b.mDirPdfW));
                CHECK(near(a.mRevPdfW, b.mRevPdfW));
            }
            for (const Vec3& rnd : {Vec3(0.1f, 0.2f, 0.3f), Vec3(0.5f, 0.7f, 0.9f), Vec3(0.95f, 0.4f, 0.6f)}) {
                const std::optional<ScatterSample> a = textured.Sample(rnd), b = reference.Sample(rnd);
                REQUIRE(a.has_value() == b.has_value());
                if (!a) continue;
                CHECK(a->mEvent == b->mEvent);
                for (int c = 0; c < 3; c++) {
                    CHECK(std::abs(a->mDirection[c] - b->mDirection[c]) <= 1e-4f);
                    CHECK(near(a->mWeight[c], b->mWeight[c]));
                }
            }
        }
    // The mapping's own numbers at one cell (metal 128/255, roughness 1; base colour
    // (0.8, 0.5, 0.3)): diffuse (1 - m) 0.96 b, Phong 0.04 (1 - m) + m b of exponent 0.
    const float m = 128.f / 255.f;
    const Material& half = scene.GetMaterial(2 + 3 * 2 + 1);
    CHECK_VEC3(half.mDiffuseReflectance, (1.f - m) * 0.96f * Vec3(0.8f, 0.5f, 0.3f), 1e-6f);
    CHECK_VEC3(half.mPhongReflectance, Vec3(0.04f * (1.f - m)) + m * Vec3(0.8f, 0.5f, 0.3f), 1e-6f);
    CHECK(half.mPhongExponent == 0.f);
}
