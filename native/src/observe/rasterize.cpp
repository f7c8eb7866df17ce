// Simulated silhouettes: surfaces and particles projected through the camera into one mask.
#include "observe/observe.h"

#include <Eigen/LU>
#include <openvdb/tools/VolumeToMesh.h>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <limits>

namespace viscoscope {

namespace {

// Geometry closer than this to the camera centre (in depth) is clipped away: it cannot be
// projected, and no real surface sits within 0.1 mm of a lens.
constexpr double kNearPlane = 1e-4;

using Polygon = std::vector<Eigen::Vector3d>;

// Sutherland–Hodgman against the half-space z ≥ kNearPlane; a convex polygon stays convex.
Polygon clipToNearPlane(const Polygon& polygon) {
    Polygon clipped;
    for (size_t i = 0; i < polygon.size(); ++i) {
        const Eigen::Vector3d& a = polygon[i];
        const Eigen::Vector3d& b = polygon[(i + 1) % polygon.size()];
        const bool aIn = a.z() >= kNearPlane, bIn = b.z() >= kNearPlane;
        if (aIn) clipped.push_back(a);
        if (aIn != bIn) clipped.push_back(a + (b - a) * ((kNearPlane - a.z()) / (b.z() - a.z())));
    }
    return clipped;
}

// Calls visit(row, firstColumn, lastColumn) for each row span of the pixel centres inside a convex
// image-space polygon. OpenCV's fillPoly/fillConvexPoly are not used because they rasterize integer
// (or fixed-point) vertices with their own edge-inclusion rule, which adds a pixel-wide bias along
// every silhouette edge; sampling centres exactly makes the filled area converge to the true
// projected area. Boundary pixels are included on both sides of a shared edge: harmless for a
// union, and it leaves no cracks between neighbouring triangles.
template <class Visit>
void forEachSpan(const std::vector<Eigen::Vector2d>& polygon, cv::Size size, Visit&& visit) {
    double yMin = std::numeric_limits<double>::infinity(), yMax = -yMin;
    for (const Eigen::Vector2d& p : polygon) {
        yMin = std::min(yMin, p.y());
        yMax = std::max(yMax, p.y());
    }
    const int firstRow = static_cast<int>(std::max(0.0, std::ceil(yMin)));
    const int lastRow = static_cast<int>(std::min(size.height - 1.0, std::floor(yMax)));
    for (int row = firstRow; row <= lastRow; ++row) {
        double left = std::numeric_limits<double>::infinity(), right = -left;
        for (size_t i = 0; i < polygon.size(); ++i) {
            const Eigen::Vector2d& a = polygon[i];
            const Eigen::Vector2d& b = polygon[(i + 1) % polygon.size()];
            if (row < std::min(a.y(), b.y()) || row > std::max(a.y(), b.y())) continue;
            const double x = a.y() == b.y() ? a.x() : a.x() + (row - a.y()) * (b.x() - a.x()) / (b.y() - a.y());
            const double otherX = a.y() == b.y() ? b.x() : x;  // a horizontal edge spans both ends
            left = std::min({left, x, otherX});
            right = std::max({right, x, otherX});
        }
        const int firstColumn = static_cast<int>(std::max(0.0, std::ceil(left)));
        const int lastColumn = static_cast<int>(std::min(size.width - 1.0, std::floor(right)));
        if (firstColumn <= lastColumn) visit(row, firstColumn, lastColumn);
    }
}

// A planar polygon's camera depth at a pixel: 1/z is affine in the image coordinates of a pinhole
// camera, so three of its projected vertices fix it (exact without lens distortion).
class DepthPlane {
public:
    DepthPlane(const Polygon& inCamera, const std::vector<Eigen::Vector2d>& projected) {
        Eigen::Matrix3d A;
        Eigen::Vector3d inverseDepth;
        for (int i = 0; i < 3; ++i) {
            A.row(i) << projected[i].x(), projected[i].y(), 1.0;
            inverseDepth[i] = 1.0 / inCamera[i].z();
        }
        const Eigen::FullPivLU<Eigen::Matrix3d> lu(A);
        if (lu.isInvertible()) {
            coefficients_ = lu.solve(inverseDepth);
        } else {  // seen edge-on: it covers no pixel's interior; its nearest point stands for it
            double nearest = std::numeric_limits<double>::infinity();
            for (const Eigen::Vector3d& p : inCamera) nearest = std::min(nearest, p.z());
            coefficients_ = {0, 0, 1.0 / nearest};
        }
    }
    double depth(int row, int column) const {
        return 1.0 / std::max(coefficients_.dot(Eigen::Vector3d(column, row, 1.0)), 1e-300);
    }

private:
    Eigen::Vector3d coefficients_;
};

// Projects each triangle, clipped to the near plane, and hands it to visit(inCamera, projected).
template <class Visit>
void forEachProjectedTriangle(const std::vector<Eigen::Vector3d>& vertices,
                              const std::vector<Eigen::Vector3i>& triangles, const PinholeCamera& camera,
                              Visit&& visit) {
    std::vector<Eigen::Vector3d> inCamera(vertices.size());
    for (size_t i = 0; i < vertices.size(); ++i) inCamera[i] = toCameraFrame(camera, vertices[i]);
    std::vector<Eigen::Vector2d> projected;
    for (const Eigen::Vector3i& triangle : triangles) {
        const Polygon clipped = clipToNearPlane({inCamera[triangle[0]], inCamera[triangle[1]], inCamera[triangle[2]]});
        if (clipped.size() < 3) continue;
        projected.clear();
        for (const Eigen::Vector3d& p : clipped) projected.push_back(projectCameraPoint(camera, p));
        visit(clipped, projected);
    }
}

cv::Mat1b emptyMask(const PinholeCamera& camera) { return cv::Mat1b(camera.height, camera.width, uchar(0)); }

}  // namespace

cv::Mat1b rasterizeMesh(const std::vector<Eigen::Vector3d>& vertices, const std::vector<Eigen::Vector3i>& triangles,
                        const PinholeCamera& camera, const SceneVisibility* view) {
    cv::Mat1b mask = emptyMask(camera);
    const bool occluded = view && !view->occluderDepth.empty();
    forEachProjectedTriangle(vertices, triangles, camera, [&](const Polygon& inCamera, const auto& projected) {
        if (!occluded) {
            forEachSpan(projected, mask.size(), [&](int row, int first, int last) {
                std::fill(mask.ptr(row) + first, mask.ptr(row) + last + 1, uchar(255));
            });
            return;
        }
        const DepthPlane plane(inCamera, projected);
        forEachSpan(projected, mask.size(), [&](int row, int first, int last) {
            for (int column = first; column <= last; ++column)
                if (view->shows(row, column, plane.depth(row, column))) mask(row, column) = 255;
        });
    });
    return mask;
}

cv::Mat1f nearestDepth(const std::vector<Eigen::Vector3d>& vertices, const std::vector<Eigen::Vector3i>& triangles,
                       const PinholeCamera& camera) {
    cv::Mat1f depth(camera.height, camera.width, std::numeric_limits<float>::infinity());
    forEachProjectedTriangle(vertices, triangles, camera, [&](const Polygon& inCamera, const auto& projected) {
        const DepthPlane plane(inCamera, projected);
        forEachSpan(projected, depth.size(), [&](int row, int first, int last) {
            for (int column = first; column <= last; ++column)
                depth(row, column) = std::min(depth(row, column), float(plane.depth(row, column)));
        });
    });
    return depth;
}

TriangleMesh meshFromLevelSet(const openvdb::FloatGrid& levelSet) {
    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec3I> triangles;
    std::vector<openvdb::Vec4I> quads;
    openvdb::tools::volumeToMesh(levelSet, points, triangles, quads, /*isovalue=*/0.0, /*adaptivity=*/0.0);
    TriangleMesh mesh;
    mesh.vertices.reserve(points.size());
    for (const openvdb::Vec3s& p : points) mesh.vertices.emplace_back(p.x(), p.y(), p.z());
    mesh.triangles.reserve(triangles.size() + 2 * quads.size());
    for (const openvdb::Vec3I& t : triangles) mesh.triangles.emplace_back(t[0], t[1], t[2]);
    for (const openvdb::Vec4I& q : quads) {
        mesh.triangles.emplace_back(q[0], q[1], q[2]);
        mesh.triangles.emplace_back(q[0], q[2], q[3]);
    }
    return mesh;
}

cv::Mat1b silhouetteFromLevelSet(const openvdb::FloatGrid& levelSet, const PinholeCamera& camera,
                                 const SceneVisibility* view) {
    const TriangleMesh mesh = meshFromLevelSet(levelSet);
    return rasterizeMesh(mesh.vertices, mesh.triangles, camera, view);
}

namespace {

// Fills the axis-aligned ellipse at pixel centres, like the triangle fill (cv::ellipse goes through
// a polygon and costs far more for discs of a few pixels). The pixel holding the centre is always
// set, so that particles far away still leave a trace for the closing to join.
void fillDisc(const Eigen::Vector2d& centre, double rx, double ry, cv::Mat1b& mask) {
    const int firstRow = std::max(0, static_cast<int>(std::ceil(centre.y() - ry)));
    const int lastRow = std::min(mask.rows - 1, static_cast<int>(std::floor(centre.y() + ry)));
    for (int row = firstRow; row <= lastRow; ++row) {
        const double dy = (row - centre.y()) / ry;
        const double halfWidth = rx * std::sqrt(std::max(0.0, 1 - dy * dy));
        const int firstColumn = std::max(0, static_cast<int>(std::ceil(centre.x() - halfWidth)));
        const int lastColumn = std::min(mask.cols - 1, static_cast<int>(std::floor(centre.x() + halfWidth)));
        if (firstColumn <= lastColumn) std::fill(mask.ptr(row) + firstColumn, mask.ptr(row) + lastColumn + 1, uchar(255));
    }
    const int col = static_cast<int>(std::lround(centre.x())), row = static_cast<int>(std::lround(centre.y()));
    if (col >= 0 && row >= 0 && col < mask.cols && row < mask.rows) mask(row, col) = 255;
}

}  // namespace

cv::Mat1b silhouetteFromParticles(const std::vector<Eigen::Vector3d>& points, double radius,
                                  const PinholeCamera& camera, int closeKernel, const SceneVisibility* view) {
    cv::Mat1b mask = emptyMask(camera);
    for (const Eigen::Vector3d& point : points) {
        const Eigen::Vector3d p = toCameraFrame(camera, point);
        if (p.z() < kNearPlane) continue;
        const Eigen::Vector2d centre = projectCameraPoint(camera, p);
        if (view && !view->occluderDepth.empty()) {
            const int col = static_cast<int>(std::lround(centre.x())), row = static_cast<int>(std::lround(centre.y()));
            const bool inImage = col >= 0 && row >= 0 && col < mask.cols && row < mask.rows;
            if (inImage && !view->shows(row, col, p.z())) continue;
        }
        fillDisc(centre, camera.K(0, 0) * radius / p.z(), camera.K(1, 1) * radius / p.z(), mask);
    }
    if (closeKernel > 1) {
        const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(closeKernel, closeKernel));
        cv::morphologyEx(mask, mask, cv::MORPH_CLOSE, kernel);
    }
    return mask;
}

std::vector<Eigen::Vector3d> innerBandPoints(const openvdb::FloatGrid& levelSet) {
    const double voxelSize = levelSet.voxelSize()[0];
    std::vector<Eigen::Vector3d> points;
    for (auto voxel = levelSet.cbeginValueOn(); voxel; ++voxel) {
        if (!voxel.isVoxelValue() || *voxel > 0 || *voxel < -voxelSize) continue;
        const openvdb::Vec3d p = levelSet.indexToWorld(voxel.getCoord());
        points.emplace_back(p.x(), p.y(), p.z());
    }
    return points;
}

cv::Mat1b silhouetteFromLevelSetFast(const openvdb::FloatGrid& levelSet, const PinholeCamera& camera,
                                     const SceneVisibility* view) {
    const double voxelSize = levelSet.voxelSize()[0];
    return silhouetteFromParticles(innerBandPoints(levelSet), 0.5 * voxelSize, camera, 3, view);
}

}  // namespace viscoscope
