// bench_embree — smallvcm's BVH beside Embree 3 on the same meshes and the same rays
// (`make bench-embree`; issue "a BVH within reach of Embree").
//
//   make bench-embree                      installs libembree-dev if missing, builds, runs
//   build/bench_embree --rounds 7 --rays 262144 --markdown table.md
//   build/bench_embree --only soup,sponza  some of the meshes (names as in the table)
//
// Embree is a benchmark-only dependency: this program is built only by that target,
// never by `make` or `make test`, and the header never includes Embree.
//
// What it does, for each mesh (all generated here, with fixed seeds):
//   1. Builds smallvcm's Bvh (Bvh::Build over a PrimitiveSoup of the triangles) and an
//      Embree scene (one RTC_GEOMETRY_TYPE_TRIANGLE, default flags and build quality, a
//      device with "threads=1"): the build time of each is the best of --build-rounds,
//      on one thread, in CPU seconds of the process. Memory per triangle: smallvcm's Bvh::StorageBytes() (its nodes and
//      primitive records, vertices included), and the bytes Embree's memory monitor saw
//      allocated while rtcCommitScene ran (its BVH with its leaves; its vertex and index
//      buffers not counted).
//   2. Makes one ray set: --rays primary rays through random pixels of a pinhole camera
//      (random order), plus one diffuse bounce ray (cosine-distributed about the
//      geometric normal, on the side the ray came from) from each primary hit; and one
//      shadow-ray set: a segment from every hit of that ray set to a random point of the
//      mesh's light region (the upper part of its bounding box, or of a room's interior).
//      The hits that place them come from smallvcm's Bvh; both tracers then get the same
//      arrays.
//   3. Traces the closest-hit set (Bvh::Intersect against rtcIntersect1) and the shadow
//      set (Bvh::Occluded against rtcOccluded1), one thread, interleaved: every round
//      times smallvcm, then Embree, on the same rays; each figure is the best of
//      --rounds, in rays per CPU second of the tracing thread. The machine is shared:
//      other programs still evict this one's caches, so absolute rays per second drift
//      with its load; the ratio of two runs measured side by side is what to read.
//   4. Checks that the two agree: for every closest-hit ray, both miss, or both hit the
//      same triangle, or both hit at distances within 1e-4 relative (a ray through an
//      edge, or a duplicate triangle); for every shadow ray, the same answer. Rays that
//      disagree are counted and printed (the first few per mesh), never hidden.
//
// Prints a markdown table (and writes it to --markdown FILE): per mesh, the triangle
// count, build milliseconds and bytes per triangle of each, closest-hit and any-hit
// Mrays/s of each with the ratio smallvcm / Embree, and the agreement.

#include "smallvcm.hpp"

#include <embree3/rtcore.h>

#include <cinttypes>
#include <ctime>
#include <unistd.h>
#include <cstring>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

using smallvcm::Vec3;

