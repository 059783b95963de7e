// [lights] The environment light (EnvironmentMap in the Scene section, a background light
// whose radiance comes from an equirectangular image) against its definition, written out
// again here from the mapping the header's comment and docs/scene_format.md state:
//   * the mapping: which texel each direction sees, with and without a rotation;
//   * sampling: the pdf a sample reports equals PdfW at its direction, PdfW integrates to
//     1 over the sphere, and texels are picked in proportion to luminance x sin(theta)
//     (chi-square);
//   * loading: bad maps are refused in one line naming the file and the problem.
// [lights][integrators] (whole renders, excluded from `make unit`):
//   * orientation: the environment seen directly, and in a mirror ball, shows the texel
//     of the mapping;
//   * a furnace of known answer: a diffuse plane under a non-uniform, rotated map renders
//     rho / pi x Integral L(w) max(0, n.w) dw, the integral summed texel by texel here;
//   * a constant map renders what the uniform background of the same radiance renders.
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <cmath>
#include <fstream>
#include <memory>
#include <vector>

using namespace smallvcm;
using namespace testutil;

namespace {

constexpr double kPiD = 3.14159265358979323846;

// The documented mapping in double: the direction at texture coordinates (u, v) of a map
// turned by aRotationDegrees about +Y (counter-clockwise seen from above).
glm::dvec3 MapDirection(double aU, double aV, double aRotationDegrees) {
    const double phi = 2.0 * kPiD * (aU - 0.5), theta = kPiD * aV;
    const glm::dvec3 local(std::sin(theta) * std::cos(phi), std::cos(theta), std::sin(theta) * std::sin(phi));
    const double a = aRotationDegrees * kPiD / 180.0;
    // Turning about +Y by a takes +X to (cos a, 0, -sin a).
    return glm::dvec3(std::cos(a) * local.x + std::sin(a) * local.z, local.y, -std::sin(a) * local.x + std::cos(a) * local.z);
}

// A map whose every texel differs: channel values from the column and row.
std::vector<Vec3> DistinctTexels(int aWidth, int aHeight) {
    std::vector<Vec3> texels;
    for (int y = 0; y < aHeight; y++)
        for (int x = 0; x < aWidth; x++) texels.push_back(Vec3(1.f + float(x), 1.f + float(y), 0.5f + 0.25f * float((x + y) % 3)));
    return texels;
}

// A non-uniform map: a smooth gradient over the sphere, a bright patch (a "sun") and a dark
// band, all texels positive except one black column (which no sample may pick).
std::vector<Vec3> PatternTexels(int aWidth, int aHeight) {
    std::vector<Vec3> texels;
    for (int y = 0; y < aHeight; y++)
        for (int x = 0; x < aWidth; x++) {
            const float u = (float(x) + 0.5f) / float(aWidth), v = (float(y) + 0.5f) / float(aHeight);
            Vec3 c(0.2f + 0.6f * u, 0.3f + 0.5f * (1.f - v), 0.4f + 0.3f * std::sin(6.f * u) * std::sin(6.f * u));
            if (x == aWidth / 4 && y == aHeight / 3) c = Vec3(40.f, 36.f, 30.f);
            if (y == aHeight - 3) c *= 0.05f;
            if (x == aWidth - 2) c = Vec3(0.f);
            texels.push_back(c);
        }
    return texels;
}

// sum over texels of L x Integral over the texel's patch of max(0, n.w) dw, by the
// midpoint rule on aSub x aSub pieces of each texel in (u, v), with dw = 2 pi^2 sin(theta)
// du dv: the irradiance a plane of normal aNormal receives from the map.
glm::dvec3 Irradiance(const std::vector<Vec3>& aTexels, int aWidth, int aHeight, double aRotationDegrees, const glm::dvec3& aNormal,
                      int aSub) {
    glm::dvec3 sum(0.0);
    for (int y = 0; y < aHeight; y++)
        for (int x = 0; x < aWidth; x++) {
            double weight = 0.0;
            for (int j = 0; j < aSub; j++)
                for (int i = 0; i < aSub; i++) {
                    const double u = (x + (i + 0.5) / aSub) / aWidth, v = (y + (j + 0.5) / aSub) / aHeight;
                    const glm::dvec3 w = MapDirection(u, v, aRotationDegrees);
                    weight += std::max(0.0, glm::dot(aNormal, w)) * std::sin(kPiD * v);
                }
            weight *= 2.0 * kPiD * kPiD / (double(aWidth) * aHeight * aSub * aSub);
            sum += weight * glm::dvec3(aTexels[size_t(y) * size_t(aWidth) + size_t(x)]);
        }
    return sum;
}

// Luminance as the header weighs it (Rec. 709 primaries, the weights SmallVCM uses).
double Luminance709(const Vec3& aColor) { return 0.212671 * aColor.x + 0.715160 * aColor.y + 0.072169 * aColor.z; }

// A PFM of aWidth x aHeight pixels with the given texels (top row first), written as
// WriteImage writes it.
void WriteMap(const std::string& aPath, int aWidth, int aHeight, const std::vector<Vec3>& aTexels) {
    Image image(aWidth, aHeight);
    image.mPixels = aTexels;
    WriteImage(aPath, image);
}

} // namespace

