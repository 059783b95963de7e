// [sampling] Random numbers and sampling: every sampling routine against the pdf it
// claims. Three kinds of check, all with fixed seeds so that a run is reproducible:
//   * units: the pdf a sampler returns equals the standalone pdf at the sampled point,
//     samples land in the routine's domain, measure conversions invert each other;
//   * Monte Carlo normalisation: each pdf integrates to 1 over its domain; the tolerance
//     is a multiple of the standard error measured from the same samples;
//   * chi-square goodness of fit: sampled directions (or points) binned into cells whose
//     expected counts come from integrating the pdf numerically over each cell.
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <cmath>
#include <functional>
#include <vector>

using namespace smallvcm;
using namespace testutil;

namespace {

constexpr double kTwoPi = 6.283185307179586;

// Cells on the sphere of directions: bands between consecutive cos(theta) edges times
// equal phi sectors, plus one last cell for every direction below the first edge.
struct DirectionGrid {
    std::vector<double> cosEdges;  // ascending, the last one 1
    int phiBins = 1;

    int CellCount() const { return int(cosEdges.size() - 1) * phiBins + 1; }
    int CellOf(const Vec3& aDirection) const {
        const double z = aDirection.z;
        if (z < cosEdges.front()) return CellCount() - 1;
        int band = int(std::upper_bound(cosEdges.begin(), cosEdges.end(), z) - cosEdges.begin()) - 1;
        band = std::min(band, int(cosEdges.size()) - 2);
        double phi = std::atan2(double(aDirection.y), double(aDirection.x));
        if (phi < 0.0) phi += kTwoPi;
        const int sector = std::min(phiBins - 1, int(phi / kTwoPi * phiBins));
        return band * phiBins + sector;
    }
    // Integral of aPdf over each cell by the midpoint rule on aSub x aSub sub-cells
    // (dw = dcos(theta) dphi); the last cell integrates [-1, cosEdges[0]] on a grid
    // of 64 bands.
    std::vector<double> Integrate(const std::function<double(const Vec3&)>& aPdf, int aSub) const {
        std::vector<double> integral(size_t(CellCount()), 0.0);
        auto integrateBand = [&](double aCos0, double aCos1, int aBands, int aCellOfSector0, bool aOneCell) {
            const double dCos = (aCos1 - aCos0) / aBands;
            const int phiSteps = phiBins * aSub;
            const double dPhi = kTwoPi / phiSteps;
            for (int i = 0; i < aBands; i++) {
                const double c = aCos0 + (i + 0.5) * dCos;
                const double s = std::sqrt(std::max(0.0, 1.0 - c * c));
                for (int j = 0; j < phiSteps; j++) {
                    const double phi = (j + 0.5) * dPhi;
                    const Vec3 w(float(s * std::cos(phi)), float(s * std::sin(phi)), float(c));
                    const int cell = aOneCell ? aCellOfSector0 : aCellOfSector0 + j / aSub;
                    integral[size_t(cell)] += aPdf(w) * dCos * dPhi;
                }
            }
        };
        for (size_t b = 0; b + 1 < cosEdges.size(); b++)
            integrateBand(cosEdges[b], cosEdges[b + 1], aSub, int(b) * phiBins, false);
        if (cosEdges.front() > -1.0) integrateBand(-1.0, cosEdges.front(), 64, CellCount() - 1, true);
        return integral;
    }
};

std::vector<double> UniformEdges(double aFrom, double aTo, int aCount) {
    std::vector<double> edges;
    for (int i = 0; i <= aCount; i++) edges.push_back(aFrom + (aTo - aFrom) * i / aCount);
    return edges;
}

// The Phong exponents the tests use: 0 (uniform hemisphere), 1, 10 and 90 (SmallVCM's floor).
const float kPowers[] = {0.f, 1.f, 10.f, 90.f};

} // namespace

// ---------------------------------------------------------------------------------
// Units: returned pdfs and domains
// ---------------------------------------------------------------------------------

TEST_CASE("The cosine hemisphere sampler returns unit directions in the upper hemisphere with the pdf CosHemispherePdfW gives", "[sampling]") {
    Rng rng(11, 0);
    for (int i = 0; i < 10000; i++) {
        const Vec3 w = SampleCosHemisphereW(rng.GetVec2());
        REQUIRE(glm::length(w) == Approx(1.f).epsilon(1e-5));
        REQUIRE(w.z >= 0.f);
        // The sampler's density at the direction it returned: cos(theta) / pi.
        REQUIRE(CosHemispherePdfW(w) == Approx(w.z * kInvPi).epsilon(1e-5));
    }
    // Known values: straight up has pdf 1/pi, below the horizon 0.
    REQUIRE(CosHemispherePdfW(Vec3(0.f, 0.f, 1.f)) == Approx(1.0 / kPi).epsilon(1e-6));
    REQUIRE(CosHemispherePdfW(Vec3(0.f, 0.6f, -0.8f)) == 0.f);
}