namespace {

// --- meshes ---------------------------------------------------------------------------

struct Mesh {
    std::string mName;
    std::string mDescription;
    std::vector<Vec3> mVertices;
    std::vector<uint32_t> mIndices;  // three per triangle
    // Where the camera stands and looks, and the box shadow rays aim at.
    Vec3 mEye{0.f}, mTarget{0.f};
    smallvcm::Aabb mLightRegion;
    size_t TriangleCount() const { return mIndices.size() / 3; }
    void AddTriangle(const Vec3& aA, const Vec3& aB, const Vec3& aC) {
        for (const Vec3& v : {aA, aB, aC}) {
            mIndices.push_back(uint32_t(mVertices.size()));
            mVertices.push_back(v);
        }
    }
    // A quad a b c d (counter-clockwise) as two triangles.
    void AddQuad(const Vec3& aA, const Vec3& aB, const Vec3& aC, const Vec3& aD) {
        AddTriangle(aA, aB, aC);
        AddTriangle(aA, aC, aD);
    }
    smallvcm::Aabb Bounds() const {
        smallvcm::Aabb box;
        for (const Vec3& v : mVertices) box.Extend(v);
        return box;
    }
};

// An axis-aligned box as 12 triangles, facing outwards.
void AddBox(Mesh& ioMesh, const Vec3& aMin, const Vec3& aMax) {
    const Vec3 p[8] = {{aMin.x, aMin.y, aMin.z}, {aMax.x, aMin.y, aMin.z}, {aMax.x, aMax.y, aMin.z}, {aMin.x, aMax.y, aMin.z},
                       {aMin.x, aMin.y, aMax.z}, {aMax.x, aMin.y, aMax.z}, {aMax.x, aMax.y, aMax.z}, {aMin.x, aMax.y, aMax.z}};
    ioMesh.AddQuad(p[0], p[3], p[2], p[1]);  // -z
    ioMesh.AddQuad(p[4], p[5], p[6], p[7]);  // +z
    ioMesh.AddQuad(p[0], p[1], p[5], p[4]);  // -y
    ioMesh.AddQuad(p[3], p[7], p[6], p[2]);  // +y
    ioMesh.AddQuad(p[0], p[4], p[7], p[3]);  // -x
    ioMesh.AddQuad(p[1], p[2], p[6], p[5]);  // +x
}

// The Cornell box: five walls (the front open), a ceiling light, a short and a tall block
// turned about y (36 triangles).
Mesh CornellBox() {
    Mesh m;
    m.mName = "cornell";
    m.mDescription = "Cornell box: five walls, a ceiling light, two turned blocks";
    const float s = 1.f;
    m.AddQuad(Vec3(-s, -s, -s), Vec3(-s, -s, s), Vec3(s, -s, s), Vec3(s, -s, -s));  // floor
    m.AddQuad(Vec3(-s, s, -s), Vec3(s, s, -s), Vec3(s, s, s), Vec3(-s, s, s));      // ceiling
    m.AddQuad(Vec3(-s, -s, -s), Vec3(s, -s, -s), Vec3(s, s, -s), Vec3(-s, s, -s));  // back
    m.AddQuad(Vec3(-s, -s, -s), Vec3(-s, s, -s), Vec3(-s, s, s), Vec3(-s, -s, s));  // left
    m.AddQuad(Vec3(s, -s, -s), Vec3(s, -s, s), Vec3(s, s, s), Vec3(s, s, -s));      // right
    const float l = 0.25f, y = s - 1e-3f;
    m.AddQuad(Vec3(-l, y, -l), Vec3(l, y, -l), Vec3(l, y, l), Vec3(-l, y, l));      // light
    auto turnedBlock = [&](Vec3 aCenter, Vec3 aHalf, float aAngle) {
        Mesh block;
        AddBox(block, -aHalf, aHalf);
        const float c = std::cos(aAngle), sn = std::sin(aAngle);
        for (size_t t = 0; t < block.TriangleCount(); t++) {
            Vec3 v[3];
            for (int k = 0; k < 3; k++) {
                const Vec3 p = block.mVertices[block.mIndices[3 * t + size_t(k)]];
                v[k] = aCenter + Vec3(c * p.x + sn * p.z, p.y, -sn * p.x + c * p.z);
            }
            m.AddTriangle(v[0], v[1], v[2]);
        }
    };
    turnedBlock(Vec3(0.35f, -0.7f, 0.3f), Vec3(0.3f, 0.3f, 0.3f), -0.3f);
    turnedBlock(Vec3(-0.35f, -0.4f, -0.35f), Vec3(0.3f, 0.6f, 0.3f), 0.3f);
    m.mEye = Vec3(0.f, 0.f, 2.7f);
    m.mTarget = Vec3(0.f);
    m.mLightRegion.Extend(Vec3(-0.8f, 0.8f, -0.8f));
    m.mLightRegion.Extend(Vec3(0.8f, 0.95f, 0.8f));
    return m;
}

// A unit sphere with bumps of a few scales and a random offset per vertex, as a
// latitude-longitude mesh of about aTriangles triangles (2 S (R - 1) for R rings of S =
// 2 R segments), appended to ioMesh, centred at aCenter with radius aRadius.
void AddDisplacedSphere(Mesh& ioMesh, size_t aTriangles, const Vec3& aCenter, float aRadius, uint64_t aSeed) {
    const int rings = std::max(3, int(std::lround(std::sqrt(double(aTriangles) / 4.0))));
    const int segments = 2 * rings;
    smallvcm::Rng rng(aSeed);
    auto vertex = [&](int aRing, int aSegment) {
        const float theta = smallvcm::kPi * float(aRing) / float(rings);
        const float phi = 2.f * smallvcm::kPi * float(aSegment % segments) / float(segments);
        return Vec3(std::sin(theta) * std::cos(phi), std::cos(theta), std::sin(theta) * std::sin(phi));
    };
    std::vector<Vec3> grid(size_t(rings + 1) * size_t(segments));
    for (int r = 0; r <= rings; r++)
        for (int s = 0; s < segments; s++) {
            const Vec3 d = vertex(r, s);
            const float theta = smallvcm::kPi * float(r) / float(rings);
            const float phi = 2.f * smallvcm::kPi * float(s) / float(segments);
            const float bump = 0.12f * std::sin(5.f * theta) * std::sin(7.f * phi) + 0.03f * std::sin(37.f * theta) * std::sin(41.f * phi);
            const float jitter = (r == 0 || r == rings) ? 0.f : (rng.GetFloat() - 0.5f) * 0.5f / float(rings);
            grid[size_t(r) * size_t(segments) + size_t(s)] = aCenter + aRadius * (1.f + bump + jitter) * d;
        }
    auto at = [&](int aRing, int aSegment) { return grid[size_t(aRing) * size_t(segments) + size_t(aSegment % segments)]; };
    for (int r = 0; r < rings; r++)
        for (int s = 0; s < segments; s++) {
            if (r > 0) ioMesh.AddTriangle(at(r, s), at(r, s + 1), at(r + 1, s));
            if (r + 1 < rings) ioMesh.AddTriangle(at(r, s + 1), at(r + 1, s + 1), at(r + 1, s));
        }
}

Mesh DisplacedSphere(size_t aTriangles) {
    Mesh m;
    m.mName = "sphere-1e" + std::to_string(int(std::lround(std::log10(double(aTriangles)))));
    m.mDescription = "displaced sphere (bumps of two scales and a random offset per vertex)";
    AddDisplacedSphere(m, aTriangles, Vec3(0.f), 1.f, 17);
    m.mEye = Vec3(0.f, 0.4f, 2.4f);
    m.mTarget = Vec3(0.f);
    m.mLightRegion.Extend(Vec3(-1.3f, 1.1f, -1.3f));
    m.mLightRegion.Extend(Vec3(1.3f, 1.4f, 1.3f));
    return m;
}

// Triangles with uniformly random centres in the unit cube and vertices up to 0.03 from
// their centre: overlapping, in no order, the hard case for a bounding-volume hierarchy.
Mesh RandomSoup(size_t aTriangles) {
    Mesh m;
    m.mName = "soup-1e" + std::to_string(int(std::lround(std::log10(double(aTriangles)))));
    m.mDescription = "random triangle soup (centres uniform in a cube, edges up to 0.06)";
    smallvcm::Rng rng(23);
    while (m.TriangleCount() < aTriangles) {
        const Vec3 c = rng.GetVec3();
        const Vec3 a = c + 0.06f * (rng.GetVec3() - Vec3(0.5f));
        const Vec3 b = c + 0.06f * (rng.GetVec3() - Vec3(0.5f));
        const Vec3 d = c + 0.06f * (rng.GetVec3() - Vec3(0.5f));
        if (smallvcm::TriangleNormal(a, b, d)) m.AddTriangle(a, b, d);
    }
    m.mEye = Vec3(0.5f, 0.6f, 2.4f);
    m.mTarget = Vec3(0.5f);
    m.mLightRegion.Extend(Vec3(0.f, 1.1f, 0.f));
    m.mLightRegion.Extend(Vec3(1.f, 1.3f, 1.f));
    return m;
}

// An interior in the manner of Sponza: a long hall whose floor, walls and roof are a few
// large triangles, two rows of columns, arches between them, and many small detailed
// objects (bumpy vases and plants of small triangles) on the floor and along the walls.
Mesh SponzaLike() {
    Mesh m;
    m.mName = "sponza-like";
    m.mDescription = "interior: large wall and floor triangles, columns, arches, 160 small detailed objects";
    const float length = 30.f, width = 12.f, height = 12.f;
    const Vec3 lo(-length / 2, 0.f, -width / 2), hi(length / 2, height, width / 2);
    m.AddQuad(Vec3(lo.x, lo.y, lo.z), Vec3(lo.x, lo.y, hi.z), Vec3(hi.x, lo.y, hi.z), Vec3(hi.x, lo.y, lo.z));  // floor
    m.AddQuad(Vec3(lo.x, hi.y, lo.z), Vec3(hi.x, hi.y, lo.z), Vec3(hi.x, hi.y, hi.z), Vec3(lo.x, hi.y, hi.z));  // roof
    m.AddQuad(Vec3(lo.x, lo.y, lo.z), Vec3(hi.x, lo.y, lo.z), Vec3(hi.x, hi.y, lo.z), Vec3(lo.x, hi.y, lo.z));  // walls
    m.AddQuad(Vec3(lo.x, lo.y, hi.z), Vec3(lo.x, hi.y, hi.z), Vec3(hi.x, hi.y, hi.z), Vec3(hi.x, lo.y, hi.z));
    m.AddQuad(Vec3(lo.x, lo.y, lo.z), Vec3(lo.x, hi.y, lo.z), Vec3(lo.x, hi.y, hi.z), Vec3(lo.x, lo.y, hi.z));
    m.AddQuad(Vec3(hi.x, lo.y, lo.z), Vec3(hi.x, lo.y, hi.z), Vec3(hi.x, hi.y, hi.z), Vec3(hi.x, hi.y, lo.z));
    // Two rows of eight columns (cylinders of 48 x 24 quads) with a slab on top.
    for (int side = -1; side <= 1; side += 2)
        for (int i = 0; i < 8; i++) {
            const Vec3 base(-12.25f + 3.5f * float(i), 0.f, 3.f * float(side));
            const int around = 48, up = 24;
            const float radius = 0.45f, columnHeight = 7.f;
            for (int u = 0; u < up; u++)
                for (int a = 0; a < around; a++) {
                    const float a0 = 2.f * smallvcm::kPi * float(a) / float(around), a1 = 2.f * smallvcm::kPi * float(a + 1) / float(around);
                    const float y0 = columnHeight * float(u) / float(up), y1 = columnHeight * float(u + 1) / float(up);
                    const float r0 = radius * (1.f + 0.05f * std::sin(float(u))), r1 = radius * (1.f + 0.05f * std::sin(float(u + 1)));
                    m.AddQuad(base + Vec3(r0 * std::cos(a0), y0, r0 * std::sin(a0)), base + Vec3(r0 * std::cos(a1), y0, r0 * std::sin(a1)),
                              base + Vec3(r1 * std::cos(a1), y1, r1 * std::sin(a1)), base + Vec3(r1 * std::cos(a0), y1, r1 * std::sin(a0)));
                }
            AddBox(m, base + Vec3(-0.7f, columnHeight, -0.7f), base + Vec3(0.7f, columnHeight + 0.4f, 0.7f));
            // An arch to the next column: a half ring of boxes.
            if (i < 7)
                for (int k = 0; k < 24; k++) {
                    const float angle = smallvcm::kPi * (float(k) + 0.5f) / 24.f;
                    const Vec3 c = base + Vec3(1.75f - 1.75f * std::cos(angle), columnHeight + 0.4f + 1.5f * std::sin(angle), 0.f);
                    AddBox(m, c - Vec3(0.12f, 0.12f, 0.3f), c + Vec3(0.12f, 0.12f, 0.3f));
                }
        }
    // Small detailed objects: 160 bumpy spheres of ~1000 triangles, radius 0.15 to 0.5.
    smallvcm::Rng rng(31);
    for (int i = 0; i < 160; i++) {
        const float radius = 0.15f + 0.35f * rng.GetFloat();
        const float x = lo.x + 1.f + (length - 2.f) * rng.GetFloat();
        const float z = (rng.GetFloat() < 0.5f ? -1.f : 1.f) * (1.f + 4.f * rng.GetFloat());
        AddDisplacedSphere(m, 1000, Vec3(x, radius, z), radius, 100 + uint64_t(i));
    }
    m.mEye = Vec3(-13.f, 3.f, 0.5f);
    m.mTarget = Vec3(0.f, 4.f, 0.f);
    m.mLightRegion.Extend(Vec3(-14.f, 10.f, -1.f));
    m.mLightRegion.Extend(Vec3(14.f, 11.5f, 1.f));
    return m;
}

// A displaced sphere of 10^5 triangles, each stored ten times (a mesh exported over
// itself): 10^6 triangles of which a tenth are distinct.
Mesh Duplicates() {
    Mesh sphere = DisplacedSphere(100000);
    Mesh m;
    m.mName = "duplicates-1e6";
    m.mDescription = "a 1e5-triangle displaced sphere stored ten times over itself";
    for (size_t t = 0; t < sphere.TriangleCount(); t++)
        for (int copy = 0; copy < 10; copy++)
            m.AddTriangle(sphere.mVertices[sphere.mIndices[3 * t]], sphere.mVertices[sphere.mIndices[3 * t + 1]],
                          sphere.mVertices[sphere.mIndices[3 * t + 2]]);
    m.mEye = sphere.mEye;
    m.mTarget = sphere.mTarget;
    m.mLightRegion = sphere.mLightRegion;
    return m;
}

// --- ray sets -------------------------------------------------------------------------

struct Segment {
    smallvcm::Ray mRay;
    float mTMax;
};

struct RaySets {
    std::vector<smallvcm::Ray> mClosest;  // primary rays, then bounce rays
    std::vector<Segment> mShadow;
    size_t mPrimaryCount = 0;
};

Vec3 TriangleGeometricNormal(const Mesh& aMesh, int aTriangle) {
    const size_t t = size_t(aTriangle);
    const Vec3 a = aMesh.mVertices[aMesh.mIndices[3 * t]], b = aMesh.mVertices[aMesh.mIndices[3 * t + 1]],
               c = aMesh.mVertices[aMesh.mIndices[3 * t + 2]];
    return glm::normalize(glm::cross(b - a, c - a));
}

// The hits that place the bounce and shadow rays come from smallvcm's Bvh (any tracer
// would do: both are then given the same arrays).
RaySets MakeRays(const Mesh& aMesh, const smallvcm::Bvh& aBvh, size_t aPrimaryCount) {
    RaySets sets;
    smallvcm::Rng rng(5);
    const smallvcm::Aabb bounds = aMesh.Bounds();
    const float offset = 1e-4f * glm::length(bounds.mMax - bounds.mMin);
    const smallvcm::Frame camera(glm::normalize(aMesh.mTarget - aMesh.mEye));
    const float halfWidth = std::tan(0.5f * smallvcm::kPi / 3.f);  // 60 degrees
    for (size_t i = 0; i < aPrimaryCount; i++) {
        const smallvcm::Vec2 pixel = rng.GetVec2() * 2.f - smallvcm::Vec2(1.f);
        const Vec3 local(pixel.x * halfWidth, pixel.y * halfWidth, 1.f);
        sets.mClosest.push_back(smallvcm::Ray{aMesh.mEye, glm::normalize(camera.ToWorld(local))});
    }
    sets.mPrimaryCount = sets.mClosest.size();
    std::vector<Vec3> hitPoints;
    auto bounce = [&](const smallvcm::Ray& aRay, bool aSpawn) {
        float t = std::numeric_limits<float>::infinity();
        const int hit = aBvh.Intersect(aRay, 0.f, t);
        if (hit < 0) return;
        Vec3 normal = TriangleGeometricNormal(aMesh, hit);
        if (glm::dot(normal, aRay.mDirection) > 0.f) normal = -normal;
        const Vec3 point = aRay.mOrigin + t * aRay.mDirection + offset * normal;
        hitPoints.push_back(point);
        if (aSpawn) {
            const Vec3 local = smallvcm::SampleCosHemisphereW(rng.GetVec2());
            sets.mClosest.push_back(smallvcm::Ray{point, glm::normalize(smallvcm::Frame(normal).ToWorld(local))});
        }
    };
    for (size_t i = 0; i < sets.mPrimaryCount; i++) bounce(sets.mClosest[i], true);
    for (size_t i = sets.mPrimaryCount; i < sets.mClosest.size(); i++) bounce(sets.mClosest[i], false);
    for (const Vec3& from : hitPoints) {
        const Vec3 to = aMesh.mLightRegion.mMin + rng.GetVec3() * (aMesh.mLightRegion.mMax - aMesh.mLightRegion.mMin);
        const float distance = glm::length(to - from);
        if (!(distance > 2.f * offset)) continue;
        sets.mShadow.push_back(Segment{smallvcm::Ray{from, (to - from) / distance}, distance - offset});
    }
    return sets;
}

// --- the two tracers -------------------------------------------------------------------

// Timers in CPU seconds, not wall seconds: on a machine shared with other programs the
// wall clock also counts the time this thread waited for a core. Tracing runs on the
// calling thread (its own clock); a build is charged with the whole process's CPU time,
// so work Embree might hand to a helper thread is counted too.
double CpuSeconds(clockid_t aClock) {
    timespec now{};
    clock_gettime(aClock, &now);
    return double(now.tv_sec) + 1e-9 * double(now.tv_nsec);
}
double Now() { return CpuSeconds(CLOCK_THREAD_CPUTIME_ID); }
double ProcessNow() { return CpuSeconds(CLOCK_PROCESS_CPUTIME_ID); }

struct Embree {
    RTCDevice mDevice = nullptr;
    RTCScene mScene = nullptr;
    static inline int64_t sAllocated = 0;  // bytes, as Embree's memory monitor reports them

