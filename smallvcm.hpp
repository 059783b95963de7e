// smallvcm.hpp — a small, readable renderer of every estimator from eye light to VCM.
//
// =====================================================================================
//  WHAT IT IS
// =====================================================================================
//  One C++17 header that implements, in the order light-transport courses teach them:
//    el   eye light (|cos| shading, back faces red: a geometry check, not an estimator)
//    pt   path tracing with next-event estimation and MIS
//    lt   light tracing (paths from the lights splatted onto the image)
//    pm   photon mapping: a kd-tree of photons, k nearest, visualised at the first hit
//    pmfg photon mapping with the partitioned estimator and final gathering
//    ppm  progressive photon mapping (merging at the first non-specular camera vertex)
//    bpm  bidirectional photon mapping (merging at every camera vertex, with MIS)
//    bpt  bidirectional path tracing (vertex connection, with MIS)
//    vcm  vertex connection and merging (BPT + BPM under one MIS)
//  The MIS weights of the last five follow Georgiev's technical report "Implementing
//  Vertex Connection and Merging" (2012/2013); every MIS line cites it as
//  [tech. rep. (NN)] so that the code can be read with the report open beside it.
//  Light also travels through homogeneous participating media (fog, smoke, absorbing
//  glass) in every one of them but pm and pmfg: ppm, bpm and vcm merge photon points in
//  media with the 3D kernel of Krivanek et al.'s "Unifying Points, Beams, and Paths in
//  Volumetric Light Transport Simulation" (2014).
//
// =====================================================================================
//  HOW TO USE IT
// =====================================================================================
//  In every translation unit that needs it:
//      #include "smallvcm.hpp"
//  In exactly ONE translation unit of the program, before the include:
//      #define SMALLVCM_IMPLEMENTATION
//      #include "smallvcm.hpp"
//  That unit compiles the parts with heavy dependencies: the glTF loader (tinygltf,
//  nlohmann-json; compressed geometry through Debian's compiled Draco and meshoptimizer
//  libraries: link with -ldraco -lmeshoptimizer) and the image writers and readers
//  (stb_image_write; OpenEXR through Debian's compiled tinyexr library: link with
//  -ltinyexr). Everything else is inline.
//
//  Link errors you may meet:
//    "undefined reference to smallvcm::LoadGltfScene / WriteImage"
//        -> no translation unit defines SMALLVCM_IMPLEMENTATION.
//    "multiple definition of tinygltf::... / stbi_write_..."
//        -> two translation units define SMALLVCM_IMPLEMENTATION.
//    "undefined reference to pthread_create"  -> link with -pthread.
//    "undefined reference to SaveEXRImageToMemory / LoadEXRImageFromMemory"
//        -> link with -ltinyexr (after the objects).
//    "undefined reference to draco::... / meshopt_decode..."
//        -> link with -ldraco -lmeshoptimizer (after the objects).
//
//  A minimal program (examples/minimal.cpp is this, character for character; a test
//  keeps the two the same, and `make` builds it: run it from the repository's folder):
//      #define SMALLVCM_IMPLEMENTATION
//      #include "smallvcm.hpp"
//
//      int main() {
//          try {
//              smallvcm::Scene scene = smallvcm::LoadGltfScene("scenes/cornell_4_default.gltf");
//              scene.mCamera.SetResolution(256, 256);
//              smallvcm::RenderOptions options;
//              options.mAlgorithm = smallvcm::Algorithm::kVertexConnectionMerging;
//              options.mIterations = 16;
//              smallvcm::RenderResult result = smallvcm::Render(scene, options);
//              smallvcm::WriteImage("vcm.png", result.mImage);
//          } catch (const smallvcm::Error& e) {
//              std::fprintf(stderr, "%s\n", e.what());
//              return 1;
//          }
//          return 0;
//      }
//
//  Errors: every problem with input (a scene file, an option, an image path) throws
//  smallvcm::Error, whose what() is one line naming the file or option and the problem.
//  Nothing else in the library throws on purpose.
//
//  Your own integrator: a class derived from AbstractRenderer that overrides
//  RunIteration(iteration, sampler) renders through the same loop as the built-ins:
//      smallvcm::Render(scene, options, smallvcm::MakeIntegrator<MyTracer>("mine", "my tracer"));
//  RegisterIntegrator (or a static IntegratorRegistration) makes it known by name, to
//  FindIntegrator and to the command line's -a. [SECTION] Integrator interface states the
//  contract; docs/writing-an-integrator.md walks through examples/my_path_tracer.hpp.
//
// =====================================================================================
//  CONFIGURATION MACROS (define before including)
// =====================================================================================
//    SMALLVCM_IMPLEMENTATION  compile the glTF loader and image writers here (one TU).
//    SMALLVCM_CHECKS          check numerical invariants while rendering (every film
//                             contribution and MIS quantity finite and non-negative);
//                             a violation aborts with the place and values. Slower;
//                             `make check` builds with it.
//    SMALLVCM_BVH_SCALAR      trace with the BVH's portable scalar loops instead of SSE/AVX
//                             vector code (same hits bit for bit; [SECTION] Appendix: BVH).
//    (no macro: -mavx2)       compiled for AVX2 (-mavx2, or -march=native
//                             -ffp-contract=off), the BVH is 8 wide instead of 4: about
//                             1.2x the rays per second on large meshes. The Makefile adds
//                             -mavx2 when the build machine has AVX2 (make BVH_ARCH= for
//                             the 4-wide SSE build). Compile every translation unit with
//                             the same flags.
//
// =====================================================================================
//  CONVENTIONS (shared with SmallVCM, so images can be compared)
// =====================================================================================
//  * Path length = number of segments, counted from the camera: a visible emitter is 1.
//  * Directions at a BSDF are "Fix" (the one we arrived along) and "Gen" (the one we
//    generate). pdfs end in W (solid angle) or A (area). Members mFoo, arguments aFoo,
//    outputs oFoo, as in SmallVCM and the report's notation (dVCM, dVC, dVM, eta).
//  * Non-specular surfaces are one-sided: they reflect only on the side their
//    geometric normal (counter-clockwise winding) points to. Emitters are one-sided too
//    (unless built two-sided: glTF doubleSided emissive materials)
//    and reflect only if their material says so (SmallVCM's lights, and glTF emitters
//    without a SMALLVCM_material, are black).
//  * Raster y = 0 is the top image row. Film values are radiance, no tone mapping.
//
// =====================================================================================
//  INDEX (search for "[SECTION] name")
// =====================================================================================
//  PART I: what a course teaches, in the order data flows
//  [SECTION] Configuration and errors
//  [SECTION] Math
//  [SECTION] Random numbers and sampling
//  [SECTION] Geometry: ray, sphere, triangle, BVH        (the BVH by its contract)
//  [SECTION] Scene: materials, lights, camera
//  [SECTION] Participating media     (transmittance, free flight, phase function,
//      the walks through media: TraceSegment, TraceConnection)
//  [SECTION] BSDF                    (a point in a medium is a Bsdf too: SetupInMedium)
//  [SECTION] Film
//  [SECTION] Integrator interface
//  [SECTION] Integrator: eye light
//  [SECTION] Integrator: path tracing
//  [SECTION] Integrator: photon mapping (classic)   (the k-nearest search by its contract)
//  [SECTION] Integrator: the VertexCM family (LT, PPM, BPM, BPT, VCM)
//      the MIS quantities (VcmMis), the range search by its contract, and VertexCM's
//      stages: 1. light sub-paths (TraceLightSubpath; light tracing: ConnectToCamera),
//      2. the range search over their vertices, 3. camera sub-paths
//      (TraceCameraSubpath: CameraHitsLight, next-event estimation ConnectToLight,
//      vertex connection ConnectVertices, merging MergeWithLightVertices)
//  PART II: appendices a student may skip, each behind an interface Part I states
//  [SECTION] Appendix: BVH
//  [SECTION] Appendix: range search    (the hashed grid; the points along rays; the kd-tree)
//  [SECTION] Appendix: film splats       (light tracing's additions, a batch at a time)
//  [SECTION] Render loop                 (threads, budgets, progress, Ctrl-C)
//  [SECTION] Image output and metrics
//  [SECTION] Scene loading (glTF)
//  [SECTION] Implementation (SMALLVCM_IMPLEMENTATION)
//      untrusted files, glTF loading, image writers and readers

#ifndef SMALLVCM_HPP
#define SMALLVCM_HPP

#include <glm/glm.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <new>
#include <numeric>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <tuple>
#include <type_traits>
#include <utility>
#include <vector>

#if defined(__unix__) || defined(__APPLE__)
#include <unistd.h>
#endif
#if defined(__linux__)
#include <sys/mman.h>  // madvise: the BVH's arrays on huge pages ([SECTION] Appendix: BVH)
#endif

namespace smallvcm {

// =====================================================================================
// [SECTION] Configuration and errors
// =====================================================================================
// Provides: the library's one exception type and the numeric tolerances every later
// section shares. The tolerances are SmallVCM's, so that images can be compared.

// Every input problem the library detects is reported as an Error whose message is
// one line: "<file or option>: <problem>".
class Error : public std::runtime_error {
public:
    explicit Error(const std::string& aMessage) : std::runtime_error(aMessage) {}
};

// A number as an error message shows it: three significant digits ("1e+30", "0.25").
inline std::string ShortNumber(double aValue) {
    char text[32];
    std::snprintf(text, sizeof text, "%.3g", aValue);
    return text;
}

// Numerical invariant checks, compiled in with SMALLVCM_CHECKS (see the manual above).
#ifdef SMALLVCM_CHECKS
#define SMALLVCM_CHECK(aCondition, aWhat)                                                        \
    do {                                                                                         \
        if (!(aCondition)) {                                                                     \
            std::fprintf(stderr, "smallvcm: check failed at %s:%d: %s\n", __FILE__, __LINE__, aWhat); \
            std::abort();                                                                        \
        }                                                                                        \
    } while (false)
#else
#define SMALLVCM_CHECK(aCondition, aWhat) ((void)0)
#endif

// A hit whose direction makes |cos| below this with the normal is treated as grazing
// and dropped: its contribution would be divided by that cosine (SmallVCM: EPS_COSINE).
inline constexpr float kEpsCosine = 1e-6f;
// The Phong lobe is cut where cos(R, w) falls below this (SmallVCM: EPS_PHONG).
inline constexpr float kEpsPhong = 1e-3f;
// New rays start this far along their direction, relative to the scene's bounding
// radius. 4.51e-4 * 2.2170596 = 1e-3, SmallVCM's absolute EPS_RAY in its Cornell box;
// making it relative keeps scenes of any scale working.
inline constexpr float kRayEpsilonPerSceneRadius = 1e-3f / 2.2170596f;
// The index-matched boundaries a ray may cross before it is taken as lost (a bound on
// every walk through media: hostile geometry cannot make one endless).
inline constexpr int kMaxMediumCrossings = 256;
// A triangle whose edges make an angle with sine below this is a line or a point: its
// normal would be rounding noise. Edges and cross product are computed in double from
// float vertices (exact differences, products rounded at 1e-16), so anything above this
// is a real, if thin, triangle.
inline constexpr double kCollinearSine = 1e-12;
// Limits on a light, so that the estimators' float arithmetic cannot overflow: the power
// it emits (radiance x pi x area, intensity x 4 pi, ...) and 1 / its area (the area pdf).
// Both keep several orders of magnitude between the limit and float overflow in every
// estimator (tests/test_stability.cpp renders at the limits).
inline constexpr float kMaxLightPower = 1e30f;
inline constexpr float kMinLightArea = 1e-30f;

// =====================================================================================
// [SECTION] Math
// =====================================================================================
// Provides: vector aliases over GLM, small helpers, and Frame, an orthonormal basis
// used to move directions between world space and a surface's local space (z = normal).

using Vec2 = glm::vec2;
using Vec3 = glm::vec3;
using Vec4 = glm::vec4;

inline constexpr float kPi = 3.14159265358979323846f;
inline constexpr float kInvPi = 1.f / kPi;

inline float Sqr(float aX) { return aX * aX; }
inline float MaxComponent(const Vec3& aV) { return std::max(aV.x, std::max(aV.y, aV.z)); }
inline bool IsBlack(const Vec3& aV) { return aV.x <= 0.f && aV.y <= 0.f && aV.z <= 0.f; }
inline bool IsFinite(const Vec3& aV) {
    return std::isfinite(aV.x) && std::isfinite(aV.y) && std::isfinite(aV.z);
}
// A function the compiler must not inline: a rarely taken branch's body, which would
// otherwise make its caller too large to be inlined itself. And one it must inline: a
// small, hot function the compiler's size limits would keep out of line (each call then
// costs more than the function's own work; Bsdf::Evaluate), or a technique whose returned
// contribution should stay in registers instead of going through memory (VertexCM's).
#if defined(__GNUC__) || defined(__clang__)
#define SMALLVCM_NOINLINE __attribute__((noinline))
#define SMALLVCM_ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define SMALLVCM_NOINLINE
#define SMALLVCM_ALWAYS_INLINE inline
#endif
// Luminance with the sRGB / Rec. 709 weights; SmallVCM uses it to pick BSDF components.
inline float Luminance(const Vec3& aRgb) {
    return 0.212671f * aRgb.x + 0.715160f * aRgb.y + 0.072169f * aRgb.z;
}

// Orthonormal basis with z along a given unit vector. The construction is the
// branch-free one of Duff et al. (2017): continuous everywhere except z = -1 exactly.
struct Frame {
    Vec3 mX{1, 0, 0}, mY{0, 1, 0}, mZ{0, 0, 1};

    Frame() = default;
    explicit Frame(const Vec3& aZ) { SetFromZ(aZ); }

    void SetFromZ(const Vec3& aZ) {
        mZ = aZ;
        const float sign = std::copysign(1.f, aZ.z);
        const float a = -1.f / (sign + aZ.z);
        const float b = aZ.x * aZ.y * a;
        mX = Vec3(1.f + sign * aZ.x * aZ.x * a, sign * b, -sign * aZ.x);
        mY = Vec3(b, sign + aZ.y * aZ.y * a, -aZ.y);
    }
    Vec3 ToWorld(const Vec3& aLocal) const { return mX * aLocal.x + mY * aLocal.y + mZ * aLocal.z; }
    // Forced inline: it is called for every BSDF evaluation, and a call costs more than it.
    SMALLVCM_ALWAYS_INLINE Vec3 ToLocal(const Vec3& aWorld) const {
        return Vec3(glm::dot(aWorld, mX), glm::dot(aWorld, mY), glm::dot(aWorld, mZ));
    }
};

// =====================================================================================
// [SECTION] Random numbers and sampling
// =====================================================================================
// Provides: Rng (PCG32: 8 bytes of state, statistically strong, and seedable by
// (seed, stream) so that every iteration of a render has its own reproducible stream),
// Sampler (what the estimators draw from: Rng's numbers, or Owen-scrambled Sobol points),
// and every sampling routine the integrators use, each beside the pdf it returns, so a
// test can check that the two agree. Local directions are in a Frame: z is the axis.

class Rng {
public:
    explicit Rng(uint64_t aSeed = 1234, uint64_t aStream = 0) {
        mIncrement = (aStream << 1u) | 1u;
        mState = 0;
        NextUint();
        mState += aSeed;
        NextUint();
    }
    // PCG-XSH-RR (O'Neill 2014): 64-bit LCG state, 32-bit permuted output.
    uint32_t NextUint() {
        const uint64_t old = mState;
        mState = old * 6364136223846793005ull + mIncrement;
        const uint32_t xorShifted = uint32_t(((old >> 18u) ^ old) >> 27u);
        const uint32_t rotation = uint32_t(old >> 59u);
        return (xorShifted >> rotation) | (xorShifted << ((32u - rotation) & 31u));
    }
    // Uniform in [0, 1): the top 24 bits make every float exactly representable.
    float GetFloat() { return float(NextUint() >> 8) * (1.f / 16777216.f); }
    Vec2 GetVec2() { const float a = GetFloat(); return Vec2(a, GetFloat()); }
    Vec3 GetVec3() { const float a = GetFloat(); const float b = GetFloat(); return Vec3(a, b, GetFloat()); }

private:
    uint64_t mState = 0;
    uint64_t mIncrement = 1;
};

// SplitMix64 (Steele et al. 2014): a bijective 64-bit mix whose outputs for consecutive
// inputs look independent. Seeds derived from (seed, index) pairs go through it.
inline uint64_t SplitMix64(uint64_t aX) {
    aX += 0x9E3779B97F4A7C15ull;
    aX = (aX ^ (aX >> 30)) * 0xBF58476D1CE4E5B9ull;
    aX = (aX ^ (aX >> 27)) * 0x94D049BB133111EBull;
    return aX ^ (aX >> 31);
}

// --- Sobol points, Owen-scrambled ----------------------------------------------------
// A point of a base-2 digital sequence is x = C i: the index's bits i_0 i_1 ... times a
// generator matrix C over GF(2) give the binary digits of x. Sobol's sequence (1967)
// gives dimension j the matrix whose column k is the direction number v_{k+1}, from a
// primitive polynomial x^s + a_1 x^{s-1} + ... + a_{s-1} x + 1 over GF(2) and s odd
// initial integers m_1..m_s (m_k < 2^k, v_k = m_k / 2^k) by the recurrence
//     v_k = a_1 v_{k-1} XOR a_2 v_{k-2} XOR ... XOR a_{s-1} v_{k-s+1} XOR v_{k-s} XOR v_{k-s} / 2^s.
// Dimension 0 is van der Corput's (v_k = 2^-k: x is the index's bits mirrored about the
// binary point). Each v_k has its leading 1 at digit k (m_k odd), so C is upper
// triangular with a unit diagonal: every dimension alone puts one point of each aligned
// block of 2^m indices (the first 2^m among them) in each cell of width 2^-m. Two
// dimensions form (t,m,2)-nets; dimensions 0 and 1 are a (0,2)-sequence (t = 0: one
// point in each of the 2^m boxes of size 2^-a x 2^-b, a + b = m). The polynomials and
// initial numbers of dimensions 1-31 are Joe and Kuo's (2008, file new-joe-kuo-6.21201),
// chosen so that pairs of dimensions have small t. Digits are 32-bit fixed point
// (bit 31 is 1/2).
namespace detail {
struct SobolPolynomial {
    int mDegree;             // s
    uint32_t mCoefficients;  // a_1 .. a_{s-1}, a_1 the most significant bit
    uint32_t mInitial[7];    // m_1 .. m_s
};
inline constexpr SobolPolynomial kJoeKuo[] = {
    {1, 0, {1}},                        {2, 1, {1, 3}},                       {3, 1, {1, 3, 1}},
    {3, 2, {1, 1, 1}},                  {4, 1, {1, 1, 3, 3}},                 {4, 4, {1, 3, 5, 13}},
    {5, 2, {1, 1, 5, 5, 17}},           {5, 4, {1, 1, 5, 5, 5}},              {5, 7, {1, 1, 7, 11, 19}},
    {5, 11, {1, 1, 5, 1, 1}},           {5, 13, {1, 1, 1, 3, 11}},            {5, 14, {1, 3, 5, 5, 31}},
    {6, 1, {1, 3, 3, 9, 7, 49}},        {6, 13, {1, 1, 1, 15, 21, 21}},       {6, 16, {1, 3, 1, 13, 27, 49}},
    {6, 19, {1, 1, 1, 15, 7, 5}},       {6, 22, {1, 3, 1, 15, 13, 25}},       {6, 25, {1, 1, 5, 5, 19, 61}},
    {7, 1, {1, 3, 7, 11, 23, 15, 103}}, {7, 4, {1, 3, 7, 13, 13, 15, 69}},    {7, 7, {1, 1, 3, 13, 7, 35, 63}},
    {7, 8, {1, 3, 5, 9, 1, 25, 53}},    {7, 14, {1, 3, 1, 13, 9, 35, 107}},   {7, 19, {1, 3, 1, 5, 27, 61, 31}},
    {7, 21, {1, 1, 5, 11, 19, 41, 61}}, {7, 28, {1, 3, 5, 3, 3, 13, 69}},     {7, 31, {1, 1, 7, 13, 1, 19, 1}},
    {7, 32, {1, 3, 7, 5, 13, 19, 59}},  {7, 37, {1, 1, 3, 9, 25, 29, 41}},    {7, 41, {1, 3, 5, 13, 23, 1, 55}},
    {7, 42, {1, 3, 7, 3, 13, 59, 17}},
};
inline constexpr int kSobolDimensions = 1 + int(sizeof(kJoeKuo) / sizeof(kJoeKuo[0]));

// Column k of dimension j's generator matrix: v_{k+1} as 32-bit fixed point.
constexpr std::array<std::array<uint32_t, 32>, kSobolDimensions> MakeSobolMatrices() {
    std::array<std::array<uint32_t, 32>, kSobolDimensions> columns{};
    for (int k = 0; k < 32; k++) columns[0][size_t(k)] = 1u << (31 - k);
    for (int j = 1; j < kSobolDimensions; j++) {
        const SobolPolynomial& p = kJoeKuo[j - 1];
        std::array<uint32_t, 32>& v = columns[size_t(j)];
        for (int k = 0; k < 32; k++) {
            if (k < p.mDegree) {
                v[size_t(k)] = p.mInitial[k] << (31 - k);
                continue;
            }
            uint32_t next = v[size_t(k - p.mDegree)] ^ (v[size_t(k - p.mDegree)] >> p.mDegree);
            for (int i = 1; i < p.mDegree; i++)
                if ((p.mCoefficients >> (p.mDegree - 1 - i)) & 1u) next ^= v[size_t(k - i)];
            v[size_t(k)] = next;
        }
    }
    return columns;
}
inline constexpr std::array<std::array<uint32_t, 32>, kSobolDimensions> kSobolMatrices = MakeSobolMatrices();

// C i: the XOR of the columns aColumns[k] of the index's set bits k.
inline uint32_t XorOfColumns(const std::array<uint32_t, 32>& aColumns, uint32_t aIndex) {
    uint32_t digits = 0;
    for (size_t k = 0; aIndex; aIndex >>= 1, k++) digits ^= aColumns[k] & (0u - (aIndex & 1u));
    return digits;
}
// The digits of point aIndex's coordinate aDimension.
inline uint32_t SobolDigits(uint32_t aIndex, int aDimension) { return XorOfColumns(kSobolMatrices[size_t(aDimension)], aIndex); }

constexpr uint32_t ReverseBits32(uint32_t aX) {
    aX = (aX << 16) | (aX >> 16);
    aX = ((aX & 0x00ff00ffu) << 8) | ((aX & 0xff00ff00u) >> 8);
    aX = ((aX & 0x0f0f0f0fu) << 4) | ((aX & 0xf0f0f0f0u) >> 4);
    aX = ((aX & 0x33333333u) << 2) | ((aX & 0xccccccccu) >> 2);
    return ((aX & 0x55555555u) << 1) | ((aX & 0xaaaaaaaau) >> 1);
}

// Owen's nested uniform scrambling (1995): digit k of x is flipped or not at random,
// the coin depending on the digits before it. A box of a net then goes to a box of
// the same shape (the net property stays) and each scrambled point is uniform on
// [0, 1). The coins come from a hash in the Laine-Karras form (2011), with Burley's
// (2020) constants: on the digits reversed (the first digit in bit 0), each step below
// changes bit j by a function of bits 0..j-1 only (x * even and the carries of + and
// * odd move information upwards), so bit j is flipped by a function of the bits
// below it — a nested scramble, seeded by aSeed.
// OwenScrambleReversed works on the reversed digits and returns them reversed.
inline uint32_t OwenScrambleReversed(uint32_t aReversedDigits, uint32_t aSeed) {
    uint32_t x = aReversedDigits;
    x ^= x * 0x3d20adeau;
    x += aSeed;
    x *= (aSeed >> 16) | 1u;
    x ^= x * 0x05526c56u;
    x ^= x * 0x53a22864u;
    return x;
}
inline uint32_t OwenScramble(uint32_t aDigits, uint32_t aSeed) {
    return ReverseBits32(OwenScrambleReversed(ReverseBits32(aDigits), aSeed));
}

// The same columns with their digits reversed (the first digit in bit 0), the form the
// scramble below works in: C i reversed is the XOR of these columns.
constexpr std::array<std::array<uint32_t, 32>, kSobolDimensions> MakeReversedSobolMatrices() {
    std::array<std::array<uint32_t, 32>, kSobolDimensions> columns = MakeSobolMatrices();
    for (std::array<uint32_t, 32>& dimension : columns)
        for (uint32_t& column : dimension) column = ReverseBits32(column);
    return columns;
}
inline constexpr std::array<std::array<uint32_t, 32>, kSobolDimensions> kReversedSobolMatrices = MakeReversedSobolMatrices();

// The top 24 digits as a float in [0, 1), as Rng::GetFloat.
inline float DigitsToFloat(uint32_t aDigits) { return float(aDigits >> 8) * (1.f / 16777216.f); }

// The same from reversed digits (the first digit in bit 0): the low 24 bits mirrored,
// a byte at a time through a table of the 256 bytes mirrored.
constexpr std::array<uint8_t, 256> MakeReversedBytes() {
    std::array<uint8_t, 256> bytes{};
    for (uint32_t b = 0; b < 256; b++) bytes[b] = uint8_t(ReverseBits32(b) >> 24);
    return bytes;
}
inline constexpr std::array<uint8_t, 256> kReversedBytes = MakeReversedBytes();
inline float ReversedDigitsToFloat(uint32_t aReversed) {
    const uint32_t digits24 = uint32_t(kReversedBytes[aReversed & 0xffu]) << 16 |
                              uint32_t(kReversedBytes[(aReversed >> 8) & 0xffu]) << 8 | kReversedBytes[(aReversed >> 16) & 0xffu];
    return float(digits24) * (1.f / 16777216.f);
}
}  // namespace detail

// Coordinate aDimension (< detail::kSobolDimensions) of point aIndex of the Sobol
// sequence, Owen-scrambled with aSeed: every point is uniform on [0, 1), and the
// scrambled sequence keeps the nets of the unscrambled one.
inline float ScrambledSobol(uint32_t aIndex, int aDimension, uint32_t aSeed) {
    return detail::DigitsToFloat(detail::OwenScramble(detail::SobolDigits(aIndex, aDimension), aSeed));
}

// --- Samplers: where an estimator's random numbers come from --------------------------
// An estimator asks its Sampler for one dimension (Get1D), two (Get2D) or three (Get3D:
// a BSDF sample's direction and its component pick), and says before each path which
// sample it starts: StartPixelSample(pixel) for a camera sub-path, StartLightPath(p, N) for
// the p-th of the iteration's N light sub-paths (photons). An estimator that connects a
// camera sub-path to a light sub-path connects pixel q's to light sub-path
// LightPathOfPixel(q, N). One Sampler serves one iteration.
// Two kinds:
//  * independent: every number the next one of the iteration's Rng, in the order asked
//    (Start does nothing): plain Monte Carlo, whose variance falls as 1/N.
//  * sobol: randomised quasi-Monte Carlo. A path's numbers are the coordinates of one
//    point of an Owen-scrambled Sobol sequence, in the order asked: its first request
//    reads dimension 0 (and 1, if 2D), the next ones the following dimensions. Which
//    point, of which randomisation:
//      camera sub-path:  index = the iteration number i,  seeds from (its pixel, dimension);
//      light sub-path p: index = i N + p (its number in the run), seeds from the dimension.
//    A pixel's first 2^k iterations thus put one sample in each 2^-k cell of every
//    dimension, and dimensions 0 and 1 (the pixel position) form a (0,k,2)-net. The light
//    sub-paths of iterations 0 .. I-1 are the first I N points of one scrambled sequence,
//    stratified together in the same way: the splats of light tracing and the merges,
//    which sum over all light sub-paths, see one stratified set, not I independent ones.
//    (An index is 32 bits: past 2^32 light sub-paths the index's high part, i N + p
//    divided by 2^32, joins the seeds, so each block of 2^32 is another scramble.)
//    Pairing. Indices i N + p and (i+1) N + p differ only in the high bits when N is a
//    power of two, and the coarse digits come from the low bits: light sub-paths p of
//    every iteration share a cell of width 1/N in dimension 0. A pixel that always
//    connected to light sub-path p would see only light sub-paths of that cell. So
//    LightPathOfPixel(q, N) is a permutation of 0 .. N-1 drawn anew each iteration,
//    (a q + b) mod N with a coprime to N, a and b hashed from the seed and iteration:
//    over the iterations a pixel's light sub-paths come from all over the set.
//    Iterations of one run are not independent (a pixel's camera sub-paths, and all the
//    light sub-paths, are parts of one scrambled sequence); runs with different seeds are
//    independent in every part, so their images may be averaged as independent ones.
//    The dimensions come from one Sobol sequence rather than from independent 2D
//    sequences of the same index: the scrambled van der Corput digits of one index in two
//    such sequences are nested permutations of each other, so the first coordinates of
//    the two would fall in the same halves, quarters, ... (coupled at every scale).
//    From dimension kSobolDimensions on (long paths) the numbers are hashed independent
//    ones (a hash of seed, index and dimension).
//    Unbiased: for one point the scrambles make each coordinate uniform and, with
//    independent seeds, the coordinates independent, so each path is distributed as with
//    independent numbers; only the correlation between samples differs, which is what
//    lowers the variance (Owen 1997: for smooth integrands the variance of N scrambled
//    points falls as N^-3 up to log factors; discontinuities leave about N^-1.5).
//    A path that never called Start reads point 0 of ever new dimensions: hashed
//    independent numbers, correct but not stratified.
//    The layout is the order of requests (docs/algorithms.md, "Samplers", per estimator):
//      camera sub-path: pixel position (2); per vertex: next-event estimation where it
//        runs: light pick (1), point on the light (2); BSDF direction and component
//        (3); Russian roulette (1);
//      light sub-path, photon: light pick (1), emission direction (2), point on the
//        light (2); per vertex: BSDF (3), Russian roulette (1).
//    A technique skipped at a vertex moves the path's later requests to other
//    dimensions: every number is still uniform and independent of the others.
enum class SamplerType { kIndependent, kSobol };

inline const char* SamplerName(SamplerType aType) { return aType == SamplerType::kSobol ? "sobol" : "independent"; }
inline std::optional<SamplerType> ParseSampler(const std::string& aName) {
    if (aName == "independent") return SamplerType::kIndependent;
    if (aName == "sobol") return SamplerType::kSobol;
    return std::nullopt;
}

class Sampler {
public:
    static constexpr int kSobolDimensions = detail::kSobolDimensions;

    // Independent numbers from aRng.
    explicit Sampler(const Rng& aRng) : mRng(aRng) {}
    // Sobol points for iteration aIteration of a render seeded with aSeed.
    static Sampler Sobol(uint64_t aSeed, int aIteration) {
        Sampler sampler{Rng()};
        sampler.mType = SamplerType::kSobol;
        sampler.mIteration = uint32_t(aIteration);
        for (uint64_t domain = 0; domain < 4; domain++) sampler.mDomainSeeds[domain] = SplitMix64(aSeed ^ SplitMix64(domain + 1));
        sampler.Start(kUnstarted, sampler.mIteration, 0);
        return sampler;
    }
    SamplerType Type() const { return mType; }

    void StartPixelSample(int aPixel) { Start(kCameraPaths, uint32_t(aPixel), mIteration); }
    // Light sub-path aPath of the aPathCount of this iteration: point i N + p of the run's
    // sequence, whose 32-bit block (the index's high part) selects the scramble.
    void StartLightPath(int aPath, int aPathCount) {
        const uint64_t index = uint64_t(mIteration) * uint64_t(aPathCount) + uint64_t(aPath);
        Start(kLightPaths, uint32_t(index >> 32), uint32_t(index));
    }
    // The light sub-path (of aPathCount) that pixel aPixel's camera sub-path connects to:
    // the pixel's own with independent numbers; with Sobol points (a aPixel + b) mod N,
    // a permutation because gcd(a, N) = 1, with a and b hashed from the seed and iteration
    // (found once per iteration and N, then kept).
    int LightPathOfPixel(int aPixel, int aPathCount) {
        if (mType == SamplerType::kIndependent) return aPixel;
        const uint64_t n = uint64_t(aPathCount);
        if (n != mPairingCount) {
            const uint64_t hash = SplitMix64(mDomainSeeds[kPairing] ^ mIteration);
            uint64_t a = (hash >> 32) % n;
            while (std::gcd(a, n) != 1) a = (a + 1) % n;
            mPairingCount = n;
            mPairingA = a;
            mPairingB = hash & 0xffffffffu;
        }
        return int((mPairingA * uint64_t(aPixel) + mPairingB) % n);
    }

    float Get1D() {
        if (mType == SamplerType::kIndependent) return mRng.GetFloat();
        return NextDimension();
    }
    Vec2 Get2D() {
        if (mType == SamplerType::kIndependent) return mRng.GetVec2();
        const float a = NextDimension();
        return Vec2(a, NextDimension());
    }
    Vec3 Get3D() {
        if (mType == SamplerType::kIndependent) return mRng.GetVec3();
        const float a = NextDimension();
        const float b = NextDimension();
        return Vec3(a, b, NextDimension());
    }

private:
    enum Domain { kUnstarted = 0, kCameraPaths = 1, kLightPaths = 2, kPairing = 3 };

    // A path's scramble seeds, one per dimension in the order asked, come from an Rng seeded
    // by its domain and stream only: every point of the stream (a pixel's iterations, a
    // block of 2^32 light sub-paths) is scrambled alike, as a scrambled net must be.
    void Start(Domain aDomain, uint32_t aStream, uint32_t aIndex) {
        if (mType == SamplerType::kIndependent) return;
        mSeeds = Rng(SplitMix64(mDomainSeeds[aDomain] ^ aStream));
        mIndex = aIndex;
        mDimension = 0;
    }
    float NextDimension() {
        const uint32_t seed = mSeeds.NextUint();
        const size_t d = mDimension++;
        if (d >= size_t(kSobolDimensions)) return detail::DigitsToFloat(uint32_t(SplitMix64(seed ^ SplitMix64(mIndex)) >> 32));
        // The digits are linear in the index: C i = C j xor C (i xor j). Each dimension keeps
        // the digits of the last index it gave (j); consecutive light paths differ in few
        // low bits, and a camera sub-path's index (the iteration) not at all.
        mDigits[d] ^= detail::XorOfColumns(detail::kReversedSobolMatrices[d], mDigitsIndex[d] ^ mIndex);
        mDigitsIndex[d] = mIndex;
        return detail::ReversedDigitsToFloat(detail::OwenScrambleReversed(mDigits[d], seed));
    }

    SamplerType mType = SamplerType::kIndependent;
    Rng mRng;
    uint32_t mIteration = 0;
    uint64_t mDomainSeeds[4] = {};
    uint64_t mPairingCount = 0, mPairingA = 0, mPairingB = 0;  // LightPathOfPixel's (a q + b) mod N
    Rng mSeeds;
    uint32_t mIndex = 0;
    size_t mDimension = 0;
    // Per dimension: the reversed digits of point mDigitsIndex (point 0's are all zero).
    std::array<uint32_t, detail::kSobolDimensions> mDigits{};
    std::array<uint32_t, detail::kSobolDimensions> mDigitsIndex{};
};

// --- Cosine-weighted hemisphere around +z: pdf = cos(theta) / pi -------------------
// BEGIN EXERCISE cosine_hemisphere
inline Vec3 SampleCosHemisphereW(const Vec2& aSamples) {
    const float term1 = 2.f * kPi * aSamples.x;
    const float term2 = std::sqrt(1.f - aSamples.y);
    return Vec3(std::cos(term1) * term2, std::sin(term1) * term2, std::sqrt(aSamples.y));
}
inline float CosHemispherePdfW(const Vec3& aLocalDirection) {
    return std::max(0.f, aLocalDirection.z) * kInvPi;
}
// END EXERCISE cosine_hemisphere

// --- Power-cosine lobe around +z (the Phong lobe): pdf = (n+1)/(2 pi) cos^n ---------
// BEGIN EXERCISE phong_bsdf/lobe
inline Vec3 SamplePowerCosHemisphereW(const Vec2& aSamples, float aPower) {
    const float term1 = 2.f * kPi * aSamples.x;
    const float cosTheta = std::pow(1.f - aSamples.y, 1.f / (aPower + 1.f));
    const float sinTheta = std::sqrt(std::max(0.f, 1.f - cosTheta * cosTheta));
    return Vec3(std::cos(term1) * sinTheta, std::sin(term1) * sinTheta, cosTheta);
}
inline float PowerCosHemispherePdfW(const Vec3& aLocalDirection, float aPower) {
    if (!(aLocalDirection.z > 0.f)) return 0.f;  // pow(0, 0) = 1 would leave exponent 0 mass below
    return (aPower + 1.f) * std::pow(aLocalDirection.z, aPower) * (0.5f * kInvPi);
}
// END EXERCISE phong_bsdf/lobe

// --- Uniform sphere: pdf = 1 / (4 pi) ----------------------------------------------
inline Vec3 SampleUniformSphereW(const Vec2& aSamples) {
    const float z = 1.f - 2.f * aSamples.y;
    const float r = std::sqrt(std::max(0.f, 1.f - z * z));
    const float phi = 2.f * kPi * aSamples.x;
    return Vec3(r * std::cos(phi), r * std::sin(phi), z);
}
inline float UniformSpherePdfW() { return 0.25f * kInvPi; }

// --- Uniform cone around +z with cos(half angle) = aCosMax: pdf = 1 / (2 pi (1 - cosMax))
inline Vec3 SampleUniformConeW(const Vec2& aSamples, float aCosMax) {
    const float cosTheta = 1.f - aSamples.y * (1.f - aCosMax);
    const float sinTheta = std::sqrt(std::max(0.f, 1.f - cosTheta * cosTheta));
    const float phi = 2.f * kPi * aSamples.x;
    return Vec3(std::cos(phi) * sinTheta, std::sin(phi) * sinTheta, cosTheta);
}
inline float UniformConePdfW(float aCosMax) { return 1.f / (2.f * kPi * (1.f - aCosMax)); }

// --- Uniform triangle: barycentrics (b0, b1) of p0, p1; pdf = 1 / area -------------
// The square-root warp keeps the mapping from the unit square area-preserving.
inline Vec2 SampleUniformTriangle(const Vec2& aSamples) {
    const float term = std::sqrt(aSamples.x);
    return Vec2(1.f - term, aSamples.y * term);
}

// --- Uniform disc of radius 1 (concentric map of Shirley and Chiu): pdf = 1 / pi ----
inline Vec2 SampleConcentricDisc(const Vec2& aSamples) {
    const float a = 2.f * aSamples.x - 1.f;
    const float b = 2.f * aSamples.y - 1.f;
    if (a == 0.f && b == 0.f) return Vec2(0.f);
    float r, phi;
    if (a * a > b * b) { r = a; phi = (kPi / 4.f) * (b / a); }
    else               { r = b; phi = (kPi / 2.f) - (kPi / 4.f) * (a / b); }
    return Vec2(r * std::cos(phi), r * std::sin(phi));
}
inline float ConcentricDiscPdfA() { return kInvPi; }

// --- Piecewise-constant density on the unit square (pbrt, "Piecewise-Constant 2D
// Distributions"): a grid of W x H cells with non-negative values f. A sample picks a row
// by the marginal density (each row's sum) and then a cell of that row by its conditional
// density, each by inverting a cumulative sum with a binary search, so sampling costs
// O(log W + log H). Inside the cell the point is uniform; the pdf on the unit square is
//     p(u, v) = f(cell) / mean(f).
class PiecewiseConstant2D {
public:
    PiecewiseConstant2D() = default;
    // aValues holds the rows one after another, aWidth values each; every value must be
    // finite and non-negative and their sum positive (the caller checks and says why).
    PiecewiseConstant2D(int aWidth, int aHeight, std::vector<float> aValues)
        : mWidth(aWidth), mHeight(aHeight), mValues(std::move(aValues)) {
        mConditionalCdf.resize(mValues.size());
        mMarginalCdf.resize(size_t(mHeight));
        double total = 0.0;
        for (int row = 0; row < mHeight; row++) {
            const float* values = &mValues[size_t(row) * size_t(mWidth)];
            float* cdf = &mConditionalCdf[size_t(row) * size_t(mWidth)];
            double rowSum = 0.0;
            for (int column = 0; column < mWidth; column++) rowSum += double(values[column]);
            // A row of zeros is never picked; its cdf is uniform so that it is still valid.
            double running = 0.0;
            for (int column = 0; column < mWidth; column++) {
                running += rowSum > 0.0 ? double(values[column]) : 1.0;
                cdf[column] = float(running / (rowSum > 0.0 ? rowSum : double(mWidth)));
            }
            cdf[mWidth - 1] = 1.f;
            total += rowSum;
            mMarginalCdf[size_t(row)] = float(total);
        }
        for (float& value : mMarginalCdf) value = float(double(value) / total);
        mMarginalCdf.back() = 1.f;
        mInvMean = float(double(mWidth) * double(mHeight) / total);
    }

    struct Sample {
        Vec2 mPoint{0.f};   // in [0, 1)^2: u along a row, v across the rows
        float mPdf = 0.f;   // p(u, v) on the unit square
    };
    Sample SampleContinuous(const Vec2& aRnd) const {
        const CdfCell row = InvertCdf(mMarginalCdf.data(), mHeight, aRnd.y);
        const CdfCell column = InvertCdf(&mConditionalCdf[size_t(row.mIndex) * size_t(mWidth)], mWidth, aRnd.x);
        Sample sample;
        sample.mPoint = Vec2((float(column.mIndex) + column.mOffset) / float(mWidth), (float(row.mIndex) + row.mOffset) / float(mHeight));
        sample.mPdf = CellPdf(column.mIndex, row.mIndex);
        return sample;
    }
    float Pdf(const Vec2& aPoint) const {
        return CellPdf(std::min(int(aPoint.x * float(mWidth)), mWidth - 1), std::min(int(aPoint.y * float(mHeight)), mHeight - 1));
    }
    float CellPdf(int aColumn, int aRow) const { return mValues[size_t(aRow) * size_t(mWidth) + size_t(aColumn)] * mInvMean; }

private:
    // The first of aCount entries whose cumulative value exceeds aRnd (so a cell of zero
    // width is never picked), and where aRnd lies inside it, rescaled to [0, 1).
    struct CdfCell {
        int mIndex = 0;
        float mOffset = 0.f;
    };
    static CdfCell InvertCdf(const float* aCdf, int aCount, float aRnd) {
        CdfCell cell;
        cell.mIndex = int(std::upper_bound(aCdf, aCdf + aCount - 1, aRnd) - aCdf);
        const float lower = cell.mIndex > 0 ? aCdf[cell.mIndex - 1] : 0.f;
        const float width = aCdf[cell.mIndex] - lower;
        cell.mOffset = width > 0.f ? std::min(std::max((aRnd - lower) / width, 0.f), 0.99999994f) : 0.f;
        return cell;
    }

    int mWidth = 0, mHeight = 0;
    std::vector<float> mValues;          // f, row by row
    std::vector<float> mConditionalCdf;  // each row's cumulative sum, normalised to 1
    std::vector<float> mMarginalCdf;     // the rows' cumulative sums, normalised to 1
    float mInvMean = 0.f;
};

// --- Measure conversions: p_A = p_W |cos| / d^2 ---------------------------------------
inline float PdfWtoA(float aPdfW, float aDist, float aCosThere) {
    return aPdfW * std::abs(aCosThere) / Sqr(aDist);
}
inline float PdfAtoW(float aPdfA, float aDist, float aCosThere) {
    return aPdfA * Sqr(aDist) / std::abs(aCosThere);
}

// =====================================================================================
// [SECTION] Geometry: ray, sphere, triangle, BVH
// =====================================================================================
// Provides: Ray, SurfacePoint (what Scene::Intersect finds), exact intersection of a ray
// with a sphere and a triangle, and the contract of the bounding-volume hierarchy over
// both kinds of primitive (its workings are the appendix at the end). Intersection is
// two-sided: back faces occlude like front faces.
// Invariant: ray directions are unit length; a SurfacePoint's geometric normal points
// out of spheres and to the counter-clockwise side of triangles; its shading normal is
// the one the BSDF shades with: the interpolated vertex normal of a smooth triangle,
// turned to the side of the geometric normal, else the geometric normal itself (and then
// the two are equal bit for bit).

struct Ray {
    Vec3 mOrigin{0.f};
    Vec3 mDirection{0.f, 0.f, 1.f};
};

// The point where a ray meets the scene, with what shading it needs. It carries the two
// normals, not frames around them: the Bsdf builds its one frame (around the shading
// normal, turned to the viewer if two-sided), so no frame is built or copied twice, and
// the point stays small: every ray writes one and every vertex reads one. A ray that meets
// nothing gives an invalid point (IsValid() false, mDist infinite) rather than an empty
// std::optional: a miss is an ordinary outcome that the integrators test once, right
// after tracing, and then read the fields many times as hit.mFoo (not hit->mFoo).
struct SurfacePoint {
    Vec3 mPosition{0.f};    // the point hit: ray origin + mDist * ray direction
    float mDist = std::numeric_limits<float>::infinity();
    int mPrimitiveId = -1;  // triangles first, then spheres (see Scene)
    int mMaterialId = -1;
    int mLightId = -1;      // >= 0 when the primitive emits
    Vec2 mUv{0.f};          // texture coordinates (set when the material or light has a texture)
    Vec3 mGeometricNormal{0.f, 0.f, 1.f};  // unit length
    Vec3 mShadingNormal{0.f, 0.f, 1.f};    // unit length, on the geometric normal's side
    bool IsValid() const { return mPrimitiveId >= 0; }
    const Vec3& GeometricNormal() const { return mGeometricNormal; }
    const Vec3& ShadingNormal() const { return mShadingNormal; }
};

// Sphere: solves |o + t d - c|^2 = r^2 for the nearest t in (aTMin, aTMax).
// Robustness: the discriminant is computed as r^2 - |f - (f.d) d|^2 (f = o - c), which
// does not lose precision when the ray starts far away, and the smaller root comes from
// c/q instead of -b - sqrt(...) to avoid cancellation (Haines et al., Ray Tracing Gems
// ch. 7). From inside the sphere the far root is returned. Returns t, or nothing.
inline std::optional<float> IntersectSphere(const Vec3& aCenter, float aRadius, const Ray& aRay, float aTMin,
                                            float aTMax) {
    const Vec3 f = aRay.mOrigin - aCenter;
    const float b = glm::dot(f, aRay.mDirection);
    const Vec3 perpendicular = f - b * aRay.mDirection;
    const float discriminant = aRadius * aRadius - glm::dot(perpendicular, perpendicular);
    if (discriminant < 0.f) return std::nullopt;
    const float c = glm::dot(f, f) - aRadius * aRadius;
    const float q = -b - std::copysign(std::sqrt(discriminant), b);
    float t0 = (q != 0.f) ? c / q : 0.f;
    float t1 = q;
    if (t0 > t1) std::swap(t0, t1);
    if (t0 > aTMin && t0 < aTMax) return t0;
    if (t1 > aTMin && t1 < aTMax) return t1;
    return std::nullopt;
}

// Triangle, watertight (Woop, Benthin and Wald 2013). The vertices are moved into a frame
// where the ray runs along +z from the origin, and three 2D edge functions U, V, W decide
// inclusion. Two triangles sharing an edge evaluate its function on the same two vertices
// in opposite order, getting exactly opposite signs, so a ray through a shared edge hits
// at least one of them (edges are inclusive). Rays parallel to the plane miss.
// The per-ray part of that test: the axis the ray mostly runs along (kz), the two others
// (kx, ky, swapped when the ray runs along -kz so the winding keeps its sign), and the
// shear that makes the ray run along +z. Computed once per ray, not per triangle.
struct WatertightRay {
    int mKx = 0, mKy = 1, mKz = 2;
    float mSx = 0.f, mSy = 0.f, mSz = 1.f;

    WatertightRay() = default;  // for the BVH, which fills it in its own way
    explicit WatertightRay(const Vec3& aDirection) {
        // Components by runtime index read from a plain array: glm's operator[] is a
        // switch (and an assert), a branch the predictor misses on random directions.
        const float d[3] = {aDirection.x, aDirection.y, aDirection.z};
        // std::fabs clears the sign bit (one instruction); glm::abs compares and selects.
        const float absX = std::fabs(d[0]), absY = std::fabs(d[1]), absZ = std::fabs(d[2]);
        // The largest axis (x over y over z on ties, z for NaN) and the order of the other
        // two, in integer arithmetic on the comparisons rather than in branches: on random
        // directions each branch would be a coin toss the predictor loses half the time.
        const int xOverY = absX > absY, xOverZ = absX > absZ, yOverZ = absY > absZ;
        mKz = 2 - 2 * (xOverY & xOverZ) - ((1 - xOverY) & yOverZ);
        const int backwards = d[mKz] < 0.f;  // then x and y swap, to keep the winding
        // (kz + 1 + backwards) % 3 and (kz + 2 - backwards) % 3, by table: % 3 compiles to
        // a multiply and shifts, a dozen instructions per ray.
        static constexpr int kModulo3[5] = {0, 1, 2, 0, 1};
        mKx = kModulo3[mKz + 1 + backwards];
        mKy = kModulo3[mKz + 2 - backwards];
        mSx = d[mKx] / d[mKz];
        mSy = d[mKy] / d[mKz];
        mSz = 1.f / d[mKz];
    }
};

// A ray on an edge in float (an edge function exactly 0) is decided in double. Rare, so
// kept out of the test below, which stays small enough for the compiler to inline.
inline void EdgeFunctionsInDouble(float ax, float ay, float bx, float by, float cx, float cy, float& u, float& v, float& w) {
    u = float(double(cx) * double(by) - double(cy) * double(bx));
    v = float(double(ax) * double(cy) - double(ay) * double(cx));
    w = float(double(bx) * double(ay) - double(by) * double(ax));
}

// The unit normal of triangle (aP0, aP1, aP2) by its winding (counter-clockwise seen
// from the front), computed in double so that long thin triangles keep an accurate normal.
// Nothing for a degenerate triangle: a repeated vertex, collinear vertices (sine of the
// angle between its edges below kCollinearSine), or coordinates so extreme that the
// normal is not representable. Scene::Finalize and the loader share this one test.
inline std::optional<Vec3> TriangleNormal(const Vec3& aP0, const Vec3& aP1, const Vec3& aP2) {
    const glm::dvec3 edge1 = glm::dvec3(aP1) - glm::dvec3(aP0);
    const glm::dvec3 edge2 = glm::dvec3(aP2) - glm::dvec3(aP0);
    const glm::dvec3 cross = glm::cross(edge1, edge2);
    const double doubleArea = glm::length(cross);
    if (!std::isfinite(doubleArea) || !(doubleArea > kCollinearSine * glm::length(edge1) * glm::length(edge2)))
        return std::nullopt;
    const Vec3 normal(cross / doubleArea);
    if (!std::isfinite(normal.x) || !std::isfinite(normal.y) || !std::isfinite(normal.z)) return std::nullopt;
    return normal;
}

// Returns t, or nothing.
inline std::optional<float> IntersectTriangle(const Vec3& aP0, const Vec3& aP1, const Vec3& aP2, const Ray& aRay,
                                              const WatertightRay& aShear, float aTMin, float aTMax) {
    const int kx = aShear.mKx, ky = aShear.mKy, kz = aShear.mKz;
    const float sx = aShear.mSx, sy = aShear.mSy, sz = aShear.mSz;
    const Vec3 pa = aP0 - aRay.mOrigin, pb = aP1 - aRay.mOrigin, pc = aP2 - aRay.mOrigin;
    const float a[3] = {pa.x, pa.y, pa.z}, b[3] = {pb.x, pb.y, pb.z}, c[3] = {pc.x, pc.y, pc.z};
    const float ax = a[kx] - sx * a[kz], ay = a[ky] - sy * a[kz];
    const float bx = b[kx] - sx * b[kz], by = b[ky] - sy * b[kz];
    const float cx = c[kx] - sx * c[kz], cy = c[ky] - sy * c[kz];
    float u = cx * by - cy * bx, v = ax * cy - ay * cx, w = bx * ay - by * ax;
    if (u == 0.f || v == 0.f || w == 0.f) EdgeFunctionsInDouble(ax, ay, bx, by, cx, cy, u, v, w);
    if ((u < 0.f || v < 0.f || w < 0.f) && (u > 0.f || v > 0.f || w > 0.f)) return std::nullopt;
    const float det = u + v + w;
    if (det == 0.f || !std::isfinite(det)) return std::nullopt;
    const float t = sz * (u * a[kz] + v * b[kz] + w * c[kz]) / det;
    if (!(t > aTMin && t < aTMax)) return std::nullopt;
    return t;
}

inline std::optional<float> IntersectTriangle(const Vec3& aP0, const Vec3& aP1, const Vec3& aP2, const Ray& aRay,
                                              float aTMin, float aTMax) {
    return IntersectTriangle(aP0, aP1, aP2, aRay, WatertightRay(aRay.mDirection), aTMin, aTMax);
}

struct Aabb {
    Vec3 mMin{std::numeric_limits<float>::infinity()};
    Vec3 mMax{-std::numeric_limits<float>::infinity()};

    void Extend(const Vec3& aPoint) { mMin = glm::min(mMin, aPoint); mMax = glm::max(mMax, aPoint); }
    void Extend(const Aabb& aBox) { mMin = glm::min(mMin, aBox.mMin); mMax = glm::max(mMax, aBox.mMax); }
    bool IsEmpty() const { return mMin.x > mMax.x; }
    Vec3 Centroid() const { return 0.5f * mMin + 0.5f * mMax; }  // mMin + mMax may overflow
    float SurfaceArea() const {
        if (IsEmpty()) return 0.f;
        const Vec3 d = mMax - mMin;
        return 2.f * (d.x * d.y + d.y * d.z + d.z * d.x);
    }
};

// The primitives the BVH is built over, in the layout the traversal reads: triangles as
// their three vertices (shared vertices stay bit-identical, which the watertight test
// needs), spheres as centre and radius. The index of a primitive is its position in
// the scene: triangles 0..T-1, then spheres T..T+S-1. mTriangleCutOut marks the triangles
// with holes (alpha cut-outs; empty: none has), whose hits the queries below confirm.
struct PrimitiveSoup {
    std::vector<Vec3> mTriangleP0, mTriangleP1, mTriangleP2;
    std::vector<uint8_t> mTriangleCutOut;
    std::vector<Vec3> mSphereCenter;
    std::vector<float> mSphereRadius;
    int TriangleCount() const { return int(mTriangleP0.size()); }
    int Count() const { return int(mTriangleP0.size() + mSphereCenter.size()); }
    Aabb Bounds(int aPrimitive) const {
        Aabb box;
        if (aPrimitive < TriangleCount()) {
            box.Extend(mTriangleP0[aPrimitive]);
            box.Extend(mTriangleP1[aPrimitive]);
            box.Extend(mTriangleP2[aPrimitive]);
        } else {
            const int s = aPrimitive - TriangleCount();
            box.Extend(mSphereCenter[s] - Vec3(mSphereRadius[s]));
            box.Extend(mSphereCenter[s] + Vec3(mSphereRadius[s]));
        }
        return box;
    }
};

// The acceleration structure, by its contract. How it works is [SECTION] Appendix:
// BVH; a reader who skips the appendix loses nothing needed to follow the renderer.
// Build(soup) builds over a PrimitiveSoup (triangles as vertex triples, then spheres) and
// keeps what it needs, so the soup may go afterwards. Intersect(ray, tMin, ioTMax)
// returns the index of the primitive with the closest hit at a t in the open interval
// (tMin, ioTMax) and lowers ioTMax to that t, or returns -1 and leaves ioTMax alone; the
// hit and its t are exactly those of IntersectTriangle / IntersectSphere above, so the
// BVH decides speed, never the image (of two primitives hit at exactly the same t,
// either may be returned). Occluded(ray, tMin, tMax) is the shadow-ray query: whether
// any primitive is hit in (tMin, tMax), stopping at the first one found (which is not
// necessarily the closest). Both are two-sided, const and touch no shared mutable state,
// so any number of threads may trace one Bvh at once; copies of a Bvh share its
// (immutable) tree.
// Cut-outs: given a test aIsSolid(triangle, t) -- is the surface of that triangle there
// at distance t along the ray? -- both queries ask it about every hit of a triangle the
// soup marks as cut out (and only those; at most once per hit that could change the
// answer) and treat a hit it refuses as no hit: Intersect returns the closest hit the
// test accepts, Occluded whether there is any. The test must depend on the triangle and
// t alone, so that every build of the BVH returns the same hits. Without a test, every
// hit counts.
class Bvh {
public:
    void Build(const PrimitiveSoup& aSoup);
    int Intersect(const Ray& aRay, float aTMin, float& ioTMax) const;
    bool Occluded(const Ray& aRay, float aTMin, float aTMax) const;
    template <typename IsSolid>
    int Intersect(const Ray& aRay, float aTMin, float& ioTMax, const IsSolid& aIsSolid) const;
    template <typename IsSolid>
    bool Occluded(const Ray& aRay, float aTMin, float aTMax, const IsSolid& aIsSolid) const;
    bool HasCutOuts() const;       // whether the soup marked any triangle

    // Statistics, for tests and benchmarks. Nodes count leaves too.
    size_t NodeCount() const;
    size_t StorageBytes() const;   // what the tree stores: nodes and primitive records
    static size_t NodeBytes();     // the size of one inner node
    int PrimitiveCount() const;
    int Depth() const;             // levels of the tree a ray walks
    int BuildDepth() const;        // levels of the binary tree it was collapsed from
    uint32_t LargestLeaf() const;  // primitives in the largest leaf

private:
    class Tree;
    std::shared_ptr<const Tree> mTree;  // null until Build
};

// =====================================================================================
// [SECTION] Scene: materials, lights, camera
// =====================================================================================
// Provides: Material (SmallVCM's sum of Lambert, normalised Phong, mirror and Fresnel
// glass), the six light kinds (the background one optionally an EnvironmentMap, an
// equirectangular image sampled by its luminance), the pinhole Camera with SmallVCM's
// conventions, and Scene, which owns them all with the geometry and answers ray queries.
// Relies on: Geometry. Invariant after Scene::Finalize(): every triangle has a valid
// unit normal, every light's sampling data is built, the BVH is current.

// How texture coordinates outside [0, 1] map into the image (glTF sampler wrap modes).
enum class TextureWrap { kRepeat, kClampToEdge, kMirroredRepeat };

// An affine map of texture coordinates (glTF's KHR_texture_transform): scale, then a
// rotation of the uv axes by `rotation` radians counter-clockwise, then an offset:
//     u' = ox + cos(rot) sx u + sin(rot) sy v,    v' = oy - sin(rot) sx u + cos(rot) sy v
// (the extension's example, rotation pi/2 with offset (0, 1) and scale 1/2, then shows
// the image's lower-left quadrant turned clockwise by 90 degrees).
struct UvTransform {
    Vec2 mOffset{0.f};
    Vec2 mU{1.f, 0.f}, mV{0.f, 1.f};  // where u and v go: uv' = mOffset + u mU + v mV
    bool mIdentity = true;            // then uv' = uv exactly

    static UvTransform Make(const Vec2& aOffset, float aRotation, const Vec2& aScale) {
        UvTransform t;
        const float c = std::cos(aRotation), s = std::sin(aRotation);
        t.mOffset = aOffset;
        t.mU = aScale.x * Vec2(c, -s);
        t.mV = aScale.y * Vec2(s, c);
        t.mIdentity = aOffset == Vec2(0.f) && aRotation == 0.f && aScale == Vec2(1.f);
        return t;
    }
    Vec2 Apply(const Vec2& aUv) const { return mIdentity ? aUv : mOffset + aUv.x * mU + aUv.y * mV; }
};

// An RGB image in linear colour, filtered bilinearly. glTF conventions: uv (0, 0) is the
// top-left corner of the image (row 0), texel centres lie at ((i + 0.5) / width, ...).
// The texture coordinates of a lookup go through mUvTransform first. A texture may also
// keep its alpha channel (mAlpha, linear coverage in [0, 1]; glTF: alpha is never
// sRGB-encoded): only the base colour of a material with a cut-out does (Material::
// mAlphaTexture), so other textures carry no fourth channel.
// The texels are held either as linear colours (mTexels) or, as the glTF loader keeps its
// 8-bit images, as three bytes each (mEncoded) with the linear value of each byte
// (mDecode): a quarter of the memory, and the same colours, so the same images.
struct Texture {
    int mWidth = 0, mHeight = 0;
    std::vector<Vec3> mTexels;      // row by row from the top; empty when mEncoded holds them
    std::vector<uint8_t> mEncoded;  // R, G, B bytes of each texel, in the same order, or empty
    std::array<float, 256> mDecode{};  // the linear value of each byte of mEncoded
    std::vector<float> mAlpha;  // the same texels' alpha, or empty
    TextureWrap mWrapU = TextureWrap::kRepeat, mWrapV = TextureWrap::kRepeat;
    UvTransform mUvTransform;

    size_t TexelCount() const { return mEncoded.empty() ? mTexels.size() : mEncoded.size() / 3; }
    Vec3 Texel(size_t aIndex) const {
        if (mEncoded.empty()) return mTexels[aIndex];
        const uint8_t* rgb = &mEncoded[3 * aIndex];
        return Vec3(mDecode[rgb[0]], mDecode[rgb[1]], mDecode[rgb[2]]);
    }
    Vec3 Lookup(const Vec2& aTexCoord) const {
        if (mEncoded.empty()) return Bilinear<Vec3>([&](size_t aIndex) { return mTexels[aIndex]; }, aTexCoord);
        return Bilinear<Vec3>([&](size_t aIndex) { return Texel(aIndex); }, aTexCoord);
    }
    // The alpha at aTexCoord, filtered and wrapped like the colour (1 without alpha).
    float LookupAlpha(const Vec2& aTexCoord) const {
        return mAlpha.empty() ? 1.f : Bilinear<float>([&](size_t aIndex) { return mAlpha[aIndex]; }, aTexCoord);
    }

private:
    // aTexel(i) is texel i (row by row from the top), a T.
    template <typename T, typename Fetch>
    T Bilinear(const Fetch& aTexel, const Vec2& aTexCoord) const {
        const Vec2 uv = mUvTransform.Apply(aTexCoord);
        const float x = Reduce(uv.x, mWrapU) * float(mWidth) - 0.5f;
        const float y = Reduce(uv.y, mWrapV) * float(mHeight) - 0.5f;
        const float fx = std::floor(x), fy = std::floor(y);
        const float tx = x - fx, ty = y - fy;
        const int x0 = int(fx), y0 = int(fy);
        const auto at = [&](int aX, int aY) {
            return aTexel(size_t(Wrap(aY, mHeight, mWrapV)) * size_t(mWidth) + size_t(Wrap(aX, mWidth, mWrapU)));
        };
        return (1.f - ty) * ((1.f - tx) * at(x0, y0) + tx * at(x0 + 1, y0)) +
               ty * ((1.f - tx) * at(x0, y0 + 1) + tx * at(x0 + 1, y0 + 1));
    }
    // A coordinate brought into [0, 1] (repeat: [0, 1), its period) before it is scaled
    // to texels, so that huge coordinates cannot overflow an int. Not finite: 0.
    static float Reduce(float aCoordinate, TextureWrap aWrap) {
        if (!std::isfinite(aCoordinate)) return 0.f;
        switch (aWrap) {
        case TextureWrap::kRepeat: return aCoordinate - std::floor(aCoordinate);
        case TextureWrap::kClampToEdge: return std::min(std::max(aCoordinate, 0.f), 1.f);
        case TextureWrap::kMirroredRepeat: {
            const float t = aCoordinate - 2.f * std::floor(0.5f * aCoordinate);  // [0, 2)
            return t <= 1.f ? t : 2.f - t;
        }
        }
        return 0.f;
    }
    // A texel index one step outside [0, aSize) (the bilinear neighbour) brought back in.
    static int Wrap(int aIndex, int aSize, TextureWrap aWrap) {
        if (aWrap == TextureWrap::kClampToEdge) return std::min(std::max(aIndex, 0), aSize - 1);
        const int period = aWrap == TextureWrap::kRepeat ? aSize : 2 * aSize;
        const int m = ((aIndex % period) + period) % period;
        return m < aSize ? m : period - 1 - m;
    }
};

// A homogeneous participating medium ([SECTION] Participating media has its maths):
// per RGB channel an absorption and a scattering coefficient, in 1 / scene unit, and the
// Henyey-Greenstein asymmetry g of its phase function (|g| < 1; 0 is isotropic, > 0
// scatters forwards). The extinction sigma_t = sigma_a + sigma_s; the single-scattering
// albedo sigma_s / sigma_t is what one scattering event keeps of the light.
// A medium fills the inside of a closed mesh or sphere whose Material::mMedium names it,
// or, as Scene::mSceneMedium, all space outside every closed mesh.
struct Medium {
    std::string mName;
    Vec3 mSigmaA{0.f};
    Vec3 mSigmaS{0.f};
    float mG = 0.f;
    Vec3 SigmaT() const { return mSigmaA + mSigmaS; }
    // Whether light is attenuated in it at all (a medium with sigma_t = 0 only marks a
    // region: rays cross it unchanged).
    bool Attenuates() const { return MaxComponent(SigmaT()) > 0.f; }
    bool Scatters() const { return MaxComponent(mSigmaS) > 0.f; }
};

// How a material's alpha cuts its surface (glTF material.alphaMode; Material below).
enum class AlphaMode { kOpaque, kMask, kBlend };

struct Material {
    std::string mName;
    Vec3 mDiffuseReflectance{0.f};
    Vec3 mPhongReflectance{0.f};
    float mPhongExponent = 1.f;
    Vec3 mMirrorReflectance{0.f};
    float mIor = -1.f;        // < 0: no refraction; > 0: glass, mirror part Fresnel-weighted
    // Glass (mIor > 0) refracts (1 - F) mTransmittance: the tint of the light that crosses
    // the surface, times the share of the surface that is glass (glTF: base colour x
    // transmission, docs/scene_format.md); 1 is clear glass. mOpaqueMirror is a mirror
    // that F does not weight, on the front side only: the smooth specular of the opaque
    // rest of a partly transmissive surface, beside the glass's own F x mMirrorReflectance.
    Vec3 mTransmittance{1.f};
    Vec3 mOpaqueMirror{0.f};
    bool mTwoSided = false;   // diffuse and Phong reflect on both sides (glTF doubleSided)
    // The medium inside the closed mesh (or sphere) this material covers (index into
    // Scene::mMedia; -1: none, empty space). Its surface is then the boundary of the
    // medium: glass (mIor > 0) refracts into it; a material with no component at all is an
    // index-matched boundary that rays cross unchanged (IsIndexMatchedBoundary). In a scene
    // with media every glass is such a boundary too (empty inside unless mMedium says).
    int mMedium = -1;
    // Base-colour texture (index into Scene::mTextures, -1 for none). Its texel multiplies
    // the diffuse reflectance and the transmittance, and tints the Phong and mirror parts
    // above mSpecularUntinted, the share no base colour reaches (glTF: specular = 0.04
    // (1 - metallic) + metallic x base colour, so mSpecularUntinted = 0.04 (1 - metallic)).
    // On glass the tinted mirror is mOpaqueMirror: the Fresnel reflection stays untinted.
    int mBaseColorTexture = -1;
    Vec3 mSpecularUntinted{0.f};
    // Normal map (glTF normalTexture; index into Scene::mTextures, -1 for none; linear
    // RGB): the shading normal tilted in the tangent frame (Scene::NormalMapped);
    // mNormalScale scales the tilt's x and y (glTF's normalTexture.scale).
    int mNormalTexture = -1;
    float mNormalScale = 1.f;
    // Cut-outs (glTF alphaMode). The coverage at a point is alpha = mBaseColorAlpha
    // (baseColorFactor's alpha) times the alpha of mAlphaTexture there (the base-colour
    // texture, with the same TEXCOORD set and transform; -1: none, alpha 1). kMask: the
    // surface is there where alpha >= mAlphaCutoff and a hole elsewhere (glTF 2.0,
    // material.alphaCutoff: "greater than or equal ... fully opaque, otherwise fully
    // transparent"). kBlend is thresholded the same way at 1/2: partial coverage is not
    // modelled (see AlphaCutoff). Only triangles have cut-outs; a hole lets every ray
    // through (Scene::IsSolidAt).
    AlphaMode mAlphaMode = AlphaMode::kOpaque;
    float mAlphaCutoff = 0.5f;  // glTF's default
    float mBaseColorAlpha = 1.f;
    int mAlphaTexture = -1;
    // glTF's metallicRoughnessTexture (index into Scene::mTextures, -1 for none; linear
    // RGB): metal is its blue channel times mMetallic, roughness its green one times
    // mRoughness, so that they vary across the surface. The reflectances above are then
    // those of the factors, and a Bsdf applies MetallicRoughnessRule (below) at each hit
    // to the texel's metal and roughness, the base colour mBaseColor (times the
    // base-colour texel), mTransmission and mRuleIor.
    int mMetallicRoughnessTexture = -1;
    Vec3 mBaseColor{1.f};
    float mMetallic = 0.f, mRoughness = 0.f, mTransmission = 0.f, mRuleIor = 1.5f;

    bool HasCutOut() const { return mAlphaMode != AlphaMode::kOpaque; }
    // The threshold of the coverage test. BLEND has no cutoff in glTF; a threshold at
    // 1/2 keeps the surface one fixed set of points, the same for every ray and every
    // estimator (a random coverage test per ray would make a point on it a different
    // surface for the camera and the light sub-path, and merging would see it twice).
    float AlphaCutoff() const { return mAlphaMode == AlphaMode::kBlend ? 0.5f : mAlphaCutoff; }

    bool HasNonSpecular() const { return !IsBlack(mDiffuseReflectance) || !IsBlack(mPhongReflectance); }
    // A medium's boundary that does not scatter: no component, only the medium behind it.
    bool IsIndexMatchedBoundary() const { return mMedium >= 0 && !HasNonSpecular() && !HasSpecular(); }
    bool HasSpecular() const { return !IsBlack(mMirrorReflectance) || !IsBlack(mOpaqueMirror) || mIor > 0.f; }

    // Russian roulette continuation probability: an upper bound of the material's
    // albedo, as in SmallVCM (floor 0.8, walls 0.803922, mirror and glass 1). It depends
    // on the material only, never on the direction, so the pdf of a path is the same
    // whichever sub-path visits the vertex -- which the MIS weights rely on.
    float ContinuationProbability() const {
        const float reflect = MaxComponent(mDiffuseReflectance + mPhongReflectance + mMirrorReflectance + mOpaqueMirror);
        const float refract = mIor > 0.f ? MaxComponent(mTransmittance) : 0.f;
        return std::min(1.f, reflect + refract);
    }
};

// The written rule that maps glTF's metallic-roughness material onto the components
// above (docs/scene_format.md section 4.2), for base colour b, metallic m, roughness r,
// transmission t (KHR_materials_transmission) and ior. The dielectric's share t is glass,
// g = (1 - m) t, which refracts (tinted by b; its Fresnel reflection untinted), and the
// rest is opaque: d = (1 - m)(1 - t) of dielectric, diffuse 0.96 d b and specular 0.04 d
// untinted, beside the metal's m b. The specular is a Phong lobe of exponent 2 / r^4 - 2
// (within [0, 10000]) when r > 0, else a mirror (beside glass, one that F does not
// weight). With ior 0 (F = 1) the glass share reflects all it receives, untinted: it
// joins that specular. The loader applies it once per material, to the factors; a Bsdf
// at each hit of a material with a metallicRoughnessTexture, to the texel's values.
struct MetallicRoughnessMaterial {
    Vec3 mDiffuse{0.f}, mPhong{0.f}, mMirror{0.f}, mOpaqueMirror{0.f}, mTransmittance{1.f};
    float mPhongExponent = 1.f;
    float mIor = -1.f;            // > 0: the glass share refracts (Material::mIor)
    Vec3 mSpecularUntinted{0.f};  // the specular share no base colour reaches
};
inline MetallicRoughnessMaterial MetallicRoughnessRule(const Vec3& aBaseColor, float aMetallic, float aRoughness,
                                                       float aTransmission, float aIor) {
    MetallicRoughnessMaterial result;
    const float glass = (1.f - aMetallic) * aTransmission;
    const float dielectric = (1.f - aMetallic) * (1.f - aTransmission);
    const bool refracts = glass > 0.f && aIor > 0.f;
    const float untinted = 0.04f * dielectric + (refracts ? 0.f : glass);
    const Vec3 specular = Vec3(untinted) + aMetallic * aBaseColor;
    result.mDiffuse = dielectric * 0.96f * aBaseColor;
    result.mSpecularUntinted = Vec3(untinted);
    if (aRoughness > 0.f) {
        result.mPhong = specular;
        result.mPhongExponent = std::min(10000.f, std::max(0.f, 2.f / std::pow(aRoughness, 4.f) - 2.f));
    } else if (refracts) {
        result.mOpaqueMirror = specular;
    } else {
        result.mMirror = specular;
    }
    if (refracts) {
        result.mIor = aIor;
        result.mMirror = Vec3(glass);
        result.mTransmittance = glass * aBaseColor;
    }
    return result;
}

// What a Bsdf (below) needs of a material that does not depend on the point it is seen
// at: Scene::Finalize computes it once per material (Bsdf::ConstantsOf) so that
// Bsdf::Setup, at every hit, only picks it up. The selection probabilities of the
// components are constant for a material with neither a base-colour texture nor
// refraction (whose Fresnel term depends on the direction): they then depend only on the
// side it is seen from.
struct MaterialConstants {
    // The reflectances of the components (diffuse, Phong, mirror), one after the other.
    // (With glass, the opaque mirror and the transmittance too: Material's.)
    struct Reflectances { Vec3 mDiffuse{0.f}, mPhong{0.f}, mMirror{0.f}, mOpaqueMirror{0.f}, mTransmittance{1.f}; };
    // Bsdf's normalised selection probabilities (diffuse, Phong, mirror, refraction) seen
    // from one side, whether only specular components are left, and whether anything is
    // (Bsdf::IsDelta(), IsValid()).
    struct Side {
        std::array<float, 4> mProbabilities{};
        bool mIsDelta = false;
        bool mValid = false;
    };
    // The material's own, gathered once, so that Setup copies them instead of gathering
    // them from the Material at every vertex.
    Reflectances mReflectance;
    float mContinuationProb = 0.f;     // Material::ContinuationProbability()
    bool mFixedProbabilities = false;  // no texture, no refraction: the two sides below hold
    Side mFront, mBack;
};
inline MaterialConstants ComputeMaterialConstants(const Material& aMaterial);  // with the Bsdf, below
inline bool SameMaterialConstants(const MaterialConstants& aA, const MaterialConstants& aB) {
    const auto sameSide = [](const MaterialConstants::Side& aX, const MaterialConstants::Side& aY) {
        return aX.mProbabilities == aY.mProbabilities && aX.mIsDelta == aY.mIsDelta && aX.mValid == aY.mValid;
    };
    return aA.mReflectance.mDiffuse == aB.mReflectance.mDiffuse && aA.mReflectance.mPhong == aB.mReflectance.mPhong &&
           aA.mReflectance.mMirror == aB.mReflectance.mMirror && aA.mReflectance.mOpaqueMirror == aB.mReflectance.mOpaqueMirror &&
           aA.mReflectance.mTransmittance == aB.mReflectance.mTransmittance && aA.mContinuationProb == aB.mContinuationProb &&
           aA.mFixedProbabilities == aB.mFixedProbabilities && sameSide(aA.mFront, aB.mFront) &&
           sameSide(aA.mBack, aB.mBack);
}

struct Triangle {
    Vec3 mP0{0.f}, mP1{0.f}, mP2{0.f};
    Vec3 mNormal{0.f};   // set by Scene::Finalize from the winding
    int mMaterialId = 0;
    int mLightId = -1;
    Vec2 mUv0{0.f}, mUv1{0.f}, mUv2{0.f};  // texture coordinates (the glTF set its material's textures use)
    // Vertex normals (glTF NORMAL) of a smooth-shaded triangle, interpolated at each hit
    // into the shading normal; Scene::Finalize normalises them. Flat triangles have none.
    bool mHasVertexNormals = false;
    Vec3 mN0{0.f}, mN1{0.f}, mN2{0.f};
    // Vertex tangents of a normal-mapped triangle (glTF TANGENT, or the loader's): xyz
    // along increasing u, w = +1 or -1, the handedness of the bitangent w (N x T).
    bool mHasTangents = false;
    Vec4 mT0{0.f}, mT1{0.f}, mT2{0.f};
    // In double: a thin triangle's float cross product loses most of its digits.
    float Area() const {
        return float(0.5 * glm::length(glm::cross(glm::dvec3(mP1) - glm::dvec3(mP0), glm::dvec3(mP2) - glm::dvec3(mP0))));
    }
};

struct Sphere {
    Vec3 mCenter{0.f};
    float mRadius = 1.f;
    int mMaterialId = 0;
    int mLightId = -1;
};

// The scene's bounding sphere: directional and background lights emit from a disc of
// its radius, and the merging radius is a fraction of it.
struct SceneSphere {
    Vec3 mCenter{0.f};
    float mRadius = 1.f;
    float mInvRadiusSqr = 1.f;
};

// Image-based light at infinity: an equirectangular (latitude-longitude) image of the
// radiance arriving from every direction. Mapping, in glTF's frame (+Y up), as Blender's
// world and the glTF viewers map such an image: the image's centre faces +X, u grows
// towards +Z, the top row is the zenith (+Y) and the bottom row the nadir (-Y):
//     phi = atan2(z, x),  u = 1/2 + phi / (2 pi),   theta = acos(y),  v = theta / pi.
// A rotation a turns the environment about +Y, counter-clockwise seen from above (the
// right-hand rule): what faced +X then faces (cos a, 0, -sin a).
//
// The radiance from a direction is its texel's (nearest, not filtered), so the radiance
// is constant on each texel's patch of the sphere. Directions are sampled in proportion
// to Luminance(texel) x sin(theta at the texel's centre) (PiecewiseConstant2D: the sine
// puts fewer samples on the rows near the poles, whose texels cover less solid angle).
// With dOmega = 2 pi^2 sin(theta) du dv the pdf in solid angle is exactly
//     p(omega) = p(u, v) / (2 pi^2 sin(theta)),
// positive wherever the radiance is (luminance > 0 when any channel is > 0), so every
// estimator that samples it stays unbiased and its MIS weights see the true pdf.
class EnvironmentMap {
public:
    EnvironmentMap() = default;
    // aTexels: aWidth x aHeight linear RGB radiance, top row first. Throws Error (starting
    // with aWhere) for a size that is not 2:1, a negative or non-finite texel, or a black
    // image.
    EnvironmentMap(const std::string& aWhere, int aWidth, int aHeight, std::vector<Vec3> aTexels, float aRotationDegrees)
        : mWidth(aWidth), mHeight(aHeight), mTexels(std::move(aTexels)) {
        if (aWidth < 2 || aHeight < 1 || aWidth != 2 * aHeight || mTexels.size() != size_t(aWidth) * size_t(aHeight))
            throw Error(aWhere + ": an equirectangular map is twice as wide as high; this one is " + std::to_string(aWidth) +
                        "x" + std::to_string(aHeight));
        if (!std::isfinite(aRotationDegrees)) throw Error(aWhere + ": the rotation is not finite");
        // Whole turns removed first, so that a rotation by 360 degrees is exactly none.
        const double radians = std::fmod(double(aRotationDegrees), 360.0) * 3.14159265358979323846 / 180.0;
        mCosRotation = float(std::cos(radians));
        mSinRotation = float(std::sin(radians));
        std::vector<float> importance(mTexels.size());
        for (int row = 0; row < mHeight; row++) {
            const float sinTheta = std::sin(kPi * (float(row) + 0.5f) / float(mHeight));
            for (int column = 0; column < mWidth; column++) {
                const size_t index = size_t(row) * size_t(mWidth) + size_t(column);
                const Vec3& texel = mTexels[index];
                if (!IsFinite(texel) || texel.x < 0.f || texel.y < 0.f || texel.z < 0.f)
                    throw Error(aWhere + ": texel (" + std::to_string(column) + ", " + std::to_string(row) +
                                ") is negative or not finite");
                mBrightestTexel = glm::max(mBrightestTexel, texel);
                importance[index] = Luminance(texel) * sinTheta;
            }
        }
        if (IsBlack(mBrightestTexel)) throw Error(aWhere + ": the environment map is black (it emits nothing)");
        mDistribution = PiecewiseConstant2D(mWidth, mHeight, std::move(importance));
    }

    // The radiance arriving from direction aDirection (unit length, pointing away from the scene).
    Vec3 Radiance(const Vec3& aDirection) const {
        const Vec2 uv = ToUv(ToMap(aDirection));
        return mTexels[size_t(Row(uv.y)) * size_t(mWidth) + size_t(Column(uv.x))];
    }
    // The pdf, in solid angle, with which Sample returns aDirection.
    float PdfW(const Vec3& aDirection) const {
        const Vec3 local = ToMap(aDirection);
        const float sinTheta = std::sqrt(local.x * local.x + local.z * local.z);
        if (!(sinTheta > 0.f)) return 0.f;
        return mDistribution.Pdf(ToUv(local)) / (2.f * kPi * kPi * sinTheta);
    }
    struct DirectionSample {
        Vec3 mDirection{0.f};  // towards the environment
        Vec3 mRadiance{0.f};   // arriving from it
        float mPdfW = 0.f;
    };
    // A direction in proportion to luminance x sin(theta); nothing at the poles (sin = 0).
    std::optional<DirectionSample> Sample(const Vec2& aRnd) const {
        const PiecewiseConstant2D::Sample uv = mDistribution.SampleContinuous(aRnd);
        const float phi = 2.f * kPi * (uv.mPoint.x - 0.5f), theta = kPi * uv.mPoint.y;
        const float sinTheta = std::sin(theta);
        if (!(sinTheta > 0.f) || !(uv.mPdf > 0.f)) return std::nullopt;
        const Vec3 local(sinTheta * std::cos(phi), std::cos(theta), sinTheta * std::sin(phi));
        DirectionSample sample;
        sample.mDirection = Vec3(mCosRotation * local.x + mSinRotation * local.z, local.y,
                                 -mSinRotation * local.x + mCosRotation * local.z);
        sample.mRadiance = mTexels[size_t(Row(uv.mPoint.y)) * size_t(mWidth) + size_t(Column(uv.mPoint.x))];
        sample.mPdfW = uv.mPdf / (2.f * kPi * kPi * sinTheta);
        return sample;
    }

    int Width() const { return mWidth; }
    int Height() const { return mHeight; }
    const Vec3& BrightestTexel() const { return mBrightestTexel; }

private:
    // World direction to the map's frame: the rotation undone.
    Vec3 ToMap(const Vec3& aDirection) const {
        return Vec3(mCosRotation * aDirection.x - mSinRotation * aDirection.z, aDirection.y,
                    mSinRotation * aDirection.x + mCosRotation * aDirection.z);
    }
    static Vec2 ToUv(const Vec3& aLocal) {
        const float u = 0.5f + std::atan2(aLocal.z, aLocal.x) * (0.5f * kInvPi);
        const float v = std::acos(std::min(std::max(aLocal.y, -1.f), 1.f)) * kInvPi;
        return Vec2(u, v);
    }
    int Column(float aU) const { return std::min(std::max(int(aU * float(mWidth)), 0), mWidth - 1); }
    int Row(float aV) const { return std::min(std::max(int(aV * float(mHeight)), 0), mHeight - 1); }

    int mWidth = 0, mHeight = 0;
    std::vector<Vec3> mTexels;
    float mCosRotation = 1.f, mSinRotation = 0.f;
    Vec3 mBrightestTexel{0.f};
    PiecewiseConstant2D mDistribution;
};

enum class LightType { kArea, kSphere, kPoint, kSpot, kDirectional, kBackground };
inline const char* LightTypeName(LightType aType) {
    switch (aType) {
    case LightType::kArea: return "area";
    case LightType::kSphere: return "sphere";
    case LightType::kPoint: return "point";
    case LightType::kSpot: return "spot";
    case LightType::kDirectional: return "directional";
    case LightType::kBackground: return "background";
    }
    return "unknown";
}

// The spot light's cone (glTF KHR_lights_punctual): angles from the axis in radians,
// 0 <= inner < outer <= pi/2 as the extension requires, and outer at least
// kMinSpotConeAngle: below it 1 - cos(outer), the cone's solid angle over 2 pi, keeps too
// few float digits (5e-5 at 0.01 rad, 1e-3 relative) for its sampling pdf.
inline constexpr float kMinSpotConeAngle = 0.01f;
// The problem with a spot light's cone angles, or nullptr when they are valid.
inline const char* SpotConeProblem(float aInnerConeAngle, float aOuterConeAngle) {
    if (!std::isfinite(aInnerConeAngle) || !std::isfinite(aOuterConeAngle)) return "a cone angle is not finite (in single precision)";
    if (aInnerConeAngle < 0.f) return "innerConeAngle is negative (it must be >= 0)";
    if (!(aOuterConeAngle <= 0.5f * kPi)) return "outerConeAngle exceeds pi/2";
    if (!(aInnerConeAngle < aOuterConeAngle)) return "innerConeAngle is not less than outerConeAngle";
    if (aOuterConeAngle < kMinSpotConeAngle)
        return "outerConeAngle is below 0.01 rad (0.57 degrees), narrower than single precision samples accurately";
    return nullptr;
}

// Next-event estimation sample: a point on the light seen from a receiving point.
struct LightSample {
    Vec3 mRadiance{0.f};      // what arrives along -mDirToLight (before the cosine at the receiver)
    Vec3 mDirToLight{0.f};
    float mDistance = 0.f;    // infinity for lights at infinity
    float mDirectPdfW = 0.f;  // pdf of this direction, solid angle at the receiver (delta: see Light)
    float mEmissionPdfW = 0.f;// pdf of emitting this position and direction from the light
    float mCosAtLight = 1.f;
};

// Emission sample: the start of a light sub-path.
struct LightEmission {
    Vec3 mEnergy{0.f};        // radiance (or intensity/irradiance) times the cosine at the light
    Vec3 mPosition{0.f};
    Vec3 mDirection{0.f};
    float mEmissionPdfW = 0.f;// position pdf (area) times direction pdf (solid angle)
    float mDirectPdfA = 0.f;  // pdf with which next-event estimation picks this position
    float mCosAtLight = 1.f;
    Vec3 mNormal{0.f};        // the light's surface normal at mPosition (area, sphere)
    Vec3 mRadiance{0.f};      // the radiance leaving mPosition (area, sphere: emission x texel)
};

// One struct for every kind of light, dispatched by a switch: no virtual calls in the
// integrators' inner loops, and each kind's three operations sit side by side.
// Emission quantities per kind:  area, sphere, background: radiance (W m^-2 sr^-1);
// point, spot: radiant intensity (W/sr; a spot's on its axis); directional: irradiance
// on a perpendicular surface. For delta lights (point, spot, directional) the "pdfs"
// follow SmallVCM's convention: the point and spot lights' mDirectPdfW is d^2 so that
// radiance / pdf gives I / d^2, the directional light's is 1.
//
// Textured area light (glTF emissiveTexture): the radiance leaving a point is mEmission
// times the texel at the point's texture coordinates (bilinear, like the base colour),
// looked up once wherever the light meets a path: where a ray hits it (GetRadiance, from
// the hit's uv), where next-event estimation samples it (Illuminate) and where a light
// sub-path starts (Emit). Positions are still sampled uniformly by area, the texel
// weighting the sample: unbiased for any texture, though a mostly black texture wastes
// the samples that land on black (importance sampling by texel power would not; it is
// left out to keep one sampling routine for every area light). Emit refuses a point
// whose radiance is black, since its sub-path would carry nothing. Lights are picked
// uniformly (as in SmallVCM), so no power enters the sampling; the power bound that
// Finalize checks uses the brightest texel, an upper bound of the average one.
//
// Spot light (glTF KHR_lights_punctual, "Inner and Outer Cone Angles"): a point light
// whose intensity in a direction at angle theta from the axis is I s(cos theta), with the
// extension's reference falloff, the square of a ramp linear in the cosine:
//     s(c) = clamp((c - cos(outer)) / d, 0, 1)^2,  d = max(0.001, cos(inner) - cos(outer))
// (the max is the reference code's guard against equal angles). Its power is
//     Phi = I * Integral s dw = 2 pi I [(1 - c1) + (c1 - cos(outer))^3 / (3 d^2)],
//     c1 = min(1, cos(outer) + d)  (where the ramp reaches 1),
// i.e. 2 pi I [(1 - cos(inner)) + (cos(inner) - cos(outer)) / 3] without the guard.
// Light sub-paths start uniformly inside the outer cone, pdf 1 / (2 pi (1 - cos(outer))),
// carrying I s(cos theta) / pdf: unbiased, since s = 0 outside the cone.
struct Light {
    LightType mType = LightType::kPoint;
    Vec3 mEmission{0.f};
    Vec3 mPosition{0.f};          // point and spot lights
    Vec3 mDirection{0.f, 0.f, -1.f}; // directional light and spot axis: the direction light travels
    float mSpotInnerConeAngle = 0.f, mSpotOuterConeAngle = 0.25f * kPi;  // radians (glTF defaults)
    // Set by Scene::Finalize from the angles: cos(outer) and 1 / d of the falloff above.
    float mSpotCosOuter = 0.f, mSpotFalloffScale = 0.f;
    // Area light: its triangles, sampled by area. Two-sided (glTF doubleSided) it emits
    // mEmission from both sides; emission then picks a side with probability 1/2, so its
    // direction pdf is cos / (2 pi) and its power 2 pi A L. Sphere lights emit outwards only.
    bool mTwoSided = false;
    std::vector<Vec3> mTriangleP0, mTriangleE1, mTriangleE2, mTriangleNormal;
    std::vector<float> mTriangleCdf;  // cumulative area, normalised to 1
    float mArea = 0.f;
    // Emission texture of an area light (index into Scene::mTextures, -1 for none), and
    // what Finalize derives from it: a copy of the texture (the light's operations get no
    // scene, and a copy cannot dangle when the scene is copied), its brightest texel per
    // channel, and each triangle's texture coordinates as a vertex and two edges.
    int mEmissionTexture = -1;
    Texture mEmissionTextureCopy;
    Vec3 mBrightestEmissionTexel{1.f};
    std::vector<Vec2> mTriangleUv0, mTriangleUvE1, mTriangleUvE2;
    // Sphere light.
    Vec3 mSphereCenter{0.f};
    float mSphereRadius = 0.f;
    // Background light: its radiance from each direction is mEmission times this map's
    // (shared: copies of a scene share one map); none, and it is mEmission everywhere.
    std::shared_ptr<const EnvironmentMap> mEnvironment;

    bool IsDelta() const { return mType == LightType::kPoint || mType == LightType::kSpot || mType == LightType::kDirectional; }

    // The radiance an area or sphere light emits at texture coordinates aUv (the one
    // texture lookup of a query; untextured lights ignore aUv).
    Vec3 EmittedRadiance(const Vec2& aUv) const {
        return mEmissionTexture >= 0 ? mEmission * mEmissionTextureCopy.Lookup(aUv) : mEmission;
    }

    // Area and sphere lights: the cosine between the surface normal aNormal and a direction
    // aOutgoing leaving the surface, on the side that emits (<= 0: that side does not).
    float EmittingCosine(const Vec3& aNormal, const Vec3& aOutgoing) const {
        const float cosine = glm::dot(aNormal, aOutgoing);
        return mTwoSided ? std::abs(cosine) : cosine;
    }
    // The probability with which Emit picks the side a direction leaves from.
    float SideProbability() const { return mTwoSided ? 0.5f : 1.f; }

    // The spot falloff s(cos theta) above; aCosTheta is the cosine to the axis.
    float SpotFalloff(float aCosTheta) const {
        const float ramp = std::min(std::max((aCosTheta - mSpotCosOuter) * mSpotFalloffScale, 0.f), 1.f);
        return ramp * ramp;
    }
    // The integral of the falloff over the sphere of directions (the spot's power over
    // its axial intensity, formula above), in double, from the same float parameters
    // that SpotFalloff uses.
    double SpotFalloffSolidAngle() const {
        const double cosOuter = double(mSpotCosOuter), ramp = 1.0 / double(mSpotFalloffScale);
        const double full = std::min(1.0, cosOuter + ramp);
        return 2.0 * 3.14159265358979323846 * ((1.0 - full) + std::pow(full - cosOuter, 3.0) / (3.0 * ramp * ramp));
    }
    bool IsFinite() const { return mType != LightType::kDirectional && mType != LightType::kBackground; }

    // Samples a point of the light for next-event estimation from aReceiver. Nothing
    // when the light cannot illuminate aReceiver with this sample.
    std::optional<LightSample> Illuminate(const SceneSphere& aSceneSphere, const Vec3& aReceiver, const Vec2& aRnd) const {
        switch (mType) {
        case LightType::kArea:
        case LightType::kSphere: return IlluminateFromSurface(aReceiver, aRnd);
        case LightType::kPoint:
        case LightType::kSpot: return IlluminateFromPoint(aReceiver);
        case LightType::kDirectional:
        case LightType::kBackground: return IlluminateFromInfinity(aSceneSphere, aRnd);
        }
        return std::nullopt;
    }

    // Samples the start of a light sub-path: a position and a direction. Nothing when the
    // sample carries no light (a black texel, a spot's direction outside its cone).
    std::optional<LightEmission> Emit(const SceneSphere& aSceneSphere, const Vec2& aRndDirection,
                                      const Vec2& aRndPosition) const {
        switch (mType) {
        case LightType::kArea:
        case LightType::kSphere: return EmitFromSurface(aRndDirection, aRndPosition);
        case LightType::kPoint:
        case LightType::kSpot: return EmitFromPoint(aRndDirection);
        case LightType::kDirectional:
        case LightType::kBackground: return EmitFromInfinity(aSceneSphere, aRndDirection, aRndPosition);
        }
        return std::nullopt;
    }

    // What a ray receives when it hits the light (area, sphere: at a point with geometric
    // normal aHitNormal and texture coordinates aHitUv, SurfacePoint::mUv) or escapes the scene
    // (background): the radiance, and the pdfs with which next-event estimation
    // (mDirectPdfA: area measure; solid angle for the background) and emission would have
    // produced the same point. All zero where the light sends nothing that way.
    struct RadianceAtHit {
        Vec3 mRadiance{0.f};
        float mDirectPdfA = 0.f;
        float mEmissionPdfW = 0.f;
    };
    RadianceAtHit GetRadiance(const SceneSphere& aSceneSphere, const Vec3& aRayDirection, const Vec3& aHitNormal,
                              const Vec2& aHitUv) const {
        RadianceAtHit result;
        switch (mType) {
        case LightType::kArea:
        case LightType::kSphere: {
            const float cosOutL = EmittingCosine(aHitNormal, -aRayDirection);
            if (cosOutL <= 0.f) return result;
            result.mDirectPdfA = 1.f / mArea;
            result.mEmissionPdfW = cosOutL * kInvPi * SideProbability() / mArea;
            result.mRadiance = EmittedRadiance(aHitUv);
            return result;
        }
        case LightType::kBackground: {
            const float directPdf = mEnvironment ? mEnvironment->PdfW(aRayDirection) : UniformSpherePdfW();
            result.mDirectPdfA = directPdf;
            result.mEmissionPdfW = directPdf * ConcentricDiscPdfA() * aSceneSphere.mInvRadiusSqr;
            result.mRadiance = mEnvironment ? mEmission * mEnvironment->Radiance(aRayDirection) : mEmission;
            return result;
        }
        default:  // delta lights cannot be hit
            return result;
        }
    }

private:
    // --- next-event estimation, per kind of light ---------------------------------------
    // Area and sphere lights: a uniform point of the surface (area pdf 1 / A), converted
    // to solid angle at the receiver.
    std::optional<LightSample> IlluminateFromSurface(const Vec3& aReceiver, const Vec2& aRnd) const {
        const SurfaceSample point = SamplePosition(aRnd);
        const Vec3 toLight = point.mPosition - aReceiver;
        const float distSqr = glm::dot(toLight, toLight);
        if (!(distSqr > 0.f)) return std::nullopt;
        LightSample sample;
        sample.mDistance = std::sqrt(distSqr);
        sample.mDirToLight = toLight / sample.mDistance;
        const float cosNormalDir = EmittingCosine(point.mNormal, -sample.mDirToLight);
        if (cosNormalDir <= kEpsCosine) return std::nullopt;  // the side facing the receiver does not emit
        sample.mDirectPdfW = PdfAtoW(1.f / mArea, sample.mDistance, cosNormalDir);
        sample.mEmissionPdfW = cosNormalDir * kInvPi * SideProbability() / mArea;
        sample.mCosAtLight = cosNormalDir;
        sample.mRadiance = EmittedRadiance(point.mUv);
        return sample;
    }

    // Point and spot lights: the one position; the "pdf" d^2 turns intensity into the
    // irradiance-carrying radiance I / d^2 (SmallVCM's convention for delta lights).
    std::optional<LightSample> IlluminateFromPoint(const Vec3& aReceiver) const {
        const Vec3 toLight = mPosition - aReceiver;
        const float distSqr = glm::dot(toLight, toLight);
        if (!(distSqr > 0.f)) return std::nullopt;
        LightSample sample;
        sample.mDistance = std::sqrt(distSqr);
        sample.mDirToLight = toLight / sample.mDistance;
        sample.mDirectPdfW = distSqr;
        sample.mCosAtLight = 1.f;
        if (mType == LightType::kPoint) {
            sample.mEmissionPdfW = UniformSpherePdfW();
            sample.mRadiance = mEmission;
            return sample;
        }
        // The spot: intensity I s(cos theta) towards the receiver, and the pdf with which
        // Emit starts a light sub-path in this direction (uniform in the cone).
        const float falloff = SpotFalloff(glm::dot(mDirection, -sample.mDirToLight));
        if (!(falloff > 0.f)) return std::nullopt;
        sample.mEmissionPdfW = UniformConePdfW(mSpotCosOuter);
        sample.mRadiance = mEmission * falloff;
        return sample;
    }

    // Directional and background lights: a direction (the background's uniform over the
    // sphere, as SmallVCM does, or by its environment map's density); emission would have
    // started the ray on the disc of the scene's radius (pdf 1 / (pi R^2)) across it.
    std::optional<LightSample> IlluminateFromInfinity(const SceneSphere& aSceneSphere, const Vec2& aRnd) const {
        LightSample sample;
        sample.mRadiance = mEmission;
        if (mType == LightType::kDirectional) {
            sample.mDirToLight = -mDirection;
            sample.mDirectPdfW = 1.f;
            sample.mEmissionPdfW = ConcentricDiscPdfA() * aSceneSphere.mInvRadiusSqr;
        } else if (mEnvironment) {
            const std::optional<EnvironmentMap::DirectionSample> direction = mEnvironment->Sample(aRnd);
            if (!direction) return std::nullopt;
            sample.mDirToLight = direction->mDirection;
            sample.mDirectPdfW = direction->mPdfW;
            sample.mEmissionPdfW = sample.mDirectPdfW * ConcentricDiscPdfA() * aSceneSphere.mInvRadiusSqr;
            sample.mRadiance = mEmission * direction->mRadiance;
        } else {
            sample.mDirToLight = SampleUniformSphereW(aRnd);
            sample.mDirectPdfW = UniformSpherePdfW();
            sample.mEmissionPdfW = sample.mDirectPdfW * ConcentricDiscPdfA() * aSceneSphere.mInvRadiusSqr;
        }
        sample.mDistance = std::numeric_limits<float>::infinity();
        sample.mCosAtLight = 1.f;
        return sample;
    }

    // --- emission, per kind of light ----------------------------------------------------
    // Area and sphere lights: a uniform point, then a cosine-weighted direction on the
    // emitting side (of a two-sided light, a side picked with probability 1/2).
    std::optional<LightEmission> EmitFromSurface(Vec2 aRndDirection, const Vec2& aRndPosition) const {
        const SurfaceSample point = SamplePosition(aRndPosition);
        const Vec3 radiance = EmittedRadiance(point.mUv);
        if (IsBlack(radiance)) return std::nullopt;  // a black texel: nothing to carry
        Vec3 normal = point.mNormal;
        if (mTwoSided) {
            // The side by the first direction number, whose rest, rescaled to [0, 1), then
            // picks the direction.
            const bool back = aRndDirection.x >= 0.5f;
            aRndDirection.x = std::min(2.f * aRndDirection.x - (back ? 1.f : 0.f), 0.99999994f);
            if (back) normal = -normal;
        }
        Vec3 localDirection = SampleCosHemisphereW(aRndDirection);
        // SmallVCM clamps the cosine so that the pdf stays positive at the horizon.
        localDirection.z = std::max(localDirection.z, kEpsCosine);
        const float directionPdfW = localDirection.z * kInvPi;
        LightEmission emission;
        emission.mPosition = point.mPosition;
        emission.mDirection = Frame(normal).ToWorld(localDirection);
        emission.mNormal = normal;  // of the emitting side
        emission.mEmissionPdfW = directionPdfW * SideProbability() / mArea;
        emission.mDirectPdfA = 1.f / mArea;
        emission.mCosAtLight = localDirection.z;
        emission.mRadiance = radiance;
        emission.mEnergy = radiance * localDirection.z;
        return emission;
    }

    // Point lights emit uniformly over the sphere; spot lights uniformly inside the outer
    // cone, where the falloff is not 0 (see above).
    std::optional<LightEmission> EmitFromPoint(const Vec2& aRndDirection) const {
        LightEmission emission;
        emission.mPosition = mPosition;
        emission.mDirectPdfA = 1.f;
        emission.mCosAtLight = 1.f;
        if (mType == LightType::kPoint) {
            emission.mDirection = SampleUniformSphereW(aRndDirection);
            emission.mEmissionPdfW = UniformSpherePdfW();
            emission.mEnergy = mEmission;
            return emission;
        }
        const Vec3 local = SampleUniformConeW(aRndDirection, mSpotCosOuter);
        emission.mEmissionPdfW = UniformConePdfW(mSpotCosOuter);
        const float falloff = SpotFalloff(local.z);
        if (!(falloff > 0.f)) return std::nullopt;
        emission.mDirection = Frame(mDirection).ToWorld(local);
        emission.mEnergy = mEmission * falloff;
        return emission;
    }

    // Directional and background lights: parallel rays start on a disc of the scene's
    // radius, perpendicular to their direction, just outside the scene's bounding sphere
    // (Georgiev's report, sec. 5.1).
    std::optional<LightEmission> EmitFromInfinity(const SceneSphere& aSceneSphere, const Vec2& aRndDirection,
                                                  const Vec2& aRndPosition) const {
        float directionPdfW = 1.f;
        Vec3 direction = mDirection;
        Vec3 energy = mEmission;
        if (mType == LightType::kBackground && mEnvironment) {
            // Light travels opposite to the direction it arrives from.
            const std::optional<EnvironmentMap::DirectionSample> arriving = mEnvironment->Sample(aRndDirection);
            if (!arriving) return std::nullopt;
            direction = -arriving->mDirection;
            directionPdfW = arriving->mPdfW;
            energy = mEmission * arriving->mRadiance;
        } else if (mType == LightType::kBackground) {
            direction = -SampleUniformSphereW(aRndDirection);
            directionPdfW = UniformSpherePdfW();
        }
        const Vec2 disc = SampleConcentricDisc(aRndPosition);
        const Frame frame(direction);
        LightEmission emission;
        emission.mPosition = aSceneSphere.mCenter + aSceneSphere.mRadius * (-direction + frame.mX * disc.x + frame.mY * disc.y);
        emission.mDirection = direction;
        emission.mEmissionPdfW = directionPdfW * ConcentricDiscPdfA() * aSceneSphere.mInvRadiusSqr;
        emission.mDirectPdfA = directionPdfW;  // NEE picks the direction with this pdf
        emission.mCosAtLight = 1.f;
        emission.mEnergy = energy;
        return emission;
    }

    // Uniform point on the light's surface (area pdf 1 / mArea), its outward normal and
    // its texture coordinates (textured area lights; otherwise 0).
    struct SurfaceSample {
        Vec3 mPosition{0.f};
        Vec3 mNormal{0.f};
        Vec2 mUv{0.f};
    };
    SurfaceSample SamplePosition(Vec2 aRnd) const {
        SurfaceSample point;
        if (mType == LightType::kSphere) {
            point.mNormal = SampleUniformSphereW(aRnd);
            point.mPosition = mSphereCenter + mSphereRadius * point.mNormal;
            return point;
        }
        // Pick a triangle in proportion to its area with aRnd.x, then reuse what is left
        // of aRnd.x, rescaled to [0, 1), for the position inside it.
        size_t index = 0;
        if (mTriangleCdf.size() > 1) {
            index = size_t(std::upper_bound(mTriangleCdf.begin(), mTriangleCdf.end() - 1, aRnd.x) - mTriangleCdf.begin());
            const float lower = index > 0 ? mTriangleCdf[index - 1] : 0.f;
            const float width = mTriangleCdf[index] - lower;
            aRnd.x = width > 0.f ? std::min((aRnd.x - lower) / width, 0.99999994f) : 0.f;
        }
        const Vec2 barycentric = SampleUniformTriangle(aRnd);
        point.mPosition = mTriangleP0[index] + barycentric.y * mTriangleE1[index] +
                          (1.f - barycentric.x - barycentric.y) * mTriangleE2[index];
        point.mNormal = mTriangleNormal[index];
        if (!mTriangleUv0.empty())
            point.mUv = mTriangleUv0[index] + barycentric.y * mTriangleUvE1[index] +
                        (1.f - barycentric.x - barycentric.y) * mTriangleUvE2[index];
        return point;
    }
};

// Pinhole camera with SmallVCM's conventions: horizontal field of view, raster y = 0 at
// the top, one focal factor for both axes so pixels are square at any aspect ratio
// (SmallVCM stretches non-square images; we keep the horizontal field of view and let
// the vertical one follow the image's aspect).
class Camera {
public:
    // aForward and aUpHint need not be unit length or orthogonal.
    void Setup(const Vec3& aPosition, const Vec3& aForward, const Vec3& aUpHint, float aHorizontalFovDegrees) {
        mPosition = aPosition;
        mForward = glm::normalize(aForward);
        mRight = glm::normalize(glm::cross(aUpHint, -mForward));
        mUp = glm::cross(-mForward, mRight);
        mHorizontalFovDegrees = aHorizontalFovDegrees;
        Update();
    }
    void SetResolution(int aWidth, int aHeight) {
        if (aWidth <= 0 || aHeight <= 0) throw Error("resolution: width and height must be positive");
        // Pixel indices are ints, and a film of 16384x16384 is already 6 GiB a thread.
        if (int64_t(aWidth) * int64_t(aHeight) > (int64_t(1) << 28))
            throw Error("resolution: " + std::to_string(aWidth) + "x" + std::to_string(aHeight) + " is more than 2^28 pixels (16384x16384)");
        mWidth = aWidth;
        mHeight = aHeight;
        Update();
    }

    int Width() const { return mWidth; }
    int Height() const { return mHeight; }
    int PixelCount() const { return mWidth * mHeight; }
    const Vec3& Position() const { return mPosition; }
    const Vec3& Forward() const { return mForward; }
    const Vec3& Right() const { return mRight; }
    const Vec3& Up() const { return mUp; }
    float HorizontalFovDegrees() const { return mHorizontalFovDegrees; }
    // Distance from the pinhole to the image plane, in pixels: W / (2 tan(fov/2)).
    float ImagePlaneDist() const { return mImagePlaneDist; }

    // Continuous raster position (x right, y down, in pixels) to a primary ray.
    Ray GenerateRay(const Vec2& aRaster) const {
        const Vec3 onPlane = mForward * mImagePlaneDist + mRight * (aRaster.x - 0.5f * float(mWidth)) -
                             mUp * (aRaster.y - 0.5f * float(mHeight));
        return Ray{mPosition, glm::normalize(onPlane)};
    }
    // World point to raster position; nothing when the point is behind the camera.
    std::optional<Vec2> WorldToRaster(const Vec3& aWorld) const {
        const Vec3 d = aWorld - mPosition;
        const float z = glm::dot(d, mForward);
        if (!(z > 0.f)) return std::nullopt;
        const float scale = mImagePlaneDist / z;
        return Vec2(0.5f * float(mWidth) + glm::dot(d, mRight) * scale,
                    0.5f * float(mHeight) - glm::dot(d, mUp) * scale);
    }
    bool CheckRaster(const Vec2& aRaster) const {
        return aRaster.x >= 0.f && aRaster.y >= 0.f && aRaster.x < float(mWidth) && aRaster.y < float(mHeight);
    }
    int RasterToIndex(const Vec2& aRaster) const {
        const int x = std::min(int(std::floor(aRaster.x)), mWidth - 1);
        const int y = std::min(int(std::floor(aRaster.y)), mHeight - 1);
        return y * mWidth + x;
    }

private:
    void Update() {
        mImagePlaneDist = float(mWidth) / (2.f * std::tan(0.5f * mHorizontalFovDegrees * kPi / 180.f));
    }

    Vec3 mPosition{0.f}, mForward{0.f, 1.f, 0.f}, mRight{1.f, 0.f, 0.f}, mUp{0.f, 0.f, 1.f};
    float mHorizontalFovDegrees = 45.f;
    int mWidth = 512, mHeight = 512;
    float mImagePlaneDist = 1.f;
};

// Rays traced by this thread (nearest-hit and shadow rays), for benchmarks: a plain
// thread-local counter costs nothing measurable and needs no synchronisation.
inline uint64_t& RayCounter() {
    static thread_local uint64_t count = 0;
    return count;
}

// One light picked for a sample (Scene::PickLight): the light, its index, and the
// probability it was picked with.
struct LightPick {
    const Light* mLight = nullptr;
    int mId = -1;
    float mProb = 0.f;
};

// The scene: geometry, materials, lights and camera. Build it by filling the vectors
// (or with LoadGltfScene) and call Finalize() before rendering, and again after changing
// them (Render refuses a scene whose materials changed since: CheckUnchangedSinceFinalize).
class Scene {
public:
    std::string mName;
    std::vector<Material> mMaterials;
    std::vector<Triangle> mTriangles;
    std::vector<Sphere> mSpheres;
    std::vector<Light> mLights;
    std::vector<Texture> mTextures;
    std::vector<Medium> mMedia;  // referred to by Material::mMedium and mSceneMedium
    int mSceneMedium = -1;       // the medium outside every closed mesh (-1: empty space)
    Camera mCamera;

    // --- building ----------------------------------------------------------------
    int AddMaterial(const Material& aMaterial) { mMaterials.push_back(aMaterial); return int(mMaterials.size()) - 1; }
    int AddMedium(const Medium& aMedium) { mMedia.push_back(aMedium); return int(mMedia.size()) - 1; }
    int AddTriangle(const Vec3& aP0, const Vec3& aP1, const Vec3& aP2, int aMaterialId) {
        Triangle triangle;
        triangle.mP0 = aP0; triangle.mP1 = aP1; triangle.mP2 = aP2; triangle.mMaterialId = aMaterialId;
        mTriangles.push_back(triangle);
        return int(mTriangles.size()) - 1;
    }
    int AddSphere(const Vec3& aCenter, float aRadius, int aMaterialId) {
        Sphere sphere;
        sphere.mCenter = aCenter; sphere.mRadius = aRadius; sphere.mMaterialId = aMaterialId;
        mSpheres.push_back(sphere);
        return int(mSpheres.size()) - 1;
    }
    // All the given triangles become one light of radiance aRadiance (times the texel of
    // mTextures[aEmissionTexture] at their texture coordinates, when >= 0), sampled by
    // area, emitting from their front sides (aTwoSided: from both).
    int AddAreaLight(const std::vector<int>& aTriangleIds, const Vec3& aRadiance, bool aTwoSided = false,
                     int aEmissionTexture = -1) {
        Light light;
        light.mType = LightType::kArea;
        light.mEmission = aRadiance;
        light.mTwoSided = aTwoSided;
        light.mEmissionTexture = aEmissionTexture;
        const int id = int(mLights.size());
        for (int t : aTriangleIds) mTriangles.at(size_t(t)).mLightId = id;
        mLights.push_back(light);
        return id;
    }
    int AddSphereLight(int aSphereId, const Vec3& aRadiance) {
        Light light;
        light.mType = LightType::kSphere;
        light.mEmission = aRadiance;
        const int id = int(mLights.size());
        mSpheres.at(size_t(aSphereId)).mLightId = id;
        mLights.push_back(light);
        return id;
    }
    int AddPointLight(const Vec3& aPosition, const Vec3& aIntensity) {
        Light light;
        light.mType = LightType::kPoint;
        light.mPosition = aPosition;
        light.mEmission = aIntensity;
        mLights.push_back(light);
        return int(mLights.size()) - 1;
    }
    // A spot light at aPosition shining along aAxis (need not be unit length), with the
    // intensity aIntensity on its axis and glTF's cone angles in radians (see Light).
    int AddSpotLight(const Vec3& aPosition, const Vec3& aAxis, const Vec3& aIntensity, float aInnerConeAngle,
                     float aOuterConeAngle) {
        Light light;
        light.mType = LightType::kSpot;
        light.mPosition = aPosition;
        light.mDirection = glm::normalize(aAxis);
        light.mEmission = aIntensity;
        light.mSpotInnerConeAngle = aInnerConeAngle;
        light.mSpotOuterConeAngle = aOuterConeAngle;
        mLights.push_back(light);
        return int(mLights.size()) - 1;
    }
    int AddDirectionalLight(const Vec3& aTravelDirection, const Vec3& aIrradiance) {
        Light light;
        light.mType = LightType::kDirectional;
        light.mDirection = glm::normalize(aTravelDirection);
        light.mEmission = aIrradiance;
        mLights.push_back(light);
        return int(mLights.size()) - 1;
    }
    int AddBackgroundLight(const Vec3& aRadiance) {
        Light light;
        light.mType = LightType::kBackground;
        light.mEmission = aRadiance;
        mLights.push_back(light);
        return int(mLights.size()) - 1;
    }
    // A background whose radiance from each direction is aScale times aMap's.
    int AddEnvironmentLight(std::shared_ptr<const EnvironmentMap> aMap, float aScale = 1.f) {
        const int id = AddBackgroundLight(Vec3(aScale));
        mLights.back().mEnvironment = std::move(aMap);
        return id;
    }

    // Validates the scene and builds everything derived from it: triangle normals, the
    // bounding sphere, light sampling data, the BVH. Throws Error naming the problem.
    void Finalize() {
        const std::string where = mName.empty() ? std::string("scene") : mName;
        ValidateLights(where);
        FinalizeGeometry(where);
        FinalizeLights(where);
        BuildAcceleration();
        FinalizeMedia(where);
        mFinalized = true;
    }

    // --- queries -----------------------------------------------------------------
    bool IsFinalized() const { return mFinalized; }
    // Finalize keeps per-material constants and per-triangle hit records (the Bsdf and
    // FillSurfacePoint read them instead of the materials and triangles): a material or a
    // triangle's material changed after it would render with the old values. Render calls
    // this, so such a change is an error that says what to do, not a wrong picture.
    void CheckUnchangedSinceFinalize() const {
        const auto changed = [](const std::string& aWhat) {
            return Error("scene: " + aWhat + " changed after Finalize(); call Finalize() again");
        };
        if (mMaterialConstants.size() != mMaterials.size()) throw changed("the number of materials");
        if (mTriangleHitRecords.size() != mTriangles.size()) throw changed("the number of triangles");
        if (MediaOfScene() != mMediaAtFinalize) throw changed("a medium, the scene medium or a material's medium");
        for (size_t m = 0; m < mMaterials.size(); m++)
            if (!SameMaterialConstants(ComputeMaterialConstants(mMaterials[m]), mMaterialConstants[m]))
                throw changed("material " + std::to_string(m) + " '" + mMaterials[m].mName + "'");
        for (size_t t = 0; t < mTriangles.size(); t++) {
            const TriangleKind& kind = mTriangleKinds[mTriangleHitRecords[t].mKind];
            if (!(kind == KindOf(mTriangles[t])))
                throw changed("the material, light, texture or vertex normals of triangle " + std::to_string(t));
        }
    }
    const SceneSphere& GetSceneSphere() const { return mSceneSphere; }
    float RayEpsilon() const { return mRayEpsilon; }
    int LightCount() const { return int(mLights.size()); }
    const Light& GetLight(int aId) const { return mLights[size_t(aId)]; }
    // Every estimator that samples a light picks it here, uniformly: aRnd in [0, 1)
    // chooses one, with probability LightPickProb(), which the light's pdfs then include.
    LightPick PickLight(float aRnd) const {
        const int lightCount = LightCount();
        const int id = std::min(int(aRnd * float(lightCount)), lightCount - 1);
        return LightPick{&mLights[size_t(id)], id, LightPickProb()};
    }
    float LightPickProb() const { return 1.f / float(LightCount()); }
    const Light* GetBackground() const { return mBackgroundLightId >= 0 ? &mLights[size_t(mBackgroundLightId)] : nullptr; }
    const Material& GetMaterial(int aId) const { return mMaterials[size_t(aId)]; }
    // The constants of material aId as Finalize computed them; nullptr for a material
    // added since (a Bsdf then computes what it needs itself).
    const MaterialConstants* FindMaterialConstants(int aId) const {
        return size_t(aId) < mMaterialConstants.size() ? &mMaterialConstants[size_t(aId)] : nullptr;
    }
    const Bvh& GetBvh() const { return mBvh; }

    // --- media (Finalize resolves them; [SECTION] Participating media uses them) -------
    // Whether the scene holds any medium; without one every medium query answers -1 and
    // the estimators trace exactly as in empty space.
    bool HasMedia() const { return mHasMedia; }
    const Medium& GetMedium(int aId) const { return mMedia[size_t(aId)]; }
    // The medium the camera sits in, and the one a light emits into (-1: empty space).
    int CameraMedium() const { return mCameraMedium; }
    int LightMedium(int aLightId) const { return mHasMedia ? mLightMedia[size_t(aLightId)] : -1; }
    // A surface the estimators step through without a vertex: an index-matched boundary
    // (not an emitter), where only the medium changes.
    bool IsIndexMatchedBoundary(const SurfacePoint& aHit) const {
        return mHasMedia && aHit.mLightId < 0 && mMaterials[size_t(aHit.mMaterialId)].IsIndexMatchedBoundary();
    }
    // The medium a ray leaving surface point aHit along aDirection travels in, for a path
    // that arrived in medium aCurrent. A medium boundary (a material with a medium, or any
    // glass in a scene with media) separates its inside (the material's medium) from its
    // outside (the medium around its closed mesh, found by Finalize); every other surface
    // has the same medium on both sides, the one the path is in. The geometric normal
    // tells the sides: it points outwards (Finalize checks the winding).
    SMALLVCM_ALWAYS_INLINE int MediumAfter(const SurfacePoint& aHit, const Vec3& aDirection, int aCurrent) const {
        if (!mHasMedia) return aCurrent;
        const int outside = mBoundaryOutside[size_t(aHit.mPrimitiveId)];
        if (outside == kNotBoundary) return aCurrent;
        return glm::dot(aDirection, aHit.GeometricNormal()) < 0.f ? mMaterials[size_t(aHit.mMaterialId)].mMedium : outside;
    }

    // Nearest surface point along aRay (origin already offset off any surface by the
    // caller); an invalid SurfacePoint when the ray leaves the scene.
    SMALLVCM_ALWAYS_INLINE SurfacePoint Intersect(const Ray& aRay) const {
        RayCounter()++;
        SurfacePoint hit;
        float tMax = std::numeric_limits<float>::infinity();
        const int primitive = mBvh.Intersect(aRay, 0.f, tMax, [&](int aTriangle, float aT) {
            return IsSolidAt(aTriangle, aRay.mOrigin + aT * aRay.mDirection);
        });
        if (primitive < 0) return hit;
        hit.mDist = tMax;
        hit.mPosition = aRay.mOrigin + tMax * aRay.mDirection;
        hit.mPrimitiveId = primitive;
        FillSurfacePoint(hit);
        return hit;
    }
    // The rest of a surface point from its primitive and position (ioPoint.mPrimitiveId,
    // mPosition): material, light, normals, texture coordinates. Intersect ends here, and
    // a stored light vertex, which keeps only those two, rebuilds its surface here bit
    // for bit.
    void FillSurfacePoint(SurfacePoint& ioPoint) const {
        const int primitive = ioPoint.mPrimitiveId;
        const int triangleCount = int(mTriangles.size());
        if (primitive < triangleCount) {
            const TriangleHitRecord& record = mTriangleHitRecords[size_t(primitive)];
            const TriangleKind& kind = mTriangleKinds[record.mKind];
            ioPoint.mMaterialId = kind.mMaterialId;
            ioPoint.mLightId = kind.mLightId;
            ioPoint.mGeometricNormal = record.mNormal;
            ioPoint.mShadingNormal = record.mNormal;
            if (kind.mTextured || kind.mHasVertexNormals) {
                const Triangle& triangle = mTriangles[size_t(primitive)];
                const TriangleBarycentrics b = Barycentrics(triangle, ioPoint.mPosition);
                if (kind.mTextured) ioPoint.mUv = TriangleUv(triangle, b);
                if (kind.mHasVertexNormals) ioPoint.mShadingNormal = InterpolatedNormal(triangle, b);
                if (kind.mNormalMapped)
                    ioPoint.mShadingNormal = NormalMapped(triangle, b, ioPoint.mShadingNormal, ioPoint.mUv,
                                                          mMaterials[size_t(kind.mMaterialId)]);
            }
        } else {
            const Sphere& sphere = mSpheres[size_t(primitive - triangleCount)];
            ioPoint.mMaterialId = sphere.mMaterialId;
            ioPoint.mLightId = sphere.mLightId;
            ioPoint.mGeometricNormal = glm::normalize(ioPoint.mPosition - sphere.mCenter);
            ioPoint.mShadingNormal = ioPoint.mGeometricNormal;  // a sphere's normal is exact
        }
    }

    // Shadow ray: is anything between aPoint and aPoint + aDistance * aDirection?
    // Both ends are pulled in by the ray epsilon so the two surfaces do not occlude.
    // A cut-out's holes let it through, as they let Intersect's rays through.
    SMALLVCM_ALWAYS_INLINE bool Occluded(const Vec3& aPoint, const Vec3& aDirection, float aDistance) const {
        RayCounter()++;
        const Ray ray{aPoint + aDirection * mRayEpsilon, aDirection};
        return mBvh.Occluded(ray, 0.f, aDistance - 2.f * mRayEpsilon, [&](int aTriangle, float aT) {
            return IsSolidAt(aTriangle, ray.mOrigin + aT * ray.mDirection);
        });
    }

    // Whether triangle aTriangle's surface is there at aPoint (on it): false in a hole of
    // its material's cut-out (Material::mAlphaMode), true on a triangle without one. The
    // BVH asks it about hits on cut-out triangles only. It depends on the point alone,
    // not on the ray, so that a camera ray, a light sub-path's ray and a shadow ray or
    // connection all see the same surface: every estimator integrates over one scene.
    bool IsSolidAt(int aTriangle, const Vec3& aPoint) const {
        const Triangle& triangle = mTriangles[size_t(aTriangle)];
        const Material& material = mMaterials[size_t(triangle.mMaterialId)];
        if (!material.HasCutOut() || triangle.mLightId >= 0) return true;
        float alpha = material.mBaseColorAlpha;
        if (material.mAlphaTexture >= 0)
            alpha *= mTextures[size_t(material.mAlphaTexture)].LookupAlpha(TriangleUv(triangle, Barycentrics(triangle, aPoint)));
        return alpha >= material.AlphaCutoff();
    }

    // The base-colour texel at a surface point (white for untextured materials).
    Vec3 BaseColorTexel(const SurfacePoint& aHit) const { return BaseColorTexel(aHit.mMaterialId, aHit.mUv); }
    // The same from a material and texture coordinates.
    Vec3 BaseColorTexel(int aMaterialId, const Vec2& aUv) const {
        const int texture = mMaterials[size_t(aMaterialId)].mBaseColorTexture;
        return texture < 0 ? Vec3(1.f) : mTextures[size_t(texture)].Lookup(aUv);
    }

    // Ray leaving a surface point: the origin moves off the surface along the direction.
    Ray SpawnRay(const Vec3& aPoint, const Vec3& aDirection) const {
        return Ray{aPoint + aDirection * mRayEpsilon, aDirection};
    }

    // The weights of vertices 1 and 2 at aPoint of aTriangle (vertex 0 has 1 - mB1 - mB2):
    // the barycentric coordinates of the point's projection onto the triangle's plane
    // (Ericson, Real-Time Collision Detection, 3.4), in double for thin triangles.
    // mValid is false for a triangle too thin to tell (then vertex 0 stands for it).
    struct TriangleBarycentrics { double mB1 = 0.0, mB2 = 0.0; bool mValid = false; };
    static TriangleBarycentrics Barycentrics(const Triangle& aTriangle, const Vec3& aPoint) {
        const glm::dvec3 p0(aTriangle.mP0), e1 = glm::dvec3(aTriangle.mP1) - p0, e2 = glm::dvec3(aTriangle.mP2) - p0;
        const glm::dvec3 toPoint = glm::dvec3(aPoint) - p0;
        const double d11 = glm::dot(e1, e1), d12 = glm::dot(e1, e2), d22 = glm::dot(e2, e2);
        const double dp1 = glm::dot(toPoint, e1), dp2 = glm::dot(toPoint, e2);
        const double denominator = d11 * d22 - d12 * d12;
        if (!(denominator > 0.0)) return {};
        return {(d22 * dp1 - d12 * dp2) / denominator, (d11 * dp2 - d12 * dp1) / denominator, true};
    }
    // Texture coordinates at a point of aTriangle with barycentric coordinates aB.
    static Vec2 TriangleUv(const Triangle& aTriangle, const TriangleBarycentrics& aB) {
        if (!aB.mValid) return aTriangle.mUv0;
        const double b1 = aB.mB1, b2 = aB.mB2;
        return Vec2(glm::dvec2(aTriangle.mUv0) * (1.0 - b1 - b2) + glm::dvec2(aTriangle.mUv1) * b1 + glm::dvec2(aTriangle.mUv2) * b2);
    }
    // The shading normal at a point of a smooth triangle: its vertex normals interpolated
    // with the barycentric coordinates aB and normalised (Phong, 1975), then turned to the
    // side of the geometric normal. The winding decides which side is the front (glTF),
    // and the Bsdf needs both normals on one side to tell the sides apart. Where the
    // vertex normals cancel out (opposite normals, nothing to interpolate) it is flat.
    static Vec3 InterpolatedNormal(const Triangle& aTriangle, const TriangleBarycentrics& aB) {
        if (!aB.mValid) return aTriangle.mNormal;
        const double b1 = aB.mB1, b2 = aB.mB2;
        const glm::dvec3 sum = glm::dvec3(aTriangle.mN0) * (1.0 - b1 - b2) + glm::dvec3(aTriangle.mN1) * b1 +
                               glm::dvec3(aTriangle.mN2) * b2;
        const double length = glm::length(sum);
        if (!(length > 1e-6) || !std::isfinite(length)) return aTriangle.mNormal;
        const Vec3 normal(sum / length);
        return glm::dot(normal, aTriangle.mNormal) < 0.f ? -normal : normal;
    }

    // The shading normal aNormal tilted by the material's normal map at aUv (glTF
    // normalTexture). The texel, mapped from [0, 1] to [-1, 1] with x and y times the
    // scale, is a direction in the tangent frame (T, B, N): N = aNormal, T the interpolated
    // tangent made orthogonal to N, B = w (N x T). The image's +x runs along T (increasing
    // u) and its up along B (decreasing v: glTF's v runs down the image). The result is a
    // shading normal like any other (the BSDF's no-leak rule and adjoint factor apply);
    // one that would face away from the surface, or a frame that cannot be built, leaves
    // aNormal as it is.
    Vec3 NormalMapped(const Triangle& aTriangle, const TriangleBarycentrics& aB, const Vec3& aNormal, const Vec2& aUv,
                      const Material& aMaterial) const {
        if (!aB.mValid) return aNormal;
        const float b1 = float(aB.mB1), b2 = float(aB.mB2), b0 = 1.f - b1 - b2;
        const Vec4 tangent = b0 * aTriangle.mT0 + b1 * aTriangle.mT1 + b2 * aTriangle.mT2;
        Vec3 t = Vec3(tangent) - aNormal * glm::dot(aNormal, Vec3(tangent));
        const float tLength = glm::length(t);
        if (!(tLength > 1e-6f) || !std::isfinite(tLength)) return aNormal;
        t /= tLength;
        const Vec3 b = (tangent.w < 0.f ? -1.f : 1.f) * glm::cross(aNormal, t);
        const Vec3 texel = mTextures[size_t(aMaterial.mNormalTexture)].Lookup(aUv);
        const Vec3 local((2.f * texel.x - 1.f) * aMaterial.mNormalScale, (2.f * texel.y - 1.f) * aMaterial.mNormalScale,
                         2.f * texel.z - 1.f);
        const Vec3 tilted = local.x * t + local.y * b + local.z * aNormal;
        const float length = glm::length(tilted);
        if (!(length > 1e-6f) || !std::isfinite(length)) return aNormal;
        const Vec3 normal = tilted / length;
        return glm::dot(normal, aTriangle.mNormal) > 0.f ? normal : aNormal;
    }

private:
    // --- Finalize's steps ------------------------------------------------------------
    // Something to render and lights that emit a finite, non-negative amount.
    void ValidateLights(const std::string& aWhere) const {
        if (mTriangles.empty() && mSpheres.empty()) throw Error(aWhere + ": the scene has no geometry");
        if (mLights.empty()) throw Error(aWhere + ": the scene has no light");
        int backgrounds = 0;
        for (const Light& light : mLights) {
            if (!IsFinite(light.mEmission) || light.mEmission.x < 0.f || light.mEmission.y < 0.f || light.mEmission.z < 0.f)
                throw Error(aWhere + ": a light has a negative or non-finite emission");
            if (light.mType == LightType::kBackground) backgrounds++;
        }
        if (backgrounds > 1) throw Error(aWhere + ": more than one background light");
    }

    // Every triangle's normal from its winding, vertex normals normalised, materials
    // checked; the bounding sphere and the ray offset that scales with it.
    void FinalizeGeometry(const std::string& aWhere) {
        Aabb box;
        for (size_t t = 0; t < mTriangles.size(); t++) {
            Triangle& triangle = mTriangles[t];
            if (!IsFinite(triangle.mP0) || !IsFinite(triangle.mP1) || !IsFinite(triangle.mP2))
                throw Error(aWhere + ": triangle " + std::to_string(t) + " has a non-finite vertex");
            const std::optional<Vec3> geometricNormal = TriangleNormal(triangle.mP0, triangle.mP1, triangle.mP2);
            if (!geometricNormal)
                throw Error(aWhere + ": triangle " + std::to_string(t) +
                            " is degenerate (zero area: its vertices coincide or lie on a line)");
            triangle.mNormal = *geometricNormal;
            if (triangle.mHasVertexNormals)
                for (Vec3* normal : {&triangle.mN0, &triangle.mN1, &triangle.mN2}) {
                    const double length = glm::length(glm::dvec3(*normal));
                    if (!IsFinite(*normal) || !(length > 0.0) || !std::isfinite(length))
                        throw Error(aWhere + ": triangle " + std::to_string(t) + " has a vertex normal that is zero or not finite");
                    *normal = Vec3(glm::dvec3(*normal) / length);
                }
            if (triangle.mHasTangents)
                for (const Vec4& tangent : {triangle.mT0, triangle.mT1, triangle.mT2})
                    if (!IsFinite(Vec3(tangent)) || !std::isfinite(tangent.w) || tangent.w == 0.f)
                        throw Error(aWhere + ": triangle " + std::to_string(t) + " has a tangent that is not finite or has no handedness (w)");
            CheckMaterial(aWhere, triangle.mMaterialId);
            box.Extend(triangle.mP0); box.Extend(triangle.mP1); box.Extend(triangle.mP2);
        }
        for (const Sphere& sphere : mSpheres) {
            if (!IsFinite(sphere.mCenter) || !std::isfinite(sphere.mRadius) || !(sphere.mRadius > 0.f))
                throw Error(aWhere + ": a sphere has a non-finite centre or a radius that is not positive");
            CheckMaterial(aWhere, sphere.mMaterialId);
            box.Extend(sphere.mCenter - Vec3(sphere.mRadius));
            box.Extend(sphere.mCenter + Vec3(sphere.mRadius));
        }
        mSceneSphere.mCenter = box.Centroid();
        mSceneSphere.mRadius = 0.5f * glm::length(box.mMax - box.mMin);
        if (!(mSceneSphere.mRadius > 0.f) || !std::isfinite(mSceneSphere.mRadius))
            throw Error(aWhere + ": the scene's bounding box is empty or infinite");
        mSceneSphere.mInvRadiusSqr = 1.f / Sqr(mSceneSphere.mRadius);
        mRayEpsilon = kRayEpsilonPerSceneRadius * mSceneSphere.mRadius;
    }

    // What each light samples from: its triangles (by area) or sphere, its emission
    // texture, its spot cone; then each light's power checked against its range.
    void FinalizeLights(const std::string& aWhere) {
        mBackgroundLightId = -1;
        for (size_t id = 0; id < mLights.size(); id++) {
            if (mLights[id].mType == LightType::kBackground) mBackgroundLightId = int(id);
            FinalizeLightParameters(aWhere, id);
        }
        for (const Triangle& triangle : mTriangles) {
            if (triangle.mLightId < 0) continue;
            if (triangle.mLightId >= int(mLights.size()) || mLights[size_t(triangle.mLightId)].mType != LightType::kArea)
                throw Error(aWhere + ": a triangle refers to a light that is not an area light");
            Light& light = mLights[size_t(triangle.mLightId)];
            light.mTriangleP0.push_back(triangle.mP0);
            light.mTriangleE1.push_back(triangle.mP1 - triangle.mP0);
            light.mTriangleE2.push_back(triangle.mP2 - triangle.mP0);
            light.mTriangleNormal.push_back(triangle.mNormal);
            light.mArea += triangle.Area();
            light.mTriangleCdf.push_back(light.mArea);
            if (light.mEmissionTexture >= 0) {
                if (!std::isfinite(triangle.mUv0.x) || !std::isfinite(triangle.mUv0.y) || !std::isfinite(triangle.mUv1.x) ||
                    !std::isfinite(triangle.mUv1.y) || !std::isfinite(triangle.mUv2.x) || !std::isfinite(triangle.mUv2.y))
                    throw Error(aWhere + ": a triangle of light " + std::to_string(triangle.mLightId) +
                                " has non-finite texture coordinates (NaN or infinity)");
                light.mTriangleUv0.push_back(triangle.mUv0);
                light.mTriangleUvE1.push_back(triangle.mUv1 - triangle.mUv0);
                light.mTriangleUvE2.push_back(triangle.mUv2 - triangle.mUv0);
            }
        }
        for (size_t s = 0; s < mSpheres.size(); s++) {
            const Sphere& sphere = mSpheres[s];
            if (sphere.mLightId < 0) continue;
            if (sphere.mLightId >= int(mLights.size()) || mLights[size_t(sphere.mLightId)].mType != LightType::kSphere)
                throw Error(aWhere + ": a sphere refers to a light that is not a sphere light");
            Light& light = mLights[size_t(sphere.mLightId)];
            light.mSphereCenter = sphere.mCenter;
            light.mSphereRadius = sphere.mRadius;
            light.mArea = 4.f * kPi * Sqr(sphere.mRadius);
        }
        for (size_t id = 0; id < mLights.size(); id++) {
            Light& light = mLights[id];
            if ((light.mType == LightType::kArea || light.mType == LightType::kSphere) && !(light.mArea > 0.f))
                throw Error(aWhere + ": an area or sphere light has no surface");
            CheckLightRange(aWhere, id);
            for (float& c : light.mTriangleCdf) c /= light.mArea;
            if (!light.mTriangleCdf.empty()) light.mTriangleCdf.back() = 1.f;
        }
    }

    // One light's own data: its emission texture (a copy, and the brightest texel) and
    // its spot cone; what its surfaces give is cleared for FinalizeLights to gather.
    void FinalizeLightParameters(const std::string& aWhere, size_t aId) {
        Light& light = mLights[aId];
        light.mTriangleP0.clear(); light.mTriangleE1.clear(); light.mTriangleE2.clear();
        light.mTriangleNormal.clear(); light.mTriangleCdf.clear();
        light.mTriangleUv0.clear(); light.mTriangleUvE1.clear(); light.mTriangleUvE2.clear();
        light.mArea = 0.f;
        light.mEmissionTextureCopy = Texture{};
        light.mBrightestEmissionTexel = Vec3(1.f);
        if (light.mEmissionTexture >= 0) {
            const std::string which = aWhere + ": light " + std::to_string(aId) + " (" + LightTypeName(light.mType) + ")";
            if (light.mType != LightType::kArea) throw Error(which + " has an emission texture; only area lights take one");
            if (!IsUsableTexture(light.mEmissionTexture))
                throw Error(which + " refers to a missing or empty emission texture");
            light.mEmissionTextureCopy = mTextures[size_t(light.mEmissionTexture)];
            light.mBrightestEmissionTexel = Vec3(0.f);
            for (size_t i = 0; i < light.mEmissionTextureCopy.TexelCount(); i++) {
                const Vec3 texel = light.mEmissionTextureCopy.Texel(i);
                if (!IsFinite(texel) || texel.x < 0.f || texel.y < 0.f || texel.z < 0.f)
                    throw Error(which + ": its emission texture has a negative or non-finite texel");
                light.mBrightestEmissionTexel = glm::max(light.mBrightestEmissionTexel, texel);
            }
        }
        if (light.mType == LightType::kSpot) {
            const std::string which = aWhere + ": light " + std::to_string(aId) + " (spot)";
            if (const char* problem = SpotConeProblem(light.mSpotInnerConeAngle, light.mSpotOuterConeAngle))
                throw Error(which + ": " + problem);
            if (!IsFinite(light.mPosition) || !IsFinite(light.mDirection) ||
                !(std::abs(glm::length(light.mDirection) - 1.f) < 1e-3f))
                throw Error(which + " has a non-finite position or an axis that is not a unit vector");
            const double cosInner = std::cos(double(light.mSpotInnerConeAngle));
            const double cosOuter = std::cos(double(light.mSpotOuterConeAngle));
            light.mSpotCosOuter = float(cosOuter);
            light.mSpotFalloffScale = float(1.0 / std::max(0.001, cosInner - cosOuter));
        }
    }

    // The BVH over every primitive, the per-triangle hit records and per-material constants.
    void BuildAcceleration() {
        PrimitiveSoup soup;
        for (const Triangle& triangle : mTriangles) {
            soup.mTriangleP0.push_back(triangle.mP0);
            soup.mTriangleP1.push_back(triangle.mP1);
            soup.mTriangleP2.push_back(triangle.mP2);
            soup.mTriangleCutOut.push_back(KindOf(triangle).mCutOut);
        }
        for (const Sphere& sphere : mSpheres) {
            soup.mSphereCenter.push_back(sphere.mCenter);
            soup.mSphereRadius.push_back(sphere.mRadius);
        }
        mBvh.Build(soup);
        BuildTriangleHitRecords();
        mMaterialConstants.clear();
        for (const Material& material : mMaterials) mMaterialConstants.push_back(ComputeMaterialConstants(material));
    }


    // Media: the coefficients checked; which primitives bound a medium, their closed
    // components and the medium outside each; the media of the camera and the lights.
    void FinalizeMedia(const std::string& aWhere) {
        ValidateMedia(aWhere);
        mMediaAtFinalize = MediaOfScene();
        mHasMedia = mSceneMedium >= 0;
        for (const Material& material : mMaterials) mHasMedia = mHasMedia || material.mMedium >= 0;
        mBoundaryOutside.clear();
        mLightMedia.clear();
        mCameraMedium = -1;
        if (!mHasMedia) return;
        int componentCount = 0;
        const std::vector<int> component = BoundaryComponents(aWhere, componentCount);
        // The medium outside a component is what a point just outside it finds, looking
        // past the component itself: nested components need one round per level.
        std::vector<int> outside(size_t(componentCount), mSceneMedium);
        for (int round = 0; round <= componentCount; round++) {
            bool changed = false;
            for (int c = 0; c < componentCount; c++) {
                const int medium = MediumAt(PointOutsideComponent(component, c), c, component, outside);
                changed = changed || medium != outside[size_t(c)];
                outside[size_t(c)] = medium;
            }
            if (!changed) break;
        }
        mBoundaryOutside.assign(component.size(), kNotBoundary);
        for (size_t p = 0; p < component.size(); p++)
            if (component[p] >= 0) mBoundaryOutside[p] = outside[size_t(component[p])];
        mCameraMedium = MediumAt(mCamera.Position(), -1, component, outside);
        for (size_t id = 0; id < mLights.size(); id++) {
            const std::optional<Vec3> point = LightPoint(int(id));
            mLightMedia.push_back(point ? MediumAt(*point, -1, component, outside) : mSceneMedium);
        }
    }
    // What FinalizeMedia resolved media from: the media, the scene medium, each material's.
    std::vector<float> MediaOfScene() const {
        std::vector<float> media{float(mSceneMedium)};
        for (const Medium& m : mMedia) media.insert(media.end(), {m.mSigmaA.x, m.mSigmaA.y, m.mSigmaA.z, m.mSigmaS.x, m.mSigmaS.y, m.mSigmaS.z, m.mG});
        for (const Material& material : mMaterials) media.push_back(float(material.mMedium));
        return media;
    }
    void ValidateMedia(const std::string& aWhere) const {
        for (size_t m = 0; m < mMedia.size(); m++) {
            const Medium& medium = mMedia[m];
            const std::string which = aWhere + ": medium " + std::to_string(m) + (medium.mName.empty() ? "" : " '" + medium.mName + "'");
            for (const Vec3& sigma : {medium.mSigmaA, medium.mSigmaS})
                if (!IsFinite(sigma) || sigma.x < 0.f || sigma.y < 0.f || sigma.z < 0.f)
                    throw Error(which + " has an absorption or scattering coefficient that is negative or not finite");
            if (!(std::abs(medium.mG) < 1.f))
                throw Error(which + " has a Henyey-Greenstein g outside (-1, 1)");
        }
        if (mSceneMedium < -1 || mSceneMedium >= int(mMedia.size()))
            throw Error(aWhere + ": the scene medium " + std::to_string(mSceneMedium) + " does not exist");
        for (size_t m = 0; m < mMaterials.size(); m++) {
            const Material& material = mMaterials[m];
            if (material.mMedium < -1 || material.mMedium >= int(mMedia.size()))
                throw Error(aWhere + ": material " + std::to_string(m) + " refers to medium " + std::to_string(material.mMedium) + ", which does not exist");
            if (material.mMedium >= 0 && !(material.mIor > 0.f) && !material.IsIndexMatchedBoundary())
                throw Error(aWhere + ": material " + std::to_string(m) + " '" + material.mName +
                            "' holds a medium but neither refracts (glass) nor is an index-matched boundary (no component): light could not enter it");
        }
    }

    // Per primitive (triangles, then spheres) the closed component of medium boundaries it
    // belongs to, or -1. A boundary is a material with a medium, or glass (in a scene with
    // media glass has an inside). Its triangles must form closed surfaces wound outwards:
    // every edge (by exact vertex positions) shared by two of its triangles in opposite
    // directions, and a positive enclosed volume. A sphere is a closed surface by itself.
    std::vector<int> BoundaryComponents(const std::string& aWhere, int& oCount) const {
        const auto isBoundary = [&](int aMaterial) {
            return mMaterials[size_t(aMaterial)].mMedium >= 0 || mMaterials[size_t(aMaterial)].mIor > 0.f;
        };
        const auto named = [&](int aMaterial) {
            return aWhere + ": material " + std::to_string(aMaterial) + " '" + mMaterials[size_t(aMaterial)].mName + "'";
        };
        std::vector<int> root(mTriangles.size());
        std::iota(root.begin(), root.end(), 0);
        const auto find = [&](int aT) { while (root[size_t(aT)] != aT) aT = root[size_t(aT)] = root[size_t(root[size_t(aT)])]; return aT; };
        std::map<std::array<float, 3>, int> vertexIds;
        std::map<std::pair<int, int>, int> edges;  // directed edge -> its triangle
        for (size_t t = 0; t < mTriangles.size(); t++) {
            const Triangle& triangle = mTriangles[t];
            if (!isBoundary(triangle.mMaterialId)) continue;
            int ids[3];
            const Vec3* corners[3] = {&triangle.mP0, &triangle.mP1, &triangle.mP2};
            for (int k = 0; k < 3; k++)
                ids[k] = vertexIds.emplace(std::array<float, 3>{corners[k]->x, corners[k]->y, corners[k]->z}, int(vertexIds.size())).first->second;
            for (int k = 0; k < 3; k++)
                if (!edges.emplace(std::make_pair(ids[k], ids[(k + 1) % 3]), int(t)).second)
                    throw Error(named(triangle.mMaterialId) + " bounds a medium, but its mesh is not a consistently wound closed surface (an edge is used twice in one direction)");
        }
        for (const auto& [edge, t] : edges) {
            const auto twin = edges.find(std::make_pair(edge.second, edge.first));
            const int material = mTriangles[size_t(t)].mMaterialId;
            if (twin == edges.end() || mTriangles[size_t(twin->second)].mMaterialId != material)
                throw Error(named(material) + " bounds a medium (or is glass in a scene with media), but its mesh is not closed: an edge belongs to one of its triangles only");
            root[size_t(find(t))] = find(twin->second);
        }
        std::vector<int> component(mTriangles.size() + mSpheres.size(), -1);
        std::map<int, int> componentOfRoot;
        std::vector<double> volume;
        for (size_t t = 0; t < mTriangles.size(); t++) {
            if (!isBoundary(mTriangles[t].mMaterialId)) continue;
            const int c = componentOfRoot.emplace(find(int(t)), int(componentOfRoot.size())).first->second;
            component[t] = c;
            volume.resize(componentOfRoot.size(), 0.0);
            const Triangle& tr = mTriangles[t];
            volume[size_t(c)] += glm::dot(glm::dvec3(tr.mP0), glm::cross(glm::dvec3(tr.mP1), glm::dvec3(tr.mP2)));
        }
        for (size_t t = 0; t < mTriangles.size(); t++)
            if (component[t] >= 0 && !(volume[size_t(component[t])] > 0.0))
                throw Error(named(mTriangles[t].mMaterialId) + " bounds a medium, but its closed mesh is wound inwards (its normals point in)");
        oCount = int(componentOfRoot.size());
        for (size_t sp = 0; sp < mSpheres.size(); sp++)
            if (isBoundary(mSpheres[sp].mMaterialId)) component[mTriangles.size() + sp] = oCount++;
        return component;
    }
    // A point just outside component aComponent, off its first primitive's front.
    Vec3 PointOutsideComponent(const std::vector<int>& aComponent, int aComponentId) const {
        const size_t p = size_t(std::find(aComponent.begin(), aComponent.end(), aComponentId) - aComponent.begin());
        if (p < mTriangles.size()) {
            const Triangle& t = mTriangles[p];
            return (t.mP0 + t.mP1 + t.mP2) / 3.f + t.mNormal * (4.f * mRayEpsilon);
        }
        const Sphere& sphere = mSpheres[p - mTriangles.size()];
        return sphere.mCenter + Vec3(0.f, sphere.mRadius + 4.f * mRayEpsilon, 0.f);
    }
    // The medium at aPoint: the first boundary a ray from it meets (component aSkip
    // aside) says, by the side it meets: its inside from behind, its outside from the front.
    int MediumAt(const Vec3& aPoint, int aSkip, const std::vector<int>& aComponent, const std::vector<int>& aOutside) const {
        const Vec3 direction = glm::normalize(Vec3(0.5381f, 0.6241f, 0.5663f));  // no axis, no diagonal
        Ray ray{aPoint, direction};
        for (size_t step = 0; step <= aComponent.size(); step++) {
            const SurfacePoint hit = Intersect(ray);
            if (!hit.IsValid()) return mSceneMedium;
            const int c = aComponent[size_t(hit.mPrimitiveId)];
            if (c >= 0 && c != aSkip)
                return glm::dot(direction, hit.GeometricNormal()) > 0.f ? mMaterials[size_t(hit.mMaterialId)].mMedium
                                                                       : aOutside[size_t(c)];
            ray = SpawnRay(hit.mPosition, direction);
        }
        return mSceneMedium;
    }
    // A point a light emits from, to find its medium: nothing for lights at infinity.
    std::optional<Vec3> LightPoint(int aLightId) const {
        const Light& light = mLights[size_t(aLightId)];
        if (light.mType == LightType::kPoint || light.mType == LightType::kSpot) return light.mPosition;
        if (light.mType == LightType::kSphere) return light.mSphereCenter + Vec3(0.f, light.mSphereRadius + 4.f * mRayEpsilon, 0.f);
        if (light.mType != LightType::kArea || light.mTriangleP0.empty()) return std::nullopt;
        return light.mTriangleP0[0] + (light.mTriangleE1[0] + light.mTriangleE2[0]) / 3.f + light.mTriangleNormal[0] * (4.f * mRayEpsilon);
    }

    // What FillSurfacePoint needs of a hit triangle, by Finalize: its normal and kind in 16
    // bytes, instead of the whole Triangle (which on a large mesh is a cache miss per hit);
    // the few kinds stay in the cache.
    struct TriangleKind {
        int mMaterialId = 0;
        int mLightId = -1;
        bool mTextured = false;          // a base-colour or emission texture: needs the uv
        bool mHasVertexNormals = false;  // smooth: needs the interpolated normal
        bool mNormalMapped = false;      // a normal map and tangents: tilts the shading normal
        bool mCutOut = false;            // an alpha cut-out: the BVH asks IsSolidAt about its hits
        bool operator==(const TriangleKind& aOther) const {
            return std::tie(mMaterialId, mLightId, mTextured, mHasVertexNormals, mNormalMapped, mCutOut) ==
                   std::tie(aOther.mMaterialId, aOther.mLightId, aOther.mTextured, aOther.mHasVertexNormals,
                            aOther.mNormalMapped, aOther.mCutOut);
        }
        bool operator<(const TriangleKind& aOther) const {
            return std::tie(mMaterialId, mLightId, mTextured, mHasVertexNormals, mNormalMapped, mCutOut) <
                   std::tie(aOther.mMaterialId, aOther.mLightId, aOther.mTextured, aOther.mHasVertexNormals,
                            aOther.mNormalMapped, aOther.mCutOut);
        }
    };
    struct alignas(16) TriangleHitRecord {
        Vec3 mNormal{0.f};
        uint32_t mKind = 0;  // index into mTriangleKinds
    };
    TriangleKind KindOf(const Triangle& aTriangle) const {
        TriangleKind kind;
        kind.mMaterialId = aTriangle.mMaterialId;
        kind.mLightId = aTriangle.mLightId;
        kind.mTextured = mMaterials[size_t(aTriangle.mMaterialId)].mBaseColorTexture >= 0 ||
                         mMaterials[size_t(aTriangle.mMaterialId)].mMetallicRoughnessTexture >= 0 ||
                         (aTriangle.mLightId >= 0 && mLights[size_t(aTriangle.mLightId)].mEmissionTexture >= 0);
        kind.mHasVertexNormals = aTriangle.mHasVertexNormals;
        kind.mNormalMapped = aTriangle.mHasTangents && mMaterials[size_t(aTriangle.mMaterialId)].mNormalTexture >= 0;
        kind.mTextured = kind.mTextured || kind.mNormalMapped;
        // An emitter stays whole: a light samples its whole area (Light::Illuminate), so
        // holes in it would be lit points that no ray can reach.
        kind.mCutOut = mMaterials[size_t(aTriangle.mMaterialId)].HasCutOut() && aTriangle.mLightId < 0;
        return kind;
    }
    void BuildTriangleHitRecords() {
        mTriangleKinds.clear();
        mTriangleHitRecords.clear();
        mTriangleHitRecords.reserve(mTriangles.size());
        std::map<TriangleKind, uint32_t> kindIds;
        for (const Triangle& triangle : mTriangles) {
            const TriangleKind kind = KindOf(triangle);
            const auto inserted = kindIds.emplace(kind, uint32_t(mTriangleKinds.size()));
            if (inserted.second) mTriangleKinds.push_back(kind);
            mTriangleHitRecords.push_back(TriangleHitRecord{triangle.mNormal, inserted.first->second});
        }
    }

    // Refuses a light whose power or area pdf would overflow float arithmetic in some
    // estimator (kMaxLightPower, kMinLightArea); the scene sphere must be set.
    void CheckLightRange(const std::string& aWhere, size_t aId) const {
        const Light& light = mLights[aId];
        // A textured light's radiance is at most its emission times the brightest texel.
        const Vec3 peak = light.mEmission * (light.mEnvironment ? light.mEnvironment->BrightestTexel() : light.mBrightestEmissionTexel);
        const double brightest = std::max({double(peak.x), double(peak.y), double(peak.z)});
        const double discArea = double(kPi) * Sqr(double(mSceneSphere.mRadius));
        double power = 0.0;
        switch (light.mType) {
        case LightType::kArea: case LightType::kSphere:
            power = brightest * double(kPi) * double(light.mArea) / double(light.SideProbability());
            break;
        case LightType::kPoint: power = brightest * 4.0 * double(kPi); break;
        case LightType::kSpot: power = brightest * light.SpotFalloffSolidAngle(); break;
        case LightType::kDirectional: power = brightest * discArea; break;
        case LightType::kBackground: power = brightest * 4.0 * double(kPi) * discArea; break;
        }
        const std::string which = aWhere + ": light " + std::to_string(aId) + " (" + LightTypeName(light.mType) + ")";
        if (!(power <= double(kMaxLightPower)))
            throw Error(which + " emits a power of " + ShortNumber(power) + ", above the " + ShortNumber(kMaxLightPower) +
                        " single-precision arithmetic allows: scale its emission down");
        if ((light.mType == LightType::kArea || light.mType == LightType::kSphere) && !(light.mArea >= kMinLightArea))
            throw Error(which + " has an area of " + ShortNumber(light.mArea) + ", below the " + ShortNumber(kMinLightArea) +
                        " whose inverse (its sampling pdf) single precision can hold: enlarge it or use a point light");
    }
    // Whether mTextures[aTexture] exists and holds width x height texels.
    bool IsUsableTexture(int aTexture) const {
        if (aTexture < 0 || aTexture >= int(mTextures.size())) return false;
        const Texture& texture = mTextures[size_t(aTexture)];
        const size_t texels = size_t(texture.mWidth) * size_t(texture.mHeight);
        return texture.mWidth > 0 && texture.mHeight > 0 && texture.TexelCount() == texels &&
               (texture.mEncoded.empty() || texture.mTexels.empty()) && texture.mEncoded.size() % 3 == 0 &&
               (texture.mAlpha.empty() || texture.mAlpha.size() == texels);
    }
    void CheckMaterial(const std::string& aWhere, int aMaterialId) const {
        if (aMaterialId >= 0 && size_t(aMaterialId) < mMaterials.size()) {
            const Material& material = mMaterials[size_t(aMaterialId)];
            for (const int texture : {material.mBaseColorTexture, material.mNormalTexture, material.mMetallicRoughnessTexture})
                if (texture >= 0 && !IsUsableTexture(texture))
                    throw Error(aWhere + ": material " + std::to_string(aMaterialId) + " refers to a missing or empty texture");
            if (!std::isfinite(material.mNormalScale))
                throw Error(aWhere + ": material " + std::to_string(aMaterialId) + " has a normal scale that is not finite");
            if (material.mAlphaTexture >= 0 && !IsUsableTexture(material.mAlphaTexture))
                throw Error(aWhere + ": material " + std::to_string(aMaterialId) + " refers to a missing or empty alpha texture");
            if (!(material.mAlphaCutoff >= 0.f) || !(material.mBaseColorAlpha >= 0.f && material.mBaseColorAlpha <= 1.f))
                throw Error(aWhere + ": material " + std::to_string(aMaterialId) +
                            " has an alpha cutoff that is negative or NaN, or a base colour alpha outside [0, 1]");
        }
        if (aMaterialId < 0 || aMaterialId >= int(mMaterials.size()))
            throw Error(aWhere + ": a primitive refers to material " + std::to_string(aMaterialId) + ", which does not exist");
    }

    SceneSphere mSceneSphere;
    float mRayEpsilon = 1e-3f;
    int mBackgroundLightId = -1;
    // Media, by FinalizeMedia: per primitive the medium outside it when it is a medium
    // boundary (kNotBoundary otherwise), per light the medium it emits into.
    static constexpr int kNotBoundary = -2;
    bool mHasMedia = false;
    int mCameraMedium = -1;
    std::vector<int> mBoundaryOutside;
    std::vector<int> mLightMedia;
    std::vector<float> mMediaAtFinalize;  // MediaOfScene() when they were resolved
    Bvh mBvh;
    std::vector<MaterialConstants> mMaterialConstants;  // one per material, by Finalize
    std::vector<TriangleKind> mTriangleKinds;             // by Finalize (BuildTriangleHitRecords)
    std::vector<TriangleHitRecord> mTriangleHitRecords;   // one per triangle, by Finalize
    bool mFinalized = false;
};


// =====================================================================================
// [SECTION] Participating media
// =====================================================================================
// Provides: what light does between surfaces in a homogeneous Medium (Scene section):
// transmittance, free-flight distance sampling, the Henyey-Greenstein phase function,
// and the two walks the estimators take through media: TraceSegment (a sub-path's next
// vertex: a surface, or a scattering point in a medium) and TraceConnection (what a
// connection, a shadow ray or a merge's neighbour sees between two points). Relies on:
// Scene (its media, MediumAfter, Intersect). A scene without media takes the same
// steps as empty space: every factor below is exactly 1 there.
//
// The maths (e.g. Pharr, Jakob and Humphreys, pbrt 4th ed., ch. 11 and 14):
//  * Transmittance over a distance d: T(d) = exp(-sigma_t d) per channel (Beer-Lambert).
//  * Radiance along a ray picks up in-scattering: L(x, w) = T(d) L(surface) +
//    int_0^d T(t) sigma_s(x_t) int p(w', w) L(x_t, w') dw' dt, so a medium vertex x_t
//    carries f = sigma_s p (the "BSDF" of a point in a medium: Bsdf::SetupInMedium) and
//    no cosine, and its pdf is a volume pdf p_W(w) p(t) / t^2.
//  * Free-flight sampling of a chromatic medium: pick a channel c uniformly, sample
//    t ~ sigma_t,c exp(-sigma_t,c t); the pdf of t is the average of the channels' pdfs
//    (one-sample MIS over the channels, balance heuristic), so it stays unbiased where
//    one channel is clear: p(t) = 1/3 sum_c sigma_t,c T_c(t) for a scattering point
//    before the surface at distance d, P(d) = 1/3 sum_c T_c(d) for reaching the surface.
//    The throughput takes T(t) / p(t) or T(d) / P(d) per channel.
//  * A segment that crosses index-matched boundaries is one straight segment through
//    several media: its transmittance and pdfs are the products over the pieces.
//  * MIS needs the pdf of a segment's end from its start (forward) and of its start from
//    its end (reverse). In a homogeneous piece they differ only at the ends: a point in a
//    medium is reached with density sigma_t T, a surface with probability T.

// Beer-Lambert per channel. A clear channel (sigma_t = 0) is 1 even at infinity.
inline Vec3 MediumTransmittance(const Medium& aMedium, float aDistance) {
    const Vec3 sigmaT = aMedium.SigmaT();
    Vec3 t;
    for (int c = 0; c < 3; c++) t[c] = sigmaT[c] > 0.f ? std::exp(-sigmaT[c] * aDistance) : 1.f;
    return t;
}
// The free-flight pdfs averaged over the channels: of scattering at distance aT, and of
// flying past aDistance.
inline float FreeFlightDensity(const Medium& aMedium, float aT) {
    const Vec3 t = MediumTransmittance(aMedium, aT);
    const Vec3 sigmaT = aMedium.SigmaT();
    return (sigmaT.x * t.x + sigmaT.y * t.y + sigmaT.z * t.z) / 3.f;
}
inline float FreeFlightProbability(const Medium& aMedium, float aDistance) {
    const Vec3 t = MediumTransmittance(aMedium, aDistance);
    return (t.x + t.y + t.z) / 3.f;
}
// A short beam's coverage over the free-flight density, R(t) = P(t) / p(t), at distance
// aT into a piece of a medium [Krivanek et al. 2014, sec. 5]: a beam technique integrates
// along the segment where a point technique sampled a free flight, so in its pdf the
// density p(t) of the point becomes the probability P(t) that the beam reaches it.
// 1 / sigma_t in a grey medium.
inline float BeamCoverageRatio(const Medium& aMedium, float aT) {
    return FreeFlightProbability(aMedium, aT) / FreeFlightDensity(aMedium, aT);
}
// A free-flight distance: aRnd picks the channel (its third) and the exponential
// distance in it; infinity for a clear channel.
inline float SampleFreeFlight(const Medium& aMedium, float aRnd) {
    const int channel = std::min(int(aRnd * 3.f), 2);
    const float u = aRnd * 3.f - float(channel);
    const float sigmaT = aMedium.SigmaT()[channel];
    if (!(sigmaT > 0.f)) return std::numeric_limits<float>::infinity();
    return -std::log1p(-std::min(u, 0.99999994f)) / sigmaT;
}

// Henyey-Greenstein (1941): p(cos) = (1 - g^2) / (4 pi (1 + g^2 - 2 g cos)^(3/2)), cos
// between the direction light travelled before and after scattering. With fix and gen
// both pointing away from the vertex (Bsdf's convention) cos = -fix . gen; p depends on
// it alone, so sampling gen given fix and fix given gen have one pdf.
inline float HenyeyGreensteinPdf(float aCosTheta, float aG) {
    const float denominator = 1.f + aG * aG - 2.f * aG * aCosTheta;
    return (1.f - aG * aG) / (4.f * kPi * denominator * std::sqrt(denominator));
}
// The direction light travels after scattering, given aTravel before it: cos theta by
// inverting HG's cdf (pbrt 4th ed., eq. 11.13), phi uniform.
inline Vec3 SampleHenyeyGreenstein(const Vec3& aTravel, float aG, const Vec2& aRnd) {
    float cosTheta;
    if (std::abs(aG) < 1e-3f) cosTheta = 1.f - 2.f * aRnd.x;
    else {
        const float s = (1.f - aG * aG) / (1.f - aG + 2.f * aG * aRnd.x);
        cosTheta = (1.f + aG * aG - s * s) / (2.f * aG);
    }
    cosTheta = std::min(1.f, std::max(-1.f, cosTheta));
    const float sinTheta = std::sqrt(std::max(0.f, 1.f - cosTheta * cosTheta));
    const float phi = 2.f * kPi * aRnd.y;
    return Frame(aTravel).ToWorld(Vec3(std::cos(phi) * sinTheta, std::sin(phi) * sinTheta, cosTheta));
}

// The MIS pdfs of a segment's distance sampling, from its pieces: every inner piece is
// flown through (probability P), the end pieces are reached with density or probability.
struct SegmentPdfs {
    float mForward = 1.f;  // of reaching the end from the start
    float mReverse = 1.f;  // of reaching the start from the end
};

// Where a sub-path's next segment ends (TraceSegment): at a surface, at a scattering
// point in a medium, or out of the scene.
struct PathSegment {
    // Where it ends: a surface point; at a point in a medium only mHit's mPosition is set
    // (IsValid() is false); out of the scene it is invalid. Its length from the vertex it
    // left, across index-matched boundaries, is mHit.mDist plus the gap of the ray that
    // found mHit (LeaveVertex).
    SurfacePoint mHit;
    float mGap = 0.f;
    bool mInMedium = false;   // it ends at a scattering point of medium mMedium
    int mMedium = -1;         // the medium it ends in (the last piece's)
    Vec3 mWeight{1.f};        // T / (its distance pdf), per channel
    SegmentPdfs mPdfs;
    // The lengths of its first and last pieces in an attenuating medium (UPBP's beam
    // ratios at its two ends: BeamCoverageRatio).
    float mFirstPiece = 0.f, mLastPiece = 0.f;
    const Vec3& Position() const { return mHit.mPosition; }
    float Length() const { return mHit.mDist + mGap; }
    bool Escaped() const { return !mHit.IsValid() && !mInMedium; }
};

// A piece of a segment in a scattering medium, for estimators that gather along the
// segment (the beam radiance estimate): from where it starts to the surface that ends it
// or the sampled scattering point, and the transmittance and the probability of flying
// through the segment's pieces before it (per channel; channels averaged).
struct SegmentPiece {
    Vec3 mStart{0.f};
    float mLength = 0.f;
    int mMedium = -1;
    Vec3 mTransmittanceBefore{1.f};
    float mProbabilityBefore = 1.f;
    float mOffset = 0.f;  // from the segment's vertex to the piece's start
};

// The next vertex from aRay's origin, a vertex in medium aMedium (aFromMedium: a medium
// point rather than a surface, which decides the reverse pdf). Steps through
// index-matched boundaries, and samples a free flight in each attenuating medium.
// aPieces, if given, receives the segment's pieces in scattering media.
// aGap: how far aRay's origin lies off the vertex it leaves (the ray epsilon of SpawnRay,
// 0 for a camera's primary ray and a point in a medium). Each piece is measured, and its
// free flight sampled, from where it starts (the vertex, or the boundary it crossed), not
// from the ray's origin a gap beyond: a gap flown for free would be a thin shell of
// medium where light neither scatters nor is absorbed, and TraceConnection measures the
// same segment whole for the techniques that connect it.
inline PathSegment TraceSegmentThroughMedia(const Scene& aScene, Ray aRay, int aMedium, bool aFromMedium, Sampler& aSampler,
                                            float aGap, std::vector<SegmentPiece>* aPieces = nullptr);
// In a scene without media the next vertex is the nearest surface, and every factor 1.
// (Both returns build the segment in the caller's place: no copy of it is made.)
SMALLVCM_ALWAYS_INLINE PathSegment TraceSegment(const Scene& aScene, const Ray& aRay, int aMedium, bool aFromMedium,
                                                Sampler& aSampler, float aGap, std::vector<SegmentPiece>* aPieces = nullptr) {
    if (aScene.HasMedia()) return TraceSegmentThroughMedia(aScene, aRay, aMedium, aFromMedium, aSampler, aGap, aPieces);
    return PathSegment{aScene.Intersect(aRay), aGap, false, -1, Vec3(1.f), SegmentPdfs{}};
}
inline PathSegment TraceSegmentThroughMedia(const Scene& aScene, Ray aRay, int aMedium, bool aFromMedium, Sampler& aSampler,
                                            float aGap, std::vector<SegmentPiece>* aPieces) {
    PathSegment segment;
    segment.mMedium = aMedium;
    float length = 0.f;     // from the vertex to where this piece starts
    float offset = aGap;    // how far aRay's origin lies past where this piece starts
    if (aPieces) aPieces->clear();
    Vec3 transmittance(1.f);  // of the pieces so far (only with aPieces)
    float probability = 1.f;
    for (int piece = 0;; piece++) {
        segment.mHit = aScene.Intersect(aRay);
        const float toSurface = segment.mHit.mDist + offset;
        if (aMedium >= 0 && aScene.GetMedium(aMedium).Attenuates()) {
            const Medium& medium = aScene.GetMedium(aMedium);
            const float t = SampleFreeFlight(medium, aSampler.Get1D());
            const bool scatters = t < toSurface;
            const float d = scatters ? t : toSurface;
            const float forward = scatters ? FreeFlightDensity(medium, d) : FreeFlightProbability(medium, d);
            segment.mWeight *= MediumTransmittance(medium, d) / forward;
            segment.mPdfs.mForward *= forward;
            segment.mPdfs.mReverse *= piece == 0 && aFromMedium ? FreeFlightDensity(medium, d) : FreeFlightProbability(medium, d);
            if (piece == 0) segment.mFirstPiece = d;
            segment.mLastPiece = d;
            if (aPieces) {
                if (medium.Scatters())
                    aPieces->push_back(SegmentPiece{aRay.mOrigin - offset * aRay.mDirection, d, aMedium, transmittance, probability, length});
                transmittance *= MediumTransmittance(medium, d);
                probability *= FreeFlightProbability(medium, d);
            }
            if (scatters) {
                segment.mInMedium = true;
                segment.mHit = SurfacePoint{};
                segment.mHit.mPosition = aRay.mOrigin + (t - offset) * aRay.mDirection;
                segment.mHit.mDist = length + t;
                return segment;
            }
        }
        length += toSurface;
        if (!segment.mHit.IsValid() || !aScene.IsIndexMatchedBoundary(segment.mHit) || piece >= kMaxMediumCrossings) break;
        aMedium = segment.mMedium = aScene.MediumAfter(segment.mHit, aRay.mDirection, aMedium);
        aRay = aScene.SpawnRay(segment.mHit.mPosition, aRay.mDirection);
        offset = aScene.RayEpsilon();
    }
    segment.mHit.mDist = length;
    return segment;
}

// The ray that leaves a vertex along aDirection: off a surface by the ray epsilon
// (SpawnRay), from a point in a medium exactly there (no surface to leave, and a gap
// would be flown through for free). Its gap is what TraceSegment's aGap takes.
SMALLVCM_ALWAYS_INLINE Ray LeaveVertex(const Scene& aScene, const Vec3& aPoint, const Vec3& aDirection, bool aInMedium) {
    return aInMedium ? Ray{aPoint, aDirection} : aScene.SpawnRay(aPoint, aDirection);
}
SMALLVCM_ALWAYS_INLINE float GapOfVertex(const Scene& aScene, bool aInMedium) { return aInMedium ? 0.f : aScene.RayEpsilon(); }

// The medium a connection from the vertex a segment ended at starts in, towards aDirection.
SMALLVCM_ALWAYS_INLINE int MediumTowards(const Scene& aScene, const PathSegment& aVertex, const Vec3& aDirection) {
    return aVertex.mInMedium ? aVertex.mMedium : aScene.MediumAfter(aVertex.mHit, aDirection, aVertex.mMedium);
}

// What lies between two points (TraceConnection): whether a surface blocks the way, and
// otherwise the transmittance and the distance pdfs of the media between them.
struct SegmentMedia {
    bool mOccluded = false;
    Vec3 mTransmittance{1.f};
    // The pieces' pdfs: the first and the last piece reached with density (the end is a
    // medium point) or flown through, and the product of the pieces between them.
    float mFirstDensity = 1.f, mFirstProbability = 1.f, mLastDensity = 1.f, mLastProbability = 1.f, mMiddle = 1.f;
    int mPieces = 0;
    // UPBP's beam ratios (BeamCoverageRatio) at the start and at the end, for end points in media.
    float FirstRatio() const { return mFirstProbability / mFirstDensity; }
    float LastRatio() const { return mLastProbability / mLastDensity; }
    // The segment's forward and reverse pdfs, for ends that are medium points or surfaces.
    SegmentPdfs Pdfs(bool aStartInMedium, bool aEndInMedium) const {
        if (mPieces <= 1)
            return {aEndInMedium ? mLastDensity : mLastProbability, aStartInMedium ? mFirstDensity : mFirstProbability};
        return {mFirstProbability * mMiddle * (aEndInMedium ? mLastDensity : mLastProbability),
                (aStartInMedium ? mFirstDensity : mFirstProbability) * mMiddle * mLastProbability};
    }
};

// The way from aPoint along aDirection over aDistance, starting in medium aMedium: a
// shadow ray in empty space, or a walk through index-matched boundaries otherwise. Both
// ends are pulled in by the ray epsilon (Scene::Occluded).
inline SegmentMedia TraceConnectionThroughMedia(const Scene& aScene, const Vec3& aPoint, const Vec3& aDirection, float aDistance,
                                                int aMedium);
SMALLVCM_ALWAYS_INLINE SegmentMedia TraceConnection(const Scene& aScene, const Vec3& aPoint, const Vec3& aDirection, float aDistance,
                                                    int aMedium) {
    if (aScene.HasMedia()) return TraceConnectionThroughMedia(aScene, aPoint, aDirection, aDistance, aMedium);
    return SegmentMedia{aScene.Occluded(aPoint, aDirection, aDistance)};  // built in the caller's place, as in TraceSegment
}
inline SegmentMedia TraceConnectionThroughMedia(const Scene& aScene, const Vec3& aPoint, const Vec3& aDirection, float aDistance,
                                                int aMedium) {
    SegmentMedia media;
    Vec3 origin = aPoint;
    float remaining = aDistance;
    for (;; media.mPieces++) {
        const Ray ray = aScene.SpawnRay(origin, aDirection);
        const SurfacePoint hit = aScene.Intersect(ray);
        const bool ends = !(hit.mDist < remaining - 2.f * aScene.RayEpsilon());
        const float length = ends ? remaining : hit.mDist + aScene.RayEpsilon();
        if (!ends && (!aScene.IsIndexMatchedBoundary(hit) || media.mPieces >= kMaxMediumCrossings)) {
            media.mOccluded = true;
            return media;
        }
        if (media.mPieces >= 2) media.mMiddle *= media.mLastProbability;  // the piece before is an inner one
        float density = 1.f, probability = 1.f;
        if (aMedium >= 0) {
            const Medium& medium = aScene.GetMedium(aMedium);
            media.mTransmittance *= MediumTransmittance(medium, length);
            density = FreeFlightDensity(medium, length);
            probability = FreeFlightProbability(medium, length);
        }
        if (media.mPieces == 0) {
            media.mFirstDensity = density;
            media.mFirstProbability = probability;
        }
        media.mLastDensity = density;
        media.mLastProbability = probability;
        if (ends) break;
        aMedium = aScene.MediumAfter(hit, aDirection, aMedium);
        origin = hit.mPosition;
        remaining -= length;
    }
    media.mPieces++;
    return media;
}

// =====================================================================================
// [SECTION] BSDF
// =====================================================================================
// Provides: Bsdf, the scattering function at one hit point, set up for a camera
// sub-path (radiance transport) or a light sub-path (importance transport), with
// Evaluate, Pdf (both directions, as MIS needs) and Sample. Relies on: Scene.
//
// A material is a sum of components, picked by sampling in proportion to the luminance
// of their albedos (SmallVCM): Lambert, normalised Phong, Fresnel-weighted mirror (plus
// an unweighted one in front: the opaque share of partly transmissive glass), and
// refraction, (1 - F) times the material's transmittance (its tint and glass share).
// Evaluate and Pdf see only the non-specular part; the specular (delta) components exist
// only through Sample. Evaluate, EvaluatePath, Pdf and Sample give the
// BSDF's own pdfs; Russian roulette enters them in one place, Bsdf::WithRoulette, through
// which EvaluateWithRoulette, EvaluatePathWithRoulette and SampleScatteringWithRoulette
// (what the integrators use) return pdfs that include it.
//
// Shading normals (Veach 1997, sec. 5.3). A smooth triangle shades with its interpolated
// normal Ns while its surface, and so every change of measure, has the geometric normal
// Ng. The rules, the same for every estimator:
//  * The components are evaluated and sampled in the frame of Ns; the cosine returned
//    beside f (cosThetaGen) is |gen . Ns|, so f cosThetaGen is one step's factor.
//  * The side is decided by Ng: a two-sided material turns both normals towards the
//    fixed direction when it arrives from behind Ng; a one-sided one is black there.
//  * No light leaks: a direction (fixed or generated) that lies on one side of the
//    shading surface and the other side of the geometric one contributes nothing.
//    Evaluate returns black for it, Sample rejects it, and Setup makes the Bsdf invalid
//    when the fixed direction is one. (With Ns = Ng this never happens.)
//  * The BSDF this defines on paths (area measure, with geometric cosines in G) is
//        f_path(wL -> wE) = f_s(wL, wE) |wL . Ns| / |wL . Ng|      (wL towards the light)
//    and it is not symmetric. Radiance (camera sub-paths, fix = wE, gen = wL) gets
//    f_path |wL . Ng| = f_s |gen . Ns| from f_s alone. Importance (light sub-paths, fix =
//    wL, gen = wE) needs f_path |wE . Ng| = f_s |fix . Ns| |gen . Ng| / |fix . Ng|, so a Bsdf
//    set up for a light sub-path returns f_s times the adjoint factor
//        |fix . Ns| |gen . Ng| / (|fix . Ng| |gen . Ns|)         (AdjointShadingFactor)
//    and f cosThetaGen is again the right step factor. Without it light tracing, photon
//    mapping, BPT and VCM converge to another image than path tracing.
//  * Every conversion between solid angle and area (the MIS quantities, a camera's or
//    BSDF's area pdf) uses the geometric cosine, GeometricCos(); a density estimate
//    (photons, merging) divides flux by geometric area, so it needs f_path itself:
//    EvaluatePath().
// For flat triangles and spheres Ns = Ng bit for bit, and every value is computed
// exactly as before shading normals existed.

enum BsdfEvent : uint32_t {
    kEventNone = 0,
    kEventDiffuse = 1,
    kEventPhong = 2,
    kEventReflect = 4,
    kEventRefract = 8,
    kEventSpecular = kEventReflect | kEventRefract,
    kEventMedium = 16,  // scattering at a point in a medium (Bsdf::SetupInMedium)
};

// Unpolarised Fresnel reflectance of a dielectric (Fresnel equations, averaged over the
// two polarisations). aCosIncident is measured against the outward normal: negative means
// the ray arrives from inside, where the index is aIor; outside it is 1.
inline float FresnelDielectric(float aCosIncident, float aIor) {
    if (aIor < 0.f) return 1.f;
    float etaIncOverEtaTrans = 1.f / aIor;
    if (aCosIncident < 0.f) { aCosIncident = -aCosIncident; etaIncOverEtaTrans = aIor; }
    const float sinTrans2 = Sqr(etaIncOverEtaTrans) * (1.f - Sqr(aCosIncident));
    if (sinTrans2 >= 1.f) return 1.f;  // total internal reflection
    const float cosTrans = std::sqrt(1.f - sinTrans2);
    const float rPerp = (etaIncOverEtaTrans * aCosIncident - cosTrans) / (etaIncOverEtaTrans * aCosIncident + cosTrans);
    const float rPar = (aCosIncident - etaIncOverEtaTrans * cosTrans) / (aCosIncident + etaIncOverEtaTrans * cosTrans);
    return 0.5f * (Sqr(rPar) + Sqr(rPerp));
}

// The factor that turns a BSDF f_s, defined with the shading normal, into its adjoint for
// importance transport (light sub-paths): |fix . Ns| |gen . Ng| / (|fix . Ng| |gen . Ns|),
// from the cosines of the fixed and generated directions with the shading and the
// geometric normal (Veach 1997, sec. 5.3; see the section's notes). 1 when Ns = Ng.
inline float AdjointShadingFactor(float aCosFixShading, float aCosFixGeometric, float aCosGenShading,
                                  float aCosGenGeometric) {
    return std::abs(aCosFixShading) * std::abs(aCosGenGeometric) /
           (std::abs(aCosFixGeometric) * std::abs(aCosGenShading));
}

// The Bsdf towards one direction (Bsdf::Evaluate), as a technique that connects (or
// merges) a path at its vertex needs it (Bsdf::EvaluateWithRoulette,
// EvaluatePathWithRoulette: the pdfs with Russian roulette included).
struct BsdfEval {
    Vec3 mValue{0.f};          // f, without the cosine (f_path from EvaluatePathWithRoulette)
    float mCosThetaGen = 0.f;  // |cos| of the direction with the shading normal
    float mDirPdfW = 0.f;      // pdf of sampling the direction
    float mRevPdfW = 0.f;      // pdf of the reverse choice (the fixed direction given it)
    bool IsBlack() const { return smallvcm::IsBlack(mValue); }
};

// One sampled direction of a Bsdf (Bsdf::Sample).
struct ScatterSample {
    Vec3 mDirection{0.f};
    Vec3 mValue{0.f};       // f of what was sampled, without the cosine
    Vec3 mWeight{0.f};      // f cos / pdf: what the path throughput is multiplied by
    float mPdfW = 0.f;      // solid-angle pdf of mDirection (with SampleScatteringWithRoulette:
                            // continuation probability included)
    float mReversePdfW = 0.f;  // the pdf of the reverse choice (sampling fix given gen), likewise
    float mCosThetaOut = 0.f;  // |cos| of mDirection with the shading normal
    uint32_t mEvent = kEventNone;
    bool IsSpecular() const { return (mEvent & kEventSpecular) != 0; }
};

// What a sub-path carries, which decides how a BSDF applies to it: radiance on camera
// sub-paths (the fixed direction points towards the camera), importance on light
// sub-paths (the fixed direction points towards the light; the adjoint BSDF, Veach 1997,
// sec. 5.2 and 5.3, and the section's notes).
enum class Transport { kRadiance, kImportance };

class Bsdf {
public:
    Bsdf() = default;

    // aRay is the ray that found aHit (its direction points into the surface); the Bsdf
    // shades in a frame around aHit's shading normal.
    // aTransport: radiance on camera sub-paths, importance on light sub-paths.
    SMALLVCM_ALWAYS_INLINE void Setup(const Ray& aRay, const SurfacePoint& aHit, const Scene& aScene, Transport aTransport) {
        Setup(-aRay.mDirection, aHit, aScene, aTransport);
    }
    // The same with the fixed direction given (pointing away from the surface), as a
    // stored light vertex has it. The material's constants come from the scene.
    SMALLVCM_ALWAYS_INLINE void Setup(const Vec3& aWorldDirFix, const SurfacePoint& aHit, const Scene& aScene,
                                      Transport aTransport) {
        const Material& material = aScene.GetMaterial(aHit.mMaterialId);
        if (material.mMetallicRoughnessTexture >= 0) {
            SetupAtTexel(aWorldDirFix, aHit, aScene, material, aTransport);
            return;
        }
        const MaterialConstants* constants = aScene.FindMaterialConstants(aHit.mMaterialId);
        if (material.mBaseColorTexture < 0)
            SetupWith(aWorldDirFix, aHit.GeometricNormal(), aHit.ShadingNormal(), material, constants, aTransport, nullptr);
        else {
            const Vec3 texel = aScene.BaseColorTexel(aHit);
            SetupWith(aWorldDirFix, aHit.GeometricNormal(), aHit.ShadingNormal(), material, constants, aTransport, &texel);
        }
    }
    // A material with a metallicRoughnessTexture: the components MetallicRoughnessRule
    // gives for this point's metal and roughness (the texel's blue and green times the
    // factors) and base colour (the factor times the base-colour texel) stand in for the
    // material's constants. Where a glass material has no glass share (metal 1), its
    // specular is the opaque mirror (the rule's when the material refracts).
    SMALLVCM_NOINLINE void SetupAtTexel(const Vec3& aWorldDirFix, const SurfacePoint& aHit, const Scene& aScene,
                                        const Material& aMaterial, Transport aTransport) {
        const Vec3 texel = aScene.mTextures[size_t(aMaterial.mMetallicRoughnessTexture)].Lookup(aHit.mUv);
        const bool glass = aMaterial.mIor > 0.f;
        const MetallicRoughnessMaterial rule =
            MetallicRoughnessRule(aMaterial.mBaseColor * aScene.BaseColorTexel(aHit), aMaterial.mMetallic * texel.z,
                                  aMaterial.mRoughness * texel.y, glass ? aMaterial.mTransmission : 0.f, aMaterial.mRuleIor);
        MaterialConstants constants;
        constants.mReflectance = {rule.mDiffuse, rule.mPhong, rule.mMirror, rule.mOpaqueMirror, rule.mTransmittance};
        if (glass && rule.mIor < 0.f) {
            constants.mReflectance.mOpaqueMirror += rule.mMirror;
            constants.mReflectance.mMirror = Vec3(0.f);
            constants.mReflectance.mTransmittance = Vec3(0.f);
        }
        const MaterialConstants::Reflectances& r = constants.mReflectance;  // as Material::ContinuationProbability
        constants.mContinuationProb = std::min(1.f, MaxComponent(r.mDiffuse + r.mPhong + r.mMirror + r.mOpaqueMirror) +
                                                        (glass ? MaxComponent(r.mTransmittance) : 0.f));
        SetupWith(aWorldDirFix, aHit.GeometricNormal(), aHit.ShadingNormal(), aMaterial, &constants, aTransport, nullptr);
        mPhongExponent = rule.mPhongExponent;
    }
    // The same from explicit data (what tests use): aWorldDirFix points away from the
    // surface.
    // The Bsdf keeps a pointer to aMaterial, which must outlive it (a temporary is refused).
    void Setup(const Vec3& aWorldDirFix, const Vec3& aNormal, const Material&& aMaterial, Transport aTransport) = delete;
    void Setup(const Vec3& aWorldDirFix, const Vec3& aGeometricNormal, const Vec3& aShadingNormal,
               const Material&& aMaterial, Transport aTransport) = delete;
    // A flat surface: the shading normal is the geometric one.
    void Setup(const Vec3& aWorldDirFix, const Vec3& aNormal, const Material& aMaterial, Transport aTransport,
               const Vec3* aBaseColorTexel = nullptr) {
        Setup(aWorldDirFix, aNormal, aNormal, aMaterial, aTransport, aBaseColorTexel);
    }
    // aGeometricNormal, aShadingNormal: unit length, on one side (SurfacePoint's
    // invariant). aBaseColorTexel: the material's texture at this point (see
    // Material::mBaseColorTexture).
    void Setup(const Vec3& aWorldDirFix, const Vec3& aGeometricNormal, const Vec3& aShadingNormal,
               const Material& aMaterial, Transport aTransport, const Vec3* aBaseColorTexel = nullptr) {
        SetupWith(aWorldDirFix, aGeometricNormal, aShadingNormal, aMaterial, nullptr, aTransport, aBaseColorTexel);
    }
    // What every Setup comes to; the shading frame is built here, once. aConstants: the
    // material's (Scene::FindMaterialConstants), or nullptr to compute what is needed of
    // them here.
    void SetupWith(const Vec3& aWorldDirFix, const Vec3& aGeometricNormal, const Vec3& aShadingNormal,
                   const Material& aMaterial, const MaterialConstants* aConstants, Transport aTransport,
                   const Vec3* aBaseColorTexel) {
        mMaterial = &aMaterial;
        mMedium = nullptr;
        mTransport = aTransport;
        mPhongExponent = aMaterial.mPhongExponent;
        if (aConstants)
            mReflectance = aConstants->mReflectance;
        else
            mReflectance = ReflectancesOf(aMaterial);
        if (aBaseColorTexel) TintReflectances(aMaterial, *aBaseColorTexel);
        // A two-sided non-glass material turns both normals towards whoever looks at it,
        // deciding by the geometric one (the side the ray really arrives from).
        mShaded = aShadingNormal != aGeometricNormal;
        const bool flip = aMaterial.mTwoSided && aMaterial.mIor < 0.f && glm::dot(aGeometricNormal, aWorldDirFix) < 0.f;
        mGeometricNormal = flip ? -aGeometricNormal : aGeometricNormal;
        mFrame.SetFromZ(flip ? -aShadingNormal : aShadingNormal);
        mLocalDirFix = mFrame.ToLocal(aWorldDirFix);
        mCosFixGeometric = mShaded ? glm::dot(mGeometricNormal, aWorldDirFix) : mLocalDirFix.z;
        // What is left of a default Bsdf should Setup stop early: nothing of a previous
        // setup stays, so a caller may set up one Bsdf again and again.
        mValid = false;
        mIsDelta = false;
        mProbabilities = {};
        mFresnel = 1.f;
        mContinuationProb = 0.f;
        if (std::abs(mLocalDirFix.z) < kEpsCosine) return;  // grazing: nothing reliable here
        if (mShaded && !SidesAgree(mLocalDirFix.z, mCosFixGeometric)) return;  // a light leak (section notes)
        if (aConstants && aConstants->mFixedProbabilities && !aBaseColorTexel && aMaterial.mIor < 0.f) {
            // What the lines below compute, computed once for the material (mFresnel is
            // 1 without refraction).
            const MaterialConstants::Side& side = mLocalDirFix.z > 0.f ? aConstants->mFront : aConstants->mBack;
            mProbabilities = side.mProbabilities;
            if (!side.mValid) return;
            mIsDelta = side.mIsDelta;
            mContinuationProb = aConstants->mContinuationProb;
            mValid = true;
            return;
        }
        mFresnel = FresnelDielectric(mLocalDirFix.z, aMaterial.mIor);
        const std::optional<std::array<float, 4>> probabilities =
            NormalisedProbabilities(mReflectance, aMaterial.mIor, mLocalDirFix.z, mFresnel);
        if (!probabilities) return;
        mProbabilities = *probabilities;
        mIsDelta = mProbabilities[kDiffuse] == 0.f && mProbabilities[kPhong] == 0.f;
        mContinuationProb = aConstants ? aConstants->mContinuationProb : aMaterial.ContinuationProbability();
        mValid = true;
    }

    // What Scene::Finalize keeps of each material for Setup (MaterialConstants): the
    // continuation probability, and the selection probabilities of both sides computed
    // here exactly as Setup computes them at a hit.
    static MaterialConstants ConstantsOf(const Material& aMaterial) {
        MaterialConstants constants;
        constants.mContinuationProb = aMaterial.ContinuationProbability();
        constants.mFixedProbabilities = aMaterial.mBaseColorTexture < 0 && aMaterial.mIor < 0.f;
        constants.mReflectance = ReflectancesOf(aMaterial);
        const Reflectances& reflectance = constants.mReflectance;
        for (const float cosFix : {1.f, -1.f}) {  // only its sign matters without refraction
            MaterialConstants::Side& side = cosFix > 0.f ? constants.mFront : constants.mBack;
            const std::optional<std::array<float, 4>> probabilities =
                NormalisedProbabilities(reflectance, aMaterial.mIor, cosFix, FresnelDielectric(cosFix, aMaterial.mIor));
            side.mValid = probabilities.has_value();
            if (probabilities) side.mProbabilities = *probabilities;
            side.mIsDelta = side.mValid && side.mProbabilities[kDiffuse] == 0.f && side.mProbabilities[kPhong] == 0.f;
        }
        return constants;
    }

    // A point in a medium instead of a surface (SmallUPBP's approach): the same interface
    // evaluates and samples f = sigma_s p(fix, gen), the Henyey-Greenstein phase function
    // times the scattering coefficient ([SECTION] Participating media), with pdfs p in both
    // directions and cosines of 1, since a medium point has no surface to project onto.
    // Russian roulette continues with the medium's largest albedo sigma_s / sigma_t.
    void SetupInMedium(const Vec3& aWorldDirFix, const Medium& aMedium, Transport aTransport) {
        mMedium = &aMedium;
        mMaterial = nullptr;
        mTransport = aTransport;
        mShaded = false;
        mFrame.SetFromZ(aWorldDirFix);
        mLocalDirFix = Vec3(0.f, 0.f, 1.f);
        mCosFixGeometric = 1.f;
        mProbabilities = {};
        mFresnel = 1.f;
        mIsDelta = false;
        mValid = aMedium.Scatters();
        const Vec3 sigmaT = aMedium.SigmaT();
        mContinuationProb = 0.f;
        for (int c = 0; c < 3; c++)
            if (sigmaT[c] > 0.f) mContinuationProb = std::max(mContinuationProb, std::min(1.f, aMedium.mSigmaS[c] / sigmaT[c]));
    }
    bool IsInMedium() const { return mMedium != nullptr; }

    bool IsValid() const { return mValid; }
    bool IsDelta() const { return mIsDelta; }
    float ContinuationProb() const { return mContinuationProb; }
    // Russian roulette is part of how a path is sampled: it goes on from this vertex with
    // probability ContinuationProb(), so a direction sampled here -- and the reverse
    // choice, which MIS needs too -- has the BSDF's pdf times that probability. This is
    // the one place where it enters a pdf.
    float WithRoulette(float aPdfW) const { return aPdfW * mContinuationProb; }
    float CosThetaFix() const { return mLocalDirFix.z; }
    // The cosine of the fixed direction with the geometric normal (what a change of
    // measure at this vertex needs); CosThetaFix() itself on a flat surface.
    float CosThetaFixGeometric() const { return mCosFixGeometric; }
    // |cos| of aWorldDir with the geometric normal, for changes of measure. aShadingCos:
    // the |cos| with the shading normal that Evaluate or Sample returned for it, which is
    // the same value on a flat surface and is then returned as it is (bit for bit).
    float GeometricCos(const Vec3& aWorldDir, float aShadingCos) const {
        return mShaded ? std::abs(glm::dot(mGeometricNormal, aWorldDir)) : aShadingCos;
    }
    Vec3 WorldDirFix() const { return mFrame.ToWorld(mLocalDirFix); }
    const Material& GetMaterial() const { return *mMaterial; }

    // f(fix, gen) of the non-specular components (no cosine), |cos theta_gen|, and the
    // pdfs of sampling gen given fix (direct) and fix given gen (reverse), solid angle.
    // Inlined, with EvaluateNonSpecular, into every connection and merge, which call it
    // more often than anything else.
    SMALLVCM_ALWAYS_INLINE BsdfEval Evaluate(const Vec3& aWorldDirGen) const {
        const Vec3 localDirGen = mFrame.ToLocal(aWorldDirGen);
        if (mMedium) return EvaluatePhase(localDirGen.z);
        BsdfEval eval = EvaluateNonSpecular(localDirGen);
        eval.mCosThetaGen = std::abs(localDirGen.z);
        if (mShaded && !eval.IsBlack()) {
            const float cosGenGeometric = glm::dot(mGeometricNormal, aWorldDirGen);
            if (!SidesAgree(localDirGen.z, cosGenGeometric)) {  // a light leak: nothing
                eval.mValue = Vec3(0.f);
                eval.mDirPdfW = eval.mRevPdfW = 0.f;
            } else if (mTransport == Transport::kImportance) {
                eval.mValue *= AdjointShadingFactor(mLocalDirFix.z, mCosFixGeometric, localDirGen.z, cosGenGeometric);
            }
        }
        return eval;
    }

    // f_path(wL -> wE) of the section's notes, for density estimation: what the flux of a
    // particle is multiplied by (on a camera sub-path, aWorldDirGen is where the particle
    // came from). Flux is spread over geometric area, so the estimate needs f_path, which
    // is f |gen . Ns| / |gen . Ng| in both transport directions (for importance, f carries
    // the adjoint factor); on a flat surface it is f itself.
    Vec3 EvaluatePath(const Vec3& aWorldDirGen) const {
        const BsdfEval eval = Evaluate(aWorldDirGen);
        return PathValue(eval.mValue, aWorldDirGen, eval.mCosThetaGen);
    }

    // Evaluate towards aWorldDirGen with both pdfs as the path sees them (WithRoulette):
    // what a connection to another vertex, a light or the camera needs. Inlined too: a
    // caller that does not read the reverse pdf (the path tracer) then does not compute it.
    SMALLVCM_ALWAYS_INLINE BsdfEval EvaluateWithRoulette(const Vec3& aWorldDirGen) const {
        BsdfEval eval = Evaluate(aWorldDirGen);
        eval.mDirPdfW = WithRoulette(eval.mDirPdfW);
        eval.mRevPdfW = WithRoulette(eval.mRevPdfW);
        return eval;
    }
    // The same with f_path (EvaluatePath): what a merge needs.
    BsdfEval EvaluatePathWithRoulette(const Vec3& aWorldDirGen) const {
        BsdfEval eval = EvaluateWithRoulette(aWorldDirGen);
        eval.mValue = PathValue(eval.mValue, aWorldDirGen, eval.mCosThetaGen);
        return eval;
    }

    // The pdf of sampling aWorldDirGen (or, with aReverse, of sampling the fixed
    // direction when aWorldDirGen were fixed), non-specular components only.
    float Pdf(const Vec3& aWorldDirGen, bool aReverse = false) const {
        const Vec3 localDirGen = mFrame.ToLocal(aWorldDirGen);
        if (mMedium) return EvaluatePhase(localDirGen.z).mDirPdfW;
        const BsdfEval eval = EvaluateNonSpecular(localDirGen);
        return aReverse ? eval.mRevPdfW : eval.mDirPdfW;
    }

    // Picks a component with aRnd.z and samples a direction with aRnd.xy. For a
    // non-specular pick f and pdf are those of all non-specular components together
    // (one-sample MIS over them); for a specular pick they are the component's, with
    // f / pdf * cos = its weight. Nothing when the sample is unusable (black).
    // mReversePdfW: the pdf of the opposite choice, sampling fix given gen (what Pdf(gen,
    // true) returns; for a specular pick the same selection probability). Evaluating the
    // non-specular components yields it anyway, and bidirectional methods need it.
    // On a smooth surface a sampled direction that would leak (section notes) is
    // unusable, and a Bsdf of a light sub-path multiplies the adjoint factor in.
    // (mWeight is left to SampleBsdf.)
    std::optional<ScatterSample> Sample(const Vec3& aRnd) const {
        std::optional<ScatterSample> sample = SampleInShadingFrame(aRnd);
        if (!mShaded || !sample) return sample;
        const float cosGenGeometric = glm::dot(mGeometricNormal, sample->mDirection);
        if (!SidesAgree(glm::dot(mFrame.mZ, sample->mDirection), cosGenGeometric)) sample.reset();
        else if (mTransport == Transport::kImportance)
            sample->mValue *= AdjointShadingFactor(mLocalDirFix.z, mCosFixGeometric, sample->mCosThetaOut, cosGenGeometric);
        return sample;
    }

private:
    // (SampleInShadingFrame's pick for a medium point; false when the sample is unusable.)
    SMALLVCM_NOINLINE bool SamplePhase(ScatterSample& oSample, const Vec2& aRnd) const {
        oSample.mDirection = SampleHenyeyGreenstein(-mFrame.mZ, mMedium->mG, aRnd);
        oSample.mEvent = kEventMedium;
        oSample.mCosThetaOut = 1.f;
        oSample.mPdfW = oSample.mReversePdfW = HenyeyGreensteinPdf(-glm::dot(mFrame.mZ, oSample.mDirection), mMedium->mG);
        oSample.mValue = mMedium->mSigmaS * oSample.mPdfW;
        return oSample.mPdfW > 0.f && !IsBlack(oSample.mValue);
    }

    // A medium point's f = sigma_s p and pdfs p. Its frame is around fix, so aCosFixGen =
    // fix . gen, which is -cos theta (both point away from the vertex).
    SMALLVCM_NOINLINE BsdfEval EvaluatePhase(float aCosFixGen) const {
        BsdfEval eval;
        const float phase = HenyeyGreensteinPdf(-aCosFixGen, mMedium->mG);
        eval.mValue = mMedium->mSigmaS * phase;
        eval.mCosThetaGen = 1.f;
        eval.mDirPdfW = eval.mRevPdfW = phase;
        return eval;
    }

    // f_path from f (EvaluatePath): f |gen . Ns| / |gen . Ng|, f itself on a flat surface.
    Vec3 PathValue(const Vec3& aF, const Vec3& aWorldDirGen, float aCosThetaGen) const {
        if (!mShaded || IsBlack(aF)) return aF;
        return aF * (aCosThetaGen / GeometricCos(aWorldDirGen, aCosThetaGen));
    }

    // Sample without the shading-normal rules: the components in the shading frame.
    // (Every return is of the one named sample, so that it is built in place.)
    std::optional<ScatterSample> SampleInShadingFrame(const Vec3& aRnd) const {
        std::optional<ScatterSample> sample(std::in_place);
        ScatterSample& s = *sample;
        Vec3 localDirGen;
        const float* p = mProbabilities.data();
        if (aRnd.z < p[kDiffuse]) {
            s.mEvent = kEventDiffuse;
            localDirGen = SampleCosHemisphereW(Vec2(aRnd));
            if (mLocalDirFix.z < 0.f) {
                sample.reset();
                return sample;
            }
        } else if (aRnd.z < p[kDiffuse] + p[kPhong]) {
            s.mEvent = kEventPhong;
            // BEGIN EXERCISE phong_bsdf/sample
            const Vec3 lobe = SamplePowerCosHemisphereW(Vec2(aRnd), mPhongExponent);
            localDirGen = Frame(ReflectLocal(mLocalDirFix)).ToWorld(lobe);
            // END EXERCISE phong_bsdf/sample
        } else if (aRnd.z < p[kDiffuse] + p[kPhong] + p[kReflect]) {
            s.mEvent = kEventReflect;
            localDirGen = ReflectLocal(mLocalDirFix);
            s.mPdfW = s.mReversePdfW = p[kReflect];
            s.mCosThetaOut = std::abs(localDirGen.z);
            s.mDirection = mFrame.ToWorld(localDirGen);
            s.mValue = MirrorReflectance() / s.mCosThetaOut;
            if (IsBlack(s.mValue)) sample.reset();
            return sample;
        } else if (mMedium) {  // a medium point has no components (every p is 0): its phase function
            if (!SamplePhase(s, Vec2(aRnd))) sample.reset();
            return sample;
        } else {
            if (!SampleRefraction(s)) sample.reset();
            return sample;
        }
        // Non-specular pick: evaluate every non-specular component for this direction.
        if (localDirGen.z < kEpsCosine) {
            sample.reset();
            return sample;
        }
        const BsdfEval eval = EvaluateNonSpecular(localDirGen);
        if (!(eval.mDirPdfW > 0.f) || IsBlack(eval.mValue)) {
            sample.reset();
            return sample;
        }
        s.mValue = eval.mValue;
        s.mPdfW = eval.mDirPdfW;
        s.mReversePdfW = eval.mRevPdfW;
        s.mCosThetaOut = localDirGen.z;
        s.mDirection = mFrame.ToWorld(localDirGen);
        return sample;
    }

    // The refraction component's sample (SampleInShadingFrame's last pick); false when it
    // is unusable (total internal reflection, no refraction share, black).
    bool SampleRefraction(ScatterSample& oSample) const {
        oSample.mEvent = kEventRefract;
        const std::optional<Refraction> refraction = RefractLocal(mLocalDirFix, mMaterial->mIor);
        if (!refraction || !(mProbabilities[kRefract] > 0.f)) return false;
        const Vec3 localDirGen = refraction->mLocalGen;
        oSample.mPdfW = oSample.mReversePdfW = mProbabilities[kRefract];
        oSample.mCosThetaOut = std::abs(localDirGen.z);
        oSample.mDirection = mFrame.ToWorld(localDirGen);
        // Radiance is not symmetric under refraction: L/eta^2 is what is conserved, so
        // camera paths carry (eta_fix / eta_gen)^2; light paths (importance) do not
        // (Veach 1997, sec. 5.2).
        const float scale = mTransport == Transport::kImportance ? 1.f : Sqr(refraction->mEtaFixOverEtaGen);
        oSample.mValue = Vec3((1.f - mFresnel) * scale / oSample.mCosThetaOut) * mReflectance.mTransmittance;
        return !IsBlack(oSample.mValue);
    }

    // A direction whose cosines with the shading and the geometric normal have one sign,
    // and that does not graze the geometric surface: the only kind a smooth surface
    // scatters from and into (section notes: no light leaks).
    static bool SidesAgree(float aCosShading, float aCosGeometric) {
        return (aCosShading > 0.f) == (aCosGeometric > 0.f) && std::abs(aCosGeometric) >= kEpsCosine;
    }

    enum Component { kDiffuse = 0, kPhong = 1, kReflect = 2, kRefract = 3 };
    // The reflectances of the components at this point.
    using Reflectances = MaterialConstants::Reflectances;
    static Reflectances ReflectancesOf(const Material& aMaterial) {
        return Reflectances{aMaterial.mDiffuseReflectance, aMaterial.mPhongReflectance, aMaterial.mMirrorReflectance,
                            aMaterial.mOpaqueMirror, aMaterial.mTransmittance};
    }
    // The base colour texel tints what glTF's base colour reaches: not the dielectric's
    // untinted specular share, nor glass's Fresnel reflection.
    void TintReflectances(const Material& aMaterial, const Vec3& aTexel) {
        const auto tint = [&](Vec3& ioSpecular) {
            if (!IsBlack(ioSpecular)) ioSpecular = aMaterial.mSpecularUntinted + (ioSpecular - aMaterial.mSpecularUntinted) * aTexel;
        };
        mReflectance.mDiffuse *= aTexel;
        tint(mReflectance.mPhong);
        if (aMaterial.mIor > 0.f) {
            tint(mReflectance.mOpaqueMirror);
            mReflectance.mTransmittance *= aTexel;
        } else {
            tint(mReflectance.mMirror);
        }
    }
    // The delta reflection's reflectance: glass's F x mirror, plus (front side only) the
    // mirror of an opaque share that F does not weight (Material::mOpaqueMirror).
    Vec3 MirrorReflectance() const {
        return mLocalDirFix.z > 0.f ? mFresnel * mReflectance.mMirror + mReflectance.mOpaqueMirror
                                    : mFresnel * mReflectance.mMirror;
    }

    static Vec3 ReflectLocal(const Vec3& aLocal) { return Vec3(-aLocal.x, -aLocal.y, aLocal.z); }

    // Snell's law in the local frame; nothing on total internal reflection.
    struct Refraction {
        Vec3 mLocalGen;
        float mEtaFixOverEtaGen;
    };
    static std::optional<Refraction> RefractLocal(const Vec3& aLocalFix, float aIor) {
        const bool fromOutside = aLocalFix.z > 0.f;
        const float eta = fromOutside ? 1.f / aIor : aIor;  // eta_fix / eta_gen
        const float sinGen2 = Sqr(eta) * (1.f - Sqr(aLocalFix.z));
        if (sinGen2 >= 1.f) return std::nullopt;
        const float cosGen = std::sqrt(1.f - sinGen2);
        return Refraction{Vec3(-eta * aLocalFix.x, -eta * aLocalFix.y, fromOutside ? -cosGen : cosGen), eta};
    }

    // Un-normalised selection weights of the components for a fixed direction whose local
    // cosine is aCosFix (the Fresnel term, and one-sidedness, depend on it).
    static std::array<float, 4> ComponentProbabilities(const Reflectances& aReflectance, float aIor, float aCosFix,
                                                       float aFresnel) {
        std::array<float, 4> p{};
        const bool frontSide = aCosFix > 0.f;  // two-sided materials were already flipped
        if (frontSide) {
            p[kDiffuse] = Luminance(aReflectance.mDiffuse);
            p[kPhong] = Luminance(aReflectance.mPhong);
        }
        p[kReflect] = aFresnel * Luminance(aReflectance.mMirror);
        if (frontSide) p[kReflect] += Luminance(aReflectance.mOpaqueMirror);
        p[kRefract] = aIor > 0.f ? (1.f - aFresnel) * Luminance(aReflectance.mTransmittance) : 0.f;
        return p;
    }
    // The same normalised to sum to 1; nothing when they are all zero: a black material,
    // or a one-sided one seen from behind.
    static std::optional<std::array<float, 4>> NormalisedProbabilities(const Reflectances& aReflectance, float aIor,
                                                                       float aCosFix, float aFresnel) {
        std::array<float, 4> probabilities = ComponentProbabilities(aReflectance, aIor, aCosFix, aFresnel);
        const float total = probabilities[0] + probabilities[1] + probabilities[2] + probabilities[3];
        if (!(total > 0.f)) return std::nullopt;
        for (float& p : probabilities) p /= total;
        return probabilities;
    }

    // Lambert + Phong for (fix, gen) in local coordinates: both must lie on the front side.
    // (mCosThetaGen is left to the caller.)
    SMALLVCM_ALWAYS_INLINE BsdfEval EvaluateNonSpecular(const Vec3& aLocalDirGen) const {
        BsdfEval eval;
        if (mIsDelta || mLocalDirFix.z < kEpsCosine || aLocalDirGen.z < kEpsCosine) return eval;
        // Selection probabilities when gen is the fixed direction: they differ from ours
        // only through the Fresnel term of glass, which then has to be recomputed.
        std::array<float, 4> reverse = mProbabilities;
        if (mMaterial->mIor > 0.f) {
            reverse = ComponentProbabilities(mReflectance, mMaterial->mIor, aLocalDirGen.z,
                                             FresnelDielectric(aLocalDirGen.z, mMaterial->mIor));
            const float total = reverse[0] + reverse[1] + reverse[2] + reverse[3];
            for (float& p : reverse) p /= total;
        }
        if (mProbabilities[kDiffuse] > 0.f) {
            eval.mValue += mReflectance.mDiffuse * kInvPi;
            eval.mDirPdfW += mProbabilities[kDiffuse] * CosHemispherePdfW(aLocalDirGen);
            eval.mRevPdfW += reverse[kDiffuse] * CosHemispherePdfW(mLocalDirFix);
        }
        // BEGIN EXERCISE phong_bsdf/evaluate
        if (mProbabilities[kPhong] > 0.f) {
            // cos(R, gen) = cos(R', fix) with R' the reflection of gen: one value serves
            // both directions.
            const float cosR = glm::dot(ReflectLocal(mLocalDirFix), aLocalDirGen);
            if (cosR > kEpsPhong) {
                const float n = mPhongExponent;
                const float lobe = std::pow(cosR, n);
                eval.mValue += mReflectance.mPhong * ((n + 2.f) * 0.5f * kInvPi * lobe);
                const float lobePdfW = (n + 1.f) * 0.5f * kInvPi * lobe;
                eval.mDirPdfW += mProbabilities[kPhong] * lobePdfW;
                eval.mRevPdfW += reverse[kPhong] * lobePdfW;
            }
        }
        // END EXERCISE phong_bsdf/evaluate
        return eval;
    }

    Frame mFrame;                 // around the shading normal (turned to the viewer if two-sided)
    Vec3 mGeometricNormal{0.f};   // turned like the frame
    Vec3 mLocalDirFix{0.f};
    float mCosFixGeometric = 0.f; // fix . mGeometricNormal (= mLocalDirFix.z when flat)
    bool mShaded = false;         // the shading normal differs from the geometric one
    const Material* mMaterial = nullptr;
    const Medium* mMedium = nullptr;  // set for a point in a medium (SetupInMedium)
    Reflectances mReflectance;  // the material's, textured at this point
    float mPhongExponent = 1.f;  // the material's, or the rule's at this point (SetupAtTexel)
    std::array<float, 4> mProbabilities{};
    float mFresnel = 1.f;
    float mContinuationProb = 0.f;
    bool mIsDelta = false;
    Transport mTransport = Transport::kRadiance;
    bool mValid = false;
};

inline MaterialConstants ComputeMaterialConstants(const Material& aMaterial) { return Bsdf::ConstantsOf(aMaterial); }

// A sample of the Bsdf with aRnd, no Russian roulette, with its weight f cos / pdf.
// Nothing when it is unusable. (Built in place and returned by name, here, in Bsdf::Sample
// and below: no copy of the sample is made.)
inline std::optional<ScatterSample> SampleBsdf(const Bsdf& aBsdf, const Vec3& aRnd) {
    std::optional<ScatterSample> sample = aBsdf.Sample(aRnd);
    if (sample) sample->mWeight = sample->mValue * (sample->mCosThetaOut / sample->mPdfW);
    return sample;
}

// One step of a random walk, shared by every integrator that walks paths: sample the
// BSDF, then Russian roulette with the material's continuation probability, which is
// part of how the direction was sampled, so it enters both pdfs (Bsdf::WithRoulette)
// and the weight. Nothing when the walk ends here (a black sample, or Russian roulette).
inline std::optional<ScatterSample> SampleScatteringWithRoulette(const Bsdf& aBsdf, Sampler& aSampler) {
    std::optional<ScatterSample> sample = SampleBsdf(aBsdf, aSampler.Get3D());
    if (sample && aSampler.Get1D() < aBsdf.ContinuationProb()) {
        sample->mPdfW = aBsdf.WithRoulette(sample->mPdfW);
        sample->mReversePdfW = aBsdf.WithRoulette(sample->mReversePdfW);
        sample->mWeight = sample->mValue * (sample->mCosThetaOut / sample->mPdfW);
    } else {
        sample.reset();
    }
    return sample;
}

// =====================================================================================
// [SECTION] Film
// =====================================================================================
// Provides: Film, a per-thread accumulation buffer in double precision (so that millions
// of small splats do not lose precision), with named extra layers the integrators write
// per-technique images into; and Image, the resolved float picture the writers take.
// Pixel index = y * width + x, y = 0 the top row.

struct Image {
    int mWidth = 0, mHeight = 0;
    std::vector<Vec3> mPixels;  // top row first
    Image() = default;
    Image(int aWidth, int aHeight) : mWidth(aWidth), mHeight(aHeight), mPixels(size_t(aWidth) * size_t(aHeight), Vec3(0.f)) {}
    Vec3& At(int aX, int aY) { return mPixels[size_t(aY) * size_t(mWidth) + size_t(aX)]; }
    const Vec3& At(int aX, int aY) const { return mPixels[size_t(aY) * size_t(mWidth) + size_t(aX)]; }
};

class Film {
public:
    Film() = default;
    Film(int aWidth, int aHeight) : mWidth(aWidth), mHeight(aHeight), mPixels(size_t(aWidth) * size_t(aHeight), glm::dvec3(0.0)) {}

    int Width() const { return mWidth; }
    int Height() const { return mHeight; }

    void AddColor(int aPixelIndex, const Vec3& aColor) {
        CheckContribution(aPixelIndex, aColor);
        AddSplats();
        mPixels[size_t(aPixelIndex)] += glm::dvec3(aColor);
    }
    // The same for a contribution that lands anywhere in the image (light tracing's
    // splats): every pixel receives the same additions in the same order as with
    // AddColor, so the image is the one AddColor would give. How the film adds them
    // is [SECTION] Appendix: film splats.
    void Splat(int aPixelIndex, const Vec3& aColor);

    // Layers: created before rendering; AddLayer returns the index to write with.
    int AddLayer(const std::string& aName) {
        const int existing = LayerIndex(aName);
        if (existing >= 0) return existing;
        mLayerNames.push_back(aName);
        mLayers.emplace_back(mPixels.size(), glm::dvec3(0.0));
        return int(mLayers.size()) - 1;
    }
    int LayerIndex(const std::string& aName) const {
        for (size_t i = 0; i < mLayerNames.size(); i++) if (mLayerNames[i] == aName) return int(i);
        return -1;
    }
    int LayerCount() const { return int(mLayers.size()); }
    const std::string& LayerName(int aLayer) const { return mLayerNames[size_t(aLayer)]; }
    void AddToLayer(int aLayer, int aPixelIndex, const Vec3& aColor) {
        SMALLVCM_CHECK(IsFinite(aColor) && aColor.x >= 0.f && aColor.y >= 0.f && aColor.z >= 0.f,
                       "a layer contribution is NaN, infinite or negative");
        mLayers[size_t(aLayer)][size_t(aPixelIndex)] += glm::dvec3(aColor);
    }

    // Adds another film of the same size and layers (the per-thread films of a render).
    void Accumulate(const Film& aOther) {
        AddSplats();
        aOther.AddSplats();
        for (size_t i = 0; i < mPixels.size(); i++) mPixels[i] += aOther.mPixels[i];
        for (size_t l = 0; l < mLayers.size(); l++)
            for (size_t i = 0; i < mPixels.size(); i++) mLayers[l][i] += aOther.mLayers[l][i];
    }

    // The image (aLayer = -1) or a layer, each pixel multiplied by aScale (1 / iterations).
    Image Resolve(double aScale, int aLayer = -1) const {
        AddSplats();
        const std::vector<glm::dvec3>& source = aLayer < 0 ? mPixels : mLayers[size_t(aLayer)];
        Image image(mWidth, mHeight);
        for (size_t i = 0; i < source.size(); i++) image.mPixels[i] = Vec3(source[i] * aScale);
        return image;
    }

private:
    void CheckContribution(int aPixelIndex, const Vec3& aColor) const {
        SMALLVCM_CHECK(IsFinite(aColor) && aColor.x >= 0.f && aColor.y >= 0.f && aColor.z >= 0.f,
                       "a film contribution is NaN, infinite or negative");
        SMALLVCM_CHECK(aPixelIndex >= 0 && size_t(aPixelIndex) < mPixels.size(), "a film write outside the image");
        (void)aPixelIndex;
        (void)aColor;
    }
    // Adds the splats Splat has not added yet, in order (const: they are part of what
    // the film holds).
    void AddSplats() const;

    struct PendingSplat { int mPixel; Vec3 mColor; };
    int mWidth = 0, mHeight = 0;
    mutable std::vector<glm::dvec3> mPixels;     // (mutable: AddSplats)
    mutable std::vector<PendingSplat> mSplats;  // Splat's, not yet in mPixels
    std::vector<std::string> mLayerNames;
    std::vector<std::vector<glm::dvec3>> mLayers;
};

// =====================================================================================
// [SECTION] Integrator interface
// =====================================================================================
// Provides: the built-in algorithm list, RenderOptions, the MIS heuristic,
// AbstractRenderer, the base of every integrator, and Integrator, the description under
// which Render() (in [SECTION] Render loop) finds one by name. The built-ins use the
// same mechanism as a user's own integrator; docs/writing-an-integrator.md walks through
// examples/my_path_tracer.hpp, a complete one.
//
// The contract, as Render() keeps it:
//  * Render() creates one renderer per thread with Integrator::mCreateRenderer(scene,
//    options), before any thread starts. Each renderer is used by one thread only, so its
//    members are that thread's private state (caches, light vertices, photon maps): no
//    locks. The scene is shared and read-only.
//  * The renderer's Film (mFilm, the camera's resolution) receives its contributions:
//    AddColor(pixel, value) adds radiance (Splat(pixel, value) one that lands anywhere
//    in the image, as light tracing's do); add extra layers in the constructor with
//    AddLayer(name) (only when mOptions.mTechniqueLayers asks for them, by convention)
//    and write them with AddToLayer.
//  * RunIteration(i, sampler) renders iteration i, conventionally one sample per pixel,
//    and draws every random number from sampler (see Sampler): made from the base seed
//    and i alone, the same whichever thread runs it, so one seed and thread count give
//    one image, bit for bit. Before each camera sub-path it calls
//    sampler.StartPixelSample(pixel), before the p-th of its N light sub-paths
//    StartLightPath(p, N).
//  * After the last iteration Render() sums the films in thread order and divides by the
//    number of iterations run: a film holds sums of per-iteration estimates.
//  * Iteration and time budgets, threads, progress, cancellation (checked between
//    iterations) and the RenderResult are Render()'s: a renderer only renders.
//  * An exception thrown by RunIteration stops every thread after its current iteration;
//    Render() rethrows its message as Error.

enum class Algorithm {
    kEyeLight,
    kPathTracing,
    kLightTracing,
    kProgressivePhotonMapping,
    kBidirectionalPhotonMapping,
    kBidirectionalPathTracing,
    kVertexConnectionMerging,
    kPhotonMapping,
    kPhotonMappingFinalGather,
    kBeamRadianceEstimate,
    kPhotonBeams,
    kUpbp,
};

// SmallVCM's short names ("el", "pt", "lt", "ppm", "bpm", "bpt", "vcm"), and UPBP's names of
// the beam radiance estimate ("pb2d": photon points queried by camera beams, 2D kernel)
// and of photon beams queried by camera beams ("bb1d", 1D kernel).
inline const char* AlgorithmShortName(Algorithm aAlgorithm) {
    switch (aAlgorithm) {
    case Algorithm::kEyeLight: return "el";
    case Algorithm::kPathTracing: return "pt";
    case Algorithm::kLightTracing: return "lt";
    case Algorithm::kProgressivePhotonMapping: return "ppm";
    case Algorithm::kBidirectionalPhotonMapping: return "bpm";
    case Algorithm::kBidirectionalPathTracing: return "bpt";
    case Algorithm::kVertexConnectionMerging: return "vcm";
    case Algorithm::kPhotonMapping: return "pm";
    case Algorithm::kPhotonMappingFinalGather: return "pmfg";
    case Algorithm::kBeamRadianceEstimate: return "pb2d";
    case Algorithm::kPhotonBeams: return "bb1d";
    case Algorithm::kUpbp: return "upbp";
    }
    return "?";
}
inline std::optional<Algorithm> ParseAlgorithm(const std::string& aName) {
    for (Algorithm a : {Algorithm::kEyeLight, Algorithm::kPathTracing, Algorithm::kLightTracing,
                        Algorithm::kProgressivePhotonMapping, Algorithm::kBidirectionalPhotonMapping,
                        Algorithm::kBidirectionalPathTracing, Algorithm::kVertexConnectionMerging,
                        Algorithm::kPhotonMapping, Algorithm::kPhotonMappingFinalGather, Algorithm::kBeamRadianceEstimate,
                        Algorithm::kPhotonBeams, Algorithm::kUpbp})
        if (aName == AlgorithmShortName(a)) return a;
    return std::nullopt;
}

enum class MisHeuristic { kBalance, kPower };

// The techniques UPBP combines under one MIS (-a upbp), by the names of its paper and of
// --techniques: bpt (light tracing, next-event estimation, connections), surf (merging on
// surfaces), pp3d (photon points at camera points in media), pb2d (photon points along
// camera segments), bb1d (photon beams along camera segments). A camera path hitting a
// light is always on.
enum UpbpTechnique : uint32_t { kUpbpBpt = 1, kUpbpSurface = 2, kUpbpPp3d = 4, kUpbpPb2d = 8, kUpbpBb1d = 16, kUpbpAll = 31 };
inline constexpr const char* kUpbpTechniqueNames[5] = {"bpt", "surf", "pp3d", "pb2d", "bb1d"};
// "bpt,surf,pb2d" as a set; nothing for an empty list, an unknown or a repeated name.
inline std::optional<uint32_t> ParseUpbpTechniques(const std::string& aList) {
    uint32_t set = 0;
    size_t start = 0;
    for (;;) {
        const size_t comma = aList.find(',', start);
        const std::string name = aList.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
        uint32_t bit = 0;
        for (int i = 0; i < 5; i++)
            if (name == kUpbpTechniqueNames[i]) bit = 1u << i;
        if (bit == 0 || (set & bit)) return std::nullopt;
        set |= bit;
        if (comma == std::string::npos) return set;
        start = comma + 1;
    }
}

// Path tracing only: the techniques that estimate direct light. kMis combines light
// sampling (next-event estimation) and BSDF sampling; the other two keep one of them
// alone, as the MIS slide compares them (F04).
enum class DirectLightSampling { kMis, kLightOnly, kBsdfOnly };

struct RenderOptions {
    // The built-in Render(scene, options) runs; a built-in run as an Integrator sets its own.
    Algorithm mAlgorithm = Algorithm::kVertexConnectionMerging;
    int mIterations = 1;          // iterations to run (0: unlimited, then mSeconds must be > 0)
    double mSeconds = 0.0;        // time budget in seconds (0: none)
    int mThreads = 0;             // 0: every hardware thread
    uint64_t mSeed = 1234;        // base seed: iteration i uses stream i of it
    SamplerType mSampler = SamplerType::kIndependent;  // where the random numbers come from (the smallvcm command: sobol)
    int mMinPathLength = 0;       // in segments, as SmallVCM counts them
    int mMaxPathLength = 10;
    float mRadiusFactor = 0.003f; // merging radius = factor * scene radius (SmallVCM's default)
    // The radius of merging at points in media, likewise: a ball holds far fewer photons
    // than a disc of the same radius, so it is larger (shrinking on the same schedule).
    float mMediumRadiusFactor = 0.03f;
    // The radius of photon beams (bb1d), likewise: a camera ray meets a beam within r far
    // more often than a point, and the 1D kernel's bias grows only with r^2 as the others'.
    float mBeamRadiusFactor = 0.003f;
    // bb1d: how many light sub-paths of an iteration store their segments as photon beams
    // (N_B, at most all N_L of them). A camera ray meets every beam near it, so the cost of
    // an iteration grows with N_L N_B: beams from all 262,144 light sub-paths of a 512 x 512
    // iteration would make each camera ray test hundreds of thousands.
    int mBeamPaths = 4096;
    uint32_t mUpbpTechniques = kUpbpAll;  // upbp: the techniques it combines (UpbpTechnique)
    float mRadiusAlpha = 0.75f;   // radius shrinks as r_i = r_0 (i+1)^((alpha-1)/2)
    MisHeuristic mMisHeuristic = MisHeuristic::kBalance;
    DirectLightSampling mDirectLight = DirectLightSampling::kMis;  // path tracing only
    bool mTechniqueLayers = false;// write per-technique layers into the film
    bool mProgress = true;        // progress line on stderr (only on a terminal, after 2 s)
    // When set (e.g. by a Ctrl-C handler), threads finish the iteration they are in and
    // Render returns what was accumulated so far (RenderResult::mStopped tells).
    const std::atomic<bool>* mStopRequested = nullptr;
    // Classic photon mapping (pm, pmfg): photons emitted per iteration, photons per
    // estimate, and the largest search radius as a fraction of the scene radius.
    int mPhotonCount = 200000;
    int mNearestPhotons = 100;
    float mMaxPhotonRadiusFactor = 0.05f;
};

// The heuristic as a function of one pdf: w_i = Mis(p_i) / sum_j Mis(p_j).
// Balance: Mis(p) = p; power (beta = 2): Mis(p) = p^2 (Veach 1997, sec. 9.2).
inline float MisPower(MisHeuristic aHeuristic, float aPdf) {
    return aHeuristic == MisHeuristic::kPower ? aPdf * aPdf : aPdf;
}

class AbstractRenderer {
public:
    AbstractRenderer(const Scene& aScene, const RenderOptions& aOptions)
        : mScene(aScene), mOptions(aOptions), mFilm(aScene.mCamera.Width(), aScene.mCamera.Height()) {}
    virtual ~AbstractRenderer() = default;
    AbstractRenderer(const AbstractRenderer&) = delete;
    AbstractRenderer& operator=(const AbstractRenderer&) = delete;

    // Runs iteration aIteration (its index counts across all threads: PPM's radius
    // depends on it) drawing every random number from aSampler.
    virtual void RunIteration(int aIteration, Sampler& aSampler) = 0;

    Film& GetFilm() { return mFilm; }

protected:
    const Scene& mScene;
    RenderOptions mOptions;
    Film mFilm;
};

// One integrator as Render() and the command line know it. mName is what `-a` takes
// (letters, digits, '_' and '-'); mDescription is the one line `--help` prints beside it.
// mCreateRenderer makes one per-thread renderer. mBytesPerRenderer, if set, is what one
// renderer allocates beyond its film (the film and its layers are counted for every
// integrator); Render() refuses a render that would not fit in memory before it starts.
struct Integrator {
    using CreateRendererFn = std::function<std::unique_ptr<AbstractRenderer>(const Scene&, const RenderOptions&)>;
    using BytesPerRendererFn = std::function<uint64_t(const Camera&, const RenderOptions&)>;

    std::string mName;
    std::string mDescription;
    CreateRendererFn mCreateRenderer;
    BytesPerRendererFn mBytesPerRenderer;
    // Whether its renderers trace through participating media (TraceSegment,
    // TraceConnection): Render() refuses a scene with media for one that does not say so,
    // rather than render it as if the media were not there.
    bool mHandlesMedia = false;
};

// The Integrator of a renderer class constructible from (scene, options), the usual case:
//     MakeIntegrator<MyPathTracer>("mypt", "my path tracer")
template <class Renderer>
Integrator MakeIntegrator(const std::string& aName, const std::string& aDescription,
                          Integrator::BytesPerRendererFn aBytesPerRenderer = nullptr) {
    return Integrator{aName, aDescription,
                      [](const Scene& aScene, const RenderOptions& aOptions) -> std::unique_ptr<AbstractRenderer> {
                          return std::make_unique<Renderer>(aScene, aOptions);
                      },
                      std::move(aBytesPerRenderer)};
}

// =====================================================================================
// [SECTION] Integrator: eye light
// =====================================================================================
// Not an estimator of light transport: it shades each first hit by |cos| between the
// shading normal and the view direction and paints back faces (by the geometric normal)
// red, so that geometry, normals and the camera can be checked at a glance (SmallVCM's "el").

class EyeLight : public AbstractRenderer {
public:
    using AbstractRenderer::AbstractRenderer;

    void RunIteration(int /*aIteration*/, Sampler& aSampler) override {
        const Camera& camera = mScene.mCamera;
        for (int y = 0; y < camera.Height(); y++) {
            for (int x = 0; x < camera.Width(); x++) {
                aSampler.StartPixelSample(y * camera.Width() + x);
                const Vec2 raster = Vec2(float(x), float(y)) + aSampler.Get2D();
                const Ray ray = camera.GenerateRay(raster);
                const SurfacePoint hit = mScene.Intersect(ray);
                if (!hit.IsValid()) continue;
                const float cosFront = glm::dot(hit.ShadingNormal(), -ray.mDirection);
                const bool front = glm::dot(hit.GeometricNormal(), -ray.mDirection) > 0.f;
                const Vec3 color = front ? Vec3(std::abs(cosFront)) : Vec3(std::abs(cosFront), 0.f, 0.f);
                mFilm.AddColor(y * camera.Width() + x, color);
            }
        }
    }
};


// =====================================================================================
// [SECTION] Integrator: path tracing
// =====================================================================================
// Estimator: Kajiya's path tracing. One camera sub-path per pixel and iteration; at each
// non-specular vertex, next-event estimation (a light sample and a shadow ray) and BSDF
// sampling (continuing the path, and counting a light the path hits) estimate the same
// direct light, combined by MIS (Veach 1997, sec. 9.2: balance heuristic by default):
//     w_light = Mis(p_light) / (Mis(p_light) + Mis(p_bsdf)),  w_bsdf = 1 - w_light,
// both pdfs in solid angle at the vertex, p_bsdf including the Russian roulette
// continuation probability (it is part of how the path was sampled).
// Russian roulette from the first hit on, with the material's continuation probability.
// RenderOptions::mDirectLight can switch one technique off (weight 1 for the other), to
// show what each does alone (the MIS figure, F04).
// With technique layers on, each contribution is also written to one of five layers that
// partition the image as the "partitioning the rendering equation" slide does:
//   emitted                    light seen directly (path length 1)
//   direct_{non}specular       light that reached the first vertex straight from a light
//   indirect_{non}specular     light that bounced at least once more
// with {non}specular the component sampled at the first vertex (next-event estimation
// counts as non-specular). They sum to the image.

class PathTracer : public AbstractRenderer {
public:
    PathTracer(const Scene& aScene, const RenderOptions& aOptions) : AbstractRenderer(aScene, aOptions) {
        if (mOptions.mTechniqueLayers)
            for (const char* name : kLayerNames) mLayers.push_back(mFilm.AddLayer(name));
    }

    void RunIteration(int /*aIteration*/, Sampler& aSampler) override {
        const Camera& camera = mScene.mCamera;
        for (int pixel = 0; pixel < camera.PixelCount(); pixel++) {
            const int x = pixel % camera.Width(), y = pixel / camera.Width();
            aSampler.StartPixelSample(pixel);
            TraceCameraPath(aSampler, pixel, Vec2(float(x), float(y)) + aSampler.Get2D());
        }
    }

private:
    static constexpr const char* kLayerNames[5] = {"emitted", "direct_nonspecular", "direct_specular",
                                                   "indirect_nonspecular", "indirect_specular"};

    // What a camera path carries from one vertex to the next.
    struct PathState {
        Vec3 mThroughput{1.f};
        int mPathLength = 1;        // segments so far, counting the one being traced
        float mLastPdfW = 1.f;      // BSDF pdf (roulette included) of the last direction
        bool mLastSpecular = true;  // the camera counts as specular: no MIS at length 1
        bool mFirstSpecular = false;// the component sampled at the first vertex (layers)
        float mGap = 0.f;           // how far the ray starts off its vertex (LeaveVertex)
    };

    // One camera path, the estimator's steps at each vertex: the light it hits (BSDF
    // sampling's share of direct light), next-event estimation (the light sample's
    // share), and the continuation by BSDF sampling with Russian roulette.
    // In a medium the next vertex may be a scattering point before the surface
    // (TraceSegment samples the free flight); it is set up as a Bsdf like a surface.
    void TraceCameraPath(Sampler& aSampler, int aPixel, const Vec2& aRaster) {
        Ray ray = mScene.mCamera.GenerateRay(aRaster);
        int medium = mScene.CameraMedium();
        Bsdf bsdf;
        for (PathState path;; path.mPathLength++) {
            const PathSegment segment = TraceSegment(mScene, ray, medium, false, aSampler, path.mGap);
            const SurfacePoint& hit = segment.mHit;
            path.mThroughput *= segment.mWeight;
            medium = segment.mMedium;
            if (segment.Escaped()) {
                AddContribution(aPixel, path, BackgroundHit(path, ray.mDirection, segment));
                return;
            }
            if (segment.mInMedium) {
                bsdf.SetupInMedium(-ray.mDirection, mScene.GetMedium(medium), Transport::kRadiance);
            } else {
                // The path goes on after a light only if the emitter's material reflects (the
                // Cornell lights are black; the furnace test's walls are not).
                if (hit.mLightId >= 0 && path.mPathLength >= mOptions.mMinPathLength)
                    AddContribution(aPixel, path, EmitterHit(path, ray, segment));
                bsdf.Setup(ray, hit, mScene, Transport::kRadiance);
            }
            if (!bsdf.IsValid() || path.mPathLength >= mOptions.mMaxPathLength) return;
            if (!bsdf.IsDelta() && path.mPathLength + 1 >= mOptions.mMinPathLength)
                AddContribution(aPixel, path, ConnectToLight(aSampler, path, segment, bsdf), /*aNextEvent=*/true);
            const std::optional<ScatterSample> scatter = SampleScatteringWithRoulette(bsdf, aSampler);
            if (!scatter) return;
            path.mThroughput *= scatter->mWeight;
            path.mLastPdfW = scatter->mPdfW;
            path.mLastSpecular = scatter->IsSpecular();
            if (path.mPathLength == 1) path.mFirstSpecular = path.mLastSpecular;
            if (!segment.mInMedium) medium = mScene.MediumAfter(hit, scatter->mDirection, medium);
            ray = LeaveVertex(mScene, segment.Position(), scatter->mDirection, segment.mInMedium);
            path.mGap = GapOfVertex(mScene, segment.mInMedium);
        }
    }

    // The ray left the scene: the background light, if any, found by BSDF sampling (and
    // by flying through the media on the way, aSegment's forward pdf).
    Vec3 BackgroundHit(const PathState& aPath, const Vec3& aDirection, const PathSegment& aSegment) const {
        const Light* background = mScene.GetBackground();
        if (!background || aPath.mPathLength < mOptions.mMinPathLength) return Vec3(0.f);
        const Light::RadianceAtHit received = background->GetRadiance(mScene.GetSceneSphere(), aDirection, Vec3(0.f), Vec2(0.f));
        const float directPdfW = received.mDirectPdfA;  // a background's "area" pdf is per solid angle
        const float weight = aPath.mLastSpecular ? 1.f : BsdfHitWeight(aPath.mLastPdfW * aSegment.mPdfs.mForward, directPdfW * mScene.LightPickProb());
        return aPath.mThroughput * received.mRadiance * weight;
    }

    // A light hit by the path, found by BSDF sampling: MIS against next-event
    // estimation, whose area pdf is converted to solid angle at the previous vertex.
    Vec3 EmitterHit(const PathState& aPath, const Ray& aRay, const PathSegment& aSegment) const {
        const SurfacePoint& hit = aSegment.mHit;
        const Light& light = mScene.GetLight(hit.mLightId);
        const Light::RadianceAtHit received = light.GetRadiance(mScene.GetSceneSphere(), aRay.mDirection, hit.GeometricNormal(), hit.mUv);
        if (IsBlack(received.mRadiance)) return Vec3(0.f);
        float weight = 1.f;
        if (!aPath.mLastSpecular) {
            const float cosAtLight = glm::dot(hit.GeometricNormal(), -aRay.mDirection);
            const float distance = aSegment.Length();
            const float directPdfW = PdfAtoW(received.mDirectPdfA, distance, cosAtLight) * mScene.LightPickProb();
            weight = BsdfHitWeight(aPath.mLastPdfW * aSegment.mPdfs.mForward, directPdfW);
        }
        return aPath.mThroughput * received.mRadiance * weight;
    }

    // Next-event estimation: one light picked, one point on it, a shadow ray; its MIS
    // weight against the BSDF sample that could have hit the same point. Through media
    // the shadow ray carries the transmittance, and the BSDF sample would have had to
    // fly through them (the connection's forward pdf).
    Vec3 ConnectToLight(Sampler& aSampler, const PathState& aPath, const PathSegment& aVertex, const Bsdf& aBsdf) const {
        // BEGIN EXERCISE pt_nee_mis
        if (mOptions.mDirectLight == DirectLightSampling::kBsdfOnly) return Vec3(0.f);
        const LightPick pick = mScene.PickLight(aSampler.Get1D());
        const Light& light = *pick.mLight;
        const std::optional<LightSample> sample = light.Illuminate(mScene.GetSceneSphere(), aVertex.Position(), aSampler.Get2D());
        if (!sample || IsBlack(sample->mRadiance)) return Vec3(0.f);
        const BsdfEval bsdf = aBsdf.EvaluateWithRoulette(sample->mDirToLight);
        if (bsdf.IsBlack()) return Vec3(0.f);
        const SegmentMedia media = TraceConnection(mScene, aVertex.Position(), sample->mDirToLight, sample->mDistance,
                                                   MediumTowards(mScene, aVertex, sample->mDirToLight));
        if (media.mOccluded) return Vec3(0.f);
        const float directPdfW = sample->mDirectPdfW * pick.mProb;
        const float bsdfPdfW = bsdf.mDirPdfW * media.Pdfs(aVertex.mInMedium, false).mForward;
        const float weight = light.IsDelta() ? 1.f : LightSampleWeight(directPdfW, bsdfPdfW);
        return aPath.mThroughput * bsdf.mValue * sample->mRadiance * media.mTransmittance * (weight * bsdf.mCosThetaGen / directPdfW);
        // END EXERCISE pt_nee_mis
    }



    // w = p^b / (p^b + q^b), written as 1 / (1 + (q/p)^b): squaring the pdfs of a small
    // light seen from afar (1e17 and more) would overflow to inf / inf = NaN.
    float MisWeight(float aPdfOfThis, float aPdfOfOther) const {
        return 1.f / (1.f + MisPower(mOptions.mMisHeuristic, aPdfOfOther / aPdfOfThis));
    }
    // The weights of the two direct-light techniques; with one technique switched off
    // the other gets weight 1 (and the path still scatters, for indirect light).
    float LightSampleWeight(float aLightPdfW, float aBsdfPdfW) const {
        return mOptions.mDirectLight == DirectLightSampling::kLightOnly ? 1.f : MisWeight(aLightPdfW, aBsdfPdfW);
    }
    float BsdfHitWeight(float aBsdfPdfW, float aLightPdfW) const {
        switch (mOptions.mDirectLight) {
        case DirectLightSampling::kLightOnly: return 0.f;
        case DirectLightSampling::kBsdfOnly: return 1.f;
        default: return MisWeight(aBsdfPdfW, aLightPdfW);
        }
    }

    // Adds a contribution to the pixel, and to its layer when layers are on: a light hit
    // at the path's current length, or (aNextEvent) a light reached one segment further
    // by next-event estimation, whose layer counts as non-specular.
    void AddContribution(int aPixel, const PathState& aPath, const Vec3& aContribution, bool aNextEvent = false) {
        if (IsBlack(aContribution)) return;
        mFilm.AddColor(aPixel, aContribution);
        if (mLayers.empty()) return;
        const int pathLength = aPath.mPathLength + (aNextEvent ? 1 : 0);
        const bool firstSpecular = aNextEvent ? false : aPath.mFirstSpecular;
        int layer = 0;
        if (pathLength == 2) layer = firstSpecular ? 2 : 1;
        else if (pathLength > 2) layer = firstSpecular ? 4 : 3;
        mFilm.AddToLayer(mLayers[size_t(layer)], aPixel, aContribution);
    }

    std::vector<int> mLayers;
};


// =====================================================================================
// [SECTION] Integrator: photon mapping (classic)
// =====================================================================================
// Jensen's photon mapping (1996; "Realistic Image Synthesis Using Photon Mapping", 2001).
// Each iteration traces mPhotonCount photons from the lights (power-carrying particles:
// a photon's power is its light sub-path throughput / photon count, Russian roulette
// keeps it near constant) and stores them at non-specular hits in a balanced kd-tree:
//   global map   every stored photon;
//   caustic map  photons that reached their surface through specular bounces only
//                (light -> specular+ -> here).
// The radiance estimate at x towards w from the k nearest photons within r_max is
//     L(x, w) ~ sum_p f(x, w_p, w) dPhi_p / (pi r^2),        r = distance to the k-th
// (the slide "photon map-based reflection"); with fewer than k photons inside r_max,
// r = r_max. Known bias of this constant kernel with k-NN: the estimate is a blur of the
// true radiance over a disc whose size adapts to the photon density -- peaks are
// flattened, edges and corners leak (photons of a neighbouring surface within r count),
// and dividing by the disc through the k-th photon overestimates slightly for small k
// (the k-th photon lies on the boundary). All of it vanishes as the photon count grows
// with k fixed, so the estimator is consistent: more photons, smaller discs. More
// iterations average independent photon maps: they reduce the noise, not the bias.
//
//   pm    visualises the global map at the first non-specular camera vertex (camera
//         paths follow specular bounces by ray tracing; a light seen directly, or through
//         specular bounces, counts its emission).
//   pmfg  the partitioned estimator ("improved photon mapping" slide): at the first
//         non-specular camera vertex x,
//           direct    next-event estimation only (one light sample, no MIS needed: light
//                     reaching x straight from a light is counted here and nowhere else);
//           caustics  the caustic map at x;
//           indirect  final gathering: one BSDF sample of x's non-specular part, followed
//                     through specular bounces to a non-specular y, where the global map
//                     gives the radiance towards x (a gather ray ending on a light adds
//                     nothing: that light is direct, or a caustic);
//           specular  x's specular components continue the camera path by ray tracing;
//         with layers: emitted, direct, caustics, indirect, and "specular" for everything
//         found after one or more specular camera bounces. They sum to the image.

struct Photon {
    Vec3 mPosition{0.f};
    Vec3 mPower{0.f};        // flux carried, already divided by the photon count
    Vec3 mDirFix{0.f};       // unit direction back towards where the photon came from
    int mPathLength = 0;     // segments from the light
};

// The k nearest points, by its contract; how it works is [SECTION] Appendix: range
// search (a kd-tree), and a reader who skips it loses nothing needed to follow the
// estimator. Build(count, positionOf) keeps the points and returns the order it keeps them
// in: order[j] is the point kept at index j, and the caller reorders its own data the
// same way, so that the indices the search reports are the caller's. FindNearest(point,
// k, maxDistSqr, accept) returns the (up to) k nearest kept points within distance^2
// maxDistSqr that accept(index) accepts -- the k nearest by distance, equal distances by
// index -- in no particular order except that, when there are k of them, the k-th nearest
// is last: all a density estimate needs (the set, and the radius). It is valid until the
// next query. KNearest returns the same sorted by distance. Used by one thread.
class NearestSearch {
public:
    struct Neighbor {
        uint32_t mIndex;
        float mDistSqr;
        // Nearer first, and equal distances by index: a total order, so the k nearest are
        // one definite set whatever order the search happens to meet them in.
        bool operator<(const Neighbor& aOther) const {
            return mDistSqr < aOther.mDistSqr || (mDistSqr == aOther.mDistSqr && mIndex < aOther.mIndex);
        }
    };

    template <class PositionOf>
    std::vector<uint32_t> Build(size_t aCount, PositionOf&& aPositionOf);
    template <class Accept>
    const std::vector<Neighbor>& FindNearest(const Vec3& aPoint, int aK, float aMaxDistSqr, Accept&& aAccept) const;
    template <class Accept>
    std::vector<Neighbor> KNearest(const Vec3& aPoint, int aK, float aMaxDistSqr, Accept&& aAccept) const;
    size_t Size() const;
    const Vec3& Position(size_t aIndex) const;  // of the point kept at aIndex

    class KdTree;  // the appendix's structure (its tests use it directly)

private:
    struct State;
    std::shared_ptr<State> mState;  // null until Build
};

// A photon map: photons in kd-tree order, and the radiance estimate over them.
class PhotonMap {
public:
    void Build(std::vector<Photon> aPhotons) {
        const std::vector<uint32_t> order = mSearch.Build(aPhotons.size(), [&](size_t i) { return aPhotons[i].mPosition; });
        mPhotons.resize(aPhotons.size());
        for (size_t i = 0; i < order.size(); i++) mPhotons[i] = aPhotons[order[i]];
    }
    size_t Size() const { return mPhotons.size(); }
    const NearestSearch& Search() const { return mSearch; }

    // sum f dPhi / (pi r^2) over the aK nearest photons within aMaxRadius whose path
    // length is at most aMaxPhotonLength (so the full path stays within the limit).
    Vec3 EstimateRadiance(const Vec3& aPoint, const Bsdf& aBsdf, int aK, float aMaxRadius, int aMaxPhotonLength) const {
        const std::vector<NearestSearch::Neighbor>& nearest = mSearch.FindNearest(
            aPoint, aK, Sqr(aMaxRadius), [&](size_t i) { return mPhotons[i].mPathLength <= aMaxPhotonLength; });
        if (nearest.empty()) return Vec3(0.f);
        const float radiusSqr = int(nearest.size()) == aK ? nearest.back().mDistSqr : Sqr(aMaxRadius);  // the k-th
        if (!(radiusSqr > 0.f)) return Vec3(0.f);
        Vec3 sum(0.f);
        for (const NearestSearch::Neighbor& n : nearest) {
            const Photon& photon = mPhotons[n.mIndex];
            // f_path, not f: the photons' flux is per unit of geometric area (Bsdf notes).
            sum += aBsdf.EvaluatePath(photon.mDirFix) * photon.mPower;
        }
        return sum / (kPi * radiusSqr);
    }

private:
    NearestSearch mSearch;
    std::vector<Photon> mPhotons;
};

struct PhotonMaps {
    PhotonMap mGlobal, mCaustic;
};

// Traces aPhotonCount photons and builds the global and caustic maps.
inline PhotonMaps TracePhotons(const Scene& aScene, int aPhotonCount, int aMaxPathLength, Sampler& aSampler) {
    std::vector<Photon> global, caustic;
    for (int p = 0; p < aPhotonCount; p++) {
        aSampler.StartLightPath(p, aPhotonCount);
        const LightPick pick = aScene.PickLight(aSampler.Get1D());
        const Light& light = *pick.mLight;
        const float lightPickProb = pick.mProb;
        const Vec2 rndDirection = aSampler.Get2D();
        const Vec2 rndPosition = aSampler.Get2D();
        const std::optional<LightEmission> emission = light.Emit(aScene.GetSceneSphere(), rndDirection, rndPosition);
        if (!emission || !(emission->mEmissionPdfW > 0.f)) continue;
        Vec3 power = emission->mEnergy / (emission->mEmissionPdfW * lightPickProb * float(aPhotonCount));
        Ray ray = aScene.SpawnRay(emission->mPosition, emission->mDirection);
        bool onlySpecular = true;
        Bsdf bsdf;  // set up anew at every vertex (Setup leaves nothing of the last)
        for (int pathLength = 1; pathLength < aMaxPathLength; pathLength++) {
            const SurfacePoint hit = aScene.Intersect(ray);
            if (!hit.IsValid()) break;
            const Vec3& hitPoint = hit.mPosition;
            bsdf.Setup(ray, hit, aScene, Transport::kImportance);
            if (!bsdf.IsValid()) break;
            if (!bsdf.IsDelta()) {
                const Photon photon{hitPoint, power, -ray.mDirection, pathLength};
                global.push_back(photon);
                if (onlySpecular && pathLength > 1) caustic.push_back(photon);
            }
            const std::optional<ScatterSample> scatter = SampleScatteringWithRoulette(bsdf, aSampler);
            if (!scatter) break;
            power *= scatter->mWeight;
            onlySpecular = onlySpecular && scatter->IsSpecular();
            ray = aScene.SpawnRay(hitPoint, scatter->mDirection);
        }
    }
    PhotonMaps maps;
    maps.mGlobal.Build(std::move(global));
    maps.mCaustic.Build(std::move(caustic));
    return maps;
}

class PhotonMapper : public AbstractRenderer {
public:
    PhotonMapper(const Scene& aScene, const RenderOptions& aOptions) : AbstractRenderer(aScene, aOptions) {
        if (aScene.HasMedia())
            throw Error(std::string(AlgorithmShortName(aOptions.mAlgorithm)) +
                        ": classic photon mapping keeps no volume photon map and does not render participating media; "
                        "use ppm, bpm or vcm (photon points in media), or pt or bpt");
        mFinalGather = aOptions.mAlgorithm == Algorithm::kPhotonMappingFinalGather;
        mMaxRadius = aOptions.mMaxPhotonRadiusFactor * aScene.GetSceneSphere().mRadius;
        if (mOptions.mTechniqueLayers) {
            if (mFinalGather) for (int l = 0; l < kLayerCount; l++) mLayers[l] = mFilm.AddLayer(kLayerNames[l]);
            else for (int l : {kEmitted, kPhotons}) mLayers[l] = mFilm.AddLayer(kLayerNames[l]);
        }
    }

    // The estimator's two steps: the photon maps of this iteration, then one camera path
    // per pixel that reads them.
    void RunIteration(int /*aIteration*/, Sampler& aSampler) override {
        mMaps = TracePhotons(mScene, mOptions.mPhotonCount, mOptions.mMaxPathLength, aSampler);
        const Camera& camera = mScene.mCamera;
        for (int pixel = 0; pixel < camera.PixelCount(); pixel++) {
            aSampler.StartPixelSample(pixel);
            const Vec2 raster = Vec2(float(pixel % camera.Width()), float(pixel / camera.Width())) + aSampler.Get2D();
            TraceCameraPath(aSampler, pixel, camera.GenerateRay(raster));
        }
    }

private:
    enum Layer { kEmitted = 0, kDirect, kCaustics, kIndirect, kSpecular, kPhotons, kLayerCount };
    static constexpr const char* kLayerNames[kLayerCount] = {"emitted", "direct", "caustics", "indirect", "specular", "photons"};

    // Follows the camera path through specular bounces (by ray tracing) and estimates
    // with the photon maps at each non-specular vertex; lights it sees count their emission.
    void TraceCameraPath(Sampler& aSampler, int aPixel, Ray aRay) {
        Vec3 throughput(1.f);
        bool afterSpecular = false;
        Bsdf bsdf;  // set up anew at every vertex (Setup leaves nothing of the last)
        for (int pathLength = 1; pathLength <= mOptions.mMaxPathLength; pathLength++) {
            const SurfacePoint hit = mScene.Intersect(aRay);
            if (!hit.IsValid()) {
                const Light* background = mScene.GetBackground();
                if (background && pathLength >= mOptions.mMinPathLength)
                    Add(aPixel, afterSpecular ? kSpecular : kEmitted,
                        throughput * background->GetRadiance(mScene.GetSceneSphere(), aRay.mDirection, Vec3(0.f), Vec2(0.f)).mRadiance);
                return;
            }
            const Vec3& hitPoint = hit.mPosition;
            if (hit.mLightId >= 0 && pathLength >= mOptions.mMinPathLength)
                Add(aPixel, afterSpecular ? kSpecular : kEmitted,
                    throughput * mScene.GetLight(hit.mLightId).GetRadiance(mScene.GetSceneSphere(), aRay.mDirection, hit.GeometricNormal(), hit.mUv).mRadiance);
            bsdf.Setup(aRay, hit, mScene, Transport::kRadiance);
            if (!bsdf.IsValid()) return;
            if (!bsdf.IsDelta()) {
                if (mFinalGather) EstimatePartitioned(aSampler, aPixel, pathLength, hitPoint, bsdf, throughput, afterSpecular);
                else Add(aPixel, kPhotons, throughput * Estimate(mMaps.mGlobal, hitPoint, bsdf, pathLength));
            }
            // Only specular components carry the camera path on (by ray tracing).
            if (!ContinueSpecular(aSampler, bsdf, hitPoint, throughput, aRay)) return;
            afterSpecular = true;
        }
    }

    void Add(int aPixel, Layer aLayer, const Vec3& aContribution) {
        mFilm.AddColor(aPixel, aContribution);
        if (mOptions.mTechniqueLayers && mLayers[aLayer] >= 0) mFilm.AddToLayer(mLayers[aLayer], aPixel, aContribution);
    }

    // Photon estimate at a camera vertex of length aPathLength: photons of length a
    // make paths of length a + aPathLength.
    Vec3 Estimate(const PhotonMap& aMap, const Vec3& aPoint, const Bsdf& aBsdf, int aPathLength) {
        if (aPathLength + 1 > mOptions.mMaxPathLength) return Vec3(0.f);
        return aMap.EstimateRadiance(aPoint, aBsdf, mOptions.mNearestPhotons, mMaxRadius,
                                     mOptions.mMaxPathLength - aPathLength);
    }

    // Samples the BSDF; continues (true) only if a specular component was picked.
    bool ContinueSpecular(Sampler& aSampler, const Bsdf& aBsdf, const Vec3& aHitPoint, Vec3& aThroughput, Ray& aRay) const {
        const std::optional<ScatterSample> scatter = SampleBsdf(aBsdf, aSampler.Get3D());
        if (!scatter || !scatter->IsSpecular()) return false;
        aThroughput *= scatter->mWeight;
        aRay = mScene.SpawnRay(aHitPoint, scatter->mDirection);
        return true;
    }

    // pmfg at the first non-specular camera vertex x: the partition of the "improved
    // photon mapping" slide, each part of the light reaching x counted once.
    void EstimatePartitioned(Sampler& aSampler, int aPixel, int aPathLength, const Vec3& aHitPoint, const Bsdf& aBsdf,
                             const Vec3& aThroughput, bool aAfterSpecular) {
        auto layer = [&](Layer aPart) { return aAfterSpecular ? kSpecular : aPart; };
        AddDirectLight(aSampler, aPixel, layer(kDirect), aPathLength, aHitPoint, aBsdf, aThroughput);
        // Caustics: the caustic map here.
        Add(aPixel, layer(kCaustics), aThroughput * Estimate(mMaps.mCaustic, aHitPoint, aBsdf, aPathLength));
        FinalGather(aSampler, aPixel, layer(kIndirect), aPathLength, aHitPoint, aBsdf, aThroughput);
    }

    // Direct light: one light sample (next-event estimation), no MIS, as no other part
    // counts light that reaches x straight from a light.
    void AddDirectLight(Sampler& aSampler, int aPixel, Layer aLayer, int aPathLength, const Vec3& aHitPoint, const Bsdf& aBsdf,
                        const Vec3& aThroughput) {
        if (aPathLength + 1 > mOptions.mMaxPathLength || aPathLength + 1 < mOptions.mMinPathLength) {
            aSampler.Get1D();  // the same random numbers drawn either way
            aSampler.Get2D();
            return;
        }
        const Light& light = *mScene.PickLight(aSampler.Get1D()).mLight;
        const std::optional<LightSample> sample = light.Illuminate(mScene.GetSceneSphere(), aHitPoint, aSampler.Get2D());
        if (!sample || IsBlack(sample->mRadiance)) return;
        const BsdfEval bsdf = aBsdf.Evaluate(sample->mDirToLight);
        if (!bsdf.IsBlack() && !mScene.Occluded(aHitPoint, sample->mDirToLight, sample->mDistance))
            Add(aPixel, aLayer, aThroughput * bsdf.mValue * sample->mRadiance *
                                    (bsdf.mCosThetaGen * float(mScene.LightCount()) / sample->mDirectPdfW));
    }

    // Indirect light by final gathering: one sample of x's non-specular part, followed
    // through specular bounces to a non-specular y, where the global map estimates.
    void FinalGather(Sampler& aSampler, int aPixel, Layer aLayer, int aPathLength, const Vec3& aHitPoint, const Bsdf& aBsdf,
                     const Vec3& aThroughput) {
        const std::optional<ScatterSample> scatter = SampleBsdf(aBsdf, aSampler.Get3D());
        if (!scatter || scatter->IsSpecular()) return;  // the specular part is traced by the caller
        Vec3 gatherThroughput = aThroughput * scatter->mValue * (scatter->mCosThetaOut / scatter->mPdfW);
        Ray ray = mScene.SpawnRay(aHitPoint, scatter->mDirection);
        Bsdf bsdf;  // set up anew at every vertex (Setup leaves nothing of the last)
        for (int length = aPathLength + 1; length < mOptions.mMaxPathLength; length++) {
            const SurfacePoint hit = mScene.Intersect(ray);
            if (!hit.IsValid()) return;
            const Vec3& hitPoint = hit.mPosition;
            bsdf.Setup(ray, hit, mScene, Transport::kRadiance);
            if (!bsdf.IsValid()) return;
            if (!bsdf.IsDelta()) {
                Add(aPixel, aLayer, gatherThroughput * Estimate(mMaps.mGlobal, hitPoint, bsdf, length));
                return;
            }
            if (!ContinueSpecular(aSampler, bsdf, hitPoint, gatherThroughput, ray)) return;
        }
    }

    bool mFinalGather = false;
    float mMaxRadius = 0.f;
    PhotonMaps mMaps;
    int mLayers[kLayerCount] = {-1, -1, -1, -1, -1, -1};
};

// =====================================================================================
// [SECTION] Integrator: the VertexCM family (LT, PPM, BPM, BPT, VCM)
// =====================================================================================
// One class serves five algorithms, as in SmallVCM. Each iteration has three stages:
//   1. trace N_L = (pixel count) light sub-paths, store their non-specular vertices, and
//      connect each vertex to the camera (light tracing);
//   2. build a range-search structure (a hash grid) over the stored vertices;
//   3. trace one camera sub-path per pixel; at each vertex: count a light it hits,
//      connect to a light (next-event estimation), connect to the vertices of one light
//      sub-path (vertex connection, VC), merge with the light vertices within radius r
//      (vertex merging, VM), and continue.
// The algorithm only switches techniques on and off:
//          light tracing  camera paths  VC (NEE, connections)  VM               MIS
//   lt     yes            no            no                     no               none
//   ppm    no             yes           no                     first non-spec.  none
//   bpm    no             yes           no                     every vertex     yes
//   bpt    yes            yes           yes                    no               yes
//   vcm    yes            yes           yes                    every vertex     yes
//
// The estimator of VCM (Georgiev et al. 2012): every technique that can build a path
// contributes f/p weighted by the balance (or power) heuristic over ALL techniques:
// unidirectional (a camera path hits a light), NEE, light tracing, each connection
// split, and a merge at each interior non-specular vertex, whose pdf is that of the
// connection times pi r^2 p_A and N_L light sub-paths [tech. rep. (10), (20)].
//
// How the MIS weights are evaluated (the point of the technical report): a weight needs
// the pdfs of all techniques of a path, but a vertex only has its own sub-path. Each
// sub-path therefore carries three running quantities, updated at every step:
//   dVCM  1 / (forward area pdf of this vertex)           -- the technique one step away
//   dVC   the sum of the relative pdfs of all techniques with fewer vertices on this
//         side, as a connection would need it            [tech. rep. (31)-(36)]
//   dVM   the same, as a merge would need it
// and a full path's weight is formed from the two vertices that meet [tech. rep. (37)].
// The functions in VcmMis below are that arithmetic, free of any ray tracing, so tests
// can drive them with the vertices of a given path and compare them with a brute-force
// sum over all techniques (tests/test_vcm_mis.cpp).
//
// Where we go beyond SmallVCM:
//   * Techniques an algorithm does not use are left out of the sums exactly: BPM has no
//     NEE and no connections, so the dVCM terms that stand for them are gated by
//     mUseVC (SmallVCM keeps some of them in, which biases BPM slightly).
//   * PPM handles materials that mix specular and non-specular parts: it merges at the
//     first vertex with a non-specular part and continues only if the sampled component
//     is specular (SmallVCM silently falls back to BPM there).
//   * Light tracing alone also splats the emitting surface points themselves, so that
//     lights seen directly appear in its image (the other algorithms see them by camera
//     paths). Point lights, which no camera path can see, are not splatted.

// The constants of one iteration that the MIS arithmetic needs.
struct VcmMisConstants {
    MisHeuristic mHeuristic = MisHeuristic::kBalance;
    bool mUseVC = true;                 // NEE, connections, light tracing
    bool mUseVM = true;                 // merging
    float mLightPathCount = 1.f;        // N_L
    float mMergeRadius = 0.f;           // r of this iteration
    float mVmWeightFactor = 0.f;        // Mis(eta_VCM) if merging is used, else 0
    float mVcWeightFactor = 0.f;        // Mis(1 / eta_VCM) if connecting is used, else 0
    float mInvEtaWeight = 0.f;          // Mis(1 / eta_VCM), used where no technique is gated
    float mVmNormalization = 0.f;       // 1 / (pi r^2 N_L): the merging kernel [tech. rep. (11)]
    // Merging at a point in a medium (photon points, UPBP's point-point 3D estimator):
    // the kernel is a ball, eta = N_L (4/3) pi r^3, and dVM keeps its surface scale 1 /
    // eta_surface, so the merge at a vertex enters the sums relative to a surface merge:
    // mMergeHere = Mis(eta_here / eta_surface), mInvMergeHere its inverse; both 1 at a
    // surface. ForMedium() gives the constants of a medium vertex.
    float mMergeHere = 1.f;
    float mInvMergeHere = 1.f;
    // UPBP's merges along beams at a point in a medium (VcmMis::BeamMerges): eta of the
    // beam radiance estimate (pb2d), N_L pi r^2, and of photon beams (bb1d), N_B 2 r; 0
    // where the technique is off (every algorithm but upbp).
    float mEtaPb2d = 0.f, mEtaBb1d = 0.f;
    bool HasBeamMerges() const { return mEtaPb2d > 0.f || mEtaBb1d > 0.f; }

    float Mis(float aPdf) const { return MisPower(mHeuristic, aPdf); }

    static VcmMisConstants Make(MisHeuristic aHeuristic, bool aUseVC, bool aUseVM, float aLightPathCount, float aRadius) {
        VcmMisConstants c;
        c.mHeuristic = aHeuristic;
        c.mUseVC = aUseVC;
        c.mUseVM = aUseVM;
        c.mLightPathCount = aLightPathCount;
        c.mMergeRadius = aRadius;
        // BEGIN EXERCISE vcm_mis/eta
        // eta_VCM = (n_VM / n_VC) pi r^2 with n_VC = 1, n_VM = N_L [tech. rep. (20)].
        const float etaVCM = kPi * Sqr(aRadius) * aLightPathCount;
        c.mInvEtaWeight = c.Mis(1.f / etaVCM);
        c.mVmWeightFactor = aUseVM ? c.Mis(etaVCM) : 0.f;
        c.mVcWeightFactor = aUseVC ? c.mInvEtaWeight : 0.f;
        // END EXERCISE vcm_mis/eta
        // BEGIN EXERCISE ppm_merging/kernel
        c.mVmNormalization = 1.f / (kPi * Sqr(aRadius) * aLightPathCount);
        // END EXERCISE ppm_merging/kernel
        return c;
    }
    // The same for a vertex in a medium: the 3D kernel 1 / ((4/3) pi r^3 N_L) [Krivanek et
    // al. 2014, sec. 4, the point-point 3D estimator] and its eta.
    // aRadius: the radius of merging in media (RenderOptions::mMediumRadiusFactor).
    VcmMisConstants ForMedium(float aRadius) const {
        VcmMisConstants c = *this;
        const float etaSurface = kPi * Sqr(mMergeRadius) * mLightPathCount;
        const float etaVolume = 4.f / 3.f * kPi * aRadius * Sqr(aRadius) * mLightPathCount;
        c.mVmWeightFactor = mUseVM ? Mis(etaVolume) : 0.f;
        c.mMergeHere = Mis(etaVolume / etaSurface);
        c.mInvMergeHere = Mis(etaSurface / etaVolume);
        c.mVmNormalization = 1.f / etaVolume;
        return c;
    }
};

// The running MIS quantities of one sub-path vertex.
struct SubpathMis {
    float dVCM = 0.f;
    float dVC = 0.f;
    float dVM = 0.f;
};

namespace VcmMis {

// Light sub-path start [tech. rep. (31)-(33)]. Pdfs include the light pick probability.
// aCosAtLight: cosine of the emitted direction at a finite light (1 at infinity).
inline SubpathMis AtLightEmission(const VcmMisConstants& c, float aDirectPdfA, float aEmissionPdfW,
                                  float aCosAtLight, bool aIsDeltaLight, bool aIsFiniteLight) {
    SubpathMis m;
    // BEGIN EXERCISE bpt_mis/emission
    m.dVCM = c.Mis(aDirectPdfA / aEmissionPdfW);                                       // (31)
    // A delta light cannot be hit by a camera path: the unidirectional technique has
    // pdf 0 there [tech. rep. (48)-(50)]; lights at infinity have no cosine (sec. 5.1).
    m.dVC = aIsDeltaLight ? 0.f : c.Mis((aIsFiniteLight ? aCosAtLight : 1.f) / aEmissionPdfW);  // (32)
    // END EXERCISE bpt_mis/emission
    // BEGIN EXERCISE vcm_mis/emission
    // (33): dVM = dVC / eta. Not gated by mUseVC: the technique it stands for is the
    // unidirectional one, which every algorithm with camera paths has.
    m.dVM = m.dVC * c.mInvEtaWeight;                                                   // (33)
    // END EXERCISE vcm_mis/emission
    return m;
}

// Camera sub-path start [tech. rep. (31)-(33), camera side]: a pinhole's position pdf
// is 1, so only light tracing (N_L samples) relates to the first camera vertex.
// aCameraPdfW: pdf of the primary ray per unit solid angle (per pixel area).
inline SubpathMis AtCameraStart(const VcmMisConstants& c, float aCameraPdfW) {
    SubpathMis m;
    // BEGIN EXERCISE bpt_mis/camera_start
    m.dVCM = c.Mis(c.mLightPathCount / aCameraPdfW);
    // END EXERCISE bpt_mis/camera_start
    return m;
}

// After tracing a segment of length aDistance that arrives with |cos| = aCosAtHit
// [tech. rep. (34)-(36), the part applied at the hit]. The distance is not applied on
// the first segment from a light at infinity, whose "area" pdf is a solid-angle pdf.
inline void AfterSegment(const VcmMisConstants& c, SubpathMis& m, float aDistance, float aCosAtHit, bool aApplyDistance) {
    // BEGIN EXERCISE bpt_mis/segment
    if (aApplyDistance) m.dVCM *= c.Mis(Sqr(aDistance));
    const float invCos = 1.f / c.Mis(std::abs(aCosAtHit));
    m.dVCM *= invCos;
    m.dVC *= invCos;
    m.dVM *= invCos;
    // END EXERCISE bpt_mis/segment
    SMALLVCM_CHECK(std::isfinite(m.dVCM) && std::isfinite(m.dVC) && std::isfinite(m.dVM) && m.dVCM >= 0.f &&
                   m.dVC >= 0.f && m.dVM >= 0.f, "an MIS quantity is not finite after a segment");
}

// After sampling a BSDF at a vertex: aCosOut is |cos| of the sampled direction, the pdfs
// include the continuation probability [tech. rep. (34)-(36); specular (53)-(55)].
inline void AfterScatter(const VcmMisConstants& c, SubpathMis& m, float aCosOut, float aDirPdfW,
                         float aRevPdfW, bool aSpecular) {
    // BEGIN EXERCISE bpt_mis/scatter
    if (aSpecular) {
        // A delta vertex can neither connect nor merge, and its forward and reverse pdfs
        // are equal and cancel: only the cosine of the new direction remains.
        m.dVCM = 0.f;
        m.dVC *= c.Mis(aCosOut);
        m.dVM *= c.Mis(aCosOut);
        return;
    }
    const float scale = c.Mis(aCosOut / aDirPdfW);
    // The dVCM term stands for connecting right here (a VC technique); the
    // mVmWeightFactor term for merging here; dVC * Mis(rev) for everything before.
    const float connectHere = c.mUseVC ? m.dVCM : 0.f;
    const float newDVC = scale * (m.dVC * c.Mis(aRevPdfW) + connectHere + c.mVmWeightFactor);    // (35)
    // END EXERCISE bpt_mis/scatter
    // BEGIN EXERCISE vcm_mis/scatter
    const float newDVM = scale * (m.dVM * c.Mis(aRevPdfW) + m.dVCM * c.mVcWeightFactor + c.mMergeHere);  // (36)
    // END EXERCISE vcm_mis/scatter
    m.dVC = newDVC;
    m.dVM = newDVM;
    // BEGIN EXERCISE bpt_mis/scatter_dvcm
    m.dVCM = c.Mis(1.f / aDirPdfW);                                                             // (34)
    // END EXERCISE bpt_mis/scatter_dvcm
    SMALLVCM_CHECK(std::isfinite(m.dVCM) && std::isfinite(m.dVC) && std::isfinite(m.dVM),
                   "an MIS quantity is not finite after a scatter");
}

// After the distance sampling of a segment through media (SegmentPdfs): the next
// vertex's forward pdf and the previous one's reverse pdf both gain the segment's
// free-flight pdfs (the distance and cosine were applied by AfterSegment). 1 and 1 in
// empty space.
inline void ThroughMedia(const VcmMisConstants& c, SubpathMis& m, float aForwardPdf, float aReversePdf) {
    const float invForward = 1.f / c.Mis(aForwardPdf);
    const float reverse = c.Mis(aReversePdf) * invForward;
    m.dVCM *= invForward;
    m.dVC *= reverse;
    m.dVM *= reverse;
}

// UPBP [Krivanek et al. 2014, sec. 5]. A path with a medium vertex x_i could also have
// been made by merging along a beam there: pb2d (photon point x_i, the camera's segment
// into x_i as a beam) and bb1d (the light's segment and the camera's segment as beams).
// Their pdfs are the point merge's, both sub-paths sampling x_i, times their eta, with a
// beam's coverage in place of the free-flight density of each side that integrates along
// its segment (R = P / p, BeamCoverageRatio), and bb1d's 1D kernel across two lines at
// angle theta: eta_pb R_camera and eta_bb sin(theta) R_light R_camera. This is their sum,
// in the units of mVmWeightFactor (a connection's pdf times eta).
inline float BeamMerges(const VcmMisConstants& c, float aRatioLight, float aRatioCamera, float aSinTheta) {
    float merges = 0.f;
    if (c.mEtaPb2d > 0.f) merges += c.Mis(c.mEtaPb2d * aRatioCamera);
    if (c.mEtaBb1d > 0.f) merges += c.Mis(c.mEtaBb1d * aSinTheta * aRatioLight * aRatioCamera);
    return merges;
}

// The beam merges of a sub-path's medium vertex x_i enter its dVC and dVM as the point
// merges do (AfterScatter's mVmWeightFactor term), but R at x_i from the other side needs
// the segment after x_i: so they are added once that segment is traced, after
// ThroughMedia. AfterScatter's term reaches the next vertex as dVCM_(i+1) times
// aReverseGeometry = the reverse free-flight pdf of the segment / d^2 (cos = 1 in a
// medium; no d^2 for a segment that left the scene), so the beam merges' term is the same
// product; dVM = dVC / eta_surface as in (36).
inline void AfterBeamMergesBehind(const VcmMisConstants& c, SubpathMis& m, float aReverseGeometry, float aBeamMerges) {
    // A segment that nothing could sample back, or of length 0 (a free flight of exactly 0,
    // a set of measure zero): no finite term.
    if (!(aReverseGeometry > 0.f) || !std::isfinite(aReverseGeometry)) return;
    const float merges = m.dVCM * c.Mis(aReverseGeometry) * aBeamMerges;
    m.dVC += merges;
    m.dVM += merges * c.mInvEtaWeight;
}

// Camera sub-path hits a light (s = 0) [tech. rep. (42), (43)]. Pdfs include the pick
// probability: aDirectPdfA is NEE's area pdf of the point (solid angle for a background),
// aEmissionPdfW the emission pdf of the point and the reversed ray direction.
inline float WeightCameraHitsLight(const VcmMisConstants& c, const SubpathMis& aCamera, float aDirectPdfA,
                                   float aEmissionPdfW) {
    // BEGIN EXERCISE bpt_mis/weight_camera_hits_light
    const float nextEvent = c.mUseVC ? c.Mis(aDirectPdfA) * aCamera.dVCM : 0.f;
    const float wCamera = nextEvent + c.Mis(aEmissionPdfW) * aCamera.dVC;
    return 1.f / (1.f + wCamera);
    // END EXERCISE bpt_mis/weight_camera_hits_light
}

// Next-event estimation (s = 1) [tech. rep. (44), (45)]. aBsdfDirPdfW / aBsdfRevPdfW: the
// camera vertex's BSDF pdfs towards the light / towards the previous camera vertex
// (with continuation probability); aDirectPdfW, aEmissionPdfW with the pick probability.
// aBeamMerges: UPBP's merges along beams at the camera vertex (BeamMerges; 0 elsewhere).
inline float WeightNextEvent(const VcmMisConstants& c, const SubpathMis& aCamera, float aBsdfDirPdfW,
                             float aBsdfRevPdfW, float aDirectPdfW, float aEmissionPdfW, float aCosToLight,
                             float aCosAtLight, bool aIsDeltaLight, float aBeamMerges = 0.f) {
    // BEGIN EXERCISE bpt_mis/weight_next_event
    // The unidirectional technique that would hit the same light point; none for delta lights.
    const float wLight = aIsDeltaLight ? 0.f : c.Mis(aBsdfDirPdfW / aDirectPdfW);
    const float wCamera = c.Mis(aEmissionPdfW * aCosToLight / (aDirectPdfW * aCosAtLight)) *
                          (c.mVmWeightFactor + aBeamMerges + aCamera.dVCM + aCamera.dVC * c.Mis(aBsdfRevPdfW));
    return 1.f / (wLight + 1.f + wCamera);
    // END EXERCISE bpt_mis/weight_next_event
}

// Light tracing: a light vertex connected to the camera (t = 1) [tech. rep. (46), (47)].
// aCameraPdfA: the camera's pdf of generating this vertex (per pixel area, in area
// measure); aBsdfRevPdfW: the light vertex's BSDF pdf towards its predecessor.
// aBeamMerges: UPBP's merges along beams at the light vertex (BeamMerges; 0 elsewhere).
inline float WeightLightTracing(const VcmMisConstants& c, const SubpathMis& aLight, float aCameraPdfA,
                                float aBsdfRevPdfW, float aBeamMerges = 0.f) {
    // BEGIN EXERCISE bpt_mis/weight_light_tracing
    const float wLight = c.Mis(aCameraPdfA / c.mLightPathCount) *
                         (c.mVmWeightFactor + aBeamMerges + aLight.dVCM + aLight.dVC * c.Mis(aBsdfRevPdfW));
    return 1.f / (wLight + 1.f);
    // END EXERCISE bpt_mis/weight_light_tracing
}

// Vertex connection of a light vertex y and a camera vertex z [tech. rep. (40), (41)].
// aCameraBsdfDirPdfA: z's BSDF generating y, as area pdf at y; aLightBsdfDirPdfA: y's
// BSDF generating z, as area pdf at z; the Rev pdfs are towards each vertex's predecessor.
// aLightVmWeightFactor, aCameraVmWeightFactor: c.mVmWeightFactor of each vertex (a surface
// or a medium point: VcmMisConstants::ForMedium), the merge each could have made.
inline float WeightConnection(const VcmMisConstants& c, const SubpathMis& aLight, const SubpathMis& aCamera,
                              float aCameraBsdfDirPdfA, float aCameraBsdfRevPdfW,
                              float aLightBsdfDirPdfA, float aLightBsdfRevPdfW,
                              float aLightVmWeightFactor, float aCameraVmWeightFactor) {
    // BEGIN EXERCISE bpt_mis/weight_connection
    const float wLight = c.Mis(aCameraBsdfDirPdfA) *
                         (aLightVmWeightFactor + aLight.dVCM + aLight.dVC * c.Mis(aLightBsdfRevPdfW));
    const float wCamera = c.Mis(aLightBsdfDirPdfA) *
                          (aCameraVmWeightFactor + aCamera.dVCM + aCamera.dVC * c.Mis(aCameraBsdfRevPdfW));
    return 1.f / (wLight + 1.f + wCamera);
    // END EXERCISE bpt_mis/weight_connection
}

// Vertex merging of a light vertex y with a camera vertex z [tech. rep. (38), (39)].
// aCameraBsdfDirPdfW: z's BSDF pdf of the direction y arrived from (z's outgoing,
// "towards the light" direction); aCameraBsdfRevPdfW: of z's own incoming direction.
inline float WeightMerge(const VcmMisConstants& c, const SubpathMis& aLight, const SubpathMis& aCamera,
                         float aCameraBsdfDirPdfW, float aCameraBsdfRevPdfW) {
    // BEGIN EXERCISE vcm_mis/merge_weight
    const float wLight = (aLight.dVCM * c.mVcWeightFactor + aLight.dVM * c.Mis(aCameraBsdfDirPdfW)) * c.mInvMergeHere;
    const float wCamera = (aCamera.dVCM * c.mVcWeightFactor + aCamera.dVM * c.Mis(aCameraBsdfRevPdfW)) * c.mInvMergeHere;
    return 1.f / (wLight + 1.f + wCamera);
    // END EXERCISE vcm_mis/merge_weight
}

// UPBP: one of several merges at a medium vertex, aThisMerge of aMergesHere (the point
// merge's mVmWeightFactor plus BeamMerges, each with the vertex's R and theta), against
// the techniques each sub-path stands for: (38), (39) multiplied out by eta_surface, as
// dVM = dVC / eta_surface.
inline float WeightMergeAmong(const VcmMisConstants& c, const SubpathMis& aLight, const SubpathMis& aCamera,
                              float aCameraBsdfDirPdfW, float aCameraBsdfRevPdfW, float aMergesHere, float aThisMerge) {
    const float connectHere = c.mUseVC ? 1.f : 0.f;
    const float wLight = aLight.dVCM * connectHere + aLight.dVC * c.Mis(aCameraBsdfDirPdfW);
    const float wCamera = aCamera.dVCM * connectHere + aCamera.dVC * c.Mis(aCameraBsdfRevPdfW);
    return aThisMerge / (aMergesHere + wLight + wCamera);
}

} // namespace VcmMis

// Range search over points, by its contract; how it works is [SECTION] Appendix: range
// search, and a reader who skips it loses nothing needed to follow the estimators.
// Build(count, radius, positionOf, itemOf) keeps a copy of itemOf(i) at positionOf(i) for
// every i < count. Process(point, visit) calls visit(item), or visit(item, i) if visit
// takes the point's index too, once for every kept point within the radius of point
// (|p - point| <= r), in an order that depends only on the points and the query. A
// RangeSearch is used by one thread (each renderer has its own).
template <class Item>
class RangeSearch {
public:
    template <class PositionOf, class ItemOf>
    void Build(size_t aCount, float aRadius, PositionOf&& aPositionOf, ItemOf&& aItemOf);
    template <class Visit>
    void Process(const Vec3& aPoint, Visit&& aVisit) const;

private:
    class Grid;
    std::shared_ptr<Grid> mGrid;  // null until Build
};

// Search of points along a ray, by its contract (the beam radiance estimate's query); how
// it works is [SECTION] Appendix: range search. Build(count, radius, positionOf, itemOf)
// keeps a copy of itemOf(i) at positionOf(i) for every i < count. Process(origin,
// direction, length, visit), with a unit direction, calls visit(item, t) once for every
// kept point p whose projection on the ray, origin + t direction, has 0 <= t <= length and
// lies within the radius of p (|p - origin - t direction| <= r), in an order that depends
// only on the points and the query. A RaySearch is used by one thread.
template <class Item>
class RaySearch {
public:
    template <class PositionOf, class ItemOf>
    void Build(size_t aCount, float aRadius, PositionOf&& aPositionOf, ItemOf&& aItemOf);
    template <class Visit>
    void Process(const Vec3& aOrigin, const Vec3& aDirection, float aLength, Visit&& aVisit) const;

private:
    class Tree;
    std::shared_ptr<Tree> mTree;  // null until Build
};

// A beam: the stretch mStart + t mDirection, 0 <= t <= mLength (a unit direction).
struct Beam {
    Vec3 mStart{0.f};
    Vec3 mDirection{0.f, 0.f, 1.f};
    float mLength = 0.f;
};
// Where a query ray passes a beam: the closest points of their lines, at t along the
// query and u along the beam, and the sine of the angle between the lines.
struct BeamPair {
    float mT = 0.f, mU = 0.f, mSinTheta = 0.f;
};

// Search of beams along a ray, by its contract (the beam x beam estimate's query), in
// [SECTION] Appendix: range search like RaySearch. Build(count, radius, beamOf, itemOf)
// keeps a copy of itemOf(i) for the Beam beamOf(i). Process(origin, direction, length,
// visit) calls visit(item, pair) once for every kept beam that Closest(origin, direction,
// length, beam, radius) finds, in an order that depends only on the beams and the query.
// A BeamSearch is used by one thread.
template <class Item>
class BeamSearch {
public:
    template <class BeamOf, class ItemOf>
    void Build(size_t aCount, float aRadius, BeamOf&& aBeamOf, ItemOf&& aItemOf);
    template <class Visit>
    void Process(const Vec3& aOrigin, const Vec3& aDirection, float aLength, Visit&& aVisit) const;

    // The closest points of the query's line, o + t w, and the beam's, a + u w_b: with
    // d = o - a, b = w . w_b, p = w . d, q = w_b . d, they are at t = (b q - p) / (1 - b^2)
    // and u = (q - b p) / (1 - b^2), and sin theta = sqrt(1 - b^2). The pair counts if the
    // lines pass within aRadius of each other there, with 0 <= t <= aLength and 0 <= u <=
    // the beam's length. Nearly parallel lines (sin theta < 1e-4) are left out: the
    // estimate divides by sin theta, and their share of the directions is ~1e-8. Most
    // beams a search tries pass far off; the lines' distance, |d . n| / |n| with
    // n = w x w_b and |n| = sin theta, turns those away before t and u are found.
    static std::optional<BeamPair> Closest(const Vec3& aOrigin, const Vec3& aDirection, float aLength, const Beam& aBeam,
                                           float aRadius) {
        const Vec3 d = aOrigin - aBeam.mStart;
        const float b = glm::dot(aDirection, aBeam.mDirection);
        const float sinSqr = 1.f - b * b;
        if (!(sinSqr >= 1e-8f)) return std::nullopt;
        if (!(Sqr(glm::dot(d, glm::cross(aDirection, aBeam.mDirection))) <= Sqr(aRadius) * sinSqr)) return std::nullopt;
        const float p = glm::dot(aDirection, d), q = glm::dot(aBeam.mDirection, d);
        const float t = (b * q - p) / sinSqr, u = (q - b * p) / sinSqr;
        if (!(t >= 0.f && t <= aLength && u >= 0.f && u <= aBeam.mLength)) return std::nullopt;
        const Vec3 gap = d + t * aDirection - u * aBeam.mDirection;
        if (!(glm::dot(gap, gap) <= Sqr(aRadius))) return std::nullopt;
        return BeamPair{t, u, std::sqrt(sinSqr)};
    }

private:
    class Tree;
    std::shared_ptr<Tree> mTree;  // null until Build
};

class VertexCM : public AbstractRenderer {
public:
    // Technique classes, the layers of the VCM overview (F15) and the VC/VM shares (F17).
    // Merging at points in a medium (photon points) is its own class; its layer exists only
    // in a scene with media.
    // pb2d and bb1d, merging along camera segments in media, are their own classes too.
    enum Technique {
        kUnidirectional = 0, kNextEvent, kLightTracing, kConnection, kMerging, kMediumMerging, kPointBeamMerging, kBeamBeamMerging,
        kTechniqueCount
    };
    static constexpr const char* kTechniqueLayerNames[kTechniqueCount] = {
        "unidirectional", "nee", "light_tracing", "connection", "merging", "merging_in_media", "pb2d", "bb1d"};
    // BPT's path pyramid: one layer per (s, t) up to this path length.
    static constexpr int kPyramidMaxLength = 5;

    VertexCM(const Scene& aScene, const RenderOptions& aOptions) : AbstractRenderer(aScene, aOptions) {
        switch (mOptions.mAlgorithm) {
        case Algorithm::kLightTracing: mLightTraceOnly = true; mUseVC = false; mUseVM = false; break;
        case Algorithm::kProgressivePhotonMapping: mPpm = true; mUseVC = false; mUseVM = true; break;
        case Algorithm::kBidirectionalPhotonMapping: mUseVC = false; mUseVM = true; break;
        case Algorithm::kBidirectionalPathTracing: mUseVC = true; mUseVM = false; break;
        case Algorithm::kVertexConnectionMerging: mUseVC = true; mUseVM = true; break;
        case Algorithm::kBeamRadianceEstimate: mPpm = true; mUseVC = false; mUseVM = true; mPointsAlongRaysOn = true; break;
        case Algorithm::kPhotonBeams: mPpm = true; mUseVC = false; mUseVM = true; mPhotonBeamsOn = true; break;
        case Algorithm::kUpbp: {
            const uint32_t techniques = mOptions.mUpbpTechniques;
            mUpbp = true;
            mUseVC = (techniques & kUpbpBpt) != 0;
            mMergeSurfaces = (techniques & kUpbpSurface) != 0;
            mMergeMediumPoints = (techniques & kUpbpPp3d) != 0;
            mPointsAlongRaysOn = (techniques & kUpbpPb2d) != 0;
            mPhotonBeamsOn = (techniques & kUpbpBb1d) != 0;
            mUseVM = mMergeSurfaces || mMergeMediumPoints || mPointsAlongRaysOn || mPhotonBeamsOn;
            break;
        }
        default: throw Error("VertexCM: algorithm '" + std::string(AlgorithmShortName(mOptions.mAlgorithm)) + "' is not of the VertexCM family");
        }
        mBeamQueries = mPointsAlongRaysOn || mPhotonBeamsOn;
        mBeamMis = mUpbp && mBeamQueries && mScene.HasMedia();
        if (!mUpbp) {  // the others merge at every kind of point they merge at (pb2d and bb1d: not at camera points in media)
            mMergeSurfaces = mUseVM;
            mMergeMediumPoints = mUseVM && !mBeamQueries;
        }
        mBaseRadius = mOptions.mRadiusFactor * mScene.GetSceneSphere().mRadius;
        if (mOptions.mTechniqueLayers) AddTechniqueLayers();
    }

    // The merging radius of iteration aIteration: r_i = r_0 (i+1)^((alpha-1)/2), the
    // progressive photon mapping schedule in SmallVCM's form (alpha = 1: fixed radius).
    float MergeRadius(int aIteration) const {
        // BEGIN EXERCISE ppm_merging/radius
        const float radius = mBaseRadius * std::pow(float(aIteration) + 1.f, 0.5f * (mOptions.mRadiusAlpha - 1.f));
        return std::max(radius, 1e-7f);
        // END EXERCISE ppm_merging/radius
    }

    // One iteration of the estimator, in the three stages of the section's notes.
    void RunIteration(int aIteration, Sampler& aSampler) override {
        const int pathCount = mScene.mCamera.PixelCount();
        const float radius = MergeRadius(aIteration);
        mMisConstants = VcmMisConstants::Make(mOptions.mMisHeuristic, mUseVC, mUseVM, float(pathCount), radius);
        const float mediumRadius = radius * (mOptions.mMediumRadiusFactor / mOptions.mRadiusFactor);
        const float beamRadius = radius * (mOptions.mBeamRadiusFactor / mOptions.mRadiusFactor);
        mMisConstantsMedium = mMisConstants.ForMedium(mediumRadius);
        if (mUpbp) SetUpbpConstants(pathCount, mediumRadius, beamRadius);

        // 1. Light sub-paths: traced, connected to the camera, their vertices stored.
        TraceLightSubpaths(aSampler, pathCount);
        if (mLightTraceOnly) return;

        // 2. The range searches over the stored vertices, for merging: the surface points,
        //    and the points in media (each merges only with its own kind); for the beam
        //    estimates, the points in media (pb2d) or the photon beams (bb1d) along rays.
        if (mUseVM) {
            if (mMergeSurfaces) BuildVertexSearch(mLightVertexSearch, mSurfaceVertexIndices, false, radius);
            if (mScene.HasMedia()) {
                if (mMergeMediumPoints) BuildVertexSearch(mMediumVertexSearch, mMediumVertexIndices, true, mediumRadius);
                if (mPointsAlongRaysOn) BuildPointsAlongRays(mediumRadius, pathCount);
                if (mPhotonBeamsOn) BuildPhotonBeamSearch(beamRadius, pathCount);
            }
        }

        // 3. Camera sub-paths, one per pixel, each connecting to the light sub-path the
        //    sampler pairs it with (the pixel's own, or a permutation: see Sampler).
        for (int pixel = 0; pixel < pathCount; pixel++)
            TraceCameraSubpath(aSampler, pixel, aSampler.LightPathOfPixel(pixel, pathCount));
    }

    // UPBP's MIS constants: eta of pb2d (its radius is the one of points in media) and of
    // bb1d (N_B light sub-paths store beams); a technique that is off has eta 0, so its
    // terms drop out of every sum exactly (and the point merges: mVmWeightFactor 0).
    void SetUpbpConstants(int aPathCount, float aMediumRadius, float aBeamRadius) {
        for (VcmMisConstants* c : {&mMisConstants, &mMisConstantsMedium}) {
            c->mEtaPb2d = mPointsAlongRaysOn ? kPi * Sqr(aMediumRadius) * float(aPathCount) : 0.f;
            c->mEtaBb1d = mPhotonBeamsOn ? 2.f * aBeamRadius * float(std::min(aPathCount, mOptions.mBeamPaths)) : 0.f;
        }
        if (!mMergeSurfaces) mMisConstants.mVmWeightFactor = mMisConstants.mMergeHere = 0.f;
        if (!mMergeMediumPoints) mMisConstantsMedium.mVmWeightFactor = mMisConstantsMedium.mMergeHere = 0.f;
    }

    // --- what tests and tools may inspect ----------------------------------------------
    size_t LightVertexCount() const { return mLightVertices.size(); }
    size_t LightVertexCapacity() const { return mLightVertices.capacity(); }  // for the memory report

    // Test hook: the full path of every weighted contribution, with the MIS weight this
    // renderer gave it, so a test can recompute that weight from the path's vertices
    // alone (tests/test_vcm_mis.cpp). It only observes: the renderer runs the same code
    // with or without it. A merge (one record per light vertex merged) lists the merged
    // point twice, as the light and as the camera sub-path reached it: the two differ by
    // up to r. Off (a null pointer) unless a test sets it; run iterations single-threaded
    // (RunIteration) while it is set.
    struct PathVertex {
        Vec3 mPosition{0.f};  // for a light at infinity: the unit direction towards it
        Vec3 mNormal{0.f};    // geometric normal; 0 at the camera, delta lights, infinity and NEE points
        int mMaterialId = -1; // -1 at the ends
        int mLightId = -1;    // the light at this point, if any
        uint32_t mEvent = kEventNone;  // the specular component sampled here, if one was
        bool mAtInfinity = false;
        int mMedium = -1;     // a point in a medium: its medium (mNormal 0); -1 on surfaces
    };
    struct PathRecord {
        Technique mTechnique = kUnidirectional;
        int mLightVertexCount = 0;  // s: x_0 .. x_{s-1} come from the light side (a merge: x_{s-1} is the merged light vertex)
        float mWeight = 0.f;
        std::vector<PathVertex> mVertices;  // x_0 (on the light) .. x_k (the camera)
    };
    void SetPathRecords(std::vector<PathRecord>* aRecords) { mPathRecords = aRecords; }

    // A stored light vertex: what a connection or a merge needs. Neither the BSDF nor the
    // surface is stored: the primitive and the point determine the normals, material and
    // texture coordinates (Scene::FillSurfacePoint), from which and the incoming
    // direction a connection rebuilds the BSDF exactly; a merge needs only the incoming
    // direction. What a merge reads (MergeData) is what the range search keeps a copy of.
    struct MergeData {
        int mPathLength = 0;
        Vec3 mThroughput{0.f};
        Vec3 mDirFix{0.f};  // the exact direction it arrived from (minus the ray direction)
        SubpathMis mMis;
    };
    // A photon beam (bb1d): a light segment's piece in a scattering medium, as far as the
    // light's flight went, and what it carries at its start: beta_L at the segment's start
    // times T / P of the segment's earlier pieces.
    // UPBP: what the MIS weight of a point on a beam (a photon beam, or a camera segment as
    // a query) needs of the segment the beam is a piece of (MisOnBeam).
    struct BeamMis {
        SubpathMis mMis;                 // the sub-path's, after scattering at the segment's start
        float mOffset = 0.f;             // from the start vertex to the piece
        float mProbabilityBefore = 1.f;  // forward: the pieces before this one flown through
        float mReverseBefore = 1.f;      // reverse: the same, but reaching a start in a medium with density
        float mRatioAtStart = 0.f;       // R at a start in a medium, when this is not its first piece
        float mRatioIn = 0.f, mSinOut = 0.f;  // the start vertex's (SubpathState)
        bool mFirstPiece = true, mStartInMedium = false, mApplyDistance = true;
    };
    struct PhotonBeam {
        Beam mBeam;
        Vec3 mThroughput{0.f};
        int mPathLength = 0;  // segments of the light sub-path, this one included
        int mMedium = -1;
        int mLightPath = -1;  // which light sub-path of the iteration stored it
        BeamMis mMis;         // upbp only
    };
    // A stored point in a medium as pb2d's search keeps it, with its place in mLightVertices.
    struct PhotonPoint : MergeData {
        uint32_t mVertex = 0;
    };
    struct LightVertex : MergeData {
        Vec3 mHitPoint{0.f};
        int mPrimitiveId = -1;  // the primitive hit (see Scene); -1 for a point in a medium
        int mMedium = -1;       // the medium it was reached through (the medium it is in)
        bool mInMedium = false; // a point in a medium rather than on a surface
    };

private:
    // The state of a sub-path while it is traced.
    struct SubpathState {
        Vec3 mOrigin{0.f};
        Vec3 mDirection{0.f};
        Vec3 mThroughput{1.f};
        int mPathLength = 1;        // segments so far, counting the one being traced
        bool mIsFiniteLight = true; // light sub-paths: did it start on a finite light?
        bool mSpecularPath = true;  // camera sub-paths: only specular vertices so far?
        int mMedium = -1;           // the medium the next segment starts in
        bool mInMedium = false;     // the last vertex is a point in a medium
        SubpathMis mMis;
        // upbp: at the last vertex, if in a medium, R of the segment that reached it
        // (BeamCoverageRatio) and sin theta between that segment and the next.
        float mRatioIn = 0.f, mSinOut = 0.f;
    };

    // What one technique adds to one pixel: the path's f/p and its MIS weight; the film
    // takes their product. mLightVertices (s) and mPathLength place it in BPT's pyramid
    // and the MIS records (-1 for a merge, which sums many paths). Light tracing's lands
    // on mPixel, the pixel its vertex projects to. A default Contribution is none: the
    // technique made no path there (blocked, black, outside the image).
    struct Contribution {
        bool mMade = false;
        Technique mTechnique = kUnidirectional;
        Vec3 mUnweighted{0.f};
        float mWeight = 0.f;
        int mLightVertices = -1;
        int mPathLength = -1;
        int mPixel = -1;
    };
    static Contribution Made(Technique aTechnique, const Vec3& aUnweighted, float aWeight, int aLightVertices,
                             int aPathLength, int aPixel = -1) {
        return Contribution{true, aTechnique, aUnweighted, aWeight, aLightVertices, aPathLength, aPixel};
    }

    // --- stage 1: light sub-paths ----------------------------------------------------------
    // The light side of the estimator: N_L light sub-paths, splatted to the camera as
    // they go and stored for stage 3 (light sub-path p ends at mPathEnds[p]).
    void TraceLightSubpaths(Sampler& aSampler, int aPathCount) {
        mLightVertices.clear();
        mLightRatios.clear();
        mPhotonBeams.clear();
        // Room for 4 stored vertices per light path before the first iteration, so the
        // vector does not grow by copying itself while it is filled (reserved pages that
        // are never written take no memory). Later iterations keep the capacity.
        if (mLightVertices.capacity() == 0 && (mUseVC || mUseVM)) mLightVertices.reserve(4 * size_t(aPathCount));
        mPathEnds.assign(size_t(aPathCount), 0);
        if (mPathRecords) mLightHistories.clear();
        for (int path = 0; path < aPathCount; path++) {
            aSampler.StartLightPath(path, aPathCount);
            mStoreBeams = mPhotonBeamsOn && path < mOptions.mBeamPaths;
            mLightPath = path;
            TraceLightSubpath(aSampler);
            mPathEnds[size_t(path)] = mLightVertices.size();
        }
    }

    // One light sub-path: each vertex updates the sub-path's MIS quantities
    // [tech. rep. (34)-(36)]; a non-specular one is stored for connections and merging,
    // and connected to the camera (light tracing, t = 1).
    void TraceLightSubpath(Sampler& aSampler) {
        std::optional<SubpathState> start = GenerateLightSample(aSampler);
        if (!start) return;  // nothing emitted (a black texel of a textured light, a spot's cone edge)
        SubpathState& light = *start;
        Bsdf bsdf;
        for (;;) {
            const Ray ray = LeaveVertex(mScene, light.mOrigin, light.mDirection, light.mInMedium);
            const PathSegment segment = TraceSegment(mScene, ray, light.mMedium, light.mInMedium, aSampler,
                                                     GapOfVertex(mScene, light.mInMedium),
                                                     mStoreBeams ? &mSegmentPieces : nullptr);
            if (mStoreBeams) StorePhotonBeams(light, ray.mDirection);
            if (segment.Escaped()) return;
            light.mThroughput *= segment.mWeight;
            if (segment.mInMedium) bsdf.SetupInMedium(-ray.mDirection, mScene.GetMedium(segment.mMedium), Transport::kImportance);
            else bsdf.Setup(ray, segment.mHit, mScene, Transport::kImportance);
            if (!bsdf.IsValid()) return;
            // The area (in a medium: volume) pdf of this vertex: a change of measure, by the
            // geometric cosine (1 in a medium), and the segment's free-flight pdfs.
            VcmMis::AfterSegment(mMisConstants, light.mMis, segment.Length(), bsdf.CosThetaFixGeometric(),
                                 light.mPathLength > 1 || light.mIsFiniteLight);
            if (mScene.HasMedia()) VcmMis::ThroughMedia(mMisConstants, light.mMis, segment.mPdfs.mForward, segment.mPdfs.mReverse);
            if (mBeamMis) FollowBeamMerges(light, segment, false, light.mPathLength > 1 || light.mIsFiniteLight);
            if (mPathRecords) mLightHistories.back().push_back(RecordedVertex(segment));

            if (!bsdf.IsDelta()) {
                if (mUseVC || mUseVM) StoreLightVertex(light, ray, segment);
                // Light tracing: connect to the camera (t = 1); the path has mPathLength + 1 segments, within both limits.
                if ((mUseVC || mLightTraceOnly) && light.mPathLength + 1 >= mOptions.mMinPathLength &&
                    light.mPathLength + 1 <= mOptions.mMaxPathLength)
                    AddSplat(ConnectToCamera(light, segment, bsdf));
            }
            // A vertex of length L is useful only if a path of length L + 1 may follow.
            if (light.mPathLength + 2 > mOptions.mMaxPathLength) return;
            const std::optional<ScatterSample> scatter = SampleScattering(aSampler, bsdf, segment, light);
            if (!scatter) return;
            if (mBeamMis && segment.mInMedium) light.mSinOut = SinBetween(ray.mDirection, scatter->mDirection);
            if (mPathRecords && scatter->IsSpecular()) mLightHistories.back().back().mEvent = scatter->mEvent;
        }
    }

    // The segment just traced, piece by piece in scattering media, as photon beams (bb1d).
    void StorePhotonBeams(const SubpathState& aLight, const Vec3& aDirection) {
        for (size_t p = 0; p < mSegmentPieces.size(); p++) {
            const SegmentPiece& piece = mSegmentPieces[p];
            mPhotonBeams.push_back(PhotonBeam{Beam{piece.mStart, aDirection, piece.mLength},
                                              aLight.mThroughput * piece.mTransmittanceBefore / piece.mProbabilityBefore,
                                              aLight.mPathLength, piece.mMedium, mLightPath, BeamMis{}});
            if (mUpbp) mPhotonBeams.back().mMis = BeamMisOf(aLight, p, aLight.mPathLength > 1 || aLight.mIsFiniteLight);
        }
    }

    void StoreLightVertex(const SubpathState& aLight, const Ray& aRay, const PathSegment& aSegment) {
        LightVertex& vertex = mLightVertices.emplace_back();
        vertex.mHitPoint = aSegment.Position();
        vertex.mPathLength = aLight.mPathLength;
        vertex.mThroughput = aLight.mThroughput;
        vertex.mPrimitiveId = aSegment.mHit.mPrimitiveId;
        vertex.mMedium = aSegment.mMedium;
        vertex.mInMedium = aSegment.mInMedium;
        vertex.mDirFix = -aRay.mDirection;
        vertex.mMis = aLight.mMis;
        if (mUpbp) mLightRatios.push_back(aLight.mRatioIn);
    }
    // What the test hook records of a vertex a segment ended at.
    // (A light sub-path's records leave the light of an emitter it hits out.)
    PathVertex RecordedVertex(const PathSegment& aSegment, bool aCameraSubpath = false) const {
        if (aSegment.mInMedium) return PathVertex{aSegment.Position(), Vec3(0.f), -1, -1, kEventMedium, false, aSegment.mMedium};
        const SurfacePoint& hit = aSegment.mHit;
        return PathVertex{hit.mPosition, hit.GeometricNormal(), hit.mMaterialId, aCameraSubpath ? hit.mLightId : -1};
    }

    // --- stage 2: the range searches ------------------------------------------------------
    // The range search over the stored vertices of one kind (surface or medium points);
    // aIndices maps its points to mLightVertices.
    // (A RaySearch too: pb2d's points in media, queried along rays.)
    template <class Search>
    void BuildVertexSearch(Search& aSearch, std::vector<uint32_t>& aIndices, bool aInMedium, float aRadius) {
        aIndices.clear();
        for (size_t i = 0; i < mLightVertices.size(); i++)
            if (mLightVertices[i].mInMedium == aInMedium) aIndices.push_back(uint32_t(i));
        aSearch.Build(aIndices.size(), aRadius, [&](size_t i) { return mLightVertices[aIndices[i]].mHitPoint; },
                      [&](size_t i) { return static_cast<const MergeData&>(mLightVertices[aIndices[i]]); });
    }

    // The beam radiance estimate's search: the stored points in media, queried along rays.
    void BuildPointsAlongRays(float aRadius, int aPathCount) {
        std::vector<uint32_t>& indices = mMediumVertexIndices;
        indices.clear();
        for (size_t i = 0; i < mLightVertices.size(); i++)
            if (mLightVertices[i].mInMedium) indices.push_back(uint32_t(i));
        mPointsAlongRays.Build(indices.size(), aRadius, [&](size_t i) { return mLightVertices[indices[i]].mHitPoint; },
                               [&](size_t i) { return PhotonPoint{static_cast<const MergeData&>(mLightVertices[indices[i]]), indices[i]}; });
        mPointBeamKernel = 1.f / (kPi * Sqr(aRadius) * float(aPathCount));
    }
    // The photon beam estimate's search: the stored photon beams, queried along rays.
    void BuildPhotonBeamSearch(float aRadius, int aPathCount) {
        mBeamsAlongRays.Build(mPhotonBeams.size(), aRadius, [&](size_t i) { return mPhotonBeams[i].mBeam; },
                              [&](size_t i) { return mPhotonBeams[i]; });
        mBeamBeamKernel = 1.f / (2.f * aRadius * float(std::min(aPathCount, mOptions.mBeamPaths)));
    }

    // --- stage 3: camera sub-paths ---------------------------------------------------------
    // One camera sub-path through aPixel; at each vertex the techniques that complete a
    // path there, each adding its contribution: a light it hits (s = 0), and at a
    // non-specular vertex next-event estimation (s = 1), connections to the vertices of
    // light sub-path aLightPath, the one paired with this pixel (VC), and merging with the
    // light vertices within r (VM).
    void TraceCameraSubpath(Sampler& aSampler, int aPixel, int aLightPath) {
        const Camera& camera = mScene.mCamera;
        aSampler.StartPixelSample(aPixel);
        const Vec2 raster = Vec2(float(aPixel % camera.Width()), float(aPixel / camera.Width())) + aSampler.Get2D();
        SubpathState cam = GenerateCameraSample(raster);
        if (mPathRecords) {
            mCameraHistory.assign(1, PathVertex{cam.mOrigin});
            mCameraLightPath = aLightPath;
        }
        if (mUseVC) ForgetPixelLightBsdfs(aLightPath);
        Ray ray{cam.mOrigin, cam.mDirection};
        Bsdf bsdf;
        for (;;) {
            const PathSegment segment = TraceSegment(mScene, ray, cam.mMedium, cam.mInMedium, aSampler,
                                                     cam.mPathLength > 1 ? GapOfVertex(mScene, cam.mInMedium) : 0.f,
                                                     mBeamQueries ? &mSegmentPieces : nullptr);
            if (mBeamQueries) GatherAlongSegment(aPixel, cam, ray.mDirection);
            const SurfacePoint& hit = segment.mHit;
            cam.mThroughput *= segment.mWeight;
            if (segment.Escaped()) {
                // Out of the scene, through the media on the way: no distance or cosine to
                // apply (a background's pdfs are per solid angle), but the free flights were
                // sampled, as next-event estimation's connection to the background knows.
                if (mScene.HasMedia()) VcmMis::ThroughMedia(mMisConstants, cam.mMis, segment.mPdfs.mForward, segment.mPdfs.mReverse);
                if (mBeamMis) FollowBeamMerges(cam, segment, true, false);
                AddToFilm(aPixel, BackgroundHit(cam, ray.mDirection));
                return;
            }
            const float cosAtHit = segment.mInMedium ? 1.f : glm::dot(hit.GeometricNormal(), -ray.mDirection);
            const float distance = segment.Length();
            VcmMis::AfterSegment(mMisConstants, cam.mMis, distance, cosAtHit, true);
            if (mScene.HasMedia()) VcmMis::ThroughMedia(mMisConstants, cam.mMis, segment.mPdfs.mForward, segment.mPdfs.mReverse);
            if (mBeamMis) FollowBeamMerges(cam, segment, true, true);
            if (mPathRecords) mCameraHistory.push_back(RecordedVertex(segment, true));

            if (segment.mInMedium) {
                if (mBeamQueries && mPpm) return;  // the scattering here was gathered along the segment
                bsdf.SetupInMedium(-ray.mDirection, mScene.GetMedium(segment.mMedium), Transport::kRadiance);
            } else {
                // Continues after a light only if the emitter's material reflects (see PathTracer).
                if (hit.mLightId >= 0 && cam.mPathLength >= mOptions.mMinPathLength)
                    AddToFilm(aPixel, CameraHitsLight(cam, mScene.GetLight(hit.mLightId), ray.mDirection, hit.GeometricNormal(), hit.mUv));
                bsdf.Setup(ray, hit, mScene, Transport::kRadiance);
            }
            if (!bsdf.IsValid()) return;
            // A vertex of length L is useful only for paths of length >= L + 1.
            if (cam.mPathLength >= mOptions.mMaxPathLength) return;
            if (!bsdf.IsDelta()) ConnectAndMerge(aSampler, aPixel, aLightPath, cam, segment, bsdf);

            const std::optional<ScatterSample> scatter = SampleScattering(aSampler, bsdf, segment, cam);
            if (!scatter) return;
            if (mBeamMis && segment.mInMedium) cam.mSinOut = SinBetween(ray.mDirection, scatter->mDirection);
            if (mPathRecords && scatter->IsSpecular()) mCameraHistory.back().mEvent = scatter->mEvent;
            // PPM's camera path ends where it merged; only a specular component (of a
            // mixed material) carries it on, to find the next non-specular vertex.
            if (mPpm && !bsdf.IsDelta() && !scatter->IsSpecular()) return;
            ray = LeaveVertex(mScene, cam.mOrigin, cam.mDirection, cam.mInMedium);
        }
    }

    // The techniques that complete a path at a non-specular camera vertex: next-event
    // estimation (s = 1), connections to the vertices of light sub-path aLightPath (VC),
    // and merging with the light vertices within r (VM).
    SMALLVCM_ALWAYS_INLINE void ConnectAndMerge(Sampler& aSampler, int aPixel, int aLightPath, const SubpathState& aCamera,
                         const PathSegment& aVertex, const Bsdf& aBsdf) {
        if (mUseVC) {
            if (aCamera.mPathLength + 1 >= mOptions.mMinPathLength) AddToFilm(aPixel, ConnectToLight(aSampler, aCamera, aVertex, aBsdf));
            const size_t begin = LightSubpathBegin(aLightPath), end = LightSubpathEnd(aLightPath);
            for (size_t i = begin; i < end; i++) {
                const LightVertex& vertex = mLightVertices[i];
                const int pathLength = vertex.mPathLength + aCamera.mPathLength + 1;
                if (pathLength > mOptions.mMaxPathLength) break;  // the sub-path's vertices only get longer
                if (pathLength < mOptions.mMinPathLength) continue;
                AddToFilm(aPixel, ConnectVertices(aCamera, aVertex, aBsdf, vertex, PixelLightBsdf(i - begin, vertex), i));
            }
        }
        if (aVertex.mInMedium ? mMergeMediumPoints : mMergeSurfaces) AddToFilm(aPixel, MergeWithLightVertices(aCamera, aVertex.Position(), aBsdf));
    }

    // --- sub-path starts and steps -----------------------------------------------------------

    // A light sub-path's first vertex: a light picked, a point and direction emitted, and
    // its MIS quantities [tech. rep. (31)-(33)]. Nothing when the light emits nothing there.
    SMALLVCM_ALWAYS_INLINE std::optional<SubpathState> GenerateLightSample(Sampler& aSampler) {
        const LightPick pick = mScene.PickLight(aSampler.Get1D());
        const Light& light = *pick.mLight;
        const Vec2 rndDirection = aSampler.Get2D();
        const Vec2 rndPosition = aSampler.Get2D();
        if (mPathRecords) mLightHistories.emplace_back();
        std::optional<LightEmission> emission = light.Emit(mScene.GetSceneSphere(), rndDirection, rndPosition);
        if (!emission || !(emission->mEmissionPdfW > 0.f)) return std::nullopt;
        emission->mEmissionPdfW *= pick.mProb;
        emission->mDirectPdfA *= pick.mProb;
        SubpathState state;
        state.mOrigin = emission->mPosition;
        state.mDirection = emission->mDirection;
        state.mThroughput = emission->mEnergy / emission->mEmissionPdfW;
        state.mIsFiniteLight = light.IsFinite();
        state.mMedium = mScene.LightMedium(pick.mId);
        state.mMis = VcmMis::AtLightEmission(mMisConstants, emission->mDirectPdfA, emission->mEmissionPdfW,
                                             emission->mCosAtLight, light.IsDelta(), light.IsFinite());
        if (mPathRecords)
            mLightHistories.back().push_back(light.IsFinite()
                ? PathVertex{emission->mPosition, light.IsDelta() ? Vec3(0.f) : emission->mNormal, -1, pick.mId}
                : PathVertex{-emission->mDirection, Vec3(0.f), -1, pick.mId, kEventNone, true});
        // Light tracing alone splats the emitting point itself (see the section's notes).
        if (mLightTraceOnly && !light.IsDelta() && light.IsFinite() && mOptions.mMinPathLength <= 1)
            AddSplat(SplatEmitterPoint(light, *emission, pick.mProb));
        if (IsBlack(state.mThroughput)) return std::nullopt;
        return state;
    }

    // A camera sub-path's first ray through aRaster and its MIS quantities [tech. rep.
    // (31)-(33), camera side].
    SubpathState GenerateCameraSample(const Vec2& aRaster) const {
        const Camera& camera = mScene.mCamera;
        const Ray ray = camera.GenerateRay(aRaster);
        // The pdf of this direction per unit image area: d_plane^2 / cos^3.
        const float cosAtCamera = glm::dot(camera.Forward(), ray.mDirection);
        const float imagePointToCameraDist = camera.ImagePlaneDist() / cosAtCamera;
        const float cameraPdfW = Sqr(imagePointToCameraDist) / cosAtCamera;
        SubpathState state;
        state.mOrigin = ray.mOrigin;
        state.mDirection = ray.mDirection;
        state.mMedium = mScene.CameraMedium();
        state.mMis = VcmMis::AtCameraStart(mMisConstants, cameraPdfW);
        return state;
    }

    // Samples the continuation of a sub-path at a vertex, with Russian roulette, and
    // updates its throughput and MIS quantities [tech. rep. (34)-(36); specular
    // (53)-(55)]. Nothing when the sub-path ends.
    std::optional<ScatterSample> SampleScattering(Sampler& aSampler, const Bsdf& aBsdf, const PathSegment& aVertex,
                                                  SubpathState& aState) const {
        std::optional<ScatterSample> scatter = SampleScatteringWithRoulette(aBsdf, aSampler);
        if (!scatter) return scatter;
        const bool specular = scatter->IsSpecular();
        // For a specular event both pdfs are the component's selection probability (the
        // Fresnel term is the same for both directions of a reflection or refraction).
        // Where a one-sided share sits beside glass (diffuse under glass, the opaque rest
        // of partly transmissive glass) a refraction's selection probability differs
        // between the two sides; every technique still drops the same ratio, so the
        // weights still sum to one (unbiased), only not exactly the balance heuristic.
        // The cosine converts the reverse pdf at this vertex to area: the geometric one.
        VcmMis::AfterScatter(MisAt(aBsdf), aState.mMis, aBsdf.GeometricCos(scatter->mDirection, scatter->mCosThetaOut),
                             scatter->mPdfW, scatter->mReversePdfW, specular);
        aState.mOrigin = aVertex.Position();
        aState.mDirection = scatter->mDirection;
        aState.mMedium = MediumTowards(mScene, aVertex, scatter->mDirection);
        aState.mInMedium = aVertex.mInMedium;
        aState.mThroughput *= scatter->mWeight;
        aState.mSpecularPath = aState.mSpecularPath && specular;
        aState.mPathLength++;
        return scatter;
    }

    // --- light tracing -------------------------------------------------------------------
    // Camera importance for a point seen at distance aDistance with |cos| aCosAtPoint: the
    // factor that turns a point's area measure into image-plane area (pixels), i.e. the
    // camera's pdf of generating that point (SmallVCM's imageToSurfaceFactor).
    float CameraPdfA(const Vec3& aDirToCamera, float aDistance, float aCosAtPoint) const {
        // BEGIN EXERCISE lt_camera/camera_pdf
        const Camera& camera = mScene.mCamera;
        const float cosAtCamera = glm::dot(camera.Forward(), -aDirToCamera);
        const float imagePointToCameraDist = camera.ImagePlaneDist() / cosAtCamera;
        const float imageToSolidAngleFactor = Sqr(imagePointToCameraDist) / cosAtCamera;
        return imageToSolidAngleFactor * std::abs(aCosAtPoint) / Sqr(aDistance);
        // END EXERCISE lt_camera/camera_pdf
    }

    // Light tracing (t = 1): a light vertex connected to the pinhole and splatted to the
    // pixel it projects to, weighted by [tech. rep. (46), (47)].
    // Through media the connection carries the transmittance, and the camera's pdf of the
    // vertex the free flight that would have reached it.
    SMALLVCM_ALWAYS_INLINE Contribution ConnectToCamera(const SubpathState& aLight, const PathSegment& aVertex, const Bsdf& aBsdf) const {
        // BEGIN EXERCISE lt_camera/connect
        const Camera& camera = mScene.mCamera;
        Vec3 dirToCamera = camera.Position() - aVertex.Position();
        if (glm::dot(camera.Forward(), -dirToCamera) <= 0.f) return {};  // behind the camera
        const float distance = glm::length(dirToCamera);
        dirToCamera /= distance;
        const std::optional<Vec2> raster = camera.WorldToRaster(aVertex.Position());
        if (!raster || !camera.CheckRaster(*raster)) return {};
        const BsdfEval toCamera = aBsdf.EvaluateWithRoulette(dirToCamera);
        if (toCamera.IsBlack()) return {};
        const SegmentMedia media = TraceConnection(mScene, aVertex.Position(), dirToCamera, distance, MediumTowards(mScene, aVertex, dirToCamera));
        if (media.mOccluded) return {};
        // The camera's area pdf of this vertex (for MIS) converts by the geometric cosine;
        // the contribution takes the shading cosine that goes with the Bsdf's f (for
        // importance, f_s times the adjoint factor; Bsdf notes). Equal on flat surfaces.
        const float cameraPdfA = CameraPdfA(dirToCamera, distance, aBsdf.GeometricCos(dirToCamera, toCamera.mCosThetaGen)) *
                                 media.Pdfs(aVertex.mInMedium, false).mReverse;
        const float beamMerges = mBeamMis && aVertex.mInMedium && !IsBlack(media.mTransmittance)
                                     ? VcmMis::BeamMerges(mMisConstants, aLight.mRatioIn, media.FirstRatio(), SinBetween(aLight.mDirection, dirToCamera))
                                     : 0.f;
        const float weight = mLightTraceOnly ? 1.f : VcmMis::WeightLightTracing(MisAt(aBsdf), aLight.mMis, cameraPdfA, toCamera.mRevPdfW, beamMerges);
        // Each of the N_L light sub-paths estimates the whole image: divide by N_L.
        const Vec3 unweighted = aLight.mThroughput * toCamera.mValue * media.mTransmittance *
                                (CameraPdfA(dirToCamera, distance, toCamera.mCosThetaGen) / mMisConstants.mLightPathCount);
        return Made(kLightTracing, unweighted, weight, aLight.mPathLength + 1, aLight.mPathLength + 1, camera.RasterToIndex(*raster));
        // END EXERCISE lt_camera/connect
    }

    // Light tracing alone (t = 1, s = 1): the emitting point itself, seen by the camera.
    SMALLVCM_ALWAYS_INLINE Contribution SplatEmitterPoint(const Light& aLight, const LightEmission& aEmission, float aLightPickProb) const {
        const Camera& camera = mScene.mCamera;
        Vec3 dirToCamera = camera.Position() - aEmission.mPosition;
        if (glm::dot(camera.Forward(), -dirToCamera) <= 0.f) return {};
        const float distance = glm::length(dirToCamera);
        dirToCamera /= distance;
        const std::optional<Vec2> raster = camera.WorldToRaster(aEmission.mPosition);
        if (!raster || !camera.CheckRaster(*raster)) return {};
        const float cosAtLight = aLight.EmittingCosine(aEmission.mNormal, dirToCamera);
        if (cosAtLight <= kEpsCosine) return {};  // the side facing the camera does not emit
        // L_e G W_e / p_A(x0) / N_L, with G W_e the camera's area pdf of the point.
        const float positionPdfA = aLightPickProb / aLight.mArea;
        const int lightId = int(&aLight - &mScene.GetLight(0));
        const SegmentMedia media = TraceConnection(mScene, aEmission.mPosition, dirToCamera, distance, mScene.LightMedium(lightId));
        if (media.mOccluded) return {};
        const Vec3 contribution = aEmission.mRadiance * media.mTransmittance *
                                  (CameraPdfA(dirToCamera, distance, cosAtLight) / (positionPdfA * mMisConstants.mLightPathCount));
        return Made(kLightTracing, contribution, 1.f, 1, 1, camera.RasterToIndex(*raster));
    }

    // --- camera sub-path techniques ------------------------------------------------------
    // The camera sub-path hit a light (or left the scene with a background light): s = 0,
    // weighted by [tech. rep. (42), (43)].
    SMALLVCM_ALWAYS_INLINE Contribution CameraHitsLight(const SubpathState& aCamera, const Light& aLight, const Vec3& aRayDirection,
                                                const Vec3& aHitNormal, const Vec2& aHitUv) const {
        const Light::RadianceAtHit received = aLight.GetRadiance(mScene.GetSceneSphere(), aRayDirection, aHitNormal, aHitUv);
        if (IsBlack(received.mRadiance)) return {};
        // Length 1 has no other technique here; PPM's camera paths reach lights only
        // through specular vertices, which no merge can replace.
        float weight = 1.f;
        if (aCamera.mPathLength > 1 && !mPpm) {
            const float lightPickProb = mScene.LightPickProb();
            weight = VcmMis::WeightCameraHitsLight(mMisConstants, aCamera.mMis, received.mDirectPdfA * lightPickProb,
                                                   received.mEmissionPdfW * lightPickProb);
        }
        return Made(kUnidirectional, aCamera.mThroughput * received.mRadiance, weight, 0, aCamera.mPathLength);
    }

    // The camera sub-path left the scene: the background light, if any, is hit (s = 0).
    Contribution BackgroundHit(const SubpathState& aCamera, const Vec3& aDirection) {
        const Light* background = mScene.GetBackground();
        if (mPathRecords && background)
            mCameraHistory.push_back(PathVertex{aDirection, Vec3(0.f), -1, int(background - &mScene.GetLight(0)),
                                                kEventNone, true});
        if (!background || aCamera.mPathLength < mOptions.mMinPathLength) return {};
        return CameraHitsLight(aCamera, *background, aDirection, Vec3(0.f), Vec2(0.f));
    }

    // Next-event estimation (s = 1): a point sampled on a light, connected by a shadow ray,
    // weighted by [tech. rep. (44), (45)].
    // Through media: the transmittance, and the free-flight pdfs of both directions.
    SMALLVCM_ALWAYS_INLINE Contribution ConnectToLight(Sampler& aSampler, const SubpathState& aCamera, const PathSegment& aVertex, const Bsdf& aBsdf) {
        const Vec3& point = aVertex.Position();
        const LightPick pick = mScene.PickLight(aSampler.Get1D());
        const Light& light = *pick.mLight;
        const Vec2 rnd = aSampler.Get2D();
        const std::optional<LightSample> sample = light.Illuminate(mScene.GetSceneSphere(), point, rnd);
        if (!sample || IsBlack(sample->mRadiance)) return {};
        if (mPathRecords)
            mNextEventVertex = light.IsFinite()
                ? PathVertex{point + sample->mDirToLight * sample->mDistance, Vec3(0.f), -1, pick.mId}
                : PathVertex{sample->mDirToLight, Vec3(0.f), -1, pick.mId, kEventNone, true};
        const BsdfEval toLight = aBsdf.EvaluateWithRoulette(sample->mDirToLight);
        if (toLight.IsBlack()) return {};
        const SegmentMedia media = TraceConnection(mScene, point, sample->mDirToLight, sample->mDistance,
                                                   MediumTowards(mScene, aVertex, sample->mDirToLight));
        if (media.mOccluded) return {};
        const SegmentPdfs flight = media.Pdfs(aVertex.mInMedium, false);
        const float directPdfW = sample->mDirectPdfW * pick.mProb;
        const float beamMerges = mBeamMis && aVertex.mInMedium && !IsBlack(media.mTransmittance)
                                     ? VcmMis::BeamMerges(mMisConstants, media.FirstRatio(), aCamera.mRatioIn,
                                                          SinBetween(aCamera.mDirection, sample->mDirToLight))
                                     : 0.f;
        // The MIS weight converts the emission pdf to area at this vertex: geometric cosine;
        // the contribution's cosine is the shading one that goes with f (Bsdf notes).
        const float weight = VcmMis::WeightNextEvent(MisAt(aBsdf), aCamera.mMis, toLight.mDirPdfW * flight.mForward, toLight.mRevPdfW,
                                                     directPdfW, sample->mEmissionPdfW * pick.mProb * flight.mReverse,
                                                     aBsdf.GeometricCos(sample->mDirToLight, toLight.mCosThetaGen),
                                                     sample->mCosAtLight, light.IsDelta(), beamMerges);
        const Vec3 unweighted = aCamera.mThroughput * toLight.mValue * sample->mRadiance * media.mTransmittance *
                                (toLight.mCosThetaGen / directPdfW);
        return Made(kNextEvent, unweighted, weight, 1, aCamera.mPathLength + 1);
    }

    // Vertex connection (s, t >= 2) of the camera vertex with one vertex of this pixel's
    // own light sub-path, weighted by [tech. rep. (40), (41)].
    // Through media: the transmittance, and the free-flight pdfs of both directions.
    // aIndex: the light vertex's place in mLightVertices.
    SMALLVCM_ALWAYS_INLINE Contribution ConnectVertices(const SubpathState& aCamera, const PathSegment& aCameraVertex, const Bsdf& aBsdf,
                                                const LightVertex& aVertex, const Bsdf& aLightBsdf, size_t aIndex) const {
        const Vec3& point = aCameraVertex.Position();
        Vec3 direction = aVertex.mHitPoint - point;
        const float distanceSqr = glm::dot(direction, direction);
        if (!(distanceSqr > 0.f)) return {};
        const float distance = std::sqrt(distanceSqr);
        direction /= distance;

        const BsdfEval cameraSide = aBsdf.EvaluateWithRoulette(direction);
        if (cameraSide.IsBlack()) return {};
        const BsdfEval lightSide = aLightBsdf.EvaluateWithRoulette(-direction);
        if (lightSide.IsBlack()) return {};
        const SegmentMedia media = TraceConnection(mScene, point, direction, distance, MediumTowards(mScene, aCameraVertex, direction));
        if (media.mOccluded) return {};
        const SegmentPdfs flight = media.Pdfs(aCameraVertex.mInMedium, aVertex.mInMedium);

        // G takes the shading cosines that go with each side's f (the light side's f
        // carries the adjoint factor, so f cos is f_path |cos_geometric|: Bsdf notes);
        // the pdfs change measure at the other vertex by its geometric cosine.
        const float geometryTerm = cameraSide.mCosThetaGen * lightSide.mCosThetaGen / distanceSqr;
        // The merges each end could have made: UPBP's beam merges at ends in media too (not
        // where nothing gets through, e.g. to the sun through a medium filling all space:
        // there R's P and p both underflow to 0, and the contribution is 0 whatever the weight).
        float lightMerges = MisAt(aLightBsdf).mVmWeightFactor, cameraMerges = MisAt(aBsdf).mVmWeightFactor;
        if (mBeamMis && !IsBlack(media.mTransmittance)) {
            if (aVertex.mInMedium)
                lightMerges += VcmMis::BeamMerges(mMisConstants, mLightRatios[aIndex], media.LastRatio(), SinBetween(aVertex.mDirFix, direction));
            if (aCameraVertex.mInMedium)
                cameraMerges += VcmMis::BeamMerges(mMisConstants, media.FirstRatio(), aCamera.mRatioIn, SinBetween(aCamera.mDirection, direction));
        }
        const float weight = VcmMis::WeightConnection(
            mMisConstants, aVertex.mMis, aCamera.mMis,
            PdfWtoA(cameraSide.mDirPdfW, distance, aLightBsdf.GeometricCos(-direction, lightSide.mCosThetaGen)) * flight.mForward,
            cameraSide.mRevPdfW,
            PdfWtoA(lightSide.mDirPdfW, distance, aBsdf.GeometricCos(direction, cameraSide.mCosThetaGen)) * flight.mReverse,
            lightSide.mRevPdfW, lightMerges, cameraMerges);
        const Vec3 unweighted = aCamera.mThroughput * aVertex.mThroughput * cameraSide.mValue * lightSide.mValue * media.mTransmittance *
                                geometryTerm;
        return Made(kConnection, unweighted, weight, aVertex.mPathLength + 1, aVertex.mPathLength + aCamera.mPathLength + 1);
    }

    // Vertex merging: the light vertices within the radius, density-estimated with a
    // constant kernel 1 / (pi r^2) over N_L light sub-paths [tech. rep. (11)], weighted
    // by [tech. rep. (38), (39)].
    // A camera point in a medium merges with the light points in media within r, with the
    // 3D kernel 1 / ((4/3) pi r^3 N_L) (VcmMisConstants::ForMedium).
    Contribution MergeWithLightVertices(const SubpathState& aCamera, const Vec3& aHitPoint, const Bsdf& aBsdf) {
        // BEGIN EXERCISE ppm_merging/merge
        const bool inMedium = aBsdf.IsInMedium();
        const VcmMisConstants& mis = MisAt(aBsdf);
        Vec3 sum(0.f);
        (inMedium ? mMediumVertexSearch : mLightVertexSearch).Process(aHitPoint, [&](const MergeData& vertex, uint32_t aIndex) {
            const int pathLength = vertex.mPathLength + aCamera.mPathLength;
            if (pathLength > mOptions.mMaxPathLength || pathLength < mOptions.mMinPathLength) return;
            // The camera's BSDF, evaluated towards where the light vertex came from: f_path,
            // as the density estimate spreads flux over geometric area (Bsdf notes).
            const BsdfEval cameraSide = aBsdf.EvaluatePathWithRoulette(vertex.mDirFix);
            if (cameraSide.IsBlack()) return;
            const float weight = mPpm ? 1.f
                                 : mBeamMis && inMedium ? PointMergeWeightUpbp(vertex, aCamera, cameraSide, mMediumVertexIndices[aIndex])
                                 : VcmMis::WeightMerge(mis, vertex.mMis, aCamera.mMis, cameraSide.mDirPdfW, cameraSide.mRevPdfW);
            if (mPathRecords) RecordMerge((inMedium ? mMediumVertexIndices : mSurfaceVertexIndices)[aIndex], weight);
            sum += cameraSide.mValue * vertex.mThroughput * weight;
        });
        if (IsBlack(sum)) return {};
        return Made(inMedium ? kMediumMerging : kMerging, aCamera.mThroughput * sum * mis.mVmNormalization, 1.f, -1, -1);
        // END EXERCISE ppm_merging/merge
    }

    // The beam radiance estimate (pb2d) [Jarosz et al. 2008; Křivánek et al. 2014, Table 1]:
    // the camera segment just traced, from its vertex along aDirection, is a beam that
    // gathers every photon point y within r of its pieces in scattering media, at the
    // distance t_y of y's projection. Replacing the free-flight sample of the camera's next
    // vertex by the integral along the segment, with a kernel 1 / (pi r^2) across it:
    //   C = beta_C sum_y T(t_y) / P(t_y) sigma_s rho(w_y, -w) beta_L(y) / (N_L pi r^2)
    // T the transmittance from the vertex to t_y, P the probability that the flight got
    // that far (this is a short beam: it ends where the flight did, so t_y is gathered
    // with probability P and T / P leaves T). The camera sub-path then ends if it
    // scattered in the medium; at a surface it goes on as in ppm. Points in any medium
    // count, as photon points merge across boundaries (see MergeWithLightVertices).
    // Under UPBP's MIS (upbp) each photon's share is weighted (PointAlongBeamWeight).
    Contribution GatherPointsAlongSegment(const SubpathState& aCamera, const Vec3& aDirection) {
        Vec3 sum(0.f);
        for (size_t p = 0; p < mSegmentPieces.size(); p++) {
            const SegmentPiece& piece = mSegmentPieces[p];
            const Medium& medium = mScene.GetMedium(piece.mMedium);
            Bsdf phase;
            phase.SetupInMedium(-aDirection, medium, Transport::kRadiance);
            const BeamMis query = mBeamMis ? BeamMisOf(aCamera, p, true) : BeamMis{};
            mPointsAlongRays.Process(piece.mStart, aDirection, piece.mLength, [&](const PhotonPoint& vertex, float aT) {
                const int pathLength = vertex.mPathLength + aCamera.mPathLength;
                if (pathLength > mOptions.mMaxPathLength || pathLength < mOptions.mMinPathLength) return;
                const Vec3 reach = piece.mTransmittanceBefore * MediumTransmittance(medium, aT) /
                                   (piece.mProbabilityBefore * FreeFlightProbability(medium, aT));
                const BsdfEval cameraSide = phase.EvaluatePathWithRoulette(vertex.mDirFix);
                float weight = 1.f;
                if (mBeamMis) {
                    weight = PointAlongBeamWeight(vertex, query, medium, aT, aDirection, cameraSide);
                    if (mPathRecords) RecordBeamMerge(kPointBeamMerging, vertex.mVertex, nullptr, piece, aT, aDirection, weight);
                }
                sum += reach * cameraSide.mValue * vertex.mThroughput * weight;
            });
        }
        if (IsBlack(sum)) return {};
        return Made(kPointBeamMerging, aCamera.mThroughput * sum * mPointBeamKernel, 1.f, -1, -1);
    }

    // pb2d and bb1d: what the camera segment just traced gathers along its length.
    SMALLVCM_NOINLINE void GatherAlongSegment(int aPixel, const SubpathState& aCamera, const Vec3& aDirection) {
        if (mPointsAlongRaysOn) AddToFilm(aPixel, GatherPointsAlongSegment(aCamera, aDirection));
        if (mPhotonBeamsOn) AddToFilm(aPixel, GatherBeamsAlongSegment(aCamera, aDirection));
    }

    // Photon beams along a camera beam (bb1d) [Jarosz et al. 2011; Křivánek et al. 2014,
    // Table 1]: the camera segment just traced gathers every photon beam b whose line
    // passes within r of its pieces' lines, at t on the camera's and u on the beam's
    // closest points, theta the angle between them (BeamSearch::Closest):
    //   C = beta_C sum_b T_C(t)/P_C(t) sigma_s rho(w_b, -w) beta_b T_L(u)/P_L(u) / (N_B 2r sin theta)
    // Both beams are short (they end where their flights did: T / P as in pb2d). The 1D
    // kernel 1 / (2r) spans the lines' offset; sliding the camera line along the beam by
    // dv moves the closest point by dv / sin theta, hence the 1 / sin theta that turns
    // the pair into a density along the beam. N_B: the light sub-paths that stored beams
    // (the first RenderOptions::mBeamPaths of the iteration's N_L).
    // Under UPBP's MIS (upbp) each pair's share is weighted (BeamAlongBeamWeight).
    Contribution GatherBeamsAlongSegment(const SubpathState& aCamera, const Vec3& aDirection) {
        Vec3 sum(0.f);
        for (size_t p = 0; p < mSegmentPieces.size(); p++) {
            const SegmentPiece& piece = mSegmentPieces[p];
            const Medium& medium = mScene.GetMedium(piece.mMedium);
            Bsdf phase;
            phase.SetupInMedium(-aDirection, medium, Transport::kRadiance);
            const BeamMis query = mBeamMis ? BeamMisOf(aCamera, p, true) : BeamMis{};
            mBeamsAlongRays.Process(piece.mStart, aDirection, piece.mLength, [&](const PhotonBeam& beam, const BeamPair& pair) {
                const int pathLength = beam.mPathLength + aCamera.mPathLength;
                if (pathLength > mOptions.mMaxPathLength || pathLength < mOptions.mMinPathLength) return;
                const Medium& beamMedium = mScene.GetMedium(beam.mMedium);
                const Vec3 cameraReach = piece.mTransmittanceBefore * MediumTransmittance(medium, pair.mT) /
                                         (piece.mProbabilityBefore * FreeFlightProbability(medium, pair.mT));
                const Vec3 lightReach = beam.mThroughput * MediumTransmittance(beamMedium, pair.mU) /
                                        FreeFlightProbability(beamMedium, pair.mU);
                const BsdfEval cameraSide = phase.EvaluatePathWithRoulette(-beam.mBeam.mDirection);
                float weight = 1.f;
                if (mBeamMis) {
                    weight = BeamAlongBeamWeight(beam, pair, query, medium, cameraSide);
                    if (mPathRecords) RecordBeamMerge(kBeamBeamMerging, 0, &beam, piece, pair.mT, aDirection, weight, pair.mU);
                }
                sum += cameraReach * cameraSide.mValue * lightReach / pair.mSinTheta * weight;
            });
        }
        if (IsBlack(sum)) return {};
        return Made(kBeamBeamMerging, aCamera.mThroughput * sum * mBeamBeamKernel, 1.f, -1, -1);
    }

    // --- UPBP's MIS along beams [Krivanek et al. 2014, sec. 5] -------------------------------
    // A beam merge meets at a point x_i that one or both sub-paths did not sample: they
    // passed it on a segment. Each such side's MIS state at x_i is the one it would have
    // had had it sampled x_i there: the segment replayed up to x_i (MisOnBeam). Then the
    // weight is the point merge's (WeightMergeAmong), among all the merges x_i allows.
    static float SinBetween(const Vec3& aA, const Vec3& aB) { return glm::length(glm::cross(aA, aB)); }

    // What MisOnBeam needs of piece aPiece of the segment just traced (mSegmentPieces) from
    // aState's last vertex.
    BeamMis BeamMisOf(const SubpathState& aState, size_t aPiece, bool aApplyDistance) const {
        const SegmentPiece& piece = mSegmentPieces[aPiece];
        BeamMis b;
        b.mMis = aState.mMis;
        b.mOffset = piece.mOffset;
        b.mProbabilityBefore = b.mReverseBefore = piece.mProbabilityBefore;
        b.mRatioIn = aState.mRatioIn;
        b.mSinOut = aState.mSinOut;
        b.mStartInMedium = aState.mInMedium;
        b.mApplyDistance = aApplyDistance;
        // From a point in a medium the first piece is its medium's: the reversed flight
        // reaches the start with density there, not with probability.
        b.mFirstPiece = aPiece == 0;
        if (aState.mInMedium && aPiece > 0) {
            const SegmentPiece& first = mSegmentPieces[0];
            const Medium& medium = mScene.GetMedium(first.mMedium);
            b.mReverseBefore *= FreeFlightDensity(medium, first.mLength) / FreeFlightProbability(medium, first.mLength);
            b.mRatioAtStart = BeamCoverageRatio(medium, first.mLength);
        }
        return b;
    }

    // The MIS state at the point aT into a beam's piece (in aMedium), as if its sub-path had
    // sampled it there, and oRatio, R there (BeamCoverageRatio).
    SubpathMis MisOnBeam(const BeamMis& aBeam, const Medium& aMedium, float aT, bool aCamera, float& oRatio) const {
        SubpathMis m = aBeam.mMis;
        const bool reachStartWithDensity = aBeam.mFirstPiece && aBeam.mStartInMedium;
        const float forward = aBeam.mProbabilityBefore * FreeFlightDensity(aMedium, aT);
        const float reverse = aBeam.mReverseBefore * (reachStartWithDensity ? FreeFlightDensity(aMedium, aT) : FreeFlightProbability(aMedium, aT));
        const float distance = aBeam.mOffset + aT;
        VcmMis::AfterSegment(mMisConstants, m, distance, 1.f, aBeam.mApplyDistance);
        VcmMis::ThroughMedia(mMisConstants, m, forward, reverse);
        if (aBeam.mStartInMedium) {  // the start vertex's own beam merges (FollowBeamMerges)
            const float ratioOut = aBeam.mFirstPiece ? BeamCoverageRatio(aMedium, aT) : aBeam.mRatioAtStart;
            const float merges = aCamera ? VcmMis::BeamMerges(mMisConstants, ratioOut, aBeam.mRatioIn, aBeam.mSinOut)
                                         : VcmMis::BeamMerges(mMisConstants, aBeam.mRatioIn, ratioOut, aBeam.mSinOut);
            VcmMis::AfterBeamMergesBehind(mMisConstants, m, reverse / Sqr(distance), merges);
        }
        oRatio = BeamCoverageRatio(aMedium, aT);
        return m;
    }

    // After a segment of a sub-path under UPBP's MIS: the beam merges of the vertex it left
    // (VcmMis::AfterBeamMergesBehind, which needs this segment's R at that vertex), and
    // R of this segment at the vertex it reached.
    void FollowBeamMerges(SubpathState& aState, const PathSegment& aSegment, bool aCamera, bool aApplyDistance) const {
        if (aState.mInMedium) {
            const float ratioOut = BeamCoverageRatio(mScene.GetMedium(aState.mMedium), aSegment.mFirstPiece);
            const float merges = aCamera ? VcmMis::BeamMerges(mMisConstants, ratioOut, aState.mRatioIn, aState.mSinOut)
                                         : VcmMis::BeamMerges(mMisConstants, aState.mRatioIn, ratioOut, aState.mSinOut);
            const float geometry = aSegment.mPdfs.mReverse / (aApplyDistance ? Sqr(aSegment.Length()) : 1.f);
            VcmMis::AfterBeamMergesBehind(mMisConstants, aState.mMis, geometry, merges);
        }
        aState.mRatioIn = aSegment.mInMedium ? BeamCoverageRatio(mScene.GetMedium(aSegment.mMedium), aSegment.mLastPiece) : 0.f;
    }

    // The merges a medium vertex allows: the point merge (pp3d, if on) and the beam merges.
    float MergesAt(float aRatioLight, float aRatioCamera, float aSinTheta) const {
        return mMisConstantsMedium.mVmWeightFactor + VcmMis::BeamMerges(mMisConstantsMedium, aRatioLight, aRatioCamera, aSinTheta);
    }
    // pp3d: both sub-paths sampled x_i.
    float PointMergeWeightUpbp(const MergeData& aVertex, const SubpathState& aCamera, const BsdfEval& aCameraSide, uint32_t aIndex) const {
        const VcmMisConstants& c = mMisConstantsMedium;
        const float merges = MergesAt(mLightRatios[aIndex], aCamera.mRatioIn, SinBetween(aVertex.mDirFix, aCamera.mDirection));
        return VcmMis::WeightMergeAmong(c, aVertex.mMis, aCamera.mMis, aCameraSide.mDirPdfW, aCameraSide.mRevPdfW, merges, c.mVmWeightFactor);
    }
    // A point on a beam at its segment's start vertex itself (in float) has a replayed
    // segment of length 0, whose pdf is not finite: such meetings (a set of measure zero)
    // are left out, by their weight 0.
    static bool AwayFromStart(const BeamMis& aBeam, float aT) { return aBeam.mOffset + aT > 0.f; }
    // pb2d: the light sampled x_i, the camera passed it.
    float PointAlongBeamWeight(const PhotonPoint& aVertex, const BeamMis& aQuery, const Medium& aMedium, float aT, const Vec3& aDirection,
                               const BsdfEval& aCameraSide) const {
        if (!AwayFromStart(aQuery, aT)) return 0.f;
        const VcmMisConstants& c = mMisConstantsMedium;
        float ratioCamera = 0.f;
        const SubpathMis camera = MisOnBeam(aQuery, aMedium, aT, true, ratioCamera);
        const float merges = MergesAt(mLightRatios[aVertex.mVertex], ratioCamera, SinBetween(aVertex.mDirFix, aDirection));
        return VcmMis::WeightMergeAmong(c, aVertex.mMis, camera, aCameraSide.mDirPdfW, aCameraSide.mRevPdfW, merges,
                                        c.Mis(c.mEtaPb2d * ratioCamera));
    }
    // bb1d: both passed it.
    float BeamAlongBeamWeight(const PhotonBeam& aBeam, const BeamPair& aPair, const BeamMis& aQuery, const Medium& aMedium,
                              const BsdfEval& aCameraSide) const {
        if (!AwayFromStart(aQuery, aPair.mT) || !AwayFromStart(aBeam.mMis, aPair.mU)) return 0.f;
        const VcmMisConstants& c = mMisConstantsMedium;
        float ratioCamera = 0.f, ratioLight = 0.f;
        const SubpathMis camera = MisOnBeam(aQuery, aMedium, aPair.mT, true, ratioCamera);
        const SubpathMis light = MisOnBeam(aBeam.mMis, mScene.GetMedium(aBeam.mMedium), aPair.mU, false, ratioLight);
        const float merges = MergesAt(ratioLight, ratioCamera, aPair.mSinTheta);
        return VcmMis::WeightMergeAmong(c, light, camera, aCameraSide.mDirPdfW, aCameraSide.mRevPdfW, merges,
                                        c.Mis(c.mEtaBb1d * aPair.mSinTheta * ratioLight * ratioCamera));
    }

    // The stored light vertices of light sub-path aPath: [begin, end).
    size_t LightSubpathBegin(int aPath) const { return aPath == 0 ? 0 : mPathEnds[size_t(aPath) - 1]; }
    size_t LightSubpathEnd(int aPath) const { return mPathEnds[size_t(aPath)]; }

    // The BSDF of the aSlot-th light vertex of the light sub-path paired with this camera
    // sub-path, built at its first connection and kept for the camera sub-path's later
    // vertices, which connect to it again (building a BSDF costs more than evaluating one).
    const Bsdf& PixelLightBsdf(size_t aSlot, const LightVertex& aVertex) {
        if (mPixelLightBsdfPath[aSlot] != mCameraPathNumber) {
            SetupAtLightVertex(mPixelLightBsdfs[aSlot], aVertex);
            mPixelLightBsdfPath[aSlot] = mCameraPathNumber;
        }
        return mPixelLightBsdfs[aSlot];
    }
    // The stored vertex's BSDF rebuilt: its surface point from the primitive (see
    // LightVertex), or its medium's phase function.
    SMALLVCM_NOINLINE void SetupAtLightVertex(Bsdf& oBsdf, const LightVertex& aVertex) const {
        if (aVertex.mInMedium) {
            oBsdf.SetupInMedium(aVertex.mDirFix, mScene.GetMedium(aVertex.mMedium), Transport::kImportance);
            return;
        }
        SurfacePoint surface;
        surface.mPosition = aVertex.mHitPoint;
        surface.mPrimitiveId = aVertex.mPrimitiveId;
        mScene.FillSurfacePoint(surface);
        oBsdf.Setup(aVertex.mDirFix, surface, mScene, Transport::kImportance);
    }
    // A new camera sub-path, paired with light sub-path aLightPath: none of its light
    // vertices' BSDFs is built yet. Each entry holds the number of the camera sub-path it
    // was built for.
    void ForgetPixelLightBsdfs(int aLightPath) {
        const size_t count = LightSubpathEnd(aLightPath) - LightSubpathBegin(aLightPath);
        if (mPixelLightBsdfs.size() < count) {
            mPixelLightBsdfs.resize(count);
            mPixelLightBsdfPath.resize(count, 0);
        }
        mCameraPathNumber++;
    }

    // --- the film, the technique layers and the test hook ----------------------------------
    void AddToFilm(int aPixel, const Contribution& aContribution) {
        if (!aContribution.mMade) return;
        mFilm.AddColor(aPixel, aContribution.mUnweighted * aContribution.mWeight);
        if (mPathRecords || mOptions.mTechniqueLayers) Record(aPixel, aContribution);
    }
    // Light tracing's contributions, to the pixels they land on.
    void AddSplat(const Contribution& aContribution) {
        if (!aContribution.mMade) return;
        mFilm.Splat(aContribution.mPixel, aContribution.mUnweighted * aContribution.mWeight);
        if (mPathRecords || mOptions.mTechniqueLayers) Record(aContribution.mPixel, aContribution);
    }

    void AddTechniqueLayers() {
        for (int t = 0; t < kTechniqueCount; t++)
            if (t < kMediumMerging || mScene.HasMedia()) mTechniqueLayers[t] = mFilm.AddLayer(kTechniqueLayerNames[t]);
        if (mOptions.mAlgorithm != Algorithm::kBidirectionalPathTracing) return;
        for (int length = 1; length <= kPyramidMaxLength; length++)
            for (int s = 0; s <= length; s++) {
                const std::string name = "s" + std::to_string(s) + "_t" + std::to_string(length + 1 - s);
                mPyramidLayers[length][s][0] = mFilm.AddLayer(name);
                mPyramidLayers[length][s][1] = mFilm.AddLayer(name + "_unweighted");
            }
        mLongerPathsLayer = mFilm.AddLayer("longer_than_5");
    }

    // Writes a contribution into the technique layers and the path records, when asked for.
    SMALLVCM_NOINLINE void Record(int aPixel, const Contribution& aContribution) {
        const Technique technique = aContribution.mTechnique;
        const int s = aContribution.mLightVertices, length = aContribution.mPathLength;
        const Vec3 weighted = aContribution.mUnweighted * aContribution.mWeight;
        if (mPathRecords && s >= 0) RecordPath(technique, s, aContribution.mWeight);
        if (!mOptions.mTechniqueLayers) return;
        mFilm.AddToLayer(mTechniqueLayers[technique], aPixel, weighted);
        if (mLongerPathsLayer < 0 || s < 0) return;
        if (length > kPyramidMaxLength) {
            mFilm.AddToLayer(mLongerPathsLayer, aPixel, weighted);
            return;
        }
        mFilm.AddToLayer(mPyramidLayers[length][s][0], aPixel, weighted);
        mFilm.AddToLayer(mPyramidLayers[length][s][1], aPixel, aContribution.mUnweighted);
    }

    // The test hook (SetPathRecords): x_0 .. x_s of a contribution with s light vertices
    // (from the light sub-path paired with this camera sub-path, or of the one being traced
    // for light tracing; x_0 alone for next-event estimation), then the camera sub-path
    // backwards.
    void RecordPath(Technique aTechnique, int aLightVertices, float aWeight) {
        PathRecord record;
        record.mTechnique = aTechnique;
        record.mLightVertexCount = aLightVertices;
        record.mWeight = aWeight;
        std::vector<PathVertex>& path = record.mVertices;
        if (aTechnique == kNextEvent) path.push_back(mNextEventVertex);
        else if (aLightVertices > 0) {
            const std::vector<PathVertex>& light = aTechnique == kLightTracing ? mLightHistories.back()
                                                                                : mLightHistories[size_t(mCameraLightPath)];
            path.assign(light.begin(), light.begin() + aLightVertices);
        }
        if (aTechnique == kLightTracing) path.push_back(PathVertex{mScene.mCamera.Position()});
        else path.insert(path.end(), mCameraHistory.rbegin(), mCameraHistory.rend());
        mPathRecords->push_back(std::move(record));
    }

    // A merge of light vertex aVertex with the camera's last vertex: x_0 .. x_s of the
    // light sub-path it ends (s = its path length), then the whole camera sub-path
    // backwards, so the merged point appears twice, once from each side.
    void RecordMerge(uint32_t aVertex, float aWeight) {
        const std::vector<PathVertex>& light = mLightHistories[LightPathOfVertex(aVertex)];
        PathRecord record;
        record.mTechnique = kMerging;
        record.mLightVertexCount = mLightVertices[aVertex].mPathLength + 1;
        record.mWeight = aWeight;
        record.mVertices.assign(light.begin(), light.begin() + record.mLightVertexCount);
        record.mVertices.insert(record.mVertices.end(), mCameraHistory.rbegin(), mCameraHistory.rend());
        mPathRecords->push_back(std::move(record));
    }
    size_t LightPathOfVertex(uint32_t aVertex) const {
        return size_t(std::upper_bound(mPathEnds.begin(), mPathEnds.end(), size_t(aVertex)) - mPathEnds.begin());
    }
    // The same for pb2d and bb1d under upbp: the light side up to the photon point aVertex
    // (pb2d) or up to the point at aU on photon beam aBeam (bb1d), then the point at aT on
    // the camera's segment (piece aPiece, along aDirection) and the camera sub-path backwards.
    void RecordBeamMerge(Technique aTechnique, uint32_t aVertex, const PhotonBeam* aBeam, const SegmentPiece& aPiece, float aT,
                         const Vec3& aDirection, float aWeight, float aU = 0.f) {
        PathRecord record;
        record.mTechnique = aTechnique;
        record.mWeight = aWeight;
        std::vector<PathVertex>& path = record.mVertices;
        if (aBeam) {
            const std::vector<PathVertex>& light = mLightHistories[size_t(aBeam->mLightPath)];
            path.assign(light.begin(), light.begin() + aBeam->mPathLength);
            path.push_back(PathVertex{aBeam->mBeam.mStart + aU * aBeam->mBeam.mDirection, Vec3(0.f), -1, -1, kEventMedium, false, aBeam->mMedium});
        } else {
            const std::vector<PathVertex>& light = mLightHistories[LightPathOfVertex(aVertex)];
            path.assign(light.begin(), light.begin() + mLightVertices[aVertex].mPathLength + 1);
        }
        record.mLightVertexCount = int(path.size());
        path.push_back(PathVertex{aPiece.mStart + aT * aDirection, Vec3(0.f), -1, -1, kEventMedium, false, aPiece.mMedium});
        path.insert(path.end(), mCameraHistory.rbegin(), mCameraHistory.rend());
        mPathRecords->push_back(std::move(record));
    }

    std::vector<PathRecord>* mPathRecords = nullptr;
    std::vector<std::vector<PathVertex>> mLightHistories;  // per light sub-path, x_0 first
    std::vector<PathVertex> mCameraHistory;                // the camera first
    int mCameraLightPath = -1;                             // the light sub-path it connects to
    PathVertex mNextEventVertex;

    bool mUseVC = false, mUseVM = false, mPpm = false, mLightTraceOnly = false;
    bool mMergeSurfaces = false;      // merging at camera points on surfaces
    bool mMergeMediumPoints = false;  // merging at camera points in media (pp3d)
    bool mPointsAlongRaysOn = false;  // pb2d: camera segments gather the stored points in media
    bool mPhotonBeamsOn = false;  // bb1d: light segments are stored as photon beams, and gathered
    bool mBeamQueries = false;    // pb2d or bb1d: camera segments gather along their length
    bool mUpbp = false;           // upbp: all of the above that --techniques names, under one MIS
    bool mBeamMis = false;        // upbp with pb2d or bb1d in a scene with media: the MIS knows beam merges
    bool mStoreBeams = false;     // bb1d: the light sub-path being traced stores its beams
    int mLightPath = 0;           // the light sub-path being traced
    float mBaseRadius = 0.f;
    VcmMisConstants mMisConstants;        // of this iteration, at surface vertices
    VcmMisConstants mMisConstantsMedium;  // the same at points in media (ForMedium)
    // The MIS constants of the vertex a Bsdf was set up at (a surface or a medium point).
    const VcmMisConstants& MisAt(const Bsdf& aBsdf) const { return aBsdf.IsInMedium() ? mMisConstantsMedium : mMisConstants; }
    std::vector<LightVertex> mLightVertices;
    std::vector<float> mLightRatios;  // upbp: each light vertex's mRatioIn (SubpathState), as mLightVertices
    std::vector<size_t> mPathEnds;  // mPathEnds[p]: one past the last vertex of light sub-path p
    RangeSearch<MergeData> mLightVertexSearch;   // the stored surface points
    RangeSearch<MergeData> mMediumVertexSearch;  // the stored points in media
    std::vector<uint32_t> mSurfaceVertexIndices, mMediumVertexIndices;  // each search's points in mLightVertices
    RaySearch<PhotonPoint> mPointsAlongRays;    // the stored points in media, for the beam radiance estimate
    std::vector<SegmentPiece> mSegmentPieces;   // of the camera segment just traced (its beams)
    std::vector<PhotonBeam> mPhotonBeams;       // bb1d: this iteration's
    BeamSearch<PhotonBeam> mBeamsAlongRays;     // bb1d: over mPhotonBeams
    float mPointBeamKernel = 0.f;               // pb2d's 1 / (pi r^2 N_L) of this iteration
    float mBeamBeamKernel = 0.f;                // bb1d's 1 / (2 r N_B)
    std::vector<Bsdf> mPixelLightBsdfs;         // PixelLightBsdf's cache, for the current pixel
    std::vector<uint64_t> mPixelLightBsdfPath;  // the camera sub-path each entry was built for
    uint64_t mCameraPathNumber = 0;             // of the current camera sub-path, from 1
    int mTechniqueLayers[kTechniqueCount] = {-1, -1, -1, -1, -1, -1, -1, -1};
    int mPyramidLayers[kPyramidMaxLength + 1][kPyramidMaxLength + 1][2] = {};
    int mLongerPathsLayer = -1;
};


// =====================================================================================
//  PART II: APPENDICES
// =====================================================================================
// What a student may skip: each appendix implements an interface that Part I states
// (the BVH's and the range search's contracts, Render, WriteImage, LoadGltfScene) and
// relies on nothing in Part I beyond it. The integrators read the same without them.

// =====================================================================================
// [SECTION] Appendix: BVH
// =====================================================================================
// Provides: how Bvh meets the contract stated above its declaration in [SECTION]
// Geometry (a reader who skips this appendix loses nothing the renderer depends on).
// Relies on IntersectTriangle, IntersectSphere, Aabb and PrimitiveSoup from that section.
// Invariant: the tree is immutable once built (Bvh holds it through a shared pointer to
// const), which is what makes concurrent queries safe.
//
// kBvhLanes floats processed together: the width of the tree's nodes and leaf blocks.
// With GCC or Clang on x86 they are a compiler vector type, each operator one
// instruction: four lanes of SSE (SSE2: every x86-64) by default, eight lanes of AVX
// when the compiler may use AVX2 (-mavx2, which the Makefile adds on a build machine that
// has AVX2, or -march=native on such a machine),
// where one instruction tests eight boxes or eight triangles: the 8-wide tree has half
// the levels of the 4-wide one, so a ray visits fewer nodes and pushes fewer of them
// (Embree's BVH8 for single rays). Elsewhere, or when SMALLVCM_BVH_SCALAR is defined,
// plain loops over four floats. Each lane is the same IEEE single-precision operation
// every way, so every way gives the same hits bit for bit (given the same contraction
// of multiply-adds: none under the Makefile's flags and with -mavx2, which has no FMA;
// -march=native brings FMA, add -ffp-contract=off to keep the multiplies separate);
// only which of two primitives hit at exactly the same t is returned may depend on the
// width, as the contract allows. Every translation unit must see the same width (the
// Makefile compiles all with one CXXFLAGS): the tree's layout depends on it.
#if defined(__GNUC__) && defined(__AVX2__) && !defined(SMALLVCM_BVH_SCALAR)
#define SMALLVCM_BVH_AVX 1
#elif defined(__GNUC__) && defined(__SSE2__) && !defined(SMALLVCM_BVH_SCALAR)
#define SMALLVCM_BVH_SSE 1
#endif

// The traversal's inner steps (the slab test of a node, the choice of the next child, the
// test of a leaf block) are forced inline: out of line, a call per node visit keeps the
// stack size and the next child in memory instead of registers, and a call per block
// costs more argument passing than the block test itself.
#if defined(__GNUC__)
#define SMALLVCM_BVH_INLINE inline __attribute__((always_inline))
#else
#define SMALLVCM_BVH_INLINE inline
#endif
namespace detail {
#if defined(SMALLVCM_BVH_AVX)
inline constexpr int kBvhLanes = 8;
#else
inline constexpr int kBvhLanes = 4;
#endif
#if defined(SMALLVCM_BVH_SSE) || defined(SMALLVCM_BVH_AVX)
typedef float FloatVector __attribute__((vector_size(4 * kBvhLanes)));
typedef int32_t IntVector __attribute__((vector_size(4 * kBvhLanes)));
struct FloatN {
    FloatVector mV;
    static FloatN Load(const float* aAligned) { return {*reinterpret_cast<const FloatVector*>(aAligned)}; }
#if defined(SMALLVCM_BVH_AVX)
    static FloatN Broadcast(float x) { return {FloatVector{x, x, x, x, x, x, x, x}}; }
#else
    static FloatN Broadcast(float x) { return {FloatVector{x, x, x, x}}; }
#endif
    float operator[](int aLane) const { return mV[aLane]; }
    void SetLane(int aLane, float aValue) { mV[aLane] = aValue; }
};
inline FloatN operator+(FloatN a, FloatN b) { return {a.mV + b.mV}; }
inline FloatN operator-(FloatN a, FloatN b) { return {a.mV - b.mV}; }
inline FloatN operator*(FloatN a, FloatN b) { return {a.mV * b.mV}; }
inline FloatN operator/(FloatN a, FloatN b) { return {a.mV / b.mV}; }
// std::max(a, b) and std::min(a, b) lane by lane, NaN in b included (then a): the x86
// instructions return their second operand when either is NaN, hence the swap.
#if defined(SMALLVCM_BVH_AVX)
inline FloatN Max(FloatN a, FloatN b) { return {__builtin_ia32_maxps256(b.mV, a.mV)}; }
inline FloatN Min(FloatN a, FloatN b) { return {__builtin_ia32_minps256(b.mV, a.mV)}; }
#else
inline FloatN Max(FloatN a, FloatN b) { return {__builtin_ia32_maxps(b.mV, a.mV)}; }
inline FloatN Min(FloatN a, FloatN b) { return {__builtin_ia32_minps(b.mV, a.mV)}; }
#endif
// Comparisons give a lane mask (all bits set where true), combined with & | ~ in vector
// registers and turned into bits only once at the end (Bits: bit i for lane i), which
// saves the test of a block of triangles a dozen mask extractions.
struct MaskN { IntVector mV; };
inline MaskN operator&(MaskN a, MaskN b) { return {a.mV & b.mV}; }
inline MaskN operator|(MaskN a, MaskN b) { return {a.mV | b.mV}; }
inline MaskN operator~(MaskN a) { return {~a.mV}; }
#if defined(SMALLVCM_BVH_AVX)
inline int Bits(MaskN a) { return __builtin_ia32_movmskps256(reinterpret_cast<FloatVector>(a.mV)); }
#else
inline int Bits(MaskN a) { return __builtin_ia32_movmskps(reinterpret_cast<FloatVector>(a.mV)); }
#endif
inline MaskN LessEqual(FloatN a, FloatN b) { return {a.mV <= b.mV}; }
inline MaskN Less(FloatN a, FloatN b) { return {a.mV < b.mV}; }
inline MaskN Greater(FloatN a, FloatN b) { return {a.mV > b.mV}; }
inline MaskN Equal(FloatN a, FloatN b) { return {a.mV == b.mV}; }
// Lanes where a, b and c do not all have the same sign bit: the sign bits compared by
// exclusive or, then spread over the lane by an arithmetic shift (four instructions).
inline MaskN SignsDiffer(FloatN a, FloatN b, FloatN c) {
    const IntVector ia = reinterpret_cast<IntVector>(a.mV), ib = reinterpret_cast<IntVector>(b.mV);
    const IntVector ic = reinterpret_cast<IntVector>(c.mV);
    return {((ia ^ ib) | (ia ^ ic)) >> 31};
}
#else
struct FloatN {
    float mV[kBvhLanes];
    static FloatN Load(const float* aAligned) {
        FloatN result;
        for (int lane = 0; lane < kBvhLanes; lane++) result.mV[lane] = aAligned[lane];
        return result;
    }
    static FloatN Broadcast(float aValue) {
        FloatN result;
        for (int lane = 0; lane < kBvhLanes; lane++) result.mV[lane] = aValue;
        return result;
    }
    float operator[](int aLane) const { return mV[aLane]; }
    void SetLane(int aLane, float aValue) { mV[aLane] = aValue; }
};
template <typename Op>
inline FloatN Lanewise(FloatN a, FloatN b, Op aOp) {
    FloatN result;
    for (int lane = 0; lane < kBvhLanes; lane++) result.mV[lane] = aOp(a.mV[lane], b.mV[lane]);
    return result;
}
// A lane mask as bits, bit i for lane i.
struct MaskN { int mBits; };
inline MaskN operator&(MaskN a, MaskN b) { return {a.mBits & b.mBits}; }
inline MaskN operator|(MaskN a, MaskN b) { return {a.mBits | b.mBits}; }
inline MaskN operator~(MaskN a) { return {~a.mBits & ((1 << kBvhLanes) - 1)}; }
inline int Bits(MaskN a) { return a.mBits; }
template <typename Op>
inline MaskN MaskOf(FloatN a, FloatN b, Op aOp) {
    int bits = 0;
    for (int lane = 0; lane < kBvhLanes; lane++) bits |= int(aOp(a.mV[lane], b.mV[lane])) << lane;
    return {bits};
}
inline FloatN operator+(FloatN a, FloatN b) { return Lanewise(a, b, [](float x, float y) { return x + y; }); }
inline FloatN operator-(FloatN a, FloatN b) { return Lanewise(a, b, [](float x, float y) { return x - y; }); }
inline FloatN operator*(FloatN a, FloatN b) { return Lanewise(a, b, [](float x, float y) { return x * y; }); }
inline FloatN operator/(FloatN a, FloatN b) { return Lanewise(a, b, [](float x, float y) { return x / y; }); }
inline FloatN Max(FloatN a, FloatN b) { return Lanewise(a, b, [](float x, float y) { return std::max(x, y); }); }
inline FloatN Min(FloatN a, FloatN b) { return Lanewise(a, b, [](float x, float y) { return std::min(x, y); }); }
inline MaskN LessEqual(FloatN a, FloatN b) { return MaskOf(a, b, [](float x, float y) { return x <= y; }); }
inline MaskN Less(FloatN a, FloatN b) { return MaskOf(a, b, [](float x, float y) { return x < y; }); }
inline MaskN Greater(FloatN a, FloatN b) { return MaskOf(a, b, [](float x, float y) { return x > y; }); }
inline MaskN Equal(FloatN a, FloatN b) { return MaskOf(a, b, [](float x, float y) { return x == y; }); }
inline MaskN SignsDiffer(FloatN a, FloatN b, FloatN c) {
    int bits = 0;
    for (int lane = 0; lane < kBvhLanes; lane++) {
        const bool sign = std::signbit(a.mV[lane]);
        bits |= int(std::signbit(b.mV[lane]) != sign || std::signbit(c.mV[lane]) != sign) << lane;
    }
    return {bits};
}
#endif
// The index of the lowest set bit of a non-zero mask (one instruction where the compiler
// has it: a loop here is a branch the predictor misses at every node).
inline int FirstLane(int aMask) {
#if defined(__GNUC__)
    return __builtin_ctz(unsigned(aMask));
#else
    int lane = 0;
    while (!(aMask & (1 << lane))) lane++;
    return lane;
#endif
}
// The number of set bits of a mask.
inline int LaneCount(int aMask) {
#if defined(__GNUC__)
    return __builtin_popcount(unsigned(aMask));
#else
    int count = 0;
    for (; aMask; aMask &= aMask - 1) count++;
    return count;
#endif
}
// The index of the highest set bit of a non-zero mask.
inline int LastLane(int aMask) {
#if defined(__GNUC__)
    return 31 - __builtin_clz(unsigned(aMask));
#else
    int lane = 31;
    while (!(aMask & (1 << lane))) lane--;
    return lane;
#endif
}
// The tree's two arrays live on 2 MiB pages where Linux offers them (transparent huge
// pages on request, madvise): a ray's node and block loads jump across the whole tree,
// and with 4 KiB pages those of a large tree miss the TLB as well as the cache (Embree
// asks for such pages too). Arrays under 2 MiB, and other systems, get ordinary memory.
// The range search's grid ([SECTION] Appendix: range search) uses them for its arrays.
inline constexpr size_t kHugePageBytes = size_t(2) << 20;
template <typename T>
struct HugePageAllocator {
    using value_type = T;
    HugePageAllocator() = default;
    template <typename U>
    HugePageAllocator(const HugePageAllocator<U>&) {}
    static bool IsHuge(size_t aCount) { return aCount * sizeof(T) >= kHugePageBytes; }
    T* allocate(size_t aCount) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
        if (IsHuge(aCount)) {
            const size_t bytes = (aCount * sizeof(T) + kHugePageBytes - 1) / kHugePageBytes * kHugePageBytes;
            void* memory = std::aligned_alloc(kHugePageBytes, bytes);
            if (!memory) throw std::bad_alloc();
            madvise(memory, bytes, MADV_HUGEPAGE);  // only advice: without it, ordinary pages
            return static_cast<T*>(memory);
        }
#endif
        return static_cast<T*>(::operator new(aCount * sizeof(T), std::align_val_t(alignof(T))));
    }
    void deallocate(T* aMemory, size_t aCount) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
        if (IsHuge(aCount)) return std::free(aMemory);
#endif
        ::operator delete(aMemory, std::align_val_t(alignof(T)));
    }
    template <typename U>
    bool operator==(const HugePageAllocator<U>&) const { return true; }
    template <typename U>
    bool operator!=(const HugePageAllocator<U>&) const { return false; }
};
} // namespace detail

// Build: top-down, splitting each node at the best of 16 binned surface-area-heuristic
// candidates along each of the three axes (Wald 2007), and stopping where the SAH
// says a leaf is cheaper (leaves of at most 8 primitives). The binary tree is then
// collapsed into a kWidth-wide one (4, or 8 with AVX2; Dammertz et al. 2008): a node
// keeps up to kWidth children, found by opening the largest child until there are kWidth.
// Why each trick pays:
// * kWidth children per node, their boxes stored axis by axis ("structure of arrays"):
//   one visit tests all their boxes with one vector instruction per step, instead of
//   walking two (or three) levels of a binary tree box by box.
// * A leaf needs no node of its own: its parent's slot says where its primitives are.
// * Leaf triangles are copied into blocks of kWidth, stored coordinate by coordinate, so
//   the watertight test runs on a whole block at once, and a leaf is a few consecutive
//   cache lines instead of indices into the scene.
// * The SAH counts blocks, not primitives: a block costs what one triangle does, so leaves
//   fill their blocks instead of padding them.
// * Ordered traversal: the nearest child is entered next and the others are pushed
//   farthest first, so the nearest hit is found early, and a popped child whose box
//   starts beyond it is dropped without another test. Shadow rays walk in the same
//   order and stop at the first hit: the nearest boxes are the likeliest to occlude.
// * A scene of a few blocks (kFlatBlocks) is a single leaf: no node to visit, and a ray
//   needs no slab-test set-up.
// Primitives that share one centroid cannot be split and stay one leaf (splitting them by
// count would leave boxes that all overlap, which every ray enters anyway); identical
// copies in such a leaf (a mesh duplicated over itself) are kept once.

class Bvh::Tree {
public:
    static constexpr int kWidth = detail::kBvhLanes;
    // An inner node (128 bytes, two cache lines; 256 bytes 8 wide): the boxes of its
    // children as six planes of kWidth floats (Min(k) and Max(k): the children's minima and
    // maxima along axis k, one flat array so that a ray can address its near and far
    // planes by offset), then for each child either an inner node (mCount == 0, mIndex =
    // node index) or a leaf (mCount blocks from mIndex). An unused slot has an inverted box
    // (min > max), which the slab test never hits.
    struct alignas(64) Node {
        float mPlanes[6 * kWidth];  // min x, min y, min z, max x, max y, max z
        float* Min(int aAxis) { return mPlanes + aAxis * kWidth; }
        float* Max(int aAxis) { return mPlanes + (3 + aAxis) * kWidth; }
        const float* Min(int aAxis) const { return mPlanes + aAxis * kWidth; }
        const float* Max(int aAxis) const { return mPlanes + (3 + aAxis) * kWidth; }
        uint32_t mIndex[kWidth];
        uint32_t mCount[kWidth];
    };
    // kWidth primitives of a leaf (160 bytes 4 wide, 320 bytes 8 wide), coordinate by
    // coordinate: triangles with vertices mA, mB, mC ([axis][lane]), or spheres with centre mA and
    // radius mB[0]. mId is the scene's primitive index, with kSphereBit set in every lane
    // of a sphere block and kCutOutBit in the lane of a triangle with cut-outs. A leaf's
    // last block is filled up by repeating its last primitive: a copy hits at the same t
    // as its original, so it never changes an answer.
    struct alignas(4 * kWidth) Block {
        uint32_t mId[kWidth];  // first: it shares the first cache line with mA
        float mA[3][kWidth];
        float mB[3][kWidth];
        float mC[3][kWidth];
        bool IsSpheres() const { return (mId[0] & kSphereBit) != 0; }
        // Whether aLane is a filling copy of the lane before it: spheres are tested one
        // at a time, so a copy would cost a whole second test.
        bool IsCopy(int aLane) const { return aLane > 0 && mId[aLane] == mId[aLane - 1]; }
        Vec3 Vertex(const float aCoordinates[3][kWidth], int aLane) const {
            return Vec3(aCoordinates[0][aLane], aCoordinates[1][aLane], aCoordinates[2][aLane]);
        }
    };

    void Build(const PrimitiveSoup& aSoup) {
        mNodes.clear();
        mBlocks.clear();
        mRoot = ChildRef{};
        mLeafCount = 0;
        mBuildDepth = 0;
        mLargestLeaf = 0;
        mBuildSoup = &aSoup;
        const int count = aSoup.Count();
        mPrimitiveCount = count;
        mHasCutOuts = std::find(aSoup.mTriangleCutOut.begin(), aSoup.mTriangleCutOut.end(), 1) != aSoup.mTriangleCutOut.end();
        std::vector<uint32_t> order(count);
        std::vector<Aabb> bounds(count);
        std::vector<Vec3> centroids(count);
        for (int i = 0; i < count; i++) {
            order[i] = uint32_t(i);
            bounds[i] = aSoup.Bounds(i);
            centroids[i] = bounds[i].Centroid();
        }
        if (count > 0) {
            std::vector<BinaryNode> binary;
            binary.reserve(size_t(count));
            const ChildRef binaryRoot = BuildBinary(bounds, centroids, order, 0, uint32_t(count), 0, binary);
            mNodes.reserve(binary.size() / 2 + 1);
            mBlocks.reserve(size_t(count) / 2 + 1);
            mRoot = Collapse(binary, order, binaryRoot);
        }
        mBuildSoup = nullptr;
    }

    // Nearest hit in (aTMin, ioTMax); returns the primitive index or -1. The root's box
    // is not tested on its own: a ray that misses it misses the boxes of the root's
    // children too, which the first visit finds, so a separate test would only cost time.
    // kCutOuts: a tree with cut-out triangles, whose hits aIsSolid confirms (one test on
    // a candidate hit, so a tree without them runs the code it ran before they existed).
    template <bool kCutOuts, typename IsSolid>
    int Intersect(const Ray& aRay, float aTMin, float& ioTMax, const IsSolid& aIsSolid) const {
        if (mBlocks.empty()) return -1;
        int hitPrimitive = -1;
        if (mRoot.mCount > 0) {  // the whole scene is one leaf
            // Every block is tested below the ray's own bound, and then the nearest hit is
            // taken block after block (KeepNearest: the same answer), so that no block's
            // test waits for the previous one's result. (kFlatBlocks at a time: a leaf of
            // primitives that share one centroid may have more.)
            const BlockRay ray(aRay);
            for (uint32_t first = 0; first < mRoot.mCount; first += kFlatBlocks) {
                const Block* const blocks = &mBlocks[mRoot.mIndex + first];
                const uint32_t count = std::min(kFlatBlocks, mRoot.mCount - first);
                const float tMax = ioTMax;
                FloatN t[kFlatBlocks];
                int hits[kFlatBlocks];
                for (uint32_t b = 0; b < count; b++) hits[b] = BlockHits(blocks[b], aRay, ray, aTMin, tMax, t[b]);
                for (uint32_t b = 0; b < count; b++)
                    KeepNearest<kCutOuts>(blocks[b], hits[b], t[b], ioTMax, hitPrimitive, aIsSolid);
            }
            return hitPrimitive;
        }
        const RayData ray(aRay);
        Pending stack[kStackSize];
        int stackSize = 0;
        uint32_t index = mRoot.mIndex, count = mRoot.mCount;
        for (;;) {
            if (count > 0) {  // a leaf: test its blocks
                for (uint32_t b = 0; b < count; b++)
                    IntersectBlock<kCutOuts>(mBlocks[index + b], aRay, ray, aTMin, ioTMax, hitPrimitive, aIsSolid);
            } else if (Descend(mNodes[index], ray, ioTMax, true, stack, stackSize, index, count)) {
                continue;
            }
            // Pop the next child whose box starts before the nearest hit so far.
            do {
                if (stackSize == 0) return hitPrimitive;
                --stackSize;
            } while (stack[stackSize].mTNear > ioTMax * kFarWidening);
            index = stack[stackSize].mIndex;
            count = stack[stackSize].mCount;
        }
    }

    // Any hit in (aTMin, aTMax) (that aIsSolid accepts, kCutOuts): the shadow-ray query.
    template <bool kCutOuts, typename IsSolid>
    bool Occluded(const Ray& aRay, float aTMin, float aTMax, const IsSolid& aIsSolid) const {
        if (mBlocks.empty()) return false;
        if (mRoot.mCount > 0) {
            // Last block first: a leaf's spheres come last, and in a small scene (a room
            // with a few objects in it) the objects are what shadow rays hit.
            const BlockRay ray(aRay);
            for (uint32_t b = mRoot.mCount; b-- > 0;)
                if (OccludedByBlock<kCutOuts>(mBlocks[mRoot.mIndex + b], aRay, ray, aTMin, aTMax, aIsSolid)) return true;
            return false;
        }
        const RayData ray(aRay);
        Pending stack[kStackSize];
        int stackSize = 0;
        uint32_t index = mRoot.mIndex, count = mRoot.mCount;
        for (;;) {
            if (count > 0) {
                for (uint32_t b = 0; b < count; b++)
                    if (OccludedByBlock<kCutOuts>(mBlocks[index + b], aRay, ray, aTMin, aTMax, aIsSolid)) return true;
            } else if (Descend(mNodes[index], ray, aTMax, false, stack, stackSize, index, count)) {
                continue;
            }
            if (stackSize == 0) return false;
            --stackSize;
            index = stack[stackSize].mIndex;
            count = stack[stackSize].mCount;
        }
    }

    // Nodes of the tree, leaves included (a leaf lives in its parent's slot).
    size_t NodeCount() const { return mNodes.size() + mLeafCount; }
    size_t StorageBytes() const { return mNodes.size() * sizeof(Node) + mBlocks.size() * sizeof(Block); }
    int PrimitiveCount() const { return mPrimitiveCount; }
    bool HasCutOuts() const { return mHasCutOuts; }
    // Levels of the kWidth-wide tree a ray walks, and of the binary tree it was collapsed from.
    int Depth() const { return mBlocks.empty() ? 0 : DepthOf(mRoot.mIndex, mRoot.mCount); }
    int BuildDepth() const { return mBuildDepth; }
    // Primitives in the largest leaf (at most kMaxLeafSize unless distinct primitives
    // share one centroid).
    uint32_t LargestLeaf() const { return mLargestLeaf; }

private:
    using FloatN = detail::FloatN;
    using MaskN = detail::MaskN;

    // A subtree as its parent sees it: its box, and an inner node or a leaf as in Node
    // (while building, a leaf's mIndex and mCount are a range of the primitive order).
    struct ChildRef {
        Aabb mBox;
        uint32_t mIndex = 0, mCount = 0;
    };
    struct BinaryNode { ChildRef mChild[2]; };
    struct Pending { uint32_t mIndex, mCount; float mTNear; };

    static constexpr uint32_t kSphereBit = 0x80000000u;
    static constexpr uint32_t kCutOutBit = 0x40000000u;
    static constexpr uint32_t kIdMask = ~(kSphereBit | kCutOutBit);
    static constexpr uint32_t kMaxLeafSize = 8;
    static constexpr uint32_t BlocksFor(uint32_t aPrimitives) { return (aPrimitives + kWidth - 1) / kWidth; }
    static constexpr int kBinCount = 16;
    // A scene of at most kFlatBlocks blocks (32 triangles 8 wide, 16 4 wide) is one leaf,
    // every block tested by every ray: SmallVCM's Cornell boxes (3-4 blocks) are faster so
    // than through a root node whose children nearly every ray enters anyway.
    static constexpr uint32_t kFlatBlocks = 4;
    // SAH costs in units of one block test: kWidth primitives cost what one does, so a
    // leaf costs its number of blocks, and the build fills blocks instead of padding them.
    // kTraversalCost is a binary node's two boxes, relative to a block test (the trees'
    // speed is flat around this value; docs/performance.md, the Embree comparison).
    static constexpr float kTraversalCost = 1.5f;
    // The binary build stops at this depth (splitting by the median when the SAH split
    // fails keeps real scenes far below it). The kWidth-wide tree is no deeper, and a visit
    // leaves at most kWidth - 1 children on the stack (sorting them there takes one more
    // entry for a moment), so (kWidth - 1) * 64 + 1 entries hold every path.
    static constexpr int kMaxDepth = 60;
    static constexpr int kStackSize = (kWidth - 1) * 64 + 1;
    // A hit exactly on a face must survive rounding in the slab test: the far distance
    // is widened by 2 ulp.
    static constexpr float kFarWidening = 1.00000024f;

    // The near and far plane offsets of the 8 sign patterns of a direction (bit k set: the
    // ray runs backwards along axis k), copied per ray from this table rather than
    // computed axis by axis.
    struct PlaneOffsets { int mNear[3], mFar[3]; };
    static constexpr PlaneOffsets PlaneOffsetsFor(int aSigns) {
        PlaneOffsets offsets{};
        for (int k = 0; k < 3; k++) {
            const int backwards = (aSigns >> k) & 1;
            offsets.mNear[k] = (k + 3 * backwards) * kWidth;
            offsets.mFar[k] = (3 + k - 3 * backwards) * kWidth;
        }
        return offsets;
    }
    // What the tests need of a ray, computed once per ray. BlockRay, for the triangle test
    // of a leaf block: the shear of WatertightRay and the origin, in the sheared axis
    // order. RayData adds, for the slab test of a node, its origin, 1 / direction
    // (infinite for a zero component) and, per axis, where in a node's mPlanes its near
    // and far planes are (the max plane is the near one when the ray runs backwards along
    // the axis; an offset instead of a branch per axis and node, which the predictor
    // missed on random directions: +0.02-0.04 on the large meshes, 8 wide). A scene that
    // is one leaf needs only BlockRay, three divisions fewer.
    struct BlockRay {
        WatertightRay mShear;
        FloatN mShearX, mShearY, mShearZ;     // the shear's mSx, mSy, mSz
        FloatN mOriginX, mOriginY, mOriginZ;  // the origin along kx, ky, kz
#if defined(SMALLVCM_BVH_SSE) || defined(SMALLVCM_BVH_AVX)
        // WatertightRay's values, computed another way with the same result bit for bit
        // (for a one-leaf scene, whose first triangle test waits for the shear, and for a
        // tree's rays, RayData below).
        // There, the divisions wait for kz, which waits for a chain of compares, integer
        // steps and loads by index (some 45 cycles before the first triangle can be
        // tested). Here the three candidates, one per axis that kz may be, are divided
        // at once, four lanes per instruction, while kz is found from the compares'
        // bits in integer registers; kz then picks a lane (the same IEEE division as
        // d[kx] / d[kz], so the same value).
        SMALLVCM_BVH_INLINE explicit BlockRay(const Ray& aRay) {
            typedef float Float4 __attribute__((vector_size(16)));
            typedef int32_t Int4 __attribute__((vector_size(16)));
            const Vec3& d = aRay.mDirection;
            const Vec3& o = aRay.mOrigin;
            // Lane i: axis i as kz; "next" is axis (i + 1) % 3, "after" (i + 2) % 3.
            // (__builtin_shufflevector: GCC 12 and clang alike.)
            const auto next = [](Float4 aV) { return __builtin_shufflevector(aV, aV, 1, 2, 0, 3); };
            const auto after = [](Float4 aV) { return __builtin_shufflevector(aV, aV, 2, 0, 1, 3); };
            const Float4 dir = {d.x, d.y, d.z, 1.f};
            const Float4 nextOver = next(dir) / dir, afterOver = after(dir) / dir;
            const Float4 inverse = Float4{1.f, 1.f, 1.f, 1.f} / dir;
            const Float4 absDir = reinterpret_cast<Float4>(reinterpret_cast<Int4>(dir) & Int4{INT32_MAX, INT32_MAX, INT32_MAX, INT32_MAX});
            const int overNext = __builtin_ia32_movmskps(reinterpret_cast<Float4>(absDir > next(absDir)));
            const int overAfter = __builtin_ia32_movmskps(reinterpret_cast<Float4>(absDir > after(absDir)));
            const int xOverY = overNext & 1, yOverZ = (overNext >> 1) & 1, xOverZ = overAfter & 1;
            const int kz = 2 - 2 * (xOverY & xOverZ) - ((1 - xOverY) & yOverZ);
            // Lanes whose axis the ray runs backwards along: were it kz, kx and ky would
            // swap, as in WatertightRay.
            const Int4 backwards = dir < Float4{};
            const int back = (__builtin_ia32_movmskps(reinterpret_cast<Float4>(backwards)) >> kz) & 1;
            const Float4 shearX = backwards ? afterOver : nextOver, shearY = backwards ? nextOver : afterOver;
            const Float4 originZ = {o.x, o.y, o.z, 0.f};
            const Float4 originNext = next(originZ), originAfter = after(originZ);
            const Float4 originX = backwards ? originAfter : originNext, originY = backwards ? originNext : originAfter;
            // (kz + 1 + back) % 3 and (kz + 2 - back) % 3: two bits each of 0x124, which
            // holds 0, 1, 2, 0, 1.
            mShear.mKz = kz;
            mShear.mKx = (0x124 >> (2 * (kz + 1 + back))) & 3;
            mShear.mKy = (0x124 >> (2 * (kz + 2 - back))) & 3;
            mShear.mSx = shearX[kz];
            mShear.mSy = shearY[kz];
            mShear.mSz = inverse[kz];
            mShearX = FloatN::Broadcast(mShear.mSx);
            mShearY = FloatN::Broadcast(mShear.mSy);
            mShearZ = FloatN::Broadcast(mShear.mSz);
            mOriginX = FloatN::Broadcast(originX[kz]);
            mOriginY = FloatN::Broadcast(originY[kz]);
            mOriginZ = FloatN::Broadcast(originZ[kz]);
        }
#else
        explicit BlockRay(const Ray& aRay) : BlockRay(aRay, WatertightRay(aRay.mDirection)) {}
#endif
        // From WatertightRay's own constructor: the portable build's way.
        BlockRay(const Ray& aRay, const WatertightRay& aShear) : mShear(aShear) {
            const float o[3] = {aRay.mOrigin.x, aRay.mOrigin.y, aRay.mOrigin.z};
            mShearX = FloatN::Broadcast(mShear.mSx);
            mShearY = FloatN::Broadcast(mShear.mSy);
            mShearZ = FloatN::Broadcast(mShear.mSz);
            mOriginX = FloatN::Broadcast(o[mShear.mKx]);
            mOriginY = FloatN::Broadcast(o[mShear.mKy]);
            mOriginZ = FloatN::Broadcast(o[mShear.mKz]);
        }
    };
    struct RayData : BlockRay {
        FloatN mOrigin[3], mInvDir[3];
        PlaneOffsets mPlanes;  // into Node::mPlanes
        static const PlaneOffsets& PlaneOffsetsOf(int aSigns) {
            static constexpr PlaneOffsets kTable[8] = {PlaneOffsetsFor(0), PlaneOffsetsFor(1), PlaneOffsetsFor(2),
                                                       PlaneOffsetsFor(3), PlaneOffsetsFor(4), PlaneOffsetsFor(5),
                                                       PlaneOffsetsFor(6), PlaneOffsetsFor(7)};
            return kTable[aSigns];
        }
#if defined(SMALLVCM_BVH_SSE) || defined(SMALLVCM_BVH_AVX)
        // The shear the vector way (above) and the three 1 / d as one 4-lane division
        // (the same IEEE quotients, hence the same values and the same hits): four
        // vector divisions side by side instead of six scalar ones, three of them queued
        // behind the compares that find kz: more instructions, less time.
        explicit RayData(const Ray& aRay) : BlockRay(aRay) {
            typedef float Float4 __attribute__((vector_size(16)));
            const Vec3& d = aRay.mDirection;
            const Float4 inverse = Float4{1.f, 1.f, 1.f, 1.f} / Float4{d.x, d.y, d.z, 1.f};
            for (int k = 0; k < 3; k++) {
                mOrigin[k] = FloatN::Broadcast(aRay.mOrigin[k]);
                mInvDir[k] = FloatN::Broadcast(inverse[k]);
            }
            mPlanes = PlaneOffsetsOf(__builtin_ia32_movmskps(inverse) & 7);
        }
#else
        explicit RayData(const Ray& aRay) : BlockRay(aRay, WatertightRay(aRay.mDirection)) {
            int signs = 0;
            for (int k = 0; k < 3; k++) {
                mOrigin[k] = FloatN::Broadcast(aRay.mOrigin[k]);
                const float invDir = 1.f / aRay.mDirection[k];
                mInvDir[k] = FloatN::Broadcast(invDir);
                signs |= int(std::signbit(invDir)) << k;
            }
            mPlanes = PlaneOffsetsOf(signs);
        }
#endif
    };

    // Slab test of a node's kWidth child boxes against [0, aTMax]: where the ray enters
    // each box (oTNear) and the mask of the boxes it hits (entry before the widened exit).
    // The near and far planes are chosen by the ray's direction, so an inverted (empty)
    // box always misses. A ray with a zero direction component that lies in the plane
    // of a face gets (plane - origin) * inf = 0 * inf = NaN there; Max(a, NaN) and
    // Min(a, NaN) return a, so that axis does not narrow the interval: the ray is inside.
    SMALLVCM_BVH_INLINE static void SlabAxis(const Node& aNode, const RayData& aRay, int k, FloatN& ioTNear, FloatN& ioTFar) {
        const float* nearPlane = aNode.mPlanes + aRay.mPlanes.mNear[k];
        const float* farPlane = aNode.mPlanes + aRay.mPlanes.mFar[k];
        ioTNear = Max(ioTNear, (FloatN::Load(nearPlane) - aRay.mOrigin[k]) * aRay.mInvDir[k]);
        ioTFar = Min(ioTFar, (FloatN::Load(farPlane) - aRay.mOrigin[k]) * aRay.mInvDir[k]);
    }
    SMALLVCM_BVH_INLINE static int SlabTestChildren(const Node& aNode, const RayData& aRay, float aTMax, FloatN& oTNear) {
        FloatN tNear = FloatN::Broadcast(0.f), tFar = FloatN::Broadcast(aTMax);
        // The three axes written out, not looped over.
        SlabAxis(aNode, aRay, 0, tNear, tFar);
        SlabAxis(aNode, aRay, 1, tNear, tFar);
        SlabAxis(aNode, aRay, 2, tNear, tFar);
        oTNear = tNear;
        return Bits(LessEqual(tNear, tFar * FloatN::Broadcast(kFarWidening)));
    }

    // Visits an inner node: continues (true) into its nearest hit child, given back in
    // ioIndex / ioCount, after pushing the other hit children (farthest first when
    // aSortAll); false when the ray misses them all.
    SMALLVCM_BVH_INLINE static bool Descend(const Node& aNode, const RayData& aRay, float aTMax, bool aSortAll, Pending* ioStack,
                        int& ioStackSize, uint32_t& ioIndex, uint32_t& ioCount) {
        // The children's references are the node's last cache line (8 wide), which the
        // slab test does not read: loaded only once it has chosen a child, they were a
        // second wait for memory per visit; requested now, they arrive with the planes.
#if defined(__GNUC__)
        __builtin_prefetch(aNode.mIndex);  // the builtin itself, which the compiler keeps here
#endif
        FloatN tNear;
        int hits = SlabTestChildren(aNode, aRay, aTMax, tNear);
        if (hits == 0) return false;
        // The hit children, nearest entered, the others pushed farthest first (of equal
        // tNear, the later lane is entered first). One or two hit children, the usual
        // case, take no branch on which of the two it is: with one, first and second are
        // the same lane, which is entered, and the entry written for the farther one is
        // not counted on the stack (a branch between one and two hit children would be
        // mispredicted often). Three or more go to a sorting loop.
        const int first = detail::FirstLane(hits);
        const int rest = hits & (hits - 1);
        if ((rest & (rest - 1)) == 0) {
            const int second = detail::LastLane(hits);
            const bool firstNearer = tNear[first] < tNear[second];
            const int nearer = firstNearer ? first : second, farther = firstNearer ? second : first;
            ioStack[ioStackSize] = Pending{aNode.mIndex[farther], aNode.mCount[farther], tNear[farther]};
            ioStackSize += rest != 0;
            ioIndex = aNode.mIndex[nearer];
            ioCount = aNode.mCount[nearer];
            return true;
        }
        const int second = detail::FirstLane(rest);
        hits = rest & (rest - 1);
        Pending* children = ioStack + ioStackSize;
        int childCount = 0;
        if (!aSortAll) {
            // Three or more for a shadow ray: only the nearest matters (entered first, it
            // is the likeliest to occlude); the others go on the stack in lane order. Saves
            // the sort's mispredicted branches: any-hit on the soup of triangles 0.68 ->
            // 0.78 of Embree, 8 wide.
            children[0] = Pending{aNode.mIndex[first], aNode.mCount[first], tNear[first]};
            children[1] = Pending{aNode.mIndex[second], aNode.mCount[second], tNear[second]};
            int nearest = tNear[second] < tNear[first] ? 1 : 0;
            childCount = 2;
            while (hits) {
                const int c = detail::FirstLane(hits);
                hits &= hits - 1;
                children[childCount] = Pending{aNode.mIndex[c], aNode.mCount[c], tNear[c]};
                nearest = tNear[c] < children[nearest].mTNear ? childCount : nearest;
                childCount++;
            }
            ioIndex = children[nearest].mIndex;
            ioCount = children[nearest].mCount;
            children[nearest] = children[childCount - 1];
            ioStackSize += childCount - 1;
            return true;
        }
        // Three or more: each goes straight to its place on the stack, by decreasing tNear
        // (of equal tNear, the earlier lane lower: the later is entered first), which is
        // the number of hit children farther than it, or as far in an earlier lane, counted
        // with one vector compare; the nearest, then on top, is taken off again. (An
        // insertion sort had a data-dependent exit per child, which the predictor missed.)
        const int all = (1 << first) | rest;
        childCount = detail::LaneCount(all);
        for (int left = all; left; left &= left - 1) {
            const int c = detail::FirstLane(left);
            const FloatN tc = FloatN::Broadcast(tNear[c]);
            const int before = Bits(Greater(tNear, tc)) | (Bits(Equal(tNear, tc)) & ((1 << c) - 1));
            children[detail::LaneCount(before & all)] = Pending{aNode.mIndex[c], aNode.mCount[c], tNear[c]};
        }
        ioStackSize += childCount - 1;
        ioIndex = children[childCount - 1].mIndex;
        ioCount = children[childCount - 1].mCount;
        return true;
    }

    // IntersectTriangle on the kWidth triangles of a block at once, operation for operation
    // (same order, same rounding), so each lane's answer is bit for bit the scalar one.
    // Returns the mask of lanes hit in (aTMin, aTMax) with their distances in oT; lanes
    // where an edge function is exactly 0 are left to the scalar test (oFallback).
    SMALLVCM_BVH_INLINE static int IntersectTriangles(const Block& aBlock, const BlockRay& aRay, float aTMin, float aTMax,
                                                      FloatN& oT, int& oFallback) {
        const int kx = aRay.mShear.mKx, ky = aRay.mShear.mKy, kz = aRay.mShear.mKz;
        const FloatN az = FloatN::Load(aBlock.mA[kz]) - aRay.mOriginZ;
        const FloatN bz = FloatN::Load(aBlock.mB[kz]) - aRay.mOriginZ;
        const FloatN cz = FloatN::Load(aBlock.mC[kz]) - aRay.mOriginZ;
        const FloatN ax = (FloatN::Load(aBlock.mA[kx]) - aRay.mOriginX) - aRay.mShearX * az;
        const FloatN ay = (FloatN::Load(aBlock.mA[ky]) - aRay.mOriginY) - aRay.mShearY * az;
        const FloatN bx = (FloatN::Load(aBlock.mB[kx]) - aRay.mOriginX) - aRay.mShearX * bz;
        const FloatN by = (FloatN::Load(aBlock.mB[ky]) - aRay.mOriginY) - aRay.mShearY * bz;
        const FloatN cx = (FloatN::Load(aBlock.mC[kx]) - aRay.mOriginX) - aRay.mShearX * cz;
        const FloatN cy = (FloatN::Load(aBlock.mC[ky]) - aRay.mOriginY) - aRay.mShearY * cz;
        const FloatN u = cx * by - cy * bx, v = ax * cy - ay * cx, w = bx * ay - by * ax;
        const FloatN zero = FloatN::Broadcast(0.f);
        const MaskN onEdge = Equal(u, zero) | Equal(v, zero) | Equal(w, zero);
        // The scalar test's "some edge function negative and some positive" is, where none
        // is 0 (onEdge lanes go to the scalar test), "their sign bits differ": four
        // instructions instead of ten. A NaN among them makes det NaN, which detUsable rejects.
        const MaskN signsDiffer = SignsDiffer(u, v, w);
        const FloatN det = u + v + w;
        // det is finite and not 0 exactly where det - det == 0 and det != 0.
        const MaskN detUsable = Equal(det - det, zero) & ~Equal(det, zero);
        oT = aRay.mShearZ * (u * az + v * bz + w * cz) / det;
        const MaskN inRange = Greater(oT, FloatN::Broadcast(aTMin)) & Less(oT, FloatN::Broadcast(aTMax));
        oFallback = Bits(onEdge);
        return Bits(~signsDiffer & detUsable & inRange & ~onEdge);
    }

    // The triangles the block test left to the scalar one, in lane order.
    static void ScalarLanes(const Block& aBlock, int aLanes, const Ray& aRay, const BlockRay& aData, float aTMin,
                            float aTMax, FloatN& ioT, int& ioHits) {
        for (int lane = 0; lane < kWidth; lane++) {
            if (!(aLanes & (1 << lane))) continue;
            const std::optional<float> t = IntersectTriangle(aBlock.Vertex(aBlock.mA, lane), aBlock.Vertex(aBlock.mB, lane),
                                                             aBlock.Vertex(aBlock.mC, lane), aRay, aData.mShear, aTMin, aTMax);
            if (t) {
                ioT.SetLane(lane, *t);
                ioHits |= 1 << lane;
            }
        }
    }

    // The hits of a block's primitives in (aTMin, aTMax): the mask of lanes hit, their
    // distances in oT. Spheres one at a time, inlined.
    SMALLVCM_BVH_INLINE static int BlockHits(const Block& aBlock, const Ray& aRay, const BlockRay& aData, float aTMin,
                                             float aTMax, FloatN& oT) {
        int hits = 0;
        if (aBlock.IsSpheres()) {
            for (int lane = 0; lane < kWidth && !aBlock.IsCopy(lane); lane++) {
                const std::optional<float> t = IntersectSphere(aBlock.Vertex(aBlock.mA, lane), aBlock.mB[0][lane], aRay, aTMin, aTMax);
                if (t) {
                    oT.SetLane(lane, *t);
                    hits |= 1 << lane;
                }
            }
            return hits;
        }
        int fallback;
        hits = IntersectTriangles(aBlock, aData, aTMin, aTMax, oT, fallback);
        if (fallback) ScalarLanes(aBlock, fallback, aRay, aData, aTMin, aTMax, oT, hits);
        return hits;
    }

    // The nearest of a block's hits below ioTMax updates ioTMax and ioPrimitive; of lanes
    // hit at the same t the first wins, as if they were tested one after the other. Hits
    // found below a larger bound give the same answer: those beyond ioTMax are dropped
    // here, and those below it are found below either bound (a sphere reports its nearer
    // root in range; where that is beyond ioTMax, so is the farther). The hit lanes only,
    // in lane order (a loop over all lanes would be kWidth branches the predictor misses).
    // A cut-out triangle's hit counts only where aIsSolid says its surface is: asked only
    // of a hit nearer than the nearest so far, the one that would change the answer.
    template <bool kCutOuts, typename IsSolid>
    SMALLVCM_BVH_INLINE static void KeepNearest(const Block& aBlock, int aHits, const FloatN& aT, float& ioTMax,
                                                int& ioPrimitive, const IsSolid& aIsSolid) {
        while (aHits) {
            const int lane = detail::FirstLane(aHits);
            aHits &= aHits - 1;
            if (aT[lane] < ioTMax) {
                const uint32_t id = aBlock.mId[lane];
                if (kCutOuts && (id & kCutOutBit) && !aIsSolid(int(id & kIdMask), aT[lane])) continue;
                ioTMax = aT[lane];
                ioPrimitive = int(id & kIdMask);
            }
        }
    }

    // The nearest hit of a block below ioTMax.
    template <bool kCutOuts, typename IsSolid>
    SMALLVCM_BVH_INLINE static void IntersectBlock(const Block& aBlock, const Ray& aRay, const BlockRay& aData, float aTMin,
                                                   float& ioTMax, int& ioPrimitive, const IsSolid& aIsSolid) {
        FloatN t;
        KeepNearest<kCutOuts>(aBlock, BlockHits(aBlock, aRay, aData, aTMin, ioTMax, t), t, ioTMax, ioPrimitive, aIsSolid);
    }

    // Whether the block has a hit in (aTMin, aTMax); with kCutOuts, a hit on a cut-out
    // triangle counts where aIsSolid says its surface is.
    template <bool kCutOuts, typename IsSolid>
    SMALLVCM_BVH_INLINE static bool OccludedByBlock(const Block& aBlock, const Ray& aRay, const BlockRay& aData, float aTMin,
                                                    float aTMax, const IsSolid& aIsSolid) {
        if (aBlock.IsSpheres()) {
            for (int lane = 0; lane < kWidth && !aBlock.IsCopy(lane); lane++)
                if (IntersectSphere(aBlock.Vertex(aBlock.mA, lane), aBlock.mB[0][lane], aRay, aTMin, aTMax)) return true;
            return false;
        }
        FloatN t;
        int fallback;
        int hits = IntersectTriangles(aBlock, aData, aTMin, aTMax, t, fallback);
        if (!kCutOuts && hits) return true;
        if (fallback) ScalarLanes(aBlock, fallback, aRay, aData, aTMin, aTMax, t, hits);
        if (!kCutOuts) return hits != 0;
        while (hits) {  // a plain triangle's hit occludes; a cut-out's where its surface is
            const int lane = detail::FirstLane(hits);
            hits &= hits - 1;
            const uint32_t id = aBlock.mId[lane];
            if (!(id & kCutOutBit) || aIsSolid(int(id & kIdMask), t[lane])) return true;
        }
        return false;
    }

    int DepthOf(uint32_t aIndex, uint32_t aCount) const {
        if (aCount > 0) return 1;
        const Node& n = mNodes[aIndex];
        int deepest = 0;
        for (int c = 0; c < kWidth; c++)
            if (n.Min(0)[c] <= n.Max(0)[c]) deepest = std::max(deepest, DepthOf(n.mIndex[c], n.mCount[c]));
        return 1 + deepest;
    }

    // Builds the binary subtree over ioOrder[aBegin, aEnd) into ioNodes and returns it
    // as its parent sees it.
    ChildRef BuildBinary(const std::vector<Aabb>& aBounds, const std::vector<Vec3>& aCentroids,
                         std::vector<uint32_t>& ioOrder, uint32_t aBegin, uint32_t aEnd, int aDepth,
                         std::vector<BinaryNode>& ioNodes) {
        mBuildDepth = std::max(mBuildDepth, aDepth + 1);
        ChildRef result;
        Aabb centroidBox;
        for (uint32_t i = aBegin; i < aEnd; i++) {
            result.mBox.Extend(aBounds[ioOrder[i]]);
            centroidBox.Extend(aCentroids[ioOrder[i]]);
        }
        const uint32_t count = aEnd - aBegin;
        auto makeLeaf = [&] {
            result.mIndex = aBegin;
            result.mCount = count > kMaxLeafSize ? KeepDistinct(ioOrder, aBegin, aEnd) : count;
            mLargestLeaf = std::max(mLargestLeaf, result.mCount);
            return result;
        };

        const Vec3 extent = centroidBox.mMax - centroidBox.mMin;
        const int axis = (extent.x >= extent.y && extent.x >= extent.z) ? 0 : (extent.y >= extent.z ? 1 : 2);
        const uint32_t triangles = uint32_t(mBuildSoup->TriangleCount());
        if (aDepth == 0 && BlocksFor(triangles) + BlocksFor(count - triangles) <= kFlatBlocks) return makeLeaf();  // a small scene
        // An extent so small (a denormal: centroids 1e-43 apart) that kBinCount / extent
        // overflows would bin by NaN (0 * inf): such primitives are one leaf, as equal ones are.
        if (count == 1 || !(extent[axis] > 0.f) || !std::isfinite(kBinCount / extent[axis]) || aDepth >= kMaxDepth)
            return makeLeaf();

        // Binned SAH: cost of a split = A_left B_left + A_right B_right, B the blocks
        // of each side (relative to the parent's area A: split cost = kTraversalCost +
        // that / A, leaf cost = B). Candidates on all three axes, binned in one pass: the
        // longest axis alone misses the better split of thin parts (columns, arches).
        struct Bin { Aabb box; uint32_t count = 0; };
        Bin bins[3][kBinCount];
        float binScale[3];
        for (int a = 0; a < 3; a++) {
            binScale[a] = kBinCount / extent[a];
            // A flat axis bins everything into bin 0, which offers no split.
            if (!(extent[a] > 0.f) || !std::isfinite(binScale[a])) binScale[a] = 0.f;
        }
        auto binOf = [&](uint32_t aPrimitive, int aAxis) {
            const int b = int((aCentroids[aPrimitive][aAxis] - centroidBox.mMin[aAxis]) * binScale[aAxis]);
            return std::min(std::max(b, 0), kBinCount - 1);
        };
        for (uint32_t i = aBegin; i < aEnd; i++) {
            const uint32_t primitive = ioOrder[i];
            for (int a = 0; a < 3; a++) {
                Bin& bin = bins[a][binOf(primitive, a)];
                bin.box.Extend(aBounds[primitive]);
                bin.count++;
            }
        }
        float bestCost = std::numeric_limits<float>::infinity();
        int bestSplit = -1, bestAxis = axis;
        for (int a = 0; a < 3; a++) {
            float rightCost[kBinCount];
            Aabb accumulated;
            uint32_t accumulatedCount = 0;
            for (int b = kBinCount - 1; b > 0; b--) {
                accumulated.Extend(bins[a][b].box);
                accumulatedCount += bins[a][b].count;
                rightCost[b] = accumulated.SurfaceArea() * float(BlocksFor(accumulatedCount));
            }
            accumulated = Aabb();
            accumulatedCount = 0;
            for (int b = 0; b < kBinCount - 1; b++) {
                accumulated.Extend(bins[a][b].box);
                accumulatedCount += bins[a][b].count;
                const float cost = accumulated.SurfaceArea() * float(BlocksFor(accumulatedCount)) + rightCost[b + 1];
                if (accumulatedCount > 0 && accumulatedCount < count && cost < bestCost) {
                    bestCost = cost;
                    bestSplit = b;
                    bestAxis = a;
                }
            }
        }
        const float area = result.mBox.SurfaceArea();
        const bool splitPays = bestSplit >= 0 && area > 0.f && kTraversalCost + bestCost / area < float(BlocksFor(count));
        if (count <= kMaxLeafSize && !splitPays) return makeLeaf();

        uint32_t middle;
        if (bestSplit >= 0) {
            uint32_t* first = ioOrder.data() + aBegin;
            uint32_t* last = ioOrder.data() + aEnd;
            middle = uint32_t(std::partition(first, last, [&](uint32_t p) { return binOf(p, bestAxis) <= bestSplit; }) - ioOrder.data());
        } else {
            middle = aBegin + count / 2;
            std::nth_element(ioOrder.begin() + aBegin, ioOrder.begin() + middle, ioOrder.begin() + aEnd,
                             [&](uint32_t a, uint32_t b) { return aCentroids[a][axis] < aCentroids[b][axis]; });
        }
        const ChildRef left = BuildBinary(aBounds, aCentroids, ioOrder, aBegin, middle, aDepth + 1, ioNodes);
        const ChildRef right = BuildBinary(aBounds, aCentroids, ioOrder, middle, aEnd, aDepth + 1, ioNodes);
        ioNodes.push_back(BinaryNode{{left, right}});
        result.mIndex = uint32_t(ioNodes.size() - 1);
        result.mCount = 0;
        return result;
    }

    // A leaf that no split could bring down to kMaxLeafSize (its primitives share one
    // centroid, or the depth cap was reached) keeps one of each group of identical
    // primitives: a copy is never nearer than its original, and a mesh duplicated a
    // million times over itself would otherwise cost every ray that enters the leaf a
    // million tests. Sorts ioOrder[aBegin, aEnd) so the distinct ones come first and
    // returns their count; the copies stay in the order, referenced by no leaf.
    uint32_t KeepDistinct(std::vector<uint32_t>& ioOrder, uint32_t aBegin, uint32_t aEnd) const {
        const PrimitiveSoup& soup = *mBuildSoup;
        // A cut-out triangle is nobody's copy (its holes depend on its material and
        // texture coordinates, which the soup does not hold): its index is in its key.
        const auto key = [&](uint32_t aPrimitive) {
            std::pair<std::array<float, 10>, uint32_t> result{};
            std::array<float, 10>& k = result.first;
            const size_t p = aPrimitive;
            if (int(p) < soup.TriangleCount()) {
                const Vec3 v[3] = {soup.mTriangleP0[p], soup.mTriangleP1[p], soup.mTriangleP2[p]};
                for (int i = 0; i < 9; i++) k[size_t(i) + 1] = v[i / 3][i % 3];
                if (IsCutOut(p)) result.second = aPrimitive + 1;
            } else {
                const size_t sphere = p - size_t(soup.TriangleCount());
                k[0] = 1.f;
                for (int i = 0; i < 3; i++) k[size_t(i) + 1] = soup.mSphereCenter[sphere][i];
                k[4] = soup.mSphereRadius[sphere];
            }
            return result;
        };
        uint32_t* first = ioOrder.data() + aBegin;
        uint32_t* last = ioOrder.data() + aEnd;
        std::sort(first, last, [&](uint32_t a, uint32_t b) { return key(a) < key(b); });
        const uint32_t* distinctEnd = std::unique(first, last, [&](uint32_t a, uint32_t b) { return key(a) == key(b); });
        return uint32_t(distinctEnd - first);
    }

    // Turns the binary subtree aSubtree into kWidth-wide nodes (depth-first, a node before
    // its children) and its leaves into blocks, and returns it as its parent sees it.
    ChildRef Collapse(const std::vector<BinaryNode>& aBinary, const std::vector<uint32_t>& aOrder, const ChildRef& aSubtree) {
        if (aSubtree.mCount > 0) {
            mLeafCount++;
            return EmitLeaf(aOrder, aSubtree);
        }
        // Open the inner child of largest surface area until there are kWidth children.
        ChildRef children[kWidth];
        int childCount = 2;
        children[0] = aBinary[aSubtree.mIndex].mChild[0];
        children[1] = aBinary[aSubtree.mIndex].mChild[1];
        while (childCount < kWidth) {
            int largest = -1;
            for (int c = 0; c < childCount; c++)
                if (children[c].mCount == 0 && (largest < 0 || children[c].mBox.SurfaceArea() > children[largest].mBox.SurfaceArea()))
                    largest = c;
            if (largest < 0) break;  // only leaves left
            const BinaryNode& opened = aBinary[children[largest].mIndex];
            children[largest] = opened.mChild[0];
            children[childCount++] = opened.mChild[1];
        }
        const uint32_t nodeIndex = uint32_t(mNodes.size());
        mNodes.push_back(Node{});
        for (int c = 0; c < kWidth; c++) {
            const ChildRef child = c < childCount ? Collapse(aBinary, aOrder, children[c]) : ChildRef{};  // empty: inverted box
            Node& node = mNodes[nodeIndex];  // Collapse may have reallocated mNodes
            for (int k = 0; k < 3; k++) {
                node.Min(k)[c] = child.mBox.mMin[k];
                node.Max(k)[c] = child.mBox.mMax[k];
            }
            node.mIndex[c] = child.mIndex;
            node.mCount[c] = child.mCount;
        }
        ChildRef result = aSubtree;
        result.mIndex = nodeIndex;
        return result;
    }

    // Copies a leaf's primitives, aOrder[mIndex, mIndex + mCount), into blocks: its
    // triangles, then its spheres, each kind's last block filled up with its last
    // primitive. Returns the leaf as its parent sees it (mCount blocks from mIndex).
    ChildRef EmitLeaf(const std::vector<uint32_t>& aOrder, const ChildRef& aLeaf) {
        const int triangleCount = mBuildSoup->TriangleCount();
        ChildRef result = aLeaf;
        result.mIndex = uint32_t(mBlocks.size());
        for (const bool spheres : {false, true}) {
            int lane = kWidth;
            uint32_t last = 0;
            for (uint32_t i = 0; i < aLeaf.mCount; i++) {
                const uint32_t primitive = aOrder[aLeaf.mIndex + i];
                if ((int(primitive) >= triangleCount) != spheres) continue;
                if (lane == kWidth) {
                    mBlocks.emplace_back();
                    lane = 0;
                }
                WriteLane(mBlocks.back(), lane++, primitive);
                last = primitive;
            }
            while (lane < kWidth) WriteLane(mBlocks.back(), lane++, last);
        }
        result.mCount = uint32_t(mBlocks.size()) - result.mIndex;
        return result;
    }

    bool IsCutOut(size_t aTriangle) const {
        return aTriangle < mBuildSoup->mTriangleCutOut.size() && mBuildSoup->mTriangleCutOut[aTriangle];
    }

    void WriteLane(Block& ioBlock, int aLane, uint32_t aPrimitive) const {
        const PrimitiveSoup& soup = *mBuildSoup;
        const size_t p = aPrimitive;
        if (int(p) < soup.TriangleCount()) {
            for (int k = 0; k < 3; k++) {
                ioBlock.mA[k][aLane] = soup.mTriangleP0[p][k];
                ioBlock.mB[k][aLane] = soup.mTriangleP1[p][k];
                ioBlock.mC[k][aLane] = soup.mTriangleP2[p][k];
            }
            ioBlock.mId[aLane] = aPrimitive | (IsCutOut(p) ? kCutOutBit : 0u);
        } else {
            const size_t sphere = p - size_t(soup.TriangleCount());
            for (int k = 0; k < 3; k++) ioBlock.mA[k][aLane] = soup.mSphereCenter[sphere][k];
            ioBlock.mB[0][aLane] = soup.mSphereRadius[sphere];
            ioBlock.mId[aLane] = aPrimitive | kSphereBit;
        }
    }

    std::vector<Node, detail::HugePageAllocator<Node>> mNodes;    // inner nodes, depth-first (a node before its children)
    std::vector<Block, detail::HugePageAllocator<Block>> mBlocks;  // the leaves' primitives, leaf after leaf
    ChildRef mRoot;              // the root, a leaf when the scene is small enough
    size_t mLeafCount = 0;
    int mPrimitiveCount = 0;
    int mBuildDepth = 0;
    uint32_t mLargestLeaf = 0;
    bool mHasCutOuts = false;
    const PrimitiveSoup* mBuildSoup = nullptr;  // during Build only
};

inline void Bvh::Build(const PrimitiveSoup& aSoup) {
    auto tree = std::make_shared<Tree>();
    tree->Build(aSoup);
    mTree = std::move(tree);
}
namespace detail {
struct EverySurfaceSolid {
    bool operator()(int, float) const { return true; }
};
} // namespace detail
inline int Bvh::Intersect(const Ray& aRay, float aTMin, float& ioTMax) const {
    return mTree ? mTree->Intersect<false>(aRay, aTMin, ioTMax, detail::EverySurfaceSolid{}) : -1;
}
inline bool Bvh::Occluded(const Ray& aRay, float aTMin, float aTMax) const {
    return mTree && mTree->Occluded<false>(aRay, aTMin, aTMax, detail::EverySurfaceSolid{});
}
// One branch per query, the same way for every ray of a scene: a scene without cut-outs
// runs the queries above.
template <typename IsSolid>
int Bvh::Intersect(const Ray& aRay, float aTMin, float& ioTMax, const IsSolid& aIsSolid) const {
    if (!mTree) return -1;
    return mTree->HasCutOuts() ? mTree->Intersect<true>(aRay, aTMin, ioTMax, aIsSolid)
                               : mTree->Intersect<false>(aRay, aTMin, ioTMax, aIsSolid);
}
template <typename IsSolid>
bool Bvh::Occluded(const Ray& aRay, float aTMin, float aTMax, const IsSolid& aIsSolid) const {
    if (!mTree) return false;
    return mTree->HasCutOuts() ? mTree->Occluded<true>(aRay, aTMin, aTMax, aIsSolid)
                               : mTree->Occluded<false>(aRay, aTMin, aTMax, aIsSolid);
}
inline bool Bvh::HasCutOuts() const { return mTree && mTree->HasCutOuts(); }
inline size_t Bvh::NodeCount() const { return mTree ? mTree->NodeCount() : 0; }
inline size_t Bvh::StorageBytes() const { return mTree ? mTree->StorageBytes() : 0; }
inline size_t Bvh::NodeBytes() { return sizeof(Tree::Node); }
inline int Bvh::PrimitiveCount() const { return mTree ? mTree->PrimitiveCount() : 0; }
inline int Bvh::Depth() const { return mTree ? mTree->Depth() : 0; }
inline int Bvh::BuildDepth() const { return mTree ? mTree->BuildDepth() : 0; }
inline uint32_t Bvh::LargestLeaf() const { return mTree ? mTree->LargestLeaf() : 0; }

// =====================================================================================
// [SECTION] Appendix: range search
// =====================================================================================
// Provides: how RangeSearch meets the contract stated above its declaration in [SECTION]
// Integrator: the VertexCM family (a reader who skips this appendix loses nothing the
// renderer depends on), HashGrid, the same search over bare point indices, and how
// NearestSearch ([SECTION] Integrator: photon mapping) finds the k nearest photons.
// Relies on Vec3, Sqr and Aabb from [SECTION] Math and Geometry.
//
// The structure is SmallVCM's hashed grid: a uniform grid of cells of size 2r, hashed
// into a table of buckets. A query visits the cells overlapping the query's bounding box
// -- at most 2 x 2 x 2 -- skipping buckets already visited (two cells can hash to one
// bucket; visiting it twice would count its points twice). The grid keeps its own copy
// of the positions in bucket order, each with the point's index (16 bytes), and beside
// them, in the same order, the items: the distance tests of a query read a few
// consecutive cache lines, and only the items of the points that pass are read.
//
// A query runs in three steps, each of which requests the memory the next one reads
// before it is needed, so that the misses of a query's cells overlap: Prepare (the
// buckets; requests their ranges), Locate (reads the ranges; requests the points),
// Select (the distance tests; requests the items of those that pass). Then the visits.
//
// Most cells around a query are empty when the points are sparse (far fewer points than
// cells near a surface). A grid whose last build's queries mostly found nothing marks,
// at its next build, the cells that have points (a bit per hash value), so that a query
// none of whose cells is marked ends at once; and it gives the table four buckets a
// point, so that fewer occupied cells share a bucket. A dense grid does neither: there
// the bits and the larger table would only be more memory to read.

namespace detail {
// Asks the processor to start loading the cache line of aAddress, which the caller will
// read soon: a hint only (no effect on any result; nothing on compilers without it).
inline void Prefetch(const void* aAddress) {
#if defined(__GNUC__) || defined(__clang__)
    __builtin_prefetch(aAddress);
#else
    (void)aAddress;
#endif
}
} // namespace detail

template <class Item>
class RangeSearch<Item>::Grid {
public:
    template <class PositionOf, class ItemOf>
    void Build(size_t aCount, float aRadius, PositionOf&& aPositionOf, ItemOf&& aItemOf) {
        // Sparse: more than two thirds of the last build's queries found no point.
        mMarkOccupiedCells = 3 * mEmptyQueries > 2 * mQueries;
        mQueries = mEmptyQueries = 0;
        mRadius = aRadius;
        mRadiusSqr = Sqr(aRadius);
        mInvCellSize = 1.f / (2.f * aRadius);
        // A power of two: the hash is masked, not divided.
        const size_t wanted = mMarkOccupiedCells ? kSparseBucketsPerPoint * aCount : aCount;
        size_t buckets = 1;
        while (buckets < wanted) buckets *= 2;
        mBucketMask = uint32_t(buckets - 1);
        mBucketEnds.assign(buckets, 0);
        ResizeForOverwrite(mPoints, aCount);
        ResizeForOverwrite(mItems, aCount);
        ResizeForOverwrite(mBucketOf, aCount);
        const size_t occupiedBits = mMarkOccupiedCells ? std::max<size_t>(64, kOccupiedBitsPerBucket * buckets) : 0;
        mOccupiedMask = uint32_t(occupiedBits - 1);
        mOccupied.assign(occupiedBits / 64, 0);
        for (size_t i = 0; i < aCount; i++) {
            const uint32_t hash = HashOf(CellOf(aPositionOf(i)));
            mBucketOf[i] = hash & mBucketMask;
            if (mMarkOccupiedCells) mOccupied[(hash & mOccupiedMask) >> 6] |= uint64_t(1) << (hash & 63u);
        }
        // Counting sort. The table's counters and the points' slots are random places in a
        // large array: each is requested kAhead points before it is written.
        constexpr size_t kAhead = 16;
        for (size_t i = 0; i < aCount; i++) {
            if (i + kAhead < aCount) detail::Prefetch(&mBucketEnds[mBucketOf[i + kAhead]]);
            mBucketEnds[mBucketOf[i]]++;
        }
        // In place: the counts become the buckets' beginnings, and filling the points in
        // advances each to its bucket's end.
        uint32_t sum = 0;
        for (uint32_t& entry : mBucketEnds) { const uint32_t count = entry; entry = sum; sum += count; }
        for (size_t i = 0; i < aCount; i++) {
            if (i + kAhead < aCount) detail::Prefetch(&mBucketEnds[mBucketOf[i + kAhead]]);
            if (i + kAhead / 2 < aCount) {  // where that point will go, unless its bucket gets a point before it
                const uint32_t slot = mBucketEnds[mBucketOf[i + kAhead / 2]];
                detail::Prefetch(&mPoints[slot]);
                detail::Prefetch(&mItems[slot]);
            }
            const uint32_t slot = mBucketEnds[mBucketOf[i]]++;
            mPoints[slot] = Point{aPositionOf(i), uint32_t(i)};
            mItems[slot] = aItemOf(i);
        }
    }

    template <class Visit>
    void Process(const Vec3& aPoint, Visit& aVisit) const {
        Query query;
        Prepare(aPoint, query);
        if (query.mBucketCount > 0) {
            Locate(query);
            Select(query);
        }
        mQueries++;
        mEmptyQueries += query.mSelectedCount == 0;
        if (query.mSelectedCount <= Query::kMaxSelected) {
            for (int i = 0; i < query.mSelectedCount; i++) VisitPoint(query.mSelected[i], aVisit);
            return;
        }
        for (int r = 0; r < query.mRangeCount; r++)  // too many passed for Select's list
            for (uint32_t k = query.mBegins[r]; k < query.mEnds[r]; k++)
                if (Passes(query, k)) VisitPoint(k, aVisit);
    }

private:
    // A query and what its steps found.
    struct Query {
        static constexpr int kMaxSelected = 32;  // more points pass: Process tests them again
        Vec3 mPoint{0.f};
        int mBucketCount = 0;
        uint32_t mBuckets[27];
        int mRangeCount = 0;              // the buckets' ranges of points, those that touch
        uint32_t mBegins[27], mEnds[27];  // joined, the empty left out (Locate)
        int mSelectedCount = 0;           // the points that passed, in visiting order (Select)
        uint32_t mSelected[kMaxSelected + 1];  // (the last entry takes the writes past the end)
    };

    // Finds the buckets of the cells around aPoint (2 x 2 x 2, as cells are 2r wide; 3 per
    // axis when rounding puts a bound on a cell border) and requests their ranges.
    void Prepare(const Vec3& aPoint, Query& aQuery) const {
        aQuery.mPoint = aPoint;
        aQuery.mBucketCount = 0;
        aQuery.mRangeCount = 0;
        aQuery.mSelectedCount = 0;
        if (mPoints.empty()) return;
        const glm::ivec3 low = CellOf(aPoint - Vec3(mRadius));
        const glm::ivec3 high = CellOf(aPoint + Vec3(mRadius));
        // The cells' hashes in the loops' order, z outermost (HashOf, its terms summed once
        // per row); the usual 2 x 2 x 2 written down at once.
        uint32_t hashes[27];
        int cells = 0;
        if (high - low == glm::ivec3(1)) {
            const uint32_t base = uint32_t(low.x) + uint32_t(low.y) * kHashY + uint32_t(low.z) * kHashZ;
            const uint32_t steps[8] = {0u, 1u, kHashY, kHashY + 1u, kHashZ, kHashZ + 1u, kHashZ + kHashY, kHashZ + kHashY + 1u};
            for (int i = 0; i < 8; i++) hashes[i] = base + steps[i];
            cells = 8;
        } else {
            for (int z = low.z; z <= high.z; z++) {
                const uint32_t zHash = uint32_t(z) * kHashZ;
                for (int y = low.y; y <= high.y; y++) {
                    const uint32_t yzHash = zHash + uint32_t(y) * kHashY;
                    for (int x = low.x; x <= high.x; x++) hashes[cells++] = uint32_t(x) + yzHash;
                }
            }
        }
        // The cells' ranges are requested before their marks are read, so that a query
        // with points waits for one round of memory here, not two.
        for (int c = 0; c < cells; c++) detail::Prefetch(&mBucketEnds[hashes[c] & mBucketMask]);
        // No marked cell: nothing can pass.
        bool anyOccupied = mOccupied.empty();
        if (!anyOccupied)
            for (int c = 0; c < cells; c++) anyOccupied |= IsOccupied(hashes[c]);
        if (!anyOccupied) return;
        uint32_t* const buckets = aQuery.mBuckets;
        int count = 0;
        uint64_t summary = 0;
        for (int c = 0; c < cells; c++) {
            const uint32_t bucket = hashes[c] & mBucketMask;
            // Two cells may share a bucket: its points are visited once. A 64-bit summary
            // of the buckets so far (one bit per bucket mod 64) rules that out cheaply, and
            // only a match is checked in full.
            const uint64_t summaryBit = uint64_t(1) << (bucket & 63u);
            if ((summary & summaryBit) && std::find(buckets, buckets + count, bucket) != buckets + count) continue;
            summary |= summaryBit;
            buckets[count++] = bucket;
        }
        aQuery.mBucketCount = count;
    }

    // Reads the ranges of the query's buckets and requests the lines of their points. Two
    // cells side by side along x have neighbouring buckets, whose ranges touch: joined into
    // one, they are the same points in the same order.
    void Locate(Query& aQuery) const {
        int ranges = 0;
        for (int b = 0; b < aQuery.mBucketCount; b++) {
            const uint32_t bucket = aQuery.mBuckets[b];
            const uint32_t begin = bucket == 0 ? 0 : mBucketEnds[bucket - 1];
            const uint32_t end = mBucketEnds[bucket];
            if (begin == end) continue;
            if (ranges > 0 && aQuery.mEnds[ranges - 1] == begin) aQuery.mEnds[ranges - 1] = end;
            else {
                aQuery.mBegins[ranges] = begin;
                aQuery.mEnds[ranges] = end;
                ranges++;
            }
            detail::Prefetch(&mPoints[begin]);
            detail::Prefetch(&mPoints[end - 1]);
            // The items of the range too, so that they arrive with the points.
            const char* first = reinterpret_cast<const char*>(&mItems[begin]);
            const char* last = reinterpret_cast<const char*>(&mItems[end]) - 1;
            if (last - first < 8 * 64)
                for (const char* line = first; line <= last + 63; line += 64) detail::Prefetch(line);
        }
        aQuery.mRangeCount = ranges;
    }

    // The distance tests: the points within the radius (distance <= r), in visiting order,
    // their items requested. More than kMaxSelected: mSelectedCount says how many, and
    // Process tests them again. Which candidates pass is random, so the index is written
    // down for every candidate and the count advanced by the test, without a branch.
    void Select(Query& aQuery) const {
        int count = 0;
        for (int r = 0; r < aQuery.mRangeCount; r++)
            for (uint32_t k = aQuery.mBegins[r]; k < aQuery.mEnds[r]; k++) {
                aQuery.mSelected[std::min(count, Query::kMaxSelected)] = k;
                count += int(Passes(aQuery, k));
            }
        aQuery.mSelectedCount = count;
        if (count > Query::kMaxSelected) return;
        for (int i = 0; i < count; i++) {
            const Item* const item = &mItems[aQuery.mSelected[i]];
            detail::Prefetch(item);
            detail::Prefetch(reinterpret_cast<const char*>(item + 1) - 1);  // an item may straddle two lines
        }
    }

    bool Passes(const Query& aQuery, uint32_t aSlot) const {
        const Vec3 d = mPoints[aSlot].mPosition - aQuery.mPoint;
        return glm::dot(d, d) <= mRadiusSqr;
    }
    template <class Visit>
    void VisitPoint(uint32_t aSlot, Visit& aVisit) const {
        if constexpr (std::is_invocable_v<Visit&, const Item&, uint32_t>) aVisit(mItems[aSlot], mPoints[aSlot].mIndex);
        else aVisit(mItems[aSlot]);
    }

    // Sizes an array that Build overwrites whole. Growing, it drops its old contents instead
    // of copying them and reserves a quarter more, as the point count differs by a few
    // percent between builds (pages never written take no memory).
    template <class Vector>
    static void ResizeForOverwrite(Vector& aArray, size_t aCount) {
        if (aArray.capacity() < aCount) {
            Vector().swap(aArray);
            aArray.reserve(aCount + aCount / 4);
        }
        aArray.resize(aCount);
    }

    glm::ivec3 CellOf(const Vec3& aPosition) const {
        // floor() by truncation and a correction for negatives (std::floor is a library
        // call without SSE4.1).
        auto floorToInt = [](float aX) { const int i = int(aX); return i - int(aX < float(i)); };
        const Vec3 scaled = aPosition * mInvCellSize;
        return glm::ivec3(floorToInt(scaled.x), floorToInt(scaled.y), floorToInt(scaled.z));
    }
    // Neighbours along x get neighbouring buckets (x enters with factor 1), so the two
    // x-cells of a query share cache lines; y and z enter with large odd factors, which
    // keeps cells of one surface from colliding in a pattern.
    static constexpr uint32_t kHashY = 73856093u, kHashZ = 19349663u;
    static uint32_t HashOf(const glm::ivec3& aCell) {
        return uint32_t(aCell.x) + uint32_t(aCell.y) * kHashY + uint32_t(aCell.z) * kHashZ;
    }
    // The occupied cells' bits: one per hash value modulo eight times the bucket count.
    static constexpr size_t kOccupiedBitsPerBucket = 8;
    static constexpr size_t kSparseBucketsPerPoint = 4;
    bool IsOccupied(uint32_t aHash) const { return (mOccupied[(aHash & mOccupiedMask) >> 6] >> (aHash & 63u)) & 1u; }

    float mRadius = 0.f, mRadiusSqr = 0.f, mInvCellSize = 1.f;
    uint32_t mBucketMask = 0;
    // On 2 MiB pages where the system offers them (detail::HugePageAllocator, [SECTION]
    // Appendix: BVH): a query's loads land anywhere in these arrays.
    template <class T>
    using Array = std::vector<T, detail::HugePageAllocator<T>>;
    Array<uint32_t> mBucketEnds;
    struct Point { Vec3 mPosition; uint32_t mIndex; };
    Array<Point> mPoints;             // in bucket order
    Array<Item> mItems;               // in the same order
    std::vector<uint32_t> mBucketOf;  // build scratch, kept to avoid reallocating
    Array<uint64_t> mOccupied;        // IsOccupied's bits (none unless mMarkOccupiedCells)
    uint32_t mOccupiedMask = 0;
    bool mMarkOccupiedCells = false;
    mutable uint64_t mQueries = 0, mEmptyQueries = 0;  // since the last Build (one thread: see the contract)
};

template <class Item>
template <class PositionOf, class ItemOf>
void RangeSearch<Item>::Build(size_t aCount, float aRadius, PositionOf&& aPositionOf, ItemOf&& aItemOf) {
    if (!mGrid) mGrid = std::make_shared<Grid>();
    mGrid->Build(aCount, aRadius, aPositionOf, aItemOf);
}

template <class Item>
template <class Visit>
void RangeSearch<Item>::Process(const Vec3& aPoint, Visit&& aVisit) const {
    if (mGrid) mGrid->Process(aPoint, aVisit);
}

namespace detail {
// The hierarchy behind RaySearch and BeamSearch: a bounding volume hierarchy over boxes
// (a point's, or a beam's). Build splits the boxes at the median of their centres along
// the longest axis of the node's box until a node holds at most kLeafSize, and returns
// the leaf order (order[k]: the box at place k), in which the searches keep their copies,
// so that a leaf is one run of their arrays. Visit walks the tree depth-first, entering a
// node whose box, grown by aGrow on every side, the ray's stretch aOrigin + t aDirection,
// 0 <= t <= aLength, crosses (anything within aGrow of the stretch lies in that grown
// box), and calls aLeaf(begin, end) for the places of each leaf it reaches.
class BoxTree {
public:
    std::vector<uint32_t> Build(const std::vector<Vec3>& aLows, const std::vector<Vec3>& aHighs) {
        mNodes.clear();
        std::vector<uint32_t> order(aLows.size());
        for (size_t i = 0; i < order.size(); i++) order[i] = uint32_t(i);
        if (order.empty()) return order;
        mNodes.reserve(2 * (order.size() / kLeafSize + 1));
        BuildNode(order, aLows, aHighs, 0, uint32_t(order.size()));
        return order;
    }

    template <class Leaf>
    void Visit(const Vec3& aOrigin, const Vec3& aDirection, float aLength, float aGrow, Leaf&& aLeaf) const {
        if (mNodes.empty() || !(aLength >= 0.f)) return;
        uint32_t stack[64];
        int depth = 0;
        stack[depth++] = 0;
        while (depth > 0) {
            const uint32_t index = stack[--depth];
            const Node& node = mNodes[index];
            if (!Crosses(node, aOrigin, aDirection, aLength, aGrow)) continue;
            if (node.mSecond == 0) aLeaf(node.mBegin, node.mEnd);
            else {
                stack[depth++] = node.mSecond;
                stack[depth++] = index + 1;  // the first child follows its parent
            }
        }
    }

private:
    static constexpr uint32_t kLeafSize = 8;
    struct Node {
        Vec3 mLow, mHigh;       // the box of its boxes
        uint32_t mBegin, mEnd;  // its boxes: places [mBegin, mEnd) of the leaf order
        uint32_t mSecond;       // its second child (the first is the next node); 0 at a leaf
    };

    // Depth: the median split halves the count, so a tree of 2^32 boxes is 32 deep and
    // Visit's stack of 64 never overflows (it holds at most one entry per level, plus one).
    void BuildNode(std::vector<uint32_t>& aOrder, const std::vector<Vec3>& aLows, const std::vector<Vec3>& aHighs,
                   uint32_t aBegin, uint32_t aEnd) {
        const uint32_t index = uint32_t(mNodes.size());
        mNodes.push_back(Node{});
        Vec3 low(std::numeric_limits<float>::infinity()), high(-std::numeric_limits<float>::infinity());
        for (uint32_t k = aBegin; k < aEnd; k++) {
            low = glm::min(low, aLows[aOrder[k]]);
            high = glm::max(high, aHighs[aOrder[k]]);
        }
        mNodes[index] = Node{low, high, aBegin, aEnd, 0};
        if (aEnd - aBegin <= kLeafSize) return;
        const Vec3 extent = high - low;
        const int axis = extent.x >= extent.y && extent.x >= extent.z ? 0 : (extent.y >= extent.z ? 1 : 2);
        const uint32_t middle = aBegin + (aEnd - aBegin) / 2;
        std::nth_element(aOrder.begin() + aBegin, aOrder.begin() + middle, aOrder.begin() + aEnd, [&](uint32_t a, uint32_t b) {
            return aLows[a][axis] + aHighs[a][axis] < aLows[b][axis] + aHighs[b][axis];
        });
        BuildNode(aOrder, aLows, aHighs, aBegin, middle);
        const uint32_t second = uint32_t(mNodes.size());
        BuildNode(aOrder, aLows, aHighs, middle, aEnd);
        mNodes[index].mSecond = second;
    }

    // Slabs; an axis the ray runs parallel to only checks the origin.
    static bool Crosses(const Node& aNode, const Vec3& aOrigin, const Vec3& aDirection, float aLength, float aGrow) {
        float enter = 0.f, leave = aLength;
        for (int a = 0; a < 3; a++) {
            const float low = aNode.mLow[a] - aGrow, high = aNode.mHigh[a] + aGrow;
            if (aDirection[a] == 0.f) {
                if (aOrigin[a] < low || aOrigin[a] > high) return false;
                continue;
            }
            const float inverse = 1.f / aDirection[a];
            float t0 = (low - aOrigin[a]) * inverse, t1 = (high - aOrigin[a]) * inverse;
            if (t0 > t1) std::swap(t0, t1);
            enter = std::max(enter, t0);
            leave = std::min(leave, t1);
            if (enter > leave) return false;
        }
        return true;
    }

    std::vector<Node> mNodes;  // depth-first: a node, its first subtree, its second
};

// How far a search grows the tree's boxes: the radius, and 1e-5 of the coordinates more,
// so that rounding in the box test never drops what the exact test would take.
inline float GrownRadius(float aRadius, const std::vector<Vec3>& aLows, const std::vector<Vec3>& aHighs) {
    float largest = 0.f;
    for (size_t i = 0; i < aLows.size(); i++)
        largest = std::max(largest, std::max(MaxComponent(glm::abs(aLows[i])), MaxComponent(glm::abs(aHighs[i]))));
    return aRadius + 1e-5f * (aRadius + largest);
}
} // namespace detail

// RaySearch: the points in a detail::BoxTree (a point is its own box); at a leaf, each
// point's projection and distance decide.
template <class Item>
class RaySearch<Item>::Tree {
public:
    template <class PositionOf, class ItemOf>
    void Build(size_t aCount, float aRadius, PositionOf&& aPositionOf, ItemOf&& aItemOf) {
        std::vector<Vec3> positions(aCount);
        for (size_t i = 0; i < aCount; i++) positions[i] = aPositionOf(i);
        const std::vector<uint32_t> order = mTree.Build(positions, positions);
        mRadius = aRadius;
        mGrow = detail::GrownRadius(aRadius, positions, positions);
        mPoints.resize(aCount);
        mItems.resize(aCount);
        for (size_t k = 0; k < aCount; k++) {
            mPoints[k] = positions[order[k]];
            mItems[k] = aItemOf(order[k]);
        }
    }

    template <class Visit>
    void Process(const Vec3& aOrigin, const Vec3& aDirection, float aLength, Visit& aVisit) const {
        const float radiusSqr = Sqr(mRadius);
        mTree.Visit(aOrigin, aDirection, aLength, mGrow, [&](uint32_t aBegin, uint32_t aEnd) {
            for (uint32_t k = aBegin; k < aEnd; k++) {
                const Vec3 toPoint = mPoints[k] - aOrigin;
                const float t = glm::dot(toPoint, aDirection);
                if (t < 0.f || t > aLength) continue;
                const Vec3 across = toPoint - t * aDirection;
                if (glm::dot(across, across) <= radiusSqr) aVisit(mItems[k], t);
            }
        });
    }

private:
    detail::BoxTree mTree;
    float mRadius = 0.f, mGrow = 0.f;
    std::vector<Vec3> mPoints;  // in leaf order
    std::vector<Item> mItems;   // in the same order
};

template <class Item>
template <class PositionOf, class ItemOf>
void RaySearch<Item>::Build(size_t aCount, float aRadius, PositionOf&& aPositionOf, ItemOf&& aItemOf) {
    if (!mTree) mTree = std::make_shared<Tree>();
    mTree->Build(aCount, aRadius, aPositionOf, aItemOf);
}

template <class Item>
template <class Visit>
void RaySearch<Item>::Process(const Vec3& aOrigin, const Vec3& aDirection, float aLength, Visit&& aVisit) const {
    if (mTree) mTree->Process(aOrigin, aDirection, aLength, aVisit);
}

// BeamSearch: the beams cut into pieces of at most 1/16 of the beams' extent (the
// largest side of their box; and at least 4r), the pieces in a detail::BoxTree (a piece's
// box is its two ends'): a long beam's own box would hold much space it does not pass,
// and every query near it would test it. At a
// leaf, each piece's beam has its closest point to the query's line found
// (BeamSearch::Closest), and the piece whose stretch [u0, u1) holds that point's u (the
// last piece: [u0, u1]) visits it: each beam once, as the pieces part its length.
template <class Item>
class BeamSearch<Item>::Tree {
public:
    template <class BeamOf, class ItemOf>
    void Build(size_t aCount, float aRadius, BeamOf&& aBeamOf, ItemOf&& aItemOf) {
        mBeams.resize(aCount);
        mItems.resize(aCount);
        for (size_t i = 0; i < aCount; i++) {
            mBeams[i] = aBeamOf(i);
            mItems[i] = aItemOf(i);
        }
        Vec3 low(std::numeric_limits<float>::max()), high(-std::numeric_limits<float>::max());
        for (const Beam& beam : mBeams) {
            const Vec3 end = beam.mStart + beam.mLength * beam.mDirection;
            low = glm::min(low, glm::min(beam.mStart, end));
            high = glm::max(high, glm::max(beam.mStart, end));
        }
        const float pieceLength = std::max(4.f * aRadius, MaxComponent(high - low) / 16.f);
        std::vector<Piece> pieces;
        std::vector<Vec3> lows, highs;
        for (size_t i = 0; i < aCount; i++) {
            const Beam& beam = mBeams[i];
            const float wanted = std::ceil(beam.mLength / pieceLength);
            const uint32_t count = wanted >= float(kMaxPieces) ? kMaxPieces : std::max(1u, uint32_t(wanted));
            for (uint32_t k = 0; k < count; k++) {
                const Piece piece{uint32_t(i), PieceEnd(beam, k, count), PieceEnd(beam, k + 1, count), k + 1 == count};
                const Vec3 a = beam.mStart + piece.mBegin * beam.mDirection, b = beam.mStart + piece.mEnd * beam.mDirection;
                pieces.push_back(piece);
                lows.push_back(glm::min(a, b));
                highs.push_back(glm::max(a, b));
            }
        }
        const std::vector<uint32_t> order = mTree.Build(lows, highs);
        mRadius = aRadius;
        mGrow = detail::GrownRadius(aRadius, lows, highs);
        mPieces.resize(pieces.size());
        for (size_t k = 0; k < pieces.size(); k++) mPieces[k] = pieces[order[k]];
    }

    template <class Visit>
    void Process(const Vec3& aOrigin, const Vec3& aDirection, float aLength, Visit& aVisit) const {
        mTree.Visit(aOrigin, aDirection, aLength, mGrow, [&](uint32_t aBegin, uint32_t aEnd) {
            for (uint32_t k = aBegin; k < aEnd; k++) {
                const Piece& piece = mPieces[k];
                const std::optional<BeamPair> pair = Closest(aOrigin, aDirection, aLength, mBeams[piece.mBeam], mRadius);
                if (pair && pair->mU >= piece.mBegin && (pair->mU < piece.mEnd || (piece.mLast && pair->mU <= piece.mEnd)))
                    aVisit(mItems[piece.mBeam], *pair);
            }
        });
    }

private:
    static constexpr uint32_t kMaxPieces = 64;
    struct Piece {
        uint32_t mBeam;
        float mBegin, mEnd;  // its stretch of the beam, u in [mBegin, mEnd)
        bool mLast;          // the beam's last piece, which takes u = mEnd too
    };
    // One expression for both pieces that share an end, so that they agree on it exactly.
    static float PieceEnd(const Beam& aBeam, uint32_t aK, uint32_t aCount) {
        return aK == aCount ? aBeam.mLength : aBeam.mLength * float(aK) / float(aCount);
    }

    detail::BoxTree mTree;
    float mRadius = 0.f, mGrow = 0.f;
    std::vector<Beam> mBeams;    // as built
    std::vector<Item> mItems;    // in the same order
    std::vector<Piece> mPieces;  // in leaf order
};

template <class Item>
template <class BeamOf, class ItemOf>
void BeamSearch<Item>::Build(size_t aCount, float aRadius, BeamOf&& aBeamOf, ItemOf&& aItemOf) {
    if (!mTree) mTree = std::make_shared<Tree>();
    mTree->Build(aCount, aRadius, aBeamOf, aItemOf);
}

template <class Item>
template <class Visit>
void BeamSearch<Item>::Process(const Vec3& aOrigin, const Vec3& aDirection, float aLength, Visit&& aVisit) const {
    if (mTree) mTree->Process(aOrigin, aDirection, aLength, aVisit);
}

// The search over point indices: aVisit(index) for every point within the radius.
class HashGrid : public RangeSearch<uint32_t> {
public:
    template <class PositionOf>
    void Build(size_t aCount, float aRadius, PositionOf&& aPositionOf) {
        RangeSearch<uint32_t>::Build(aCount, aRadius, aPositionOf, [](size_t i) { return uint32_t(i); });
    }
};

// NearestSearch is a balanced kd-tree over the points, built by recursive median splits
// on the axis of largest extent (the points are reordered: node = median of its range).
// FindNearest returns the k nearest points within a maximum radius, exactly.
//
// The search is most of pm's time at k = 100, so it is kept cheap: candidates within
// the current bound are only collected, and cut back to the k nearest by one
// std::nth_element whenever there are 1.5 k of them (a max-heap of the best k would pay
// log k steps for every candidate); small subtrees are scanned without recursion; and
// the caller may pass the k-th distance of its previous query as a first bound
// (neighbouring pixels see similar photon densities), widened only if fewer than k
// points lie inside it.
// None of it changes the result: the k nearest by distance, equal distances by index.
// NearestSearch keeps the k-th distance of its last query as the next query's guess (one
// per search: the global and caustic maps' densities differ by orders of magnitude),
// none after a Build (an iteration depends on its random numbers only).
class NearestSearch::KdTree {
public:
    using Neighbor = NearestSearch::Neighbor;

    // Builds the tree over aCount points given by aPositionOf(i); oOrder[j] is the point
    // stored at tree position j (the caller reorders its own data the same way).
    // The median splits move compact (position, index) records, not indices into the
    // caller's data: a comparison then reads the record itself, not a point somewhere in
    // the caller's larger records (photons are 40 bytes). The build is mostly comparisons.
    template <class PositionOf>
    void Build(size_t aCount, PositionOf&& aPositionOf, std::vector<uint32_t>& oOrder) {
        std::vector<BuildRecord> records(aCount);
        for (size_t i = 0; i < aCount; i++) records[i] = BuildRecord{aPositionOf(i), uint32_t(i)};
        mAxes.assign(aCount, 0);
        BuildRange(records, 0, aCount);
        oOrder.resize(aCount);
        mPositions.resize(aCount);
        for (size_t i = 0; i < aCount; i++) {
            mPositions[i] = records[i].mPosition;
            oOrder[i] = records[i].mIndex;
        }
    }

    size_t Size() const { return mPositions.size(); }
    const Vec3& Position(size_t aIndex) const { return mPositions[aIndex]; }

    // The (up to) aK nearest points with distance^2 <= aMaxDistSqr that aAccept(index)
    // accepts, in no particular order except that, when there are aK of them, the k-th
    // nearest is last. That is all a density estimate needs (the set, and the distance
    // of the k-th); sorting them would cost about as much as finding them.
    // ioHintSqr (optional): in, a first guess of the k-th distance^2 (0: none); out, the
    // guess for the next query (the k-th distance^2 found here, with a margin).
    template <class Accept>
    void FindNearest(const Vec3& aQuery, int aK, float aMaxDistSqr, Accept&& aAccept, std::vector<Neighbor>& oNeighbors,
                     float* ioHintSqr = nullptr) const {
        oNeighbors.clear();
        if (mPositions.empty() || aK <= 0) return;
        const size_t k = size_t(aK);
        float bound = aMaxDistSqr;
        if (ioHintSqr && *ioHintSqr > 0.f) bound = std::min(bound, *ioHintSqr);
        for (;;) {
            oNeighbors.clear();
            float worst = bound;
            Search(aQuery, k, worst, aAccept, oNeighbors, 0, mPositions.size());
            if (oNeighbors.size() >= k || bound >= aMaxDistSqr) break;
            bound = std::min(aMaxDistSqr, 4.f * bound);  // the guess was too small: twice the radius
        }
        if (oNeighbors.size() >= k) KeepNearest(oNeighbors, k);  // also when exactly k: puts the k-th last
        if (ioHintSqr) *ioHintSqr = kHintMargin * (oNeighbors.size() == k ? oNeighbors.back().mDistSqr : bound);
    }
    // The same, sorted by distance (equal distances by index).
    template <class Accept>
    void KNearest(const Vec3& aQuery, int aK, float aMaxDistSqr, Accept&& aAccept, std::vector<Neighbor>& oNeighbors) const {
        FindNearest(aQuery, aK, aMaxDistSqr, aAccept, oNeighbors);
        std::sort(oNeighbors.begin(), oNeighbors.end());
    }

private:
    struct BuildRecord { Vec3 mPosition; uint32_t mIndex; };

    // Subtrees this small are scanned point by point: below it, recursing costs more than
    // the distance tests it would skip.
    static constexpr size_t kScanSize = 16;
    // The next query's first bound: 1.5 x the k-th distance^2 found. A tighter guess is
    // too often too small, and the search runs again wider; a looser one collects more
    // candidates than it needs.
    static constexpr float kHintMargin = 1.5f;

    void BuildRange(std::vector<BuildRecord>& ioRecords, size_t aBegin, size_t aEnd) {
        if (aEnd - aBegin <= 1) return;
        Aabb box;
        for (size_t i = aBegin; i < aEnd; i++) box.Extend(ioRecords[i].mPosition);
        const Vec3 extent = box.mMax - box.mMin;
        const int axis = (extent.x >= extent.y && extent.x >= extent.z) ? 0 : (extent.y >= extent.z ? 1 : 2);
        const size_t middle = (aBegin + aEnd) / 2;
        std::nth_element(ioRecords.begin() + long(aBegin), ioRecords.begin() + long(middle), ioRecords.begin() + long(aEnd),
                         [axis](const BuildRecord& a, const BuildRecord& b) { return a.mPosition[axis] < b.mPosition[axis]; });
        mAxes[middle] = uint8_t(axis);
        BuildRange(ioRecords, aBegin, middle);
        BuildRange(ioRecords, middle + 1, aEnd);
    }

    // Keeps the aK nearest candidates, the k-th nearest last.
    static void KeepNearest(std::vector<Neighbor>& ioCandidates, size_t aK) {
        std::nth_element(ioCandidates.begin(), ioCandidates.begin() + long(aK - 1), ioCandidates.end());
        ioCandidates.resize(aK);
    }

    // Depth-first, nearer side first; a subtree is entered only if its splitting plane is
    // within the current bound ioWorst, which shrinks to the k-th distance^2 so far each
    // time the candidates are cut back.
    template <class Accept>
    void Search(const Vec3& aQuery, size_t aK, float& ioWorst, Accept& aAccept, std::vector<Neighbor>& ioCandidates,
                size_t aBegin, size_t aEnd) const {
        if (aEnd - aBegin <= kScanSize) {
            for (size_t i = aBegin; i < aEnd; i++) Consider(aQuery, i, aK, ioWorst, aAccept, ioCandidates);
            return;
        }
        const size_t middle = (aBegin + aEnd) / 2;
        const int axis = mAxes[middle];
        const float planeDistance = aQuery[axis] - mPositions[middle][axis];
        const bool leftFirst = planeDistance < 0.f;
        if (leftFirst) Search(aQuery, aK, ioWorst, aAccept, ioCandidates, aBegin, middle);
        else Search(aQuery, aK, ioWorst, aAccept, ioCandidates, middle + 1, aEnd);
        Consider(aQuery, middle, aK, ioWorst, aAccept, ioCandidates);
        if (planeDistance * planeDistance <= ioWorst) {
            if (leftFirst) Search(aQuery, aK, ioWorst, aAccept, ioCandidates, middle + 1, aEnd);
            else Search(aQuery, aK, ioWorst, aAccept, ioCandidates, aBegin, middle);
        }
    }

    template <class Accept>
    void Consider(const Vec3& aQuery, size_t aPoint, size_t aK, float& ioWorst, Accept& aAccept,
                  std::vector<Neighbor>& ioCandidates) const {
        const Vec3 d = mPositions[aPoint] - aQuery;
        const float distSqr = glm::dot(d, d);
        if (distSqr <= ioWorst && aAccept(aPoint)) {
            ioCandidates.push_back(Neighbor{uint32_t(aPoint), distSqr});
            if (ioCandidates.size() == aK + aK / 2) {
                KeepNearest(ioCandidates, aK);
                ioWorst = ioCandidates.back().mDistSqr;
            }
        }
    }

    std::vector<Vec3> mPositions;
    std::vector<uint8_t> mAxes;
};

struct NearestSearch::State {
    KdTree mTree;
    std::vector<Neighbor> mFound;  // the last query's answer
    float mHintSqr = 0.f;          // the next query's first guess of the k-th distance^2
};

template <class PositionOf>
std::vector<uint32_t> NearestSearch::Build(size_t aCount, PositionOf&& aPositionOf) {
    if (!mState) mState = std::make_shared<State>();
    std::vector<uint32_t> order;
    mState->mTree.Build(aCount, aPositionOf, order);
    mState->mHintSqr = 0.f;
    return order;
}

template <class Accept>
const std::vector<NearestSearch::Neighbor>& NearestSearch::FindNearest(const Vec3& aPoint, int aK, float aMaxDistSqr,
                                                                       Accept&& aAccept) const {
    static const std::vector<Neighbor> kNone;
    if (!mState) return kNone;
    mState->mTree.FindNearest(aPoint, aK, aMaxDistSqr, aAccept, mState->mFound, &mState->mHintSqr);
    return mState->mFound;
}

template <class Accept>
std::vector<NearestSearch::Neighbor> NearestSearch::KNearest(const Vec3& aPoint, int aK, float aMaxDistSqr,
                                                             Accept&& aAccept) const {
    std::vector<Neighbor> nearest;
    if (mState) mState->mTree.KNearest(aPoint, aK, aMaxDistSqr, aAccept, nearest);
    return nearest;
}

inline size_t NearestSearch::Size() const { return mState ? mState->mTree.Size() : 0; }
inline const Vec3& NearestSearch::Position(size_t aIndex) const { return mState->mTree.Position(aIndex); }

// =====================================================================================
// [SECTION] Appendix: film splats
// =====================================================================================
// Provides: how Film::Splat meets what [SECTION] Film states of it. Relies on Film and on
// detail::Prefetch ([SECTION] Appendix: range search).
//
// A splat's pixel is anywhere in the image (6 MiB of doubles at 512x512), so adding it
// at once waits for a cache miss. The film instead asks for the pixel's memory when the
// splat comes and adds the splats a batch at a time, in the order given, so that the
// misses of pixels far apart overlap; every other use of the film (AddColor,
// Accumulate, Resolve) adds the pending ones first. Each pixel receives the same
// additions in the same order, so the image is the same bit for bit.

namespace detail {
inline constexpr size_t kFilmSplatBatch = 32;
} // namespace detail

inline void Film::Splat(int aPixelIndex, const Vec3& aColor) {
    CheckContribution(aPixelIndex, aColor);
    detail::Prefetch(&mPixels[size_t(aPixelIndex)]);
    PendingSplat& splat = mSplats.emplace_back();
    splat.mPixel = aPixelIndex;
    splat.mColor = aColor;
    if (mSplats.size() == detail::kFilmSplatBatch) AddSplats();
}

inline void Film::AddSplats() const {
    if (mSplats.empty()) return;
    for (const PendingSplat& splat : mSplats) mPixels[size_t(splat.mPixel)] += glm::dvec3(splat.mColor);
    mSplats.clear();
}

// =====================================================================================
// [SECTION] Render loop
// =====================================================================================
// Provides: the integrator registry (the built-ins, and any the program registers: found
// by name with FindIntegrator, listed by RegisteredIntegrators) and Render(), which runs
// an integrator on a scene with a budget of iterations or seconds on all cores, and
// returns the averaged image (and layers). Each thread owns a renderer and its film;
// iteration i draws its random numbers from stream i of the base seed. With an iteration
// budget thread t runs iterations t, t + T, t + 2T, ... and the films are summed in thread
// order, so one seed and one thread count give one image, bit for bit. With a time budget
// threads take the next iteration until time runs out.
// Render(scene, options) runs the built-in that RenderOptions::mAlgorithm names;
// Render(scene, options, integrator) runs any Integrator (see [SECTION] Integrator
// interface for what it must provide).

struct RenderResult {
    Image mImage;
    std::vector<std::pair<std::string, Image>> mLayers;  // technique layers, if asked for
    int mIterations = 0;
    double mSeconds = 0.0;
    uint64_t mRays = 0;  // nearest-hit and shadow rays traced, all threads
    bool mStopped = false;  // stopped early by RenderOptions::mStopRequested
};

namespace detail {

// A built-in: its renderer runs with RenderOptions::mAlgorithm set to its own algorithm,
// whatever the caller's options say, because PhotonMapper and VertexCM read from it which
// of their techniques to use.
template <class Renderer>
Integrator MakeBuiltIn(Algorithm aAlgorithm, const char* aDescription,
                       Integrator::BytesPerRendererFn aBytesPerRenderer = nullptr) {
    // Every built-in handles media (pm and pmfg by refusing them with their own message).
    return Integrator{AlgorithmShortName(aAlgorithm), aDescription,
                      [aAlgorithm](const Scene& aScene, const RenderOptions& aOptions) -> std::unique_ptr<AbstractRenderer> {
                          RenderOptions options = aOptions;
                          options.mAlgorithm = aAlgorithm;
                          return std::make_unique<Renderer>(aScene, options);
                      },
                      std::move(aBytesPerRenderer), true};
}

// What a renderer allocates beyond its film, roughly from above: the photon maps (4
// photons per emitted path, twice: photons and the kd-tree) or the VertexCM family's
// light vertices (3 per light path, plus the range-search grid: the Cornell scenes store
// 0.5 to 2.2; the room reserved for 4 is not touched).
inline uint64_t PhotonMapBytes(const Camera&, const RenderOptions& aOptions) {
    return uint64_t(aOptions.mPhotonCount) * 4 * 2 * sizeof(Photon);
}
inline uint64_t LightVertexBytes(const Camera& aCamera, const RenderOptions&) {
    return uint64_t(aCamera.PixelCount()) * (3 * (sizeof(VertexCM::LightVertex) + 16) + sizeof(int));
}
// pb2d and bb1d: the same, plus the ray search's copy of every vertex as if all were in
// media (a point, its item, its share of the tree's nodes, the build's scratch), and the
// photon beams, as many, twice (stored, and in the beam search with their boxes).
inline uint64_t BeamQueryBytes(const Camera& aCamera, const RenderOptions& aOptions) {
    return LightVertexBytes(aCamera, aOptions) +
           uint64_t(aCamera.PixelCount()) * 3 * (sizeof(Vec3) + sizeof(VertexCM::MergeData) + 8 + sizeof(Vec3) + 4) +
           uint64_t(aCamera.PixelCount()) * 3 * (2 * sizeof(VertexCM::PhotonBeam) + 2 * sizeof(Vec3) + 12);
}

// The built-ins in the order the header teaches them; the registry starts with these.
inline std::deque<Integrator> BuiltInIntegrators() {
    return {
        MakeBuiltIn<EyeLight>(Algorithm::kEyeLight, "eye light: |cos| at the first hit, back faces red (a geometry check)"),
        MakeBuiltIn<PathTracer>(Algorithm::kPathTracing, "path tracing with next-event estimation and MIS"),
        MakeBuiltIn<VertexCM>(Algorithm::kLightTracing, "light tracing: light sub-paths splatted onto the image",
                                    LightVertexBytes),
        MakeBuiltIn<PhotonMapper>(Algorithm::kPhotonMapping, "photon mapping: k nearest photons at the first hit",
                                        PhotonMapBytes),
        MakeBuiltIn<PhotonMapper>(Algorithm::kPhotonMappingFinalGather,
                                        "photon mapping, partitioned estimator with final gathering", PhotonMapBytes),
        MakeBuiltIn<VertexCM>(Algorithm::kProgressivePhotonMapping,
                                    "progressive photon mapping (merging at the first non-specular camera vertex)",
                                    LightVertexBytes),
        MakeBuiltIn<VertexCM>(Algorithm::kBidirectionalPhotonMapping,
                                    "bidirectional photon mapping (merging at every camera vertex, MIS)", LightVertexBytes),
        MakeBuiltIn<VertexCM>(Algorithm::kBidirectionalPathTracing, "bidirectional path tracing (vertex connection, MIS)",
                                    LightVertexBytes),
        MakeBuiltIn<VertexCM>(Algorithm::kVertexConnectionMerging, "vertex connection and merging (BPT + BPM under one MIS)",
                                    LightVertexBytes),
        MakeBuiltIn<VertexCM>(Algorithm::kBeamRadianceEstimate,
                                    "beam radiance estimate: ppm whose camera rays gather the photon points in media "
                                    "within r (pb2d)", BeamQueryBytes),
        MakeBuiltIn<VertexCM>(Algorithm::kPhotonBeams,
                                    "photon beams: ppm whose camera rays gather the light sub-paths' segments in media "
                                    "passing within r (bb1d)", BeamQueryBytes),
        MakeBuiltIn<VertexCM>(Algorithm::kUpbp,
                                    "unified points, beams and paths: bpt, merging on surfaces and the point and beam "
                                    "merges in media under one MIS (--techniques)", BeamQueryBytes),
    };
}

// One per program, made on first use (so registration objects in other translation units
// may run before or after any other static initialization). A deque, so that the
// Integrator a lookup returned stays where it is when more are registered.
struct IntegratorRegistry {
    std::mutex mMutex;
    std::deque<Integrator> mIntegrators = BuiltInIntegrators();
};
inline IntegratorRegistry& GetIntegratorRegistry() {
    static IntegratorRegistry registry;
    return registry;
}

} // namespace detail

// Adds an integrator that Render() and the command line can then find by name. Throws
// Error on a name that is empty, not of letters, digits, '_' and '-', or already taken
// (the built-ins' names included), and on an Integrator without mCreateRenderer.
// Register before rendering: at static initialization (IntegratorRegistration) or early
// in main.
inline const Integrator& RegisterIntegrator(Integrator aIntegrator) {
    const std::string what = "integrator '" + aIntegrator.mName + "'";
    if (aIntegrator.mName.empty() ||
        aIntegrator.mName.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-") != std::string::npos)
        throw Error(what + ": a name must be letters, digits, '_' and '-'");
    if (!aIntegrator.mCreateRenderer) throw Error(what + ": has no mCreateRenderer");
    detail::IntegratorRegistry& registry = detail::GetIntegratorRegistry();
    std::lock_guard<std::mutex> lock(registry.mMutex);
    for (const Integrator& known : registry.mIntegrators)
        if (known.mName == aIntegrator.mName) throw Error(what + ": the name is already registered");
    registry.mIntegrators.push_back(std::move(aIntegrator));
    return registry.mIntegrators.back();
}

// The integrator of that name, or nullptr.
inline const Integrator* FindIntegrator(const std::string& aName) {
    detail::IntegratorRegistry& registry = detail::GetIntegratorRegistry();
    std::lock_guard<std::mutex> lock(registry.mMutex);
    for (const Integrator& known : registry.mIntegrators)
        if (known.mName == aName) return &known;
    return nullptr;
}

// Every registered integrator: the built-ins first, then the others in registration order.
inline std::vector<const Integrator*> RegisteredIntegrators() {
    detail::IntegratorRegistry& registry = detail::GetIntegratorRegistry();
    std::lock_guard<std::mutex> lock(registry.mMutex);
    std::vector<const Integrator*> all;
    for (const Integrator& known : registry.mIntegrators) all.push_back(&known);
    return all;
}

// The built-in integrator of an Algorithm (always registered).
inline const Integrator& BuiltInIntegrator(Algorithm aAlgorithm) { return *FindIntegrator(AlgorithmShortName(aAlgorithm)); }

// Registers an integrator during static initialization, from the translation unit that
// defines it, so that linking that unit into a program (the command line, say) is all it
// takes to make it known:
//     static const smallvcm::IntegratorRegistration kRegistration(
//         smallvcm::MakeIntegrator<MyPathTracer>("mypt", "my path tracer"));
// A refused registration cannot be caught there: it prints the Error's line and exits 1.
struct IntegratorRegistration {
    explicit IntegratorRegistration(Integrator aIntegrator) {
        try {
            RegisterIntegrator(std::move(aIntegrator));
        } catch (const Error& e) {
            std::fprintf(stderr, "smallvcm: %s\n", e.what());
            std::exit(1);
        }
    }
};

// One renderer of the built-in that aOptions.mAlgorithm names (what Render() runs on each
// thread; the convergence and benchmark tools drive renderers themselves).
inline std::unique_ptr<AbstractRenderer> CreateRenderer(const Scene& aScene, const RenderOptions& aOptions) {
    return BuiltInIntegrator(aOptions.mAlgorithm).mCreateRenderer(aScene, aOptions);
}

// Threads beyond a few per core only add memory (a film each) and scheduling delay.
inline int MaxThreads() { return 4 * int(std::max(1u, std::thread::hardware_concurrency())); }

// A merging radius above a quarter of the scene's radius blurs light across whole walls
// and makes every lookup visit a large share of all light vertices; a photon search
// radius beyond the scene finds nothing more.
constexpr float kMaxRadiusFactor = 0.25f;
constexpr float kMaxPhotonRadiusFactor = 1.f;

// Throws Error naming the first option that is out of range.
inline void ValidateRenderOptions(const RenderOptions& aOptions) {
    if (aOptions.mIterations < 0) throw Error("iterations: must be >= 0 (0 = until the time budget ends)");
    if (!(aOptions.mSeconds >= 0.0) || !std::isfinite(aOptions.mSeconds)) throw Error("seconds: must be a finite number >= 0");
    if (aOptions.mIterations == 0 && aOptions.mSeconds <= 0.0) throw Error("iterations: 0 needs a time budget (seconds > 0)");
    if (aOptions.mThreads < 0) throw Error("threads: must be >= 0 (0 = all cores)");
    if (aOptions.mThreads > MaxThreads())
        throw Error("threads: " + std::to_string(aOptions.mThreads) + " is more than 4 per core (at most " + std::to_string(MaxThreads()) +
                    " here): more threads only cost memory and time");
    if (aOptions.mMinPathLength < 0) throw Error("min path length: must be >= 0");
    if (aOptions.mMaxPathLength < 1) throw Error("max path length: must be >= 1");
    if (aOptions.mMinPathLength > aOptions.mMaxPathLength) throw Error("min path length: must not exceed the max path length");
    if (!(aOptions.mRadiusFactor > 0.f) || !std::isfinite(aOptions.mRadiusFactor)) throw Error("radius factor: must be a finite number > 0");
    if (aOptions.mRadiusFactor > kMaxRadiusFactor)
        throw Error("radius factor: " + std::to_string(aOptions.mRadiusFactor) + " is above " + std::to_string(kMaxRadiusFactor) +
                    " (a merging radius that large blurs light across whole surfaces and makes every lookup visit most light vertices)");
    if (!(aOptions.mMediumRadiusFactor > 0.f) || !(aOptions.mMediumRadiusFactor <= kMaxRadiusFactor))
        throw Error("medium radius factor: must be a number in (0, " + std::to_string(kMaxRadiusFactor) + "]");
    if (!(aOptions.mBeamRadiusFactor > 0.f) || !(aOptions.mBeamRadiusFactor <= kMaxRadiusFactor))
        throw Error("beam radius factor: must be a number in (0, " + std::to_string(kMaxRadiusFactor) + "]");
    if (aOptions.mBeamPaths < 1) throw Error("beam paths: must be >= 1");
    if (aOptions.mUpbpTechniques == 0 || (aOptions.mUpbpTechniques & ~uint32_t(kUpbpAll)) != 0)
        throw Error("techniques: must be a non-empty subset of bpt,surf,pp3d,pb2d,bb1d");
    if (!(aOptions.mRadiusAlpha > 0.f && aOptions.mRadiusAlpha <= 1.f)) throw Error("radius alpha: must be in (0, 1]");
    if (aOptions.mPhotonCount < 1) throw Error("photon count: must be >= 1");
    if (aOptions.mNearestPhotons < 1) throw Error("nearest photons: must be >= 1");
    if (!(aOptions.mMaxPhotonRadiusFactor > 0.f) || !std::isfinite(aOptions.mMaxPhotonRadiusFactor))
        throw Error("max photon radius: must be a finite number > 0");
    if (aOptions.mMaxPhotonRadiusFactor > kMaxPhotonRadiusFactor)
        throw Error("max photon radius: must not exceed 1 (the scene's radius: a larger search finds nothing more)");
}

// The bytes Render touches for aThreads threads, roughly from above: per thread a film
// (double RGB per pixel, and per layer: with technique layers asked for, room for 64, as
// VertexCM's pyramid has up to 56) and what the integrator's mBytesPerRenderer says; once,
// the resolved images.
inline uint64_t EstimateRenderBytes(const Camera& aCamera, const RenderOptions& aOptions, const Integrator& aIntegrator,
                                    int aThreads) {
    const uint64_t pixels = uint64_t(aCamera.PixelCount());
    const uint64_t layers = aOptions.mTechniqueLayers ? 64 : 0;
    uint64_t perThread = pixels * sizeof(glm::dvec3) * (1 + layers);
    if (aIntegrator.mBytesPerRenderer) perThread += aIntegrator.mBytesPerRenderer(aCamera, aOptions);
    return perThread * uint64_t(aThreads) + pixels * sizeof(Vec3) * (1 + layers);
}
// The same for the built-in that aOptions.mAlgorithm names.
inline uint64_t EstimateRenderBytes(const Camera& aCamera, const RenderOptions& aOptions, int aThreads) {
    return EstimateRenderBytes(aCamera, aOptions, BuiltInIntegrator(aOptions.mAlgorithm), aThreads);
}

// The machine's physical memory in bytes (0 where it cannot be asked).
inline uint64_t PhysicalMemoryBytes() {
#if defined(__unix__) || defined(__APPLE__)
    const long pages = sysconf(_SC_PHYS_PAGES), pageSize = sysconf(_SC_PAGE_SIZE);
    if (pages > 0 && pageSize > 0) return uint64_t(pages) * uint64_t(pageSize);
#endif
    return 0;
}

// Throws Error when the render would need more than 3/4 of the machine's memory: one
// clear line before the first allocation instead of std::bad_alloc (or the OOM killer)
// in the middle.
inline void CheckRenderMemory(const Camera& aCamera, const RenderOptions& aOptions, const Integrator& aIntegrator,
                              int aThreads) {
    const uint64_t needed = EstimateRenderBytes(aCamera, aOptions, aIntegrator, aThreads);
    const uint64_t physical = PhysicalMemoryBytes();
    if (physical == 0 || needed <= physical / 4 * 3) return;
    auto gib = [](uint64_t aBytes) { return std::to_string(aBytes >> 30) + "." + std::to_string(((aBytes >> 20) & 1023) * 10 / 1024) + " GiB"; };
    throw Error("memory: " + std::to_string(aCamera.Width()) + "x" + std::to_string(aCamera.Height()) + " with " +
                aIntegrator.mName + " on " + std::to_string(aThreads) + " thread(s) needs about " + gib(needed) +
                ", more than 3/4 of this machine's " + gib(physical) + ": use fewer threads or a smaller resolution");
}
// The same for the built-in that aOptions.mAlgorithm names.
inline void CheckRenderMemory(const Camera& aCamera, const RenderOptions& aOptions, int aThreads) {
    CheckRenderMemory(aCamera, aOptions, BuiltInIntegrator(aOptions.mAlgorithm), aThreads);
}

// The random stream of one iteration: independent of thread count and order.
inline Rng IterationRng(uint64_t aSeed, int aIteration) {
    return Rng(SplitMix64(aSeed ^ SplitMix64(uint64_t(aIteration))), uint64_t(aIteration));
}
// The sampler of one iteration: the independent one draws from IterationRng.
inline Sampler IterationSampler(SamplerType aType, uint64_t aSeed, int aIteration) {
    return aType == SamplerType::kSobol ? Sampler::Sobol(aSeed, aIteration) : Sampler(IterationRng(aSeed, aIteration));
}

// Throws Error naming the integrator if its renderers' films cannot be summed: each must
// have the camera's size, and all the same layers (made in the constructor).
inline void CheckRendererFilms(const Integrator& aIntegrator, const Camera& aCamera,
                               const std::vector<std::unique_ptr<AbstractRenderer>>& aRenderers) {
    const Film& first = aRenderers[0]->GetFilm();
    for (const std::unique_ptr<AbstractRenderer>& renderer : aRenderers) {
        const Film& film = renderer->GetFilm();
        if (film.Width() != aCamera.Width() || film.Height() != aCamera.Height())
            throw Error("integrator '" + aIntegrator.mName + "': a renderer's film is " + std::to_string(film.Width()) + "x" +
                        std::to_string(film.Height()) + ", not the camera's " + std::to_string(aCamera.Width()) + "x" +
                        std::to_string(aCamera.Height()));
        bool sameLayers = film.LayerCount() == first.LayerCount();
        for (int l = 0; sameLayers && l < film.LayerCount(); l++) sameLayers = film.LayerName(l) == first.LayerName(l);
        if (!sameLayers)
            throw Error("integrator '" + aIntegrator.mName + "': its renderers' films have different layers (add them in the constructor)");
    }
}

namespace detail {

inline constexpr const char* kRenderOutOfMemory =
    "memory: out of memory while rendering (use fewer threads or a smaller resolution)";

// One renderer per thread, all made before any thread starts, and checked to have films
// that can be summed.
inline std::vector<std::unique_ptr<AbstractRenderer>> CreateRenderers(const Scene& aScene, const RenderOptions& aOptions,
                                                                      const Integrator& aIntegrator, int aThreadCount) {
    std::vector<std::unique_ptr<AbstractRenderer>> renderers;
    try {
        for (int t = 0; t < aThreadCount; t++) {
            renderers.push_back(aIntegrator.mCreateRenderer(aScene, aOptions));
            if (!renderers.back()) throw Error("integrator '" + aIntegrator.mName + "': mCreateRenderer returned no renderer");
        }
    } catch (const std::bad_alloc&) {
        throw Error(kRenderOutOfMemory);
    }
    CheckRendererFilms(aIntegrator, aScene.mCamera, renderers);
    return renderers;
}

// The iterations of one render, shared out to its threads: with an iteration budget
// thread t runs t, t + T, t + 2T, ...; with a time budget each takes the next one until
// the time is up. Every thread stops at a stop request or at the first failure.
class IterationSchedule {
public:
    using Clock = std::chrono::steady_clock;
    IterationSchedule(const RenderOptions& aOptions, int aThreadCount, Clock::time_point aStart)
        : mOptions(aOptions), mThreadCount(aThreadCount), mStart(aStart) {}

    double Elapsed() const { return std::chrono::duration<double>(Clock::now() - mStart).count(); }
    int Completed() const { return mCompleted.load(); }
    uint64_t Rays() const { return mRays.load(); }

    // Thread aThread's share, rendered with aRenderer; an exception stops every thread.
    void Work(int aThread, AbstractRenderer& aRenderer) {
        const uint64_t raysBefore = RayCounter();
        try {
            for (int k = 0;; k++) {
                const int iteration = NextIteration(aThread, k);
                if (iteration < 0) break;
                Sampler sampler = IterationSampler(mOptions.mSampler, mOptions.mSeed, iteration);
                aRenderer.RunIteration(iteration, sampler);
                mCompleted++;
            }
        } catch (const std::bad_alloc&) {
            if (!mFailed.exchange(true)) mFailure = kRenderOutOfMemory;
        } catch (const std::exception& e) {
            if (!mFailed.exchange(true)) mFailure = e.what();
        }
        mRays += RayCounter() - raysBefore;
    }

    // After every thread has ended: the first failure, as Error.
    void ThrowIfFailed() const {
        if (mFailed) throw Error(mFailure);
    }

private:
    // The k-th iteration of thread aThread, or -1 when it is to stop.
    int NextIteration(int aThread, int aK) {
        int iteration;
        if (mOptions.mSeconds > 0.0) {
            if (Elapsed() >= mOptions.mSeconds) return -1;
            iteration = mNextIteration.fetch_add(1);
        } else {
            iteration = aThread + aK * mThreadCount;
        }
        if (mOptions.mIterations > 0 && iteration >= mOptions.mIterations) return -1;
        if (mFailed || (mOptions.mStopRequested && mOptions.mStopRequested->load())) return -1;
        return iteration;
    }

    const RenderOptions& mOptions;
    const int mThreadCount;
    const Clock::time_point mStart;
    std::atomic<int> mNextIteration{0};
    std::atomic<int> mCompleted{0};
    std::atomic<uint64_t> mRays{0};
    std::atomic<bool> mFailed{false};
    std::string mFailure;
};

// A progress line on stderr from a watcher thread, only on a terminal and only once the
// render has taken longer than two seconds; erased when the render ends.
class ProgressLine {
public:
    ProgressLine(const RenderOptions& aOptions, const std::string& aName, const IterationSchedule& aSchedule) {
#if defined(__unix__) || defined(__APPLE__)
        if (!aOptions.mProgress || !isatty(2)) return;
        mWatcher = std::thread([this, &aOptions, &aName, &aSchedule] {
            bool printed = false;
            while (!mDone) {
                std::this_thread::sleep_for(std::chrono::milliseconds(250));
                if (mDone || aSchedule.Elapsed() < 2.0) continue;
                std::fprintf(stderr, "\r%s: iteration %d%s, %.1f s   ", aName.c_str(), aSchedule.Completed(),
                             aOptions.mIterations > 0 ? ("/" + std::to_string(aOptions.mIterations)).c_str() : "",
                             aSchedule.Elapsed());
                printed = true;
            }
            if (printed) std::fprintf(stderr, "\r%60s\r", "");
        });
#else
        (void)aOptions; (void)aName; (void)aSchedule;
#endif
    }
    ~ProgressLine() {
        mDone = true;
        if (mWatcher.joinable()) mWatcher.join();
    }
    ProgressLine(const ProgressLine&) = delete;
    ProgressLine& operator=(const ProgressLine&) = delete;

private:
    std::atomic<bool> mDone{false};
    std::thread mWatcher;
};

// The films summed in thread order (so the sum does not depend on timing) and divided by
// the iterations run: the image and its layers.
inline void ResolveFilms(std::vector<Film>& aFilms, RenderResult& ioResult) {
    Film& film = aFilms[0];
    for (size_t t = 1; t < aFilms.size(); t++) film.Accumulate(aFilms[t]);
    const double scale = ioResult.mIterations > 0 ? 1.0 / ioResult.mIterations : 0.0;
    ioResult.mImage = film.Resolve(scale);
    for (int l = 0; l < film.LayerCount(); l++) ioResult.mLayers.emplace_back(film.LayerName(l), film.Resolve(scale, l));
}

} // namespace detail

// Runs aIntegrator: one renderer per thread, the budget of aOptions, and the result.
inline RenderResult Render(const Scene& aScene, const RenderOptions& aOptions, const Integrator& aIntegrator) {
    ValidateRenderOptions(aOptions);
    if (!aIntegrator.mCreateRenderer) throw Error("integrator '" + aIntegrator.mName + "': has no mCreateRenderer");
    if (!aScene.IsFinalized()) throw Error("scene: Finalize() was not called");
    aScene.CheckUnchangedSinceFinalize();
    if (aScene.HasMedia() && !aIntegrator.mHandlesMedia)
        throw Error("integrator '" + aIntegrator.mName + "': the scene has participating media, which this integrator does not "
                    "trace (Integrator::mHandlesMedia is false); render it with pt, lt, ppm, bpm, bpt or vcm");
    const auto start = detail::IterationSchedule::Clock::now();

    int threadCount = aOptions.mThreads > 0 ? aOptions.mThreads : int(std::max(1u, std::thread::hardware_concurrency()));
    if (aOptions.mIterations > 0) threadCount = std::min(threadCount, aOptions.mIterations);
    CheckRenderMemory(aScene.mCamera, aOptions, aIntegrator, threadCount);
    std::vector<std::unique_ptr<AbstractRenderer>> renderers = detail::CreateRenderers(aScene, aOptions, aIntegrator, threadCount);

    // Each thread keeps its renderer's film and frees the rest (light vertices, grids) as
    // soon as its share is done: a thread that finishes first does it while the others
    // still render, not one renderer after another at the end.
    std::vector<Film> films(static_cast<size_t>(threadCount));
    detail::IterationSchedule schedule(aOptions, threadCount, start);
    const auto work = [&schedule, &renderers, &films](int aThread) {
        AbstractRenderer& renderer = *renderers[size_t(aThread)];
        schedule.Work(aThread, renderer);
        films[size_t(aThread)] = std::move(renderer.GetFilm());
        renderers[size_t(aThread)].reset();
    };
    {
        std::vector<std::thread> threads;
        for (int t = 1; t < threadCount; t++) threads.emplace_back(work, t);
        const detail::ProgressLine progress(aOptions, aIntegrator.mName, schedule);
        work(0);
        for (std::thread& thread : threads) thread.join();
    }
    schedule.ThrowIfFailed();

    RenderResult result;
    result.mIterations = schedule.Completed();
    result.mSeconds = schedule.Elapsed();
    result.mRays = schedule.Rays();
    result.mStopped = aOptions.mStopRequested && aOptions.mStopRequested->load();
    detail::ResolveFilms(films, result);
    return result;
}

// Runs the built-in that aOptions.mAlgorithm names.
inline RenderResult Render(const Scene& aScene, const RenderOptions& aOptions) {
    return Render(aScene, aOptions, BuiltInIntegrator(aOptions.mAlgorithm));
}

// =====================================================================================
// [SECTION] Image output and metrics
// =====================================================================================
// Provides: image metrics (mean, RMSE, relative MSE against a reference), the display
// mapping of PNGs (exposure and tone curve) and, compiled under SMALLVCM_IMPLEMENTATION,
// the writers: PNG (exposed, tone-mapped, sRGB-encoded), Radiance .hdr (RGBE, top row
// first as the format expects), PFM (exact floats, bottom row first as the PFM
// convention requires) and OpenEXR (exact floats, through Debian's tinyexr library, with
// optional named layers), plus readers of PFM, .hdr and OpenEXR. Every writer writes
// temporary files and renames them, so a failed write never leaves a partial image (nor
// half of a set of files written together) under the requested names.

// Average over pixels and channels.
inline double MeanValue(const Image& aImage) {
    double sum = 0.0;
    for (const Vec3& p : aImage.mPixels) sum += double(p.x) + double(p.y) + double(p.z);
    return aImage.mPixels.empty() ? 0.0 : sum / (3.0 * double(aImage.mPixels.size()));
}

inline void CheckSameSize(const Image& aImage, const Image& aReference) {
    if (aImage.mWidth != aReference.mWidth || aImage.mHeight != aReference.mHeight)
        throw Error("image metrics: the image is " + std::to_string(aImage.mWidth) + "x" + std::to_string(aImage.mHeight) +
                    " but the reference is " + std::to_string(aReference.mWidth) + "x" + std::to_string(aReference.mHeight));
}

// Root mean squared error over pixels and channels.
inline double Rmse(const Image& aImage, const Image& aReference) {
    CheckSameSize(aImage, aReference);
    double sum = 0.0;
    for (size_t i = 0; i < aImage.mPixels.size(); i++) {
        const glm::dvec3 d = glm::dvec3(aImage.mPixels[i]) - glm::dvec3(aReference.mPixels[i]);
        sum += glm::dot(d, d);
    }
    return std::sqrt(sum / (3.0 * double(std::max<size_t>(1, aImage.mPixels.size()))));
}

// Relative MSE: mean of (x - ref)^2 / (ref^2 + 0.01); the 0.01 keeps black pixels of
// the reference from dominating (a common choice in rendering papers).
inline double RelativeMse(const Image& aImage, const Image& aReference) {
    CheckSameSize(aImage, aReference);
    double sum = 0.0;
    for (size_t i = 0; i < aImage.mPixels.size(); i++)
        for (int c = 0; c < 3; c++) {
            const double reference = aReference.mPixels[i][c];
            const double difference = double(aImage.mPixels[i][c]) - reference;
            sum += difference * difference / (reference * reference + 0.01);
        }
    return sum / (3.0 * double(std::max<size_t>(1, aImage.mPixels.size())));
}

enum class ImageFormat { kUnknown, kPng, kHdr, kPfm, kExr };

// The format an image path asks for, by its extension in any case (.png, .PNG, ...).
inline ImageFormat ImageFormatOf(const std::string& aPath) {
    const size_t dot = aPath.find_last_of("./");
    if (dot == std::string::npos || aPath[dot] != '.' || dot == 0 || aPath[dot - 1] == '/') return ImageFormat::kUnknown;
    std::string extension = aPath.substr(dot + 1);
    for (char& c : extension) c = char(std::tolower(static_cast<unsigned char>(c)));
    if (extension == "png") return ImageFormat::kPng;
    if (extension == "hdr") return ImageFormat::kHdr;
    if (extension == "pfm") return ImageFormat::kPfm;
    if (extension == "exr") return ImageFormat::kExr;
    return ImageFormat::kUnknown;
}
inline bool IsSupportedImagePath(const std::string& aPath) { return ImageFormatOf(aPath) != ImageFormat::kUnknown; }

// How a PNG shows radiance. A PNG holds 8-bit sRGB values in [0, 1], so each channel is
// scaled by 2^exposure (EV, photographic stops), mapped into [0, 1] by the tone curve,
// then sRGB-encoded. HDR, PFM and EXR ignore these options: they keep linear radiance, as
// rendered, so that images can be measured, compared and merged.
//   kClamp  min(max(x, 0), 1). The default: at exposure 0 a PNG is byte for byte what it
//           was before these options existed.
//   kAces   a filmic curve with a toe and a soft shoulder, so bright lights and caustics
//           keep their shape instead of clipping to white (AcesFilmic below).
enum class ToneMap { kClamp, kAces };
inline constexpr float kMaxExposure = 32.f;  // 2^32: beyond that a float image has nothing left to show

struct ImageWriteOptions {
    float mExposure = 0.f;  // EV in [-kMaxExposure, kMaxExposure]: PNG value = tone(radiance * 2^EV)
    ToneMap mToneMap = ToneMap::kClamp;
};

inline const char* ToneMapName(ToneMap aToneMap) { return aToneMap == ToneMap::kAces ? "aces" : "clamp"; }
inline bool ParseToneMap(const std::string& aName, ToneMap& oToneMap) {
    for (ToneMap t : {ToneMap::kClamp, ToneMap::kAces})
        if (aName == ToneMapName(t)) { oToneMap = t; return true; }
    return false;
}

// Throws Error naming the option unless the exposure is a finite number of stops in range.
inline void ValidateImageWriteOptions(const ImageWriteOptions& aOptions) {
    if (!(aOptions.mExposure >= -kMaxExposure && aOptions.mExposure <= kMaxExposure))
        throw Error("exposure: must be a finite number of stops in [-32, 32]");
}

// K. Narkowicz, "ACES Filmic Tone Mapping Curve" (2016): a rational fit, per channel, of
// the ACES reference rendering and output transforms ODT(RRT(x)) for a Rec.709 display
// with its 2.4 gamma removed, pre-exposed so that 1 maps to about 0.8:
//     f(x) = x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14),  clamped to [0, 1].
// Its output is display-linear (sRGB encoding follows). f(0) = 0, f is increasing on
// x >= 0 and tends to 2.51 / 2.43 > 1, so it reaches 1 (white) at x of about 7.24.
inline float AcesFilmic(float aValue) {
    const float x = std::min(std::max(aValue, 0.f), 8.f);  // white from 7.24 on; 8 keeps x^2 from overflowing
    return std::min(x * (2.51f * x + 0.03f) / (x * (2.43f * x + 0.59f) + 0.14f), 1.f);
}

// The display-linear value in [0, 1] a PNG shows for aRadiance (before sRGB encoding).
inline float DisplayValue(float aRadiance, const ImageWriteOptions& aOptions) {
    const float exposed = aRadiance * std::exp2(aOptions.mExposure);  // exp2(0) is exactly 1
    return aOptions.mToneMap == ToneMap::kAces ? AcesFilmic(exposed) : std::min(std::max(exposed, 0.f), 1.f);
}

// One file of a set written together by WriteFilesTogether.
struct OutputFile {
    std::string mPath;
    std::vector<unsigned char> mBytes;
};

// The bytes of aImage in the format of aPath's extension (.png, .hdr, .pfm, .exr);
// aOptions apply to PNG only. Throws Error on failure.
std::vector<unsigned char> EncodeImage(const std::string& aPath, const Image& aImage, const ImageWriteOptions& aOptions = {});
// An image stored beside the main one in a multi-layer OpenEXR file. Its name is the
// prefix of its channels, NAME.R, NAME.G, NAME.B (OpenEXR's naming of layers, "Technical
// Introduction to OpenEXR", Layers): 1 to 250 bytes, no control characters.
struct ExrLayer {
    std::string mName;
    const Image* mImage = nullptr;
};
// The bytes of an OpenEXR file (one part, scanlines, ZIP compression, which is lossless)
// holding aImage as the channels R, G, B and each of aLayers as NAME.R, NAME.G, NAME.B,
// every channel 32-bit float: the values are kept bit for bit, as in a PFM. The layers
// must have aImage's size and distinct names. Throws Error naming aPath on failure.
std::vector<unsigned char> EncodeExr(const std::string& aPath, const Image& aImage, const std::vector<ExrLayer>& aLayers = {});
// Writes every file, or none. Each file's bytes go to a new temporary file of a unique
// name in its folder (created exclusively: never an existing file, never through a
// symlink); once all are complete they are renamed onto their paths, each in one step.
// If a write or a rename fails, the temporaries are removed and so are the new files
// already renamed into place: no new file of the set remains (an old file that a rename
// had already replaced is gone too). Two programs writing the same paths each leave
// complete files. SIGINT, SIGTERM and SIGHUP are held back on the calling thread while
// temporary files exist, so a signal cannot leave one behind. Throws Error naming the file.
void WriteFilesTogether(const std::vector<OutputFile>& aFiles);
// Writes .png, .hdr, .pfm or .exr by the file's extension (WriteFilesTogether with one file):
// aPath holds the old file or the whole new image. Throws Error on failure.
void WriteImage(const std::string& aPath, const Image& aImage, const ImageWriteOptions& aOptions = {});
// Throws Error naming aPath unless an image can be written there: a known extension, an
// existing folder in which files can be created, and no directory of that name. Call it
// before a long render; it leaves nothing behind.
void CheckOutputPath(const std::string& aPath);
// The readers below take aMaxPixels, a bound on width x height checked from the header,
// before the pixels are allocated or decoded (by default the largest image they read).
inline constexpr uint64_t kMaxReadPixels = uint64_t(65536) * 65536;
// Reads a PFM written by WriteImage (or any 3-channel PFM). Throws Error on failure.
Image ReadPfm(const std::string& aPath, uint64_t aMaxPixels = kMaxReadPixels);
// Reads a Radiance .hdr in RGBE (flat or run-length encoded scanlines, -Y H +X W), as
// WriteImage writes it: each value to within 1/256 of itself. Throws Error on failure.
Image ReadHdr(const std::string& aPath, uint64_t aMaxPixels = kMaxReadPixels);
// Reads the channels R, G, B of an OpenEXR file (aLayer empty), or those of the layer
// aLayer, NAME.R, NAME.G, NAME.B; half floats are converted to float exactly, any other
// channel (A, other layers) is ignored. Only single-part scanline files whose data window
// is the whole image (the display window) are read, of at most 65536x65536 pixels whose
// channels take at most 4 GiB once decoded (tinyexr decodes every channel of the file at
// once: a few bytes of header must not make it allocate more); a luminance-only (Y)
// image is refused, not converted. Throws Error naming aPath and the problem.
Image ReadExr(const std::string& aPath, const std::string& aLayer = "", uint64_t aMaxPixels = kMaxReadPixels);
// Reads linear radiance from a .pfm, .hdr or .exr (its R, G, B), by the extension in any
// case; a .png is refused (its values are exposed, tone-mapped and 8-bit: not radiance).
Image ReadImage(const std::string& aPath, uint64_t aMaxPixels = kMaxReadPixels);
// An environment map from an equirectangular .hdr, .exr or .pfm (read as ReadImage reads
// it) of at most kMaxEnvironmentMapWidth x kMaxEnvironmentMapWidth / 2 texels, checked
// before the pixels are decoded, turned by aRotationDegrees about +Y (EnvironmentMap states
// the mapping). Throws Error naming aPath and the problem.
inline constexpr int kMaxEnvironmentMapWidth = 8192;
std::shared_ptr<const EnvironmentMap> LoadEnvironmentMap(const std::string& aPath, float aRotationDegrees = 0.f);

// =====================================================================================
// [SECTION] Scene loading (glTF)
// =====================================================================================
// Provides: LoadGltfScene, which reads the subset of glTF 2.0 documented in
// docs/scene_format.md (triangle meshes, spheres and a background by our SMALLVCM_*
// extensions, KHR_lights_punctual, emissive materials, participating media by
// KHR_materials_volume and SMALLVCM_medium, one perspective camera) into a
// finalized Scene. Anything outside the subset throws Error naming the file and the
// feature: a scene is never silently rendered differently from what the file says.
// Compiled under SMALLVCM_IMPLEMENTATION (it needs tinygltf).

struct GltfLoadReport {
    int mSkippedDegenerateTriangles = 0;  // zero-area triangles, dropped
    std::string mCamera;                  // which camera: "camera 0 'Name'", or "a default camera ..."
    bool mDefaultCamera = false;          // the file has no camera: one frames the scene
    bool mInteriorCamera = false;         // ... and, as the scene is an interior, stands inside it
    bool mDefaultBackground = false;      // the file has no emitter: the default sky and sun were added
    std::vector<std::string> mNotes;      // what was approximated, ignored or looks wrong, one line each
    // Where the loading time went (wall clock): reading (the file, its JSON, buffers and
    // images, the triangles, lights and camera) and Scene::Finalize (validation, light
    // sampling data and the BVH build, which dominates it for large meshes).
    double mReadSeconds = 0.0, mFinalizeSeconds = 0.0;
};

// What a scene file may make the loader read. A scene is an untrusted document: every
// URI must name a regular file inside mResourceRoot (after resolving ".." and symlinks),
// and no file, nor all of them together, may exceed the byte limits (checked before a
// byte is read). docs/testing.md states the whole threat model.
struct GltfLoadOptions {
    std::string mResourceRoot;                  // "" = the folder of the scene file
    uint64_t mMaxFileBytes = uint64_t(1) << 30;  // the scene file, and each file it names
    uint64_t mMaxTotalBytes = uint64_t(4) << 30; // the scene file and its files together
    // Which camera: the N-th camera node met in the scene's depth-first walk (-1: the first,
    // or, when the file has none, a default camera that frames the scene's bounding box
    // from the front (+Z) and a little above, or stands inside an interior (one whose
    // geometry encloses the box's centre), for images of mDefaultCameraAspect = W / H).
    int mCamera = -1;
    float mDefaultCameraAspect = 1.f;
    // The background light: the file's (kFromFile: and, when the file has no emitter at
    // all, the default sky and sun, AddDefaultSkyAndSun, so a model without lights still
    // renders and shows its shape), none, or mBackgroundRadiance replacing the file's.
    enum class Background { kFromFile, kNone, kRadiance };
    Background mBackground = Background::kFromFile;
    Vec3 mBackgroundRadiance{1.f};
    // An environment map (LoadEnvironmentMap: an equirectangular .hdr, .exr or .pfm) that
    // replaces the file's background and the default sky and sun; its radiance is scaled
    // by mEnvironmentScale. It goes with mBackground = kFromFile only.
    std::string mEnvironmentMap;
    float mEnvironmentRotationDegrees = 0.f;
    float mEnvironmentScale = 1.f;
    // With mReplaceSceneMedium, mSceneMedium fills all space outside every closed mesh
    // (Scene::mSceneMedium) instead of the file's scene medium (SMALLVCM_medium on the
    // scene, or none). Scene::Finalize, at the end of loading, validates it.
    bool mReplaceSceneMedium = false;
    Medium mSceneMedium;
};

// The light a file without one gets (GltfLoadOptions::Background::kFromFile): a neutral
// sky, brighter at the horizon than at the zenith, over a darker ground (an environment
// map, so the sky seen behind the model is not white and a white model stands out from
// it), and a sun, a directional light from 50 degrees above the horizon and 40 degrees
// to the left of straight behind aCamera, so that the faces a camera sees differ in
// brightness and cast shadows it can see. Sky radiance 0.2-0.6, sun irradiance 3: the
// sunlit side of a white surface is about twice as bright as its shaded side.
void AddDefaultSkyAndSun(Scene& aScene, const Camera& aCamera);

Scene LoadGltfScene(const std::string& aPath, GltfLoadReport* oReport = nullptr, const GltfLoadOptions& aOptions = {});

} // namespace smallvcm

#endif // SMALLVCM_HPP

// =====================================================================================
// [SECTION] Implementation (SMALLVCM_IMPLEMENTATION)
// =====================================================================================
#if defined(SMALLVCM_IMPLEMENTATION) && !defined(SMALLVCM_IMPLEMENTATION_DONE)
#define SMALLVCM_IMPLEMENTATION_DONE

// The heavy dependencies, configured identically wherever they are included.
#define TINYGLTF_IMPLEMENTATION
#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#define TINYGLTF_NO_INCLUDE_STB_IMAGE
#define TINYGLTF_NO_INCLUDE_STB_IMAGE_WRITE
#include <tiny_gltf.h>
#define STB_IMAGE_WRITE_STATIC
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb/stb_image_write.h>
#define STB_IMAGE_STATIC
#define STB_IMAGE_IMPLEMENTATION
#define STBI_ONLY_PNG   // the two image formats glTF 2.0 allows
#define STBI_ONLY_JPEG
#include <stb/stb_image.h>
// Debian's libtinyexr-dev is a compiled library (libtinyexr.so, which brings its own zlib):
// the header only declares it, so no TINYEXR_IMPLEMENTATION here; programs link -ltinyexr.
#include <tinyexr.h>
// The decoders of compressed glTF geometry, Debian's compiled libraries (libdraco-dev,
// libmeshoptimizer-dev): programs link -ldraco -lmeshoptimizer.
#include <draco/compression/decode.h>
#include <meshoptimizer.h>

#include <cctype>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <map>
#include <new>
#include <optional>
#include <set>
#include <sstream>
#include <unordered_map>

#include <csignal>
#include <fcntl.h>
#include <pthread.h>
#include <sys/stat.h>
#include <unistd.h>

namespace smallvcm {
namespace detail {

// Holds back the signals that end a program (SIGINT, SIGTERM, SIGHUP) on this thread
// while it lives; one that arrives meanwhile is delivered when it ends.
class SignalsHeldBack {
public:
    SignalsHeldBack() {
        sigset_t held;
        sigemptyset(&held);
        sigaddset(&held, SIGINT);
        sigaddset(&held, SIGTERM);
        sigaddset(&held, SIGHUP);
        pthread_sigmask(SIG_BLOCK, &held, &mPrevious);
    }
    ~SignalsHeldBack() { pthread_sigmask(SIG_SETMASK, &mPrevious, nullptr); }
    SignalsHeldBack(const SignalsHeldBack&) = delete;
    SignalsHeldBack& operator=(const SignalsHeldBack&) = delete;
private:
    sigset_t mPrevious;
};

// Creates a new file "aPath.XXXXXXXX.partial" that did not exist (O_EXCL: an existing
// name or a symlink planted there is never opened) and returns its descriptor and name.
inline int CreateUniqueTemporary(const std::string& aPath, std::string& oName) {
    static std::atomic<uint64_t> counter{0};
    const uint64_t seed = uint64_t(std::chrono::steady_clock::now().time_since_epoch().count()) ^ (uint64_t(::getpid()) << 32);
    for (int attempt = 0; attempt < 64; attempt++) {
        uint64_t bits = SplitMix64(seed + counter.fetch_add(1));
        char suffix[9];
        for (int i = 0; i < 8; i++, bits >>= 5) suffix[i] = "abcdefghijklmnopqrstuvwxyz234567"[bits & 31];
        suffix[8] = '\0';
        oName = aPath + "." + suffix + ".partial";
        const int fd = ::open(oName.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0666);
        if (fd >= 0 || errno != EEXIST) return fd;
    }
    errno = EEXIST;
    return -1;
}

// Writes aBytes to a new unique temporary file next to aPath and returns its name; on
// failure removes it and throws Error naming aPath. The caller holds signals back.
inline std::string WriteTemporary(const std::string& aPath, const std::vector<unsigned char>& aBytes) {
    std::string temporary;
    const int fd = CreateUniqueTemporary(aPath, temporary);
    if (fd < 0) throw Error(aPath + ": cannot create a file next to it (" + std::strerror(errno) + ")");
    size_t written = 0;
    while (written < aBytes.size()) {
        const ssize_t count = ::write(fd, aBytes.data() + written, aBytes.size() - written);
        if (count < 0 && errno == EINTR) continue;
        if (count <= 0) break;
        written += size_t(count);
    }
    const bool closed = ::close(fd) == 0;
    if (written != aBytes.size() || !closed) {
        ::unlink(temporary.c_str());
        throw Error(aPath + ": write failed (disk full?)");
    }
    return temporary;
}

inline void AppendBytes(void* aContext, void* aData, int aSize) {
    auto* bytes = static_cast<std::vector<unsigned char>*>(aContext);
    const auto* data = static_cast<const unsigned char*>(aData);
    bytes->insert(bytes->end(), data, data + aSize);
}

// The sRGB transfer function (IEC 61966-2-1).
inline float LinearToSrgb(float aValue) {
    aValue = std::min(std::max(aValue, 0.f), 1.f);
    return aValue <= 0.0031308f ? 12.92f * aValue : 1.055f * std::pow(aValue, 1.f / 2.4f) - 0.055f;
}

inline bool EndsWithIgnoringCase(const std::string& aText, const std::string& aSuffix) {
    if (aText.size() < aSuffix.size()) return false;
    for (size_t i = 0; i < aSuffix.size(); i++)
        if (std::tolower(static_cast<unsigned char>(aText[aText.size() - aSuffix.size() + i])) != std::tolower(static_cast<unsigned char>(aSuffix[i])))
            return false;
    return true;
}

// tinyexr's error message, which may span lines, as one line of at most 160 characters;
// frees it (tinyexr allocates it).
inline std::string TinyexrMessage(const char* aMessage) {
    std::string line;
    for (const char* c = aMessage; c && *c && line.size() < 160; c++) {
        const bool control = static_cast<unsigned char>(*c) < 0x20 || *c == 0x7f;
        if (!control) line += *c;
        else if (!line.empty() && line.back() != ' ') line += ' ';
    }
    FreeEXRErrorMessage(aMessage);
    while (!line.empty() && line.back() == ' ') line.pop_back();
    return line.empty() ? std::string("no details") : line;
}

// The value of the "type" attribute of a single-part OpenEXR file's header ("" if it has
// none). tinyexr 1.0.1 stops the program (a failed assert) on a type other than the four
// OpenEXR defines, or one the version field contradicts, so the reader checks it first.
// The attributes are walked as tinyexr walks them: each is a name, a type name (both
// NUL-terminated), a 4-byte little-endian size and the value, and an empty name ends the
// header (OpenEXR File Layout, Header). Where the walk stops early tinyexr's parse fails too.
inline std::string ExrTypeAttribute(const std::vector<unsigned char>& aBytes) {
    std::string type;
    size_t position = 8;  // after the magic number and the version field
    for (int attribute = 0; attribute < 1024 && position < aBytes.size() && aBytes[position] != 0; attribute++) {
        std::string strings[2];  // the attribute's name and its type's name
        for (std::string& text : strings) {
            const auto end = std::find(aBytes.begin() + long(position), aBytes.end(), 0);
            if (end == aBytes.end()) return type;
            text.assign(aBytes.begin() + long(position), end);
            position = size_t(end - aBytes.begin()) + 1;
        }
        if (aBytes.size() - position < 4) return type;
        uint32_t size;
        std::memcpy(&size, &aBytes[position], 4);  // little endian, as the machines we build on
        position += 4;
        if (aBytes.size() - position < size) return type;
        if (strings[0] == "type" && size > 0 && aBytes[position] != 0) {
            const auto begin = aBytes.begin() + long(position);
            type.assign(begin, std::find(begin, begin + long(size), 0));
        }
        position += size;
    }
    return type;
}

// Refuses an image of more than aMaxPixels pixels, before its pixels are read.
inline void CheckPixelCount(const std::string& aPath, int64_t aWidth, int64_t aHeight, uint64_t aMaxPixels) {
    if (uint64_t(aWidth) * uint64_t(aHeight) > aMaxPixels)
        throw Error(aPath + ": " + std::to_string(aWidth) + "x" + std::to_string(aHeight) + " pixels, more than the " +
                    std::to_string(aMaxPixels) + " read here");
}

// The bytes of the regular file aPath; one larger than aMaxBytes is refused with
// aTooLarge before a byte is read.
inline std::vector<unsigned char> ReadImageFile(const std::string& aPath, uint64_t aMaxBytes, const std::string& aTooLarge) {
    struct stat info;
    if (::stat(aPath.c_str(), &info) != 0) throw Error(aPath + ": cannot open (" + std::strerror(errno) + ")");
    if (!S_ISREG(info.st_mode)) throw Error(aPath + ": not a regular file");
    if (uint64_t(info.st_size) > aMaxBytes) throw Error(aPath + ": " + aTooLarge);
    std::ifstream file(aPath, std::ios::binary);
    if (!file) throw Error(aPath + ": cannot open");
    return std::vector<unsigned char>((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
}

} // namespace detail

void CheckOutputPath(const std::string& aPath) {
    if (!IsSupportedImagePath(aPath)) throw Error(aPath + ": unknown image format (use .png, .hdr, .pfm or .exr)");
    struct stat info;
    if (::stat(aPath.c_str(), &info) == 0 && S_ISDIR(info.st_mode)) throw Error(aPath + ": is a directory");
    const std::filesystem::path parent = std::filesystem::path(aPath).parent_path();
    const std::string folder = parent.empty() ? std::string(".") : parent.string();
    if (::stat(folder.c_str(), &info) != 0) throw Error(aPath + ": the folder " + folder + " does not exist");
    if (!S_ISDIR(info.st_mode)) throw Error(aPath + ": " + folder + " is not a folder");
    // The one sure test of "can a file be made here": make one, exclusively, and remove it.
    const detail::SignalsHeldBack held;
    std::string probe;
    const int fd = detail::CreateUniqueTemporary(aPath, probe);
    if (fd < 0) throw Error(aPath + ": cannot write here (" + std::strerror(errno) + ")");
    ::close(fd);
    ::unlink(probe.c_str());
}

void WriteFilesTogether(const std::vector<OutputFile>& aFiles) {
    const detail::SignalsHeldBack held;
    std::vector<std::string> temporaries;
    try {
        for (const OutputFile& file : aFiles) temporaries.push_back(detail::WriteTemporary(file.mPath, file.mBytes));
    } catch (const Error&) {
        for (const std::string& temporary : temporaries) ::unlink(temporary.c_str());
        throw;
    }
    for (size_t i = 0; i < aFiles.size(); i++) {
        if (std::rename(temporaries[i].c_str(), aFiles[i].mPath.c_str()) == 0) continue;
        const int renameError = errno;
        for (size_t k = 0; k < i; k++) ::unlink(aFiles[k].mPath.c_str());  // ours: renamed a moment ago
        for (size_t k = i; k < aFiles.size(); k++) ::unlink(temporaries[k].c_str());
        throw Error(aFiles[i].mPath + ": cannot put the file in place (" + std::strerror(renameError) + ")");
    }
}

std::vector<unsigned char> EncodeImage(const std::string& aPath, const Image& aImage, const ImageWriteOptions& aOptions) {
    if (aImage.mWidth <= 0 || aImage.mHeight <= 0) throw Error(aPath + ": the image is empty");
    ValidateImageWriteOptions(aOptions);
    std::vector<unsigned char> bytes;
    const ImageFormat format = ImageFormatOf(aPath);
    if (format == ImageFormat::kPng) {
        std::vector<unsigned char> pixels(aImage.mPixels.size() * 3);
        for (size_t i = 0; i < aImage.mPixels.size(); i++)
            for (int c = 0; c < 3; c++) {
                const float display = DisplayValue(aImage.mPixels[i][c], aOptions);
                pixels[3 * i + size_t(c)] = (unsigned char)(detail::LinearToSrgb(display) * 255.f + 0.5f);
            }
        if (!stbi_write_png_to_func(detail::AppendBytes, &bytes, aImage.mWidth, aImage.mHeight, 3, pixels.data(), aImage.mWidth * 3))
            throw Error(aPath + ": PNG encoding failed");
    } else if (format == ImageFormat::kHdr) {
        if (!stbi_write_hdr_to_func(detail::AppendBytes, &bytes, aImage.mWidth, aImage.mHeight, 3, &aImage.mPixels[0].x))
            throw Error(aPath + ": HDR encoding failed");
    } else if (format == ImageFormat::kPfm) {
        // PFM: "PF", size, scale (negative = little endian), rows bottom to top.
        // A row of Vec3 is the row's floats in PFM's order, copied whole into bytes sized once.
        static_assert(sizeof(Vec3) == 3 * sizeof(float), "a Vec3 is three packed floats");
        const std::string header = "PF\n" + std::to_string(aImage.mWidth) + " " + std::to_string(aImage.mHeight) + "\n-1\n";
        const size_t rowBytes = size_t(aImage.mWidth) * sizeof(Vec3);
        bytes.resize(header.size() + rowBytes * size_t(aImage.mHeight));
        std::memcpy(bytes.data(), header.data(), header.size());
        unsigned char* out = bytes.data() + header.size();
        for (int y = aImage.mHeight - 1; y >= 0; y--, out += rowBytes)
            std::memcpy(out, &aImage.At(0, y), rowBytes);  // the machines we build on are little endian
    } else if (format == ImageFormat::kExr) {
        bytes = EncodeExr(aPath, aImage);
    } else {
        throw Error(aPath + ": unknown image format (use .png, .hdr, .pfm or .exr)");
    }
    return bytes;
}

std::vector<unsigned char> EncodeExr(const std::string& aPath, const Image& aImage, const std::vector<ExrLayer>& aLayers) {
    if (aImage.mWidth <= 0 || aImage.mHeight <= 0) throw Error(aPath + ": the image is empty");
    // One plane of floats per channel, as tinyexr takes them. OpenEXR keeps a file's
    // channels sorted by name, and its pixel data in that order (OpenEXR File Layout, the
    // "channels" attribute): readers that sort the list must find the data where they expect it.
    std::map<std::string, std::vector<float>> channels;
    auto addChannels = [&](const std::string& aPrefix, const Image& aSource) {
        for (int c = 0; c < 3; c++) {
            std::vector<float>& plane = channels[aPrefix + "RGB"[c]];
            plane.resize(aSource.mPixels.size());
            for (size_t i = 0; i < aSource.mPixels.size(); i++) plane[i] = aSource.mPixels[i][c];
        }
    };
    addChannels("", aImage);
    std::set<std::string> names;
    for (const ExrLayer& layer : aLayers) {
        const bool printable = std::none_of(layer.mName.begin(), layer.mName.end(), [](char c) {
            return static_cast<unsigned char>(c) < 0x20 || c == 0x7f;
        });
        if (layer.mName.empty() || layer.mName.size() > 250 || !printable)
            throw Error(aPath + ": the layer name '" + layer.mName.substr(0, 64) + "' is not 1 to 250 printable bytes");
        if (!names.insert(layer.mName).second) throw Error(aPath + ": two layers are named '" + layer.mName.substr(0, 64) + "'");
        if (!layer.mImage || layer.mImage->mWidth != aImage.mWidth || layer.mImage->mHeight != aImage.mHeight)
            throw Error(aPath + ": the layer '" + layer.mName.substr(0, 64) + "' is not the image's size");
        addChannels(layer.mName + ".", *layer.mImage);
    }
    std::vector<EXRChannelInfo> infos(channels.size());
    std::vector<int> pixelTypes(channels.size(), TINYEXR_PIXELTYPE_FLOAT);
    std::vector<unsigned char*> planes;
    bool longNames = false;
    size_t c = 0;
    for (auto& [name, plane] : channels) {
        std::memset(&infos[c], 0, sizeof(EXRChannelInfo));
        std::memcpy(infos[c].name, name.c_str(), name.size() + 1);
        infos[c].pixel_type = TINYEXR_PIXELTYPE_FLOAT;
        infos[c].x_sampling = infos[c].y_sampling = 1;
        planes.push_back(reinterpret_cast<unsigned char*>(plane.data()));
        longNames = longNames || name.size() > 31;  // the version field's long-names flag (OpenEXR File Layout)
        c++;
    }
    EXRHeader header;
    InitEXRHeader(&header);
    header.num_channels = int(infos.size());
    header.channels = infos.data();
    header.pixel_types = pixelTypes.data();            // what the planes hold
    header.requested_pixel_types = pixelTypes.data();  // what the file stores
    header.compression_type = TINYEXR_COMPRESSIONTYPE_ZIP;
    header.long_name = longNames ? 1 : 0;
    EXRImage image;
    InitEXRImage(&image);
    image.images = planes.data();
    image.width = aImage.mWidth;
    image.height = aImage.mHeight;
    image.num_channels = int(planes.size());
    // The header and image point into the vectors above, which free them: no FreeEXRHeader
    // or FreeEXRImage here. tinyexr mallocs the file's bytes and its message.
    unsigned char* memory = nullptr;
    const char* message = nullptr;
    const size_t size = SaveEXRImageToMemory(&image, &header, &memory, &message);
    if (size == 0 || !memory) {
        const std::string problem = detail::TinyexrMessage(message);
        std::free(memory);
        throw Error(aPath + ": OpenEXR encoding failed (tinyexr: " + problem + ")");
    }
    std::vector<unsigned char> bytes(memory, memory + size);
    std::free(memory);
    return bytes;
}

void WriteImage(const std::string& aPath, const Image& aImage, const ImageWriteOptions& aOptions) {
    WriteFilesTogether({{aPath, EncodeImage(aPath, aImage, aOptions)}});
}

Image ReadPfm(const std::string& aPath, uint64_t aMaxPixels) {
    std::ifstream file(aPath, std::ios::binary);
    if (!file) throw Error(aPath + ": cannot open");
    std::string magic;
    int width = 0, height = 0;
    double scale = 0.0;
    file >> magic >> width >> height >> scale;
    if (magic != "PF" || width <= 0 || height <= 0 || scale >= 0.0 || width > 65536 || height > 65536)
        throw Error(aPath + ": not a little-endian 3-channel PFM file");
    detail::CheckPixelCount(aPath, width, height, aMaxPixels);
    file.get();  // the single whitespace after the header
    // Before allocating: a few bytes must not claim gigabytes of pixels.
    const std::streampos pixelsStart = file.tellg();
    file.seekg(0, std::ios::end);
    if (!file || file.tellg() - pixelsStart < std::streamoff(12) * width * height) throw Error(aPath + ": the file is truncated");
    file.seekg(pixelsStart);
    Image image(width, height);
    for (int y = height - 1; y >= 0; y--)
        for (int x = 0; x < width; x++)
            for (int c = 0; c < 3; c++) {
                float value;
                if (!file.read(reinterpret_cast<char*>(&value), 4)) throw Error(aPath + ": the file is truncated");
                image.At(x, y)[c] = value;
            }
    return image;
}

Image ReadHdr(const std::string& aPath, uint64_t aMaxPixels) {
    const std::vector<unsigned char> bytes =
        detail::ReadImageFile(aPath, uint64_t(1) << 34, "larger than any .hdr of at most 65536x65536 pixels");
    const Error notRgbe(aPath + ": not a Radiance RGBE .hdr file");
    // The header: "#?RADIANCE" (or "#?RGBE"), lines of variables, an empty line, then the
    // resolution line; only the orientation writers use, top row first: "-Y H +X W".
    size_t position = 0;
    auto nextLine = [&](std::string& oLine) {
        const size_t end = std::find(bytes.begin() + long(position), bytes.begin() + long(std::min(bytes.size(), position + 4096)), '\n') - bytes.begin();
        if (end >= bytes.size() || bytes[end] != '\n') throw notRgbe;
        oLine.assign(bytes.begin() + long(position), bytes.begin() + long(end));
        position = end + 1;
    };
    std::string line;
    nextLine(line);
    if (line != "#?RADIANCE" && line != "#?RGBE") throw notRgbe;
    for (int lines = 0;; lines++) {
        nextLine(line);
        if (line.empty()) break;
        if (lines > 256) throw notRgbe;
        if (line.rfind("FORMAT=", 0) == 0 && line != "FORMAT=32-bit_rle_rgbe")
            throw Error(aPath + ": " + line.substr(0, 40) + " is not supported (only FORMAT=32-bit_rle_rgbe)");
    }
    nextLine(line);
    std::istringstream resolution(line);
    std::string yAxis, xAxis, rest;
    int width = 0, height = 0;
    resolution >> yAxis >> height >> xAxis >> width;
    if (!resolution || yAxis != "-Y" || xAxis != "+X" || (resolution >> rest) || width < 1 || height < 1 || width > 65536 || height > 65536)
        throw Error(aPath + ": only the resolution line '-Y H +X W' with sizes in [1, 65536] is supported");
    detail::CheckPixelCount(aPath, width, height, aMaxPixels);
    // Before allocating: a scanline takes at least 4 bytes plus 2 per 127 pixels per channel.
    if (uint64_t(bytes.size() - position) < uint64_t(height) * (4 + 8 * (uint64_t(width) / 127))) throw Error(aPath + ": the file is truncated");
    const Error corrupt(aPath + ": the pixel data is truncated or corrupt");
    Image image(width, height);
    std::vector<unsigned char> scanline(size_t(width) * 4);
    for (int y = 0; y < height; y++) {
        const bool runLengthEncoded = width >= 8 && width < 32768 && position + 4 <= bytes.size() && bytes[position] == 2 &&
                                      bytes[position + 1] == 2 && ((bytes[position + 2] << 8) | bytes[position + 3]) == width;
        if (runLengthEncoded) {
            // Each channel in turn: a count byte c > 128 repeats the next byte c - 128
            // times, otherwise the next c bytes are literal.
            position += 4;
            for (int c = 0; c < 4; c++)
                for (int x = 0; x < width;) {
                    if (position >= bytes.size()) throw corrupt;
                    const int count = bytes[position++];
                    const bool run = count > 128;
                    const int length = run ? count - 128 : count;
                    if (length == 0 || length > width - x || position + (run ? 1 : size_t(length)) > bytes.size()) throw corrupt;
                    for (int k = 0; k < length; k++, x++) scanline[4 * size_t(x) + size_t(c)] = bytes[run ? position : position + size_t(k)];
                    position += run ? 1 : size_t(length);
                }
        } else {
            if (position + scanline.size() > bytes.size()) throw corrupt;
            std::copy(bytes.begin() + long(position), bytes.begin() + long(position + scanline.size()), scanline.begin());
            position += scanline.size();
        }
        // RGBE to float as Radiance's colr_color does: (mantissa + 1/2) 2^(exponent - 136),
        // the middle of the interval the writer's truncation mapped the value into.
        for (int x = 0; x < width; x++) {
            const unsigned char* rgbe = &scanline[4 * size_t(x)];
            const float scale = rgbe[3] == 0 ? 0.f : std::ldexp(1.f, int(rgbe[3]) - 136);
            for (int c = 0; c < 3; c++) image.At(x, y)[c] = scale == 0.f ? 0.f : (float(rgbe[c]) + 0.5f) * scale;
        }
    }
    return image;
}

Image ReadExr(const std::string& aPath, const std::string& aLayer, uint64_t aMaxPixels) {
    // The file is read whole, so its size is bounded first, as the .hdr reader bounds it.
    const std::vector<unsigned char> bytes = detail::ReadImageFile(aPath, uint64_t(1) << 34, "larger than 16 GiB: not read as an OpenEXR file");
    auto fail = [&](const std::string& aProblem) { return Error(aPath + ": " + aProblem); };
    // The version field (magic number and flags) first, then the header; both are parsed
    // from the bytes without allocating pixels, so every bound below holds before tinyexr
    // allocates the image.
    EXRVersion version;
    if (ParseEXRVersionFromMemory(&version, bytes.data(), bytes.size()) != TINYEXR_SUCCESS)
        throw fail(bytes.size() >= 4 && bytes[0] == 0x76 && bytes[1] == 0x2f && bytes[2] == 0x31 && bytes[3] == 0x01
                       ? "the OpenEXR version field is truncated or unknown" : "not an OpenEXR file (no OpenEXR magic number)");
    if (version.multipart) throw fail("a multi-part OpenEXR file: only single-part files are read");
    if (version.non_image) throw fail("a deep OpenEXR file: only flat images are read");
    if (version.tiled) throw fail("a tiled OpenEXR file: only scanline files are read");
    const std::string type = detail::ExrTypeAttribute(bytes);
    if (!type.empty() && type != "scanlineimage") {
        std::string shown;
        for (char c : type.substr(0, 40)) shown += static_cast<unsigned char>(c) < 0x20 || c == 0x7f ? '?' : c;
        throw fail("its type attribute is '" + shown + "': only scanline images are read");
    }
    struct HeaderOwner {
        EXRHeader mHeader;
        HeaderOwner() { InitEXRHeader(&mHeader); }
        ~HeaderOwner() { FreeEXRHeader(&mHeader); }
    } owner;
    EXRHeader& header = owner.mHeader;
    const char* headerMessage = nullptr;
    const int parsed = ParseEXRHeaderFromMemory(&header, &version, bytes.data(), bytes.size(), &headerMessage);
    if (parsed == TINYEXR_ERROR_UNSUPPORTED_FORMAT || parsed == TINYEXR_ERROR_UNSUPPORTED_FEATURE)
        throw fail("uses what tinyexr does not read; the compressions read are none, RLE, ZIPS, ZIP and PIZ (tinyexr: " +
                   detail::TinyexrMessage(headerMessage) + ")");
    if (parsed != TINYEXR_SUCCESS)
        throw fail("its OpenEXR header is truncated or invalid (tinyexr: " + detail::TinyexrMessage(headerMessage) + ")");
    FreeEXRErrorMessage(headerMessage);
    if (header.tiled) throw fail("a tiled OpenEXR file: only scanline files are read");
    const EXRBox2i& data = header.data_window;
    const EXRBox2i& display = header.display_window;
    const int64_t width = int64_t(data.max_x) - int64_t(data.min_x) + 1, height = int64_t(data.max_y) - int64_t(data.min_y) + 1;
    if (width < 1 || height < 1 || width > 65536 || height > 65536)
        throw fail("the OpenEXR header claims " + std::to_string(width) + "x" + std::to_string(height) +
                   " pixels: only sizes in [1, 65536] are read");
    detail::CheckPixelCount(aPath, width, height, aMaxPixels);
    if (data.min_x != display.min_x || data.min_y != display.min_y || data.max_x != display.max_x || data.max_y != display.max_y)
        throw fail("its data window differs from its display window: only whole images are read");
    // tinyexr flips the rows of a file stored bottom block first; every common writer
    // stores increasing y.
    if (header.line_order != 0) throw fail("its line order is not increasing y: only increasing-y files are read");
    // A scanline file has one chunk per block of 1 (no compression, RLE, ZIPS), 16 (ZIP)
    // or 32 (PIZ) rows; a chunkCount attribute that says otherwise would size tinyexr's
    // offset table.
    const int64_t rowsPerChunk = header.compression_type == TINYEXR_COMPRESSIONTYPE_ZIP ? 16
                                 : header.compression_type == TINYEXR_COMPRESSIONTYPE_PIZ ? 32 : 1;
    if (header.chunk_count != 0 && int64_t(header.chunk_count) != (height + rowsPerChunk - 1) / rowsPerChunk)
        throw fail("its chunkCount attribute does not match the image's height");
    // Every channel is decoded, so every channel must be one tinyexr can decode, and all
    // of them together must fit the bound.
    const std::string prefix = aLayer.empty() ? std::string() : aLayer + ".";
    int rgb[3] = {-1, -1, -1};
    std::string names;
    uint64_t decodedBytes = 0;
    for (int c = 0; c < header.num_channels; c++) {
        const EXRChannelInfo& channel = header.channels[c];
        const std::string name(channel.name, strnlen(channel.name, sizeof(channel.name)));
        if (names.size() < 80) names += (names.empty() ? "" : ", ") + name.substr(0, 40);
        const int pixelType = header.pixel_types[c];
        if (pixelType != TINYEXR_PIXELTYPE_UINT && pixelType != TINYEXR_PIXELTYPE_HALF && pixelType != TINYEXR_PIXELTYPE_FLOAT)
            throw fail("its channel '" + name.substr(0, 40) + "' has an unknown pixel type");
        if (channel.x_sampling != 1 || channel.y_sampling != 1)
            throw fail("its channel '" + name.substr(0, 40) + "' is subsampled: only full-resolution channels are read");
        for (int k = 0; k < 3; k++)
            if (name == prefix + "RGB"[k]) {
                if (rgb[k] >= 0) throw fail("its channel '" + name.substr(0, 40) + "' appears twice");
                if (pixelType == TINYEXR_PIXELTYPE_UINT) throw fail("its channel '" + name.substr(0, 40) + "' holds integers, not radiance");
                rgb[k] = c;
                header.requested_pixel_types[c] = TINYEXR_PIXELTYPE_FLOAT;  // half to float is exact
            }
        decodedBytes += uint64_t(width) * uint64_t(height) * (header.requested_pixel_types[c] == TINYEXR_PIXELTYPE_HALF ? 2 : 4);
    }
    if (rgb[0] < 0 || rgb[1] < 0 || rgb[2] < 0) {
        const std::string wanted = aLayer.empty() ? std::string("R, G, B") : prefix + "R, " + prefix + "G, " + prefix + "B";
        throw fail("has no channels " + wanted.substr(0, 200) + " (its channels: " + (names.empty() ? std::string("none") : names) +
                   "); only RGB radiance is read, a luminance-only (Y) image is not converted");
    }
    if (decodedBytes > (uint64_t(1) << 32))
        throw fail("its " + std::to_string(header.num_channels) + " channels of " + std::to_string(width) + "x" + std::to_string(height) +
                   " pixels would take more than 4 GiB to decode: not read");
    struct ImageOwner {
        EXRImage mImage;
        bool mLoaded = false;  // when loading fails, tinyexr frees what it allocated itself
        ImageOwner() { InitEXRImage(&mImage); }
        ~ImageOwner() { if (mLoaded) FreeEXRImage(&mImage); }
    } pixels;
    // tinyexr 1.0.1 frees a failed load's channels up to the image's num_channels, which it
    // sets only on success: set it first, or every corrupt file leaks its channels.
    pixels.mImage.num_channels = header.num_channels;
    const char* pixelMessage = nullptr;
    if (LoadEXRImageFromMemory(&pixels.mImage, &header, bytes.data(), bytes.size(), &pixelMessage) != TINYEXR_SUCCESS)
        throw fail("its OpenEXR pixel data is truncated or corrupt (tinyexr: " + detail::TinyexrMessage(pixelMessage) + ")");
    pixels.mLoaded = true;
    FreeEXRErrorMessage(pixelMessage);
    if (pixels.mImage.width != width || pixels.mImage.height != height || !pixels.mImage.images)
        throw fail("tinyexr decoded an image of another size than its header's");
    Image image(pixels.mImage.width, pixels.mImage.height);
    for (int k = 0; k < 3; k++) {
        const float* plane = reinterpret_cast<const float*>(pixels.mImage.images[rgb[k]]);
        for (size_t i = 0; i < image.mPixels.size(); i++) image.mPixels[i][k] = plane[i];
    }
    return image;
}

std::shared_ptr<const EnvironmentMap> LoadEnvironmentMap(const std::string& aPath, float aRotationDegrees) {
    const uint64_t most = uint64_t(kMaxEnvironmentMapWidth) * uint64_t(kMaxEnvironmentMapWidth / 2);
    Image image;
    try {
        image = ReadImage(aPath, most);
    } catch (const Error& error) {
        throw Error(std::string("environment map ") + error.what());
    }
    return std::make_shared<const EnvironmentMap>("environment map " + aPath, image.mWidth, image.mHeight, std::move(image.mPixels),
                                                  aRotationDegrees);
}

void AddDefaultSkyAndSun(Scene& aScene, const Camera& aCamera) {
    // The sky by elevation y = cos(theta): from the horizon's colour to the zenith's as
    // 1 - (1 - y)^2, to the ground's below the horizon over 15 degrees. Each row of the map
    // (0.35 degrees) then differs from the next by under 1 % of its brightness, so the
    // nearest-texel lookup shows no bands.
    const Vec3 zenith(0.22f, 0.3f, 0.45f), horizon(0.55f, 0.58f, 0.62f), ground(0.2f, 0.19f, 0.18f);
    const int width = 1024, height = 512;
    std::vector<Vec3> texels(size_t(width) * size_t(height));
    for (int row = 0; row < height; row++) {
        const float y = std::cos(kPi * (float(row) + 0.5f) / float(height));
        const Vec3 color = y >= 0.f ? horizon + (zenith - horizon) * (1.f - Sqr(1.f - y))
                                    : horizon + (ground - horizon) * std::min(1.f, -y * 4.f);
        std::fill(texels.begin() + long(row) * width, texels.begin() + long(row + 1) * width, color);
    }
    aScene.AddEnvironmentLight(std::make_shared<const EnvironmentMap>("the default sky", width, height, std::move(texels), 0.f));
    // The sun: from behind the camera, turned 40 degrees to its left, 50 degrees up. A
    // camera that looks straight up or down has no "behind": the sun then comes from +Z.
    Vec3 back(-aCamera.Forward().x, 0.f, -aCamera.Forward().z), left(-aCamera.Right().x, 0.f, -aCamera.Right().z);
    if (!(glm::length(back) > 1e-3f) || !(glm::length(left) > 1e-3f)) { back = Vec3(0.f, 0.f, 1.f); left = Vec3(-1.f, 0.f, 0.f); }
    back = glm::normalize(back);
    left = glm::normalize(left - back * glm::dot(left, back));
    const float azimuth = 40.f * kPi / 180.f, elevation = 50.f * kPi / 180.f;
    const Vec3 toSun = std::cos(elevation) * (std::cos(azimuth) * back + std::sin(azimuth) * left) + Vec3(0.f, std::sin(elevation), 0.f);
    aScene.AddDirectionalLight(-toSun, Vec3(3.f, 2.9f, 2.7f));
}

Image ReadImage(const std::string& aPath, uint64_t aMaxPixels) {
    switch (ImageFormatOf(aPath)) {
    case ImageFormat::kPfm: return ReadPfm(aPath, aMaxPixels);
    case ImageFormat::kHdr: return ReadHdr(aPath, aMaxPixels);
    case ImageFormat::kExr: return ReadExr(aPath, "", aMaxPixels);
    case ImageFormat::kPng: throw Error(aPath + ": a PNG holds exposed, tone-mapped 8-bit values, not radiance (use the .pfm, .hdr or .exr)");
    default: throw Error(aPath + ": unknown image format (use .pfm, .hdr or .exr)");
    }
}

// -------------------------------------------------------------------------------------
// Untrusted files
// -------------------------------------------------------------------------------------
// A scene file, and every file its URIs name, may come from anyone. So: read regular
// files only (a FIFO blocks forever, /dev/zero never ends), opened without blocking, and
// check their size before reading a byte; read a URI's file only if it lies inside the
// scene's folder after resolving ".." and symlinks, and say the same words whether an
// outside file exists or not, so a scene cannot learn anything about one; quote user text
// in messages only as a short excerpt.
namespace detail {

// User text (a name, a URI, a parser message) as quoted in an error: at most aMax
// characters, control characters replaced, so a 60 KB data URI cannot flood a terminal.
inline std::string Excerpt(const std::string& aText, size_t aMax = 64) {
    std::string excerpt;
    for (size_t i = 0; i < std::min(aMax, aText.size()); i++) {
        const unsigned char c = static_cast<unsigned char>(aText[i]);
        excerpt += (c < 0x20 || c == 0x7f) ? '?' : char(c);
    }
    if (aText.size() > aMax) excerpt += "... (" + std::to_string(aText.size()) + " characters)";
    return excerpt;
}

// The canonical absolute path (".." and symlinks resolved), or "" if there is none.
inline std::string RealPath(const std::string& aPath) {
    char* resolved = ::realpath(aPath.c_str(), nullptr);
    if (!resolved) return std::string();
    const std::string result(resolved);
    std::free(resolved);
    return result;
}

// True when the canonical path aPath is the canonical folder aFolder or lies below it.
inline bool IsInsideFolder(const std::string& aPath, const std::string& aFolder) {
    if (aPath.compare(0, aFolder.size(), aFolder) != 0) return false;
    return aPath.size() == aFolder.size() || aFolder == "/" || aPath[aFolder.size()] == '/';
}

inline std::string ByteCount(uint64_t aBytes) {
    if (aBytes < (uint64_t(1) << 20)) return std::to_string(aBytes) + " bytes";
    char text[32];
    std::snprintf(text, sizeof(text), "%.1f MiB", double(aBytes) / double(uint64_t(1) << 20));
    return text;
}

// Reads the file aPath whole into oBytes; returns "" or the problem in a few words.
// With aRoot (a canonical folder) the file must resolve inside it, and every failure
// to find such a file has the same words. aSizeProblem(size) says why a file of that
// size must not be read ("" to read it); it is asked before reading.
inline std::string ReadUntrustedFile(const std::string& aPath, const std::string& aRoot,
                                     const std::function<std::string(uint64_t)>& aSizeProblem,
                                     std::vector<unsigned char>& oBytes) {
    static const char* const kNotInside = "no readable file of that name inside the scene's folder";
    std::string path = aPath;
    if (!aRoot.empty()) {
        path = RealPath(aPath);
        if (path.empty() || !IsInsideFolder(path, aRoot)) return kNotInside;
    }
    // O_NONBLOCK: opening a FIFO must not wait for a writer. O_NOFOLLOW on the resolved
    // path, and the check of what was opened, close the gap a link swapped since then.
    const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY | (aRoot.empty() ? 0 : O_NOFOLLOW));
    if (fd < 0) return aRoot.empty() ? std::string("cannot open the file (") + std::strerror(errno) + ")" : kNotInside;
    struct Closer { int mFd; ~Closer() { ::close(mFd); } } closer{fd};
    if (!aRoot.empty()) {
        const std::string opened = RealPath("/proc/self/fd/" + std::to_string(fd));
        if (!opened.empty() && !IsInsideFolder(opened, aRoot)) return kNotInside;
    }
    struct stat info;
    if (::fstat(fd, &info) != 0) return std::string("cannot read the file (") + std::strerror(errno) + ")";
    if (S_ISDIR(info.st_mode)) return "is a directory, not a file";
    if (!S_ISREG(info.st_mode)) return "is not a regular file (a FIFO, socket or device is never read)";
    const uint64_t size = uint64_t(info.st_size);
    const std::string sizeProblem = aSizeProblem(size);
    if (!sizeProblem.empty()) return sizeProblem;
    oBytes.resize(size_t(size));
    size_t done = 0;
    while (done < size) {
        const ssize_t got = ::read(fd, oBytes.data() + done, size_t(size) - done);
        if (got < 0 && errno == EINTR) continue;
        if (got < 0) return std::string("read error (") + std::strerror(errno) + ")";
        if (got == 0) return "the file shrank while it was read";
        done += size_t(got);
    }
    return "";
}

} // namespace detail

// -------------------------------------------------------------------------------------
// glTF loading
// -------------------------------------------------------------------------------------
namespace detail {

using Mat4 = glm::dmat4;

class GltfLoader {
public:
    GltfLoader(const std::string& aPath, const GltfLoadOptions& aOptions) : mPath(aPath), mOptions(aOptions) {}

    Scene Load(GltfLoadReport* oReport) {
        const auto start = std::chrono::steady_clock::now();
        ParseFile();
        for (const std::vector<std::string>* list : {&mModel.extensionsUsed, &mModel.extensionsRequired})
            mQuantized = mQuantized || std::count(list->begin(), list->end(), "KHR_mesh_quantization") > 0;
        DecodeMeshoptViews();
        DecodeDracoPrimitives();
        CheckModelFeatures();
        ConvertMaterials();
        NoteApproximations();
        const int sceneIndex = mModel.defaultScene >= 0 ? mModel.defaultScene : 0;
        if (mModel.scenes.empty()) Fail("the file has no scene");
        if (sceneIndex >= int(mModel.scenes.size())) Fail("the default scene " + std::to_string(sceneIndex) + " does not exist");
        ReadSceneMedium(sceneIndex);
        for (int root : mModel.scenes[size_t(sceneIndex)].nodes) VisitNode(root, Mat4(1.0), 0);
        FinishPrimitiveNotes();
        if (mOptions.mCamera >= 0 && !mHasCamera)
            Fail("camera " + std::to_string(mOptions.mCamera) + " was asked for, but the scene has " + std::to_string(mCameraNodes) +
                 " camera node(s)" + (mCameraNodes > 0 ? " (0.." + std::to_string(mCameraNodes - 1) + ")" : std::string()));
        if (!mHasCamera) AddDefaultCamera();
        ChooseBackground();  // the default sun is placed from the camera
        CheckSomethingEmits();
        NoteLightFromInfinityInMedium();
        mScene.mName = mPath;
        const auto finalizeStart = std::chrono::steady_clock::now();
        mScene.Finalize();  // its Error messages start with the path too
        mReport.mFinalizeSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - finalizeStart).count();
        mReport.mReadSeconds = std::chrono::duration<double>(finalizeStart - start).count();
        mReport.mSkippedDegenerateTriangles = mSkippedTriangles;
        if (!mIgnoredExtensions.empty()) {
            std::string list;
            for (const std::string& name : mIgnoredExtensions) list += (list.empty() ? "" : ", ") + Excerpt(name);
            mReport.mNotes.push_back("ignored extensions (used by the file, not required, not modelled here): " + list);
        }
        if (oReport) *oReport = mReport;
        return std::move(mScene);
    }

private:
    [[noreturn]] void Fail(const std::string& aProblem) const { throw Error(mPath + ": " + aProblem); }

    // Reads the scene file (bounded, regular files only), checks what tinygltf would
    // trip over, then parses it; buffer files are read through ReadBufferFile.
    void ParseFile() {
        std::vector<unsigned char> bytes;
        const std::string problem = ReadUntrustedFile(mPath, "", [&](uint64_t aSize) { return SizeProblem(aSize); }, bytes);
        if (!problem.empty()) Fail(problem);
        if (bytes.empty()) Fail("the file is empty (0 bytes)");
        // URIs are relative to the scene's folder and must resolve inside mRoot.
        const std::string parent = std::filesystem::path(mPath).parent_path().string();
        mFolder = RealPath(parent.empty() ? std::string(".") : parent);
        mRoot = mOptions.mResourceRoot.empty() ? mFolder : RealPath(mOptions.mResourceRoot);
        if (mRoot.empty()) Fail("the resource folder '" + Excerpt(mOptions.mResourceRoot) + "' does not exist");
        // A binary glTF starts with "glTF", a version and the total length; its JSON is
        // the first chunk. Only version 2 is glTF 2.0.
        const bool binary = bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
        size_t jsonBegin = 0, jsonEnd = bytes.size();
        if (binary && bytes.size() >= 20) {
            uint32_t version, total, length;
            std::memcpy(&version, bytes.data() + 4, 4);
            std::memcpy(&total, bytes.data() + 8, 4);
            std::memcpy(&length, bytes.data() + 12, 4);
            if (version != 2)
                Fail("a binary glTF (.glb) of version " + std::to_string(version) + " is not supported (glTF 2.0 binaries have version 2)");
            jsonBegin = 20;
            jsonEnd = std::min(bytes.size(), size_t(20) + length);
            // tinygltf 2.7 checks a BIN chunk's length against the file without the
            // chunk's own 8-byte header, then copies up to 8 bytes past the end of the
            // file into the buffer: check the layout here (header length <= file size,
            // and the BIN chunk, header included, inside that length).
            const uint64_t binStart = uint64_t(20) + length;
            if (total <= bytes.size() && binStart + 8 <= total) {
                uint32_t binLength;
                std::memcpy(&binLength, bytes.data() + binStart, 4);
                if (binStart + 8 + binLength > total)
                    Fail("glTF parse error: the BIN chunk of the .glb is longer than the file (invalid glTF binary)");
            }
        }
        CheckJsonNesting(bytes, jsonBegin, jsonEnd);
        const nlohmann::json json = nlohmann::json::parse(bytes.begin() + std::ptrdiff_t(jsonBegin), bytes.begin() + std::ptrdiff_t(jsonEnd),
                                                          nullptr, false);
        if (json.is_object()) {  // otherwise tinygltf says what is wrong with it
            CheckVersionAndExtensions(json);
            const std::set<size_t> emptyFallbacks = EmptyFallbackBuffers(json, binary);
            CheckDeclaredBuffers(json);
            CheckSpotAnglesAreNumbers(json);
            CheckAlphaModes(json);
            CheckMediaAreObjects(json);
            const std::map<size_t, nlohmann::json> dracoAccessors = DracoAccessorsWithoutView(json);
            if (!emptyFallbacks.empty() || !dracoAccessors.empty()) ForTinygltf(json, emptyFallbacks, dracoAccessors, binary, jsonEnd, bytes);
        }

        tinygltf::TinyGLTF gltf;
        // Images in buffer views and data URIs arrive here still encoded; they are kept so
        // and decoded only if a material uses them (DecodeImage). External image files
        // are not read by tinygltf at all (TINYGLTF_NO_EXTERNAL_IMAGE) but by DecodeImage.
        gltf.SetImageLoader([](tinygltf::Image* aImage, const int, std::string*, std::string*, int, int,
                               const unsigned char* aBytes, int aSize, void*) {
            aImage->image.assign(aBytes, aBytes + std::max(aSize, 0));
            aImage->as_is = true;
            return true;
        }, nullptr);
        // Every file a URI names is read by ReadBufferFile. FileExists says yes without
        // looking, so tinygltf never falls back to its second search path, the current
        // directory, and never probes the file system itself.
        tinygltf::FsCallbacks files;
        files.FileExists = [](const std::string&, void*) { return true; };
        files.ExpandFilePath = &tinygltf::ExpandFilePath;
        files.ReadWholeFile = [](std::vector<unsigned char>* oBytes, std::string* oError, const std::string& aFile, void* aLoader) {
            return static_cast<GltfLoader*>(aLoader)->ReadBufferFile(*oBytes, *oError, aFile);
        };
        files.WriteWholeFile = &tinygltf::WriteWholeFile;
        files.user_data = this;
        gltf.SetFsCallbacks(files);
        std::string error, warning;
        const bool ok = binary || EndsWithIgnoringCase(mPath, ".glb")
            ? gltf.LoadBinaryFromMemory(&mModel, &error, &warning, bytes.data(), unsigned(bytes.size()), mFolder)
            : gltf.LoadASCIIFromString(&mModel, &error, &warning, reinterpret_cast<const char*>(bytes.data()), unsigned(bytes.size()), mFolder);
        if (!mBufferProblem.empty()) Fail(mBufferProblem);
        if (!ok || !error.empty()) {
            std::string message = error.empty() ? std::string("not a valid glTF file") : error;
            while (!message.empty() && (message.back() == '\n' || message.back() == ' ')) message.pop_back();
            std::replace(message.begin(), message.end(), '\n', ';');
            Fail("glTF parse error: " + Excerpt(message, 240));
        }
        if (mModel.asset.version.compare(0, 2, "2.") != 0)
            Fail("glTF version " + Excerpt(mModel.asset.version) + " is not supported (asset.version must be \"2.0\")");
    }

    std::string SizeProblem(uint64_t aSize) {
        if (aSize > mOptions.mMaxFileBytes)
            return "the file is " + ByteCount(aSize) + ", more than the loader's limit of " + ByteCount(mOptions.mMaxFileBytes) +
                   " per file (GltfLoadOptions::mMaxFileBytes)";
        if (aSize > mOptions.mMaxTotalBytes - std::min(mOptions.mMaxTotalBytes, mBytesRead))
            return "the scene's files together exceed the loader's limit of " + ByteCount(mOptions.mMaxTotalBytes) +
                   " (GltfLoadOptions::mMaxTotalBytes)";
        mBytesRead += aSize;
        return "";
    }

    // tinygltf turns extras and extensions into values recursively: a file nested
    // thousands of levels deep would overflow the stack, so bound the nesting first.
    void CheckJsonNesting(const std::vector<unsigned char>& aBytes, size_t aBegin, size_t aEnd) const {
        int depth = 0, deepest = 0;
        bool inString = false, escaped = false;
        for (size_t i = aBegin; i < aEnd; i++) {
            const char c = char(aBytes[i]);
            if (inString) {
                if (escaped) escaped = false;
                else if (c == '\\') escaped = true;
                else if (c == '"') inString = false;
            } else if (c == '"') inString = true;
            else if (c == '[' || c == '{') deepest = std::max(deepest, ++depth);
            else if (c == ']' || c == '}') depth--;
        }
        if (deepest > 512) Fail("the JSON is nested " + std::to_string(deepest) + " levels deep (at most 512 are read)");
    }

    // The extensions this loader reads; any other required one is refused, any other used
    // one is ignored and listed in a note.
    static const std::set<std::string>& SupportedExtensions() {
        static const std::set<std::string> kSupported = {
            "KHR_materials_volume", "SMALLVCM_medium",
            "KHR_lights_punctual", "KHR_materials_emissive_strength", "KHR_materials_transmission",
            "KHR_materials_ior", "KHR_texture_transform", "SMALLVCM_material", "SMALLVCM_sphere", "SMALLVCM_background",
            "KHR_mesh_quantization", "EXT_meshopt_compression", "KHR_draco_mesh_compression"};
        return kSupported;
    }

    // How to get a file that loads, for the unsupported extensions files carry most; null
    // for any other.
    static const char* HowToGetAPlainFile(const std::string& aExtension) {
        static const std::pair<const char*, const char*> kHints[] = {
            {"KHR_texture_basisu", "its textures are KTX2/Basis: convert them to PNG or JPEG first (e.g. re-export with PNG textures)"},
            {"EXT_texture_webp", "its textures are WebP: convert them to PNG or JPEG first"},
        };
        for (const auto& [name, hint] : kHints)
            if (aExtension == name) return hint;
        return nullptr;
    }

    // The refusal of the required extensions not modelled here, or "" when there are
    // none: every one is named in one line (fixing the first would only lead to the next),
    // each with its hint. A known name is written as is, any other quoted as an excerpt,
    // and a list longer than a screen line ends in how many more there are.
    static std::string UnsupportedRequiredExtensions(const std::vector<std::string>& aRequired) {
        std::vector<std::string> names;
        std::set<std::string> seen;
        size_t more = 0;
        for (const std::string& name : aRequired) {
            if (SupportedExtensions().count(name) || !seen.insert(name).second) continue;
            if (names.size() < 8) names.push_back(name);
            else more++;
        }
        if (names.empty()) return "";
        const bool several = names.size() > 1;
        std::string list, hints;
        for (size_t i = 0; i < names.size(); i++) {
            const char* hint = HowToGetAPlainFile(names[i]);
            const bool last = i + 1 == names.size() && more == 0;
            list += std::string(i == 0 ? "" : last ? " and " : ", ") + (hint ? names[i] : "'" + Excerpt(names[i]) + "'");
            if (hint) hints += (hints.empty() ? "" : "; ") + (several ? names[i] + ": " : std::string()) + hint;
        }
        if (more > 0) list += " and " + std::to_string(more) + " more";
        return std::string(several ? "required extensions " : "required extension ") + list + (several ? " are" : " is") +
               " not supported" + (hints.empty() ? "" : ": " + hints);
    }

    // Before any buffer is read: a glTF 1.0 file, or the extensions the file requires that
    // are not modelled here (compressed meshes, KTX2 textures...), are named in one line
    // that says how to get a file that loads.
    void CheckVersionAndExtensions(const nlohmann::json& aJson) {
        if (aJson.contains("asset") && aJson["asset"].is_object() && aJson["asset"].contains("version") &&
            aJson["asset"]["version"].is_string()) {
            const std::string& version = aJson["asset"]["version"].get_ref<const std::string&>();
            if (version.compare(0, 2, "1.") == 0 || version == "1")
                Fail("this is a glTF 1.0 file (asset.version \"" + Excerpt(version) + "\"); only glTF 2.0 is supported: convert it "
                     "(e.g. import it into Blender and export glTF 2.0)");
        }
        if (aJson.contains("extensionsRequired") && aJson["extensionsRequired"].is_array()) {
            std::vector<std::string> required;
            for (const nlohmann::json& entry : aJson["extensionsRequired"])
                if (entry.is_string()) required.push_back(entry.get<std::string>());
            const std::string problem = UnsupportedRequiredExtensions(required);
            if (!problem.empty()) Fail(problem);
        }
        if (aJson.contains("extensionsUsed") && aJson["extensionsUsed"].is_array())
            for (const nlohmann::json& entry : aJson["extensionsUsed"])
                if (entry.is_string() && !SupportedExtensions().count(entry.get<std::string>()) && mIgnoredExtensions.size() < 32)
                    mIgnoredExtensions.insert(entry.get<std::string>());
    }

    // aObject[aKey], or null when aObject is not an object or has no such member.
    static const nlohmann::json& Member(const nlohmann::json& aObject, const char* aKey) {
        static const nlohmann::json kNull;
        if (!aObject.is_object()) return kNull;
        const auto found = aObject.find(aKey);
        return found == aObject.end() ? kNull : *found;
    }
    // aArray[aIndex] when aIndex is an index into the array aArray, else null.
    static const nlohmann::json& Element(const nlohmann::json& aArray, const nlohmann::json& aIndex) {
        static const nlohmann::json kNull;
        if (!aArray.is_array() || !aIndex.is_number_unsigned() || aIndex.get<uint64_t>() >= aArray.size()) return kNull;
        return aArray[aIndex.get<size_t>()];
    }

    // Buffer aBuffer holds no bytes of its own: it has no URI, and is not the first buffer
    // of a .glb (which stands for the BIN chunk).
    static bool HasNoData(const nlohmann::json& aBuffers, size_t aBuffer, bool aBinary) {
        const nlohmann::json& uri = Member(aBuffers[aBuffer], "uri");
        return aBuffers[aBuffer].is_object() && (uri.is_null() || uri == "") && !(aBinary && aBuffer == 0);
    }

    // EXT_meshopt_compression: a compressed buffer view reads its bytes through the
    // extension (DecodeMeshoptViews); its own buffer, the fallback, holds the same bytes
    // uncompressed for readers without the extension, or nothing (no URI). tinygltf 2.7
    // refuses a buffer without a URI in a .gltf and copies a .glb's BIN chunk (the
    // compressed bytes) into one: the empty fallbacks returned here get one placeholder
    // byte instead (ForTinygltf), which no decoded view reads. Any other buffer
    // without a URI is refused: only a .glb's first buffer stands for its BIN chunk.
    std::set<size_t> EmptyFallbackBuffers(const nlohmann::json& aJson, bool aBinary) const {
        const nlohmann::json& buffers = Member(aJson, "buffers");
        const nlohmann::json& views = Member(aJson, "bufferViews");
        std::set<size_t> fallbackBuffers;  // under a compressed view, or marked as a fallback
        for (size_t v = 0; views.is_array() && v < views.size(); v++) {
            if (!Member(Member(views[v], "extensions"), "EXT_meshopt_compression").is_object()) continue;
            const nlohmann::json& buffer = Member(views[v], "buffer");
            if (Element(buffers, buffer).is_object()) fallbackBuffers.insert(buffer.get<size_t>());  // else tinygltf says what is wrong
        }
        for (size_t b = 0; buffers.is_array() && b < buffers.size(); b++)
            if (Member(Member(Member(buffers[b], "extensions"), "EXT_meshopt_compression"), "fallback") == true) fallbackBuffers.insert(b);
        std::set<size_t> empty;
        for (size_t b = 0; buffers.is_array() && b < buffers.size(); b++) {
            if (!HasNoData(buffers, b, aBinary)) continue;
            if (!fallbackBuffers.count(b))
                Fail("buffer " + std::to_string(b) + " has no URI (only a .glb's first buffer may go without one: it stands for the "
                     "BIN chunk, and an EXT_meshopt_compression fallback buffer holds nothing)");
            empty.insert(b);
        }
        return empty;
    }

    // KHR_draco_mesh_compression: the accessors a compressed primitive's stream fills may
    // have no bufferView (their data is only in the stream), which tinygltf 2.7 refuses.
    // Returns them, each with the stream's bufferView, which tinygltf is told they read
    // until DecodeDracoPrimitives gives them the decoded bytes.
    static std::map<size_t, nlohmann::json> DracoAccessorsWithoutView(const nlohmann::json& aJson) {
        std::map<size_t, nlohmann::json> result;
        const nlohmann::json& accessors = Member(aJson, "accessors");
        const nlohmann::json& meshes = Member(aJson, "meshes");
        for (size_t m = 0; meshes.is_array() && m < meshes.size(); m++) {
            const nlohmann::json& primitives = Member(meshes[m], "primitives");
            for (size_t p = 0; primitives.is_array() && p < primitives.size(); p++) {
                const nlohmann::json& draco = Member(Member(primitives[p], "extensions"), "KHR_draco_mesh_compression");
                const nlohmann::json& stream = Member(draco, "bufferView");
                const nlohmann::json& ids = Member(draco, "attributes");
                if (!stream.is_number_unsigned() || !ids.is_object()) continue;  // DecodeDracoPrimitive says what is wrong
                std::vector<const nlohmann::json*> filled = {&Member(primitives[p], "indices")};
                for (const auto& entry : ids.items()) filled.push_back(&Member(Member(primitives[p], "attributes"), entry.key().c_str()));
                for (const nlohmann::json* index : filled)
                    if (Element(accessors, *index).is_object() && !Element(accessors, *index).contains("bufferView"))
                        result[index->get<size_t>()] = stream;
            }
        }
        return result;
    }

    // The file as tinygltf is given it when aEmpty names buffers or aDracoAccessors
    // accessors: each of those buffers one placeholder byte (a data URI), each of those
    // accessors its stream's bufferView, in the JSON; in a .glb the JSON chunk is written
    // anew and the chunks after it are kept as they are.
    static void ForTinygltf(nlohmann::json aJson, const std::set<size_t>& aEmpty, const std::map<size_t, nlohmann::json>& aDracoAccessors,
                            bool aBinary, size_t aJsonEnd, std::vector<unsigned char>& ioBytes) {
        for (const size_t b : aEmpty) {
            aJson["buffers"][b]["uri"] = "data:application/octet-stream;base64,AA==";
            aJson["buffers"][b]["byteLength"] = 1;
        }
        for (const auto& [accessor, view] : aDracoAccessors) aJson["accessors"][accessor]["bufferView"] = view;
        std::string text = aJson.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
        if (!aBinary) {
            ioBytes.assign(text.begin(), text.end());
            return;
        }
        while (text.size() % 4 != 0) text += ' ';  // a chunk's length is a multiple of 4
        std::vector<unsigned char> glb(ioBytes.begin(), ioBytes.begin() + 12);
        const auto append32 = [&](uint32_t aValue) {
            const auto* bytes = reinterpret_cast<const unsigned char*>(&aValue);
            glb.insert(glb.end(), bytes, bytes + 4);
        };
        append32(uint32_t(text.size()));
        append32(0x4E4F534Au);  // "JSON"
        glb.insert(glb.end(), text.begin(), text.end());
        glb.insert(glb.end(), ioBytes.begin() + std::ptrdiff_t(aJsonEnd), ioBytes.end());
        const uint32_t total = uint32_t(std::min<size_t>(glb.size(), std::numeric_limits<uint32_t>::max()));
        std::memcpy(glb.data() + 8, &total, 4);
        ioBytes = std::move(glb);
    }

    // tinygltf keeps the default of a spot cone angle that is not a number ("0.5" as a
    // string): such a file would silently render another cone, so it is refused here.
    void CheckSpotAnglesAreNumbers(const nlohmann::json& aJson) {
        const nlohmann::json* lights = &aJson;
        for (const char* key : {"extensions", "KHR_lights_punctual", "lights"}) {
            if (!lights->is_object() || !lights->contains(key)) return;
            lights = &(*lights)[key];
        }
        if (!lights->is_array()) return;  // tinygltf says what is wrong
        for (size_t l = 0; l < lights->size(); l++) {
            const nlohmann::json& light = (*lights)[l];
            if (!light.is_object() || !light.contains("spot")) continue;
            const nlohmann::json& spot = light["spot"];
            if (!spot.is_object()) Fail("light " + std::to_string(l) + ": 'spot' must be an object");
            for (const char* angle : {"innerConeAngle", "outerConeAngle"})
                if (spot.contains(angle) && !spot[angle].is_number())
                    Fail("light " + std::to_string(l) + ": spot." + angle + " must be a number (radians)");
        }
    }

    // A material's alphaMode and alphaCutoff as the specification types them: tinygltf
    // keeps the default of a cutoff that is not a number (the string "0.3") and passes on
    // any alphaMode string, and either would render another surface than the file asks for.
    void CheckAlphaModes(const nlohmann::json& aJson) {
        if (!aJson.contains("materials") || !aJson["materials"].is_array()) return;  // tinygltf says what is wrong
        const nlohmann::json& materials = aJson["materials"];
        for (size_t m = 0; m < materials.size(); m++) {
            const nlohmann::json& material = materials[m];
            if (!material.is_object()) continue;
            const nlohmann::json& name = Member(material, "name");
            const std::string what = "material " + std::to_string(m) +
                                     (name.is_string() && !name.get<std::string>().empty() ? " '" + Excerpt(name.get<std::string>()) + "'" : "");
            if (material.contains("alphaMode")) {
                const nlohmann::json& mode = material["alphaMode"];
                if (!mode.is_string() || (mode != "OPAQUE" && mode != "MASK" && mode != "BLEND"))
                    Fail(what + ": alphaMode must be \"OPAQUE\", \"MASK\" or \"BLEND\"");
            }
            if (material.contains("alphaCutoff")) {
                const nlohmann::json& cutoff = material["alphaCutoff"];
                if (!cutoff.is_number() || !(cutoff.get<double>() >= 0.0))
                    Fail(what + ": alphaCutoff must be a number >= 0 (glTF 2.0; the default is 0.5)");
            }
        }
    }

    // tinygltf drops an extension whose value is not an object: a medium written as an
    // array or a number would silently vanish from the scene (docs/scene_format.md 4.4).
    void CheckMediaAreObjects(const nlohmann::json& aJson) {
        const nlohmann::json& materials = Member(aJson, "materials");
        for (size_t m = 0; materials.is_array() && m < materials.size(); m++) {
            const nlohmann::json& extensions = Member(materials[m], "extensions");
            const nlohmann::json& name = Member(materials[m], "name");
            const std::string what = "material " + std::to_string(m) +
                                     (name.is_string() && !name.get<std::string>().empty() ? " '" + Excerpt(name.get<std::string>()) + "'" : "");
            for (const char* extension : {"SMALLVCM_medium", "KHR_materials_volume"})
                if (extensions.is_object() && extensions.contains(extension) && !extensions[extension].is_object())
                    Fail(what + ": " + extension + " must be an object");
        }
        const nlohmann::json& scenes = Member(aJson, "scenes");
        for (size_t i = 0; scenes.is_array() && i < scenes.size(); i++) {
            const nlohmann::json& extensions = Member(scenes[i], "extensions");
            if (extensions.is_object() && extensions.contains("SMALLVCM_medium") && !extensions["SMALLVCM_medium"].is_object())
                Fail("scene " + std::to_string(i) + ": SMALLVCM_medium must be an object");
        }
    }

    // What the buffers declare, known before tinygltf reads or decodes a byte. Their
    // sizes: a file is read only if it is as long as some buffer says, and a data URI is
    // decoded only if its text is no longer than its byteLength needs (tinygltf itself
    // reads a whole file, or decodes a whole URI, before it compares the size). And the
    // file each URI names, under the name tinygltf will ask ReadBufferFile for.
    void CheckDeclaredBuffers(const nlohmann::json& aJson) {
        if (!aJson.contains("buffers") || !aJson["buffers"].is_array()) return;  // tinygltf says what is wrong
        const nlohmann::json& buffers = aJson["buffers"];
        for (size_t b = 0; b < buffers.size(); b++) {
            const nlohmann::json& buffer = buffers[b];
            if (!buffer.is_object() || !buffer.contains("uri") || !buffer["uri"].is_string()) continue;
            const std::string& uri = buffer["uri"].get_ref<const std::string&>();
            const bool sized = buffer.contains("byteLength") && buffer["byteLength"].is_number_unsigned();
            const uint64_t byteLength = sized ? buffer["byteLength"].get<uint64_t>() : 0;
            if (uri.compare(0, 5, "data:") == 0) {
                const size_t comma = uri.find(',');
                const uint64_t encoded = comma == std::string::npos ? 0 : uint64_t(uri.size() - comma - 1);
                if (sized && encoded / 4 * 3 > byteLength + 3)
                    Fail("buffer " + std::to_string(b) + ": its data URI holds about " + ByteCount(encoded / 4 * 3) +
                         ", more than its byteLength of " + ByteCount(byteLength) + " (not decoded)");
            } else {
                if (sized) mDeclaredBufferSizes.insert(byteLength);
                mBufferFileNames[TinygltfDecoded(uri)].push_back(PercentDecoded(uri));
            }
        }
    }

    // The name tinygltf 2.7 decodes a buffer URI to before it asks for the file (dlib's
    // urldecode): '+' is read as a space, as in HTML forms, and '%' with the two characters
    // after it as the byte they spell (a character that is no hex digit counts as 0).
    static std::string TinygltfDecoded(const std::string& aUri) {
        const auto digit = [](char aChar) {
            return aChar >= '0' && aChar <= '9' ? aChar - '0' : aChar >= 'a' && aChar <= 'f' ? aChar - 'a' + 10
                 : aChar >= 'A' && aChar <= 'F' ? aChar - 'A' + 10 : 0;
        };
        std::string decoded;
        for (size_t i = 0; i < aUri.size(); i++) {
            if (aUri[i] == '+') {
                decoded += ' ';
            } else if (aUri[i] == '%' && i + 2 < aUri.size()) {
                decoded += char(digit(aUri[i + 1]) * 16 + digit(aUri[i + 2]));
                i += 2;
            } else {
                decoded += aUri[i];
            }
        }
        return decoded;
    }

    // tinygltf's file reader: aFile is the scene's folder joined with tinygltf's decoding
    // of a buffer's URI. A URI names a file by RFC 3986 (a '+' is a plus), so the file read
    // is the one CheckDeclaredBuffers noted under that decoding, the first not yet read
    // when two URIs decode alike (tinygltf reads the buffers in order).
    bool ReadBufferFile(std::vector<unsigned char>& oBytes, std::string& oError, const std::string& aFile) {
        std::string name = aFile.substr(std::min(aFile.size(), mFolder.size()));
        if (!name.empty() && name[0] == '/') name.erase(0, 1);
        const auto noted = mBufferFileNames.find(name);
        if (noted != mBufferFileNames.end() && !noted->second.empty()) {
            name = noted->second.front();
            noted->second.pop_front();
        }
        const std::string problem = ReadFileNamedByUri(name, [&](uint64_t aSize) -> std::string {
            if (!mDeclaredBufferSizes.count(aSize)) return "its size, " + ByteCount(aSize) + ", is no buffer's byteLength (not read)";
            return SizeProblem(aSize);
        }, oBytes);
        if (problem.empty()) return true;
        // Kept for the message: tinygltf would quote the whole joined path.
        if (mBufferProblem.empty()) mBufferProblem = "buffer URI '" + Excerpt(name) + "': " + problem;
        oError += problem;
        return false;
    }

    // Reads the file that a decoded URI aName names, relative to the scene's folder and
    // inside mRoot; returns "" or the problem. No file name holds a NUL byte ("%00"), and
    // the system would read the name only up to it.
    std::string ReadFileNamedByUri(const std::string& aName, const std::function<std::string(uint64_t)>& aSizeProblem,
                                   std::vector<unsigned char>& oBytes) const {
        if (aName.find('\0') != std::string::npos) return "the URI decodes to a NUL byte, which no file name holds";
        return ReadUntrustedFile(mFolder + "/" + aName, mRoot, aSizeProblem, oBytes);
    }

    void CheckModelFeatures() {
        const std::string unsupported = UnsupportedRequiredExtensions(mModel.extensionsRequired);
        if (!unsupported.empty()) Fail(unsupported);
        if (!mModel.skins.empty()) Fail("skins are not supported");
        for (const tinygltf::Accessor& accessor : mModel.accessors)
            if (accessor.sparse.isSparse) Fail("sparse accessors are not supported");
    }

    // --- materials -------------------------------------------------------------------
    static double NumberOr(const tinygltf::Value& aObject, const char* aKey, double aDefault) {
        if (!aObject.IsObject() || !aObject.Has(aKey)) return aDefault;
        const tinygltf::Value& v = aObject.Get(aKey);
        return v.IsNumber() ? v.GetNumberAsDouble() : std::numeric_limits<double>::quiet_NaN();
    }
    Vec3 ColorOr(const tinygltf::Value& aObject, const char* aKey, const Vec3& aDefault, const std::string& aWhat) const {
        if (!aObject.IsObject() || !aObject.Has(aKey)) return aDefault;
        const tinygltf::Value& v = aObject.Get(aKey);
        if (!v.IsArray() || v.ArrayLen() != 3) Fail(aWhat + ": '" + aKey + "' must be an array of 3 numbers");
        Vec3 color;
        for (int c = 0; c < 3; c++) {
            if (!v.Get(c).IsNumber()) Fail(aWhat + ": '" + aKey + "' must be an array of 3 numbers");
            color[c] = float(v.Get(c).GetNumberAsDouble());
        }
        return color;
    }
    void CheckColor(const Vec3& aColor, const std::string& aWhat, bool aAtMostOne) const {
        if (!IsFinite(aColor) || aColor.x < 0.f || aColor.y < 0.f || aColor.z < 0.f)
            Fail(aWhat + " must be finite and non-negative");
        if (aAtMostOne && MaxComponent(aColor) > 1.f) Fail(aWhat + " must not exceed 1 (it would create energy)");
    }

    // One note lists every approximated feature once, with how many times it occurs.
    void Approximated(const std::string& aFeature) { mApproximated[aFeature]++; }
    void NoteApproximations() {
        if (mApproximated.empty()) return;
        std::string note = "approximated (not modelled):";
        for (const auto& [feature, count] : mApproximated)
            note += " " + feature + (count > 1 ? " x" + std::to_string(count) : "") + ";";
        note.pop_back();
        mReport.mNotes.push_back(note);
    }

    // A material's use of a texture: the scene texture (one per glTF texture and
    // transform, decoded once however many materials use it) and the TEXCOORD set it reads.
    struct TextureUse {
        int mTexture = -1;
        int mTexCoord = 0;
    };
    // aSlot names the use ("baseColorTexture", "emissiveTexture", "normalTexture"): its
    // index, TEXCOORD set and extensions come from the textureInfo; KHR_texture_transform
    // gives the texture its UvTransform and may choose another set. aSrgb: colour (the
    // base colour, emission) is sRGB-encoded, a normal map is not. aAlpha: the texture
    // keeps its alpha channel (the base colour of a material with a cut-out).
    TextureUse UseTexture(int aIndex, int aTexCoord, const tinygltf::ExtensionMap& aExtensions, bool aSrgb,
                          const char* aSlot, const std::string& aWhat, bool aAlpha = false) {
        const std::string slot = aWhat + ": its " + aSlot;
        TextureUse use;
        use.mTexCoord = aTexCoord;
        Vec2 offset(0.f), scale(1.f);
        float rotation = 0.f;
        auto transform = aExtensions.find("KHR_texture_transform");
        if (transform != aExtensions.end()) {
            const tinygltf::Value& t = transform->second;
            if (!t.IsObject()) Fail(slot + ": KHR_texture_transform must be an object");
            auto pair = [&](const char* aKey, Vec2 aDefault) {
                if (!t.Has(aKey)) return aDefault;
                const tinygltf::Value& v = t.Get(aKey);
                if (!v.IsArray() || v.ArrayLen() != 2 || !v.Get(0).IsNumber() || !v.Get(1).IsNumber())
                    Fail(slot + ": KHR_texture_transform." + aKey + " must be an array of 2 numbers");
                const Vec2 value(float(v.Get(0).GetNumberAsDouble()), float(v.Get(1).GetNumberAsDouble()));
                if (!std::isfinite(value.x) || !std::isfinite(value.y))
                    Fail(slot + ": KHR_texture_transform." + aKey + " is not finite (NaN, infinity, or beyond float)");
                return value;
            };
            offset = pair("offset", offset);
            scale = pair("scale", scale);
            if (t.Has("rotation")) {
                const tinygltf::Value& v = t.Get("rotation");
                rotation = v.IsNumber() ? float(v.GetNumberAsDouble()) : std::numeric_limits<float>::quiet_NaN();
                if (!std::isfinite(rotation))
                    Fail(slot + ": KHR_texture_transform.rotation must be a finite number (radians)");
            }
            if (t.Has("texCoord")) {
                const tinygltf::Value& v = t.Get("texCoord");
                if (!v.IsInt() || v.GetNumberAsInt() < 0)
                    Fail(slot + ": KHR_texture_transform.texCoord must be a non-negative integer");
                use.mTexCoord = v.GetNumberAsInt();
            }
        }
        if (use.mTexCoord < 0 || use.mTexCoord > kMaxTexCoordSet)
            Fail(slot + " uses TEXCOORD_" + std::to_string(use.mTexCoord) + "; sets 0 to " + std::to_string(kMaxTexCoordSet) +
                 " are read");
        use.mTexture = TextureIndex(aIndex, UvTransform::Make(offset, rotation, scale), aSrgb, aAlpha, aWhat);
        return use;
    }
    static constexpr int kMaxTexCoordSet = 7;

    // The scene texture for glTF texture aTexture seen through aTransform, its texels
    // decoded from sRGB or taken as they are (aSrgb), with its alpha or without (aAlpha).
    int TextureIndex(int aTexture, const UvTransform& aTransform, bool aSrgb, bool aAlpha, const std::string& aWhat) {
        if (aTexture < 0 || aTexture >= int(mModel.textures.size()))
            Fail(aWhat + " refers to texture " + std::to_string(aTexture) + ", which does not exist");
        const TextureKey key{aTexture, aSrgb, aAlpha, aTransform.mOffset.x, aTransform.mOffset.y, aTransform.mU.x,
                             aTransform.mU.y, aTransform.mV.x, aTransform.mV.y};
        auto known = mTextureIndex.find(key);
        if (known != mTextureIndex.end()) return known->second;
        const tinygltf::Texture& texture = mModel.textures[size_t(aTexture)];
        const std::string what = "texture " + std::to_string(aTexture);
        if (texture.source < 0 || texture.source >= int(mModel.images.size()))
            Fail(what + " has no image (source " + std::to_string(texture.source) + "; PNG or JPEG images are supported)");
        const DecodedImage& image = Decoded(texture.source);
        Texture result;
        result.mWidth = image.mWidth;
        result.mHeight = image.mHeight;
        // The bytes as they are, with the linear value of each (Texture::mDecode).
        result.mEncoded.assign(image.mRgb.begin(), image.mRgb.end());
        float* toLinear = result.mDecode.data();
        for (int v = 0; v < 256; v++) toLinear[v] = aSrgb ? SrgbToLinear(float(v) / 255.f) : float(v) / 255.f;
        // Alpha is linear whatever the colour's encoding (glTF 2.0, "Metallic-Roughness
        // Material": the alpha channel is not sRGB-encoded); an image without one is opaque.
        if (aAlpha) {
            result.mAlpha.assign(result.TexelCount(), 1.f);
            for (size_t i = 0; i < image.mAlpha.size(); i++) result.mAlpha[i] = float(image.mAlpha[i]) / 255.f;
        }
        if (texture.sampler >= 0) {
            if (texture.sampler >= int(mModel.samplers.size()))
                Fail(what + " refers to sampler " + std::to_string(texture.sampler) + ", which does not exist");
            const tinygltf::Sampler& sampler = mModel.samplers[size_t(texture.sampler)];
            result.mWrapU = WrapMode(sampler.wrapS, what);
            result.mWrapV = WrapMode(sampler.wrapT, what);
        }
        result.mUvTransform = aTransform;
        mScene.mTextures.push_back(std::move(result));
        const int index = int(mScene.mTextures.size()) - 1;
        mTextureIndex[key] = index;
        return index;
    }
    TextureWrap WrapMode(int aGltfWrap, const std::string& aWhat) const {
        switch (aGltfWrap) {
        case TINYGLTF_TEXTURE_WRAP_REPEAT: return TextureWrap::kRepeat;
        case TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE: return TextureWrap::kClampToEdge;
        case TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT: return TextureWrap::kMirroredRepeat;
        default: Fail(aWhat + ": unknown sampler wrap mode " + std::to_string(aGltfWrap));
        }
    }

    // An image's 8-bit RGB pixels, decoded once for all the textures that use it (as
    // colour and as a normal map, or under several transforms), and its 8-bit alpha when
    // a material with a cut-out reads it (mImagesWithAlpha; empty otherwise).
    // Bytes come from a buffer view or data URI (kept by the image loader above) or from
    // a file inside the scene's folder, read like a buffer file: regular files only,
    // confined, size-checked before reading. The size in pixels is checked before decoding.
    struct DecodedImage {
        int mWidth = 0, mHeight = 0;
        std::vector<unsigned char> mRgb;
        std::vector<unsigned char> mAlpha;
    };
    const DecodedImage& Decoded(int aImage) {
        auto known = mDecodedImages.find(aImage);
        if (known != mDecodedImages.end()) return known->second;
        tinygltf::Image& image = mModel.images[size_t(aImage)];
        const std::string what = "image " + std::to_string(aImage) + (image.uri.empty() || image.uri.compare(0, 5, "data:") == 0
                                                                          ? std::string() : " '" + Excerpt(image.uri) + "'");
        std::vector<unsigned char> fileBytes;
        const std::vector<unsigned char>* bytes = &image.image;
        if (image.image.empty()) {
            if (image.uri.empty()) Fail(what + " has neither a URI nor a buffer view");
            const std::string problem = ReadFileNamedByUri(PercentDecoded(image.uri), [&](uint64_t aSize) { return SizeProblem(aSize); },
                                                           fileBytes);
            if (!problem.empty()) Fail(what + ": " + problem);
            bytes = &fileBytes;
        }
        if (bytes->empty()) Fail(what + ": the image is empty (0 bytes)");
        if (bytes->size() > size_t(std::numeric_limits<int>::max())) Fail(what + ": the image is larger than 2 GiB");
        int width = 0, height = 0, channels = 0;
        if (!stbi_info_from_memory(bytes->data(), int(bytes->size()), &width, &height, &channels))
            Fail(what + ": not a PNG or JPEG image that can be decoded (" + Excerpt(stbi_failure_reason()) + ")");
        if (width <= 0 || height <= 0 || uint64_t(width) * uint64_t(height) > kMaxTexturePixels)
            Fail(what + ": " + std::to_string(width) + "x" + std::to_string(height) + " pixels, more than the loader's limit of " +
                 std::to_string(kMaxTexturePixels) + " per texture");
        const bool alpha = mImagesWithAlpha.count(aImage) > 0;
        unsigned char* pixels = stbi_load_from_memory(bytes->data(), int(bytes->size()), &width, &height, &channels, alpha ? 4 : 3);
        if (!pixels) Fail(what + ": decoding failed (" + Excerpt(stbi_failure_reason()) + ")");
        DecodedImage& decoded = mDecodedImages[aImage];
        decoded.mWidth = width;
        decoded.mHeight = height;
        const size_t count = size_t(width) * size_t(height);
        if (alpha) {
            decoded.mRgb.resize(count * 3);
            decoded.mAlpha.resize(count);
            for (size_t i = 0; i < count; i++) {
                for (size_t c = 0; c < 3; c++) decoded.mRgb[3 * i + c] = pixels[4 * i + c];
                decoded.mAlpha[i] = pixels[4 * i + 3];
            }
        } else {
            decoded.mRgb.assign(pixels, pixels + count * 3);
        }
        stbi_image_free(pixels);
        image.image.clear();
        image.image.shrink_to_fit();
        return decoded;
    }
    // The inverse sRGB transfer function (IEC 61966-2-1).
    static float SrgbToLinear(float aEncoded) {
        return aEncoded <= 0.04045f ? aEncoded / 12.92f : std::pow((aEncoded + 0.055f) / 1.055f, 2.4f);
    }
    // RFC 3986 percent-decoding of a relative URI ("my%20image.png"); a bad escape stays as is.
    static std::string PercentDecoded(const std::string& aUri) {
        std::string decoded;
        for (size_t i = 0; i < aUri.size(); i++) {
            if (aUri[i] == '%' && i + 2 < aUri.size() && std::isxdigit((unsigned char)aUri[i + 1]) && std::isxdigit((unsigned char)aUri[i + 2])) {
                decoded += char(std::stoi(aUri.substr(i + 1, 2), nullptr, 16));
                i += 2;
            } else {
                decoded += aUri[i];
            }
        }
        return decoded;
    }

    // The glTF alpha mode of a material (CheckAlphaModes has refused any other string).
    static AlphaMode AlphaModeOf(const tinygltf::Material& aMaterial) {
        return aMaterial.alphaMode == "MASK" ? AlphaMode::kMask : aMaterial.alphaMode == "BLEND" ? AlphaMode::kBlend : AlphaMode::kOpaque;
    }

    void ConvertMaterials() {
        // The images whose alpha a cut-out reads are decoded with it; no other is.
        for (const tinygltf::Material& source : mModel.materials) {
            const int texture = source.pbrMetallicRoughness.baseColorTexture.index;
            if (AlphaModeOf(source) != AlphaMode::kOpaque && texture >= 0 && texture < int(mModel.textures.size()))
                mImagesWithAlpha.insert(mModel.textures[size_t(texture)].source);
        }
        for (size_t m = 0; m < mModel.materials.size(); m++) {
            const tinygltf::Material& source = mModel.materials[m];
            const std::string what = "material " + std::to_string(m) + (source.name.empty() ? "" : " '" + Excerpt(source.name) + "'");
            const auto& pbr = source.pbrMetallicRoughness;
            std::vector<std::pair<const char*, int>> texCoordSets;  // the textures read, and their sets
            // What the header does not model is approximated and listed in one note.
            if (source.occlusionTexture.index >= 0) Approximated("occlusionTexture (occlusion is computed, not baked)");
            if (source.alphaMode == "BLEND") Approximated("alphaMode BLEND (thresholded: a hole where alpha < 0.5)");

            Material material;
            material.mName = source.name;
            material.mTwoSided = source.doubleSided;
            // Cut-outs: alpha = baseColorFactor's alpha x the base-colour texture's alpha,
            // read with the base colour's TEXCOORD set and transform (Material::mAlphaMode).
            material.mAlphaMode = AlphaModeOf(source);
            const bool cutOut = material.HasCutOut();
            if (cutOut) {
                material.mAlphaCutoff = float(source.alphaCutoff);
                if (pbr.baseColorFactor.size() == 4) material.mBaseColorAlpha = float(pbr.baseColorFactor[3]);
                if (!(material.mBaseColorAlpha >= 0.f && material.mBaseColorAlpha <= 1.f))
                    Fail(what + ": the alpha of baseColorFactor must be in [0, 1]");
                if (pbr.baseColorTexture.index >= 0) {
                    const TextureUse use = UseTexture(pbr.baseColorTexture.index, pbr.baseColorTexture.texCoord,
                                                      pbr.baseColorTexture.extensions, true, "baseColorTexture", what, true);
                    material.mAlphaTexture = use.mTexture;
                    texCoordSets.push_back({"baseColorTexture", use.mTexCoord});
                }
            }
            auto extension = source.extensions.find("SMALLVCM_material");
            if (extension != source.extensions.end()) {
                const tinygltf::Value& e = extension->second;
                if (!e.IsObject()) Fail(what + ": SMALLVCM_material must be an object");
                material.mDiffuseReflectance = ColorOr(e, "diffuse", Vec3(0.f), what);
                material.mPhongReflectance = ColorOr(e, "phong", Vec3(0.f), what);
                material.mMirrorReflectance = ColorOr(e, "mirror", Vec3(0.f), what);
                material.mPhongExponent = float(NumberOr(e, "phongExponent", 1.0));
                material.mIor = float(NumberOr(e, "ior", -1.0));
                if (pbr.baseColorTexture.index >= 0) Approximated("baseColorTexture with SMALLVCM_material (its colours are used)");
                if (pbr.metallicRoughnessTexture.index >= 0)
                    Approximated("metallicRoughnessTexture with SMALLVCM_material (its colours are used)");
            } else {
                // The documented mapping of pbrMetallicRoughness (docs/scene_format.md).
                Vec3 baseColor(1.f);
                if (pbr.baseColorFactor.size() >= 3)
                    baseColor = Vec3(float(pbr.baseColorFactor[0]), float(pbr.baseColorFactor[1]), float(pbr.baseColorFactor[2]));
                const float metallic = float(pbr.metallicFactor);
                const float roughness = float(pbr.roughnessFactor);
                if (!(metallic >= 0.f && metallic <= 1.f) || !(roughness >= 0.f && roughness <= 1.f))
                    Fail(what + ": metallicFactor and roughnessFactor must be in [0, 1]");
                // KHR_materials_transmission: the dielectric's share t of the surface is
                // glass, so g = (1 - metallic) t is glass (refraction tinted by the base
                // colour, Fresnel reflection untinted) and the rest is the opaque mapping
                // with (1 - t) of its dielectric part.
                auto transmission = source.extensions.find("KHR_materials_transmission");
                float t = 0.f;
                if (transmission != source.extensions.end()) {
                    t = float(NumberOr(transmission->second, "transmissionFactor", 0.0));
                    if (!(t >= 0.f && t <= 1.f))
                        Fail(what + ": KHR_materials_transmission.transmissionFactor must be a number in [0, 1]");
                    if (transmission->second.Has("transmissionTexture"))
                        Approximated("transmissionTexture (transmissionFactor is used)");
                }
                const float glass = (1.f - metallic) * t;
                if (t > 0.f && glass == 0.f)  // glTF's metallicFactor defaults to 1: a metal
                    Approximated("KHR_materials_transmission on a fully metallic material (no glass: metallicFactor is 1; set it to 0 for glass)");
                float ior = 1.5f;
                if (glass > 0.f) {
                    auto iorExtension = source.extensions.find("KHR_materials_ior");
                    if (iorExtension != source.extensions.end()) ior = float(NumberOr(iorExtension->second, "ior", 1.5));
                    if (!(ior >= 1.f || ior == 0.f) || !std::isfinite(ior))
                        Fail(what + ": KHR_materials_ior.ior must be a number >= 1, or 0");
                    if (roughness > 0.f) Approximated("roughnessFactor on transmission (rendered as smooth glass)");
                }
                // The written rule (MetallicRoughnessRule), once for the factors.
                const MetallicRoughnessMaterial rule = MetallicRoughnessRule(baseColor, metallic, roughness, t, ior);
                material.mDiffuseReflectance = rule.mDiffuse;
                material.mPhongReflectance = rule.mPhong;
                material.mPhongExponent = rule.mPhongExponent;
                material.mMirrorReflectance = rule.mMirror;
                material.mOpaqueMirror = rule.mOpaqueMirror;
                material.mTransmittance = rule.mTransmittance;
                material.mIor = rule.mIor;
                if (pbr.baseColorTexture.index >= 0) {
                    const TextureUse use = UseTexture(pbr.baseColorTexture.index, pbr.baseColorTexture.texCoord,
                                                      pbr.baseColorTexture.extensions, true, "baseColorTexture", what, cutOut);
                    material.mBaseColorTexture = use.mTexture;
                    texCoordSets.push_back({"baseColorTexture", use.mTexCoord});
                    material.mSpecularUntinted = rule.mSpecularUntinted;
                }
                // Metal and roughness per texel: the Bsdf applies the rule at each hit
                // (Material::mMetallicRoughnessTexture); the texture is linear, not sRGB.
                if (pbr.metallicRoughnessTexture.index >= 0) {
                    const TextureUse use = UseTexture(pbr.metallicRoughnessTexture.index, pbr.metallicRoughnessTexture.texCoord,
                                                      pbr.metallicRoughnessTexture.extensions, false, "metallicRoughnessTexture", what);
                    material.mMetallicRoughnessTexture = use.mTexture;
                    texCoordSets.push_back({"metallicRoughnessTexture", use.mTexCoord});
                    material.mBaseColor = baseColor;
                    material.mMetallic = metallic;
                    material.mRoughness = roughness;
                    material.mTransmission = t;
                    material.mRuleIor = ior;
                }
            }
            CheckColor(material.mDiffuseReflectance, what + ": the diffuse reflectance", true);
            CheckColor(material.mPhongReflectance, what + ": the Phong reflectance", true);
            CheckColor(material.mMirrorReflectance, what + ": the mirror reflectance", true);
            CheckColor(material.mOpaqueMirror, what + ": the opaque mirror reflectance", true);
            CheckColor(material.mTransmittance, what + ": the transmittance", true);
            if (MaxComponent(material.mDiffuseReflectance + material.mPhongReflectance) > 1.f)
                Fail(what + ": diffuse + Phong reflectance exceeds 1 (it would create energy)");
            if (!std::isfinite(material.mPhongExponent) || material.mPhongExponent < 0.f)
                Fail(what + ": the Phong exponent must be finite and >= 0");
            if (!std::isfinite(material.mIor) || (material.mIor >= 0.f && material.mIor < 1e-3f))
                Fail(what + ": ior must be a positive index of refraction, or -1 for none");
            if (material.mIor > 0.f && !IsBlack(material.mDiffuseReflectance + material.mPhongReflectance + material.mOpaqueMirror))
                material.mTwoSided = false;  // glass decides inside from outside by the normal
            // The medium inside the material's closed mesh (docs/scene_format.md 4.4). Without
            // refraction its surface is an index-matched boundary: no component at all.
            const int medium = MaterialMedium(source, what, material.mIor > 0.f);
            if (medium >= 0 && !(material.mIor > 0.f)) {
                Material boundary;
                boundary.mName = material.mName;
                material = boundary;
            }

            // Emission: emissiveFactor times KHR_materials_emissive_strength.
            Vec3 emission(0.f);
            if (source.emissiveFactor.size() == 3)
                emission = Vec3(float(source.emissiveFactor[0]), float(source.emissiveFactor[1]), float(source.emissiveFactor[2]));
            auto strength = source.extensions.find("KHR_materials_emissive_strength");
            if (strength != source.extensions.end())
                emission *= float(NumberOr(strength->second, "emissiveStrength", 1.0));
            CheckColor(emission, what + ": the emission", false);
            if (cutOut && !IsBlack(emission)) Approximated("alphaMode " + source.alphaMode + " on an emitting material (rendered whole)");
            // emissiveTexture multiplies the factor (an sRGB texture, like the base colour);
            // with a black factor it changes nothing, and is not decoded.
            int emissionTexture = -1;
            if (source.emissiveTexture.index >= 0 && !IsBlack(emission)) {
                const TextureUse use = UseTexture(source.emissiveTexture.index, source.emissiveTexture.texCoord,
                                                  source.emissiveTexture.extensions, true, "emissiveTexture", what);
                emissionTexture = use.mTexture;
                texCoordSets.push_back({"emissiveTexture", use.mTexCoord});
            }
            // The normal map (any material: it tilts the shading normal, whatever reflects).
            if (source.normalTexture.index >= 0) {
                const TextureUse use = UseTexture(source.normalTexture.index, source.normalTexture.texCoord,
                                                  source.normalTexture.extensions, false, "normalTexture", what);
                material.mNormalTexture = use.mTexture;
                material.mNormalScale = float(source.normalTexture.scale);
                if (!std::isfinite(material.mNormalScale))
                    Fail(what + ": normalTexture.scale must be a finite number");
                texCoordSets.push_back({"normalTexture", use.mTexCoord});
            }
            // One set of texture coordinates per triangle: the textures a material reads
            // must agree on it.
            for (const auto& [slot, set] : texCoordSets)
                if (set != texCoordSets.front().second)
                    Fail(what + ": its " + texCoordSets.front().first + " reads TEXCOORD_" + std::to_string(texCoordSets.front().second) +
                         " and its " + slot + " TEXCOORD_" + std::to_string(set) +
                         "; the textures of one material must share one set of texture coordinates");
            mMaterialTexCoord.push_back(texCoordSets.empty() ? 0 : texCoordSets.front().second);
            mMaterialEmission.push_back(emission);
            mMaterialEmissionTexture.push_back(emissionTexture);
            mMaterialEmitsTwoSided.push_back(source.doubleSided);
            // Emitters are black (SmallVCM's lights do not reflect) unless an explicit
            // SMALLVCM_material gives them a reflectance, or an emissiveTexture says where
            // they glow: such a material is a surface like any other with a glow map on it
            // (a screen, a label, a lamp's bulb), as glTF adds emission to reflection.
            if (!IsBlack(emission) && extension == source.extensions.end() && emissionTexture < 0) {
                Material black;
                black.mName = material.mName;
                material = black;
            }
            material.mMedium = medium;
            mScene.AddMaterial(material);
        }
    }

    // --- media (docs/scene_format.md 4.4) ------------------------------------------------
    // SMALLVCM_medium: {"sigmaA": [r, g, b], "sigmaS": [r, g, b], "g": g}, coefficients in
    // 1 / scene unit (default 0), g the Henyey-Greenstein asymmetry (default 0). Any other
    // member is refused: a misspelt one would silently leave a coefficient 0.
    Medium ReadMedium(const tinygltf::Value& aValue, const std::string& aWhat, const std::string& aName) const {
        const std::string what = aWhat + ": SMALLVCM_medium";
        if (!aValue.IsObject()) Fail(what + " must be an object");
        for (const std::string& key : aValue.Keys())
            if (key != "sigmaA" && key != "sigmaS" && key != "g")
                Fail(what + " has an unknown member '" + Excerpt(key) + "' (it has sigmaA, sigmaS and g)");
        Medium medium;
        medium.mName = aName;
        medium.mSigmaA = ColorOr(aValue, "sigmaA", Vec3(0.f), what);
        medium.mSigmaS = ColorOr(aValue, "sigmaS", Vec3(0.f), what);
        CheckColor(medium.mSigmaA, what + ".sigmaA", false);
        CheckColor(medium.mSigmaS, what + ".sigmaS", false);
        medium.mG = float(NumberOr(aValue, "g", 0.0));
        if (!(std::abs(medium.mG) < 1.f)) Fail(what + ".g must be a number in (-1, 1) (the Henyey-Greenstein asymmetry)");
        return medium;
    }

    // KHR_materials_volume's medium: white light that travels attenuationDistance d in it
    // becomes attenuationColor c (Beer-Lambert), so sigma_a = -ln(c) / d per channel; it
    // does not scatter. d defaults to infinity (no absorption). A channel c = 0 (all of it
    // absorbed: sigma_a infinite) is clamped to 1e-38, sigma_a = 87.5 / d, and noted when
    // the medium is used (aUsed). thicknessFactor's value does not matter here (it stands
    // in for the geometry in a rasteriser, and the geometry is traced), only whether it is
    // 0: VolumeIsThinWalled.
    Medium VolumeMedium(const tinygltf::Value& aVolume, const std::string& aWhat, const std::string& aName, bool aUsed) {
        const std::string what = aWhat + ": KHR_materials_volume";
        if (!aVolume.IsObject()) Fail(what + " must be an object");
        const double distance = NumberOr(aVolume, "attenuationDistance", std::numeric_limits<double>::infinity());
        if (!(distance > 0.0)) Fail(what + ".attenuationDistance must be a number > 0 (absent: infinity, no absorption)");
        const Vec3 color = ColorOr(aVolume, "attenuationColor", Vec3(1.f), what);
        if (!(color.x >= 0.f && color.y >= 0.f && color.z >= 0.f && MaxComponent(color) <= 1.f))
            Fail(what + ".attenuationColor must be 3 numbers in [0, 1]");
        Medium medium;
        medium.mName = aName;
        for (int c = 0; c < 3; c++) {
            double kept = double(color[c]);
            if (kept == 0.0 && std::isfinite(distance)) {
                kept = 1e-38;
                if (aUsed) Approximated("KHR_materials_volume attenuationColor 0 (sigma_a clamped to 87.5 / attenuationDistance)");
            }
            medium.mSigmaA[c] = float(std::max(0.0, -std::log(kept) / distance));
        }
        CheckColor(medium.mSigmaA, what + ": sigma_a = -ln(attenuationColor) / attenuationDistance", false);
        return medium;
    }

    // glTF's thin-walled material: KHR_materials_volume's thicknessFactor 0 (its default)
    // says the surface has no volume behind it, so nothing inside it absorbs.
    bool VolumeIsThinWalled(const tinygltf::Value& aVolume, const std::string& aWhat) const {
        const double thickness = NumberOr(aVolume, "thicknessFactor", 0.0);
        if (!(thickness >= 0.0 && std::isfinite(thickness)))
            Fail(aWhat + ": KHR_materials_volume.thicknessFactor must be a finite number >= 0");
        return thickness == 0.0;
    }

    // The medium inside the closed mesh a material covers, added to the scene, or -1:
    // SMALLVCM_medium when the material has it, else KHR_materials_volume's when it
    // absorbs, the material refracts (aRefracts: glTF's volume needs transmission) and
    // is not thin-walled.
    // Every medium extension is checked, used or not.
    int MaterialMedium(const tinygltf::Material& aSource, const std::string& aWhat, bool aRefracts) {
        const std::string name = aSource.name.empty() ? aWhat : aSource.name;
        const auto own = aSource.extensions.find("SMALLVCM_medium");
        const auto volume = aSource.extensions.find("KHR_materials_volume");
        const bool hasOwn = own != aSource.extensions.end(), hasVolume = volume != aSource.extensions.end();
        const bool thinWalled = hasVolume && VolumeIsThinWalled(volume->second, aWhat);
        const Medium absorbing = hasVolume ? VolumeMedium(volume->second, aWhat, name, !hasOwn && aRefracts && !thinWalled) : Medium();
        if (hasOwn) {
            const Medium medium = ReadMedium(own->second, aWhat, name);
            if (hasVolume) Approximated("KHR_materials_volume beside SMALLVCM_medium (ignored: SMALLVCM_medium is used)");
            return mScene.AddMedium(medium);
        }
        if (!hasVolume) return -1;
        if (!aRefracts) {
            Approximated("KHR_materials_volume on a material that does not refract (ignored: the volume needs KHR_materials_transmission)");
            return -1;
        }
        if (!absorbing.Attenuates()) return -1;
        if (thinWalled) {
            Approximated("KHR_materials_volume with thicknessFactor 0 (glTF's thin-walled surface: no volume inside, its attenuation ignored)");
            return -1;
        }
        return mScene.AddMedium(absorbing);
    }

    // The medium filling all space outside every closed mesh: the scene's SMALLVCM_medium,
    // or the options' instead (the file's is checked all the same).
    void ReadSceneMedium(int aSceneIndex) {
        const tinygltf::Scene& scene = mModel.scenes[size_t(aSceneIndex)];
        const auto extension = scene.extensions.find("SMALLVCM_medium");
        if (extension != scene.extensions.end()) {
            const Medium medium = ReadMedium(extension->second, "scene " + std::to_string(aSceneIndex), "scene medium");
            if (!mOptions.mReplaceSceneMedium) mScene.mSceneMedium = mScene.AddMedium(medium);
        }
        if (mOptions.mReplaceSceneMedium) {
            Medium medium = mOptions.mSceneMedium;
            if (medium.mName.empty()) medium.mName = "scene medium";
            mScene.mSceneMedium = mScene.AddMedium(medium);
        }
    }

    // The default material of glTF (no material index): white, metallic 1, roughness 1.
    int DefaultMaterial() {
        if (mDefaultMaterial < 0) {
            Material material;
            material.mName = "glTF default";
            material.mPhongReflectance = Vec3(1.f);
            material.mPhongExponent = 0.f;
            mDefaultMaterial = mScene.AddMaterial(material);
            mMaterialEmission.push_back(Vec3(0.f));
            mMaterialEmissionTexture.push_back(-1);
            mMaterialTexCoord.push_back(0);
            mMaterialEmitsTwoSided.push_back(false);
        }
        return mDefaultMaterial;
    }

    int MaterialIndex(int aIndex, const std::string& aWhat) {
        if (aIndex == -1) return DefaultMaterial();  // tinygltf's "absent"; other negatives are no index
        if (aIndex < 0) Fail(aWhat + " refers to material " + std::to_string(aIndex) + ", which does not exist");
        if (aIndex >= int(mModel.materials.size())) Fail(aWhat + " refers to material " + std::to_string(aIndex) + ", which does not exist");
        return aIndex;
    }

    // --- float32 ---------------------------------------------------------------------------
    // Transforms are combined in double, the scene stores float32: a value can be finite
    // in double (1e300) and infinite in float, and |v| of such a vector overflows even in
    // double (then normalize gives 0, or NaN).
    Vec3 ToFloat(const glm::dvec3& aValue, const std::string& aWhat) const {
        const Vec3 value(aValue);
        if (!IsFinite(value)) Fail(aWhat + " is not finite in float32 (a coordinate beyond 3.4e38)");
        return value;
    }
    // aValue / |aValue| without overflow or underflow; false when there is no direction.
    static bool Direction(const glm::dvec3& aValue, glm::dvec3& oDirection) {
        const double largest = std::max(std::abs(aValue.x), std::max(std::abs(aValue.y), std::abs(aValue.z)));
        if (!(largest > 0.0) || !std::isfinite(largest)) return false;
        oDirection = glm::normalize(aValue / largest);
        return true;
    }

    // --- nodes ---------------------------------------------------------------------------
    Mat4 LocalMatrix(const tinygltf::Node& aNode, const std::string& aWhat) const {
        if (aNode.matrix.size() == 16) {
            Mat4 m;
            for (int c = 0; c < 4; c++) for (int r = 0; r < 4; r++) m[c][r] = aNode.matrix[size_t(4 * c + r)];
            return m;
        }
        if (!aNode.matrix.empty()) Fail(aWhat + ": 'matrix' must have 16 numbers");
        // tinygltf keeps a number array of any length; anything but 3, 4, 3 was ignored.
        if (!aNode.translation.empty() && aNode.translation.size() != 3) Fail(aWhat + ": 'translation' must have 3 numbers");
        if (!aNode.rotation.empty() && aNode.rotation.size() != 4) Fail(aWhat + ": 'rotation' must have 4 numbers");
        if (!aNode.scale.empty() && aNode.scale.size() != 3) Fail(aWhat + ": 'scale' must have 3 numbers");
        Mat4 translation(1.0), rotation(1.0), scale(1.0);
        if (aNode.translation.size() == 3)
            translation[3] = glm::dvec4(aNode.translation[0], aNode.translation[1], aNode.translation[2], 1.0);
        if (aNode.rotation.size() == 4) {
            // Scaled by the largest component first: the squares of (1e300, ...) overflow
            // to infinity (n = inf, q = 0: no rotation), those of (1e-300, ...) underflow.
            const double largest = std::max(std::max(std::abs(aNode.rotation[0]), std::abs(aNode.rotation[1])),
                                            std::max(std::abs(aNode.rotation[2]), std::abs(aNode.rotation[3])));
            if (!std::isfinite(largest)) Fail(aWhat + ": the rotation quaternion is not finite");
            if (!(largest > 0.0)) Fail(aWhat + ": the rotation quaternion is zero");
            const double x = aNode.rotation[0] / largest, y = aNode.rotation[1] / largest, z = aNode.rotation[2] / largest,
                         w = aNode.rotation[3] / largest;
            const double n = std::sqrt(x * x + y * y + z * z + w * w);
            const double qx = x / n, qy = y / n, qz = z / n, qw = w / n;
            rotation[0] = glm::dvec4(1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy + qz * qw), 2 * (qx * qz - qy * qw), 0);
            rotation[1] = glm::dvec4(2 * (qx * qy - qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz + qx * qw), 0);
            rotation[2] = glm::dvec4(2 * (qx * qz + qy * qw), 2 * (qy * qz - qx * qw), 1 - 2 * (qx * qx + qy * qy), 0);
        }
        if (aNode.scale.size() == 3) {
            scale[0][0] = aNode.scale[0]; scale[1][1] = aNode.scale[1]; scale[2][2] = aNode.scale[2];
        }
        return translation * rotation * scale;
    }

    void VisitNode(int aNodeIndex, const Mat4& aParent, int aDepth) {
        if (aNodeIndex < 0 || aNodeIndex >= int(mModel.nodes.size())) Fail("a scene refers to node " + std::to_string(aNodeIndex) + ", which does not exist");
        if (aDepth > 64) Fail("the node hierarchy is deeper than 64 levels, or has a cycle");
        if (!mVisitedNodes.insert(aNodeIndex).second)
            Fail("node " + std::to_string(aNodeIndex) + " is reached twice: it has more than one parent, or is part of a cycle (glTF nodes form trees)");
        const tinygltf::Node& node = mModel.nodes[size_t(aNodeIndex)];
        const std::string what = "node " + std::to_string(aNodeIndex) + (node.name.empty() ? "" : " '" + Excerpt(node.name) + "'");
        const Mat4 world = aParent * LocalMatrix(node, what);
        for (int c = 0; c < 4; c++) for (int r = 0; r < 4; r++)
            if (!std::isfinite(world[c][r])) Fail(what + ": its transform is not finite");
        // tinygltf stores an absent index as -1 and a written one as it is: -5 is no index.
        if (node.skin != -1) Fail(what + ": skins are not supported");
        if (node.mesh != -1) AddMesh(node.mesh, world, what);
        if (node.camera != -1) AddCamera(node.camera, world, what);
        auto sphere = node.extensions.find("SMALLVCM_sphere");
        if (sphere != node.extensions.end()) AddSphere(sphere->second, world, what);
        auto light = node.extensions.find("KHR_lights_punctual");
        if (light != node.extensions.end()) AddPunctualLight(light->second, world, what);
        for (int child : node.children) VisitNode(child, world, aDepth + 1);
    }

    // --- compressed geometry ---------------------------------------------------------
    // Decoded bytes come from untrusted ones: each decoded size is checked against the
    // loader's limits (as if it were one more file read) before it is allocated.
    void CheckDecodedSize(uint64_t aBytes, const std::string& aWhat) {
        if (aBytes > mOptions.mMaxFileBytes || aBytes > mOptions.mMaxTotalBytes - std::min(mOptions.mMaxTotalBytes, mBytesRead))
            Fail(aWhat + ": decodes to " + ByteCount(aBytes) + ", more than the loader's limits allow (GltfLoadOptions::mMaxFileBytes, "
                         "mMaxTotalBytes)");
        mBytesRead += aBytes;
    }
    // Decoded bytes go to a buffer and a view of their own; returns the view.
    int AddDecodedView(std::vector<unsigned char>&& aBytes) {
        tinygltf::Buffer buffer;
        buffer.data = std::move(aBytes);
        tinygltf::BufferView view;
        view.buffer = int(mModel.buffers.size());
        view.byteLength = buffer.data.size();
        mModel.buffers.push_back(std::move(buffer));
        mModel.bufferViews.push_back(view);
        return int(mModel.bufferViews.size()) - 1;
    }
    // A member of an extension object that must be an integer in [0, 2^53).
    uint64_t ExtensionInteger(const tinygltf::Value& aObject, const char* aKey, const std::string& aWhat) const {
        if (!aObject.Has(aKey)) Fail(aWhat + ": '" + aKey + "' is missing");
        const tinygltf::Value& value = aObject.Get(aKey);
        const double number = value.IsNumber() ? value.GetNumberAsDouble() : -1.0;
        if (!(number >= 0.0 && number < 9.0e15 && number == std::floor(number)))
            Fail(aWhat + ": '" + aKey + "' must be a non-negative integer");
        return uint64_t(number);
    }

    // EXT_meshopt_compression: each compressed buffer view is decoded from the bytes the
    // extension names (its buffer, byteOffset, byteLength) into count x byteStride bytes:
    // mode ATTRIBUTES by meshopt_decodeVertexBuffer, TRIANGLES by meshopt_decodeIndexBuffer,
    // INDICES by meshopt_decodeIndexSequence, then its filter (OCTAHEDRAL, QUATERNION,
    // EXPONENTIAL) undone in place. The view then names the decoded bytes, and accessors
    // read it as any other; its fallback buffer is not read.
    void DecodeMeshoptViews() {
        for (size_t v = 0; v < mModel.bufferViews.size(); v++) {
            const auto found = mModel.bufferViews[v].extensions.find("EXT_meshopt_compression");
            if (found == mModel.bufferViews[v].extensions.end()) continue;
            const std::string what = "bufferView " + std::to_string(v) + ": EXT_meshopt_compression";
            const tinygltf::Value& e = found->second;
            if (!e.IsObject()) Fail(what + " must be an object");
            const uint64_t buffer = ExtensionInteger(e, "buffer", what), length = ExtensionInteger(e, "byteLength", what);
            const uint64_t offset = e.Has("byteOffset") ? ExtensionInteger(e, "byteOffset", what) : 0;
            const uint64_t stride = ExtensionInteger(e, "byteStride", what), count = ExtensionInteger(e, "count", what);
            const auto text = [&](const char* aKey, const char* aDefault) {
                if (!e.Has(aKey)) return std::string(aDefault);
                if (!e.Get(aKey).IsString()) Fail(what + ": '" + aKey + "' must be a string");
                return e.Get(aKey).Get<std::string>();
            };
            const std::string mode = text("mode", ""), filter = text("filter", "NONE");
            if (buffer >= mModel.buffers.size()) Fail(what + " refers to buffer " + std::to_string(buffer) + ", which does not exist");
            const size_t sourceSize = mModel.buffers[size_t(buffer)].data.size();
            if (offset > sourceSize || length > sourceSize - offset)
                Fail(what + ": its compressed bytes (byteOffset " + std::to_string(offset) + ", byteLength " + std::to_string(length) +
                     ") lie past the end of buffer " + std::to_string(buffer) + " (" + ByteCount(sourceSize) + ")");
            // What the decoders require (meshoptimizer asserts it rather than returning an error).
            const bool attributes = mode == "ATTRIBUTES";
            if (attributes) {
                if (stride == 0 || stride > 256 || stride % 4 != 0)
                    Fail(what + ": byteStride " + std::to_string(stride) + " (mode ATTRIBUTES takes a multiple of 4 from 4 to 256)");
            } else if (mode == "TRIANGLES" || mode == "INDICES") {
                if (stride != 2 && stride != 4) Fail(what + ": byteStride " + std::to_string(stride) + " (mode " + mode + " takes 2 or 4)");
                if (mode == "TRIANGLES" && count % 3 != 0) Fail(what + ": count " + std::to_string(count) + " (mode TRIANGLES takes a multiple of 3)");
            } else {
                Fail(what + ": mode '" + Excerpt(mode) + "' (ATTRIBUTES, TRIANGLES or INDICES)");
            }
            const bool filterFits = filter == "NONE" || (attributes && (filter == "EXPONENTIAL" || (filter == "QUATERNION" && stride == 8) ||
                                                                        (filter == "OCTAHEDRAL" && (stride == 4 || stride == 8))));
            if (!filterFits)
                Fail(what + ": filter '" + Excerpt(filter) + "' with mode " + mode + " and byteStride " + std::to_string(stride) +
                     " (OCTAHEDRAL takes ATTRIBUTES of stride 4 or 8, QUATERNION of stride 8, EXPONENTIAL any ATTRIBUTES)");
            if (count > (uint64_t(1) << 31)) Fail(what + ": count " + std::to_string(count) + " is more than 2^31");
            CheckDecodedSize(count * stride, what);
            std::vector<unsigned char> decoded(size_t(count * stride));
            const unsigned char* source = mModel.buffers[size_t(buffer)].data.data() + offset;
            const int status = attributes ? meshopt_decodeVertexBuffer(decoded.data(), size_t(count), size_t(stride), source, size_t(length))
                             : mode == "TRIANGLES" ? meshopt_decodeIndexBuffer(decoded.data(), size_t(count), size_t(stride), source, size_t(length))
                                                   : meshopt_decodeIndexSequence(decoded.data(), size_t(count), size_t(stride), source, size_t(length));
            if (status != 0)
                Fail(what + ": its " + std::to_string(length) + " compressed bytes do not decode to " + std::to_string(count) + " x " +
                     std::to_string(stride) + " bytes (meshoptimizer error " + std::to_string(status) + ": damaged, or not meshopt data)");
            if (filter == "OCTAHEDRAL") meshopt_decodeFilterOct(decoded.data(), size_t(count), size_t(stride));
            else if (filter == "QUATERNION") meshopt_decodeFilterQuat(decoded.data(), size_t(count), size_t(stride));
            else if (filter == "EXPONENTIAL") meshopt_decodeFilterExp(decoded.data(), size_t(count), size_t(stride));
            const int decodedView = AddDecodedView(std::move(decoded));
            tinygltf::BufferView& view = mModel.bufferViews[v];
            view.buffer = mModel.bufferViews[size_t(decodedView)].buffer;
            view.byteOffset = 0;
            view.byteLength = size_t(count * stride);
            if (attributes) view.byteStride = size_t(stride);
        }
    }

    // KHR_draco_mesh_compression: a compressed primitive's stream (the extension's
    // bufferView) is decoded by libdraco into a mesh of points and faces. The indices
    // accessor gets the faces' corners (3 per face, unsigned int), each attribute the
    // extension names gets the stream's attribute of that unique id, one value per point,
    // in the component type its accessor declares; each is written to a view of its own
    // that the accessor then names, so that it is read like any accessor. The accessors'
    // counts and types are what the stream must hold: a stream that disagrees is refused.
    void DecodeDracoPrimitives() {
        std::map<int, int> filledBy;  // accessor -> the view of the stream that filled it
        for (size_t m = 0; m < mModel.meshes.size(); m++)
            for (size_t p = 0; p < mModel.meshes[m].primitives.size(); p++) {
                const tinygltf::Primitive& primitive = mModel.meshes[m].primitives[p];
                const auto found = primitive.extensions.find("KHR_draco_mesh_compression");
                if (found != primitive.extensions.end())
                    DecodeDracoPrimitive(primitive, found->second, "mesh " + std::to_string(m) + " primitive " + std::to_string(p) +
                                                                    ": KHR_draco_mesh_compression", filledBy);
            }
    }
    void DecodeDracoPrimitive(const tinygltf::Primitive& aPrimitive, const tinygltf::Value& aExtension, const std::string& aWhat,
                              std::map<int, int>& ioFilledBy) {
        if (!aExtension.IsObject() || !aExtension.Has("attributes") || !aExtension.Get("attributes").IsObject())
            Fail(aWhat + " must be an object with a bufferView and an attributes object");
        const uint64_t streamView = ExtensionInteger(aExtension, "bufferView", aWhat);
        if (streamView >= mModel.bufferViews.size()) Fail(aWhat + " refers to bufferView " + std::to_string(streamView) + ", which does not exist");
        // The accessors it fills (-1: the indices), all checked before a byte is decoded.
        struct Target { std::string mSemantic; int mAccessor; int mId; };
        std::vector<Target> targets;
        if (aPrimitive.indices >= 0) targets.push_back({"indices", aPrimitive.indices, -1});
        const tinygltf::Value& ids = aExtension.Get("attributes");
        for (const std::string& semantic : ids.Keys()) {
            const tinygltf::Value& id = ids.Get(semantic);
            if (!id.IsInt() || id.GetNumberAsInt() < 0) Fail(aWhat + ": the id of " + Excerpt(semantic) + " must be a non-negative integer");
            const auto attribute = aPrimitive.attributes.find(semantic);
            if (attribute == aPrimitive.attributes.end())
                Fail(aWhat + ": it compresses " + Excerpt(semantic) + ", which the primitive has no accessor for");
            targets.push_back({semantic, attribute->second, id.GetNumberAsInt()});
        }
        for (const Target& target : targets) {
            if (target.mAccessor < 0 || target.mAccessor >= int(mModel.accessors.size()))
                Fail(aWhat + ": its " + Excerpt(target.mSemantic) + " refers to accessor " + std::to_string(target.mAccessor) + ", which does not exist");
            const auto filled = ioFilledBy.find(target.mAccessor);
            if (filled == ioFilledBy.end()) continue;
            if (filled->second == int(streamView)) return;  // the same stream, decoded already for another primitive
            Fail(aWhat + ": accessor " + std::to_string(target.mAccessor) + " is filled by two Draco streams (bufferViews " +
                 std::to_string(filled->second) + " and " + std::to_string(streamView) + ")");
        }
        const auto componentSize = [](int aType) {
            switch (aType) {
            case TINYGLTF_COMPONENT_TYPE_BYTE: case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return 1;
            case TINYGLTF_COMPONENT_TYPE_SHORT: case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: return 2;
            case TINYGLTF_COMPONENT_TYPE_FLOAT: return 4;
            default: return 0;
            }
        };
        for (const Target& target : targets) {
            const tinygltf::Accessor& accessor = mModel.accessors[size_t(target.mAccessor)];
            const int components = target.mId < 0 ? 1 : tinygltf::GetNumComponentsInType(uint32_t(accessor.type));
            const int size = target.mId < 0 ? 4 : componentSize(accessor.componentType);
            if (components < 1 || components > 4 || size == 0)
                Fail(aWhat + ": the accessor of " + Excerpt(target.mSemantic) + " (accessor " + std::to_string(target.mAccessor) +
                     ") has a type this loader does not read from Draco (scalars and vectors of float, byte or short)");
            if (accessor.count > (size_t(1) << 31)) Fail(aWhat + ": accessor " + std::to_string(target.mAccessor) + " counts more than 2^31");
            CheckDecodedSize(uint64_t(accessor.count) * uint64_t(components * size), aWhat);
        }
        const tinygltf::BufferView& view = mModel.bufferViews[size_t(streamView)];
        if (view.buffer < 0 || view.buffer >= int(mModel.buffers.size())) Fail(aWhat + ": its bufferView refers to a missing buffer");
        const std::vector<unsigned char>& bytes = mModel.buffers[size_t(view.buffer)].data;
        if (view.byteOffset > bytes.size() || view.byteLength > bytes.size() - view.byteOffset)
            Fail(aWhat + ": its bufferView " + std::to_string(streamView) + " lies past the end of its buffer");
        draco::DecoderBuffer input;
        input.Init(reinterpret_cast<const char*>(bytes.data() + view.byteOffset), view.byteLength);
        draco::Decoder decoder;
        draco::StatusOr<std::unique_ptr<draco::Mesh>> decoded = decoder.DecodeMeshFromBuffer(&input);
        if (!decoded.ok() || !decoded.value())
            Fail(aWhat + ": the stream in bufferView " + std::to_string(streamView) + " does not decode (libdraco: " +
                 Excerpt(decoded.ok() ? std::string("no mesh") : decoded.status().error_msg_string(), 120) + ")");
        const std::unique_ptr<draco::Mesh> mesh = std::move(decoded).value();
        const uint64_t points = mesh->num_points();
        for (const Target& target : targets) {
            tinygltf::Accessor& accessor = mModel.accessors[size_t(target.mAccessor)];
            std::vector<unsigned char> out;
            if (target.mId < 0) {
                if (uint64_t(mesh->num_faces()) * 3 != accessor.count)
                    Fail(aWhat + ": the stream holds " + std::to_string(mesh->num_faces()) + " triangles, the indices accessor " +
                         std::to_string(target.mAccessor) + " counts " + std::to_string(accessor.count) + " indices");
                out.resize(accessor.count * 4);
                for (uint32_t f = 0; f < mesh->num_faces(); f++)
                    for (int c = 0; c < 3; c++) {
                        const uint32_t index = mesh->face(draco::FaceIndex(f))[size_t(c)].value();
                        if (index >= points) Fail(aWhat + ": the stream's triangle " + std::to_string(f) + " names a point it does not hold");
                        std::memcpy(out.data() + (size_t(f) * 3 + size_t(c)) * 4, &index, 4);
                    }
                accessor.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
            } else {
                const draco::PointAttribute* attribute = mesh->GetAttributeByUniqueId(uint32_t(target.mId));
                const int components = tinygltf::GetNumComponentsInType(uint32_t(accessor.type));
                if (!attribute) Fail(aWhat + ": the stream has no attribute of id " + std::to_string(target.mId) + " (" + Excerpt(target.mSemantic) + ")");
                if (attribute->num_components() != components)
                    Fail(aWhat + ": the stream's " + Excerpt(target.mSemantic) + " has " + std::to_string(int(attribute->num_components())) +
                         " components, its accessor " + std::to_string(components));
                if (points != accessor.count)
                    Fail(aWhat + ": the stream holds " + std::to_string(points) + " points, the accessor of " + Excerpt(target.mSemantic) +
                         " (accessor " + std::to_string(target.mAccessor) + ") counts " + std::to_string(accessor.count));
                const int size = componentSize(accessor.componentType);
                out.resize(accessor.count * size_t(components * size));
                bool converted = false;
                switch (accessor.componentType) {
                case TINYGLTF_COMPONENT_TYPE_BYTE: converted = DracoValues<int8_t>(*attribute, points, components, out.data()); break;
                case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: converted = DracoValues<uint8_t>(*attribute, points, components, out.data()); break;
                case TINYGLTF_COMPONENT_TYPE_SHORT: converted = DracoValues<int16_t>(*attribute, points, components, out.data()); break;
                case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: converted = DracoValues<uint16_t>(*attribute, points, components, out.data()); break;
                default: converted = DracoValues<float>(*attribute, points, components, out.data()); break;
                }
                if (!converted) Fail(aWhat + ": the stream's " + Excerpt(target.mSemantic) + " does not convert to its accessor's component type");
            }
            accessor.bufferView = AddDecodedView(std::move(out));
            accessor.byteOffset = 0;
            ioFilledBy[target.mAccessor] = int(streamView);
        }
    }
    // aPoints values of aComponents components of aAttribute as T, one after the other.
    template <typename T>
    static bool DracoValues(const draco::PointAttribute& aAttribute, uint64_t aPoints, int aComponents, unsigned char* oBytes) {
        std::array<T, 4> value{};
        for (uint64_t i = 0; i < aPoints; i++) {
            const draco::AttributeValueIndex index = aAttribute.mapped_index(draco::PointIndex(uint32_t(i)));
            if (index.value() >= aAttribute.size() || !aAttribute.ConvertValue<T>(index, int8_t(aComponents), value.data())) return false;
            std::memcpy(oBytes + i * sizeof(T) * size_t(aComponents), value.data(), sizeof(T) * size_t(aComponents));
        }
        return true;
    }

    // Reads an accessor as aComponents-wide rows of doubles, after checking its type,
    // component type and that every byte it names lies inside its buffer.
    enum class AccessorKind { kIndices, kPositions, kNormals, kTexcoords, kTangents };
    std::vector<double> ReadAccessor(int aIndex, int aType, AccessorKind aKind, const std::string& aWhat) const {
        const bool aIndices = aKind == AccessorKind::kIndices;
        if (aIndex < 0 || aIndex >= int(mModel.accessors.size())) Fail(aWhat + " refers to accessor " + std::to_string(aIndex) + ", which does not exist");
        const tinygltf::Accessor& accessor = mModel.accessors[size_t(aIndex)];
        const std::string where = aWhat + " (accessor " + std::to_string(aIndex) + ")";
        if (accessor.type != aType)
            Fail(where + ": wrong type (" + (aIndices ? "SCALAR" : aKind == AccessorKind::kTexcoords ? "VEC2"
                                                 : aKind == AccessorKind::kTangents ? "VEC4" : "VEC3") + " expected)");
        const int componentType = accessor.componentType;
        size_t componentSize;
        if (aIndices) {
            if (componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE) componentSize = 1;
            else if (componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT) componentSize = 2;
            else if (componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT) componentSize = 4;
            else Fail(where + ": indices must be unsigned byte, short or int");
        } else if (!mQuantized) {
            if (aKind == AccessorKind::kTexcoords) {  // glTF: float, or normalised unsigned byte/short
                if (componentType == TINYGLTF_COMPONENT_TYPE_FLOAT) componentSize = 4;
                else if (componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE && accessor.normalized) componentSize = 1;
                else if (componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT && accessor.normalized) componentSize = 2;
                else Fail(where + ": texture coordinates must be FLOAT or normalised unsigned byte or short");
            } else {
                if (componentType != TINYGLTF_COMPONENT_TYPE_FLOAT)
                    Fail(where + (aKind == AccessorKind::kNormals ? ": normals must be FLOAT"
                                  : aKind == AccessorKind::kTangents ? ": tangents must be FLOAT" : ": positions must be FLOAT"));
                componentSize = 4;
            }
        } else {
            // KHR_mesh_quantization adds integer components: positions and texture
            // coordinates of (unsigned) byte or short, normalised or not; normals and
            // tangents of normalised (signed) byte or short. The node transform scales
            // and offsets what they hold into the model's units (the extension's
            // dequantization), as it places any mesh.
            const bool small = componentType == TINYGLTF_COMPONENT_TYPE_BYTE || componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
                               componentType == TINYGLTF_COMPONENT_TYPE_SHORT || componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT;
            const bool isSigned = componentType == TINYGLTF_COMPONENT_TYPE_BYTE || componentType == TINYGLTF_COMPONENT_TYPE_SHORT;
            const bool directional = aKind == AccessorKind::kNormals || aKind == AccessorKind::kTangents;
            if (componentType == TINYGLTF_COMPONENT_TYPE_FLOAT) componentSize = 4;
            else if (small && (!directional || (isSigned && accessor.normalized)))
                componentSize = componentType == TINYGLTF_COMPONENT_TYPE_BYTE || componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ? 1 : 2;
            else Fail(where + (directional ? (aKind == AccessorKind::kNormals ? ": normals" : ": tangents") +
                                                 std::string(" must be FLOAT or normalised byte or short (KHR_mesh_quantization)")
                                           : (aKind == AccessorKind::kTexcoords ? ": texture coordinates" : ": positions") +
                                                 std::string(" must be FLOAT, byte or short (KHR_mesh_quantization)")));
        }
        const bool signedComponents = componentType == TINYGLTF_COMPONENT_TYPE_BYTE || componentType == TINYGLTF_COMPONENT_TYPE_SHORT;
        const size_t components = aIndices ? 1 : aKind == AccessorKind::kTexcoords ? 2 : aKind == AccessorKind::kTangents ? 4 : 3;
        // A normalised integer c stands for c / (2^bits - 1) unsigned, max(c / (2^(bits-1) - 1), -1) signed.
        const double normalisation = aIndices || componentSize == 4 || !accessor.normalized ? 1.0
                                     : signedComponents ? (componentSize == 1 ? 1.0 / 127.0 : 1.0 / 32767.0)
                                     : componentSize == 1 ? 1.0 / 255.0 : 1.0 / 65535.0;
        if (accessor.bufferView < 0 || accessor.bufferView >= int(mModel.bufferViews.size()))
            Fail(where + ": missing or invalid bufferView");
        const tinygltf::BufferView& view = mModel.bufferViews[size_t(accessor.bufferView)];
        if (view.buffer < 0 || view.buffer >= int(mModel.buffers.size())) Fail(where + ": its bufferView refers to a missing buffer");
        const tinygltf::Buffer& buffer = mModel.buffers[size_t(view.buffer)];
        const size_t elementSize = componentSize * components;
        const size_t stride = view.byteStride > 0 ? view.byteStride : elementSize;
        if (stride < elementSize) Fail(where + ": byteStride is smaller than an element");
        const size_t count = accessor.count;
        if (count == 0) return {};
        // Every sum below is checked before it is formed, so a huge offset cannot wrap.
        const size_t bufferSize = buffer.data.size();
        const bool viewInside = view.byteOffset <= bufferSize && view.byteLength <= bufferSize - view.byteOffset;
        const bool firstInside = accessor.byteOffset <= view.byteLength && elementSize <= view.byteLength - accessor.byteOffset;
        const size_t room = firstInside ? view.byteLength - accessor.byteOffset - elementSize : 0;
        if (!viewInside || !firstInside || count > (size_t(1) << 31) || (count > 1 && stride > room / (count - 1)))
            Fail(where + ": reads past the end of its buffer");
        const unsigned char* base = buffer.data.data() + view.byteOffset + accessor.byteOffset;
        std::vector<double> values(count * components);
        for (size_t i = 0; i < count; i++) {
            const unsigned char* element = base + i * stride;
            for (size_t c = 0; c < components; c++) {
                const unsigned char* p = element + c * componentSize;
                double value;
                if (componentSize == 1) value = signedComponents ? double(int8_t(*p)) : double(*p);
                else if (componentSize == 2 && signedComponents) { int16_t v; std::memcpy(&v, p, 2); value = v; }
                else if (componentSize == 2) { uint16_t v; std::memcpy(&v, p, 2); value = v; }
                else if (aIndices) { uint32_t v; std::memcpy(&v, p, 4); value = v; }
                else { float v; std::memcpy(&v, p, 4); value = v; }
                values[i * components + c] = signedComponents && normalisation != 1.0 ? std::max(value * normalisation, -1.0)
                                                                                      : value * normalisation;
            }
        }
        return values;
    }

    void AddMesh(int aMeshIndex, const Mat4& aWorld, const std::string& aWhat) {
        if (aMeshIndex < 0 || aMeshIndex >= int(mModel.meshes.size())) Fail(aWhat + " refers to mesh " + std::to_string(aMeshIndex) + ", which does not exist");
        const tinygltf::Mesh& mesh = mModel.meshes[size_t(aMeshIndex)];
        // A transform that mirrors (negative determinant) reverses the winding (glTF spec).
        const bool flip = glm::determinant(glm::dmat3(aWorld)) < 0.0;
        for (size_t p = 0; p < mesh.primitives.size(); p++) {
            const tinygltf::Primitive& primitive = mesh.primitives[p];
            const std::string what = aWhat + ", mesh " + std::to_string(aMeshIndex) + " primitive " + std::to_string(p);
            mNotedPrimitive = {aMeshIndex, int(p), flip};
            if (primitive.mode != -1 && primitive.mode != TINYGLTF_MODE_TRIANGLES)
                Fail(what + ": primitive mode " + std::to_string(primitive.mode) + " is not supported (only TRIANGLES)");
            if (!primitive.targets.empty()) Fail(what + ": morph targets are not supported");
            auto position = primitive.attributes.find("POSITION");
            if (position == primitive.attributes.end()) Fail(what + ": has no POSITION attribute");
            const std::vector<double> positions = ReadAccessor(position->second, TINYGLTF_TYPE_VEC3, AccessorKind::kPositions, what + " POSITION");
            const size_t vertexCount = positions.size() / 3;
            std::vector<double> indices;
            if (primitive.indices != -1) {
                indices = ReadAccessor(primitive.indices, TINYGLTF_TYPE_SCALAR, AccessorKind::kIndices, what + " indices");
            } else {
                indices.resize(vertexCount);
                for (size_t i = 0; i < vertexCount; i++) indices[i] = double(i);
            }
            if (indices.size() % 3 != 0) Fail(what + ": the index count " + std::to_string(indices.size()) + " is not a multiple of 3");
            // Nodes, primitives and accessors may all share data: a 64 KB file can ask for
            // billions of triangles. Count them before any work (degenerate ones too).
            mTriangleCount += indices.size() / 3;
            if (mTriangleCount > kMaxTriangles)
                Fail(what + ": the scene has more than " + std::to_string(kMaxTriangles) + " triangles (the loader's limit)");
            std::vector<Vec3> world(vertexCount);
            for (size_t v = 0; v < vertexCount; v++) {
                const glm::dvec4 local(positions[3 * v], positions[3 * v + 1], positions[3 * v + 2], 1.0);
                const glm::dvec3 w = glm::dvec3(aWorld * local);
                if (!std::isfinite(w.x) || !std::isfinite(w.y) || !std::isfinite(w.z) || !IsFinite(Vec3(w)))
                    Fail(what + ": vertex " + std::to_string(v) + " is not finite (NaN or infinity, in float32)");
                world[v] = Vec3(w);
            }
            const int material = MaterialIndex(primitive.material, what);
            // Texture coordinates, read only for textured materials (and then required).
            std::vector<double> uvs;
            const bool normalMapped = mScene.mMaterials[size_t(material)].mNormalTexture >= 0;
            const Material& sceneMaterial = mScene.mMaterials[size_t(material)];
            const char* texture = sceneMaterial.mBaseColorTexture >= 0 || sceneMaterial.mAlphaTexture >= 0 ? "a baseColorTexture"
                                  : mMaterialEmissionTexture[size_t(material)] >= 0       ? "an emissiveTexture"
                                  : normalMapped                                           ? "a normalTexture"
                                  : sceneMaterial.mMetallicRoughnessTexture >= 0           ? "a metallicRoughnessTexture"
                                                                                           : nullptr;
            if (texture) {
                const std::string set = "TEXCOORD_" + std::to_string(mMaterialTexCoord[size_t(material)]);
                auto texcoord = primitive.attributes.find(set);
                if (texcoord == primitive.attributes.end())
                    Fail(what + ": its material has " + texture + " but the primitive has no " + set);
                uvs = ReadAccessor(texcoord->second, TINYGLTF_TYPE_VEC2, AccessorKind::kTexcoords, what + " " + set);
                if (uvs.size() != 2 * vertexCount) Fail(what + ": " + set + " and POSITION have different counts");
                for (size_t v = 0; v < uvs.size(); v++)
                    if (!std::isfinite(uvs[v]) || !std::isfinite(float(uvs[v])))
                        Fail(what + ": " + set + " of vertex " + std::to_string(v / 2) + " is not finite (NaN or infinity)");
            }
            const std::vector<Vec3> normals = WorldNormals(primitive, aWorld, vertexCount, what);
            const std::vector<Vec4> tangents =
                normalMapped ? CornerTangents(primitive, aWorld, vertexCount, world, uvs, normals, indices, flip, what) : std::vector<Vec4>();
            size_t againstWinding = 0;
            std::vector<int> triangleIds;
            // Room for this primitive's triangles, growing geometrically (a file with many
            // small primitives must not reallocate the whole list for each one).
            const size_t needed = mScene.mTriangles.size() + indices.size() / 3;
            if (needed > mScene.mTriangles.capacity()) mScene.mTriangles.reserve(std::max(needed, 2 * mScene.mTriangles.capacity()));
            for (size_t t = 0; t + 2 < indices.size(); t += 3) {
                size_t i0 = size_t(indices[t]), i1 = size_t(indices[t + 1]), i2 = size_t(indices[t + 2]);
                if (i0 >= vertexCount || i1 >= vertexCount || i2 >= vertexCount)
                    Fail(what + ": index out of range in triangle " + std::to_string(t / 3) + " (vertex count " + std::to_string(vertexCount) + ")");
                size_t c1 = t + 1, c2 = t + 2;  // the corners, which tangents belong to
                if (flip) {
                    std::swap(i1, i2);
                    std::swap(c1, c2);
                }
                const std::optional<Vec3> normal = TriangleNormal(world[i0], world[i1], world[i2]);
                if (!normal) { mSkippedTriangles++; continue; }
                triangleIds.push_back(mScene.AddTriangle(world[i0], world[i1], world[i2], material));
                if (!tangents.empty() && tangents[t].w != 0.f && tangents[c1].w != 0.f && tangents[c2].w != 0.f) {
                    Triangle& added = mScene.mTriangles.back();
                    added.mHasTangents = true;
                    added.mT0 = tangents[t];
                    added.mT1 = tangents[c1];
                    added.mT2 = tangents[c2];
                }
                if (!uvs.empty()) {
                    Triangle& added = mScene.mTriangles.back();
                    added.mUv0 = Vec2(float(uvs[2 * i0]), float(uvs[2 * i0 + 1]));
                    added.mUv1 = Vec2(float(uvs[2 * i1]), float(uvs[2 * i1 + 1]));
                    added.mUv2 = Vec2(float(uvs[2 * i2]), float(uvs[2 * i2 + 1]));
                }
                // Smooth shading where all three vertex normals survived the transform.
                if (!normals.empty() && normals[i0] != Vec3(0.f) && normals[i1] != Vec3(0.f) && normals[i2] != Vec3(0.f)) {
                    Triangle& added = mScene.mTriangles.back();
                    added.mHasVertexNormals = true;
                    added.mN0 = normals[i0];
                    added.mN1 = normals[i1];
                    added.mN2 = normals[i2];
                    if (glm::dot(normals[i0] + normals[i1] + normals[i2], *normal) < 0.f) againstWinding++;
                }
            }
            if (againstWinding > 0)
                NotePrimitive(kNoteAgainstWinding, what + ": NORMAL points against the winding on " + std::to_string(againstWinding) +
                                                       " of " + std::to_string(triangleIds.size()) +
                                                       " triangles (the winding decides the front, as in glTF; shading turns the "
                                                       "normals to it)");
            // An emissive primitive instance is one area light over all its triangles.
            if (!IsBlack(mMaterialEmission[size_t(material)]) && !triangleIds.empty())
                mScene.AddAreaLight(triangleIds, mMaterialEmission[size_t(material)], mMaterialEmitsTwoSided[size_t(material)],
                                    mMaterialEmissionTexture[size_t(material)]);
            // Whether its outside reflects depends on the material: say which.
            const bool twoSided = mScene.mMaterials[size_t(material)].mTwoSided;
            if (LooksInsideOut(world, indices, flip))
                NotePrimitive(kNoteInsideOut, what + " looks inside-out: a closed mesh with negative volume (its triangles face "
                                                     "inwards; " +
                                                     (twoSided ? std::string("its doubleSided material reflects on both sides, but")
                                                               : std::string("its material is not doubleSided, so its outside is "
                                                                             "black; and")) +
                                                     " one-sided emission and glass work inside out)");
        }
    }

    // The tangents of a normal-mapped primitive in world space, one per corner (as
    // aIndices lists them): xyz along increasing u, w = +1 or -1 the handedness (glTF:
    // bitangent = w (N x T)); w = 0 where there is none (then that triangle is not
    // normal-mapped). From TANGENT when the primitive has it (xyz carried by the node's
    // matrix, w flipped by a mirroring one); otherwise generated as the glTF specification
    // asks, in MikkTSpace's manner: each triangle's dP/du and image-up direction (-dP/dv,
    // glTF's v running down) from its positions and texture coordinates, summed per
    // vertex weighted by the corner's angle, separately for the two handednesses (so that
    // a mirrored uv seam does not average opposite frames away), then made orthogonal to
    // the vertex's normal. (MikkTSpace also splits vertices at other seams and welds by
    // position; this sums per index, as the file shares vertices.)
    std::vector<Vec4> CornerTangents(const tinygltf::Primitive& aPrimitive, const Mat4& aWorld, size_t aVertexCount,
                                     const std::vector<Vec3>& aPositions, const std::vector<double>& aUvs,
                                     const std::vector<Vec3>& aNormals, const std::vector<double>& aIndices, bool aFlip,
                                     const std::string& aWhat) {
        std::vector<Vec4> corners(aIndices.size(), Vec4(0.f));
        auto attribute = aPrimitive.attributes.find("TANGENT");
        if (attribute != aPrimitive.attributes.end()) {
            const std::vector<double> local = ReadAccessor(attribute->second, TINYGLTF_TYPE_VEC4, AccessorKind::kTangents, aWhat + " TANGENT");
            if (local.size() != 4 * aVertexCount)
                Fail(aWhat + ": TANGENT has " + std::to_string(local.size() / 4) + " elements but POSITION has " +
                     std::to_string(aVertexCount) + " (one tangent per vertex)");
            const glm::dmat3 matrix(aWorld);
            const double handedness = glm::determinant(matrix) < 0.0 ? -1.0 : 1.0;
            std::vector<Vec4> world(aVertexCount);
            for (size_t v = 0; v < aVertexCount; v++) {
                const glm::dvec4 t(local[4 * v], local[4 * v + 1], local[4 * v + 2], local[4 * v + 3]);
                if (!std::isfinite(t.x) || !std::isfinite(t.y) || !std::isfinite(t.z) || !std::isfinite(t.w))
                    Fail(aWhat + ": TANGENT of vertex " + std::to_string(v) + " is not finite (NaN or infinity)");
                if (t.w != 1.0 && t.w != -1.0)
                    Fail(aWhat + ": TANGENT of vertex " + std::to_string(v) + " has w = " + std::to_string(t.w) +
                         " (glTF: +1 or -1, the bitangent's handedness)");
                const glm::dvec3 xyz = matrix * glm::dvec3(t);
                const double length = glm::length(xyz);
                if (length > 0.0 && std::isfinite(length)) world[v] = Vec4(Vec3(xyz / length), float(t.w * handedness));
            }
            for (size_t c = 0; c < aIndices.size(); c++)
                if (size_t(aIndices[c]) < aVertexCount) corners[c] = world[size_t(aIndices[c])];
            return corners;
        }
        // Per vertex and handedness (0: +1, 1: -1): the sums of tangents and up directions.
        std::vector<glm::dvec3> tangentSum[2], upSum[2];
        for (int h = 0; h < 2; h++) {
            tangentSum[h].assign(aVertexCount, glm::dvec3(0.0));
            upSum[h].assign(aVertexCount, glm::dvec3(0.0));
        }
        std::vector<int> cornerHandedness(aIndices.size(), -1);
        for (size_t t = 0; t + 2 < aIndices.size(); t += 3) {
            const size_t v[3] = {size_t(aIndices[t]), size_t(aIndices[t + 1]), size_t(aIndices[t + 2])};
            if (v[0] >= aVertexCount || v[1] >= aVertexCount || v[2] >= aVertexCount) continue;  // refused by the caller
            const glm::dvec3 p[3] = {glm::dvec3(aPositions[v[0]]), glm::dvec3(aPositions[v[1]]), glm::dvec3(aPositions[v[2]])};
            const glm::dvec2 uv[3] = {{aUvs[2 * v[0]], aUvs[2 * v[0] + 1]}, {aUvs[2 * v[1]], aUvs[2 * v[1] + 1]},
                                      {aUvs[2 * v[2]], aUvs[2 * v[2] + 1]}};
            const glm::dvec3 e1 = p[1] - p[0], e2 = p[2] - p[0];
            const glm::dvec2 d1 = uv[1] - uv[0], d2 = uv[2] - uv[0];
            const double det = d1.x * d2.y - d2.x * d1.y;
            const glm::dvec3 faceNormal = glm::cross(e1, e2);
            if (!(std::abs(det) > 0.0) || !(glm::length(faceNormal) > 0.0)) continue;  // no uv area: no frame
            const glm::dvec3 dPdu = (e1 * d2.y - e2 * d1.y) / det;
            const glm::dvec3 dPdv = (e2 * d1.x - e1 * d2.x) / det;
            const double tLength = glm::length(dPdu), vLength = glm::length(dPdv);
            if (!(tLength > 0.0) || !(vLength > 0.0) || !std::isfinite(tLength) || !std::isfinite(vLength)) continue;
            const glm::dvec3 tangent = dPdu / tLength, up = -dPdv / vLength;
            const int h = glm::dot(glm::cross(faceNormal, tangent), up) < 0.0 ? 1 : 0;
            for (int k = 0; k < 3; k++) {
                const glm::dvec3 a = p[(k + 1) % 3] - p[k], b = p[(k + 2) % 3] - p[k];
                const double angle = std::acos(std::clamp(glm::dot(a, b) / (glm::length(a) * glm::length(b)), -1.0, 1.0));
                if (!std::isfinite(angle)) continue;
                tangentSum[h][v[k]] += angle * tangent;
                upSum[h][v[k]] += angle * up;
                cornerHandedness[t + size_t(k)] = h;
            }
        }
        for (size_t c = 0; c < aIndices.size(); c++) {
            const int h = cornerHandedness[c];
            if (h < 0) continue;
            const size_t v = size_t(aIndices[c]);
            // The normal the renderer will tilt: the vertex normal (or the face's), turned
            // to the front the winding gives, as the shading normal is (a mirroring node
            // reverses the winding: aFlip).
            const size_t t = c - c % 3;
            const glm::dvec3 p0(aPositions[size_t(aIndices[t])]);
            const glm::dvec3 front = (aFlip ? -1.0 : 1.0) * glm::cross(glm::dvec3(aPositions[size_t(aIndices[t + 1])]) - p0,
                                                                     glm::dvec3(aPositions[size_t(aIndices[t + 2])]) - p0);
            glm::dvec3 n = !aNormals.empty() && aNormals[v] != Vec3(0.f) ? glm::dvec3(aNormals[v]) : glm::normalize(front);
            if (glm::dot(n, front) < 0.0) n = -n;
            const glm::dvec3 sum = tangentSum[h][v];
            const glm::dvec3 orthogonal = sum - n * glm::dot(n, sum);
            const double length = glm::length(orthogonal);
            if (!(length > 1e-12) || !std::isfinite(length)) continue;
            const glm::dvec3 tangent = orthogonal / length;
            const float w = glm::dot(glm::cross(n, tangent), upSum[h][v]) < 0.0 ? -1.f : 1.f;
            corners[c] = Vec4(Vec3(tangent), w);
        }
        return corners;
    }

    // A note about the primitive being read (mNotedPrimitive), made once per mesh
    // primitive, kind and handedness of the transform: the other nodes that place the same
    // mesh add no line of their own, only a count that FinishPrimitiveNotes appends (a
    // model placed a hundred times would otherwise fill the notes with one problem).
    enum PrimitiveNoteKind { kNoteAgainstWinding, kNoteInsideOut, kNoteNormalLength };
    void NotePrimitive(PrimitiveNoteKind aKind, const std::string& aText) {
        const auto key = std::make_tuple(std::get<0>(mNotedPrimitive), std::get<1>(mNotedPrimitive), std::get<2>(mNotedPrimitive), int(aKind));
        auto known = mPrimitiveNotes.find(key);
        if (known != mPrimitiveNotes.end()) { known->second.second++; return; }
        const bool room = mReport.mNotes.size() < 64;
        mPrimitiveNotes[key] = {room ? mReport.mNotes.size() : std::string::npos, 0};
        if (room) mReport.mNotes.push_back(aText);
    }
    void FinishPrimitiveNotes() {
        for (const auto& [key, note] : mPrimitiveNotes)
            if (note.first != std::string::npos && note.second > 0)
                mReport.mNotes[note.first] += " (and in " + std::to_string(note.second) + " more placement" +
                                              (note.second == 1 ? "" : "s") + " of mesh " + std::to_string(std::get<0>(key)) + ")";
    }

    // The vertex normals (NORMAL) of a primitive in world space, or none when it has no
    // NORMAL. glTF: a VEC3 FLOAT accessor with one unit vector per vertex, transformed by
    // the inverse transpose of the node's matrix. A non-finite or zero normal is refused
    // (nothing to repair it from); one that is not of unit length is normalised, as the
    // spec requires of the file, and noted. A normal the transform cannot carry (a
    // singular matrix, whose triangles are all degenerate and skipped) becomes zero.
    std::vector<Vec3> WorldNormals(const tinygltf::Primitive& aPrimitive, const Mat4& aWorld, size_t aVertexCount,
                                   const std::string& aWhat) {
        auto attribute = aPrimitive.attributes.find("NORMAL");
        if (attribute == aPrimitive.attributes.end()) return {};
        const std::vector<double> local = ReadAccessor(attribute->second, TINYGLTF_TYPE_VEC3, AccessorKind::kNormals, aWhat + " NORMAL");
        if (local.size() != 3 * aVertexCount)
            Fail(aWhat + ": NORMAL has " + std::to_string(local.size() / 3) + " elements but POSITION has " +
                 std::to_string(aVertexCount) + " (one normal per vertex)");
        const glm::dmat3 normalMatrix = glm::transpose(glm::inverse(glm::dmat3(aWorld)));
        std::vector<Vec3> world(aVertexCount);
        size_t notUnit = 0;
        // A quantized normal (KHR_mesh_quantization: often 8 to 10 bits, stored in bytes or
        // shorts) is of unit length only to within its steps, up to about 1/127.
        const double unitTolerance = mModel.accessors[size_t(attribute->second)].componentType == TINYGLTF_COMPONENT_TYPE_FLOAT ? 1e-3 : 1e-2;
        for (size_t v = 0; v < aVertexCount; v++) {
            const glm::dvec3 n(local[3 * v], local[3 * v + 1], local[3 * v + 2]);
            const double length = glm::length(n);
            if (!std::isfinite(n.x) || !std::isfinite(n.y) || !std::isfinite(n.z))
                Fail(aWhat + ": NORMAL of vertex " + std::to_string(v) + " is not finite (NaN or infinity)");
            if (!(length > 0.0)) Fail(aWhat + ": NORMAL of vertex " + std::to_string(v) + " has zero length");
            if (std::abs(length - 1.0) > unitTolerance) notUnit++;
            const glm::dvec3 w = normalMatrix * (n / length);
            const double worldLength = glm::length(w);
            if (worldLength > 0.0 && std::isfinite(worldLength)) world[v] = Vec3(w / worldLength);
        }
        if (notUnit > 0)
            NotePrimitive(kNoteNormalLength, aWhat + ": NORMAL of " + std::to_string(notUnit) + " of " + std::to_string(aVertexCount) +
                                                 " vertices is not of unit length (glTF requires it): normalised");
        return world;
    }

    // True for a closed mesh (every edge used once in each direction, so it bounds a
    // volume) whose signed volume, sum of p0 . (p1 x p2) / 6, is negative: wound inwards.
    // Vertices are matched by position, so meshes split at seams (or not indexed at all)
    // are judged as the surface they form.
    static bool LooksInsideOut(const std::vector<Vec3>& aWorld, const std::vector<double>& aIndices, bool aFlip) {
        // Weld: vertices at the same position get one id. By sorting, not hashing: a
        // million-triangle mesh would spend most of its loading time in hash nodes.
        struct Keyed { uint32_t mBits[3]; uint32_t mVertex; };
        std::vector<Keyed> keyed(aWorld.size());
        for (size_t v = 0; v < aWorld.size(); v++) {
            const Vec3 p = aWorld[v] + Vec3(0.f);  // -0 becomes +0: equal positions, equal bits
            std::memcpy(keyed[v].mBits, &p, sizeof(keyed[v].mBits));
            keyed[v].mVertex = uint32_t(v);
        }
        const auto samePosition = [](const Keyed& aA, const Keyed& aB) {
            return aA.mBits[0] == aB.mBits[0] && aA.mBits[1] == aB.mBits[1] && aA.mBits[2] == aB.mBits[2];
        };
        std::sort(keyed.begin(), keyed.end(), [](const Keyed& aA, const Keyed& aB) {
            return std::lexicographical_compare(aA.mBits, aA.mBits + 3, aB.mBits, aB.mBits + 3);
        });
        std::vector<uint32_t> weld(aWorld.size());
        uint32_t id = 0;
        for (size_t k = 0; k < keyed.size(); k++) {
            if (k > 0 && !samePosition(keyed[k - 1], keyed[k])) id++;
            weld[keyed[k].mVertex] = id;
        }
        // Each edge as (smaller id, larger id, direction): in a closed, consistently wound
        // 2-manifold every edge occurs exactly twice, once in each direction.
        std::vector<uint64_t> edges;
        edges.reserve(aIndices.size());
        double volume = 0.0;
        for (size_t t = 0; t + 2 < aIndices.size(); t += 3) {
            size_t corner[3] = {size_t(aIndices[t]), size_t(aIndices[t + 1]), size_t(aIndices[t + 2])};
            if (aFlip) std::swap(corner[1], corner[2]);
            const uint64_t v[3] = {weld[corner[0]], weld[corner[1]], weld[corner[2]]};
            if (v[0] == v[1] || v[1] == v[2] || v[0] == v[2]) continue;
            for (int e = 0; e < 3; e++) {
                const uint64_t from = v[e], to = v[(e + 1) % 3];
                edges.push_back(from < to ? (from << 32) | (to << 1) : (to << 32) | (from << 1) | 1u);
            }
            const glm::dvec3 p0(aWorld[corner[0]]), p1(aWorld[corner[1]]), p2(aWorld[corner[2]]);
            volume += glm::dot(p0, glm::cross(p1, p2)) / 6.0;
        }
        if (edges.empty()) return false;
        // Sorted by the smaller id with one counting pass (the ids are dense, at most id),
        // then each vertex's few edges by std::sort: the same order as one std::sort over
        // all of them, in linear time.
        std::vector<uint32_t> bucketStart(size_t(id) + 2, 0u);
        for (const uint64_t edge : edges) bucketStart[size_t(edge >> 32) + 1]++;
        for (size_t b = 1; b < bucketStart.size(); b++) bucketStart[b] += bucketStart[b - 1];
        {
            std::vector<uint64_t> bucketed(edges.size());
            std::vector<uint32_t> fill(bucketStart.begin(), bucketStart.end() - 1);
            for (const uint64_t edge : edges) bucketed[fill[size_t(edge >> 32)]++] = edge;
            edges.swap(bucketed);
        }
        for (size_t b = 0; b + 1 < bucketStart.size(); b++)
            std::sort(edges.begin() + bucketStart[b], edges.begin() + bucketStart[b + 1]);
        for (size_t e = 0; e < edges.size(); e += 2)  // sorted pairs: (a, b, forward), (a, b, backward)
            if ((edges[e] & 1u) || e + 1 >= edges.size() || edges[e + 1] != (edges[e] | 1u))
                return false;  // an open border, or an edge shared otherwise than by two opposite triangles
        return volume < 0.0;
    }

    void AddSphere(const tinygltf::Value& aSphere, const Mat4& aWorld, const std::string& aWhat) {
        if (!aSphere.IsObject() || !aSphere.Has("radius") || !aSphere.Get("radius").IsNumber())
            Fail(aWhat + ": SMALLVCM_sphere needs a numeric 'radius'");
        if (!aSphere.Has("material") || !aSphere.Get("material").IsInt())
            Fail(aWhat + ": SMALLVCM_sphere needs an integer 'material'");
        const double radius = aSphere.Get("radius").GetNumberAsDouble();
        if (!std::isfinite(radius) || !(radius > 0.0)) Fail(aWhat + ": the sphere radius must be finite and positive");
        // The node's transform must scale uniformly: a sphere stays a sphere.
        const double sx = glm::length(glm::dvec3(aWorld[0])), sy = glm::length(glm::dvec3(aWorld[1])), sz = glm::length(glm::dvec3(aWorld[2]));
        if (std::abs(sx - sy) > 1e-4 * sx || std::abs(sx - sz) > 1e-4 * sx || !(sx > 0.0))
            Fail(aWhat + ": a sphere node must have a uniform scale (non-uniform scale would make an ellipsoid)");
        const int materialIndex = aSphere.Get("material").GetNumberAsInt();
        if (materialIndex < 0)
            Fail(aWhat + ": SMALLVCM_sphere refers to material " + std::to_string(materialIndex) + ", which does not exist");
        const int material = MaterialIndex(materialIndex, aWhat + ": SMALLVCM_sphere");
        if (mMaterialEmissionTexture[size_t(material)] >= 0)
            Fail(aWhat + ": SMALLVCM_sphere's material has an emissiveTexture, but a sphere has no texture coordinates");
        const int id = mScene.AddSphere(Vec3(glm::dvec3(aWorld[3])), float(radius * sx), material);
        if (!IsBlack(mMaterialEmission[size_t(material)])) mScene.AddSphereLight(id, mMaterialEmission[size_t(material)]);
    }

    void AddPunctualLight(const tinygltf::Value& aValue, const Mat4& aWorld, const std::string& aWhat) {
        if (!aValue.IsObject() || !aValue.Has("light") || !aValue.Get("light").IsInt())
            Fail(aWhat + ": KHR_lights_punctual needs an integer 'light'");
        const int index = aValue.Get("light").GetNumberAsInt();
        if (index < 0 || index >= int(mModel.lights.size())) Fail(aWhat + " refers to light " + std::to_string(index) + ", which does not exist");
        const tinygltf::Light& light = mModel.lights[size_t(index)];
        const std::string what = "light " + std::to_string(index) + (light.name.empty() ? "" : " '" + Excerpt(light.name) + "'");
        if (light.range > 0.0) Fail(what + ": 'range' is not supported (lights here have no cut-off)");
        Vec3 color(1.f);
        if (!light.color.empty() && light.color.size() != 3) Fail(what + ": 'color' must have 3 numbers");
        if (light.color.size() == 3) color = Vec3(float(light.color[0]), float(light.color[1]), float(light.color[2]));
        const Vec3 emission = color * float(light.intensity);
        CheckColor(emission, what + ": color * intensity", false);
        if (light.type == "point") {
            mScene.AddPointLight(ToFloat(glm::dvec3(aWorld[3]), aWhat + ": the point light position"), emission);
        } else if (light.type == "spot") {
            // Cone angles as the extension defines them (defaults inner 0, outer pi/4);
            // the light shines down its node's local -Z, scale does not change the cone.
            const float inner = float(light.spot.innerConeAngle), outer = float(light.spot.outerConeAngle);
            if (const char* problem = SpotConeProblem(inner, outer))
                Fail(what + " (spot, innerConeAngle " + ShortNumber(light.spot.innerConeAngle) + ", outerConeAngle " +
                     ShortNumber(light.spot.outerConeAngle) + "): " + problem);
            glm::dvec3 axis;
            if (!Direction(-glm::dvec3(aWorld[2]), axis)) Fail(aWhat + ": the spot light's node has a degenerate transform");
            mScene.AddSpotLight(ToFloat(glm::dvec3(aWorld[3]), aWhat + ": the spot light position"), Vec3(axis), emission,
                                inner, outer);
        } else if (light.type == "directional") {
            glm::dvec3 direction;
            if (!Direction(-glm::dvec3(aWorld[2]), direction)) Fail(aWhat + ": the directional light's node has a degenerate transform");
            mScene.AddDirectionalLight(Vec3(direction), emission);
        } else {
            Fail(what + ": light type '" + Excerpt(light.type) + "' is not supported (point, spot and directional are)");
        }
    }

    void AddCamera(int aCameraIndex, const Mat4& aWorld, const std::string& aWhat) {
        // The first camera in depth-first order is used, or the one GltfLoadOptions asks for.
        const int order = mCameraNodes++;
        if (mHasCamera || order != std::max(0, mOptions.mCamera)) return;
        if (aCameraIndex < 0 || aCameraIndex >= int(mModel.cameras.size())) Fail(aWhat + " refers to camera " + std::to_string(aCameraIndex) + ", which does not exist");
        const tinygltf::Camera& camera = mModel.cameras[size_t(aCameraIndex)];
        if (camera.type != "perspective") Fail("camera " + std::to_string(aCameraIndex) + ": type '" + Excerpt(camera.type) + "' is not supported (only perspective)");
        const double yfov = camera.perspective.yfov;
        const double aspect = camera.perspective.aspectRatio > 0.0 ? camera.perspective.aspectRatio : 1.0;
        if (!(yfov > 0.0 && yfov < 3.1) || !std::isfinite(aspect))
            Fail("camera " + std::to_string(aCameraIndex) + ": yfov must be in (0, 3.1) radians");
        // The horizontal field of view is what stays fixed when the image size changes.
        const double horizontalFov = 2.0 * std::atan(std::tan(0.5 * yfov) * aspect);
        // Narrower, and the image plane (width / (2 tan(fov / 2)) pixels away) is so far
        // that float32 ray directions overflow, or the angle rounds to 0: NaN rays.
        if (!(horizontalFov >= 1e-6))
            Fail("camera " + std::to_string(aCameraIndex) + ": the horizontal field of view is below 1e-6 radians (yfov or aspectRatio too small)");
        if (!(horizontalFov < 3.1)) Fail("camera " + std::to_string(aCameraIndex) + ": the horizontal field of view is 180 degrees or more");
        glm::dvec3 up, back;  // unit vectors
        if (!Direction(glm::dvec3(aWorld[1]), up) || !Direction(glm::dvec3(aWorld[2]), back) || glm::length(glm::cross(up, back)) < 1e-6)
            Fail(aWhat + ": the camera's transform is degenerate");
        mScene.mCamera.Setup(ToFloat(glm::dvec3(aWorld[3]), aWhat + ": the camera position"), Vec3(-back), Vec3(up),
                             float(horizontalFov * 180.0 / 3.14159265358979323846));
        mHasCamera = true;
        mReport.mCamera = "camera node " + std::to_string(order) + " (" + aWhat + ", camera " + std::to_string(aCameraIndex) +
                          (camera.name.empty() ? std::string() : " '" + Excerpt(camera.name) + "'") + ")";
    }

    void ReadBackground() {
        auto background = mModel.extensions.find("SMALLVCM_background");
        if (background == mModel.extensions.end()) return;
        const Vec3 radiance = ColorOr(background->second, "radiance", Vec3(-1.f), "SMALLVCM_background");
        if (radiance.x < 0.f && !background->second.Has("radiance")) Fail("SMALLVCM_background needs 'radiance'");
        CheckColor(radiance, "SMALLVCM_background: the radiance", false);
        mScene.AddBackgroundLight(radiance);
    }

    // The background by GltfLoadOptions::mBackground, after every node's lights and the
    // camera are in. A black one emits nothing: it is no light, the same as none.
    void ChooseBackground() {
        using Background = GltfLoadOptions::Background;
        if (!mOptions.mEnvironmentMap.empty()) {
            if (mOptions.mBackground != Background::kFromFile)
                Fail("an environment map and a background radiance (or none) both replace the background: give one");
            if (!std::isfinite(mOptions.mEnvironmentScale) || !(mOptions.mEnvironmentScale > 0.f))
                Fail("the environment map's scale is not a positive finite number");
            mScene.AddEnvironmentLight(LoadEnvironmentMap(mOptions.mEnvironmentMap, mOptions.mEnvironmentRotationDegrees),
                                       mOptions.mEnvironmentScale);
            return;
        }
        if (mOptions.mBackground == Background::kRadiance) {
            CheckColor(mOptions.mBackgroundRadiance, "the background radiance", false);
            if (!IsBlack(mOptions.mBackgroundRadiance)) mScene.AddBackgroundLight(mOptions.mBackgroundRadiance);
            return;
        }
        if (mOptions.mBackground == Background::kNone) return;
        ReadBackground();
        // A model with no emitter (most real-world files), or whose only emitters carry an
        // emissiveTexture (glow maps of a model, not lamps that light a scene): the default
        // sky and sun, so that it renders at all, and one line that says so and how to change it.
        bool glowOnly = !mScene.mLights.empty();
        for (const Light& light : mScene.mLights) glowOnly = glowOnly && light.mEmissionTexture >= 0;
        if (!mScene.mLights.empty() && !glowOnly) return;
        AddDefaultSkyAndSun(mScene, mScene.mCamera);
        mReport.mDefaultBackground = true;
        mReport.mNotes.push_back(std::string(glowOnly ? "the scene's only lights are emissive textures (glow maps)"
                                                      : "the scene has no light") +
                                 ": added the default sky and sun (a sun from above, behind and left of the camera; "
                                 "--envmap FILE, --background R,G,B or --background none replace them)" +
                                 (mReport.mInteriorCamera ? std::string("; the default camera is inside an interior, which "
                                                                        "they light only through its openings: a closed room "
                                                                        "renders black, give it lights")
                                                          : std::string()));
    }

    // The scene medium fills all space (Scene's rule): light from infinity (a background,
    // an environment map, the sun) is extinguished in it. Said once, as it darkens a scene
    // that had such lights (the default sky and sun included).
    void NoteLightFromInfinityInMedium() {
        if (mScene.mSceneMedium < 0 || !mScene.mMedia[size_t(mScene.mSceneMedium)].Attenuates()) return;
        for (const Light& light : mScene.mLights)
            if (!light.IsFinite()) {
                mReport.mNotes.push_back("the scene medium fills all space, so light from infinity (the background, an "
                                         "environment map, directional lights and the default sky and sun) is extinguished in "
                                         "it: light the scene from inside, or give the medium a closed mesh (SMALLVCM_medium "
                                         "on a material)");
                return;
            }
    }

    // A scene in which nothing emits renders black with every estimator: refused, with why
    // and how to light it. A light of zero emission (a point light of intensity 0, a black
    // background in the file) counts as none. Scene::Finalize names a scene without
    // geometry first.
    void CheckSomethingEmits() const {
        if (mScene.mTriangles.empty() && mScene.mSpheres.empty()) return;
        for (const Light& light : mScene.mLights)
            if (!IsBlack(light.mEmission)) return;
        using Background = GltfLoadOptions::Background;
        const size_t lights = mScene.mLights.size();
        const std::string fileLights = lights == 0 ? "the file has no other light"
            : "the file's " + std::to_string(lights) + (lights == 1 ? " light emits" : " lights emit") +
              " nothing (zero intensity or black radiance)";
        const std::string why = mOptions.mBackground == Background::kNone       ? "--background none removes the background and " + fileLights
                                : mOptions.mBackground == Background::kRadiance ? "--background 0,0,0 is black and " + fileLights
                                                                                : fileLights;
        Fail("the scene has no light: " + why + "; give a non-black --background R,G,B, or " +
             (lights == 0 ? "add lights to the file" : "lights that emit"));
    }

    // A camera for a file without one. An interior (the geometry encloses the centre of its
    // bounding box: Enclosed) gets a camera inside it (AddInteriorCamera). Any other
    // scene gets one that looks at the centre of the bounding box of all geometry from the
    // front (+Z, glTF's front) and 15 degrees above, with a 40-degree vertical field of
    // view, just far enough (plus 5%) that all eight corners of the box lie inside the
    // frame at the image's aspect ratio.
    void AddDefaultCamera() {
        Aabb box;
        for (const Triangle& triangle : mScene.mTriangles) { box.Extend(triangle.mP0); box.Extend(triangle.mP1); box.Extend(triangle.mP2); }
        for (const Sphere& sphere : mScene.mSpheres) { box.Extend(sphere.mCenter - Vec3(sphere.mRadius)); box.Extend(sphere.mCenter + Vec3(sphere.mRadius)); }
        if (mScene.mTriangles.empty() && mScene.mSpheres.empty()) Fail("the scene has no geometry");
        const float aspect = mOptions.mDefaultCameraAspect;
        if (!(aspect > 0.f) || !std::isfinite(aspect)) Fail("the default camera's aspect ratio must be a positive number");
        if (AddInteriorCamera(box, aspect)) return;
        const double pi = 3.14159265358979323846;
        const double tanHalfVertical = std::tan(0.5 * 40.0 * pi / 180.0);
        const double tanHalfHorizontal = tanHalfVertical * double(aspect);
        const double elevation = 15.0 * pi / 180.0;
        const glm::dvec3 towardsCamera(0.0, std::sin(elevation), std::cos(elevation));
        const glm::dvec3 forward = -towardsCamera, right(1.0, 0.0, 0.0), up = glm::cross(right, forward);
        const glm::dvec3 center = 0.5 * (glm::dvec3(box.mMin) + glm::dvec3(box.mMax));
        // The camera at center + d * towardsCamera sees corner X at depth dot(X - center,
        // forward) + d; it is inside the frame when |x| <= tan(fov / 2) * depth on both axes.
        double distance = 1e-6 * (1.0 + glm::length(center));
        for (int c = 0; c < 8; c++) {
            const glm::dvec3 corner(c & 1 ? box.mMax.x : box.mMin.x, c & 2 ? box.mMax.y : box.mMin.y, c & 4 ? box.mMax.z : box.mMin.z);
            const glm::dvec3 relative = corner - center;
            const double depthOffset = glm::dot(relative, forward);
            distance = std::max({distance, std::abs(glm::dot(relative, right)) / tanHalfHorizontal - depthOffset,
                                 std::abs(glm::dot(relative, up)) / tanHalfVertical - depthOffset});
        }
        distance *= 1.05;
        const Vec3 position = ToFloat(center + distance * towardsCamera, "the default camera's position");
        const double horizontalFov = 2.0 * std::atan(tanHalfHorizontal);
        mScene.mCamera.Setup(position, Vec3(forward), Vec3(0.f, 1.f, 0.f), float(horizontalFov * 180.0 / pi));
        mReport.mDefaultCamera = true;
        mReport.mCamera = "a default camera (the file has none): from the front, 15 degrees above, framing the whole scene";
    }

    // The first surface each ray (aOrigin, aDirections[i]) meets: its distance (infinity
    // when none) and whether it shows its front (the glTF winding's side; a sphere's
    // outside) to the ray. Triangles of a doubleSided material do not count as that
    // surface: they have no inside (a curtain, a leaf, a sheet of paper) to tell. But they
    // are in the way of a camera: mNearest is the distance to the first surface of any
    // kind. Every triangle and sphere is tested (the BVH is built later, by
    // Scene::Finalize): a handful of rays costs about what a pass over the geometry does.
    struct EnclosureHit {
        float mDistance = std::numeric_limits<float>::infinity();
        bool mFront = false;
        float mNearest = std::numeric_limits<float>::infinity();
    };
    std::vector<EnclosureHit> FirstHits(const Vec3& aOrigin, const std::vector<Vec3>& aDirections) const {
        std::vector<EnclosureHit> hits(aDirections.size());
        for (const Triangle& triangle : mScene.mTriangles) {
            const bool sheet = mScene.mMaterials[size_t(triangle.mMaterialId)].mTwoSided;
            const Vec3 e1 = triangle.mP1 - triangle.mP0, e2 = triangle.mP2 - triangle.mP0, s = aOrigin - triangle.mP0;
            const Vec3 q = glm::cross(s, e1);
            for (size_t r = 0; r < aDirections.size(); r++) {
                // Moeller-Trumbore; det > 0 where the ray meets the front (cross(e1, e2) faces it).
                const Vec3 p = glm::cross(aDirections[r], e2);
                const float det = glm::dot(e1, p);
                if (det == 0.f) continue;
                const float inverse = 1.f / det, u = glm::dot(s, p) * inverse;
                if (u < 0.f || u > 1.f) continue;
                const float v = glm::dot(aDirections[r], q) * inverse;
                if (v < 0.f || u + v > 1.f) continue;
                const float t = glm::dot(e2, q) * inverse;
                if (!(t > 0.f)) continue;
                hits[r].mNearest = std::min(hits[r].mNearest, t);
                if (!sheet && t < hits[r].mDistance) { hits[r].mDistance = t; hits[r].mFront = det > 0.f; }
            }
        }
        for (const Sphere& sphere : mScene.mSpheres) {
            const Vec3 toOrigin = aOrigin - sphere.mCenter;
            const float c = glm::dot(toOrigin, toOrigin) - sphere.mRadius * sphere.mRadius;
            for (size_t r = 0; r < aDirections.size(); r++) {
                const float b = glm::dot(toOrigin, aDirections[r]), discriminant = b * b - c;
                if (discriminant < 0.f) continue;
                const float root = std::sqrt(discriminant);
                const float t = c > 0.f ? -b - root : -b + root;  // outside: the near side; inside: the far one
                if (!(t > 0.f)) continue;
                hits[r].mNearest = std::min(hits[r].mNearest, t);
                if (t < hits[r].mDistance) { hits[r].mDistance = t; hits[r].mFront = c > 0.f; }
            }
        }
        return hits;
    }

    // The directions of the enclosure test: eight horizontal ones, every 45 degrees from
    // +X (so +Z is the third), and straight down last.
    static std::vector<Vec3> EnclosureDirections() {
        std::vector<Vec3> directions;
        const float diagonal = 0.70710678f;
        for (const Vec3& d : {Vec3(1.f, 0.f, 0.f), Vec3(diagonal, 0.f, diagonal), Vec3(0.f, 0.f, 1.f), Vec3(-diagonal, 0.f, diagonal),
                              Vec3(-1.f, 0.f, 0.f), Vec3(-diagonal, 0.f, -diagonal), Vec3(0.f, 0.f, -1.f), Vec3(diagonal, 0.f, -diagonal),
                              Vec3(0.f, -1.f, 0.f)})
            directions.push_back(d);
        return directions;
    }
    // The enclosure test of a point: the first surface in each EnclosureDirections
    // direction is a front face, not closer than aClearance. Up is not asked: an atrium or
    // a courtyard may be open to the sky. Returns the hits, in that order, or none.
    std::optional<std::vector<EnclosureHit>> Enclosed(const Vec3& aPoint, float aClearance) const {
        std::vector<EnclosureHit> hits = FirstHits(aPoint, EnclosureDirections());
        for (const EnclosureHit& hit : hits)
            if (!hit.mFront || !(hit.mNearest > aClearance)) return std::nullopt;
        return hits;
    }

    // The default camera of an interior: a scene whose geometry encloses the centre of its
    // bounding box (Enclosed: front faces all around it and below it) gets a camera inside,
    // not one that would show the outside of a wall. The camera looks level along the
    // longer horizontal axis of the box (-Z when it is the longer or they are equal, else
    // -X), with a 60-degree vertical field of view, from the first of these points that is
    // enclosed too: back from the centre by 60% of the way to the surface behind it and
    // down by half the way to the floor below it (about eye height in a room); only down;
    // the centre itself. False, and no camera, when the centre is not enclosed.
    bool AddInteriorCamera(const Aabb& aBox, float aAspect) {
        const Vec3 center = aBox.Centroid();
        const float clearance = 1e-3f * glm::length(aBox.mMax - aBox.mMin);
        const std::optional<std::vector<EnclosureHit>> around = Enclosed(center, clearance);
        if (!around) return false;
        const Vec3 extent = aBox.mMax - aBox.mMin;
        const bool alongZ = extent.z >= extent.x;
        const Vec3 forward = alongZ ? Vec3(0.f, 0.f, -1.f) : Vec3(-1.f, 0.f, 0.f);
        const float behind = (*around)[alongZ ? 2 : 0].mNearest;  // EnclosureDirections: +Z is 2, +X is 0
        const float below = (*around)[8].mNearest;
        Vec3 position = center;
        for (const Vec3& candidate : {center - 0.6f * behind * forward - Vec3(0.f, 0.5f * below, 0.f),
                                      center - Vec3(0.f, 0.5f * below, 0.f)})
            if (Enclosed(candidate, clearance)) { position = candidate; break; }
        const double pi = 3.14159265358979323846;
        const double tanHalfHorizontal = std::tan(0.5 * 60.0 * pi / 180.0) * double(aAspect);
        mScene.mCamera.Setup(position, forward, Vec3(0.f, 1.f, 0.f), float(2.0 * std::atan(tanHalfHorizontal) * 180.0 / pi));
        mReport.mDefaultCamera = true;
        mReport.mInteriorCamera = true;
        // A room's shell is a closed mesh wound inwards: its inside-out note is then no warning.
        for (std::string& note : mReport.mNotes)
            if (note.find(" looks inside-out: ") != std::string::npos)
                note += " -- the default camera stands inside: for the shell of an interior, facing inwards is right";
        mReport.mCamera = std::string("a default camera (the file has none): inside, as the geometry encloses the centre of its "
                                      "bounding box (an interior), looking along ") + (alongZ ? "-Z" : "-X");
        return true;
    }

    std::string mPath;
    GltfLoadOptions mOptions;
    std::string mFolder;                        // the scene file's canonical folder: URIs are relative to it
    std::string mRoot;                          // canonical folder every URI must resolve into
    std::set<uint64_t> mDeclaredBufferSizes;    // byteLength of every buffer with a file URI
    std::map<std::string, std::deque<std::string>> mBufferFileNames;  // tinygltf's decoding of a file URI -> the files it names, in order
    uint64_t mBytesRead = 0;                    // scene file and buffer files so far (and decoded geometry)
    bool mQuantized = false;                    // the file uses KHR_mesh_quantization
    std::string mBufferProblem;                 // why a buffer file was not read, if one was not
    tinygltf::Model mModel;
    Scene mScene;
    std::vector<Vec3> mMaterialEmission;  // per scene material
    std::vector<int> mMaterialEmissionTexture;  // per scene material: index into Scene::mTextures, or -1
    std::vector<int> mMaterialTexCoord;         // per scene material: the TEXCOORD set its textures read
    std::vector<bool> mMaterialEmitsTwoSided;  // per scene material: glTF doubleSided (area lights only)
    std::map<std::string, int> mApproximated;  // feature -> occurrences, for one note
    // glTF texture and transform -> scene texture
    struct TextureKey {
        int mTexture;
        bool mSrgb, mAlpha;
        float mOffsetX, mOffsetY, mUx, mUy, mVx, mVy;
        bool operator<(const TextureKey& aOther) const {
            return std::tie(mTexture, mSrgb, mAlpha, mOffsetX, mOffsetY, mUx, mUy, mVx, mVy) <
                   std::tie(aOther.mTexture, aOther.mSrgb, aOther.mAlpha, aOther.mOffsetX, aOther.mOffsetY, aOther.mUx,
                            aOther.mUy, aOther.mVx, aOther.mVy);
        }
    };
    std::map<TextureKey, int> mTextureIndex;
    std::map<int, DecodedImage> mDecodedImages;  // glTF image -> its pixels, while loading
    std::set<int> mImagesWithAlpha;              // glTF images a cut-out's base colour reads
    static constexpr uint64_t kMaxTexturePixels = uint64_t(1) << 26;  // 64 Mpixel: 768 MB of linear texels
    int mDefaultMaterial = -1;
    bool mHasCamera = false;
    int mCameraNodes = 0;                       // camera nodes met so far in the walk
    GltfLoadReport mReport;
    std::set<std::string> mIgnoredExtensions;   // used by the file, not required, not modelled
    int mSkippedTriangles = 0;
    static constexpr size_t kMaxTriangles = size_t(1) << 22;  // ~1 GB of scene and BVH; raise for big meshes
    size_t mTriangleCount = 0;  // triangles read so far, degenerate ones included
    std::set<int> mVisitedNodes;
    std::tuple<int, int, bool> mNotedPrimitive{-1, -1, false};  // mesh, primitive and mirroring being read
    // (mesh, primitive, mirroring, PrimitiveNoteKind) -> (its note's index, or npos when the
    // notes were full; placements after the first)
    std::map<std::tuple<int, int, bool, int>, std::pair<size_t, size_t>> mPrimitiveNotes;
};

} // namespace detail

Scene LoadGltfScene(const std::string& aPath, GltfLoadReport* oReport, const GltfLoadOptions& aOptions) {
    try {
        return detail::GltfLoader(aPath, aOptions).Load(oReport);
    } catch (const Error&) {
        throw;
    } catch (const std::bad_alloc&) {
        throw Error(aPath + ": out of memory while loading (the scene needs more memory than this machine can give)");
    } catch (const std::exception& e) {
        // tinygltf and nlohmann-json may throw on input they cannot handle.
        throw Error(aPath + ": " + e.what());
    }
}

} // namespace smallvcm

#endif // SMALLVCM_IMPLEMENTATION
