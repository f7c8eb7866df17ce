// Extraction on a synthetic video rendered here, frame weights, and scalar tracks.
#include "observe/observe.h"
#include "scene/scene.h"

#include <gtest/gtest.h>

#include <random>
#include <unistd.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>

using namespace viscoscope;
namespace fs = std::filesystem;

namespace {

constexpr int kWidth = 640, kHeight = 480, kFrames = 40, kLiquidFreeFrames = 10;
constexpr double kScale = kWidth / 480.0;  // the liquid's shape was laid out at 480 px wide
constexpr double kFps = 25;

// A grey-brown textured table with coloured blotches: smooth noise at two scales.
cv::Mat3f texturedBackground() {
    cv::Mat3f background(kHeight, kWidth);
    cv::Mat3f fine(kHeight, kWidth), coarse(kHeight / 8, kWidth / 8);
    cv::randu(fine, cv::Scalar::all(-1), cv::Scalar::all(1));
    cv::randu(coarse, cv::Scalar::all(-1), cv::Scalar::all(1));
    cv::GaussianBlur(fine, fine, cv::Size(0, 0), 2.0);
    cv::resize(coarse, coarse, background.size(), 0, 0, cv::INTER_CUBIC);
    background = cv::Scalar(120, 125, 130) + 90 * fine + 40 * coarse;
    return background;
}

// The liquid: a stream falling from the top edge into a puddle that spreads, both wobbling.
cv::Mat1b liquidMask(int frame) {
    cv::Mat1b mask(kHeight, kWidth, uchar(0));
    if (frame < kLiquidFreeFrames) return mask;
    const double t = (frame - kLiquidFreeFrames + 1) / double(kFrames - kLiquidFreeFrames);
    const cv::Point puddleCentre(kWidth / 2 + int(20 * kScale * t), int(kHeight * 0.72));
    const cv::Size puddleAxes(int(kScale * (25 + 140 * t)), int(kScale * (10 + 45 * t)));
    cv::ellipse(mask, puddleCentre, puddleAxes, 8 * std::sin(7 * t), 0, 360, cv::Scalar(255), cv::FILLED);
    const int streamWidth = int(kScale * (10 + 6 * std::sin(11 * t)));
    const int streamBottom = std::min(puddleCentre.y, int(kHeight * (0.2 + 1.5 * t)));
    cv::rectangle(mask, cv::Rect(kWidth / 2 - streamWidth / 2, 0, streamWidth, streamBottom), cv::Scalar(255),
                  cv::FILLED);
    return mask;
}

// Background × slow exposure drift, the amber liquid, and per-frame sensor noise.
cv::Mat3b renderFrame(const cv::Mat3f& background, const cv::Mat1b& liquid, int frame) {
    // Auto exposure reacting to the dark liquid: the picture brightens by up to 8 % after the
    // background was learned, more than MOG2's learned variance absorbs.
    const double exposure = 1.0 + 0.08 * std::max(0, frame - kLiquidFreeFrames) / double(kFrames - kLiquidFreeFrames);
    cv::Mat3f picture = background * exposure;
    cv::Mat3f honey(kHeight, kWidth, cv::Vec3f(25, 85, 160));  // BGR amber
    honey += 0.15 * (background - cv::Scalar(120, 125, 130));   // a little of the table shows through
    honey.copyTo(picture, liquid);
    cv::Mat3f noise(kHeight, kWidth);
    cv::randn(noise, cv::Scalar::all(0), cv::Scalar::all(3.0));
    picture += noise;
    cv::Mat3b out;
    picture.convertTo(out, CV_8UC3);
    return out;
}

// An empty folder for one test, removed afterwards; the process id keeps parallel runs apart.
struct TempDirectory {
    explicit TempDirectory(const std::string& name)
        : path(fs::temp_directory_path() / (name + "_" + std::to_string(getpid()))) {
        fs::remove_all(path);
        fs::create_directories(path);
    }
    ~TempDirectory() { fs::remove_all(path); }
    fs::path path;
};

}  // namespace

