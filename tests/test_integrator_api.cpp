// [integrator_api] The integrator registry and Render()'s contract with an integrator
// (see [SECTION] Integrator interface): the built-ins are registered under their short
// names and Render(scene, options) is Render(scene, options, that built-in) bit for bit;
// registration refuses bad names; a user's integrator gets one renderer per thread, every
// iteration exactly once with its own random stream, layers, cancellation, a time budget,
// errors turned into Error, and a memory estimate. Deterministic and fast (make unit).
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <atomic>
#include <chrono>
#include <mutex>
#include <set>
#include <stdexcept>
#include <thread>

using namespace testutil;

namespace {

bool SameImage(const Image& aA, const Image& aB) {
    if (aA.mWidth != aB.mWidth || aA.mHeight != aB.mHeight) return false;
    for (size_t i = 0; i < aA.mPixels.size(); i++)
        if (aA.mPixels[i] != aB.mPixels[i]) return false;
    return true;
}

// What the recording integrator saw, shared by its per-thread renderers.
struct Record {
    std::mutex mMutex;
    int mRenderers = 0;
    std::multiset<int> mIterations;
    std::set<float> mFirstRandomNumbers;  // the first number of each iteration's stream
    void Clear() {
        mRenderers = 0;
        mIterations.clear();
        mFirstRandomNumbers.clear();
    }
};
Record gRecord;

// Writes 1 into every pixel and the iteration's index into a layer "index", and records
// which iterations it ran and the first random number of each.
class RecordingRenderer : public AbstractRenderer {
public:
    RecordingRenderer(const Scene& aScene, const RenderOptions& aOptions) : AbstractRenderer(aScene, aOptions) {
        mIndexLayer = mFilm.AddLayer("index");
        std::lock_guard<std::mutex> lock(gRecord.mMutex);
        gRecord.mRenderers++;
    }
    void RunIteration(int aIteration, Sampler& aSampler) override {
        const float first = aSampler.Get1D();
        for (int pixel = 0; pixel < mScene.mCamera.PixelCount(); pixel++) {
            mFilm.AddColor(pixel, Vec3(1.f));
            mFilm.AddToLayer(mIndexLayer, pixel, Vec3(float(aIteration)));
        }
        std::lock_guard<std::mutex> lock(gRecord.mMutex);
        gRecord.mIterations.insert(aIteration);
        gRecord.mFirstRandomNumbers.insert(first);
    }

private:
    int mIndexLayer = -1;
};

// Sleeps a little per iteration, so that a time budget ends a run of it.
class SlowRenderer : public AbstractRenderer {
public:
    using AbstractRenderer::AbstractRenderer;
    void RunIteration(int, Sampler&) override { std::this_thread::sleep_for(std::chrono::milliseconds(5)); }
};

class ThrowingRenderer : public AbstractRenderer {
public:
    using AbstractRenderer::AbstractRenderer;
    void RunIteration(int aIteration, Sampler&) override {
        if (aIteration == 3) throw std::runtime_error("my integrator: iteration 3 failed");
    }
};

// A renderer that replaces its film by one of the wrong size.
class WrongFilmRenderer : public AbstractRenderer {
public:
    WrongFilmRenderer(const Scene& aScene, const RenderOptions& aOptions) : AbstractRenderer(aScene, aOptions) {
        mFilm = Film(3, 3);
    }
    void RunIteration(int, Sampler&) override {}
};

Scene SmallCornell() { return LoadCornell(4, 12, 8); }

} // namespace

TEST_CASE("The built-in estimators are registered under their short names, in teaching order", "[integrator_api]") {
    const std::vector<std::string> expected = {"el", "pt", "lt", "pm", "pmfg", "ppm", "bpm", "bpt", "vcm", "pb2d", "bb1d"};
    const std::vector<const Integrator*> all = RegisteredIntegrators();
    REQUIRE(all.size() >= expected.size());
    for (size_t i = 0; i < expected.size(); i++) {
        CHECK(all[i]->mName == expected[i]);
        CHECK_FALSE(all[i]->mDescription.empty());
        const std::optional<Algorithm> algorithm = ParseAlgorithm(expected[i]);
        REQUIRE(algorithm);
        CHECK(&BuiltInIntegrator(*algorithm) == all[i]);
        CHECK(FindIntegrator(expected[i]) == all[i]);
    }
    CHECK(FindIntegrator("no-such-integrator") == nullptr);
}

