// The Blender → OpenCV conversion against an independent view-plane projection and
// cv::projectPoints, points with known image positions, the camera JSON, and solvePnP.
#include "camera/camera.h"
#include "scene/scene.h"

#include <Eigen/Geometry>
#include <gtest/gtest.h>
#include <unistd.h>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/eigen.hpp>
#include <opencv2/imgproc.hpp>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>

using namespace viscoscope;

namespace {

// Blender's own way to find a pixel: normalize matrix_world, go to camera-local coordinates,
// intersect the view plane of BKE_camera_params_compute_viewplane, and read the pixel off it
// (Blender's y up, pixel centres at i + 0.5). Written independently of cameraFromBlender.
Eigen::Vector2d blenderPixel(const BlenderCameraParams& b, const Eigen::Vector3d& world) {
    const double winx = std::floor(b.resolutionX * b.resolutionPercentage / 100.0);
    const double winy = std::floor(b.resolutionY * b.resolutionPercentage / 100.0);
    Eigen::Matrix4d viewInverse = b.matrixWorld;
    for (int c = 0; c < 3; ++c) viewInverse.col(c).head<3>().normalize();
    const Eigen::Vector4d local = viewInverse.inverse() * world.homogeneous();
    const double ycor = b.pixelAspectY / b.pixelAspectX;
    const double sensor = b.sensorFit == SensorFit::Vertical ? b.sensorHeightMm : b.sensorWidthMm;
    bool horizontal = b.sensorFit == SensorFit::Horizontal;
    if (b.sensorFit == SensorFit::Auto) horizontal = b.pixelAspectX * winx >= b.pixelAspectY * winy;
    const double viewfac = horizontal ? winx : ycor * winy;
    const double clipStart = 0.1;
    const double pixsize = sensor * clipStart / b.lensMm / viewfac;
    const double xmin = (-0.5 * winx + b.shiftX * viewfac) * pixsize;
    const double xmax = (0.5 * winx + b.shiftX * viewfac) * pixsize;
    const double ymin = (-0.5 * ycor * winy + b.shiftY * viewfac) * pixsize;
    const double ymax = (0.5 * ycor * winy + b.shiftY * viewfac) * pixsize;
    // Perspective divide onto the plane z = −clip_start.
    const double xPlane = local.x() * clipStart / -local.z(), yPlane = local.y() * clipStart / -local.z();
    const double fromLeft = (xPlane - xmin) / (xmax - xmin) * winx;
    const double fromBottom = (yPlane - ymin) / (ymax - ymin) * winy;
    return {fromLeft - 0.5, (winy - fromBottom) - 0.5};
}

Eigen::Vector2d cvProjectPoint(const PinholeCamera& camera, const Eigen::Vector3d& world) {
    cv::Mat K, distortion, R, rvec, tvec;
    cv::eigen2cv(camera.K, K);
    cv::eigen2cv(camera.distortion, distortion);
    cv::eigen2cv(camera.R, R);
    cv::Rodrigues(R, rvec);
    cv::eigen2cv(camera.t, tvec);
    std::vector<cv::Point3d> in{{world.x(), world.y(), world.z()}};
    std::vector<cv::Point2d> out;
    cv::projectPoints(in, rvec, tvec, K, distortion, out);
    return {out[0].x, out[0].y};
}

Eigen::Matrix3d randomRotation(std::mt19937& rng) {
    std::normal_distribution<double> normal;
    return Eigen::Quaterniond(normal(rng), normal(rng), normal(rng), normal(rng)).normalized().toRotationMatrix();
}

BlenderCameraParams randomBlenderCamera(std::mt19937& rng, SensorFit fit) {
    std::uniform_real_distribution<double> unit(0, 1);
    const auto between = [&](double lo, double hi) { return lo + (hi - lo) * unit(rng); };
    BlenderCameraParams b;
    b.lensMm = between(12, 120);
    b.sensorWidthMm = between(10, 40);
    b.sensorHeightMm = between(8, 30);
    b.sensorFit = fit;
    b.shiftX = between(-0.4, 0.4);
    b.shiftY = between(-0.4, 0.4);
    b.resolutionX = static_cast<int>(between(200, 2500));
    b.resolutionY = static_cast<int>(between(200, 2500));
    b.resolutionPercentage = unit(rng) < 0.5 ? 100 : between(20, 150);
    b.pixelAspectX = between(0.7, 1.5);
    b.pixelAspectY = between(0.7, 1.5);
    Eigen::Matrix4d M = Eigen::Matrix4d::Identity();
    const Eigen::Vector3d scale(between(0.3, 3), between(0.3, 3), between(0.3, 3));
    M.topLeftCorner<3, 3>() = randomRotation(rng) * scale.asDiagonal();
    M.block<3, 1>(0, 3) = Eigen::Vector3d(between(-5, 5), between(-5, 5), between(0, 5));
    b.matrixWorld = M;
    return b;
}

// A world point in front of the camera: camera-local (x, y, −depth) taken through matrix_world.
Eigen::Vector3d pointInFront(const BlenderCameraParams& b, const Eigen::Vector3d& local) {
    Eigen::Matrix4d M = b.matrixWorld;
    for (int c = 0; c < 3; ++c) M.col(c).head<3>().normalize();
    return (M * local.homogeneous()).head<3>();
}

}  // namespace

