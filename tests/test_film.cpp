// [film] Film accumulation, layers and Resolve; image metrics against hand-computed
// values; the image writers (PFM round trip bit for bit, orientation in the file, PNG and
// HDR signatures) and their failure behaviour (Error naming the path, nothing left behind);
// PNG exposure and tone curves (decoded again), files written together, the .hdr reader;
// OpenEXR (round trip bit for bit, layers as named channels, files of other writers made
// with tinyexr here, and a fuzz set of bad files each refused in one line).
// Files go to a per-process folder under the system's temporary directory.
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <tinyexr.h>
#include <unistd.h>

#define STB_IMAGE_STATIC
#define STB_IMAGE_IMPLEMENTATION
#define STBI_ONLY_PNG
#include <stb/stb_image.h>

using namespace smallvcm;
namespace fs = std::filesystem;

namespace {

// A fresh folder for this test case's files, removed when the test case ends.
using testutil::ReadText;

class TempFolder {
public:
    TempFolder() {
        mPath = fs::temp_directory_path() / ("smallvcm_test_film_" + std::to_string(::getpid()));
        fs::remove_all(mPath);
        fs::create_directories(mPath);
    }
    ~TempFolder() {
        std::error_code ignored;
        fs::remove_all(mPath, ignored);
    }
    std::string File(const std::string& aName) const { return (mPath / aName).string(); }
    // Every entry of the folder, so a test can see that nothing stray was left.
    std::vector<std::string> Entries() const {
        std::vector<std::string> names;
        for (const auto& entry : fs::directory_iterator(mPath)) names.push_back(entry.path().filename().string());
        return names;
    }

private:
    fs::path mPath;
};

std::vector<unsigned char> ReadBytes(const std::string& aPath) {
    std::ifstream file(aPath, std::ios::binary);
    return std::vector<unsigned char>(std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>());
}

uint32_t FloatBits(float aValue) {
    uint32_t bits;
    std::memcpy(&bits, &aValue, 4);
    return bits;
}

// aBack holds aImage's size and every channel's bits (NaN payloads, infinities, -0 included).
void RequireSameBits(const Image& aBack, const Image& aImage) {
    REQUIRE(aBack.mWidth == aImage.mWidth);
    REQUIRE(aBack.mHeight == aImage.mHeight);
    for (int y = 0; y < aImage.mHeight; y++)
        for (int x = 0; x < aImage.mWidth; x++)
            for (int c = 0; c < 3; c++) {
                INFO("pixel " << x << ", " << y << ", channel " << c);
                REQUIRE(FloatBits(aBack.At(x, y)[c]) == FloatBits(aImage.At(x, y)[c]));
            }
}

// A small image whose every channel of every pixel is different.
Image MakeGradient(int aWidth, int aHeight) {
    Image image(aWidth, aHeight);
    for (int y = 0; y < aHeight; y++)
        for (int x = 0; x < aWidth; x++) image.At(x, y) = Vec3(float(x) + 0.25f, float(y) + 0.5f, float(x * 100 + y) + 0.125f);
    return image;
}

} // namespace

// ---------------------------------------------------------------------------------
// Film
// ---------------------------------------------------------------------------------

TEST_CASE("Film adds colours per pixel and Resolve scales them", "[film]") {
    Film film(4, 3);
    REQUIRE(film.Width() == 4);
    REQUIRE(film.Height() == 3);
    film.AddColor(0, Vec3(1.f, 2.f, 3.f));
    film.AddColor(0, Vec3(0.5f, 0.5f, 0.5f));
    film.AddColor(2 * 4 + 3, Vec3(4.f, 0.f, 1.f));  // pixel (3, 2), the last one
    const Image image = film.Resolve(0.5);
    REQUIRE(image.mWidth == 4);
    REQUIRE(image.mHeight == 3);
    REQUIRE(image.mPixels.size() == 12);
    REQUIRE(image.At(0, 0) == Vec3(0.75f, 1.25f, 1.75f));
    REQUIRE(image.At(3, 2) == Vec3(2.f, 0.f, 0.5f));
    for (int y = 0; y < 3; y++)
        for (int x = 0; x < 4; x++)
            if ((x | y) != 0 && !(x == 3 && y == 2)) REQUIRE(image.At(x, y) == Vec3(0.f));
}

TEST_CASE("Film accumulates in double precision", "[film]") {
    // A million splats of 0.1f: a float sum would drift by ~1e-3 relative (each addition
    // to a sum near 1e5 rounds by up to 4e-3); in double the mean comes back as 0.1f.
    Film film(1, 1);
    for (int i = 0; i < 1000000; i++) film.AddColor(0, Vec3(0.1f));
    REQUIRE(film.Resolve(1e-6).At(0, 0).x == Approx(0.1f).epsilon(1e-6));
}

TEST_CASE("AddLayer is idempotent by name and AddToLayer writes only its layer", "[film]") {
    Film film(3, 2);
    REQUIRE(film.LayerCount() == 0);
    const int direct = film.AddLayer("direct");
    const int indirect = film.AddLayer("indirect");
    REQUIRE(direct == 0);
    REQUIRE(indirect == 1);
    REQUIRE(film.AddLayer("direct") == direct);
    REQUIRE(film.AddLayer("indirect") == indirect);
    REQUIRE(film.LayerCount() == 2);
    REQUIRE(film.LayerName(direct) == "direct");
    REQUIRE(film.LayerName(indirect) == "indirect");
    REQUIRE(film.LayerIndex("indirect") == indirect);
    REQUIRE(film.LayerIndex("missing") == -1);

    film.AddToLayer(indirect, 4, Vec3(2.f, 4.f, 6.f));
    film.AddToLayer(indirect, 4, Vec3(2.f, 0.f, 0.f));
    film.AddColor(1, Vec3(1.f));
    const Image main = film.Resolve(1.0), first = film.Resolve(1.0, direct), second = film.Resolve(0.25, indirect);
    REQUIRE(main.At(1, 0) == Vec3(1.f));
    REQUIRE(main.At(1, 1) == Vec3(0.f));  // pixel 4 = (1, 1): the layer write did not leak
    REQUIRE(MeanValue(first) == 0.0);
    REQUIRE(second.At(1, 1) == Vec3(1.f, 1.f, 1.5f));
    REQUIRE(second.At(1, 0) == Vec3(0.f));
}

