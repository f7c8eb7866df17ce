// Projection, the Blender conversion, and the camera JSON files.
#include "camera/camera.h"

#include "scene/scene.h"

#include <Eigen/Dense>
#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <functional>

namespace viscoscope {

Eigen::Vector3d toCameraFrame(const PinholeCamera& camera, const Eigen::Vector3d& world) {
    return camera.R * world + camera.t;
}

Eigen::Vector2d projectCameraPoint(const PinholeCamera& camera, const Eigen::Vector3d& p) {
    const double x = p.x() / p.z(), y = p.y() / p.z();
    const auto& d = camera.distortion;  // k1 k2 p1 p2 k3, OpenCV's model
    const double r2 = x * x + y * y;
    const double radial = 1 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]));
    const double xd = x * radial + 2 * d[2] * x * y + d[3] * (r2 + 2 * x * x);
    const double yd = y * radial + d[2] * (r2 + 2 * y * y) + 2 * d[3] * x * y;
    const Eigen::Matrix3d& K = camera.K;
    return {K(0, 0) * xd + K(0, 1) * yd + K(0, 2), K(1, 1) * yd + K(1, 2)};
}

Eigen::Vector2d project(const PinholeCamera& camera, const Eigen::Vector3d& world) {
    return projectCameraPoint(camera, toCameraFrame(camera, world));
}

bool anyPointInFront(const PinholeCamera& camera, const std::vector<Eigen::Vector3d>& world) {
    for (const Eigen::Vector3d& p : world)
        if (toCameraFrame(camera, p).z() > 0) return true;
    return false;
}

namespace {

// Blender resolves AUTO on the aspect-corrected image size (BKE_camera_sensor_fit).
bool fitsHorizontally(const BlenderCameraParams& b, double winx, double winy) {
    if (b.sensorFit == SensorFit::Horizontal) return true;
    if (b.sensorFit == SensorFit::Vertical) return false;
    return b.pixelAspectX * winx >= b.pixelAspectY * winy;
}

void requirePositive(double value, const char* field) {
    if (!(std::isfinite(value) && value > 0))
        throw InputError(std::string("blender camera: ") + field + ": must be a finite number > 0, got " +
                         std::to_string(value));
}

Eigen::Matrix3d intrinsicsFromBlender(const BlenderCameraParams& b, int width, int height) {
    const double winx = width, winy = height;
    const double ycor = b.pixelAspectY / b.pixelAspectX;
    const bool horizontal = fitsHorizontally(b, winx, winy);
    // AUTO uses sensor_width for whichever axis it fits (BKE_camera_sensor_size).
    const double sensor = b.sensorFit == SensorFit::Vertical ? b.sensorHeightMm : b.sensorWidthMm;
    const double viewfac = horizontal ? winx : ycor * winy;
    // The view plane spans winx × ycor·winy units of sensor/viewfac each; shift moves it by
    // shift·viewfac units. Blender's y points up and its pixel centres sit at i + 0.5.
    const double fx = b.lensMm * viewfac / sensor;
    const double fy = fx / ycor;
    const double cx = 0.5 * winx - b.shiftX * viewfac - 0.5;
    const double cy = 0.5 * winy + b.shiftY * viewfac / ycor - 0.5;
    Eigen::Matrix3d K;
    K << fx, 0, cx, 0, fy, cy, 0, 0, 1;
    return K;
}

}  // namespace

