#define SMALLVCM_IMPLEMENTATION
#include "smallvcm.hpp"

int main() {
    try {
        smallvcm::Scene scene = smallvcm::LoadGltfScene("scenes/cornell_4_default.gltf");
        scene.mCamera.SetResolution(256, 256);
        smallvcm::RenderOptions options;
        options.mAlgorithm = smallvcm::Algorithm::kVertexConnectionMerging;
        options.mIterations = 16;
        smallvcm::RenderResult result = smallvcm::Render(scene, options);
        smallvcm::WriteImage("vcm.png", result.mImage);
    } catch (const smallvcm::Error& e) {
        std::fprintf(stderr, "%s\n", e.what());
        return 1;
    }
    return 0;
}
