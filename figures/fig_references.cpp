// fig_references — renders every reference image the figure programs use, ahead of them
// (each figure program would otherwise render the ones it needs when they are missing).
// The estimator, iterations and reason of each are StandardReference's (figure_kit.hpp);
// each is written to <out>/references/<scene>_<W>x<H>.pfm with a .json of its settings,
// time and measured noise, and kept while those settings do not change.
//
//   build/fig_references [--quick] [--out DIR] [--threads N]

#include "figure_kit.hpp"

using namespace figures;

int main(int argc, char** argv) {
    return RunFigureProgram(argc, argv, "fig_references: the reference images of the figures", [](const Kit& aKit) {
        const int size = aKit.Pick(256, 64);
        struct Needed { const char* mScene; int mWidth, mHeight; };
        // Scene and resolution of every figure that measures an error (see each program).
        const Needed needed[] = {
            {"cornell_4_default.gltf", size, size},                            // F02, F03, F05, F15, F17, F19
            {"cornell_4_default.gltf", aKit.Pick(64, 32), aKit.Pick(64, 32)},   // F18
            {"veach_plates.gltf", aKit.Pick(384, 96), aKit.Pick(256, 64)},     // F04
            {"indirect_room.gltf", size, size},                                // F06
            {"caustic_glass_sphere.gltf", size, size},                         // F07, F09-F12
            {"sds_glass_sphere.gltf", size, size},                             // F08, F13, F16, F17
            {"diffuse_box.gltf", size, size},                                  // F14, F16
            {"cornell_0_sun.gltf", aKit.Pick(256, 48), aKit.Pick(256, 48)},    // F19
            {"cornell_1_mirror_ceiling.gltf", aKit.Pick(256, 48), aKit.Pick(256, 48)},
            {"cornell_2_point.gltf", aKit.Pick(256, 48), aKit.Pick(256, 48)},
            {"cornell_3_background.gltf", aKit.Pick(256, 48), aKit.Pick(256, 48)},
            {"cornell_4_default.gltf", aKit.Pick(256, 48), aKit.Pick(256, 48)},
        };
        for (const Needed& n : needed) {
            const Reference reference = GetReference(aKit, StandardReference(aKit, n.mScene, n.mWidth, n.mHeight));
            std::printf("  %s %dx%d: %s, noise RMSE %.3g\n", n.mScene, n.mWidth, n.mHeight,
                        reference.mRecord["settings"]["algorithm"].get<std::string>().c_str(), reference.mNoiseRmse);
        }
    });
}
