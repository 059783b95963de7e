// fig_bidirectional — the bidirectional figures of both lectures (seeds 000 and 001):
//   F05  the path pyramid: BPT split into one image per technique (s light vertices, t camera
//        vertices) for path lengths 1..5, unweighted and MIS-weighted
//        (scenes/cornell_4_default.gltf)
//   F06  BPT vs. path tracing at equal time on a room lit from a lamp that faces the ceiling
//        (scenes/indirect_room.gltf)
//   F07  light tracing vs. path tracing at equal time: the floor caustic of a glass sphere, and
//        the specular surfaces light tracing cannot show (scenes/caustic_glass_sphere.gltf)
//   F08  the limitation of BPT: a point light's caustic seen through a glass sphere (light -
//        specular - diffuse - specular - eye) has no BPT technique; VCM's merging renders it
//        (scenes/sds_glass_sphere.gltf)
//
//   build/fig_bidirectional [--quick] [--out DIR] [--threads N] [--only F05,F06,F07,F08]
// writes F05_*.png ... F08.json (see figures/figure_kit.hpp).
//
// F07 and F08 measure their claims on pixel masks (which surface the camera sees in a pixel),
// built here by tracing the primary rays with the scene API; the masks are saved as panels.

#include "figure_kit.hpp"

#include <array>
#include <map>
#include <unordered_map>
#include <tuple>

using namespace figures;

namespace {

// ------------------------------------------------------------------------------------
// Pixel masks: what the camera sees first in each pixel
// ------------------------------------------------------------------------------------

enum class Surface { kNothing, kLight, kNonSpecular, kSpecular, kMixed };

// The surface kind the primary rays of each pixel hit first. A render jitters its rays
// over the whole pixel, so a pixel on the edge of a sphere mixes two surfaces; such pixels
// would blur a mask's statistics. Each pixel is therefore probed with 3x3 rays spread over
// it, and only pixels whose nine rays agree get a kind (the others are kMixed).
// Specular means a delta BSDF (mirror, glass: no diffuse or glossy part), told by Bsdf.
std::vector<Surface> SurfaceKinds(const Scene& aScene) {
    const smallvcm::Camera& camera = aScene.mCamera;
    std::vector<Surface> kinds(size_t(camera.PixelCount()), Surface::kNothing);
    for (int y = 0; y < camera.Height(); y++)
        for (int x = 0; x < camera.Width(); x++) {
            Surface pixelKind = Surface::kNothing;
            for (int j = 0; j < 3; j++)
                for (int i = 0; i < 3; i++) {
                    const smallvcm::Vec2 raster(float(x) + (float(i) + 0.5f) / 3.f, float(y) + (float(j) + 0.5f) / 3.f);
                    const smallvcm::Ray ray = camera.GenerateRay(raster);
                    const smallvcm::SurfacePoint hit = aScene.Intersect(ray);
                    Surface kind = Surface::kNothing;
                    if (hit.IsValid()) {
                        if (hit.mLightId >= 0) {
                            kind = Surface::kLight;
                        } else {
                            smallvcm::Bsdf bsdf;
                            bsdf.Setup(ray, hit, aScene, smallvcm::Transport::kRadiance);
                            // A grazing hit leaves the Bsdf invalid; the material then decides.
                            const smallvcm::Material& material = aScene.GetMaterial(hit.mMaterialId);
                            const bool delta = bsdf.IsValid() ? bsdf.IsDelta()
                                                              : material.HasSpecular() && !material.HasNonSpecular();
                            kind = delta ? Surface::kSpecular : Surface::kNonSpecular;
                        }
                    }
                    if (i == 0 && j == 0) pixelKind = kind;
                    else if (kind != pixelKind) pixelKind = Surface::kMixed;
                }
            kinds[size_t(y) * size_t(camera.Width()) + size_t(x)] = pixelKind;
        }
    return kinds;
}


// Where a ray ends after mirrors and glass: a non-specular point, and the fraction of
// the ray's light that takes this branch (Fresnel and mirror reflectance).
struct Landing {
    Vec3 mPoint;
    int mMaterialId;
    Vec3 mWeight;
};

// Follows a ray through mirrors and glass deterministically along every branch (glass
// splits into the Fresnel-reflected and the refracted ray) to the first non-specular
// surfaces, dropping branches that keep less than 1% of the light; appends the ends
// reached after at least one specular bounce. Radiance's (eta_i/eta_t)^2 factor at each
// refraction is left out: into and out of a sphere it cancels.
void FollowSpecular(const Scene& aScene, const smallvcm::Ray& aRay, const Vec3& aWeight, int aBounces,
                    std::vector<Landing>& oLandings) {
    if (aBounces > 12 || smallvcm::MaxComponent(aWeight) < 0.01f) return;
    const smallvcm::SurfacePoint hit = aScene.Intersect(aRay);
    if (!hit.IsValid() || hit.mLightId >= 0) return;
    const smallvcm::Material& material = aScene.GetMaterial(hit.mMaterialId);
    const Vec3 point = aRay.mOrigin + hit.mDist * aRay.mDirection;
    if (material.HasNonSpecular() || !material.HasSpecular()) {
        if (aBounces > 0) oLandings.push_back({point, hit.mMaterialId, aWeight});
        return;
    }
    // The normal points out of the glass: a negative cosine means the ray leaves it.
    const float cosIncident = -glm::dot(aRay.mDirection, hit.GeometricNormal());
    const Vec3 reflected = aRay.mDirection + 2.f * cosIncident * hit.GeometricNormal();
    if (material.mIor < 0.f) {
        FollowSpecular(aScene, aScene.SpawnRay(point, reflected), aWeight * material.mMirrorReflectance, aBounces + 1,
                       oLandings);
        return;
    }
    const float fresnel = smallvcm::FresnelDielectric(cosIncident, material.mIor);
    FollowSpecular(aScene, aScene.SpawnRay(point, reflected), aWeight * fresnel * material.mMirrorReflectance,
                   aBounces + 1, oLandings);
    if (fresnel >= 1.f) return;  // total internal reflection
    const bool entering = cosIncident > 0.f;
    const Vec3 normal = entering ? hit.GeometricNormal() : -hit.GeometricNormal();
    const float cosine = std::abs(cosIncident);
    const float eta = entering ? 1.f / material.mIor : material.mIor;
    const float k = 1.f - eta * eta * (1.f - cosine * cosine);
    const Vec3 refracted = glm::normalize(eta * aRay.mDirection + (eta * cosine - std::sqrt(std::max(0.f, k))) * normal);
    FollowSpecular(aScene, aScene.SpawnRay(point, refracted), aWeight * (1.f - fresnel), aBounces + 1, oLandings);
}

// The irradiance that the point light delivers through mirrors and glass (its caustics),
// from a small deterministic particle map that no renderer shares. From the light, an even
// lattice of rays over the cone each specular sphere subtends is followed through the
// glass (FollowSpecular); each landing carries its ray's solid angle times its branch
// weight, and the irradiance at a point is the light's intensity times the solid angle
// landed within mRadius, divided by the disc's area.
class CausticMap {
public:
    CausticMap(const Scene& aScene, int aRaysPerSide, float aRadius) : mRadius(aRadius) {
        const smallvcm::Light* light = nullptr;
        for (const smallvcm::Light& candidate : aScene.mLights)
            if (candidate.mType == smallvcm::LightType::kPoint) { light = &candidate; break; }
        if (!light) return;
        mIntensity = light->mEmission;
        std::vector<Landing> landings;
        for (const smallvcm::Sphere& sphere : aScene.mSpheres) {
            const smallvcm::Material& material = aScene.GetMaterial(sphere.mMaterialId);
            if (material.HasNonSpecular() || !material.HasSpecular()) continue;
            const Vec3 axis = sphere.mCenter - light->mPosition;
            const float distance = glm::length(axis);
            if (distance <= sphere.mRadius) continue;
            const float cosMax = std::sqrt(1.f - (sphere.mRadius / distance) * (sphere.mRadius / distance));
            const double solidAngle = 2.0 * smallvcm::kPi * (1.0 - double(cosMax));
            const float rayWeight = float(solidAngle / double(aRaysPerSide * aRaysPerSide));
            const smallvcm::Frame frame(axis / distance);
            for (int i = 0; i < aRaysPerSide; i++)
                for (int j = 0; j < aRaysPerSide; j++) {
                    // A square grid mapped to the disc by Shirley and Chiu's concentric map
                    // (equal areas, little distortion), and the disc to the cone's cap by
                    // 1 - cos(theta) = rho^2 (1 - cos(theta_max)) (equal solid angles): an
                    // even lattice of directions, which a density count needs.
                    const float a = 2.f * (float(i) + 0.5f) / float(aRaysPerSide) - 1.f;
                    const float b = 2.f * (float(j) + 0.5f) / float(aRaysPerSide) - 1.f;
                    const float quarter = 0.25f * smallvcm::kPi;
                    const float rho = std::abs(a) > std::abs(b) ? a : b;
                    const float phi = std::abs(a) > std::abs(b) ? quarter * (b / a) : 2.f * quarter - quarter * (a / b);
                    const float cosTheta = 1.f - rho * rho * (1.f - cosMax);
                    const float sinTheta = std::sqrt(std::max(0.f, 1.f - cosTheta * cosTheta));
                    const float sign = rho < 0.f ? -1.f : 1.f;
                    const Vec3 direction = frame.ToWorld(
                        Vec3(sign * sinTheta * std::cos(phi), sign * sinTheta * std::sin(phi), cosTheta));
                    landings.clear();
                    FollowSpecular(aScene, smallvcm::Ray{light->mPosition, direction}, Vec3(1.f), 0, landings);
                    for (const Landing& landing : landings)
                        mCells[CellKey(CellOf(landing.mPoint))].push_back(
                            {landing.mPoint, landing.mMaterialId, landing.mWeight * rayWeight});
                }
        }
    }