TEST(BlenderCamera, AgreesWithViewPlaneAndProjectPointsForAllFitsShiftsAndAspects) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> lateral(-1.5, 1.5), depth(0.5, 20);
    double worstPx = 0;
    for (SensorFit fit : {SensorFit::Auto, SensorFit::Horizontal, SensorFit::Vertical}) {
        for (int cameraIndex = 0; cameraIndex < 40; ++cameraIndex) {
            const BlenderCameraParams b = randomBlenderCamera(rng, fit);
            const PinholeCamera camera = cameraFromBlender(b);
            for (int i = 0; i < 25; ++i) {
                const double z = depth(rng);
                const Eigen::Vector3d world = pointInFront(b, {lateral(rng) * z, lateral(rng) * z, -z});
                const Eigen::Vector2d expected = blenderPixel(b, world);
                const Eigen::Vector2d viaOpenCv = cvProjectPoint(camera, world);
                const Eigen::Vector2d ours = project(camera, world);
                PinholeCamera distorted = camera;  // our distortion model must be OpenCV's
                distorted.distortion << 0.05, -0.01, 0.001, -0.0005, 0.002;
                const double distortedPx = (project(distorted, world) - cvProjectPoint(distorted, world)).norm();
                worstPx = std::max({worstPx, (viaOpenCv - expected).norm(), (ours - viaOpenCv).norm()});
                ASSERT_NEAR((viaOpenCv - expected).norm(), 0, 1e-6) << "fit " << int(fit) << " camera " << cameraIndex;
                ASSERT_NEAR((ours - viaOpenCv).norm(), 0, 1e-6);
                ASSERT_NEAR(distortedPx, 0, 1e-6);
            }
        }
    }
    std::printf("[ figures  ] Blender conversion: worst disagreement %.3g px over 3000 points\n", worstPx);
}