TEST_CASE("The power-cosine sampler's directions have the pdf PowerCosHemispherePdfW gives, for exponents 0, 1, 10 and 90", "[sampling]") {
    Rng rng(12, 0);
    for (float power : kPowers) {
        INFO("exponent " << power);
        for (int i = 0; i < 10000; i++) {
            const Vec3 w = SamplePowerCosHemisphereW(rng.GetVec2(), power);
            REQUIRE(glm::length(w) == Approx(1.f).epsilon(1e-5));
            REQUIRE(w.z >= 0.f);
            // The sampler's density at the direction it returned: (n+1)/(2 pi) cos^n(theta).
            REQUIRE(PowerCosHemispherePdfW(w, power) ==
                    Approx((power + 1.f) * std::pow(w.z, power) * (0.5f * kInvPi)).epsilon(1e-5));
        }
        // At the pole the pdf is (n+1)/(2 pi); below the horizon the lobe has no mass.
        REQUIRE(PowerCosHemispherePdfW(Vec3(0.f, 0.f, 1.f), power) == Approx((power + 1.0) / kTwoPi).epsilon(1e-6));
        CHECK(PowerCosHemispherePdfW(Vec3(0.f, 0.6f, -0.8f), power) == 0.f);
    }
    // Exponent 0 is the uniform hemisphere; exponent 1 is the cosine lobe.
    REQUIRE(PowerCosHemispherePdfW(Vec3(0.6f, 0.f, 0.8f), 0.f) == Approx(1.0 / kTwoPi).epsilon(1e-6));
    REQUIRE(PowerCosHemispherePdfW(Vec3(0.6f, 0.f, 0.8f), 1.f) == Approx(0.8 / kPi).epsilon(1e-6));
}

TEST_CASE("The uniform sphere sampler returns unit directions with pdf 1/(4 pi)", "[sampling]") {
    Rng rng(13, 0);
    for (int i = 0; i < 10000; i++) {
        const Vec3 w = SampleUniformSphereW(rng.GetVec2());
        REQUIRE(glm::length(w) == Approx(1.f).epsilon(1e-5));
        // The sampler's density at the direction it returned (the same everywhere).
        REQUIRE(UniformSpherePdfW() == Approx(0.25f * kInvPi).epsilon(1e-5));
    }
    REQUIRE(UniformSpherePdfW() == Approx(1.0 / (2.0 * kTwoPi)).epsilon(1e-6));
}

TEST_CASE("The uniform cone sampler stays inside the cone, where its pdf is the one UniformConePdfW gives", "[sampling]") {
    Rng rng(14, 0);
    for (float cosMax : {-0.5f, 0.f, 0.3f, 0.95f, 0.9999f}) {
        INFO("cos max " << cosMax);
        for (int i = 0; i < 10000; i++) {
            const Vec3 w = SampleUniformConeW(rng.GetVec2(), cosMax);
            REQUIRE(glm::length(w) == Approx(1.f).epsilon(1e-5));
            REQUIRE(w.z >= cosMax - 1e-6f);
            // The sampler's density at the direction it returned (the same inside the cone).
            REQUIRE(UniformConePdfW(cosMax) == Approx(1.f / (2.f * kPi * (1.f - cosMax))).epsilon(1e-5));
        }
        REQUIRE(UniformConePdfW(cosMax) == Approx(1.0 / (kTwoPi * (1.0 - cosMax))).epsilon(1e-5));
    }
}

TEST_CASE("Triangle samples are valid barycentrics; u1 = 0 gives vertex 0 and u1 = 1 the opposite edge", "[sampling]") {
    Rng rng(15, 0);
    for (int i = 0; i < 10000; i++) {
        const Vec2 b = SampleUniformTriangle(rng.GetVec2());
        REQUIRE(b.x >= 0.f);
        REQUIRE(b.y >= 0.f);
        REQUIRE(b.x + b.y <= 1.f + 1e-6f);
    }
    // u1 = 0 collapses onto vertex 0 (b0 = 1); u1 = 1 gives the opposite edge (b0 = 0).
    REQUIRE(SampleUniformTriangle(Vec2(0.f, 0.7f)).x == 1.f);
    REQUIRE(SampleUniformTriangle(Vec2(0.f, 0.7f)).y == 0.f);
    REQUIRE(SampleUniformTriangle(Vec2(1.f, 0.25f)).x == 0.f);
    REQUIRE(SampleUniformTriangle(Vec2(1.f, 0.25f)).y == 0.25f);
}

TEST_CASE("Concentric disc samples lie in the unit disc and the square's edge maps to the circle", "[sampling]") {
    Rng rng(16, 0);
    for (int i = 0; i < 10000; i++) {
        const Vec2 p = SampleConcentricDisc(rng.GetVec2());
        REQUIRE(glm::length(p) <= 1.f + 1e-6f);
    }
    REQUIRE(glm::length(SampleConcentricDisc(Vec2(0.5f, 0.5f))) == 0.f);
    for (const Vec2 u : {Vec2(1.f, 0.5f), Vec2(0.f, 0.2f), Vec2(0.3f, 1.f), Vec2(0.f, 0.f), Vec2(1.f, 1.f)})
        REQUIRE(glm::length(SampleConcentricDisc(u)) == Approx(1.f).epsilon(1e-6));
    REQUIRE(ConcentricDiscPdfA() == Approx(1.0 / kPi).epsilon(1e-6));
}

TEST_CASE("PdfWtoA and PdfAtoW are inverses of each other and use |cos| / d^2", "[sampling]") {
    REQUIRE(PdfWtoA(2.f, 3.f, 0.5f) == Approx(2.0 * 0.5 / 9.0).epsilon(1e-6));
    REQUIRE(PdfAtoW(2.f, 3.f, -0.5f) == Approx(2.0 * 9.0 / 0.5).epsilon(1e-6));
    Rng rng(17, 0);
    for (int i = 0; i < 1000; i++) {
        const float pdf = 0.01f + 100.f * rng.GetFloat();
        const float dist = 0.001f + 50.f * rng.GetFloat();
        const float cosine = (rng.GetFloat() < 0.5f ? -1.f : 1.f) * (0.001f + 0.999f * rng.GetFloat());
        REQUIRE(PdfAtoW(PdfWtoA(pdf, dist, cosine), dist, cosine) == Approx(pdf).epsilon(1e-5));
        REQUIRE(PdfWtoA(PdfAtoW(pdf, dist, cosine), dist, cosine) == Approx(pdf).epsilon(1e-5));
    }
}

