// fig_convergence — the convergence-rate figure of the VCM course talk (seed 000):
//   F18  RMSE against iterations and against seconds, log-log, for BPT, PPM and VCM (and
//        PT and BPM), with the fitted slopes; the slide reads BPT O(N^-0.5),
//        PPM O(N^-0.33), VCM O(N^-0.5). The sampler is a second dimension: PT, BPT, PPM
//        and VCM run with independent numbers and with Owen-scrambled Sobol points
//        (--sampler sobol; curves "pt-sobol", ... on the chart, see "THE SAMPLER")
// Scene: scenes/cornell_4_default.gltf (SmallVCM's default Cornell box), 64x64 (a
// reference of 8192 iterations stays well ahead of runs of up to 2048).
//
//   build/fig_convergence [--quick] [--out DIR] [--threads N]
//   python3 figures/plot_figures.py DIR        # the chart F18_convergence.png from F18.csv
// writes F18.csv (algorithm,iterations,seconds,rmse,rmse_own,fitted; algorithm is the
// estimator's short name, with "-sobol" for Sobol points), F18_<alg>.png (each estimator's
// image at its last checkpoint) and F18.json (see figures/figure_kit.hpp).
//
// HOW. As benchmarks/convergence.cpp does: for each estimator ONE progressive run, its
// renderers (one per thread, made by smallvcm::CreateRenderer) running iterations
// 0, 1, 2, ... with smallvcm::IterationRng(seed, i) exactly as Render() would; at the
// checkpoints 1, 2, 4, 8, ... the film is resolved (Resolve(1 / iterations)) and compared
// with the reference. The run stops once its time budget is spent or at a quarter of the
// reference's iterations, with a last checkpoint there. Each estimator runs 4 times with
// different seeds; the chart and the claim use the mean of their MSE at each checkpoint
// (the expected error, whose rate the theory gives: one run's slope scatters, because a
// caustic through the glass sphere arrives as rare bright samples). Seconds are wall-clock rendering time (creating the renderers and running
// iterations; resolving and measuring are not counted).
//
// THE FIT. The measured error includes the reference's own noise n (its two halves give
// it, see GetReference): rmse^2 = own^2 + n^2, so own = sqrt(rmse^2 - n^2) is what is
// fitted (a curve that reaches n otherwise flattens and its slope means nothing). The
// slope is the least-squares line through (log N, log own) over the checkpoints
//   * from 8 iterations on: before that one pixel's few samples are dominated by rare
//     bright paths (a caustic through the glass sphere found or not), and PPM/VCM start
//     at their largest merging radius, whose bias shrinks only later; neither is the
//     rate at which the error goes on falling;
//   * while the estimator's own MSE is at least half the reference's (own >= 0.71 n):
//     below that the subtracted n^2 dominates and its own uncertainty (a few percent)
//     would decide the last points.
//
// PPM's RATE. The radius shrinks as r_i = r_0 (i+1)^((alpha-1)/2), so one iteration's
// variance grows as 1/r_i^2 ~ i^(1-alpha) and the bias (~ r^2) falls as i^(alpha-1): after
// N iterations the variance of the average falls as N^-alpha and the bias as N^(alpha-1).
// RMSE ~ N^(-alpha/2) from the variance and N^(alpha-1) from the bias; SmallVCM's
// alpha = 0.75 gives N^-0.375 while the variance dominates and N^-0.25 in the end, and
// alpha = 2/3 balances both at N^-1/3, the slide's rate. PPM and BPM (merging, no
// connections) run with alpha = 2/3; VCM keeps SmallVCM's 0.75: on this scene its MIS
// gives merging a tiny share of the light (technique_shares in the record), its error is
// that of its unbiased techniques.
//
// THE MARGIN. A slope is "near" its rate within +-0.08: less than half the gap between
// -1/2 and -1/3 (1/6), so a slope that passes is nearer its own rate than the other one.
// Its basis is the spread of the fitted slope from run to run: the record gives the
// single-run slopes and their standard deviation per estimator (in a 128x128 run of one
// seed each BPT's single slope was -0.42 and VCM's -0.55: that scatter is why the claim
// is fitted to the mean of 4 runs, whose standard error is half a single run's).
//
// THE SAMPLER. The claim is the slide's, with independent numbers. With Sobol points a
// pixel's camera sub-paths are stratified across iterations, a light sub-path only
// among the light sub-paths of its own iteration (iterations draw independent
// scrambles; smallvcm.hpp's Sampler): what the camera sub-path alone finds (PT, BPT's
// camera-side techniques) can converge faster than N^-0.5, what comes from light
// sub-paths (light tracing, connections to light vertices, merging) keeps N^-0.5 with a
// smaller constant, and PPM's rate stays the one its radius shrinkage sets. The record
// gives each sampler's slope and the ratio of their MSE at the last common checkpoint
// (numbers.sobol_vs_independent); tests/test_figures.cpp's F18 case checks these
// claims where they are cheap to check (diffuse_box, 16x16).
//
// THE RADIUS. A merging estimate's error has two parts: the photon part (which photons
// fell into the disk), whose rate is the one above, and a part the radius does not change
// (where the camera's samples land in a pixel: edges, the light seen directly, what the
// glass and mirror show), which falls as N^-0.5 like any unbiased estimator's. The fitted
// slope is a mix until the photon part dominates. SmallVCM's radius, 0.003 x the scene
// radius, is kept: at 64x64 (4096 light sub-paths per iteration) few photons fall into
// a disk and the photon part dominates from the first checkpoints. Scaling the radius up
// for the smaller image (x 512 / width, as many photons per disk as SmallVCM at 512x512)
// gives a better image at equal time but makes the r-independent part dominate: in a
// 64x64 test of 6 s per estimator PPM's slope was then -0.44 (-0.36 with 0.003), the
// pre-asymptotic mix, not the rate.

