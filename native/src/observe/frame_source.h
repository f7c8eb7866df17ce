// Internal to the observe stage: frames from a video file or from a folder of numbered images.
#pragma once

#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>

#include <filesystem>
#include <optional>
#include <vector>

namespace viscoscope {

class FrameSource {
public:
    // Throws InputError when the source cannot be opened, has no readable frame, or (for an
    // image folder) no fps is given.
    FrameSource(const std::filesystem::path& source, std::optional<double> fpsOverride);

    // Reads the next frame (BGR, rotated upright); false at the end of the source.
    bool read(cv::Mat& frame);
    // Skips the next frame without decoding it where the source allows; false at the end.
    bool skip();
    int nextIndex() const { return next_; }
    double fps() const { return fps_; }
    // The source's frame count, or −1 when the container does not say.
    int frameCount() const { return frameCount_; }
    cv::Size frameSize() const { return frameSize_; }

private:
    std::filesystem::path source_;
    cv::VideoCapture video_;
    std::vector<std::filesystem::path> images_;  // empty for a video
    int next_ = 0;
    double fps_ = 0;
    int frameCount_ = -1;
    cv::Size frameSize_;
    std::optional<cv::Mat> firstFrame_;  // read while opening, handed out by the first read()
};

}  // namespace viscoscope
