// [media] Participating media ([SECTION] Participating media): the transmittance, the
// free-flight sampler and the Henyey-Greenstein phase function against their formulas,
// and whole scenes with media against analytic answers and against each other.
#include "test_util.hpp"

#include <catch2/catch.hpp>

using namespace smallvcm;
using namespace testutil;

TEST_CASE("A scattering medium in the emissive furnace keeps its radiance Le / (1 - a) in every estimator", "[media]") {
    // Tolerance: 4 standard errors of the image mean (pixels are independent samples of
    // one value), plus 1e-3 relative for the geodesic sphere's facets, as the furnaces
    // of test_integrators. Paths of up to 64 vertices: the rest, a^k with ~k/3 wall
    // bounces, is below 1e-6 of the answer.
    const float albedo = 0.5f, emitted = 1.f;
    const double expected = emitted / (1.0 - albedo);
    const Scene scene = MakeMediumFurnace(albedo, emitted, 1.f, 0.4f, 24, 24);
    // (Merging in the medium uses the default medium radius, 3 % of the scene radius.)
    for (Algorithm algorithm : kTransportEstimators) {
        const RenderResult result = RenderWith(scene, algorithm, 32, 17, 64);
        const MeanAndError stats = PixelStatistics(result.mImage);
        INFO(AlgorithmShortName(algorithm) << ": mean " << stats.mean << " +- " << stats.standardError << ", expected " << expected);
        CHECK(std::abs(stats.mean - expected) <= 4.0 * stats.standardError + 1e-3 * expected);
    }
}