TEST(Extraction, SyntheticVideoMatchesTrueMasks) {
    const TempDirectory temp("viscoscope_extract_test");
    const fs::path& dir = temp.path;
    cv::theRNG().state = 5;  // the texture and the noise come from OpenCV's generator
    const cv::Mat3f background = texturedBackground();
    const fs::path video = dir / "pour.mp4";
    cv::VideoWriter writer(video.string(), cv::VideoWriter::fourcc('m', 'p', '4', 'v'), kFps, {kWidth, kHeight});
    ASSERT_TRUE(writer.isOpened());
    std::vector<cv::Mat1b> truth;
    for (int f = 0; f < kFrames; ++f) {
        truth.push_back(liquidMask(f));
        writer.write(renderFrame(background, truth.back(), f));
    }
    writer.release();

    ExtractionOptions options;
    options.backgroundFrames = kLiquidFreeFrames;
    options.weights = "0-9:0";
    int progressCalls = 0;
    const ReferenceManifest written =
        extractSilhouettes(video, options, dir / "reference", [&](int, int) { ++progressCalls; });
    const ReferenceManifest manifest = loadReferenceManifest(dir / "reference");
    ASSERT_EQ(manifest.frames.size(), size_t(kFrames));
    EXPECT_EQ(written.frames, manifest.frames);
    EXPECT_EQ(progressCalls, kFrames);
    EXPECT_NEAR(manifest.fps, kFps, 1e-6);
    EXPECT_NEAR(manifest.times[20], 20 / kFps, 1e-9);
    EXPECT_EQ(manifest.weights[9], 0);
    EXPECT_EQ(manifest.weights[10], 1);
    EXPECT_TRUE(fs::exists(dir / "reference" / "preview.png"));

    double iouSum = 0, worstIou = 1;
    for (size_t i = kLiquidFreeFrames; i < manifest.frames.size(); ++i) {
        const double iou = intersectionOverUnion(manifest.mask(i), truth[manifest.frames[i]]);
        iouSum += iou;
        worstIou = std::min(worstIou, iou);
    }
    const double meanIou = iouSum / (kFrames - kLiquidFreeFrames);
    long long falsePixelsBeforePour = 0;
    for (int i = 0; i < kLiquidFreeFrames; ++i) falsePixelsBeforePour += cv::countNonZero(manifest.mask(i));
    std::printf("[ figures  ] extraction on a %dx%d mp4v video with lighting drift and noise: mean IoU %.4f, "
                "worst %.4f, %lld foreground pixels in the %d liquid-free frames\n",
                kWidth, kHeight, meanIou, worstIou, falsePixelsBeforePour, kLiquidFreeFrames);
    EXPECT_GE(meanIou, 0.95);
    EXPECT_LT(falsePixelsBeforePour, 0.001 * kWidth * kHeight * kLiquidFreeFrames);

    // A frame range and a step, on the same video.
    options.first = 12;
    options.last = 30;
    options.step = 6;
    options.weights = "";
    const ReferenceManifest ranged = extractSilhouettes(video, options, dir / "ranged");
    EXPECT_EQ(ranged.frames, (std::vector<int>{12, 18, 24, 30}));
    EXPECT_TRUE(fs::exists(dir / "ranged" / "masks" / "mask_00024.png"));
    options.last = kFrames + 5;
    EXPECT_THROW(extractSilhouettes(video, options, dir / "past_end"), InputError);
    EXPECT_FALSE(fs::exists(dir / "past_end" / "manifest.json"));
}

namespace {

double srgbToLinear(double v) { return v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4); }
double linearToSrgb(double v) { return v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055; }

const cv::Vec3d kBackdrop(200, 196, 190), kHoney(25, 85, 160);  // BGR, sRGB-encoded

