// [bsdf] The BSDF on SmallVCM's materials: reciprocity, forward/reverse pdf agreement,
// energy conservation (Monte Carlo albedo), Sample/Evaluate/Pdf consistency with a
// chi-square test of the sampled directions, Fresnel and refraction, one-sidedness and
// the Russian-roulette continuation probabilities. Every Bsdf is built with
// Bsdf::Setup(worldDirFix, normal, material, transport), on a tilted normal so that the
// local frame is not the world's.
#include "test_util.hpp"

#include <catch2/catch.hpp>

#include <cmath>
#include <functional>
#include <string>
#include <vector>

using namespace smallvcm;
using namespace testutil;

namespace {

constexpr double kTwoPi = 6.283185307179586;
const Vec3 kNormal = glm::normalize(Vec3(0.3f, -0.5f, 0.8f));

// --- materials (SmallVCM's numbers where they exist) -----------------------------------
Material Lambert(const Vec3& aAlbedo) {
    Material m;
    m.mName = "Lambert";
    m.mDiffuseReflectance = aAlbedo;
    return m;
}
Material Phong(float aExponent) {
    Material m;
    m.mName = "Phong " + std::to_string(int(aExponent));
    m.mPhongReflectance = Vec3(0.9f);
    m.mPhongExponent = aExponent;
    return m;
}
Material GlossyFloor() {  // SmallVCM material 2
    Material m;
    m.mName = "glossy floor";
    m.mDiffuseReflectance = Vec3(0.1f);
    m.mPhongReflectance = Vec3(0.7f);
    m.mPhongExponent = 90.f;
    return m;
}
Material Mirror() {  // SmallVCM material 6
    Material m;
    m.mName = "mirror";
    m.mMirrorReflectance = Vec3(1.f);
    return m;
}
Material Glass() {  // SmallVCM material 7
    Material m;
    m.mName = "glass";
    m.mMirrorReflectance = Vec3(1.f);
    m.mIor = 1.6f;
    return m;
}
Material DiffuseMirror() {
    Material m;
    m.mName = "diffuse + mirror";
    m.mDiffuseReflectance = Vec3(0.4f);
    m.mMirrorReflectance = Vec3(0.5f);
    return m;
}
// Diffuse with a Fresnel-weighted dielectric: the only kind of material whose component
// probabilities depend on the direction (through F, because the mirror's luminance 0.6
// differs from the refraction's 1), so that the reverse pdf differs from the direct one.
// SmallVCM adds its lobes without coupling them, so this one is not energy conserving
// (0.5 + 0.6 F + (1 - F) can exceed 1) and stays out of the energy test.
Material DiffuseGlass() {
    Material m;
    m.mName = "diffuse + glass";
    m.mDiffuseReflectance = Vec3(0.5f);
    m.mMirrorReflectance = Vec3(0.6f);
    m.mIor = 1.5f;
    return m;
}

// glTF's KHR_materials_transmission rule (docs/scene_format.md 4.3) at t = 0.5, m = 0,
// b = (0.8, 0.5, 0.2): half the surface is glass (mirror 0.5 x F, transmittance 0.5 b),
// the rest diffuse 0.48 b with ks = 0.02, a mirror that F does not weight at r = 0
// (HalfGlass), a Phong lobe of exponent 30 at r = 0.5 (RoughHalfGlass). Energy conserving:
// 0.5 (F + (1 - F) b) + 0.48 b + 0.02 <= 1.
const Vec3 kTint(0.8f, 0.5f, 0.2f);
Material HalfGlass() {
    Material m;
    m.mName = "tinted half glass";
    m.mDiffuseReflectance = 0.48f * kTint;
    m.mOpaqueMirror = Vec3(0.02f);
    m.mMirrorReflectance = Vec3(0.5f);
    m.mTransmittance = 0.5f * kTint;
    m.mIor = 1.5f;
    return m;
}
Material RoughHalfGlass() {
    Material m = HalfGlass();
    m.mName = "tinted half glass, Phong";
    m.mOpaqueMirror = Vec3(0.f);
    m.mPhongReflectance = Vec3(0.02f);
    m.mPhongExponent = 30.f;
    return m;
}
// Tinted glass (t = 1, b = (0.8, 0.5, 0.2), ior 1.5).
Material TintedGlass() {
    Material m = Glass();
    m.mName = "tinted glass";
    m.mTransmittance = kTint;
    m.mIor = 1.5f;
    return m;
}

std::vector<Material> NonSpecularMaterials() {
    return {Lambert(Vec3(0.8f, 0.5f, 0.2f)), Phong(1.f), Phong(10.f), Phong(90.f), GlossyFloor(), DiffuseMirror(), DiffuseGlass(),
            HalfGlass(), RoughHalfGlass()};
}

// --- directions ----------------------------------------------------------------------
// An orthonormal basis around the normal, built here rather than with the header's Frame.
struct Basis {
    Vec3 x, y, z;
    explicit Basis(const Vec3& aNormal) : z(aNormal) {
        const Vec3 helper = std::abs(z.x) < 0.9f ? Vec3(1.f, 0.f, 0.f) : Vec3(0.f, 1.f, 0.f);
        x = glm::normalize(glm::cross(z, helper));
        y = glm::cross(z, x);
    }
    Vec3 ToWorld(const Vec3& aLocal) const { return aLocal.x * x + aLocal.y * y + aLocal.z * z; }
    Vec3 ToLocal(const Vec3& aWorld) const { return Vec3(glm::dot(aWorld, x), glm::dot(aWorld, y), glm::dot(aWorld, z)); }
};
const Basis kBasis(kNormal);

// A world direction at polar angle acos(aCos) from the normal and azimuth aPhi.
Vec3 DirectionAt(float aCos, float aPhi) {
    const float s = std::sqrt(std::max(0.f, 1.f - aCos * aCos));
    return glm::normalize(kBasis.ToWorld(Vec3(s * std::cos(aPhi), s * std::sin(aPhi), aCos)));
}
// A random direction in the upper hemisphere with cos >= 0.02 (away from the grazing cut).
Vec3 RandomUpper(Rng& aRng) {
    return DirectionAt(0.02f + 0.98f * aRng.GetFloat(), float(kTwoPi) * aRng.GetFloat());
}

Bsdf Make(const Vec3& aFix, const Material& aMaterial, Transport aTransport = Transport::kRadiance,
          const Vec3& aNormal = kNormal) {
    Bsdf bsdf;
    bsdf.Setup(aFix, aNormal, aMaterial, aTransport);
    return bsdf;
}

// Monte Carlo albedo of one channel: the mean of f cos / pdf over Sample() (unusable
// samples count as 0), with its standard error measured from the same samples.
MeanAndError Albedo(const Bsdf& aBsdf, int aSamples, uint64_t aSeed, int aChannel = 0) {
    Rng rng(aSeed, 0);
    std::vector<double> weights(size_t(aSamples), 0.0);
    for (double& w : weights) {
        const std::optional<ScatterSample> sample = aBsdf.Sample(rng.GetVec3());
        if (sample && sample->mPdfW > 0.f) w = double(sample->mValue[aChannel]) * sample->mCosThetaOut / sample->mPdfW;
    }
    return MeanOf(weights);
}

// Independent double-precision Fresnel reflectance for unpolarised light going from index
// aEtaI to aEtaT at incidence cosine aCosI > 0.
double FresnelReference(double aCosI, double aEtaI, double aEtaT) {
    const double sinT2 = (aEtaI / aEtaT) * (aEtaI / aEtaT) * (1.0 - aCosI * aCosI);
    if (sinT2 >= 1.0) return 1.0;
    const double cosT = std::sqrt(1.0 - sinT2);
    const double rs = (aEtaI * aCosI - aEtaT * cosT) / (aEtaI * aCosI + aEtaT * cosT);
    const double rp = (aEtaT * aCosI - aEtaI * cosT) / (aEtaT * aCosI + aEtaI * cosT);
    return 0.5 * (rs * rs + rp * rp);
}

} // namespace

