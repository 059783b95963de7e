// The command line's image sidecars and `smallvcm merge`.
//
// Every image the command line writes gets a sidecar, IMAGE.json beside
// IMAGE.png/.hdr/.pfm/.exr, written together with it (WriteFilesTogether: both files or
// neither). It says how the
// image was made, so that a figure or a merge can always tell:
//   "format"          "smallvcm image sidecar 1"
//   "image"           the image's file name; "image_fnv1a64": FNV-1a of its bytes, so a
//                     sidecar that was paired with another image is found out
//   "scene"           the scene file as given (a Cornell index resolved to its file)
//   "estimator"       everything that decides what the pixels are an estimate of: the
//                     algorithm, the scene file's FNV-1a, the resolution, the camera,
//                     background and --medium, the path lengths, radii, MIS and photon settings the
//                     algorithm uses, and which layer (null: the image itself). Runs
//                     merge only if these are equal.
//   "seed"            the base seed (a merged image lists "seeds")
//   "iterations"      iterations completed; "seconds" the time they took
//   "run"             what was asked for (iterations, time budget, threads) and whether
//                     a signal stopped the run early
//   "png"             exposure and tone curve (they apply to PNG files only)
//   "mean"            the mean radiance over pixels and channels
//   "smallvcm_commit" `git describe` of the sources the program was built from, or null
//   "merged_from"     (merged images only) each input: file, iterations, seeds, FNV-1a
//
// Merging: each run's image is an average of its iterations, and the iterations of runs
// with different seeds are independent samples of one estimator, so the merge weights run
// k by its share of the iterations, n_k / sum n: the result is exactly the average of all
// iterations, as one run of sum n iterations would be (for unbiased estimators, with the
// same expectation and variance). Runs that share a seed repeat the same random numbers
// and are refused. For ppm, bpm and vcm see docs/output.md, "Merging runs": each
// run shrinks its radius from the start, so the merge keeps the bias of n_k iterations.
#pragma once
#include "smallvcm.hpp"

#include <nlohmann/json.hpp>

#include <sys/stat.h>

#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <set>
#include <string>
#include <vector>

