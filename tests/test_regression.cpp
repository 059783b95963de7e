// [regression] The renderer's output is pinned bit for bit by golden images (made by
// tests/data/golden/make_golden.sh; its header says when and why they were last made):
// restructuring for speed must not change a single result. A change of what is sampled
// regenerates them on purpose, in its own commit.
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <cstring>

using namespace smallvcm;
using namespace testutil;

TEST_CASE("Every algorithm renders exactly its golden image on a fixed seed", "[regression]") {
    for (int sceneIndex : {0, 3, 4}) {
        const Scene scene = LoadCornell(sceneIndex, 16, 16);
        for (const char* name : {"el", "pt", "lt", "ppm", "bpm", "bpt", "vcm", "pm", "pmfg"}) {
            RenderOptions options;
            const std::optional<Algorithm> algorithm = ParseAlgorithm(name);
            REQUIRE(algorithm);
            options.mAlgorithm = *algorithm;
            options.mIterations = 2;
            options.mThreads = 1;
            options.mSeed = 5;
            options.mPhotonCount = 2000;
            options.mProgress = false;
            const Image image = Render(scene, options).mImage;
            const Image golden = ReadPfm("data/golden/" + std::string(name) + "_s" + std::to_string(sceneIndex) + ".pfm");
            int differing = 0;
            for (size_t i = 0; i < image.mPixels.size(); i++)
                differing += std::memcmp(&image.mPixels[i], &golden.mPixels[i], sizeof(Vec3)) != 0;
            INFO(name << " on scene " << sceneIndex << ": " << differing << " of 256 pixels differ from the golden image");
            CHECK(differing == 0);
        }
    }
}
