// The camera stage: a pinhole camera with OpenCV's 5-coefficient distortion, its JSON file, the
// conversion from a Blender camera, and calibration from checkerboards and clicked points.
//
// Conventions (OpenCV): x_cam = R X_world + t, +Z forward, +x right, +y down; pixel (i, j) has its
// centre at image coordinates (i, j), so a W-pixel-wide image spans [-0.5, W - 0.5].
// The world is Blender's: right-handed, Z up, metres.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json_fwd.hpp>
#include <opencv2/core.hpp>

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace viscoscope {

struct PinholeCamera {
    Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
    Eigen::Matrix<double, 5, 1> distortion = Eigen::Matrix<double, 5, 1>::Zero();  // k1 k2 p1 p2 k3
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
    Eigen::Vector3d t = Eigen::Vector3d::Zero();
    int width = 0, height = 0;
    std::optional<double> reprojectionErrorPx;  // RMS, when the camera came from a calibration
};

// World point → camera frame (metres, +Z forward).
Eigen::Vector3d toCameraFrame(const PinholeCamera& camera, const Eigen::Vector3d& world);
// Camera-frame point with z > 0 → pixel coordinates, distortion applied exactly as cv::projectPoints.
Eigen::Vector2d projectCameraPoint(const PinholeCamera& camera, const Eigen::Vector3d& cameraPoint);
// World point → pixel coordinates. Meaningless for points with camera depth ≤ 0: check depth first.
Eigen::Vector2d project(const PinholeCamera& camera, const Eigen::Vector3d& world);
// True when at least one point lies in front of the camera (depth > 0).
bool anyPointInFront(const PinholeCamera& camera, const std::vector<Eigen::Vector3d>& world);

// A Blender camera as the add-on exports it (bpy names; lengths in mm, matrix_world row-major).
enum class SensorFit { Auto, Horizontal, Vertical };
struct BlenderCameraParams {
    double lensMm = 50;
    double sensorWidthMm = 36, sensorHeightMm = 24;
    SensorFit sensorFit = SensorFit::Auto;
    double shiftX = 0, shiftY = 0;  // in units of the larger (fitted) image dimension
    int resolutionX = 1920, resolutionY = 1080;
    double resolutionPercentage = 100;
    double pixelAspectX = 1, pixelAspectY = 1;
    Eigen::Matrix4d matrixWorld = Eigen::Matrix4d::Identity();  // may contain scale
};

// The one place where Blender's camera becomes an OpenCV camera. Follows Blender's
// BKE_camera_params_compute_viewplane: the sensor size (sensor_width unless the fit is VERTICAL)
// spans `viewfac` pixels, where viewfac is the resolution along the fitted axis; shift moves the
// view plane by shift·viewfac. The camera looks down its local −Z with +Y up; scale in
// matrix_world is ignored, as Blender ignores it for rendering. Throws InputError on bad values.
PinholeCamera cameraFromBlender(const BlenderCameraParams& params);
// The inverse, for rendering a camera in Blender: HORIZONTAL fit on a 36 mm sensor, resolution
// percentage 100, fx ≠ fy as a pixel aspect (Blender keeps both aspects ≥ 1), the principal point as
// shift. cameraFromBlender(blenderFromCamera(c)) reproduces c's K, R, t and size. Throws InputError
// (naming `origin`) when Blender cannot represent the camera: lens distortion or a skewed K.
BlenderCameraParams blenderFromCamera(const PinholeCamera& camera, const std::string& origin);

// Camera JSON. `loadCamera` accepts "viscoscope.camera" and "viscoscope.blender_camera" files and
// validates every field; errors name the file and the field.
PinholeCamera parseCamera(const nlohmann::json& doc, const std::string& origin);
PinholeCamera loadCamera(const std::filesystem::path& file);
BlenderCameraParams parseBlenderCamera(const nlohmann::json& doc, const std::string& origin);
nlohmann::json blenderCameraToJson(const BlenderCameraParams& params);  // what parseBlenderCamera reads
nlohmann::json cameraToJson(const PinholeCamera& camera);
void saveCamera(const PinholeCamera& camera, const std::filesystem::path& file);
// Throws InputError("<origin>: <field>: ...") for non-finite values, non-positive sizes or focal
// lengths, a K whose last row is not (0 0 1), or an R that is not a rotation.
void validateCamera(const PinholeCamera& camera, const std::string& origin);

// Intrinsics from checkerboard photos (cv::findChessboardCorners + cv::calibrateCamera).
// `innerCorners` counts inner corners (e.g. 9×6); `squareSize` in metres. Extrinsics are left at
// identity. Needs at least 3 images where the board is found, all of one size; else InputError.
struct CheckerboardCalibration {
    PinholeCamera camera;
    double rmsPx = 0;
    std::vector<bool> boardFound;  // per input image
};
CheckerboardCalibration calibrateFromCheckerboards(const std::vector<cv::Mat>& images,
                                                   cv::Size innerCorners, double squareSize);

// Extrinsics from ≥ 4 known world points and their clicked pixel positions (cv::solvePnP, SQPnP
// then Levenberg–Marquardt refinement). Returns `intrinsics` with R, t and the reprojection RMS set.
PinholeCamera poseFromPoints(const PinholeCamera& intrinsics,
                             const std::vector<Eigen::Vector3d>& worldPoints,
                             const std::vector<Eigen::Vector2d>& imagePoints);

// RMS pixel distance between projected world points and observed pixels.
double reprojectionRmsPx(const PinholeCamera& camera, const std::vector<Eigen::Vector3d>& worldPoints,
                         const std::vector<Eigen::Vector2d>& imagePoints);

}  // namespace viscoscope