TEST_CASE("Film::Accumulate adds another film's image and layers", "[film]") {
    Film a(2, 2), b(2, 2);
    for (Film* film : {&a, &b}) {
        film->AddLayer("x");
        film->AddLayer("y");
    }
    a.AddColor(3, Vec3(1.f));
    b.AddColor(3, Vec3(2.f));
    b.AddColor(0, Vec3(5.f));
    a.AddToLayer(1, 2, Vec3(0.5f));
    b.AddToLayer(1, 2, Vec3(0.25f));
    b.AddToLayer(0, 1, Vec3(7.f));
    a.Accumulate(b);
    const Image image = a.Resolve(1.0), x = a.Resolve(1.0, 0), y = a.Resolve(1.0, 1);
    REQUIRE(image.At(1, 1) == Vec3(3.f));
    REQUIRE(image.At(0, 0) == Vec3(5.f));
    REQUIRE(x.At(1, 0) == Vec3(7.f));
    REQUIRE(y.At(0, 1) == Vec3(0.75f));
    // b is unchanged.
    REQUIRE(b.Resolve(1.0).At(1, 1) == Vec3(2.f));
}

// ---------------------------------------------------------------------------------
// Metrics
// ---------------------------------------------------------------------------------

TEST_CASE("MeanValue, Rmse and RelativeMse match hand-computed values", "[film]") {
    Image image(2, 1), reference(2, 1);
    image.At(0, 0) = Vec3(1.f, 2.f, 3.f);
    image.At(1, 0) = Vec3(4.f, 5.f, 6.f);
    reference.At(0, 0) = Vec3(1.f, 1.f, 1.f);
    reference.At(1, 0) = Vec3(2.f, 0.f, 0.1f);
    // Mean over 6 values: 21 / 6.
    REQUIRE(MeanValue(image) == Approx(3.5).epsilon(1e-12));
    REQUIRE(MeanValue(reference) == Approx(5.1 / 6.0).epsilon(1e-7));
    // Differences 0, 1, 2, 2, 5, 5.9: squares sum to 4 + 1 + 4 + 25 + 34.81 = 68.81.
    REQUIRE(Rmse(image, reference) == Approx(std::sqrt(68.81 / 6.0)).epsilon(1e-6));
    REQUIRE(Rmse(image, image) == 0.0);
    // Relative: d^2 / (r^2 + 0.01): 0, 1/1.01, 4/1.01, 4/4.01, 25/0.01, 34.81/0.02.
    const double relative = (1.0 / 1.01 + 4.0 / 1.01 + 4.0 / 4.01 + 25.0 / 0.01 + 34.81 / 0.02) / 6.0;
    REQUIRE(RelativeMse(image, reference) == Approx(relative).epsilon(1e-6));
    REQUIRE(RelativeMse(reference, reference) == 0.0);
    // Empty images: mean 0.
    REQUIRE(MeanValue(Image()) == 0.0);
}

TEST_CASE("Image metrics reject images of different sizes with an Error naming both sizes", "[film]") {
    const Image a(2, 3), b(3, 2);
    REQUIRE_THROWS_AS(Rmse(a, b), Error);
    REQUIRE_THROWS_WITH(RelativeMse(a, b), Catch::Contains("2x3") && Catch::Contains("3x2"));
}

// ---------------------------------------------------------------------------------
// Writing and reading
// ---------------------------------------------------------------------------------

TEST_CASE("A PFM written and read back is bit-for-bit the same image", "[film]") {
    const TempFolder folder;
    Image image = MakeGradient(5, 3);
    // Values a lossy or text format would not keep.
    image.At(0, 0) = Vec3(-0.f, 1e-40f, 3.4e38f);                                   // signed zero, denormal, near max
    image.At(1, 0) = Vec3(std::numeric_limits<float>::infinity(), -1.5f, 0.1f);
    image.At(4, 2) = Vec3(1.f / 3.f, -1e-30f, 16777217.f);
    const std::string path = folder.File("round trip.pfm");  // a space in the name, too
    WriteImage(path, image);
    RequireSameBits(ReadPfm(path), image);
}

TEST_CASE("A PFM keeps pixel (0, 0) at the top left and stores the bottom row first", "[film]") {
    const TempFolder folder;
    const Image image = MakeGradient(3, 2);
    const std::string path = folder.File("orientation.pfm");
    WriteImage(path, image);
    REQUIRE(ReadPfm(path).At(0, 0) == image.At(0, 0));

    const std::vector<unsigned char> bytes = ReadBytes(path);
    const std::string header = "PF\n3 2\n-1\n";
    REQUIRE(bytes.size() == header.size() + 3 * 2 * 12);
    REQUIRE(std::string(bytes.begin(), bytes.begin() + long(header.size())) == header);
    auto pixelInFile = [&](int aIndex) {
        Vec3 p;
        std::memcpy(&p.x, &bytes[header.size() + size_t(aIndex) * 12 + 0], 4);
        std::memcpy(&p.y, &bytes[header.size() + size_t(aIndex) * 12 + 4], 4);
        std::memcpy(&p.z, &bytes[header.size() + size_t(aIndex) * 12 + 8], 4);
        return p;
    };
    // The file's first pixel is the image's bottom-left, its last the top-right.
    REQUIRE(pixelInFile(0) == image.At(0, 1));
    REQUIRE(pixelInFile(2) == image.At(2, 1));
    REQUIRE(pixelInFile(3) == image.At(0, 0));
    REQUIRE(pixelInFile(5) == image.At(2, 0));
}

TEST_CASE("PNG and HDR files start with their formats' signatures and the image size", "[film]") {
    const TempFolder folder;
    const Image image = MakeGradient(7, 5);

    const std::string png = folder.File("image.png");
    WriteImage(png, image);
    const std::vector<unsigned char> pngBytes = ReadBytes(png);
    const unsigned char signature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
    REQUIRE(pngBytes.size() > 33);
    REQUIRE(std::memcmp(pngBytes.data(), signature, 8) == 0);
    // The first chunk is IHDR: big-endian width and height at bytes 16 and 20.
    REQUIRE(std::string(pngBytes.begin() + 12, pngBytes.begin() + 16) == "IHDR");
    auto bigEndian = [&](size_t aOffset) {
        return (uint32_t(pngBytes[aOffset]) << 24) | (uint32_t(pngBytes[aOffset + 1]) << 16) |
               (uint32_t(pngBytes[aOffset + 2]) << 8) | uint32_t(pngBytes[aOffset + 3]);
    };
    REQUIRE(bigEndian(16) == 7);
    REQUIRE(bigEndian(20) == 5);
    REQUIRE(pngBytes[24] == 8);  // 8 bits per channel
    REQUIRE(pngBytes[25] == 2);  // colour type 2: RGB

    const std::string hdr = folder.File("image.hdr");
    WriteImage(hdr, image);
    const std::vector<unsigned char> hdrBytes = ReadBytes(hdr);
    const std::string text(hdrBytes.begin(), hdrBytes.begin() + long(std::min<size_t>(hdrBytes.size(), 200)));
    REQUIRE(text.rfind("#?RADIANCE\n", 0) == 0);
    // The resolution line: rows top to bottom (-Y), 5 of them, 7 columns.
    REQUIRE(text.find("\n-Y 5 +X 7\n") != std::string::npos);

    // Only the two images are left in the folder: no temporary files.
    std::vector<std::string> entries = folder.Entries();
    std::sort(entries.begin(), entries.end());
    REQUIRE(entries == std::vector<std::string>{"image.hdr", "image.png"});
}