// ---------------------------------------------------------------------------------
// Reciprocity and pdf symmetry
// ---------------------------------------------------------------------------------

TEST_CASE("Non-specular BSDFs are reciprocal: f(a, b) = f(b, a)", "[bsdf]") {
    // Tolerance 1e-4 relative: cos(R, w) is computed once as R(a).b and once as R(b).a,
    // which may differ by an ulp; f ~ cos^n turns that into n 6e-8 / cos, up to ~5e-5 for
    // n = 90 at the lobe's edge.
    for (const Material& material : NonSpecularMaterials()) {
        INFO(material.mName);
        Rng rng(301, 0);
        int nonZero = 0;
        for (int i = 0; i < 2000; i++) {
            const Vec3 a = RandomUpper(rng), b = RandomUpper(rng);
            for (const Transport transport : {Transport::kRadiance, Transport::kImportance}) {
                const BsdfEval evalAB = Make(a, material, transport).Evaluate(b);
                const BsdfEval evalBA = Make(b, material, transport).Evaluate(a);
                const Vec3 fab = evalAB.mValue, fba = evalBA.mValue;
                const float cosAB = evalAB.mCosThetaGen, cosBA = evalBA.mCosThetaGen;
                for (int c = 0; c < 3; c++) REQUIRE(fab[c] == Approx(fba[c]).epsilon(1e-4).margin(1e-12));
                REQUIRE(cosAB == Approx(glm::dot(b, kNormal)).epsilon(1e-5));
                REQUIRE(cosBA == Approx(glm::dot(a, kNormal)).epsilon(1e-5));
                if (!IsBlack(fab)) nonZero++;
            }
        }
        REQUIRE(nonZero > 400);  // the lobes were actually evaluated somewhere
    }
}

TEST_CASE("The reverse pdf of Evaluate(b) set up at a equals the direct pdf of Evaluate(a) set up at b", "[bsdf]") {
    // Same tolerance as reciprocity, for the same reason (the Phong lobe's cos^n).
    for (const Material& material : NonSpecularMaterials()) {
        INFO(material.mName);
        Rng rng(302, 0);
        for (int i = 0; i < 2000; i++) {
            const Vec3 a = RandomUpper(rng), b = RandomUpper(rng);
            const Bsdf atA = Make(a, material), atB = Make(b, material);
            const BsdfEval evalA = atA.Evaluate(b), evalB = atB.Evaluate(a);
            const float directA = evalA.mDirPdfW, reverseA = evalA.mRevPdfW;
            const float directB = evalB.mDirPdfW, reverseB = evalB.mRevPdfW;
            REQUIRE(reverseA == Approx(directB).epsilon(1e-4).margin(1e-12));
            REQUIRE(reverseB == Approx(directA).epsilon(1e-4).margin(1e-12));
            // Pdf() gives the same two numbers as Evaluate.
            REQUIRE(atA.Pdf(b) == directA);
            REQUIRE(atA.Pdf(b, true) == reverseA);
        }
    }
}

TEST_CASE("For diffuse under glass the reverse pdf uses the Fresnel term of the other direction", "[bsdf]") {
    // Component probabilities ~ luminance: diffuse 0.5, mirror 0.6 F(cos), refraction 1 - F.
    // Direct pdf = P_diffuse(F(fix)) cos(gen)/pi; reverse = P_diffuse(F(gen)) cos(fix)/pi.
    const Material material = DiffuseGlass();
    const Vec3 a = DirectionAt(0.95f, 0.3f), b = DirectionAt(0.1f, 2.f);
    const double lumD = double(Luminance(material.mDiffuseReflectance)), lumM = double(Luminance(material.mMirrorReflectance));
    auto diffuseProbability = [&](float aCos) {
        const double f = FresnelReference(aCos, 1.0, 1.5);
        return lumD / (lumD + f * lumM + (1.0 - f));
    };
    const BsdfEval eval = Make(a, material).Evaluate(b);
    const float direct = eval.mDirPdfW, reverse = eval.mRevPdfW;
    const float cosA = glm::dot(a, kNormal), cosB = glm::dot(b, kNormal);
    REQUIRE(direct == Approx(diffuseProbability(cosA) * cosB / kPi).epsilon(1e-4));
    REQUIRE(reverse == Approx(diffuseProbability(cosB) * cosA / kPi).epsilon(1e-4));
    // Near-normal and grazing directions have different Fresnel terms, so this is not vacuous.
    REQUIRE(std::abs(diffuseProbability(cosA) - diffuseProbability(cosB)) > 0.05);
}

// ---------------------------------------------------------------------------------
// Energy conservation
// ---------------------------------------------------------------------------------

namespace {
const float kIncidentCosines[] = {1.f, 0.9f, 0.7f, 0.5f, 0.3f, 0.1f, 0.02f};
}

