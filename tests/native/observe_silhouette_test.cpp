// Simulated silhouettes against analytic projections, fast against exact, and the objective.
#include "observe/observe.h"
#include "scene/scene.h"

#include <gtest/gtest.h>
#include <openvdb/tools/LevelSetSphere.h>
#include <openvdb/tools/ParticlesToLevelSet.h>

#include <cmath>
#include <cstdio>
#include <random>

using namespace viscoscope;

namespace {

// A camera at `centre` looking along world +Y, with world +Z up in the image.
PinholeCamera cameraLookingAlongY(int width, int height, double focalPx, const Eigen::Vector3d& centre) {
    PinholeCamera camera;
    camera.width = width;
    camera.height = height;
    camera.K << focalPx, 0, (width - 1) / 2.0, 0, focalPx, (height - 1) / 2.0, 0, 0, 1;
    camera.R << 1, 0, 0,  //
        0, 0, -1,         // image down = world −Z
        0, 1, 0;          // forward = world +Y
    camera.t = -camera.R * centre;
    return camera;
}

// Particles as OpenVDB's ParticlesToLevelSet wants them.
struct ParticleList {
    using PosType = openvdb::Vec3R;
    std::vector<Eigen::Vector3d> positions;
    double radius;
    size_t size() const { return positions.size(); }
    void getPos(size_t i, openvdb::Vec3R& p) const { p = {positions[i].x(), positions[i].y(), positions[i].z()}; }
    void getPosRad(size_t i, openvdb::Vec3R& p, openvdb::Real& r) const {
        getPos(i, p);
        r = radius;
    }
};

cv::Mat1b maskFromRects(cv::Size size, const std::vector<cv::Rect>& rects) {
    cv::Mat1b mask(size, uchar(0));
    for (const cv::Rect& r : rects) mask(r).setTo(255);
    return mask;
}

}  // namespace

// A sphere of radius r at distance d on the optical axis projects to a disc of radius
// f·r/√(d² − r²) (the cone of tangent rays has half-angle asin(r/d)).
TEST(Rasterization, MeshedSphereMatchesAnalyticDiscAtTwoResolutions) {
    const double radius = 0.05, distance = 0.4;
    const Eigen::Vector3d sphereCentre(0.1, 0.2, 0.3);
    auto sphere = openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
        float(radius), openvdb::Vec3f(0.1f, 0.2f, 0.3f), float(radius / 25));
    for (const auto& [width, height, focal] : {std::tuple{320, 240, 300.0}, std::tuple{1280, 960, 1200.0}}) {
        const PinholeCamera camera =
            cameraLookingAlongY(width, height, focal, sphereCentre - Eigen::Vector3d(0, distance, 0));
        const double discRadius = focal * radius / std::sqrt(distance * distance - radius * radius);
        const double analyticArea = M_PI * discRadius * discRadius;
        const double rasterArea = silhouetteArea(silhouetteFromLevelSet(*sphere, camera));
        const double relativeError = (rasterArea - analyticArea) / analyticArea;
        std::printf("[ figures  ] meshed sphere at %dx%d: %.0f px vs analytic %.1f px, error %+.3f %%\n", width, height,
                    rasterArea, analyticArea, 100 * relativeError);
        EXPECT_LT(std::abs(relativeError), 0.01);
    }
}

TEST(Rasterization, FillsPixelCentresExactly) {
    PinholeCamera camera = cameraLookingAlongY(20, 20, 10, {0, -1, 0});
    camera.R.setIdentity();  // camera frame = world frame; z = 1 maps (x, y) to 10x + 9.5, 10y + 9.5
    camera.t.setZero();
    // A square with corners at pixel coordinates (2, 2) and (6.99, 4): centres x 2..6, y 2..4.
    const auto at = [](double u, double v) { return Eigen::Vector3d((u - 9.5) / 10, (v - 9.5) / 10, 1); };
    const std::vector<Eigen::Vector3d> vertices{at(2, 2), at(6.99, 2), at(6.99, 4), at(2, 4)};
    const cv::Mat1b mask = rasterizeMesh(vertices, {{0, 1, 2}, {0, 2, 3}}, camera);
    EXPECT_EQ(silhouetteArea(mask), 15);
    EXPECT_EQ(mask(2, 2), 255);
    EXPECT_EQ(mask(4, 6), 255);
    EXPECT_EQ(mask(5, 6), 0);
    EXPECT_EQ(mask(2, 7), 0);
}

