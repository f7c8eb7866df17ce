#include "observe/observe.h"

#include <opencv2/imgcodecs.hpp>

namespace viscoscope {

void writeImage(const cv::Mat& image, const std::filesystem::path& file) {
    std::vector<uchar> encoded;
    if (image.empty() || !cv::imencode(file.extension().string(), image, encoded))
        throw OutputError(file.string() + ": cannot encode the image");
    writeFileAtomically(file, [&](std::ostream& out) {
        out.write(reinterpret_cast<const char*>(encoded.data()), std::streamsize(encoded.size()));
    });
}

}  // namespace viscoscope