// ---------------------------------------------------------------------------------
// Monte Carlo normalisation
// ---------------------------------------------------------------------------------

TEST_CASE("Every direction pdf integrates to 1 over the sphere (Monte Carlo with uniform sphere samples)", "[sampling]") {
    // Estimate of the integral of p over the sphere: the mean of p(w) / (1/(4 pi)) over
    // uniform directions w. Its standard error is measured from the same samples, and the
    // tolerance is 5 standard errors (a correct pdf fails with probability ~6e-7).
    const int n = 1000000;
    Rng rng(21, 0);
    std::vector<Vec3> directions(n);
    for (Vec3& w : directions) w = SampleUniformSphereW(rng.GetVec2());

    auto check = [&](const char* aName, const std::function<double(const Vec3&)>& aPdf) {
        std::vector<double> values(directions.size());
        for (size_t i = 0; i < directions.size(); i++) values[i] = aPdf(directions[i]) / double(UniformSpherePdfW());
        const MeanAndError e = MeanOf(values);
        INFO(aName << ": integral " << e.mean << " +- " << e.standardError);
        CHECK(std::abs(e.mean - 1.0) <= 5.0 * e.standardError);
    };
    check("cosine hemisphere", [](const Vec3& w) { return CosHemispherePdfW(w); });
    for (float power : kPowers) {
        INFO("exponent " << power);
        check("power cosine", [power](const Vec3& w) { return PowerCosHemispherePdfW(w, power); });
    }
    // The uniform sphere pdf is constant: its estimate has no variance, so the check is exact.
    REQUIRE(double(UniformSpherePdfW()) * 4.0 * kPi == Approx(1.0).epsilon(1e-6));
    for (float cosMax : {0.3f, 0.9f})
        check("uniform cone", [cosMax](const Vec3& w) { return w.z >= cosMax ? double(UniformConePdfW(cosMax)) : 0.0; });
}

TEST_CASE("The concentric disc pdf integrates to 1 over the disc (Monte Carlo over the enclosing square)", "[sampling]") {
    // Points uniform in [-1,1]^2 (area 4): the estimate is the mean of 4 p(x) [x in disc].
    // Tolerance: 5 standard errors measured from the samples.
    Rng rng(22, 0);
    std::vector<double> values(400000);
    for (double& v : values) {
        const Vec2 x = 2.f * rng.GetVec2() - Vec2(1.f);
        v = glm::dot(x, x) <= 1.f ? 4.0 * double(ConcentricDiscPdfA()) : 0.0;
    }
    const MeanAndError e = MeanOf(values);
    INFO("integral " << e.mean << " +- " << e.standardError);
    REQUIRE(std::abs(e.mean - 1.0) <= 5.0 * e.standardError);
}

// ---------------------------------------------------------------------------------
// Chi-square goodness of fit
// ---------------------------------------------------------------------------------

TEST_CASE("Cosine hemisphere samples pass a chi-square test against the cosine pdf", "[sampling]") {
    const int n = 1000000;  // enough to notice a 5% error in the lobe's exponent
    DirectionGrid grid;
    grid.cosEdges = UniformEdges(0.0, 1.0, 16);
    grid.phiBins = 24;
    const std::vector<double> integral = grid.Integrate([](const Vec3& w) { return CosHemispherePdfW(w); }, 8);
    std::vector<double> observed(integral.size(), 0.0), expected(integral.size());
    for (size_t i = 0; i < integral.size(); i++) expected[i] = n * integral[i];
    Rng rng(31, 0);
    for (int i = 0; i < n; i++) observed[size_t(grid.CellOf(SampleCosHemisphereW(rng.GetVec2())))] += 1.0;
    // Threshold: the chi-square quantile at significance 1e-3 (Wilson-Hilferty).
    const ChiSquare chi = ComputeChiSquare(observed, expected);
    INFO("chi2 = " << chi.statistic << " with " << chi.dof << " dof, threshold " << chi.threshold);
    REQUIRE(chi.dof >= 300);
    REQUIRE(chi.statistic < chi.threshold);
}

TEST_CASE("Power-cosine samples pass a chi-square test against the Phong lobe pdf for exponents 0, 1, 10 and 90", "[sampling]") {
    const int n = 1000000;  // enough to notice a 5% error in the lobe's exponent
    for (float power : kPowers) DYNAMIC_SECTION("exponent " << power) {
        // Bands uniform in cos(theta) over [1 - 10/(n+1), 1], where all but ~e^-10 of the
        // lobe lies (cos^(n+1) ~ exp(-(n+1)(1 - cos))), so a narrow lobe still spreads
        // over many cells; the rest of the sphere is the last cell.
        DirectionGrid grid;
        grid.cosEdges = UniformEdges(std::max(0.0, 1.0 - 10.0 / (power + 1.0)), 1.0, 16);
        grid.phiBins = 24;
        const std::vector<double> integral =
            grid.Integrate([power](const Vec3& w) { return PowerCosHemispherePdfW(w, power); }, 8);
        double total = 0.0;
        for (double v : integral) total += v;
        // The numerical integral itself must be 1, or the expected counts are meaningless.
        REQUIRE(total == Approx(1.0).epsilon(1e-3));
        std::vector<double> observed(integral.size(), 0.0), expected(integral.size());
        for (size_t i = 0; i < integral.size(); i++) expected[i] = n * integral[i];
        Rng rng(32, uint64_t(power));
        for (int i = 0; i < n; i++) observed[size_t(grid.CellOf(SamplePowerCosHemisphereW(rng.GetVec2(), power)))] += 1.0;
        // Threshold: the chi-square quantile at significance 1e-3 (Wilson-Hilferty).
        const ChiSquare chi = ComputeChiSquare(observed, expected);
        INFO("chi2 = " << chi.statistic << " with " << chi.dof << " dof, threshold " << chi.threshold);
        REQUIRE(chi.dof >= 200);  // most of the 385 cells expect enough samples to count
        REQUIRE(chi.statistic < chi.threshold);
    }
}

