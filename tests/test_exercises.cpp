// [exercise] The graders of the coursework kit (docs/exercises/): one or more test cases
// per exercise, tagged [ex:<name>], that check the marked code of smallvcm.hpp against
// what it must compute -- the analytic distribution, the formula, an analytic radiance --
// and never against itself. `make grade STUDENT=...` compiles this file (and
// test_vcm_mis.cpp, which holds the MIS graders) against a student's copy of the header
// and turns each failure message into a diagnosis, so every failure says what is wrong
// in a student's terms. In the normal suite they check the reference.
//
// Each grader touches only its own exercise's code and code no exercise cuts (the kit's
// proof, `tests/exercises/kit.py prove`, cuts each exercise and checks that the others'
// graders still pass). That is why the light-tracing and photon-mapping graders use a
// point light (an area light's emission samples the cosine hemisphere, exercise 01) and
// the path-tracing grader uses Lambert surfaces only.
//
// Statistical tolerances: chi-square tests at significance 1e-3 (the threshold of
// test_util.hpp); renders are compared with analytic values within 4 standard errors
// measured from 8 independent renders (different seeds) plus 1e-3 relative (float
// rounding and the geodesic sphere's facets), as the furnace tests of test_integrators do.
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <cmath>
#include <sstream>
#include <string>
#include <vector>

using namespace smallvcm;
using namespace testutil;

// A check whose failure message is the diagnosis `make grade` shows to the student.
#define GRADE(aOk, aDiagnosis)             \
    do {                                   \
        if (aOk) SUCCEED();                \
        else FAIL_CHECK(aDiagnosis);       \
    } while (false)

