// sRGB transfer function (IEC 61966-2-1) between 8-bit images and linear light.
#include "observe/observe.h"

#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>

namespace viscoscope {

cv::Mat srgbToLinear(const cv::Mat& image) {
    CV_Assert(image.depth() == CV_8U);
    static const cv::Mat1f table = [] {
        cv::Mat1f t(1, 256);
        for (int v = 0; v < 256; ++v) {
            const double c = v / 255.0;
            t(0, v) = float(c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4));
        }
        return t;
    }();
    cv::Mat linear;
    cv::LUT(image, table, linear);
    return linear;
}

cv::Mat linearToSrgb(const cv::Mat& image) {
    CV_Assert(image.depth() == CV_32F);
    cv::Mat encoded(image.size(), CV_8UC(image.channels()));
    const int values = image.cols * image.channels();
    for (int row = 0; row < image.rows; ++row) {
        const float* in = image.ptr<float>(row);
        uchar* out = encoded.ptr<uchar>(row);
        for (int i = 0; i < values; ++i) {
            const double c = std::clamp(double(in[i]), 0.0, 1.0);
            out[i] = cv::saturate_cast<uchar>(255 * (c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1 / 2.4) - 0.055));
        }
    }
    return encoded;
}

}  // namespace viscoscope