PinholeCamera cameraFromBlender(const BlenderCameraParams& b) {
    requirePositive(b.lensMm, "lens_mm");
    requirePositive(b.sensorWidthMm, "sensor_width_mm");
    requirePositive(b.sensorHeightMm, "sensor_height_mm");
    requirePositive(b.resolutionPercentage, "resolution_percentage");
    requirePositive(b.pixelAspectX, "pixel_aspect_x");
    requirePositive(b.pixelAspectY, "pixel_aspect_y");
    if (!std::isfinite(b.shiftX) || !std::isfinite(b.shiftY) || !b.matrixWorld.allFinite())
        throw InputError("blender camera: shift and matrix_world must be finite numbers");
    // Blender truncates the scaled resolution to whole pixels (render size = res · pct / 100).
    const int width = static_cast<int>(b.resolutionX * b.resolutionPercentage / 100.0);
    const int height = static_cast<int>(b.resolutionY * b.resolutionPercentage / 100.0);
    if (width <= 0 || height <= 0)
        throw InputError("blender camera: resolution_x/resolution_y · resolution_percentage: image has no pixels");

    // Blender renders through the normalized object matrix, so scale does not change the view.
    Eigen::Matrix3d axes = b.matrixWorld.topLeftCorner<3, 3>();
    for (int c = 0; c < 3; ++c) {
        const double length = axes.col(c).norm();
        if (!(length > 1e-12)) throw InputError("blender camera: matrix_world: axis " + std::to_string(c) + " has zero scale");
        axes.col(c) /= length;
    }
    if ((axes.transpose() * axes - Eigen::Matrix3d::Identity()).norm() > 1e-6 || axes.determinant() < 0)
        throw InputError("blender camera: matrix_world: rotation part is sheared or mirrored");
    const Eigen::Vector3d centre = b.matrixWorld.block<3, 1>(0, 3);
    // OpenCV's camera axes are Blender's camera axes with y and z flipped.
    const Eigen::Matrix3d blenderToOpenCv = Eigen::Vector3d(1, -1, -1).asDiagonal();

    PinholeCamera camera;
    camera.width = width;
    camera.height = height;
    camera.K = intrinsicsFromBlender(b, width, height);
    camera.R = blenderToOpenCv * axes.transpose();
    camera.t = -camera.R * centre;
    validateCamera(camera, "blender camera");
    return camera;
}

BlenderCameraParams blenderFromCamera(const PinholeCamera& camera, const std::string& origin) {
    validateCamera(camera, origin);
    if (!camera.distortion.isZero())
        throw InputError(origin + ": distortion: Blender cameras have no lens distortion; undistort first");
    if (camera.K(0, 1) != 0) throw InputError(origin + ": K: Blender cannot render a skewed K (K[0][1] != 0)");
    const double width = camera.width, height = camera.height;
    const double fx = camera.K(0, 0), fy = camera.K(1, 1), cx = camera.K(0, 2), cy = camera.K(1, 2);
    BlenderCameraParams b;
    b.sensorFit = SensorFit::Horizontal;  // the sensor width spans the image width: viewfac = width
    b.sensorWidthMm = 36;
    b.sensorHeightMm = 36 * height / width;
    b.lensMm = fx * b.sensorWidthMm / width;
    b.resolutionX = camera.width;
    b.resolutionY = camera.height;
    b.resolutionPercentage = 100;
    const double ycor = fx / fy;  // Blender's pixel_aspect_y / pixel_aspect_x
    b.pixelAspectX = ycor >= 1 ? 1 : 1 / ycor;
    b.pixelAspectY = ycor >= 1 ? ycor : 1;
    // cameraFromBlender's principal point solved for the shifts.
    b.shiftX = (0.5 * width - 0.5 - cx) / width;
    b.shiftY = (cy + 0.5 - 0.5 * height) * ycor / width;
    const Eigen::Matrix3d openCvToBlender = Eigen::Vector3d(1, -1, -1).asDiagonal();
    b.matrixWorld.setIdentity();
    b.matrixWorld.topLeftCorner<3, 3>() = camera.R.transpose() * openCvToBlender;
    b.matrixWorld.block<3, 1>(0, 3) = -camera.R.transpose() * camera.t;
    return b;
}

// ---------------------------------------------------------------------------------------------
// JSON

namespace {

struct JsonReader {
    const nlohmann::json& doc;
    std::string origin;