TEST_CASE("Uniform cone samples pass a chi-square test against the constant cone pdf", "[sampling]") {
    const int n = 200000;
    const float cosMax = 0.725f;  // on the integration sub-grid, away from the band edges
    DirectionGrid grid;
    grid.cosEdges = UniformEdges(0.0, 1.0, 20);  // bands below cosMax expect nothing
    grid.phiBins = 16;
    const std::vector<double> integral =
        grid.Integrate([cosMax](const Vec3& w) { return w.z >= cosMax ? double(UniformConePdfW(cosMax)) : 0.0; }, 8);
    std::vector<double> observed(integral.size(), 0.0), expected(integral.size());
    for (size_t i = 0; i < integral.size(); i++) expected[i] = n * integral[i];
    Rng rng(33, 0);
    for (int i = 0; i < n; i++) observed[size_t(grid.CellOf(SampleUniformConeW(rng.GetVec2(), cosMax)))] += 1.0;
    // Threshold: the chi-square quantile at significance 1e-3 (Wilson-Hilferty).
    const ChiSquare chi = ComputeChiSquare(observed, expected);
    INFO("chi2 = " << chi.statistic << " with " << chi.dof << " dof, threshold " << chi.threshold);
    REQUIRE(chi.statistic < chi.threshold);
}

TEST_CASE("Triangle samples fall into the four sub-triangles of a midpoint subdivision equally often", "[sampling]") {
    // With barycentrics (b0, b1, b2): the corner sub-triangle of vertex k is b_k > 1/2,
    // the middle one is everything else. Each has a quarter of the area.
    const int n = 400000;
    std::vector<double> observed(4, 0.0), expected(4, n / 4.0);
    Rng rng(34, 0);
    for (int i = 0; i < n; i++) {
        const Vec2 b = SampleUniformTriangle(rng.GetVec2());
        const float b2 = 1.f - b.x - b.y;
        const int cell = b.x > 0.5f ? 0 : (b.y > 0.5f ? 1 : (b2 > 0.5f ? 2 : 3));
        observed[size_t(cell)] += 1.0;
    }
    // Threshold: the chi-square quantile at significance 1e-3 (Wilson-Hilferty), 3 dof.
    const ChiSquare chi = ComputeChiSquare(observed, expected);
    INFO("chi2 = " << chi.statistic << " with " << chi.dof << " dof, threshold " << chi.threshold);
    REQUIRE(chi.dof == 3);
    REQUIRE(chi.statistic < chi.threshold);
}

TEST_CASE("Concentric disc samples fall into equal-area rings and sectors equally often", "[sampling]") {
    // Ring k lies between radii sqrt(k/8) and sqrt((k+1)/8); 8 rings x 16 sectors of
    // equal area pi/128 each.
    const int n = 256000, rings = 8, sectors = 16;
    std::vector<double> observed(size_t(rings * sectors), 0.0), expected(observed.size(), double(n) / (rings * sectors));
    Rng rng(35, 0);
    for (int i = 0; i < n; i++) {
        const Vec2 p = SampleConcentricDisc(rng.GetVec2());
        const int ring = std::min(rings - 1, int(double(glm::dot(p, p)) * rings));
        double phi = std::atan2(double(p.y), double(p.x));
        if (phi < 0.0) phi += kTwoPi;
        const int sector = std::min(sectors - 1, int(phi / kTwoPi * sectors));
        observed[size_t(ring * sectors + sector)] += 1.0;
    }
    // Threshold: the chi-square quantile at significance 1e-3 (Wilson-Hilferty).
    const ChiSquare chi = ComputeChiSquare(observed, expected);
    INFO("chi2 = " << chi.statistic << " with " << chi.dof << " dof, threshold " << chi.threshold);
    REQUIRE(chi.statistic < chi.threshold);
}

// ---------------------------------------------------------------------------------
// Rng
// ---------------------------------------------------------------------------------

TEST_CASE("Rng is PCG32: seed 42, stream 54 gives the reference generator's first outputs", "[sampling]") {
    // The first six outputs of O'Neill's pcg32 demo program (pcg32_srandom(42, 54)).
    Rng rng(42, 54);
    const uint32_t expected[] = {0xa15c02b7u, 0x7b47f409u, 0xba1d3330u, 0x83d2f293u, 0xbfa4784bu, 0xcbed606eu};
    for (uint32_t e : expected) REQUIRE(rng.NextUint() == e);
}

TEST_CASE("Rng::GetFloat lies in [0, 1) and has mean 1/2", "[sampling]") {
    const int n = 1000000;
    Rng rng(41, 3);
    double sum = 0.0;
    float smallest = 1.f, largest = 0.f;
    for (int i = 0; i < n; i++) {
        const float x = rng.GetFloat();
        smallest = std::min(smallest, x);
        largest = std::max(largest, x);
        sum += x;
    }
    REQUIRE(smallest >= 0.f);
    REQUIRE(largest < 1.f);
    // U[0,1) has variance 1/12: the mean's standard error is sqrt(1/(12 n)); tolerance 5 of them.
    const double standardError = std::sqrt(1.0 / (12.0 * n));
    REQUIRE(std::abs(sum / n - 0.5) <= 5.0 * standardError);
}