TEST_CASE("Writing to an unwritable path throws an Error naming the path and leaves nothing behind", "[film]") {
    const TempFolder folder;
    const Image image = MakeGradient(2, 2);
    // A folder that does not exist, and a "folder" that is a regular file.
    const std::string missingFolder = folder.File("no such folder") + "/image.pfm";
    const std::string notAFolder = folder.File("plain file");
    std::ofstream(notAFolder) << "x";
    const std::string underAFile = notAFolder + "/image.png";
    for (const std::string& path : {missingFolder, underAFile}) {
        INFO(path);
        REQUIRE_THROWS_AS(WriteImage(path, image), Error);
        REQUIRE_THROWS_WITH(WriteImage(path, image), Catch::Contains(path));
        REQUIRE_FALSE(fs::exists(path));
        REQUIRE_FALSE(fs::exists(path + ".partial"));
    }
    std::vector<std::string> entries = folder.Entries();
    REQUIRE(entries == std::vector<std::string>{"plain file"});
}

TEST_CASE("A failed write leaves an existing image untouched", "[film]") {
    const TempFolder folder;
    const std::string path = folder.File("keep.pfm");
    const Image image = MakeGradient(3, 3);
    WriteImage(path, image);
    const std::vector<unsigned char> before = ReadBytes(path);
    REQUIRE_THROWS_WITH(WriteImage(path, Image()), Catch::Contains(path));  // an empty image
    REQUIRE(ReadBytes(path) == before);
    REQUIRE_FALSE(fs::exists(path + ".partial"));
}

TEST_CASE("An unknown image extension throws an Error and writes nothing", "[film]") {
    const TempFolder folder;
    const Image image = MakeGradient(2, 2);
    for (const char* name : {"image.bmp", "image", "image.pfm.txt", "png", "folder.png/image"}) {
        const std::string path = folder.File(name);
        INFO(path);
        REQUIRE_FALSE(IsSupportedImagePath(path));
        REQUIRE_THROWS_AS(WriteImage(path, image), Error);
        REQUIRE_THROWS_WITH(WriteImage(path, image), Catch::Contains(path));
    }
    REQUIRE(folder.Entries().empty());
    for (const char* name : {"a.png", "a.hdr", "a.pfm", "a.exr"}) REQUIRE(IsSupportedImagePath(name));
}

TEST_CASE("ReadPfm rejects missing, foreign and truncated files with an Error naming the file", "[film]") {
    const TempFolder folder;
    const std::string missing = folder.File("missing.pfm");
    REQUIRE_THROWS_WITH(ReadPfm(missing), Catch::Contains(missing));

    const std::string foreign = folder.File("foreign.pfm");
    std::ofstream(foreign, std::ios::binary) << "P6\n2 2\n255\n";
    REQUIRE_THROWS_WITH(ReadPfm(foreign), Catch::Contains(foreign));

    const std::string truncated = folder.File("truncated.pfm");
    WriteImage(truncated, MakeGradient(4, 4));
    std::vector<unsigned char> bytes = ReadBytes(truncated);
    bytes.resize(bytes.size() - 7);
    std::ofstream(truncated, std::ios::binary | std::ios::trunc).write(reinterpret_cast<const char*>(bytes.data()), long(bytes.size()));
    REQUIRE_THROWS_WITH(ReadPfm(truncated), Catch::Contains(truncated));
}

TEST_CASE("Image extensions are known in any case", "[film]") {
    const TempFolder folder;
    const Image image = MakeGradient(3, 2);
    for (const char* name : {"upper.PNG", "mixed.Hdr", "upper.PFM", "upper.EXR"}) {
        INFO(name);
        REQUIRE(IsSupportedImagePath(name));
        WriteImage(folder.File(name), image);
    }
    CHECK(ReadPfm(folder.File("upper.PFM")).mPixels == image.mPixels);
    CHECK(ReadImage(folder.File("upper.EXR")).mPixels == image.mPixels);
    CHECK(ImageFormatOf("a.PNG") == ImageFormat::kPng);
    CHECK(ImageFormatOf("dir.png/a") == ImageFormat::kUnknown);
}

TEST_CASE("A symlink planted at the old temporary name, or at the output, is never written through", "[film]") {
    const TempFolder folder;
    const std::string victim = folder.File("victim");
    std::ofstream(victim) << "keep me";
    const std::string path = folder.File("out.pfm");
    fs::create_symlink(victim, path + ".partial");  // where earlier versions wrote
    const Image image = MakeGradient(4, 4);
    WriteImage(path, image);
    CHECK(ReadText(victim) == "keep me");
    CHECK(ReadPfm(path).mPixels == image.mPixels);
    // The output name itself a symlink: the rename replaces the link, not its target.
    const std::string linked = folder.File("linked.pfm");
    fs::create_symlink(victim, linked);
    WriteImage(linked, image);
    CHECK(ReadText(victim) == "keep me");
    CHECK_FALSE(fs::is_symlink(linked));
    CHECK(ReadPfm(linked).mPixels == image.mPixels);
    std::vector<std::string> entries = folder.Entries();
    std::sort(entries.begin(), entries.end());
    CHECK(entries == std::vector<std::string>{"linked.pfm", "out.pfm", "out.pfm.partial", "victim"});
}