    [[noreturn]] void fail(const std::string& field, const std::string& problem) const {
        throw InputError(origin + ": " + field + ": " + problem);
    }
    const nlohmann::json& at(const std::string& field) const {
        if (!doc.contains(field)) fail(field, "missing");
        return doc.at(field);
    }
    static double finite(const nlohmann::json& v, const std::function<void(const std::string&)>& onError) {
        if (!v.is_number()) onError("must be a number");
        const double x = v.get<double>();
        if (!std::isfinite(x)) onError("must be finite");
        return x;
    }
    double number(const std::string& field) const {
        return finite(at(field), [&](const std::string& p) { fail(field, p); });
    }
    int positiveInt(const std::string& field) const {
        const nlohmann::json& v = at(field);
        if (!v.is_number_integer() || v.get<long long>() <= 0 || v.get<long long>() > 1'000'000)
            fail(field, "must be a positive integer");
        return v.get<int>();
    }
    Eigen::MatrixXd matrix(const std::string& field, int rows, int cols) const {
        const nlohmann::json& v = at(field);
        const std::string shape = std::to_string(rows) + "x" + std::to_string(cols);
        if (!v.is_array() || static_cast<int>(v.size()) != rows) fail(field, "must be a " + shape + " array");
        Eigen::MatrixXd m(rows, cols);
        for (int r = 0; r < rows; ++r) {
            if (!v[r].is_array() || static_cast<int>(v[r].size()) != cols) fail(field, "must be a " + shape + " array");
            for (int c = 0; c < cols; ++c) m(r, c) = finite(v[r][c], [&](const std::string& p) { fail(field, p); });
        }
        return m;
    }
    Eigen::VectorXd vector(const std::string& field, int size) const {
        const nlohmann::json& v = at(field);
        if (!v.is_array() || static_cast<int>(v.size()) != size)
            fail(field, "must be an array of " + std::to_string(size) + " numbers");
        Eigen::VectorXd out(size);
        for (int i = 0; i < size; ++i) out[i] = finite(v[i], [&](const std::string& p) { fail(field, p); });
        return out;
    }
    void requireFormat(const std::string& format) const {
        if (!doc.is_object()) throw InputError(origin + ": not a JSON object");
        if (!at("format").is_string() || at("format").get<std::string>() != format)
            fail("format", "expected \"" + format + "\"");
        if (!at("version").is_number_integer() || at("version").get<int>() != 1) fail("version", "unsupported (expected 1)");
    }
};

nlohmann::json rowsOf(const Eigen::MatrixXd& m) {
    nlohmann::json rows = nlohmann::json::array();
    for (int r = 0; r < m.rows(); ++r) {
        nlohmann::json row = nlohmann::json::array();
        for (int c = 0; c < m.cols(); ++c) row.push_back(m(r, c));
        rows.push_back(row);
    }
    return rows;
}

SensorFit parseSensorFit(const JsonReader& in) {
    const nlohmann::json& v = in.at("sensor_fit");
    const std::string fit = v.is_string() ? v.get<std::string>() : "";
    if (fit == "AUTO") return SensorFit::Auto;
    if (fit == "HORIZONTAL") return SensorFit::Horizontal;
    if (fit == "VERTICAL") return SensorFit::Vertical;
    in.fail("sensor_fit", "must be \"AUTO\", \"HORIZONTAL\" or \"VERTICAL\"");
}

// Bounds past which a camera is a typo or a unit mistake, not a lens: a field of view outside
// 0.1°–179°, an optical axis farther outside the image than Blender's lens shift can put it (10
// image sizes), distortion no lens has, or a camera ten times farther away than a domain can be wide.
constexpr double kMinFieldOfViewDeg = 0.1, kMaxFieldOfViewDeg = 179;
constexpr double kMaxAxisOffImage = 10;
constexpr double kMaxDistortionCoefficient = 1e3;
constexpr double kMaxCameraDistanceOverDomain = 10;

template <class Fail>
void requireLensLike(const PinholeCamera& camera, const Fail& fail) {
    const auto focalFor = [](double pixels, double fovDeg) { return pixels / (2 * std::tan(fovDeg * M_PI / 360)); };
    const auto fmt = formatNumber;
    const int sizes[2] = {camera.width, camera.height};
    for (int axis = 0; axis < 2; ++axis) {
        const std::string entry = axis == 0 ? "K[0][0]" : "K[1][1]";
        const double focal = camera.K(axis, axis), lo = focalFor(sizes[axis], kMaxFieldOfViewDeg),
                     hi = focalFor(sizes[axis], kMinFieldOfViewDeg);
        if (focal < lo || focal > hi)
            fail("K", entry + " = " + fmt(focal) + " px is outside [" + fmt(lo) + ", " + fmt(hi) +
                          "] px, a field of view of " + fmt(kMinFieldOfViewDeg) + "° to " + fmt(kMaxFieldOfViewDeg) +
                          "° across " + std::to_string(sizes[axis]) + " px");
        const std::string centreEntry = axis == 0 ? "K[0][2]" : "K[1][2]";
        const double centre = camera.K(axis, 2);
        if (std::abs(centre - 0.5 * sizes[axis]) > (kMaxAxisOffImage + 0.5) * sizes[axis])
            fail("K", centreEntry + " = " + fmt(centre) + " px puts the optical axis more than " +
                          fmt(kMaxAxisOffImage) + " image sizes (" + std::to_string(sizes[axis]) + " px) outside it");
    }
    for (int i = 0; i < 5; ++i)
        if (std::abs(camera.distortion[i]) > kMaxDistortionCoefficient)
            fail("distortion", "coefficient " + std::to_string(i) + " = " + fmt(camera.distortion[i]) +
                                   " is beyond ±" + fmt(kMaxDistortionCoefficient) + ", which no lens has");
    const double distance = camera.t.norm();  // |centre| = |Rᵀt| for a rotation R
    if (distance > kMaxCameraDistanceOverDomain * kMaxDomainSide)
        fail("t", "the camera lies " + fmt(distance) + " m from the origin, beyond the " +
                      fmt(kMaxCameraDistanceOverDomain * kMaxDomainSide) + " m in which a scene can be seen; is it in another unit?");
    if (camera.reprojectionErrorPx && !(*camera.reprojectionErrorPx >= 0))
        fail("reprojection_error_px", "must be ≥ 0, got " + fmt(*camera.reprojectionErrorPx));
}

}  // namespace

