// Pieces shared by the file tests (pose_graph_file_test.cc, prior_file_test.cc): reading text
// under a fixed name, the error a text reads to, exact number formatting, random values.
#pragma once

#include <charconv>
#include <random>
#include <sstream>
#include <string>
#include <variant>

#include <gtest/gtest.h>

#include "arbor_slam/io/pose_graph_file.h"

namespace arbor::testing {

inline constexpr char kFileName[] = "test.g2o";

inline AnyPoseGraph readText(const std::string& text, const ReadOptions& options = {},
                             ReadReport* report = nullptr) {
  std::istringstream in(text);
  return readPoseGraph(in, kFileName, options, report);
}

template <class G>
PoseGraph<G> readAs(const std::string& text, const ReadOptions& options = {},
                    ReadReport* report = nullptr) {
  AnyPoseGraph any = readText(text, options, report);
  EXPECT_TRUE(std::holds_alternative<PoseGraph<G>>(any));
  return std::get<PoseGraph<G>>(std::move(any));
}

/// The FileError message of reading `text`, or "" when it reads without error.
inline std::string readError(const std::string& text, const ReadOptions& options = {}) {
  try {
    readText(text, options);
  } catch (const FileError& error) {
    return error.what();
  }
  return "";
}

/// v in its shortest exactly-round-tripping form.
inline std::string num(double v) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), v);
  return std::string(buffer, result.ptr);
}

/// A dense, exactly symmetric, positive-definite N×N matrix.
template <int N>
Eigen::Matrix<double, N, N> randomSpd(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Matrix<double, N, N> a;
  for (int k = 0; k < a.size(); ++k) a.data()[k] = n(rng);
  Eigen::Matrix<double, N, N> omega =
      a * a.transpose() + 0.1 * Eigen::Matrix<double, N, N>::Identity();
  return 0.5 * (omega + omega.transpose());  // exactly symmetric
}

template <class G>
G randomPose(std::mt19937_64& rng, double scale) {
  std::normal_distribution<double> n(0.0, scale);
  typename G::Tangent tau;
  for (int k = 0; k < G::kDoF; ++k) tau(k) = n(rng);
  return G::Exp(tau);
}

inline void expectSamePose(const SE2& a, const SE2& b) {
  EXPECT_EQ(a.x(), b.x());
  EXPECT_EQ(a.y(), b.y());
  EXPECT_NEAR(a.cos(), b.cos(), 1e-15);
  EXPECT_NEAR(a.sin(), b.sin(), 1e-15);
}

inline void expectSamePose(const SE3& a, const SE3& b) {
  EXPECT_TRUE((a.translation().array() == b.translation().array()).all());
  EXPECT_LE((a.quaternion().coeffs() - b.quaternion().coeffs()).cwiseAbs().maxCoeff(), 1e-15);
}

}  // namespace arbor::testing
