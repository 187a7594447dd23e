// One Eigen vocabulary for all of flank (STYLE 5). Shapes are documented as "#P by 3".
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace flank {

using Vec2 = Eigen::Vector2d;
using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using VecX = Eigen::VectorXd;
using MatX = Eigen::MatrixXd;
// #P by 3 point or vector sets, row-major so that one row is one contiguous point.
using Points = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
// #F by 3 triangle vertex indices.
using Faces = Eigen::Matrix<int, Eigen::Dynamic, 3, Eigen::RowMajor>;

using PointsRef = Eigen::Ref<const Points>;

}  // namespace flank
