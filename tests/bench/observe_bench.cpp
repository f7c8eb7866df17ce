// Figures, not tests: extraction speed at 1280×720, and scoring time per frame for the exact
// (volumeToMesh + triangle fill) and fast (band splatting) silhouettes.
#include "observe/observe.h"

#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/Composite.h>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>

using namespace viscoscope;
namespace fs = std::filesystem;

namespace {

using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

// A textured background with a dark spreading blob, MJPG-compressed like a phone export.
fs::path writeClip(const fs::path& dir, int frames, cv::Size size) {
    const fs::path video = dir / "bench.avi";
    cv::VideoWriter writer(video.string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 30, size);
    cv::Mat3b background(size);
    cv::randu(background, cv::Scalar::all(60), cv::Scalar::all(200));
    cv::GaussianBlur(background, background, cv::Size(0, 0), 3);
    for (int f = 0; f < frames; ++f) {
        cv::Mat3b frame = background.clone();
        if (f >= 10)
            cv::ellipse(frame, {size.width / 2, size.height * 2 / 3}, {10 + 8 * f, 4 + 3 * f}, 0, 0, 360,
                        cv::Scalar(20, 70, 140), cv::FILLED);
        writer.write(frame);
    }
    return video;
}

void benchExtraction(const fs::path& dir) {
    constexpr int kFrames = 60;
    const fs::path video = writeClip(dir, kFrames, {1280, 720});
    ExtractionOptions options;
    options.backgroundFrames = 10;
    const auto decodeStart = Clock::now();
    cv::VideoCapture capture(video.string(), cv::CAP_FFMPEG);
    cv::Mat frame;
    int decoded = 0;
    while (capture.read(frame)) ++decoded;
    const double decodeSeconds = secondsSince(decodeStart);
    const auto start = Clock::now();
    extractSilhouettes(video, options, dir / "reference");
    const double seconds = secondsSince(start);
    std::printf("extraction 1280x720 MJPG, %d frames (+10 background frames learned): %.1f frames/s end to end "
                "(decode alone: %.1f frames/s)\n",
                kFrames, kFrames / seconds, decoded / decodeSeconds);
}

// Two overlapping spheres in a 0.16 m domain at 1 mm voxels: the size of a 160³ simulation.
openvdb::FloatGrid::Ptr liquidLevelSet() {
    const float voxel = 0.001f;
    auto puddle = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(0.05f, {0, 0, 0.02f}, voxel);
    auto drop = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(0.025f, {0.03f, 0.01f, 0.08f}, voxel);
    openvdb::tools::csgUnion(*puddle, *drop);
    return puddle;
}

void benchScoring() {
    const openvdb::FloatGrid::Ptr levelSet = liquidLevelSet();
    PinholeCamera camera;
    camera.width = 1280;
    camera.height = 720;
    camera.K << 1400, 0, 639.5, 0, 1400, 359.5, 0, 0, 1;
    camera.R << 1, 0, 0, 0, 0, -1, 0, 1, 0;  // looking along world +Y, Z up
    camera.t = -camera.R * Eigen::Vector3d(0, -0.45, 0.05);
    const cv::Mat1b reference = silhouetteFromLevelSet(*levelSet, camera);

    constexpr int kRepeats = 5;
    cv::Mat1b exact, fast;
    auto start = Clock::now();
    for (int i = 0; i < kRepeats; ++i) exact = silhouetteFromLevelSet(*levelSet, camera);
    const double exactMs = 1e3 * secondsSince(start) / kRepeats;
    start = Clock::now();
    for (int i = 0; i < kRepeats; ++i) fast = silhouetteFromLevelSetFast(*levelSet, camera);
    const double fastMs = 1e3 * secondsSince(start) / kRepeats;
    start = Clock::now();
    for (int i = 0; i < kRepeats; ++i) frameObjective(exact, reference);
    const double objectiveMs = 1e3 * secondsSince(start) / kRepeats;
    std::printf("scoring 1280x720, level set of %zu active voxels (%zu triangles): exact %.1f ms/frame, fast %.1f "
                "ms/frame, exact/fast %.2fx, fast-vs-exact IoU %.4f; E_f itself %.2f ms\n",
                static_cast<size_t>(levelSet->activeVoxelCount()), meshFromLevelSet(*levelSet).triangles.size(),
                exactMs, fastMs, exactMs / fastMs, intersectionOverUnion(fast, exact), objectiveMs);
}

}  // namespace

int main() {
    const fs::path dir = fs::temp_directory_path() / "viscoscope_observe_bench";
    fs::remove_all(dir);
    fs::create_directories(dir);
    benchExtraction(dir);
    benchScoring();
    fs::remove_all(dir);
    return 0;
}
