// my_path_tracer — renders a scene with a student's own path tracer (MyPathTracer, in
// examples/my_path_tracer.hpp) through smallvcm::Render, and the same scene with the
// built-in path tracer, so the two can be compared.
//
//   make build/my_path_tracer
//   build/my_path_tracer [scene.gltf [iterations]]   (from the repository's folder)
//
// Writes mypt.png and pt.png (256x256, 16 iterations of the default Cornell box unless
// told otherwise) and prints each image's mean and render time. The command line runs
// the same integrator as `build/smallvcm -a mypt` (see examples/integrators/).
#include "smallvcm.hpp"
#include "my_path_tracer.hpp"
#include "command_line.hpp"

#include <cstdio>
#include <string>

int main(int argc, char** argv) {
    try {
        const std::string scenePath = argc > 1 ? argv[1] : "scenes/cornell_4_default.gltf";
        smallvcm::Scene scene = smallvcm::LoadGltfScene(scenePath);
        scene.mCamera.SetResolution(256, 256);
        smallvcm::RenderOptions options;
        options.mIterations = argc > 2 ? ParseNumber<int>("iterations", argv[2], 1, 1000000) : 16;

        const smallvcm::RenderResult mine = smallvcm::Render(scene, options, MyPathTracerIntegrator());
        smallvcm::WriteImage("mypt.png", mine.mImage);
        options.mAlgorithm = smallvcm::Algorithm::kPathTracing;
        const smallvcm::RenderResult builtIn = smallvcm::Render(scene, options);
        smallvcm::WriteImage("pt.png", builtIn.mImage);

        std::printf("%s, %d iterations:\n  mypt: mean %.6f in %.2f s -> mypt.png\n  pt:   mean %.6f in %.2f s -> pt.png\n",
                    scenePath.c_str(), options.mIterations, smallvcm::MeanValue(mine.mImage), mine.mSeconds,
                    smallvcm::MeanValue(builtIn.mImage), builtIn.mSeconds);
    } catch (const smallvcm::Error& e) {
        std::fprintf(stderr, "my_path_tracer: %s\n", e.what());
        return 1;
    }
    return 0;
}