TEST_CASE("Render with a built-in's Integrator is Render with its Algorithm, bit for bit, whatever mAlgorithm says",
          "[integrator_api]") {
    const Scene scene = LoadCornell(1, 16, 12);
    for (const char* name : {"pt", "bpt", "vcm", "pm"}) {
        INFO(name);
        RenderOptions options;
        options.mIterations = 3;
        options.mThreads = 2;
        options.mProgress = false;
        options.mPhotonCount = 2000;
        const std::optional<Algorithm> algorithm = ParseAlgorithm(name);
        REQUIRE(algorithm);
        options.mAlgorithm = *algorithm;
        const RenderResult byAlgorithm = Render(scene, options);
        options.mAlgorithm = Algorithm::kEyeLight;  // ignored: the Integrator decides
        const RenderResult byIntegrator = Render(scene, options, *FindIntegrator(name));
        CHECK(SameImage(byAlgorithm.mImage, byIntegrator.mImage));
        CHECK(MeanValue(byAlgorithm.mImage) > 0.0);
    }
}

TEST_CASE("RegisterIntegrator refuses bad names, taken names and a missing factory, with one line", "[integrator_api]") {
    Integrator good = MakeIntegrator<SlowRenderer>("api-test_slow1", "a test integrator");
    const Integrator& registered = RegisterIntegrator(good);
    CHECK(&registered == FindIntegrator("api-test_slow1"));
    CHECK(RegisteredIntegrators().back() == &registered);
    CHECK_THROWS_WITH(RegisterIntegrator(good), "integrator 'api-test_slow1': the name is already registered");
    CHECK_THROWS_WITH(RegisterIntegrator(MakeIntegrator<SlowRenderer>("pt", "")), "integrator 'pt': the name is already registered");
    CHECK_THROWS_WITH(RegisterIntegrator(MakeIntegrator<SlowRenderer>("", "")), "integrator '': a name must be letters, digits, '_' and '-'");
    CHECK_THROWS_WITH(RegisterIntegrator(MakeIntegrator<SlowRenderer>("my pt", "")),
                      "integrator 'my pt': a name must be letters, digits, '_' and '-'");
    CHECK_THROWS_WITH(RegisterIntegrator(Integrator{"nofactory", "", nullptr, nullptr, false}), "integrator 'nofactory': has no mCreateRenderer");
    // A lookup stays valid while more integrators are registered.
    for (int i = 0; i < 100; i++) RegisterIntegrator(MakeIntegrator<SlowRenderer>("api-test_many" + std::to_string(i), ""));
    CHECK(registered.mName == "api-test_slow1");
}

TEST_CASE("A user's integrator gets one renderer per thread, each iteration once with its own stream, and its layers",
          "[integrator_api]") {
    const Scene scene = SmallCornell();
    const Integrator recording = MakeIntegrator<RecordingRenderer>("recording", "");
    RenderOptions options;
    options.mIterations = 10;
    options.mThreads = 3;
    options.mProgress = false;
    gRecord.Clear();
    const RenderResult result = Render(scene, options, recording);
    CHECK(gRecord.mRenderers == 3);
    CHECK(gRecord.mIterations == std::multiset<int>{0, 1, 2, 3, 4, 5, 6, 7, 8, 9});
    CHECK(gRecord.mFirstRandomNumbers.size() == 10);  // ten different streams
    CHECK(result.mIterations == 10);
    CHECK_FALSE(result.mStopped);
    // The films are summed and divided by the iteration count: 1 per pixel, and the mean
    // of the indices 0..9 in the layer.
    REQUIRE(result.mLayers.size() == 1);
    CHECK(result.mLayers[0].first == "index");
    CHECK(result.mImage.At(5, 3) == Vec3(1.f));
    CHECK(result.mLayers[0].second.At(11, 7) == Vec3(4.5f));

    SECTION("the streams are those of the iteration indices, whichever thread runs them") {
        std::set<float> expected;
        for (int i = 0; i < 10; i++) expected.insert(IterationRng(options.mSeed, i).GetFloat());
        CHECK(gRecord.mFirstRandomNumbers == expected);
    }
    SECTION("no more renderers than iterations") {
        options.mIterations = 2;
        options.mThreads = 4;
        gRecord.Clear();
        Render(scene, options, recording);
        CHECK(gRecord.mRenderers == 2);
    }
}

