// The rigid motion that best carries a body's rest positions to where its grains are now (least
// squares: the centroids and the rotation of the SVD of the cross-covariance; Kabsch 1976), for
// tests that measure how far grains are from moving as one rigid piece.
#pragma once
#include <Eigen/Dense>
#include <cstddef>
#include <vector>

namespace grains::test {

struct RigidFit {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();       // of the present positions
  Eigen::Vector3d rest_centre = Eigen::Vector3d::Zero();  // of the rest positions
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  // Where the fit puts a rest position.
  Eigen::Vector3d place(const Eigen::Vector3d& rest) const { return centre + R * (rest - rest_centre); }
};

// now[k] and rest[k] are the same grain; both non-empty and of equal length.
inline RigidFit rigid_fit(const std::vector<Eigen::Vector3d>& now,
                          const std::vector<Eigen::Vector3d>& rest) {
  RigidFit f;
  const double n = static_cast<double>(now.size());
  for (size_t k = 0; k < now.size(); ++k) {
    f.centre += now[k] / n;
    f.rest_centre += rest[k] / n;
  }
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  for (size_t k = 0; k < now.size(); ++k)
    A += (now[k] - f.centre) * (rest[k] - f.rest_centre).transpose();
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(A, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU();
  if ((U * svd.matrixV().transpose()).determinant() < 0) U.col(2) = -U.col(2);  // no reflection
  f.R = U * svd.matrixV().transpose();
  return f;
}

// Grain k of a packed 3-vector attribute.
inline Eigen::Vector3d point_of(const float* a, size_t k) {
  return {a[3 * k], a[3 * k + 1], a[3 * k + 2]};
}

}  // namespace grains::test