    static bool Monitor(void*, ssize_t aBytes, bool) {
        sAllocated += int64_t(aBytes);
        return true;
    }
    Embree() {
        mDevice = rtcNewDevice("threads=1");
        if (!mDevice) {
            std::fprintf(stderr, "bench_embree: rtcNewDevice failed (error %d)\n", int(rtcGetDeviceError(nullptr)));
            std::exit(1);
        }
        rtcSetDeviceMemoryMonitorFunction(mDevice, Monitor, nullptr);
    }
    ~Embree() {
        if (mScene) rtcReleaseScene(mScene);
        rtcReleaseDevice(mDevice);
    }
    // Builds the scene; returns the seconds rtcCommitScene took and sets oBvhBytes to what
    // was allocated meanwhile.
    double Build(const Mesh& aMesh, int64_t& oBvhBytes) {
        if (mScene) rtcReleaseScene(mScene);
        mScene = rtcNewScene(mDevice);
        RTCGeometry geometry = rtcNewGeometry(mDevice, RTC_GEOMETRY_TYPE_TRIANGLE);
        auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                                     3 * sizeof(float), aMesh.mVertices.size()));
        for (size_t i = 0; i < aMesh.mVertices.size(); i++)
            for (int k = 0; k < 3; k++) vertices[3 * i + size_t(k)] = aMesh.mVertices[i][k];
        auto* indices = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                                       3 * sizeof(uint32_t), aMesh.TriangleCount()));
        std::memcpy(indices, aMesh.mIndices.data(), aMesh.mIndices.size() * sizeof(uint32_t));
        rtcCommitGeometry(geometry);
        rtcAttachGeometry(mScene, geometry);
        rtcReleaseGeometry(geometry);
        const int64_t before = sAllocated;
        const double start = ProcessNow();
        rtcCommitScene(mScene);
        const double seconds = ProcessNow() - start;
        oBvhBytes = sAllocated - before;
        return seconds;
    }
    int Intersect(const smallvcm::Ray& aRay, float& oT) const {
        RTCIntersectContext context;
        rtcInitIntersectContext(&context);
        RTCRayHit rh;
        rh.ray.org_x = aRay.mOrigin.x; rh.ray.org_y = aRay.mOrigin.y; rh.ray.org_z = aRay.mOrigin.z;
        rh.ray.dir_x = aRay.mDirection.x; rh.ray.dir_y = aRay.mDirection.y; rh.ray.dir_z = aRay.mDirection.z;
        rh.ray.tnear = 0.f;
        rh.ray.tfar = std::numeric_limits<float>::infinity();
        rh.ray.time = 0.f;
        rh.ray.mask = 0xFFFFFFFFu;
        rh.ray.id = 0;
        rh.ray.flags = 0;
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(mScene, &context, &rh);
        if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return -1;
        oT = rh.ray.tfar;
        return int(rh.hit.primID);
    }
    bool Occluded(const Segment& aSegment) const {
        RTCIntersectContext context;
        rtcInitIntersectContext(&context);
        RTCRay ray;
        ray.org_x = aSegment.mRay.mOrigin.x; ray.org_y = aSegment.mRay.mOrigin.y; ray.org_z = aSegment.mRay.mOrigin.z;
        ray.dir_x = aSegment.mRay.mDirection.x; ray.dir_y = aSegment.mRay.mDirection.y; ray.dir_z = aSegment.mRay.mDirection.z;
        ray.tnear = 0.f;
        ray.tfar = aSegment.mTMax;
        ray.time = 0.f;
        ray.mask = 0xFFFFFFFFu;
        ray.id = 0;
        ray.flags = 0;
        rtcOccluded1(mScene, &context, &ray);
        return ray.tfar < 0.f;  // Embree sets tfar to -inf on a hit
    }
};

