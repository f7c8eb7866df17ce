// Simulated silhouettes against analytic projections, fast against exact, and the objective.
#include "observe/observe.h"
#include "scene/scene.h"

#include <Eigen/Geometry>
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

namespace {

// A camera at `centre` looking at `target`, world +Z up in the image.
PinholeCamera cameraLookingAt(int width, int height, double focalPx, const Eigen::Vector3d& centre,
                              const Eigen::Vector3d& target) {
    PinholeCamera camera = cameraLookingAlongY(width, height, focalPx, centre);
    const Eigen::Vector3d forward = (target - centre).normalized();
    const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
    camera.R.row(0) = right;
    camera.R.row(1) = forward.cross(right);  // image down
    camera.R.row(2) = forward;
    camera.t = -camera.R * centre;
    return camera;
}

// The sample cup's proportions on the ground, in a 20 cm domain.
Scene cupOnTheGround() {
    Scene scene;
    scene.domain.min = {-0.1, -0.1, 0.0};
    scene.domain.max = {0.1, 0.1, 0.2};
    scene.domain.resolution = 32;
    CupSolid cup;
    cup.position = {0, 0, 0.05};
    cup.innerRadius = 0.04;
    cup.height = 0.06;  // rim at z = 0.114
    scene.solids = {GroundSolid{0.0}, cup};
    return scene;
}

openvdb::FloatGrid::Ptr liquidBall(const Eigen::Vector3d& centre, double radius) {
    return openvdb::tools::createLevelSetSphere<openvdb::FloatGrid>(
        float(radius), openvdb::Vec3f(float(centre.x()), float(centre.y()), float(centre.z())), float(radius / 20));
}

}  // namespace

// Liquid inside an opaque cup is hidden by its wall, liquid in front of it is not, and a glass cup
// hides nothing; from above, the liquid inside shows through the cup's mouth.
TEST(Visibility, OpaqueSolidsHideTheLiquidBehindAndInsideThem) {
    Scene scene = cupOnTheGround();
    const PinholeCamera level = cameraLookingAlongY(160, 120, 300, {0, -0.5, 0.08});
    const SceneVisibility view = sceneVisibility(scene, level);
    const auto inside = liquidBall({0, 0, 0.08}, 0.02), inFront = liquidBall({0, -0.07, 0.08}, 0.02);

    const double insideUnseen = silhouetteArea(silhouetteFromLevelSet(*inside, level));
    const double inFrontUnseen = silhouetteArea(silhouetteFromLevelSet(*inFront, level));
    ASSERT_GT(insideUnseen, 400);  // a disc of 12 px radius
    EXPECT_EQ(silhouetteArea(silhouetteFromLevelSet(*inside, level, &view)), 0);
    EXPECT_EQ(silhouetteArea(silhouetteFromLevelSet(*inFront, level, &view)), inFrontUnseen);
    EXPECT_EQ(silhouetteArea(silhouetteFromLevelSetFast(*inside, level, &view)), 0);
    EXPECT_GT(silhouetteArea(silhouetteFromLevelSetFast(*inFront, level, &view)), 0.9 * inFrontUnseen);

    scene.transparentSolids = {1};
    const SceneVisibility glass = sceneVisibility(scene, level);
    EXPECT_EQ(silhouetteArea(silhouetteFromLevelSet(*inside, level, &glass)), insideUnseen);

    // From 20° above, the top of a ball raised to 4 mm below the rim shows through the mouth: a line
    // of sight grazing the near rim is at z = 0.0996 on the axis, and the near wall hides the rest.
    scene.transparentSolids.clear();
    const auto raised = liquidBall({0, 0, 0.09}, 0.02);
    const PinholeCamera above = cameraLookingAt(160, 120, 300, {0, -0.3, 0.2}, {0, 0, 0.09});
    const SceneVisibility fromAbove = sceneVisibility(scene, above);
    const double all = silhouetteArea(silhouetteFromLevelSet(*raised, above));
    const double seen = silhouetteArea(silhouetteFromLevelSet(*raised, above, &fromAbove));
    std::printf("[ figures  ] ball in the cup from above: %.0f of %.0f px seen through the mouth\n", seen, all);
    EXPECT_GT(seen, 0.1 * all);
    EXPECT_LT(seen, 0.5 * all);
}

// Where no ray meets the space the liquid can reach (the domain outside every solid) before an
// opaque solid, no θ can show liquid: those pixels leave the comparison, counted.
TEST(Visibility, LeavesOutThePixelsWhereNoLiquidCanShow) {
    const Scene scene = cupOnTheGround();
    // Level, 0.5 m away: the 20 cm domain's near face, 0.4 m away, spans columns 79.5 ± 75.
    const PinholeCamera level = cameraLookingAlongY(160, 120, 300, {0, -0.5, 0.08});
    const SceneVisibility view = sceneVisibility(scene, level);
    EXPECT_EQ(cv::countNonZero(view.liquidCanShow.colRange(0, 4)), 0);
    EXPECT_EQ(cv::countNonZero(view.liquidCanShow.colRange(156, 160)), 0);
    EXPECT_EQ(cv::countNonZero(view.liquidCanShow.colRange(6, 154)), 148 * 120);
    // In front of the cup's wall there is room for liquid: those pixels stay.
    EXPECT_EQ(view.liquidCanShow(50, 80), 255);
    EXPECT_GT(view.occluderDepth(50, 80), 0.45);
    EXPECT_LT(view.occluderDepth(50, 80), 0.46);  // the wall's outer face, 0.043 m before the axis

    cv::Mat1b initial(level.height, level.width, uchar(0));
    initial(cv::Rect(70, 40, 20, 10)).setTo(255);
    const ComparedRegion region = comparedRegion({}, view, initial);
    EXPECT_EQ(region.neverVisible, level.height * level.width - cv::countNonZero(view.liquidCanShow));
    EXPECT_GT(region.inBackground, 20 * 10);  // the rectangle, widened by 2 px
    EXPECT_LE(region.inBackground, 24 * 14);
    EXPECT_EQ(cv::countNonZero(region.compared), cv::countNonZero(view.liquidCanShow) - region.inBackground);

    // Footage with liquid only beside the domain is liquid the simulation can never show.
    cv::Mat1b outside(level.height, level.width, uchar(0)), inView = outside.clone();
    outside(cv::Rect(0, 40, 4, 10)).setTo(255);
    inView(cv::Rect(70, 40, 4, 10)).setTo(255);
    EXPECT_DOUBLE_EQ(liquidOutOfViewShare({outside, inView}, {}, view), 0.5);
    EXPECT_DOUBLE_EQ(liquidOutOfViewShare({inView}, {}, view), 0.0);
}