// A disc and a thin stream that move by fractions of a pixel, as a camera sees them: each pixel
// mixes liquid and backdrop in linear light by the share of it the shapes cover (8 × 8 samples),
// then the picture is sRGB-encoded, noised and compressed. `covered` gets the pixels ≥ half covered.
// Inside `shadow` the backdrop's light is scaled by `shade`, as a cast shadow would scale it.
cv::Mat3b antialiasedFrame(int frame, cv::Mat1b& covered, const cv::Vec3d& liquid = kHoney,
                           const std::optional<cv::Rect>& shadow = std::nullopt, double shade = 1.0) {
    constexpr int kW = 160, kH = 120, kSub = 8;
    const double cx = 70 + 0.37 * frame, cy = 75 + 0.21 * frame, radius = 14.3 + 0.4 * frame;
    const double streamLeft = 77.3 + 0.13 * frame, streamWidth = 2.6;
    cv::Mat3b picture(kH, kW);
    covered.create(kH, kW);
    for (int row = 0; row < kH; ++row)
        for (int col = 0; col < kW; ++col) {
            int inside = 0;
            for (int sy = 0; sy < kSub; ++sy)
                for (int sx = 0; sx < kSub; ++sx) {
                    const double x = col + (sx + 0.5) / kSub, y = row + (sy + 0.5) / kSub;
                    const bool disc = std::hypot(x - cx, y - cy) < radius;
                    const bool stream = y < cy && x >= streamLeft && x < streamLeft + streamWidth;
                    inside += disc || stream;
                }
            const double alpha = inside / double(kSub * kSub);
            covered(row, col) = alpha >= 0.5 ? 255 : 0;
            const bool shaded = shadow && shadow->contains({col, row});
            for (int c = 0; c < 3; ++c) {
                const double backdrop = srgbToLinear(kBackdrop[c] / 255) * (shaded ? shade : 1.0);
                const double light = alpha * srgbToLinear(liquid[c] / 255) + (1 - alpha) * backdrop;
                picture(row, col)[c] = cv::saturate_cast<uchar>(255 * linearToSrgb(light) + cv::theRNG().gaussian(1.5));
            }
        }
    return picture;
}

}  // namespace

// The reference must hold the pixels a simulated silhouette holds (centre inside, about half
// covered), or it is fatter by a fraction of a pixel all round and pulls η low.
TEST(Extraction, OutlineKeepsThePixelsTheLiquidHalfCovers) {
    const TempDirectory temp("viscoscope_extract_outline_test");
    const fs::path& dir = temp.path;
    cv::theRNG().state = 11;
    constexpr int kEmpty = 5, kCount = 20;
    const fs::path video = dir / "drop.mp4";
    cv::VideoWriter writer(video.string(), cv::VideoWriter::fourcc('m', 'p', '4', 'v'), kFps, {160, 120});
    ASSERT_TRUE(writer.isOpened());
    std::vector<cv::Mat1b> truth(kCount);
    cv::Mat1b unused;
    const cv::Mat3b backdrop = antialiasedFrame(-1000, unused);  // far off: no liquid in view
    for (int f = 0; f < kCount; ++f)
        writer.write(f < kEmpty ? backdrop : antialiasedFrame(f, truth[f]));
    writer.release();

    ExtractionOptions options;
    options.backgroundFrames = kEmpty;
    auto areaRatio = [&](double edgeCoverage, const std::string& name) {
        options.edgeCoverage = edgeCoverage;
        const ReferenceManifest manifest = extractSilhouettes(video, options, dir / name);
        double extracted = 0, covered = 0, iou = 0;
        for (int f = kEmpty; f < kCount; ++f) {
            extracted += cv::countNonZero(manifest.mask(f));
            covered += cv::countNonZero(truth[f]);
            iou += intersectionOverUnion(manifest.mask(f), truth[f]) / (kCount - kEmpty);
        }
        std::printf("[ figures  ] edge coverage %.2f: extracted area / half-covered area %.4f, mean IoU %.4f\n",
                    edgeCoverage, extracted / covered, iou);
        return extracted / covered;
    };
    const double trimmed = areaRatio(0.5, "trimmed"), untrimmed = areaRatio(0, "untrimmed");
    EXPECT_NEAR(trimmed, 1.0, 0.03);
    EXPECT_GT(untrimmed, 1.05);  // what the trimming is for: MOG2 alone takes in the grazed pixels
}