TEST_CASE("Lambert's albedo is its reflectance for every incident direction", "[bsdf]") {
    // f cos / pdf = (rho/pi) cos / (cos/pi) = rho for every sample, up to float rounding:
    // the per-sample check is exact to 1e-5, and the mean must equal rho within 4 measured
    // standard errors plus that rounding (the standard error itself is ~1e-8 here).
    const Vec3 rho(0.8f, 0.5f, 0.2f);
    const Material material = Lambert(rho);
    for (const float cosIn : kIncidentCosines) {
        INFO("cos incident " << cosIn);
        const Bsdf bsdf = Make(DirectionAt(cosIn, 1.f), material);
        REQUIRE(bsdf.IsValid());
        Rng rng(311, 0);
        for (int i = 0; i < 2000; i++) {
            const std::optional<ScatterSample> sample = bsdf.Sample(rng.GetVec3());
            REQUIRE(sample);  // every Lambert sample is usable
            for (int c = 0; c < 3; c++)
                REQUIRE(sample->mValue[c] * sample->mCosThetaOut / sample->mPdfW == Approx(rho[c]).epsilon(1e-5));
        }
        for (int c = 0; c < 3; c++) {
            const MeanAndError albedo = Albedo(bsdf, 20000, 312, c);
            REQUIRE(std::abs(albedo.mean - rho[c]) <= 4.0 * albedo.standardError + 1e-5 * rho[c]);
        }
    }
}

TEST_CASE("Phong's albedo never exceeds its reflectance and equals it at normal incidence", "[bsdf]") {
    // Albedo = rho_s E[(n+2)/(n+1) cos(theta_gen)] over the lobe: exactly rho_s when the
    // lobe is centred on the normal (E[cos] = (n+1)/(n+2)), less when the horizon cuts
    // it. Tolerance: 4 standard errors measured from the samples.
    for (const float exponent : {1.f, 10.f, 90.f}) {
        const Material material = Phong(exponent);
        const double rho = material.mPhongReflectance.x;
        for (const float cosIn : kIncidentCosines) {
            INFO("exponent " << exponent << ", cos incident " << cosIn);
            const MeanAndError albedo = Albedo(Make(DirectionAt(cosIn, 0.5f), material), 40000, 313);
            INFO("albedo " << albedo.mean << " +- " << albedo.standardError);
            REQUIRE(albedo.mean <= rho + 4.0 * albedo.standardError);
            if (cosIn == 1.f) REQUIRE(std::abs(albedo.mean - rho) <= 4.0 * albedo.standardError);
        }
    }
}

TEST_CASE("No material reflects more energy than it receives", "[bsdf]") {
    // Monte Carlo albedo (f cos / pdf over Sample) <= 1 + 4 measured standard errors, on
    // every channel, for many incident directions; glass in importance mode (radiance
    // mode legitimately scales by eta^2 when it refracts into the denser side). Every
    // material here has component reflectances summing to at most 1. Mirror and glass
    // samples weigh exactly 1 up to float rounding (so their standard error is ~1e-8):
    // 1e-6, a few ulps, is added for that rounding.
    std::vector<std::pair<Material, Transport>> cases;
    for (const Material& m : NonSpecularMaterials())
        if (m.mName != "diffuse + glass") cases.push_back({m, Transport::kRadiance});
    cases.push_back({Mirror(), Transport::kRadiance});
    cases.push_back({Glass(), Transport::kImportance});
    for (const auto& [material, transport] : cases) {
        for (const float cosIn : kIncidentCosines) {
            INFO(material.mName << ", cos incident " << cosIn);
            const Bsdf bsdf = Make(DirectionAt(cosIn, 2.5f), material, transport);
            REQUIRE(bsdf.IsValid());
            for (int c = 0; c < 3; c++) {
                const MeanAndError albedo = Albedo(bsdf, 20000, 314, c);
                INFO("albedo " << albedo.mean << " +- " << albedo.standardError);
                REQUIRE(albedo.mean <= 1.0 + 4.0 * albedo.standardError + 1e-6);
            }
        }
    }
}

TEST_CASE("Albedos of the glossy floor and of diffuse + mirror are the sums of their reflectances", "[bsdf]") {
    // Floor at normal incidence: 0.1 (diffuse) + 0.7 (Phong, whole lobe above the horizon);
    // tolerance 4 measured standard errors. Diffuse + mirror: every sample weighs
    // 0.4 / P(diffuse) = 0.5 / P(mirror) = 0.9 (probabilities ~ luminance), at any angle.
    const MeanAndError floor = Albedo(Make(kNormal, GlossyFloor()), 100000, 315);
    INFO("floor albedo " << floor.mean << " +- " << floor.standardError);
    REQUIRE(std::abs(floor.mean - 0.8) <= 4.0 * floor.standardError);
    for (const float cosIn : kIncidentCosines) {
        const MeanAndError mix = Albedo(Make(DirectionAt(cosIn, 0.f), DiffuseMirror()), 5000, 316);
        REQUIRE(mix.mean == Approx(0.9).epsilon(1e-5));
    }
}

// ---------------------------------------------------------------------------------
// Sample / Evaluate / Pdf consistency
// ---------------------------------------------------------------------------------