TEST_CASE("Concurrent writers of one path each leave a whole image and no temporary file", "[film]") {
    const TempFolder folder;
    const std::string path = folder.File("shared.pfm");
    const Image first = MakeGradient(16, 16);
    Image second = first;
    for (Vec3& p : second.mPixels) p += Vec3(1.f);
    std::vector<std::thread> writers;
    for (int w = 0; w < 4; w++)
        writers.emplace_back([&, w] {
            for (int i = 0; i < 50; i++) WriteImage(path, w % 2 ? first : second);
        });
    for (std::thread& writer : writers) writer.join();
    const Image written = ReadPfm(path);
    CHECK((written.mPixels == first.mPixels || written.mPixels == second.mPixels));
    CHECK(folder.Entries() == std::vector<std::string>{"shared.pfm"});
}

TEST_CASE("CheckOutputPath finds output problems before rendering and leaves nothing behind", "[film]") {
    const TempFolder folder;
    fs::create_directories(folder.File("a folder.png"));
    std::ofstream(folder.File("plain")) << "x";
    const struct {
        std::string mPath, mProblem;
    } cases[] = {
        {folder.File("a folder.png"), "is a directory"},
        {folder.File("missing/out.png"), "the folder " + folder.File("missing") + " does not exist"},
        {folder.File("plain/out.png"), folder.File("plain") + " is not a folder"},
        {folder.File("out.jpg"), "unknown image format"},
    };
    for (const auto& c : cases) {
        INFO(c.mPath);
        REQUIRE_THROWS_WITH(CheckOutputPath(c.mPath), Catch::StartsWith(c.mPath + ": ") && Catch::Contains(c.mProblem));
    }
    REQUIRE_NOTHROW(CheckOutputPath(folder.File("fine.png")));
    if (geteuid() != 0) {  // root may write anywhere: the permission case needs another user
        const std::string locked = folder.File("locked");
        fs::create_directories(locked);
        fs::permissions(locked, fs::perms::owner_read | fs::perms::owner_exec);
        REQUIRE_THROWS_WITH(CheckOutputPath(locked + "/out.png"), Catch::Contains("cannot write here"));
        fs::permissions(locked, fs::perms::owner_all);
    }
    std::vector<std::string> entries = folder.Entries();
    std::sort(entries.begin(), entries.end());
    const bool onlyWhatWasThere =
        entries == std::vector<std::string>{"a folder.png", "plain"} || entries == std::vector<std::string>{"a folder.png", "locked", "plain"};
    CHECK(onlyWhatWasThere);
}

// -------------------------------------------------------------------------------------
// PNG exposure and tone curves, files written together, the .hdr reader
// -------------------------------------------------------------------------------------

namespace {

// The sRGB encoding, written out again here (IEC 61966-2-1) so the test does not read the
// writer's own function.
double SrgbEncode(double aLinear) {
    return aLinear <= 0.0031308 ? 12.92 * aLinear : 1.055 * std::pow(aLinear, 1.0 / 2.4) - 0.055;
}

// A PNG file decoded by stb_image (compiled privately into this test: STB_IMAGE_STATIC).
std::vector<unsigned char> DecodePng(const std::string& aPath, int aWidth, int aHeight) {
    int width = 0, height = 0, channels = 0;
    unsigned char* pixels = stbi_load(aPath.c_str(), &width, &height, &channels, 3);
    REQUIRE(pixels != nullptr);
    REQUIRE(width == aWidth);
    REQUIRE(height == aHeight);
    std::vector<unsigned char> values(pixels, pixels + size_t(width) * size_t(height) * 3);
    stbi_image_free(pixels);
    return values;
}

} // namespace

TEST_CASE("The ACES fit is Narkowicz's formula: 0 at 0, about 0.8 at 1, increasing, white from about 7.24", "[film]") {
    CHECK(AcesFilmic(0.f) == 0.f);
    CHECK(AcesFilmic(-3.f) == 0.f);
    CHECK(AcesFilmic(1.f) == Approx(2.54 / 3.16).epsilon(1e-6));  // (2.51 + 0.03) / (2.43 + 0.59 + 0.14)
    CHECK(AcesFilmic(0.18f) == Approx(0.18 * (2.51 * 0.18 + 0.03) / (0.18 * (2.43 * 0.18 + 0.59) + 0.14)).epsilon(1e-6));
    CHECK(AcesFilmic(7.2f) < 1.f);
    CHECK(AcesFilmic(7.3f) == 1.f);
    CHECK(AcesFilmic(1e30f) == 1.f);
    float previous = 0.f;
    bool increasing = true;
    for (int i = 1; i <= 7200; i++) {
        const float value = AcesFilmic(float(i) * 1e-3f);
        increasing = increasing && value > previous;
        previous = value;
    }
    CHECK(increasing);
}

