// Trajectory I/O (TUM, KITTI, EuRoC) round trips and line-numbered errors, interpolation
// exactness, resampling.
#include "m2s/common/trajectory.h"

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

namespace m2s {
namespace {

namespace fs = std::filesystem;

class TrajectoryTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("m2s_trajectory_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Write(const std::string& name, const std::string& text) const {
    std::ofstream((dir_ / name).string()) << text;
    return (dir_ / name).string();
  }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  fs::path dir_;
};

Pose3 RandomPose(int i) {
  const double a = 0.37 * i;
  return Pose3(Eigen::Quaterniond(
                   Eigen::AngleAxisd(a, Eigen::Vector3d(std::sin(a), 1.0, 0.3 * i).normalized())),
               Eigen::Vector3d(std::cos(a) * 1.3, 0.1 * i - 2.0, 1.0 / (1.0 + i)));
}

Trajectory MakeTrajectory(int n, double t0, double dt) {
  std::vector<TimedPose> poses;
  for (int i = 0; i < n; ++i) poses.push_back({t0 + dt * i, RandomPose(i)});
  return *Trajectory::FromPoses(poses);
}

void ExpectPoseNear(const Pose3& a, const Pose3& b, double tolerance) {
  EXPECT_LT((a.translation() - b.translation()).norm(), tolerance);
  EXPECT_LT(RotationAngle(a.rotation().conjugate() * b.rotation()), tolerance);
}

void ExpectError(const Expected<Trajectory>& result, const std::string& fragment) {
  ASSERT_FALSE(result.ok());
  EXPECT_NE(result.error().find(fragment), std::string::npos) << result.error();
}

TEST_F(TrajectoryTest, TumRoundTripIsExact) {
  const Trajectory original = MakeTrajectory(50, 1403636579.763555527, 1.0 / 30.0);
  ASSERT_TRUE(WriteTum(Path("a.tum"), original).ok());
  const Expected<Trajectory> read = ReadTum(Path("a.tum"));
  ASSERT_TRUE(read.ok()) << read.error();
  ASSERT_EQ(read->size(), original.size());
  for (size_t i = 0; i < original.size(); ++i) {
    EXPECT_EQ((*read)[i].timestamp, original[i].timestamp);
    EXPECT_EQ((*read)[i].world_from_camera.translation(),
              original[i].world_from_camera.translation());
    EXPECT_TRUE((*read)[i].world_from_camera.rotation().coeffs().isApprox(
        original[i].world_from_camera.rotation().coeffs(), 1e-15));
  }
}

TEST_F(TrajectoryTest, TumAcceptsCommentsBlankLinesCommasAndUnsortedLines) {
  const Expected<Trajectory> t =
      ReadTum(Write("b.tum",
                    "# header\n\n"
                    "2.0 1 2 3 0 0 0 1\n"
                    "  # indented comment\n"
                    "1.0,0,0,0,0,0,0.7071067811865476,0.7071067811865476\n"
                    "3.0\t0 0 0 0 0 0 2\r\n"));
  ASSERT_TRUE(t.ok()) << t.error();
  ASSERT_EQ(t->size(), 3u);
  EXPECT_EQ((*t)[0].timestamp, 1.0);
  EXPECT_NEAR(RotationAngle((*t)[0].world_from_camera.rotation()), M_PI / 2, 1e-12);
  EXPECT_EQ((*t)[1].world_from_camera.translation(), Eigen::Vector3d(1, 2, 3));
  EXPECT_NEAR((*t)[2].world_from_camera.rotation().w(), 1.0, 1e-15);  // normalised
}

TEST_F(TrajectoryTest, TumErrorsNameTheLine) {
  ExpectError(ReadTum(Path("missing.tum")), "cannot open");
  ExpectError(ReadTum(Write("c.tum", "# only a comment\n")), "no poses");
  ExpectError(ReadTum(Write("d.tum", "0 0 0 0 0 0 0 1\n1 0 0 0 0 0 1\n")), "line 2: expected 8");
  ExpectError(ReadTum(Write("e.tum", "#\n#\n0 0 0 x 0 0 0 1\n")), "line 3: field 4 'x'");
  ExpectError(ReadTum(Write("f.tum", "0 0 0 0 0 0 0 0\n")), "line 1: quaternion has zero norm");
  ExpectError(ReadTum(Write("g.tum", "0 nan 0 0 0 0 0 1\n")), "not a finite number");
  ExpectError(ReadTum(Write("h.tum", "1 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n")), "duplicate timestamp");
}

TEST_F(TrajectoryTest, KittiPosesWithFramePeriodOrTimesFile) {
  // Pose 1: a rotation of 90 degrees about y and a translation.
  const std::string poses = Write("poses.txt",
                                  "1 0 0 0 0 1 0 0 0 0 1 0\n"
                                  "0 0 1 1.5 0 1 0 -2 -1 0 0 3\n");
  KittiReadOptions options;
  options.frame_period_s = 0.1;
  options.start_time_s = 5.0;
  const Expected<Trajectory> t = ReadKitti(poses, options);
  ASSERT_TRUE(t.ok()) << t.error();
  ASSERT_EQ(t->size(), 2u);
  EXPECT_DOUBLE_EQ((*t)[1].timestamp, 5.1);
  const Pose3& p = (*t)[1].world_from_camera;
  EXPECT_EQ(p.translation(), Eigen::Vector3d(1.5, -2, 3));
  // world_from_camera maps the camera's forward axis (z) to the matrix's third column.
  EXPECT_LT((p.rotation() * Eigen::Vector3d::UnitZ() - Eigen::Vector3d(1, 0, 0)).norm(), 1e-12);

  options.times_path = Write("times.txt", "0.0\n0.103\n");
  const Expected<Trajectory> timed = ReadKitti(poses, options);
  ASSERT_TRUE(timed.ok()) << timed.error();
  EXPECT_EQ((*timed)[1].timestamp, 0.103);

  options.times_path = Write("short_times.txt", "0.0\n");
  ExpectError(ReadKitti(poses, options), "1 timestamps for 2 poses");
  ExpectError(ReadKitti(Write("p2.txt", "1 0 0 0 0 1 0 0 0 0 1\n")), "line 1: expected 12");
  ExpectError(ReadKitti(Write("p3.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n2 0 0 0 0 1 0 0 0 0 1 0\n")),
              "line 2: the 3x3 block is not a rotation");
}

TEST_F(TrajectoryTest, EurocGroundTruth) {
  const std::string path = Write(
      "data.csv",
      "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], "
      "q_RS_z [], v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x\n"
      "1403636580838555648,4.688319,-1.786938,0.783338,0.534108,-0.153029,-0.827383,-0.082152,"
      "-0.027876,0.033207,0.800006,-0.003172\n"
      "1403636580843555328,4.688177,-1.786770,0.787350,0.534640,-0.152990,-0.826976,-0.082863,"
      "-0.029272,0.033992,0.804771,-0.003172\n");
  const Expected<Trajectory> body = ReadEuroc(path);
  ASSERT_TRUE(body.ok()) << body.error();
  ASSERT_EQ(body->size(), 2u);
  EXPECT_NEAR((*body)[0].timestamp, 1403636580.838555648, 1e-6);
  EXPECT_NEAR((*body)[1].timestamp - (*body)[0].timestamp, 0.00499968, 1e-6);
  const Eigen::Quaterniond q(0.534108, -0.153029, -0.827383, -0.082152);  // w, x, y, z
  EXPECT_TRUE(
      (*body)[0].world_from_camera.rotation().coeffs().isApprox(q.normalized().coeffs(), 1e-12));
  EXPECT_EQ((*body)[0].world_from_camera.translation(),
            Eigen::Vector3d(4.688319, -1.786938, 0.783338));

  EurocReadOptions options;
  options.body_from_camera = RandomPose(3);
  const Expected<Trajectory> camera = ReadEuroc(path, options);
  ASSERT_TRUE(camera.ok());
  ExpectPoseNear((*camera)[1].world_from_camera,
                 (*body)[1].world_from_camera * options.body_from_camera, 1e-12);

  ExpectError(ReadEuroc(Write("bad.csv", "#h\n1.5e9,0,0,0,1,0,0,0\n")), "line 2: timestamp");
  ExpectError(ReadEuroc(Write("short.csv", "100,0,0,0,1,0,0\n")), "line 1: expected at least 8");
}

TEST(Trajectory, InterpolationIsExactAtSamplesAndSlerpsBetween) {
  const Trajectory t = MakeTrajectory(10, 2.0, 0.5);
  for (const TimedPose& sample : t) {
    const Expected<Pose3> p = t.Interpolate(sample.timestamp);
    ASSERT_TRUE(p.ok());
    EXPECT_EQ(p->translation(), sample.world_from_camera.translation());
    EXPECT_EQ(p->rotation().coeffs(), sample.world_from_camera.rotation().coeffs());
  }
  // Midpoint: the mean translation and the rotation half-way along the relative rotation.
  for (size_t i = 0; i + 1 < t.size(); ++i) {
    const Pose3& a = t[i].world_from_camera;
    const Pose3& b = t[i + 1].world_from_camera;
    const Expected<Pose3> mid = t.Interpolate(0.5 * (t[i].timestamp + t[i + 1].timestamp));
    ASSERT_TRUE(mid.ok());
    EXPECT_LT((mid->translation() - 0.5 * (a.translation() + b.translation())).norm(), 1e-12);
    Eigen::AngleAxisd relative(a.rotation().conjugate() * b.rotation());
    if (relative.angle() > M_PI) relative.angle() -= 2 * M_PI;
    const Eigen::Quaterniond expected =
        a.rotation() *
        Eigen::Quaterniond(Eigen::AngleAxisd(0.5 * relative.angle(), relative.axis()));
    EXPECT_LT(RotationAngle(expected.conjugate() * mid->rotation()), 1e-9) << i;
  }
  EXPECT_FALSE(t.Interpolate(1.999).ok());
  EXPECT_FALSE(t.Interpolate(6.501).ok());
  EXPECT_NE(t.Interpolate(7.0).error().find("outside"), std::string::npos);
  EXPECT_FALSE(Trajectory().Interpolate(0.0).ok());
}

TEST(Trajectory, ResampleAtAFrameRate) {
  const Trajectory t = MakeTrajectory(21, 10.0, 0.1);  // [10, 12] at 10 Hz
  const Expected<Trajectory> r = t.Resample(30.0);
  ASSERT_TRUE(r.ok()) << r.error();
  ASSERT_EQ(r->size(), 61u);
  for (size_t k = 0; k < r->size(); ++k) {
    EXPECT_NEAR((*r)[k].timestamp, 10.0 + k / 30.0, 1e-12);
    ExpectPoseNear((*r)[k].world_from_camera, *t.Interpolate((*r)[k].timestamp), 1e-12);
  }
  EXPECT_EQ(r->end_time(), t.end_time());
  EXPECT_EQ(t.Resample(7.0)->size(), 15u);  // 10 + 14/7 = 12 exactly
  EXPECT_EQ(t.Resample(4.0)->size(), 9u);
  EXPECT_FALSE(t.Resample(0.0).ok());
  EXPECT_FALSE(t.Resample(-30.0).ok());
  EXPECT_FALSE(Trajectory().Resample(30.0).ok());
  EXPECT_FALSE(t.SampleAt({10.5, 12.5}).ok());
}

TEST(Trajectory, FromPosesSortsAndRejectsNonFinite) {
  const Expected<Trajectory> t =
      Trajectory::FromPoses({{3.0, RandomPose(1)}, {1.0, RandomPose(2)}, {2.0, RandomPose(3)}});
  ASSERT_TRUE(t.ok());
  EXPECT_EQ((*t)[0].timestamp, 1.0);
  EXPECT_EQ((*t)[2].timestamp, 3.0);
  EXPECT_FALSE(Trajectory::FromPoses({{NAN, Pose3()}}).ok());
  EXPECT_FALSE(Trajectory::FromPoses(
                   {{0.0, Pose3(Eigen::Quaterniond::Identity(), Eigen::Vector3d(INFINITY, 0, 0))}})
                   .ok());
}

TEST_F(TrajectoryTest, LoadTrajectoryOrDefaultReadsTheFileOrTakesTheDefaultWalk) {
  const Trajectory original = MakeTrajectory(5, 10.0, 0.1);
  ASSERT_TRUE(WriteTum(Path("b.tum"), original).ok());
  const Expected<Trajectory> read = LoadTrajectoryOrDefault(Path("b.tum"));
  ASSERT_TRUE(read.ok()) << read.error();
  ASSERT_EQ(read->size(), 5u);
  EXPECT_EQ((*read)[4].timestamp, original[4].timestamp);
  ExpectError(LoadTrajectoryOrDefault(Path("missing.tum")), "missing.tum");

  const Expected<Trajectory> walk = LoadTrajectoryOrDefault("");
  ASSERT_TRUE(walk.ok()) << walk.error();
  const Trajectory reference = DefaultTrajectory();
  ASSERT_EQ(walk->size(), reference.size());
  EXPECT_EQ((*walk)[walk->size() - 1].world_from_camera.translation(),
            reference[reference.size() - 1].world_from_camera.translation());
}

}  // namespace
}  // namespace m2s