TEST_CASE("A non-specular sample's f, pdf and reverse pdf are what Evaluate and Pdf give for its direction", "[bsdf]") {
    // Evaluate sees the sampled direction after a trip through world space and back, which
    // moves its local coordinates by a few 1e-8: the Phong lobe's slope (n / cos relative)
    // turns that into up to ~1e-5 relative, hence 1e-4; near the horizon the cosine (and
    // Lambert's pdf with it) is only known to ~1e-7 absolute, hence a 1e-6 margin.
    for (const Material& material : NonSpecularMaterials()) {
        for (const float cosIn : kIncidentCosines) {
            INFO(material.mName << ", cos incident " << cosIn);
            const Bsdf bsdf = Make(DirectionAt(cosIn, 4.f), material);
            Rng rng(321, 0);
            int checked = 0;
            for (int i = 0; i < 2000; i++) {
                const std::optional<ScatterSample> sample = bsdf.Sample(rng.GetVec3());
                if (!sample) continue;  // nothing sampled: no event to check
                const Vec3 direction = sample->mDirection, f = sample->mValue;
                const float pdf = sample->mPdfW, cosine = sample->mCosThetaOut, reversePdf = sample->mReversePdfW;
                const uint32_t event = sample->mEvent;
                if (event & kEventSpecular) REQUIRE(reversePdf == pdf);  // a selection probability, both ways
                if (!(event == kEventDiffuse || event == kEventPhong)) continue;
                checked++;
                REQUIRE(reversePdf == Approx(bsdf.Pdf(direction, true)).epsilon(1e-4).margin(1e-6));
                const BsdfEval eval = bsdf.Evaluate(direction);
                const Vec3 evaluated = eval.mValue;
                const float evalCosine = eval.mCosThetaGen, evalPdf = eval.mDirPdfW;
                REQUIRE(glm::length(direction) == Approx(1.f).epsilon(1e-5));
                REQUIRE(glm::dot(direction, kNormal) > 0.f);
                for (int c = 0; c < 3; c++) REQUIRE(f[c] == Approx(evaluated[c]).epsilon(1e-4).margin(1e-6));
                REQUIRE(pdf == Approx(evalPdf).epsilon(1e-4).margin(1e-6));
                REQUIRE(pdf == Approx(bsdf.Pdf(direction)).epsilon(1e-4).margin(1e-6));
                REQUIRE(cosine == Approx(evalCosine).epsilon(1e-4).margin(1e-6));
                REQUIRE(cosine == Approx(glm::dot(direction, kNormal)).epsilon(1e-4).margin(1e-6));
            }
            REQUIRE(checked > 500);
        }
    }
}

namespace {

// Chi-square test of the directions Bsdf::Sample draws against Bsdf::Pdf and the
// specular selection probabilities. Cells: a grid over the upper hemisphere of the
// normal, uniform in cos(theta) and phi (plus one cell for everything below), and one
// cell each for "specular reflection", "refraction" and "no sample" (a lobe sample below
// the horizon, or under the Phong cut-off). Expected counts: n times the integral of Pdf
// over each cell (midpoint rule on 8 x 8 sub-cells), n p_reflect, n p_refract, and the
// rest for "no sample". aReflect / aRefract are computed by the caller independently.
ChiSquare SampleDirectionChiSquare(const Bsdf& aBsdf, int aSamples, double aReflect, double aRefract, uint64_t aSeed,
                                   double* oNonSpecularMass = nullptr) {
    const int cosBins = 32, phiBins = 64, sub = 8;
    const int gridCells = cosBins * phiBins + 1;  // + below the horizon
    const int reflectCell = gridCells, refractCell = gridCells + 1, noneCell = gridCells + 2;
    auto cellOf = [&](const Vec3& aWorld) {
        const Vec3 local = kBasis.ToLocal(aWorld);
        if (local.z < 0.f) return gridCells - 1;
        const int band = std::min(cosBins - 1, int(double(local.z) * cosBins));
        double phi = std::atan2(double(local.y), double(local.x));
        if (phi < 0.0) phi += kTwoPi;
        return band * phiBins + std::min(phiBins - 1, int(phi / kTwoPi * phiBins));
    };
    std::vector<double> expected(size_t(gridCells + 3), 0.0), observed(expected.size(), 0.0);
    double mass = 0.0;
    const double dCos = 1.0 / (cosBins * sub), dPhi = kTwoPi / (phiBins * sub);
    for (int i = 0; i < cosBins * sub; i++) {
        const double c = (i + 0.5) * dCos, s = std::sqrt(1.0 - c * c);
        for (int j = 0; j < phiBins * sub; j++) {
            const double phi = (j + 0.5) * dPhi;
            const Vec3 w = glm::normalize(kBasis.ToWorld(Vec3(float(s * std::cos(phi)), float(s * std::sin(phi)), float(c))));
            const double p = double(aBsdf.Pdf(w)) * dCos * dPhi;
            expected[size_t((i / sub) * phiBins + j / (sub))] += p;
            mass += p;
        }
    }
    for (int k = 0; k < gridCells; k++) expected[size_t(k)] *= aSamples;
    expected[size_t(reflectCell)] = aSamples * aReflect;
    expected[size_t(refractCell)] = aSamples * aRefract;
    expected[size_t(noneCell)] = std::max(0.0, aSamples * (1.0 - aReflect - aRefract - mass));
    if (oNonSpecularMass) *oNonSpecularMass = mass;

    Rng rng(aSeed, 0);
    for (int i = 0; i < aSamples; i++) {
        const std::optional<ScatterSample> sample = aBsdf.Sample(rng.GetVec3());
        int cell = noneCell;
        if (!sample || sample->mEvent == kEventNone) cell = noneCell;
        else if (sample->mEvent == kEventReflect) cell = reflectCell;
        else if (sample->mEvent == kEventRefract) cell = refractCell;
        else cell = cellOf(sample->mDirection);
        observed[size_t(cell)] += 1.0;
    }
    return ComputeChiSquare(observed, expected);
}

} // namespace

TEST_CASE("Sampled directions follow Pdf() and the specular selection probabilities (chi-square)", "[bsdf]") {
    // Threshold: the chi-square quantile at significance 1e-3 (Wilson-Hilferty).
    struct Case {
        Material material;
        float cosIn;
    };
    const std::vector<Case> cases = {{Lambert(Vec3(0.8f)), 0.6f},  {Phong(1.f), 0.9f},       {Phong(10.f), 0.7f},
                                     {Phong(90.f), 0.5f},          {Phong(10.f), 0.15f},     {GlossyFloor(), 0.8f},
                                     {GlossyFloor(), 0.25f},       {DiffuseMirror(), 0.4f},  {DiffuseGlass(), 0.3f},
                                     {HalfGlass(), 0.35f},         {RoughHalfGlass(), 0.8f}};
    for (const Case& c : cases) {
        INFO(c.material.mName << ", cos incident " << c.cosIn);
        const Bsdf bsdf = Make(DirectionAt(c.cosIn, 1.3f), c.material);
        REQUIRE(bsdf.IsValid());
        // Specular selection, from SmallVCM's rule (probabilities ~ luminance of the
        // diffuse, Phong, F mirror (+ the opaque mirror) and (1 - F) x transmittance
        // refraction albedos), computed here.
        const Material& m = c.material;
        const double fresnel = m.mIor > 0.f ? FresnelReference(c.cosIn, 1.0, m.mIor) : 1.0;
        const double weights[4] = {Luminance(m.mDiffuseReflectance), Luminance(m.mPhongReflectance),
                                   fresnel * Luminance(m.mMirrorReflectance) + Luminance(m.mOpaqueMirror),
                                   m.mIor > 0.f ? (1.0 - fresnel) * Luminance(m.mTransmittance) : 0.0};
        const double total = weights[0] + weights[1] + weights[2] + weights[3];
        double mass = 0.0;
        const ChiSquare chi = SampleDirectionChiSquare(bsdf, 300000, weights[2] / total, weights[3] / total, 322, &mass);
        INFO("chi2 = " << chi.statistic << " with " << chi.dof << " dof, threshold " << chi.threshold
                       << "; non-specular mass " << mass);
        // The integrated non-specular pdf cannot exceed the non-specular selection probability.
        REQUIRE(mass <= (weights[0] + weights[1]) / total + 1e-3);
        REQUIRE(chi.dof >= 20);
        REQUIRE(chi.statistic < chi.threshold);
    }
}