TEST_CASE("A user's integrator stops on request and at the end of its time budget", "[integrator_api]") {
    const Scene scene = SmallCornell();
    const Integrator slow = MakeIntegrator<SlowRenderer>("slow", "");
    RenderOptions options;
    options.mProgress = false;
    options.mThreads = 2;
    SECTION("a stop requested before the start runs no iteration") {
        std::atomic<bool> stop{true};
        options.mIterations = 1000;
        options.mStopRequested = &stop;
        const RenderResult result = Render(scene, options, slow);
        CHECK(result.mStopped);
        CHECK(result.mIterations == 0);
    }
    SECTION("a time budget of 0.1 s ends a run of 5 ms iterations") {
        options.mIterations = 0;
        options.mSeconds = 0.1;
        const RenderResult result = Render(scene, options, slow);
        CHECK(result.mIterations > 0);
        CHECK(result.mIterations < 1000);
        CHECK_FALSE(result.mStopped);
    }
}

TEST_CASE("A user's integrator's failures become one Error naming it", "[integrator_api]") {
    const Scene scene = SmallCornell();
    RenderOptions options;
    options.mIterations = 8;
    options.mThreads = 2;
    options.mProgress = false;
    CHECK_THROWS_WITH(Render(scene, options, MakeIntegrator<ThrowingRenderer>("throwing", "")), "my integrator: iteration 3 failed");
    CHECK_THROWS_WITH(Render(scene, options, MakeIntegrator<WrongFilmRenderer>("wrongfilm", "")),
                      "integrator 'wrongfilm': a renderer's film is 3x3, not the camera's 12x8");
    CHECK_THROWS_WITH(Render(scene, options, Integrator{"nofactory", "", nullptr, nullptr, false}), "integrator 'nofactory': has no mCreateRenderer");
    const Integrator none{"none", "", [](const Scene&, const RenderOptions&) { return std::unique_ptr<AbstractRenderer>(); }, nullptr};
    CHECK_THROWS_WITH(Render(scene, options, none), "integrator 'none': mCreateRenderer returned no renderer");
}

TEST_CASE("The memory estimate counts the film for every integrator, and what mBytesPerRenderer adds", "[integrator_api]") {
    Camera camera;
    camera.SetResolution(100, 50);
    RenderOptions options;
    const uint64_t film = 100 * 50 * sizeof(glm::dvec3), image = 100 * 50 * sizeof(Vec3);
    Integrator mine = MakeIntegrator<SlowRenderer>("estimate", "");
    CHECK(EstimateRenderBytes(camera, options, mine, 3) == 3 * film + image);
    mine.mBytesPerRenderer = [](const Camera& aCamera, const RenderOptions&) { return uint64_t(aCamera.PixelCount()) * 10; };
    CHECK(EstimateRenderBytes(camera, options, mine, 3) == 3 * (film + 5000 * 10) + image);
    // The built-ins: the path tracer needs only its film; VCM and photon mapping more.
    options.mAlgorithm = Algorithm::kPathTracing;
    CHECK(EstimateRenderBytes(camera, options, 3) == 3 * film + image);
    options.mAlgorithm = Algorithm::kVertexConnectionMerging;
    CHECK(EstimateRenderBytes(camera, options, 3) > 3 * film + image);
    CHECK(EstimateRenderBytes(camera, options, 3) == EstimateRenderBytes(camera, options, *FindIntegrator("vcm"), 3));
    options.mAlgorithm = Algorithm::kPhotonMapping;
    CHECK(EstimateRenderBytes(camera, options, 3) > 3 * film + image);
}