double BuildSmallvcm(const Mesh& aMesh, smallvcm::Bvh& oBvh) {
    smallvcm::PrimitiveSoup soup;
    for (size_t t = 0; t < aMesh.TriangleCount(); t++) {
        soup.mTriangleP0.push_back(aMesh.mVertices[aMesh.mIndices[3 * t]]);
        soup.mTriangleP1.push_back(aMesh.mVertices[aMesh.mIndices[3 * t + 1]]);
        soup.mTriangleP2.push_back(aMesh.mVertices[aMesh.mIndices[3 * t + 2]]);
    }
    const double start = ProcessNow();
    oBvh.Build(soup);
    return ProcessNow() - start;
}

// --- measuring ------------------------------------------------------------------------

struct Options {
    int mRounds = 5;
    int mBuildRounds = 3;
    size_t mRays = 131072;  // primary rays per mesh (bounce rays come on top)
    std::string mMarkdown;
    std::vector<std::string> mOnly;
};

struct Row {
    std::string mName, mDescription;
    size_t mTriangles = 0;
    double mBuildS = 0, mBuildE = 0;                 // seconds, best of the build rounds
    double mBytesPerTriangleS = 0, mBytesPerTriangleE = 0;
    double mClosestS = 0, mClosestE = 0;             // rays per second, best of the rounds
    double mAnyS = 0, mAnyE = 0;
    size_t mClosestRays = 0, mShadowRays = 0, mHits = 0, mOccluded = 0;
    size_t mSamePrimitive = 0, mSameDistance = 0, mClosestMismatch = 0, mShadowMismatch = 0;
};

