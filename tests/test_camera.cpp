// [camera] The pinhole camera: raster -> ray -> world -> raster round trips, the
// horizontal field of view, square pixels at any aspect ratio, orientation (raster y = 0
// is the top row), points behind the camera, and the SmallVCM Cornell camera's basis.
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <cmath>

using namespace smallvcm;

namespace {

constexpr double kDegrees = 180.0 / 3.14159265358979323846;

double AngleDegrees(const Vec3& aA, const Vec3& aB) {
    const glm::dvec3 a = glm::normalize(glm::dvec3(aA)), b = glm::normalize(glm::dvec3(aB));
    // atan2(|a x b|, a.b) is accurate at every angle (acos is not near 0).
    return std::atan2(glm::length(glm::cross(a, b)), glm::dot(a, b)) * kDegrees;
}

Camera MakeCamera(int aWidth, int aHeight, float aFov = 60.f) {
    Camera camera;
    camera.Setup(Vec3(1.f, 2.f, 3.f), Vec3(0.3f, 1.f, -0.2f), Vec3(0.f, 0.f, 1.f), aFov);
    camera.SetResolution(aWidth, aHeight);
    return camera;
}

const int kResolutions[][2] = {{512, 512}, {640, 360}, {100, 300}};

} // namespace

TEST_CASE("Raster to ray to world point to raster returns to the same raster position", "[camera]") {
    // Tolerance 1e-3 px: the world point is up to 100 units away, where float positions
    // carry ~1e-5 relative error; projected through the image plane that is ~3e-4 px.
    for (const auto& resolution : kResolutions) {
        const int width = resolution[0], height = resolution[1];
        INFO(width << "x" << height);
        const Camera camera = MakeCamera(width, height);
        Rng rng(401, 0);
        for (int i = 0; i < 10000; i++) {
            const Vec2 raster(rng.GetFloat() * float(width), rng.GetFloat() * float(height));
            const Ray ray = camera.GenerateRay(raster);
            REQUIRE(ray.mOrigin == camera.Position());
            REQUIRE(glm::length(ray.mDirection) == Approx(1.f).epsilon(1e-6));
            const float distance = 0.1f + 100.f * rng.GetFloat();
            const std::optional<Vec2> back = camera.WorldToRaster(ray.mOrigin + distance * ray.mDirection);
            REQUIRE(back.has_value());
            REQUIRE(std::abs(back->x - raster.x) <= 1e-3f);
            REQUIRE(std::abs(back->y - raster.y) <= 1e-3f);
            REQUIRE(camera.CheckRaster(*back) == camera.CheckRaster(raster));
        }
    }
}

TEST_CASE("The ray through the image centre is the forward direction", "[camera]") {
    for (const auto& resolution : kResolutions) {
        const Camera camera = MakeCamera(resolution[0], resolution[1]);
        const Ray ray = camera.GenerateRay(Vec2(0.5f * float(resolution[0]), 0.5f * float(resolution[1])));
        REQUIRE(glm::length(ray.mDirection - camera.Forward()) <= 1e-6f);
        REQUIRE(glm::length(camera.Forward() - glm::normalize(Vec3(0.3f, 1.f, -0.2f))) <= 1e-6f);
    }
}

TEST_CASE("The camera basis is orthonormal and right-handed: right x up = -forward", "[camera]") {
    const Camera camera = MakeCamera(640, 360);
    REQUIRE(glm::length(camera.Right()) == Approx(1.f).epsilon(1e-6));
    REQUIRE(glm::length(camera.Up()) == Approx(1.f).epsilon(1e-6));
    REQUIRE(std::abs(glm::dot(camera.Right(), camera.Up())) <= 1e-6f);
    REQUIRE(std::abs(glm::dot(camera.Right(), camera.Forward())) <= 1e-6f);
    REQUIRE(std::abs(glm::dot(camera.Up(), camera.Forward())) <= 1e-6f);
    REQUIRE(glm::length(glm::cross(camera.Right(), camera.Up()) + camera.Forward()) <= 1e-6f);
    // Up leans towards the up hint (+z), right is horizontal.
    REQUIRE(camera.Up().z > 0.9f);
    REQUIRE(std::abs(camera.Right().z) <= 1e-6f);
}

