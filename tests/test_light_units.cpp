// [light_units] Each light kind as a unit, against analytic values and against itself
// across the three ways the integrators see it (Illuminate for next-event estimation,
// Emit for light sub-paths, GetRadiance for a ray that hits it):
//   * next-event estimation's solid-angle pdf integrates to one over the light as seen
//     from a point: E[1 / p_W] over its samples is the solid angle the light's front
//     subtends (analytic for triangles and spheres); a back face adds nothing;
//   * light sub-paths carry the light's power: E[energy / emission pdf] = Phi;
//   * sampled points are uniform by area (chi-square over sub-triangles);
//   * the three operations report the same pdfs for the same point and direction.
// Tolerances: 4 standard errors of the Monte Carlo mean (measured from the samples) plus
// 1e-4 relative (float rounding of the sample values); chi-square at significance 1e-3
// (test_util.hpp); equal pdfs to 1e-4 relative, cosines above 0.01 (a few float operations
// on each side, each cosine from a separately normalised float vector; 1e-5 failed on a
// sphere at cosines near 1e-3).
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <cstdio>
#include <sstream>

using namespace smallvcm;
using namespace testutil;

namespace {

// A scene of lights only (and the geometry they need): an area light made of a unit
// square at z = 1 facing down (-z), a smaller triangle at z = 1.5 facing down and a
// triangle at z = 1.2 facing UP (away from a receiver at the origin); a sphere light of
// radius 0.5 at (0, 0, -3); a point light, a directional light and a background.
struct LightScene {
    Scene scene;
    int area = -1, sphere = -1, point = -1, directional = -1, background = -1;
};

LightScene MakeLightScene() {
    LightScene l;
    Scene& scene = l.scene;
    Material black;
    const int material = scene.AddMaterial(black);
    std::vector<int> ids;
    // Wound so that the normal (Scene::Finalize: from the winding) is -z.
    ids.push_back(scene.AddTriangle(Vec3(-0.5f, -0.5f, 1.f), Vec3(0.5f, 0.5f, 1.f), Vec3(0.5f, -0.5f, 1.f), material));
    ids.push_back(scene.AddTriangle(Vec3(-0.5f, -0.5f, 1.f), Vec3(-0.5f, 0.5f, 1.f), Vec3(0.5f, 0.5f, 1.f), material));
    ids.push_back(scene.AddTriangle(Vec3(1.f, 0.f, 1.5f), Vec3(1.f, 1.f, 1.5f), Vec3(2.f, 0.f, 1.5f), material));
    ids.push_back(scene.AddTriangle(Vec3(-2.f, 0.f, 1.2f), Vec3(-1.f, 0.f, 1.2f), Vec3(-2.f, 1.f, 1.2f), material));
    l.area = scene.AddAreaLight(ids, Vec3(2.f, 1.f, 0.5f));
    l.sphere = scene.AddSphereLight(scene.AddSphere(Vec3(0.f, 0.f, -3.f), 0.5f, material), Vec3(1.5f));
    l.point = scene.AddPointLight(Vec3(0.3f, -0.2f, 0.4f), Vec3(3.f));
    l.directional = scene.AddDirectionalLight(Vec3(0.2f, 0.3f, -1.f), Vec3(0.7f));
    l.background = scene.AddBackgroundLight(Vec3(0.25f));
    scene.Finalize();
    return l;
}

// The solid angle of triangle (a, b, c) seen from the origin (Van Oosterom and Strackee 1983).
double TriangleSolidAngle(const glm::dvec3& aA, const glm::dvec3& aB, const glm::dvec3& aC) {
    const double la = glm::length(aA), lb = glm::length(aB), lc = glm::length(aC);
    const double numerator = std::abs(glm::dot(aA, glm::cross(aB, aC)));
    const double denominator = la * lb * lc + glm::dot(aA, aB) * lc + glm::dot(aA, aC) * lb + glm::dot(aB, aC) * la;
    return 2.0 * std::atan2(numerator, denominator);
}

// E[1 / p_W] over aSamples next-event samples of aLight from aReceiver.
MeanAndError InverseDirectPdf(const Scene& aScene, const Light& aLight, const Vec3& aReceiver, int aSamples, uint64_t aSeed) {
    Rng rng(aSeed);
    std::vector<double> values;
    values.reserve(size_t(aSamples));
    for (int i = 0; i < aSamples; i++) {
        const std::optional<LightSample> sample = aLight.Illuminate(aScene.GetSceneSphere(), aReceiver, rng.GetVec2());
        values.push_back(sample && sample->mDirectPdfW > 0.f ? 1.0 / double(sample->mDirectPdfW) : 0.0);
    }
    return MeanOf(values);
}

bool WithinNoise(const MeanAndError& aStats, double aExpected) {
    return std::abs(aStats.mean - aExpected) <= 4.0 * aStats.standardError + 1e-4 * std::abs(aExpected);
}

bool Close(double aA, double aB) { return std::abs(aA - aB) <= 1e-4 * std::max(std::abs(aA), std::abs(aB)); }

} // namespace