// ---------------------------------------------------------------------------------------
// Mapping, sampling, loading
// ---------------------------------------------------------------------------------------

TEST_CASE("An environment map's texel centres face the directions of the documented mapping, turned about +Y by its rotation", "[lights]") {
    const int width = 8, height = 4;
    const std::vector<Vec3> texels = DistinctTexels(width, height);
    for (const float rotation : {0.f, 90.f, -30.f, 405.f}) {
        const EnvironmentMap map("test map", width, height, texels, rotation);
        for (int y = 0; y < height; y++)
            for (int x = 0; x < width; x++) {
                const Vec3 direction(MapDirection((x + 0.5) / width, (y + 0.5) / height, rotation));
                INFO("rotation " << rotation << ", texel (" << x << ", " << y << ")");
                CHECK(map.Radiance(direction) == texels[size_t(y) * width + size_t(x)]);
            }
    }
    // The named directions, without a rotation: the image centre (u = 1/2, the left edge of
    // column 4 of 8) faces +X, u = 3/4 (column 6's left edge) faces +Z, u = 1/4 (column 2's)
    // faces -Z, u grows from -Z through +X to +Z; the top row is the zenith +Y and the
    // bottom row -Y. Each direction below is a little past its edge, into one texel.
    const EnvironmentMap map("test map", width, height, texels, 0.f);
    auto at = [&](int aX, int aY) { return texels[size_t(aY) * width + size_t(aX)]; };
    CHECK(map.Radiance(glm::normalize(Vec3(1.f, 0.1f, 0.01f))) == at(4, 1));
    CHECK(map.Radiance(glm::normalize(Vec3(1.f, 0.1f, -0.01f))) == at(3, 1));
    CHECK(map.Radiance(glm::normalize(Vec3(-0.01f, 0.1f, 1.f))) == at(6, 1));
    CHECK(map.Radiance(glm::normalize(Vec3(-0.01f, 0.1f, -1.f))) == at(1, 1));
    CHECK(map.Radiance(glm::normalize(Vec3(0.01f, -0.1f, -1.f))) == at(2, 2));
    CHECK(map.Radiance(Vec3(0.f, 1.f, 0.f)).y == at(0, 0).y);  // every column of the top row has row 0's green
    CHECK(map.Radiance(Vec3(0.f, -1.f, 0.f)).y == at(0, 3).y);
    // Turned by 90 degrees counter-clockwise seen from above, the centre faces -Z.
    const EnvironmentMap turned("test map", width, height, texels, 90.f);
    CHECK(turned.Radiance(glm::normalize(Vec3(0.01f, 0.1f, -1.f))) == at(4, 1));
}

