// Calibration with OpenCV: intrinsics from checkerboards, extrinsics from clicked points.
#include "camera/camera.h"

#include "scene/scene.h"

#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>

namespace viscoscope {

namespace {

std::vector<cv::Point3f> checkerboardCorners(cv::Size innerCorners, double squareSize) {
    std::vector<cv::Point3f> corners;
    for (int row = 0; row < innerCorners.height; ++row)
        for (int col = 0; col < innerCorners.width; ++col)
            corners.emplace_back(static_cast<float>(col * squareSize), static_cast<float>(row * squareSize), 0.f);
    return corners;
}

std::optional<std::vector<cv::Point2f>> findBoard(const cv::Mat& image, cv::Size innerCorners) {
    cv::Mat gray;
    if (image.channels() == 1)
        gray = image;
    else
        cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
    std::vector<cv::Point2f> corners;
    const int flags = cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE;
    if (!cv::findChessboardCorners(gray, innerCorners, corners, flags)) return std::nullopt;
    const cv::TermCriteria criteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 30, 1e-3);
    cv::cornerSubPix(gray, corners, cv::Size(11, 11), cv::Size(-1, -1), criteria);
    return corners;
}

cv::Mat cvIntrinsics(const PinholeCamera& camera) {
    cv::Mat K;
    cv::eigen2cv(camera.K, K);
    return K;
}

cv::Mat cvDistortion(const PinholeCamera& camera) {
    cv::Mat d;
    cv::eigen2cv(camera.distortion, d);
    return d;
}

}  // namespace

CheckerboardCalibration calibrateFromCheckerboards(const std::vector<cv::Mat>& images, cv::Size innerCorners,
                                                   double squareSize) {
    if (innerCorners.width < 2 || innerCorners.height < 2)
        throw InputError("checkerboard: pattern must have at least 2x2 inner corners");
    if (!(std::isfinite(squareSize) && squareSize > 0)) throw InputError("checkerboard: square size must be > 0");
    CheckerboardCalibration result;
    std::vector<std::vector<cv::Point2f>> imageCorners;
    const cv::Size imageSize = images.empty() ? cv::Size() : images.front().size();
    for (const cv::Mat& image : images) {
        if (image.size() != imageSize) throw InputError("checkerboard: all images must have the same size");
        const auto corners = findBoard(image, innerCorners);
        result.boardFound.push_back(corners.has_value());
        if (corners) imageCorners.push_back(*corners);
    }
    if (imageCorners.size() < 3)
        throw InputError("checkerboard: board found in " + std::to_string(imageCorners.size()) +
                         " images, need at least 3");
    const std::vector<std::vector<cv::Point3f>> boardCorners(imageCorners.size(),
                                                             checkerboardCorners(innerCorners, squareSize));
    cv::Mat K, distortion;
    std::vector<cv::Mat> rvecs, tvecs;
    result.rmsPx = cv::calibrateCamera(boardCorners, imageCorners, imageSize, K, distortion, rvecs, tvecs);
    cv::cv2eigen(K, result.camera.K);
    for (int i = 0; i < 5; ++i) result.camera.distortion[i] = distortion.at<double>(i);
    result.camera.width = imageSize.width;
    result.camera.height = imageSize.height;
    result.camera.reprojectionErrorPx = result.rmsPx;
    return result;
}

PinholeCamera poseFromPoints(const PinholeCamera& intrinsics, const std::vector<Eigen::Vector3d>& worldPoints,
                             const std::vector<Eigen::Vector2d>& imagePoints) {
    if (worldPoints.size() != imagePoints.size())
        throw InputError("points: \"world\" and \"image\" must have the same number of points");
    if (worldPoints.size() < 4)
        throw InputError("points: need at least 4 point pairs, got " + std::to_string(worldPoints.size()));
    std::vector<cv::Point3d> world;
    std::vector<cv::Point2d> image;
    for (size_t i = 0; i < worldPoints.size(); ++i) {
        world.emplace_back(worldPoints[i].x(), worldPoints[i].y(), worldPoints[i].z());
        image.emplace_back(imagePoints[i].x(), imagePoints[i].y());
    }
    const cv::Mat K = cvIntrinsics(intrinsics), distortion = cvDistortion(intrinsics);
    cv::Mat rvec, tvec;
    // SQPnP finds the global minimum for any point layout (planar or not) from 3+ points; the
    // Levenberg–Marquardt pass then minimizes the reprojection error itself.
    if (!cv::solvePnP(world, image, K, distortion, rvec, tvec, false, cv::SOLVEPNP_SQPNP))
        throw InputError("points: solvePnP found no pose (are the points degenerate, e.g. collinear?)");
    cv::solvePnPRefineLM(world, image, K, distortion, rvec, tvec);
    cv::Mat rotation;
    cv::Rodrigues(rvec, rotation);
    PinholeCamera camera = intrinsics;
    cv::cv2eigen(rotation, camera.R);
    cv::cv2eigen(tvec, camera.t);
    camera.reprojectionErrorPx = reprojectionRmsPx(camera, worldPoints, imagePoints);
    return camera;
}

double reprojectionRmsPx(const PinholeCamera& camera, const std::vector<Eigen::Vector3d>& worldPoints,
                         const std::vector<Eigen::Vector2d>& imagePoints) {
    double sum = 0;
    for (size_t i = 0; i < worldPoints.size(); ++i)
        sum += (project(camera, worldPoints[i]) - imagePoints[i]).squaredNorm();
    return worldPoints.empty() ? 0 : std::sqrt(sum / static_cast<double>(worldPoints.size()));
}

}  // namespace viscoscope