namespace {

constexpr double kPiD = 3.14159265358979323846;

// P(X >= aStatistic) for X chi-square with aDof degrees of freedom, by the same
// Wilson-Hilferty approximation that ChiSquareThreshold inverts (p < 1e-3 exactly when
// the statistic exceeds the threshold); good to a few percent of p where it matters.
double ChiSquarePValue(double aStatistic, int aDof) {
    const double k = double(aDof);
    const double a = 2.0 / (9.0 * k);
    const double z = (std::cbrt(aStatistic / k) - (1.0 - a)) / std::sqrt(a);
    return 0.5 * std::erfc(z / std::sqrt(2.0));
}

std::string Percent(double aValue, double aExpected) {
    std::ostringstream out;
    out.precision(3);
    const double relative = 100.0 * (aValue / aExpected - 1.0);
    out << std::abs(relative) << " % too " << (relative < 0.0 ? "low" : "high");
    return out.str();
}

// Chi-square over a (u, phi) grid of 16 x 16 cells of equal probability under the
// expected distribution, plus one cell for samples outside it (expected 0 unless given).
struct GridTest {
    static constexpr int kCells = 16;
    std::vector<double> observed = std::vector<double>(kCells * kCells + 1, 0.0);
    std::vector<double> expected = std::vector<double>(kCells * kCells + 1, 0.0);
    void Add(double aU, double aPhi) {
        if (!(aU >= 0.0 && aU < 1.0)) { observed.back() += 1.0; return; }
        double phi = std::atan2(std::sin(aPhi), std::cos(aPhi));
        if (phi < 0.0) phi += 2.0 * kPiD;
        const int iu = std::min(kCells - 1, int(aU * kCells));
        const int iphi = std::min(kCells - 1, int(phi / (2.0 * kPiD) * kCells));
        observed[size_t(iu * kCells + iphi)] += 1.0;
    }
    std::string Describe(const ChiSquare& aChi) const {
        // The cell that is furthest off, as a hint of where the density is wrong.
        size_t worst = 0;
        double worstZ = 0.0;
        for (size_t i = 0; i < expected.size(); i++) {
            const double z = (observed[i] - expected[i]) / std::sqrt(std::max(expected[i], 1.0));
            if (std::abs(z) > std::abs(worstZ)) { worstZ = z; worst = i; }
        }
        std::ostringstream out;
        out.precision(3);
        out << "chi2 = " << aChi.statistic << " with " << aChi.dof << " dof, p = " << ChiSquarePValue(aChi.statistic, aChi.dof)
            << " (fails below 1e-3); most off: ";
        if (worst + 1 == expected.size()) out << "directions outside the expected support: " << observed[worst] << " samples";
        else out << "cell u in [" << double(worst / kCells) / kCells << ", " << double(worst / kCells + 1) / kCells
                 << "), phi sector " << worst % kCells << " has " << observed[worst] << " samples, expected " << expected[worst];
        return out.str();
    }
};

// An orthonormal basis around aZ built here, not with the header's Frame.
struct Basis {
    Vec3 x, y, z;
    explicit Basis(const Vec3& aZ) : z(glm::normalize(aZ)) {
        const Vec3 helper = std::abs(z.x) < 0.9f ? Vec3(1.f, 0.f, 0.f) : Vec3(0.f, 1.f, 0.f);
        x = glm::normalize(glm::cross(z, helper));
        y = glm::cross(z, x);
    }
    Vec3 ToWorld(const Vec3& aLocal) const { return aLocal.x * x + aLocal.y * y + aLocal.z * z; }
    Vec3 ToLocal(const Vec3& aWorld) const { return Vec3(glm::dot(aWorld, x), glm::dot(aWorld, y), glm::dot(aWorld, z)); }
};

// --- renders -------------------------------------------------------------------------

RenderOptions Options(Algorithm aAlgorithm, int aIterations, int aMaxPathLength) {
    RenderOptions options;
    options.mAlgorithm = aAlgorithm;
    options.mIterations = aIterations;
    options.mMaxPathLength = aMaxPathLength;
    options.mProgress = false;
    return options;
}

// aCount renders with different seeds: independent estimates of the same image.
std::vector<Image> IndependentRenders(const Scene& aScene, RenderOptions aOptions, int aCount, uint64_t aSeed) {
    std::vector<Image> images;
    for (int i = 0; i < aCount; i++) {
        aOptions.mSeed = aSeed + uint64_t(i) * 7919u;
        images.push_back(Render(aScene, aOptions).mImage);
    }
    return images;
}

// Mean over the pixels (channel average) of each render, then their mean and its SE.
MeanAndError ImageMean(const std::vector<Image>& aImages) {
    std::vector<double> means;
    for (const Image& image : aImages) means.push_back(PixelStatistics(image).mean);
    return MeanOf(means);
}

std::string RenderVerdict(const std::string& aWhat, const MeanAndError& aMeasured, double aExpected) {
    std::ostringstream out;
    out.precision(4);
    out << aWhat << " renders " << aMeasured.mean << " +- " << aMeasured.standardError << ", analytic " << aExpected << ": "
        << Percent(aMeasured.mean, aExpected);
    if (aMeasured.standardError > 0.0)
        out << " (" << std::abs(aMeasured.mean - aExpected) / aMeasured.standardError << " standard errors)";
    return out.str();
}

bool WithinTolerance(const MeanAndError& aMeasured, double aExpected) {
    return std::abs(aMeasured.mean - aExpected) <= 4.0 * aMeasured.standardError + 1e-3 * aExpected;
}

// The emissive furnace of test_util.hpp with its emitting triangles split into two
// lights (the upper and the lower half), so that picking a light has probability 1/2.
Scene MakeTwoLightFurnace(float aAlbedo, float aEmitted, int aWidth, int aHeight) {
    Scene scene;
    scene.mName = "two-light emissive furnace";
    Material wall;
    wall.mDiffuseReflectance = Vec3(aAlbedo);
    const int material = scene.AddMaterial(wall);
    std::vector<int> upper, lower;
    for (const auto& tri : InwardGeodesicSphere(1.f, 3)) {
        const int id = scene.AddTriangle(tri[0], tri[1], tri[2], material);
        ((tri[0].z + tri[1].z + tri[2].z) > 0.f ? upper : lower).push_back(id);
    }
    scene.AddAreaLight(upper, Vec3(aEmitted));
    scene.AddAreaLight(lower, Vec3(aEmitted));
    scene.mCamera.Setup(Vec3(0.1f, -0.2f, 0.05f), Vec3(0.3f, 1.f, 0.2f), Vec3(0.f, 0.f, 1.f), 60.f);
    scene.mCamera.SetResolution(aWidth, aHeight);
    scene.Finalize();
    return scene;
}

// An open box [-1, 1]^3 (floor, ceiling, back and side walls; open towards the camera)
// of Lambert albedo kBoxAlbedo lit by a point light of intensity kBoxIntensity: the
// direct light at every visible point is analytic, rho / pi * I cos / d^2.
constexpr float kBoxAlbedo = 0.6f;
const Vec3 kBoxLight(0.2f, 0.1f, 0.55f);
constexpr float kBoxIntensity = 2.f;
const char* const kWallNames[5] = {"floor", "ceiling", "back wall", "left wall", "right wall"};
const Vec3 kWallNormals[5] = {{0, 0, 1}, {0, 0, -1}, {0, -1, 0}, {1, 0, 0}, {-1, 0, 0}};

Scene MakeLitBox(int aWidth, int aHeight) {
    Scene scene;
    scene.mName = "open box with a point light";
    Material wall;
    wall.mDiffuseReflectance = Vec3(kBoxAlbedo);
    const int material = scene.AddMaterial(wall);
    for (const Vec3& inward : kWallNormals) {
        // The quad of the box's face opposite the inward normal, wound so that its
        // geometric normal points inwards.
        const Vec3 centre = -inward;
        const Vec3 u = std::abs(inward.z) > 0.5f ? Vec3(1, 0, 0) : Vec3(0, 0, 1);
        const Vec3 v = glm::cross(inward, u);
        Vec3 q[4] = {centre - u - v, centre + u - v, centre + u + v, centre - u + v};
        if (glm::dot(glm::cross(q[1] - q[0], q[2] - q[0]), inward) < 0.f) std::swap(q[1], q[3]);
        scene.AddTriangle(q[0], q[1], q[2], material);
        scene.AddTriangle(q[0], q[2], q[3], material);
    }
    scene.AddPointLight(kBoxLight, Vec3(kBoxIntensity));
    scene.mCamera.Setup(Vec3(0.f, -3.4f, 0.f), Vec3(0.f, 1.f, 0.f), Vec3(0.f, 0.f, 1.f), 42.f);
    scene.mCamera.SetResolution(aWidth, aHeight);
    scene.Finalize();
    return scene;
}

int WallOf(const Vec3& aNormal) {
    for (int w = 0; w < 5; w++)
        if (glm::dot(aNormal, kWallNormals[w]) > 0.99f) return w;
    return -1;
}

// Per pixel: the wall all of its 4 x 4 sub-pixel rays hit (-1 if they disagree or miss)
// and the mean analytic direct radiance over them (midpoint rule; the radiance is smooth
// on a wall, so the rule's error is far below the tests' noise).
void AnalyticDirectLight(const Scene& aScene, std::vector<int>& oWall, std::vector<double>& oRadiance) {
    const Camera& camera = aScene.mCamera;
    oWall.assign(size_t(camera.PixelCount()), -1);
    oRadiance.assign(size_t(camera.PixelCount()), 0.0);
    for (int y = 0; y < camera.Height(); y++)
        for (int x = 0; x < camera.Width(); x++) {
            int wall = -2;
            double sum = 0.0;
            for (int j = 0; j < 4; j++)
                for (int i = 0; i < 4; i++) {
                    const Ray ray = camera.GenerateRay(Vec2(float(x) + (float(i) + 0.5f) / 4.f, float(y) + (float(j) + 0.5f) / 4.f));
                    const SurfacePoint hit = aScene.Intersect(ray);
                    const int w = hit.IsValid() ? WallOf(hit.GeometricNormal()) : -1;
                    wall = (wall == -2 || wall == w) ? w : -1;
                    if (w < 0) continue;
                    const glm::dvec3 p = glm::dvec3(ray.mOrigin) + glm::dvec3(ray.mDirection) * double(hit.mDist);
                    const glm::dvec3 toLight = glm::dvec3(kBoxLight) - p;
                    const double d2 = glm::dot(toLight, toLight);
                    const double cosine = glm::dot(glm::dvec3(hit.GeometricNormal()), toLight) / std::sqrt(d2);
                    sum += double(kBoxAlbedo) / kPiD * double(kBoxIntensity) * std::max(0.0, cosine) / d2;
                }
            const size_t pixel = size_t(y * camera.Width() + x);
            oWall[pixel] = wall;
            oRadiance[pixel] = sum / 16.0;
        }
}

} // namespace

