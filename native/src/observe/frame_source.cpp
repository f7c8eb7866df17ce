#include "observe/frame_source.h"

#include "observe/observe.h"
#include "scene/scene.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <regex>
#include <set>

namespace viscoscope {

namespace {

// The number in a file name (its last run of digits), so that frame_2 sorts before frame_10.
long long frameNumberOf(const std::filesystem::path& file) {
    static const std::regex lastDigits("(\\d+)(?!.*\\d)");
    const std::string stem = file.stem().string();
    std::smatch match;
    return std::regex_search(stem, match, lastDigits) ? std::stoll(match[1].str()) : -1;
}

std::vector<std::filesystem::path> numberedImages(const std::filesystem::path& folder) {
    static const std::set<std::string> extensions{".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".exr"};
    std::vector<std::filesystem::path> images;
    for (const auto& entry : std::filesystem::directory_iterator(folder)) {
        std::string extension = entry.path().extension().string();
        std::transform(extension.begin(), extension.end(), extension.begin(), ::tolower);
        if (entry.is_regular_file() && extensions.count(extension)) images.push_back(entry.path());
    }
    std::sort(images.begin(), images.end(), [](const auto& a, const auto& b) {
        return std::make_pair(frameNumberOf(a), a.filename()) < std::make_pair(frameNumberOf(b), b.filename());
    });
    return images;
}

cv::Mat asBgr(const cv::Mat& image) {
    if (image.channels() == 3) return image;
    cv::Mat bgr;
    cv::cvtColor(image, bgr, image.channels() == 4 ? cv::COLOR_BGRA2BGR : cv::COLOR_GRAY2BGR);
    return bgr;
}

}  // namespace

FrameSource::FrameSource(const std::filesystem::path& source, std::optional<double> fpsOverride) : source_(source) {
    if (!std::filesystem::exists(source)) throw InputError(source.string() + ": no such file or folder");
    if (std::filesystem::is_directory(source)) {
        images_ = numberedImages(source);
        if (images_.empty()) throw InputError(source.string() + ": folder holds no images");
        frameCount_ = static_cast<int>(images_.size());
    } else {
        // A FIFO or a device would block FFmpeg's open until something writes to it, past any cancel.
        if (!std::filesystem::is_regular_file(source))
            throw InputError(source.string() + ": not a video file (a pipe, device or socket)");
        // FFmpeg logs its own complaints about corrupt files to stderr, which would break the CLI's
        // one-line error; quiet it unless the user asked for a log level.
        setenv("OPENCV_FFMPEG_LOGLEVEL", "-8", /*overwrite=*/0);
        if (!video_.open(source.string(), cv::CAP_FFMPEG))
            throw InputError(source.string() + ": cannot be read as a video (unknown format, corrupt file, or no video frames)");
        // Phones store portrait video as landscape plus a rotation tag; honour it.
        video_.set(cv::CAP_PROP_ORIENTATION_AUTO, 1);
        fps_ = video_.get(cv::CAP_PROP_FPS);
        const double count = video_.get(cv::CAP_PROP_FRAME_COUNT);
        frameCount_ = count > 0 ? static_cast<int>(count) : -1;
    }
    if (fpsOverride) fps_ = *fpsOverride;
    if (!(std::isfinite(fps_) && fps_ > 0))
        throw InputError(source.string() + ": frame rate unknown; give it with --fps");
    cv::Mat first;
    if (!read(first)) throw InputError(source.string() + ": contains no readable frames");
    frameSize_ = first.size();
    firstFrame_ = first;
    next_ = 0;
}

bool FrameSource::read(cv::Mat& frame) {
    if (firstFrame_) {
        frame = *firstFrame_;
        firstFrame_.reset();
        ++next_;
        return true;
    }
    if (images_.empty()) {
        if (!video_.read(frame) || frame.empty()) return false;
    } else {
        if (next_ >= static_cast<int>(images_.size())) return false;
        const std::filesystem::path& file = images_[next_];
        frame = readImage(file, cv::IMREAD_COLOR);
        if (frame.empty()) throw InputError(file.string() + ": cannot read image");
        if (!frameSize_.empty() && frame.size() != frameSize_)
            throw InputError(file.string() + ": image size differs from the first image's");
    }
    frame = asBgr(frame);
    ++next_;
    return true;
}

bool FrameSource::skip() {
    const bool available = firstFrame_ || (images_.empty() ? video_.grab() : next_ < static_cast<int>(images_.size()));
    if (!available) return false;
    firstFrame_.reset();
    ++next_;
    return true;
}

}  // namespace viscoscope