TEST_CASE("An environment map samples directions with the pdf PdfW reports, the texel they see, and a pdf that integrates to 1", "[lights]") {
    const int width = 64, height = 32;
    const std::vector<Vec3> texels = PatternTexels(width, height);
    const EnvironmentMap map("test map", width, height, texels, 25.f);
    Rng rng(5, 0);
    int samples = 0, mismatchedPdf = 0, mismatchedTexel = 0, black = 0;
    for (int i = 0; i < 200000; i++) {
        const std::optional<EnvironmentMap::DirectionSample> sample = map.Sample(rng.GetVec2());
        if (!sample) continue;
        samples++;
        REQUIRE(std::abs(glm::length(sample->mDirection) - 1.f) < 1e-5f);
        // A direction on a texel's edge may round into its neighbour: a few in a million.
        if (!(std::abs(map.PdfW(sample->mDirection) - sample->mPdfW) <= 1e-4f * sample->mPdfW)) mismatchedPdf++;
        if (!(map.Radiance(sample->mDirection) == sample->mRadiance)) mismatchedTexel++;
        if (IsBlack(sample->mRadiance)) black++;
    }
    INFO(samples << " samples, " << mismatchedPdf << " with another pdf, " << mismatchedTexel << " with another texel");
    CHECK(samples >= 199990);  // only a sample exactly at a pole is dropped
    CHECK(mismatchedPdf <= 20);
    CHECK(mismatchedTexel <= 20);
    CHECK(black == 0);  // the black column is never picked
    // The integral of PdfW over the sphere, by the midpoint rule on a grid finer than the
    // texels (16 x 16 per texel) in (theta, phi): PdfW is constant in phi on a texel and
    // smooth in theta, so the rule errs by far less than 1e-3.
    double integral = 0.0;
    const int thetaSteps = height * 16, phiSteps = width * 16;
    for (int j = 0; j < thetaSteps; j++) {
        const double theta = (j + 0.5) * kPiD / thetaSteps;
        for (int i = 0; i < phiSteps; i++) {
            const double phi = (i + 0.5) * 2.0 * kPiD / phiSteps;
            const Vec3 w(float(std::sin(theta) * std::cos(phi)), float(std::cos(theta)), float(std::sin(theta) * std::sin(phi)));
            integral += double(map.PdfW(w)) * std::sin(theta) * (kPiD / thetaSteps) * (2.0 * kPiD / phiSteps);
        }
    }
    INFO("integral of PdfW " << integral);
    CHECK(std::abs(integral - 1.0) < 1e-3);
}

TEST_CASE("An environment map picks texels in proportion to luminance x sin(theta) (chi-square)", "[lights]") {
    const int width = 32, height = 16;
    const std::vector<Vec3> texels = PatternTexels(width, height);
    const EnvironmentMap map("test map", width, height, texels, 0.f);
    // Expected share of each texel from the documented weights, computed here in double.
    std::vector<double> weight(texels.size());
    double total = 0.0;
    for (int y = 0; y < height; y++)
        for (int x = 0; x < width; x++) {
            const size_t index = size_t(y) * width + size_t(x);
            weight[index] = Luminance709(texels[index]) * std::sin(kPiD * (y + 0.5) / height);
            total += weight[index];
        }
    const int n = 2000000;
    std::vector<double> observed(texels.size(), 0.0), expected(texels.size());
    for (size_t i = 0; i < texels.size(); i++) expected[i] = n * weight[i] / total;
    Rng rng(17, 0);
    for (int i = 0; i < n; i++) {
        const std::optional<EnvironmentMap::DirectionSample> sample = map.Sample(rng.GetVec2());
        REQUIRE(sample);
        // The texel of the direction, by the test's own inverse of the mapping.
        const glm::dvec3 w(sample->mDirection);
        double u = 0.5 + std::atan2(w.z, w.x) / (2.0 * kPiD);
        const double v = std::acos(std::min(1.0, std::max(-1.0, w.y))) / kPiD;
        const int x = std::min(width - 1, int(u * width)), y = std::min(height - 1, int(v * height));
        observed[size_t(y) * width + size_t(x)] += 1.0;
    }
    // Threshold: the chi-square quantile at significance 1e-3 (Wilson-Hilferty).
    const ChiSquare chi = ComputeChiSquare(observed, expected);
    INFO("chi2 = " << chi.statistic << " with " << chi.dof << " dof, threshold " << chi.threshold);
    CHECK(chi.dof >= 400);
    CHECK(chi.statistic < chi.threshold);
}