#include "figure_kit.hpp"

#include <thread>

using namespace figures;
using smallvcm::SamplerType;

namespace {

const char* const kScene = "cornell_4_default.gltf";
constexpr int kFitFirstIteration = 8;
constexpr double kFitOwnMseFloor = 0.5;  // fit while own MSE >= this x the reference's noise^2
constexpr double kSlopeMargin = 0.08;
constexpr float kPpmAlpha = 2.f / 3.f;

// The merging radius: SmallVCM's default, 0.003 x the scene radius (see "THE RADIUS").
constexpr float kRadiusFactor = 0.003f;

struct Estimator {
    Algorithm mAlgorithm;
    double mTheorySlope;  // of RMSE against iterations, asymptotically
    float mAlpha;         // radius reduction (merging estimators)
    bool mInClaim;        // the slide names it
    SamplerType mSampler = SamplerType::kIndependent;
};

// BPM is not on the slide; its merged part has PPM's rate, but MIS gives much of its light
// to camera paths that hit the light (unbiased, N^-0.5), so a run of this length shows a
// mix (the record gives the share of each technique).
const Estimator kEstimators[] = {
    {Algorithm::kPathTracing, -0.5, 0.75f, false},
    {Algorithm::kBidirectionalPathTracing, -0.5, 0.75f, true},
    {Algorithm::kProgressivePhotonMapping, -1.0 / 3.0, kPpmAlpha, true},
    {Algorithm::kBidirectionalPhotonMapping, -1.0 / 3.0, kPpmAlpha, false},
    {Algorithm::kVertexConnectionMerging, -0.5, 0.75f, true},
    // The sampler dimension (see "THE SAMPLER"); theory slopes are those of independent numbers.
    {Algorithm::kPathTracing, -0.5, 0.75f, false, SamplerType::kSobol},
    {Algorithm::kBidirectionalPathTracing, -0.5, 0.75f, false, SamplerType::kSobol},
    {Algorithm::kProgressivePhotonMapping, -1.0 / 3.0, kPpmAlpha, false, SamplerType::kSobol},
    {Algorithm::kVertexConnectionMerging, -0.5, 0.75f, false, SamplerType::kSobol},
};

// "bpt" with independent numbers, "bpt-sobol" with Sobol points.
std::string EstimatorName(const Estimator& aEstimator) {
    return std::string(smallvcm::AlgorithmShortName(aEstimator.mAlgorithm)) +
           (aEstimator.mSampler == SamplerType::kSobol ? "-sobol" : "");
}

struct Checkpoint {
    int mIterations = 0;
    double mSeconds = 0.0;
    double mRmse = 0.0;     // against the reference, as measured
    double mOwnRmse = 0.0;  // without the reference's noise
    bool mFitted = false;
};

struct Run {
    std::vector<Checkpoint> mCheckpoints;
    Image mLast;  // the image at the last checkpoint
    double mSlopeIterations = NAN, mSlopeSeconds = NAN;
    int mFittedPoints = 0;
};

double Seconds(std::chrono::steady_clock::time_point aStart) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - aStart).count();
}