    Vec3 Irradiance(const Vec3& aPoint) const {
        const glm::ivec3 cell = CellOf(aPoint);
        Vec3 solidAngle(0.f);
        for (int dx = -1; dx <= 1; dx++)
            for (int dy = -1; dy <= 1; dy++)
                for (int dz = -1; dz <= 1; dz++) {
                    const auto found = mCells.find(CellKey(cell + glm::ivec3(dx, dy, dz)));
                    if (found == mCells.end()) continue;
                    for (const Landing& landing : found->second)
                        if (glm::dot(landing.mPoint - aPoint, landing.mPoint - aPoint) < mRadius * mRadius)
                            solidAngle += landing.mWeight;
                }
        return mIntensity * solidAngle / (smallvcm::kPi * mRadius * mRadius);
    }

private:
    glm::ivec3 CellOf(const Vec3& aPoint) const { return glm::ivec3(glm::floor(aPoint / mRadius)); }
    // Cells that share a key only cost extra distance tests.
    static int64_t CellKey(const glm::ivec3& aCell) {
        return (int64_t(aCell.x) * 73856093) ^ (int64_t(aCell.y) * 19349663) ^ (int64_t(aCell.z) * 83492791);
    }

    float mRadius;
    Vec3 mIntensity{0.f};
    std::unordered_map<int64_t, std::vector<Landing>> mCells;
};

// The SDS light of each pixel, predicted: the camera's rays (3x3 per pixel) followed
// through mirrors and glass to diffuse points, each reflecting the caustic irradiance there
// (Lambert: albedo / pi). It counts only light - specular(s) - diffuse - specular(s) - eye
// paths with one diffuse bounce, the light no BPT technique can sample in a scene with a
// point light.
Image PredictedSdsLight(const Scene& aScene, const CausticMap& aCaustics) {
    const smallvcm::Camera& camera = aScene.mCamera;
    Image image(camera.Width(), camera.Height());
    std::vector<Landing> landings;
    for (int y = 0; y < camera.Height(); y++)
        for (int x = 0; x < camera.Width(); x++) {
            Vec3 sum(0.f);
            for (int j = 0; j < 3; j++)
                for (int i = 0; i < 3; i++) {
                    const smallvcm::Vec2 raster(float(x) + (float(i) + 0.5f) / 3.f, float(y) + (float(j) + 0.5f) / 3.f);
                    landings.clear();
                    FollowSpecular(aScene, camera.GenerateRay(raster), Vec3(1.f), 0, landings);
                    for (const Landing& landing : landings)
                        sum += landing.mWeight * aScene.GetMaterial(landing.mMaterialId).mDiffuseReflectance *
                               smallvcm::kInvPi * aCaustics.Irradiance(landing.mPoint);
                }
            image.At(x, y) = sum / 9.f;
        }
    return image;
}

Mask MaskOf(const std::vector<Surface>& aKinds, Surface aKind) {
    Mask mask(aKinds.size());
    for (size_t i = 0; i < aKinds.size(); i++) mask[i] = aKinds[i] == aKind;
    return mask;
}

double PixelValue(const Vec3& aPixel) { return (double(aPixel.x) + double(aPixel.y) + double(aPixel.z)) / 3.0; }

// An exposure that is a power of two (so panels compare by eye), the nearest to aFactor.
float PowerOfTwoExposure(double aFactor, float aLargest) {
    const double exponent = std::round(std::log2(std::max(1.0, aFactor)));
    return std::min(aLargest, float(std::exp2(exponent)));
}

std::string SceneSetting(const char* aScene) { return std::string("scenes/") + aScene; }

// The name of BPT's technique layer with aS light and aT camera vertices.
std::string TechniqueName(int aS, int aT) { return "s" + std::to_string(aS) + "_t" + std::to_string(aT); }

// ------------------------------------------------------------------------------------
// F05: the path pyramid
// ------------------------------------------------------------------------------------

void FigurePathPyramid(const Kit& aKit, int aSize) {
    const char* const scene_file = "cornell_4_default.gltf";
    Figure figure(aKit, "F05", "The path pyramid of bidirectional path tracing", "Path Pyramid (Monte Carlo III, seed 001)",
                  "the MIS-weighted images of each path length sum to the full BPT image");
    const Scene scene = LoadScene(aKit, scene_file, aSize, aSize);
    const Reference reference = GetReference(aKit, StandardReference(aKit, scene_file, aSize, aSize));
    figure.SetReference(reference);
    const int iterations = aKit.Pick(64, 8);
    constexpr int kLongest = 5;  // the pyramid's rows: VertexCM keeps s/t layers up to this length
    figure.Settings() = {{"scene", SceneSetting(scene_file)}, {"resolution", aSize},
                         {"algorithm", "bpt with technique layers (balance heuristic)"},
                         {"iterations", iterations}, {"max_path_length", 10}, {"seed", 5}};
    RenderOptions options = BaseOptions(aKit, Algorithm::kBidirectionalPathTracing);
    options.mSeed = 5;
    options.mTechniqueLayers = true;
    const RenderResult result = RenderIterations(scene, options, iterations);
    const double imageMean = smallvcm::MeanValue(result.mImage);
    figure.AddRender("image", result, "the BPT image (all techniques, all path lengths)", &reference.mImage);

    std::vector<const Image*> allWeighted;
    Json lengths = Json::object();
    for (int length = 1; length <= kLongest; length++) {
        // Path length counts segments; a path of `length` segments has length + 1 vertices,
        // s of them from the light sub-path and t = length + 1 - s from the camera's.
        std::vector<const Image*> weighted;
        for (int s = 0; s <= length; s++) weighted.push_back(&Layer(result, TechniqueName(s, length + 1 - s)));
        const Image lengthSum = Sum(weighted);
        allWeighted.insert(allWeighted.end(), weighted.begin(), weighted.end());
        const double lengthMean = smallvcm::MeanValue(lengthSum);
        // Each unweighted technique estimates all the light of its length on its own, so a
        // row is shown at one exposure that brings the row's light to the whole image's
        // brightness (a power of two, at most 16; 1 for the brightest row).
        const float exposure = PowerOfTwoExposure(imageMean / std::max(1e-12, lengthMean), 16.f);
        const std::string row = "len" + std::to_string(length);
        figure.AddPanel(row + "_sum", lengthSum,
                        "length " + std::to_string(length) + ": the sum of its MIS-weighted techniques", exposure)["mean"] =
            lengthMean;
        Json techniques = Json::object();
        std::string line = "    length " + std::to_string(length) + ": " + Num(100.0 * lengthMean / imageMean, "%.1f") +
                           "% of the image (exposure x" + Num(exposure, "%g") + "); weight share / unweighted mean:";
        for (int s = 0; s <= length; s++) {
            const int t = length + 1 - s;
            const std::string name = TechniqueName(s, t);
            const Image& weightedLayer = Layer(result, name);
            const Image& unweightedLayer = Layer(result, name + "_unweighted");
            std::string what = std::to_string(s) + " light and " + std::to_string(t) + " camera vertices";
            // SmallVCM's BPT never connects a point on an area light straight to the camera
            // (only pure light tracing splats it), so this technique stays black.
            if (s == 1 && t == 1) what += " (not used by this BPT: the light seen directly is s0_t2's alone)";
            const double weightedMean = smallvcm::MeanValue(weightedLayer);
            const double unweightedMean = smallvcm::MeanValue(unweightedLayer);
            figure.AddPanel(row + "_" + name, weightedLayer, name + ", MIS-weighted: " + what, exposure)["mean"] =
                weightedMean;
            figure.AddPanel(row + "_" + name + "_unweighted", unweightedLayer, name + ", unweighted: " + what,
                            exposure)["mean"] = unweightedMean;
            // The weight share says how much of the row's light MIS takes from this
            // technique; the unweighted mean matches the row's when the technique can
            // sample every path of the length (not so for paths through the specular
            // spheres, e.g. t = 1 cannot see a mirror).
            techniques[name] = {{"weighted_mean", weightedMean}, {"unweighted_mean", unweightedMean},
                                {"weight_share", weightedMean / std::max(1e-12, lengthMean)},
                                {"unweighted_mean_over_length_mean", unweightedMean / std::max(1e-12, lengthMean)}};
            line += " " + name + " " + Num(100.0 * weightedMean / std::max(1e-12, lengthMean), "%.0f") + "%/" +
                    Num(unweightedMean / std::max(1e-12, lengthMean), "%.2f");
        }
        std::printf("%s\n", line.c_str());
        lengths[std::to_string(length)] = {{"mean", lengthMean}, {"share_of_image", lengthMean / imageMean},
                                           {"exposure", exposure}, {"techniques", techniques}};
    }
    const Image& longer = Layer(result, "longer_than_5");
    const double longerMean = smallvcm::MeanValue(longer);
    figure.AddPanel("longer_than_5", longer, "all techniques of paths longer than 5 segments, MIS-weighted",
                    PowerOfTwoExposure(imageMean / std::max(1e-12, longerMean), 16.f))["mean"] = longerMean;
    std::printf("    longer than 5: %s%% of the image\n", Num(100.0 * longerMean / imageMean, "%.1f").c_str());
    allWeighted.push_back(&longer);
    const Image sum = Sum(allWeighted);
    figure.AddPanel("sum", sum, "the sum of every weighted technique image and 'longer than 5'")["mean"] =
        smallvcm::MeanValue(sum);

    double largest = 0.0;
    for (size_t i = 0; i < sum.mPixels.size(); i++)
        for (int c = 0; c < 3; c++)
            largest = std::max(largest, double(std::abs(sum.mPixels[i][c] - result.mImage.mPixels[i][c])) /
                                            std::max(1e-3, double(std::abs(result.mImage.mPixels[i][c]))));
    figure.Numbers()["lengths"] = lengths;
    figure.Numbers()["longer_than_5_share_of_image"] = longerMean / imageMean;
    figure.Numbers()["largest_relative_difference_sum_vs_image"] = largest;
    figure.Numbers()["layers_summed"] = allWeighted.size();
    // Each contribution goes to the image and to exactly one (s, t) layer (or "longer than
    // 5"), both accumulated in double and resolved to float: the sum of the 21 layers agrees
    // with the image to float rounding (1e-5 relative: far above it, far below the noise).
    // Sorting the layers by length is a partition of the image by length, so this also says
    // the weighted images of each length add up to that length's share of the image.
    figure.Verdict(largest < 1e-5, "the " + std::to_string(allWeighted.size()) +
                                       " weighted technique images (lengths 1-5, and longer) sum to the BPT image "
                                       "within " + Num(largest) + " (relative, largest over pixels)");
    figure.Write();
}

// ------------------------------------------------------------------------------------
// F06: BPT vs. PT at equal time on indirect light
// ------------------------------------------------------------------------------------

void FigureEqualTime(const Kit& aKit, int aSize) {
    const char* const scene_file = "indirect_room.gltf";
    Figure figure(aKit, "F06", "BPT vs. path tracing at equal time, indirect light",
                  "Bidirectional path tracing: BPT 25 spp vs PT 56 spp (VCM course, seed 000; Monte Carlo III, seed 001)",
                  "BPT's RMSE is lower than PT's at equal time on a scene lit mostly indirectly");
    const Scene scene = LoadScene(aKit, scene_file, aSize, aSize);
    const Reference reference = GetReference(aKit, StandardReference(aKit, scene_file, aSize, aSize));
    figure.SetReference(reference);
    const double budget = aKit.Pick(20.0, 1.0);
    figure.Settings() = {{"scene", SceneSetting(scene_file)}, {"resolution", aSize}, {"seconds_each", budget},
                         {"algorithms", "bpt (balance heuristic), pt (next-event estimation + BSDF sampling, MIS)"},
                         {"seeds", {61, 62}}};
    RenderOptions options = BaseOptions(aKit, Algorithm::kBidirectionalPathTracing);
    options.mSeed = 61;
    const RenderResult bpt = RenderSeconds(scene, options, budget);
    options = BaseOptions(aKit, Algorithm::kPathTracing);
    options.mSeed = 62;
    const RenderResult pt = RenderSeconds(scene, options, budget);
    const double rmseBpt = smallvcm::Rmse(bpt.mImage, reference.mImage);
    const double rmsePt = smallvcm::Rmse(pt.mImage, reference.mImage);
    const double relBpt = smallvcm::RelativeMse(bpt.mImage, reference.mImage);
    const double relPt = smallvcm::RelativeMse(pt.mImage, reference.mImage);
    figure.AddRender("bpt", bpt, "BPT, " + std::to_string(bpt.mIterations) + " samples per pixel", &reference.mImage);
    figure.AddRender("pt", pt, "path tracing, " + std::to_string(pt.mIterations) + " samples per pixel", &reference.mImage);
    figure.AddPanel("reference", reference.mImage, "reference");
    // Without the reference's own noise n (rmse^2 = own^2 + n^2), the ratio of the two
    // estimators' errors.
    const double noise2 = reference.mNoiseRmse * reference.mNoiseRmse;
    const double ownRatio = std::sqrt(std::max(0.0, rmsePt * rmsePt - noise2) / std::max(1e-30, rmseBpt * rmseBpt - noise2));
    Json& numbers = figure.Numbers();
    numbers["bpt_iterations"] = bpt.mIterations;
    numbers["pt_iterations"] = pt.mIterations;
    numbers["bpt_seconds"] = bpt.mSeconds;
    numbers["pt_seconds"] = pt.mSeconds;
    numbers["rmse_bpt"] = rmseBpt;
    numbers["rmse_pt"] = rmsePt;
    numbers["relmse_bpt"] = relBpt;
    numbers["relmse_pt"] = relPt;
    numbers["rmse_ratio_pt_over_bpt"] = rmsePt / rmseBpt;
    numbers["rmse_ratio_without_reference_noise"] = ownRatio;
    numbers["reference_noise_rmse"] = reference.mNoiseRmse;
    numbers["slide"] = "BPT 25 spp vs PT 56 spp (Veach's images)";
    std::printf("    BPT %d spp in %.1f s: RMSE %s, relMSE %s; PT %d spp in %.1f s: RMSE %s, relMSE %s\n", bpt.mIterations,
                bpt.mSeconds, Num(rmseBpt).c_str(), Num(relBpt).c_str(), pt.mIterations, pt.mSeconds,
                Num(rmsePt).c_str(), Num(relPt).c_str());
    figure.Verdict(rmseBpt < rmsePt && relBpt < relPt,
                   "in " + Num(budget, "%g") + " s each, BPT (" + std::to_string(bpt.mIterations) + " spp) has RMSE " +
                       Num(rmseBpt) + ", PT (" + std::to_string(pt.mIterations) + " spp) " + Num(rmsePt) +
                       ": PT/BPT = " + Num(rmsePt / rmseBpt) + " (" + Num(ownRatio) +
                       " without the reference's noise); relMSE " + Num(relBpt) + " vs " + Num(relPt) +
                       " (slide: BPT 25 spp vs PT 56 spp)");
    figure.Write();
}

// ------------------------------------------------------------------------------------
// F07: light tracing vs. path tracing
// ------------------------------------------------------------------------------------

void FigureLightTracing(const Kit& aKit, int aSize) {
    const char* const scene_file = "caustic_glass_sphere.gltf";
    Figure figure(aKit, "F07", "Light tracing vs. path tracing", "Tracing Paths from Lights (Monte Carlo III, seed 001)",
                  "light tracing renders the floor caustic well and cannot render specular surfaces seen directly");
    const Scene scene = LoadScene(aKit, scene_file, aSize, aSize);
    const Reference reference = GetReference(aKit, StandardReference(aKit, scene_file, aSize, aSize));
    figure.SetReference(reference);
    const double budget = aKit.Pick(15.0, 1.0);
    const int directIterations = aKit.Pick(32, 16);
    // A caustic pixel sees a diffuse surface whose indirect light (reference minus a
    // direct-light-only render) is many times the typical indirect light of the diffuse
    // pixels: light focused by the sphere, not the soft bounce light of the room.
    const double causticFactor = 4.0;
    figure.Settings() = {{"scene", SceneSetting(scene_file)}, {"resolution", aSize}, {"seconds_each", budget},
                         {"algorithms", "lt (light tracing: light sub-paths splatted to the camera), pt (MIS)"},
                         {"seeds", {71, 72}},
                         {"direct_light_render", "pt, max path length 2, " + std::to_string(directIterations) +
                                                     " iterations, seed 73 (for the caustic mask)"},
                         {"specular_mask", "pixels whose 3x3 primary rays all hit a delta (mirror/glass) surface"},
                         {"caustic_mask", "pixels whose 3x3 primary rays all hit a non-specular surface and whose "
                                          "indirect light (reference - direct-only render) exceeds " +
                                              Num(causticFactor, "%g") +
                                              "x the median indirect light of such pixels"}};

    const std::vector<Surface> kinds = SurfaceKinds(scene);
    const Mask specular = MaskOf(kinds, Surface::kSpecular);
    const Mask nonSpecular = MaskOf(kinds, Surface::kNonSpecular);
    RenderOptions options = BaseOptions(aKit, Algorithm::kPathTracing);
    options.mSeed = 73;
    options.mMaxPathLength = 2;
    const RenderResult direct = RenderIterations(scene, options, directIterations);
    std::vector<double> indirect(kinds.size(), 0.0), diffuseIndirect;
    for (size_t i = 0; i < kinds.size(); i++) {
        indirect[i] = PixelValue(reference.mImage.mPixels[i]) - PixelValue(direct.mImage.mPixels[i]);
        if (nonSpecular[i]) diffuseIndirect.push_back(indirect[i]);
    }
    const double medianIndirect = Median(diffuseIndirect);
    Mask caustic(kinds.size(), false);
    for (size_t i = 0; i < kinds.size(); i++) caustic[i] = nonSpecular[i] && indirect[i] > causticFactor * medianIndirect;

    options = BaseOptions(aKit, Algorithm::kLightTracing);
    options.mSeed = 71;
    const RenderResult lt = RenderSeconds(scene, options, budget);
    options = BaseOptions(aKit, Algorithm::kPathTracing);
    options.mSeed = 72;
    const RenderResult pt = RenderSeconds(scene, options, budget);

    figure.AddRender("lt", lt, "light tracing, " + std::to_string(lt.mIterations) + " iterations", &reference.mImage);
    figure.AddRender("pt", pt, "path tracing, " + std::to_string(pt.mIterations) + " samples per pixel", &reference.mImage);
    figure.AddPanel("reference", reference.mImage, "reference");
    figure.AddPanel("direct", direct.mImage, "direct light only (for the caustic mask)");
    figure.AddPanel("mask_specular", MaskPanel(specular, reference.mImage),
                    "magenta: pixels that see a specular (delta) surface first")["pixels"] = CountOf(specular);
    figure.AddPanel("mask_caustic", MaskPanel(caustic, reference.mImage),
                    "magenta: caustic pixels (diffuse, indirect light > " + Num(causticFactor, "%g") +
                        "x the median)")["pixels"] = CountOf(caustic);

    const double refSpecular = MaskedMean(reference.mImage, specular);
    const double ltSpecular = MaskedMean(lt.mImage, specular);
    const double ptSpecular = MaskedMean(pt.mImage, specular);
    const double refCaustic = MaskedMean(reference.mImage, caustic);
    const double ltCausticRmse = MaskedRmse(lt.mImage, reference.mImage, caustic);
    const double ptCausticRmse = MaskedRmse(pt.mImage, reference.mImage, caustic);
    Json& numbers = figure.Numbers();
    numbers["specular_pixels"] = CountOf(specular);
    numbers["caustic_pixels"] = CountOf(caustic);
    numbers["median_indirect_of_diffuse_pixels"] = medianIndirect;
    numbers["specular_mean_reference"] = refSpecular;
    numbers["specular_mean_lt"] = ltSpecular;
    numbers["specular_mean_pt"] = ptSpecular;
    numbers["caustic_mean_reference"] = refCaustic;
    numbers["caustic_mean_lt"] = MaskedMean(lt.mImage, caustic);
    numbers["caustic_mean_pt"] = MaskedMean(pt.mImage, caustic);
    numbers["caustic_rmse_lt"] = ltCausticRmse;
    numbers["caustic_rmse_pt"] = ptCausticRmse;
    numbers["specular_rmse_lt"] = MaskedRmse(lt.mImage, reference.mImage, specular);
    numbers["specular_rmse_pt"] = MaskedRmse(pt.mImage, reference.mImage, specular);
    numbers["lt_iterations"] = lt.mIterations;
    numbers["pt_iterations"] = pt.mIterations;
    std::printf("    specular pixels (%d): mean LT %s, PT %s, reference %s; caustic pixels (%d): RMSE LT %s, PT %s "
                "(reference mean %s)\n",
                CountOf(specular), Num(ltSpecular).c_str(), Num(ptSpecular).c_str(), Num(refSpecular).c_str(),
                CountOf(caustic), Num(ltCausticRmse).c_str(), Num(ptCausticRmse).c_str(), Num(refCaustic).c_str());
    // "Cannot render": light tracing's splats never come from a delta vertex, so what it
    // shows there is (almost) nothing -- below 5% of the reference's light. "Renders the
    // caustic well": a lower error than path tracing's on the caustic pixels.
    const bool enough = CountOf(specular) > 0 && CountOf(caustic) > 0;
    const bool specularDark = ltSpecular < 0.05 * refSpecular;
    const bool causticBetter = ltCausticRmse < ptCausticRmse;
    figure.Verdict(enough && specularDark && causticBetter,
                   "on the " + std::to_string(CountOf(specular)) + " pixels that see glass, light tracing's mean is " +
                       Num(ltSpecular) + " against the reference's " + Num(refSpecular) + " (" +
                       Num(100.0 * ltSpecular / std::max(1e-12, refSpecular), "%.1f") + "%); on the " +
                       std::to_string(CountOf(caustic)) + " caustic pixels its RMSE is " + Num(ltCausticRmse) +
                       " against path tracing's " + Num(ptCausticRmse) + " at equal time (" + Num(budget, "%g") +
                       " s each)");
    figure.Write();
}

// ------------------------------------------------------------------------------------
// F08: specular-diffuse-specular paths, BPT vs. VCM over time
// ------------------------------------------------------------------------------------

void FigureSdsPaths(const Kit& aKit, int aSize) {
    const char* const scene_file = "sds_glass_sphere.gltf";
    Figure figure(aKit, "F08", "Limitations of BPT: specular-diffuse-specular paths",
                  "Limitations of bidirectional path tracing (VCM course, seed 000)",
                  "BPT misses the specular-diffuse-specular light however long it runs; VCM captures it");
    const Scene scene = LoadScene(aKit, scene_file, aSize, aSize);
    const Reference reference = GetReference(aKit, StandardReference(aKit, scene_file, aSize, aSize));
    figure.SetReference(reference);
    const std::vector<double> budgets =
        aKit.Pick(std::vector<double>{5.0, 20.0, 60.0}, std::vector<double>{0.25, 0.75, 2.0});
    // The caustic map: 512 x 512 rays over the sphere's cone; its count disc, 1% of the
    // scene radius (about 0.02 here), holds hundreds of landings where the caustic is.
    const int causticRays = 512;
    const float causticRadius = 0.01f * scene.GetSceneSphere().mRadius;
    // SDS pixels: sphere pixels whose predicted SDS light is at least this share of the
    // sphere's mean light in the reference (a threshold on the prediction alone, so that no
    // render's noise decides which pixels are measured).
    const double sdsThreshold = 0.25;
    figure.Settings() = {
        {"scene", SceneSetting(scene_file)}, {"resolution", aSize}, {"seconds", budgets},
        {"algorithms", "bpt, vcm (balance heuristic, radius factor 0.003, alpha 0.75)"},
        {"seeds", "80 + budget index (bpt), 90 + budget index (vcm)"},
        {"sphere_mask", "pixels whose 3x3 primary rays all hit a delta surface (here: the glass sphere)"},
        {"sds_prediction", "the light - specular - diffuse - specular - eye light with one diffuse bounce, computed "
                           "without any renderer: " + std::to_string(causticRays) + "^2 rays from the point light "
                           "followed through the glass (all branches, Fresnel-weighted) give the caustic irradiance "
                           "(landings within " + Num(causticRadius) + "), the camera's rays followed through the glass "
                           "read it at the diffuse points they reach (see CausticMap, PredictedSdsLight)"},
        {"sds_mask", "sphere pixels whose predicted SDS light is at least " + Num(sdsThreshold, "%g") +
                         "x the reference's mean over the sphere pixels"}};
    const Mask sphere = MaskOf(SurfaceKinds(scene), Surface::kSpecular);
    const CausticMap caustics(scene, causticRays, causticRadius);
    const Image predicted = PredictedSdsLight(scene, caustics);
    const double refSphere = MaskedMean(reference.mImage, sphere);
    Mask sds(sphere.size(), false);
    for (size_t i = 0; i < sds.size(); i++)
        sds[i] = sphere[i] && PixelValue(predicted.mPixels[i]) >= sdsThreshold * refSphere;
    const double refSds = MaskedMean(reference.mImage, sds);
    const double predictedSphereShare = MaskedMean(predicted, sphere) / std::max(1e-12, refSphere);
    const double predictedSdsShare = MaskedMean(predicted, sds) / std::max(1e-12, refSds);
    figure.AddPanel("reference", reference.mImage, "reference (VCM)");
    figure.AddPanel("sds_predicted", predicted,
                    "the SDS light with one diffuse bounce, predicted from a caustic map (no renderer)")["mean"] =
        smallvcm::MeanValue(predicted);
    figure.AddPanel("mask_sphere", MaskPanel(sphere, reference.mImage),
                    "magenta: pixels that see the glass sphere first")["pixels"] = CountOf(sphere);
    figure.AddPanel("mask_sds", MaskPanel(sds, reference.mImage),
                    "magenta: sphere pixels whose predicted SDS light is at least " + Num(sdsThreshold, "%g") +
                        "x the sphere's mean light")["pixels"] = CountOf(sds);
    std::printf("    predicted SDS light: %s%% of the sphere pixels' light (reference mean %s over %d pixels); "
                "%d SDS pixels, where it is %s%%\n",
                Num(100.0 * predictedSphereShare, "%.2f").c_str(), Num(refSphere).c_str(), CountOf(sphere),
                CountOf(sds), Num(100.0 * predictedSdsShare, "%.1f").c_str());

    struct Run {
        double mSeconds, mRmse, mSphereRmse, mSphereMean, mSdsRmse, mSdsMean;
        int mIterations;
    };
    std::map<std::string, std::vector<Run>> runs;
    Json curves = Json::object();
    for (const auto& [name, algorithm, seedBase] :
         {std::tuple{std::string("bpt"), Algorithm::kBidirectionalPathTracing, 80},
          std::tuple{std::string("vcm"), Algorithm::kVertexConnectionMerging, 90}}) {
        for (size_t b = 0; b < budgets.size(); b++) {
            RenderOptions options = BaseOptions(aKit, algorithm);
            options.mSeed = uint64_t(seedBase + int(b));
            const RenderResult result = RenderSeconds(scene, options, budgets[b]);
            const Run run{result.mSeconds,
                          smallvcm::Rmse(result.mImage, reference.mImage),
                          MaskedRmse(result.mImage, reference.mImage, sphere),
                          MaskedMean(result.mImage, sphere),
                          MaskedRmse(result.mImage, reference.mImage, sds),
                          MaskedMean(result.mImage, sds),
                          result.mIterations};
            runs[name].push_back(run);
            curves[name].push_back({{"budget", budgets[b]}, {"seconds", run.mSeconds}, {"iterations", run.mIterations},
                                    {"rmse", run.mRmse}, {"sphere_rmse", run.mSphereRmse},
                                    {"sphere_mean", run.mSphereMean}, {"sds_rmse", run.mSdsRmse},
                                    {"sds_mean", run.mSdsMean}});
            std::printf("    %s %5.1f s (%4d it): RMSE %-8s sphere: RMSE %-8s mean %-8s SDS pixels: RMSE %-8s mean %s\n",
                        name.c_str(), run.mSeconds, run.mIterations, Num(run.mRmse).c_str(),
                        Num(run.mSphereRmse).c_str(), Num(run.mSphereMean).c_str(), Num(run.mSdsRmse).c_str(),
                        Num(run.mSdsMean).c_str());
            if (b + 1 == budgets.size()) {
                Json& numbers = figure.AddRender(name, result,
                                                 (name == "bpt" ? "BPT, " : "VCM, ") + Num(run.mSeconds, "%.0f") +
                                                     " s (" + std::to_string(run.mIterations) + " iterations)",
                                                 &reference.mImage);
                numbers["sphere_mean"] = run.mSphereMean;
                numbers["sds_rmse"] = run.mSdsRmse;
                numbers["sds_mean"] = run.mSdsMean;
            }
        }
    }
    std::printf("    reference: sphere mean %s, SDS pixels mean %s, noise RMSE %s\n", Num(refSphere).c_str(),
                Num(refSds).c_str(), Num(reference.mNoiseRmse).c_str());
    const Run& bptFirst = runs["bpt"].front();
    const Run& bptLast = runs["bpt"].back();
    const Run& vcmFirst = runs["vcm"].front();
    const Run& vcmLast = runs["vcm"].back();
    // The shortfall: the share of the reference's light that a render lacks on a set of
    // pixels. BPT is unbiased for every path it can sample, so its shortfall on the SDS
    // pixels is the SDS light it misses, and its SDS-pixel RMSE can never fall below
    // |mean difference| there (an RMSE over pixels is at least the size of their mean
    // difference): an error floor that time does not lower.
    auto shortfall = [](double aMean, double aReference) { return 1.0 - aMean / std::max(1e-12, aReference); };
    const double bptFall = bptFirst.mSdsRmse / std::max(1e-12, bptLast.mSdsRmse);
    const double vcmFall = vcmFirst.mSdsRmse / std::max(1e-12, vcmLast.mSdsRmse);
    const double timeRatio = bptLast.mSeconds / bptFirst.mSeconds;
    Json& numbers = figure.Numbers();
    numbers["curves"] = curves;
    numbers["sphere_pixels"] = CountOf(sphere);
    numbers["sphere_mean_reference"] = refSphere;
    numbers["predicted_sds_share_of_sphere_light"] = predictedSphereShare;
    numbers["sphere_shortfall_bpt_longest"] = shortfall(bptLast.mSphereMean, refSphere);
    numbers["sphere_shortfall_vcm_longest"] = shortfall(vcmLast.mSphereMean, refSphere);
    numbers["sds_pixels"] = CountOf(sds);
    numbers["sds_mean_reference"] = refSds;
    numbers["predicted_sds_share_of_sds_pixel_light"] = predictedSdsShare;
    numbers["sds_shortfall_bpt"] = Json::array();
    numbers["sds_shortfall_vcm"] = Json::array();
    for (const Run& run : runs["bpt"]) numbers["sds_shortfall_bpt"].push_back(shortfall(run.mSdsMean, refSds));
    for (const Run& run : runs["vcm"]) numbers["sds_shortfall_vcm"].push_back(shortfall(run.mSdsMean, refSds));
    numbers["bpt_sds_error_floor"] = std::abs(bptLast.mSdsMean - refSds);
    numbers["sds_rmse_fall_bpt"] = bptFall;
    numbers["sds_rmse_fall_vcm"] = vcmFall;
    numbers["sds_rmse_fall_if_noise_only"] = std::sqrt(timeRatio);
    numbers["reference_noise_rmse"] = reference.mNoiseRmse;
    if (CountOf(sds) == 0)  // nothing measured on an empty mask: no numbers rather than zeros
        for (const char* key : {"sds_mean_reference", "predicted_sds_share_of_sds_pixel_light", "sds_shortfall_bpt",
                                "sds_shortfall_vcm", "bpt_sds_error_floor", "sds_rmse_fall_bpt", "sds_rmse_fall_vcm"})
            numbers[key] = nullptr;

    // Too few SDS pixels to measure anything: the scene does not show the case (the claim
    // can then be neither confirmed nor refuted here, and the record says why).
    const int minimumPixels = std::max(16, CountOf(sphere) / 20);
    if (CountOf(sds) < minimumPixels) {
        figure.Verdict(false, "not measurable on this scene: the SDS light the camera sees is predicted at " +
                                  Num(100.0 * predictedSphereShare, "%.2f") + "% of the glass sphere's light, and only " +
                                  std::to_string(CountOf(sds)) + " pixels (fewer than " +
                                  std::to_string(minimumPixels) + ") get a quarter of the sphere's light from it; on "
                                  "the sphere BPT lacks " +
                                  Num(100.0 * shortfall(bptLast.mSphereMean, refSphere), "%.1f") +
                                  "% of the reference's light after " + Num(bptLast.mSeconds, "%.0f") + " s, VCM " +
                                  Num(100.0 * shortfall(vcmLast.mSphereMean, refSphere), "%.1f") + "%");
        figure.Write();
        return;
    }
    // The claim, in numbers: BPT lacks a clear share (> 10%) of the SDS pixels' light at
    // every budget, while VCM's shortfall at the longest budget is under a quarter of BPT's;
    // and from the shortest to the longest budget VCM's SDS error falls by more than BPT's
    // and ends lower.
    bool bptAlwaysShort = true;
    for (const Run& run : runs["bpt"]) bptAlwaysShort = bptAlwaysShort && shortfall(run.mSdsMean, refSds) > 0.1;
    const double bptShort = shortfall(bptLast.mSdsMean, refSds), vcmShort = shortfall(vcmLast.mSdsMean, refSds);
    const bool vcmCaptures = std::abs(vcmShort) < 0.25 * bptShort;
    const bool vcmFallsMore = vcmFall > bptFall && vcmLast.mSdsRmse < bptLast.mSdsRmse;
    figure.Verdict(bptAlwaysShort && vcmCaptures && vcmFallsMore,
                   "on the " + std::to_string(CountOf(sds)) + " pixels that show the caustic through the glass (its "
                       "predicted share " + Num(100.0 * predictedSdsShare, "%.0f") + "%), BPT lacks " +
                       Num(100.0 * shortfall(bptFirst.mSdsMean, refSds), "%.0f") + "% of the reference's light after " +
                       Num(bptFirst.mSeconds, "%.1f") + " s and still " + Num(100.0 * bptShort, "%.0f") + "% after " +
                       Num(bptLast.mSeconds, "%.1f") + " s (VCM: " + Num(100.0 * vcmShort, "%.0f") +
                       "%); from the shortest to the longest budget BPT's SDS RMSE falls " + Num(bptFall) + "x (" +
                       Num(bptFirst.mSdsRmse) + " -> " + Num(bptLast.mSdsRmse) + ", floor " +
                       Num(std::abs(bptLast.mSdsMean - refSds)) + "), VCM's " + Num(vcmFall) + "x (" +
                       Num(vcmFirst.mSdsRmse) + " -> " + Num(vcmLast.mSdsRmse) + "); noise alone would fall " +
                       Num(std::sqrt(timeRatio)) + "x");
    figure.Write();
}

}  // namespace

int main(int argc, char** argv) {
    return RunFigureProgram(argc, argv, "fig_bidirectional: figures F05-F08 (bidirectional methods)", [](const Kit& aKit) {
        const int size = aKit.Pick(256, 64);
        if (aKit.Wants("F05")) FigurePathPyramid(aKit, size);
        if (aKit.Wants("F06")) FigureEqualTime(aKit, size);
        if (aKit.Wants("F07")) FigureLightTracing(aKit, size);
        if (aKit.Wants("F08")) FigureSdsPaths(aKit, size);
    });
}