TEST_CASE("A bad environment map is refused in one line naming it and the problem", "[lights]") {
    auto refusal = [](const std::function<void()>& aMake) {
        try {
            aMake();
        } catch (const Error& error) {
            return std::string(error.what());
        }
        return std::string("(accepted)");
    };
    const std::vector<Vec3> square(16, Vec3(1.f));
    CHECK_THAT(refusal([&] { EnvironmentMap("m", 4, 4, square, 0.f); }), Catch::Contains("twice as wide as high; this one is 4x4"));
    std::vector<Vec3> texels(32, Vec3(1.f));
    texels[9] = Vec3(1.f, -0.5f, 1.f);
    CHECK_THAT(refusal([&] { EnvironmentMap("m", 8, 4, texels, 0.f); }), Catch::Contains("m: texel (1, 1) is negative or not finite"));
    texels[9] = Vec3(std::numeric_limits<float>::quiet_NaN());
    CHECK_THAT(refusal([&] { EnvironmentMap("m", 8, 4, texels, 0.f); }), Catch::Contains("texel (1, 1) is negative or not finite"));
    texels[9] = Vec3(std::numeric_limits<float>::infinity());
    CHECK_THAT(refusal([&] { EnvironmentMap("m", 8, 4, texels, 0.f); }), Catch::Contains("texel (1, 1) is negative or not finite"));
    CHECK_THAT(refusal([&] { EnvironmentMap("m", 8, 4, std::vector<Vec3>(32, Vec3(0.f)), 0.f); }),
               Catch::Contains("m: the environment map is black"));
    CHECK_THAT(refusal([&] { EnvironmentMap("m", 8, 4, std::vector<Vec3>(32, Vec3(1.f)), std::nanf("")); }),
               Catch::Contains("the rotation is not finite"));

    TemporaryFolder folder;
    CHECK_THAT(refusal([&] { LoadEnvironmentMap(folder / "missing.hdr"); }),
               Catch::Contains("environment map " + (folder / "missing.hdr") + ": cannot open"));
    WriteMap(folder / "square.pfm", 4, 4, square);
    CHECK_THAT(refusal([&] { LoadEnvironmentMap(folder / "square.pfm"); }),
               Catch::Contains("environment map " + (folder / "square.pfm") + ": an equirectangular map is twice as wide as high"));
    WriteMap(folder / "map.exr", 8, 4, std::vector<Vec3>(32, Vec3(2.f)));
    CHECK(LoadEnvironmentMap(folder / "map.exr")->Radiance(Vec3(1.f, 0.f, 0.f)) == Vec3(2.f));
    WriteMap(folder / "map.hdr", 8, 4, std::vector<Vec3>(32, Vec3(2.f)));
    // RGBE keeps 8 bits of mantissa: 2 is read back within 1/256.
    CHECK(LoadEnvironmentMap(folder / "map.hdr")->Radiance(Vec3(1.f, 0.f, 0.f)).x == Approx(2.f).epsilon(1.f / 256.f));
    // Truncated: the header of an 8x4 PFM with half its pixels.
    {
        std::ofstream file(folder / "truncated.pfm", std::ios::binary);
        file << "PF\n8 4\n-1\n";
        const std::vector<float> half(48, 1.f);
        file.write(reinterpret_cast<const char*>(half.data()), std::streamsize(half.size() * sizeof(float)));
    }
    CHECK_THAT(refusal([&] { LoadEnvironmentMap(folder / "truncated.pfm"); }), Catch::Contains("truncated"));
    // Oversized: a header claiming 16384 x 8192 pixels is refused before a pixel is read
    // (the file holds none: the size is checked first).
    {
        std::ofstream file(folder / "huge.pfm", std::ios::binary);
        file << "PF\n16384 8192\n-1\n";
    }
    CHECK_THAT(refusal([&] { LoadEnvironmentMap(folder / "huge.pfm"); }), Catch::Contains("16384x8192 pixels, more than the 33554432"));
    {
        std::ofstream file(folder / "huge.hdr", std::ios::binary);
        file << "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 8192 +X 16384\n";
        file << std::string(size_t(8192) * 4 * 200, '\0');
    }
    CHECK_THAT(refusal([&] { LoadEnvironmentMap(folder / "huge.hdr"); }), Catch::Contains("16384x8192 pixels, more than the 33554432"));
    WriteImage(folder / "map.png", Image(8, 4));
    CHECK_THAT(refusal([&] { LoadEnvironmentMap(folder / "map.png"); }), Catch::Contains("a PNG holds exposed"));
    std::filesystem::create_directory(folder / "folder.exr");
    CHECK_THAT(refusal([&] { LoadEnvironmentMap(folder / "folder.exr"); }), Catch::Contains("not a regular file"));
}