std::string Format(const char* aFormat, double aValue) {
    char buffer[64];
    std::snprintf(buffer, sizeof buffer, aFormat, aValue);
    return buffer;
}

Row Measure(const Mesh& aMesh, const Options& aOptions) {
    Row row;
    row.mName = aMesh.mName;
    row.mDescription = aMesh.mDescription;
    row.mTriangles = aMesh.TriangleCount();
    smallvcm::Bvh bvh;
    Embree embree;
    row.mBuildS = row.mBuildE = std::numeric_limits<double>::infinity();
    int64_t embreeBytes = 0;
    for (int round = 0; round < aOptions.mBuildRounds; round++) {
        row.mBuildS = std::min(row.mBuildS, BuildSmallvcm(aMesh, bvh));
        row.mBuildE = std::min(row.mBuildE, embree.Build(aMesh, embreeBytes));
    }
    row.mBytesPerTriangleS = double(bvh.StorageBytes()) / double(row.mTriangles);
    row.mBytesPerTriangleE = double(embreeBytes) / double(row.mTriangles);

    const RaySets rays = MakeRays(aMesh, bvh, aOptions.mRays);
    row.mClosestRays = rays.mClosest.size();
    row.mShadowRays = rays.mShadow.size();

    // Agreement, once.
    int printed = 0;
    for (const smallvcm::Ray& ray : rays.mClosest) {
        float tS = std::numeric_limits<float>::infinity(), tE = 0.f;
        const int hitS = bvh.Intersect(ray, 0.f, tS);
        const int hitE = embree.Intersect(ray, tE);
        if (hitS >= 0) row.mHits++;
        if (hitS < 0 && hitE < 0) { row.mSamePrimitive++; continue; }
        if (hitS == hitE) { row.mSamePrimitive++; continue; }
        if (hitS >= 0 && hitE >= 0 && std::abs(tS - tE) <= 1e-4f * std::max(1.f, tS)) { row.mSameDistance++; continue; }
        row.mClosestMismatch++;
        if (printed++ < 3)
            std::fprintf(stderr, "  %s: closest hit differs: smallvcm triangle %d at %.7g, Embree %d at %.7g\n", aMesh.mName.c_str(),
                         hitS, double(hitS >= 0 ? tS : 0.f), hitE, double(hitE >= 0 ? tE : 0.f));
    }
    for (const Segment& s : rays.mShadow) {
        const bool occludedS = bvh.Occluded(s.mRay, 0.f, s.mTMax);
        if (occludedS) row.mOccluded++;
        if (occludedS != embree.Occluded(s)) {
            row.mShadowMismatch++;
            if (printed++ < 6)
                std::fprintf(stderr, "  %s: shadow ray differs: smallvcm %s, Embree %s\n", aMesh.mName.c_str(),
                             occludedS ? "occluded" : "clear", occludedS ? "clear" : "occluded");
        }
    }

    // Throughput, interleaved: each round times smallvcm then Embree on the same rays.
    // The sums keep the compiler from dropping the work.
    double bestS = 1e30, bestE = 1e30, bestAnyS = 1e30, bestAnyE = 1e30;
    volatile int sink = 0;
    for (int round = 0; round < aOptions.mRounds; round++) {
        double start = Now();
        int sum = 0;
        for (const smallvcm::Ray& ray : rays.mClosest) {
            float t = std::numeric_limits<float>::infinity();
            sum += bvh.Intersect(ray, 0.f, t);
        }
        bestS = std::min(bestS, Now() - start);
        start = Now();
        for (const smallvcm::Ray& ray : rays.mClosest) {
            float t;
            sum += embree.Intersect(ray, t);
        }
        bestE = std::min(bestE, Now() - start);
        start = Now();
        for (const Segment& s : rays.mShadow) sum += bvh.Occluded(s.mRay, 0.f, s.mTMax);
        bestAnyS = std::min(bestAnyS, Now() - start);
        start = Now();
        for (const Segment& s : rays.mShadow) sum += embree.Occluded(s);
        bestAnyE = std::min(bestAnyE, Now() - start);
        sink = sink + sum;
    }
    row.mClosestS = double(rays.mClosest.size()) / bestS;
    row.mClosestE = double(rays.mClosest.size()) / bestE;
    row.mAnyS = double(rays.mShadow.size()) / bestAnyS;
    row.mAnyE = double(rays.mShadow.size()) / bestAnyE;
    return row;
}