TEST_CASE("Next-event estimation's pdf integrates to one over the light's front as seen from a point", "[light_units]") {
    const LightScene l = MakeLightScene();
    const Scene& scene = l.scene;
    SECTION("area light: the two triangles facing the receiver count, the one facing away does not") {
        const double expected =
            TriangleSolidAngle({-0.5, -0.5, 1}, {0.5, 0.5, 1}, {0.5, -0.5, 1}) +
            TriangleSolidAngle({-0.5, -0.5, 1}, {-0.5, 0.5, 1}, {0.5, 0.5, 1}) +
            TriangleSolidAngle({1, 0, 1.5}, {1, 1, 1.5}, {2, 0, 1.5});
        const MeanAndError stats = InverseDirectPdf(scene, scene.GetLight(l.area), Vec3(0.f), 200000, 3);
        std::printf("[light_units] area light: E[1/p_W] %.5f +- %.5f, solid angle %.5f\n", stats.mean, stats.standardError, expected);
        INFO("E[1/p_W] " << stats.mean << " +- " << stats.standardError << ", solid angle " << expected);
        CHECK(WithinNoise(stats, expected));
    }
    SECTION("sphere light: the cap seen from the receiver") {
        const double sinMax = 0.5 / 3.0;
        const double expected = 2.0 * 3.14159265358979323846 * (1.0 - std::sqrt(1.0 - sinMax * sinMax));
        const MeanAndError stats = InverseDirectPdf(scene, scene.GetLight(l.sphere), Vec3(0.f), 200000, 4);
        std::printf("[light_units] sphere light: E[1/p_W] %.6f +- %.6f, solid angle %.6f\n", stats.mean, stats.standardError, expected);
        INFO("E[1/p_W] " << stats.mean << " +- " << stats.standardError << ", solid angle " << expected);
        CHECK(WithinNoise(stats, expected));
    }
    SECTION("background: the whole sphere of directions") {
        const MeanAndError stats = InverseDirectPdf(scene, scene.GetLight(l.background), Vec3(0.f), 20000, 5);
        CHECK(WithinNoise(stats, 4.0 * 3.14159265358979323846));
    }
}