// A translucent liquid that only darkens the backdrop (here grey, 0.3 of it in linear light) passes
// MOG2's shadow test where it half covers a pixel: those edge pixels must still count as liquid,
// while a cast shadow (0.7 of the backdrop) beside it, and under it where the two meet, must not.
TEST(Extraction, ATranslucentLiquidsEdgeIsLiquidAndTheShadowBesideItIsNot) {
    const TempDirectory temp("viscoscope_extract_translucent_test");
    const fs::path& dir = temp.path;
    cv::theRNG().state = 13;
    constexpr int kEmpty = 5, kCount = 20;
    constexpr double kLiquidShare = 0.3, kShade = 0.7;
    cv::Vec3d grey;
    for (int c = 0; c < 3; ++c) grey[c] = 255 * linearToSrgb(kLiquidShare * srgbToLinear(kBackdrop[c] / 255));
    // The disc's right edge runs from 2 px short of the band (first frame with liquid) into it.
    const cv::Rect band(90, 68, 40, 16);
    const fs::path video = dir / "grey.mp4";
    cv::VideoWriter writer(video.string(), cv::VideoWriter::fourcc('m', 'p', '4', 'v'), kFps, {160, 120});
    ASSERT_TRUE(writer.isOpened());
    std::vector<cv::Mat1b> truth(kCount);
    cv::Mat1b unused;
    const cv::Mat3b backdrop = antialiasedFrame(-1000, unused);
    for (int f = 0; f < kCount; ++f)
        writer.write(f < kEmpty ? backdrop : antialiasedFrame(f, truth[f], grey, band, kShade));
    writer.release();

    ExtractionOptions options;
    options.backgroundFrames = kEmpty;
    const ReferenceManifest manifest = extractSilhouettes(video, options, dir / "out");
    double extracted = 0, covered = 0, shadowExtracted = 0, shadowArea = 0;
    for (int f = kEmpty; f < kCount; ++f) {
        const cv::Mat1b mask = manifest.mask(f);
        extracted += cv::countNonZero(mask);
        covered += cv::countNonZero(truth[f]);
        const cv::Mat1b shadowOnly = truth[f](band) == 0;  // not half covered by the liquid
        shadowExtracted += cv::countNonZero(mask(band) & shadowOnly);
        shadowArea += cv::countNonZero(shadowOnly);
    }
    std::printf("[ figures  ] translucent grey liquid: extracted area / half-covered area %.4f; %.4f of the shadow "
                "beside it extracted\n", extracted / covered, shadowExtracted / shadowArea);
    EXPECT_NEAR(extracted / covered, 1.0, 0.03);
    EXPECT_LT(shadowExtracted / shadowArea, 0.02);
}

TEST(Extraction, CancelLeavesNoManifest) {
    const TempDirectory temp("viscoscope_extract_cancel_test");
    const fs::path& dir = temp.path;
    for (int f = 0; f < 4; ++f)
        cv::imwrite((dir / ("frame_" + std::to_string(f) + ".png")).string(), cv::Mat3b(40, 60, cv::Vec3b(90, 90, 90)));
    ExtractionOptions options;
    options.backgroundFrames = 2;
    options.fps = 30;
    requestCancel();
    EXPECT_THROW(extractSilhouettes(dir, options, dir / "out"), Cancelled);
    withdrawCancel();
    EXPECT_FALSE(fs::exists(dir / "out" / "manifest.json"));
    EXPECT_FALSE(fs::exists(dir / "out" / "masks"));
    const ReferenceManifest manifest = extractSilhouettes(dir, options, dir / "out");
    EXPECT_EQ(manifest.frames.size(), 4u);
    options.fps.reset();
    EXPECT_THROW(extractSilhouettes(dir, options, dir / "out2"), InputError);  // image folders need --fps
}

// A frame of the footage as the clean plate draws the same masks as that frame saved as an image;
// the first liquid, which leading background frames would learn as background, is found.
TEST(Extraction, ACleanPlateFrameOfTheFootageIsThePlate) {
    const TempDirectory temp("viscoscope_extract_plate_frame_test");
    const fs::path& dir = temp.path;
    cv::theRNG().state = 7;
    const cv::Mat3f background = texturedBackground();
    const fs::path frames = dir / "frames";
    fs::create_directories(frames);
    for (int f = 0; f < 14; ++f) {
        const cv::Mat1b liquid = f < 2 ? cv::Mat1b(kHeight, kWidth, uchar(0)) : liquidMask(f);
        cv::imwrite((frames / ("frame_" + std::to_string(100 + f) + ".png")).string(), renderFrame(background, liquid, f));
    }
    ExtractionOptions byFrame;
    byFrame.fps = kFps;
    byFrame.cleanPlateFrame = 1;
    const ReferenceManifest fromFrame = extractSilhouettes(frames, byFrame, dir / "by_frame");
    EXPECT_EQ(fromFrame.parameters.at("background"), "clean_plate_frame");
    EXPECT_EQ(fromFrame.parameters.at("clean_plate_frame"), 1);
    ExtractionOptions byImage = byFrame;
    byImage.cleanPlateFrame.reset();
    byImage.cleanPlate = frames / "frame_101.png";
    const ReferenceManifest fromImage = extractSilhouettes(frames, byImage, dir / "by_image");
    ASSERT_EQ(fromFrame.frames.size(), fromImage.frames.size());
    for (size_t i = 0; i < fromFrame.frames.size(); ++i)
        EXPECT_EQ(cv::countNonZero(fromFrame.mask(i) != fromImage.mask(i)), 0) << "frame " << i;
    // Frames 2 … 11 hold the first liquid, which ten leading background frames take for background.
    EXPECT_GT(silhouetteArea(fromFrame.mask(2)), 0.8 * silhouetteArea(liquidMask(2)));

    ExtractionOptions both = byImage;
    both.cleanPlateFrame = 1;
    EXPECT_THROW(extractSilhouettes(frames, both, dir / "both"), InputError);
    ExtractionOptions past = byFrame;
    past.cleanPlateFrame = 14;
    try {
        extractSilhouettes(frames, past, dir / "past");
        FAIL() << "a clean plate frame past the end was accepted";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("the clean plate frame 14 is not among them"), std::string::npos)
            << e.what();
    }
}