// The fit of "THE FIT" over a run's checkpoints (those marked mFitted).
void FitSlopes(Run& aRun) {
    std::vector<double> iterations, seconds, errors;
    for (const Checkpoint& point : aRun.mCheckpoints)
        if (point.mFitted) {
            iterations.push_back(point.mIterations);
            seconds.push_back(point.mSeconds);
            errors.push_back(point.mOwnRmse);
        }
    aRun.mFittedPoints = int(errors.size());
    // Two points always fit exactly: a slope needs three.
    if (aRun.mFittedPoints >= 3) {
        aRun.mSlopeIterations = LogLogSlope(iterations, errors);
        aRun.mSlopeSeconds = LogLogSlope(seconds, errors);
    }
}

// A checkpoint from its (mean) MSE against the reference, whose noise^2 is aNoise2.
Checkpoint MakeCheckpoint(int aIterations, double aSeconds, double aMse, double aNoise2) {
    Checkpoint point;
    point.mIterations = aIterations;
    point.mSeconds = aSeconds;
    point.mRmse = std::sqrt(aMse);
    const double own2 = aMse - aNoise2;
    point.mOwnRmse = std::sqrt(std::max(0.0, own2));
    point.mFitted = aIterations >= kFitFirstIteration && own2 >= kFitOwnMseFloor * aNoise2 && own2 > 0.0;
    return point;
}

// One progressive run until aBudget seconds of rendering or aMaxIterations; see "HOW".
Run RunProgressively(const Scene& aScene, const RenderOptions& aOptions, const Reference& aReference, double aBudget,
                     int aMaxIterations) {
    smallvcm::ValidateRenderOptions(aOptions);
    const int threadCount =
        aOptions.mThreads > 0 ? aOptions.mThreads : int(std::max(1u, std::thread::hardware_concurrency()));
    double rendering = 0.0;
    auto start = std::chrono::steady_clock::now();
    std::vector<std::unique_ptr<smallvcm::AbstractRenderer>> renderers;
    for (int t = 0; t < threadCount; t++) renderers.push_back(smallvcm::CreateRenderer(aScene, aOptions));
    // Iterations [aBegin, aEnd), iteration i on renderer i mod T, as Render() does.
    auto runIterations = [&](int aBegin, int aEnd) {
        auto work = [&](int aThread) {
            for (int i = aBegin; i < aEnd; i++) {
                if (i % threadCount != aThread) continue;
                smallvcm::Sampler sampler = smallvcm::IterationSampler(aOptions.mSampler, aOptions.mSeed, i);
                renderers[size_t(aThread)]->RunIteration(i, sampler);
            }
        };
        std::vector<std::thread> threads;
        for (int t = 1; t < threadCount; t++) threads.emplace_back(work, t);
        work(0);
        for (std::thread& thread : threads) thread.join();
    };

    const double noise2 = aReference.mNoiseRmse * aReference.mNoiseRmse;
    Run run;
    int done = 0;
    for (int checkpoint = 1;; checkpoint *= 2) {
        bool outOfTime = false;
        while (done < checkpoint && !outOfTime) {
            // Batches of about 1/8 of the iterations so far: the budget is looked at often
            // (overshooting it by at most ~1/8) while starting threads stays negligible.
            const int batch = threadCount * std::max(1, done / (8 * threadCount));
            const int end = std::min(checkpoint, done + batch);
            runIterations(done, end);
            done = end;
            outOfTime = rendering + Seconds(start) >= aBudget || done >= aMaxIterations;
        }
        rendering += Seconds(start);

        // Not timed: the threads' films summed, resolved, measured.
        smallvcm::Film film = renderers[0]->GetFilm();
        for (int t = 1; t < threadCount; t++) film.Accumulate(renderers[size_t(t)]->GetFilm());
        run.mLast = film.Resolve(1.0 / done);
        const double rmse = smallvcm::Rmse(run.mLast, aReference.mImage);
        const Checkpoint point = MakeCheckpoint(done, rendering, rmse * rmse, noise2);
        run.mCheckpoints.push_back(point);
        if (outOfTime) break;
        start = std::chrono::steady_clock::now();
    }

    FitSlopes(run);
    return run;
}