TEST_CASE("Light sub-paths carry each light's analytic power: E[energy / emission pdf] = Phi", "[light_units]") {
    const LightScene l = MakeLightScene();
    const Scene& scene = l.scene;
    const double pi = 3.14159265358979323846;
    const double sceneRadius = double(scene.GetSceneSphere().mRadius);
    const double disc = pi * sceneRadius * sceneRadius;
    const double areaOfAreaLight = 1.0 + 0.5 + 0.5;
    struct Case { const char* name; int light; double power; };  // red channel
    const Case cases[] = {
        {"area", l.area, pi * 2.0 * areaOfAreaLight},             // pi Le A
        {"sphere", l.sphere, pi * 1.5 * 4.0 * pi * 0.25},         // pi Le 4 pi r^2
        {"point", l.point, 4.0 * pi * 3.0},                       // 4 pi I
        {"directional", l.directional, 0.7 * disc},               // E pi R^2 through the scene's disc
        {"background", l.background, 0.25 * 4.0 * pi * disc},     // Le 4 pi x pi R^2
    };
    for (const Case& c : cases) {
        const Light& light = scene.GetLight(c.light);
        Rng rng(17);
        std::vector<double> values;
        for (int i = 0; i < 100000; i++) {
            const Vec2 direction = rng.GetVec2();
            const Vec2 position = rng.GetVec2();
            const std::optional<LightEmission> emission = light.Emit(scene.GetSceneSphere(), direction, position);
            const bool ok = emission && emission->mEmissionPdfW > 0.f;
            values.push_back(ok ? double(emission->mEnergy.x) / double(emission->mEmissionPdfW) : 0.0);
        }
        const MeanAndError stats = MeanOf(values);
        std::printf("[light_units] %-11s power %.5f +- %.5f, analytic %.5f\n", c.name, stats.mean, stats.standardError, c.power);
        INFO(c.name << ": E[energy / pdf] " << stats.mean << " +- " << stats.standardError << ", analytic " << c.power);
        CHECK(WithinNoise(stats, c.power));
    }
}

TEST_CASE("Points sampled on an area light are uniform by area across and within its triangles (chi-square)", "[light_units]") {
    // Bins: each of the four triangles split at its edge midpoints into four of equal area.
    const LightScene l = MakeLightScene();
    const Scene& scene = l.scene;
    const Light& light = scene.GetLight(l.area);
    const int triangles = int(light.mTriangleP0.size());
    REQUIRE(triangles == 4);
    const int samples = 160000;
    std::vector<double> counts(size_t(4 * triangles), 0.0);
    Rng rng(23);
    int unplaced = 0;
    for (int i = 0; i < samples; i++) {
        const std::optional<LightEmission> emission = light.Emit(scene.GetSceneSphere(), rng.GetVec2(), rng.GetVec2());
        if (!emission) {  // no point to place (cannot happen: the light is not textured)
            unplaced++;
            continue;
        }
        int bin = -1;
        for (int t = 0; t < triangles && bin < 0; t++) {
            // Barycentric coordinates of the point in triangle t.
            const glm::dvec3 e1(light.mTriangleE1[size_t(t)]), e2(light.mTriangleE2[size_t(t)]);
            const glm::dvec3 q = glm::dvec3(emission->mPosition) - glm::dvec3(light.mTriangleP0[size_t(t)]);
            const glm::dvec3 n = glm::cross(e1, e2);
            if (std::abs(glm::dot(q, n)) > 1e-5 * glm::length(n)) continue;  // not in its plane
            const double nn = glm::dot(n, n);
            const double u = glm::dot(glm::cross(q, e2), n) / nn, v = glm::dot(glm::cross(e1, q), n) / nn;
            const double eps = 1e-6;
            if (u < -eps || v < -eps || u + v > 1.0 + eps) continue;
            // Sub-triangles: corner 0 (u + v < 1/2), corner 1 (u > 1/2), corner 2 (v > 1/2), middle.
            const int sub = u + v < 0.5 ? 0 : u > 0.5 ? 1 : v > 0.5 ? 2 : 3;
            bin = 4 * t + sub;
        }
        if (bin < 0) unplaced++;
        else counts[size_t(bin)] += 1.0;
    }
    CHECK(unplaced == 0);
    double total = 0.0;
    for (int t = 0; t < triangles; t++) total += glm::length(glm::cross(glm::dvec3(light.mTriangleE1[size_t(t)]), glm::dvec3(light.mTriangleE2[size_t(t)]))) / 2.0;
    double chi2 = 0.0;
    for (int t = 0; t < triangles; t++) {
        const double area = glm::length(glm::cross(glm::dvec3(light.mTriangleE1[size_t(t)]), glm::dvec3(light.mTriangleE2[size_t(t)]))) / 2.0;
        for (int sub = 0; sub < 4; sub++) {
            const double expected = double(samples) * area / total / 4.0;
            chi2 += Sqr(float(counts[size_t(4 * t + sub)] - expected)) / expected;
        }
    }
    INFO("chi-square " << chi2 << " with " << 4 * triangles - 1 << " degrees of freedom, threshold " << ChiSquareThreshold(4 * triangles - 1));
    CHECK(chi2 < ChiSquareThreshold(4 * triangles - 1));
}