std::string Table(const std::vector<Row>& aRows, const Options& aOptions) {
    std::ostringstream out;
    out << "| mesh | triangles | build ms smallvcm / Embree | bytes/triangle smallvcm / Embree | closest-hit Mrays/s smallvcm / Embree | "
           "**ratio** | any-hit Mrays/s smallvcm / Embree | **ratio** | agreement (closest: same triangle + same t; shadow) |\n"
           "|---|---:|---:|---:|---:|---:|---:|---:|---|\n";
    for (const Row& r : aRows) {
        const double agree = double(r.mSamePrimitive + r.mSameDistance) / double(r.mClosestRays);
        out << "| " << r.mName << " | " << r.mTriangles << " | " << Format("%.1f", 1e3 * r.mBuildS) << " / " << Format("%.1f", 1e3 * r.mBuildE)
            << " | " << Format("%.0f", r.mBytesPerTriangleS) << " / " << Format("%.0f", r.mBytesPerTriangleE) << " | "
            << Format("%.2f", 1e-6 * r.mClosestS) << " / " << Format("%.2f", 1e-6 * r.mClosestE) << " | **"
            << Format("%.2f", r.mClosestS / r.mClosestE) << "** | " << Format("%.2f", 1e-6 * r.mAnyS) << " / "
            << Format("%.2f", 1e-6 * r.mAnyE) << " | **" << Format("%.2f", r.mAnyS / r.mAnyE) << "** | "
            << Format("%.4f%%", 100.0 * agree) << " (" << r.mClosestMismatch << " of " << r.mClosestRays << " differ; "
            << r.mSameDistance << " other triangle, same t); " << r.mShadowMismatch << " of " << r.mShadowRays << " differ |\n";
    }
    out << "\nOne thread each. Rays: " << aOptions.mRays
        << " primary rays through random pixels plus a cosine-distributed bounce ray from each primary hit (closest-hit set); a "
           "segment from every hit of that set to a random point of the mesh's light region (any-hit set). Each throughput is "
           "the best of "
        << aOptions.mRounds << " interleaved rounds; each build the best of " << aOptions.mBuildRounds
        << ". Times are CPU seconds (of the tracing thread; of the process for builds). Ratio = smallvcm / Embree, measured "
           "side by side; absolute rates drift with the machine's load, ratios much less.\n\nMeshes:\n";
    for (const Row& r : aRows)
        out << "- " << r.mName << ": " << r.mDescription << "; " << Format("%.1f%%", 100.0 * double(r.mHits) / double(r.mClosestRays))
            << " of closest-hit rays hit, " << Format("%.1f%%", 100.0 * double(r.mOccluded) / double(std::max<size_t>(1, r.mShadowRays)))
            << " of shadow rays are occluded.\n";
    return out.str();
}