RenderOptions EstimatorOptions(const Kit& aKit, const Estimator& aEstimator, uint64_t aSeed) {
    RenderOptions options = BaseOptions(aKit, aEstimator.mAlgorithm);
    options.mSeed = aSeed;
    options.mRadiusFactor = kRadiusFactor;
    options.mRadiusAlpha = aEstimator.mAlpha;
    options.mSampler = aEstimator.mSampler;
    return options;
}

Json OrNull(double aValue) { return std::isfinite(aValue) ? Json(aValue) : Json(nullptr); }

// The seed-averaged curve: at each checkpoint every run reached with the same iteration
// count, the mean over the runs of the MSE and of the seconds; its fit is the claim's
// slope. One run's slope scatters (a caustic through the glass sphere is found as rare
// bright samples); the mean MSE is the expected error whose rate the theory gives.
Run AverageRuns(const std::vector<Run>& aRuns, double aNoise2) {
    Run mean;
    mean.mLast = aRuns.front().mLast;
    for (size_t c = 0;; c++) {
        bool common = true;
        for (const Run& run : aRuns)
            common = common && c < run.mCheckpoints.size() &&
                     run.mCheckpoints[c].mIterations == aRuns.front().mCheckpoints[c].mIterations;
        if (!common) break;
        double mse = 0.0, seconds = 0.0;
        for (const Run& run : aRuns) {
            mse += run.mCheckpoints[c].mRmse * run.mCheckpoints[c].mRmse / double(aRuns.size());
            seconds += run.mCheckpoints[c].mSeconds / double(aRuns.size());
        }
        mean.mCheckpoints.push_back(MakeCheckpoint(aRuns.front().mCheckpoints[c].mIterations, seconds, mse, aNoise2));
    }
    FitSlopes(mean);
    return mean;
}

// Each technique's share of the image's mean light for the merging estimators, from a
// short render with technique layers: which part of the light is merged (PPM's rate) and
// which comes from unbiased techniques (rate N^-0.5).
Json TechniqueShares(const Kit& aKit, const Scene& aScene) {
    Json shares;
    for (const Estimator& estimator : kEstimators) {
        if (estimator.mAlgorithm == Algorithm::kPathTracing || estimator.mSampler != SamplerType::kIndependent) continue;
        RenderOptions options = EstimatorOptions(aKit, estimator, 1899);
        options.mTechniqueLayers = true;
        const RenderResult result = RenderIterations(aScene, options, aKit.Pick(16, 8));
        const double total = std::max(1e-30, smallvcm::MeanValue(result.mImage));
        Json& share = shares[smallvcm::AlgorithmShortName(estimator.mAlgorithm)];
        for (const char* layer : {"unidirectional", "nee", "light_tracing", "connection", "merging"})
            share[layer] = smallvcm::MeanValue(Layer(result, layer)) / total;
    }
    return shares;
}