void validateCamera(const PinholeCamera& camera, const std::string& origin) {
    const auto fail = [&](const std::string& field, const std::string& problem) {
        throw InputError(origin + ": " + field + ": " + problem);
    };
    if (camera.width <= 0 || camera.height <= 0) fail("width/height", "must be positive");
    if (!camera.K.allFinite() || !camera.R.allFinite() || !camera.t.allFinite() || !camera.distortion.allFinite())
        fail("K/R/t/distortion", "must be finite");
    if (!(camera.K(0, 0) > 0 && camera.K(1, 1) > 0)) fail("K", "focal lengths K[0][0], K[1][1] must be > 0");
    if (camera.K(1, 0) != 0 || camera.K(2, 0) != 0 || camera.K(2, 1) != 0 || camera.K(2, 2) != 1)
        fail("K", "rows 2 and 3 must be [0, fy, cy] and [0, 0, 1]");
    if ((camera.R.transpose() * camera.R - Eigen::Matrix3d::Identity()).norm() > 1e-5 || camera.R.determinant() <= 0)
        fail("R", "must be a rotation (orthonormal, determinant +1)");
    requireLensLike(camera, fail);
}

PinholeCamera parseCamera(const nlohmann::json& doc, const std::string& origin) {
    const JsonReader in{doc, origin};
    const bool isBlender = doc.is_object() && doc.contains("format") &&
                           doc["format"] == nlohmann::json("viscoscope.blender_camera");
    if (isBlender) {
        try {
            return cameraFromBlender(parseBlenderCamera(doc, origin));
        } catch (const InputError& e) {
            const std::string what = e.what();
            // cameraFromBlender does not know the file; name it.
            throw InputError(what.rfind(origin, 0) == 0 ? what : origin + ": " + what);
        }
    }
    in.requireFormat("viscoscope.camera");
    rejectUnknownKeys(doc, {"format", "version", "width", "height", "K", "distortion", "R", "t", "reprojection_error_px"},
                      origin + ": ");
    PinholeCamera camera;
    camera.width = in.positiveInt("width");
    camera.height = in.positiveInt("height");
    camera.K = in.matrix("K", 3, 3);
    camera.distortion = in.vector("distortion", 5);
    camera.R = in.matrix("R", 3, 3);
    camera.t = in.vector("t", 3);
    if (doc.contains("reprojection_error_px")) camera.reprojectionErrorPx = in.number("reprojection_error_px");
    validateCamera(camera, origin);
    return camera;
}