TEST_CASE("Rng::GetFloat passes a chi-square test on 256 equal bins", "[sampling]") {
    const int n = 512000, bins = 256;
    std::vector<double> observed(bins, 0.0), expected(bins, double(n) / bins);
    Rng rng(42, 7);
    for (int i = 0; i < n; i++) observed[size_t(rng.GetFloat() * bins)] += 1.0;
    // Threshold: the chi-square quantile at significance 1e-3 (Wilson-Hilferty), 255 dof.
    const ChiSquare chi = ComputeChiSquare(observed, expected);
    INFO("chi2 = " << chi.statistic << " with " << chi.dof << " dof, threshold " << chi.threshold);
    REQUIRE(chi.dof == 255);
    REQUIRE(chi.statistic < chi.threshold);
}

TEST_CASE("Rng is reproducible for the same seed and stream, and different streams or seeds differ", "[sampling]") {
    Rng a(1234, 5), b(1234, 5), otherStream(1234, 6), otherSeed(1235, 5);
    int sameStream = 0, sameSeed = 0;
    for (int i = 0; i < 1000; i++) {
        const uint32_t x = a.NextUint();
        REQUIRE(b.NextUint() == x);
        if (otherStream.NextUint() == x) sameStream++;
        if (otherSeed.NextUint() == x) sameSeed++;
    }
    // Independent 32-bit streams agree at one position with probability 2^-32: over 1000
    // positions, even one agreement would be suspicious.
    REQUIRE(sameStream == 0);
    REQUIRE(sameSeed == 0);
    // Reproducible through the float interface as well.
    Rng c(99, 1), d(99, 1);
    for (int i = 0; i < 100; i++) REQUIRE(c.GetFloat() == d.GetFloat());
}

TEST_CASE("Consecutive Rng floats are uncorrelated", "[sampling]") {
    // Lag-1 sample correlation of n uniform values: under independence it is ~N(0, 1/n);
    // tolerance 5/sqrt(n).
    const int n = 500000;
    Rng rng(43, 0);
    double prev = rng.GetFloat() - 0.5, sumProduct = 0.0, sumSqr = 0.0;
    for (int i = 0; i < n; i++) {
        const double x = rng.GetFloat() - 0.5;
        sumProduct += x * prev;
        sumSqr += x * x;
        prev = x;
    }
    const double correlation = sumProduct / sumSqr;
    REQUIRE(std::abs(correlation) <= 5.0 / std::sqrt(double(n)));
}

// ---------------------------------------------------------------------------------
// Sobol points and the Sampler
// ---------------------------------------------------------------------------------
namespace {

// The digits of point aIndex of the 2D Sobol sequence, each dimension scrambled with its
// half of aSeed (or not at all).
std::array<uint32_t, 2> SobolPointDigits(uint32_t aIndex, std::optional<uint64_t> aSeed) {
    std::array<uint32_t, 2> digits = {detail::SobolDigits(aIndex, 0), detail::SobolDigits(aIndex, 1)};
    if (aSeed) {
        digits[0] = detail::OwenScramble(digits[0], uint32_t(*aSeed));
        digits[1] = detail::OwenScramble(digits[1], uint32_t(*aSeed >> 32));
    }
    return digits;
}

// True if points aFirst .. aFirst + 2^m - 1 put exactly one point in each box
// [i 2^-a, (i+1) 2^-a) x [j 2^-b, (j+1) 2^-b) for every a + b = m: a (0,m,2)-net.
bool IsZeroMTwoNet(uint32_t aFirst, int aM, std::optional<uint64_t> aSeed) {
    const uint32_t count = 1u << aM;
    for (int a = 0; a <= aM; a++) {
        const int b = aM - a;
        std::vector<int> boxes(count, 0);
        for (uint32_t i = aFirst; i < aFirst + count; i++) {
            const std::array<uint32_t, 2> d = SobolPointDigits(i, aSeed);
            const uint32_t x = a == 0 ? 0u : d[0] >> (32 - a), y = b == 0 ? 0u : d[1] >> (32 - b);
            if (++boxes[(x << b) | y] > 1) return false;
        }
    }
    return true;
}

}  // namespace

TEST_CASE("The van der Corput dimension mirrors the index's bits and the second Sobol dimension follows v_k = v_{k-1} xor v_{k-1}/2", "[sampling]") {
    CHECK(detail::SobolDigits(1, 0) == 0x80000000u);
    CHECK(detail::SobolDigits(6, 0) == 0x60000000u);  // 0.011 in binary
    // Dimension 1: v_1 = 0.1, v_2 = 0.11, v_3 = 0.101, v_4 = 0.1111 (binary).
    CHECK(detail::SobolDigits(1, 1) == 0x80000000u);
    CHECK(detail::SobolDigits(2, 1) == 0xc0000000u);
    CHECK(detail::SobolDigits(4, 1) == 0xa0000000u);
    CHECK(detail::SobolDigits(8, 1) == 0xf0000000u);
    CHECK(detail::SobolDigits(3, 1) == (0x80000000u ^ 0xc0000000u));
    CHECK(detail::ReverseBits32(0x00000001u) == 0x80000000u);
    CHECK(detail::ReverseBits32(0x12345678u) == 0x1e6a2c48u);
    // The Sampler's float from reversed digits (a byte table) is DigitsToFloat of the digits.
    Rng rng(91);
    for (uint32_t digits : {0u, 0xffffffffu, 0x80000000u, 0x00000100u, 0x000000ffu, 0x12345678u})
        CHECK(detail::ReversedDigitsToFloat(detail::ReverseBits32(digits)) == detail::DigitsToFloat(digits));
    for (int i = 0; i < 100000; i++) {
        const uint32_t digits = rng.NextUint();
        REQUIRE(detail::ReversedDigitsToFloat(detail::ReverseBits32(digits)) == detail::DigitsToFloat(digits));
    }
}