TEST_CASE("DisplayValue scales by 2^EV before the tone curve; clamp at EV 0 is the identity on [0, 1]", "[film]") {
    const ImageWriteOptions clamp;
    for (float x : {0.f, 0.25f, 0.5f, 1.f}) CHECK(DisplayValue(x, clamp) == x);
    CHECK(DisplayValue(3.f, clamp) == 1.f);
    CHECK(DisplayValue(-1.f, clamp) == 0.f);
    ImageWriteOptions brighter;
    brighter.mExposure = 2.f;
    CHECK(DisplayValue(0.125f, brighter) == 0.5f);
    brighter.mExposure = -1.f;
    CHECK(DisplayValue(0.5f, brighter) == 0.25f);
    ImageWriteOptions aces;
    aces.mToneMap = ToneMap::kAces;
    aces.mExposure = 1.f;
    CHECK(DisplayValue(0.5f, aces) == AcesFilmic(1.f));
    ToneMap parsed = ToneMap::kClamp;
    CHECK(ParseToneMap("aces", parsed));
    CHECK(parsed == ToneMap::kAces);
    CHECK_FALSE(ParseToneMap("ACES", parsed));
    CHECK_FALSE(ParseToneMap("reinhard", parsed));
    for (float bad : {33.f, -33.f, std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
        ImageWriteOptions options;
        options.mExposure = bad;
        CHECK_THROWS_WITH(ValidateImageWriteOptions(options), Catch::StartsWith("exposure: "));
    }
}

TEST_CASE("A PNG holds sRGB(tone(radiance * 2^EV)) in 8 bits; HDR and PFM ignore exposure and tone curve", "[film]") {
    const TempFolder folder;
    Image image(6, 1);
    const float values[6] = {0.f, 0.01f, 0.2f, 0.7f, 1.5f, 40.f};
    for (int x = 0; x < 6; x++) image.At(x, 0) = Vec3(values[x], values[x] * 0.5f, values[x] * 0.25f);
    for (ToneMap toneMap : {ToneMap::kClamp, ToneMap::kAces})
        for (float exposure : {0.f, 1.5f, -2.f}) {
            ImageWriteOptions options;
            options.mExposure = exposure;
            options.mToneMap = toneMap;
            INFO(ToneMapName(toneMap) << " at EV " << exposure);
            const std::string path = folder.File("tone.png");
            WriteImage(path, image, options);
            const std::vector<unsigned char> decoded = DecodePng(path, 6, 1);
            for (int x = 0; x < 6; x++)
                for (int c = 0; c < 3; c++) {
                    const double exposed = double(image.At(x, 0)[c]) * std::pow(2.0, double(exposure));
                    const double display = toneMap == ToneMap::kAces
                                               ? std::min(exposed * (2.51 * exposed + 0.03) / (exposed * (2.43 * exposed + 0.59) + 0.14), 1.0)
                                               : std::min(std::max(exposed, 0.0), 1.0);
                    INFO("pixel " << x << " channel " << c);
                    CHECK(std::abs(double(decoded[3 * size_t(x) + size_t(c)]) - 255.0 * SrgbEncode(display)) <= 0.5 + 1e-3);
                }
            // The linear formats keep radiance exactly, whatever the PNG options say.
            WriteImage(folder.File("tone.pfm"), image, options);
            CHECK(ReadPfm(folder.File("tone.pfm")).mPixels == image.mPixels);
            CHECK(EncodeImage("x.hdr", image, options) == EncodeImage("x.hdr", image));
        }
    ImageWriteOptions bad;
    bad.mExposure = 100.f;
    CHECK_THROWS_WITH(WriteImage(folder.File("bad.png"), image, bad), Catch::StartsWith("exposure: "));
    CHECK_FALSE(fs::exists(folder.File("bad.png")));
}

TEST_CASE("WriteFilesTogether leaves all files or none, and no temporary file", "[film]") {
    const TempFolder folder;
    const std::vector<unsigned char> first{'1'}, second{'2', '2'};
    WriteFilesTogether({{folder.File("a.txt"), first}, {folder.File("b.txt"), second}});
    CHECK(ReadText(folder.File("a.txt")) == "1");
    CHECK(ReadText(folder.File("b.txt")) == "22");
    SECTION("the second file's name is taken by a directory: the rename fails, the first file goes too") {
        fs::create_directories(folder.File("taken"));
        fs::create_directories(folder.File("taken/inside"));  // a non-empty directory: rename(2) cannot replace it
        REQUIRE_THROWS_WITH(WriteFilesTogether({{folder.File("new.txt"), first}, {folder.File("taken"), second}}),
                            Catch::StartsWith(folder.File("taken") + ": cannot put the file in place"));
        std::vector<std::string> entries = folder.Entries();
        std::sort(entries.begin(), entries.end());
        CHECK(entries == std::vector<std::string>{"a.txt", "b.txt", "taken"});
    }
    SECTION("the second file's folder does not exist: nothing is created") {
        REQUIRE_THROWS_WITH(WriteFilesTogether({{folder.File("new.txt"), first}, {folder.File("missing/b.txt"), second}}),
                            Catch::StartsWith(folder.File("missing/b.txt") + ": cannot create a file next to it"));
        std::vector<std::string> entries = folder.Entries();
        std::sort(entries.begin(), entries.end());
        CHECK(entries == std::vector<std::string>{"a.txt", "b.txt"});
    }
}

TEST_CASE("ReadHdr reads back what WriteImage wrote, flat and run-length encoded, to RGBE precision", "[film]") {
    const TempFolder folder;
    // Width 5 is written flat, 300 with run-length encoded scanlines (stb_image_write's
    // choice: 8 <= width < 32768); runs appear where neighbours share a byte.
    for (int width : {5, 300}) {
        Image image(width, 7);
        for (int y = 0; y < 7; y++)
            for (int x = 0; x < width; x++)
                image.At(x, y) = x < width / 2 ? Vec3(0.25f, 0.5f, 1.f) : Vec3(float(x) * 0.37f + 0.01f, float(y) * 3.1f, 1e-3f * float(x + y));
        image.At(0, 0) = Vec3(0.f);
        const std::string path = folder.File("round.HDR");
        WriteImage(path, image);
        const Image read = ReadImage(path);
        REQUIRE(read.mWidth == width);
        REQUIRE(read.mHeight == 7);
        // RGBE keeps 8 bits of mantissa shared by the pixel's channels: the writer truncates,
        // the reader takes the middle of the interval, so each channel is within half a step,
        // 2^-8 of the pixel's largest channel.
        double worst = 0.0;
        for (size_t i = 0; i < image.mPixels.size(); i++) {
            const Vec3& p = image.mPixels[i];
            const double largest = std::max({p.x, p.y, p.z});
            for (int c = 0; c < 3; c++)
                worst = std::max(worst, largest == 0.0 ? double(read.mPixels[i][c]) : std::abs(double(read.mPixels[i][c]) - p[c]) / largest);
        }
        INFO("width " << width << ": worst error " << worst << " of the largest channel");
        CHECK(worst <= 1.0 / 256.0);
        CHECK(read.At(0, 0) == Vec3(0.f));
    }
}

TEST_CASE("ReadHdr and ReadImage refuse foreign, truncated and corrupt files, and PNGs, naming the file", "[film]") {
    const TempFolder folder;
    const Image image = MakeGradient(40, 3);
    const std::string good = folder.File("good.hdr");
    WriteImage(good, image);
    const std::vector<unsigned char> bytes = ReadBytes(good);
    auto writeVariant = [&](const std::string& aName, std::vector<unsigned char> aBytes) {
        const std::string path = folder.File(aName);
        std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(aBytes.data()), long(aBytes.size()));
        return path;
    };
    std::vector<unsigned char> truncated = bytes;
    truncated.resize(bytes.size() - 10);
    std::vector<unsigned char> corrupt = bytes;
    const std::string text(bytes.begin(), bytes.end());
    const size_t firstScanline = text.find("+X 40\n") + 6;
    corrupt[firstScanline + 4] = 200;  // a run of 72 in a scanline of 40
    std::string xyze = text;
    xyze.replace(xyze.find("FORMAT=32-bit_rle_rgbe"), 22, "FORMAT=32-bit_rle_xyze");
    std::string flipped = text;
    flipped.replace(flipped.find("-Y 3 +X 40"), 10, "+Y 3 +X 40");
    std::string huge = text;
    huge.replace(huge.find("-Y 3 +X 40"), 10, "-Y 60000 +X 60000");
    const struct {
        std::string mPath, mProblem;
    } cases[] = {
        {folder.File("missing.hdr"), "cannot open"},
        {writeVariant("foreign.hdr", {'P', '6', '\n'}), "not a Radiance RGBE .hdr file"},
        {writeVariant("truncated.hdr", truncated), "truncated"},
        {writeVariant("corrupt.hdr", corrupt), "truncated or corrupt"},
        {writeVariant("xyze.hdr", {xyze.begin(), xyze.end()}), "FORMAT=32-bit_rle_xyze is not supported"},
        {writeVariant("flipped.hdr", {flipped.begin(), flipped.end()}), "only the resolution line"},
        {writeVariant("huge.hdr", {huge.begin(), huge.end()}), "truncated"},
        {folder.File("folder.hdr"), "not a regular file"},
    };
    fs::create_directories(folder.File("folder.hdr"));
    for (const auto& c : cases) {
        INFO(c.mPath);
        REQUIRE_THROWS_WITH(ReadHdr(c.mPath), Catch::StartsWith(c.mPath + ": ") && Catch::Contains(c.mProblem));
    }
    REQUIRE_THROWS_WITH(ReadImage(folder.File("x.png")), Catch::StartsWith(folder.File("x.png") + ": a PNG holds"));
    CHECK(ReadImage(good).mWidth == 40);
    // A PFM header that claims far more pixels than the file holds is refused before allocating.
    const std::string claims = writeVariant("claims.pfm", {'P', 'F', '\n', '6', '0', '0', '0', '0', ' ', '6', '0', '0', '0', '0', '\n', '-', '1', '\n', 0, 0});
    REQUIRE_THROWS_WITH(ReadPfm(claims), Catch::Contains("truncated"));
}