TEST(BlenderCamera, KnownImagePositions) {
    BlenderCameraParams b;  // 1920x1080, 50 mm on a 36 mm sensor, camera at the origin
    b.sensorFit = SensorFit::Auto;
    const Eigen::Vector3d onAxis(0, 0, -3);  // Blender camera looks down local −Z
    const PinholeCamera centred = cameraFromBlender(b);
    EXPECT_NEAR((project(centred, onAxis) - Eigen::Vector2d(959.5, 539.5)).norm(), 0, 1e-9);
    // A point on the sensor's right edge lands on the image's right edge (pixel 1919's far side).
    const Eigen::Vector3d rightEdge(18.0 / 50.0 * 3, 0, -3);
    EXPECT_NEAR(project(centred, rightEdge).x(), 1919.5, 1e-9);
    // +Y (up in Blender's camera) is up in the image: a smaller row.
    EXPECT_LT(project(centred, Eigen::Vector3d(0, 0.1, -3)).y(), 539.5);

    b.shiftX = 0.1;
    b.shiftY = -0.05;  // shifts are in units of the larger image dimension, 1920 here
    const Eigen::Vector2d shifted = project(cameraFromBlender(b), onAxis);
    EXPECT_NEAR(shifted.x(), 959.5 - 0.1 * 1920, 1e-9);
    EXPECT_NEAR(shifted.y(), 539.5 - 0.05 * 1920, 1e-9);

    b.resolutionX = 1080;  // portrait: AUTO now fits the sensor width to the height
    b.resolutionY = 1920;
    b.resolutionPercentage = 50;
    const PinholeCamera portrait = cameraFromBlender(b);
    EXPECT_EQ(portrait.width, 540);
    EXPECT_NEAR(project(portrait, onAxis).x(), 269.5 - 0.1 * 960, 1e-9);
    // The sensor's top edge sits on the image's top edge, moved up by the negative shift.
    EXPECT_NEAR(project(portrait, Eigen::Vector3d(0, 18.0 / 50.0 * 3, -3)).y() + 0.5, -0.05 * 960, 1e-9);
}

TEST(BlenderCamera, ScaleInMatrixWorldDoesNotChangeTheView) {
    BlenderCameraParams b;
    b.matrixWorld.block<3, 1>(0, 3) = Eigen::Vector3d(1, -2, 0.5);
    const PinholeCamera plain = cameraFromBlender(b);
    b.matrixWorld.topLeftCorner<3, 3>() *= 2.5;
    const PinholeCamera scaled = cameraFromBlender(b);
    EXPECT_NEAR((plain.R - scaled.R).norm(), 0, 1e-12);
    EXPECT_NEAR((plain.t - scaled.t).norm(), 0, 1e-12);
}

TEST(BlenderCamera, InverseConversionRoundTripsAndRendersTheSamePixels) {
    // Cameras from random Blender settings (every fit, shift and pixel aspect, so fx ≠ fy both
    // ways) and a hand-made K, R, t; back to Blender and forward again must give the same camera,
    // and Blender's own view plane (blenderPixel) must put every point on the same pixel.
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> lateral(-1.2, 1.2), depth(0.3, 10);
    std::vector<PinholeCamera> cameras;
    for (SensorFit fit : {SensorFit::Auto, SensorFit::Horizontal, SensorFit::Vertical})
        for (int i = 0; i < 20; ++i) cameras.push_back(cameraFromBlender(randomBlenderCamera(rng, fit)));
    PinholeCamera handMade;
    handMade.width = 96;
    handMade.height = 64;
    handMade.K << 180, 0, 40.25, 0, 230, 20.5, 0, 0, 1;  // fx < fy: pixel_aspect_x > 1
    handMade.R << 1, 0, 0, 0, 0, -1, 0, 1, 0;
    handMade.t << -0.05, 0.03, 0.25;
    cameras.push_back(handMade);
    double worstPx = 0;
    for (size_t i = 0; i < cameras.size(); ++i) {
        const PinholeCamera& camera = cameras[i];
        const BlenderCameraParams b = blenderFromCamera(camera, "camera " + std::to_string(i));
        EXPECT_GE(std::min(b.pixelAspectX, b.pixelAspectY), 1.0);  // Blender's lower limit
        const PinholeCamera back = cameraFromBlender(parseBlenderCamera(blenderCameraToJson(b), "json"));
        EXPECT_EQ(back.width, camera.width);
        EXPECT_EQ(back.height, camera.height);
        EXPECT_NEAR((back.K - camera.K).norm(), 0, 1e-9 * camera.K.norm()) << i;
        EXPECT_NEAR((back.R - camera.R).norm(), 0, 1e-12) << i;
        EXPECT_NEAR((back.t - camera.t).norm(), 0, 1e-9) << i;
        const Eigen::Vector3d centre = -camera.R.transpose() * camera.t;
        for (int k = 0; k < 20; ++k) {
            const double z = depth(rng);
            const Eigen::Vector3d world = centre + camera.R.transpose() * Eigen::Vector3d(lateral(rng) * z, lateral(rng) * z, z);
            const double px = (blenderPixel(b, world) - project(camera, world)).norm();
            worstPx = std::max(worstPx, px);
            ASSERT_NEAR(px, 0, 1e-6) << "camera " << i;
        }
    }
    std::printf("[ figures  ] K,R,t -> Blender -> view plane: worst disagreement %.3g px over %zu cameras\n", worstPx,
                cameras.size());

    PinholeCamera distorted = handMade;
    distorted.distortion[0] = 0.01;
    EXPECT_THROW(blenderFromCamera(distorted, "d.json"), InputError);
    PinholeCamera skewed = handMade;
    skewed.K(0, 1) = 0.5;
    try {
        blenderFromCamera(skewed, "s.json");
        FAIL() << "a skewed K was accepted";
    } catch (const InputError& e) {
        EXPECT_EQ(std::string(e.what()).rfind("s.json: K:", 0), 0u) << e.what();
    }
}