// =======================================================================================
// Exercise 01: cosine-weighted hemisphere sampling
// =======================================================================================

TEST_CASE("Exercise 01: SampleCosHemisphereW returns unit directions above the horizon with pdf cos(theta)/pi, as CosHemispherePdfW says",
          "[exercise][ex:cosine_hemisphere]") {
    Rng rng(101, 1);
    int bad = 0;
    std::string first;
    for (int i = 0; i < 20000; i++) {
        const Vec2 u = rng.GetVec2();
        const Vec3 d = SampleCosHemisphereW(u);
        const float pdf = CosHemispherePdfW(d);  // the density at the direction sampled
        const double expected = std::max(0.0, double(d.z)) / kPiD;
        std::ostringstream problem;
        if (!(std::abs(glm::length(d) - 1.f) < 1e-4f)) problem << "has length " << glm::length(d) << ", not 1";
        else if (!(d.z >= 0.f)) problem << "lies below the horizon (z = " << d.z << ")";
        else if (!(std::abs(pdf - expected) <= 1e-4 * expected + 1e-7))
            problem << ": CosHemispherePdfW gives " << pdf << ", but cos(theta)/pi = " << expected;
        if (problem.str().empty()) continue;
        if (bad++ == 0) {
            std::ostringstream out;
            out << "the sample for u = (" << u.x << ", " << u.y << "), direction (" << d.x << ", " << d.y << ", " << d.z << "), "
                << problem.str();
            first = out.str();
        }
    }
    GRADE(bad == 0, bad << " of 20000 samples are wrong; e.g. " << first);
    const float below = CosHemispherePdfW(glm::normalize(Vec3(0.3f, 0.2f, -0.5f)));
    GRADE(below == 0.f, "CosHemispherePdfW of a direction below the horizon is " << below << ", expected 0");
}