TEST_CASE("Glass picks reflection with probability F and refraction with 1 - F (chi-square)", "[bsdf]") {
    // Threshold: the chi-square quantile at significance 1e-3 (Wilson-Hilferty), 1 dof.
    for (const float cosIn : {0.95f, 0.5f, 0.1f}) {
        INFO("cos incident " << cosIn);
        const double fresnel = FresnelReference(cosIn, 1.0, 1.6);
        const ChiSquare chi = SampleDirectionChiSquare(Make(DirectionAt(cosIn, 0.f), Glass(), Transport::kImportance), 100000, fresnel, 1.0 - fresnel, 323);
        INFO("chi2 = " << chi.statistic << " with " << chi.dof << " dof, threshold " << chi.threshold);
        REQUIRE(chi.statistic < chi.threshold);
    }
}

// ---------------------------------------------------------------------------------
// Fresnel, mirror and glass
// ---------------------------------------------------------------------------------

TEST_CASE("FresnelDielectric matches the Fresnel equations and their limits", "[bsdf]") {
    const float ior = 1.6f;
    // Normal incidence, from either side: ((n - 1) / (n + 1))^2.
    const double normal = Sqr((ior - 1.0f) / (ior + 1.0f));
    REQUIRE(FresnelDielectric(1.f, ior) == Approx(normal).epsilon(1e-5));
    REQUIRE(FresnelDielectric(-1.f, ior) == Approx(normal).epsilon(1e-5));
    // Grazing from outside: F -> 1.
    REQUIRE(FresnelDielectric(1e-6f, ior) > 0.9999f);
    REQUIRE(FresnelDielectric(1e-3f, ior) > 0.99f);
    // Total internal reflection from inside beyond the critical angle (cos_c = 0.7806).
    const float cosCritical = std::sqrt(1.f - 1.f / (ior * ior));
    for (const float c : {-0.77f, -0.5f, -0.1f, -1e-4f}) REQUIRE(FresnelDielectric(c, ior) == 1.f);
    REQUIRE(FresnelDielectric(-(cosCritical + 0.01f), ior) < 1.f);
    // Against an independent double implementation over the whole range, both sides.
    for (int i = 1; i <= 1000; i++) {
        const float c = float(i) / 1000.f;
        REQUIRE(FresnelDielectric(c, ior) == Approx(FresnelReference(c, 1.0, ior)).margin(2e-6));
        REQUIRE(FresnelDielectric(-c, ior) == Approx(FresnelReference(c, ior, 1.0)).margin(2e-6));
    }
    // Monotone from normal incidence to grazing (outside).
    for (int i = 1; i < 1000; i++) REQUIRE(FresnelDielectric(float(i) / 1000.f, ior) >= FresnelDielectric(float(i + 1) / 1000.f, ior));
    // No refraction index: a perfect mirror.
    REQUIRE(FresnelDielectric(0.5f, -1.f) == 1.f);
}

TEST_CASE("Fresnel reflectance is the same for both directions of a refracted pair", "[bsdf]") {
    // For a float cosine cosT inside the glass, the outside cosine of the same pair is
    // computed in double, so that the pair is exact; cosI >= 0.1 keeps both evaluations
    // well conditioned (away from grazing and from the critical angle, where F's slope
    // turns float rounding of the cosine into large changes). Tolerance 1e-5.
    const double ior = 1.6;
    int pairs = 0;
    for (int i = 0; i <= 1000; i++) {
        const float cosT = 0.79f + 0.21f * float(i) / 1000.f;
        const double cosI = std::sqrt(1.0 - ior * ior * (1.0 - double(cosT) * cosT));
        if (cosI < 0.1) continue;
        pairs++;
        REQUIRE(FresnelDielectric(float(cosI), float(ior)) == Approx(FresnelDielectric(-cosT, float(ior))).margin(1e-5));
    }
    REQUIRE(pairs > 900);
}

TEST_CASE("A refracted direction obeys Snell's law and lies in the plane of incidence", "[bsdf]") {
    const Material glass = Glass();
    Rng rng(331, 0);
    int refracted = 0;
    for (int i = 0; i < 1000; i++) {
        const bool fromInside = i % 2 == 1;
        Vec3 fix = RandomUpper(rng);
        // From inside, stay within the critical angle so that refraction exists.
        if (fromInside) fix = -DirectionAt(0.8f + 0.2f * rng.GetFloat(), float(kTwoPi) * rng.GetFloat());
        const Bsdf bsdf = Make(fix, glass, Transport::kImportance);
        const std::optional<ScatterSample> sample = bsdf.Sample(Vec3(rng.GetFloat(), rng.GetFloat(), 0.99999f));
        REQUIRE(sample);  // not black
        REQUIRE(sample->mEvent == kEventRefract);
        const Vec3 gen = sample->mDirection;
        refracted++;
        const double etaFix = fromInside ? 1.6 : 1.0, etaGen = fromInside ? 1.0 : 1.6;
        const double cosFix = glm::dot(fix, kNormal), cosGen = glm::dot(gen, kNormal);
        REQUIRE(cosFix * cosGen < 0.0);  // the other side of the surface
        const double sinFix = std::sqrt(std::max(0.0, 1.0 - cosFix * cosFix));
        const double sinGen = std::sqrt(std::max(0.0, 1.0 - cosGen * cosGen));
        REQUIRE(etaGen * sinGen == Approx(etaFix * sinFix).margin(1e-5));
        // In the plane of incidence, on the far side of the normal: the tangential parts
        // point in opposite directions.
        const Vec3 fixTangent = fix - float(cosFix) * kNormal, genTangent = gen - float(cosGen) * kNormal;
        REQUIRE(glm::length(glm::cross(fixTangent, genTangent)) <= 1e-5f);
        REQUIRE(glm::dot(fixTangent, genTangent) <= 0.f);
        REQUIRE(glm::length(gen) == Approx(1.f).epsilon(1e-5));
    }
    REQUIRE(refracted == 1000);
}