TEST(CameraJson, RoundTripsAndLoadsBlenderCameras) {
    const auto dir = std::filesystem::temp_directory_path() / ("viscoscope_camera_test_" + std::to_string(getpid()));
    std::filesystem::create_directories(dir);
    std::mt19937 rng(3);
    PinholeCamera camera = cameraFromBlender(randomBlenderCamera(rng, SensorFit::Auto));
    camera.distortion << 0.1, -0.02, 0.001, -0.002, 0.003;
    camera.reprojectionErrorPx = 0.42;
    saveCamera(camera, dir / "camera.json");
    const PinholeCamera loaded = loadCamera(dir / "camera.json");
    EXPECT_NEAR((loaded.K - camera.K).norm(), 0, 1e-9);
    EXPECT_NEAR((loaded.R - camera.R).norm(), 0, 1e-12);
    EXPECT_NEAR((loaded.t - camera.t).norm(), 0, 1e-12);
    EXPECT_NEAR((loaded.distortion - camera.distortion).norm(), 0, 1e-15);
    EXPECT_EQ(loaded.reprojectionErrorPx, camera.reprojectionErrorPx);

    nlohmann::json blender = {{"format", "viscoscope.blender_camera"}, {"version", 1}, {"lens_mm", 35},
                              {"sensor_width_mm", 36}, {"sensor_height_mm", 24}, {"sensor_fit", "AUTO"},
                              {"shift_x", 0}, {"shift_y", 0}, {"resolution_x", 640}, {"resolution_y", 480},
                              {"resolution_percentage", 100}, {"pixel_aspect_x", 1}, {"pixel_aspect_y", 1},
                              {"matrix_world", {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}}}};
    std::ofstream(dir / "blender.json") << blender.dump();
    EXPECT_NEAR(loadCamera(dir / "blender.json").K(0, 0), 35.0 / 36.0 * 640, 1e-9);

    blender["sensor_fit"] = "DIAGONAL";
    EXPECT_THROW(parseCamera(blender, "b.json"), InputError);
    blender["sensor_fit"] = "AUTO";
    blender["lens_mm"] = -1;
    EXPECT_THROW(parseCamera(blender, "b.json"), InputError);

    nlohmann::json plain = cameraToJson(camera);
    plain["R"][0][0] = 2.0;
    EXPECT_THROW(parseCamera(plain, "c.json"), InputError);
    plain = cameraToJson(camera);
    plain["width"] = 0;
    EXPECT_THROW(parseCamera(plain, "c.json"), InputError);
    plain = cameraToJson(camera);
    plain["t"] = {0, 1};
    try {
        parseCamera(plain, "c.json");
        FAIL() << "a 2-element t was accepted";
    } catch (const InputError& e) {
        EXPECT_EQ(std::string(e.what()).rfind("c.json: t:", 0), 0u) << e.what();
    }
    std::ofstream(dir / "garbage.json") << "{not json";
    EXPECT_THROW(loadCamera(dir / "garbage.json"), InputError);
    EXPECT_THROW(loadCamera(dir / "missing.json"), InputError);
    std::filesystem::remove_all(dir);
}