// -------------------------------------------------------------------------------------
// OpenEXR
// -------------------------------------------------------------------------------------

namespace {

void WriteBytes(const std::string& aPath, const std::vector<unsigned char>& aBytes) {
    std::ofstream(aPath, std::ios::binary | std::ios::trunc).write(reinterpret_cast<const char*>(aBytes.data()), long(aBytes.size()));
}

// An OpenEXR file as another program might write it, made with tinyexr directly: the
// channels in the order given (tinyexr keeps it), each of pixel type aTypes[c]
// (TINYEXR_PIXELTYPE_HALF or _FLOAT), channel c of pixel i being aValue(c, i).
std::vector<unsigned char> ForeignExr(int aWidth, int aHeight, const std::vector<std::string>& aNames, const std::vector<int>& aTypes,
                                      const std::function<float(size_t, size_t)>& aValue) {
    const size_t count = size_t(aWidth) * size_t(aHeight);
    std::vector<std::vector<float>> planes(aNames.size(), std::vector<float>(count));
    std::vector<unsigned char*> pointers;
    std::vector<EXRChannelInfo> channels(aNames.size());
    std::vector<int> floats(aNames.size(), TINYEXR_PIXELTYPE_FLOAT);
    for (size_t c = 0; c < aNames.size(); c++) {
        for (size_t i = 0; i < count; i++) planes[c][i] = aValue(c, i);
        pointers.push_back(reinterpret_cast<unsigned char*>(planes[c].data()));
        std::memset(&channels[c], 0, sizeof(EXRChannelInfo));
        std::strncpy(channels[c].name, aNames[c].c_str(), 255);
    }
    std::vector<int> stored = aTypes;
    EXRHeader header;
    InitEXRHeader(&header);
    header.num_channels = int(aNames.size());
    header.channels = channels.data();
    header.pixel_types = floats.data();
    header.requested_pixel_types = stored.data();
    header.compression_type = TINYEXR_COMPRESSIONTYPE_PIZ;
    EXRImage image;
    InitEXRImage(&image);
    image.images = pointers.data();
    image.width = aWidth;
    image.height = aHeight;
    image.num_channels = int(aNames.size());
    unsigned char* memory = nullptr;
    const char* message = nullptr;
    const size_t size = SaveEXRImageToMemory(&image, &header, &memory, &message);
    INFO((message ? message : ""));
    REQUIRE(size > 0);
    std::vector<unsigned char> bytes(memory, memory + size);
    std::free(memory);
    return bytes;
}

// The channel names in an OpenEXR file's header, in the file's order, read by tinyexr.
std::vector<std::string> ExrChannelNames(const std::vector<unsigned char>& aBytes) {
    EXRVersion version;
    REQUIRE(ParseEXRVersionFromMemory(&version, aBytes.data(), aBytes.size()) == TINYEXR_SUCCESS);
    EXRHeader header;
    InitEXRHeader(&header);
    const char* message = nullptr;
    REQUIRE(ParseEXRHeaderFromMemory(&header, &version, aBytes.data(), aBytes.size(), &message) == TINYEXR_SUCCESS);
    std::vector<std::string> names;
    for (int c = 0; c < header.num_channels; c++) {
        names.push_back(header.channels[c].name);
        CHECK(header.pixel_types[c] == TINYEXR_PIXELTYPE_FLOAT);
    }
    FreeEXRHeader(&header);
    return names;
}

// Where the value of the header attribute aName starts in an OpenEXR file (after its name,
// type and size), for tests that change one.
size_t AttributeValue(const std::vector<unsigned char>& aBytes, const std::string& aName, const std::string& aType) {
    std::string pattern = aName;
    pattern += '\0';
    pattern += aType;
    pattern += '\0';
    const auto at = std::search(aBytes.begin(), aBytes.end(), pattern.begin(), pattern.end());
    REQUIRE(at != aBytes.end());
    return size_t(at - aBytes.begin()) + pattern.size() + 4;
}

void PutInt(std::vector<unsigned char>& aBytes, size_t aOffset, int32_t aValue) { std::memcpy(&aBytes[aOffset], &aValue, 4); }

// ReadExr refuses aPath with one line starting with the path and containing aProblem.
void CheckRefused(const std::string& aPath, const std::string& aProblem) {
    INFO(aPath << ": expecting '" << aProblem << "'");
    try {
        ReadExr(aPath);
        FAIL("read without an error");
    } catch (const Error& e) {
        const std::string message = e.what();
        INFO(message);
        CHECK(message.rfind(aPath + ": ", 0) == 0);
        CHECK(message.find('\n') == std::string::npos);
        CHECK(message.find(aProblem) != std::string::npos);
    }
}

} // namespace