TEST_CASE("The rays at the left and right image edges make half the horizontal field of view with forward", "[camera]") {
    // Tolerance 1e-4 degrees: the directions are normalised floats (~1e-7 rad).
    for (const float fov : {30.f, 45.f, 60.f, 90.f, 120.f}) {
        for (const auto& resolution : kResolutions) {
            const int width = resolution[0], height = resolution[1];
            INFO("fov " << fov << ", " << width << "x" << height);
            const Camera camera = MakeCamera(width, height, fov);
            REQUIRE(camera.HorizontalFovDegrees() == fov);
            REQUIRE(camera.ImagePlaneDist() == Approx(width / (2.0 * std::tan(0.5 * fov / kDegrees))).epsilon(1e-5));
            const float yCentre = 0.5f * float(height);
            REQUIRE(AngleDegrees(camera.GenerateRay(Vec2(0.f, yCentre)).mDirection, camera.Forward()) == Approx(0.5 * fov).margin(1e-4));
            REQUIRE(AngleDegrees(camera.GenerateRay(Vec2(float(width), yCentre)).mDirection, camera.Forward()) ==
                    Approx(0.5 * fov).margin(1e-4));
            // The vertical field of view follows the aspect ratio: tan(v/2) = tan(h/2) H / W.
            const double vertical = 2.0 * std::atan(std::tan(0.5 * fov / kDegrees) * height / width) * kDegrees;
            REQUIRE(AngleDegrees(camera.GenerateRay(Vec2(0.5f * float(width), 0.f)).mDirection, camera.Forward()) ==
                    Approx(0.5 * vertical).margin(1e-4));
        }
    }
}

TEST_CASE("Raster x grows to the right and raster y = 0 is the top row", "[camera]") {
    const Camera camera = MakeCamera(640, 360);
    const Ray left = camera.GenerateRay(Vec2(0.f, 180.f)), right = camera.GenerateRay(Vec2(640.f, 180.f));
    const Ray top = camera.GenerateRay(Vec2(320.f, 0.f)), bottom = camera.GenerateRay(Vec2(320.f, 360.f));
    REQUIRE(glm::dot(left.mDirection, camera.Right()) < 0.f);
    REQUIRE(glm::dot(right.mDirection, camera.Right()) > 0.f);
    REQUIRE(glm::dot(top.mDirection, camera.Up()) > 0.f);
    REQUIRE(glm::dot(bottom.mDirection, camera.Up()) < 0.f);
    // A point above the camera's axis lands in the upper half of the image.
    const std::optional<Vec2> raster =
        camera.WorldToRaster(camera.Position() + 5.f * camera.Forward() + 0.5f * camera.Up());
    REQUIRE(raster.has_value());
    REQUIRE(raster->y < 180.f);
    REQUIRE(raster->x == Approx(320.f).margin(1e-3));
    // Pixel indices: y * width + x, top-left first.
    REQUIRE(camera.RasterToIndex(Vec2(0.5f, 0.5f)) == 0);
    REQUIRE(camera.RasterToIndex(Vec2(639.9f, 0.2f)) == 639);
    REQUIRE(camera.RasterToIndex(Vec2(3.5f, 2.5f)) == 2 * 640 + 3);
    REQUIRE(camera.RasterToIndex(Vec2(639.99f, 359.99f)) == 640 * 360 - 1);
    REQUIRE(camera.CheckRaster(Vec2(0.f, 0.f)));
    REQUIRE_FALSE(camera.CheckRaster(Vec2(640.f, 10.f)));
    REQUIRE_FALSE(camera.CheckRaster(Vec2(10.f, 360.f)));
    REQUIRE_FALSE(camera.CheckRaster(Vec2(-0.01f, 10.f)));
}

TEST_CASE("Pixels are square: a circle facing the camera projects to equal width and height", "[camera]") {
    // A circle centred on the optical axis, in a plane perpendicular to it, projects to a
    // circle exactly when both raster axes use the same focal length. Its extent is
    // measured over 3600 points; tolerance 1e-3 px (float projection error, ~1e-4 px at
    // these distances, plus the 0.1 degree point spacing: 1 - cos(0.05 deg) = 4e-7 relative).
    for (const auto& resolution : kResolutions) {
        const int width = resolution[0], height = resolution[1];
        INFO(width << "x" << height);
        const Camera camera = MakeCamera(width, height);
        for (const float distance : {2.f, 10.f}) {
            const Vec3 centre = camera.Position() + distance * camera.Forward();
            const float radius = 0.1f * distance;
            float minX = 1e9f, maxX = -1e9f, minY = 1e9f, maxY = -1e9f;
            for (int i = 0; i < 3600; i++) {
                const float phi = 2.f * kPi * float(i) / 3600.f;
                const Vec3 onCircle = centre + radius * (std::cos(phi) * camera.Right() + std::sin(phi) * camera.Up());
                const std::optional<Vec2> raster = camera.WorldToRaster(onCircle);
                REQUIRE(raster.has_value());
                minX = std::min(minX, raster->x); maxX = std::max(maxX, raster->x);
                minY = std::min(minY, raster->y); maxY = std::max(maxY, raster->y);
            }
            const float expected = 2.f * 0.1f * camera.ImagePlaneDist();  // 2 r f / d
            REQUIRE(maxX - minX == Approx(expected).margin(1e-3));
            REQUIRE(maxY - minY == Approx(expected).margin(1e-3));
            REQUIRE(std::abs((maxX - minX) - (maxY - minY)) <= 1e-3f);
        }
    }
}