BlenderCameraParams parseBlenderCamera(const nlohmann::json& doc, const std::string& origin) {
    const JsonReader in{doc, origin};
    in.requireFormat("viscoscope.blender_camera");
    rejectUnknownKeys(doc,
                      {"format", "version", "lens_mm", "sensor_width_mm", "sensor_height_mm", "sensor_fit", "shift_x",
                       "shift_y", "resolution_x", "resolution_y", "resolution_percentage", "pixel_aspect_x",
                       "pixel_aspect_y", "matrix_world"},
                      origin + ": ");
    BlenderCameraParams b;
    b.lensMm = in.number("lens_mm");
    b.sensorWidthMm = in.number("sensor_width_mm");
    b.sensorHeightMm = in.number("sensor_height_mm");
    b.sensorFit = parseSensorFit(in);
    b.shiftX = in.number("shift_x");
    b.shiftY = in.number("shift_y");
    b.resolutionX = in.positiveInt("resolution_x");
    b.resolutionY = in.positiveInt("resolution_y");
    b.resolutionPercentage = in.number("resolution_percentage");
    b.pixelAspectX = in.number("pixel_aspect_x");
    b.pixelAspectY = in.number("pixel_aspect_y");
    b.matrixWorld = in.matrix("matrix_world", 4, 4);
    return b;
}

nlohmann::json blenderCameraToJson(const BlenderCameraParams& b) {
    const char* fit = b.sensorFit == SensorFit::Horizontal ? "HORIZONTAL"
                      : b.sensorFit == SensorFit::Vertical ? "VERTICAL"
                                                           : "AUTO";
    return {{"format", "viscoscope.blender_camera"}, {"version", 1},
            {"lens_mm", b.lensMm},                   {"sensor_width_mm", b.sensorWidthMm},
            {"sensor_height_mm", b.sensorHeightMm},  {"sensor_fit", fit},
            {"shift_x", b.shiftX},                   {"shift_y", b.shiftY},
            {"resolution_x", b.resolutionX},         {"resolution_y", b.resolutionY},
            {"resolution_percentage", b.resolutionPercentage},
            {"pixel_aspect_x", b.pixelAspectX},      {"pixel_aspect_y", b.pixelAspectY},
            {"matrix_world", rowsOf(b.matrixWorld)}};
}

PinholeCamera loadCamera(const std::filesystem::path& file) {
    std::ifstream stream(file);
    if (!stream) throw InputError(file.string() + ": cannot open camera file");
    return parseCamera(parseJsonStrictly(stream, file.string()), file.string());
}

nlohmann::json cameraToJson(const PinholeCamera& camera) {
    nlohmann::json doc{{"format", "viscoscope.camera"}, {"version", 1},  {"width", camera.width},
                       {"height", camera.height},        {"K", rowsOf(camera.K)}, {"R", rowsOf(camera.R)}};
    doc["distortion"] = std::vector<double>(camera.distortion.data(), camera.distortion.data() + 5);
    doc["t"] = std::vector<double>(camera.t.data(), camera.t.data() + 3);
    if (camera.reprojectionErrorPx) doc["reprojection_error_px"] = *camera.reprojectionErrorPx;
    return doc;
}

void saveCamera(const PinholeCamera& camera, const std::filesystem::path& file) {
    writeJsonAtomically(cameraToJson(camera), file);
}

}  // namespace viscoscope