TEST_CASE("Next-event estimation, emission and a ray hitting a light report the same pdfs for the same point and direction", "[light_units]") {
    const LightScene l = MakeLightScene();
    const Scene& scene = l.scene;
    const SceneSphere& sphere = scene.GetSceneSphere();
    Rng rng(29);
    int compared = 0;
    SECTION("area and sphere lights: Illuminate's sample against GetRadiance for the same point") {
        for (int id : {l.area, l.sphere}) {
            const Light& light = scene.GetLight(id);
            for (int i = 0; i < 2000; i++) {
                const Vec3 receiver = id == l.area ? Vec3(0.f) : Vec3(0.f, 0.f, -1.f);
                const std::optional<LightSample> lit = light.Illuminate(sphere, receiver, rng.GetVec2());
                // Near the horizon the two sides' float cosines differ relatively more.
                if (!lit || lit->mCosAtLight < 0.01f) continue;
                const LightSample& sample = *lit;
                const Vec3 point = receiver + sample.mDirToLight * sample.mDistance;
                const Vec3 normal = id == l.sphere ? glm::normalize(point - light.mSphereCenter) : Vec3(0.f, 0.f, -1.f);
                const Light::RadianceAtHit received = light.GetRadiance(sphere, sample.mDirToLight, normal, Vec2(0.f));
                const Vec3 radiance = received.mRadiance;
                const float directPdfA = received.mDirectPdfA, emissionPdfW = received.mEmissionPdfW;
                INFO(LightTypeName(light.mType) << " light, sample " << i);
                CHECK(radiance == sample.mRadiance);
                CHECK(Close(emissionPdfW, sample.mEmissionPdfW));
                CHECK(Close(PdfAtoW(directPdfA, sample.mDistance, sample.mCosAtLight), sample.mDirectPdfW));
                compared++;
            }
        }
        CHECK(compared > 1500);
    }
    SECTION("area and sphere lights: Emit's pdfs against GetRadiance for the emitted ray") {
        for (int id : {l.area, l.sphere}) {
            const Light& light = scene.GetLight(id);
            for (int i = 0; i < 2000; i++) {
                const Vec2 direction = rng.GetVec2();
                const std::optional<LightEmission> emitted = light.Emit(sphere, direction, rng.GetVec2());
                if (!emitted) continue;
                const LightEmission& emission = *emitted;
                const Light::RadianceAtHit received = light.GetRadiance(sphere, -emission.mDirection, emission.mNormal, Vec2(0.f));
                const float directPdfA = received.mDirectPdfA, emissionPdfW = received.mEmissionPdfW;
                INFO(LightTypeName(light.mType) << " light, sample " << i << ", cos " << emission.mCosAtLight);
                if (emission.mCosAtLight <= kEpsCosine * 1.01f) continue;  // Emit clamps the cosine at the horizon
                CHECK(Close(emissionPdfW, emission.mEmissionPdfW));
                CHECK(Close(directPdfA, emission.mDirectPdfA));
                compared++;
            }
        }
        CHECK(compared > 3000);
    }
    SECTION("point, directional and background lights: Emit against Illuminate (and GetRadiance)") {
        for (int id : {l.point, l.directional, l.background}) {
            const Light& light = scene.GetLight(id);
            for (int i = 0; i < 200; i++) {
                const std::optional<LightEmission> emitted = light.Emit(sphere, rng.GetVec2(), rng.GetVec2());
                REQUIRE(emitted.has_value());
                const LightEmission& emission = *emitted;
                // A receiver along the emitted ray; for the background, Illuminate's
                // sample is another direction, whose pdfs must be the same constants.
                const Vec3 receiver = emission.mPosition + 0.7f * emission.mDirection;
                const std::optional<LightSample> lit = light.Illuminate(sphere, receiver, rng.GetVec2());
                REQUIRE(lit.has_value());
                const LightSample& sample = *lit;
                INFO(LightTypeName(light.mType) << " light, sample " << i);
                CHECK(Close(sample.mEmissionPdfW, emission.mEmissionPdfW));
                // Delta and infinite lights: Illuminate's "solid angle" pdf is the area pdf
                // times d^2 (point light) or the direction's pdf itself.
                const float directPdfA = light.mType == LightType::kPoint ? sample.mDirectPdfW / Sqr(sample.mDistance)
                                                                          : sample.mDirectPdfW;
                CHECK(Close(directPdfA, emission.mDirectPdfA));
                if (light.mType == LightType::kBackground) {
                    const Light::RadianceAtHit received = light.GetRadiance(sphere, -sample.mDirToLight, Vec3(0.f), Vec2(0.f));
                    const float hitDirectPdf = received.mDirectPdfA, hitEmissionPdf = received.mEmissionPdfW;
                    CHECK(Close(hitDirectPdf, sample.mDirectPdfW));
                    CHECK(Close(hitEmissionPdf, sample.mEmissionPdfW));
                }
            }
        }
    }
}