TEST(FrameWeights, RangesListsAndErrors) {
    const std::vector<int> frames{0, 5, 10, 15, 20};
    EXPECT_EQ(parseFrameWeights("", frames), (std::vector<double>{1, 1, 1, 1, 1}));
    EXPECT_EQ(parseFrameWeights("0-10:1,11-20:0", frames), (std::vector<double>{1, 1, 1, 0, 0}));
    EXPECT_EQ(parseFrameWeights("5:0, 15-15:0", frames), (std::vector<double>{1, 0, 1, 0, 1}));
    EXPECT_EQ(parseFrameWeights("1,0,1,1,0", frames), (std::vector<double>{1, 0, 1, 1, 0}));
    EXPECT_THROW(parseFrameWeights("1,0", frames), InputError);
    EXPECT_THROW(parseFrameWeights("3-1:1", frames), InputError);
    EXPECT_THROW(parseFrameWeights("a-b:1", frames), InputError);
    EXPECT_THROW(parseFrameWeights("0-3:-1", frames), InputError);
    EXPECT_THROW(parseFrameWeights("0-3:1,,", frames), InputError);
}

TEST(ExtractionOptions, ParsedFromAJobsExtractionObject) {
    const fs::path dir = fs::temp_directory_path() / ("viscoscope_extraction_options_" + std::to_string(getpid()));
    fs::create_directories(dir);
    cv::imwrite((dir / "plate.png").string(), cv::Mat3b(4, 4, cv::Vec3b(90, 90, 90)));
    const nlohmann::json doc{{"first", 2},           {"last", 9},          {"step", 3},
                             {"fps", 24.0},          {"clean_plate", "plate.png"},
                             {"exclude_polygons", {{{0, 0}, {3, 0}, {0, 3}}}},
                             {"weights", "0-2:0"},   {"mog2_variance_threshold", 9.5},
                             {"mog2_minimum_variance", 20}, {"compensate_gain", false},
                             {"threshold", 200},     {"close_kernel_px", 7}, {"open_kernel_px", 0},
                             {"mog2_shadow_threshold", 0.6}};
    const ExtractionOptions o = parseExtractionOptions(doc, "job.json: extraction", dir);
    EXPECT_EQ(o.first, 2);
    EXPECT_EQ(o.last, 9);
    EXPECT_EQ(o.step, 3);
    EXPECT_EQ(o.fps, 24.0);
    EXPECT_EQ(o.cleanPlate, dir / "plate.png");  // relative to the job's folder
    EXPECT_FALSE(o.excludeMask);
    ASSERT_EQ(o.excludePolygons.size(), 1u);
    EXPECT_EQ(o.excludePolygons[0][1], cv::Point2d(3, 0));
    EXPECT_EQ(o.weights, "0-2:0");
    EXPECT_EQ(o.varianceThreshold, 9.5);
    EXPECT_EQ(o.minimumVariance, 20);
    EXPECT_FALSE(o.compensateGain);
    EXPECT_EQ(o.threshold, 200);
    EXPECT_EQ(o.shadowThreshold, 0.6);
    EXPECT_EQ(o.closeKernel, 7);
    EXPECT_EQ(o.openKernel, 0);
    EXPECT_EQ(parseExtractionOptions(nlohmann::json::object(), "x", dir).threshold, ExtractionOptions().threshold);

    const auto fails = [&](const nlohmann::json& bad, const std::string& message) {
        try {
            parseExtractionOptions(bad, "job.json: extraction", dir);
            ADD_FAILURE() << bad.dump() << " was accepted";
        } catch (const InputError& e) {
            EXPECT_NE(std::string(e.what()).find(message), std::string::npos) << e.what();
        }
    };
    fails({{"treshold", 100}}, "job.json: extraction.treshold: unknown field; did you mean `threshold`?");
    fails({{"clean_plate", "absent.png"}}, "extraction.clean_plate: " + (dir / "absent.png").string() + " not found");
    fails({{"step", 0}}, "job.json: extraction: --step must be ≥ 1");
    fails({{"mog2_shadow_threshold", 1.5}}, "job.json: extraction: --shadow-threshold must be in (0, 1]");
    fails({{"weights", "0-3:x"}}, "job.json: extraction:");
    fails({{"threshold", "high"}}, "extraction.threshold: must be an integer");
    fails({{"exclude_polygons", {{1, 2}}}}, "extraction.exclude_polygons");
    fails(nlohmann::json::array(), "must be an object");
    fs::remove_all(dir);
}