// Values no lens has, each a finite number the type checks let through: refused naming the entry.
TEST(CameraJson, ValuesNoLensHasAreRefusedNamingTheEntry) {
    std::mt19937 rng(3);
    const nlohmann::json valid = cameraToJson(cameraFromBlender(randomBlenderCamera(rng, SensorFit::Auto)));
    const std::vector<std::pair<std::string, double>> cases{
        {"/K/0/0", 1e-320}, {"/K/1/1", 1e308}, {"/K/0/2", -1e6}, {"/K/1/2", 1e9},
        {"/distortion/4", 1e308}, {"/t/2", 2e9}, {"/reprojection_error_px", -1},
    };
    for (const auto& [pointer, value] : cases) {
        nlohmann::json doc = valid;
        doc[nlohmann::json::json_pointer(pointer)] = value;
        const std::string field = pointer.substr(1, pointer.find('/', 1) - 1);
        try {
            parseCamera(doc, "c.json");
            ADD_FAILURE() << pointer << " = " << value << " was accepted";
        } catch (const InputError& e) {
            EXPECT_EQ(std::string(e.what()).rfind("c.json: " + field + ": ", 0), 0u) << e.what();
            std::printf("[ refused  ] %s\n", e.what());
        }
    }
}

TEST(SolvePnP, RecoversPoseFromNoisyClicks) {
    std::mt19937 rng(11);
    PinholeCamera truth;
    truth.width = 1280;
    truth.height = 720;
    truth.K << 1100, 0, 640, 0, 1100, 360, 0, 0, 1;
    // Camera 0.6 m away, looking at the origin from above and to the side.
    const Eigen::Vector3d centre(0.45, -0.35, 0.25);
    const Eigen::Vector3d forward = -centre.normalized();
    const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
    const Eigen::Vector3d down = forward.cross(right);
    truth.R.row(0) = right;
    truth.R.row(1) = down;
    truth.R.row(2) = forward;
    truth.t = -truth.R * centre;

    std::uniform_real_distribution<double> inBox(-0.08, 0.08);
    std::normal_distribution<double> clickNoise(0, 0.7);  // px
    std::vector<Eigen::Vector3d> world;
    std::vector<Eigen::Vector2d> clicks;
    for (int i = 0; i < 8; ++i) {
        world.emplace_back(inBox(rng), inBox(rng), std::abs(inBox(rng)));
        clicks.push_back(project(truth, world.back()) + Eigen::Vector2d(clickNoise(rng), clickNoise(rng)));
    }
    const PinholeCamera recovered = poseFromPoints(truth, world, clicks);
    const double rotationErrorDeg =
        Eigen::AngleAxisd(recovered.R * truth.R.transpose()).angle() * 180 / M_PI;
    const Eigen::Vector3d recoveredCentre = -recovered.R.transpose() * recovered.t;
    const double centreErrorMm = (recoveredCentre - centre).norm() * 1e3;
    std::printf("[ figures  ] solvePnP, 8 clicks with 0.7 px noise: reprojection RMS %.3f px, rotation error "
                "%.3f deg, camera-centre error %.2f mm of %.0f mm\n",
                *recovered.reprojectionErrorPx, rotationErrorDeg, centreErrorMm, centre.norm() * 1e3);
    EXPECT_LT(*recovered.reprojectionErrorPx, 1.5);
    EXPECT_LT(rotationErrorDeg, 1.0);
    EXPECT_LT(centreErrorMm, 0.03 * centre.norm() * 1e3);

    world.resize(3);
    clicks.resize(3);
    EXPECT_THROW(poseFromPoints(truth, world, clicks), InputError);
}