namespace sidecar {

using Json = nlohmann::ordered_json;
using smallvcm::Error;

inline constexpr const char* kFormat = "smallvcm image sidecar 1";

// FNV-1a, 64 bits, in hex: a fingerprint (not a defence against forgery).
inline uint64_t Fnv1a64Update(uint64_t aHash, const unsigned char* aData, size_t aSize) {
    for (size_t i = 0; i < aSize; i++) aHash = (aHash ^ uint64_t(aData[i])) * 1099511628211ull;
    return aHash;
}
inline constexpr uint64_t kFnv1a64Start = 1469598103934665603ull;
inline std::string Hex(uint64_t aHash) {
    char text[17];
    std::snprintf(text, sizeof(text), "%016llx", static_cast<unsigned long long>(aHash));
    return text;
}
inline std::string Fnv1a64(const unsigned char* aData, size_t aSize) { return Hex(Fnv1a64Update(kFnv1a64Start, aData, aSize)); }

inline std::string FileFnv1a64(const std::string& aPath) {
    std::ifstream file(aPath, std::ios::binary);
    if (!file) throw Error(aPath + ": cannot read it again to fingerprint it");
    uint64_t hash = kFnv1a64Start;
    std::vector<char> buffer(size_t(1) << 16);
    while (file.read(buffer.data(), std::streamsize(buffer.size())) || file.gcount() > 0)
        hash = Fnv1a64Update(hash, reinterpret_cast<const unsigned char*>(buffer.data()), size_t(file.gcount()));
    if (file.bad()) throw Error(aPath + ": cannot read it again to fingerprint it");
    return Hex(hash);
}

// A float option as the shortest decimal that reads back as the same float (0.003, not
// 0.0030000000260770321), so sidecars read well and compare exactly.
inline double Shortest(float aValue) {
    char text[32];
    const auto end = std::to_chars(text, text + sizeof(text), aValue).ptr;
    return std::strtod(std::string(text, end).c_str(), nullptr);
}

inline std::string FileName(const std::string& aPath) {
    const size_t slash = aPath.find_last_of('/');
    return slash == std::string::npos ? aPath : aPath.substr(slash + 1);
}

inline std::string SidecarPath(const std::string& aImagePath) { return aImagePath + ".json"; }

// The image's bytes and its sidecar (aRecord completed with the image's name, mean and
// fingerprint) appended to aFiles, to be written together. aLayers (an .exr only) go
// into the same file as channels NAME.R, NAME.G, NAME.B; the sidecar describes the image.
inline void AddImage(std::vector<smallvcm::OutputFile>& aFiles, const std::string& aPath, const smallvcm::Image& aImage,
                     const smallvcm::ImageWriteOptions& aWrite, Json aRecord, const std::vector<smallvcm::ExrLayer>& aLayers = {}) {
    std::vector<unsigned char> bytes =
        aLayers.empty() ? smallvcm::EncodeImage(aPath, aImage, aWrite) : smallvcm::EncodeExr(aPath, aImage, aLayers);
    aRecord["image"] = FileName(aPath);
    aRecord["image_fnv1a64"] = Fnv1a64(bytes.data(), bytes.size());
    aRecord["mean"] = smallvcm::MeanValue(aImage);
    const std::string text = aRecord.dump(2) + "\n";
    aFiles.push_back({aPath, std::move(bytes)});
    aFiles.push_back({SidecarPath(aPath), std::vector<unsigned char>(text.begin(), text.end())});
}

inline Json PngRecord(const smallvcm::ImageWriteOptions& aWrite) {
    return Json{{"exposure", Shortest(aWrite.mExposure)}, {"tonemap", smallvcm::ToneMapName(aWrite.mToneMap)}};
}

inline Json Commit() {
#ifdef SMALLVCM_COMMIT
    if (SMALLVCM_COMMIT[0] != '\0') return SMALLVCM_COMMIT;
#endif
    return nullptr;
}

// Throws Error naming aPath unless it is a regular file (a FIFO would block a reader).
inline void RequireRegularFile(const std::string& aPath, const std::string& aWhat) {
    struct stat info;
    if (::stat(aPath.c_str(), &info) != 0) throw Error(aPath + ": " + aWhat + " does not exist (or cannot be read)");
    if (!S_ISREG(info.st_mode)) throw Error(aPath + ": " + aWhat + " is not a regular file");
    if (info.st_size > (16 << 20) && aWhat == "the sidecar") throw Error(aPath + ": the sidecar is larger than 16 MiB");
}

// One input of a merge: its image, its sidecar, and what the merge takes from them.
struct Run {
    std::string mPath;
    smallvcm::Image mImage;
    Json mRecord;
    int64_t mIterations = 0;
    std::vector<uint64_t> mSeeds;
};

// Reads aPath (.pfm, .hdr or .exr: its R, G, B) and its sidecar and checks that they
// belong together.
inline Run ReadRun(const std::string& aPath) {
    if (smallvcm::ImageFormatOf(aPath) == smallvcm::ImageFormat::kPng)
        throw Error(aPath + ": a PNG holds exposed, tone-mapped 8-bit values, not radiance: merge the runs' .pfm, .hdr or .exr files");
    if (!smallvcm::IsSupportedImagePath(aPath)) throw Error(aPath + ": unknown image format (merge .pfm, .hdr or .exr files)");
    RequireRegularFile(aPath, "the image");
    const std::string sidecarPath = SidecarPath(aPath);
    RequireRegularFile(sidecarPath, "the sidecar");
    Run run;
    run.mPath = aPath;
    run.mImage = smallvcm::ReadImage(aPath);
    const std::string malformed = sidecarPath + ": malformed sidecar: ";
    try {
        std::ifstream file(sidecarPath, std::ios::binary);
        run.mRecord = Json::parse(file);
    } catch (const nlohmann::json::exception&) {
        throw Error(malformed + "not valid JSON");
    }
    const Json& r = run.mRecord;
    if (!r.is_object() || r.value("format", Json()) != kFormat) throw Error(malformed + "no \"format\": \"" + kFormat + "\"");
    if (!r.contains("estimator") || !r["estimator"].is_object()) throw Error(malformed + "no \"estimator\" object");
    const Json& estimator = r["estimator"];
    for (const char* size : {"width", "height"})
        if (!estimator.contains(size) || !estimator[size].is_number_integer()) throw Error(malformed + "no integer estimator." + size);
    if (!r.contains("iterations") || !r["iterations"].is_number_integer() || r["iterations"].get<int64_t>() < 1 ||
        r["iterations"].get<int64_t>() > (int64_t(1) << 40))
        throw Error(malformed + "\"iterations\" is not an integer in [1, 2^40]");
    run.mIterations = r["iterations"].get<int64_t>();
    if (r.contains("seeds") && r["seeds"].is_array()) {
        for (const Json& seed : r["seeds"]) {
            if (!seed.is_number_unsigned()) throw Error(malformed + "\"seeds\" holds a value that is not a seed");
            run.mSeeds.push_back(seed.get<uint64_t>());
        }
    } else if (r.contains("seed") && r["seed"].is_number_unsigned()) {
        run.mSeeds.push_back(r["seed"].get<uint64_t>());
    }
    if (run.mSeeds.empty()) throw Error(malformed + "no \"seed\"");
    if (!r.contains("image_fnv1a64") || !r["image_fnv1a64"].is_string()) throw Error(malformed + "no \"image_fnv1a64\"");
    if (r["image_fnv1a64"].get<std::string>() != FileFnv1a64(aPath))
        throw Error(aPath + ": its sidecar describes another image (the two files were not written together)");
    if (estimator["width"] != run.mImage.mWidth || estimator["height"] != run.mImage.mHeight)
        throw Error(aPath + ": the image is " + std::to_string(run.mImage.mWidth) + "x" + std::to_string(run.mImage.mHeight) +
                    " but its sidecar says " + estimator["width"].dump() + "x" + estimator["height"].dump());
    return run;
}

// Throws Error naming aRun's file unless its estimator is aFirst's, key for key.
inline void RequireSameEstimator(const Run& aFirst, const Run& aRun) {
    const Json& a = aFirst.mRecord["estimator"];
    const Json& b = aRun.mRecord["estimator"];
    auto value = [](const Json& aEstimator, const std::string& aKey) {
        return aEstimator.contains(aKey) ? aEstimator[aKey].dump() : std::string("(none)");
    };
    for (const Json& estimator : {a, b})
        for (const auto& item : estimator.items())
            if (value(a, item.key()) != value(b, item.key())) {
                std::string mine = value(b, item.key()), theirs = value(a, item.key());
                if (mine.size() > 80) mine = mine.substr(0, 77) + "...";
                if (theirs.size() > 80) theirs = theirs.substr(0, 77) + "...";
                throw Error(aRun.mPath + ": its " + item.key() + " (" + mine + ") differs from " + aFirst.mPath + "'s (" + theirs +
                            "): only runs of the same scene, resolution, algorithm and settings merge");
            }
}

struct MergeResult {
    int64_t mIterations = 0;
    double mMean = 0.0;
    std::string mAlgorithm;
};

// Reads every run, checks they merge, and writes aOutput (with its sidecar): the runs'
// images weighted by their iterations.
inline MergeResult Merge(const std::string& aOutput, const std::vector<std::string>& aInputs, const smallvcm::ImageWriteOptions& aWrite) {
    std::vector<Run> runs;
    std::set<uint64_t> seeds;
    std::vector<std::string> seedOwner;
    for (const std::string& input : aInputs) {
        Run run = ReadRun(input);
        if (!runs.empty()) RequireSameEstimator(runs.front(), run);
        for (uint64_t seed : run.mSeeds)
            if (!seeds.insert(seed).second)
                throw Error(input + ": seed " + std::to_string(seed) + " was used by an earlier input too (its iterations would be "
                            "counted twice: give every run its own --seed)");
        runs.push_back(std::move(run));
    }
    const smallvcm::Image& first = runs.front().mImage;
    int64_t iterations = 0;
    double seconds = 0.0;
    bool stoppedEarly = false;
    for (const Run& run : runs) {
        iterations += run.mIterations;
        seconds += run.mRecord.value("seconds", 0.0);
        stoppedEarly = stoppedEarly || run.mRecord.value("run", Json::object()).value("stopped_early", false) ||
                       run.mRecord.value("stopped_early", false);
    }
    std::vector<glm::dvec3> sum(first.mPixels.size(), glm::dvec3(0.0));
    for (const Run& run : runs) {
        const double weight = double(run.mIterations) / double(iterations);
        for (size_t i = 0; i < sum.size(); i++) sum[i] += weight * glm::dvec3(run.mImage.mPixels[i]);
    }
    smallvcm::Image merged(first.mWidth, first.mHeight);
    for (size_t i = 0; i < sum.size(); i++) merged.mPixels[i] = smallvcm::Vec3(sum[i]);

    Json record;
    record["format"] = kFormat;
    record["image"] = nullptr;  // AddImage fills in the image's name, fingerprint and mean
    record["image_fnv1a64"] = nullptr;
    record["scene"] = runs.front().mRecord.value("scene", Json());
    record["estimator"] = runs.front().mRecord["estimator"];
    record["seeds"] = Json(std::vector<uint64_t>(seeds.begin(), seeds.end()));
    record["iterations"] = iterations;
    record["seconds"] = seconds;
    record["stopped_early"] = stoppedEarly;
    record["png"] = PngRecord(aWrite);
    record["mean"] = nullptr;
    record["smallvcm_commit"] = Commit();
    Json inputs = Json::array();
    for (const Run& run : runs)
        inputs.push_back({{"file", run.mPath}, {"iterations", run.mIterations}, {"seeds", run.mSeeds},
                          {"image_fnv1a64", run.mRecord["image_fnv1a64"]}});
    record["merged_from"] = inputs;
    std::vector<smallvcm::OutputFile> files;
    AddImage(files, aOutput, merged, aWrite, record);
    smallvcm::WriteFilesTogether(files);
    return {iterations, smallvcm::MeanValue(merged), runs.front().mRecord["estimator"].value("algorithm", "?")};
}

} // namespace sidecar