void WriteCsv(const Kit& aKit, const std::vector<std::pair<std::string, Run>>& aRuns) {
    const std::string path = aKit.mOut + "/F18.csv";
    {
        std::ofstream csv(path + ".partial");
        csv << "algorithm,iterations,seconds,rmse,rmse_own,fitted\n";
        for (const auto& [name, run] : aRuns)
            for (const Checkpoint& point : run.mCheckpoints) {
                char line[256];
                std::snprintf(line, sizeof(line), "%s,%d,%.6f,%.9g,%.9g,%d\n", name.c_str(), point.mIterations,
                              point.mSeconds, point.mRmse, point.mOwnRmse, point.mFitted ? 1 : 0);
                csv << line;
            }
        if (!csv) throw Error(path + ": cannot write");
    }
    fs::rename(path + ".partial", path);
}

void FigureConvergence(const Kit& aKit) {
    Figure figure(aKit, "F18", "Convergence rate", "Convergence rate (VCM course talk, seed 000)",
                  "fitted slopes near -0.5 (BPT, VCM) and -1/3 (PPM)");
    const int size = aKit.Pick(64, 32);
    const double budget = aKit.Pick(10.0, 0.4);
    // K runs per estimator with their own seeds (no two estimators share one either: BPT
    // and VCM would share their light sub-paths and, mostly, their error). The claim is
    // the fit of the mean curve; the spread of the K single-run slopes is reported too.
    const int runsPerEstimator = 4;
    const uint64_t firstSeed = 1810;
    const Scene scene = LoadScene(aKit, kScene, size, size);
    const Reference reference = GetReference(aKit, StandardReference(aKit, kScene, size, size));
    figure.SetReference(reference);
    // A run stops at a quarter of the reference's iterations, so that the reference's
    // noise stays well below every error it measures.
    const int maxIterations = reference.mRecord["settings"]["iterations"].get<int>() / 4;
    Json alphas;
    for (const Estimator& estimator : kEstimators)
        if (estimator.mAlgorithm != Algorithm::kPathTracing &&
            estimator.mAlgorithm != Algorithm::kBidirectionalPathTracing)
            alphas[smallvcm::AlgorithmShortName(estimator.mAlgorithm)] = estimator.mAlpha;
    figure.Settings() = {
        {"scene", std::string("scenes/") + kScene},
        {"resolution", size},
        {"seconds_per_run", budget},
        {"max_iterations_per_run", maxIterations},
        {"runs_per_estimator", runsPerEstimator},
        {"clock", "wall-clock rendering time (renderer creation + iterations), resolving and measuring excluded"},
        {"threads", aKit.mThreads > 0 ? aKit.mThreads : int(std::max(1u, std::thread::hardware_concurrency()))},
        {"seeds", "1810 + 10 x the estimator's index in pt, bpt, ppm, bpm, vcm, pt-sobol, bpt-sobol, ppm-sobol, "
                  "vcm-sobol + the run's index"},
        {"samplers", "independent numbers; '-sobol': Owen-scrambled Sobol points (RenderOptions::mSampler)"},
        {"checkpoints", "1, 2, 4, 8, ... iterations and the last one when the budget ran out"},
        {"radius_factor", kRadiusFactor},
        {"radius_factor_why", "SmallVCM's default: at this size few photons fall in a disk, so the merged "
                              "error shows its own rate from the first checkpoints (see the program's comment)"},
        {"radius_alpha", alphas},
        {"fit", "least squares of log(own RMSE) against log(iterations) (and log(seconds)) over the checkpoints "
                "from " + std::to_string(kFitFirstIteration) + " iterations on where own MSE = mean MSE over the runs - "
                "reference noise^2 is at least " + Num(kFitOwnMseFloor) + " x reference noise^2"},
        {"slope_margin", kSlopeMargin}};

    std::vector<std::pair<std::string, Run>> runs;
    double largestStd = 0.0;
    for (const Estimator& estimator : kEstimators) {
        const std::string name = EstimatorName(estimator);
        std::vector<Run> single;
        std::vector<double> slopes;
        for (int k = 0; k < runsPerEstimator; k++) {
            const uint64_t seed = firstSeed + 10 * runs.size() + uint64_t(k);
            single.push_back(RunProgressively(scene, EstimatorOptions(aKit, estimator, seed), reference, budget,
                                              maxIterations));
            if (std::isfinite(single.back().mSlopeIterations)) slopes.push_back(single.back().mSlopeIterations);
        }
        double meanSlope = 0.0, variance = 0.0;
        for (double slope : slopes) meanSlope += slope / double(slopes.size());
        for (double slope : slopes) variance += (slope - meanSlope) * (slope - meanSlope) / std::max(1.0, double(slopes.size()) - 1.0);
        const double deviation = slopes.size() >= 2 ? std::sqrt(variance) : NAN;
        if (std::isfinite(deviation) && estimator.mInClaim) largestStd = std::max(largestStd, deviation);
        Run run = AverageRuns(single, reference.mNoiseRmse * reference.mNoiseRmse);
        const Checkpoint& last = run.mCheckpoints.back();
        std::printf("  %-9s %6d iterations %6.1f s  RMSE %.4g (own %.4g)  slope of the mean %+.3f vs iterations, "
                    "%+.3f vs seconds (%d points); single runs %s\n", name.c_str(), last.mIterations, last.mSeconds,
                    last.mRmse, last.mOwnRmse, run.mSlopeIterations, run.mSlopeSeconds, run.mFittedPoints,
                    Json(slopes).dump().c_str());
        std::fflush(stdout);
        // PPM's and BPM's images are noisy at this size: few photons per merging disk (see
        // "THE RADIUS"); the figure is the chart, the images show what the errors look like.
        const bool merging = estimator.mAlgorithm != Algorithm::kPathTracing &&
                             estimator.mAlgorithm != Algorithm::kBidirectionalPathTracing;
        const Checkpoint& firstRunLast = single.front().mCheckpoints.back();
        Json& numbers = figure.AddPanel(
            name, single.front().mLast,
            name + " after " + std::to_string(firstRunLast.mIterations) + " iterations (" +
                Num(firstRunLast.mSeconds) + " s, one run)" +
                (merging ? ", merging radius 0.003 x scene radius, alpha " + Num(estimator.mAlpha) : "") +
                (estimator.mSampler == SamplerType::kSobol ? ", Sobol points" : ""));
        numbers["iterations"] = firstRunLast.mIterations;
        numbers["seconds"] = firstRunLast.mSeconds;
        numbers["rmse"] = firstRunLast.mRmse;
        numbers["relmse"] = smallvcm::RelativeMse(single.front().mLast, reference.mImage);
        figure.Numbers()["slope_vs_iterations"][name] = OrNull(run.mSlopeIterations);
        figure.Numbers()["slope_vs_seconds"][name] = OrNull(run.mSlopeSeconds);
        figure.Numbers()["single_run_slopes"][name] = slopes;
        figure.Numbers()["single_run_slope_std"][name] = OrNull(deviation);
        figure.Numbers()["theory_slope"][name] = estimator.mTheorySlope;
        figure.Numbers()["fitted_points"][name] = run.mFittedPoints;
        runs.emplace_back(name, std::move(run));
    }
    WriteCsv(aKit, runs);
    figure.Numbers()["reference_noise_rmse"] = reference.mNoiseRmse;
    figure.Numbers()["largest_single_run_slope_std_bpt_ppm_vcm"] = largestStd;

    const Json shares = TechniqueShares(aKit, scene);
    figure.Numbers()["technique_shares"] = shares;

    // Each sampler's slope, and the ratio of their mean MSE at the last checkpoint both
    // reached (the same iteration count).
    std::string samplers;
    for (const Estimator& estimator : kEstimators) {
        if (estimator.mSampler != SamplerType::kSobol) continue;
        const std::string name = smallvcm::AlgorithmShortName(estimator.mAlgorithm), sobolName = EstimatorName(estimator);
        const Run* independent = nullptr;
        const Run* sobol = nullptr;
        for (const auto& [runName, run] : runs) {
            if (runName == name) independent = &run;
            if (runName == sobolName) sobol = &run;
        }
        if (!independent || !sobol) continue;
        double ratio = NAN;
        int at = 0;
        for (const Checkpoint& a : independent->mCheckpoints)
            for (const Checkpoint& b : sobol->mCheckpoints)
                if (a.mIterations == b.mIterations && b.mRmse > 0.0) {
                    ratio = (a.mRmse * a.mRmse) / (b.mRmse * b.mRmse);
                    at = a.mIterations;
                }
        Json& entry = figure.Numbers()["sobol_vs_independent"][name];
        entry["slope_independent"] = OrNull(independent->mSlopeIterations);
        entry["slope_sobol"] = OrNull(sobol->mSlopeIterations);
        entry["mse_ratio_independent_over_sobol"] = OrNull(ratio);
        entry["at_iterations"] = at;
        samplers += (samplers.empty() ? "" : ", ") + name + " " + Num(independent->mSlopeIterations, "%+.3f") + " -> " +
                    Num(sobol->mSlopeIterations, "%+.3f") + " (MSE / " + Num(ratio, "%.2f") + " at " +
                    std::to_string(at) + " it.)";
    }

    bool holds = true;
    std::string claimed, others;
    for (const Estimator& estimator : kEstimators) {
        if (estimator.mSampler != SamplerType::kIndependent) continue;
        const std::string name = EstimatorName(estimator);
        const Json slope = figure.Numbers()["slope_vs_iterations"][name];
        const bool near = slope.is_number() && std::abs(slope.get<double>() - estimator.mTheorySlope) <= kSlopeMargin;
        std::string text = name + " " + (slope.is_number() ? Num(slope.get<double>(), "%+.3f") : "n/a") + " (" +
                           Num(estimator.mTheorySlope, "%+.3f") + ")";
        if (estimator.mAlgorithm == Algorithm::kBidirectionalPhotonMapping)
            text += " [" + Num(100.0 * shares["bpm"]["unidirectional"].get<double>(), "%.0f") +
                    "% of its light from camera paths hitting the light: unbiased, a mix of rates]";
        if (estimator.mInClaim) {
            holds = holds && near;
            claimed += (claimed.empty() ? "" : ", ") + text;
        } else {
            others += (others.empty() ? "" : ", ") + text;
        }
    }
    figure.Verdict(holds, "slopes of own RMSE vs iterations (theory): " + claimed + ", margin +-" +
                              Num(kSlopeMargin) + "; not claimed: " + others + "; fitted to the mean MSE of " +
                              std::to_string(runsPerEstimator) + " runs each, whose single-run slopes spread by "
                              "std <= " + Num(largestStd, "%.3f") + " (BPT, PPM, VCM); independent -> Sobol "
                              "slopes: " + samplers);
    figure.AddChart("F18_convergence.png");
    figure.Write();
    std::printf("  chart: python3 figures/plot_figures.py %s\n", aKit.mOut.c_str());
}

}  // namespace

int main(int argc, char** argv) {
    return RunFigureProgram(argc, argv, "fig_convergence: figure F18 (convergence rate)", [](const Kit& aKit) {
        if (aKit.Wants("F18")) FigureConvergence(aKit);
    });
}