TEST_CASE("Every Sobol dimension's first 2^k points, scrambled or not, put one point in each cell of width 2^-k", "[sampling]") {
    for (std::optional<uint64_t> seed : {std::optional<uint64_t>(), std::optional<uint64_t>(1), std::optional<uint64_t>(0x9e3779b97f4a7c15ull)}) {
        for (int dim = 0; dim < detail::kSobolDimensions; dim++) {
            for (int k = 0; k <= 12; k++) {
                std::vector<int> cells(size_t(1) << k, 0);
                bool once = true;
                for (uint32_t i = 0; i < (1u << k); i++) {
                    uint32_t digits = detail::SobolDigits(i, dim);
                    if (seed) digits = detail::OwenScramble(digits, uint32_t(*seed >> dim));
                    once = once && ++cells[k == 0 ? 0 : digits >> (32 - k)] == 1;
                }
                INFO("seed " << (seed ? std::to_string(*seed) : "none") << ", k = " << k << ", dimension " << dim);
                REQUIRE(once);
            }
        }
    }
}

TEST_CASE("The Sobol points in Gray-code order are the published ones: the first eight of dimensions 0-2", "[sampling]") {
    // Joe and Kuo's generator, which visits the indices in Gray-code order n ^ (n >> 1).
    const float expected[8][3] = {{0.f, 0.f, 0.f},         {0.5f, 0.5f, 0.5f},     {0.75f, 0.25f, 0.25f},
                                  {0.25f, 0.75f, 0.75f},   {0.375f, 0.375f, 0.625f}, {0.875f, 0.875f, 0.125f},
                                  {0.625f, 0.125f, 0.875f}, {0.125f, 0.625f, 0.375f}};
    for (uint32_t n = 0; n < 8; n++)
        for (int dim = 0; dim < 3; dim++)
            CHECK(detail::DigitsToFloat(detail::SobolDigits(n ^ (n >> 1), dim)) == expected[n][dim]);
    // Dimension 4 (s = 3, a = 2, m = 1 1 1: x^3 + x^2 + 1): the recurrence gives
    // v_4 = v_3 ^ v_1 ^ v_1 / 2^3, worked out by hand.
    CHECK(detail::kSobolMatrices[4][3] == (detail::kSobolMatrices[4][2] ^ detail::kSobolMatrices[4][0] ^ (detail::kSobolMatrices[4][0] >> 3)));
    CHECK(detail::kSobolMatrices[4][3] == 0xb0000000u);  // m_4 = 11 (binary 1011)
    // Every column of every dimension:
    for (int dim = 0; dim < detail::kSobolDimensions; dim++)
        for (int k = 0; k < 32; k++) {
            INFO("dimension " << dim << ", column " << k);
            // m_k odd and below 2^k: digit k + 1 is 1 and nothing follows (a unit diagonal).
            const uint32_t column = detail::kSobolMatrices[size_t(dim)][size_t(k)];
            REQUIRE(((column >> (31 - k)) & 1u) == 1u);
            REQUIRE((k == 31 || (column & ((1u << (31 - k)) - 1u)) == 0u));
        }
}

TEST_CASE("The first 2^m 2D Sobol points and every aligned block of 2^m are (0,m,2)-nets, scrambled or not", "[sampling]") {
    for (std::optional<uint64_t> seed : {std::optional<uint64_t>(), std::optional<uint64_t>(7), std::optional<uint64_t>(0xdeadbeefcafef00dull)}) {
        for (int m = 1; m <= 10; m++) {
            INFO("seed " << (seed ? std::to_string(*seed) : "none") << ", m = " << m);
            REQUIRE(IsZeroMTwoNet(0, m, seed));
            REQUIRE(IsZeroMTwoNet(3u << m, m, seed));  // the fourth block of 2^m
        }
    }
}

TEST_CASE("Owen scrambling is a bijection of the digits that differs by seed and is reproducible", "[sampling]") {
    // Different seeds scramble the same points differently; one seed always the same way.
    int same = 0;
    for (uint32_t i = 0; i < 256; i++) {
        const Vec2 a(ScrambledSobol(i, 0, 11), ScrambledSobol(i, 1, 11)), b(ScrambledSobol(i, 0, 12), ScrambledSobol(i, 1, 12));
        REQUIRE(ScrambledSobol(i, 0, 11) == a.x);
        if (a == b) same++;
    }
    CHECK(same == 0);
    // A nested scramble maps distinct digit strings to distinct ones (here all 16-bit
    // prefixes of the top bits: 65536 distinct inputs, 65536 distinct outputs).
    std::vector<uint32_t> outputs;
    for (uint32_t x = 0; x < 65536; x++) outputs.push_back(detail::OwenScramble(x << 16, 0x1234567u) >> 16);
    std::sort(outputs.begin(), outputs.end());
    CHECK(std::unique(outputs.begin(), outputs.end()) == outputs.end());
}