// An endless ground plane seen by a level camera 1 m up: its triangles reach behind the camera and
// must be clipped at the near plane; the horizon is the principal row.
TEST(Rasterization, ClipsTrianglesCrossingTheCameraPlane) {
    const PinholeCamera camera = cameraLookingAlongY(200, 100, 100, {0, 0, 1});
    const double far = 1e4;
    const std::vector<Eigen::Vector3d> ground{{-far, -far, 0}, {far, -far, 0}, {far, far, 0}, {-far, far, 0}};
    const cv::Mat1b mask = rasterizeMesh(ground, {{0, 1, 2}, {0, 2, 3}}, camera);
    const double horizonRow = camera.K(1, 2);
    for (int row = 0; row < mask.rows; ++row) {
        const int filled = cv::countNonZero(mask.row(row));
        if (row < horizonRow) EXPECT_EQ(filled, 0) << "row " << row;
        if (row > horizonRow + 1) EXPECT_EQ(filled, mask.cols) << "row " << row;
    }
    // Everything behind the camera: nothing drawn, and the scorer can tell.
    const std::vector<Eigen::Vector3d> behind{{0, -2, 0}, {1, -2, 0}, {0, -2, 1}};
    EXPECT_EQ(silhouetteArea(rasterizeMesh(behind, {{0, 1, 2}}, camera)), 0);
    EXPECT_FALSE(anyPointInFront(camera, behind));
}

TEST(FastSilhouette, ParticleBlobAgreesWithMeshedLevelSet) {
    std::mt19937 rng(2);
    std::uniform_real_distribution<double> jitter(-0.3, 0.3);
    const double spacing = 0.002, particleRadius = 0.0025;
    ParticleList blob{{}, particleRadius};
    for (double x = -0.04; x <= 0.04; x += spacing)
        for (double y = -0.03; y <= 0.03; y += spacing)
            for (double z = -0.035; z <= 0.035; z += spacing) {
                const Eigen::Vector3d p = Eigen::Vector3d(x, y, z) + spacing * Eigen::Vector3d(jitter(rng), jitter(rng), jitter(rng));
                const double ellipsoid = std::pow(p.x() / 0.04, 2) + std::pow(p.y() / 0.03, 2) + std::pow(p.z() / 0.035, 2);
                if (ellipsoid <= 1) blob.positions.push_back(p);
            }
    auto levelSet = openvdb::createLevelSet<openvdb::FloatGrid>(particleRadius / 2.5);
    openvdb::tools::ParticlesToLevelSet<openvdb::FloatGrid> raster(*levelSet);
    raster.rasterizeSpheres(blob);
    raster.finalize(true);

    const PinholeCamera camera = cameraLookingAlongY(640, 480, 900, {0.01, -0.35, 0.02});
    const cv::Mat1b exact = silhouetteFromLevelSet(*levelSet, camera);
    const cv::Mat1b fastParticles = silhouetteFromParticles(blob.positions, particleRadius, camera);
    const cv::Mat1b fastBand = silhouetteFromLevelSetFast(*levelSet, camera);
    const double particlesIou = intersectionOverUnion(fastParticles, exact);
    const double bandIou = intersectionOverUnion(fastBand, exact);
    std::printf("[ figures  ] fast vs exact silhouette of a %zu-particle blob (%.0f px): IoU %.4f splatting "
                "particles, %.4f splatting the level set's inner band\n",
                blob.size(), silhouetteArea(exact), particlesIou, bandIou);
    EXPECT_GT(particlesIou, 0.95);
    EXPECT_GT(bandIou, 0.95);
}

// Row widths ignore where in a row the liquid lies, and count what each row has too much or too little.
TEST(Objective, RowWidthsIgnoreSidewaysShifts) {
    const cv::Size size(8, 4);
    const auto rowWidths = SilhouetteComparison::kRowWidths;
    const cv::Mat1b stream = maskFromRects(size, {{2, 0, 2, 4}});
    const cv::Mat1b shifted = maskFromRects(size, {{5, 0, 2, 4}});  // the same stream 3 pixels to the right
    EXPECT_DOUBLE_EQ(frameObjective(shifted, stream), 16.0 / (2 * 32));  // eq. 9 counts both edges' pixels
    EXPECT_DOUBLE_EQ(frameObjective(shifted, stream, {}, rowWidths), 0);
    // One pixel wider in each of the bottom two rows, and one row split into two pieces of the same width.
    const cv::Mat1b wider = maskFromRects(size, {{5, 0, 2, 2}, {4, 2, 3, 2}});
    EXPECT_DOUBLE_EQ(frameObjective(wider, stream, {}, rowWidths), 2.0 / (2 * 32));
    const cv::Mat1b split = maskFromRects(size, {{2, 0, 2, 3}, {0, 3, 1, 1}, {7, 3, 1, 1}});
    EXPECT_DOUBLE_EQ(frameObjective(split, stream, {}, rowWidths), 0);
    // Excluded pixels count in neither width.
    cv::Mat1b compared(size, uchar(255));
    compared.col(2).setTo(0);  // the reference stream is 1 pixel wide there, the wider one 2 or 3
    EXPECT_DOUBLE_EQ(frameObjective(wider, stream, compared, rowWidths), 6.0 / (2 * 32));
    EXPECT_EQ(parseSilhouetteComparison("row_widths", "job"), rowWidths);
    EXPECT_THROW(parseSilhouetteComparison("rows", "job"), InputError);
}