TEST_CASE("Glass splits importance into F reflected and 1 - F refracted, and radiance refraction carries (eta_fix/eta_gen)^2", "[bsdf]") {
    const Material glass = Glass();
    for (const float cosIn : {0.95f, 0.6f, 0.2f, -0.99f, -0.85f}) {
        INFO("cos incident " << cosIn);
        const Vec3 fix = cosIn > 0.f ? DirectionAt(cosIn, 0.7f) : -DirectionAt(-cosIn, 0.7f);
        const float fresnel = FresnelDielectric(cosIn, glass.mIor);
        const double etaFixOverGen = cosIn > 0.f ? 1.0 / 1.6 : 1.6;
        for (const Transport transport : {Transport::kImportance, Transport::kRadiance}) {
            const Bsdf bsdf = Make(fix, glass, transport);
            REQUIRE(bsdf.IsValid());
            REQUIRE(bsdf.IsDelta());
            const std::optional<ScatterSample> reflectSample = bsdf.Sample(Vec3(0.3f, 0.3f, 0.f));
            const std::optional<ScatterSample> refractSample = bsdf.Sample(Vec3(0.3f, 0.3f, 0.99999f));
            REQUIRE(reflectSample);
            REQUIRE(refractSample);
            REQUIRE(reflectSample->mEvent == kEventReflect);
            REQUIRE(refractSample->mEvent == kEventRefract);
            const Vec3 reflectDir = reflectSample->mDirection, fr = reflectSample->mValue, ft = refractSample->mValue;
            const float reflectPdf = reflectSample->mPdfW, refractPdf = refractSample->mPdfW;
            const float reflectCos = reflectSample->mCosThetaOut, refractCos = refractSample->mCosThetaOut;
            // The selection probabilities are F and 1 - F (mirror reflectance 1).
            REQUIRE(reflectPdf == Approx(fresnel).epsilon(1e-5));
            REQUIRE(refractPdf == Approx(1.f - fresnel).epsilon(1e-5));
            // Reflected and refracted fractions: f cos.
            const double reflected = fr.x * reflectCos, transmitted = ft.x * refractCos;
            REQUIRE(reflected == Approx(fresnel).epsilon(1e-5));
            if (transport == Transport::kImportance) {
                REQUIRE(transmitted == Approx(1.0 - fresnel).epsilon(1e-5));
                REQUIRE(reflected + transmitted == Approx(1.0).epsilon(1e-5));
            } else {
                REQUIRE(transmitted == Approx((1.0 - fresnel) * etaFixOverGen * etaFixOverGen).epsilon(1e-5));
            }
            // The mirror direction: reflection of fix about the normal.
            const Vec3 mirror = 2.f * glm::dot(fix, kNormal) * kNormal - fix;
            REQUIRE(glm::length(reflectDir - mirror) <= 1e-5f);
            // A delta BSDF has nothing to evaluate.
            const BsdfEval eval = bsdf.Evaluate(reflectDir);
            REQUIRE(IsBlack(eval.mValue));
            REQUIRE(eval.mDirPdfW == 0.f);
        }
    }
    // Under total internal reflection every sample reflects with weight 1.
    const Bsdf tir = Make(-DirectionAt(0.3f, 0.f), glass, Transport::kRadiance);
    REQUIRE(tir.IsValid());
    Rng rng(332, 0);
    for (int i = 0; i < 100; i++) {
        const std::optional<ScatterSample> sample = tir.Sample(rng.GetVec3());
        REQUIRE(sample);
        REQUIRE(sample->mEvent == kEventReflect);
        REQUIRE(sample->mValue.x * sample->mCosThetaOut / sample->mPdfW == Approx(1.f).epsilon(1e-5));
    }
}

TEST_CASE("A mirror reflects about the normal with weight 1 from either side and evaluates to zero elsewhere", "[bsdf]") {
    for (const float side : {1.f, -1.f}) {
        const Vec3 fix = side * DirectionAt(0.4f, 2.f);
        const Material mirror = Mirror();  // a Bsdf points to its material: keep it alive
        const Bsdf bsdf = Make(fix, mirror);
        REQUIRE(bsdf.IsValid());
        REQUIRE(bsdf.IsDelta());
        Rng rng(341, 0);
        for (int i = 0; i < 100; i++) {
            const std::optional<ScatterSample> sample = bsdf.Sample(rng.GetVec3());
            REQUIRE(sample);
            REQUIRE(sample->mEvent == kEventReflect);
            REQUIRE(glm::length(sample->mDirection - (2.f * glm::dot(fix, kNormal) * kNormal - fix)) <= 1e-5f);
            REQUIRE(sample->mValue.x * sample->mCosThetaOut / sample->mPdfW == Approx(1.f).epsilon(1e-5));
        }
        const BsdfEval eval = bsdf.Evaluate(side * kNormal);
        REQUIRE(IsBlack(eval.mValue));
        REQUIRE(eval.mDirPdfW == 0.f);
        REQUIRE(bsdf.Pdf(side * kNormal) == 0.f);
    }
}

// ---------------------------------------------------------------------------------
// One-sidedness
// ---------------------------------------------------------------------------------

TEST_CASE("Lambert and Phong seen from behind are invalid unless the material is two-sided", "[bsdf]") {
    for (const Material& material : {Lambert(Vec3(0.5f)), Phong(10.f), GlossyFloor()}) {
        INFO(material.mName);
        REQUIRE_FALSE(Make(-DirectionAt(0.7f, 1.f), material).IsValid());
        REQUIRE_FALSE(Make(-DirectionAt(0.7f, 1.f), material, Transport::kImportance).IsValid());
        REQUIRE(Make(DirectionAt(0.7f, 1.f), material).IsValid());
        // From the front, nothing is transmitted to the back.
        const BsdfEval eval = Make(DirectionAt(0.7f, 1.f), material).Evaluate(-DirectionAt(0.5f, 3.f));
        REQUIRE(IsBlack(eval.mValue));
        REQUIRE(eval.mDirPdfW == 0.f);
    }
}