TEST_CASE("Exercise 01: cosine hemisphere samples are distributed as cos(theta)/pi (chi-square)", "[exercise][ex:cosine_hemisphere]") {
    // Under cos(theta)/pi, u = cos^2(theta) and phi are uniform and independent: 256
    // cells of equal probability.
    const int n = 100000;
    GridTest grid;
    for (size_t i = 0; i + 1 < grid.expected.size(); i++) grid.expected[i] = double(n) / (GridTest::kCells * GridTest::kCells);
    Rng rng(102, 3);
    for (int i = 0; i < n; i++) {
        const Vec3 d = SampleCosHemisphereW(rng.GetVec2());
        grid.Add(d.z >= 0.f ? double(d.z) * double(d.z) : -1.0, std::atan2(double(d.y), double(d.x)));
    }
    const ChiSquare chi = ComputeChiSquare(grid.observed, grid.expected);
    GRADE(chi.statistic < chi.threshold, "sampled directions' density differs from cos(theta)/pi: " << grid.Describe(chi));
}

// =======================================================================================
// Exercise 02: next-event estimation with MIS in the path tracer
// =======================================================================================

TEST_CASE("Exercise 02: the path tracer renders the emissive furnace's analytic radiance with light sampling alone and with MIS",
          "[exercise][ex:pt_nee_mis]") {
    // Two lights (the two halves of the sphere): L = Le (1 - a^k) / (1 - a) for paths of
    // at most k segments, whichever technique finds the light.
    const float albedo = 0.5f, emitted = 1.f;
    const int maxPathLength = 3;
    const double expected = emitted * (1.0 - std::pow(albedo, maxPathLength)) / (1.0 - albedo);
    const Scene scene = MakeTwoLightFurnace(albedo, emitted, 16, 16);
    struct Mode { const char* name; DirectLightSampling sampling; MisHeuristic heuristic; };
    const Mode modes[] = {{"light sampling alone", DirectLightSampling::kLightOnly, MisHeuristic::kBalance},
                          {"MIS, balance heuristic", DirectLightSampling::kMis, MisHeuristic::kBalance},
                          {"MIS, power heuristic", DirectLightSampling::kMis, MisHeuristic::kPower}};
    for (const Mode& mode : modes) {
        RenderOptions options = Options(Algorithm::kPathTracing, 4, maxPathLength);
        options.mDirectLight = mode.sampling;
        options.mMisHeuristic = mode.heuristic;
        const MeanAndError measured = ImageMean(IndependentRenders(scene, options, 8, 201));
        std::string hint;
        if (measured.mean < 0.6 * expected && mode.sampling == DirectLightSampling::kLightOnly)
            hint = "; only the light seen directly arrives: light sampling alone must find all the rest, is next-event estimation's contribution added?";
        else if (mode.sampling == DirectLightSampling::kLightOnly)
            hint = "; light sampling alone is wrong: check the light pick probability (1 / light count), that Illuminate's pdf is per "
                   "unit solid angle, the cosine at the vertex and the shadow ray";
        else if (measured.mean > 1.02 * expected && mode.sampling == DirectLightSampling::kMis)
            hint = "; too bright with MIS: is the light counted by both techniques without weights that sum to 1?";
        else if (measured.mean < 0.98 * expected && mode.sampling == DirectLightSampling::kMis)
            hint = "; too dark with MIS: are both pdfs in solid angle, with the light pick probability and the continuation probability?";
        GRADE(WithinTolerance(measured, expected),
              RenderVerdict("pt with " + std::string(mode.name) + " on the two-light emissive furnace", measured, expected) << hint);
    }
}