TEST_CASE("A textured area light gives each point it samples the texel at that point (Illuminate and Emit)", "[light_units]") {
    // The area light of MakeLightScene given texture coordinates u = (x + 2.1) / 4.2,
    // v = (y + 0.6) / 1.7 on all four triangles (inside [0, 1]) and a 4 x 4 texture whose 16 texels all
    // differ, read bilinearly with clamp-to-edge: the emitted radiance varies smoothly over
    // the light, and no two points on a triangle share it along the texture's diagonals.
    // For each sample of next-event estimation (Illuminate) and of light sub-paths (Emit),
    // the test finds the point's triangle and barycentric coordinates itself (in double,
    // as the chi-square test above does), interpolates the triangle's texture coordinates
    // and looks the texel up: the light must report emission x that texel. A point sampled
    // with one set of barycentrics but given the texture coordinates of another (mutant
    // M51: position and uv built from permuted barycentrics) gets another point's texel.
    // Tolerance: 1e-4 relative (the texture coordinates from the two routes differ by float
    // rounding, ~1e-7, and a texel step of 0.06 spans 1/4 of the coordinate: < 1e-5 change).
    LightScene l = MakeLightScene();
    Scene& scene = l.scene;
    Texture texture;
    texture.mWidth = texture.mHeight = 4;
    texture.mWrapU = texture.mWrapV = TextureWrap::kClampToEdge;
    for (int i = 0; i < 16; i++) texture.mTexels.push_back(Vec3(0.05f + 0.06f * float(i), 1.f - 0.055f * float(i), 0.3f));
    scene.mTextures.push_back(texture);
    const auto uvOf = [](const Vec3& aPoint) { return Vec2((aPoint.x + 2.1f) / 4.2f, (aPoint.y + 0.6f) / 1.7f); };
    for (Triangle& triangle : scene.mTriangles) {
        if (triangle.mLightId != l.area) continue;
        triangle.mUv0 = uvOf(triangle.mP0);
        triangle.mUv1 = uvOf(triangle.mP1);
        triangle.mUv2 = uvOf(triangle.mP2);
    }
    scene.mLights[size_t(l.area)].mEmissionTexture = int(scene.mTextures.size()) - 1;
    scene.Finalize();
    const Light& light = scene.GetLight(l.area);
    REQUIRE(light.mEmissionTexture >= 0);

    // Emission x texel at aPoint, found from the scene's triangles (not from the light).
    const auto expectedRadiance = [&](const Vec3& aPoint, bool& oFound) {
        oFound = false;
        for (const Triangle& triangle : scene.mTriangles) {
            if (triangle.mLightId != l.area) continue;
            const glm::dvec3 p0(triangle.mP0), e1 = glm::dvec3(triangle.mP1) - p0, e2 = glm::dvec3(triangle.mP2) - p0;
            const glm::dvec3 q = glm::dvec3(aPoint) - p0, n = glm::cross(e1, e2);
            if (std::abs(glm::dot(q, n)) > 1e-5 * glm::length(n)) continue;  // not in its plane
            const double nn = glm::dot(n, n);
            const double b1 = glm::dot(glm::cross(q, e2), n) / nn, b2 = glm::dot(glm::cross(e1, q), n) / nn;
            if (b1 < -1e-6 || b2 < -1e-6 || b1 + b2 > 1.0 + 1e-6) continue;
            const glm::dvec2 uv = (1.0 - b1 - b2) * glm::dvec2(triangle.mUv0) + b1 * glm::dvec2(triangle.mUv1) +
                                  b2 * glm::dvec2(triangle.mUv2);
            oFound = true;
            return light.mEmission * texture.Lookup(Vec2(uv));
        }
        return Vec3(0.f);
    };
    const auto close = [](const Vec3& aA, const Vec3& aB) {
        for (int c = 0; c < 3; c++)
            if (std::abs(aA[c] - aB[c]) > 1e-4f * std::max(std::abs(aA[c]), std::abs(aB[c]))) return false;
        return true;
    };

    Rng rng(31);
    int illuminated = 0, emitted = 0, wrongIlluminate = 0, wrongEmit = 0;
    std::ostringstream firstWrong;  // the first disagreement of each operation
    const auto describe = [&](const char* aOperation, int aSample, const Vec3& aGot, const Vec3& aExpected) {
        firstWrong << aOperation << ", sample " << aSample << ": radiance (" << aGot.x << ", " << aGot.y << ", " << aGot.z
                   << "), the texture at the point gives (" << aExpected.x << ", " << aExpected.y << ", " << aExpected.z << ")\n";
    };
    for (int i = 0; i < 4000; i++) {
        if (const std::optional<LightSample> lit = light.Illuminate(scene.GetSceneSphere(), Vec3(0.f), rng.GetVec2())) {
            const LightSample& sample = *lit;
            const Vec3 point = sample.mDirToLight * sample.mDistance;
            bool found = false;
            const Vec3 expected = expectedRadiance(point, found);
            REQUIRE(found);
            if (!close(sample.mRadiance, expected)) {
                if (wrongIlluminate++ == 0) describe("Illuminate", i, sample.mRadiance, expected);
            }
            illuminated++;
        }
        const Vec2 direction = rng.GetVec2();
        if (const std::optional<LightEmission> emitting = light.Emit(scene.GetSceneSphere(), direction, rng.GetVec2())) {
            const LightEmission& emission = *emitting;
            bool found = false;
            const Vec3 expected = expectedRadiance(emission.mPosition, found);
            REQUIRE(found);
            if (!close(emission.mRadiance, expected)) {
                if (wrongEmit++ == 0) describe("Emit", i, emission.mRadiance, expected);
            }
            emitted++;
        }
    }
    std::printf("[light_units] textured area light: %d of %d Illuminate and %d of %d Emit samples disagree with the texel at their point\n",
                wrongIlluminate, illuminated, wrongEmit, emitted);
    CHECK(illuminated > 2500);
    CHECK(emitted > 3500);
    INFO(firstWrong.str());
    CHECK(wrongIlluminate == 0);
    CHECK(wrongEmit == 0);
}