TEST_CASE("A two-sided Lambert surface reflects on the side it is seen from", "[bsdf]") {
    Material material = Lambert(Vec3(0.6f));
    material.mTwoSided = true;
    const Vec3 fix = -DirectionAt(0.7f, 1.f);  // behind the geometric normal
    const Bsdf bsdf = Make(fix, material);
    REQUIRE(bsdf.IsValid());
    REQUIRE(bsdf.CosThetaFix() == Approx(0.7f).epsilon(1e-5));
    const Vec3 back = -DirectionAt(0.5f, 3.f), front = DirectionAt(0.5f, 3.f);
    const BsdfEval eval = bsdf.Evaluate(back);
    REQUIRE(eval.mValue.x == Approx(0.6 / kPi).epsilon(1e-5));
    REQUIRE(eval.mDirPdfW == Approx(0.5 / kPi).epsilon(1e-4));
    REQUIRE(IsBlack(bsdf.Evaluate(front).mValue));
    Rng rng(351, 0);
    for (int i = 0; i < 1000; i++) {
        const std::optional<ScatterSample> sample = bsdf.Sample(rng.GetVec3());
        if (!sample) continue;
        REQUIRE(glm::dot(sample->mDirection, kNormal) < 0.f);
        REQUIRE(sample->mValue.x * sample->mCosThetaOut / sample->mPdfW == Approx(0.6f).epsilon(1e-5));
    }
    // From the front it behaves like the one-sided material.
    REQUIRE(Make(-fix, material).Evaluate(front).mValue.x == Approx(0.6 / kPi).epsilon(1e-5));
}

// ---------------------------------------------------------------------------------
// Russian roulette
// ---------------------------------------------------------------------------------

TEST_CASE("Continuation probabilities of SmallVCM's materials: floor 0.8, walls 0.803922, mirror and glass 1", "[bsdf]") {
    REQUIRE(Make(DirectionAt(0.5f, 0.f), GlossyFloor()).ContinuationProb() == Approx(0.8f).epsilon(1e-6));
    REQUIRE(Make(DirectionAt(0.5f, 0.f), Mirror()).ContinuationProb() == 1.f);
    REQUIRE(Make(DirectionAt(0.5f, 0.f), Glass()).ContinuationProb() == 1.f);
    REQUIRE(Make(-DirectionAt(0.5f, 0.f), Glass()).ContinuationProb() == 1.f);
    // The same from the materials of the scene files (cornell_0 has the glossy floor and
    // the blue back wall; every wall's largest channel is 0.803922).
    const Scene scene = testutil::LoadCornell(0, 16, 16);
    int checked = 0;
    for (const Material& material : scene.mMaterials) {
        INFO(material.mName);
        double expected = -1.0;
        if (material.mName.find("glossy floor") != std::string::npos) expected = 0.8;
        else if (material.mName.find("mirror") != std::string::npos || material.mName.find("glass") != std::string::npos) expected = 1.0;
        else if (material.mName.find("wall") != std::string::npos || material.mName.find("white") != std::string::npos) expected = 0.803922;
        REQUIRE(expected > 0.0);
        REQUIRE(material.ContinuationProbability() == Approx(expected).epsilon(1e-6));
        REQUIRE(Make(DirectionAt(0.5f, 0.f), material).ContinuationProb() == Approx(expected).epsilon(1e-6));
        checked++;
    }
    REQUIRE(checked == 7);
}

// ---------------------------------------------------------------------------------
// Tinted and partly transmissive glass (glTF's KHR_materials_transmission rule)
// ---------------------------------------------------------------------------------

TEST_CASE("Half glass: reflection 0.5 F untinted plus the opaque mirror in front, refraction 0.5 (1 - F) b, picked by luminance", "[bsdf][glass]") {
    // HalfGlass: diffuse 0.48 b, mirror 0.5 x F + 0.02 (front side only), refraction
    // (1 - F) 0.5 b; selection weights Lum(0.48 b), 0.5 F + 0.02, (1 - F) Lum(0.5 b) in
    // front, 0.5 F and (1 - F) Lum(0.5 b) behind (the opaque share is one-sided).
    const Material material = HalfGlass();
    const double lumB = 0.212671 * 0.8 + 0.715160 * 0.5 + 0.072169 * 0.2;
    for (const float cosIn : {0.95f, 0.6f, 0.2f, -0.99f, -0.85f, -0.3f}) {
        INFO("cos incident " << cosIn);
        const bool front = cosIn > 0.f;
        const Vec3 fix = front ? DirectionAt(cosIn, 0.7f) : -DirectionAt(-cosIn, 0.7f);
        const double fresnel = front ? FresnelReference(cosIn, 1.0, 1.5) : FresnelReference(-cosIn, 1.5, 1.0);
        const double eta = front ? 1.0 / 1.5 : 1.5;  // eta_fix / eta_gen
        const double wDiffuse = front ? 0.48 * lumB : 0.0, wReflect = 0.5 * fresnel + (front ? 0.02 : 0.0),
                     wRefract = (1.0 - fresnel) * 0.5 * lumB, total = wDiffuse + wReflect + wRefract;
        for (const Transport transport : {Transport::kImportance, Transport::kRadiance}) {
            const Bsdf bsdf = Make(fix, material, transport);
            REQUIRE(bsdf.IsValid());
            CHECK(bsdf.IsDelta() == !front);
            const float justAboveDiffuse = float(wDiffuse / total) + 1e-4f;
            const std::optional<ScatterSample> reflect = bsdf.Sample(Vec3(0.3f, 0.3f, justAboveDiffuse));
            const std::optional<ScatterSample> refract = bsdf.Sample(Vec3(0.3f, 0.3f, 0.99999f));
            REQUIRE(reflect);
            REQUIRE(reflect->mEvent == kEventReflect);
            CHECK(reflect->mPdfW == Approx(wReflect / total).epsilon(1e-5));
            for (int c = 0; c < 3; c++)
                CHECK(reflect->mValue[c] * reflect->mCosThetaOut == Approx(0.5 * fresnel + (front ? 0.02 : 0.0)).epsilon(1e-5));
            if (fresnel == 1.0) continue;  // total internal reflection: nothing refracts
            REQUIRE(refract);
            REQUIRE(refract->mEvent == kEventRefract);
            CHECK(refract->mPdfW == Approx(wRefract / total).epsilon(1e-5));
            const double scale = transport == Transport::kRadiance ? eta * eta : 1.0;
            for (int c = 0; c < 3; c++)
                CHECK(refract->mValue[c] * refract->mCosThetaOut == Approx((1.0 - fresnel) * 0.5 * kTint[c] * scale).epsilon(1e-5));
        }
    }
}

