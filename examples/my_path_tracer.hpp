// my_path_tracer.hpp — a student's own path tracer, written against smallvcm's public API
// only, and rendered through smallvcm::Render like the built-ins (threads, budgets,
// progress, Ctrl-C and the RenderResult come from there). docs/writing-an-integrator.md
// walks through it line by line.
//
// Estimator: Kajiya's path tracing. At each non-specular vertex, next-event estimation
// (one light picked uniformly, one point on it, a shadow ray) and BSDF sampling (which
// continues the path and may hit a light) estimate the same direct light; the balance
// heuristic weights them (Veach 1997, sec. 9.2):
//     w_light = p_light / (p_light + p_bsdf),   w_bsdf = p_bsdf / (p_bsdf + p_light),
// both pdfs in solid angle at the vertex, p_light including the probability of picking
// the light and p_bsdf the Russian roulette continuation probability.
//
// Used by examples/my_path_tracer.cpp (a program), examples/integrators/my_path_tracer.cpp
// (which adds it to the command line as -a mypt) and tests/test_my_path_tracer.cpp (which
// checks that it agrees with the built-in pt).
#pragma once
#include "smallvcm.hpp"

#include <algorithm>

class MyPathTracer : public smallvcm::AbstractRenderer {
public:
    // Render() makes one MyPathTracer per thread; members would be that thread's own.
    using AbstractRenderer::AbstractRenderer;

    // One sample per pixel, every random number from aSampler (this iteration's).
    void RunIteration(int /*aIteration*/, smallvcm::Sampler& aSampler) override {
        using namespace smallvcm;
        const Camera& camera = mScene.mCamera;
        for (int pixel = 0; pixel < camera.PixelCount(); pixel++) {
            const Vec2 raster(float(pixel % camera.Width()), float(pixel / camera.Width()));
            aSampler.StartPixelSample(pixel);  // this pixel's numbers (a stratified sequence with sobol)
            Ray ray = camera.GenerateRay(raster + aSampler.Get2D());
            Vec3 throughput(1.f), radiance(0.f);
            float bsdfPdfW = 0.f;  // pdf of the last scattering direction; 0: camera or specular
            for (int length = 1;; length++) {  // path length in segments; this segment is `length`
                const SurfacePoint hit = mScene.Intersect(ray);
                if (!hit.IsValid()) {  // left the scene: the background, if any
                    if (const Light* background = mScene.GetBackground()) {
                        const Light::RadianceAtHit emitted =
                            background->GetRadiance(mScene.GetSceneSphere(), ray.mDirection, Vec3(0.f), Vec2(0.f));
                        // A background's direct pdf is per solid angle already.
                        radiance += throughput * emitted.mRadiance *
                                    BsdfWeight(bsdfPdfW, emitted.mDirectPdfA * mScene.LightPickProb());
                    }
                    break;
                }
                const Vec3& point = hit.mPosition;
                if (hit.mLightId >= 0) {  // a light found by BSDF sampling
                    const Light::RadianceAtHit emitted = mScene.GetLight(hit.mLightId).GetRadiance(
                        mScene.GetSceneSphere(), ray.mDirection, hit.GeometricNormal(), hit.mUv);
                    // The ray started RayEpsilon() off the previous surface.
                    const float lightPdfW = PdfAtoW(emitted.mDirectPdfA, hit.mDist + mScene.RayEpsilon(),
                                                    glm::dot(hit.GeometricNormal(), -ray.mDirection));
                    radiance += throughput * emitted.mRadiance * BsdfWeight(bsdfPdfW, lightPdfW * mScene.LightPickProb());
                }
                Bsdf bsdf;
                bsdf.Setup(ray, hit, mScene, Transport::kRadiance);  // a camera path carries radiance
                if (!bsdf.IsValid() || length >= mOptions.mMaxPathLength) break;
                if (!bsdf.IsDelta()) radiance += throughput * NextEventEstimate(bsdf, point, aSampler);
                // Its weight f cos / pdf includes Russian roulette; nothing: the path ends.
                const std::optional<ScatterSample> scatter = SampleScatteringWithRoulette(bsdf, aSampler);
                if (!scatter) break;
                throughput *= scatter->mWeight;
                bsdfPdfW = scatter->IsSpecular() ? 0.f : scatter->mPdfW;
                ray = mScene.SpawnRay(point, scatter->mDirection);
            }
            mFilm.AddColor(pixel, radiance);
        }
    }

private:
    // The weight of a light hit by BSDF sampling; after the camera or a specular
    // bounce next-event estimation could not have found it: weight 1.
    static float BsdfWeight(float aBsdfPdfW, float aLightPdfW) {
        return aBsdfPdfW == 0.f ? 1.f : aBsdfPdfW / (aBsdfPdfW + aLightPdfW);
    }

    // Direct light at aPoint from one light sample, MIS-weighted against BSDF sampling.
    smallvcm::Vec3 NextEventEstimate(const smallvcm::Bsdf& aBsdf, const smallvcm::Vec3& aPoint, smallvcm::Sampler& aSampler) const {
        using namespace smallvcm;
        const LightPick pick = mScene.PickLight(aSampler.Get1D());  // a light and its probability
        const std::optional<LightSample> sample = pick.mLight->Illuminate(mScene.GetSceneSphere(), aPoint, aSampler.Get2D());
        if (!sample) return Vec3(0.f);
        const BsdfEval bsdf = aBsdf.EvaluateWithRoulette(sample->mDirToLight);  // its pdfs include Russian roulette
        if (bsdf.IsBlack() || mScene.Occluded(aPoint, sample->mDirToLight, sample->mDistance)) return Vec3(0.f);
        const float lightPdfW = sample->mDirectPdfW * pick.mProb;
        // A point or directional light cannot be hit by BSDF sampling: weight 1.
        const float weight = pick.mLight->IsDelta() ? 1.f : lightPdfW / (lightPdfW + bsdf.mDirPdfW);
        return sample->mRadiance * bsdf.mValue * (weight * bsdf.mCosThetaGen / lightPdfW);
    }
};

// Its description: the name -a takes, the line --help prints, and how to make one.
inline smallvcm::Integrator MyPathTracerIntegrator() {
    return smallvcm::MakeIntegrator<MyPathTracer>("mypt", "a student's path tracer (examples/my_path_tracer.hpp)");
}