TEST(ScalarTracks, FrontAreaCsvAndNormalizedError) {
    cv::Mat1b mask(50, 100, uchar(0));
    cv::rectangle(mask, cv::Rect(10, 15, 50, 10), cv::Scalar(255), cv::FILLED);  // columns 10..59
    EXPECT_NEAR(frontAlongRay(mask, {{0, 20}, {1, 0}}), 59, 0.5);
    EXPECT_NEAR(frontAlongRay(mask, {{-30, 20}, {2, 0}}), 89, 0.5);  // origin outside the image
    EXPECT_NEAR(frontAlongRay(mask, {{99, 20}, {-1, 0}}), 89, 0.5);
    EXPECT_EQ(frontAlongRay(mask, {{0, 40}, {1, 0}}), 0);
    EXPECT_EQ(silhouetteArea(mask), 500);

    const fs::path measured = fs::path(VISCOSCOPE_SOURCE_DIR) / "../shared/data/measured/dambreak_syrup_validation.csv";
    if (fs::exists(measured)) {
        const ScalarTrack track = loadScalarTrackCsv(measured);
        EXPECT_EQ(track.columns, std::vector<std::string>{"front_m"});
        EXPECT_EQ(track.time.size(), 668u);
    }
    const TempDirectory temp("viscoscope_tracks_test");
    const fs::path& dir = temp.path;
    ScalarTrack track{{"front_m"}, {0, 1, 2, 3}, {{0.0, 0.1, 0.2, 0.3}}};
    saveScalarTrackCsv(track, dir / "track.csv");
    const ScalarTrack loaded = loadScalarTrackCsv(dir / "track.csv");
    EXPECT_EQ(loaded.values, track.values);
    EXPECT_NEAR(sampleTrack(loaded, 0, {1.5, -1, 9})[0], 0.15, 1e-12);
    EXPECT_EQ(sampleTrack(loaded, 0, {-1})[0], 0.0);
    const std::vector<double> reference{1, 2, 3}, simulated{1.1, 2.2, 3.3};
    EXPECT_NEAR(normalizedSquaredError(simulated, reference), 0.01, 1e-12);

    std::ofstream(dir / "bad.csv") << "time_s,front_m\n0,0.1\n1,abc\n";
    try {
        loadScalarTrackCsv(dir / "bad.csv");
        FAIL() << "a non-numeric value was accepted";
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("bad.csv:3"), std::string::npos) << e.what();
    }
    std::ofstream(dir / "backwards.csv") << "time_s,front_m\n1,0.1\n0,0.2\n";
    EXPECT_THROW(loadScalarTrackCsv(dir / "backwards.csv"), InputError);
}