TEST_CASE("An EXR written and read back is bit-for-bit the same image, as the PFM is", "[film]") {
    const TempFolder folder;
    Image image = MakeGradient(37, 21);  // 21 rows: two ZIP blocks of 16, the second partial
    image.At(0, 0) = Vec3(-0.f, 1e-40f, 3.4e38f);  // signed zero, denormal, near max
    image.At(1, 0) = Vec3(std::numeric_limits<float>::infinity(), -1.5f, std::numeric_limits<float>::quiet_NaN());
    image.At(36, 20) = Vec3(1.f / 3.f, -1e-30f, 16777217.f);
    const std::string path = folder.File("round trip.exr");
    WriteImage(path, image);
    const std::vector<unsigned char> bytes = ReadBytes(path);
    REQUIRE(bytes.size() > 4);
    const unsigned char magic[4] = {0x76, 0x2f, 0x31, 0x01};  // OpenEXR's magic number
    CHECK(std::memcmp(bytes.data(), magic, 4) == 0);
    CHECK(ExrChannelNames(bytes) == std::vector<std::string>{"B", "G", "R"});  // sorted, as OpenEXR stores them
    for (const Image& back : {ReadExr(path), ReadImage(path)}) RequireSameBits(back, image);
    // The PNG options do not touch it; encoding is deterministic; nothing else is left.
    ImageWriteOptions options;
    options.mExposure = 3.f;
    options.mToneMap = ToneMap::kAces;
    CHECK(EncodeImage(path, image, options) == bytes);
    CHECK(folder.Entries() == std::vector<std::string>{"round trip.exr"});
}

TEST_CASE("EXR layers are channels NAME.R, NAME.G, NAME.B beside R, G, B, and read back by name", "[film]") {
    const TempFolder folder;
    const Image image = MakeGradient(9, 5);
    Image direct = MakeGradient(9, 5), indirect = MakeGradient(9, 5);
    for (Vec3& p : direct.mPixels) p *= 0.5f;
    for (Vec3& p : indirect.mPixels) p = Vec3(p.z, -p.x, 1e-3f * p.y);
    const std::string path = folder.File("layers.exr");
    WriteFilesTogether({{path, EncodeExr(path, image, {{"indirect_nonspecular", &indirect}, {"direct_nonspecular", &direct}})}});
    CHECK(ExrChannelNames(ReadBytes(path)) ==
          std::vector<std::string>{"B", "G", "R", "direct_nonspecular.B", "direct_nonspecular.G", "direct_nonspecular.R",
                                   "indirect_nonspecular.B", "indirect_nonspecular.G", "indirect_nonspecular.R"});
    CHECK(ReadExr(path).mPixels == image.mPixels);
    CHECK(ReadImage(path).mPixels == image.mPixels);  // merge and metrics read the image, not a layer
    CHECK(ReadExr(path, "direct_nonspecular").mPixels == direct.mPixels);
    CHECK(ReadExr(path, "indirect_nonspecular").mPixels == indirect.mPixels);
    REQUIRE_THROWS_WITH(ReadExr(path, "emitted"),
                        Catch::StartsWith(path + ": has no channels emitted.R, emitted.G, emitted.B (its channels: B, G, R, direct"));
    // A long layer name sets the file's long-names flag (names over 31 bytes) and reads back.
    const std::string longName(120, 'x');
    const std::string longPath = folder.File("long.exr");
    WriteFilesTogether({{longPath, EncodeExr(longPath, image, {{longName, &direct}})}});
    CHECK(ReadExr(longPath, longName).mPixels == direct.mPixels);
    // Names that cannot be channel prefixes, twice the same name, a layer of another size.
    const Image small = MakeGradient(3, 3);
    const struct {
        std::vector<ExrLayer> mLayers;
        std::string mProblem;
    } bad[] = {
        {{{"", &direct}}, "is not 1 to 250 printable bytes"},
        {{{std::string(251, 'y'), &direct}}, "is not 1 to 250 printable bytes"},
        {{{"tab\there", &direct}}, "is not 1 to 250 printable bytes"},
        {{{"same", &direct}, {"same", &indirect}}, "two layers are named 'same'"},
        {{{"small", &small}}, "the layer 'small' is not the image's size"},
    };
    for (const auto& b : bad) {
        INFO(b.mProblem);
        REQUIRE_THROWS_WITH(EncodeExr(path, image, b.mLayers), Catch::StartsWith(path + ": ") && Catch::Contains(b.mProblem));
    }
}

TEST_CASE("ReadExr reads other writers' files: half floats exactly, RGBA without A, channels in any order; "
          "a luminance-only file is refused", "[film]") {
    const TempFolder folder;
    const int width = 6, height = 40;  // PIZ blocks of 32 rows: two, the second partial
    // Values that half floats hold exactly (multiples of 1/64 below 32), different per channel.
    auto value = [](size_t aChannel, size_t aPixel) { return float(aPixel % 97) / 64.f + float(aChannel); };
    const std::string half = folder.File("half rgba.exr");
    WriteBytes(half, ForeignExr(width, height, {"A", "R", "G", "B"},
                                {TINYEXR_PIXELTYPE_HALF, TINYEXR_PIXELTYPE_HALF, TINYEXR_PIXELTYPE_HALF, TINYEXR_PIXELTYPE_HALF}, value));
    const Image read = ReadExr(half);
    REQUIRE(read.mWidth == width);
    REQUIRE(read.mHeight == height);
    for (size_t i = 0; i < read.mPixels.size(); i++)
        for (int c = 0; c < 3; c++) {
            INFO("pixel " << i << " channel " << c);
            REQUIRE(read.mPixels[i][c] == value(size_t(c) + 1, i));  // R, G, B are channels 1, 2, 3 here
        }
    const std::string mixed = folder.File("mixed.exr");
    WriteBytes(mixed, ForeignExr(width, height, {"B", "G", "R"}, {TINYEXR_PIXELTYPE_FLOAT, TINYEXR_PIXELTYPE_HALF, TINYEXR_PIXELTYPE_FLOAT}, value));
    const Image mixedRead = ReadExr(mixed);
    CHECK(mixedRead.At(5, 39) == Vec3(value(2, 239), value(1, 239), value(0, 239)));
    const std::string luminance = folder.File("luminance.exr");
    WriteBytes(luminance, ForeignExr(width, height, {"Y"}, {TINYEXR_PIXELTYPE_HALF}, value));
    CheckRefused(luminance, "has no channels R, G, B (its channels: Y); only RGB radiance is read, a luminance-only (Y) image is not converted");
}