TEST_CASE("Half glass and tinted glass return their albedo per channel: 0.5 F + 0.02 + 0.5 (1 - F) b + 0.48 b in front, 0.5 F + 0.5 (1 - F) b behind", "[bsdf][glass]") {
    // Monte Carlo albedo (importance, no eta^2) against the sum of the components'
    // albedos, within 4 measured standard errors; every sample weighs its component's
    // reflectance over its luminance share, so the SE is the spread of those weights.
    for (const float cosIn : {0.9f, 0.5f, 0.1f, -0.95f, -0.7f}) {
        const bool front = cosIn > 0.f;
        const Vec3 fix = front ? DirectionAt(cosIn, 1.1f) : -DirectionAt(-cosIn, 1.1f);
        const double fresnel = front ? FresnelReference(cosIn, 1.0, 1.5) : FresnelReference(-cosIn, 1.5, 1.0);
        for (int c = 0; c < 3; c++) {
            INFO("cos incident " << cosIn << ", channel " << c);
            const double half = 0.5 * fresnel + 0.5 * (1.0 - fresnel) * kTint[c] + (front ? 0.02 + 0.48 * kTint[c] : 0.0);
            const MeanAndError albedo = Albedo(Make(fix, HalfGlass(), Transport::kImportance), 40000, 340, c);
            INFO("half glass: " << albedo.mean << " +- " << albedo.standardError << ", expected " << half);
            CHECK(std::abs(albedo.mean - half) <= 4.0 * albedo.standardError + 1e-6);
            const double tinted = fresnel + (1.0 - fresnel) * kTint[c];
            const MeanAndError glass = Albedo(Make(fix, TintedGlass(), Transport::kImportance), 40000, 341, c);
            INFO("tinted glass: " << glass.mean << " +- " << glass.standardError << ", expected " << tinted);
            CHECK(std::abs(glass.mean - tinted) <= 4.0 * glass.standardError + 1e-6);
        }
    }
}

TEST_CASE("A base-colour texel tints glass's refraction and its opaque share above the untinted part, never its Fresnel reflection", "[bsdf][glass]") {
    Material material = HalfGlass();
    material.mOpaqueMirror = Vec3(0.1f);
    material.mSpecularUntinted = Vec3(0.02f);
    const Vec3 texel(0.5f, 1.f, 0.25f);
    const float cosIn = 0.7f;
    const double fresnel = FresnelReference(cosIn, 1.0, 1.5);
    Bsdf bsdf;
    bsdf.Setup(DirectionAt(cosIn, 0.2f), kNormal, material, Transport::kImportance, &texel);
    REQUIRE(bsdf.IsValid());
    // The diffuse pick's f is Lambert's 0.48 b texel / pi.
    const std::optional<ScatterSample> diffuse = bsdf.Sample(Vec3(0.4f, 0.6f, 0.f));
    REQUIRE(diffuse);
    REQUIRE(diffuse->mEvent == kEventDiffuse);
    const std::optional<ScatterSample> refract = bsdf.Sample(Vec3(0.3f, 0.3f, 0.99999f));
    REQUIRE(refract);
    REQUIRE(refract->mEvent == kEventRefract);
    // The reflection: the largest z below the refraction's share picks it.
    const double lumD = Luminance(0.48f * kTint * texel), lumT = Luminance(0.5f * kTint * texel);
    const double wReflect = 0.5 * fresnel + Luminance(Vec3(0.02f) + 0.08f * texel);
    const double total = lumD + wReflect + (1.0 - fresnel) * lumT;
    const std::optional<ScatterSample> reflect = bsdf.Sample(Vec3(0.3f, 0.3f, float((lumD + 0.5 * wReflect) / total)));
    REQUIRE(reflect);
    REQUIRE(reflect->mEvent == kEventReflect);
    for (int c = 0; c < 3; c++) {
        INFO("channel " << c);
        CHECK(diffuse->mValue[c] == Approx(0.48 * kTint[c] * texel[c] / kPi).epsilon(1e-5));
        CHECK(refract->mValue[c] * refract->mCosThetaOut == Approx((1.0 - fresnel) * 0.5 * kTint[c] * texel[c]).epsilon(1e-5));
        CHECK(reflect->mValue[c] * reflect->mCosThetaOut == Approx(0.5 * fresnel + 0.02 + 0.08 * texel[c]).epsilon(1e-5));
    }
    CHECK(refract->mPdfW == Approx((1.0 - fresnel) * lumT / total).epsilon(1e-5));
}

TEST_CASE("Clear glass, a plain mirror and Lambert give the same bits with the default transmittance and opaque mirror as without those terms", "[bsdf][glass]") {
    // The defaults (transmittance 1, opaque mirror 0) must enter exactly: 1 x and + 0 in
    // float, and Luminance(1, 1, 1) == 1 (what keeps the golden images bit for bit).
    CHECK(Luminance(Vec3(1.f)) == 1.f);
    for (const float cosIn : {0.8f, 0.3f, -0.9f}) {
        const Vec3 fix = cosIn > 0.f ? DirectionAt(cosIn, 0.4f) : -DirectionAt(-cosIn, 0.4f);
        const Bsdf bsdf = Make(fix, Glass(), Transport::kRadiance);
        const float fresnel = FresnelDielectric(bsdf.CosThetaFix(), 1.6f);
        const std::optional<ScatterSample> reflect = bsdf.Sample(Vec3(0.5f, 0.5f, 0.f));
        const std::optional<ScatterSample> refract = bsdf.Sample(Vec3(0.5f, 0.5f, 0.99999f));
        REQUIRE(reflect);
        REQUIRE(refract);
        CHECK(reflect->mPdfW == fresnel / (fresnel + (1.f - fresnel)));
        CHECK(reflect->mValue.x == fresnel * 1.f / reflect->mCosThetaOut);
        const float eta = cosIn > 0.f ? 1.f / 1.6f : 1.6f;
        CHECK(refract->mValue.x == (1.f - fresnel) * (eta * eta) / refract->mCosThetaOut);
    }
}