TEST_CASE("Points behind the camera or in its plane are rejected by WorldToRaster", "[camera]") {
    const Camera camera = MakeCamera(512, 512);
    REQUIRE_FALSE(camera.WorldToRaster(camera.Position() - 3.f * camera.Forward()).has_value());
    REQUIRE_FALSE(camera.WorldToRaster(camera.Position() - 0.1f * camera.Forward() + 5.f * camera.Right()).has_value());
    REQUIRE_FALSE(camera.WorldToRaster(camera.Position() + 2.f * camera.Right() + 1.f * camera.Up()).has_value());
    REQUIRE_FALSE(camera.WorldToRaster(camera.Position()).has_value());
    // Just in front it is accepted (even if far outside the image).
    const std::optional<Vec2> raster =
        camera.WorldToRaster(camera.Position() + 1e-3f * camera.Forward() + 1.f * camera.Right());
    REQUIRE(raster.has_value());
    REQUIRE_FALSE(camera.CheckRaster(*raster));
}

TEST_CASE("A camera rejects a non-positive resolution with an Error", "[camera]") {
    Camera camera;
    REQUIRE_THROWS_AS(camera.SetResolution(0, 10), Error);
    REQUIRE_THROWS_AS(camera.SetResolution(10, -1), Error);
    camera.SetResolution(7, 3);
    REQUIRE(camera.Width() == 7);
    REQUIRE(camera.Height() == 3);
    REQUIRE(camera.PixelCount() == 21);
}

TEST_CASE("The Cornell camera loaded from the scene file has SmallVCM's position, basis and field of view", "[camera]") {
    // Numbers from SMALLVCM_SCENES.md, section 5; tolerance 1e-5 (the document's digits).
    const Scene scene = testutil::LoadCornell(4, 256, 256);
    const Camera& camera = scene.mCamera;
    auto near = [](const Vec3& aA, const Vec3& aB) {
        return std::abs(aA.x - aB.x) <= 1e-5f && std::abs(aA.y - aB.y) <= 1e-5f && std::abs(aA.z - aB.z) <= 1e-5f;
    };
    INFO("position " << camera.Position().x << " " << camera.Position().y << " " << camera.Position().z);
    INFO("forward " << camera.Forward().x << " " << camera.Forward().y << " " << camera.Forward().z);
    INFO("right " << camera.Right().x << " " << camera.Right().y << " " << camera.Right().z);
    INFO("up " << camera.Up().x << " " << camera.Up().y << " " << camera.Up().z);
    REQUIRE(near(camera.Position(), Vec3(-0.0439815f, -4.12529f, 0.222539f)));
    REQUIRE(near(camera.Forward(), Vec3(0.00688625f, 0.998505f, -0.0542161f)));
    REQUIRE(near(camera.Right(), Vec3(0.999976f, -0.006896f, 0.f)));
    REQUIRE(near(camera.Up(), Vec3(3.739e-4f, 0.054215f, 0.998529f)));
    REQUIRE(camera.HorizontalFovDegrees() == Approx(45.f).epsilon(1e-5));
    // Image-plane distance W / (2 tan(22.5 deg)) = 309.019 px at W = 256.
    REQUIRE(camera.ImagePlaneDist() == Approx(309.019).margin(1e-3));
    REQUIRE(camera.Width() == 256);
    REQUIRE(camera.Height() == 256);
    // And the round trip holds for this camera as well.
    Rng rng(402, 0);
    for (int i = 0; i < 1000; i++) {
        const Vec2 raster = rng.GetVec2() * 256.f;
        const Ray ray = camera.GenerateRay(raster);
        const std::optional<Vec2> back = camera.WorldToRaster(ray.mOrigin + 3.f * ray.mDirection);
        REQUIRE(back.has_value());
        REQUIRE(glm::length(*back - raster) <= 1e-3f);
    }
}