[[noreturn]] void Usage(const std::string& aProblem) {
    if (!aProblem.empty()) std::fprintf(stderr, "bench_embree: %s\n", aProblem.c_str());
    std::fprintf(stderr, "usage: bench_embree [--rounds N] [--build-rounds N] [--rays N] [--only mesh,mesh] [--markdown FILE]\n");
    std::exit(aProblem.empty() ? 0 : 2);
}

long ParseCount(const std::string& aOption, const char* aValue, long aMin, long aMax) {
    char* end = nullptr;
    const long value = std::strtol(aValue, &end, 10);
    if (end == aValue || *end != '\0' || value < aMin || value > aMax)
        Usage(aOption + ": '" + aValue + "' is not a whole number in [" + std::to_string(aMin) + ", " + std::to_string(aMax) + "]");
    return value;
}

}  // namespace

int main(int argc, char** argv) {
    Options options;
    for (int i = 1; i < argc; i++) {
        const std::string arg = argv[i];
        auto value = [&]() -> const char* {
            if (i + 1 >= argc) Usage(arg + " needs a value");
            return argv[++i];
        };
        if (arg == "--rounds") options.mRounds = int(ParseCount(arg, value(), 1, 1000));
        else if (arg == "--build-rounds") options.mBuildRounds = int(ParseCount(arg, value(), 1, 100));
        else if (arg == "--rays") options.mRays = size_t(ParseCount(arg, value(), 1000, 100000000));
        else if (arg == "--markdown") options.mMarkdown = value();
        else if (arg == "--only") {
            std::stringstream list(value());
            for (std::string name; std::getline(list, name, ',');) options.mOnly.push_back(name);
        } else if (arg == "--help" || arg == "-h") Usage("");
        else Usage("unknown option " + arg);
    }
    using MakeMesh = Mesh (*)();
    const std::vector<std::pair<std::string, MakeMesh>> meshes = {
        {"cornell", [] { return CornellBox(); }},
        {"sphere-1e4", [] { return DisplacedSphere(10000); }},
        {"sphere-1e5", [] { return DisplacedSphere(100000); }},
        {"sphere-1e6", [] { return DisplacedSphere(1000000); }},
        {"soup-1e5", [] { return RandomSoup(100000); }},
        {"sponza-like", [] { return SponzaLike(); }},
        {"duplicates-1e6", [] { return Duplicates(); }},
    };
    for (const std::string& name : options.mOnly)
        if (std::none_of(meshes.begin(), meshes.end(), [&](const auto& m) { return m.first == name; }))
            Usage("--only: no mesh named '" + name + "'");
    // Checked before measuring, without creating the file: a run that fails leaves none.
    if (!options.mMarkdown.empty()) {
        const size_t slash = options.mMarkdown.rfind('/');
        const std::string folder = slash == std::string::npos ? "." : slash == 0 ? "/" : options.mMarkdown.substr(0, slash);
        if (access(folder.c_str(), W_OK) != 0) Usage("--markdown: cannot write in the folder of " + options.mMarkdown);
    }
    std::vector<Row> rows;
    for (const auto& [name, make] : meshes) {
        if (!options.mOnly.empty() && std::find(options.mOnly.begin(), options.mOnly.end(), name) == options.mOnly.end()) continue;
        const Mesh mesh = make();
        std::fprintf(stderr, "%s: %zu triangles...\n", mesh.mName.c_str(), mesh.TriangleCount());
        rows.push_back(Measure(mesh, options));
        const Row& r = rows.back();
        std::fprintf(stderr, "  closest-hit %.2f / %.2f Mrays/s (%.2fx), any-hit %.2f / %.2f Mrays/s (%.2fx), build %.1f / %.1f ms\n",
                     1e-6 * r.mClosestS, 1e-6 * r.mClosestE, r.mClosestS / r.mClosestE, 1e-6 * r.mAnyS, 1e-6 * r.mAnyE,
                     r.mAnyS / r.mAnyE, 1e3 * r.mBuildS, 1e3 * r.mBuildE);
    }
    const std::string table = Table(rows, options);
    std::cout << table;
    if (!options.mMarkdown.empty()) {  // whole or not at all: a temporary file, then rename
        const std::string temporary = options.mMarkdown + ".tmp";
        std::ofstream(temporary) << table;
        if (std::rename(temporary.c_str(), options.mMarkdown.c_str()) != 0) {
            std::remove(temporary.c_str());
            std::fprintf(stderr, "bench_embree: --markdown: cannot write %s\n", options.mMarkdown.c_str());
            return 1;
        }
    }
    return 0;
}