TEST(Objective, LeavesOutTheRowsOfTheGroundBand) {
    // The outlet of a cup 10 cm above the ground, seen level from 0.5 m at 5 cm high, 100 px focal:
    // the ground at the outlet projects to y = 33.5, the band's top (2.5 cm) to 28.5: rows 29 and below go.
    Scene scene;
    scene.solids = {GroundSolid{0.0}, CupSolid{{0, 0, 0.1}}};
    const PinholeCamera camera = cameraLookingAlongY(64, 48, 100, {0, -0.5, 0.05});
    EXPECT_DOUBLE_EQ(outletHeight(scene), 0.1);
    cv::Mat1b compared(48, 64, uchar(255));
    compared.col(0).setTo(0);  // an exclusion already there stays
    const cv::Mat1b banded = excludeGroundBand(compared, camera, scene, 0.025);
    EXPECT_EQ(cv::countNonZero(banded.rowRange(0, 29)), 29 * 63);
    EXPECT_EQ(cv::countNonZero(banded.rowRange(29, 48)), 0);
    EXPECT_EQ(cv::countNonZero(excludeGroundBand({}, camera, scene, 0.025)), 29 * 64);  // empty: all pixels
    EXPECT_EQ(cv::countNonZero(excludeGroundBand(compared, camera, scene, 0.0)), 48 * 63);
    // No band without a ground, or without a cup with a hole to fall from.
    Scene noGround = scene;
    noGround.solids = {CupSolid{{0, 0, 0.1}}};
    EXPECT_EQ(outletHeight(noGround), 0);
    EXPECT_TRUE(excludeGroundBand({}, camera, noGround, 0.025).empty());
    Scene noHole = scene;
    std::get<CupSolid>(noHole.solids[1]).holeRadius = 0;
    EXPECT_EQ(cv::countNonZero(excludeGroundBand(compared, camera, noHole, 0.025)), 48 * 63);
}

TEST(Objective, FollowsEquationNine) {
    const cv::Size size(4, 4);
    const cv::Mat1b simulated = maskFromRects(size, {{0, 0, 2, 4}});  // left half
    const cv::Mat1b reference = maskFromRects(size, {{0, 0, 4, 2}});  // top half
    // They disagree on the top-right and bottom-left quarters: 8 of M = 16 pixels.
    EXPECT_DOUBLE_EQ(frameObjective(simulated, reference), 8.0 / (2 * 16));
    EXPECT_DOUBLE_EQ(intersectionOverUnion(simulated, reference), 4.0 / 12);
    // Excluding the right column removes 2 disagreeing pixels; M stays the full pixel count.
    cv::Mat1b compared(size, uchar(255));
    compared.col(3).setTo(0);
    EXPECT_DOUBLE_EQ(frameObjective(simulated, reference, compared), 6.0 / (2 * 16));
    EXPECT_DOUBLE_EQ(intersectionOverUnion(simulated, reference, compared), 4.0 / 10);
    EXPECT_DOUBLE_EQ(frameObjective(reference, reference), 0);
    EXPECT_DOUBLE_EQ(intersectionOverUnion(cv::Mat1b(size, uchar(0)), cv::Mat1b(size, uchar(0))), 1);
    EXPECT_THROW(frameObjective(simulated, cv::Mat1b(5, 4, uchar(0))), InputError);

    const cv::Mat3b picture = differenceImage(simulated, reference, compared);
    EXPECT_NE(picture(3, 0), picture(0, 2));       // false positive vs false negative colours
    EXPECT_EQ(picture(0, 0), picture(0, 1));       // agreement inside
    EXPECT_NE(picture(0, 3), picture(0, 2));       // excluded pixels are darkened
    EXPECT_DOUBLE_EQ(totalObjective({{"silhouette", 1, 0.25}, {"front", 0.5, 0.1}}), 0.3);
}