TEST_CASE("Exercise 02: a point light is sampled with weight 1 (no other technique can find it)", "[exercise][ex:pt_nee_mis]") {
    // L = 1 - 0.5^(k-1) for at most k segments (test_util.hpp's point-light furnace).
    const int maxPathLength = 4;
    const double expected = 1.0 - std::pow(0.5, maxPathLength - 1);
    const Scene scene = MakePointLightFurnace(16, 16);
    const MeanAndError measured = ImageMean(IndependentRenders(scene, Options(Algorithm::kPathTracing, 4, maxPathLength), 8, 202));
    GRADE(WithinTolerance(measured, expected),
          RenderVerdict("pt with MIS on the point-light furnace", measured, expected)
              << "; a point light (Light::IsDelta) has no BSDF-sampled technique, so next-event estimation takes weight 1");
}

// =======================================================================================
// Exercise 03: the Phong BSDF
// =======================================================================================

namespace {

Material PhongMaterial(float aExponent) {
    Material m;
    m.mName = "Phong " + std::to_string(int(aExponent));
    m.mPhongReflectance = Vec3(0.8f, 0.6f, 0.4f);
    m.mPhongExponent = aExponent;
    return m;
}
const Vec3 kTiltedNormal = glm::normalize(Vec3(0.3f, -0.5f, 0.8f));
const Basis kTilted(kTiltedNormal);
Vec3 Direction(float aCos, float aPhi) {
    const float s = std::sqrt(std::max(0.f, 1.f - aCos * aCos));
    return glm::normalize(kTilted.ToWorld(Vec3(s * std::cos(aPhi), s * std::sin(aPhi), aCos)));
}

} // namespace

TEST_CASE("Exercise 03: SamplePowerCosHemisphereW follows (n+1)/(2 pi) cos^n theta, the pdf PowerCosHemispherePdfW gives",
          "[exercise][ex:phong_bsdf]") {
    for (const float exponent : {1.f, 10.f, 90.f}) {
        const int n = 60000;
        GridTest grid;
        for (size_t i = 0; i + 1 < grid.expected.size(); i++) grid.expected[i] = double(n) / (GridTest::kCells * GridTest::kCells);
        Rng rng(301, uint64_t(exponent));
        int badPdf = 0;
        std::string first;
        for (int i = 0; i < n; i++) {
            const Vec3 d = SamplePowerCosHemisphereW(rng.GetVec2(), exponent);
            const float pdf = PowerCosHemispherePdfW(d, exponent);  // the density at the direction sampled
            // Under the lobe, u = cos^(n+1)(theta) is uniform.
            grid.Add(d.z > 0.f ? std::pow(double(d.z), double(exponent) + 1.0) : -1.0, std::atan2(double(d.y), double(d.x)));
            const double expected = d.z > 0.f ? (exponent + 1.0) / (2.0 * kPiD) * std::pow(double(d.z), double(exponent)) : 0.0;
            const double tolerance = 1e-3 * expected + 1e-6;
            if (std::abs(pdf - expected) > tolerance) {
                if (badPdf++ == 0) {
                    std::ostringstream out;
                    out << "at cos(theta) = " << d.z << " PowerCosHemispherePdfW says pdf " << pdf << ", expected " << expected;
                    first = out.str();
                }
            }
        }
        const ChiSquare chi = ComputeChiSquare(grid.observed, grid.expected);
        GRADE(chi.statistic < chi.threshold, "exponent " << exponent << ": sampled directions' density differs from the lobe "
                                                         "(n+1)/(2 pi) cos^n theta: " << grid.Describe(chi));
        GRADE(badPdf == 0, "exponent " << exponent << ": " << badPdf << " of " << n << " pdfs are wrong; e.g. " << first);
    }
}