TEST_CASE("A scrambled Sobol point is uniform over seeds: chi-square of point 5 over 64 x 64 cells", "[sampling]") {
    // Randomised QMC is unbiased because each scrambled point is uniform on [0, 1)^2: the
    // point of one index over many seeds, binned on a 64 x 64 grid (significance 1e-3).
    const int n = 409600, bins = 64;
    std::vector<double> observed(size_t(bins * bins), 0.0), expected(observed.size(), double(n) / double(bins * bins));
    for (int s = 0; s < n; s++) {
        const uint64_t seed = SplitMix64(uint64_t(s));
        const Vec2 p(ScrambledSobol(5, 0, uint32_t(seed)), ScrambledSobol(5, 1, uint32_t(seed >> 32)));
        observed[size_t(int(p.x * bins) * bins + int(p.y * bins))] += 1.0;
    }
    const ChiSquare chi = ComputeChiSquare(observed, expected);
    INFO("chi2 = " << chi.statistic << " with " << chi.dof << " dof, threshold " << chi.threshold);
    REQUIRE(chi.statistic < chi.threshold);
}

TEST_CASE("The independent Sampler draws the Rng's numbers in order; Start does nothing; pixel q connects to light sub-path q", "[sampling]") {
    Rng rng(5, 9);
    Sampler sampler(rng);
    for (int i = 0; i < 100; i++) {
        sampler.StartPixelSample(i);
        REQUIRE(sampler.Get1D() == rng.GetFloat());
        REQUIRE(sampler.Get2D() == rng.GetVec2());
        sampler.StartLightPath(i, 100);
        REQUIRE(sampler.Get3D() == rng.GetVec3());
        REQUIRE(sampler.LightPathOfPixel(i, 100) == i);  // each pixel with its own light sub-path
    }
}

TEST_CASE("The sobol Sampler stratifies each dimension of a pixel over its iterations, and light paths within an iteration", "[sampling]") {
    const int k = 8, n = 1 << k;
    const int pixel = 37;
    // Dimension d of the pixel's samples over iterations 0 .. n-1: one per cell of width
    // 1/n, in [0, 1); the first two (the pixel position) a (0,k,2)-net (its 16 x 16 boxes).
    std::vector<std::vector<int>> cells(size_t(Sampler::kSobolDimensions), std::vector<int>(n, 0));
    std::vector<int> boxes(n, 0);
    for (int iteration = 0; iteration < n; iteration++) {
        Sampler sampler = IterationSampler(SamplerType::kSobol, 99, iteration);
        sampler.StartPixelSample(pixel);
        const Vec2 position = sampler.Get2D();
        boxes[size_t(int(position.x * 16) * 16 + int(position.y * 16))]++;
        cells[0][size_t(position.x * n)]++;
        cells[1][size_t(position.y * n)]++;
        for (int d = 2; d < Sampler::kSobolDimensions; d++) {
            const float u = sampler.Get1D();
            REQUIRE((u >= 0.f && u < 1.f));
            cells[size_t(d)][size_t(u * n)]++;
        }
    }
    REQUIRE(std::count(boxes.begin(), boxes.end(), 1) == n);
    for (int d = 0; d < Sampler::kSobolDimensions; d++) {
        INFO("dimension " << d);
        REQUIRE(std::count(cells[size_t(d)].begin(), cells[size_t(d)].end(), 1) == n);
    }
    // The light sub-paths 0 .. n-1 of one iteration: each dimension stratified too;
    // another iteration's are another scramble (independent), not the same points.
    for (int iteration : {0, 5}) {
        Sampler sampler = IterationSampler(SamplerType::kSobol, 99, iteration);
        std::vector<int> second(n, 0);
        for (int path = 0; path < n; path++) {
            sampler.StartLightPath(path, n);
            sampler.Get1D();
            second[size_t(sampler.Get1D() * n)]++;
        }
        REQUIRE(std::count(second.begin(), second.end(), 1) == n);
    }
    Sampler a = IterationSampler(SamplerType::kSobol, 99, 0), b = IterationSampler(SamplerType::kSobol, 99, 1);
    a.StartLightPath(3, n);
    b.StartLightPath(3, n);
    CHECK(a.Get2D() != b.Get2D());
    // Another seed: another scramble of the same pixel's sample.
    Sampler c = IterationSampler(SamplerType::kSobol, 100, 0);
    Sampler d = IterationSampler(SamplerType::kSobol, 99, 0);
    c.StartPixelSample(pixel);
    d.StartPixelSample(pixel);
    CHECK(c.Get2D() != d.Get2D());
}

TEST_CASE("The sobol Sampler's light sub-paths of iterations 0 .. I-1 are the first I N points of one sequence: stratified together", "[sampling]") {
    // N = 64 light sub-paths per iteration, I = 16 iterations: in every dimension the 1024
    // light sub-paths put one point in each cell of width 1/1024 (with a scramble per
    // iteration, the 16 iterations' points would be 16 independent sets of 64).
    const int pathCount = 64, iterations = 16, n = pathCount * iterations;
    std::vector<std::vector<int>> cells(size_t(Sampler::kSobolDimensions), std::vector<int>(n, 0));
    for (int iteration = 0; iteration < iterations; iteration++) {
        Sampler sampler = IterationSampler(SamplerType::kSobol, 7, iteration);
        for (int path = 0; path < pathCount; path++) {
            sampler.StartLightPath(path, pathCount);
            for (int d = 0; d < Sampler::kSobolDimensions; d++) cells[size_t(d)][size_t(sampler.Get1D() * n)]++;
        }
    }
    for (int d = 0; d < Sampler::kSobolDimensions; d++) {
        INFO("dimension " << d);
        REQUIRE(std::count(cells[size_t(d)].begin(), cells[size_t(d)].end(), 1) == n);
    }
    // Another seed: another scramble.
    Sampler a = IterationSampler(SamplerType::kSobol, 7, 3), b = IterationSampler(SamplerType::kSobol, 8, 3);
    a.StartLightPath(5, pathCount);
    b.StartLightPath(5, pathCount);
    CHECK(a.Get2D() != b.Get2D());
}

