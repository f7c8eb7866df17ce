#include "observe/observe.h"

#include <opencv2/imgcodecs.hpp>

#include <fstream>
#include <iostream>
#include <iterator>
#include <mutex>
#include <sstream>

namespace viscoscope {

cv::Mat readImage(const std::filesystem::path& file, int flags) {
    std::ifstream in(file, std::ios::binary);
    const std::vector<uchar> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (bytes.empty()) return {};
    // OpenCV's decoders print a damaged file's error on std::cerr (imgcodecs' loadsave.cpp) besides
    // returning no image, and the caller says what is wrong in its one line: the print is held back,
    // under a lock since std::cerr is the process's.
    static std::mutex decoding;
    const std::lock_guard<std::mutex> lock(decoding);
    std::ostringstream heldBack;
    std::streambuf* const cerr = std::cerr.rdbuf(heldBack.rdbuf());
    cv::Mat image;
    try {
        image = cv::imdecode(bytes, flags);
    } catch (const cv::Exception&) {  // a decoder that throws instead: no image all the same
    }
    std::cerr.rdbuf(cerr);
    return image;
}

void writeImage(const cv::Mat& image, const std::filesystem::path& file) {
    std::vector<uchar> encoded;
    if (image.empty() || !cv::imencode(file.extension().string(), image, encoded))
        throw OutputError(file.string() + ": cannot encode the image");
    writeFileAtomically(file, [&](std::ostream& out) {
        out.write(reinterpret_cast<const char*>(encoded.data()), std::streamsize(encoded.size()));
    });
}

}  // namespace viscoscope