TEST_CASE("Exercise 03: Bsdf::Evaluate gives the normalised Phong lobe rho (n+2)/(2 pi) cos^n(alpha) and pdf (n+1)/(2 pi) cos^n(alpha) both ways",
          "[exercise][ex:phong_bsdf]") {
    for (const float exponent : {1.f, 10.f, 90.f}) {
        const Material material = PhongMaterial(exponent);
        Rng rng(302, uint64_t(exponent));
        int bad = 0, compared = 0;
        std::string first;
        for (int i = 0; i < 4000; i++) {
            const Vec3 fix = Direction(0.05f + 0.95f * rng.GetFloat(), 6.2831853f * rng.GetFloat());
            // Half of the directions near the mirror direction, where the lobe lives.
            const Vec3 mirror = 2.f * glm::dot(kTiltedNormal, fix) * kTiltedNormal - fix;
            Vec3 gen = i % 2 ? Direction(0.02f + 0.98f * rng.GetFloat(), 6.2831853f * rng.GetFloat())
                             : glm::normalize(mirror + 0.3f * (rng.GetVec3() - Vec3(0.5f)));
            if (glm::dot(gen, kTiltedNormal) < 0.02f) continue;
            Bsdf bsdf;
            bsdf.Setup(fix, kTiltedNormal, material, Transport::kRadiance);
            REQUIRE(bsdf.IsValid());
            const BsdfEval eval = bsdf.Evaluate(gen);
            const Vec3 f = eval.mValue;
            const float cosGen = eval.mCosThetaGen, directPdfW = eval.mDirPdfW, reversePdfW = eval.mRevPdfW;
            const double cosAlpha = glm::dot(glm::dvec3(mirror), glm::dvec3(gen));
            const double lobe = cosAlpha > 0.0 ? std::pow(cosAlpha, double(exponent)) : 0.0;
            const double expectedF = double(material.mPhongReflectance.x) * (exponent + 2.0) / (2.0 * kPiD) * lobe;
            const double expectedPdf = (exponent + 1.0) / (2.0 * kPiD) * lobe;
            // Relative float error, plus what the header's cut at cos(alpha) = kEpsPhong may
            // drop, plus float underflow (cos^90 of 0.18 is 5e-66, 0 in float).
            const double slack = (exponent + 2.0) / (2.0 * kPiD) * std::pow(double(kEpsPhong), double(exponent)) + 1e-30;
            compared++;
            const bool ok = std::abs(f.x - expectedF) <= 1e-3 * expectedF + slack &&
                            std::abs(f.z / material.mPhongReflectance.z - f.x / material.mPhongReflectance.x) <= 1e-3 * expectedF / 0.8 + slack &&
                            std::abs(directPdfW - expectedPdf) <= 1e-3 * expectedPdf + slack &&
                            std::abs(reversePdfW - expectedPdf) <= 1e-3 * expectedPdf + slack &&
                            std::abs(cosGen - glm::dot(gen, kTiltedNormal)) < 1e-4f;
            if (!ok && bad++ == 0) {
                std::ostringstream out;
                out << "at cos(alpha) = " << cosAlpha << " (alpha: angle to the mirror direction) your f.r = " << f.x
                    << ", pdf " << directPdfW << ", reverse pdf " << reversePdfW << ", |cos| " << cosGen << "; expected f.r = "
                    << expectedF << ", pdf = reverse pdf = " << expectedPdf << ", |cos| " << glm::dot(gen, kTiltedNormal);
                first = out.str();
            }
        }
        GRADE(bad == 0, "exponent " << exponent << ": " << bad << " of " << compared << " evaluations are wrong; e.g. " << first);
    }
}