// ---------------------------------------------------------------------------------------
// Renders
// ---------------------------------------------------------------------------------------

namespace {

// A small diffuse ball far below the camera (a scene needs geometry) and a camera at the
// origin looking along aForward with a narrow field of view, under aMap.
Scene MakeEnvironmentView(std::shared_ptr<const EnvironmentMap> aMap, const Vec3& aForward, int aSize, float aFov) {
    Scene scene;
    scene.mName = "environment seen directly";
    scene.AddSphere(Vec3(0.f, -50.f, 0.f), 0.1f, scene.AddMaterial(DiffuseMaterial(0.5f, 0.5f, 0.5f)));
    scene.AddEnvironmentLight(std::move(aMap));
    const Vec3 up = std::abs(aForward.y) > 0.9f ? Vec3(1.f, 0.f, 0.f) : Vec3(0.f, 1.f, 0.f);
    scene.mCamera.Setup(Vec3(0.f), aForward, up, aFov);
    scene.mCamera.SetResolution(aSize, aSize);
    scene.Finalize();
    return scene;
}

} // namespace

TEST_CASE("The environment seen directly and in a mirror ball shows the texels of the documented mapping", "[lights][integrators]") {
    const int width = 8, height = 4;
    const std::vector<Vec3> texels = DistinctTexels(width, height);
    for (const float rotation : {0.f, 60.f}) {
        const auto map = std::make_shared<const EnvironmentMap>("test map", width, height, texels, rotation);
        // Directly: a camera aimed at a texel's centre with a 2-degree field of view sees
        // only that texel (a texel spans 45 degrees).
        for (const auto& texel : {std::pair<int, int>{4, 1}, {6, 2}, {0, 1}, {2, 2}, {5, 1}}) {
            const Vec3 forward(MapDirection((texel.first + 0.5) / width, (texel.second + 0.5) / height, rotation));
            const Image image = RenderWith(MakeEnvironmentView(map, forward, 4, 2.f), Algorithm::kPathTracing, 1).mImage;
            const Vec3& expected = texels[size_t(texel.second) * width + size_t(texel.first)];
            for (const Vec3& pixel : image.mPixels) {
                INFO("rotation " << rotation << ", texel (" << texel.first << ", " << texel.second << ")");
                for (int c = 0; c < 3; c++) CHECK(pixel[c] == Approx(expected[c]).epsilon(1e-6));
            }
        }
        // In a mirror ball: a camera far out along texel (5, 1)'s direction looks at a mirror
        // ball at the origin with a 1-degree field of view; the ball reflects its rays back
        // within a few degrees of where they came from, so every pixel shows the texel
        // behind the camera.
        const Vec3 behind(MapDirection(5.5 / width, 1.5 / height, rotation));
        Scene scene;
        scene.mName = "mirror ball";
        Material mirror;
        mirror.mMirrorReflectance = Vec3(1.f);
        scene.AddSphere(Vec3(0.f), 1.f, scene.AddMaterial(mirror));
        scene.AddEnvironmentLight(map);
        scene.mCamera.Setup(10.f * behind, -behind, Vec3(0.f, 1.f, 0.f), 1.f);
        scene.mCamera.SetResolution(4, 4);
        scene.Finalize();
        const Image image = RenderWith(scene, Algorithm::kPathTracing, 1).mImage;
        // The direction behind the camera, +X, in texel coordinates of the map.
        for (const Vec3& pixel : image.mPixels) {
            INFO("rotation " << rotation << ": mirror ball pixel " << pixel.x << " " << pixel.y << " " << pixel.z);
            for (int c = 0; c < 3; c++) CHECK(pixel[c] == Approx(texels[size_t(1) * width + 5][c]).epsilon(1e-5));
        }
    }
}