TEST_CASE("Bad EXR files are each refused with one line naming the file: truncated, foreign, random, "
          "huge or unsupported", "[film]") {
    const TempFolder folder;
    const std::string goodPath = folder.File("good.exr");
    WriteImage(goodPath, MakeGradient(24, 40));
    const std::vector<unsigned char> good = ReadBytes(goodPath);
    int count = 0;
    auto variant = [&](const std::vector<unsigned char>& aBytes) {
        const std::string path = folder.File("bad" + std::to_string(count++) + ".exr");
        WriteBytes(path, aBytes);
        return path;
    };
    // Truncated: inside the magic number, the version field, the header, the offset table
    // and the pixel data, and one byte short.
    const size_t headerEnd = AttributeValue(good, "screenWindowWidth", "float") + 4 + 1;
    for (size_t length : {size_t(0), size_t(3), size_t(6), size_t(8), size_t(40), headerEnd - 1, headerEnd + 5, headerEnd + 8 * 3 + 2,
                          good.size() / 2, good.size() - 1}) {
        INFO("truncated to " << length << " of " << good.size() << " bytes");
        const std::string path = variant(std::vector<unsigned char>(good.begin(), good.begin() + long(length)));
        CheckRefused(path, length < 4           ? "not an OpenEXR file"
                           : length < 8         ? "the OpenEXR version field is truncated"
                           : length < headerEnd ? "header is truncated or invalid"
                                                : "pixel data is truncated or corrupt");
    }
    CheckRefused(variant({'P', 'F', '\n', '1', ' ', '1', '\n', '-', '1', '\n', 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0}), "not an OpenEXR file");
    // Random bytes after the magic number and a version field of 2.
    std::mt19937 random(34);
    for (size_t length : {size_t(8), size_t(64), size_t(1000), size_t(5000)}) {
        std::vector<unsigned char> bytes = {0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0};
        while (bytes.size() < length) bytes.push_back((unsigned char)(random() & 0xff));
        CheckRefused(variant(bytes), "header is truncated or invalid");
    }
    // A header claiming 2^20 x 2^20 pixels, one claiming 65536 x 65536 (allowed sizes, but
    // 48 GiB to decode) and one whose display window is larger than its data.
    const size_t dataWindow = AttributeValue(good, "dataWindow", "box2i"), displayWindow = AttributeValue(good, "displayWindow", "box2i");
    std::vector<unsigned char> huge = good;
    PutInt(huge, dataWindow + 8, (1 << 20) - 1);
    PutInt(huge, dataWindow + 12, (1 << 20) - 1);
    CheckRefused(variant(huge), "claims 1048576x1048576 pixels: only sizes in [1, 65536] are read");
    std::vector<unsigned char> large = good;
    for (size_t window : {dataWindow, displayWindow}) {
        PutInt(large, window + 8, 65535);
        PutInt(large, window + 12, 65535);
    }
    CheckRefused(variant(large), "would take more than 4 GiB to decode");
    std::vector<unsigned char> negative = good;
    PutInt(negative, dataWindow + 8, -5);
    CheckRefused(variant(negative), "pixels: only sizes in [1, 65536] are read");
    std::vector<unsigned char> cropped = good;
    PutInt(cropped, displayWindow + 8, 99);
    CheckRefused(variant(cropped), "its data window differs from its display window");
    // The version field's flags: tiled, deep, multi-part.
    for (const auto& [flag, problem] : {std::pair<unsigned char, const char*>{0x02, "a tiled OpenEXR file"}, {0x08, "a deep OpenEXR file"},
                                        {0x10, "a multi-part OpenEXR file"}}) {
        std::vector<unsigned char> flagged = good;
        flagged[5] |= flag;
        CheckRefused(variant(flagged), problem);
    }
    // A type attribute (multi-part and deep files have one) other than a scanline image's:
    // tinyexr would stop the program on an unknown one.
    for (const std::string& type : {std::string("deepscanline"), std::string("tiledimage"), std::string("bogus\x01")}) {
        std::vector<unsigned char> typed = good;
        std::string attribute = std::string("type") + '\0' + "string" + '\0' + "    " + type;
        const int32_t size = int32_t(type.size());
        std::memcpy(&attribute[12], &size, 4);
        typed.insert(typed.begin() + long(headerEnd - 1), attribute.begin(), attribute.end());
        CheckRefused(variant(typed), "its type attribute is '" + type.substr(0, 5) + (type == "bogus\x01" ? "?" : type.substr(5)) +
                                         "': only scanline images are read");
    }
    // A compression tinyexr does not decode (PXR24, OpenEXR's number 5).
    std::vector<unsigned char> pxr24 = good;
    pxr24[AttributeValue(good, "compression", "compression")] = 5;
    CheckRefused(variant(pxr24), "uses what tinyexr does not read; the compressions read are none, RLE, ZIPS, ZIP and PIZ");
    // A channel's pixel type that tinyexr cannot decode (it would not check it itself).
    std::vector<unsigned char> unknownType = good;
    const size_t channels = AttributeValue(good, "channels", "chlist");
    PutInt(unknownType, channels + 2, 7);  // the first entry is "B\0", then its pixel type
    CheckRefused(variant(unknownType), "its channel 'B' has an unknown pixel type");
    std::vector<unsigned char> integers = good;
    PutInt(integers, channels + 2, TINYEXR_PIXELTYPE_UINT);
    CheckRefused(variant(integers), "its channel 'B' holds integers, not radiance");
    // Bytes flipped at random in the header, the offsets and the pixels: read or refused in
    // one line, never a crash (the sanitizer build, make check, runs this too).
    for (int trial = 0; trial < 300; trial++) {
        std::vector<unsigned char> bytes = good;
        const int flips = 1 + int(random() % 4);
        for (int f = 0; f < flips; f++) bytes[8 + random() % (bytes.size() - 8)] ^= (unsigned char)(1u << (random() % 8));
        const std::string path = folder.File("flipped.exr");
        WriteBytes(path, bytes);
        try {
            const Image image = ReadExr(path);
            CHECK(image.mWidth * image.mHeight >= 1);
        } catch (const Error& e) {
            const std::string message = e.what();
            INFO("trial " << trial << ": " << message);
            CHECK(message.rfind(path + ": ", 0) == 0);
            CHECK(message.find('\n') == std::string::npos);
        }
    }
}