TEST_CASE("Exercise 03: Bsdf::Sample draws Phong directions from the lobe around the mirror direction, with the f and pdfs of Evaluate (chi-square)",
          "[exercise][ex:phong_bsdf]") {
    struct Case { float exponent, cosIn; };
    for (const Case c : {Case{10.f, 0.7f}, Case{90.f, 0.5f}, Case{3.f, 0.2f}}) {
        const Material material = PhongMaterial(c.exponent);
        const Vec3 fix = Direction(c.cosIn, 0.8f);
        Bsdf bsdf;
        bsdf.Setup(fix, kTiltedNormal, material, Transport::kRadiance);
        REQUIRE(bsdf.IsValid());
        const Vec3 mirror = 2.f * glm::dot(kTiltedNormal, fix) * kTiltedNormal - fix;
        const Basis lobeFrame(mirror);
        // Cells of equal probability under the lobe, u = cos^(n+1)(alpha) and phi around
        // the mirror direction; the part of a cell below the horizon (where Sample must
        // give up) is measured with 8 x 8 sub-cells and expected in the outside cell.
        GridTest grid;
        const int n = 60000;
        double inside = 0.0;
        for (int iu = 0; iu < GridTest::kCells; iu++)
            for (int iphi = 0; iphi < GridTest::kCells; iphi++) {
                int above = 0;
                for (int s = 0; s < 64; s++) {
                    const double u = (iu + (s % 8 + 0.5) / 8.0) / GridTest::kCells;
                    const double phi = 2.0 * kPiD * (iphi + (s / 8 + 0.5) / 8.0) / GridTest::kCells;
                    const double cosAlpha = std::pow(u, 1.0 / (c.exponent + 1.0));
                    const double sinAlpha = std::sqrt(std::max(0.0, 1.0 - cosAlpha * cosAlpha));
                    const Vec3 d = lobeFrame.ToWorld(Vec3(float(sinAlpha * std::cos(phi)), float(sinAlpha * std::sin(phi)), float(cosAlpha)));
                    if (glm::dot(d, kTiltedNormal) > 1e-3f) above++;
                }
                const double mass = double(above) / 64.0 / (GridTest::kCells * GridTest::kCells);
                grid.expected[size_t(iu * GridTest::kCells + iphi)] = n * mass;
                inside += mass;
            }
        grid.expected.back() = n * (1.0 - inside);
        Rng rng(303, uint64_t(c.exponent));
        int mismatched = 0;
        std::string first;
        for (int i = 0; i < n; i++) {
            const std::optional<ScatterSample> sample = bsdf.Sample(rng.GetVec3());
            if (!sample || !(sample->mPdfW > 0.f)) { grid.Add(-1.0, 0.0); continue; }
            const Vec3 d = sample->mDirection, f = sample->mValue;
            const float pdf = sample->mPdfW, reversePdf = sample->mReversePdfW;
            const uint32_t event = sample->mEvent;
            const Vec3 local = lobeFrame.ToLocal(d);
            grid.Add(local.z > 0.f ? std::pow(double(local.z), c.exponent + 1.0) : -1.0, std::atan2(double(local.y), double(local.x)));
            const BsdfEval eval = bsdf.Evaluate(d);
            const Vec3 fEval = eval.mValue;
            const float pdfEval = eval.mDirPdfW, reverseEval = eval.mRevPdfW;
            const bool same = glm::length(f - fEval) <= 1e-4f * glm::length(fEval) + 1e-7f &&
                              std::abs(pdf - pdfEval) <= 1e-4f * pdfEval + 1e-7f &&
                              std::abs(reversePdf - reverseEval) <= 1e-4f * reverseEval + 1e-7f && event == kEventPhong;
            if (!same && mismatched++ == 0) {
                std::ostringstream out;
                out << "Sample returned f.r = " << f.x << ", pdf " << pdf << ", reverse pdf " << reversePdf << ", event " << event
                    << "; Evaluate for the same direction gives f.r = " << fEval.x << ", pdf " << pdfEval << ", reverse pdf "
                    << reverseEval << " (event should be kEventPhong = " << kEventPhong << ")";
                first = out.str();
            }
        }
        const ChiSquare chi = ComputeChiSquare(grid.observed, grid.expected);
        GRADE(chi.statistic < chi.threshold, "exponent " << c.exponent << ", cos incident " << c.cosIn
                                             << ": Bsdf::Sample's directions do not follow the Phong lobe around the mirror direction: "
                                             << grid.Describe(chi));
        GRADE(mismatched == 0, "exponent " << c.exponent << ": " << mismatched << " samples disagree with Evaluate; e.g. " << first);
    }
}

// =======================================================================================
// Exercise 04: light tracing, the connection to the camera
// =======================================================================================

TEST_CASE("Exercise 04: light tracing's direct light matches the analytic value on every wall of a box lit by a point light",
          "[exercise][ex:lt_camera]") {
    // Paths of at most 2 segments: light -> wall -> camera, all through ConnectToCamera.
    // Per wall, the mean over the pixels that see only that wall; SE from 8 renders of 64
    // iterations (measured: 0.24 % of the value on the right wall, so a 1-2 % error in
    // the camera pdf fails; a missing cosine at the camera gave 6-7 % on the side walls).
    const Scene scene = MakeLitBox(32, 32);
    std::vector<int> wall;
    std::vector<double> analytic;
    AnalyticDirectLight(scene, wall, analytic);
    const std::vector<Image> images = IndependentRenders(scene, Options(Algorithm::kLightTracing, 64, 2), 8, 401);
    for (int w = 0; w < 5; w++) {
        double expected = 0.0;
        int pixels = 0;
        for (size_t p = 0; p < wall.size(); p++)
            if (wall[p] == w) { expected += analytic[p]; pixels++; }
        REQUIRE(pixels >= 20);
        expected /= pixels;
        std::vector<double> means;
        for (const Image& image : images) {
            double sum = 0.0;
            for (size_t p = 0; p < wall.size(); p++)
                if (wall[p] == w) sum += (double(image.mPixels[p].x) + image.mPixels[p].y + image.mPixels[p].z) / 3.0;
            means.push_back(sum / pixels);
        }
        const MeanAndError measured = MeanOf(means);
        GRADE(WithinTolerance(measured, expected),
              "your lt and the analytic direct light disagree by " << Percent(measured.mean, expected) << " on the "
              << kWallNames[w] << " (" << pixels << " pixels; lt " << measured.mean << " +- " << measured.standardError
              << ", analytic " << expected << ")");
    }
}