namespace {

// A diffuse square of albedo aAlbedo, 6 units wide and tilted to the normal aNormal,
// under aMap (and nothing else: it cannot see itself, so every path has 2 segments); the
// camera 1 unit above its centre looks at it with a 60-degree field of view and sees
// only its middle (within 1.3 units of the centre). Small, so that a fair share of the
// light sub-paths, which start on a disc of the scene's radius, land in view.
Scene MakePlaneUnderEnvironment(std::shared_ptr<const EnvironmentMap> aMap, const Vec3& aNormal, float aAlbedo, int aSize) {
    Scene scene;
    scene.mName = "plane under an environment map";
    const Frame frame(aNormal);
    const float h = 3.f;
    const Vec3 a = (-frame.mX - frame.mY) * h, b = (frame.mX - frame.mY) * h, c = (frame.mX + frame.mY) * h, d = (-frame.mX + frame.mY) * h;
    AddQuadFacing(scene, a, b, c, d, aNormal, scene.AddMaterial(DiffuseMaterial(aAlbedo, aAlbedo, aAlbedo)));
    scene.AddEnvironmentLight(std::move(aMap));
    scene.mCamera.Setup(aNormal, -aNormal + 0.2f * frame.mX, frame.mY, 60.f);
    scene.mCamera.SetResolution(aSize, aSize);
    scene.Finalize();
    return scene;
}

// The mean of aRenders renders of aIterations each (seeds aSeed + 1000 r) and its standard
// error: the pixels of one render of lt, ppm or bpm share light sub-paths, so only
// independent renders give an honest spread.
MeanAndError IndependentRenderMeans(const Scene& aScene, Algorithm aAlgorithm, int aRenders, int aIterations, uint64_t aSeed,
                                    float aRadiusFactor) {
    std::vector<double> means;
    for (int r = 0; r < aRenders; r++) {
        RenderOptions options;
        options.mAlgorithm = aAlgorithm;
        options.mIterations = aIterations;
        options.mSeed = aSeed + 1000u * uint64_t(r);
        options.mRadiusFactor = aRadiusFactor;
        options.mPhotonCount = 20000;  // pm, pmfg
        options.mNearestPhotons = 100;
        options.mProgress = false;
        means.push_back(PixelStatistics(Render(aScene, options).mImage).mean);
    }
    return MeanOf(means);
}

} // namespace