TEST_CASE("The sobol Sampler pairs pixels with light sub-paths by a permutation drawn anew each iteration", "[sampling]") {
    // A permutation of 0 .. N-1 for every N (powers of two, primes, products), at several
    // iterations and seeds.
    for (int pathCount = 1; pathCount <= 300; pathCount++)
        for (int iteration : {0, 1, 17, 1000000}) {
            Sampler sampler = IterationSampler(SamplerType::kSobol, uint64_t(pathCount), iteration);
            std::vector<int> hits(size_t(pathCount), 0);
            for (int pixel = 0; pixel < pathCount; pixel++) {
                const int path = sampler.LightPathOfPixel(pixel, pathCount);
                REQUIRE((path >= 0 && path < pathCount));
                hits[size_t(path)]++;
            }
            INFO("N = " << pathCount << ", iteration " << iteration);
            REQUIRE(std::count(hits.begin(), hits.end(), 1) == pathCount);
        }
    // Light sub-paths i N + p share their first log2 N digits of dimension 0 (the light
    // pick) for every i. Over 64 iterations, the ones a pixel connects to spread over
    // the cells of width 1/16 of dimension 0 (with the pixel's own index every time, all
    // 64 would lie in one cell of width 1/4096).
    const int pathCount = 4096, pixel = 1234;
    std::vector<int> cells(16, 0);
    std::vector<int> paths;
    for (int iteration = 0; iteration < 64; iteration++) {
        Sampler sampler = IterationSampler(SamplerType::kSobol, 5, iteration);
        const int path = sampler.LightPathOfPixel(pixel, pathCount);
        paths.push_back(path);
        sampler.StartLightPath(path, pathCount);
        cells[size_t(sampler.Get1D() * 16.f)]++;
    }
    CHECK(std::count(cells.begin(), cells.end(), 0) <= 4);
    std::sort(paths.begin(), paths.end());
    CHECK(std::unique(paths.begin(), paths.end()) - paths.begin() >= 60);
}

TEST_CASE("Past 2^32 light sub-paths the sobol Sampler scrambles the next block of 2^32 anew, stratified again", "[sampling]") {
    // N = 2^20 light sub-paths per iteration: iteration 4096 starts at index 2^32, the
    // first of block 1. Its first point is not block 0's first point again, and its first
    // 1024 light sub-paths are stratified in every dimension.
    const int pathCount = 1 << 20, n = 1024;
    Sampler first = IterationSampler(SamplerType::kSobol, 3, 0), wrapped = IterationSampler(SamplerType::kSobol, 3, 4096);
    first.StartLightPath(0, pathCount);
    wrapped.StartLightPath(0, pathCount);
    CHECK(first.Get3D() != wrapped.Get3D());
    std::vector<std::vector<int>> cells(size_t(Sampler::kSobolDimensions), std::vector<int>(n, 0));
    for (int path = 0; path < n; path++) {
        wrapped.StartLightPath(path, pathCount);
        for (int d = 0; d < Sampler::kSobolDimensions; d++) {
            const float u = wrapped.Get1D();
            REQUIRE((u >= 0.f && u < 1.f));
            cells[size_t(d)][size_t(u * n)]++;
        }
    }
    for (int d = 0; d < Sampler::kSobolDimensions; d++) {
        INFO("dimension " << d);
        REQUIRE(std::count(cells[size_t(d)].begin(), cells[size_t(d)].end(), 1) == n);
    }
    // The largest run: iteration 2^31 - 1 with 2^31 - 1 light sub-paths (index < 2^62).
    Sampler last = IterationSampler(SamplerType::kSobol, 3, std::numeric_limits<int>::max());
    last.StartLightPath(std::numeric_limits<int>::max() - 1, std::numeric_limits<int>::max());
    const Vec3 u = last.Get3D();
    CHECK((u.x >= 0.f && u.x < 1.f && u.y >= 0.f && u.y < 1.f && u.z >= 0.f && u.z < 1.f));
}

TEST_CASE("Past its Sobol dimensions, or without Start, the sobol Sampler gives uniform numbers in [0, 1)", "[sampling]") {
    // Dimensions from kSobolDimensions on are hashed: their values over many pixels pass a chi-square
    // test on 64 bins (significance 1e-3), as do the numbers of a sampler never started.
    const int n = 64000, bins = 64;
    std::vector<double> deep(bins, 0.0), unstarted(bins, 0.0), expected(bins, double(n) / bins);
    Sampler never = IterationSampler(SamplerType::kSobol, 3, 2);
    for (int pixel = 0; pixel < n; pixel++) {
        Sampler sampler = IterationSampler(SamplerType::kSobol, 3, 2);
        sampler.StartPixelSample(pixel);
        for (int d = 0; d < Sampler::kSobolDimensions; d++) sampler.Get1D();
        const float x = sampler.Get1D(), y = never.Get1D();
        REQUIRE((x >= 0.f && x < 1.f && y >= 0.f && y < 1.f));
        deep[size_t(x * bins)] += 1.0;
        unstarted[size_t(y * bins)] += 1.0;
    }
    for (const std::vector<double>* observed : {&deep, &unstarted}) {
        const ChiSquare chi = ComputeChiSquare(*observed, expected);
        INFO("chi2 = " << chi.statistic << " with " << chi.dof << " dof, threshold " << chi.threshold);
        REQUIRE(chi.statistic < chi.threshold);
    }
}