TEST_CASE("Exercise 04: light tracing renders the point-light furnace's analytic radiance", "[exercise][ex:lt_camera]") {
    const int maxPathLength = 4;
    const double expected = 1.0 - std::pow(0.5, maxPathLength - 1);
    const Scene scene = MakePointLightFurnace(16, 16);
    const MeanAndError measured = ImageMean(IndependentRenders(scene, Options(Algorithm::kLightTracing, 32, maxPathLength), 8, 402));
    GRADE(WithinTolerance(measured, expected), RenderVerdict("lt on the point-light furnace", measured, expected));
}

// =======================================================================================
// Exercise 05: progressive photon mapping, the kernel and the radius schedule
// =======================================================================================

TEST_CASE("Exercise 05: the merging radius follows r_i = r_0 (i+1)^((alpha-1)/2)", "[exercise][ex:ppm_merging]") {
    const Scene scene = MakePointLightFurnace(8, 8);
    for (const float alpha : {0.5f, 0.75f, 1.f}) {
        RenderOptions options = Options(Algorithm::kProgressivePhotonMapping, 1, 4);
        options.mRadiusFactor = 0.01f;
        options.mRadiusAlpha = alpha;
        const VertexCM renderer(scene, options);
        const double r0 = 0.01 * double(scene.GetSceneSphere().mRadius);
        for (const int i : {0, 1, 9, 99, 9999}) {
            const double expected = r0 * std::pow(double(i) + 1.0, 0.5 * (double(alpha) - 1.0));
            const double radius = renderer.MergeRadius(i);
            GRADE(std::abs(radius - expected) <= 1e-5 * expected,
                  "alpha " << alpha << ": your radius at iteration " << i << " is " << radius << ", expected r_0 (i+1)^((alpha-1)/2) = "
                           << expected << " with r_0 = " << r0);
        }
    }
}

TEST_CASE("Exercise 05: progressive photon mapping renders the point-light furnace's analytic radiance", "[exercise][ex:ppm_merging]") {
    // On a sphere the photons within distance r of a point lie on a cap of area exactly
    // pi r^2 (Archimedes) and their density is uniform, so the estimate is unbiased at
    // any radius: only the kernel's normalisation and the gathering decide the mean.
    const int maxPathLength = 4;
    const double expected = 1.0 - std::pow(0.5, maxPathLength - 1);
    // 24 x 24 pixels (N_L = 576 light paths), radius 0.03 x scene radius, 8 renders of 32
    // iterations: measured SE 0.9 % of the value (a kernel without pi is 190 % off).
    const Scene scene = MakePointLightFurnace(24, 24);
    RenderOptions options = Options(Algorithm::kProgressivePhotonMapping, 32, maxPathLength);
    options.mRadiusFactor = 0.03f;
    const MeanAndError measured = ImageMean(IndependentRenders(scene, options, 8, 501));
    GRADE(WithinTolerance(measured, expected),
          RenderVerdict("ppm on the point-light furnace", measured, expected)
              << "; the estimate is sum f * throughput over the vertices within r, times 1 / (pi r^2 N_L)");
}

// =======================================================================================
// Every copy: the stubs (and a student's code) must be safe to run
// =======================================================================================

TEST_CASE("Kit: every algorithm renders a finite, non-negative image of every Cornell scene", "[exercise][ex:safety]") {
    // Not an exercise's grader: `make grade` and the kit's proof run it on every copy, so
    // that a stub (or a student's code) that writes NaN, infinity or negative values, or
    // crashes, is named even where no grader looks.
    for (int s = 0; s < 5; s++) {
        const Scene scene = LoadCornell(s, 16, 16);
        for (Algorithm algorithm : {Algorithm::kEyeLight, Algorithm::kPathTracing, Algorithm::kLightTracing,
                                    Algorithm::kProgressivePhotonMapping, Algorithm::kBidirectionalPhotonMapping,
                                    Algorithm::kBidirectionalPathTracing, Algorithm::kVertexConnectionMerging,
                                    Algorithm::kPhotonMapping, Algorithm::kPhotonMappingFinalGather}) {
            RenderOptions options = Options(algorithm, 2, 10);
            options.mPhotonCount = 5000;
            const Image image = Render(scene, options).mImage;
            int bad = 0;
            for (const Vec3& p : image.mPixels)
                if (!IsFinite(p) || p.x < 0.f || p.y < 0.f || p.z < 0.f) bad++;
            GRADE(bad == 0, AlgorithmShortName(algorithm) << " on Cornell scene " << s << " writes " << bad
                                                          << " pixels that are NaN, infinite or negative");
        }
    }
}