TEST_CASE("Every estimator renders a diffuse plane under a non-uniform, rotated environment map at rho / pi times its irradiance", "[lights][integrators]") {
    // The answer: L = rho / pi x Integral L_env(w) max(0, n.w) dw over the map, summed
    // texel by texel in double (Irradiance, 48 x 48 pieces per texel: it changes by less
    // than 1e-5 relative from 32 x 32). Tolerance: 5 standard errors of the mean of 24
    // independent renders (23 degrees of freedom: a 5 SE deviation has probability ~5e-5,
    // Student t) plus 1e-3 relative (float rounding; the merging radius adds no bias on a
    // plane lit uniformly, as long as the disc stays on the plane). Merging estimators use
    // a radius of 5 % of the scene (at 16 x 16 the default would find few photons). The
    // iterations per render give each estimator a standard error of at most ~0.6 % of the
    // answer (printed; lt, ppm and bpm need the most: few of their light sub-paths land in
    // the camera's view).
    const int width = 32, height = 16;
    const std::vector<Vec3> texels = PatternTexels(width, height);
    const float rotation = 35.f, albedo = 0.7f;
    const Vec3 normal = glm::normalize(Vec3(0.3f, 1.f, -0.25f));
    const glm::dvec3 irradiance = Irradiance(texels, width, height, rotation, glm::dvec3(normal), 48);
    const double expected = albedo / kPiD * (irradiance.x + irradiance.y + irradiance.z) / 3.0;
    const Scene scene =
        MakePlaneUnderEnvironment(std::make_shared<const EnvironmentMap>("pattern", width, height, texels, rotation), normal, albedo, 16);
    for (Algorithm algorithm : kTransportEstimators) {
        const int iterations = algorithm == Algorithm::kLightTracing                 ? 2048
                               : algorithm == Algorithm::kProgressivePhotonMapping   ? 1024
                               : algorithm == Algorithm::kBidirectionalPhotonMapping ? 512
                               : algorithm == Algorithm::kVertexConnectionMerging    ? 64 : 16;
        const MeanAndError stats = IndependentRenderMeans(scene, algorithm, 24, iterations, 3, 0.05f);
        INFO(AlgorithmShortName(algorithm) << ": mean " << stats.mean << " +- " << stats.standardError << ", expected " << expected);
        CHECK(std::abs(stats.mean - expected) <= 5.0 * stats.standardError + 1e-3 * expected);
    }
    // Classic photon mapping (20,000 photons, 100 nearest): its k-NN estimate of a uniform
    // density is biased by k / (k - 1), +1 % (test_photon_mapping.cpp), which the
    // tolerance adds; pmfg gathers the direct light by next-event estimation and BSDF
    // sampling under MIS (a plane has no indirect light), so the same bound holds for it.
    for (Algorithm algorithm : {Algorithm::kPhotonMapping, Algorithm::kPhotonMappingFinalGather}) {
        const MeanAndError stats = IndependentRenderMeans(scene, algorithm, 24, 4, 5, 0.05f);
        INFO(AlgorithmShortName(algorithm) << ": mean " << stats.mean << " +- " << stats.standardError << ", expected " << expected);
        CHECK(std::abs(stats.mean - expected) <= 5.0 * stats.standardError + 0.01 * expected);
    }
}

TEST_CASE("A constant environment map renders what the uniform background of the same radiance renders", "[lights][integrators]") {
    // Cornell scene 3 (lit by its background) as the file has it and with the background
    // replaced by a constant 8 x 4 map of the same radiance: the same expected image, sampled
    // with other pdfs (the map's are uniform in each row's texels, not over the sphere).
    // Tolerance: 5 standard errors of the difference of the two means (24 independent
    // renders each) plus 1e-3 relative.
    const Scene file = LoadCornell(3, 16, 16);
    Scene constant = file;
    Vec3 radiance(0.f);
    for (Light& light : constant.mLights)
        if (light.mType == LightType::kBackground) radiance = light.mEmission;
    REQUIRE_FALSE(IsBlack(radiance));
    constant.mLights.erase(std::remove_if(constant.mLights.begin(), constant.mLights.end(),
                                          [](const Light& aLight) { return aLight.mType == LightType::kBackground; }),
                           constant.mLights.end());
    constant.AddEnvironmentLight(std::make_shared<const EnvironmentMap>("constant", 8, 4, std::vector<Vec3>(32, radiance), 0.f));
    constant.Finalize();
    for (Algorithm algorithm : {Algorithm::kPathTracing, Algorithm::kBidirectionalPathTracing, Algorithm::kVertexConnectionMerging}) {
        const MeanAndError a = IndependentRenderMeans(file, algorithm, 24, 2, 21, 0.003f);
        const MeanAndError b = IndependentRenderMeans(constant, algorithm, 24, 2, 21, 0.003f);
        const double se = std::sqrt(a.standardError * a.standardError + b.standardError * b.standardError);
        INFO(AlgorithmShortName(algorithm) << ": background " << a.mean << " +- " << a.standardError << ", constant map " << b.mean
                                           << " +- " << b.standardError);
        CHECK(std::abs(a.mean - b.mean) <= 5.0 * se + 1e-3 * a.mean);
    }
}