// Simulation-side observables on particle sets whose answers are known by construction: a disc of
// liquid of radius R on the ground centred at (cx, cy), plus a column still above the ground.
TEST(ScalarTracks, GroundObservablesOfParticles) {
    std::mt19937 random(5);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    const double radius = 0.04, cx = 0.01, cy = -0.02;
    std::vector<Eigen::Vector3d> particles;
    for (int i = 0; i < 20000; ++i) {
        const double r = radius * std::sqrt(unit(random)), a = 2 * M_PI * unit(random);
        particles.emplace_back(cx + r * std::cos(a), cy + r * std::sin(a), 0.004 * unit(random));
    }
    for (int i = 0; i < 5000; ++i) particles.emplace_back(cx, cy, 0.05 + 0.05 * unit(random));
    const GroundObservables ground{0.0, 0.005};
    const double diameter = puddleDiameter(particles, Eigen::Vector3d(cx, cy, 0), ground);
    const double front = frontAlongGround(particles, Eigen::Vector3d(cx, cy, 0), Eigen::Vector3d(1, 0, 0), ground);
    std::printf("puddle diameter %.4f m (true %.4f), front %.4f m (true %.4f)\n", diameter, 2 * radius, front, radius);
    EXPECT_NEAR(diameter, 2 * radius, 0.01 * 2 * radius);
    EXPECT_NEAR(front, radius, 0.02 * radius);
    EXPECT_DOUBLE_EQ(drainedVolume(particles, 1e-9, 0.01), 20000 * 1e-9);
    EXPECT_THROW(frontAlongGround(particles, Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 0, 1), ground), InputError);
}

// A small dark drop loses its colour to a phone's 4:2:0 chroma and reads like a shadow: darker by
// a brightness ratio near 0.55, grey. A soft cast shadow darkens by 0.85. The default shadow
// threshold must keep the drop and drop the shadow; OpenCV's 0.5 loses the drop.
TEST(Extraction, ADarkDropIsLiquidAndASoftShadowIsNot) {
    const TempDirectory temp("viscoscope_extract_shadow_test");
    const fs::path& dir = temp.path;
    cv::theRNG().state = 17;
    constexpr int kEmpty = 5, kCount = 15, kW = 160, kH = 120;
    const cv::Rect drop(70, 40, 10, 3), shadow(20, 80, 40, 16);
    const cv::Vec3f backdrop(210, 210, 212), dropColour(100, 110, 125);  // BGR; the drop a grey brown
    const fs::path video = dir / "drop.mp4";
    cv::VideoWriter writer(video.string(), cv::VideoWriter::fourcc('m', 'p', '4', 'v'), kFps, {kW, kH});
    ASSERT_TRUE(writer.isOpened());
    for (int f = 0; f < kCount; ++f) {
        cv::Mat3f picture(kH, kW, backdrop);
        if (f >= kEmpty) {
            picture(drop).setTo(dropColour);
            picture(shadow) *= 0.85;
        }
        cv::Mat3f noise(kH, kW);
        cv::randn(noise, cv::Scalar::all(0), cv::Scalar::all(1.5));
        picture += noise;
        cv::Mat3b out;
        picture.convertTo(out, CV_8UC3);
        writer.write(out);
    }
    writer.release();

    ExtractionOptions options;
    options.backgroundFrames = kEmpty;
    auto shares = [&](double shadowThreshold, const std::string& name) {
        options.shadowThreshold = shadowThreshold;
        const ReferenceManifest manifest = extractSilhouettes(video, options, dir / name);
        double dropShare = 0, shadowShare = 0;
        for (int f = kEmpty; f < kCount; ++f) {
            dropShare += cv::countNonZero(manifest.mask(f)(drop)) / double(drop.area() * (kCount - kEmpty));
            shadowShare += cv::countNonZero(manifest.mask(f)(shadow)) / double(shadow.area() * (kCount - kEmpty));
        }
        std::printf("[ figures  ] shadow threshold %.2f: %.3f of the drop and %.3f of the shadow extracted\n",
                    shadowThreshold, dropShare, shadowShare);
        return std::array<double, 2>{dropShare, shadowShare};
    };
    const auto [dropKept, shadowKept] = shares(ExtractionOptions{}.shadowThreshold, "default");
    EXPECT_GT(dropKept, 0.8);
    EXPECT_LT(shadowKept, 0.02);
    const auto [dropAtHalf, shadowAtHalf] = shares(0.5, "opencv_default");
    EXPECT_LT(dropAtHalf, 0.5);  // the case the default is for
    EXPECT_LT(shadowAtHalf, 0.02);
}