namespace {

// A photo of a checkerboard (squares × squares, `squareSize` m, one white square of margin) seen
// by camera K from pose (R, t) of the board plane: the printed texture warped by its homography.
cv::Mat photographBoard(const Eigen::Matrix3d& K, const Eigen::Matrix3d& R, const Eigen::Vector3d& t, cv::Size squares,
                        double squareSize, cv::Size imageSize) {
    constexpr int kTexelsPerSquare = 40;
    cv::Mat1b texture((squares.height + 2) * kTexelsPerSquare, (squares.width + 2) * kTexelsPerSquare, uchar(235));
    for (int row = 0; row < squares.height; ++row)
        for (int col = 0; col < squares.width; ++col)
            if ((row + col) % 2 == 0)
                texture(cv::Rect((col + 1) * kTexelsPerSquare, (row + 1) * kTexelsPerSquare, kTexelsPerSquare,
                                 kTexelsPerSquare)) = 20;
    // Board point (X, Y) in metres sits at texel s·(X, Y) + margin − 0.5 (texel centres are integers).
    const double s = kTexelsPerSquare / squareSize, offset = kTexelsPerSquare - 0.5;
    Eigen::Matrix3d boardFromTexture;
    boardFromTexture << 1 / s, 0, -offset / s, 0, 1 / s, -offset / s, 0, 0, 1;
    Eigen::Matrix3d imageFromBoard;
    imageFromBoard << R.col(0), R.col(1), t;
    cv::Mat H;
    cv::eigen2cv(Eigen::Matrix3d(K * imageFromBoard * boardFromTexture), H);
    cv::Mat photo;
    cv::warpPerspective(texture, photo, H, imageSize, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(128));
    cv::Mat noise(photo.size(), CV_16S);
    cv::randn(noise, 0, 2);  // sensor noise, σ = 2 grey levels
    cv::add(photo, noise, photo, cv::noArray(), CV_8U);
    return photo;
}

}  // namespace

TEST(Checkerboard, CalibrationRecoversIntrinsics) {
    Eigen::Matrix3d K;
    K << 800, 0, 319.5, 0, 800, 239.5, 0, 0, 1;
    const cv::Size squares(8, 6), imageSize(640, 480);
    const double squareSize = 0.03;
    const Eigen::Vector3d boardCentre(4 * squareSize, 3 * squareSize, 0);
    std::vector<cv::Mat> photos;
    for (const auto& [tiltX, tiltY] : {std::pair{0.0, 0.0}, {0.45, 0.0}, {-0.4, 0.2}, {0.1, 0.5}, {0.25, -0.45}}) {
        const Eigen::Matrix3d R = (Eigen::AngleAxisd(tiltX, Eigen::Vector3d::UnitX()) *
                                   Eigen::AngleAxisd(tiltY, Eigen::Vector3d::UnitY())).toRotationMatrix();
        const Eigen::Vector3d t = Eigen::Vector3d(0, 0, 0.55) - R * boardCentre;  // board centre 0.55 m ahead
        photos.push_back(photographBoard(K, R, t, squares, squareSize, imageSize));
    }
    const CheckerboardCalibration result = calibrateFromCheckerboards(photos, {7, 5}, squareSize);
    const Eigen::Matrix3d& found = result.camera.K;
    std::printf("[ figures  ] checkerboard calibration from 5 synthetic photos: RMS %.3f px, fx %.2f fy %.2f "
                "(true 800), cx %.2f cy %.2f (true 319.5, 239.5)\n",
                result.rmsPx, found(0, 0), found(1, 1), found(0, 2), found(1, 2));
    EXPECT_EQ(std::count(result.boardFound.begin(), result.boardFound.end(), true), 5);
    EXPECT_LT(result.rmsPx, 0.5);
    EXPECT_NEAR(found(0, 0), 800, 16);
    EXPECT_NEAR(found(1, 1), 800, 16);
    EXPECT_NEAR(found(0, 2), 319.5, 8);
    EXPECT_NEAR(found(1, 2), 239.5, 8);
    EXPECT_EQ(result.camera.width, 640);

    photos.resize(2);
    EXPECT_THROW(calibrateFromCheckerboards(photos, {7, 5}, squareSize), InputError);
}
